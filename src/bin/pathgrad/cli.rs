//! The command line's grammar: the global flags and one subcommand per module.

use clap::{Parser, Subcommand};

use crate::common::parse_define;
use crate::{batch, grad, optimize, render, variance};

/// A differentiable path tracer on Vulkan compute shaders.
#[derive(Parser, Debug)]
#[command(name = "pathgrad", version, about)]
pub(crate) struct Cli {
    /// Log more (repeat for debug output); `RUST_LOG` overrides.
    #[arg(short, long, global = true, action = clap::ArgAction::Count)]
    pub(crate) verbose: u8,
    #[command(subcommand)]
    pub(crate) command: Command,
}

#[derive(Subcommand, Debug)]
pub(crate) enum Command {
    /// Render a scene to an EXR (plus a PNG preview) or a PNG.
    Render(render::RenderArgs),
    /// Gradients of a loss against a target image, or a forward-mode image gradient.
    Grad(grad::GradArgs),
    /// Variance of gradient estimates per strategy over independent runs: per-pixel image-gradient
    /// variance maps, or the loss gradient's variance (--target), with equal-time efficiency.
    Variance(variance::VarianceArgs),
    /// Recover parameters from a target image: Adam on loss gradients, with CSV, curves and resume.
    Optimize(optimize::OptimizeArgs),
    /// Run the items of a JSONL manifest (renders, losses, gradients, image gradients), or this
    /// process's shard of them (--shard I/N, Slurm job arrays, Kubernetes Indexed Jobs).
    Batch(batch::BatchArgs),
    /// Merge the summaries of `batch` shards and sum their gradients in item order.
    Reduce(batch::ReduceArgs),
    /// List a scene's differentiable parameters: names, sizes, bounds and current values.
    Params {
        /// The scene: builtin:NAME or a scene file.
        scene: String,
        /// Override a scene file's default: NAME=VALUE (repeatable).
        #[arg(short = 'D', long = "define", value_name = "NAME=VALUE", value_parser = parse_define)]
        defines: Vec<(String, String)>,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
        /// Let the scene read files outside its own folder (absolute paths, `..`).
        #[arg(long)]
        allow_outside_folder: bool,
    },
    /// List the Vulkan devices and whether pathgrad can use them.
    Devices {
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
    },
}

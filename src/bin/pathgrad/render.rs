//! `pathgrad render`: a scene to an EXR (with a PNG preview) or a PNG.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context as _, Result, bail};
use clap::Args;
use pathgrad::output::OutputSet;
use pathgrad::phases::{Memory, PhaseReport};

use crate::common::{
    RenderFlags, check_output, options, parse_define, preview_path, progress_bar, refuse_non_finite, save,
};

#[derive(Args, Debug)]
pub(crate) struct RenderArgs {
    /// The scene: builtin:cornell-box, builtin:furnace or builtin:blend.
    pub(crate) scene: String,
    /// Override a scene file's default: NAME=VALUE (repeatable).
    #[arg(short = 'D', long = "define", value_name = "NAME=VALUE", value_parser = parse_define)]
    pub(crate) defines: Vec<(String, String)>,
    /// Output file, .exr or .png.
    #[arg(short, long)]
    pub(crate) output: PathBuf,
    #[command(flatten)]
    pub(crate) flags: RenderFlags,
    /// With an .exr output, do not write the .png preview beside it.
    #[arg(long)]
    pub(crate) no_preview: bool,
    /// Exposure of PNG output in stops (negative darkens).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub(crate) exposure: f32,
    /// Print a JSON summary instead of text. Its `phases` list each phase (parse, assemble,
    /// flatten, bvh, then shading on the CPU reference or device and upload on a GPU, render,
    /// write) with its seconds and the process's RSS and peak RSS at its end (Linux only, else null); `device_bytes` gives the scene's device
    /// buffers (`scene`) and the most device buffer memory held at once (`peak`).
    #[arg(long)]
    pub(crate) json: bool,
    /// After the render, render the same image N more times in this process and report each
    /// one's time (`repeat_s` in the JSON): the steady throughput, without the one-off costs of
    /// opening the device and building the kernels.
    #[arg(long, value_name = "N", default_value_t = 0)]
    pub(crate) repeat: u32,
}

pub(crate) fn render(args: &RenderArgs) -> Result<()> {
    // Every option and output path is checked before anything is rendered.
    let is_exr = check_output(&args.output)?;
    if !args.exposure.is_finite() {
        bail!("invalid --exposure {}: must be a finite number of stops", args.exposure);
    }
    let mut outputs = OutputSet::new();
    let main_file = outputs.stage(&args.output)?;
    let preview_file =
        if is_exr && !args.no_preview { Some(outputs.stage(&preview_path(&args.output))?) } else { None };
    let mut report = PhaseReport::new();
    let scene = args.flags.load_reporting(&args.scene, &args.defines, &mut report)?;
    let opts = options(&scene, &args.flags)?;
    let progress = progress_bar(u64::from(opts.spp), "rendering [{bar:40}] {pos}/{len} spp", args.json);
    let start = Instant::now();
    // The backend takes the scene over: a copy's meshes would only take memory.
    let opened = args.flags.backend_owned(scene, &args.scene, args.json)?;
    report.extend(&opened.report);
    let mut backend = opened.backend;
    let device = backend.describe();
    let render_start = Instant::now();
    let image = backend
        .render_pass(&opts, pathgrad::rng::PassTag::Primal, &mut |done, _| progress.set_position(u64::from(done)))
        .with_context(|| format!("rendering {}", args.scene))?;
    report.record("render", render_start);
    let seconds = start.elapsed().as_secs_f64();
    progress.finish_and_clear();
    refuse_non_finite(&image, "the render")?;
    let mut repeat_s = Vec::new();
    for _ in 0..args.repeat {
        let start = Instant::now();
        backend
            .render_pass(&opts, pathgrad::rng::PassTag::Primal, &mut |_, _| {})
            .with_context(|| format!("rendering {} again (--repeat)", args.scene))?;
        repeat_s.push(start.elapsed().as_secs_f64());
    }
    let write_start = Instant::now();
    save(&image, &main_file, is_exr, args.exposure)?;
    if let Some(preview) = &preview_file {
        image.write_png(preview, args.exposure)?;
    }
    report.record("write", write_start);
    let written = outputs.destinations();
    outputs.commit()?;
    let samples = f64::from(opts.width) * f64::from(opts.height) * f64::from(opts.spp);
    if args.json {
        let summary = serde_json::json!({
            "scene": args.scene, "device": device, "width": opts.width, "height": opts.height, "spp": opts.spp,
            "max_depth": opts.max_depth, "seed": opts.seed, "time_s": seconds, "samples_per_second": samples / seconds,
            "mean": image.mean(), "outputs": written, "repeat_s": repeat_s,
            "phases": phases_json(&report), "peak_rss_bytes": Memory::now().map(|m| m.peak_rss_bytes),
            "device_bytes": {
                "scene": opened.scene_device_bytes,
                "peak": opened.ctx.as_ref().map(|c| c.peak_buffer_bytes()),
            },
        });
        println!("{summary}");
    } else {
        let names: Vec<_> = written.iter().map(|p| p.display().to_string()).collect();
        println!(
            "rendered {} at {}×{}, {} spp on {device} in {seconds:.2} s ({:.3} M samples/s) → {}",
            args.scene,
            opts.width,
            opts.height,
            opts.spp,
            samples / seconds / 1e6,
            names.join(", ")
        );
        if let Some(best) = repeat_s.iter().copied().reduce(f64::min) {
            println!("  {} repeats: fastest {best:.3} s ({:.3} M samples/s)", repeat_s.len(), samples / best / 1e6);
        }
    }
    Ok(())
}

/// The phases of `report` as JSON objects: `name`, `seconds`, and (Linux) `rss_bytes` and
/// `peak_rss_bytes` at the phase's end.
pub(crate) fn phases_json(report: &PhaseReport) -> serde_json::Value {
    report
        .phases()
        .iter()
        .map(|p| {
            serde_json::json!({
                "name": p.name, "seconds": p.seconds,
                "rss_bytes": p.memory.map(|m| m.rss_bytes), "peak_rss_bytes": p.memory.map(|m| m.peak_rss_bytes),
            })
        })
        .collect()
}

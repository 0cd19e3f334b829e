//! The `pathgrad` command line: `render`, `grad`, `variance`, `optimize`, `batch`, `reduce`, `params` and `devices`,
//! one module each; `common` holds what they share and `cli` the grammar.

mod batch;
mod cli;
mod common;
mod curves;
mod devices;
mod flags;
mod grad;
mod optimize;
mod params;
mod render;
mod variance;

use std::process::ExitCode;

use anyhow::Result;
use clap::Parser;

use cli::{Cli, Command};

fn main() -> ExitCode {
    let cli = Cli::parse();
    let default_level = match cli.verbose {
        0 => "warn",
        1 => "info",
        _ => "debug",
    };
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(default_level));
    // Colours and timestamps help a person at a terminal; in a log file or a CI transcript they
    // are noise (escape codes, a clock nobody asked for).
    let terminal = std::io::IsTerminal::is_terminal(&std::io::stderr());
    let subscriber = tracing_subscriber::fmt().with_env_filter(filter).with_writer(std::io::stderr).with_ansi(terminal);
    if terminal {
        subscriber.init()
    } else {
        subscriber.without_time().init()
    }
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", error_message(&e));
            ExitCode::FAILURE
        }
    }
}

/// The error and its causes on one line, `a: b: c`, leaving out a cause whose text the line
/// already ends with (pathgrad's errors print their OS error, which is also their source).
fn error_message(e: &anyhow::Error) -> String {
    let mut line = String::new();
    for cause in e.chain() {
        let text = flags::with_flags(&cause.to_string());
        if line.ends_with(&text) {
            continue;
        }
        if !line.is_empty() {
            line.push_str(": ");
        }
        line.push_str(&text);
    }
    line
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Params { scene, defines, json, allow_outside_folder } => {
            params::params(&scene, &defines, json, allow_outside_folder)
        }
        Command::Devices { json } => devices::devices(json),
        Command::Render(args) => render::render(&args),
        Command::Grad(args) => grad::grad(&args),
        Command::Variance(args) => variance::run(&args),
        Command::Optimize(args) => optimize::optimize(&args),
        Command::Batch(args) => batch::batch(&args),
        Command::Reduce(args) => batch::reduce(&args),
    }
}

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
    lavapipe_vector_width();
    return_freed_memory();
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
    let subscriber = tracing_subscriber::fmt().with_env_filter(filter).with_writer(|| FlagWriter).with_ansi(terminal);
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

/// stderr for log lines, with the library's option names in them (a warning that names
/// `LoadOptions::environment`) spelled as this CLI's flags.
struct FlagWriter;

impl std::io::Write for FlagWriter {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        // The formatter writes each event whole; a name split across writes stays as it is.
        let text = flags::with_flags(&String::from_utf8_lossy(buf));
        std::io::stderr().write_all(text.as_bytes())?;
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        std::io::stderr().flush()
    }
}

/// lavapipe builds its kernels for the vector width `LP_NATIVE_VECTOR_WIDTH` names, set here with
/// Mesa's shader cache folder by [`pathgrad::gpu::lavapipe_environment`] (512 bits on AVX-512
/// hosts, 128 elsewhere, unless the environment sets a width; a folder per width above 128).
/// Other drivers ignore the width.
fn lavapipe_vector_width() {
    for (name, value) in pathgrad::gpu::lavapipe_environment() {
        // SAFETY: the first thing `main` does, before any thread exists that could read the
        // environment at the same time.
        unsafe { std::env::set_var(name, value) };
    }
}

/// glibc's malloc serves blocks of 128 KiB and more by `mmap` and unmaps them when freed, but
/// raises that threshold (up to 32 MiB) each time such a block is freed, after which blocks below
/// it come from the heap, whose freed middle is never returned to the system. A big scene's
/// loading and BVH build free many such arrays of a few to a few tens of MiB, and at 2 M
/// triangles the heap kept about 75 MiB of them for the rest of the process (issue 38,
/// BENCHMARKS.md): setting the threshold, to its default, turns that raising off.
fn return_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        unsafe extern "C" {
            fn mallopt(param: std::ffi::c_int, value: std::ffi::c_int) -> std::ffi::c_int;
        }
        /// glibc's `M_MMAP_THRESHOLD` (malloc.h).
        const M_MMAP_THRESHOLD: std::ffi::c_int = -3;
        // SAFETY: `mallopt` only sets an allocator parameter; called before any thread exists.
        unsafe { mallopt(M_MMAP_THRESHOLD, 128 * 1024) };
    }
}

/// The error and its causes on one line, `a: b: c`, leaving out a cause whose text the line
/// already ends with (pathgrad's errors print their OS error, which is also their source).
fn error_message(e: &anyhow::Error) -> String {
    error_message_with(e, flags::with_flags)
}

/// [`error_message`] with the library's option names spelled by `names` (the CLI's flags, or a
/// manifest's keys: [`flags::with_keys`]).
fn error_message_with(e: &anyhow::Error, names: fn(&str) -> String) -> String {
    let mut line = String::new();
    for cause in e.chain() {
        let text = names(&cause.to_string());
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

//! The `pathgrad` command line: `render`, `grad`, `variance`, `optimize`, `params` and `devices`.

mod curves;
mod flags;
mod optimize;
mod variance;

use pathgrad::backend::Backend;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{Context as _, Result, bail};
use clap::{Args, Parser, Subcommand};
use pathgrad::gpu::{Context, ContextDesc, DeviceChoice, Renderer};
use pathgrad::image::Image;
use pathgrad::integrator::RenderOptions;
use pathgrad::output::OutputSet;

/// Samples per pixel when neither `--spp` nor the scene names a number.
const DEFAULT_SPP: u32 = 16;

/// A differentiable path tracer on Vulkan compute shaders.
#[derive(Parser, Debug)]
#[command(name = "pathgrad", version, about)]
struct Cli {
    /// Log more (repeat for debug output); `RUST_LOG` overrides.
    #[arg(short, long, global = true, action = clap::ArgAction::Count)]
    verbose: u8,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Render a scene to an EXR (plus a PNG preview) or a PNG.
    Render(RenderArgs),
    /// Gradients of a loss against a target image, or a forward-mode image gradient.
    Grad(GradArgs),
    /// Variance of gradient estimates per strategy over independent runs: per-pixel image-gradient
    /// variance maps, or the loss gradient's variance (--target), with equal-time efficiency.
    Variance(variance::VarianceArgs),
    /// Recover parameters from a target image: Adam on loss gradients, with CSV, curves and resume.
    Optimize(optimize::OptimizeArgs),
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

/// A backend opened by [`RenderFlags::backend`].
struct Opened {
    backend: Box<dyn Backend>,
    /// The Vulkan context (none for the CPU reference): memory figures.
    ctx: Option<std::sync::Arc<pathgrad::gpu::Context>>,
    /// Microseconds spent building kernel variants so far (see `announce_compiles`).
    compile_us: std::sync::Arc<std::sync::atomic::AtomicU64>,
}

/// Options every rendering command accepts.
#[derive(Args, Debug)]
struct RenderFlags {
    /// Samples per pixel, at most 1048576 (default: the scene's, else 16).
    #[arg(long)]
    spp: Option<u32>,
    /// Image width (default: the scene's).
    #[arg(long)]
    width: Option<u32>,
    /// Image height (default: the scene's).
    #[arg(long)]
    height: Option<u32>,
    /// Maximum surface interactions per path, at most 1024; -1 is unbounded: Russian roulette
    /// ends paths, and none goes beyond 1024 (default: the scene's).
    #[arg(long, allow_negative_numbers = true)]
    max_depth: Option<i64>,
    /// Random seed.
    #[arg(long, default_value_t = 0)]
    seed: u32,
    /// Vulkan device: an index or UUID from `pathgrad devices`, or `cpu` (env: PATHGRAD_DEVICE).
    #[arg(long)]
    device: Option<String>,
    /// Run on the CPU reference implementation instead of Vulkan (the same estimators and random
    /// numbers; slower).
    #[arg(long, conflicts_with = "device")]
    cpu: bool,
    /// Let the scene read files outside its own folder (absolute paths, `..`); by default a
    /// scene reads only the files beside and below it.
    #[arg(long)]
    allow_outside_folder: bool,
}

impl RenderFlags {
    /// The backend these flags ask for, on `scene`: the CPU reference with `--cpu`, else a
    /// renderer on the chosen device (first compiles announced on stderr unless `quiet`).
    fn backend(&self, scene: &pathgrad::scene::Scene, spec: &str, quiet: bool) -> Result<Opened> {
        if self.cpu {
            let cpu = pathgrad::cpu::Reference::new(scene).with_context(|| format!("loading {spec}"))?;
            return Ok(Opened { backend: Box::new(cpu), ctx: None, compile_us: Default::default() });
        }
        let ctx = context(&self.device)?;
        let mut renderer = Renderer::new(&ctx, scene).with_context(|| format!("loading {spec}"))?;
        let compile_us = announce_compiles(&mut renderer, quiet);
        Ok(Opened { backend: Box::new(renderer), ctx: Some(ctx), compile_us })
    }

    /// Loads `spec` for these flags: curved shapes are tessellated for the size rendered.
    fn load(&self, spec: &str, defines: &[(String, String)]) -> Result<pathgrad::scene::Scene> {
        let options = pathgrad::scene::LoadOptions {
            defines: defines.to_vec(),
            width: self.width,
            height: self.height,
            allow_outside_folder: self.allow_outside_folder,
        };
        Ok(pathgrad::scene::load_with(spec, &options)?)
    }
}

/// How gradient passes sample paths: every command that estimates gradients takes these.
#[derive(Args, Debug, Clone)]
struct StrategyArgs {
    /// Gradient sampling strategy: `bsdf` (plain PRB, the baseline) or `diff` (differential path
    /// sampling of one vertex, Su & Gkioulekas).
    #[arg(long, default_value = "bsdf")]
    strategy: String,
    /// Probability that `diff` makes a capable vertex the differential vertex [default: 0.5]
    /// (only with `--strategy diff`).
    #[arg(long)]
    q: Option<f32>,
    /// Turn next-event estimation off (for both strategies).
    #[arg(long)]
    no_nee: bool,
    /// The parameter whose derivative drives `diff`'s sampler (default: the first parameter the
    /// command differentiates).
    #[arg(long, value_name = "NAME")]
    diff_param: Option<String>,
}

impl StrategyArgs {
    /// `--q`, or its default.
    fn q(&self) -> f32 {
        self.q.unwrap_or(pathgrad::integrator::DEFAULT_DIFF_Q)
    }

    /// Sets `opts.strategy` and `opts.nee`; `default_target` is the parameter the command
    /// differentiates first. Warns when `diff` has no sampler for the target.
    fn apply(
        &self,
        scene: &pathgrad::scene::Scene,
        default_target: Option<&str>,
        opts: &mut RenderOptions,
    ) -> Result<()> {
        use pathgrad::integrator::Strategy;
        opts.nee = !self.no_nee;
        if self.strategy != "diff" {
            if let Some(q) = self.q {
                bail!("--q {q} applies only to --strategy diff (this run uses {})", self.strategy);
            }
            if let Some(name) = &self.diff_param {
                bail!("--diff-param {name} applies only to --strategy diff (this run uses {})", self.strategy);
            }
        }
        let target = self.diff_param.as_deref().or(default_target);
        opts.strategy = match (self.strategy.as_str(), target) {
            ("diff", None) => bail!("--strategy diff needs --diff-param NAME (the parameter that drives the sampler)"),
            (name, target) => Strategy::from_name(scene, name, self.q(), target.unwrap_or(""))?,
        };
        warn_without_sampler(scene, opts.strategy);
        opts.validate()?;
        Ok(())
    }
}

/// Warns when `strategy` is `diff` driven by a parameter no material has a differential sampler for
/// (it then samples like `bsdf`, with the balance heuristic).
fn warn_without_sampler(scene: &pathgrad::scene::Scene, strategy: pathgrad::integrator::Strategy) {
    use pathgrad::integrator::Strategy;
    if let Strategy::Diff { target, .. } = strategy
        && !Strategy::has_differential_sampler(scene, target)
    {
        tracing::warn!(
            "{} is neither a roughness nor a blend weight: --strategy diff samples like bsdf (balance heuristic)",
            scene.params.entry(target).name
        );
    }
}

#[derive(Args, Debug)]
struct RenderArgs {
    /// The scene: builtin:cornell-box, builtin:furnace or builtin:blend.
    scene: String,
    /// Override a scene file's default: NAME=VALUE (repeatable).
    #[arg(short = 'D', long = "define", value_name = "NAME=VALUE", value_parser = parse_define)]
    defines: Vec<(String, String)>,
    /// Output file, .exr or .png.
    #[arg(short, long)]
    output: PathBuf,
    #[command(flatten)]
    flags: RenderFlags,
    /// With an .exr output, do not write the .png preview beside it.
    #[arg(long)]
    no_preview: bool,
    /// Exposure of PNG output in stops (negative darkens).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    exposure: f32,
    /// Print a JSON summary instead of text.
    #[arg(long)]
    json: bool,
}

#[derive(Args, Debug)]
struct GradArgs {
    /// The scene: builtin:NAME or a scene file.
    scene: String,
    /// Override a scene file's default: NAME=VALUE (repeatable).
    #[arg(short = 'D', long = "define", value_name = "NAME=VALUE", value_parser = parse_define)]
    defines: Vec<(String, String)>,
    /// Parameters to report, by name or glob (`*.alpha.value`); repeatable.
    #[arg(long = "param", value_name = "NAME")]
    params: Vec<String>,
    /// The target image (EXR) the loss compares against.
    #[arg(long, conflicts_with = "target_set")]
    target: Option<PathBuf>,
    /// Render the target at these parameter values instead (NAME=V or NAME=R,G,B; repeatable),
    /// with 4× the spp (at least 64) and an independent seed.
    #[arg(long = "target-set", value_name = "NAME=VALUE", value_parser = parse_define)]
    target_set: Vec<(String, String)>,
    /// The loss: relmse, relmse_max, l2 or l1.
    #[arg(long, default_value = "relmse")]
    loss: String,
    /// Accumulate gradients in 64-bit fixed point: bitwise reproducible runs.
    #[arg(long)]
    deterministic: bool,
    /// Instead of a loss gradient, write the forward-mode image gradient ∂I/∂NAME to -o.
    #[arg(long, value_name = "NAME", conflicts_with_all = ["target", "target_set"])]
    image_gradient: Option<String>,
    /// Output of --image-gradient: an .exr (a signed false-colour .png is written beside it).
    #[arg(short, long)]
    output: Option<PathBuf>,
    #[command(flatten)]
    flags: RenderFlags,
    #[command(flatten)]
    sampling: StrategyArgs,
    /// Print JSON: {"loss", "gradients": {name: [..]}, "time_s"}.
    #[arg(long)]
    json: bool,
}

/// The target of `--target-set` gets this many times the gradient render's spp (at least
/// `TARGET_MIN_SPP`), so its noise is small next to the render's.
const TARGET_SPP_FACTOR: u32 = 4;
const TARGET_MIN_SPP: u32 = 64;
/// The target of `--target-set` uses this seed offset and the reference key ([`Renderer::render_reference`]), so its paths are independent of every render of the run.
const TARGET_SEED_OFFSET: u32 = 0x5EED;

fn parse_values(flag: &str, name: &str, text: &str) -> Result<Vec<f32>> {
    text.split(',')
        .map(|v| {
            v.trim().parse::<f32>().map_err(|_| anyhow::anyhow!("invalid {flag} {name}={text}: '{v}' is not a number"))
        })
        .collect()
}

/// The image a loss compares against: `--target REF.exr`, or the scene rendered at `--target-set`
/// values with [`TARGET_SPP_FACTOR`]× the spp (at least [`TARGET_MIN_SPP`]), an independent seed
/// and plain BSDF sampling with NEE. The renderer's parameters are restored to the scene's after.
fn target_image(
    renderer: &mut dyn Backend,
    scene: &pathgrad::scene::Scene,
    opts: &RenderOptions,
    target: Option<&Path>,
    target_set: &[(String, String)],
) -> Result<Image> {
    Ok(match (target, target_set.is_empty()) {
        (Some(path), true) => {
            let image = Image::read_exr(path)?;
            if let Some(bad) = image.non_finite() {
                bail!(
                    "invalid --target {}: pixel ({}, {}) channel {} is {} (a loss needs finite values)",
                    path.display(),
                    bad.x,
                    bad.y,
                    bad.channel,
                    bad.value
                );
            }
            image
        }
        (None, false) => {
            let table = with_values(&scene.params, target_set, "--target-set")?;
            renderer.set_params(&table)?;
            let target_opts = RenderOptions {
                spp: (opts.spp * TARGET_SPP_FACTOR).max(TARGET_MIN_SPP),
                seed: opts.seed.wrapping_add(TARGET_SEED_OFFSET),
                strategy: pathgrad::integrator::Strategy::Bsdf,
                nee: true,
                ..*opts
            };
            let target = renderer.render_reference(&target_opts).context("rendering the target")?;
            renderer.set_params(&scene.params)?;
            target
        }
        _ => bail!("give --target REF.exr or --target-set NAME=VALUE"),
    })
}

/// `table` with the values of `settings` (NAME=V sets every value of the parameter or glob,
/// NAME=R,G,B each); `flag` names the option in errors.
fn with_values(
    table: &pathgrad::params::ParamTable,
    settings: &[(String, String)],
    flag: &str,
) -> Result<pathgrad::params::ParamTable> {
    let mut table = table.clone();
    for (name, text) in settings {
        let ids = table.select(&[name.as_str()])?;
        for id in ids {
            let entry = table.entry(id).clone();
            let mut values = parse_values(flag, name, text)?;
            if values.len() == 1 {
                values = vec![values[0]; entry.len as usize];
            }
            table.set(&entry.name, &values)?;
        }
    }
    Ok(table)
}

fn grad(args: &GradArgs) -> Result<()> {
    use pathgrad::gpu::renderer::GradMode;
    // The outputs of --image-gradient are checked before anything is loaded or rendered.
    let image_gradient_outputs = match (&args.image_gradient, &args.output) {
        (None, Some(_)) => bail!("-o is the output of --image-gradient (a loss gradient is printed)"),
        (None, None) => None,
        (Some(_), None) => bail!("--image-gradient needs -o OUT.exr"),
        (Some(_), Some(output)) => {
            if !check_output(output)? {
                bail!("invalid -o {}: an image gradient is written as .exr (plus a .png preview)", output.display());
            }
            let mut outputs = OutputSet::new();
            let exr_file = outputs.stage(output)?;
            let png_file = outputs.stage(&preview_path(output))?;
            Some((output, outputs, exr_file, png_file))
        }
    };
    let scene = args.flags.load(&args.scene, &args.defines)?;
    let mut opts = options(&scene, &args.flags)?;
    let first_param = args.image_gradient.as_deref().or_else(|| args.params.first().map(String::as_str));
    args.sampling.apply(&scene, first_param, &mut opts)?;
    // Names, the loss and the target's values are checked before the device is opened.
    let loss: pathgrad::loss::Loss = args.loss.parse()?;
    let patterns: Vec<&str> =
        if args.params.is_empty() { vec!["*"] } else { args.params.iter().map(String::as_str).collect() };
    let chosen = scene.params.select(&patterns).context("--param")?;
    if let Some(name) = &args.image_gradient {
        scene.params.select(&[name.as_str()]).context("--image-gradient")?;
    }
    with_values(&scene.params, &args.target_set, "--target-set").context("--target-set")?;
    let mut renderer = args.flags.backend(&scene, &args.scene, args.json)?.backend;
    let start = Instant::now();
    if let (Some(name), Some((output, outputs, exr_file, png_file))) = (&args.image_gradient, image_gradient_outputs) {
        let image = renderer.image_gradient(&opts, name).with_context(|| format!("differentiating {}", args.scene))?;
        let seconds = start.elapsed().as_secs_f64();
        refuse_non_finite(&image, &format!("the image gradient ∂I/∂{name}"))?;
        image.write_exr(&exr_file)?;
        image.write_signed_png(&png_file, None)?;
        outputs.commit()?;
        let preview = preview_path(output);
        if args.json {
            println!(
                "{}",
                serde_json::json!({"param": name, "time_s": seconds, "outputs": [output, preview], "mean": image.mean()})
            );
        } else {
            println!("∂I/∂{name} in {seconds:.2} s → {}, {}", output.display(), preview.display());
        }
        return Ok(());
    }
    // Only the kinds of the parameters reported are compiled into the gradient kernel.
    opts.differentiate = renderer.param_kinds(&chosen);
    let target = target_image(renderer.as_mut(), &scene, &opts, args.target.as_deref(), &args.target_set)?;
    let mode = if args.deterministic { GradMode::Deterministic } else { GradMode::Float };
    // time_s is the gradient step (render, loss, fused adjoint), not the --target-set render.
    let start = Instant::now();
    let (value, gradients) = renderer
        .loss_and_gradient(&opts, &target, loss, mode)
        .with_context(|| format!("differentiating {}", args.scene))?;
    let seconds = start.elapsed().as_secs_f64();
    if args.json {
        let map: serde_json::Map<String, serde_json::Value> = chosen
            .iter()
            .map(|&id| {
                let name = scene.params.entry(id).name.clone();
                let values = gradients.get(&name).expect("the gradient has the table's layout").to_vec();
                (name, serde_json::json!(values))
            })
            .collect();
        println!("{}", serde_json::json!({"loss": value, "gradients": map, "time_s": seconds}));
    } else {
        println!("loss ({}) = {value:.6e}   ({seconds:.2} s)", args.loss);
        for id in chosen {
            let name = &scene.params.entry(id).name;
            let values = gradients.get(name).expect("the gradient has the table's layout");
            if values.len() <= 4 {
                println!("  ∂loss/∂{name} = {values:?}");
            } else {
                let norm = values.iter().map(|v| f64::from(*v).powi(2)).sum::<f64>().sqrt();
                println!("  ∂loss/∂{name} = [{} values, norm {norm:.4e}]", values.len());
            }
        }
    }
    Ok(())
}

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

fn parse_define(text: &str) -> std::result::Result<(String, String), String> {
    match text.split_once('=') {
        Some((name, value)) if !name.trim().is_empty() => Ok((name.trim().to_string(), value.to_string())),
        _ => Err(format!("expected NAME=VALUE, got '{text}'")),
    }
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Params { scene, defines, json, allow_outside_folder } => {
            params(&scene, &defines, json, allow_outside_folder)
        }
        Command::Devices { json } => devices(json),
        Command::Render(args) => render(&args),
        Command::Grad(args) => grad(&args),
        Command::Variance(args) => variance::run(&args),
        Command::Optimize(args) => optimize::optimize(&args),
    }
}

fn params(spec: &str, defines: &[(String, String)], json: bool, allow_outside_folder: bool) -> Result<()> {
    let options =
        pathgrad::scene::LoadOptions { defines: defines.to_vec(), allow_outside_folder, ..Default::default() };
    let scene = pathgrad::scene::load_with(spec, &options)?;
    let table = &scene.params;
    if json {
        let items: Vec<serde_json::Value> = table
            .entries()
            .iter()
            .map(|e| {
                let values = &table.values()[e.offset as usize..(e.offset + e.len) as usize];
                // JSON has no infinity: an open upper bound is null.
                let upper = e.bounds.1.is_finite().then_some(e.bounds.1);
                serde_json::json!({"name": e.name, "size": e.len, "bounds": [e.bounds.0, upper], "values": values})
            })
            .collect();
        println!("{}", serde_json::to_string_pretty(&items)?);
    } else {
        for e in table.entries() {
            let values = &table.values()[e.offset as usize..(e.offset + e.len) as usize];
            let shown = if values.len() <= 4 {
                format!("{values:?}")
            } else {
                let mean = values.iter().map(|&v| f64::from(v)).sum::<f64>() / values.len() as f64;
                format!("[{} values, mean {mean:.4}]", values.len())
            };
            println!("{:<48} {:>8}  [{}, {}]  {shown}", e.name, e.len, e.bounds.0, e.bounds.1);
        }
    }
    Ok(())
}

fn devices(json: bool) -> Result<()> {
    let list = pathgrad::gpu::list_devices()?;
    if json {
        let items: Vec<_> = list
            .iter()
            .map(|d| serde_json::json!({"index": d.index, "name": d.name, "type": format!("{:?}", d.device_type), "driver": d.driver, "uuid": d.uuid, "subgroup_size": d.subgroup_size, "usable": d.missing.is_empty(), "missing": d.missing}))
            .collect();
        println!("{}", serde_json::to_string_pretty(&items)?);
    } else {
        for d in &list {
            println!("{}", d.summary());
        }
    }
    Ok(())
}

fn context(device: &Option<String>) -> Result<std::sync::Arc<Context>> {
    let validation = std::env::var("PATHGRAD_VALIDATION").is_ok_and(|v| v == "1");
    let device = device.as_deref().map(DeviceChoice::parse).unwrap_or_default();
    Ok(Context::new(&ContextDesc { device, validation })?)
}

fn options(scene: &pathgrad::scene::Scene, flags: &RenderFlags) -> Result<RenderOptions> {
    let mut o = RenderOptions::for_scene(scene);
    o.spp = flags.spp.or(scene.default_spp).unwrap_or(DEFAULT_SPP);
    o.seed = flags.seed;
    // The one rule for --width/--height (a scene from `RenderFlags::load` already has this size,
    // and applying it again leaves it so).
    let size = pathgrad::scene::LoadOptions { width: flags.width, height: flags.height, ..Default::default() };
    (o.width, o.height) = size.size_for((scene.camera.width, scene.camera.height));
    o.max_depth = match flags.max_depth {
        None => Some(scene.max_depth),
        Some(-1) => None,
        Some(d) if d >= 1 && d <= i64::from(u32::MAX) => Some(d as u32),
        Some(d) => bail!("invalid --max-depth {d}: must be at least 1, or -1 for unbounded"),
    };
    o.validate()?;
    Ok(o)
}

fn check_output(path: &Path) -> Result<bool> {
    match path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).as_deref() {
        Some("exr") => Ok(true),
        Some("png") => Ok(false),
        _ => bail!("invalid -o {}: the output must end in .exr or .png", path.display()),
    }
}

/// Tells the user, on stderr, when building a kernel variant takes more than a moment: lavapipe
/// compiles each variant on its first use on a machine (later runs load it from Mesa's shader
/// cache), and a silent wait of seconds looks like a hang. Nothing is printed when `quiet` or when
/// the build is quick. Returns the total time spent building variants so far, in microseconds,
/// which keeps growing as later calls build more (`optimize` counts it as set-up, not iterations).
fn announce_compiles(renderer: &mut Renderer, quiet: bool) -> std::sync::Arc<std::sync::atomic::AtomicU64> {
    use pathgrad::gpu::renderer::{COMPILE_NOTICE_MS, CompileEvent};
    let total_us = std::sync::Arc::new(std::sync::atomic::AtomicU64::new(0));
    let total = total_us.clone();
    let mut pending: Option<(std::sync::mpsc::Sender<()>, std::thread::JoinHandle<()>)> = None;
    renderer.set_compile_observer(Box::new(move |event| match event {
        CompileEvent::Started { .. } if quiet => {}
        CompileEvent::Started { kernel, features } => {
            let (done, wait) = std::sync::mpsc::channel::<()>();
            let what = format!("{kernel} kernel ({features})");
            let timer = std::thread::spawn(move || {
                let delay = std::time::Duration::from_millis(COMPILE_NOTICE_MS as u64);
                if wait.recv_timeout(delay).is_err() {
                    eprintln!(
                        "compiling the {what} for this scene: the driver builds it on first use \
                         (seconds on lavapipe); later runs load it from the shader cache"
                    );
                    let _ = wait.recv();
                }
            });
            pending = Some((done, timer));
        }
        CompileEvent::Finished { kernel, seconds } => {
            total.fetch_add((*seconds * 1e6) as u64, std::sync::atomic::Ordering::Relaxed);
            if let Some((done, timer)) = pending.take() {
                let _ = done.send(());
                let _ = timer.join();
            }
            if !quiet && *seconds * 1e3 > COMPILE_NOTICE_MS as f64 {
                eprintln!("compiled the {kernel} kernel in {seconds:.1} s");
            }
        }
    }));
    total_us
}

/// A progress bar of `len` steps showing `what` (an indicatif template fragment) with elapsed time
/// and ETA; hidden when `hidden` (a `--json` run prints nothing but its summary).
fn progress_bar(len: u64, what: &str, hidden: bool) -> indicatif::ProgressBar {
    let progress = indicatif::ProgressBar::new(len);
    if hidden {
        progress.set_draw_target(indicatif::ProgressDrawTarget::hidden());
    }
    let template = format!("{{spinner}} {what} ({{elapsed}}, eta {{eta}})");
    progress.set_style(
        indicatif::ProgressStyle::with_template(&template).expect("the template is valid").progress_chars("=> "),
    );
    progress
}

fn render(args: &RenderArgs) -> Result<()> {
    // Every option and output path is checked before anything is rendered.
    let is_exr = check_output(&args.output)?;
    if !args.exposure.is_finite() {
        bail!("invalid --exposure {}: must be a finite number of stops", args.exposure);
    }
    let mut outputs = OutputSet::new();
    let main_file = outputs.stage(&args.output)?;
    let preview_file =
        if is_exr && !args.no_preview { Some(outputs.stage(&preview_path(&args.output))?) } else { None };
    let scene = args.flags.load(&args.scene, &args.defines)?;
    let opts = options(&scene, &args.flags)?;
    let progress = progress_bar(u64::from(opts.spp), "rendering [{bar:40}] {pos}/{len} spp", args.json);
    let start = Instant::now();
    let mut backend = args.flags.backend(&scene, &args.scene, args.json)?.backend;
    let device = backend.describe();
    let image = backend
        .render_pass(&opts, pathgrad::rng::PassTag::Primal, &mut |done, _| progress.set_position(u64::from(done)))
        .with_context(|| format!("rendering {}", args.scene))?;
    let seconds = start.elapsed().as_secs_f64();
    progress.finish_and_clear();
    refuse_non_finite(&image, "the render")?;
    save(&image, &main_file, is_exr, args.exposure)?;
    if let Some(preview) = &preview_file {
        image.write_png(preview, args.exposure)?;
    }
    let written = outputs.destinations();
    outputs.commit()?;
    let samples = f64::from(opts.width) * f64::from(opts.height) * f64::from(opts.spp);
    if args.json {
        let summary = serde_json::json!({
            "scene": args.scene, "device": device, "width": opts.width, "height": opts.height, "spp": opts.spp,
            "max_depth": opts.max_depth, "seed": opts.seed, "time_s": seconds, "samples_per_second": samples / seconds,
            "mean": image.mean(), "outputs": written,
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
    }
    Ok(())
}

/// The PNG preview written beside an EXR output.
fn preview_path(output: &Path) -> PathBuf {
    output.with_extension("png")
}

/// Refuses an image with a NaN or an infinite value (`what` names it): such a result is never
/// written. Radiance beyond the f32 range (a constant environment of 3e38, say) ends up here.
fn refuse_non_finite(image: &Image, what: &str) -> Result<()> {
    if let Some(bad) = image.non_finite() {
        bail!(
            "{what} has {} non-finite values (the first: pixel ({}, {}) channel {} is {}); the scene's \
             values overflow 32-bit floats or are invalid, so nothing was written",
            bad.count,
            bad.x,
            bad.y,
            bad.channel,
            bad.value
        );
    }
    Ok(())
}

fn save(image: &Image, path: &Path, is_exr: bool, exposure: f32) -> Result<()> {
    if is_exr {
        image.write_exr(path)?
    } else {
        image.write_png(path, exposure)?
    }
    Ok(())
}

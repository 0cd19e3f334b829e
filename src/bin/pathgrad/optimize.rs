//! `pathgrad optimize`: inverse rendering with Adam — a progress bar, a CSV row per iteration, and at the end (or on Ctrl-C) curves, the final image, the parameters and a resumable state.
//!
//! Everything is checked (scene, parameters, initial values, target, resume state) before the
//! output directory is created, so bad input leaves nothing behind. `DIR/history.csv` gets one
//! row per iteration, flushed, and `DIR/state.json` (iteration, elapsed time, parameters, Adam's
//! moments, the options) is replaced atomically after every iteration, so even a killed run can
//! be resumed; `--resume DIR` drops CSV rows the state does not cover. Ctrl-C sets a flag: the
//! current iteration finishes, the outputs are written and the command exits with status 130 (a
//! second Ctrl-C exits at once; every file is replaced atomically, so none is left half-written).

use pathgrad::backend::Backend;
use std::collections::{BTreeMap, BTreeSet};
use std::fs;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Instant;

use anyhow::{Context as _, Result, bail};
use clap::Args;
use pathgrad::adaptive::AdaptiveEstimator;
use pathgrad::gpu::renderer::GradMode;
use pathgrad::image::Image;
use pathgrad::integrator::{RenderOptions, Strategy};
use pathgrad::loss::Loss;
use pathgrad::optim::{Adam, AdamOptions, AdamState, IterationOptions, Optimization, parameter_error};
use pathgrad::output::write_bytes_atomically;
use pathgrad::params::{ParamId, ParamTable};
use pathgrad::scene::Scene;
use serde::{Deserialize, Serialize};

use super::curves::{History, Row};
use super::{Opened, RenderFlags, StrategyArgs, options, parse_define, target_image, with_values};

/// Iterations when `--iters` is not given.
const DEFAULT_ITERS: u64 = 100;
/// Samples per pixel of pass 1 and of the gradient pass by default: 3:1, the paper's best budget
/// split and its Sphere configuration (ALGORITHMS.md §6 "Budget", §7.3).
const DEFAULT_SPP_PRIMAL: u32 = 6;
const DEFAULT_SPP_GRAD: u32 = 2;
/// Output directory when `-o` is not given.
const DEFAULT_OUTPUT: &str = "optimize-out";
/// Version of `state.json`'s layout.
const STATE_VERSION: u32 = 1;
/// Exit status after Ctrl-C (128 + SIGINT, the shell's convention).
const INTERRUPTED_STATUS: i32 = 130;
/// Process memory and buffer accounting are logged (debug level) every this many iterations.
const MEMORY_LOG_EVERY: u64 = 100;

/// `pathgrad optimize`.
#[derive(Args, Debug)]
pub(super) struct OptimizeArgs {
    /// The scene: builtin:NAME or a scene file (with --resume, taken from the state).
    scene: Option<String>,
    /// Override a scene file's default: NAME=VALUE (repeatable).
    #[arg(short = 'D', long = "define", value_name = "NAME=VALUE", value_parser = parse_define)]
    defines: Vec<(String, String)>,
    /// A parameter to optimise, by name or glob, optionally with its initial value (NAME=V sets
    /// every value, NAME=R,G,B each; NAME alone keeps the scene's); repeatable. Only these change.
    #[arg(long = "param", value_name = "NAME[=INIT]")]
    params: Vec<String>,
    /// The target image (EXR) the loss compares against.
    #[arg(long, conflicts_with = "target_set")]
    target: Option<PathBuf>,
    /// Render the target at these values instead (NAME=V or NAME=R,G,B; repeatable), with 4× the
    /// final render's spp (at least 64) and an independent seed; the parameter error is reported.
    #[arg(long = "target-set", value_name = "NAME=VALUE", value_parser = parse_define)]
    target_set: Vec<(String, String)>,
    /// Total iterations (with --resume: including those done) [default: 100].
    #[arg(long)]
    iters: Option<u64>,
    /// Stop once the iterations have taken this many seconds of wall time in all (whichever of
    /// --iters and --time-budget comes first).
    #[arg(long, value_name = "S")]
    time_budget: Option<f64>,
    /// Adam's learning rate [default: 0.01].
    #[arg(long)]
    lr: Option<f64>,
    /// Samples per pixel of pass 1, the loss image [default: 6].
    #[arg(long, value_name = "N")]
    spp_primal: Option<u32>,
    /// Samples per pixel of the gradient pass (adaptive: W·H·N samples in all) [default: 2].
    #[arg(long, value_name = "N")]
    spp_grad: Option<u32>,
    /// The loss: relmse, relmse_max, l2 or l1 [default: relmse].
    #[arg(long)]
    loss: Option<String>,
    /// Loss-aware adaptive pixel sampling of the gradient pass (Su & Gkioulekas, Algorithm 2).
    #[arg(long)]
    adaptive: bool,
    /// Weighting of adaptive samples: importance (unbiased, A/(N·π)) or pixel_mean (the authors'
    /// per-pixel mean) [default: importance].
    #[arg(long, requires = "adaptive", value_name = "NAME")]
    adaptive_estimator: Option<String>,
    /// Accumulate gradients in 64-bit fixed point: a run (and its resumption) is bitwise
    /// reproducible.
    #[arg(long)]
    deterministic: bool,
    /// Output directory [default: optimize-out].
    #[arg(short, long, value_name = "DIR", conflicts_with = "resume")]
    output: Option<PathBuf>,
    /// Continue the run in DIR (its state.json) with the same options; only --iters,
    /// --time-budget, --device and --json may change.
    #[arg(long, value_name = "DIR")]
    resume: Option<PathBuf>,
    /// With --resume: accept a --target file whose content changed since the run started (the
    /// run then continues towards the new image).
    #[arg(long, requires = "resume")]
    allow_changed_target: bool,
    #[command(flatten)]
    flags: RenderFlags,
    #[command(flatten)]
    sampling: StrategyArgs,
    /// Print a one-line JSON summary instead of text (and no progress bar).
    #[arg(long)]
    json: bool,
}

/// Everything that determines a run's trajectory, as stored in `state.json`.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
struct RunConfig {
    scene: String,
    defines: Vec<(String, String)>,
    /// `--param` as given.
    param_args: Vec<String>,
    /// The optimised parameters' full names, in table order.
    params: Vec<String>,
    /// `--target`, as an absolute path.
    target: Option<PathBuf>,
    /// A hash of the target file's bytes ([`content_hash`]), so that `--resume` notices a
    /// changed target.
    #[serde(default)]
    target_hash: Option<String>,
    target_set: Vec<(String, String)>,
    iters: u64,
    time_budget: Option<f64>,
    lr: f64,
    spp_primal: u32,
    spp_grad: u32,
    /// Samples per pixel of the final render (`--spp`); a `--target-set` target gets 4×.
    spp_final: u32,
    loss: String,
    adaptive: bool,
    adaptive_estimator: String,
    deterministic: bool,
    width: u32,
    height: u32,
    max_depth: Option<u32>,
    seed: u32,
    strategy: String,
    q: f32,
    nee: bool,
    /// The parameter driving `diff`'s sampler (resolved); `None` for `bsdf`.
    diff_param: Option<String>,
    /// `--allow-outside-folder`.
    #[serde(default)]
    allow_outside_folder: bool,
}

/// `state.json`: a run between two iterations.
#[derive(Serialize, Deserialize, Debug)]
struct State {
    version: u32,
    config: RunConfig,
    /// Iterations done; the next has this index (and seed `seed + iteration`).
    iteration: u64,
    /// Wall time of the iterations so far, in seconds (set-up, kernel builds and outputs excluded).
    elapsed_s: f64,
    /// Values of the optimised parameters, as f64 copies of their f32 values.
    params: BTreeMap<String, Vec<f64>>,
    initial: BTreeMap<String, Vec<f64>>,
    adam_m: Vec<f64>,
    adam_v: Vec<f64>,
    adam_steps: Vec<u64>,
    /// Why the run stopped last: `completed`, `time budget`, `interrupted`, or an error.
    stopped: String,
}

/// A run ready to iterate: renderer, target, the optimisation and where it writes.
struct Session {
    /// The output directory, opened and locked for the run (see [`lock_dir`]).
    _lock: fs::File,
    config: RunConfig,
    dir: PathBuf,
    scene: Scene,
    renderer: Box<dyn Backend>,
    /// The Vulkan context, for memory figures (none on the CPU reference).
    ctx: Option<Arc<pathgrad::gpu::Context>>,
    /// Microseconds spent building kernel variants so far.
    compile_us: Arc<AtomicU64>,
    /// Set-up time of this session in seconds: loading, the target, and every kernel build
    /// (including those during the first iterations), none of which counts as iteration time.
    setup_s: f64,
    target: Image,
    truth: Option<ParamTable>,
    ids: Vec<ParamId>,
    run: Optimization,
    /// Wall time of the iterations done, over every session of the run (seconds).
    elapsed: f64,
    initial: BTreeMap<String, Vec<f64>>,
    history: History,
}

pub(super) fn optimize(args: &OptimizeArgs) -> Result<()> {
    let begun = Instant::now();
    let given = given_on_command_line();
    let mut session = match &args.resume {
        None => start(args)?,
        Some(dir) => resume(args, dir, &given)?,
    };
    let interrupted = Arc::new(AtomicBool::new(false));
    {
        let flag = interrupted.clone();
        ctrlc::set_handler(move || {
            if flag.swap(true, Ordering::SeqCst) {
                // A second Ctrl-C: stop at once. Files are replaced atomically, so none is torn.
                std::process::exit(INTERRUPTED_STATUS);
            }
        })
        .context("installing the Ctrl-C handler")?;
    }
    session.setup_s = begun.elapsed().as_secs_f64();
    let outcome = iterate(&mut session, args.json, &interrupted);
    let stopped = match &outcome {
        Ok(reason) => reason.to_string(),
        Err(e) => format!("error: {e:#}"),
    };
    let written = finish(&mut session, &stopped);
    let error = outcome.err();
    match (written, error) {
        (Err(w), Some(e)) => return Err(e.context(format!("also writing the outputs failed: {w:#}"))),
        (Err(w), None) => return Err(w),
        (Ok(()), Some(e)) => {
            return Err(e.context(format!("stopped; the run so far is in {}", session.dir.display())));
        }
        (Ok(()), None) => {}
    }
    summary(&session, &stopped, args.json);
    if stopped == "interrupted" {
        let dir = session.dir.clone();
        drop(session);
        if !args.json {
            eprintln!("interrupted: continue with --resume {}", dir.display());
        }
        std::process::exit(INTERRUPTED_STATUS);
    }
    Ok(())
}

/// The argument ids the user gave on the command line (not defaults), so `--resume` can tell
/// "left at the default" from "given, and equal to the default".
fn given_on_command_line() -> BTreeSet<String> {
    use clap::CommandFactory as _;
    use clap::parser::ValueSource;
    let matches = super::Cli::command().get_matches();
    let Some(m) = matches.subcommand_matches("optimize") else { return BTreeSet::new() };
    m.ids()
        .filter(|id| m.value_source(id.as_str()) == Some(ValueSource::CommandLine))
        .map(|id| id.to_string())
        .collect()
}

/// A fresh run: checks everything, renders the target, then creates the output directory.
fn start(args: &OptimizeArgs) -> Result<Session> {
    let Some(spec) = &args.scene else { bail!("give a SCENE (or --resume DIR)") };
    if args.params.is_empty() {
        bail!("give at least one --param NAME[=INIT] to optimise");
    }
    let scene = args.flags.load(spec, &args.defines).with_context(|| format!("loading {spec}"))?;
    // --param NAME[=INIT]: the names (globs) to optimise and the initial values.
    let mut patterns = Vec::new();
    let mut inits = Vec::new();
    for p in &args.params {
        match p.split_once('=') {
            Some((name, value)) => {
                patterns.push(name.trim().to_string());
                inits.push((name.trim().to_string(), value.to_string()));
            }
            None => patterns.push(p.trim().to_string()),
        }
    }
    let pattern_refs: Vec<&str> = patterns.iter().map(String::as_str).collect();
    let ids = scene.params.select(&pattern_refs).context("--param")?;
    let initial_table = with_values(&scene.params, &inits, "--param").context("--param")?;
    let mut opts = options(&scene, &args.flags)?;
    let first = scene.params.entry(ids[0]).name.clone();
    args.sampling.apply(&scene, Some(&first), &mut opts)?;
    let diff_param = match opts.strategy {
        Strategy::Bsdf => None,
        Strategy::Diff { target, .. } => Some(scene.params.entry(target).name.clone()),
    };
    let target = args.target.as_deref().map(absolute).transpose()?;
    let target_hash = target.as_deref().map(content_hash).transpose()?;
    let config = RunConfig {
        scene: absolute_scene(spec)?,
        defines: args.defines.clone(),
        param_args: args.params.clone(),
        params: ids.iter().map(|&id| scene.params.entry(id).name.clone()).collect(),
        target,
        target_hash,
        target_set: args.target_set.clone(),
        iters: args.iters.unwrap_or(DEFAULT_ITERS),
        time_budget: args.time_budget,
        lr: args.lr.unwrap_or(pathgrad::optim::DEFAULT_LEARNING_RATE),
        spp_primal: args.spp_primal.unwrap_or(DEFAULT_SPP_PRIMAL),
        spp_grad: args.spp_grad.unwrap_or(DEFAULT_SPP_GRAD),
        spp_final: opts.spp,
        loss: args.loss.clone().unwrap_or_else(|| "relmse".into()),
        adaptive: args.adaptive,
        adaptive_estimator: args
            .adaptive_estimator
            .clone()
            .unwrap_or_else(|| AdaptiveEstimator::default().name().to_string()),
        deterministic: args.deterministic,
        width: opts.width,
        height: opts.height,
        max_depth: opts.max_depth,
        seed: opts.seed,
        strategy: args.sampling.strategy.clone(),
        q: args.sampling.q(),
        nee: opts.nee,
        diff_param,
        allow_outside_folder: args.flags.allow_outside_folder,
    };
    let dir = args.output.clone().unwrap_or_else(|| PathBuf::from(DEFAULT_OUTPUT));
    refuse_existing_run(&dir)?;
    let adam = Adam::new(&initial_table, &ids, adam_options(&config)?)?;
    let initial = values_of(&initial_table, &ids);
    let prepared = prepare(&config, &scene, &ids, &args.flags, args.json)?;
    let history = History::new(&scene.params, &ids, prepared.truth.is_some());
    let run = Optimization::resume(initial_table, adam, 0, prepared.options)?;
    fs::create_dir_all(&dir).with_context(|| format!("creating -o {}", dir.display()))?;
    // Checked again under the lock: another run may have started in DIR since the first check.
    let lock = lock_dir(&dir, "-o")?;
    refuse_existing_run(&dir)?;
    let mut session = Session {
        _lock: lock,
        config,
        dir,
        scene,
        renderer: prepared.renderer,
        ctx: prepared.ctx,
        compile_us: prepared.compile_us,
        setup_s: 0.0,
        target: prepared.target,
        truth: prepared.truth,
        ids,
        run,
        elapsed: 0.0,
        initial,
        history,
    };
    session.history.create(&session.dir.join("history.csv"))?;
    write_state(&session, "started")?;
    Ok(session)
}

/// `path` made absolute (against the working directory), so that a run resumes from anywhere.
fn absolute(path: &Path) -> Result<PathBuf> {
    std::path::absolute(path).with_context(|| format!("making {} absolute", path.display()))
}

/// A scene spec with its file made absolute (`builtin:NAME` as it is).
fn absolute_scene(spec: &str) -> Result<String> {
    if spec.starts_with("builtin:") {
        return Ok(spec.to_string());
    }
    Ok(absolute(Path::new(spec))?.display().to_string())
}

/// A 64-bit FNV-1a hash of the bytes of `path`, as 16 hex digits: enough to notice that a file
/// changed (it is no defence against a deliberate collision).
fn content_hash(path: &Path) -> Result<String> {
    const OFFSET: u64 = 0xcbf2_9ce4_8422_2325;
    const PRIME: u64 = 0x0000_0100_0000_01b3;
    let bytes = fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    let hash = bytes.iter().fold(OFFSET, |h, &b| (h ^ u64::from(b)).wrapping_mul(PRIME));
    Ok(format!("{hash:016x}"))
}

/// Refuses an output directory that already holds a run.
fn refuse_existing_run(dir: &Path) -> Result<()> {
    for existing in ["state.json", "history.csv"] {
        if dir.join(existing).exists() {
            bail!(
                "invalid -o {}: it already holds a run ({existing}); continue it with --resume {} or choose another -o",
                dir.display(),
                dir.display()
            );
        }
    }
    Ok(())
}

/// Takes an exclusive advisory lock (`flock`) on the run directory `dir` itself, held until the
/// returned handle is dropped (the process ends, however it ends), so that two `optimize` runs
/// never write one directory; nothing is left in the directory. `flag` names the option in errors.
fn lock_dir(dir: &Path, flag: &str) -> Result<fs::File> {
    let handle = fs::File::open(dir).with_context(|| format!("{flag} {}: opening the directory", dir.display()))?;
    match handle.try_lock() {
        Ok(()) => Ok(handle),
        Err(fs::TryLockError::WouldBlock) => bail!(
            "{flag} {}: another pathgrad optimize is running in this directory (it holds its lock)",
            dir.display()
        ),
        Err(fs::TryLockError::Error(e)) => {
            Err(anyhow::Error::new(e).context(format!("{flag} {}: locking the directory", dir.display())))
        }
    }
}

/// A resumed run: the state's options, checked against those given now.
fn resume(args: &OptimizeArgs, dir: &Path, given: &BTreeSet<String>) -> Result<Session> {
    let path = dir.join("state.json");
    if !path.is_file() {
        bail!("--resume {}: reading {}: there is no run there (no state.json)", dir.display(), path.display());
    }
    let lock = lock_dir(dir, "--resume")?;
    let text =
        fs::read_to_string(&path).with_context(|| format!("--resume {}: reading {}", dir.display(), path.display()))?;
    let state: State = serde_json::from_str(&text)
        .with_context(|| format!("--resume {}: {} is not a pathgrad optimize state", dir.display(), path.display()))?;
    if state.version != STATE_VERSION {
        bail!(
            "--resume {}: {} has version {} (expected {STATE_VERSION})",
            dir.display(),
            path.display(),
            state.version
        );
    }
    let mut config = state.config.clone();
    check_unchanged(args, given, &config, &path)?;
    if let (Some(target), Some(stored)) = (&config.target, &config.target_hash) {
        let now = content_hash(target)?;
        if now != *stored && !args.allow_changed_target {
            bail!(
                "--resume {}: the target {} changed since the run started (its content hash was {stored}, now {now}); \
                 restore it, or pass --allow-changed-target to continue towards the new image",
                dir.display(),
                target.display()
            );
        }
        config.target_hash = Some(now);
    }
    if let Some(iters) = args.iters {
        config.iters = iters;
    }
    if args.time_budget.is_some() {
        config.time_budget = args.time_budget;
    }
    let load = pathgrad::scene::LoadOptions {
        defines: config.defines.clone(),
        width: Some(config.width),
        height: Some(config.height),
        allow_outside_folder: config.allow_outside_folder,
    };
    let scene = pathgrad::scene::load_with(&config.scene, &load)
        .with_context(|| format!("loading {} (from {})", config.scene, path.display()))?;
    let mut table = scene.params.clone();
    let mut ids = Vec::new();
    for name in &config.params {
        let values: Vec<f32> = state
            .params
            .get(name)
            .with_context(|| format!("{}: no values for {name}", path.display()))?
            .iter()
            .map(|&v| v as f32)
            .collect();
        table.set(name, &values).with_context(|| format!("{}: parameter {name}", path.display()))?;
        ids.push(table.find(name).expect("set found it"));
    }
    let adam_state = AdamState { m: state.adam_m.clone(), v: state.adam_v.clone(), steps: state.adam_steps.clone() };
    let adam = Adam::with_state(&table, &ids, adam_options(&config)?, adam_state)
        .with_context(|| format!("{}: Adam state", path.display()))?;
    let prepared = prepare(&config, &scene, &ids, &args.flags, args.json)?;
    let mut history = History::new(&scene.params, &ids, prepared.truth.is_some());
    let csv = dir.join("history.csv");
    history.read(&csv, state.iteration)?;
    let run = Optimization::resume(table, adam, state.iteration, prepared.options)?;
    history.rewrite(&csv)?;
    Ok(Session {
        _lock: lock,
        config,
        dir: dir.to_path_buf(),
        scene,
        renderer: prepared.renderer,
        ctx: prepared.ctx,
        compile_us: prepared.compile_us,
        setup_s: 0.0,
        target: prepared.target,
        truth: prepared.truth,
        ids,
        run,
        elapsed: state.elapsed_s,
        initial: state.initial,
        history,
    })
}

/// Rejects options given with `--resume` that differ from the stored run's.
fn check_unchanged(args: &OptimizeArgs, given: &BTreeSet<String>, c: &RunConfig, state: &Path) -> Result<()> {
    let mut conflicts = Vec::new();
    let mut check = |id: &str, flag: &str, now: Option<String>, stored: String| {
        if let Some(now) = now
            && given.contains(id)
            && now != stored
        {
            conflicts.push(format!("{flag} {now} (the run has {stored})"));
        }
    };
    let pairs = |v: &[(String, String)]| v.iter().map(|(n, x)| format!("{n}={x}")).collect::<Vec<_>>().join(" ");
    let path = |p: &Option<PathBuf>| p.as_deref().map_or("none".into(), |p| p.display().to_string());
    let text = |v: &dyn std::fmt::Display| v.to_string();
    check("scene", "SCENE", args.scene.as_deref().map(absolute_scene).transpose()?, c.scene.clone());
    check("defines", "-D", Some(pairs(&args.defines)), pairs(&c.defines));
    check("params", "--param", Some(args.params.join(" ")), c.param_args.join(" "));
    let target = args.target.as_deref().map(absolute).transpose()?;
    check("target", "--target", Some(path(&target)), path(&c.target));
    check(
        "allow_outside_folder",
        "--allow-outside-folder",
        Some(text(&args.flags.allow_outside_folder)),
        text(&c.allow_outside_folder),
    );
    check("target_set", "--target-set", Some(pairs(&args.target_set)), pairs(&c.target_set));
    check("lr", "--lr", args.lr.map(|v| text(&v)), text(&c.lr));
    check("spp_primal", "--spp-primal", args.spp_primal.map(|v| text(&v)), text(&c.spp_primal));
    check("spp_grad", "--spp-grad", args.spp_grad.map(|v| text(&v)), text(&c.spp_grad));
    check("loss", "--loss", args.loss.clone(), c.loss.clone());
    check("adaptive", "--adaptive", Some(text(&args.adaptive)), text(&c.adaptive));
    check("adaptive_estimator", "--adaptive-estimator", args.adaptive_estimator.clone(), c.adaptive_estimator.clone());
    check("deterministic", "--deterministic", Some(text(&args.deterministic)), text(&c.deterministic));
    check("spp", "--spp", args.flags.spp.map(|v| text(&v)), text(&c.spp_final));
    check("width", "--width", args.flags.width.map(|v| text(&v)), text(&c.width));
    check("height", "--height", args.flags.height.map(|v| text(&v)), text(&c.height));
    check("max_depth", "--max-depth", args.flags.max_depth.map(|v| text(&v)), text(&c.max_depth.map_or(-1, i64::from)));
    check("seed", "--seed", Some(text(&args.flags.seed)), text(&c.seed));
    check("strategy", "--strategy", Some(args.sampling.strategy.clone()), c.strategy.clone());
    check("q", "--q", args.sampling.q.map(|q| text(&q)), text(&c.q));
    check("no_nee", "--no-nee", Some(text(&args.sampling.no_nee)), text(&!c.nee));
    check("diff_param", "--diff-param", args.sampling.diff_param.clone(), c.diff_param.clone().unwrap_or_default());
    if !conflicts.is_empty() {
        bail!(
            "--resume: {} conflict with the run in {} (leave them out to continue it as it was)",
            conflicts.join(", "),
            state.display()
        );
    }
    Ok(())
}

fn adam_options(config: &RunConfig) -> Result<AdamOptions> {
    let o = AdamOptions::with_learning_rate(config.lr);
    o.validate()?;
    Ok(o)
}

/// The render options of `config` on `scene`: the gradient pass's (spp = spp_grad).
fn iteration_options(scene: &Scene, config: &RunConfig) -> Result<IterationOptions> {
    let strategy = Strategy::from_name(scene, &config.strategy, config.q, config.diff_param.as_deref().unwrap_or(""))?;
    if config.spp_grad == 0 {
        bail!("invalid --spp-grad: must be at least 1");
    }
    if config.spp_primal == 0 {
        bail!("invalid --spp-primal: must be at least 1");
    }
    if let Some(t) = config.time_budget
        && !(t > 0.0 && t.is_finite())
    {
        bail!("invalid --time-budget {t}: must be a positive number of seconds");
    }
    let render = RenderOptions {
        width: config.width,
        height: config.height,
        spp: config.spp_grad,
        max_depth: config.max_depth,
        seed: config.seed,
        nee: config.nee,
        strategy,
        ..RenderOptions::for_scene(scene)
    };
    let options = IterationOptions {
        render,
        spp_primal: config.spp_primal,
        adaptive: if config.adaptive { Some(config.adaptive_estimator.parse()?) } else { None },
        loss: config.loss.parse::<Loss>()?,
        mode: if config.deterministic { GradMode::Deterministic } else { GradMode::Float },
    };
    options.validate()?;
    Ok(options)
}

/// What a run needs besides its parameters and Adam: the renderer, the target, the truth (with
/// `--target-set`) and the iteration options.
struct Prepared {
    renderer: Box<dyn Backend>,
    ctx: Option<Arc<pathgrad::gpu::Context>>,
    /// Microseconds spent building kernel variants so far (see `announce_compiles`).
    compile_us: Arc<AtomicU64>,
    target: Image,
    truth: Option<ParamTable>,
    options: IterationOptions,
}

/// Checks `config` on `scene`, creates the device and the renderer and renders or reads the target;
/// the gradient passes compile only the parameter kinds of `ids`, the parameters optimised.
fn prepare(config: &RunConfig, scene: &Scene, ids: &[ParamId], flags: &RenderFlags, quiet: bool) -> Result<Prepared> {
    let mut options = iteration_options(scene, config)?;
    let truth = if config.target_set.is_empty() {
        None
    } else {
        Some(with_values(&scene.params, &config.target_set, "--target-set")?)
    };
    let Opened { backend: mut renderer, ctx, compile_us } = flags.backend(scene, &config.scene, quiet)?;
    let final_opts = RenderOptions { spp: config.spp_final, ..options.render };
    let target = target_image(renderer.as_mut(), scene, &final_opts, config.target.as_deref(), &config.target_set)?;
    if (target.width(), target.height()) != (config.width, config.height) {
        bail!(
            "invalid --target {}: it is {}×{} but the render is {}×{} (set --width/--height to match)",
            config.target.as_deref().unwrap_or(Path::new("")).display(),
            target.width(),
            target.height(),
            config.width,
            config.height
        );
    }
    options.render.differentiate = renderer.param_kinds(ids);
    Ok(Prepared { renderer, ctx, compile_us, target, truth, options })
}

fn values_of(table: &ParamTable, ids: &[ParamId]) -> BTreeMap<String, Vec<f64>> {
    ids.iter()
        .map(|&id| (table.entry(id).name.clone(), table.get(id).iter().map(|&v| f64::from(v)).collect()))
        .collect()
}

/// Runs iterations until `--iters`, `--time-budget` or Ctrl-C; returns why it stopped.
fn iterate(s: &mut Session, json: bool, interrupted: &AtomicBool) -> Result<&'static str> {
    let bar = super::progress_bar(s.config.iters, "optimising [{bar:30}] {pos}/{len} it {msg}", json);
    bar.set_position(s.run.iteration());
    let ctx = s.ctx.clone();
    log_memory(ctx.as_deref(), s.run.iteration());
    let (started, before) = (Instant::now(), s.elapsed);
    let compiled_before = s.compile_us.load(Ordering::Relaxed);
    // Kernel builds during iterations (the first gradient builds its variants) are set-up time.
    let compile_s = |s: &Session| (s.compile_us.load(Ordering::Relaxed) - compiled_before) as f64 * 1e-6;
    let iteration_s = |s: &Session| (started.elapsed().as_secs_f64() - compile_s(s)).max(0.0);
    let mut compiled_seen = 0.0;
    let reason = loop {
        if interrupted.load(Ordering::SeqCst) {
            break "interrupted";
        }
        if s.run.iteration() >= s.config.iters {
            break "completed";
        }
        if s.config.time_budget.is_some_and(|b| before + iteration_s(s) >= b) {
            break "time budget";
        }
        let (loss, gradients) = s
            .run
            .gradient(s.renderer.as_mut(), &s.target)
            .with_context(|| format!("iteration {}", s.run.iteration()))?;
        let report = s.run.apply(loss, &gradients)?;
        let compiling = compile_s(s);
        if compiling > compiled_seen {
            // A first build made this iteration slow: its pace says nothing about the rest.
            bar.reset_eta();
            compiled_seen = compiling;
        }
        s.elapsed = before + iteration_s(s);
        let row = row(s, report.iteration, s.elapsed, loss, report.gradient_norm);
        s.history.append(&s.dir.join("history.csv"), row)?;
        write_state(s, "running")?;
        bar.set_position(s.run.iteration());
        bar.set_message(progress_message(s, loss));
        if s.run.iteration().is_multiple_of(MEMORY_LOG_EVERY) {
            log_memory(ctx.as_deref(), s.run.iteration());
        }
    };
    bar.finish_and_clear();
    s.setup_s += compile_s(s);
    log_memory(ctx.as_deref(), s.run.iteration());
    Ok(reason)
}

fn row(s: &Session, iteration: u64, time_s: f64, loss: f64, grad_norm: f64) -> Row {
    let params = s.run.params();
    let mut values = Vec::new();
    let mut errors = Vec::new();
    for &id in &s.ids {
        let v = params.get(id);
        if v.len() <= 4 {
            values.extend(v.iter().map(|&x| f64::from(x)));
        } else {
            values.push(v.iter().map(|&x| f64::from(x)).sum::<f64>() / v.len() as f64);
        }
        if let Some(truth) = &s.truth {
            errors.push(parameter_error(v, truth.get(id)));
        }
    }
    let error = s.truth.as_ref().map(|truth| overall_error(params, truth, &s.ids));
    Row { iteration, time_s, loss, values, errors, error, grad_norm }
}

/// ALGORITHMS.md §7.1's relative squared error averaged over every optimised value.
fn overall_error(params: &ParamTable, truth: &ParamTable, ids: &[ParamId]) -> f64 {
    let (mut sum, mut n) = (0.0, 0usize);
    for &id in ids {
        let len = params.get(id).len();
        sum += parameter_error(params.get(id), truth.get(id)) * len as f64;
        n += len;
    }
    sum / n as f64
}

fn progress_message(s: &Session, loss: f64) -> String {
    let mut parts = vec![format!("loss {loss:.4e}")];
    for &id in s.ids.iter().take(3) {
        let v = s.run.params().get(id);
        let name = &s.run.params().entry(id).name;
        parts.push(if v.len() == 1 {
            format!("{name}={:.4}", v[0])
        } else {
            format!("{name}={:.3?}", &v[..v.len().min(3)])
        });
    }
    parts.join("  ")
}

/// Resident set size of this process in KiB (Linux `/proc/self/status`), if known.
fn rss_kib() -> Option<u64> {
    let status = fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmRSS:"))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

fn log_memory(ctx: Option<&pathgrad::gpu::Context>, iteration: u64) {
    let Some(ctx) = ctx else { return };
    tracing::debug!(
        iteration,
        rss_kib = rss_kib().unwrap_or(0),
        buffer_bytes = ctx.buffer_bytes(),
        peak_buffer_bytes = ctx.peak_buffer_bytes(),
        live_objects = ctx.live_objects(),
        "memory"
    );
}

/// Replaces `state.json` with the run as it is now.
fn write_state(s: &Session, stopped: &str) -> Result<()> {
    let adam = s.run.adam().state();
    let state = State {
        version: STATE_VERSION,
        config: s.config.clone(),
        iteration: s.run.iteration(),
        elapsed_s: s.elapsed,
        params: values_of(s.run.params(), &s.ids),
        initial: s.initial.clone(),
        adam_m: adam.m.clone(),
        adam_v: adam.v.clone(),
        adam_steps: adam.steps.clone(),
        stopped: stopped.to_string(),
    };
    Ok(write_bytes_atomically(s.dir.join("state.json"), serde_json::to_string_pretty(&state)?.as_bytes())?)
}

/// Writes the end-of-run outputs: state, parameters, the final image and the curves.
fn finish(s: &mut Session, stopped: &str) -> Result<()> {
    write_state(s, stopped)?;
    let params = values_of(s.run.params(), &s.ids);
    write_bytes_atomically(s.dir.join("params.json"), serde_json::to_string_pretty(&params)?.as_bytes())?;
    s.history.write_svg(&s.dir.join("curves.svg"), &s.initial_point())?;
    s.renderer.set_params(s.run.params())?;
    let opts = RenderOptions { spp: s.config.spp_final, strategy: Strategy::Bsdf, nee: true, ..s.run.options().render };
    let image = s.renderer.render(&opts).context("rendering the final image")?;
    image.write_exr(s.dir.join("final.exr"))?;
    image.write_png(s.dir.join("final.png"), 0.0)?;
    Ok(())
}

impl Session {
    /// The parameter error before the first iteration, the curves' first point (if the truth is
    /// known).
    fn initial_point(&self) -> Option<f64> {
        let truth = self.truth.as_ref()?;
        let mut table = self.scene.params.clone();
        for (name, values) in &self.initial {
            let v: Vec<f32> = values.iter().map(|&x| x as f32).collect();
            table.set(name, &v).ok()?;
        }
        Some(overall_error(&table, truth, &self.ids))
    }
}

fn summary(s: &Session, stopped: &str, json: bool) {
    let last = s.history.last();
    let params = values_of(s.run.params(), &s.ids);
    let outputs: Vec<PathBuf> = ["history.csv", "curves.svg", "final.exr", "final.png", "params.json", "state.json"]
        .iter()
        .map(|f| s.dir.join(f))
        .collect();
    let ctx = s.ctx.as_deref();
    if json {
        let v = serde_json::json!({
            "iterations": s.run.iteration(),
            "stopped": stopped,
            "time_s": s.elapsed,
            "setup_s": s.setup_s,
            "loss": last.map(|r| r.loss),
            "param_error": last.and_then(|r| r.error),
            "params": params,
            "dir": s.dir,
            "outputs": outputs,
            "rss_kib": rss_kib(),
            "buffer_bytes": ctx.map(|c| c.buffer_bytes()),
            "peak_buffer_bytes": ctx.map(|c| c.peak_buffer_bytes()),
        });
        println!("{v}");
    } else {
        println!(
            "{stopped} after {} iterations in {:.2} s (set-up {:.2} s: loading, the target, kernel builds){}{} → {}",
            s.run.iteration(),
            s.elapsed,
            s.setup_s,
            last.map(|r| format!(", loss {:.4e}", r.loss)).unwrap_or_default(),
            last.and_then(|r| r.error).map(|e| format!(", parameter error {e:.4e}")).unwrap_or_default(),
            s.dir.display()
        );
        for (name, values) in &params {
            if values.len() <= 4 {
                println!("  {name} = {values:?}");
            } else {
                let mean = values.iter().sum::<f64>() / values.len() as f64;
                println!("  {name} = [{} values, mean {mean:.4}]", values.len());
            }
        }
    }
}

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
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Instant;

use anyhow::{Context as _, Result, bail};
use clap::Args;
use pathgrad::adaptive::AdaptiveEstimator;
use pathgrad::image::Image;
use pathgrad::integrator::{Strategy, View};
use pathgrad::optim::{Adam, Optimization};
use pathgrad::params::{ParamId, ParamTable};
use pathgrad::scene::Scene;
use serde::{Deserialize, Serialize};

use crate::common::{RenderFlags, StrategyArgs, options, parse_define, parse_views, with_values};
use crate::curves::History;

mod control;
mod prepare;
mod report;
mod resume;

use prepare::*;
use report::*;
use resume::*;

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
    /// Optimise over several views: SENSOR=TARGET.exr, or SENSOR with --target-set (repeatable;
    /// by index or name). The loss is the mean of the views' losses; each iteration renders and
    /// differentiates every view in one pass. The final image is the first view's.
    #[arg(long = "view", value_name = "SENSOR[=TARGET.exr]", conflicts_with = "target")]
    views: Vec<String>,
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
    /// Adam's first-moment decay β₁, in [0, 1) [default: 0.9]; 0 steps with each iteration's
    /// gradient alone (no momentum).
    #[arg(long, value_name = "B")]
    beta1: Option<f64>,
    /// Add a smoothness prior of this weight λ to the objective: λ times the mean squared
    /// difference between neighbouring voxels (texels) of every optimised volume grid (bitmap
    /// texture). It steadies grids that the views determine poorly; the loss shown stays the
    /// images' loss.
    #[arg(long, value_name = "LAMBDA")]
    smooth: Option<f64>,
    /// Samples per pixel of pass 1, the loss image [default: 6].
    #[arg(long, value_name = "N")]
    spp_primal: Option<u32>,
    /// Samples per pixel of the gradient pass (adaptive: W·H·N samples in all) [default: 2].
    #[arg(long, value_name = "N")]
    spp_grad: Option<u32>,
    /// The loss: relmse, relmse_max, l2 or l1 [default: relmse].
    #[arg(long)]
    loss: Option<String>,
    /// Loss-aware adaptive pixel sampling of the gradient pass (Su & Gkioulekas, Algorithm 2):
    /// on by default, `--adaptive=false` samples every pixel alike (docs/gradients.md "Which to
    /// use" says why it is the default).
    #[arg(long, value_name = "BOOL", num_args = 0..=1, require_equals = true, default_missing_value = "true")]
    adaptive: Option<bool>,
    /// Weighting of adaptive samples: importance (unbiased, A/(N·π)) or pixel_mean (the authors'
    /// per-pixel mean) [default: importance].
    #[arg(long, value_name = "NAME")]
    adaptive_estimator: Option<String>,
    /// Accumulate gradients in 64-bit fixed point: a run (and its resumption) is bitwise
    /// reproducible.
    #[arg(long)]
    deterministic: bool,
    /// Recursive control variates across iterations (Nicolet et al. 2023): pass 1 is rendered at
    /// the current and at the previous parameters with the same random numbers, and the loss
    /// and its adjoint image are taken from a per-pixel running estimate that reuses the earlier
    /// iterations' images. Costs a second pass 1 per iteration; the gradient pass is unchanged.
    /// On by default (off with `--reuse`); `--control-variates=false` turns it off.
    #[arg(long, value_name = "BOOL", num_args = 0..=1, require_equals = true, default_missing_value = "true")]
    control_variates: Option<bool>,
    /// Gradient reuse across iterations (after Bálint et al. 2023): each iteration takes the loss
    /// gradient at the current and at the previous parameters with the same random numbers, and
    /// Adam steps with a per-parameter running estimate that carries the earlier iterations'
    /// gradients forward along the trajectory. Costs a second gradient (both passes) per
    /// iteration. It replaces the control variates (not with --control-variates).
    #[arg(long)]
    reuse: bool,
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

impl OptimizeArgs {
    /// `--adaptive`, on unless `--adaptive=false`.
    fn adaptive(&self) -> bool {
        self.adaptive.unwrap_or(true)
    }

    /// `--control-variates`: on unless `--control-variates=false` or `--reuse` (which replaces
    /// them).
    ///
    /// # Errors
    /// Both `--control-variates` and `--reuse` given.
    fn control_variates(&self) -> Result<bool> {
        match (self.control_variates, self.reuse) {
            (Some(true), true) => {
                bail!("--reuse replaces the control variates: give one of --reuse and --control-variates")
            }
            (given, reuse) => Ok(given.unwrap_or(!reuse)),
        }
    }
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
    /// `--beta1` (Adam's first-moment decay).
    #[serde(default = "default_beta1")]
    beta1: f64,
    /// `--smooth`: the smoothness prior's weight, if any.
    #[serde(default)]
    smooth: Option<f64>,
    spp_primal: u32,
    spp_grad: u32,
    /// Samples per pixel of the final render (`--spp`); a `--target-set` target gets 4×.
    spp_final: u32,
    loss: String,
    adaptive: bool,
    adaptive_estimator: String,
    deterministic: bool,
    /// `--control-variates`.
    #[serde(default)]
    control_variates: bool,
    /// `--reuse`.
    #[serde(default)]
    reuse: bool,
    width: u32,
    height: u32,
    max_depth: Option<u32>,
    seed: u32,
    strategy: String,
    q: f32,
    nee: bool,
    /// The parameter driving `diff`'s sampler (resolved; with `auto`, the one piloted on); `None`
    /// for `bsdf`.
    diff_param: Option<String>,
    /// `--placement-mis`: how `diff` weights its placements.
    #[serde(default = "balance")]
    placement_mis: String,
    /// `--hero-weights` with several `--diff-param`s: fixed hero probabilities; `None` adapts
    /// them to each target's gradient variance (ALGORITHMS.md §5.8).
    #[serde(default)]
    hero_weights: Option<Vec<f32>>,
    /// `--sampling`: `detached` or `attached`.
    #[serde(default = "detached")]
    sampling: String,
    /// `--jacobian-noise` with attached sampling.
    #[serde(default)]
    jacobian_noise: Option<f32>,
    /// `--strategy auto`: what the pilot in preparation picked, stored so that `--resume` reuses it.
    #[serde(default)]
    pilot: Option<PilotChoice>,
    /// `--allow-outside-folder`.
    #[serde(default)]
    allow_outside_folder: bool,
    /// `--sensor`, if given.
    #[serde(default)]
    sensor: Option<String>,
    /// `--env`, if given: `[r, g, b]` or a map file.
    #[serde(default)]
    env: Option<crate::common::EnvArg>,
    /// `--view`s: the sensors (by name) and their target files.
    #[serde(default)]
    views: Vec<ViewConfig>,
}

/// Adam's β₁ of a run saved before `--beta1` existed.
fn default_beta1() -> f64 {
    pathgrad::optim::BETA1
}

fn balance() -> String {
    "balance".into()
}

fn detached() -> String {
    "detached".into()
}

/// The strategy `--strategy auto`'s pilot picked (`bsdf` or `diff` at `q`) and its report (the
/// `pilot` object of `grad --json`: candidates, their variance and time, the pilot's cost).
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
struct PilotChoice {
    strategy: String,
    q: f32,
    report: serde_json::Value,
}

/// One `--view` of a run.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
struct ViewConfig {
    /// The sensor's name.
    sensor: String,
    /// Its target, as an absolute path (none with `--target-set`).
    target: Option<PathBuf>,
    /// A hash of the target file's bytes, as [`RunConfig::target_hash`].
    target_hash: Option<String>,
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
    /// The hero probabilities' running state (several `--diff-param`s without
    /// `--hero-weights`).
    #[serde(default)]
    hero: Option<HeroState>,
}

/// [`pathgrad::optim::HeroAdaptation`] in `state.json` (f64s round-trip exactly).
#[derive(Serialize, Deserialize, Debug, Clone, PartialEq)]
struct HeroState {
    steps: u64,
    mean: Vec<f64>,
    square: Vec<f64>,
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
    /// The views optimised over (the scene's camera alone without `--view`) and their targets.
    views: Vec<View>,
    targets: Vec<Image>,
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
    let matches = crate::cli::Cli::command().get_matches();
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
    let ids =
        crate::common::select_differentiated(&scene, &pattern_refs, args.sampling.directions()?).context("--param")?;
    let initial_table = with_values(&scene.params, &inits, "--param").context("--param")?;
    let mut opts = options(&scene, &args.flags)?;
    let mut views = Vec::new();
    if !args.views.is_empty() {
        for (view, target) in parse_views(&scene, &args.flags, &args.views, !args.target_set.is_empty(), &mut opts)? {
            let target = target.as_deref().map(absolute).transpose()?;
            let target_hash = target.as_deref().map(content_hash).transpose()?;
            let sensor = scene.sensors[view.stream as usize].name.clone();
            views.push(ViewConfig { sensor, target, target_hash });
        }
    }
    let first = scene.params.entry(ids[0]).name.clone();
    args.sampling.apply(&scene, Some(&first), &mut opts)?;
    let diff_param = match opts.strategy {
        // `auto` pilots on --diff-param, else on the first parameter optimised.
        Strategy::Bsdf if args.sampling.strategy == "auto" => Some(args.sampling.diff_param.clone().unwrap_or(first)),
        Strategy::Bsdf => None,
        Strategy::Diff { target, .. } => Some(scene.params.entry(target).name.clone()),
        Strategy::Hero { heroes, .. } => {
            Some(heroes.targets().iter().map(|t| scene.params.entry(*t).name.as_str()).collect::<Vec<_>>().join(","))
        }
    };
    if !args.adaptive() && args.adaptive_estimator.is_some() {
        bail!("--adaptive-estimator weighs adaptive pixel samples: not with --adaptive=false");
    }
    let target = args.target.as_deref().map(absolute).transpose()?;
    let target_hash = target.as_deref().map(content_hash).transpose()?;
    let mut config = RunConfig {
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
        beta1: args.beta1.unwrap_or(pathgrad::optim::BETA1),
        smooth: args.smooth,
        spp_primal: args.spp_primal.unwrap_or(DEFAULT_SPP_PRIMAL),
        spp_grad: args.spp_grad.unwrap_or(DEFAULT_SPP_GRAD),
        spp_final: opts.spp,
        loss: args.loss.clone().unwrap_or_else(|| "relmse".into()),
        adaptive: args.adaptive(),
        adaptive_estimator: args
            .adaptive_estimator
            .clone()
            .unwrap_or_else(|| AdaptiveEstimator::default().name().to_string()),
        deterministic: args.deterministic,
        control_variates: args.control_variates()?,
        reuse: args.reuse,
        width: opts.width,
        height: opts.height,
        max_depth: opts.max_depth,
        seed: opts.seed,
        strategy: args.sampling.strategy.clone(),
        q: args.sampling.q(),
        nee: opts.nee,
        diff_param,
        placement_mis: args.sampling.placement()?.name().to_string(),
        hero_weights: args.sampling.hero_weights()?,
        sampling: args.sampling.sampling.clone(),
        jacobian_noise: args.sampling.jacobian_noise,
        pilot: None,
        allow_outside_folder: args.flags.allow_outside_folder,
        sensor: args.flags.sensor.clone(),
        env: args.flags.env.clone(),
        views,
    };
    let dir = args.output.clone().unwrap_or_else(|| PathBuf::from(DEFAULT_OUTPUT));
    refuse_existing_run(&dir)?;
    let adam = Adam::new(&initial_table, &ids, adam_options(&config)?)?;
    let initial = values_of(&initial_table, &ids);
    let prepared = prepare(&mut config, &scene, &ids, &args.flags, args.json)?;
    let history = History::new(&scene.params, &ids, prepared.truth.is_some());
    let run = with_smoothness(Optimization::resume(initial_table, adam, 0, prepared.options)?, &scene, &ids, &config)?;
    let run = with_hero(run, &config, None)?;
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
        views: prepared.views,
        targets: prepared.targets,
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

/// Runs iterations until `--iters`, `--time-budget` or Ctrl-C; returns why it stopped.
fn iterate(s: &mut Session, json: bool, interrupted: &AtomicBool) -> Result<&'static str> {
    let bar = crate::common::progress_bar(s.config.iters, "optimising [{bar:30}] {pos}/{len} it {msg}", json);
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
            .gradient_views(s.renderer.as_mut(), &s.views, &s.targets)
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

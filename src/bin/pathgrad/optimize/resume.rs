//! Runs that already exist: absolute paths and content hashes for the state, the directory lock, and `--resume`.

use std::collections::BTreeSet;
use std::fs;
use std::path::{Path, PathBuf};

use anyhow::{Context as _, Result, bail};
use pathgrad::optim::{Adam, AdamState, Optimization};

use crate::curves::History;

use super::*;

/// `path` made absolute (against the working directory), so that a run resumes from anywhere.
pub(super) fn absolute(path: &Path) -> Result<PathBuf> {
    std::path::absolute(path).with_context(|| format!("making {} absolute", path.display()))
}

/// A scene spec with its file made absolute (`builtin:NAME` as it is).
pub(super) fn absolute_scene(spec: &str) -> Result<String> {
    if spec.starts_with("builtin:") {
        return Ok(spec.to_string());
    }
    Ok(absolute(Path::new(spec))?.display().to_string())
}

/// A 64-bit FNV-1a hash of the bytes of `path`, as 16 hex digits: enough to notice that a file
/// changed (it is no defence against a deliberate collision).
pub(super) fn content_hash(path: &Path) -> Result<String> {
    const OFFSET: u64 = 0xcbf2_9ce4_8422_2325;
    const PRIME: u64 = 0x0000_0100_0000_01b3;
    let bytes = fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    let hash = bytes.iter().fold(OFFSET, |h, &b| (h ^ u64::from(b)).wrapping_mul(PRIME));
    Ok(format!("{hash:016x}"))
}

/// Refuses an output directory that already holds a run.
pub(super) fn refuse_existing_run(dir: &Path) -> Result<()> {
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
pub(super) fn lock_dir(dir: &Path, flag: &str) -> Result<fs::File> {
    let handle = fs::File::open(dir).with_context(|| format!("{flag} {}: opening the directory", dir.display()))?;
    crate::common::try_lock(
        handle,
        || {
            format!(
                "{flag} {}: another pathgrad optimize is running in this directory (it holds its lock)",
                dir.display()
            )
        },
        || format!("{flag} {}: locking the directory", dir.display()),
    )
}

/// A resumed run: the state's options, checked against those given now.
pub(super) fn resume(args: &OptimizeArgs, dir: &Path, given: &BTreeSet<String>) -> Result<Session> {
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
    for view in &mut config.views {
        let (Some(target), Some(stored)) = (&view.target, &view.target_hash) else { continue };
        let now = content_hash(target)?;
        if now != *stored && !args.allow_changed_target {
            bail!(
                "--resume {}: the target {} of view {} changed since the run started (its content hash was {stored}, \
                 now {now}); restore it, or pass --allow-changed-target to continue towards the new image",
                dir.display(),
                target.display(),
                view.sensor
            );
        }
        view.target_hash = Some(now);
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
        sensor: config.sensor.clone(),
        environment: crate::common::EnvArg::options(config.env.as_ref()).0,
        environment_map: crate::common::EnvArg::options(config.env.as_ref()).1,
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
    let prepared = prepare(&mut config, &scene, &ids, &args.flags, args.json)?;
    let mut history = History::new(&scene.params, &ids, prepared.truth.is_some());
    let csv = dir.join("history.csv");
    history.read(&csv, state.iteration)?;
    let run = with_smoothness(
        Optimization::resume(table.clone(), adam, state.iteration, prepared.options)?,
        &scene,
        &ids,
        &config,
    )?;
    let run = if config.control_variates { super::control::read(dir, run, &table, &ids)? } else { run };
    let run = if config.reuse { super::control::read_reuse(dir, run, &table, &ids)? } else { run };
    if state.hero.is_none()
        && state.iteration > 0
        && config.hero_weights.is_none()
        && matches!(run.options().render.strategy, pathgrad::integrator::Strategy::Hero { .. })
    {
        bail!(
            "{}: the run adapts its hero weights but the file has no `hero` state to continue them from",
            path.display()
        );
    }
    let run =
        with_hero(run, &config, state.hero.as_ref()).with_context(|| format!("{}: hero state", path.display()))?;
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
        views: prepared.views,
        targets: prepared.targets,
        truth: prepared.truth,
        ids,
        run,
        elapsed: state.elapsed_s,
        initial: state.initial,
        history,
    })
}

/// Rejects options given with `--resume` that differ from the stored run's.
pub(super) fn check_unchanged(
    args: &OptimizeArgs,
    given: &BTreeSet<String>,
    c: &RunConfig,
    state: &Path,
) -> Result<()> {
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
    check("sensor", "--sensor", args.flags.sensor.clone(), c.sensor.clone().unwrap_or_else(|| "0".into()));
    let env = |e: &Option<crate::common::EnvArg>| crate::common::EnvArg::show(e.as_ref());
    check("env", "--env", args.flags.env.is_some().then(|| env(&args.flags.env)), env(&c.env));
    check("target_set", "--target-set", Some(pairs(&args.target_set)), pairs(&c.target_set));
    let views: Vec<String> = c
        .views
        .iter()
        .map(|v| v.target.as_deref().map_or(v.sensor.clone(), |t| format!("{}={}", v.sensor, t.display())))
        .collect();
    let given_views: Vec<String> = args
        .views
        .iter()
        .map(|spec| match spec.split_once('=') {
            Some((s, t)) => absolute(Path::new(t)).map(|t| format!("{s}={}", t.display())),
            None => Ok(spec.clone()),
        })
        .collect::<Result<_>>()?;
    check("views", "--view", Some(given_views.join(" ")), views.join(" "));
    check("lr", "--lr", args.lr.map(|v| text(&v)), text(&c.lr));
    check("beta1", "--beta1", args.beta1.map(|v| text(&v)), text(&c.beta1));
    check("smooth", "--smooth", args.smooth.map(|v| text(&v)), c.smooth.map_or("none".into(), |v| text(&v)));
    check("spp_primal", "--spp-primal", args.spp_primal.map(|v| text(&v)), text(&c.spp_primal));
    check("spp_grad", "--spp-grad", args.spp_grad.map(|v| text(&v)), text(&c.spp_grad));
    check("loss", "--loss", args.loss.clone(), c.loss.clone());
    check("adaptive", "--adaptive", Some(text(&args.adaptive())), text(&c.adaptive));
    check("adaptive_estimator", "--adaptive-estimator", args.adaptive_estimator.clone(), c.adaptive_estimator.clone());
    check("deterministic", "--deterministic", Some(text(&args.deterministic)), text(&c.deterministic));
    check("control_variates", "--control-variates", args.control_variates.map(|v| text(&v)), text(&c.control_variates));
    check("reuse", "--reuse", Some(text(&args.reuse)), text(&c.reuse));
    check("spp", "--spp", args.flags.spp.map(|v| text(&v)), text(&c.spp_final));
    check("width", "--width", args.flags.width.map(|v| text(&v)), text(&c.width));
    check("height", "--height", args.flags.height.map(|v| text(&v)), text(&c.height));
    check("max_depth", "--max-depth", args.flags.max_depth.map(|v| text(&v)), text(&c.max_depth.map_or(-1, i64::from)));
    check("seed", "--seed", Some(text(&args.flags.seed)), text(&c.seed));
    check("strategy", "--strategy", Some(args.sampling.strategy.clone()), c.strategy.clone());
    check("q", "--q", args.sampling.q.map(|q| text(&q)), text(&c.q));
    check("no_nee", "--no-nee", Some(text(&args.sampling.no_nee)), text(&!c.nee));
    check("diff_param", "--diff-param", args.sampling.diff_param.clone(), c.diff_param.clone().unwrap_or_default());
    check("placement_mis", "--placement-mis", args.sampling.placement_mis.clone(), c.placement_mis.clone());
    check("sampling", "--sampling", Some(args.sampling.sampling.clone()), c.sampling.clone());
    check(
        "jacobian_noise",
        "--jacobian-noise",
        args.sampling.jacobian_noise.map(|a| text(&a)),
        c.jacobian_noise.map_or("0".into(), |a| text(&a)),
    );
    check(
        "hero_weights",
        "--hero-weights",
        args.sampling.hero_weights.clone(),
        c.hero_weights
            .as_ref()
            .map_or("adapted".into(), |w| w.iter().map(|x| x.to_string()).collect::<Vec<_>>().join(",")),
    );
    if !conflicts.is_empty() {
        bail!(
            "--resume: {} conflict with the run in {} (leave them out to continue it as it was)",
            conflicts.join(", "),
            state.display()
        );
    }
    Ok(())
}

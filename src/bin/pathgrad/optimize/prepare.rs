//! Before the first iteration: Adam's and the iterations' options, the backend, and the target.

use pathgrad::backend::Backend;
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::AtomicU64;

use anyhow::{Result, bail};
use pathgrad::gpu::renderer::GradMode;
use pathgrad::image::Image;
use pathgrad::integrator::{PlacementMis, RenderOptions, Strategy};
use pathgrad::loss::Loss;
use pathgrad::optim::{AdamOptions, ControlVariateOptions, IterationOptions, Optimization};
use pathgrad::params::{ParamId, ParamTable};
use pathgrad::prior::Smoothness;
use pathgrad::scene::Scene;
use pathgrad::variance::{PilotBudget, PilotLoss, choose_strategy};

use crate::common::{Opened, RenderFlags, target_image, view_targets, with_values};
use pathgrad::integrator::View;

use super::*;

pub(super) fn adam_options(config: &RunConfig) -> Result<AdamOptions> {
    let o = AdamOptions { beta1: config.beta1, ..AdamOptions::with_learning_rate(config.lr) };
    o.validate()?;
    Ok(o)
}

/// `run` with `--smooth`'s prior over the gridded parameters among `ids`, if it was given.
pub(super) fn with_smoothness(
    run: Optimization,
    scene: &Scene,
    ids: &[ParamId],
    config: &RunConfig,
) -> Result<Optimization> {
    let Some(weight) = config.smooth else { return Ok(run) };
    let prior = Smoothness::new(scene, ids, weight).map_err(|e| anyhow::anyhow!("--smooth {weight}: {e}"))?;
    Ok(run.with_prior(prior))
}

/// The render options of `config` on `scene`: the gradient pass's (spp = spp_grad). With
/// `--strategy auto` before its pilot has run, the strategy is `bsdf` for now.
pub(super) fn iteration_options(scene: &Scene, config: &RunConfig) -> Result<IterationOptions> {
    let (name, q) = match &config.pilot {
        Some(pilot) => (pilot.strategy.as_str(), pilot.q),
        None if config.strategy == "auto" => ("bsdf", config.q),
        None => (config.strategy.as_str(), config.q),
    };
    let strategy = match config.diff_param.as_deref() {
        // Several targets: the hero strategy (its adapted weights are set by `with_hero`).
        Some(names) if name == "diff" && names.contains(',') => {
            let names: Vec<&str> = names.split(',').collect();
            Strategy::hero(scene, &names, q, config.hero_weights.as_deref())?
        }
        target => Strategy::from_name(scene, name, q, target.unwrap_or(""))?
            .with_placement(PlacementMis::from_name(&config.placement_mis)?),
    };
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
        sampling: match config.sampling.as_str() {
            "detached" => pathgrad::integrator::Sampling::Detached,
            "attached" => pathgrad::integrator::Sampling::Attached { noise: config.jacobian_noise.unwrap_or(0.0) },
            other => bail!("invalid sampling {other} in the run's configuration"),
        },
        ..RenderOptions::for_scene(scene)
    };
    let options = IterationOptions {
        render,
        spp_primal: config.spp_primal,
        adaptive: if config.adaptive { Some(config.adaptive_estimator.parse()?) } else { None },
        loss: config.loss.parse::<Loss>()?,
        mode: if config.deterministic { GradMode::Deterministic } else { GradMode::Float },
        control_variates: config.control_variates.then(ControlVariateOptions::default),
        gradient_reuse: config.reuse.then(ControlVariateOptions::default),
    };
    options.validate()?;
    Ok(options)
}

/// What a run needs besides its parameters and Adam: the renderer, the target, the truth (with
/// `--target-set`) and the iteration options.
pub(super) struct Prepared {
    pub(super) renderer: Box<dyn Backend>,
    pub(super) ctx: Option<Arc<pathgrad::gpu::Context>>,
    /// Microseconds spent building kernel variants so far (see `announce_compiles`).
    pub(super) compile_us: Arc<AtomicU64>,
    /// The views optimised over and their targets.
    pub(super) views: Vec<View>,
    pub(super) targets: Vec<Image>,
    pub(super) truth: Option<ParamTable>,
    pub(super) options: IterationOptions,
}

/// Checks `config` on `scene`, creates the device and the renderer and renders or reads the target;
/// the gradient passes compile only the parameter kinds of `ids`, the parameters optimised. With
/// `--strategy auto` and no stored choice, runs the pilot at the gradient pass's options and stores
/// its choice in `config` (a resumed run has it and does not pilot again).
pub(super) fn prepare(
    config: &mut RunConfig,
    scene: &Scene,
    ids: &[ParamId],
    flags: &RenderFlags,
    quiet: bool,
) -> Result<Prepared> {
    let mut options = iteration_options(scene, config)?;
    let truth = if config.target_set.is_empty() {
        None
    } else {
        Some(with_values(&scene.params, &config.target_set, "--target-set")?)
    };
    let Opened { backend: mut renderer, ctx, compile_us, .. } = flags.backend(scene, &config.scene, quiet)?;
    let final_opts = RenderOptions { spp: config.spp_final, ..options.render };
    if !config.views.is_empty() {
        let mut views = Vec::new();
        for v in &config.views {
            let index = scene.sensor_index(&v.sensor).context("--view")?;
            views.push((View::sensor(scene, index)?, v.target.clone()));
        }
        let targets = view_targets(renderer.as_mut(), scene, &final_opts, &views, &config.target_set)?;
        options.render.differentiate = renderer.param_kinds(ids);
        pilot(config, scene, renderer.as_mut(), &mut options, None)?;
        let views = views.into_iter().map(|(v, _)| v).collect();
        return Ok(Prepared { renderer, ctx, compile_us, views, targets, truth, options });
    }
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
    let measure = PilotLoss { target: &target, loss: options.loss, spp_primal: config.spp_primal, params: ids };
    pilot(config, scene, renderer.as_mut(), &mut options, Some(&measure))?;
    let views = vec![View::current(scene)];
    Ok(Prepared { renderer, ctx, compile_us, views, targets: vec![target], truth, options })
}

/// `--strategy auto` without a stored choice: runs the pilot at the gradient pass's options — on the
/// loss gradient with `measure` (one view), else on the image gradient — stores its choice in
/// `config` and sets it in `options`.
fn pilot(
    config: &mut RunConfig,
    scene: &Scene,
    renderer: &mut dyn Backend,
    options: &mut IterationOptions,
    measure: Option<&PilotLoss>,
) -> Result<()> {
    if config.strategy != "auto" || config.pilot.is_some() {
        return Ok(());
    }
    let param = config.diff_param.clone().context("--strategy auto: no parameter to pilot on")?;
    let placement = PlacementMis::from_name(&config.placement_mis)?;
    let choice = choose_strategy(renderer, &options.render, &param, placement, PilotBudget::default(), measure)
        .context("running --strategy auto's pilot")?;
    tracing::info!(
        "--strategy auto picked {} for {param} (pilot: {} renders, {} spp per pixel in all, {:.2} s of which {:.2} s kernel warm-up)",
        crate::common::strategy_label(&choice.strategy),
        choice.renders,
        choice.samples_per_pixel,
        choice.seconds,
        choice.warm_up_seconds
    );
    let q = match choice.strategy {
        Strategy::Diff { q, .. } | Strategy::Hero { q, .. } => q,
        Strategy::Bsdf => config.q,
    };
    let report = crate::common::pilot_json(scene, &param, &choice, measure.is_some());
    config.pilot = Some(PilotChoice { strategy: choice.strategy.name().to_string(), q, report });
    options.render.strategy = iteration_options(scene, config)?.render.strategy;
    Ok(())
}

/// `run` with its hero probabilities adapted (several `--diff-param`s without `--hero-weights`),
/// from `state` (`None`: a fresh run), else `run` as it is.
pub(super) fn with_hero(run: Optimization, config: &RunConfig, state: Option<&HeroState>) -> Result<Optimization> {
    let Strategy::Hero { heroes, .. } = run.options().render.strategy else { return Ok(run) };
    if config.hero_weights.is_some() {
        return Ok(run);
    }
    let adaptation = match state {
        None => pathgrad::optim::HeroAdaptation::new(&heroes),
        Some(s) => pathgrad::optim::HeroAdaptation { steps: s.steps, mean: s.mean.clone(), square: s.square.clone() },
    };
    run.with_hero_adaptation(adaptation).map_err(|e| {
        anyhow::anyhow!("--diff-param {}: {e} (or give --hero-weights)", config.diff_param.as_deref().unwrap_or(""))
    })
}

pub(super) fn values_of(table: &ParamTable, ids: &[ParamId]) -> BTreeMap<String, Vec<f64>> {
    ids.iter()
        .map(|&id| (table.entry(id).name.clone(), table.get(id).iter().map(|&v| f64::from(v)).collect()))
        .collect()
}

//! What every command shares: the rendering flags and the backend they open, targets, parameter
//! values, progress bars and output files.

use std::borrow::Cow;
use std::path::{Path, PathBuf};

use anyhow::{Context as _, Result, bail};
use clap::Args;
use pathgrad::backend::Backend;
use pathgrad::gpu::{Context, ContextDesc, DeviceChoice, Renderer};
use pathgrad::image::Image;
use pathgrad::integrator::{RenderOptions, View};
use pathgrad::phases::PhaseReport;

/// Samples per pixel when neither `--spp` nor the scene names a number.
pub(crate) const DEFAULT_SPP: u32 = 16;

/// A backend opened by [`RenderFlags::backend`].
pub(crate) struct Opened {
    pub(crate) backend: Box<dyn Backend>,
    /// The Vulkan context (none for the CPU reference): memory figures.
    pub(crate) ctx: Option<std::sync::Arc<pathgrad::gpu::Context>>,
    /// Microseconds spent building kernel variants so far (see `announce_compiles`).
    pub(crate) compile_us: std::sync::Arc<std::sync::atomic::AtomicU64>,
    /// The phases of opening it: `flatten` and `bvh`, then `shading` (CPU reference only: on the
    /// GPU the shading data is made during `upload`), or `device` (the Vulkan context) and `upload`.
    pub(crate) report: PhaseReport,
    /// Bytes of device memory the scene's buffers take (GPU only).
    pub(crate) scene_device_bytes: Option<u64>,
}

/// Options every rendering command accepts.
#[derive(Args, Debug)]
pub(crate) struct RenderFlags {
    /// Samples per pixel, at most 1048576 (default: the scene's, else 16).
    #[arg(long)]
    pub(crate) spp: Option<u32>,
    /// Image width (default: the scene's).
    #[arg(long)]
    pub(crate) width: Option<u32>,
    /// Image height (default: the scene's).
    #[arg(long)]
    pub(crate) height: Option<u32>,
    /// Maximum surface interactions per path, at most 1024; -1 is unbounded: Russian roulette
    /// ends paths, and none goes beyond 1024 (default: the scene's).
    #[arg(long, allow_negative_numbers = true)]
    pub(crate) max_depth: Option<i64>,
    /// Random seed.
    #[arg(long, default_value_t = 0)]
    pub(crate) seed: u32,
    /// Vulkan device: an index or UUID from `pathgrad devices`, or `cpu` for a CPU Vulkan device
    /// such as lavapipe (the CPU reference implementation is `--cpu`) (env: PATHGRAD_DEVICE).
    #[arg(long)]
    pub(crate) device: Option<String>,
    /// Run on the CPU reference implementation instead of Vulkan (the same estimators and random
    /// numbers; slower).
    #[arg(long, conflicts_with = "device")]
    pub(crate) cpu: bool,
    /// The sensor to render: its index or name in a scene with several (`pathgrad params`
    /// lists them; default: the first).
    #[arg(long)]
    pub(crate) sensor: Option<String>,
    /// Let the scene read files outside its own folder (absolute paths, `..`); by default a
    /// scene reads only the files beside and below it.
    #[arg(long)]
    pub(crate) allow_outside_folder: bool,
    /// Light the scene with an environment: a constant linear RGB radiance (`R,G,B`, or one number
    /// for grey), or an environment map file (EXR, HDR or PNG, latitude-longitude as Mitsuba's
    /// `envmap`, parameter `env.data`): for scenes without lights of their own, as most glTF
    /// assets are. A scene's own constant environment takes a constant's radiance instead; a map
    /// is refused on a scene with an environment of its own.
    #[arg(long, value_name = "R,G,B|FILE", value_parser = parse_environment)]
    pub(crate) env: Option<EnvArg>,
}

/// What `--env` (and a batch item's `env`) gives: a constant radiance or a map file.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(untagged)]
pub(crate) enum EnvArg {
    /// A constant linear RGB radiance.
    Rgb([f32; 3]),
    /// An environment map file.
    Map(PathBuf),
}

impl EnvArg {
    /// The two load options it sets: `environment` and `environment_map`.
    pub(crate) fn options(env: Option<&EnvArg>) -> (Option<[f32; 3]>, Option<PathBuf>) {
        match env {
            None => (None, None),
            Some(EnvArg::Rgb(rgb)) => (Some(*rgb), None),
            Some(EnvArg::Map(path)) => (None, Some(path.clone())),
        }
    }

    /// As the user gives it: `r,g,b` or the file.
    pub(crate) fn show(env: Option<&EnvArg>) -> String {
        match env {
            None => "none".into(),
            Some(EnvArg::Rgb([r, g, b])) => format!("{r},{g},{b}"),
            Some(EnvArg::Map(path)) => path.display().to_string(),
        }
    }
}

/// `--env`: `R,G,B` or one number, each finite and ≥ 0; anything that is not numbers is a file.
pub(crate) fn parse_environment(text: &str) -> std::result::Result<EnvArg, String> {
    let numbers: Option<Vec<f32>> = text.split(',').map(|v| v.trim().parse::<f32>().ok()).collect();
    let Some(values) = numbers else { return Ok(EnvArg::Map(PathBuf::from(text))) };
    let rgb = match values[..] {
        [v] => [v; 3],
        [r, g, b] => [r, g, b],
        _ => return Err(format!("{} values: give R,G,B or one number", values.len())),
    };
    if !rgb.iter().all(|v| v.is_finite() && *v >= 0.0) {
        return Err(format!("{rgb:?}: every channel must be finite and ≥ 0"));
    }
    Ok(EnvArg::Rgb(rgb))
}

impl RenderFlags {
    /// The backend these flags ask for, on `scene`: the CPU reference with `--cpu`, else a
    /// renderer on the chosen device (first compiles announced on stderr unless `quiet`).
    pub(crate) fn backend(&self, scene: &pathgrad::scene::Scene, spec: &str, quiet: bool) -> Result<Opened> {
        self.open(Cow::Borrowed(scene), spec, quiet)
    }

    /// [`RenderFlags::backend`] for a caller that no longer needs `scene`: a renderer takes it
    /// over instead of a copy, so the two are never held together (issue 38).
    pub(crate) fn backend_owned(&self, scene: pathgrad::scene::Scene, spec: &str, quiet: bool) -> Result<Opened> {
        self.open(Cow::Owned(scene), spec, quiet)
    }

    fn open(&self, scene: Cow<'_, pathgrad::scene::Scene>, spec: &str, quiet: bool) -> Result<Opened> {
        let mut report = PhaseReport::new();
        if self.cpu {
            let cpu = pathgrad::cpu::Reference::new(&scene).with_context(|| format!("loading {spec}"))?;
            report.extend(cpu.report());
            let backend = Box::new(cpu);
            return Ok(Opened { backend, ctx: None, compile_us: Default::default(), report, scene_device_bytes: None });
        }
        // Flattened (and its BVH built) before the device opens, so that the build's transient
        // memory and the device's are never held together (issue 38).
        let flat = {
            let _span = tracing::info_span!("load", scene = %scene.source).entered();
            pathgrad::scene::flat::FlatScene::for_device_reporting(&scene, &mut report)
                .with_context(|| format!("loading {spec}"))?
        };
        let start = std::time::Instant::now();
        let ctx = context(&self.device)?;
        report.record("device", start);
        let mut renderer =
            Renderer::from_flat(&ctx, scene.into_owned(), flat).with_context(|| format!("loading {spec}"))?;
        report.extend(renderer.report());
        let scene_device_bytes = Some(renderer.scene_device_bytes());
        let compile_us = announce_compiles(&mut renderer, quiet);
        Ok(Opened { backend: Box::new(renderer), ctx: Some(ctx), compile_us, report, scene_device_bytes })
    }

    /// Loads `spec` for these flags: curved shapes are tessellated for the size rendered.
    pub(crate) fn load(&self, spec: &str, defines: &[(String, String)]) -> Result<pathgrad::scene::Scene> {
        self.load_reporting(spec, defines, &mut PhaseReport::new())
    }

    /// [`RenderFlags::load`], recording the phases `parse` and `assemble` in `report`.
    pub(crate) fn load_reporting(
        &self,
        spec: &str,
        defines: &[(String, String)],
        report: &mut PhaseReport,
    ) -> Result<pathgrad::scene::Scene> {
        let options = pathgrad::scene::LoadOptions {
            defines: defines.to_vec(),
            width: self.width,
            height: self.height,
            allow_outside_folder: self.allow_outside_folder,
            sensor: self.sensor.clone(),
            environment: EnvArg::options(self.env.as_ref()).0,
            environment_map: EnvArg::options(self.env.as_ref()).1,
        };
        Ok(pathgrad::scene::load_reporting(spec, &options, report)?)
    }
}

/// How gradient passes sample paths: every command that estimates gradients takes these.
#[derive(Args, Debug, Clone)]
pub(crate) struct StrategyArgs {
    /// Gradient sampling strategy: `bsdf` (plain PRB, the baseline), `diff` (differential path
    /// sampling of one vertex, Su & Gkioulekas) or `auto` (a short pilot of a few 1-spp image
    /// gradients picks bsdf or diff and its q, whichever has the least variance × time).
    #[arg(long, default_value = "bsdf")]
    pub(crate) strategy: String,
    /// How `diff` weights its placements of the differential vertex: `balance` (the mixture
    /// density, the paper's) or `power` (the power heuristic) (only with `--strategy diff|auto`).
    #[arg(long, value_name = "balance|power")]
    pub(crate) placement_mis: Option<String>,
    /// Probability that `diff` makes a capable vertex the differential vertex [default: 0.5]
    /// (only with `--strategy diff`).
    #[arg(long)]
    pub(crate) q: Option<f32>,
    /// Turn next-event estimation off (for both strategies).
    #[arg(long)]
    pub(crate) no_nee: bool,
    /// The parameter whose derivative drives `diff`'s sampler (default: the first parameter the
    /// command differentiates). Several, comma-separated (`A,B`, at most 4, each a roughness or
    /// blend weight): each path draws one of them as its hero and samples its derivative
    /// (ALGORITHMS.md §5.8).
    #[arg(long, value_name = "NAME[,NAME…]")]
    pub(crate) diff_param: Option<String>,
    /// With several `--diff-param`s: the probability of each being a path's hero, comma-separated
    /// in the same order (normalised to sum 1) [default: uniform; `optimize`: adapted to each
    /// parameter's gradient variance].
    #[arg(long, value_name = "W,W…")]
    pub(crate) hero_weights: Option<String>,
    /// How sampled directions relate to the parameters in gradient passes: `detached` (held
    /// fixed, Mitsuba's prb) or `attached` (they move with the parameters: the index of
    /// refraction of dielectrics becomes differentiable, and a near-specular rough conductor's
    /// roughness gets a lower-variance gradient; scenes of smooth dielectrics and conductors,
    /// isotropic, untextured rough conductors and rough dielectrics and diffuse surfaces whose
    /// albedo is constant or smoothly textured only, docs/gradients.md "Attached derivatives").
    #[arg(long, value_name = "detached|attached", default_value = "detached")]
    pub(crate) sampling: String,
    /// With `--sampling attached`: the amplitude of the zero-mean noise added to each ray
    /// Jacobian (PRB supplemental §2), in [0, 1) [default: 0, none; diffuse vertices, which
    /// need noise, then take amplitude 1].
    #[arg(long, value_name = "A")]
    pub(crate) jacobian_noise: Option<f32>,
}

impl StrategyArgs {
    /// `--q`, or its default.
    pub(crate) fn q(&self) -> f32 {
        self.q.unwrap_or(pathgrad::integrator::DEFAULT_DIFF_Q)
    }

    /// `--sampling` and `--jacobian-noise` as the library's [`pathgrad::integrator::Sampling`].
    pub(crate) fn directions(&self) -> Result<pathgrad::integrator::Sampling> {
        use pathgrad::integrator::{DEFAULT_JACOBIAN_NOISE, Sampling};
        match (self.sampling.as_str(), self.jacobian_noise) {
            ("detached", None) => Ok(Sampling::Detached),
            ("detached", Some(a)) => bail!("--jacobian-noise {a} applies only to --sampling attached"),
            ("attached", a) => Ok(Sampling::Attached { noise: a.unwrap_or(DEFAULT_JACOBIAN_NOISE) }),
            (other, _) => bail!("invalid --sampling {other}: expected detached or attached"),
        }
    }

    /// `--hero-weights` as numbers, if given.
    pub(crate) fn hero_weights(&self) -> Result<Option<Vec<f32>>> {
        let Some(w) = &self.hero_weights else { return Ok(None) };
        let parsed: std::result::Result<Vec<f32>, _> = w.split(',').map(|x| x.trim().parse::<f32>()).collect();
        match parsed {
            Ok(v) => Ok(Some(v)),
            Err(e) => bail!("--hero-weights {w}: {e} (expected numbers, comma-separated)"),
        }
    }

    /// `--placement-mis`, or the balance heuristic.
    pub(crate) fn placement(&self) -> Result<pathgrad::integrator::PlacementMis> {
        Ok(pathgrad::integrator::PlacementMis::from_name(self.placement_mis.as_deref().unwrap_or("balance"))?)
    }

    /// With `--strategy auto`: runs the pilot ([`pathgrad::variance::choose_strategy`]) for the
    /// parameter `--diff-param` names, else `default_target`, under `opts` (its resolution, NEE,
    /// seed and parameter kinds) — on the loss gradient with `loss`, else on the image gradient —
    /// sets `opts.strategy` to its choice, says what it picked (info line) and returns the choice
    /// as JSON; without, `None`.
    pub(crate) fn choose(
        &self,
        backend: &mut dyn pathgrad::backend::Backend,
        default_target: Option<&str>,
        opts: &mut RenderOptions,
        loss: Option<&pathgrad::variance::PilotLoss>,
    ) -> Result<Option<serde_json::Value>> {
        if self.strategy != "auto" {
            return Ok(None);
        }
        let Some(target) = self.diff_param.as_deref().or(default_target) else {
            bail!("--strategy auto needs a parameter to pilot on: give --diff-param NAME");
        };
        if target.contains(',') {
            bail!("--strategy auto pilots on one --diff-param, not several ({target}): use --strategy diff");
        }
        let choice = pathgrad::variance::choose_strategy(
            backend,
            opts,
            target,
            self.placement()?,
            pathgrad::variance::PilotBudget::default(),
            loss,
        )
        .context("running --strategy auto's pilot")?;
        opts.strategy = choice.strategy;
        let json = pilot_json(backend.scene(), target, &choice, loss.is_some());
        tracing::info!(
            "--strategy auto picked {} for {target} (pilot: {} renders, {} spp per pixel in all, {:.2} s of which {:.2} s kernel warm-up)",
            strategy_label(&choice.strategy),
            choice.renders,
            choice.samples_per_pixel,
            choice.seconds,
            choice.warm_up_seconds
        );
        Ok(Some(json))
    }

    /// Sets `opts.strategy` and `opts.nee`; `default_target` is the parameter the command
    /// differentiates first. Warns when `diff` has no sampler for the target.
    pub(crate) fn apply(
        &self,
        scene: &pathgrad::scene::Scene,
        default_target: Option<&str>,
        opts: &mut RenderOptions,
    ) -> Result<()> {
        use pathgrad::integrator::Strategy;
        opts.nee = !self.no_nee;
        opts.sampling = self.directions()?;
        if self.strategy != "diff"
            && let Some(q) = self.q
        {
            bail!("--q {q} applies only to --strategy diff (this run uses {}; auto chooses q)", self.strategy);
        }
        if self.strategy == "bsdf" {
            if let Some(name) = &self.diff_param {
                bail!("--diff-param {name} applies only to --strategy diff or auto (this run uses bsdf)");
            }
            if let Some(name) = &self.placement_mis {
                bail!("--placement-mis {name} applies only to --strategy diff or auto (this run uses bsdf)");
            }
        }
        let placement = self.placement()?;
        let target = self.diff_param.as_deref().or(default_target);
        if let Some(w) = &self.hero_weights
            && !(self.strategy == "diff" && self.diff_param.as_deref().is_some_and(|t| t.contains(',')))
        {
            bail!("--hero-weights {w} applies only to --strategy diff with several --diff-param NAME,NAME");
        }
        if self.strategy != "bsdf"
            && let Some(names) = target.filter(|t| t.contains(','))
        {
            if self.strategy != "diff" {
                bail!(
                    "--strategy {} takes one --diff-param, not several ({names}): use --strategy diff",
                    self.strategy
                );
            }
            if placement == pathgrad::integrator::PlacementMis::Power {
                bail!("--placement-mis power is not built for several --diff-param ({names}): use balance");
            }
            let names: Vec<&str> = names.split(',').map(str::trim).collect();
            let weights = self.hero_weights()?;
            opts.strategy = Strategy::hero(scene, &names, self.q(), weights.as_deref())
                .with_context(|| format!("invalid --diff-param {}", names.join(",")))?;
            opts.validate()?;
            return Ok(());
        }
        opts.strategy = match (self.strategy.as_str(), target) {
            ("diff", None) => bail!("--strategy diff needs --diff-param NAME (the parameter that drives the sampler)"),
            // The pilot (`choose`) sets the strategy once the device is open; its target is checked here.
            ("auto", Some(target)) => {
                Strategy::from_name(scene, "diff", self.q(), target)?;
                Strategy::Bsdf
            }
            ("auto", None) => bail!("--strategy auto needs a parameter to pilot on: give --diff-param NAME"),
            (name, target) => Strategy::from_name(scene, name, self.q(), target.unwrap_or(""))
                .with_context(|| format!("invalid --strategy {name}"))?
                .with_placement(placement),
        };
        warn_without_sampler(scene, opts.strategy);
        opts.validate()?;
        Ok(())
    }
}

/// The parameters `patterns` select (as [`pathgrad::params::ParamTable::select`]), for gradient
/// passes sampled as `sampling` ([`pathgrad::attached::differentiated`]: with detached sampling a
/// dielectric's index of refraction is an error when a pattern names it exactly, and a wildcard
/// leaves it out).
pub(crate) fn select_differentiated(
    scene: &pathgrad::scene::Scene,
    patterns: &[&str],
    sampling: pathgrad::integrator::Sampling,
) -> Result<Vec<pathgrad::params::ParamId>> {
    let chosen = scene.params.select(patterns)?;
    let named: Vec<_> =
        chosen.iter().copied().filter(|&id| patterns.contains(&scene.params.entry(id).name.as_str())).collect();
    Ok(pathgrad::attached::differentiated(scene, chosen, &named, sampling)?)
}

/// `bsdf`, or `diff q=Q` (with `power` placements: `diff q=Q power`).
pub(crate) fn strategy_label(strategy: &pathgrad::integrator::Strategy) -> String {
    use pathgrad::integrator::{PlacementMis, Strategy};
    match strategy {
        Strategy::Bsdf => "bsdf".into(),
        Strategy::Diff { q, placement: PlacementMis::Balance, .. } => format!("diff q={q}"),
        Strategy::Diff { q, placement: PlacementMis::Power, .. } => format!("diff q={q} power"),
        Strategy::Hero { q, heroes } => {
            let p: Vec<String> = heroes.weights().iter().map(|p| format!("{p:.3}")).collect();
            format!("diff q={q} heroes p={}", p.join(","))
        }
    }
}

/// A strategy as JSON: `{"technique", "strategy", "q", "placement_mis", "diff_param"}` (`null`s
/// for bsdf; `technique` is [`strategy_label`]'s).
pub(crate) fn strategy_json(
    scene: &pathgrad::scene::Scene,
    strategy: &pathgrad::integrator::Strategy,
) -> serde_json::Value {
    use pathgrad::integrator::Strategy;
    match strategy {
        Strategy::Bsdf => {
            serde_json::json!({"technique": "bsdf", "strategy": "bsdf", "q": null, "placement_mis": null, "diff_param": null})
        }
        Strategy::Diff { target, q, placement } => serde_json::json!({
            "technique": strategy_label(strategy), "strategy": "diff", "q": q, "placement_mis": placement.name(),
            "diff_param": scene.params.entry(*target).name,
        }),
        Strategy::Hero { heroes, q } => {
            let names: Vec<&str> = heroes.targets().iter().map(|t| scene.params.entry(*t).name.as_str()).collect();
            serde_json::json!({
                "technique": strategy_label(strategy), "strategy": "diff", "q": q, "placement_mis": "balance",
                "diff_param": names.join(","), "hero_weights": heroes.weights(),
            })
        }
    }
}

/// What `--strategy auto`'s pilot picked and measured, with its cost, as JSON.
pub(crate) fn pilot_json(
    scene: &pathgrad::scene::Scene,
    param: &str,
    choice: &pathgrad::variance::StrategyChoice,
    loss: bool,
) -> serde_json::Value {
    let candidates: Vec<serde_json::Value> = choice
        .candidates
        .iter()
        .map(|c| {
            serde_json::json!({
                "technique": strategy_label(&c.strategy),
                "variance": c.variance,
                "seconds_per_estimate": c.seconds_per_estimate,
                "efficiency": c.efficiency,
            })
        })
        .collect();
    serde_json::json!({
        "picked": strategy_json(scene, &choice.strategy),
        "param": param,
        "measure": if loss { "loss gradient" } else { "image gradient" },
        "candidates": candidates,
        "pilot_s": choice.seconds,
        "pilot_warm_up_s": choice.warm_up_seconds,
        "pilot_cpu_s": choice.cpu_seconds,
        "pilot_renders": choice.renders,
        "pilot_spp": choice.samples_per_pixel,
    })
}

/// Warns when `strategy` is `diff` driven by a parameter no material has a differential sampler for
/// (it then samples like `bsdf`, with the balance heuristic).
pub(crate) fn warn_without_sampler(scene: &pathgrad::scene::Scene, strategy: pathgrad::integrator::Strategy) {
    use pathgrad::integrator::Strategy;
    if let Strategy::Diff { target, .. } = strategy
        && !Strategy::has_differential_sampler(scene, target)
    {
        tracing::warn!(
            "{} is neither a roughness, a blend weight nor a medium's g: --strategy diff samples like bsdf (balance heuristic)",
            scene.params.entry(target).name
        );
    }
}

/// The target of `--target-set` gets this many times the gradient render's spp (at least
/// `TARGET_MIN_SPP`), so its noise is small next to the render's.
pub(crate) const TARGET_SPP_FACTOR: u32 = 4;
pub(crate) const TARGET_MIN_SPP: u32 = 64;
/// The target of `--target-set` uses this seed offset and the reference key ([`Renderer::render_reference`]), so its paths are independent of every render of the run.
pub(crate) const TARGET_SEED_OFFSET: u32 = 0x5EED;

pub(crate) fn parse_values(flag: &str, name: &str, text: &str) -> Result<Vec<f32>> {
    text.split(',')
        .map(|v| {
            v.trim().parse::<f32>().map_err(|_| anyhow::anyhow!("invalid {flag} {name}={text}: '{v}' is not a number"))
        })
        .collect()
}

/// The image a loss compares against: `--target REF.exr`, or the scene rendered at `--target-set`
/// values with [`TARGET_SPP_FACTOR`]× the spp (at least [`TARGET_MIN_SPP`]), an independent seed
/// and plain BSDF sampling with NEE. The renderer's parameters are restored to the scene's after.
pub(crate) fn target_image(
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
            let view = pathgrad::integrator::View::current(scene);
            rendered_targets(renderer, scene, opts, &[view], target_set)?.remove(0)
        }
        _ => bail!("give --target REF.exr or --target-set NAME=VALUE"),
    })
}

/// `views` rendered at `--target-set` values in one pass, as [`target_image`] renders one; the
/// renderer's parameters are restored to the scene's after.
fn rendered_targets(
    renderer: &mut dyn Backend,
    scene: &pathgrad::scene::Scene,
    opts: &RenderOptions,
    views: &[View],
    target_set: &[(String, String)],
) -> Result<Vec<Image>> {
    let table = with_values(&scene.params, target_set, "--target-set")?;
    renderer.set_params(&table)?;
    let target_opts = RenderOptions {
        spp: (opts.spp * TARGET_SPP_FACTOR).max(TARGET_MIN_SPP),
        seed: opts.seed.wrapping_add(TARGET_SEED_OFFSET),
        strategy: pathgrad::integrator::Strategy::Bsdf,
        nee: true,
        ..*opts
    };
    let targets = renderer
        .render_views(&target_opts, views, pathgrad::rng::PassTag::Reference, &mut |_, _| {})
        .context("rendering the target")?;
    renderer.set_params(&scene.params)?;
    Ok(targets)
}

/// The views of `--view SENSOR[=TARGET.exr]` flags, each with its target file if it names one.
/// Every view names a sensor once; either every view names a target or none does (they are then
/// rendered with `--target-set`). The views share one film size, which `opts` takes unless
/// `--width`/`--height` are given. Checked before any device is opened.
pub(crate) fn parse_views(
    scene: &pathgrad::scene::Scene,
    flags: &RenderFlags,
    specs: &[String],
    has_target_set: bool,
    opts: &mut RenderOptions,
) -> Result<Vec<(View, Option<PathBuf>)>> {
    if let Some(sensor) = &flags.sensor {
        bail!("--sensor {sensor} and --view both choose cameras: give the sensors as --view SENSOR only");
    }
    let mut out: Vec<(View, Option<PathBuf>, usize)> = Vec::new();
    for spec in specs {
        let (sensor, target) = match spec.split_once('=') {
            Some((s, "")) => {
                bail!("invalid --view {spec}: the target path after '=' is empty (give --view {s}=TARGET.exr)")
            }
            Some((s, t)) => (s, Some(PathBuf::from(t))),
            None => (spec.as_str(), None),
        };
        let index = scene.sensor_index(sensor).with_context(|| format!("invalid --view {spec}"))?;
        if out.iter().any(|(_, _, i)| *i == index) {
            bail!("invalid --view {spec}: sensor {index} ('{}') is given twice", scene.sensors[index].name);
        }
        match (&target, has_target_set) {
            (Some(_), true) => {
                bail!("invalid --view {spec}: with --target-set the targets are rendered (give --view SENSOR)")
            }
            (None, false) => bail!(
                "invalid --view {spec}: give its target as --view {sensor}=TARGET.exr, or render the targets with --target-set"
            ),
            _ => {}
        }
        out.push((View::sensor(scene, index)?, target, index));
    }
    let film = |i: usize| (scene.sensors[i].camera.width, scene.sensors[i].camera.height);
    let first = film(out[0].2);
    if let Some((_, _, other)) = out.iter().find(|(_, _, i)| film(*i) != first) {
        let (w, h) = film(*other);
        bail!(
            "--view: the views of one step share a film size, but sensor '{}' is {}×{} and '{}' is {w}×{h}",
            scene.sensors[out[0].2].name,
            first.0,
            first.1,
            scene.sensors[*other].name
        );
    }
    opts.width = flags.width.unwrap_or(first.0);
    opts.height = flags.height.unwrap_or(first.1);
    Ok(out.into_iter().map(|(v, t, _)| (v, t)).collect())
}

/// The targets of views from [`parse_views`]: the EXR files they name, or all of them rendered at
/// `--target-set` values in one pass.
pub(crate) fn view_targets(
    renderer: &mut dyn Backend,
    scene: &pathgrad::scene::Scene,
    opts: &RenderOptions,
    views: &[(View, Option<PathBuf>)],
    target_set: &[(String, String)],
) -> Result<Vec<Image>> {
    if !target_set.is_empty() {
        let list: Vec<View> = views.iter().map(|(v, _)| *v).collect();
        return rendered_targets(renderer, scene, opts, &list, target_set);
    }
    views
        .iter()
        .map(|(view, path)| {
            let path = path.as_deref().expect("parse_views checked that every view names a target");
            let image = target_image(renderer, scene, opts, Some(path), &[]).with_context(|| {
                let sensor = scene.sensors.get(view.stream as usize).map_or("?", |s| s.name.as_str());
                format!("--view {sensor}={}", path.display())
            })?;
            if (image.width(), image.height()) != (opts.width, opts.height) {
                bail!(
                    "invalid --view target {}: it is {}×{} but the views render at {}×{}",
                    path.display(),
                    image.width(),
                    image.height(),
                    opts.width,
                    opts.height
                );
            }
            Ok(image)
        })
        .collect()
}

/// `table` with the values of `settings` (NAME=V sets every value of the parameter or glob,
/// NAME=R,G,B each); `flag` names the option in errors.
pub(crate) fn with_values(
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

pub(crate) fn parse_define(text: &str) -> std::result::Result<(String, String), String> {
    match text.split_once('=') {
        Some((name, value)) if !name.trim().is_empty() => Ok((name.trim().to_string(), value.to_string())),
        _ => Err(format!("expected NAME=VALUE, got '{text}'")),
    }
}

pub(crate) fn context(device: &Option<String>) -> Result<std::sync::Arc<Context>> {
    let validation = std::env::var("PATHGRAD_VALIDATION").is_ok_and(|v| v == "1");
    let device = device.as_deref().map(DeviceChoice::parse).unwrap_or_default();
    Ok(Context::new(&ContextDesc { device, validation })?)
}

pub(crate) fn options(scene: &pathgrad::scene::Scene, flags: &RenderFlags) -> Result<RenderOptions> {
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

pub(crate) fn check_output(path: &Path) -> Result<bool> {
    match path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).as_deref() {
        Some("exr") => Ok(true),
        Some("png") => Ok(false),
        _ => bail!("invalid -o {}: the output must end in .exr or .png", path.display()),
    }
}

/// Tells the user, on stderr, when building a kernel variant takes more than a moment: lavapipe
/// compiles each variant on its first use on a machine (later runs load it from Mesa's shader
/// cache), and a silent wait of seconds looks like a hang. Nothing is printed when `quiet` or when
/// the build is quick. Returns the wall time spent building variants so far, in microseconds
/// (variants built side by side count once), which keeps growing as later calls build more
/// (`optimize` counts it as set-up, not iterations).
pub(crate) fn announce_compiles(renderer: &mut Renderer, quiet: bool) -> std::sync::Arc<std::sync::atomic::AtomicU64> {
    use pathgrad::gpu::renderer::{COMPILE_NOTICE_MS, CompileEvent};
    let total_us = std::sync::Arc::new(std::sync::atomic::AtomicU64::new(0));
    let total = total_us.clone();
    // The builds under way: each one's kernel and the timer thread that announces it if it is slow.
    let mut pending: Vec<(&'static str, std::sync::mpsc::Sender<()>, std::thread::JoinHandle<()>)> = Vec::new();
    let mut outstanding = 0usize;
    let mut busy_since = std::time::Instant::now();
    renderer.set_compile_observer(Box::new(move |event| match event {
        CompileEvent::Started { kernel, features } => {
            if outstanding == 0 {
                busy_since = std::time::Instant::now();
            }
            outstanding += 1;
            if quiet {
                return;
            }
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
            pending.push((kernel, done, timer));
        }
        CompileEvent::Finished { kernel, seconds } => {
            outstanding = outstanding.saturating_sub(1);
            if outstanding == 0 {
                total.fetch_add(busy_since.elapsed().as_micros() as u64, std::sync::atomic::Ordering::Relaxed);
            }
            if let Some(i) = pending.iter().position(|(k, _, _)| k == kernel) {
                let (_, done, timer) = pending.remove(i);
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
pub(crate) fn progress_bar(len: u64, what: &str, hidden: bool) -> indicatif::ProgressBar {
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

/// Takes an exclusive advisory lock (`flock`) on `handle` (a file or a directory) without waiting,
/// held until the returned handle is dropped (the process ends, however it ends; on NFS the lock
/// holds across machines). `busy` is the error when another process holds it, `failed` the context
/// of any other failure.
pub(crate) fn try_lock(
    handle: std::fs::File,
    busy: impl FnOnce() -> String,
    failed: impl FnOnce() -> String,
) -> Result<std::fs::File> {
    match handle.try_lock() {
        Ok(()) => Ok(handle),
        Err(std::fs::TryLockError::WouldBlock) => bail!("{}", busy()),
        Err(std::fs::TryLockError::Error(e)) => Err(anyhow::Error::new(e).context(failed())),
    }
}

/// The PNG preview written beside an EXR output.
pub(crate) fn preview_path(output: &Path) -> PathBuf {
    output.with_extension("png")
}

/// Refuses an image with a NaN or an infinite value (`what` names it): such a result is never
/// written. Radiance beyond the f32 range (a constant environment of 3e38, say) ends up here.
pub(crate) fn refuse_non_finite(image: &Image, what: &str) -> Result<()> {
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

pub(crate) fn save(image: &Image, path: &Path, is_exr: bool, exposure: f32) -> Result<()> {
    if is_exr {
        image.write_exr(path)?
    } else {
        image.write_png(path, exposure)?
    }
    Ok(())
}

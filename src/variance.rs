//! Variance of gradient estimators over independent runs (ALGORITHMS.md §7.4): per-pixel
//! image-gradient variance maps and the variance of loss gradients, each with its time per estimate.
//!
//! Both protocols repeat one estimate R times with seeds `seed, seed + 1, …, seed + R − 1` — the
//! same seeds for every technique, so techniques are compared on equal footing — and accumulate the
//! mean and the *sample* variance (divisor R − 1) of every value in f64 with Welford's update. The
//! paper's scripts report the population variance (divisor R); ratios between techniques are the
//! same either way, and absolute values differ by R/(R − 1).
//!
//! Equal-time efficiency: an estimator with variance σ² that takes t seconds reaches variance σ²·t/T
//! in time T by averaging T/t runs, so σ²·t is its cost at equal time; [`efficiency`] is that
//! product, to be compared as a ratio to the baseline's. Wall time is what a user waits; on a
//! machine shared with other work it is noisy, so the process's CPU time (all threads, lavapipe's
//! included; Linux only) is measured beside it — on a CPU device it is the work an estimate costs.
//!
//! [`choose_strategy`] is the same measurement made small: a pilot of a few low-spp image gradients
//! per candidate strategy, interleaved, that picks the most efficient one (`--strategy auto`).

use std::time::Instant;

use crate::adaptive::{AdaptiveEstimator, PixelSampling};
use crate::backend::Backend;
use crate::error::{Error, Result};
use crate::gpu::renderer::GradMode;
use crate::image::Image;
use crate::integrator::{PlacementMis, RenderOptions, Strategy, check_spp_primal};
use crate::loss::{Loss, loss_and_adjoint};
use crate::params::ParamId;

/// Seed offset of the render whose adjoint image fixes the pixel weights of adaptive loss-gradient
/// runs (the reference's `variance_loss.py` uses seed 2000); it is rendered under the reference
/// key ([`Backend::render_reference`]), so no run's pass 1 shares its paths.
pub const WEIGHTS_SEED_OFFSET: u32 = 2000;

/// Running mean and sum of squared deviations of many values at once (Welford, in f64).
#[derive(Clone, Debug)]
pub struct Moments {
    count: u32,
    mean: Vec<f64>,
    m2: Vec<f64>,
}

impl Moments {
    /// Moments of `len` values, none added yet.
    pub fn new(len: usize) -> Moments {
        Moments { count: 0, mean: vec![0.0; len], m2: vec![0.0; len] }
    }

    /// Adds one sample of every value.
    ///
    /// # Panics
    /// If `sample` does not have the length given to [`Moments::new`] (a caller bug).
    pub fn add(&mut self, sample: impl IntoIterator<Item = f64>) {
        self.count += 1;
        let n = f64::from(self.count);
        let mut len = 0;
        for ((mean, m2), x) in self.mean.iter_mut().zip(&mut self.m2).zip(sample) {
            let delta = x - *mean;
            *mean += delta / n;
            *m2 += delta * (x - *mean);
            len += 1;
        }
        assert_eq!(len, self.mean.len(), "a sample must have one value per accumulated value");
    }

    /// Number of samples added.
    pub fn count(&self) -> u32 {
        self.count
    }

    /// The mean of every value.
    pub fn mean(&self) -> &[f64] {
        &self.mean
    }

    /// The sample variance (divisor count − 1) of every value; zeros before two samples.
    pub fn variance(&self) -> Vec<f64> {
        let d = f64::from(self.count.saturating_sub(1).max(1));
        let scale = if self.count < 2 { 0.0 } else { 1.0 / d };
        self.m2.iter().map(|m| m * scale).collect()
    }
}

/// Clock ticks per second of `/proc/self/stat`'s CPU times (Linux's USER_HZ, fixed for user space).
const USER_HZ: f64 = 100.0;

/// CPU time this process has used so far, user and system, over all its threads: fields 14 and
/// 15 of `/proc/self/stat`. `None` where there is no such file (not Linux).
pub fn process_cpu_seconds() -> Option<f64> {
    cpu_seconds_from_stat(&std::fs::read_to_string("/proc/self/stat").ok()?)
}

/// User + system CPU seconds from the text of a `/proc/PID/stat` file.
fn cpu_seconds_from_stat(stat: &str) -> Option<f64> {
    // The command name (field 2) is parenthesised and may hold spaces and ')': count from the last.
    let rest = &stat[stat.rfind(')')? + 1..];
    let mut fields = rest.split_whitespace().skip(11);
    let user: f64 = fields.next()?.parse().ok()?;
    let system: f64 = fields.next()?.parse().ok()?;
    Some((user + system) / USER_HZ)
}

/// Wall and CPU time of a run of estimates.
struct Stopwatch {
    wall: f64,
    cpu: Option<f64>,
}

impl Stopwatch {
    fn new() -> Stopwatch {
        Stopwatch { wall: 0.0, cpu: Some(0.0) }
    }

    /// Runs `f`, adding its wall and CPU time.
    fn time<T>(&mut self, f: impl FnOnce() -> Result<T>) -> Result<T> {
        let (start, cpu) = (Instant::now(), process_cpu_seconds());
        let value = f()?;
        self.wall += start.elapsed().as_secs_f64();
        self.cpu = match (self.cpu, cpu, process_cpu_seconds()) {
            (Some(sum), Some(a), Some(b)) => Some(sum + (b - a)),
            _ => None,
        };
        Ok(value)
    }
}

/// Variance × time per estimate: the variance an estimator reaches in unit time is this divided by
/// the time (see the [module docs](self)).
pub fn efficiency(variance: f64, seconds_per_estimate: f64) -> f64 {
    variance * seconds_per_estimate
}

/// The result of [`image_gradient_variance`] for one technique.
#[derive(Clone, Debug)]
pub struct ImageGradientVariance {
    /// Mean ∂I/∂θ over the runs.
    pub mean: Image,
    /// Per pixel and channel, the sample variance of ∂I/∂θ over the runs.
    pub variance: Image,
    /// The variance averaged over pixels and channels (the paper's Figures 5–7 compare these).
    pub mean_variance: f64,
    /// Mean wall time of one estimate (one forward-mode image gradient), in seconds.
    pub seconds_per_estimate: f64,
    /// Mean CPU time of the process per estimate, in seconds (see [`process_cpu_seconds`]).
    pub cpu_seconds_per_estimate: Option<f64>,
}

/// Checks the run count shared by both protocols.
fn check_runs(runs: u32) -> Result<()> {
    if runs < 2 {
        return Err(Error::InvalidArgument {
            parameter: "variance::runs".into(),
            message: format!("{runs}: a variance needs at least 2 runs"),
        });
    }
    Ok(())
}

/// The per-pixel variance of the forward-mode image gradient ∂I/∂`param` (tangent 1 on every value
/// of the parameter, as [`Backend::image_gradient`]) over `runs` estimates with seeds
/// `options.seed + i`, all with `options` (its strategy, NEE and spp). `progress` is called after
/// every run with the number done.
///
/// ```no_run
/// use pathgrad::gpu::{Context, ContextDesc, Renderer};
/// use pathgrad::integrator::{PlacementMis, RenderOptions, Strategy};
///
/// let scene = pathgrad::scene::builtin::load("blend")?;
/// let ctx = Context::new(&ContextDesc::default())?;
/// let mut renderer = Renderer::new(&ctx, &scene)?;
/// let bsdf = RenderOptions { spp: 2, ..RenderOptions::for_scene(&scene) };
/// let weight = scene.params.find("object.weight.value").unwrap();
/// let diff = RenderOptions { strategy: Strategy::Diff { target: weight, q: 0.5, placement: PlacementMis::Balance }, ..bsdf };
/// let param = "object.weight.value";
/// let a = pathgrad::variance::image_gradient_variance(&mut renderer, &bsdf, param, 32, &mut |_| {})?;
/// let b = pathgrad::variance::image_gradient_variance(&mut renderer, &diff, param, 32, &mut |_| {})?;
/// println!("diff/bsdf variance: {:.3}", b.mean_variance / a.mean_variance);
/// # Ok::<(), pathgrad::Error>(())
/// ```
///
/// # Errors
/// [`Error::InvalidArgument`] for fewer than 2 runs or an unknown parameter; as
/// [`Backend::image_gradient`].
pub fn image_gradient_variance(
    backend: &mut dyn Backend,
    options: &RenderOptions,
    param: &str,
    runs: u32,
    progress: &mut dyn FnMut(u32),
) -> Result<ImageGradientVariance> {
    check_runs(runs)?;
    options.validate()?;
    let mut moments = Moments::new(options.width as usize * options.height as usize * 3);
    let mut clock = Stopwatch::new();
    for i in 0..runs {
        let run = RenderOptions { seed: options.seed.wrapping_add(i), ..*options };
        let gradient = clock.time(|| backend.image_gradient(&run, param))?;
        moments.add(gradient.as_slice().iter().map(|&v| f64::from(v)));
        progress(i + 1);
    }
    let variance = moments.variance();
    let mean_variance = variance.iter().sum::<f64>() / variance.len() as f64;
    let to_image =
        |values: &[f64]| Image::from_rgb(options.width, options.height, values.iter().map(|&v| v as f32).collect());
    Ok(ImageGradientVariance {
        mean: to_image(moments.mean())?,
        variance: to_image(&variance)?,
        mean_variance,
        seconds_per_estimate: clock.wall / f64::from(runs),
        cpu_seconds_per_estimate: clock.cpu.map(|c| c / f64::from(runs)),
    })
}

/// How the loss-gradient runs of [`loss_gradient_variance`] are set up.
#[derive(Clone, Debug)]
pub struct LossGradientSetup<'a> {
    /// The image the loss compares against.
    pub target: &'a Image,
    /// The loss.
    pub loss: Loss,
    /// Samples per pixel of pass 1 (the render that gives the loss and its adjoint image); pass 1
    /// always uses plain BSDF sampling with next-event estimation.
    pub spp_primal: u32,
    /// `Some(estimator)`: the gradient pass draws its pixels adaptively from weights fixed once, from
    /// the adjoint image of a render at seed `seed + WEIGHTS_SEED_OFFSET` with `spp_primal` (the
    /// Tables 1–2 protocol; [`Backend::render_reference`]); `None`: every pixel gets spp_grad
    /// samples.
    pub adaptive: Option<AdaptiveEstimator>,
    /// The parameters whose gradient is recorded.
    pub params: &'a [ParamId],
}

/// The result of [`loss_gradient_variance`] for one technique.
#[derive(Clone, Debug)]
pub struct LossGradientVariance {
    /// Per recorded value (the values of the recorded parameters in order), the mean gradient.
    pub mean: Vec<f64>,
    /// Per recorded value, the sample variance of the gradient.
    pub variance: Vec<f64>,
    /// The sum of [`Self::variance`]: the trace of the gradient's covariance (for one scalar
    /// parameter, its variance — the figure of Tables 1–2).
    pub total_variance: f64,
    /// Mean loss of pass 1 over the runs.
    pub mean_loss: f64,
    /// Mean wall time of one estimate (pass 1, loss, gradient pass), in seconds; the one render that
    /// fixes adaptive weights is not counted (Algorithm 2 gets its weights from pass 1 for free).
    pub seconds_per_estimate: f64,
    /// Mean CPU time of the process per estimate, in seconds (see [`process_cpu_seconds`]).
    pub cpu_seconds_per_estimate: Option<f64>,
}

/// The variance of the loss gradient over `runs` estimates with seeds `options.seed + i`: pass 1 at
/// `setup.spp_primal` spp, the loss against `setup.target` and its adjoint image, then the fused
/// gradient pass with `options` (its spp is spp_grad; its strategy and NEE apply), uniformly or with
/// adaptive pixel sampling from fixed weights (ALGORITHMS.md §7.4, Tables 1–2).
///
/// # Errors
/// [`Error::InvalidArgument`] for fewer than 2 runs, `spp_primal` = 0, no recorded parameter or a
/// target of the wrong size; as [`Backend::render`] and [`Backend::backward`].
pub fn loss_gradient_variance(
    backend: &mut dyn Backend,
    options: &RenderOptions,
    setup: &LossGradientSetup,
    runs: u32,
    progress: &mut dyn FnMut(u32),
) -> Result<LossGradientVariance> {
    check_runs(runs)?;
    options.validate()?;
    let pass1 = options.loss_pass(setup.spp_primal)?;
    if setup.params.is_empty() {
        return Err(Error::InvalidArgument {
            parameter: "LossGradientSetup::params".into(),
            message: "no parameter to record".into(),
        });
    }
    let sampling = match setup.adaptive {
        None => None,
        Some(estimator) => {
            let seed = options.seed.wrapping_add(WEIGHTS_SEED_OFFSET);
            let image = backend.render_reference(&RenderOptions { seed, ..pass1 })?;
            let (_, adjoint) = loss_and_adjoint(&image, setup.target, setup.loss)?;
            Some(PixelSampling::from_adjoint(&adjoint, estimator)?)
        }
    };
    let entries: Vec<_> = setup.params.iter().map(|&id| backend.scene().params.entry(id).clone()).collect();
    let len: usize = entries.iter().map(|e| e.len as usize).sum();
    let mut moments = Moments::new(len);
    let (mut clock, mut loss_sum) = (Stopwatch::new(), 0.0);
    for i in 0..runs {
        let seed = options.seed.wrapping_add(i);
        let (loss, gradients) = clock.time(|| {
            let run = RenderOptions { seed, ..*options };
            let (loss, adjoint) = backend.loss_image(&run, setup.spp_primal, setup.target, setup.loss)?;
            let gradients = match &sampling {
                None => backend.backward(&run, &adjoint, GradMode::Float)?,
                Some(sampling) => backend.backward_adaptive(&run, &adjoint, sampling, GradMode::Float)?,
            };
            Ok((loss, gradients))
        })?;
        loss_sum += loss;
        let values = gradients.values();
        moments.add(
            entries.iter().flat_map(|e| &values[e.offset as usize..(e.offset + e.len) as usize]).map(|&v| f64::from(v)),
        );
        progress(i + 1);
    }
    let variance = moments.variance();
    Ok(LossGradientVariance {
        mean: moments.mean().to_vec(),
        total_variance: variance.iter().sum(),
        variance,
        mean_loss: loss_sum / f64::from(runs),
        seconds_per_estimate: clock.wall / f64::from(runs),
        cpu_seconds_per_estimate: clock.cpu.map(|c| c / f64::from(runs)),
    })
}

/// The probabilities of the differential technique that [`choose_strategy`] tries.
pub const PILOT_QS: [f32; 3] = [0.5, 0.75, 0.9];

/// Pilot times within this fraction of the fastest candidate's count as equal to it: on a shared
/// machine one run's timing varies by about this much, and the cost differences between the
/// candidates (the differential strategy is about a tenth slower per sample) are of that order, so
/// within it the choice goes by variance alone — and the same seed then picks the same strategy.
pub const PILOT_TIME_TIE: f64 = 0.15;

/// A later candidate replaces an earlier pick only if its variance × time is below the pick's by
/// more than this fraction: a pilot of a few runs cannot resolve smaller differences, and candidates
/// that sample alike (a blend at weight ½, where the differential density is the BSDF's) then keep
/// the first of them instead of a winner by rounding.
pub const PILOT_MARGIN: f64 = 0.05;

/// How much [`choose_strategy`] spends: `runs` image gradients of `spp` samples per pixel per
/// candidate, at the request's resolution.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PilotBudget {
    /// Estimates per candidate (at least 2: a variance needs two).
    pub runs: u32,
    /// Samples per pixel of each estimate.
    pub spp: u32,
}

impl Default for PilotBudget {
    /// 4 runs of 1 spp per candidate: 16 one-sample image gradients for four candidates.
    fn default() -> PilotBudget {
        PilotBudget { runs: 4, spp: 1 }
    }
}

/// What the pilot measured for one candidate strategy.
#[derive(Clone, Debug)]
pub struct PilotCandidate {
    /// The candidate.
    pub strategy: Strategy,
    /// Per-pixel variance of ∂I/∂θ averaged over pixels and channels, at the pilot's spp; with a
    /// [`PilotLoss`], the summed variance of the loss gradient's values.
    pub variance: f64,
    /// Wall time of its fastest estimate, in seconds (the least disturbed by other work); with a
    /// [`PilotLoss`], plus the fastest pass 1.
    pub seconds_per_estimate: f64,
    /// Variance × time, with times within [`PILOT_TIME_TIE`] of the fastest taken as the fastest's:
    /// the figure the choice minimises (by more than [`PILOT_MARGIN`] to displace an earlier one).
    pub efficiency: f64,
}

/// With a loss, [`choose_strategy`] measures the variance of the loss gradient (pass 1 at
/// `spp_primal`, shared by the candidates, then each candidate's gradient pass with uniform pixel
/// sampling) instead of the image gradient's.
#[derive(Clone, Copy, Debug)]
pub struct PilotLoss<'a> {
    /// The image the loss compares against.
    pub target: &'a Image,
    /// The loss.
    pub loss: Loss,
    /// Samples per pixel of pass 1.
    pub spp_primal: u32,
    /// The parameters whose gradient is measured (the trace of their covariance is the variance).
    pub params: &'a [ParamId],
}

/// The result of [`choose_strategy`].
#[derive(Clone, Debug)]
pub struct StrategyChoice {
    /// The most efficient candidate.
    pub strategy: Strategy,
    /// Every candidate, in the order tried (`bsdf` first, then q ascending; within
    /// [`PILOT_MARGIN`] the earlier one is kept).
    pub candidates: Vec<PilotCandidate>,
    /// Wall time of the whole pilot (warm-up included), in seconds.
    pub seconds: f64,
    /// Of which the warm-up: the first dispatch of each kernel, where a driver compiles it (on
    /// lavapipe seconds, once per scene and kernel; any run with that kernel pays it once).
    pub warm_up_seconds: f64,
    /// CPU time of the process during the pilot, in seconds (see [`process_cpu_seconds`]).
    pub cpu_seconds: Option<f64>,
    /// Gradient passes and pass-1 renders (warm-up included).
    pub renders: u32,
    /// Samples rendered in all, per pixel, gradient passes and pass-1 renders together.
    pub samples_per_pixel: u64,
}

/// Picks, for the image gradient ∂I/∂`param` under `options` (resolution, NEE, depth, seed), the
/// strategy with the least variance × time: plain `bsdf` and, where some material has a
/// differential sampler for `param`, `diff` driven by `param` at each q of [`PILOT_QS`] with its
/// placements weighted by `placement`. Each candidate renders `budget.runs` image gradients of
/// `budget.spp` spp with seeds `options.seed + i`, interleaved run by run so that a slow spell of
/// the machine falls on all of them; kernels are warmed up first, untimed. Variances are those of
/// [`image_gradient_variance`], times those of each candidate's fastest estimate (the `diff`
/// candidates, one kernel, share the fastest of theirs); times within
/// [`PILOT_TIME_TIE`] of the fastest count as equal, and a candidate displaces an earlier one only
/// if better by more than [`PILOT_MARGIN`], so the same seed picks the same strategy. With `loss`,
/// the figure is the loss gradient's variance instead (see [`PilotLoss`]): what an optimisation
/// pays for, which the image gradient's variance need not predict.
///
/// ```no_run
/// use pathgrad::gpu::{Context, ContextDesc, Renderer};
/// use pathgrad::integrator::{PlacementMis, RenderOptions};
/// use pathgrad::variance::{PilotBudget, choose_strategy};
///
/// let scene = pathgrad::scene::builtin::load("blend")?;
/// let ctx = Context::new(&ContextDesc::default())?;
/// let mut renderer = Renderer::new(&ctx, &scene)?;
/// let opts = RenderOptions { width: 64, height: 64, ..RenderOptions::for_scene(&scene) };
/// let choice =
///     choose_strategy(&mut renderer, &opts, "object.weight.value", PlacementMis::Balance, PilotBudget::default(), None)?;
/// println!("picked {:?} in {:.2} s", choice.strategy, choice.seconds);
/// # Ok::<(), pathgrad::Error>(())
/// ```
///
/// # Errors
/// [`Error::InvalidArgument`] naming `PilotBudget::runs` (below 2) or `PilotBudget::spp` (0), an
/// unknown parameter, a parameter the differential sampler refuses by name
/// ([`Strategy::from_name`]), `spp_primal` = 0 or no parameter in `loss`; as
/// [`Backend::image_gradient`], [`Backend::loss_image`] and [`Backend::backward`].
pub fn choose_strategy(
    backend: &mut dyn Backend,
    options: &RenderOptions,
    param: &str,
    placement: PlacementMis,
    budget: PilotBudget,
    loss: Option<&PilotLoss>,
) -> Result<StrategyChoice> {
    if budget.runs < 2 {
        return Err(Error::InvalidArgument {
            parameter: "PilotBudget::runs".into(),
            message: format!("{}: a variance needs at least 2 runs", budget.runs),
        });
    }
    if budget.spp == 0 {
        return Err(Error::InvalidArgument {
            parameter: "PilotBudget::spp".into(),
            message: "must be at least 1".into(),
        });
    }
    let scene = backend.scene();
    let target = scene.params.find(param).ok_or_else(|| Error::InvalidArgument {
        parameter: param.to_string(),
        message: "no such parameter to choose a strategy for (see `pathgrad params SCENE`)".into(),
    })?;
    let mut strategies = vec![Strategy::Bsdf];
    if Strategy::has_differential_sampler(scene, target) {
        for q in PILOT_QS {
            strategies.push(Strategy::from_name(scene, "diff", q, param)?.with_placement(placement));
        }
    }
    let base = RenderOptions { spp: budget.spp, ..*options };
    base.validate()?;
    let entries: Vec<_> = match loss {
        None => Vec::new(),
        Some(l) => {
            check_spp_primal(l.spp_primal)?;
            if l.params.is_empty() {
                return Err(Error::InvalidArgument {
                    parameter: "PilotLoss::params".into(),
                    message: "no parameter to measure".into(),
                });
            }
            l.params.iter().map(|&id| scene.params.entry(id).clone()).collect()
        }
    };
    let (start, cpu_start) = (Instant::now(), process_cpu_seconds());
    let (mut renders, mut samples) = (0u32, 0u64);
    // One estimate: the image gradient, or the loss gradient's values from pass 1's adjoint.
    let mut estimate = |backend: &mut dyn Backend, run: &RenderOptions, adjoint: Option<&Image>| -> Result<Vec<f64>> {
        renders += 1;
        samples += u64::from(run.spp);
        Ok(match adjoint {
            None => backend.image_gradient(run, param)?.as_slice().iter().map(|&v| f64::from(v)).collect(),
            Some(adjoint) => {
                let g = backend.backward(run, adjoint, GradMode::Float)?;
                let values = g.values();
                entries
                    .iter()
                    .flat_map(|e| &values[e.offset as usize..(e.offset + e.len) as usize])
                    .map(|&v| f64::from(v))
                    .collect()
            }
        })
    };
    // Pass 1 of run `seed` (loss mode): the adjoint image all candidates share.
    let pass1 = |backend: &mut dyn Backend, run: &RenderOptions, renders: &mut u32, samples: &mut u64| {
        loss.map(|l| {
            *renders += 1;
            *samples += u64::from(l.spp_primal);
            backend.loss_image(run, l.spp_primal, l.target, l.loss).map(|(_, adjoint)| adjoint)
        })
        .transpose()
    };
    // Warm-up, untimed: lavapipe compiles a kernel at its first dispatch; the diff candidates
    // differ only in uniforms, so one warm-up serves them all.
    let (mut pass1_renders, mut pass1_samples) = (0u32, 0u64);
    let warm = RenderOptions { spp: 1, ..base };
    let adjoint = pass1(backend, &warm, &mut pass1_renders, &mut pass1_samples)?;
    for strategy in strategies.iter().take(2) {
        estimate(backend, &RenderOptions { strategy: *strategy, ..warm }, adjoint.as_ref())?;
    }
    let warm_up_seconds = start.elapsed().as_secs_f64();
    let mut moments: Vec<Option<Moments>> = strategies.iter().map(|_| None).collect();
    let mut fastest = vec![f64::INFINITY; strategies.len()];
    let mut fastest_pass1 = if loss.is_some() { f64::INFINITY } else { 0.0 };
    for i in 0..budget.runs {
        let seeded = RenderOptions { seed: base.seed.wrapping_add(i), ..base };
        let mut clock = Stopwatch::new();
        let adjoint = clock.time(|| pass1(backend, &seeded, &mut pass1_renders, &mut pass1_samples))?;
        if loss.is_some() {
            fastest_pass1 = fastest_pass1.min(clock.wall);
        }
        for (k, strategy) in strategies.iter().enumerate() {
            let run = RenderOptions { strategy: *strategy, ..seeded };
            let mut clock = Stopwatch::new();
            let values = clock.time(|| estimate(backend, &run, adjoint.as_ref()))?;
            fastest[k] = fastest[k].min(clock.wall);
            moments[k].get_or_insert_with(|| Moments::new(values.len())).add(values);
        }
    }
    let measured: Vec<(Strategy, f64, f64)> = strategies
        .iter()
        .zip(&moments)
        .zip(&fastest)
        .map(|((s, m), &t)| {
            let variance = m.as_ref().expect("at least 2 runs").variance();
            let figure = variance.iter().sum::<f64>() / if loss.is_some() { 1.0 } else { variance.len() as f64 };
            (*s, figure, t + fastest_pass1)
        })
        .collect();
    let candidates = pilot_efficiencies(&measured);
    let best = pilot_pick(&candidates);
    let cpu_seconds = match (cpu_start, process_cpu_seconds()) {
        (Some(a), Some(b)) => Some(b - a),
        _ => None,
    };
    Ok(StrategyChoice {
        strategy: candidates[best].strategy,
        seconds: start.elapsed().as_secs_f64(),
        warm_up_seconds,
        cpu_seconds,
        renders: renders + pass1_renders,
        samples_per_pixel: samples + pass1_samples,
        candidates,
    })
}

/// Each candidate's (strategy, variance, seconds per estimate) with its efficiency: variance × time.
/// The `diff` candidates run one kernel that differs only in its uniforms (q), so they share one
/// time, the fastest of theirs: their choice goes by variance alone, which the seed fixes, and a
/// slow spell of the machine during one of them cannot pick another q. A time within
/// [`PILOT_TIME_TIE`] of the fastest is then taken as the fastest.
fn pilot_efficiencies(measured: &[(Strategy, f64, f64)]) -> Vec<PilotCandidate> {
    let is_diff = |s: &Strategy| matches!(s, Strategy::Diff { .. });
    let diff_time = measured.iter().filter(|m| is_diff(&m.0)).map(|m| m.2).fold(f64::INFINITY, f64::min);
    let shared = |m: &(Strategy, f64, f64)| if is_diff(&m.0) { diff_time } else { m.2 };
    let fastest = measured.iter().map(shared).fold(f64::INFINITY, f64::min);
    measured
        .iter()
        .map(|m| {
            let &(strategy, variance, seconds) = m;
            let seconds_shared = shared(m);
            let time = if seconds_shared <= fastest * (1.0 + PILOT_TIME_TIE) { fastest } else { seconds_shared };
            // A NaN variance (a non-finite gradient) must never win.
            let efficiency = if variance.is_finite() { efficiency(variance, time) } else { f64::INFINITY };
            PilotCandidate { strategy, variance, seconds_per_estimate: seconds, efficiency }
        })
        .collect()
}

/// The index of the candidate [`choose_strategy`] picks: the first, displaced by each later one
/// whose efficiency is below the pick's by more than [`PILOT_MARGIN`].
fn pilot_pick(candidates: &[PilotCandidate]) -> usize {
    (1..candidates.len()).fold(0, |best, k| {
        if candidates[k].efficiency < (1.0 - PILOT_MARGIN) * candidates[best].efficiency { k } else { best }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pilot_times_within_the_tie_count_as_equal() {
        let diff = |q| Strategy::Diff { target: ParamId(0), q, placement: PlacementMis::Balance };
        // 10 % slower: the time counts as the fastest's, the variance decides.
        let c = pilot_efficiencies(&[(Strategy::Bsdf, 2.0, 1.0), (diff(0.5), 1.5, 1.1)]);
        assert_eq!(c[1].efficiency, 1.5);
        assert_eq!(c[1].seconds_per_estimate, 1.1);
        // Twice as slow: the time counts, and the lower variance no longer pays.
        let c = pilot_efficiencies(&[(Strategy::Bsdf, 2.0, 1.0), (diff(0.5), 1.5, 2.0), (diff(0.9), f64::NAN, 2.0)]);
        assert_eq!(c[1].efficiency, 3.0);
        assert_eq!(c[0].efficiency, 2.0);
        assert_eq!(c[2].efficiency, f64::INFINITY);
        assert_eq!(pilot_pick(&c), 0);
        // The diff candidates share their fastest time: a slow spell during one q (here 3× on
        // q = 0.5) does not change which q wins; its own time is still reported.
        let c = pilot_efficiencies(&[(Strategy::Bsdf, 2.0, 1.0), (diff(0.5), 1.5, 3.0), (diff(0.9), 1.5, 1.0)]);
        assert_eq!((c[1].efficiency, c[2].efficiency, c[1].seconds_per_estimate), (1.5, 1.5, 3.0));
        assert_eq!(pilot_pick(&c), 1);
        // Within the margin the earlier candidate stays; beyond it the later one wins.
        let c = pilot_efficiencies(&[(Strategy::Bsdf, 1.0, 1.0), (diff(0.5), 0.96, 1.0), (diff(0.9), 0.9, 1.0)]);
        assert_eq!(pilot_pick(&c[..2]), 0);
        assert_eq!(pilot_pick(&c), 2);
    }

    #[test]
    fn moments_match_the_two_pass_formulas() {
        let samples = [[1.0, -2.0], [4.0, 0.5], [2.5, 3.0], [-1.0, 1e6]];
        let mut m = Moments::new(2);
        for s in samples {
            m.add(s);
        }
        for c in 0..2 {
            let mean = samples.iter().map(|s| s[c]).sum::<f64>() / 4.0;
            let var = samples.iter().map(|s| (s[c] - mean).powi(2)).sum::<f64>() / 3.0;
            assert!((m.mean()[c] - mean).abs() <= 1e-12 * mean.abs().max(1.0));
            assert!((m.variance()[c] - var).abs() <= 1e-12 * var, "{} vs {var}", m.variance()[c]);
        }
        assert_eq!(m.count(), 4);
    }

    #[test]
    fn moments_of_one_sample_have_no_variance() {
        let mut m = Moments::new(1);
        m.add([3.0]);
        assert_eq!(m.variance(), vec![0.0]);
    }

    #[test]
    fn cpu_time_is_read_from_fields_14_and_15() {
        // A command name with a space and a parenthesis; utime 250 and stime 17 ticks.
        let stat = "4242 (my (odd) cmd) R 1 4242 4242 0 -1 4194304 500 0 0 0 250 17 0 0 20 0 3 0 100 1000 50";
        assert_eq!(cpu_seconds_from_stat(stat), Some(2.67));
        assert_eq!(cpu_seconds_from_stat("4242 (cut"), None);
        assert_eq!(cpu_seconds_from_stat("4242 (x) R 1 2"), None);
    }

    #[test]
    fn process_cpu_time_grows_with_work() {
        // Other tests' threads in this process can only add to the difference.
        let before = process_cpu_seconds().expect("Linux has /proc/self/stat");
        let start = Instant::now();
        let mut x = 0u64;
        while start.elapsed().as_secs_f64() < 0.3 {
            x = std::hint::black_box(x.wrapping_mul(6364136223846793005).wrapping_add(1));
        }
        let worked = process_cpu_seconds().unwrap() - before;
        // 0.3 s of spinning; ticks are 10 ms and another process may hold the core part of the time.
        assert!(worked > 0.05, "0.3 s of spinning showed {worked} s of CPU");
    }

    #[test]
    fn efficiency_is_variance_times_time() {
        // Twice the variance at half the time is the same cost at equal time.
        assert_eq!(efficiency(2.0, 0.5), efficiency(1.0, 1.0));
    }
}

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

use std::time::Instant;

use crate::adaptive::{AdaptiveEstimator, PixelSampling};
use crate::backend::Backend;
use crate::error::{Error, Result};
use crate::gpu::renderer::GradMode;
use crate::image::Image;
use crate::integrator::RenderOptions;
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
/// use pathgrad::integrator::{RenderOptions, Strategy};
///
/// let scene = pathgrad::scene::builtin::load("blend")?;
/// let ctx = Context::new(&ContextDesc::default())?;
/// let mut renderer = Renderer::new(&ctx, &scene)?;
/// let bsdf = RenderOptions { spp: 2, ..RenderOptions::for_scene(&scene) };
/// let weight = scene.params.find("object.weight.value").unwrap();
/// let diff = RenderOptions { strategy: Strategy::Diff { target: weight, q: 0.5 }, ..bsdf };
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

#[cfg(test)]
mod tests {
    use super::*;

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

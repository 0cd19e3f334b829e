//! Recursive control variates across optimisation iterations (Nicolet et al. 2023): the per-pixel running estimate F_i = v_i·(F_{i−1} − H_i) + G_i of the loss image.
//!
//! Iteration i renders pass 1 twice with the same seed (the same random numbers): G_i at the
//! current parameters θ_i and H_i at the previous ones θ_{i−1}. F_{i−1} and H_i estimate the same
//! image, so F_{i−1} − H_i is a zero-mean correction that cancels most of G_i's noise when the
//! parameters moved little; the weight v_i ∈ [0, 1] per pixel and channel comes from running
//! estimates of Var H, Var G and Cov(H, G) (exponential moving averages with decays β₁ for the
//! means and β₂ for the (co)variances, bias-corrected as Adam's moments are) and a running
//! estimate of Var F. This is the authors' `MetaIntegrator` (rgl-epfl/recursive_control_variates,
//! `plugins/metaintegrator.py`, method `cv_pss`, `pre_update = False`, warm-up 1) formula for
//! formula; `docs/gradients.md` states it. The state is image-sized: nothing per path, nothing
//! that grows with spp or depth.

use crate::error::{Error, Result};
use crate::image::Image;

/// β₁ of the running means of H and G (the authors' default).
pub const DEFAULT_BETA1: f64 = 0.9;
/// β₂ of the running variances and covariance (the authors' default).
pub const DEFAULT_BETA2: f64 = 0.999;
/// Steps after the first during which the weight stays 0 (the authors' `warmup`): the weights are
/// first computed at step `WARMUP + 1`, from statistics of the steps before it.
pub const WARMUP: u64 = 1;

/// The decays of the control variates' running statistics.
///
/// ```
/// use pathgrad::optim::ControlVariateOptions;
/// let cv = ControlVariateOptions::default();
/// assert_eq!((cv.beta1, cv.beta2), (0.9, 0.999));
/// assert!(ControlVariateOptions { beta2: 1.0, ..cv }.validate().is_err());
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ControlVariateOptions {
    /// Decay of the running means of H and G, in [0, 1).
    pub beta1: f64,
    /// Decay of the running variances of H and G and of their covariance, in [0, 1).
    pub beta2: f64,
}

impl Default for ControlVariateOptions {
    fn default() -> ControlVariateOptions {
        ControlVariateOptions { beta1: DEFAULT_BETA1, beta2: DEFAULT_BETA2 }
    }
}

impl ControlVariateOptions {
    /// Checks ranges.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `ControlVariateOptions::beta1` or `beta2` for a decay
    /// outside [0, 1).
    pub fn validate(&self) -> Result<()> {
        for (name, beta) in [("ControlVariateOptions::beta1", self.beta1), ("ControlVariateOptions::beta2", self.beta2)]
        {
            if !(0.0..1.0).contains(&beta) {
                return Err(Error::InvalidArgument {
                    parameter: name.into(),
                    message: format!("{beta} is not in [0, 1)"),
                });
            }
        }
        Ok(())
    }
}

/// A running estimate F_i = v_i·(F_{i−1} − H_i) + G_i of a vector of values and the statistics
/// its weights come from, one of each per value: the recursion shared by the loss image's control
/// variates ([`ControlVariateState`]) and the gradient's reuse across iterations
/// ([`crate::optim::gradient_reuse`]). Every array has the same length.
#[derive(Clone, Debug, PartialEq)]
pub struct RunningEstimate {
    /// Steps combined so far (the authors' `it`); 0: the next step's estimate is its G.
    pub steps: u64,
    /// Updates of the running statistics (the authors' `n`): one per step after the first.
    pub updates: u64,
    /// The running estimate F.
    pub estimate: Vec<f64>,
    /// The last weight v.
    pub weight: Vec<f64>,
    /// The running estimate of Var F (the authors' `v_n`).
    pub estimate_variance: Vec<f64>,
    /// Running mean of H, bias-corrected (m̂ = m/(1 − β₁ⁿ) of the authors' m).
    pub mean_h: Vec<f64>,
    /// Running mean of G, bias-corrected.
    pub mean_g: Vec<f64>,
    /// Running variance of H (not bias-corrected).
    pub var_h: Vec<f64>,
    /// Running variance of G (not bias-corrected).
    pub var_g: Vec<f64>,
    /// Running covariance of H and G (not bias-corrected).
    pub cov: Vec<f64>,
}

impl RunningEstimate {
    /// The state before the first step, for `len` values.
    pub fn new(len: usize) -> RunningEstimate {
        RunningEstimate {
            steps: 0,
            updates: 0,
            estimate: vec![0.0; len],
            weight: vec![0.0; len],
            estimate_variance: vec![0.0; len],
            mean_h: vec![0.0; len],
            mean_g: vec![0.0; len],
            var_h: vec![0.0; len],
            var_g: vec![0.0; len],
            cov: vec![0.0; len],
        }
    }

    /// The number of values.
    pub fn len(&self) -> usize {
        self.estimate.len()
    }

    /// Whether it holds no values.
    pub fn is_empty(&self) -> bool {
        self.estimate.is_empty()
    }

    /// The arrays, in a fixed order (for saving and loading a state).
    pub fn arrays(&self) -> [&Vec<f64>; 8] {
        [
            &self.estimate,
            &self.weight,
            &self.estimate_variance,
            &self.mean_h,
            &self.mean_g,
            &self.var_h,
            &self.var_g,
            &self.cov,
        ]
    }

    /// The arrays, mutably, in the order of [`RunningEstimate::arrays`].
    pub fn arrays_mut(&mut self) -> [&mut Vec<f64>; 8] {
        [
            &mut self.estimate,
            &mut self.weight,
            &mut self.estimate_variance,
            &mut self.mean_h,
            &mut self.mean_g,
            &mut self.var_h,
            &mut self.var_g,
            &mut self.cov,
        ]
    }

    /// Checks that every array holds `len` values and the counts are consistent (a state read
    /// back from a file).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `what`.
    pub fn check(&self, len: usize, what: &str) -> Result<()> {
        let bad = |m: String| Err(Error::InvalidArgument { parameter: what.into(), message: m });
        if self.arrays().iter().any(|a| a.len() != len) {
            return bad(format!("arrays are not of {len} values"));
        }
        if self.updates > self.steps {
            return bad(format!("{} updates in {} steps", self.updates, self.steps));
        }
        Ok(())
    }

    /// One step: combines this iteration's `g` (G_i) and `h` (H_i: the same random numbers at
    /// the previous parameters; `None` only on the first step) into the new estimate F_i,
    /// updates the statistics, and returns F_i.
    ///
    /// In order, as the authors' code: if `steps > WARMUP`, the weight is recomputed per value
    /// from the bias-corrected statistics of the steps before this one,
    /// V ← v²(V + Var H) + Var G − 2v·Cov(H, G), v ← Cov(H, G)/(Var H + V), NaN or ±∞ → 0,
    /// clamped to [0, 1]; then F ← v(F − H) + G (F ← G where v = 0); then, after the first step,
    /// the statistics take (H, G).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `G` or `H` for another number of values than the
    /// state's, or no `h` after the first step.
    ///
    /// ```
    /// use pathgrad::optim::{ControlVariateOptions, RunningEstimate};
    /// let mut state = RunningEstimate::new(2);
    /// let options = ControlVariateOptions::default();
    /// // The first step's estimate is G itself.
    /// assert_eq!(state.step(&options, &[1.0, 2.0], None)?, &[1.0, 2.0]);
    /// # Ok::<(), pathgrad::Error>(())
    /// ```
    pub fn step(&mut self, options: &ControlVariateOptions, g: &[f64], h: Option<&[f64]>) -> Result<&[f64]> {
        options.validate()?;
        let bad = |p: &str, m: String| Err(Error::InvalidArgument { parameter: p.into(), message: m });
        if g.len() != self.len() {
            return bad("G", format!("has {} values, the estimate {}", g.len(), self.len()));
        }
        match h {
            Some(h) if h.len() != self.len() => {
                return bad("H", format!("has {} values, the estimate {}", h.len(), self.len()));
            }
            None if self.steps > 0 => {
                return bad("H", format!("step {} needs the values at the previous parameters", self.steps));
            }
            _ => {}
        }
        let ControlVariateOptions { beta1, beta2 } = *options;
        if self.steps > WARMUP {
            let correction = 1.0 - beta2.powf(self.updates as f64);
            for k in 0..g.len() {
                let (v0, v1, c) = (self.var_h[k] / correction, self.var_g[k] / correction, self.cov[k] / correction);
                let (w, vn) = weight(self.weight[k], self.estimate_variance[k], v0, v1, c);
                self.weight[k] = w;
                self.estimate_variance[k] = vn;
            }
        }
        match h {
            None => self.estimate.copy_from_slice(g),
            Some(h) => {
                for k in 0..g.len() {
                    let w = self.weight[k];
                    self.estimate[k] = if w == 0.0 { g[k] } else { w * (self.estimate[k] - h[k]) + g[k] };
                }
            }
        }
        if self.steps > 0
            && let Some(h) = h
        {
            // The bias-corrected means are updated in place, m̂ ← m̂ + (1 − β₁)(x − m̂)/(1 − β₁ⁿ⁺¹),
            // which is the authors' m ← β₁m + (1 − β₁)x, m̂ = m/(1 − β₁ⁿ⁺¹) rearranged so that the
            // first update gives m̂ = x exactly: one sample then has exactly zero variance (their
            // code gets rounding noise there, and weights from it).
            let gain = (1.0 - beta1) / (1.0 - beta1.powf(self.updates as f64 + 1.0));
            for k in 0..g.len() {
                let (x, y) = (h[k], g[k]);
                let (dx1, dy1) = (x - self.mean_h[k], y - self.mean_g[k]);
                self.mean_h[k] += gain * dx1;
                self.mean_g[k] += gain * dy1;
                let (dx2, dy2) = (x - self.mean_h[k], y - self.mean_g[k]);
                self.var_h[k] = beta2 * self.var_h[k] + (1.0 - beta2) * dx1 * dx2;
                self.var_g[k] = beta2 * self.var_g[k] + (1.0 - beta2) * dy1 * dy2;
                self.cov[k] = beta2 * self.cov[k] + (1.0 - beta2) * dx1 * dy2;
            }
            self.updates += 1;
        }
        self.steps += 1;
        Ok(&self.estimate)
    }
}

/// The running estimate of the loss image and its statistics, per view, pixel and channel (views
/// one after another, each W·H·3 values in [`Image`] order).
#[derive(Clone, Debug, PartialEq)]
pub struct ControlVariateState {
    /// Width of each view's image.
    pub width: u32,
    /// Height of each view's image.
    pub height: u32,
    /// Views.
    pub views: u32,
    /// The estimate and its statistics, W·H·3·views values.
    pub running: RunningEstimate,
}

impl ControlVariateState {
    /// The state before the first step, for `views` views of `width`×`height`.
    pub fn new(width: u32, height: u32, views: u32) -> ControlVariateState {
        let n = width as usize * height as usize * 3 * views as usize;
        ControlVariateState { width, height, views, running: RunningEstimate::new(n) }
    }

    /// Checks that the arrays have the layout of `views` views of `width`×`height` and hold finite
    /// statistics (a state read back from a file).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming "control-variate state".
    pub fn check(&self, width: u32, height: u32, views: u32) -> Result<()> {
        if (self.width, self.height, self.views) != (width, height, views) {
            return Err(Error::InvalidArgument {
                parameter: "control-variate state".into(),
                message: format!(
                    "is for {} view(s) of {}×{}, the run has {views} of {width}×{height}",
                    self.views, self.width, self.height
                ),
            });
        }
        self.running.check(width as usize * height as usize * 3 * views as usize, "control-variate state")
    }

    /// One step of [`RunningEstimate::step`] on the loss images: `g` (G_i, one image per view)
    /// and `h` (H_i: the same random numbers at the previous parameters; `None` only on the first
    /// step) give the new estimate F_i per view (rounded to f32).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for images of another size or count, or no `h` after the
    /// first step.
    ///
    /// ```
    /// use pathgrad::image::Image;
    /// use pathgrad::optim::{ControlVariateOptions, ControlVariateState};
    /// let mut state = ControlVariateState::new(1, 1, 1);
    /// let cv = ControlVariateOptions::default();
    /// let g = Image::from_rgb(1, 1, vec![1.0, 2.0, 3.0])?;
    /// // The first step's estimate is G itself.
    /// assert_eq!(state.step(&cv, &[g.clone()], None)?[0], g);
    /// # Ok::<(), pathgrad::Error>(())
    /// ```
    pub fn step(&mut self, options: &ControlVariateOptions, g: &[Image], h: Option<&[Image]>) -> Result<Vec<Image>> {
        self.check_images(g, "G")?;
        if let Some(h) = h {
            self.check_images(h, "H")?;
        } else if self.running.steps > 0 {
            return Err(Error::InvalidArgument {
                parameter: "H".into(),
                message: format!("step {} needs the image at the previous parameters", self.running.steps),
            });
        }
        let g: Vec<f64> = g.iter().flat_map(|i| i.as_slice()).map(|&v| f64::from(v)).collect();
        let h: Option<Vec<f64>> = h.map(|h| h.iter().flat_map(|i| i.as_slice()).map(|&v| f64::from(v)).collect());
        let estimate = self.running.step(options, &g, h.as_deref())?;
        let per_view = self.width as usize * self.height as usize * 3;
        estimate
            .chunks(per_view)
            .map(|f| Image::from_rgb(self.width, self.height, f.iter().map(|&v| v as f32).collect()))
            .collect()
    }

    fn check_images(&self, images: &[Image], what: &str) -> Result<()> {
        if images.len() != self.views as usize {
            return Err(Error::InvalidArgument {
                parameter: what.into(),
                message: format!("{} images for {} views", images.len(), self.views),
            });
        }
        if let Some(i) = images.iter().find(|i| (i.width(), i.height()) != (self.width, self.height)) {
            return Err(Error::InvalidArgument {
                parameter: what.into(),
                message: format!("is {}×{} but the estimate is {}×{}", i.width(), i.height(), self.width, self.height),
            });
        }
        Ok(())
    }
}

/// The weight update of one value: from the previous weight `w` and variance estimate `vn` of F,
/// and Var H = `v0`, Var G = `v1`, Cov(H, G) = `cov`, returns (v, V):
/// V = w²(vn + v0) + v1 − 2w·cov (the variance of the last estimate F = w(F' − H) + G, with F'
/// independent of H and G), v = cov/(v0 + V) (the v minimising Var(v(F − H) + G)), 0 if that
/// is not finite, clamped to [0, 1].
pub(crate) fn weight(w: f64, vn: f64, v0: f64, v1: f64, cov: f64) -> (f64, f64) {
    let vn = w * w * (vn + v0) + v1 - 2.0 * w * cov;
    let v = cov / (v0 + vn);
    let v = if v.is_finite() { v.clamp(0.0, 1.0) } else { 0.0 };
    (v, vn)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(values: &[f32]) -> Image {
        Image::from_rgb(values.len() as u32 / 3, 1, values.to_vec()).unwrap()
    }

    /// With the exact variances (Var H = Var G = Cov = σ², H ≡ G: the same parameters in both
    /// states) the weight recursion gives v = k/(k+1) at its k-th use and F is the running mean
    /// of the samples since the weights started.
    #[test]
    fn with_exact_variances_and_equal_states_the_estimate_is_the_running_mean() {
        let samples = [0.3, 1.7, -0.4, 2.5, 0.9, 1.1, 0.2, 3.0];
        let sigma2 = 0.8;
        // As the step does: the first use of the weights starts from w = 0, V = 0.
        let (mut w, mut vn) = (0.0, 0.0);
        let mut f = samples[0];
        for (k, &x) in samples.iter().enumerate().skip(1) {
            (w, vn) = weight(w, vn, sigma2, sigma2, sigma2);
            assert!((w - k as f64 / (k as f64 + 1.0)).abs() < 1e-15, "use {k}: v = {w}");
            f = w * (f - x) + x;
            let mean = samples[..=k].iter().sum::<f64>() / (k as f64 + 1.0);
            assert!((f - mean).abs() < 1e-14, "after {k}: F = {f}, mean {mean}");
        }
    }

    /// The same through [`ControlVariateState::step`] with H = G: the statistics make Var H = Var G
    /// = Cov exactly, the weights follow the authors' schedule — 0 at steps 0 and 1 (warm-up) and
    /// at step 2 (one update: zero variance, 0/0 → 0) — and afterwards F_i = v·F_{i−1} + (1 − v)·G_i
    /// with the state's own v ∈ (0, 1]: a running weighted average of the G's. (It is the plain
    /// running mean only where the variance estimates stay constant, which the test above checks.)
    #[test]
    fn equal_states_give_a_convex_running_average_with_the_warm_up_schedule() {
        let cv = ControlVariateOptions::default();
        let mut state = ControlVariateState::new(1, 1, 1);
        let xs =
            [[1.0f32, 2.0, 0.5], [1.4, 1.0, 0.7], [0.6, 2.5, 0.2], [1.2, 1.5, 0.9], [0.8, 2.2, 0.4], [1.1, 1.8, 0.6]];
        let mut previous: Vec<f64> = Vec::new();
        for (i, x) in xs.iter().enumerate() {
            let g = image(x);
            let h = (i > 0).then(|| vec![g.clone()]);
            let f = state.step(&cv, std::slice::from_ref(&g), h.as_deref()).unwrap().remove(0);
            assert_eq!(state.running.var_h, state.running.var_g);
            assert_eq!(state.running.var_h, state.running.cov);
            for c in 0..3 {
                let w = state.running.weight[c];
                if i <= 2 {
                    assert_eq!(w, 0.0, "step {i}");
                    assert_eq!(f.as_slice()[c], x[c]);
                } else {
                    assert!(w > 0.0 && w <= 1.0, "step {i}: v = {w}");
                    let want: f64 = w * previous[c] + (1.0 - w) * f64::from(x[c]);
                    assert!((state.running.estimate[c] - want).abs() < 1e-12, "step {i}");
                }
            }
            previous = state.running.estimate.clone();
        }
        assert_eq!((state.running.steps, state.running.updates), (6, 5));
    }

    /// v ≡ 0 (forced: a state whose statistics are all zero keeps v = 0/0 → 0) gives F = G bit
    /// for bit, whatever F and H were, even an H with ±∞.
    #[test]
    fn a_zero_weight_gives_g_itself() {
        let cv = ControlVariateOptions::default();
        let mut state = ControlVariateState::new(1, 1, 1);
        state.running.steps = 5;
        state.running.estimate = vec![9.0, -3.0, 1e30];
        let g = image(&[0.1, 0.2, 0.3]);
        let h = image(&[f32::INFINITY, 7.0, -1.0]);
        // Constant H and G: zero variances, zero covariance.
        for _ in 0..3 {
            state.running.var_h.fill(0.0);
            state.running.var_g.fill(0.0);
            state.running.cov.fill(0.0);
            let f = state.step(&cv, std::slice::from_ref(&g), Some(std::slice::from_ref(&h))).unwrap().remove(0);
            assert_eq!(state.running.weight, [0.0; 3]);
            assert_eq!(f, g);
        }
    }

    /// The Welford updates against the authors' formulas written out for two samples (β₁ = 0.9,
    /// β₂ = 0.999): after (x₁, y₁), (x₂, y₂) the bias-corrected means are the EMA means and the
    /// bias-corrected covariance is β₂(1−β₂)·dx₁dy₂/(1−β₂²) with dx₁ = x₂ − x₁, dy₂ = y₂ − m̂_y.
    #[test]
    fn the_statistics_follow_the_authors_welford_updates() {
        let cv = ControlVariateOptions::default();
        let mut state = ControlVariateState::new(1, 1, 1);
        state.step(&cv, &[image(&[0.0, 0.0, 0.0])], None).unwrap();
        state.step(&cv, &[image(&[2.0, 2.0, 2.0])], Some(&[image(&[1.0, 1.0, 1.0])])).unwrap();
        // One update: the bias-corrected means are the samples, the variances exactly zero.
        assert_eq!((state.running.mean_h[0], state.running.mean_g[0]), (1.0, 2.0));
        assert_eq!((state.running.var_h[0], state.running.var_g[0], state.running.cov[0]), (0.0, 0.0, 0.0));
        state.step(&cv, &[image(&[5.0, 5.0, 5.0])], Some(&[image(&[3.0, 3.0, 3.0])])).unwrap();
        let (b1, b2) = (0.9f64, 0.999f64);
        let (mh, mg) =
            ((b1 * 0.1 + (1.0 - b1) * 3.0) / (1.0 - b1 * b1), (b1 * 0.2 + (1.0 - b1) * 5.0) / (1.0 - b1 * b1));
        let (dx1, dy1) = (3.0 - 1.0, 5.0 - 2.0);
        let (dx2, dy2) = (3.0 - mh, 5.0 - mg);
        let var_h = (1.0 - b2) * dx1 * dx2;
        let var_g = (1.0 - b2) * dy1 * dy2;
        let cov = (1.0 - b2) * dx1 * dy2;
        assert!((state.running.var_h[0] - var_h).abs() < 1e-15, "{} vs {var_h}", state.running.var_h[0]);
        assert!((state.running.var_g[0] - var_g).abs() < 1e-15);
        assert!((state.running.cov[0] - cov).abs() < 1e-15);
        // Step 2 still had v = 0 (one update, zero statistics); step 3 uses these.
        assert_eq!(state.running.weight[0], 0.0);
        let c = 1.0 - b2 * b2;
        let (w, _) = weight(0.0, 0.0, var_h / c, var_g / c, cov / c);
        state.step(&cv, &[image(&[4.0, 4.0, 4.0])], Some(&[image(&[3.5, 3.5, 3.5])])).unwrap();
        assert!((state.running.weight[0] - w).abs() < 1e-15 && w > 0.0, "v = {} vs {w}", state.running.weight[0]);
        assert!((state.running.estimate[0] - (w * (5.0 - 3.5) + 4.0)).abs() < 1e-12);
    }

    #[test]
    fn bad_inputs_are_refused_by_name() {
        let cv = ControlVariateOptions::default();
        let mut state = ControlVariateState::new(2, 1, 1);
        let e = state.step(&cv, &[image(&[0.0; 3])], None).unwrap_err().to_string();
        assert!(e.contains("G") && e.contains("1×1"), "{e}");
        state.step(&cv, &[image(&[0.0; 6])], None).unwrap();
        let e = state.step(&cv, &[image(&[0.0; 6])], None).unwrap_err().to_string();
        assert!(e.contains("previous parameters"), "{e}");
        let e = state.step(&cv, &[image(&[0.0; 6]), image(&[0.0; 6])], None).unwrap_err().to_string();
        assert!(e.contains("2 images for 1 views"), "{e}");
        let e = ControlVariateOptions { beta1: -0.1, ..cv }.validate().unwrap_err().to_string();
        assert!(e.contains("ControlVariateOptions::beta1"), "{e}");
        assert!(state.check(2, 1, 2).unwrap_err().to_string().contains("control-variate state"));
    }
}

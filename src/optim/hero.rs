//! The hero strategy's adapted probabilities (ALGORITHMS.md §5.8): a running estimate of each hero parameter's gradient variance, and p_k proportional to it, clamped away from 0.
//!
//! After every optimisation step the loss gradient of each target k of the hero set is observed:
//! g_k = the sum over the parameter's values of their gradient (a hero target is a roughness or
//! blend weight, one value; a parameter of several values would be summed, its texels being one
//! parameter). Exponential moving averages of g_k and g_k², with β = [`HERO_BETA`] and Adam's bias
//! correction, give a running variance σ²_k = ŝ_k − m̂_k² (at least 0). The next iteration's
//! probabilities are p_k = f + (1 − K f)·σ²_k / Σ_j σ²_j with the floor f = [`HERO_FLOOR`] / K, so
//! that no target ever loses its sampler; uniform until two steps are observed or while every
//! σ² is 0. The state is 2K + 1 numbers: parameter-sized, nothing per pixel or path.

use crate::error::{Error, Result};
use crate::integrator::HeroSet;
use crate::params::{Gradients, ParamTable};

/// Decay of the moving averages of the hero targets' gradients and squared gradients.
pub const HERO_BETA: f64 = 0.9;

/// Each target keeps at least this fraction of a uniform share: p_k ≥ `HERO_FLOOR` / K.
pub const HERO_FLOOR: f64 = 0.25;

/// The running estimate of each hero target's gradient variance, in the hero set's order.
///
/// ```
/// use pathgrad::integrator::HeroSet;
/// use pathgrad::optim::HeroAdaptation;
/// use pathgrad::params::ParamId;
/// let set = HeroSet::new(&[ParamId(0), ParamId(1)], None)?;
/// let mut h = HeroAdaptation::new(&set);
/// assert_eq!(h.weights(), vec![0.5, 0.5]); // uniform before two observations
/// for g in [[1.0, 0.1], [-1.0, 0.1], [1.0, 0.12]] {
///     h.observe_values(&g);
/// }
/// let w = h.weights();
/// assert!(w[0] > 0.8 && w[1] >= 0.125);
/// # Ok::<(), pathgrad::Error>(())
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct HeroAdaptation {
    /// Steps observed.
    pub steps: u64,
    /// Moving average of each target's gradient (not bias-corrected).
    pub mean: Vec<f64>,
    /// Moving average of each target's squared gradient (not bias-corrected).
    pub square: Vec<f64>,
}

impl HeroAdaptation {
    /// The state before any step, for `set`'s targets.
    pub fn new(set: &HeroSet) -> HeroAdaptation {
        let k = set.targets().len();
        HeroAdaptation { steps: 0, mean: vec![0.0; k], square: vec![0.0; k] }
    }

    /// Observes one step's gradient of each target, `values[k]` for target k.
    pub fn observe_values(&mut self, values: &[f64]) {
        for ((m, s), &g) in self.mean.iter_mut().zip(&mut self.square).zip(values) {
            *m = HERO_BETA * *m + (1.0 - HERO_BETA) * g;
            *s = HERO_BETA * *s + (1.0 - HERO_BETA) * g * g;
        }
        self.steps += 1;
    }

    /// Observes one step's `gradients` of `set`'s targets in `table` (each target's values summed).
    pub fn observe(&mut self, set: &HeroSet, table: &ParamTable, gradients: &Gradients) {
        let values: Vec<f64> = set
            .targets()
            .iter()
            .map(|&t| {
                let e = table.entry(t);
                gradients.values()[e.offset as usize..(e.offset + e.len) as usize].iter().map(|&v| f64::from(v)).sum()
            })
            .collect();
        self.observe_values(&values);
    }

    /// Each target's running gradient variance σ²_k (0 before two steps).
    pub fn variances(&self) -> Vec<f64> {
        if self.steps < 2 {
            return vec![0.0; self.mean.len()];
        }
        let c = 1.0 - HERO_BETA.powi(self.steps.min(i32::MAX as u64) as i32);
        self.mean.iter().zip(&self.square).map(|(m, s)| (s / c - (m / c) * (m / c)).max(0.0)).collect()
    }

    /// The probabilities of the next step: p_k = f + (1 − K f) σ²_k / Σ σ², f = `HERO_FLOOR` / K
    /// (uniform while Σ σ² is 0 or not finite).
    pub fn weights(&self) -> Vec<f32> {
        let k = self.mean.len();
        let v = self.variances();
        let total: f64 = v.iter().sum();
        if !(total > 0.0 && total.is_finite()) {
            return vec![1.0 / k as f32; k];
        }
        let floor = HERO_FLOOR / k as f64;
        v.iter().map(|x| (floor + (1.0 - k as f64 * floor) * x / total) as f32).collect()
    }

    /// Checks that the state fits `set` (as read back from a file).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming "hero state" if its sizes differ from the set's or a
    /// value is not finite.
    pub fn check(&self, set: &HeroSet) -> Result<()> {
        let k = set.targets().len();
        if self.mean.len() != k || self.square.len() != k {
            return Err(Error::InvalidArgument {
                parameter: "hero state".into(),
                message: format!("has {} and {} values for {k} targets", self.mean.len(), self.square.len()),
            });
        }
        if self.mean.iter().chain(&self.square).any(|v| !v.is_finite()) {
            return Err(Error::InvalidArgument {
                parameter: "hero state".into(),
                message: "a value is not finite".into(),
            });
        }
        Ok(())
    }
}

//! Gradient reuse across optimisation iterations (after Bálint et al. 2023, "Joint sampling and optimisation for inverse rendering"): the running estimate F_i = v_i·(F_{i−1} − H_i) + G_i of the loss gradient, per optimised value.
//!
//! Iteration i takes two loss gradients with the same seed (the same random numbers in both
//! passes): G_i at the current parameters θ_i and H_i at the previous ones θ_{i−1}. G_i is the
//! paper's *proportional* sample of ∇L(θ_i); G_i − H_i is its *finite-difference* sample of
//! ∇L(θ_i) − ∇L(θ_{i−1}), low in variance because both ends share their paths. The meta-estimate
//! F_i = v(F_{i−1} + G_i − H_i) + (1 − v)·G_i, rewritten F_i = v(F_{i−1} − H_i) + G_i, carries the
//! earlier iterations' samples forward along the trajectory. Given the trajectory, E(F_{i−1}) =
//! ∇L(θ_{i−1}) = E(H_i) and E(G_i) = ∇L(θ_i), so E(F_i) = ∇L(θ_i) for any weight v fixed before
//! the step's samples are drawn. The weight per value is the variance-minimising one,
//! v = Cov(H, G)/(Var H + Var F), clamped to [0, 1], from running statistics of earlier steps —
//! the same recursion as the loss image's control variates ([`RunningEstimate`], Nicolet et al.
//! 2023), here in parameter space instead of image space. The paper's own weights are written in
//! terms of proportional and finite-difference sample counts; this weight is our choice, made so
//! that one recursion serves both estimators (`docs/gradients.md`).
//!
//! The state is parameter-sized: eight f64 per optimised value, nothing per pixel or path. A step
//! costs two gradients (each its pass 1 and its gradient pass); Adam then takes F_i as its
//! gradient.

use crate::error::{Error, Result};
use crate::optim::control_variates::{ControlVariateOptions, RunningEstimate};
use crate::params::{Gradients, ParamId, ParamTable};

/// Gradient reuse's state between iterations: the running estimate over the optimised values (in
/// the order of the run's parameters, each parameter's values in table order), and the
/// parameters the last iteration took its G at (θ_{i−1}, where this iteration takes H). Both are
/// `None` before the first iteration.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GradientReuse {
    /// The running estimate and its statistics.
    pub state: Option<RunningEstimate>,
    /// The parameters of the last iteration.
    pub previous: Option<ParamTable>,
}

/// The optimised values of `gradients`, `params` in order, as f64.
pub(crate) fn gather(gradients: &Gradients, table: &ParamTable, params: &[ParamId]) -> Vec<f64> {
    params
        .iter()
        .flat_map(|&p| {
            let e = table.entry(p);
            gradients.values()[e.offset as usize..(e.offset + e.len) as usize].iter().map(|&v| f64::from(v))
        })
        .collect()
}

/// `gradients` with the optimised values (`params` in order) replaced by `values` (rounded to
/// f32); the other values stay as they are (Adam does not read them).
pub(crate) fn scatter(gradients: &Gradients, table: &ParamTable, params: &[ParamId], values: &[f64]) -> Gradients {
    let mut out = gradients.values().to_vec();
    let mut at = 0;
    for &p in params {
        let e = table.entry(p);
        for v in &mut out[e.offset as usize..(e.offset + e.len) as usize] {
            *v = values[at] as f32;
            at += 1;
        }
    }
    Gradients::new(table, out)
}

/// One step of gradient reuse: combines `g` (G_i) and `h` (H_i, `None` on the first step) over the
/// optimised values `params` with the running estimate in `state` (a fresh one if `None`), and
/// returns the gradients with those values replaced by F_i, and the new state.
///
/// # Errors
/// [`Error::InvalidArgument`] naming "gradient-reuse state" for a state of another number of
/// values, and those of [`RunningEstimate::step`].
///
/// ```
/// use pathgrad::optim::{ControlVariateOptions, gradient_reuse};
/// use pathgrad::params::{Gradients, ParamTable};
/// let mut table = ParamTable::default();
/// let w = table.add("object.weight.value", &[0.5], (0.0, 1.0))?;
/// let g = Gradients::new(&table, vec![0.25]);
/// // The first step's estimate is G itself.
/// let (f, state) = gradient_reuse::step(&ControlVariateOptions::default(), None, &table, &[w], &g, None)?;
/// assert_eq!(f.values(), &[0.25]);
/// assert_eq!(state.steps, 1);
/// # Ok::<(), pathgrad::Error>(())
/// ```
pub fn step(
    options: &ControlVariateOptions,
    state: Option<&RunningEstimate>,
    table: &ParamTable,
    params: &[ParamId],
    g: &Gradients,
    h: Option<&Gradients>,
) -> Result<(Gradients, RunningEstimate)> {
    let gv = gather(g, table, params);
    let hv = h.map(|h| gather(h, table, params));
    let mut state = match state {
        Some(state) => state.clone(),
        None => RunningEstimate::new(gv.len()),
    };
    if state.len() != gv.len() {
        return Err(Error::InvalidArgument {
            parameter: "gradient-reuse state".into(),
            message: format!("has {} values, the run optimises {}", state.len(), gv.len()),
        });
    }
    let f = state.step(options, &gv, hv.as_deref())?;
    Ok((scatter(g, table, params, f), state))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Gathering and scattering take exactly the optimised values, in `params` order, and leave
    /// the others alone.
    #[test]
    fn the_optimised_values_go_in_and_out_in_parameter_order() {
        let mut table = ParamTable::default();
        let a = table.add("a", &[1.0, 2.0], (0.0, 10.0)).unwrap();
        let _b = table.add("b", &[3.0], (0.0, 10.0)).unwrap();
        let c = table.add("c", &[4.0, 5.0, 6.0], (0.0, 10.0)).unwrap();
        let g = Gradients::new(&table, vec![0.1, 0.2, 0.3, 0.4, 0.5, 0.6]);
        assert_eq!(gather(&g, &table, &[c, a]), [0.4f32, 0.5, 0.6, 0.1, 0.2].map(f64::from));
        let out = scatter(&g, &table, &[c, a], &[4.0, 5.0, 6.0, 1.0, 2.0]);
        assert_eq!(out.values(), &[1.0, 2.0, 0.3, 4.0, 5.0, 6.0]);
    }

    /// Along a still trajectory (H ≡ G: the same parameters) the estimate becomes a convex running
    /// average of the G's once the weights start (step 3), and a state of another size is refused
    /// by name.
    #[test]
    fn equal_states_average_and_a_wrong_state_is_refused() {
        let options = ControlVariateOptions::default();
        let mut table = ParamTable::default();
        let w = table.add("w", &[0.5], (0.0, 1.0)).unwrap();
        let mut state: Option<RunningEstimate> = None;
        let samples = [1.0f32, 3.0, 2.0, 0.0, 4.0];
        for (i, &x) in samples.iter().enumerate() {
            let g = Gradients::new(&table, vec![x]);
            let h = (i > 0).then(|| g.clone());
            let (f, next) = step(&options, state.as_ref(), &table, &[w], &g, h.as_ref()).unwrap();
            if i <= 2 {
                assert_eq!(f.values(), &[x], "step {i}: the weight is still 0");
            } else {
                let (lo, hi) = samples[..=i].iter().fold((f32::MAX, f32::MIN), |(l, h), &s| (l.min(s), h.max(s)));
                assert!(next.weight[0] > 0.0 && (lo..=hi).contains(&f.values()[0]), "step {i}: {}", f.values()[0]);
                assert_ne!(f.values(), &[x]);
            }
            state = Some(next);
        }
        let mut two = ParamTable::default();
        let v = two.add("v", &[0.5, 0.5], (0.0, 1.0)).unwrap();
        let g = Gradients::new(&two, vec![1.0, 1.0]);
        let e = step(&options, state.as_ref(), &two, &[v], &g, Some(&g)).unwrap_err().to_string();
        assert!(e.contains("gradient-reuse state") && e.contains("has 1 values, the run optimises 2"), "{e}");
    }
}

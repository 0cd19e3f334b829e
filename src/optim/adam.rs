//! Adam with projection onto each parameter's bounds (ALGORITHMS.md §7.2).

use crate::error::{Error, Result};
use crate::params::{Gradients, ParamId, ParamTable};

/// Adam's first-moment decay β₁ (ALGORITHMS.md §7.2, the paper's default).
pub const BETA1: f64 = 0.9;
/// Adam's second-moment decay β₂.
pub const BETA2: f64 = 0.999;
/// Adam's ε, added to √v (not to the bias-corrected √v̂), so a zero gradient history gives a
/// zero step instead of 0/0.
pub const EPSILON: f64 = 1e-8;
/// The learning rate when none is given (the Dragon configuration of ALGORITHMS.md §7.3).
pub const DEFAULT_LEARNING_RATE: f64 = 0.01;
/// Adam's hyper-parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AdamOptions {
    /// The learning rate η.
    pub learning_rate: f64,
    /// First-moment decay β₁.
    pub beta1: f64,
    /// Second-moment decay β₂.
    pub beta2: f64,
    /// ε added to √v.
    pub epsilon: f64,
}

impl Default for AdamOptions {
    fn default() -> AdamOptions {
        AdamOptions { learning_rate: DEFAULT_LEARNING_RATE, beta1: BETA1, beta2: BETA2, epsilon: EPSILON }
    }
}

impl AdamOptions {
    /// The paper's defaults with learning rate `learning_rate`.
    pub fn with_learning_rate(learning_rate: f64) -> AdamOptions {
        AdamOptions { learning_rate, ..AdamOptions::default() }
    }

    /// Checks ranges.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `AdamOptions::learning_rate` for a learning rate that is not positive and
    /// finite, or the decay rates and ε outside their ranges.
    pub fn validate(&self) -> Result<()> {
        let bad = |p: &str, m: String| Err(Error::InvalidArgument { parameter: p.into(), message: m });
        if !(self.learning_rate > 0.0 && self.learning_rate.is_finite()) {
            return bad("AdamOptions::learning_rate", format!("{} must be positive and finite", self.learning_rate));
        }
        for (name, beta) in [("AdamOptions::beta1", self.beta1), ("AdamOptions::beta2", self.beta2)] {
            if !(0.0..1.0).contains(&beta) {
                return bad(name, format!("{beta} is not in [0, 1)"));
            }
        }
        if !(self.epsilon > 0.0 && self.epsilon.is_finite()) {
            return bad("AdamOptions::epsilon", format!("{} must be positive and finite", self.epsilon));
        }
        Ok(())
    }
}

/// Adam's state: the moments m and v of every optimised value, and each parameter's step count t.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct AdamState {
    /// First moments, one per optimised value, parameters in [`Adam::params`] order.
    pub m: Vec<f64>,
    /// Second moments, laid out as `m`.
    pub v: Vec<f64>,
    /// Steps taken, one per optimised parameter.
    pub steps: Vec<u64>,
}

/// Adam over some of a [`ParamTable`]'s parameters (ALGORITHMS.md §7.2): per value
/// m ← β₁m + (1−β₁)g, v ← β₂v + (1−β₂)g², θ ← θ − η_t·m/(√v + ε) with the bias-corrected step
/// η_t = η·√(1−β₂ᵗ)/(1−β₁ᵗ), then θ is projected onto the parameter's bounds (clamped: alpha to
/// [1e-3, 1], weights and albedo to [0, 1]; see [`crate::scene::bounds`]).
///
/// ```
/// use pathgrad::optim::{Adam, AdamOptions};
/// use pathgrad::params::{Gradients, ParamTable};
/// let mut table = ParamTable::default();
/// let w = table.add("object.weight.value", &[0.5], (0.0, 1.0))?;
/// let mut adam = Adam::new(&table, &[w], AdamOptions::with_learning_rate(0.1))?;
/// // A positive gradient moves the weight down by about the learning rate.
/// let gradient = Gradients::new(&table, vec![2.0]);
/// adam.step(&mut table, &gradient, 0)?;
/// assert!((table.get(w)[0] - 0.4).abs() < 1e-6);
/// // Steps beyond the bound are projected onto it.
/// for t in 1..20 {
///     adam.step(&mut table, &gradient, t)?;
/// }
/// assert_eq!(table.get(w)[0], 0.0);
/// # Ok::<(), pathgrad::Error>(())
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct Adam {
    options: AdamOptions,
    params: Vec<ParamId>,
    state: AdamState,
}

impl Adam {
    /// Adam with zero moments over `params` of `table`.
    ///
    /// # Errors
    /// As [`AdamOptions::validate`]; [`Error::InvalidArgument`] for an empty or repeated
    /// parameter list.
    pub fn new(table: &ParamTable, params: &[ParamId], options: AdamOptions) -> Result<Adam> {
        let values: usize = params.iter().map(|&p| table.entry(p).len as usize).sum();
        let state = AdamState { m: vec![0.0; values], v: vec![0.0; values], steps: vec![0; params.len()] };
        Adam::with_state(table, params, options, state)
    }

    /// Adam over `params` of `table` continuing from `state` (as saved from [`Adam::state`]).
    ///
    /// # Errors
    /// As [`Adam::new`]; [`Error::InvalidArgument`] if `state` does not have the layout of
    /// `params` or holds non-finite or negative moments.
    pub fn with_state(table: &ParamTable, params: &[ParamId], options: AdamOptions, state: AdamState) -> Result<Adam> {
        options.validate()?;
        let bad = |m: String| Err(Error::InvalidArgument { parameter: "optimised parameters".into(), message: m });
        if params.is_empty() {
            return bad("none given".into());
        }
        for (i, p) in params.iter().enumerate() {
            if params[..i].contains(p) {
                return bad(format!("{} is listed twice", table.entry(*p).name));
            }
        }
        let values: usize = params.iter().map(|&p| table.entry(p).len as usize).sum();
        let state_error = |m: String| Err(Error::InvalidArgument { parameter: "Adam state".into(), message: m });
        if state.m.len() != values || state.v.len() != values || state.steps.len() != params.len() {
            return state_error(format!(
                "has {} + {} moments and {} step counts for {values} values of {} parameters",
                state.m.len(),
                state.v.len(),
                state.steps.len(),
                params.len()
            ));
        }
        if state.m.iter().any(|m| !m.is_finite()) || state.v.iter().any(|v| !(v.is_finite() && *v >= 0.0)) {
            return state_error("holds a non-finite or negative moment".into());
        }
        Ok(Adam { options, params: params.to_vec(), state })
    }

    /// The optimised parameters, in the order of the state's moments.
    pub fn params(&self) -> &[ParamId] {
        &self.params
    }

    /// The hyper-parameters.
    pub fn options(&self) -> &AdamOptions {
        &self.options
    }

    /// The moments and step counts (what a resumed run needs).
    pub fn state(&self) -> &AdamState {
        &self.state
    }

    /// One Adam step on `table` with `gradients` (the table's layout) at optimisation iteration
    /// `iteration` (used in error messages only), then the projection onto each parameter's
    /// bounds. Values of parameters that are not optimised are left alone.
    ///
    /// # Errors
    /// [`Error::NonFiniteGradient`] naming `iteration`, the parameter and the value's index if an
    /// optimised value's gradient is NaN or infinite — checked before anything changes, so the
    /// table and the state are untouched; [`Error::InvalidArgument`] if `gradients` has another
    /// layout than `table`.
    pub fn step(&mut self, table: &mut ParamTable, gradients: &Gradients, iteration: u64) -> Result<()> {
        gradients.check_layout(table)?;
        for &p in &self.params {
            let e = table.entry(p);
            let g = &gradients.values()[e.offset as usize..(e.offset + e.len) as usize];
            if let Some(index) = g.iter().position(|v| !v.is_finite()) {
                return Err(Error::NonFiniteGradient {
                    iteration,
                    parameter: e.name.clone(),
                    index: index as u32,
                    value: g[index],
                });
            }
        }
        let AdamOptions { learning_rate, beta1, beta2, epsilon } = self.options;
        let mut k = 0;
        for (i, &p) in self.params.iter().enumerate() {
            let e = table.entry(p).clone();
            self.state.steps[i] += 1;
            let t = self.state.steps[i] as f64;
            let eta = learning_rate * (1.0 - beta2.powf(t)).sqrt() / (1.0 - beta1.powf(t));
            let (lo, hi) = (f64::from(e.bounds.0), f64::from(e.bounds.1));
            let range = e.offset as usize..(e.offset + e.len) as usize;
            let mut values = table.values()[range.clone()].to_vec();
            for (value, &g) in values.iter_mut().zip(&gradients.values()[range]) {
                let g = f64::from(g);
                let (m, v) = (&mut self.state.m[k], &mut self.state.v[k]);
                *m = beta1 * *m + (1.0 - beta1) * g;
                *v = beta2 * *v + (1.0 - beta2) * g * g;
                let theta = f64::from(*value) - eta * *m / (v.sqrt() + epsilon);
                // Clamping in f64 to bounds that are f32 values, then rounding, stays within them.
                *value = theta.clamp(lo, hi) as f32;
                k += 1;
            }
            table.set(&e.name, &values).expect("projected values lie within the parameter's bounds");
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    impl Adam {
        /// A step with gradient values `g` in `table`'s layout.
        fn step_with(&mut self, table: &mut ParamTable, g: Vec<f32>, iteration: u64) -> Result<()> {
            let gradients = Gradients::new(table, g);
            self.step(table, &gradients, iteration)
        }
    }

    fn table() -> (ParamTable, ParamId, ParamId, ParamId) {
        let mut t = ParamTable::default();
        let albedo = t.add("wall.reflectance.value", &[0.5, 0.5, 0.5], (0.0, 1.0)).unwrap();
        let alpha = t.add("sphere.bsdf.alpha.value", &[0.5], (1e-3, 1.0)).unwrap();
        let other = t.add("light.emitter.radiance.value", &[2.0, 2.0, 2.0], (0.0, f32::INFINITY)).unwrap();
        (t, albedo, alpha, other)
    }

    /// The first two steps against values worked out by hand from ALGORITHMS.md §7.2 with η = 0.1,
    /// θ₀ = 0.5, g₁ = 0.5, g₂ = −0.25:
    /// step 1: m = 0.05, v = 2.5e-4, η₁ = 0.1·√0.001/0.1 = 0.0316228, Δ = η₁·0.05/(0.0158114 + 1e-8)
    /// = 0.0999999368 → θ₁ = 0.4000000632;
    /// step 2: m = 0.9·0.05 − 0.1·0.25 = 0.02, v = 0.999·2.5e-4 + 0.001·0.0625 = 3.1225e-4,
    /// η₂ = 0.1·√(1 − 0.999²)/(1 − 0.9²) = 0.1·0.0447102/0.19 = 0.0235317,
    /// Δ = 0.0235317·0.02/0.0176706 = 0.0266337 → θ₂ = 0.3733664.
    /// Values are stored as f32, so they agree to f32 rounding (a relative 6e-8 per step).
    #[test]
    fn first_two_steps_match_the_hand_computation() {
        let (mut t, albedo, alpha, other) = table();
        let mut adam = Adam::new(&t, &[alpha, albedo], AdamOptions::with_learning_rate(0.1)).unwrap();
        adam.step_with(&mut t, vec![0.0, 0.5, -0.5, 0.5, 7.0, 7.0, 7.0], 0).unwrap();
        assert!((f64::from(t.get(alpha)[0]) - 0.400_000_063_2).abs() < 1e-7, "{:?}", t.get(alpha));
        let s = adam.state();
        // Moments are laid out in the order the parameters were given: alpha first, then albedo.
        assert!((s.m[0] - 0.05).abs() < 1e-12 && (s.v[0] - 2.5e-4).abs() < 1e-15, "{s:?}");
        assert_eq!(s.steps, [1, 1]);
        // A zero gradient gives a zero step; ±g give ∓η (to ε).
        assert_eq!(t.get(albedo)[0], 0.5);
        assert!((t.get(albedo)[1] - 0.4).abs() < 1e-6 && (t.get(albedo)[2] - 0.6).abs() < 1e-6);
        adam.step_with(&mut t, vec![0.0, 0.5, -0.5, -0.25, 7.0, 7.0, 7.0], 1).unwrap();
        assert!((f64::from(t.get(alpha)[0]) - 0.373_366_4).abs() < 1e-7, "{:?}", t.get(alpha));
        assert!((adam.state().m[0] - 0.02).abs() < 1e-12 && (adam.state().v[0] - 3.1225e-4).abs() < 1e-15);
        assert_eq!(t.get(other), [2.0, 2.0, 2.0], "a parameter that is not optimised keeps its values");
    }

    /// On f(θ) = Σ (θᵢ − cᵢ)² with noiseless gradients Adam reaches the minimum after 2 000 steps
    /// at η = 0.01 (the whole way is at most 0.45, ≥ 45 steps of η): in f64 the same iteration ends
    /// within 1e-15 of cᵢ, so the bound is f32 storage of θ (an ulp below 1 is 6e-8); 1e-5 leaves
    /// a margin for steps that round away near the minimum.
    #[test]
    fn adam_converges_on_a_quadratic() {
        let (mut t, albedo, alpha, _) = table();
        let centre = [0.2f32, 0.7, 0.9, 0.05];
        let mut adam = Adam::new(&t, &[albedo, alpha], AdamOptions::default()).unwrap();
        for it in 0..2000 {
            let v = t.values().to_vec();
            let mut g = vec![0.0; v.len()];
            for (i, c) in centre.iter().enumerate() {
                g[i] = 2.0 * (v[i] - c);
            }
            adam.step_with(&mut t, g, it).unwrap();
        }
        for (got, want) in t.values()[..4].iter().zip(centre) {
            assert!((got - want).abs() < 1e-5, "{:?} vs {centre:?}", t.values());
        }
    }

    /// A minimum outside the bounds: the iterate sits on the bound, never beyond it, for albedo
    /// ([0, 1]) and roughness ([1e-3, 1]).
    #[test]
    fn steps_are_projected_onto_the_bounds() {
        let (mut t, albedo, alpha, _) = table();
        let mut adam = Adam::new(&t, &[albedo, alpha], AdamOptions::with_learning_rate(0.2)).unwrap();
        // Gradients pull channel 0 up, 1 and 2 down, alpha down.
        for it in 0..20 {
            adam.step_with(&mut t, vec![-1.0, 1.0, 1e6, 1.0, 0.0, 0.0, 0.0], it).unwrap();
            assert!(t.values()[..3].iter().all(|v| (0.0..=1.0).contains(v)));
            assert!((1e-3..=1.0).contains(&t.get(alpha)[0]));
        }
        assert_eq!(t.get(albedo), [1.0, 0.0, 0.0]);
        assert_eq!(t.get(alpha), [1e-3]);
        // And back off the bound once the gradient has turned long enough for m to change sign
        // (m ≈ 0.88 after 20 steps of g = 1; 20 steps of g = −1 take it to ≈ −0.78).
        for it in 20..40 {
            adam.step_with(&mut t, vec![0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0], it).unwrap();
        }
        assert!(t.get(alpha)[0] > 1e-3);
    }

    /// NaN or ±∞ in an optimised value's gradient is an error naming the iteration and the
    /// parameter (name and index); the parameters and Adam's state are as before the call. A
    /// NaN in a parameter that is not optimised does not matter.
    #[test]
    fn non_finite_gradients_are_rejected_and_change_nothing() {
        let (mut t, albedo, alpha, _) = table();
        let mut adam = Adam::new(&t, &[alpha, albedo], AdamOptions::default()).unwrap();
        adam.step_with(&mut t, vec![0.1, 0.2, 0.3, 0.4, 0.0, 0.0, 0.0], 0).unwrap();
        let (t_before, adam_before) = (t.clone(), adam.clone());
        for (bad, index, name) in
            [(f32::NAN, 2, "wall.reflectance.value[2]"), (f32::INFINITY, 3, "sphere.bsdf.alpha.value[0]")]
        {
            for value in [bad, -bad] {
                let mut g = vec![0.1, 0.2, 0.3, 0.4, 0.0, 0.0, 0.0];
                g[index] = value;
                let err = adam.step_with(&mut t, g, 17).unwrap_err();
                assert!(matches!(err, Error::NonFiniteGradient { iteration: 17, .. }), "{err:?}");
                let text = err.to_string();
                assert!(text.contains("iteration 17") && text.contains(name), "{text}");
                assert_eq!(t, t_before);
                assert_eq!(adam, adam_before);
            }
        }
        adam.step_with(&mut t, vec![0.1, 0.2, 0.3, 0.4, f32::NAN, 0.0, 0.0], 1).unwrap();
        assert_eq!(adam.state().steps, [2, 2]);
    }

    #[test]
    fn bad_options_and_states_are_rejected() {
        let (t, albedo, alpha, _) = table();
        for lr in [0.0, -0.1, f64::NAN, f64::INFINITY] {
            let e = Adam::new(&t, &[alpha], AdamOptions::with_learning_rate(lr)).unwrap_err().to_string();
            assert!(e.contains("AdamOptions::learning_rate"), "{e}");
        }
        assert!(Adam::new(&t, &[], AdamOptions::default()).unwrap_err().to_string().contains("none given"));
        assert!(Adam::new(&t, &[alpha, alpha], AdamOptions::default()).unwrap_err().to_string().contains("twice"));
        let short = AdamState { m: vec![0.0; 3], v: vec![0.0; 3], steps: vec![0; 2] };
        let e = Adam::with_state(&t, &[alpha, albedo], AdamOptions::default(), short).unwrap_err().to_string();
        assert!(e.contains("Adam state"), "{e}");
    }
}

//! Inverse rendering: Adam with projection onto each parameter's bounds (ALGORITHMS.md §7.2) and the two-pass iteration of Su & Gkioulekas' Algorithm 2 (§3.4, §6).
//!
//! One iteration t ([`Optimization::step`]) renders pass 1 with `spp_primal` samples per pixel
//! (plain BSDF sampling with next-event estimation, the primal key), takes the loss and its
//! adjoint image on the host, runs the fused gradient pass with `spp_grad` samples — uniformly
//! per pixel, or drawn from the loss-aware pixel weights ([`crate::adaptive`]) — and hands the
//! gradient to [`Adam`]. Both passes of iteration t use seed `base + t`; their pass tags keep
//! their paths independent of each other (ALGORITHMS.md §2.3). A gradient value that is NaN or
//! infinite stops the step before anything is written: [`Error::NonFiniteGradient`] names the
//! iteration and the parameter, and the parameters and Adam's moments stay as they were.
//!
//! With [`IterationOptions::control_variates`], pass 1 is rendered twice per iteration, at the
//! current and at the previous parameters with the same seed, and the loss and adjoint images
//! are taken from the recursive control-variate estimate of [`control_variates`] instead of the
//! plain render; the gradient pass is unchanged.
//!
//! With [`IterationOptions::gradient_reuse`], each iteration takes its loss gradient twice, at the
//! current and at the previous parameters with the same seed, and hands Adam the running
//! estimate of [`gradient_reuse`] instead of the plain gradient.

mod adam;
pub mod control_variates;
pub mod gradient_reuse;
pub mod hero;

pub use adam::{Adam, AdamOptions, AdamState, BETA1, BETA2, DEFAULT_LEARNING_RATE, EPSILON};
pub use control_variates::{ControlVariateOptions, ControlVariateState, RunningEstimate};
pub use gradient_reuse::GradientReuse;
pub use hero::HeroAdaptation;

use crate::adaptive::{AdaptiveEstimator, AdaptiveOptions, PixelSampling};
use crate::backend::{Backend, check_views};
use crate::error::{Error, Result};
use crate::gpu::renderer::GradMode;
use crate::image::Image;
use crate::integrator::{RenderOptions, View};
use crate::loss::{Loss, loss_and_adjoint};
use crate::params::{Gradients, ParamId, ParamTable};
use crate::prior::Smoothness;

/// ε of the relative parameter error ((θ − θ*)/(θ* + ε))² (ALGORITHMS.md §7.1), so a true value
/// of 0 does not divide by zero.
pub const PARAM_ERROR_EPSILON: f64 = 1e-3;

/// The relative squared parameter error of ALGORITHMS.md §7.1, ((θ − θ*)/(θ* + ε))² with
/// ε = [`PARAM_ERROR_EPSILON`], averaged over the values.
///
/// ```
/// let e = pathgrad::optim::parameter_error(&[0.3], &[0.05]);
/// // 24.03, up to the f32 rounding of 0.3 and 0.05.
/// assert!((e / (0.25f64 / 0.051).powi(2) - 1.0).abs() < 1e-6);
/// ```
///
/// # Panics
/// If the slices differ in length or are empty (the caller compares a parameter with itself).
pub fn parameter_error(values: &[f32], truth: &[f32]) -> f64 {
    assert!(values.len() == truth.len() && !values.is_empty(), "a parameter error compares equal, non-empty shapes");
    values
        .iter()
        .zip(truth)
        .map(|(&v, &t)| ((f64::from(v) - f64::from(t)) / (f64::from(t) + PARAM_ERROR_EPSILON)).powi(2))
        .sum::<f64>()
        / values.len() as f64
}

/// How each iteration estimates its gradient.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IterationOptions {
    /// The gradient pass: image size, depth, strategy and NEE; `spp` is spp_grad (samples per
    /// pixel, or W·H·spp adaptively placed samples); `seed` is the base seed (iteration t uses
    /// `seed + t`). Pass 1 always uses plain BSDF sampling with NEE.
    pub render: RenderOptions,
    /// Samples per pixel of pass 1 (the loss image).
    pub spp_primal: u32,
    /// Loss-aware adaptive pixel sampling with this estimator, or uniform sampling.
    pub adaptive: Option<AdaptiveEstimator>,
    /// The loss.
    pub loss: Loss,
    /// How the gradient is accumulated.
    pub mode: GradMode,
    /// Recursive control variates across iterations (Nicolet et al. 2023) on the loss image, or
    /// none: pass 1 is then rendered once per iteration and used as it is.
    pub control_variates: Option<ControlVariateOptions>,
    /// Gradient reuse across iterations ([`gradient_reuse`], after Bálint et al. 2023) with
    /// these decays of its running statistics, or none: each iteration's gradient is then used
    /// as it is. Not together with [`IterationOptions::control_variates`].
    pub gradient_reuse: Option<ControlVariateOptions>,
}

impl IterationOptions {
    /// The render options of iteration `iteration`: [`IterationOptions::render`] with seed
    /// `seed + iteration` (wrapping).
    pub fn at(&self, iteration: u64) -> RenderOptions {
        RenderOptions { seed: self.render.seed.wrapping_add(iteration as u32), ..self.render }
    }

    /// Checks ranges.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming the option.
    pub fn validate(&self) -> Result<()> {
        self.render.validate()?;
        if let Some(cv) = &self.control_variates {
            cv.validate()?;
        }
        if let Some(reuse) = &self.gradient_reuse {
            reuse.validate()?;
            if self.control_variates.is_some() {
                return Err(Error::InvalidArgument {
                    parameter: "IterationOptions::gradient_reuse".into(),
                    message: "does not combine with control variates on the loss image (each would need the \
                              other's state at the previous parameters): choose one"
                        .into(),
                });
            }
        }
        AdaptiveOptions { spp_primal: self.spp_primal, estimator: AdaptiveEstimator::default() }.validate()
    }
}

/// What one iteration did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepReport {
    /// The iteration's index t (its seed is base + t).
    pub iteration: u64,
    /// The loss of pass 1 at the parameters before the step.
    pub loss: f64,
    /// The Euclidean norm of the gradient over the optimised values.
    pub gradient_norm: f64,
}

/// An inverse-rendering run: the parameters, Adam's state and the iteration count.
///
/// ```no_run
/// use pathgrad::backend::Backend;
/// use pathgrad::gpu::{Context, ContextDesc, Renderer};
/// use pathgrad::gpu::renderer::GradMode;
/// use pathgrad::integrator::RenderOptions;
/// use pathgrad::loss::Loss;
/// use pathgrad::optim::{AdamOptions, IterationOptions, Optimization};
///
/// let scene = pathgrad::scene::builtin::load("blend")?;
/// let ctx = Context::new(&ContextDesc::default())?;
/// let mut renderer = Renderer::new(&ctx, &scene)?;
/// let render = RenderOptions { width: 64, height: 48, spp: 2, ..RenderOptions::for_scene(&scene) };
/// // The target: the scene at weight 0.4.
/// let mut truth = scene.params.clone();
/// truth.set("object.weight.value", &[0.4])?;
/// renderer.set_params(&truth)?;
/// let target = renderer.render(&RenderOptions { spp: 256, seed: 99, ..render })?;
/// // Start at 0.8 and optimise the weight only.
/// let mut start = scene.params.clone();
/// start.set("object.weight.value", &[0.8])?;
/// let weight = start.find("object.weight.value").unwrap();
/// let options = IterationOptions {
///     render,
///     spp_primal: 6,
///     adaptive: None,
///     loss: Loss::RelMse,
///     mode: GradMode::Float,
///     // Recursive control variates on the loss image; `None` renders it plainly.
///     control_variates: Some(Default::default()),
///     // Gradient reuse across iterations would be `Some(Default::default())` (not with control
///     // variates).
///     gradient_reuse: None,
/// };
/// let mut run = Optimization::new(start, &[weight], AdamOptions::with_learning_rate(0.01), options)?;
/// for _ in 0..100 {
///     let report = run.step(&mut renderer, &target)?;
///     println!("{}: loss {:.4e}, weight {}", report.iteration, report.loss, run.params().get(weight)[0]);
/// }
/// # Ok::<(), pathgrad::Error>(())
/// ```
#[derive(Clone, Debug)]
pub struct Optimization {
    options: IterationOptions,
    params: ParamTable,
    adam: Adam,
    iteration: u64,
    prior: Option<Smoothness>,
    /// The control variates' committed state (with [`IterationOptions::control_variates`]).
    control: ControlVariates,
    /// The state the last [`Optimization::gradient_views`] computed for iteration `.0`, which
    /// [`Optimization::apply`] commits.
    pending: Option<(u64, ControlVariateState)>,
    /// Gradient reuse's committed state (with [`IterationOptions::gradient_reuse`]).
    reuse: GradientReuse,
    /// The state the last [`Optimization::gradient_views`] computed for iteration `.0`, with
    /// reuse.
    pending_reuse: Option<(u64, RunningEstimate)>,
    /// The hero strategy's adapted probabilities (with [`Optimization::with_hero_adaptation`]).
    hero: Option<HeroAdaptation>,
}

/// The control variates' state between iterations: the running estimate and its statistics, and
/// the parameters the last iteration rendered its G at (θ_{i−1}, where this iteration renders H).
/// Both are `None` before the first iteration.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ControlVariates {
    /// The running estimate and its statistics.
    pub state: Option<ControlVariateState>,
    /// The parameters of the last iteration.
    pub previous: Option<ParamTable>,
}

impl Optimization {
    /// A run from `initial` that optimises `params` with fresh Adam state.
    ///
    /// # Errors
    /// As [`IterationOptions::validate`] and [`Adam::new`].
    pub fn new(
        initial: ParamTable,
        params: &[ParamId],
        adam: AdamOptions,
        options: IterationOptions,
    ) -> Result<Optimization> {
        let adam = Adam::new(&initial, params, adam)?;
        Optimization::resume(initial, adam, 0, options)
    }

    /// A run that continues at iteration `iteration` with `params` and `adam` (as saved from
    /// [`Optimization::params`], [`Optimization::adam`] and [`Optimization::iteration`]).
    ///
    /// # Errors
    /// As [`IterationOptions::validate`].
    pub fn resume(params: ParamTable, adam: Adam, iteration: u64, options: IterationOptions) -> Result<Optimization> {
        options.validate()?;
        Ok(Optimization {
            options,
            params,
            adam,
            iteration,
            prior: None,
            control: ControlVariates::default(),
            pending: None,
            reuse: GradientReuse::default(),
            pending_reuse: None,
            hero: None,
        })
    }

    /// The same run with its hero probabilities adapted to each target's gradient variance
    /// (ALGORITHMS.md §5.8, [`HeroAdaptation`]), continuing from `state` (a fresh run:
    /// [`HeroAdaptation::new`]). The next iteration's probabilities are `state`'s; every
    /// [`Optimization::apply`] observes the step's gradients and sets those of the one after.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `Optimization::with_hero_adaptation` if the run's strategy
    /// is not [`crate::integrator::Strategy::Hero`] or a hero target is not optimised (its gradient is not
    /// computed), and as [`HeroAdaptation::check`].
    pub fn with_hero_adaptation(mut self, state: HeroAdaptation) -> Result<Optimization> {
        let crate::integrator::Strategy::Hero { heroes, q } = self.options.render.strategy else {
            return Err(Error::InvalidArgument {
                parameter: "Optimization::with_hero_adaptation".into(),
                message: "the run's strategy has no hero set (Strategy::Hero)".into(),
            });
        };
        if let Some(t) = heroes.targets().iter().find(|t| !self.adam.params().contains(t)) {
            return Err(Error::InvalidArgument {
                parameter: "Optimization::with_hero_adaptation".into(),
                message: format!(
                    "hero target {} is not optimised, so its gradient variance is unknown (fix its weight instead)",
                    self.params.entry(*t).name
                ),
            });
        }
        state.check(&heroes)?;
        let heroes = heroes.with_weights(&state.weights())?;
        self.options.render.strategy = crate::integrator::Strategy::Hero { heroes, q };
        self.hero = Some(state);
        Ok(self)
    }

    /// The hero probabilities' running state, with [`Optimization::with_hero_adaptation`].
    pub fn hero_adaptation(&self) -> Option<&HeroAdaptation> {
        self.hero.as_ref()
    }

    /// The same run continuing from the control variates' state `control` (as saved from
    /// [`Optimization::control_variates`] after the same iteration).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `IterationOptions::control_variates` if the run has no
    /// control variates, "control-variate state" if `control` has one of its parts but not the
    /// other, a size other than the render's, a step count other than the iteration count, or
    /// parameters of another layout.
    pub fn with_control_variates(self, control: ControlVariates) -> Result<Optimization> {
        let bad = |p: &str, m: String| Err(Error::InvalidArgument { parameter: p.into(), message: m });
        if self.options.control_variates.is_none() {
            return bad("IterationOptions::control_variates", "the run has none, so it takes no state".into());
        }
        match (&control.state, &control.previous) {
            (None, None) => {}
            (Some(state), Some(previous)) => {
                state.check(self.options.render.width, self.options.render.height, state.views)?;
                if state.running.steps != self.iteration {
                    return bad(
                        "control-variate state",
                        format!("has {} steps but the run is at iteration {}", state.running.steps, self.iteration),
                    );
                }
                if previous.entries() != self.params.entries() {
                    return bad("control-variate state", "its parameters have another layout than the run's".into());
                }
            }
            _ => {
                return bad(
                    "control-variate state",
                    "has an estimate without parameters or parameters without one".into(),
                );
            }
        }
        Ok(Optimization { control, pending: None, ..self })
    }

    /// The control variates' committed state (empty without control variates or before the first
    /// iteration).
    pub fn control_variates(&self) -> &ControlVariates {
        &self.control
    }

    /// The same run continuing from gradient reuse's state `reuse` (as saved from
    /// [`Optimization::gradient_reuse`] after the same iteration).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `IterationOptions::gradient_reuse` if the run has no
    /// gradient reuse, "gradient-reuse state" if `reuse` has one of its parts but not the other, a
    /// number of values other than the run optimises, a step count other than the iteration
    /// count, or parameters of another layout.
    pub fn with_gradient_reuse(self, reuse: GradientReuse) -> Result<Optimization> {
        let bad = |p: &str, m: String| Err(Error::InvalidArgument { parameter: p.into(), message: m });
        if self.options.gradient_reuse.is_none() {
            return bad("IterationOptions::gradient_reuse", "the run has none, so it takes no state".into());
        }
        match (&reuse.state, &reuse.previous) {
            (None, None) => {}
            (Some(state), Some(previous)) => {
                let values: usize = self.adam.params().iter().map(|&p| self.params.entry(p).len as usize).sum();
                state.check(values, "gradient-reuse state")?;
                if state.steps != self.iteration {
                    return bad(
                        "gradient-reuse state",
                        format!("has {} steps but the run is at iteration {}", state.steps, self.iteration),
                    );
                }
                if previous.entries() != self.params.entries() {
                    return bad("gradient-reuse state", "its parameters have another layout than the run's".into());
                }
            }
            _ => {
                return bad(
                    "gradient-reuse state",
                    "has an estimate without parameters or parameters without one".into(),
                );
            }
        }
        Ok(Optimization { reuse, pending_reuse: None, ..self })
    }

    /// Gradient reuse's committed state (empty without gradient reuse or before the first
    /// iteration).
    pub fn gradient_reuse(&self) -> &GradientReuse {
        &self.reuse
    }

    /// The same run with `prior` added to the objective: every gradient from now on includes its
    /// gradient ([`Smoothness::add_gradient`]); the losses reported stay the images' losses.
    pub fn with_prior(self, prior: Smoothness) -> Optimization {
        Optimization { prior: Some(prior), ..self }
    }

    /// The prior added to the objective, if any.
    pub fn prior(&self) -> Option<&Smoothness> {
        self.prior.as_ref()
    }

    /// The current parameter values.
    pub fn params(&self) -> &ParamTable {
        &self.params
    }

    /// The optimiser and its state.
    pub fn adam(&self) -> &Adam {
        &self.adam
    }

    /// The number of iterations done; the next one has this index.
    pub fn iteration(&self) -> u64 {
        self.iteration
    }

    /// The iteration options.
    pub fn options(&self) -> &IterationOptions {
        &self.options
    }

    /// The loss and its gradient at the current parameters with the seed of the next iteration:
    /// uploads the parameters to `renderer`, renders pass 1, and runs the gradient pass (uniform
    /// or adaptive). Changes neither the parameters nor Adam; [`Optimization::apply`] takes the
    /// step. With control variates it also renders pass 1 at the previous iteration's parameters
    /// and holds the new running estimate until [`Optimization::apply`] commits it (calling this
    /// again before then recomputes the same estimate). With gradient reuse it also takes the
    /// gradient at the previous iteration's parameters (first, so the current ones stay on
    /// `renderer`) and returns the running gradient estimate, held the same way.
    ///
    /// # Errors
    /// Those of [`Backend::set_params`], [`Backend::loss_and_gradient_split`] and
    /// [`Backend::loss_and_gradient_adaptive`] (a target of the wrong size, Vulkan failures).
    pub fn gradient(&mut self, backend: &mut dyn Backend, target: &Image) -> Result<(f64, Gradients)> {
        let view = View::current(backend.scene());
        self.gradient_views(backend, &[view], std::slice::from_ref(target))
    }

    /// [`Optimization::gradient`] of the mean loss over `views`, view v against `targets[v]`:
    /// every view in each pass of one step ([`Backend::loss_and_gradient_views`]). With a prior
    /// ([`Optimization::with_prior`]) the gradient includes the prior's; the loss does not.
    ///
    /// # Errors
    /// As [`Optimization::gradient`]; targets not one per view; with control variates, another
    /// number of views than the run's earlier iterations had.
    pub fn gradient_views(
        &mut self,
        backend: &mut dyn Backend,
        views: &[View],
        targets: &[Image],
    ) -> Result<(f64, Gradients)> {
        let o = self.options;
        let render = o.at(self.iteration);
        let (loss, gradients) = match (o.control_variates, o.gradient_reuse) {
            (None, None) => self.plain_gradient(backend, &self.params, &render, views, targets)?,
            (Some(cv), _) => {
                backend.prepare_gradient(&render, o.spp_primal, o.mode, o.adaptive.is_some())?;
                let (loss, adjoints, state) = self.control_variate_pass1(backend, &cv, &render, views, targets)?;
                self.pending = Some((self.iteration, state));
                let sum = match o.adaptive {
                    None => backend.backward_views(&render, views, &adjoints, o.mode)?,
                    Some(estimator) => {
                        if adjoints.iter().all(|a| a.as_slice().iter().all(|&v| v == 0.0)) {
                            let n = self.params.values().len();
                            Gradients::new(&self.params, vec![0.0; n])
                        } else {
                            let sampling = PixelSampling::from_adjoint(&Image::stack(&adjoints)?, estimator)?;
                            backend.backward_adaptive_views(&render, views, &adjoints, &sampling, o.mode)?
                        }
                    }
                };
                (loss, Gradients::sum_divided(&[sum], views.len())?)
            }
            (None, Some(reuse)) => {
                // H at the previous parameters first, so that the current ones stay on the backend.
                let h = match &self.reuse.previous {
                    Some(previous) => Some(self.plain_gradient(backend, previous, &render, views, targets)?.1),
                    None => None,
                };
                let (loss, g) = self.plain_gradient(backend, &self.params, &render, views, targets)?;
                let (f, state) = gradient_reuse::step(
                    &reuse,
                    self.reuse.state.as_ref(),
                    &self.params,
                    self.adam.params(),
                    &g,
                    h.as_ref(),
                )?;
                self.pending_reuse = Some((self.iteration, state));
                (loss, f)
            }
        };
        match &self.prior {
            None => Ok((loss, gradients)),
            Some(prior) => Ok((loss, prior.add_gradient(&self.params, &gradients)?)),
        }
    }

    /// The plain step's loss and gradient at `params` with the render options `render`: pass 1,
    /// then the gradient pass (uniform or adaptive). Leaves `params` on `backend`.
    fn plain_gradient(
        &self,
        backend: &mut dyn Backend,
        params: &ParamTable,
        render: &RenderOptions,
        views: &[View],
        targets: &[Image],
    ) -> Result<(f64, Gradients)> {
        let o = &self.options;
        backend.set_params(params)?;
        match o.adaptive {
            None => backend.loss_and_gradient_views(render, o.spp_primal, views, targets, o.loss, o.mode),
            Some(estimator) => {
                let adaptive = AdaptiveOptions { spp_primal: o.spp_primal, estimator };
                backend.loss_and_gradient_views_adaptive(render, &adaptive, views, targets, o.loss, o.mode)
            }
        }
    }

    /// Pass 1 with control variates: H_i at the previous parameters (after the first iteration)
    /// and G_i at the current ones, both with the iteration's seed and pass 1's estimator, the
    /// running estimate F_i, and each view's loss and adjoint image at F_i. Leaves the current
    /// parameters on `backend`. Returns the mean loss, the adjoints and the new state.
    fn control_variate_pass1(
        &self,
        backend: &mut dyn Backend,
        cv: &ControlVariateOptions,
        render: &RenderOptions,
        views: &[View],
        targets: &[Image],
    ) -> Result<(f64, Vec<Image>, ControlVariateState)> {
        let o = &self.options;
        let pass1 = render.loss_pass(o.spp_primal)?;
        render.validate()?;
        check_views(views, targets, render, "target image")?;
        // Pass 1 as the plain step renders it: with the gradient kernel for uniform sampling,
        // with the render kernel for adaptive sampling (Backend::loss_and_gradient_views{,_adaptive}).
        let kernel = if o.adaptive.is_none() { Some(o.mode) } else { None };
        let mut state = match &self.control.state {
            Some(state) => state.clone(),
            None => ControlVariateState::new(render.width, render.height, views.len() as u32),
        };
        let h = match &self.control.previous {
            Some(previous) => {
                backend.set_params(previous)?;
                Some(backend.render_loss_pass(render, &pass1, views, kernel)?)
            }
            None => None,
        };
        backend.set_params(&self.params)?;
        let g = backend.render_loss_pass(render, &pass1, views, kernel)?;
        let estimates = state.step(cv, &g, h.as_deref()).map_err(|e| match e {
            Error::InvalidArgument { parameter, message } if parameter == "G" || parameter == "H" => {
                Error::InvalidArgument {
                    parameter: "views".into(),
                    message: format!("with control variates every iteration has the same views: {message}"),
                }
            }
            e => e,
        })?;
        let mut total = 0.0;
        let mut adjoints = Vec::with_capacity(views.len());
        for (f, target) in estimates.iter().zip(targets) {
            let (loss, adjoint) = loss_and_adjoint(f, target, o.loss)?;
            total += loss;
            adjoints.push(adjoint);
        }
        Ok((total / views.len() as f64, adjoints, state))
    }

    /// Takes the Adam step of the next iteration with `gradients` (whose pass-1 loss was `loss`)
    /// and counts the iteration; with control variates, commits the running estimate that
    /// [`Optimization::gradient_views`] computed for this iteration.
    ///
    /// # Errors
    /// [`Error::NonFiniteGradient`] (nothing changes, the iteration is not counted) and the
    /// other errors of [`Adam::step`]; [`Error::InvalidArgument`] naming
    /// `Optimization::apply` with control variates when no gradient of this iteration was taken.
    pub fn apply(&mut self, loss: f64, gradients: &Gradients) -> Result<StepReport> {
        let iteration = self.iteration;
        let missing = |what: &str| {
            Err(Error::InvalidArgument {
                parameter: "Optimization::apply".into(),
                message: format!(
                    "with {what}, iteration {iteration} needs its gradient (Optimization::gradient) first"
                ),
            })
        };
        let committed = match (self.options.control_variates, &self.pending) {
            (None, _) => None,
            (Some(_), Some((at, state))) if *at == iteration => Some(state.clone()),
            (Some(_), _) => return missing("control variates"),
        };
        let reused = match (self.options.gradient_reuse, &self.pending_reuse) {
            (None, _) => None,
            (Some(_), Some((at, state))) if *at == iteration => Some(state.clone()),
            (Some(_), _) => return missing("gradient reuse"),
        };
        let before = (committed.is_some() || reused.is_some()).then(|| self.params.clone());
        self.adam.step(&mut self.params, gradients, iteration)?;
        if let Some(state) = committed {
            self.control = ControlVariates { state: Some(state), previous: before.clone() };
            self.pending = None;
        }
        if let Some(state) = reused {
            self.reuse = GradientReuse { state: Some(state), previous: before };
            self.pending_reuse = None;
        }
        if let (Some(state), crate::integrator::Strategy::Hero { heroes, q }) =
            (&mut self.hero, self.options.render.strategy)
        {
            state.observe(&heroes, &self.params, gradients);
            let heroes = heroes.with_weights(&state.weights())?;
            self.options.render.strategy = crate::integrator::Strategy::Hero { heroes, q };
        }
        self.iteration += 1;
        let mut norm2 = 0.0;
        for &p in self.adam.params() {
            let e = self.params.entry(p);
            norm2 += gradients.values()[e.offset as usize..(e.offset + e.len) as usize]
                .iter()
                .map(|&g| f64::from(g).powi(2))
                .sum::<f64>();
        }
        Ok(StepReport { iteration, loss, gradient_norm: norm2.sqrt() })
    }

    /// One iteration: [`Optimization::gradient`], then [`Optimization::apply`].
    ///
    /// # Errors
    /// As those two.
    pub fn step(&mut self, backend: &mut dyn Backend, target: &Image) -> Result<StepReport> {
        let (loss, gradients) = self.gradient(backend, target)?;
        self.apply(loss, &gradients)
    }

    /// One iteration over several views: [`Optimization::gradient_views`], then
    /// [`Optimization::apply`].
    ///
    /// # Errors
    /// As those two.
    pub fn step_views(&mut self, backend: &mut dyn Backend, views: &[View], targets: &[Image]) -> Result<StepReport> {
        let (loss, gradients) = self.gradient_views(backend, views, targets)?;
        self.apply(loss, &gradients)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(control_variates: Option<ControlVariateOptions>) -> Optimization {
        let mut table = ParamTable::default();
        let w = table.add("object.weight.value", &[0.5], (0.0, 1.0)).unwrap();
        let scene = crate::scene::builtin::load("blend").unwrap();
        let render = RenderOptions { width: 4, height: 3, spp: 1, ..RenderOptions::for_scene(&scene) };
        let options = IterationOptions {
            render,
            spp_primal: 1,
            adaptive: None,
            loss: Loss::L2,
            mode: GradMode::Float,
            control_variates,
            gradient_reuse: None,
        };
        Optimization::new(table, &[w], AdamOptions::default(), options).unwrap()
    }

    /// With control variates a step commits the estimate its gradient computed: `apply` without
    /// a gradient of this iteration is refused by name and changes nothing; a state is refused by
    /// a run without control variates, and one whose step count is not the run's iteration.
    #[test]
    fn control_variate_states_are_refused_where_they_cannot_apply() {
        let mut cv = run(Some(ControlVariateOptions::default()));
        let g = Gradients::new(cv.params(), vec![1.0]);
        let e = cv.apply(0.0, &g).unwrap_err().to_string();
        assert!(e.contains("Optimization::apply") && e.contains("iteration 0 needs its gradient"), "{e}");
        assert_eq!((cv.iteration(), cv.params().values()), (0, &[0.5][..]));
        // Without control variates the same call steps.
        let mut plain = run(None);
        plain.apply(0.0, &g).unwrap();
        let state = ControlVariateState::new(4, 3, 1);
        let control = ControlVariates { state: Some(state.clone()), previous: Some(plain.params().clone()) };
        let e = plain.clone().with_control_variates(control.clone()).unwrap_err().to_string();
        assert!(e.contains("IterationOptions::control_variates"), "{e}");
        // A fresh state (0 steps) for a run at iteration 0 is accepted; at another iteration not.
        let fresh = run(Some(ControlVariateOptions::default()));
        fresh.clone().with_control_variates(control.clone()).unwrap();
        let later = Optimization { iteration: 3, ..fresh.clone() };
        let e = later.with_control_variates(control.clone()).unwrap_err().to_string();
        assert!(e.contains("control-variate state") && e.contains("0 steps") && e.contains("iteration 3"), "{e}");
        let half = ControlVariates { state: Some(state), previous: None };
        assert!(fresh.clone().with_control_variates(half).unwrap_err().to_string().contains("without parameters"));
        let wrong_size = ControlVariates { state: Some(ControlVariateState::new(5, 3, 1)), ..control };
        assert!(fresh.with_control_variates(wrong_size).unwrap_err().to_string().contains("5×3"));
        let bad = IterationOptions {
            control_variates: Some(ControlVariateOptions { beta1: 1.0, beta2: 0.999 }),
            gradient_reuse: None,
            ..*run(None).options()
        };
        let e = Optimization::resume(run(None).params().clone(), run(None).adam().clone(), 0, bad).unwrap_err();
        assert!(e.to_string().contains("ControlVariateOptions::beta1"), "{e}");
    }

    #[test]
    fn parameter_error_is_the_relative_squared_error() {
        assert_eq!(parameter_error(&[0.4], &[0.4]), 0.0);
        // Averaged over the values: ((0.5 − 0.25)/0.251)² and 0.
        let e = parameter_error(&[0.5, 0.1], &[0.25, 0.1]);
        assert!((e - 0.5 * (0.25f64 / 0.251).powi(2)).abs() < 1e-7, "{e}");
        // A true value of 0 divides by ε.
        assert!((parameter_error(&[0.01], &[0.0]) - 100.0).abs() < 1e-3);
    }
}

//! One interface over the GPU renderer and the CPU reference, and the loss-step protocol written
//! once against it.
//!
//! [`Backend`] is what both [`crate::gpu::Renderer`] and [`crate::cpu::Reference`] do: render
//! (under the primal or the reference key), reverse-mode gradients of an adjoint image (uniform
//! or with adaptive pixel sampling), forward-mode image gradients, and new parameter values. The
//! provided methods — a gradient step's pass 1 and its loss, the split and adaptive loss
//! gradients — are the protocol (ALGORITHMS.md §3.4, §6); `optim`, `variance` and the CLI use
//! nothing else, so every tool runs on either backend.
//!
//! ```no_run
//! use pathgrad::backend::Backend;
//! use pathgrad::integrator::RenderOptions;
//! use pathgrad::loss::Loss;
//! use pathgrad::gpu::renderer::GradMode;
//!
//! fn loss_gradient(backend: &mut dyn Backend, target: &pathgrad::image::Image) -> pathgrad::Result<f64> {
//!     let options = RenderOptions { spp: 4, ..RenderOptions::for_scene(backend.scene()) };
//!     let (loss, _gradients) = backend.loss_and_gradient(&options, target, Loss::RelMse, GradMode::Float)?;
//!     Ok(loss)
//! }
//! let scene = pathgrad::scene::builtin::load("cornell-box")?;
//! let mut cpu = pathgrad::cpu::Reference::new(&scene)?;
//! let target = cpu.render(&RenderOptions { spp: 4, ..RenderOptions::for_scene(&scene) })?;
//! println!("{}", loss_gradient(&mut cpu, &target)?);
//! # Ok::<(), pathgrad::Error>(())
//! ```

use crate::adaptive::{AdaptiveOptions, PixelSampling};
use crate::error::{Error, Result};
use crate::gpu::renderer::GradMode;
use crate::image::Image;
use crate::integrator::{ParamKinds, RenderOptions, View};
use crate::loss::{Loss, loss_and_adjoint};
use crate::params::{Gradients, ParamId, ParamTable};
use crate::rng::PassTag;
use crate::scene::Scene;

/// Renders and differentiates one scene: the GPU renderer or the CPU reference.
pub trait Backend {
    /// The scene, with the parameter values last set.
    fn scene(&self) -> &Scene;

    /// Which backend this is, for messages: the device's name or `CPU reference`.
    fn describe(&self) -> String;

    /// Replaces the parameter values (same table layout).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] if the layout differs; backend failures.
    fn set_params(&mut self, params: &ParamTable) -> Result<()>;

    /// Renders `views` (at least one) with `options` under the key of `pass` (primal for images
    /// and pass 1, reference for targets), all in one pass over the device: one image per view.
    /// `progress(samples_done, spp)` hears how far it is.
    ///
    /// # Errors
    /// Option errors, no views; backend failures.
    fn render_views(
        &mut self,
        options: &RenderOptions,
        views: &[View],
        pass: PassTag,
        progress: &mut dyn FnMut(u32, u32),
    ) -> Result<Vec<Image>>;

    /// Reverse-mode gradient of Σ_v ⟨A_v, I_v⟩ over `views`, where `adjoints[v]` is A_v
    /// (∂loss/∂pixel of view v's image): every view's paths in one pass, into one gradient.
    ///
    /// Under detached sampling (`options.sampling`), the parameters that act only through the
    /// sampled directions ([`crate::attached::attached_only_params`]: a dielectric's `eta`) get 0:
    /// [`crate::attached::differentiated`] says which of a selection a sampling differentiates, and
    /// refuses such a parameter by name, as the program's `--param` and Python's `wrt` do.
    ///
    /// # Errors
    /// Option errors, an adjoint of the wrong size or count, a mode the backend cannot do;
    /// backend failures.
    fn backward_views(
        &mut self,
        options: &RenderOptions,
        views: &[View],
        adjoints: &[Image],
        mode: GradMode,
    ) -> Result<Gradients>;

    /// [`Backend::backward_views`] with loss-aware adaptive pixel sampling over every view's
    /// pixels: `sampling` is for the views' adjoint images stacked top to bottom
    /// ([`Image::stack`]); W·H·spp samples per view are drawn in all.
    ///
    /// # Errors
    /// As [`Backend::backward_views`]; a sampling of another size.
    fn backward_adaptive_views(
        &mut self,
        options: &RenderOptions,
        views: &[View],
        adjoints: &[Image],
        sampling: &PixelSampling,
        mode: GradMode,
    ) -> Result<Gradients>;

    /// The kinds of the parameters `ids` (for [`RenderOptions::differentiate`]: a GPU kernel then
    /// compiles only their derivative code; the CPU reference computes every kind anyway).
    fn param_kinds(&self, ids: &[ParamId]) -> ParamKinds;

    /// Forward-mode image gradient ∂I/∂θ by the parameter `name` (with attached sampling,
    /// `options.sampling`, three fused passes: one per colour channel).
    ///
    /// # Errors
    /// An unknown parameter; an index of refraction under detached sampling, which does not
    /// differentiate it; as [`Backend::backward`].
    fn image_gradient(&mut self, options: &RenderOptions, name: &str) -> Result<Image>;

    /// Renders the scene's camera ([`View::current`]) with `options` under the key of `pass`.
    ///
    /// # Errors
    /// As [`Backend::render_views`].
    fn render_pass(
        &mut self,
        options: &RenderOptions,
        pass: PassTag,
        progress: &mut dyn FnMut(u32, u32),
    ) -> Result<Image> {
        let view = View::current(self.scene());
        Ok(self.render_views(options, &[view], pass, progress)?.remove(0))
    }

    /// Reverse-mode gradient of a loss whose adjoint image (∂loss/∂pixel) of the scene's camera
    /// is `adjoint`.
    ///
    /// # Errors
    /// As [`Backend::backward_views`].
    fn backward(&mut self, options: &RenderOptions, adjoint: &Image, mode: GradMode) -> Result<Gradients> {
        let view = View::current(self.scene());
        self.backward_views(options, &[view], std::slice::from_ref(adjoint), mode)
    }

    /// Reverse-mode gradient of the scene's camera with adaptive pixel sampling drawn from
    /// `sampling`.
    ///
    /// # Errors
    /// As [`Backend::backward_adaptive_views`].
    fn backward_adaptive(
        &mut self,
        options: &RenderOptions,
        adjoint: &Image,
        sampling: &PixelSampling,
        mode: GradMode,
    ) -> Result<Gradients> {
        let view = View::current(self.scene());
        self.backward_adaptive_views(options, &[view], std::slice::from_ref(adjoint), sampling, mode)
    }

    /// Renders with `options` (the primal key).
    ///
    /// # Errors
    /// As [`Backend::render_pass`].
    fn render(&mut self, options: &RenderOptions) -> Result<Image> {
        self.render_pass(options, PassTag::Primal, &mut |_, _| {})
    }

    /// Renders a reference (a target) under the reference key, whose paths no render, loss image
    /// or gradient pass of any seed replays (ALGORITHMS.md §2.3).
    ///
    /// # Errors
    /// As [`Backend::render_pass`].
    fn render_reference(&mut self, options: &RenderOptions) -> Result<Image> {
        self.render_pass(options, PassTag::Reference, &mut |_, _| {})
    }

    /// Gets ready for gradient steps of `options` with a pass 1 of `spp_primal` spp, in `mode`,
    /// with adaptive pixel sampling or not: a backend that compiles kernels builds the kernels of
    /// both passes now (side by side, or one serving both), rather than one after the other on
    /// first use.
    /// The loss-and-gradient calls below call it; calling it again costs nothing. The default
    /// does nothing.
    ///
    /// # Errors
    /// Option errors; kernel builds that fail.
    fn prepare_gradient(
        &mut self,
        options: &RenderOptions,
        spp_primal: u32,
        mode: GradMode,
        adaptive: bool,
    ) -> Result<()> {
        let _ = (options, spp_primal, mode, adaptive);
        Ok(())
    }

    /// Renders `pass1` (a [`RenderOptions::loss_pass`]) of `views` under the primal key: the
    /// image of [`Backend::loss_images`]. With `gradient`, it is pass 1 of a gradient step of
    /// `options` in that mode, and a backend may render it with that step's gradient kernel (the
    /// GPU does where the kernel's features are pass 1's, so that a first step builds one kernel,
    /// not two): the same estimator, paths and random numbers. The default renders
    /// [`Backend::render_views`].
    ///
    /// # Errors
    /// As [`Backend::render_views`].
    fn render_loss_pass(
        &mut self,
        options: &RenderOptions,
        pass1: &RenderOptions,
        views: &[View],
        gradient: Option<GradMode>,
    ) -> Result<Vec<Image>> {
        let _ = (options, gradient);
        self.render_views(pass1, views, PassTag::Primal, &mut |_, _| {})
    }

    /// Pass 1 of a gradient step: renders [`RenderOptions::loss_pass`] (`spp_primal` spp, plain
    /// BSDF sampling with NEE, the primal key) and returns its loss against `target` and the
    /// adjoint image ∂loss/∂I, computed on the host.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for `spp_primal` = 0 or a target of the wrong size; as
    /// [`Backend::render_pass`].
    fn loss_image(
        &mut self,
        options: &RenderOptions,
        spp_primal: u32,
        target: &Image,
        loss: Loss,
    ) -> Result<(f64, Image)> {
        let view = View::current(self.scene());
        let (mut losses, mut adjoints) =
            self.loss_images(options, spp_primal, &[view], std::slice::from_ref(target), loss)?;
        Ok((losses.remove(0), adjoints.remove(0)))
    }

    /// Pass 1 of a multi-view step: renders every view of `views` with
    /// [`RenderOptions::loss_pass`] in one pass and returns each view's loss against its target
    /// and its adjoint image ∂loss_v/∂I_v.
    ///
    /// # Errors
    /// As [`Backend::loss_image`]; a number of targets other than of views.
    fn loss_images(
        &mut self,
        options: &RenderOptions,
        spp_primal: u32,
        views: &[View],
        targets: &[Image],
        loss: Loss,
    ) -> Result<(Vec<f64>, Vec<Image>)> {
        pass1_losses(self, options, spp_primal, views, targets, loss, None)
    }

    /// The loss of a render against `target` and its gradient: pass 1 ([`Backend::loss_image`])
    /// with `spp_primal` spp, then the fused gradient pass with `options.spp` on independent paths.
    /// `options.strategy` and `options.nee` apply to the gradient pass.
    ///
    /// # Errors
    /// As [`Backend::loss_image`] and [`Backend::backward`].
    fn loss_and_gradient_split(
        &mut self,
        options: &RenderOptions,
        spp_primal: u32,
        target: &Image,
        loss: Loss,
        mode: GradMode,
    ) -> Result<(f64, Gradients)> {
        let view = View::current(self.scene());
        self.loss_and_gradient_views(options, spp_primal, &[view], std::slice::from_ref(target), loss, mode)
    }

    /// The mean of the views' losses, each view against its target, and its gradient: pass 1 of
    /// every view in one pass, then one fused gradient pass over every view
    /// ([`Backend::backward_views`]) divided by the number of views as [`Gradients::mean`]
    /// divides, so that it equals the mean of the views' single-view gradients (bit for bit in
    /// deterministic mode, where the views' paths are the same as alone: [`View`]).
    ///
    /// # Errors
    /// As [`Backend::loss_images`] and [`Backend::backward_views`].
    fn loss_and_gradient_views(
        &mut self,
        options: &RenderOptions,
        spp_primal: u32,
        views: &[View],
        targets: &[Image],
        loss: Loss,
        mode: GradMode,
    ) -> Result<(f64, Gradients)> {
        self.prepare_gradient(options, spp_primal, mode, false)?;
        let (losses, adjoints) = pass1_losses(self, options, spp_primal, views, targets, loss, Some(mode))?;
        let sum = self.backward_views(options, views, &adjoints, mode)?;
        Ok((mean(&losses), Gradients::sum_divided(&[sum], views.len())?))
    }

    /// [`Backend::loss_and_gradient_split`] with `options.spp` for both passes.
    ///
    /// # Errors
    /// As [`Backend::loss_and_gradient_split`].
    fn loss_and_gradient(
        &mut self,
        options: &RenderOptions,
        target: &Image,
        loss: Loss,
        mode: GradMode,
    ) -> Result<(f64, Gradients)> {
        self.loss_and_gradient_split(options, options.spp, target, loss, mode)
    }

    /// The loss and its gradient with loss-aware adaptive pixel sampling (Su & Gkioulekas'
    /// Algorithm 2): pass 1 with `adaptive.spp_primal` spp gives the adjoint image A; the pixel
    /// weights are π_p ∝ Σ_c |A_pc|; the gradient pass draws N = W·H·`options.spp` samples from
    /// them. If A is zero everywhere the gradient is exactly zero, without a gradient pass.
    ///
    /// # Errors
    /// As [`Backend::loss_and_gradient`] and [`Backend::backward_adaptive`]; a non-finite adjoint value.
    fn loss_and_gradient_adaptive(
        &mut self,
        options: &RenderOptions,
        adaptive: &AdaptiveOptions,
        target: &Image,
        loss: Loss,
        mode: GradMode,
    ) -> Result<(f64, Gradients)> {
        let view = View::current(self.scene());
        self.loss_and_gradient_views_adaptive(options, adaptive, &[view], std::slice::from_ref(target), loss, mode)
    }

    /// [`Backend::loss_and_gradient_views`] with adaptive pixel sampling over every view's pixels:
    /// the weights π come from all views' adjoint images together, so views where the loss is
    /// larger get more of the V·W·H·`options.spp` samples.
    ///
    /// # Errors
    /// As [`Backend::loss_and_gradient_views`] and [`Backend::backward_adaptive_views`].
    fn loss_and_gradient_views_adaptive(
        &mut self,
        options: &RenderOptions,
        adaptive: &AdaptiveOptions,
        views: &[View],
        targets: &[Image],
        loss: Loss,
        mode: GradMode,
    ) -> Result<(f64, Gradients)> {
        self.prepare_gradient(options, adaptive.spp_primal, mode, true)?;
        let (losses, adjoints) = self.loss_images(options, adaptive.spp_primal, views, targets, loss)?;
        if adjoints.iter().all(|a| a.as_slice().iter().all(|&v| v == 0.0)) {
            let n = self.scene().params.values().len();
            return Ok((mean(&losses), Gradients::new(&self.scene().params, vec![0.0; n])));
        }
        let sampling = PixelSampling::from_adjoint(&Image::stack(&adjoints)?, adaptive.estimator)?;
        let sum = self.backward_adaptive_views(options, views, &adjoints, &sampling, mode)?;
        Ok((mean(&losses), Gradients::sum_divided(&[sum], views.len())?))
    }
}

/// [`Backend::loss_images`], rendered as pass 1 of a gradient step in `gradient`'s mode if given
/// ([`Backend::render_loss_pass`]).
fn pass1_losses<B: Backend + ?Sized>(
    backend: &mut B,
    options: &RenderOptions,
    spp_primal: u32,
    views: &[View],
    targets: &[Image],
    loss: Loss,
    gradient: Option<GradMode>,
) -> Result<(Vec<f64>, Vec<Image>)> {
    let pass1 = options.loss_pass(spp_primal)?;
    options.validate()?;
    check_views(views, targets, options, "target image")?;
    let images = backend.render_loss_pass(options, &pass1, views, gradient)?;
    let mut losses = Vec::with_capacity(views.len());
    let mut adjoints = Vec::with_capacity(views.len());
    for (image, target) in images.iter().zip(targets) {
        let (value, adjoint) = loss_and_adjoint(image, target, loss)?;
        losses.push(value);
        adjoints.push(adjoint);
    }
    Ok((losses, adjoints))
}

/// The mean of per-view losses, summed in view order.
fn mean(losses: &[f64]) -> f64 {
    losses.iter().sum::<f64>() / losses.len() as f64
}

/// Refuses a bad list of views ([`check_view_list`]), or `images` (targets or adjoints) that are
/// not one per view at the render's size.
pub(crate) fn check_views(views: &[View], images: &[Image], options: &RenderOptions, what: &str) -> Result<()> {
    check_view_list(views)?;
    if images.len() != views.len() {
        return Err(Error::InvalidArgument {
            parameter: what.to_string(),
            message: format!("{} given for {} views", images.len(), views.len()),
        });
    }
    images.iter().try_for_each(|image| check_size(image, options, what))
}

/// Refuses an empty list of views or a stream past 2²⁴.
pub(crate) fn check_view_list(views: &[View]) -> Result<()> {
    if views.is_empty() {
        return Err(Error::InvalidArgument {
            parameter: "views".into(),
            message: "at least one view is needed".into(),
        });
    }
    if let Some(v) = views.iter().find(|v| v.stream >= 1 << 24) {
        return Err(Error::InvalidArgument {
            parameter: "View::stream".into(),
            message: format!("{} is not below 2^24", v.stream),
        });
    }
    Ok(())
}

/// Refuses an image whose size is not the render's.
pub(crate) fn check_size(image: &Image, options: &RenderOptions, what: &str) -> Result<()> {
    if (image.width(), image.height()) != (options.width, options.height) {
        return Err(Error::InvalidArgument {
            parameter: what.to_string(),
            message: format!(
                "is {}×{} but the render is {}×{}",
                image.width(),
                image.height(),
                options.width,
                options.height
            ),
        });
    }
    Ok(())
}

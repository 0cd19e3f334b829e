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
use crate::integrator::{ParamKinds, RenderOptions};
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

    /// Renders with `options` under the key of `pass` (primal for images and pass 1, reference
    /// for targets), calling `progress(samples_done, spp)` as it goes.
    ///
    /// # Errors
    /// Option errors; backend failures.
    fn render_pass(
        &mut self,
        options: &RenderOptions,
        pass: PassTag,
        progress: &mut dyn FnMut(u32, u32),
    ) -> Result<Image>;

    /// Reverse-mode gradient of a loss whose adjoint image (∂loss/∂pixel) is `adjoint`.
    ///
    /// # Errors
    /// Option errors, an adjoint of the wrong size, a mode the backend cannot do; backend failures.
    fn backward(&mut self, options: &RenderOptions, adjoint: &Image, mode: GradMode) -> Result<Gradients>;

    /// Reverse-mode gradient with loss-aware adaptive pixel sampling drawn from `sampling`.
    ///
    /// # Errors
    /// As [`Backend::backward`]; a sampling of another size.
    fn backward_adaptive(
        &mut self,
        options: &RenderOptions,
        adjoint: &Image,
        sampling: &PixelSampling,
        mode: GradMode,
    ) -> Result<Gradients>;

    /// The kinds of the parameters `ids` (for [`RenderOptions::differentiate`]: a GPU kernel then
    /// compiles only their derivative code; the CPU reference computes every kind anyway).
    fn param_kinds(&self, ids: &[ParamId]) -> ParamKinds;

    /// Forward-mode image gradient ∂I/∂θ by the parameter `name`.
    ///
    /// # Errors
    /// An unknown parameter; as [`Backend::backward`].
    fn image_gradient(&mut self, options: &RenderOptions, name: &str) -> Result<Image>;

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
        let pass1 = options.loss_pass(spp_primal)?;
        options.validate()?;
        check_size(target, options, "target image")?;
        let image = self.render(&pass1)?;
        loss_and_adjoint(&image, target, loss)
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
        let (value, adjoint) = self.loss_image(options, spp_primal, target, loss)?;
        Ok((value, self.backward(options, &adjoint, mode)?))
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
        let (value, adjoint) = self.loss_image(options, adaptive.spp_primal, target, loss)?;
        if adjoint.as_slice().iter().all(|&a| a == 0.0) {
            let n = self.scene().params.values().len();
            return Ok((value, Gradients::new(&self.scene().params, vec![0.0; n])));
        }
        let sampling = PixelSampling::from_adjoint(&adjoint, adaptive.estimator)?;
        Ok((value, self.backward_adaptive(options, &adjoint, &sampling, mode)?))
    }
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

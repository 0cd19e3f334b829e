//! Work inside an engine's frame: a [`Frame`] keeps the device buffers of one request (image,
//! adjoint image, gradient, per-pass constants), exposes them, and records renders and gradient
//! passes into command buffers the caller owns, or submits them with timeline semaphores.
//!
//! # Recorded commands and access states
//!
//! Every `record_*` call starts with a barrier that makes all earlier writes on the device
//! (`ALL_COMMANDS`, `MEMORY_WRITE`) visible to pathgrad's transfers and compute shaders, and ends
//! with one that makes its compute-shader and transfer writes visible to all later commands
//! (`ALL_COMMANDS`, `MEMORY_READ | MEMORY_WRITE`). Between them, pathgrad resets its work counter
//! with `vkCmdFillBuffer` (TRANSFER) before each launch and dispatches (COMPUTE_SHADER). So an
//! engine that writes the parameter or adjoint buffer in its own pass before a recorded call, or
//! reads the image or gradient buffer after it, needs no barrier of its own around pathgrad's
//! commands; it may record them into any primary command buffer of a queue family with compute,
//! outside a render pass. The recorded commands use only pathgrad's descriptor sets and pipeline;
//! they leave the bound compute pipeline and descriptor sets changed.
//!
//! # Long work
//!
//! A recorded call records every launch of its sample range into the one command buffer. On a CPU
//! device a submission of `samples_per_submission()` samples runs for about a second at 256²;
//! record a range per submission (or per frame) to keep each one short.
//!
//! Thread safety: `Frame` is `Send + Sync`; its buffers are the caller's to synchronise on the
//! device, and a frame must not be recorded into two command buffers that run at once (they share
//! the work counter and status word).

use std::ops::Range;
use std::sync::Arc;

use ash::vk;

use crate::contract::*;
use crate::error::{Error, Result};
use crate::gpu::buffer::Buffer;
use crate::gpu::context::{Context, Pending, SubmitSync};
use crate::gpu::dispatch::{self, PATHS_PER_SUBMISSION, Request, Work};
use crate::gpu::kernels::{KernelKind, Variant};
use crate::gpu::pipeline::{BindGroup, memory_barrier};
use crate::gpu::renderer::{GradMode, Renderer, reverse_kinds};
use crate::gpu::variant;
use crate::image::Image;
use crate::integrator::{ParamKinds, RenderOptions, View};
use crate::params::Gradients;
use crate::rng::PassTag;

/// What a buffer pathgrad exposes holds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum BufferLayout {
    /// One f32 per parameter value, at the offsets of the scene's `ParamTable` (`pathgrad params`).
    ParamValues,
    /// RGB f32 per pixel, row-major from the top-left: the sum over the samples rendered since the
    /// last clear (divide by their number for the image).
    RgbSums,
    /// RGB f32 per pixel, row-major: the adjoint image ∂loss/∂I that the gradient pass reads.
    RgbAdjoint,
    /// One f32 per parameter value (`ParamTable` offsets): ∂loss/∂θ, accumulated by float atomics.
    GradientF32,
    /// One i64 per parameter value (`ParamTable` offsets): ∂loss/∂θ in fixed point; multiply by
    /// `unit` for the value. Bitwise reproducible.
    GradientFixed {
        /// The value of one integer step.
        unit: f64,
    },
}

/// A buffer of pathgrad's that an engine may bind, copy from or write, with what it holds.
#[derive(Clone, Copy, Debug)]
pub struct BufferView {
    /// The Vulkan buffer (owned by pathgrad; alive as long as what returned it).
    pub buffer: vk::Buffer,
    /// Byte offset of the data.
    pub offset: u64,
    /// Size of the data in bytes.
    pub size: u64,
    /// What the bytes are.
    pub layout: BufferLayout,
}

/// One kernel's resident state in a frame.
struct Pass {
    variant: Variant,
    /// Kept alive for the descriptor set, which refers to it.
    _globals: Buffer,
    /// Kept alive for the kernels, which read it through its address.
    _views: Buffer,
    status: Buffer,
    counter: Buffer,
    group: BindGroup,
}

/// The device buffers of one request (size, samples, strategy, gradient mode) on one renderer:
/// create with [`Renderer::frame`], record with [`Renderer::record_render`] and
/// [`Renderer::record_backward`], or submit with [`Renderer::submit_render`] and
/// [`Renderer::submit_backward`].
///
/// A frame refers to its renderer's scene buffers: drop it, and let its recorded work finish,
/// before the renderer goes.
pub struct Frame {
    ctx: Arc<Context>,
    renderer_id: usize,
    options: RenderOptions,
    mode: GradMode,
    image: Buffer,
    adjoint: Buffer,
    gradient: Buffer,
    fixed_unit: f64,
    primal: Pass,
    backward: Pass,
}

const ALL_WRITES: (vk::PipelineStageFlags, vk::AccessFlags) =
    (vk::PipelineStageFlags::ALL_COMMANDS, vk::AccessFlags::MEMORY_WRITE);
const ALL_ACCESS: (vk::PipelineStageFlags, vk::AccessFlags) = (
    vk::PipelineStageFlags::ALL_COMMANDS,
    vk::AccessFlags::from_raw(vk::AccessFlags::MEMORY_READ.as_raw() | vk::AccessFlags::MEMORY_WRITE.as_raw()),
);

impl Frame {
    /// The options it was made for.
    pub fn options(&self) -> &RenderOptions {
        &self.options
    }

    /// The image buffer: RGB sums over the samples rendered since the last clear.
    pub fn image(&self) -> BufferView {
        view(&self.image, BufferLayout::RgbSums)
    }

    /// The adjoint image the gradient pass reads: the engine's to write (or [`Frame::write_adjoint`]).
    pub fn adjoint(&self) -> BufferView {
        view(&self.adjoint, BufferLayout::RgbAdjoint)
    }

    /// The gradient buffer, in the frame's [`GradMode`].
    pub fn gradient(&self) -> BufferView {
        let layout = match self.mode {
            GradMode::Float => BufferLayout::GradientF32,
            GradMode::Deterministic => BufferLayout::GradientFixed { unit: self.fixed_unit },
        };
        view(&self.gradient, layout)
    }

    /// Samples per pixel in one of pathgrad's own submissions at this size: a range this long
    /// keeps one submission well under a few seconds on lavapipe.
    pub fn samples_per_submission(&self) -> u32 {
        let pixels = u64::from(self.options.width * self.options.height);
        (PATHS_PER_SUBMISSION / pixels).clamp(1, u64::from(self.options.spp)) as u32
    }

    /// Uploads `adjoint` into the adjoint buffer and waits (a convenience; an engine may write the
    /// buffer in its own pass instead).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for an image of another size; Vulkan failures.
    pub fn write_adjoint(&self, adjoint: &Image) -> Result<()> {
        if (adjoint.width(), adjoint.height()) != (self.options.width, self.options.height) {
            return Err(Error::InvalidArgument {
                parameter: "adjoint image".into(),
                message: format!(
                    "is {}×{}, the frame {}×{}",
                    adjoint.width(),
                    adjoint.height(),
                    self.options.width,
                    self.options.height
                ),
            });
        }
        self.adjoint.upload(adjoint.as_slice())
    }

    /// Reads the image back (blocking): the sums divided by `samples`.
    ///
    /// # Errors
    /// Vulkan failures.
    pub fn read_image(&self, samples: u32) -> Result<Image> {
        let n = (self.options.width * self.options.height * 3) as usize;
        let sums: Vec<f32> = self.image.download(n)?;
        let s = samples.max(1) as f32;
        Image::from_rgb(self.options.width, self.options.height, sums.into_iter().map(|v| v / s).collect())
    }

    /// Reads the gradient back (blocking), by the parameter names of `renderer`'s scene.
    ///
    /// # Errors
    /// Vulkan failures.
    pub fn read_gradients(&self, renderer: &Renderer) -> Result<Gradients> {
        let n = renderer.flat().params.len();
        let values = match self.mode {
            GradMode::Float => self.gradient.download::<f32>(n)?,
            GradMode::Deterministic => {
                self.gradient.download::<i64>(n)?.iter().map(|&v| (v as f64 * self.fixed_unit) as f32).collect()
            }
        };
        Ok(Gradients::new(&renderer.scene().params, values))
    }

    /// Checks the status words of the work recorded so far (blocking; call once it has finished):
    /// a truncated loop, a stack overflow, a replay that drifted or a fixed-point overflow is an error.
    ///
    /// # Errors
    /// As [`Backend::render`](crate::backend::Backend::render) and [`Backend::backward`](crate::backend::Backend::backward); Vulkan failures.
    pub fn check_status(&self) -> Result<()> {
        for pass in [&self.primal, &self.backward] {
            let flags: Vec<u32> = pass.status.download(1)?;
            dispatch::check_status(flags[0], pass.variant.kind.name())?;
        }
        Ok(())
    }
}

fn view(buffer: &Buffer, layout: BufferLayout) -> BufferView {
    BufferView { buffer: buffer.raw(), offset: 0, size: buffer.size(), layout }
}

impl Renderer {
    /// Creates the resident buffers and builds the kernels for `options` (primal render, and the
    /// fused adjoint of `mode` with the parameter kinds of `options.differentiate`; attached
    /// sampling's adjoint where `options.sampling` asks for it) — the compile happens here, not in
    /// a recorded call.
    ///
    /// ```no_run
    /// # use pathgrad::gpu::{Context, ContextDesc, Renderer, renderer::GradMode};
    /// # use pathgrad::integrator::RenderOptions;
    /// # let scene = pathgrad::scene::builtin::load("cornell-box")?;
    /// # let ctx = Context::new(&ContextDesc::default())?;
    /// let mut renderer = Renderer::new(&ctx, &scene)?;
    /// let options = RenderOptions { spp: 8, ..RenderOptions::for_scene(&scene) };
    /// let frame = renderer.frame(&options, GradMode::Float)?;
    /// // Into a command buffer the caller owns (here pathgrad's own, for brevity):
    /// ctx.submit_and_wait("frame", |cmd| {
    ///     renderer.record_clear(&frame, cmd);
    ///     renderer.record_render(&frame, cmd, 0..options.spp).unwrap();
    /// })?;
    /// frame.check_status()?;
    /// let image = frame.read_image(options.spp)?;
    /// # Ok::<(), pathgrad::Error>(())
    /// ```
    ///
    /// # Errors
    /// Option errors; [`Error::InvalidArgument`] for deterministic mode without 64-bit atomics,
    /// and for a scene attached sampling does not cover
    /// ([`crate::attached::refuse_unsupported`]); Vulkan and allocation failures.
    pub fn frame(&mut self, options: &RenderOptions, mode: GradMode) -> Result<Frame> {
        // The plan is made per recorded range; these requests give the checked options and constants.
        let whole = Work::Pixels { begin: 0, end: options.spp };
        let view = [View::current(self.scene())];
        let primal_request = self.request(options, &view, PassTag::Primal, whole)?;
        let backward_request = self.request(options, &view, PassTag::Gradient, whole)?;
        // Attached sampling's kernel runs its own primal pass per path (the attached sums need the
        // adjoint image first), then the replay: one dispatch still.
        let kinds = reverse_kinds(
            self.flat(),
            options,
            [KernelKind::Adjoint, KernelKind::AdjointFixed],
            [KernelKind::AdjointAttached, KernelKind::AdjointAttachedFixed],
        )?;
        if mode == GradMode::Deterministic && !self.context().info().int64_atomics {
            return Err(Error::InvalidArgument {
                parameter: "GradMode::Deterministic".into(),
                message: format!("device '{}' has no 64-bit integer atomics", self.context().info().name),
            });
        }
        let ctx = self.context().clone();
        let pixels = u64::from(options.width * options.height);
        let image = Buffer::storage(&ctx, "frame image", pixels * 12)?;
        let adjoint = Buffer::storage(&ctx, "frame adjoint image", pixels * 12)?;
        adjoint.clear()?;
        let n = self.flat().params.len() as u64;
        let (gradient, grad_binding, kind) = match mode {
            GradMode::Float => (Buffer::storage(&ctx, "frame gradient", n * 4)?, BINDING_GRADS, kinds[0]),
            GradMode::Deterministic => {
                (Buffer::storage(&ctx, "frame gradient (fixed point)", n * 8)?, BINDING_GRADS_FIXED, kinds[1])
            }
        };
        let fixed_unit = 1.0 / f64::from(backward_request.globals.fixed_scale);
        let primal_variant = Variant {
            kind: KernelKind::Primal,
            features: variant::request_features(self.scene_features, options, ParamKinds::NONE),
        };
        let backward_variant = Variant {
            kind,
            features: variant::request_features(self.scene_features, options, self.grad_kinds(options)),
        };
        self.kernels.prepare(&[primal_variant, backward_variant])?;
        let primal = self.pass(primal_variant, &primal_request, &[(BINDING_ACCUM, &image)])?;
        let backward =
            // The image is bound where the gradient kernel declares its pass-1 output; the replay
            // (`primal_only` = 0) never writes it.
            self.pass(backward_variant, &backward_request, &[(BINDING_ADJOINT, &adjoint), (grad_binding, &gradient), (BINDING_ACCUM, &image)])?;
        let frame = Frame {
            ctx,
            renderer_id: self.id(),
            options: *options,
            mode,
            image,
            adjoint,
            gradient,
            fixed_unit,
            primal,
            backward,
        };
        frame.ctx.submit_and_wait("frame clear", |cmd| self.record_clear(&frame, cmd))?;
        Ok(frame)
    }

    fn pass(&mut self, variant: Variant, request: &Request, extra: &[(u32, &Buffer)]) -> Result<Pass> {
        let ctx = self.context().clone();
        let views = self.views_buffer(request)?;
        let globals =
            Buffer::uniform_with(&ctx, "frame globals", std::slice::from_ref(&self.globals_for(request, &views)))?;
        let status = Buffer::storage(&ctx, "frame status", 4)?;
        let counter = Buffer::storage(&ctx, "frame work counter", 4)?;
        let mut bindings: Vec<(u32, &Buffer)> =
            vec![(BINDING_GLOBALS, &globals), (BINDING_STATUS, &status), (BINDING_WORK, &counter)];
        bindings.extend_from_slice(extra);
        let group = self.kernels.get(variant)?.bind(&bindings)?;
        Ok(Pass { variant, _globals: globals, _views: views, status, counter, group })
    }

    /// The parameter buffer the kernels read: the engine may write it in its own passes (or use
    /// [`Backend::set_params`](crate::backend::Backend::set_params)). A write there does not change the renderer's host copy
    /// (`scene().params`), which only [`Backend::set_params`](crate::backend::Backend::set_params) replaces.
    pub fn params_buffer(&self) -> BufferView {
        view(&self.gpu.params, BufferLayout::ParamValues)
    }

    /// Records zeroing the frame's image, gradient and status words (not the adjoint image).
    pub fn record_clear(&self, frame: &Frame, cmd: vk::CommandBuffer) {
        let d = frame.ctx.device();
        memory_barrier(
            &frame.ctx,
            cmd,
            ALL_WRITES,
            (vk::PipelineStageFlags::TRANSFER, vk::AccessFlags::TRANSFER_WRITE),
        );
        for buffer in [&frame.image, &frame.gradient, &frame.primal.status, &frame.backward.status] {
            // SAFETY: `cmd` is recording; the frame's buffers outlive its recorded work (its contract).
            unsafe { d.cmd_fill_buffer(cmd, buffer.raw(), 0, vk::WHOLE_SIZE, 0) };
        }
        memory_barrier(
            &frame.ctx,
            cmd,
            (vk::PipelineStageFlags::TRANSFER, vk::AccessFlags::TRANSFER_WRITE),
            ALL_ACCESS,
        );
    }

    /// Records rendering samples `samples` (a part of `0..options.spp`) of every pixel, added into
    /// the frame's image.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for a frame of another renderer or a range outside `0..spp`.
    pub fn record_render(&self, frame: &Frame, cmd: vk::CommandBuffer, samples: Range<u32>) -> Result<()> {
        self.record_pass(frame, &frame.primal, cmd, samples)
    }

    /// Records the fused adjoint of samples `samples`: reads the frame's adjoint image (δL of a
    /// sample is its pixel's value / spp) and adds into the frame's gradient.
    ///
    /// # Errors
    /// As [`Renderer::record_render`].
    pub fn record_backward(&self, frame: &Frame, cmd: vk::CommandBuffer, samples: Range<u32>) -> Result<()> {
        self.record_pass(frame, &frame.backward, cmd, samples)
    }

    /// Refuses a frame of another renderer or a sample range outside `0..spp`.
    fn check_request(&self, frame: &Frame, samples: &Range<u32>) -> Result<()> {
        if frame.renderer_id != self.id() {
            return Err(Error::InvalidArgument {
                parameter: "frame".into(),
                message: "belongs to another renderer".into(),
            });
        }
        let spp = frame.options.spp;
        if samples.start > samples.end || samples.end > spp {
            return Err(Error::InvalidArgument {
                parameter: "samples".into(),
                message: format!("{}..{} is not within 0..{spp}", samples.start, samples.end),
            });
        }
        Ok(())
    }

    fn record_pass(&self, frame: &Frame, pass: &Pass, cmd: vk::CommandBuffer, samples: Range<u32>) -> Result<()> {
        self.check_request(frame, &samples)?;
        let (o, spp) = (&frame.options, frame.options.spp);
        let work = Work::Pixels { begin: samples.start, end: samples.end };
        let plan = dispatch::plan(work, o.width, o.height, 1, spp, self.one_path_per_lane)?;
        // A frame's kernels are built with it, in this renderer's cache (checked above).
        let kernel = self.kernels.built(pass.variant).ok_or_else(|| Error::InvalidArgument {
            parameter: "frame".into(),
            message: "its kernels are not built in this renderer".into(),
        })?;
        memory_barrier(
            &frame.ctx,
            cmd,
            ALL_WRITES,
            (
                vk::PipelineStageFlags::COMPUTE_SHADER | vk::PipelineStageFlags::TRANSFER,
                vk::AccessFlags::SHADER_READ | vk::AccessFlags::SHADER_WRITE | vk::AccessFlags::TRANSFER_WRITE,
            ),
        );
        for submission in &plan {
            dispatch::record(&frame.ctx, cmd, kernel, &pass.group, &pass.counter, &submission.launches);
        }
        memory_barrier(
            &frame.ctx,
            cmd,
            (
                vk::PipelineStageFlags::COMPUTE_SHADER | vk::PipelineStageFlags::TRANSFER,
                vk::AccessFlags::SHADER_WRITE | vk::AccessFlags::TRANSFER_WRITE,
            ),
            ALL_ACCESS,
        );
        Ok(())
    }

    /// Submits [`Renderer::record_render`] of `samples` on the context's queue, waiting for and
    /// signalling the timeline semaphores of `sync`; returns at once.
    ///
    /// # Errors
    /// As [`Renderer::record_render`] and [`Context::submit`].
    pub fn submit_render(&self, frame: &Frame, samples: Range<u32>, sync: &SubmitSync) -> Result<Pending> {
        self.submit_pass(frame, false, samples, sync)
    }

    /// Submits [`Renderer::record_backward`] of `samples` like [`Renderer::submit_render`].
    ///
    /// # Errors
    /// As [`Renderer::submit_render`].
    pub fn submit_backward(&self, frame: &Frame, samples: Range<u32>, sync: &SubmitSync) -> Result<Pending> {
        self.submit_pass(frame, true, samples, sync)
    }

    fn submit_pass(&self, frame: &Frame, backward: bool, samples: Range<u32>, sync: &SubmitSync) -> Result<Pending> {
        let pass = if backward { &frame.backward } else { &frame.primal };
        // Checked before recording, so a bad request is an error and not an empty submission.
        self.check_request(frame, &samples)?;
        let mut recorded = Ok(());
        let pending = frame.ctx.submit(pass.variant.kind.name(), sync, |cmd| {
            recorded = self.record_pass(frame, pass, cmd, samples);
        })?;
        recorded.map(|()| pending)
    }
}

/// `Frame` is used from any thread (the module's thread-safety note).
const _: fn() = || {
    fn send_sync<T: Send + Sync>() {}
    send_sync::<Frame>();
};

//! Renderers (a scene on a device) and frames (one request's buffers, recorded into the
//! engine's command buffers).

use std::ffi::c_char;
use std::ops::Range;
use std::sync::{Arc, Mutex, MutexGuard};

use ash::vk;
use ash::vk::Handle;
use pathgrad::backend::Backend;
use pathgrad::gpu::renderer::GradMode;
use pathgrad::gpu::{BufferLayout, BufferView, Frame, Renderer};
use pathgrad::image::Image;

use crate::context::{PgContext, VkBuffer, VkCommandBuffer};
use crate::error::{Failure, Outcome, PgStatus, arg, arg_mut, guard, out_slice, slice, string};
use crate::scene::{PgFrameDesc, PgScene, find, get_param};

/// A scene uploaded to a context's device, with its kernels. Calls on one renderer (and its
/// frames) from several threads take turns.
pub struct PgRenderer {
    renderer: Arc<Mutex<Renderer>>,
}

/// The device buffers of one request (size, samples, seed, gradient mode) on a renderer, and
/// its built kernels. Keeps its renderer alive.
pub struct PgFrame {
    // Dropped before the renderer whose scene buffers it refers to.
    frame: Frame,
    renderer: Arc<Mutex<Renderer>>,
    desc: PgFrameDesc,
}

/// Which buffer `pg_frame_buffer` describes (`PG_BUFFER_*`).
pub type PgBufferKind = u32;
/// The image: RGB float sums per pixel over the samples rendered since the last clear.
pub const PG_BUFFER_IMAGE: PgBufferKind = 0;
/// The adjoint image the backward pass reads: RGB floats per pixel, ∂loss/∂pixel.
pub const PG_BUFFER_ADJOINT: PgBufferKind = 1;
/// The gradient: one value per parameter value (float, or fixed point in deterministic mode).
pub const PG_BUFFER_GRADIENT: PgBufferKind = 2;
/// The renderer's parameter values: one float per value, which the kernels read.
pub const PG_BUFFER_PARAMS: PgBufferKind = 3;

/// What a buffer holds.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PgLayout {
    /// One float per parameter value, at the offsets of `PgParamInfo`.
    ParamValues = 0,
    /// RGB floats per pixel, row-major from the top-left: sums over the samples rendered since
    /// the last clear (divide by their number).
    RgbSums = 1,
    /// RGB floats per pixel, row-major: ∂loss/∂pixel.
    RgbAdjoint = 2,
    /// One float per parameter value: ∂loss/∂θ.
    GradientF32 = 3,
    /// One `int64_t` per parameter value: ∂loss/∂θ in fixed point; multiply by `fixed_unit`.
    GradientFixed = 4,
}

/// A pathgrad buffer that an engine may bind, copy from or write in its own passes. The buffer
/// lives as long as the frame (or, for the parameters, the renderer).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct PgBufferView {
    /// The buffer.
    pub buffer: VkBuffer,
    /// Byte offset of the data.
    pub offset: u64,
    /// Size of the data in bytes.
    pub size: u64,
    /// What the bytes are.
    pub layout: PgLayout,
    /// For `PG_LAYOUT_GRADIENT_FIXED`, the value of one integer step; else 0.
    pub fixed_unit: f64,
}

impl From<BufferView> for PgBufferView {
    fn from(v: BufferView) -> PgBufferView {
        let (layout, fixed_unit) = match v.layout {
            BufferLayout::ParamValues => (PgLayout::ParamValues, 0.0),
            BufferLayout::RgbSums => (PgLayout::RgbSums, 0.0),
            BufferLayout::RgbAdjoint => (PgLayout::RgbAdjoint, 0.0),
            BufferLayout::GradientF32 => (PgLayout::GradientF32, 0.0),
            BufferLayout::GradientFixed { unit } => (PgLayout::GradientFixed, unit),
        };
        PgBufferView { buffer: v.buffer.as_raw(), offset: v.offset, size: v.size, layout, fixed_unit }
    }
}

fn lock(renderer: &Mutex<Renderer>) -> MutexGuard<'_, Renderer> {
    // A panic inside a call is reported as PG_STATUS_PANIC; the renderer stays usable or fails cleanly.
    renderer.lock().unwrap_or_else(|p| p.into_inner())
}

/// Uploads a copy of `scene` to the context's device.
///
/// # Safety
/// `context` and `scene` are null or live; `out` is a valid place for the handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pg_renderer_create(
    context: *const PgContext,
    scene: *const PgScene,
    out: *mut *mut PgRenderer,
) -> PgStatus {
    guard("pg_renderer_create", || {
        // SAFETY: the caller's guarantees.
        let (context, scene, out) = unsafe { (arg(context, "context")?, arg(scene, "scene")?, arg_mut(out, "out")?) };
        *out = std::ptr::null_mut();
        let renderer = Renderer::new(&context.ctx, &scene.scene)?;
        *out = Box::into_raw(Box::new(PgRenderer { renderer: Arc::new(Mutex::new(renderer)) }));
        Ok(())
    })
}

/// Copies the renderer's values of parameter `name` into `values` (`count`: exactly its number
/// of values).
///
/// # Safety
/// `renderer` is null or live; `name` a NUL-terminated string; `values` null or `count` floats.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pg_renderer_get_param(
    renderer: *const PgRenderer,
    name: *const c_char,
    values: *mut f32,
    count: usize,
) -> PgStatus {
    guard("pg_renderer_get_param", || {
        // SAFETY: the caller's guarantees.
        let (renderer, name) = unsafe { (arg(renderer, "renderer")?, string(name, "name")?) };
        get_param(lock(&renderer.renderer).scene(), name, values, count)
    })
}

/// Sets parameter `name` on the renderer and uploads the values (blocking, on the context's
/// queue): later recorded work reads them. Not while recorded work of its frames is pending.
///
/// # Safety
/// `renderer` is null or live; `name` a NUL-terminated string; `values` null or `count` floats.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pg_renderer_set_param(
    renderer: *const PgRenderer,
    name: *const c_char,
    values: *const f32,
    count: usize,
) -> PgStatus {
    guard("pg_renderer_set_param", || {
        // SAFETY: the caller's guarantees.
        let (renderer, name, values) =
            unsafe { (arg(renderer, "renderer")?, string(name, "name")?, slice(values, count, "values")?) };
        let mut renderer = lock(&renderer.renderer);
        find(renderer.scene(), name)?;
        let mut table = renderer.scene().params.clone();
        table.set(name, values)?;
        renderer.set_params(&table)?;
        Ok(())
    })
}

/// The renderer's parameter buffer (`PG_LAYOUT_PARAM_VALUES`), which an engine may write in its
/// own passes; such writes do not change what `pg_renderer_get_param` returns.
///
/// # Safety
/// `renderer` is null or live; `out` valid for writing.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pg_renderer_params_buffer(renderer: *const PgRenderer, out: *mut PgBufferView) -> PgStatus {
    guard("pg_renderer_params_buffer", || {
        // SAFETY: the caller's guarantees.
        let (renderer, out) = unsafe { (arg(renderer, "renderer")?, arg_mut(out, "out")?) };
        *out = lock(&renderer.renderer).params_buffer().into();
        Ok(())
    })
}

/// Releases the caller's share of a renderer (null: nothing); its frames keep it alive until
/// they are destroyed. Its recorded work must have finished before the last share goes.
///
/// # Safety
/// `renderer` is null or live, not used again.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pg_renderer_destroy(renderer: *mut PgRenderer) {
    if !renderer.is_null() {
        let _ = guard("pg_renderer_destroy", || {
            // SAFETY: made by `Box::into_raw`, not used again (the caller's guarantee).
            drop(unsafe { Box::from_raw(renderer) });
            Ok(())
        });
    }
}

/// Creates a frame for `desc` (null: the scene's defaults): allocates its buffers, builds its
/// render and backward kernels (the slow part: seconds on lavapipe) and clears it (blocking, on
/// the context's queue).
///
/// # Safety
/// `renderer` is null or live; `desc` null or valid; `out` a valid place for the handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pg_frame_create(
    renderer: *const PgRenderer,
    desc: *const PgFrameDesc,
    out: *mut *mut PgFrame,
) -> PgStatus {
    guard("pg_frame_create", || {
        // SAFETY: the caller's guarantees.
        let (renderer, out) = unsafe { (arg(renderer, "renderer")?, arg_mut(out, "out")?) };
        *out = std::ptr::null_mut();
        // SAFETY: the caller's guarantees.
        let desc = unsafe { desc.as_ref() }.copied().unwrap_or_default();
        let mut guard = lock(&renderer.renderer);
        let options = desc.options(guard.scene())?;
        let mode = if desc.deterministic != 0 { GradMode::Deterministic } else { GradMode::Float };
        let frame = guard.frame(&options, mode)?;
        drop(guard);
        let desc = PgFrameDesc {
            width: options.width,
            height: options.height,
            spp: options.spp,
            seed: options.seed,
            max_depth: options.max_depth.map_or(-1, |d| d as i32),
            deterministic: desc.deterministic.min(1),
            attached: desc.attached.min(1),
            jacobian_noise: desc.jacobian_noise,
        };
        *out = Box::into_raw(Box::new(PgFrame { frame, renderer: renderer.renderer.clone(), desc }));
        Ok(())
    })
}

/// The frame's request with every default resolved (size, spp, seed, max depth, mode, sampling).
///
/// # Safety
/// `frame` is null or live; `out` valid for writing.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pg_frame_desc(frame: *const PgFrame, out: *mut PgFrameDesc) -> PgStatus {
    guard("pg_frame_desc", || {
        // SAFETY: the caller's guarantees.
        let (frame, out) = unsafe { (arg(frame, "frame")?, arg_mut(out, "out")?) };
        *out = frame.desc;
        Ok(())
    })
}

/// Describes one of the frame's buffers (`kind`: `PG_BUFFER_*`).
///
/// # Safety
/// `frame` is null or live; `out` valid for writing.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pg_frame_buffer(
    frame: *const PgFrame,
    kind: PgBufferKind,
    out: *mut PgBufferView,
) -> PgStatus {
    guard("pg_frame_buffer", || {
        // SAFETY: the caller's guarantees.
        let (frame, out) = unsafe { (arg(frame, "frame")?, arg_mut(out, "out")?) };
        *out = match kind {
            PG_BUFFER_IMAGE => frame.frame.image(),
            PG_BUFFER_ADJOINT => frame.frame.adjoint(),
            PG_BUFFER_GRADIENT => frame.frame.gradient(),
            PG_BUFFER_PARAMS => lock(&frame.renderer).params_buffer(),
            other => return Err(Failure::argument(format!("buffer kind {other} is none of PG_BUFFER_*"))),
        }
        .into();
        Ok(())
    })
}

/// A command buffer argument, which must not be null.
fn command_buffer(cmd: VkCommandBuffer) -> Outcome<vk::CommandBuffer> {
    if cmd.is_null() {
        return Err(Failure::new(PgStatus::NullPointer, "`command_buffer` is null"));
    }
    Ok(vk::CommandBuffer::from_raw(cmd as u64))
}

/// Which recorded pass.
#[derive(Clone, Copy)]
enum Pass {
    Clear,
    Render,
    Backward,
}

fn record(frame: &PgFrame, cmd: vk::CommandBuffer, pass: Pass, samples: Range<u32>) -> Outcome {
    let renderer = lock(&frame.renderer);
    match pass {
        Pass::Clear => renderer.record_clear(&frame.frame, cmd),
        Pass::Render => renderer.record_render(&frame.frame, cmd, samples)?,
        Pass::Backward => renderer.record_backward(&frame.frame, cmd, samples)?,
    }
    Ok(())
}

/// Records into `command_buffer` (recording, primary, of a queue family with compute, outside a
/// render pass) the work of `pass`; `None` submits it on the context's queue and waits.
fn run(frame: *const PgFrame, cmd: Option<VkCommandBuffer>, pass: Pass, first: u32, end: u32) -> Outcome {
    // SAFETY: the entry points' contract (null or live).
    let frame = unsafe { arg(frame, "frame") }?;
    match cmd {
        Some(cmd) => record(frame, command_buffer(cmd)?, pass, first..end),
        None => {
            let ctx = lock(&frame.renderer).context().clone();
            // Checked before submitting, so that a bad range is an error and not an empty submission.
            if !matches!(pass, Pass::Clear) && (first > end || end > frame.desc.spp) {
                return Err(Failure::argument(format!("samples {first}..{end} are not within 0..{}", frame.desc.spp)));
            }
            let mut recorded = Ok(());
            ctx.submit_and_wait("pg_frame", |cmd| recorded = record(frame, cmd, pass, first..end))?;
            recorded
        }
    }
}

/// Records zeroing the frame's image, gradient and status words (not the adjoint image) into
/// `command_buffer`. Barriers are included (src/gpu/frame.rs: "Recorded commands and access
/// states"): the engine needs none of its own around pathgrad's commands.
///
/// # Safety
/// `frame` is null or live; `command_buffer` a command buffer of the context's device in the
/// recording state; the frame outlives the recorded work.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pg_frame_record_clear(frame: *const PgFrame, command_buffer: VkCommandBuffer) -> PgStatus {
    guard("pg_frame_record_clear", || run(frame, Some(command_buffer), Pass::Clear, 0, 0))
}

/// Records rendering samples `first_sample..end_sample` (within `0..spp`) of every pixel, added
/// into the image buffer.
///
/// # Safety
/// As `pg_frame_record_clear`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pg_frame_record_render(
    frame: *const PgFrame,
    command_buffer: VkCommandBuffer,
    first_sample: u32,
    end_sample: u32,
) -> PgStatus {
    guard("pg_frame_record_render", || run(frame, Some(command_buffer), Pass::Render, first_sample, end_sample))
}

/// Records the backward pass of samples `first_sample..end_sample`: reads the adjoint image
/// (∂loss/∂pixel) and adds ∂loss/∂θ into the gradient buffer.
///
/// # Safety
/// As `pg_frame_record_clear`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pg_frame_record_backward(
    frame: *const PgFrame,
    command_buffer: VkCommandBuffer,
    first_sample: u32,
    end_sample: u32,
) -> PgStatus {
    guard("pg_frame_record_backward", || run(frame, Some(command_buffer), Pass::Backward, first_sample, end_sample))
}

/// `pg_frame_record_clear`, submitted on the context's queue; waits.
///
/// # Safety
/// `frame` is null or live.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pg_frame_clear(frame: *const PgFrame) -> PgStatus {
    guard("pg_frame_clear", || run(frame, None, Pass::Clear, 0, 0))
}

/// `pg_frame_record_render`, submitted on the context's queue; waits.
///
/// # Safety
/// `frame` is null or live.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pg_frame_render(frame: *const PgFrame, first_sample: u32, end_sample: u32) -> PgStatus {
    guard("pg_frame_render", || run(frame, None, Pass::Render, first_sample, end_sample))
}

/// `pg_frame_record_backward`, submitted on the context's queue; waits.
///
/// # Safety
/// `frame` is null or live.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pg_frame_backward(frame: *const PgFrame, first_sample: u32, end_sample: u32) -> PgStatus {
    guard("pg_frame_backward", || run(frame, None, Pass::Backward, first_sample, end_sample))
}

/// Reads the image back (blocking; after the recorded work finished): the sums divided by
/// `samples`, into `rgb` (`count` = width × height × 3 floats).
///
/// # Safety
/// `frame` is null or live; `rgb` null or `count` writable floats.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pg_frame_read_image(
    frame: *const PgFrame,
    samples: u32,
    rgb: *mut f32,
    count: usize,
) -> PgStatus {
    guard("pg_frame_read_image", || {
        // SAFETY: the caller's guarantees.
        let frame = unsafe { arg(frame, "frame") }?;
        let wanted = frame.desc.width as usize * frame.desc.height as usize * 3;
        // SAFETY: the caller's guarantees.
        let out = unsafe { out_slice(rgb, count, wanted, "rgb") }?;
        out.copy_from_slice(frame.frame.read_image(samples)?.as_slice());
        Ok(())
    })
}

/// Uploads `rgb` (`count` = width × height × 3 floats) into the adjoint image buffer and waits;
/// an engine may write the buffer in its own pass instead (`pg_frame_buffer`).
///
/// # Safety
/// `frame` is null or live; `rgb` null or `count` floats.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pg_frame_write_adjoint(frame: *const PgFrame, rgb: *const f32, count: usize) -> PgStatus {
    guard("pg_frame_write_adjoint", || {
        // SAFETY: the caller's guarantees.
        let (frame, rgb) = unsafe { (arg(frame, "frame")?, slice(rgb, count, "rgb")?) };
        let (w, h) = (frame.desc.width, frame.desc.height);
        let wanted = w as usize * h as usize * 3;
        if count != wanted {
            return Err(Failure::argument(format!("`rgb` holds {count} floats; the {w}×{h} frame needs {wanted}")));
        }
        frame.frame.write_adjoint(&Image::from_rgb(w, h, rgb.to_vec())?)?;
        Ok(())
    })
}

/// Reads the gradient back (blocking; after the recorded work finished) as floats, in either
/// mode, into `values` (`count` = `pg_scene_value_count`).
///
/// # Safety
/// `frame` is null or live; `values` null or `count` writable floats.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pg_frame_read_gradients(frame: *const PgFrame, values: *mut f32, count: usize) -> PgStatus {
    guard("pg_frame_read_gradients", || {
        // SAFETY: the caller's guarantees.
        let frame = unsafe { arg(frame, "frame") }?;
        let renderer = lock(&frame.renderer);
        let gradients = frame.frame.read_gradients(&renderer)?;
        // SAFETY: the caller's guarantees.
        let out = unsafe { out_slice(values, count, gradients.values().len(), "values") }?;
        out.copy_from_slice(gradients.values());
        Ok(())
    })
}

/// Checks the status words of the work recorded so far (blocking; call once it has finished):
/// a truncated loop, a replay that drifted or a fixed-point overflow is `PG_STATUS_NUMERIC`.
///
/// # Safety
/// `frame` is null or live.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pg_frame_check_status(frame: *const PgFrame) -> PgStatus {
    guard("pg_frame_check_status", || {
        // SAFETY: the caller's guarantees.
        let frame = unsafe { arg(frame, "frame") }?;
        frame.frame.check_status()?;
        Ok(())
    })
}

/// Destroys a frame (null: nothing). Its recorded work must have finished.
///
/// # Safety
/// `frame` is null or live, not used again.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pg_frame_destroy(frame: *mut PgFrame) {
    if !frame.is_null() {
        let _ = guard("pg_frame_destroy", || {
            // SAFETY: made by `Box::into_raw`, not used again (the caller's guarantee).
            drop(unsafe { Box::from_raw(frame) });
            Ok(())
        });
    }
}

//! Dispatch plans: how a request's samples become kernel launches grouped into submissions, how
//! one submission's launches are recorded, and what the kernels' status word means.

use ash::vk;

use crate::backend::check_view_list;
use crate::contract::*;
use crate::error::{Error, Result};
use crate::gpu::buffer::Buffer;
use crate::gpu::context::Context;
use crate::gpu::pipeline::{BindGroup, Kernel, compute_barrier, groups_for, memory_barrier};
use crate::integrator::{RenderOptions, View};
use crate::rng::PassTag;
use crate::scene::Scene;
use crate::scene::flat::FlatScene;

/// Path samples per submission: enough work to hide submission overhead, little enough that a
/// progress bar moves and a fence wait stays far below its timeout.
pub const PATHS_PER_SUBMISSION: u64 = 1 << 20;

/// Most invocations one dispatch launches when lanes take work from the counter: enough to keep a
/// large GPU full (an H200 holds ~270 000 resident invocations); on lavapipe the lanes of the
/// first subgroups take all the items and the rest find the counter exhausted at once.
const MAX_LANES: u32 = 1 << 18;

/// How a dispatch hands out work.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Work {
    /// Every pixel of every view, samples `begin..end` each.
    Pixels { begin: u32, end: u32 },
    /// `count` global samples whose views and pixels the kernel draws (adaptive pixel sampling).
    Samples { count: u64 },
}

/// A request checked once: its options (validated), the constants its kernels read (`Globals`,
/// before the scene's device addresses are filled in; its views' cameras) and its dispatch plan.
/// Every render, gradient and image-gradient call starts by building one and uses nothing else of
/// its options.
pub(crate) struct Request {
    pub options: RenderOptions,
    pub globals: Globals,
    pub views: Vec<ViewCamera>,
    pub plan: Vec<Submission>,
}

impl Request {
    /// Validates `options` and `views` and derives the constants of `pass` and the plan of `work`.
    ///
    /// # Errors
    /// Option and view errors; those of [`plan`].
    pub(crate) fn new(
        scene: &Scene,
        flat: &FlatScene,
        options: &RenderOptions,
        views: &[View],
        pass: PassTag,
        work: Work,
        one_path_per_lane: bool,
    ) -> Result<Request> {
        options.validate()?;
        check_view_list(views)?;
        let mut globals = options.globals(scene, flat, pass);
        globals.view_count = views.len() as u32;
        let cameras = views.iter().map(|v| options.view_camera(v, pass)).collect();
        let (w, h) = (options.width, options.height);
        let plan = plan(work, w, h, views.len() as u32, options.spp, one_path_per_lane)?;
        Ok(Request { options: *options, globals, views: cameras, plan })
    }
}

/// One kernel launch: its push constants and workgroup counts.
pub(crate) type Launch = (KernelPush, [u32; 3]);

/// One submission's launches, and the samples per pixel done once it has run (for progress).
pub(crate) struct Submission {
    pub launches: Vec<Launch>,
    pub done: u32,
}

/// Splits `work` on `views` images of `width`×`height` into submissions of about
/// [`PATHS_PER_SUBMISSION`] paths. With `one_path_per_lane` (drivers with a loop budget) each
/// launch traces one sample index with one path per invocation. `spp` scales the progress of
/// adaptive work.
///
/// # Errors
/// [`Error::InvalidArgument`] if the work exceeds the 32-bit item or sample counters.
pub(crate) fn plan(
    work: Work,
    width: u32,
    height: u32,
    views: u32,
    spp: u32,
    one_path_per_lane: bool,
) -> Result<Vec<Submission>> {
    let too_many = |what: String| Error::InvalidArgument { parameter: "views".into(), message: what };
    let pixels = (width * height)
        .checked_mul(views)
        .ok_or_else(|| too_many(format!("{views} views of {width}×{height} exceed the 32-bit pixel counter")))?;
    let launch = |push: KernelPush| {
        let lanes = if one_path_per_lane { push.item_count } else { push.item_count.min(MAX_LANES) };
        (push, groups_for(lanes.max(1)))
    };
    let mut out = Vec::new();
    match work {
        Work::Pixels { begin, end } => {
            let tiles = width.div_ceil(TILE_SIZE) * height.div_ceil(TILE_SIZE);
            let items = (tiles * TILE_SIZE * TILE_SIZE)
                .checked_mul(views)
                .ok_or_else(|| too_many(format!("{views} views of {width}×{height} exceed the 32-bit item counter")))?;
            let per_submit = (PATHS_PER_SUBMISSION / u64::from(pixels)).clamp(1, u64::from(end - begin).max(1)) as u32;
            let mut done = begin;
            while done < end {
                let stop = (done + per_submit).min(end);
                let launches = if one_path_per_lane {
                    (done..stop)
                        .map(|s| {
                            launch(KernelPush { sample_begin: s, sample_count: 1, item_count: items, lane_items: 1 })
                        })
                        .collect()
                } else {
                    vec![launch(KernelPush {
                        sample_begin: done,
                        sample_count: stop - done,
                        item_count: items,
                        lane_items: u32::MAX,
                    })]
                };
                out.push(Submission { launches, done: stop });
                done = stop;
            }
        }
        Work::Samples { count } => {
            if count > u64::from(u32::MAX) {
                return Err(Error::InvalidArgument {
                    parameter: "RenderOptions::spp".into(),
                    message: format!("{count} samples exceed the 32-bit sample counter"),
                });
            }
            let chunk = if one_path_per_lane { u64::from(pixels) } else { PATHS_PER_SUBMISSION };
            let mut done = 0u64;
            while done < count {
                let stop = (done + chunk).min(count);
                let push = KernelPush {
                    sample_begin: done as u32,
                    sample_count: 1,
                    item_count: (stop - done) as u32,
                    lane_items: if one_path_per_lane { 1 } else { u32::MAX },
                };
                out.push(Submission { launches: vec![launch(push)], done: (stop * u64::from(spp) / count) as u32 });
                done = stop;
            }
        }
    }
    Ok(out)
}

/// Records `launches` of `kernel` into `cmd`: before each, the work counter is reset (a transfer
/// write made visible to the shader); after each, the shader's writes are made visible to the next
/// launch and to the next counter reset.
pub(crate) fn record(
    ctx: &Context,
    cmd: vk::CommandBuffer,
    kernel: &Kernel,
    group: &BindGroup,
    counter: &Buffer,
    launches: &[Launch],
) {
    let shader_rw = vk::AccessFlags::SHADER_READ | vk::AccessFlags::SHADER_WRITE;
    for (push, groups) in launches {
        // SAFETY: `cmd` is recording; the counter outlives the command buffer's execution (its
        // owner waits for it, or keeps it in the frame).
        unsafe { ctx.device().cmd_fill_buffer(cmd, counter.raw(), 0, vk::WHOLE_SIZE, 0) };
        memory_barrier(
            ctx,
            cmd,
            (vk::PipelineStageFlags::TRANSFER, vk::AccessFlags::TRANSFER_WRITE),
            (vk::PipelineStageFlags::COMPUTE_SHADER, shader_rw),
        );
        kernel.record(cmd, group, bytemuck::bytes_of(push), *groups);
        compute_barrier(ctx, cmd);
        memory_barrier(
            ctx,
            cmd,
            (vk::PipelineStageFlags::COMPUTE_SHADER, shader_rw),
            (vk::PipelineStageFlags::TRANSFER, vk::AccessFlags::TRANSFER_WRITE),
        );
    }
}

/// Turns the kernels' status word into an error.
pub(crate) fn check_status(flags: u32, kernel: &'static str) -> Result<()> {
    if flags & STATUS_LOOP_BUDGET != 0 {
        return Err(Error::LoopBudget { kernel });
    }
    if flags & STATUS_STACK_OVERFLOW != 0 {
        return Err(Error::Scene { location: "BVH".into(), message: format!("{kernel}: traversal stack overflow") });
    }
    if flags & STATUS_REPLAY_RESIDUAL != 0 {
        return Err(Error::Numeric {
            kernel,
            message: "a replay ended with radiance left over: the replay drifted from its primal path".into(),
        });
    }
    if flags & STATUS_FIXED_OVERFLOW != 0 {
        return Err(Error::Numeric {
            kernel,
            message: "a fixed-point gradient sum overflowed ±2³¹; use float gradients or a smaller loss scale".into(),
        });
    }
    Ok(())
}

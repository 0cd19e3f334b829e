//! `Renderer`: uploads a scene once and dispatches the primal megakernel, one sample index per
//! dispatch, accumulating in a fixed order so the same seed gives the same image on the same device.

use std::sync::Arc;

use crate::error::{Error, Result};
use crate::gpu::abi::*;
use crate::gpu::buffer::Buffer;
use crate::gpu::context::Context;
use crate::gpu::pipeline::{Kernel, compute_barrier, groups_for};
use crate::image::Image;
use crate::integrator::RenderOptions;
use crate::params::ParamTable;
use crate::scene::Scene;
use crate::scene::flat::FlatScene;

/// Path samples per submission: enough work to hide submission overhead, little enough that a
/// progress bar moves and a fence wait stays far below its timeout.
const PATHS_PER_SUBMISSION: u64 = 1 << 20;

/// The scene's arrays on the device.
struct GpuScene {
    nodes: Buffer,
    tris: Buffer,
    prim_ids: Buffer,
    shading: Buffer,
    materials: Buffer,
    emitters: Buffer,
    params: Buffer,
}

/// Renders one scene on one device.
///
/// ```no_run
/// use pathgrad::gpu::{Context, ContextDesc, Renderer};
/// use pathgrad::integrator::RenderOptions;
/// let scene = pathgrad::scene::builtin::load("cornell-box")?;
/// let ctx = Context::new(&ContextDesc::default())?;
/// let mut renderer = Renderer::new(&ctx, &scene)?;
/// let image = renderer.render(&RenderOptions { spp: 64, ..RenderOptions::for_scene(&scene) })?;
/// image.save("cornell.exr")?;
/// # Ok::<(), pathgrad::Error>(())
/// ```
pub struct Renderer {
    ctx: Arc<Context>,
    scene: Scene,
    flat: FlatScene,
    gpu: GpuScene,
    primal: Kernel,
}

impl std::fmt::Debug for Renderer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Renderer").field("scene", &self.scene.source).finish_non_exhaustive()
    }
}

impl Renderer {
    /// Flattens `scene`, builds its BVH and uploads everything.
    ///
    /// # Errors
    /// Scene validation errors; Vulkan and allocation failures.
    pub fn new(ctx: &Arc<Context>, scene: &Scene) -> Result<Renderer> {
        let flat = {
            let _span = tracing::info_span!("load", scene = %scene.source).entered();
            FlatScene::new(scene)?
        };
        let _span = tracing::info_span!("upload").entered();
        let gpu = GpuScene {
            nodes: Buffer::storage_with(ctx, "BVH nodes", &flat.bvh.nodes)?,
            tris: Buffer::storage_with(ctx, "triangles (leaf order)", &flat.bvh.tris)?,
            prim_ids: Buffer::storage_with(ctx, "triangle ids", &flat.bvh.prim_ids)?,
            shading: Buffer::storage_with(ctx, "triangle shading", &flat.shading)?,
            materials: Buffer::storage_with(ctx, "materials", &flat.materials)?,
            emitters: Buffer::storage_with(ctx, "emitters", &flat.emitters)?,
            params: Buffer::storage_with(ctx, "param buffer", &flat.params)?,
        };
        let primal = Kernel::new(ctx, "primal", &Self::PRIMAL_BINDINGS, 4)?;
        Ok(Renderer { ctx: ctx.clone(), scene: scene.clone(), flat, gpu, primal })
    }

    const PRIMAL_BINDINGS: [u32; 10] = [
        BINDING_GLOBALS,
        BINDING_NODES,
        BINDING_TRIS,
        BINDING_PRIM_IDS,
        BINDING_SHADING,
        BINDING_MATERIALS,
        BINDING_EMITTERS,
        BINDING_PARAMS,
        BINDING_ACCUM,
        BINDING_STATUS,
    ];

    /// The scene being rendered.
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// The flattened scene (what the CPU reference consumes too).
    pub fn flat(&self) -> &FlatScene {
        &self.flat
    }

    /// The device context.
    pub fn context(&self) -> &Arc<Context> {
        &self.ctx
    }

    /// Replaces the parameter values (same table layout) and uploads them.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] if the layout differs; Vulkan failures.
    pub fn set_params(&mut self, params: &ParamTable) -> Result<()> {
        if params.entries() != self.scene.params.entries() {
            return Err(Error::InvalidArgument {
                parameter: "params".into(),
                message: "the table's layout differs from the scene's".into(),
            });
        }
        self.scene.params = params.clone();
        self.flat.params = params.values().to_vec();
        self.gpu.params.upload(&self.flat.params)
    }

    /// Renders with `options`.
    ///
    /// # Errors
    /// Option errors, Vulkan failures, [`Error::LoopBudget`] if the driver truncated a kernel loop.
    pub fn render(&mut self, options: &RenderOptions) -> Result<Image> {
        self.render_with_progress(options, &mut |_, _| {})
    }

    /// Renders with `options`, calling `progress(samples_done, spp)` after each submission.
    ///
    /// # Errors
    /// As [`Renderer::render`].
    pub fn render_with_progress(
        &mut self,
        options: &RenderOptions,
        progress: &mut dyn FnMut(u32, u32),
    ) -> Result<Image> {
        options.validate()?;
        let _span =
            tracing::info_span!("primal", width = options.width, height = options.height, spp = options.spp).entered();
        let pixels = options.width * options.height;
        let globals = Buffer::storage_with(
            &self.ctx,
            "globals",
            std::slice::from_ref(&options.globals(&self.scene, &self.flat)),
        )?;
        let accum = Buffer::storage(&self.ctx, "accumulation image", u64::from(pixels) * 12)?;
        let status = Buffer::storage(&self.ctx, "status flags", 4)?;
        accum.clear()?;
        status.clear()?;
        let g = &self.gpu;
        let group = self.primal.bind(&[
            (BINDING_GLOBALS, &globals),
            (BINDING_NODES, &g.nodes),
            (BINDING_TRIS, &g.tris),
            (BINDING_PRIM_IDS, &g.prim_ids),
            (BINDING_SHADING, &g.shading),
            (BINDING_MATERIALS, &g.materials),
            (BINDING_EMITTERS, &g.emitters),
            (BINDING_PARAMS, &g.params),
            (BINDING_ACCUM, &accum),
            (BINDING_STATUS, &status),
        ])?;
        let per_submit = (PATHS_PER_SUBMISSION / u64::from(pixels)).clamp(1, u64::from(options.spp)) as u32;
        let groups = groups_for(pixels);
        let mut done = 0;
        while done < options.spp {
            let end = (done + per_submit).min(options.spp);
            self.ctx.submit_and_wait("primal render", |cmd| {
                for sample in done..end {
                    self.primal.record(cmd, &group, bytemuck::bytes_of(&sample), groups);
                    compute_barrier(&self.ctx, cmd);
                }
            })?;
            done = end;
            progress(done, options.spp);
        }
        let flags: Vec<u32> = status.download(1)?;
        check_status(flags[0], "primal")?;
        let sums: Vec<f32> = accum.download(pixels as usize * 3)?;
        let inv = options.spp as f32;
        Image::from_rgb(options.width, options.height, sums.into_iter().map(|v| v / inv).collect())
    }
}

/// Turns the kernels' status word into an error.
fn check_status(flags: u32, kernel: &'static str) -> Result<()> {
    if flags & STATUS_LOOP_BUDGET != 0 {
        return Err(Error::LoopBudget { kernel });
    }
    if flags & STATUS_STACK_OVERFLOW != 0 {
        return Err(Error::Scene { location: "BVH".into(), message: format!("{kernel}: traversal stack overflow") });
    }
    Ok(())
}

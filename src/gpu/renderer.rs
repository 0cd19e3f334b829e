//! `Renderer`: uploads a scene once and dispatches the megakernels — the primal render, the fused
//! adjoint (reverse-mode gradients, with uniform or loss-aware adaptive pixel sampling) and
//! forward-mode image gradients — one sample index per dispatch, in a fixed order, so the same seed
//! gives the same image on the same device.

use std::collections::HashMap;
use std::sync::Arc;
use std::time::Instant;

use ash::vk;

use crate::adaptive::{AdaptiveOptions, PixelSampling};
use crate::contract::*;
use crate::error::{Error, Result};
use crate::gpu::buffer::Buffer;
use crate::gpu::context::Context;
use crate::gpu::pipeline::{Kernel, compute_barrier, groups_for, memory_barrier};
use crate::gpu::variant;
use crate::image::Image;
use crate::integrator::{ParamKinds, RenderOptions};
use crate::loss::{Loss, loss_and_adjoint};
use crate::params::{Gradients, ParamTable};
use crate::rng::PassTag;
use crate::scene::Scene;
use crate::scene::flat::FlatScene;

/// Path samples per submission: enough work to hide submission overhead, little enough that a
/// progress bar moves and a fence wait stays far below its timeout.
const PATHS_PER_SUBMISSION: u64 = 1 << 20;

/// Most invocations one dispatch launches when lanes take work from the counter: enough to keep a
/// large GPU full (an H200 holds ~270 000 resident invocations); on lavapipe the lanes of the
/// first subgroups take all the items and the rest find the counter exhausted at once.
const MAX_LANES: u32 = 1 << 18;

/// A first compile that takes longer than this is reported to the compile observer.
pub const COMPILE_NOTICE_MS: u128 = 300;

/// How reverse-mode gradients are accumulated.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum GradMode {
    /// Float atomics with subgroup reduction: fastest; the last bits vary run to run.
    #[default]
    Float,
    /// 64-bit fixed-point integer atomics (unit 2⁻³²): two runs give bitwise identical gradients.
    Deterministic,
}

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

/// A kernel variant: which kernel, and the value of its `FEATURES` specialisation constant.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
struct Variant {
    kind: KernelKind,
    features: u32,
}

/// What a compile observer is told (see [`Renderer::set_compile_observer`]).
#[derive(Clone, Debug)]
pub enum CompileEvent {
    /// A kernel variant is about to be built (the driver compiles it now, or loads it from its
    /// shader cache).
    Started {
        /// The kernel's name.
        kernel: &'static str,
        /// Its features, as [`variant::describe`] writes them.
        features: String,
    },
    /// The variant is ready.
    Finished {
        /// The kernel's name.
        kernel: &'static str,
        /// Time spent building it, first dispatch included.
        seconds: f64,
    },
}

/// Receives [`CompileEvent`]s.
pub type CompileObserver = Box<dyn FnMut(&CompileEvent) + Send>;

/// How a dispatch hands out work.
#[derive(Clone, Copy, Debug)]
enum Work {
    /// Every pixel, `spp` samples each.
    Pixels { spp: u32 },
    /// `count` global samples whose pixels the kernel draws (adaptive pixel sampling).
    Samples { count: u64 },
}

/// Renders one scene on one device: images, gradients and image gradients.
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
    /// Parameter offset of the environment's radiance, or `NO_PARAM`.
    env_param: u32,
    /// Feature bits of what the scene contains.
    scene_features: u32,
    /// The parameter kinds the scene has (what refers to its parameters never changes).
    scene_kinds: ParamKinds,
    kernels: HashMap<Variant, Kernel>,
    /// One path per invocation (drivers with a loop budget, PLATFORM.md §6.1).
    one_path_per_lane: bool,
    observer: Option<CompileObserver>,
}

impl std::fmt::Debug for Renderer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Renderer").field("scene", &self.scene.source).finish_non_exhaustive()
    }
}

/// The bindings every render kernel has: the per-render constants (a uniform buffer that also
/// holds the scene arrays' device addresses), the status word and the work counter.
const SCENE_BINDINGS: [u32; 3] = [BINDING_GLOBALS, BINDING_STATUS, BINDING_WORK];

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
        let env_param = scene.environment.map_or(NO_PARAM, |p| scene.params.entry(p).offset);
        let scene_features = variant::scene_features(&flat, env_param);
        let scene_kinds = variant::param_kinds(&flat, env_param, 0, flat.params.len() as u32);
        Ok(Renderer {
            ctx: ctx.clone(),
            scene: scene.clone(),
            flat,
            gpu,
            env_param,
            scene_features,
            scene_kinds,
            kernels: HashMap::new(),
            one_path_per_lane: ctx.info().loop_budget,
            observer: None,
        })
    }

    /// Calls `observer` when a kernel variant is built (on its first use in this process), so a
    /// front end can tell its user that a first compile is under way.
    pub fn set_compile_observer(&mut self, observer: CompileObserver) {
        self.observer = Some(observer);
    }

    /// Traces one path per kernel invocation, one dispatch per sample index, instead of letting
    /// lanes take work until none is left. On by default where the driver cuts long loops short
    /// ([`crate::gpu::DeviceInfo::loop_budget`]); tests turn it on elsewhere to cover that schedule.
    pub fn set_one_path_per_invocation(&mut self, on: bool) {
        self.one_path_per_lane = on;
    }

    /// The kinds of the parameters `ids` (for [`RenderOptions::differentiate`]).
    pub fn param_kinds(&self, ids: &[crate::params::ParamId]) -> ParamKinds {
        ids.iter().fold(ParamKinds::NONE, |k, &id| {
            let e = self.scene.params.entry(id);
            k.union(variant::param_kinds(&self.flat, self.env_param, e.offset, e.offset + e.len))
        })
    }

    /// The parameter kinds present in the scene and asked for by `options`.
    fn grad_kinds(&self, options: &RenderOptions) -> ParamKinds {
        self.scene_kinds.intersection(options.differentiate)
    }

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
        self.render_pass(options, PassTag::Primal, progress)
    }

    /// Renders a reference (a target image) with `options`: the same estimator as
    /// [`Renderer::render`] under the [`PassTag::Reference`] key, so its paths are independent of
    /// every render, loss image and gradient pass of any seed (ALGORITHMS.md §2.3) — an
    /// optimisation whose iteration t uses seed base + t never replays its target's paths.
    ///
    /// # Errors
    /// As [`Renderer::render`].
    pub fn render_reference(&mut self, options: &RenderOptions) -> Result<Image> {
        self.render_pass(options, PassTag::Reference, &mut |_, _| {})
    }

    /// Renders with `options` under the key of `pass`.
    fn render_pass(
        &mut self,
        options: &RenderOptions,
        pass: PassTag,
        progress: &mut dyn FnMut(u32, u32),
    ) -> Result<Image> {
        options.validate()?;
        let _span =
            tracing::info_span!("primal", width = options.width, height = options.height, spp = options.spp).entered();
        let pixels = options.width * options.height;
        let globals = options.globals(&self.scene, &self.flat, pass);
        let accum = Buffer::storage(&self.ctx, "accumulation image", u64::from(pixels) * 12)?;
        accum.clear()?;
        let features = variant::request_features(self.scene_features, options, ParamKinds::NONE);
        let v = Variant { kind: KernelKind::Primal, features };
        self.dispatch(v, &globals, options, Work::Pixels { spp: options.spp }, &[(BINDING_ACCUM, &accum)], progress)?;
        let sums: Vec<f32> = accum.download(pixels as usize * 3)?;
        let spp = options.spp as f32;
        Image::from_rgb(options.width, options.height, sums.into_iter().map(|v| v / spp).collect())
    }

    /// Reverse-mode gradient of a loss whose adjoint image (∂loss/∂pixel) is `adjoint`: the fused
    /// primal + replay kernel (PRB) with the gradient key, so its paths are independent of the
    /// render that produced `adjoint` (ALGORITHMS.md §1, §3.4).
    ///
    /// # Errors
    /// Option errors; [`Error::InvalidArgument`] for an adjoint image of the wrong size or
    /// deterministic mode without 64-bit atomics; Vulkan failures; [`Error::LoopBudget`];
    /// [`Error::Numeric`] if a replay drifted from its primal path or a fixed-point sum overflowed.
    pub fn backward(&mut self, options: &RenderOptions, adjoint: &Image, mode: GradMode) -> Result<Gradients> {
        options.validate()?;
        check_size(adjoint, options, "adjoint image")?;
        let _span = tracing::info_span!("adjoint", spp = options.spp, ?mode).entered();
        let globals = options.globals(&self.scene, &self.flat, PassTag::Gradient);
        let adjoint_buf = Buffer::storage_with(&self.ctx, "adjoint image", adjoint.as_slice())?;
        let work = Work::Pixels { spp: options.spp };
        self.reverse([KernelKind::Adjoint, KernelKind::AdjointFixed], &globals, options, work, &adjoint_buf, &[], mode)
    }

    /// Reverse-mode gradient with loss-aware adaptive pixel sampling (ALGORITHMS.md §6): the
    /// N = W·H·`options.spp` samples of the fused primal + replay kernel draw their pixels from
    /// `sampling` on the device (sample k: pixel p(k) from the alias table, path counters (p(k), k))
    /// and carry the adjoint radiance of [`PixelSampling::sample_adjoint`] — A_p/(N·π_p) for the
    /// unbiased importance estimator, A_p/n_p for the per-pixel mean, whose histogram n_p is drawn
    /// on the host from the same uniforms before the launch.
    ///
    /// # Errors
    /// As [`Renderer::backward`]; [`Error::InvalidArgument`] if `sampling` is for another image size
    /// or N exceeds the 32-bit sample counter.
    pub fn backward_adaptive(
        &mut self,
        options: &RenderOptions,
        adjoint: &Image,
        sampling: &PixelSampling,
        mode: GradMode,
    ) -> Result<Gradients> {
        options.validate()?;
        check_size(adjoint, options, "adjoint image")?;
        let delta = sampling.sample_adjoint(options, adjoint)?;
        let _span =
            tracing::info_span!("adjoint_adaptive", spp = options.spp, ?mode, estimator = sampling.estimator().name())
                .entered();
        let mut globals = options.globals(&self.scene, &self.flat, PassTag::Gradient);
        // δL is in `delta` already.
        globals.adjoint_scale = 1.0;
        let table = sampling.table();
        let entries: Vec<AliasEntry> =
            table.prob().iter().zip(table.alias()).map(|(&prob, &alias)| AliasEntry { prob, alias }).collect();
        let alias_buf = Buffer::storage_with(&self.ctx, "pixel alias table", &entries)?;
        let adjoint_buf = Buffer::storage_with(&self.ctx, "adjoint image (per-sample δL)", delta.as_slice())?;
        let count = u64::from(options.width * options.height) * u64::from(options.spp);
        self.reverse(
            [KernelKind::AdjointAdaptive, KernelKind::AdjointAdaptiveFixed],
            &globals,
            options,
            Work::Samples { count },
            &adjoint_buf,
            &[(BINDING_ALIAS, &alias_buf)],
            mode,
        )
    }

    /// Runs the reverse-mode kernel of `mode` — `kinds[0]` with float atomics, `kinds[1]` in fixed
    /// point — over the scene bindings, the adjoint image, the gradient and `extra`.
    #[allow(clippy::too_many_arguments)]
    fn reverse(
        &mut self,
        kinds: [KernelKind; 2],
        globals: &Globals,
        options: &RenderOptions,
        work: Work,
        adjoint_buf: &Buffer,
        extra: &[(u32, &Buffer)],
        mode: GradMode,
    ) -> Result<Gradients> {
        let n = self.flat.params.len();
        let features = variant::request_features(self.scene_features, options, self.grad_kinds(options));
        match mode {
            GradMode::Float => {
                let grads = Buffer::storage(&self.ctx, "gradient", (n * 4) as u64)?;
                grads.clear()?;
                let mut bindings = vec![(BINDING_ADJOINT, adjoint_buf), (BINDING_GRADS, &grads)];
                bindings.extend_from_slice(extra);
                let v = Variant { kind: kinds[0], features };
                self.dispatch(v, globals, options, work, &bindings, &mut |_, _| {})?;
                Ok(Gradients::new(&self.scene.params, grads.download(n)?))
            }
            GradMode::Deterministic => {
                if !self.ctx.info().int64_atomics {
                    return Err(Error::InvalidArgument {
                        parameter: "GradMode::Deterministic".into(),
                        message: format!("device '{}' has no 64-bit integer atomics", self.ctx.info().name),
                    });
                }
                let grads = Buffer::storage(&self.ctx, "gradient (fixed point)", (n * 8) as u64)?;
                grads.clear()?;
                let mut bindings = vec![(BINDING_ADJOINT, adjoint_buf), (BINDING_GRADS_FIXED, &grads)];
                bindings.extend_from_slice(extra);
                let v = Variant { kind: kinds[1], features };
                self.dispatch(v, globals, options, work, &bindings, &mut |_, _| {})?;
                let fixed: Vec<i64> = grads.download(n)?;
                let unit = 1.0 / f64::from(globals.fixed_scale);
                Ok(Gradients::new(&self.scene.params, fixed.iter().map(|&v| (v as f64 * unit) as f32).collect()))
            }
        }
    }

    /// The loss of a render against `target` and its gradient: pass 1 renders with the primal key
    /// and gives the loss and its adjoint image; the fused pass then replays independent paths.
    /// Pass 1 always uses plain BSDF sampling with next-event estimation (as \[SG24\]'s Algorithm 2);
    /// `options.strategy` and `options.nee` apply to the gradient pass.
    ///
    /// # Errors
    /// As [`Renderer::render`] and [`Renderer::backward`]; a target of the wrong size.
    pub fn loss_and_gradient(
        &mut self,
        options: &RenderOptions,
        target: &Image,
        loss: Loss,
        mode: GradMode,
    ) -> Result<(f64, Gradients)> {
        self.loss_and_gradient_split(options, options.spp, target, loss, mode)
    }

    /// As [`Renderer::loss_and_gradient`] with separate sample budgets (ALGORITHMS.md §3.4, §6
    /// "Budget"): pass 1 renders `spp_primal` samples per pixel, the fused gradient pass
    /// `options.spp`.
    ///
    /// # Errors
    /// As [`Renderer::loss_and_gradient`]; [`Error::InvalidArgument`] naming `--spp-primal` if it
    /// is 0.
    pub fn loss_and_gradient_split(
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

    /// Pass 1 of a gradient step: renders [`RenderOptions::loss_pass`] (`spp_primal` spp, plain
    /// BSDF sampling with NEE, the primal key) and returns its loss against `target` and the
    /// adjoint image ∂loss/∂I, computed on the host.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `--spp-primal` if it is 0, or for a target of the wrong
    /// size; as [`Renderer::render`].
    pub fn loss_image(
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

    /// The loss of a render against `target` and its gradient with loss-aware adaptive pixel
    /// sampling (ALGORITHMS.md §6, Su & Gkioulekas' Algorithm 2): pass 1 renders `adaptive.spp_primal`
    /// samples per pixel with the primal key (plain BSDF sampling with next-event estimation) and
    /// gives the loss and its adjoint image A; the pixel weights are π_p ∝ Σ_c |A_pc|; the fused
    /// pass then draws N = W·H·`options.spp` samples from them ([`Renderer::backward_adaptive`]).
    /// `options.strategy` and `options.nee` apply to the gradient pass. If A is zero everywhere
    /// the gradient is exactly zero and is returned without a gradient pass.
    ///
    /// # Errors
    /// As [`Renderer::loss_and_gradient`] and [`Renderer::backward_adaptive`];
    /// [`Error::InvalidArgument`] for `adaptive.spp_primal` = 0 or a non-finite adjoint value.
    pub fn loss_and_gradient_adaptive(
        &mut self,
        options: &RenderOptions,
        adaptive: &AdaptiveOptions,
        target: &Image,
        loss: Loss,
        mode: GradMode,
    ) -> Result<(f64, Gradients)> {
        let (value, adjoint) = self.loss_image(options, adaptive.spp_primal, target, loss)?;
        if adjoint.as_slice().iter().all(|&a| a == 0.0) {
            return Ok((value, Gradients::new(&self.scene.params, vec![0.0; self.flat.params.len()])));
        }
        let sampling = PixelSampling::from_adjoint(&adjoint, adaptive.estimator)?;
        Ok((value, self.backward_adaptive(options, &adjoint, &sampling, mode)?))
    }

    /// Forward-mode image gradient ∂I/∂θ: per pixel and channel, the derivative of the image by
    /// the parameter `name` (tangent 1 on each of its values, so for an RGB parameter the
    /// derivative along scaling all three together), through the same replay with δL = 1.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for an unknown parameter; as [`Renderer::backward`].
    pub fn image_gradient(&mut self, options: &RenderOptions, name: &str) -> Result<Image> {
        options.validate()?;
        let id = self.scene.params.find(name).ok_or_else(|| Error::InvalidArgument {
            parameter: name.to_string(),
            message: "no such parameter (see `pathgrad params SCENE`)".into(),
        })?;
        let entry = self.scene.params.entry(id).clone();
        let _span = tracing::info_span!("image_gradient", param = name).entered();
        let mut globals = options.globals(&self.scene, &self.flat, PassTag::Gradient);
        globals.forward_begin = entry.offset;
        globals.forward_end = entry.offset + entry.len;
        let pixels = options.width * options.height;
        let ones = vec![1.0f32; pixels as usize * 3];
        let adjoint_buf = Buffer::storage_with(&self.ctx, "adjoint image (ones)", &ones)?;
        let accum = Buffer::storage(&self.ctx, "image gradient", u64::from(pixels) * 12)?;
        accum.clear()?;
        // δL = 1 per sample: the adjoint scale must not divide by spp here; the mean is taken below.
        globals.adjoint_scale = 1.0;
        let kinds = variant::param_kinds(&self.flat, self.env_param, entry.offset, entry.offset + entry.len);
        let features = variant::request_features(self.scene_features, options, kinds);
        self.dispatch(
            Variant { kind: KernelKind::ImageGradient, features },
            &globals,
            options,
            Work::Pixels { spp: options.spp },
            &[(BINDING_ADJOINT, &adjoint_buf), (BINDING_ACCUM, &accum)],
            &mut |_, _| {},
        )?;
        let sums: Vec<f32> = accum.download(pixels as usize * 3)?;
        let spp = options.spp as f32;
        Image::from_rgb(options.width, options.height, sums.into_iter().map(|v| v / spp).collect())
    }

    /// Builds the kernel variant `v` if this renderer has not yet, warming it up with an empty
    /// dispatch so the driver's compile (or shader-cache load) happens here and is timed.
    fn kernel(&mut self, v: Variant) -> Result<()> {
        if self.kernels.contains_key(&v) {
            return Ok(());
        }
        let (name, extra) = v.kind.layout();
        let features = variant::describe(v.features);
        let started = Instant::now();
        if let Some(observer) = self.observer.as_mut() {
            observer(&CompileEvent::Started { kernel: name, features: features.clone() });
        }
        let bindings: Vec<(u32, vk::DescriptorType)> = SCENE_BINDINGS
            .iter()
            .chain(extra)
            .map(|&b| {
                let ty = if b == BINDING_GLOBALS {
                    vk::DescriptorType::UNIFORM_BUFFER
                } else {
                    vk::DescriptorType::STORAGE_BUFFER
                };
                (b, ty)
            })
            .collect();
        let kernel = Kernel::specialised(
            &self.ctx,
            name,
            &bindings,
            std::mem::size_of::<KernelPush>() as u32,
            Some(v.features),
        )?;
        self.kernels.insert(v, kernel);
        self.warm_up(v)?;
        let seconds = started.elapsed().as_secs_f64();
        tracing::info!(kernel = name, features = %features, seconds, "kernel variant built");
        if let Some(observer) = self.observer.as_mut() {
            observer(&CompileEvent::Finished { kernel: name, seconds });
        }
        Ok(())
    }

    /// One dispatch of `v` with no work: lavapipe compiles a pipeline at its first dispatch.
    fn warm_up(&self, v: Variant) -> Result<()> {
        let (_, extra) = v.kind.layout();
        let scratch = Buffer::storage(&self.ctx, "warm-up scratch", 16)?;
        let globals = Buffer::uniform_with(
            &self.ctx,
            "globals",
            std::slice::from_ref(&<Globals as bytemuck::Zeroable>::zeroed()),
        )?;
        let bindings: Vec<(u32, &Buffer)> = SCENE_BINDINGS
            .iter()
            .chain(extra)
            .map(|&b| (b, if b == BINDING_GLOBALS { &globals } else { &scratch }))
            .collect();
        let kernel = &self.kernels[&v];
        let group = kernel.bind(&bindings)?;
        let push = KernelPush { sample_begin: 0, sample_count: 0, item_count: 0, lane_items: 0 };
        self.ctx.submit_and_wait(v.kind.layout().0, |cmd| {
            kernel.record(cmd, &group, bytemuck::bytes_of(&push), [1, 1, 1]);
        })
    }

    /// Builds `v` if needed, then [`Renderer::run`]s it.
    fn dispatch(
        &mut self,
        v: Variant,
        globals: &Globals,
        options: &RenderOptions,
        work: Work,
        extra: &[(u32, &Buffer)],
        progress: &mut dyn FnMut(u32, u32),
    ) -> Result<()> {
        self.kernel(v)?;
        self.run(v, globals, options, work, extra, progress)
    }

    /// Dispatches `v` over `work` with the scene bindings plus `extra`, in submissions of about
    /// [`PATHS_PER_SUBMISSION`] paths, then checks the kernels' status word. `progress` hears
    /// (samples per pixel done, spp) after each submission.
    fn run(
        &self,
        v: Variant,
        globals: &Globals,
        options: &RenderOptions,
        work: Work,
        extra: &[(u32, &Buffer)],
        progress: &mut dyn FnMut(u32, u32),
    ) -> Result<()> {
        let g = &self.gpu;
        let globals = Globals {
            addr_nodes: g.nodes.device_address(),
            addr_tris: g.tris.device_address(),
            addr_prim_ids: g.prim_ids.device_address(),
            addr_shading: g.shading.device_address(),
            addr_materials: g.materials.device_address(),
            addr_emitters: g.emitters.device_address(),
            addr_params: g.params.device_address(),
            ..*globals
        };
        let globals_buf = Buffer::uniform_with(&self.ctx, "globals", std::slice::from_ref(&globals))?;
        let status = Buffer::storage(&self.ctx, "status flags", 4)?;
        status.clear()?;
        let counter = Buffer::storage(&self.ctx, "work counter", 4)?;
        let ctx = &self.ctx;
        let mut bindings: Vec<(u32, &Buffer)> =
            vec![(BINDING_GLOBALS, &globals_buf), (BINDING_STATUS, &status), (BINDING_WORK, &counter)];
        bindings.extend_from_slice(extra);
        let kernel = &self.kernels[&v];
        let group = kernel.bind(&bindings)?;
        let name = v.kind.layout().0;
        let pixels = options.width * options.height;
        // One dispatch: (push constants, lanes).
        let launch = |push: KernelPush| {
            let lanes = if self.one_path_per_lane { push.item_count } else { push.item_count.min(MAX_LANES) };
            (push, groups_for(lanes.max(1)))
        };
        let record = |cmd: vk::CommandBuffer, dispatches: &[(KernelPush, [u32; 3])]| {
            for (push, groups) in dispatches {
                // SAFETY: `cmd` is recording; the counter is alive until the submission is waited on.
                unsafe { ctx.device().cmd_fill_buffer(cmd, counter.raw(), 0, vk::WHOLE_SIZE, 0) };
                memory_barrier(
                    ctx,
                    cmd,
                    (vk::PipelineStageFlags::TRANSFER, vk::AccessFlags::TRANSFER_WRITE),
                    (
                        vk::PipelineStageFlags::COMPUTE_SHADER,
                        vk::AccessFlags::SHADER_READ | vk::AccessFlags::SHADER_WRITE,
                    ),
                );
                kernel.record(cmd, &group, bytemuck::bytes_of(push), *groups);
                compute_barrier(ctx, cmd);
                memory_barrier(
                    ctx,
                    cmd,
                    (
                        vk::PipelineStageFlags::COMPUTE_SHADER,
                        vk::AccessFlags::SHADER_READ | vk::AccessFlags::SHADER_WRITE,
                    ),
                    (vk::PipelineStageFlags::TRANSFER, vk::AccessFlags::TRANSFER_WRITE),
                );
            }
        };
        match work {
            Work::Pixels { spp } => {
                let tiles_x = options.width.div_ceil(TILE_SIZE);
                let tiles_y = options.height.div_ceil(TILE_SIZE);
                let items = tiles_x * tiles_y * TILE_SIZE * TILE_SIZE;
                let per_submit = (PATHS_PER_SUBMISSION / u64::from(pixels)).clamp(1, u64::from(spp)) as u32;
                let mut done = 0;
                while done < spp {
                    let end = (done + per_submit).min(spp);
                    let dispatches: Vec<_> = if self.one_path_per_lane {
                        (done..end)
                            .map(|s| {
                                launch(KernelPush {
                                    sample_begin: s,
                                    sample_count: 1,
                                    item_count: items,
                                    lane_items: 1,
                                })
                            })
                            .collect()
                    } else {
                        let push = KernelPush {
                            sample_begin: done,
                            sample_count: end - done,
                            item_count: items,
                            lane_items: u32::MAX,
                        };
                        vec![launch(push)]
                    };
                    ctx.submit_and_wait(name, |cmd| record(cmd, &dispatches))?;
                    done = end;
                    progress(done, spp);
                }
            }
            Work::Samples { count } => {
                if count > u64::from(u32::MAX) {
                    return Err(Error::InvalidArgument {
                        parameter: "RenderOptions::spp".into(),
                        message: format!("{count} samples exceed the 32-bit sample counter"),
                    });
                }
                let chunk = if self.one_path_per_lane { u64::from(pixels) } else { PATHS_PER_SUBMISSION };
                let mut done = 0u64;
                while done < count {
                    let end = (done + chunk).min(count);
                    let push = KernelPush {
                        sample_begin: done as u32,
                        sample_count: 1,
                        item_count: (end - done) as u32,
                        lane_items: if self.one_path_per_lane { 1 } else { u32::MAX },
                    };
                    let dispatches = [launch(push)];
                    ctx.submit_and_wait(name, |cmd| record(cmd, &dispatches))?;
                    done = end;
                    progress((done * u64::from(options.spp) / count) as u32, options.spp);
                }
            }
        }
        let flags: Vec<u32> = status.download(1)?;
        check_status(flags[0], name)
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
enum KernelKind {
    Primal,
    Adjoint,
    AdjointFixed,
    AdjointAdaptive,
    AdjointAdaptiveFixed,
    ImageGradient,
}

impl KernelKind {
    /// The kernel table: each kernel's `shaders/*.comp` name and the bindings it adds to
    /// [`SCENE_BINDINGS`]. Adding a kernel is one entry here.
    fn layout(self) -> (&'static str, &'static [u32]) {
        match self {
            KernelKind::Primal => ("primal", &[BINDING_ACCUM]),
            KernelKind::Adjoint => ("adjoint", &[BINDING_ADJOINT, BINDING_GRADS]),
            KernelKind::AdjointFixed => ("adjoint_fixed", &[BINDING_ADJOINT, BINDING_GRADS_FIXED]),
            KernelKind::AdjointAdaptive => ("adjoint_adaptive", &[BINDING_ADJOINT, BINDING_GRADS, BINDING_ALIAS]),
            KernelKind::AdjointAdaptiveFixed => {
                ("adjoint_adaptive_fixed", &[BINDING_ADJOINT, BINDING_GRADS_FIXED, BINDING_ALIAS])
            }
            KernelKind::ImageGradient => ("image_gradient", &[BINDING_ADJOINT, BINDING_ACCUM]),
        }
    }
}

fn check_size(image: &Image, options: &RenderOptions, what: &str) -> Result<()> {
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

/// Turns the kernels' status word into an error.
fn check_status(flags: u32, kernel: &'static str) -> Result<()> {
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

//! `Renderer`: uploads a scene once and runs the megakernels — the primal render, the fused
//! adjoint (reverse-mode gradients, with uniform or loss-aware adaptive pixel sampling) and
//! forward-mode image gradients — through the kernel table (`kernels.rs`) and dispatch plans
//! (`dispatch.rs`); each item in a fixed sample order, so the same seed gives the same image on the
//! same device. `frame.rs` records the same plans into an engine's command buffers.

use std::sync::Arc;
use std::time::Instant;

use crate::adaptive::PixelSampling;
use crate::backend::Backend;
use crate::backend::check_views;
use crate::contract::*;
use crate::error::{Error, Result};
use crate::gpu::buffer::Buffer;
use crate::gpu::context::Context;
use crate::gpu::dispatch::{self, Request, Work, check_status};
pub use crate::gpu::kernels::{COMPILE_NOTICE_MS, CompileEvent, CompileObserver};
use crate::gpu::kernels::{KernelCache, KernelKind, Variant};
use crate::gpu::upload::GpuScene;
use crate::gpu::variant;
use crate::image::Image;
use crate::integrator::{ParamKinds, RenderOptions, View};
use crate::params::{Gradients, ParamTable};
use crate::phases::PhaseReport;
use crate::rng::PassTag;
use crate::scene::Scene;
use crate::scene::flat::FlatScene;

/// How reverse-mode gradients are accumulated.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum GradMode {
    /// Float atomics with subgroup reduction: fastest; the last bits vary run to run.
    #[default]
    Float,
    /// 64-bit fixed-point integer atomics (unit 2⁻³²): two runs give bitwise identical gradients.
    Deterministic,
}

/// Renders one scene on one device: images, gradients and image gradients.
///
/// Thread safety: `Renderer` is `Send` (move it to the thread that renders) but not `Sync`: every
/// call takes `&mut self`, and its compile observer is an `FnMut`. Several renderers may share one
/// `Arc<Context>` from different threads; their submissions serialise on the context's queue.
///
/// ```no_run
/// use pathgrad::backend::Backend;
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
    /// Tells this renderer's frames from another's.
    id: usize,
    scene: Scene,
    flat: FlatScene,
    pub(crate) gpu: GpuScene,
    /// The environment's parameter values (offset, count), or `(NO_PARAM, 0)`.
    env: (u32, u32),
    /// Feature bits of what the scene contains.
    pub(crate) scene_features: u64,
    /// The parameter kinds the scene has (what refers to its parameters never changes).
    scene_kinds: ParamKinds,
    pub(crate) kernels: KernelCache,
    /// One path per invocation (drivers with a loop budget, PLATFORM.md §6.1).
    pub(crate) one_path_per_lane: bool,
    /// The phases of [`Renderer::new`].
    report: PhaseReport,
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
        let mut report = PhaseReport::new();
        let flat = {
            let _span = tracing::info_span!("load", scene = %scene.source).entered();
            FlatScene::for_device_reporting(scene, &mut report)?
        };
        Renderer::with_report(ctx, scene.clone(), flat, report)
    }

    /// [`Renderer::new`] from `flat`, the flattened form of this very `scene`
    /// ([`FlatScene::for_device_reporting`], or [`FlatScene::new`] with its shading data, which is
    /// then uploaded as it is), for a caller that flattens before it opens the device: the BVH
    /// build's transient memory and the device's are then never held together (issue 38: the CLI
    /// saves about 65 MB of peak this way on lavapipe). Without shading data the upload makes it
    /// from `scene` chunk by chunk. The renderer keeps `scene` (a caller that needs it after gives
    /// a clone): at 2 M triangles a second copy held while uploading was 46 MiB of the process's
    /// peak. Its [`Renderer::report`] holds the `upload` phase only.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] if `flat` cannot be `scene`'s (its triangle, mesh, material or
    /// parameter counts, or its shading data's where it has any, differ); Vulkan and allocation
    /// failures.
    pub fn from_flat(ctx: &Arc<Context>, scene: Scene, flat: FlatScene) -> Result<Renderer> {
        if flat.bvh.prim_ids.len() != scene.triangle_count()
            || !(flat.tri_vertices.is_empty() || flat.tri_vertices.len() == scene.triangle_count())
            || flat.meshes.len() != scene.meshes.len()
            || flat.materials.len() != scene.materials.len()
            || flat.params.len() != scene.params.values().len()
        {
            return Err(Error::InvalidArgument {
                parameter: "flat".into(),
                message: format!("is not the flattened form of the scene '{}'", scene.source),
            });
        }
        Renderer::with_report(ctx, scene, flat, PhaseReport::new())
    }

    /// Uploads `flat` (`scene`'s) and records the `upload` phase in `report`.
    fn with_report(ctx: &Arc<Context>, scene: Scene, mut flat: FlatScene, mut report: PhaseReport) -> Result<Renderer> {
        let start = Instant::now();
        let gpu = GpuScene::new(ctx, &scene, &mut flat)?;
        report.record("upload", start);
        let env = variant::env_range(&scene);
        // hide_emitters is the scene's, not its flat records': its kernels alone carry it.
        let hide = if scene.hide_emitters { variant::word2(crate::contract::F2_HIDE_EMITTERS) } else { 0 };
        let scene_features = variant::scene_features(&flat, env.0) | hide;
        let scene_kinds = variant::param_kinds(&flat, env, 0, flat.params.len() as u32);
        static NEXT_ID: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
        Ok(Renderer {
            ctx: ctx.clone(),
            id: NEXT_ID.fetch_add(1, std::sync::atomic::Ordering::Relaxed),
            scene,
            flat,
            gpu,
            env,
            scene_features,
            scene_kinds,
            kernels: KernelCache::new(ctx),
            one_path_per_lane: ctx.info().loop_budget,
            report,
        })
    }

    /// How [`Renderer::new`] went: its phases `flatten` and `bvh`
    /// ([`FlatScene::for_device_reporting`]) and `upload` (the scene's device buffers created and
    /// filled, the shading data made on the way).
    pub fn report(&self) -> &PhaseReport {
        &self.report
    }

    /// Bytes of device memory the scene's buffers take (BVH nodes, triangles, triangle ids,
    /// vertex indices, vertex normals and uvs, meshes, materials, emitters, parameters, media,
    /// lights, tables): what the renderer holds between renders, without a render's own images
    /// and gradient buffers.
    pub fn scene_device_bytes(&self) -> u64 {
        self.gpu.bytes()
    }

    /// Calls `observer` when a kernel variant is built (on its first use in this process), so a
    /// front end can tell its user that a first compile is under way.
    pub fn set_compile_observer(&mut self, observer: CompileObserver) {
        self.kernels.observer = Some(observer);
    }

    /// Traces one path per kernel invocation, one dispatch per sample index, instead of letting
    /// lanes take work until none is left. On by default where the driver cuts long loops short
    /// ([`crate::gpu::DeviceInfo::loop_budget`]); tests turn it on elsewhere to cover that schedule.
    pub fn set_one_path_per_invocation(&mut self, on: bool) {
        self.one_path_per_lane = on;
    }

    /// The parameter kinds present in the scene and asked for by `options`.
    pub(crate) fn grad_kinds(&self, options: &RenderOptions) -> ParamKinds {
        self.scene_kinds.intersection(options.differentiate)
    }

    pub(crate) fn id(&self) -> usize {
        self.id
    }

    /// The scene being rendered.
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// The flattened scene (what the CPU reference consumes too), without its BVH and
    /// per-triangle arrays: the BVH's nodes, triangles and triangle ids and the shading data live
    /// on the device only, so those are empty here (the BVH's depth, the materials, emitters,
    /// parameters and the rest are kept).
    pub fn flat(&self) -> &FlatScene {
        &self.flat
    }

    /// The device context.
    pub fn context(&self) -> &Arc<Context> {
        &self.ctx
    }

    /// Renders `views` with `options` under the key of `pass` on kernel variant `v`: the primal
    /// kernel, or a reverse-mode kernel over pixels in `primal_only` mode (a gradient step's pass 1,
    /// [`Renderer::loss_pass_kernel`]), which adds the same paths' radiance in the same order.
    fn render_views_on(
        &mut self,
        v: Variant,
        options: &RenderOptions,
        views: &[View],
        pass: PassTag,
        progress: &mut dyn FnMut(u32, u32),
    ) -> Result<Vec<Image>> {
        let mut request = self.request(options, views, pass, Work::Pixels { begin: 0, end: options.spp })?;
        let on_reverse = v.kind != KernelKind::Primal;
        request.globals.primal_only = u32::from(on_reverse);
        let _span = tracing::info_span!(
            "primal",
            kernel = v.kind.name(),
            width = options.width,
            height = options.height,
            spp = options.spp,
            views = views.len()
        )
        .entered();
        let values = u64::from(options.width * options.height) * 3 * views.len() as u64;
        let accum = Buffer::storage(&self.ctx, "accumulation image", values * 4)?;
        accum.clear()?;
        // A gradient kernel's other buffers (the kernel table's) are bound because it declares
        // them; primal_only mode reads and writes none of them. The primal kernel has no others.
        let others: Vec<u32> = v.kind.layout().1.iter().copied().filter(|&b| b != BINDING_ACCUM).collect();
        let unused = if others.is_empty() { None } else { Some(Buffer::storage(&self.ctx, "unused binding", 16)?) };
        let mut bindings = vec![(BINDING_ACCUM, &accum)];
        bindings.extend(unused.iter().flat_map(|u| others.iter().map(move |&b| (b, u))));
        self.run(v, &request, &bindings, progress)?;
        let sums: Vec<f32> = accum.download(values as usize)?;
        let spp = options.spp as f32;
        let stacked = options.stacked(views.len())?;
        Image::from_rgb(stacked.width, stacked.height, sums.into_iter().map(|v| v / spp).collect())?
            .split(views.len() as u32)
    }

    /// The gradient kernel of a (non-adaptive) gradient step of `options` in `mode` if it can
    /// render the step's pass 1, `pass1`: its features are pass 1's plus parameter kinds (which
    /// compile adjoint-only code) and perhaps the differential strategy (chosen at run time as
    /// well), so one kernel build serves both passes. `None` where the step renders without NEE,
    /// or the mode has no kernel here.
    pub(crate) fn loss_pass_kernel(
        &self,
        options: &RenderOptions,
        pass1: &RenderOptions,
        mode: GradMode,
    ) -> Option<Variant> {
        let kind = match mode {
            GradMode::Float if options.sampling.is_attached() => KernelKind::AdjointAttached,
            GradMode::Float => KernelKind::Adjoint,
            GradMode::Deterministic if !self.ctx.info().int64_atomics => return None,
            GradMode::Deterministic if options.sampling.is_attached() => KernelKind::AdjointAttachedFixed,
            GradMode::Deterministic => KernelKind::AdjointFixed,
        };
        let features = variant::request_features(self.scene_features, options, self.grad_kinds(options));
        let primal = variant::request_features(self.scene_features, pass1, ParamKinds::NONE);
        (features & !(u64::from(G_ANY | F_DIFF) | variant::word2(F2_HERO)) == primal)
            .then_some(Variant { kind, features })
    }

    /// Runs the reverse-mode kernel of `mode` — `kinds[0]` with float atomics, `kinds[1]` in fixed
    /// point — over the scene bindings, the adjoint image, the gradient and `extra`.
    fn reverse(
        &mut self,
        kinds: [KernelKind; 2],
        request: &Request,
        adjoint_buf: &Buffer,
        extra: &[(u32, &Buffer)],
        mode: GradMode,
    ) -> Result<Gradients> {
        let n = self.flat.params.len();
        let options = &request.options;
        let features = variant::request_features(self.scene_features, options, self.grad_kinds(options));
        match mode {
            GradMode::Float => {
                let grads = Buffer::storage(&self.ctx, "gradient", (n * 4) as u64)?;
                grads.clear()?;
                let mut bindings = vec![(BINDING_ADJOINT, adjoint_buf), (BINDING_GRADS, &grads)];
                bindings.extend_from_slice(extra);
                let v = Variant { kind: kinds[0], features };
                self.run(v, request, &bindings, &mut |_, _| {})?;
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
                self.run(v, request, &bindings, &mut |_, _| {})?;
                let fixed: Vec<i64> = grads.download(n)?;
                let unit = 1.0 / f64::from(request.globals.fixed_scale);
                Ok(Gradients::from_fixed(&self.scene.params, fixed, unit))
            }
        }
    }

    /// The request of `options` and `views` under the key of `pass`, planned for `work` on this
    /// device.
    pub(crate) fn request(
        &self,
        options: &RenderOptions,
        views: &[View],
        pass: PassTag,
        work: Work,
    ) -> Result<Request> {
        Request::new(&self.scene, &self.flat, options, views, pass, work, self.one_path_per_lane)
    }

    /// The request of `options` for the scene's camera alone.
    fn request_current(&self, options: &RenderOptions, pass: PassTag, work: Work) -> Result<Request> {
        self.request(options, &[View::current(&self.scene)], pass, work)
    }

    /// `request`'s constants with the scene's device addresses and that of `views`, a buffer of
    /// its views' cameras (made by [`Renderer::views_buffer`]).
    pub(crate) fn globals_for(&self, request: &Request, views: &Buffer) -> Globals {
        Globals { addr_views: views.device_address(), ..self.gpu.with_addresses(&request.globals) }
    }

    /// A buffer of `request`'s views' cameras.
    pub(crate) fn views_buffer(&self, request: &Request) -> Result<Buffer> {
        Buffer::storage_with(&self.ctx, "views", &request.views)
    }

    /// Builds `v` if needed, then dispatches it along `request`'s plan with the scene bindings
    /// plus `extra`, one submission at a time (each waited for), and checks the kernels' status
    /// word. `progress` hears (samples per pixel done, spp) after each submission.
    fn run(
        &mut self,
        v: Variant,
        request: &Request,
        extra: &[(u32, &Buffer)],
        progress: &mut dyn FnMut(u32, u32),
    ) -> Result<()> {
        let views = self.views_buffer(request)?;
        let globals = self.globals_for(request, &views);
        let globals_buf = Buffer::uniform_with(&self.ctx, "globals", std::slice::from_ref(&globals))?;
        let status = Buffer::storage(&self.ctx, "status flags", 4)?;
        status.clear()?;
        let counter = Buffer::storage(&self.ctx, "work counter", 4)?;
        let mut bindings: Vec<(u32, &Buffer)> =
            vec![(BINDING_GLOBALS, &globals_buf), (BINDING_STATUS, &status), (BINDING_WORK, &counter)];
        bindings.extend_from_slice(extra);
        let ctx = self.ctx.clone();
        let kernel = self.kernels.get(v)?;
        let group = kernel.bind(&bindings)?;
        for submission in &request.plan {
            ctx.submit_and_wait(v.kind.name(), |cmd| {
                dispatch::record(&ctx, cmd, kernel, &group, &counter, &submission.launches)
            })?;
            progress(submission.done, request.options.spp);
        }
        let flags: Vec<u32> = status.download(1)?;
        check_status(flags[0], v.kind.name())
    }
}

const _: fn() = || {
    fn send<T: Send>() {}
    send::<Renderer>();
};

impl Backend for Renderer {
    fn scene(&self) -> &Scene {
        &self.scene
    }

    fn describe(&self) -> String {
        self.ctx.info().name.clone()
    }

    /// Replaces the parameter values (same table layout) and uploads them.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] if the layout differs; Vulkan failures.
    fn set_params(&mut self, params: &ParamTable) -> Result<()> {
        crate::scene::flat::replace_params(&mut self.scene, &mut self.flat, params)?;
        self.gpu.params.upload(&self.flat.params)?;
        if !self.flat.media.is_empty() {
            self.gpu.media.upload(&self.flat.media)?;
        }
        if !self.flat.majorants.is_empty() {
            self.gpu.majorants.upload(&self.flat.majorants)?;
        }
        if !self.flat.env_cells.is_empty() {
            self.gpu.env_cells.upload(&self.flat.env_cells)?;
        }
        // Only the coating tables follow the parameters; the normal maps after them are constants.
        let coating = self.flat.coating_tables_len();
        if coating > 0 {
            self.gpu.tables.upload(&self.flat.tables[..coating])?;
        }
        Ok(())
    }

    /// Renders `views` with `options` under the key of `pass`: one kernel pass over every view's
    /// pixels into one image buffer, the views one after another.
    fn render_views(
        &mut self,
        options: &RenderOptions,
        views: &[View],
        pass: PassTag,
        progress: &mut dyn FnMut(u32, u32),
    ) -> Result<Vec<Image>> {
        let features = variant::request_features(self.scene_features, options, ParamKinds::NONE);
        self.render_views_on(Variant { kind: KernelKind::Primal, features }, options, views, pass, progress)
    }

    fn render_loss_pass(
        &mut self,
        options: &RenderOptions,
        pass1: &RenderOptions,
        views: &[View],
        gradient: Option<GradMode>,
    ) -> Result<Vec<Image>> {
        match gradient.and_then(|mode| self.loss_pass_kernel(options, pass1, mode)) {
            Some(v) => self.render_views_on(v, pass1, views, PassTag::Primal, &mut |_, _| {}),
            None => self.render_views(pass1, views, PassTag::Primal, &mut |_, _| {}),
        }
    }

    /// Reverse-mode gradient of Σ_v ⟨A_v, I_v⟩: the fused primal + replay kernel (PRB) over every
    /// view, with the gradient key, so its paths are independent of the render that produced the
    /// adjoints (ALGORITHMS.md §1, §3.4).
    ///
    /// # Errors
    /// Option errors; [`Error::InvalidArgument`] for adjoint images of the wrong size or number,
    /// or deterministic mode without 64-bit atomics; Vulkan failures; [`Error::LoopBudget`];
    /// [`Error::Numeric`] if a replay drifted from its primal path or a fixed-point sum overflowed.
    fn backward_views(
        &mut self,
        options: &RenderOptions,
        views: &[View],
        adjoints: &[Image],
        mode: GradMode,
    ) -> Result<Gradients> {
        let request = self.request(options, views, PassTag::Gradient, Work::Pixels { begin: 0, end: options.spp })?;
        check_views(views, adjoints, options, "adjoint image")?;
        let kinds = reverse_kinds(
            &self.flat,
            options,
            [KernelKind::Adjoint, KernelKind::AdjointFixed],
            [KernelKind::AdjointAttached, KernelKind::AdjointAttachedFixed],
        )?;
        let _span = tracing::info_span!("adjoint", spp = options.spp, ?mode, views = views.len()).entered();
        let adjoint_buf = Buffer::storage_with(&self.ctx, "adjoint image", Image::stack(adjoints)?.as_slice())?;
        // Declared by the kernel for pass 1 (`primal_only`); a replay never touches it.
        let unused_accum = Buffer::storage(&self.ctx, "accumulation image (unused by the replay)", 16)?;
        self.reverse(kinds, &request, &adjoint_buf, &[(BINDING_ACCUM, &unused_accum)], mode)
    }

    /// Reverse-mode gradient with loss-aware adaptive pixel sampling (ALGORITHMS.md §6) over
    /// every view's pixels: the N = V·W·H·`options.spp` samples of the fused primal + replay
    /// kernel draw their (view, pixel) from `sampling` on the device (sample k: pixel g(k) of the
    /// stacked adjoint images from the alias table, path counters (g(k) mod W·H, k) in its view)
    /// and carry the adjoint radiance of [`PixelSampling::sample_adjoint`] — A_g/(N·π_g) for the
    /// unbiased importance estimator, A_g/n_g for the per-pixel mean, whose histogram n_g is drawn
    /// on the host from the same uniforms before the launch.
    ///
    /// # Errors
    /// As [`Renderer::backward_views`]; [`Error::InvalidArgument`] if `sampling` is for another
    /// size or N exceeds the 32-bit sample counter.
    fn backward_adaptive_views(
        &mut self,
        options: &RenderOptions,
        views: &[View],
        adjoints: &[Image],
        sampling: &PixelSampling,
        mode: GradMode,
    ) -> Result<Gradients> {
        check_views(views, adjoints, options, "adjoint image")?;
        let kinds = reverse_kinds(
            &self.flat,
            options,
            [KernelKind::AdjointAdaptive, KernelKind::AdjointAdaptiveFixed],
            [KernelKind::AdjointAdaptiveAttached, KernelKind::AdjointAdaptiveAttachedFixed],
        )?;
        let stacked = options.stacked(views.len())?;
        let count = u64::from(sampling.sample_count(&stacked)?);
        let mut request = self.request(options, views, PassTag::Gradient, Work::Samples { count })?;
        let delta = sampling.sample_adjoint(&stacked, &Image::stack(adjoints)?)?;
        let _span = tracing::info_span!(
            "adjoint_adaptive",
            spp = options.spp,
            ?mode,
            estimator = sampling.estimator().name(),
            views = views.len()
        )
        .entered();
        // δL is in `delta` already.
        request.globals.adjoint_scale = 1.0;
        let table = sampling.table();
        let entries: Vec<AliasEntry> =
            table.prob().iter().zip(table.alias()).map(|(&prob, &alias)| AliasEntry { prob, alias }).collect();
        let alias_buf = Buffer::storage_with(&self.ctx, "pixel alias table", &entries)?;
        let adjoint_buf = Buffer::storage_with(&self.ctx, "adjoint image (per-sample δL)", delta.as_slice())?;
        self.reverse(kinds, &request, &adjoint_buf, &[(BINDING_ALIAS, &alias_buf)], mode)
    }

    /// Forward-mode image gradient ∂I/∂θ: per pixel and channel, the derivative of the image by
    /// the parameter `name` (tangent 1 on each of its values, so for an RGB parameter the
    /// derivative along scaling all three together), through the same replay with δL = 1 — with
    /// attached sampling, once per channel with δL on that channel alone (three times the work).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for an unknown parameter, or an index of refraction under
    /// detached sampling (which does not differentiate it); as [`Renderer::backward`].
    fn image_gradient(&mut self, options: &RenderOptions, name: &str) -> Result<Image> {
        let mut request =
            self.request_current(options, PassTag::Gradient, Work::Pixels { begin: 0, end: options.spp })?;
        crate::attached::refuse_unsupported(&self.flat, options)?;
        let id = self.scene.params.find(name).ok_or_else(|| Error::InvalidArgument {
            parameter: name.to_string(),
            message: "no such parameter (see `pathgrad params SCENE`)".into(),
        })?;
        // Detached sampling would give an index of refraction a gradient image of zeros: refused by name.
        crate::attached::differentiated(&self.scene, vec![id], &[id], options.sampling)?;
        let entry = self.scene.params.entry(id).clone();
        // The kernels carry the terms of this parameter's kinds, whatever `options.differentiate` says.
        let kinds = variant::param_kinds(&self.flat, self.env, entry.offset, entry.offset + entry.len);
        let _span = tracing::info_span!("image_gradient", param = name).entered();
        request.globals.forward_begin = entry.offset;
        request.globals.forward_end = entry.offset + entry.len;
        let pixels = options.width * options.height;
        let accum = Buffer::storage(&self.ctx, "image gradient", u64::from(pixels) * 12)?;
        // δL = 1 per sample: the adjoint scale must not divide by spp here; the mean is taken below.
        request.globals.adjoint_scale = 1.0;
        let spp = options.spp as f32;
        let features = variant::request_features(self.scene_features, options, kinds);
        let n = pixels as usize * 3;
        // As the CPU twin (`cpu::image_gradient`): detached, one run with δL = 1 gives every
        // channel's derivative; attached sampling's sums weigh the channels by δL, so one run per
        // channel c with δL = e_c, whose accumulated components sum to channel c's derivative.
        let (kind, runs) = if options.sampling.is_attached() {
            (KernelKind::ImageGradientAttached, vec![Some(0), Some(1), Some(2)])
        } else {
            (KernelKind::ImageGradient, vec![None])
        };
        let mut data = vec![0.0f32; n];
        for channel in runs {
            let adjoint: Vec<f32> =
                (0..n).map(|i| if channel.is_none_or(|c| i % 3 == c) { 1.0 } else { 0.0 }).collect();
            let adjoint_buf = Buffer::storage_with(&self.ctx, "adjoint image (δL per channel)", &adjoint)?;
            accum.clear()?;
            self.run(
                Variant { kind, features },
                &request,
                &[(BINDING_ADJOINT, &adjoint_buf), (BINDING_ACCUM, &accum)],
                &mut |_, _| {},
            )?;
            let sums: Vec<f32> = accum.download(n)?;
            match channel {
                None => data.iter_mut().zip(&sums).for_each(|(d, s)| *d = s / spp),
                Some(c) => {
                    for (p, rgb) in sums.chunks_exact(3).enumerate() {
                        data[3 * p + c] = (rgb[0] + rgb[1] + rgb[2]) / spp;
                    }
                }
            }
        }
        Image::from_rgb(options.width, options.height, data)
    }

    /// Builds the gradient pass's variant, which renders pass 1 too where it can (its features
    /// are pass 1's plus parameter kinds and the strategy); otherwise the pass-1 primal variant
    /// beside it, each pipeline created on its own thread.
    fn prepare_gradient(
        &mut self,
        options: &RenderOptions,
        spp_primal: u32,
        mode: GradMode,
        adaptive: bool,
    ) -> Result<()> {
        let pass1 = options.loss_pass(spp_primal)?;
        if !adaptive && let Some(v) = self.loss_pass_kernel(options, &pass1, mode) {
            // One kernel for both passes (render_loss_pass).
            return self.kernels.prepare(&[v]);
        }
        let mut variants = vec![Variant {
            kind: KernelKind::Primal,
            features: variant::request_features(self.scene_features, &pass1, ParamKinds::NONE),
        }];
        let kind = match (adaptive, mode) {
            (false, GradMode::Float) if options.sampling.is_attached() => Some(KernelKind::AdjointAttached),
            (false, GradMode::Float) => Some(KernelKind::Adjoint),
            (true, GradMode::Float) if options.sampling.is_attached() => Some(KernelKind::AdjointAdaptiveAttached),
            (true, GradMode::Float) => Some(KernelKind::AdjointAdaptive),
            // Without 64-bit atomics the gradient pass refuses the mode, by name, when it runs.
            (_, GradMode::Deterministic) if !self.ctx.info().int64_atomics => None,
            (false, GradMode::Deterministic) if options.sampling.is_attached() => {
                Some(KernelKind::AdjointAttachedFixed)
            }
            (false, GradMode::Deterministic) => Some(KernelKind::AdjointFixed),
            (true, GradMode::Deterministic) if options.sampling.is_attached() => {
                Some(KernelKind::AdjointAdaptiveAttachedFixed)
            }
            (true, GradMode::Deterministic) => Some(KernelKind::AdjointAdaptiveFixed),
        };
        if let Some(kind) = kind {
            let features = variant::request_features(self.scene_features, options, self.grad_kinds(options));
            variants.push(Variant { kind, features });
        }
        self.kernels.prepare(&variants)
    }

    fn param_kinds(&self, ids: &[crate::params::ParamId]) -> ParamKinds {
        variant::kinds_of(&self.scene, &self.flat, ids)
    }
}

/// The reverse-mode kernels of a request (float, fixed point): `plain` with detached sampling;
/// with attached sampling, where the scene allows it ([`crate::attached::refuse_unsupported`]),
/// `attached`.
pub(crate) fn reverse_kinds(
    flat: &FlatScene,
    options: &RenderOptions,
    plain: [KernelKind; 2],
    attached: [KernelKind; 2],
) -> Result<[KernelKind; 2]> {
    crate::attached::refuse_unsupported(flat, options)?;
    Ok(if options.sampling.is_attached() { attached } else { plain })
}

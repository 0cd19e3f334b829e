//! The CPU reference: the same estimators as the kernels, on the same flattened scene, with the same
//! random numbers — the yardstick every GPU result is checked against.
//!
//! Each file is the twin of a GLSL include: `surface.rs` ↔ `shaders/lib/surface.glsl`,
//! `emitter.rs` ↔ `shaders/lib/emitter.glsl`, `path.rs` ↔ `shaders/integrator.glsl`. Arithmetic is
//! f32 in the same order, so paths agree with the GPU's except where transcendental functions
//! round differently (ALGORITHMS.md §2.4).

pub(crate) mod emitter;
pub mod medium;
#[doc(hidden)]
pub mod path;
pub(crate) mod slope;
pub(crate) mod surface;

use glam::Vec3;
use rayon::prelude::*;

use crate::adaptive::{PixelSampling, select_pixel};
use crate::attached::Row6;
use crate::contract::{Globals, ViewCamera};
use crate::cpu::path::GradSink;
use crate::rng::{PassTag, RngKey};

use crate::backend::{Backend, check_size, check_view_list, check_views};
use crate::error::Result;
use crate::gpu::renderer::GradMode;
use crate::image::Image;
use crate::integrator::{RenderOptions, View};
use crate::params::{Gradients, ParamTable};
use crate::phases::PhaseReport;
use crate::scene::Scene;
use crate::scene::flat::FlatScene;

/// Gradient sums are split into this many fixed parts of the pixels (or samples), each summed in
/// order and the parts added in order: the result does not depend on the number of threads or on
/// how rayon schedules them, so CPU gradients are deterministic.
const GRADIENT_PARTS: usize = 64;

/// The CPU reference as a [`Backend`]: the scene flattened (BVH included) once and kept between
/// calls. Gradients are summed in f64 in a fixed order (deterministic in either [`GradMode`]).
/// Thread safety: `Send + Sync`; each call runs on rayon's thread pool.
///
/// ```
/// use pathgrad::backend::Backend;
/// use pathgrad::integrator::RenderOptions;
/// let scene = pathgrad::scene::builtin::load("cornell-box")?;
/// let mut cpu = pathgrad::cpu::Reference::new(&scene)?;
/// let image = cpu.render(&RenderOptions { width: 8, height: 8, spp: 1, ..RenderOptions::for_scene(&scene) })?;
/// assert_eq!(image.width(), 8);
/// # Ok::<(), pathgrad::Error>(())
/// ```
pub struct Reference {
    scene: Scene,
    flat: FlatScene,
    report: PhaseReport,
}

impl Reference {
    /// Flattens `scene` and builds its BVH.
    ///
    /// # Errors
    /// Scene validation errors.
    pub fn new(scene: &Scene) -> Result<Reference> {
        let mut report = PhaseReport::new();
        let flat = FlatScene::new_reporting(scene, &mut report)?;
        Ok(Reference { scene: scene.clone(), flat, report })
    }

    /// How [`Reference::new`] went: its phases `flatten`, `bvh` and `shading`
    /// ([`FlatScene::new_reporting`]).
    pub fn report(&self) -> &PhaseReport {
        &self.report
    }

    fn gradients(&self, sums: Vec<f64>) -> Gradients {
        Gradients::from_wide(&self.scene.params, sums)
    }
}

impl Backend for Reference {
    fn scene(&self) -> &Scene {
        &self.scene
    }

    fn describe(&self) -> String {
        "CPU reference".into()
    }

    fn set_params(&mut self, params: &ParamTable) -> Result<()> {
        crate::scene::flat::replace_params(&mut self.scene, &mut self.flat, params)
    }

    fn render_views(
        &mut self,
        options: &RenderOptions,
        views: &[View],
        pass: PassTag,
        progress: &mut dyn FnMut(u32, u32),
    ) -> Result<Vec<Image>> {
        options.validate()?;
        check_view_list(views)?;
        let images = views.iter().map(|v| render_flat(&self.scene, &self.flat, options, v, pass)).collect();
        progress(options.spp, options.spp);
        images
    }

    fn backward_views(
        &mut self,
        options: &RenderOptions,
        views: &[View],
        adjoints: &[Image],
        _mode: GradMode,
    ) -> Result<Gradients> {
        options.validate()?;
        check_views(views, adjoints, options, "adjoint image")?;
        let mut sums = vec![0.0f64; self.flat.params.len()];
        for (view, adjoint) in views.iter().zip(adjoints) {
            sums = add_vectors(sums, backward_flat(&self.scene, &self.flat, options, view, adjoint)?);
        }
        Ok(self.gradients(sums))
    }

    fn backward_adaptive_views(
        &mut self,
        options: &RenderOptions,
        views: &[View],
        adjoints: &[Image],
        sampling: &PixelSampling,
        _mode: GradMode,
    ) -> Result<Gradients> {
        options.validate()?;
        check_views(views, adjoints, options, "adjoint image")?;
        backward_adaptive_flat(&self.scene, &self.flat, options, views, &Image::stack(adjoints)?, sampling)
            .map(|g| self.gradients(g))
    }

    fn image_gradient(&mut self, options: &RenderOptions, name: &str) -> Result<Image> {
        options.validate()?;
        image_gradient_flat(&self.scene, &self.flat, options, name)
    }

    fn param_kinds(&self, ids: &[crate::params::ParamId]) -> crate::integrator::ParamKinds {
        crate::gpu::variant::kinds_of(&self.scene, &self.flat, ids)
    }
}

const _: fn() = || {
    fn send_sync<T: Send + Sync>() {}
    send_sync::<Reference>();
};

/// Sums `term(i, grads)` over `i` in `0..count` into one vector of `n` values, in the fixed
/// order of [`GRADIENT_PARTS`].
fn fixed_order_sum(count: u32, n: usize, term: impl Fn(u32, &mut [f64]) + Sync) -> Vec<f64> {
    let per = count.div_ceil(GRADIENT_PARTS as u32).max(1);
    let parts: Vec<Vec<f64>> = (0..GRADIENT_PARTS as u32)
        .into_par_iter()
        .map(|p| {
            let mut grads = vec![0.0f64; n];
            for i in (p * per).min(count)..((p + 1) * per).min(count) {
                term(i, &mut grads);
            }
            grads
        })
        .collect();
    parts.into_iter().fold(vec![0.0f64; n], add_vectors)
}

/// Renders `scene` on the CPU: per pixel, the sum of `spp` path radiances taken in sample order,
/// divided by `spp` — the same accumulation order as the GPU's.
///
/// # Errors
/// Scene validation and option errors.
pub fn render(scene: &Scene, options: &RenderOptions) -> Result<Image> {
    options.validate()?;
    render_flat(scene, &FlatScene::new(scene)?, options, &View::current(scene), PassTag::Primal)
}

fn render_flat(scene: &Scene, flat: &FlatScene, options: &RenderOptions, view: &View, pass: PassTag) -> Result<Image> {
    let globals = options.globals(scene, flat, pass);
    let camera = options.view_camera(view, pass);
    let pixels = (options.width * options.height) as usize;
    let data: Vec<f32> = (0..pixels)
        .into_par_iter()
        .flat_map_iter(|pixel| {
            let mut sum = Vec3::ZERO;
            for s in 0..options.spp {
                sum += path::trace_path::<false>(
                    flat,
                    &globals,
                    &camera,
                    pixel as u32,
                    s,
                    Vec3::ZERO,
                    Vec3::ZERO,
                    &mut GradSink::None,
                    &mut Row6::default(),
                );
            }
            (sum / options.spp as f32).to_array()
        })
        .collect();
    Image::from_rgb(options.width, options.height, data)
}

/// Reverse-mode gradient on the CPU: the twin of [`crate::gpu::Renderer::backward`] (same key,
/// same fused primal + replay per sample), accumulated in f64 per parameter value. Under detached
/// sampling, as there, [`crate::attached::attached_only_params`] get 0.
///
/// # Errors
/// Scene and option errors; an adjoint image of the wrong size.
pub fn backward(scene: &Scene, options: &RenderOptions, adjoint: &Image) -> Result<Vec<f64>> {
    options.validate()?;
    let flat = FlatScene::new(scene)?;
    backward_flat(scene, &flat, options, &View::current(scene), adjoint)
}

fn backward_flat(
    scene: &Scene,
    flat: &FlatScene,
    options: &RenderOptions,
    view: &View,
    adjoint: &Image,
) -> Result<Vec<f64>> {
    crate::attached::refuse_unsupported(flat, options)?;
    check_size(adjoint, options, "adjoint image")?;
    let globals = options.globals(scene, flat, PassTag::Gradient);
    let camera = options.view_camera(view, PassTag::Gradient);
    let drifted = std::sync::atomic::AtomicUsize::new(0);
    let grads = fixed_order_sum(options.width * options.height, flat.params.len(), |pixel, grads| {
        let adj = adjoint_at(adjoint, pixel) * globals.adjoint_scale;
        for s in 0..options.spp {
            replay_sample(flat, &globals, &camera, pixel, s, adj, grads, &drifted);
        }
    });
    check_replays(drifted.into_inner())?;
    Ok(grads)
}

/// Reverse-mode gradient with adaptive pixel sampling on the CPU: the twin of
/// [`crate::gpu::Renderer::backward_adaptive`]. Sample k = 0..N−1 (N = W·H·spp) draws its pixel
/// p(k) with [`crate::adaptive::select_pixel`] — the same draws as the kernel — and replays the
/// path (p(k), k) with the δL of [`PixelSampling::sample_adjoint`] (ALGORITHMS.md §6).
///
/// # Errors
/// Scene and option errors; an adjoint image or pixel sampling of another size; more samples
/// than the 32-bit counter holds.
pub fn backward_adaptive(
    scene: &Scene,
    options: &RenderOptions,
    adjoint: &Image,
    sampling: &PixelSampling,
) -> Result<Vec<f64>> {
    options.validate()?;
    check_size(adjoint, options, "adjoint image")?;
    let flat = FlatScene::new(scene)?;
    backward_adaptive_flat(scene, &flat, options, &[View::current(scene)], adjoint, sampling)
}

/// Adaptive samples over `views`, whose adjoint images are stacked in `adjoint`: a drawn pixel g
/// of the stack is pixel g mod W·H of view ⌊g / W·H⌋.
fn backward_adaptive_flat(
    scene: &Scene,
    flat: &FlatScene,
    options: &RenderOptions,
    views: &[View],
    adjoint: &Image,
    sampling: &PixelSampling,
) -> Result<Vec<f64>> {
    crate::attached::refuse_unsupported(flat, options)?;
    let stacked = options.stacked(views.len())?;
    let delta = sampling.sample_adjoint(&stacked, adjoint)?;
    let samples = sampling.sample_count(&stacked)?;
    let cameras: Vec<ViewCamera> = views.iter().map(|v| options.view_camera(v, PassTag::Gradient)).collect();
    let pixels = options.width * options.height;
    let mut globals = options.globals(scene, flat, PassTag::Gradient);
    // δL is in `delta` already (the kernel's adjoint_scale is 1 too).
    globals.adjoint_scale = 1.0;
    let key = RngKey([globals.key0, globals.key1]);
    let drifted = std::sync::atomic::AtomicUsize::new(0);
    let grads = fixed_order_sum(samples, flat.params.len(), |k, grads| {
        let drawn = select_pixel(sampling.table(), key, k);
        let adj = adjoint_at(&delta, drawn) * globals.adjoint_scale;
        let camera = &cameras[(drawn / pixels) as usize];
        replay_sample(flat, &globals, camera, drawn % pixels, k, adj, grads, &drifted);
    });
    check_replays(drifted.into_inner())?;
    Ok(grads)
}

/// The RGB value of `image` at row-major `pixel`.
fn adjoint_at(image: &Image, pixel: u32) -> Vec3 {
    Vec3::from_slice(&image.as_slice()[3 * pixel as usize..3 * pixel as usize + 3])
}

fn add_vectors(a: Vec<f64>, b: Vec<f64>) -> Vec<f64> {
    a.iter().zip(&b).map(|(x, y)| x + y).collect()
}

/// One fused sample of the adjoint kernels: the path (`pixel`, `sample`) in primal mode for its
/// radiance, then its replay with adjoint radiance `adj`, scattering into `grads`; a replay that
/// does not return to zero is counted in `drifted`.
#[allow(clippy::too_many_arguments)]
fn replay_sample(
    flat: &FlatScene,
    globals: &Globals,
    camera: &ViewCamera,
    pixel: u32,
    sample: u32,
    adj: Vec3,
    grads: &mut [f64],
    drifted: &std::sync::atomic::AtomicUsize,
) {
    // Attached sampling: the primal pass weights Γ by δL, and the replay starts from it.
    let mut gamma = Row6::ZERO;
    let total = path::trace_path::<false>(
        flat,
        globals,
        camera,
        pixel,
        sample,
        adj,
        Vec3::ZERO,
        &mut GradSink::None,
        &mut gamma,
    );
    let mut sink = GradSink::Backward(grads);
    let left = path::trace_path::<true>(flat, globals, camera, pixel, sample, adj, total, &mut sink, &mut gamma);
    if !path::replay_returned_to_zero(total, left) {
        drifted.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    }
}

/// Forward-mode image gradient on the CPU: the twin of [`crate::gpu::Renderer::image_gradient`]
/// (with attached sampling, one fused sample per colour channel).
///
/// # Errors
/// Scene and option errors (a scene attached sampling does not cover); an unknown parameter; an
/// index of refraction under detached sampling.
pub fn image_gradient(scene: &Scene, options: &RenderOptions, name: &str) -> Result<Image> {
    options.validate()?;
    let flat = FlatScene::new(scene)?;
    image_gradient_flat(scene, &flat, options, name)
}

fn image_gradient_flat(scene: &Scene, flat: &FlatScene, options: &RenderOptions, name: &str) -> Result<Image> {
    crate::attached::refuse_unsupported(flat, options)?;
    let id = scene.params.find(name).ok_or_else(|| crate::Error::InvalidArgument {
        parameter: name.to_string(),
        message: "no such parameter".into(),
    })?;
    // Detached sampling would give an index of refraction a gradient image of zeros: refused by name.
    crate::attached::differentiated(scene, vec![id], &[id], options.sampling)?;
    let entry = scene.params.entry(id).clone();
    let globals = options.globals(scene, flat, PassTag::Gradient);
    let camera = options.view_camera(&View::current(scene), PassTag::Gradient);
    let pixels = (options.width * options.height) as usize;
    let drifted = std::sync::atomic::AtomicUsize::new(0);
    let attached = options.sampling.is_attached();
    let data: Vec<f32> = (0..pixels)
        .into_par_iter()
        .flat_map_iter(|pixel| {
            let mut sum = Vec3::ZERO;
            for s in 0..options.spp {
                let p = pixel as u32;
                // Attached sampling sums its rows over the channels weighted by δL (Γ, Φ): one
                // fused sample per channel c with δL = e_c gives channel c's derivative, the sum
                // of what that sample's terms add. Detached: one sample with δL = 1, per channel.
                let passes: &[Vec3] = if attached { &[Vec3::X, Vec3::Y, Vec3::Z] } else { &[Vec3::ONE] };
                for &adj in passes {
                    let mut gamma = Row6::ZERO;
                    let total = path::trace_path::<false>(
                        flat,
                        &globals,
                        &camera,
                        p,
                        s,
                        if attached { adj } else { Vec3::ZERO },
                        Vec3::ZERO,
                        &mut GradSink::None,
                        &mut gamma,
                    );
                    let mut sink = GradSink::Forward {
                        begin: entry.offset,
                        end: entry.offset + entry.len,
                        derivative: Vec3::ZERO,
                    };
                    let left =
                        path::trace_path::<true>(flat, &globals, &camera, p, s, adj, total, &mut sink, &mut gamma);
                    if !path::replay_returned_to_zero(total, left) {
                        drifted.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                    }
                    if let GradSink::Forward { derivative, .. } = sink {
                        sum += if attached { adj * (derivative.x + derivative.y + derivative.z) } else { derivative };
                    }
                }
            }
            (sum / options.spp as f32).to_array()
        })
        .collect();
    check_replays(drifted.into_inner())?;
    Image::from_rgb(options.width, options.height, data)
}

fn check_replays(drifted: usize) -> Result<()> {
    if drifted > 0 {
        return Err(crate::Error::Numeric {
            kernel: "cpu replay",
            message: format!(
                "{drifted} replay(s) ended with radiance left over: the replay drifted from its primal path"
            ),
        });
    }
    Ok(())
}

//! The CPU reference: the same estimators as the kernels, on the same flattened scene, with the same
//! random numbers — the yardstick every GPU result is checked against.
//!
//! Each file is the twin of a GLSL include: `surface.rs` ↔ `shaders/lib/surface.glsl`,
//! `emitter.rs` ↔ `shaders/lib/emitter.glsl`, `path.rs` ↔ `shaders/integrator.glsl`. Arithmetic is
//! f32 in the same order, so paths agree with the GPU's except where transcendental functions
//! round differently (ALGORITHMS.md §2.4).

pub mod emitter;
pub mod path;
pub mod surface;

use glam::Vec3;
use rayon::prelude::*;

use crate::cpu::path::GradSink;
use crate::rng::PassTag;

use crate::error::Result;
use crate::image::Image;
use crate::integrator::RenderOptions;
use crate::scene::Scene;
use crate::scene::flat::FlatScene;

/// Renders `scene` on the CPU: per pixel, the sum of `spp` path radiances taken in sample order,
/// divided by `spp` — the same accumulation order as the GPU's.
///
/// # Errors
/// Scene validation and option errors.
pub fn render(scene: &Scene, options: &RenderOptions) -> Result<Image> {
    options.validate()?;
    let flat = FlatScene::new(scene)?;
    let globals = options.globals(scene, &flat, PassTag::Primal);
    let pixels = (options.width * options.height) as usize;
    let data: Vec<f32> = (0..pixels)
        .into_par_iter()
        .flat_map_iter(|pixel| {
            let mut sum = Vec3::ZERO;
            for s in 0..options.spp {
                sum += path::trace_path::<false>(
                    &flat,
                    &globals,
                    pixel as u32,
                    s,
                    Vec3::ZERO,
                    Vec3::ZERO,
                    &mut GradSink::None,
                );
            }
            (sum / options.spp as f32).to_array()
        })
        .collect();
    Image::from_rgb(options.width, options.height, data)
}

/// Reverse-mode gradient on the CPU: the twin of [`crate::gpu::Renderer::backward`] (same key,
/// same fused primal + replay per sample), accumulated in f64 per parameter value.
///
/// # Errors
/// Scene and option errors; an adjoint image of the wrong size.
pub fn backward(scene: &Scene, options: &RenderOptions, adjoint: &Image) -> Result<Vec<f64>> {
    options.validate()?;
    if (adjoint.width(), adjoint.height()) != (options.width, options.height) {
        return Err(crate::Error::InvalidArgument {
            parameter: "adjoint image".into(),
            message: "size differs from the render".into(),
        });
    }
    let flat = FlatScene::new(scene)?;
    let globals = options.globals(scene, &flat, PassTag::Gradient);
    let n = flat.params.len();
    let pixels = (options.width * options.height) as usize;
    let drifted = std::sync::atomic::AtomicUsize::new(0);
    let grads = (0..pixels)
        .into_par_iter()
        .fold(
            || vec![0.0f64; n],
            |mut grads, pixel| {
                let a = adjoint.as_slice();
                let adj = Vec3::new(a[3 * pixel], a[3 * pixel + 1], a[3 * pixel + 2]) * globals.adjoint_scale;
                for s in 0..options.spp {
                    let p = pixel as u32;
                    let total =
                        path::trace_path::<false>(&flat, &globals, p, s, Vec3::ZERO, Vec3::ZERO, &mut GradSink::None);
                    let mut sink = GradSink::Backward(&mut grads);
                    let left = path::trace_path::<true>(&flat, &globals, p, s, adj, total, &mut sink);
                    if !path::replay_returned_to_zero(total, left) {
                        drifted.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                    }
                }
                grads
            },
        )
        .reduce(|| vec![0.0f64; n], |a, b| a.iter().zip(&b).map(|(x, y)| x + y).collect());
    check_replays(drifted.into_inner())?;
    Ok(grads)
}

/// Forward-mode image gradient on the CPU: the twin of [`crate::gpu::Renderer::image_gradient`].
///
/// # Errors
/// Scene and option errors; an unknown parameter.
pub fn image_gradient(scene: &Scene, options: &RenderOptions, name: &str) -> Result<Image> {
    options.validate()?;
    let id = scene.params.find(name).ok_or_else(|| crate::Error::InvalidArgument {
        parameter: name.to_string(),
        message: "no such parameter".into(),
    })?;
    let entry = scene.params.entry(id).clone();
    let flat = FlatScene::new(scene)?;
    let globals = options.globals(scene, &flat, PassTag::Gradient);
    let pixels = (options.width * options.height) as usize;
    let drifted = std::sync::atomic::AtomicUsize::new(0);
    let data: Vec<f32> = (0..pixels)
        .into_par_iter()
        .flat_map_iter(|pixel| {
            let mut sum = Vec3::ZERO;
            for s in 0..options.spp {
                let p = pixel as u32;
                let total =
                    path::trace_path::<false>(&flat, &globals, p, s, Vec3::ZERO, Vec3::ZERO, &mut GradSink::None);
                let mut sink =
                    GradSink::Forward { begin: entry.offset, end: entry.offset + entry.len, derivative: Vec3::ZERO };
                let left = path::trace_path::<true>(&flat, &globals, p, s, Vec3::ONE, total, &mut sink);
                if !path::replay_returned_to_zero(total, left) {
                    drifted.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                }
                if let GradSink::Forward { derivative, .. } = sink {
                    sum += derivative;
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

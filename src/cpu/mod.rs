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

use rayon::prelude::*;

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
    let globals = options.globals(scene, &flat);
    let pixels = (options.width * options.height) as usize;
    let data: Vec<f32> = (0..pixels)
        .into_par_iter()
        .flat_map_iter(|pixel| {
            let mut sum = glam::Vec3::ZERO;
            for s in 0..options.spp {
                sum += path::trace_path(&flat, &globals, pixel as u32, s);
            }
            (sum / options.spp as f32).to_array()
        })
        .collect();
    Image::from_rgb(options.width, options.height, data)
}

//! Area emitters on triangles: area-proportional sampling and densities (twin of
//! `shaders/lib/emitter.glsl`).

use glam::{Vec2, Vec3};

use crate::cpu::surface::param_color;
use crate::gpu::abi::Globals;
use crate::sampling::sample_uniform_triangle;
use crate::scene::flat::FlatScene;

/// A point on an emitter.
#[derive(Clone, Copy, Debug)]
pub struct EmitterSample {
    /// Position.
    pub point: Vec3,
    /// Unit normal of the emitting side.
    pub normal: Vec3,
    /// Emitted radiance.
    pub radiance: Vec3,
}

/// Chooses an emissive triangle with probability proportional to its area, then a uniform point
/// on it; the area density is 1 / total emissive area.
pub fn sample_emitter(flat: &FlatScene, u_select: f32, u_pos: Vec2) -> Option<EmitterSample> {
    if flat.emitters.is_empty() {
        return None;
    }
    let (mut lo, mut hi) = (0usize, flat.emitters.len() - 1);
    while lo < hi {
        let mid = (lo + hi) / 2;
        if flat.emitters[mid].cdf > u_select { hi = mid } else { lo = mid + 1 }
    }
    let e = &flat.emitters[lo];
    let b = sample_uniform_triangle(u_pos);
    let point = (1.0 - b.x - b.y) * e.v0 + b.x * e.v1 + b.y * e.v2;
    let normal = (e.v1 - e.v0).cross(e.v2 - e.v0).normalize();
    Some(EmitterSample { point, normal, radiance: param_color(flat, e.p_radiance) })
}

/// Solid-angle density of reaching an emitter point at `dist` whose normal makes cosine
/// `cos_emitter` with the direction back to the shading point.
pub fn emitter_pdf_solid_angle(globals: &Globals, dist: f32, cos_emitter: f32) -> f32 {
    if cos_emitter > 0.0 { dist * dist / (cos_emitter * globals.emitter_total_area) } else { 0.0 }
}

//! Area emitters on triangles: area-proportional sampling and densities (twin of
//! `shaders/lib/emitter.glsl`).

use glam::{Vec2, Vec3};

use crate::contract::Globals;
use crate::cpu::surface::param_color;
use crate::sampling::{UNIFORM_SPHERE_PDF, sample_uniform_sphere, sample_uniform_triangle};
use crate::scene::flat::FlatScene;

/// A next-event sample: a point on an area emitter, or a direction toward the environment.
#[derive(Clone, Copy, Debug)]
pub struct EmitterSample {
    /// Position, or the direction when `environment`.
    pub point: Vec3,
    /// Unit normal of the emitting side.
    pub normal: Vec3,
    /// Emitted radiance.
    pub radiance: Vec3,
    /// Parameter offset of the radiance.
    pub param: u32,
    /// Whether this samples the constant environment.
    pub environment: bool,
}

/// With probability `env_select_prob` a uniform direction toward the environment; otherwise an
/// emissive triangle with probability proportional to its area, then a uniform point on it (area
/// density (1 − env_select_prob) / total emissive area).
pub fn sample_emitter(flat: &FlatScene, globals: &Globals, u_select: f32, u_pos: Vec2) -> Option<EmitterSample> {
    if u_select < globals.env_select_prob {
        let radiance = param_color(flat, globals.env_param);
        return Some(EmitterSample {
            point: sample_uniform_sphere(u_pos),
            normal: Vec3::ZERO,
            radiance,
            param: globals.env_param,
            environment: true,
        });
    }
    if flat.emitters.is_empty() {
        return None;
    }
    let u_select = (u_select - globals.env_select_prob) / (1.0 - globals.env_select_prob);
    let (mut lo, mut hi) = (0usize, flat.emitters.len() - 1);
    while lo < hi {
        let mid = (lo + hi) / 2;
        if flat.emitters[mid].cdf > u_select { hi = mid } else { lo = mid + 1 }
    }
    let e = &flat.emitters[lo];
    let b = sample_uniform_triangle(u_pos);
    let point = (1.0 - b.x - b.y) * e.v0 + b.x * e.v1 + b.y * e.v2;
    let normal = (e.v1 - e.v0).cross(e.v2 - e.v0).normalize();
    Some(EmitterSample {
        point,
        normal,
        radiance: param_color(flat, e.p_radiance),
        param: e.p_radiance,
        environment: false,
    })
}

/// Solid-angle density of reaching an emitter point at `dist` whose normal makes cosine
/// `cos_emitter` with the direction back to the shading point.
pub fn emitter_pdf_solid_angle(globals: &Globals, dist: f32, cos_emitter: f32) -> f32 {
    if cos_emitter > 0.0 {
        (1.0 - globals.env_select_prob) * dist * dist / (cos_emitter * globals.emitter_total_area)
    } else {
        0.0
    }
}

/// Solid-angle density with which next-event estimation samples a direction toward the environment.
pub fn environment_pdf(globals: &Globals) -> f32 {
    globals.env_select_prob * UNIFORM_SPHERE_PDF
}

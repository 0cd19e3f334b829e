//! Lambertian diffuse (ALGORITHMS.md §4.1).

use std::f32::consts::FRAC_1_PI;

use glam::{Vec2, Vec3};

use crate::sampling::sample_cosine_hemisphere;

/// f̂ = ρ cos θo / π on the upper hemisphere of both directions.
pub fn diffuse_eval(albedo: Vec3, wi: Vec3, wo: Vec3) -> Vec3 {
    if wi.z > 0.0 && wo.z > 0.0 { albedo * (wo.z * FRAC_1_PI) } else { Vec3::ZERO }
}

/// cos θo / π on the upper hemisphere of both directions.
pub fn diffuse_pdf(wi: Vec3, wo: Vec3) -> f32 {
    if wi.z > 0.0 && wo.z > 0.0 { wo.z * FRAC_1_PI } else { 0.0 }
}

/// A cosine-weighted direction, or `None` from below the surface.
pub fn diffuse_sample(wi: Vec3, u: Vec2) -> Option<Vec3> {
    if wi.z <= 0.0 {
        return None;
    }
    let wo = sample_cosine_hemisphere(u);
    (wo.z > 0.0).then_some(wo)
}

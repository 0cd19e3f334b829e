//! Blend of two leaves, `(1 − w)·f̂0 + w·f̂1` (ALGORITHMS.md §4.3).

use glam::Vec3;

use crate::bsdf::{Bsdf, leaf_eval, leaf_pdf};

/// The weight clamped to [0, 1].
pub fn blend_weight(b: &Bsdf) -> f32 {
    b.weight.clamp(0.0, 1.0)
}

/// f̂ of the mixture.
pub fn blend_eval(b: &Bsdf, wi: Vec3, wo: Vec3) -> Vec3 {
    let w = blend_weight(b);
    leaf_eval(&b.leaves[0], wi, wo) * (1.0 - w) + leaf_eval(&b.leaves[1], wi, wo) * w
}

/// Density of the mixture's sampling: child 1 with probability w, child 0 otherwise.
pub fn blend_pdf(b: &Bsdf, wi: Vec3, wo: Vec3) -> f32 {
    let w = blend_weight(b);
    leaf_pdf(&b.leaves[0], wi, wo) * (1.0 - w) + leaf_pdf(&b.leaves[1], wi, wo) * w
}

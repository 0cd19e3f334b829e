//! Differential samplers (ALGORITHMS.md §4.2–4.3): the positivised α-derivative of the microfacet
//! half-vector density, split into its signed parts with exact inverse-CDF samplers, and the
//! BSDF-level differential technique (coin-chosen part for a conductor, ½/½ children for a blend).
//! Twin of `shaders/lib/differential.glsl`: same names, same f32 operation order.

use std::f32::consts::{E, PI};

use glam::{Vec2, Vec3};

use crate::bsdf::differential_aniso::{aniso_diff_pdf_mixed_h, aniso_diff_pdf_part_h, sample_aniso_diff_half};
use crate::bsdf::rough_conductor::Distribution;
use crate::bsdf::rough_dielectric::RoughDielectricLeaf;
use crate::bsdf::rough_plastic::PlasticLeaf;
use crate::bsdf::{Bsdf, BsdfSample, Leaf, bsdf_eval, leaf_pdf, leaf_sample};

use crate::contract::{EULER_E_LO as E_LO, LAMBERT_SERIES_ONLY, LAMBERT_W0_SMALL, LAMBERT_WM1_SMALL};
/// Fixed number of Halley steps (written out in GLSL: no data-dependent loops).
const LAMBERT_HALLEY_STEPS: usize = 3;
pub use crate::contract::DIFF_COS_EPSILON;

/// 1 + e·x, with e·x formed by a fused multiply-add plus the rounding error of e: no cancellation
/// near the branch point x = −1/e (clamped at 0 below it).
fn lambert_branch_offset(x: f32) -> f32 {
    (x.mul_add(E, 1.0) + E_LO * x).max(0.0)
}

/// The branch-point series W ≈ −1 + p − p²/3 + 11p³/72 − 43p⁴/540 + 769p⁵/17280 (p > 0: W0,
/// p < 0: W−1).
fn lambert_series(p: f32) -> f32 {
    -1.0 + p * (1.0 + p * (-1.0 / 3.0 + p * (11.0 / 72.0 + p * (-43.0 / 540.0 + p * (769.0 / 17280.0)))))
}

/// One Halley step on w·e^w − x = 0.
fn lambert_halley(w: f32, x: f32) -> f32 {
    let ew = w.exp();
    let f = w * ew - x;
    let wp1 = w + 1.0;
    w - f / (ew * wp1 - (w + 2.0) * f / (2.0 * wp1))
}

/// Principal branch W0(x) on [−1/e, 0] (W0 ∈ [−1, 0]).
pub fn lambert_w0(x: f32) -> f32 {
    let p = (2.0 * lambert_branch_offset(x)).sqrt();
    let series = lambert_series(p);
    if p < LAMBERT_SERIES_ONLY {
        return series;
    }
    let mut w = if x > LAMBERT_W0_SMALL { x * (1.0 - x) } else { series };
    for _ in 0..LAMBERT_HALLEY_STEPS {
        w = lambert_halley(w, x);
    }
    w
}

/// Lower branch W−1(x) on [−1/e, 0) (W−1 ∈ (−∞, −1]); −∞ at x ≥ 0.
pub fn lambert_wm1(x: f32) -> f32 {
    if x >= 0.0 {
        return f32::NEG_INFINITY;
    }
    let p = (2.0 * lambert_branch_offset(x)).sqrt();
    let series = lambert_series(-p);
    if p < LAMBERT_SERIES_ONLY {
        return series;
    }
    let mut w = if x > LAMBERT_WM1_SMALL {
        let l1 = (-x).ln();
        let l2 = (-l1).ln();
        l1 - l2 + l2 / l1
    } else {
        series
    };
    for _ in 0..LAMBERT_HALLEY_STEPS {
        w = lambert_halley(w, x);
    }
    w
}

/// N_α = ∫|Λ|: 4/(eα) for Beckmann, 1/α for GGX (each signed part holds half).
pub fn diff_norm(distribution: Distribution, alpha: f32) -> f32 {
    match distribution {
        Distribution::Beckmann => 4.0 / (E * alpha),
        Distribution::Ggx => 1.0 / alpha,
    }
}

/// p_abs(h) = |Λ(h)|/N_α, Λ = ∂α[D(h) cos θh], in the NaN-free closed forms of ALGORITHMS.md §4.2;
/// 0 if cos θh < 1e-9. This is ½p⁺ + ½p⁻.
pub fn diff_pdf_abs_h(distribution: Distribution, alpha: f32, h: Vec3) -> f32 {
    let c = h.z;
    if c < DIFF_COS_EPSILON {
        return 0.0;
    }
    let t = (h.x * h.x + h.y * h.y) / (c * c);
    let a2 = alpha * alpha;
    match distribution {
        Distribution::Beckmann => {
            let g = (-t / a2).exp();
            if g == 0.0 {
                return 0.0;
            }
            E * g * (t - a2).abs() / (2.0 * PI * a2 * a2 * c * c * c)
        }
        Distribution::Ggx => {
            let cs = c * (a2 + t);
            2.0 * a2 * (t - a2).abs() / (PI * cs * cs * cs)
        }
    }
}

/// Half-vector density of one signed part: p⁺ (Λ > 0, tan²θh > α²) or p⁻ (Λ < 0), each 2·p_abs on
/// its support.
pub fn diff_pdf_part_h(distribution: Distribution, alpha: f32, h: Vec3, positive: bool) -> f32 {
    let c = h.z;
    if c < DIFF_COS_EPSILON {
        return 0.0;
    }
    let t = (h.x * h.x + h.y * h.y) / (c * c);
    if (t > alpha * alpha) != positive {
        return 0.0;
    }
    2.0 * diff_pdf_abs_h(distribution, alpha, h)
}

/// x = tan²θh/α² drawn from one signed part's marginal by inverting its closed-form CDF with `u_b`
/// (ALGORITHMS.md §4.2 table). May be +∞ for the positive parts at u_b = 1.
pub fn diff_sample_x(distribution: Distribution, positive: bool, u_b: f32) -> f32 {
    match (distribution, positive) {
        // F(x) = x e^{1−x} on [0, 1].
        (Distribution::Beckmann, false) => -lambert_w0(-u_b / E),
        // F(x) = 1 − x e^{1−x} on [1, ∞).
        (Distribution::Beckmann, true) => -lambert_wm1((u_b - 1.0) / E),
        // F(x) = 4x/(1+x)²: x = (1 − s)/(1 + s) = u/(1 + s)², s = √(1 − u).
        (Distribution::Ggx, false) => {
            let s = (1.0 - u_b).max(0.0).sqrt();
            u_b / ((1.0 + s) * (1.0 + s))
        }
        // F(x) = ((x − 1)/(x + 1))²: x = (1 + √u)/(1 − √u) = (1 + √u)²/(1 − u).
        (Distribution::Ggx, true) => {
            let r = u_b.max(0.0).sqrt();
            (1.0 + r) * (1.0 + r) / (1.0 - u_b)
        }
    }
}

/// A half vector (upper hemisphere) drawn from one signed part with density
/// [`diff_pdf_part_h`]: φ = 2π u.x, tan²θh = α²x with x from u.y; `None` if cos θh < 1e-9.
pub fn sample_diff_half(distribution: Distribution, alpha: f32, positive: bool, u: Vec2) -> Option<Vec3> {
    let x = diff_sample_x(distribution, positive, u.y);
    let t = alpha * alpha * x;
    let cos_h = 1.0 / (1.0 + t).sqrt();
    if !(cos_h >= DIFF_COS_EPSILON) {
        return None;
    }
    let sin_h = t.sqrt() * cos_h;
    let phi = 2.0 * PI * u.x;
    Some(Vec3::new(sin_h * phi.cos(), sin_h * phi.sin(), cos_h))
}

/// A direction reflected about a half vector drawn from one signed part (φ = 2π u.x, x from u.y),
/// or `None` if cos θo ≤ 0, wi·h ≤ 0, or cos θh < 1e-9.
pub fn sample_diff_part(distribution: Distribution, alpha: f32, wi: Vec3, positive: bool, u: Vec2) -> Option<Vec3> {
    if wi.z <= 0.0 {
        return None;
    }
    let h = sample_diff_half(distribution, alpha, positive, u)?;
    let wih = wi.dot(h);
    let wo = 2.0 * wih * h - wi;
    (wo.z > 0.0 && wih > 0.0).then_some(wo)
}

/// The negative part's piece uniform of an anisotropic sampler, from `u_sign` ∈ [½, 1) (the
/// positive part, `u_sign` < ½, has one piece and ignores it).
pub fn diff_piece(u_sign: f32) -> f32 {
    (u_sign - 0.5) / 0.5
}

/// A half vector from one signed part of the roughness derivative of a leaf with roughness
/// (α_u, α_v): the isotropic sampler when they are equal, else the anisotropic one targeting α_v
/// (`target_v`) or α_u ([`crate::bsdf::differential_aniso`]); `u_piece` picks the anisotropic
/// negative part's piece.
pub fn sample_diff_half_leaf(
    distribution: Distribution,
    alpha: Vec2,
    target_v: bool,
    positive: bool,
    u_piece: f32,
    u: Vec2,
) -> Option<Vec3> {
    if alpha.x != alpha.y {
        return sample_aniso_diff_half(distribution, alpha, target_v, positive, u_piece, u);
    }
    sample_diff_half(distribution, alpha.x, positive, u)
}

/// Half-vector density of one signed part of [`sample_diff_half_leaf`].
pub fn diff_pdf_part_h_leaf(distribution: Distribution, alpha: Vec2, target_v: bool, h: Vec3, positive: bool) -> f32 {
    if alpha.x != alpha.y {
        return aniso_diff_pdf_part_h(distribution, alpha, target_v, h, positive);
    }
    diff_pdf_part_h(distribution, alpha.x, h, positive)
}

/// Half-vector density of the coin-mixed [`sample_diff_half_leaf`], ½p⁺ + ½p⁻.
pub fn diff_pdf_mixed_h_leaf(distribution: Distribution, alpha: Vec2, target_v: bool, h: Vec3) -> f32 {
    if alpha.x != alpha.y {
        return aniso_diff_pdf_mixed_h(distribution, alpha, target_v, h);
    }
    diff_pdf_abs_h(distribution, alpha.x, h)
}

/// The half vector of (wi, wo) if the configuration is valid for a reflection density (cos θi,
/// cos θo, wi·h, wo·h all > 0), with wo·h.
fn reflection_half(wi: Vec3, wo: Vec3) -> Option<(Vec3, f32)> {
    if wi.z <= 0.0 || wo.z <= 0.0 {
        return None;
    }
    let h = (wi + wo).normalize();
    let woh = wo.dot(h);
    (wi.dot(h) > 0.0 && woh > 0.0).then_some((h, woh))
}

/// Direction density of the coin-mixed differential technique, p_abs(h)/(4 wo·h) = ½p⁺ + ½p⁻,
/// with the validity of the primal density.
pub fn diff_pdf(distribution: Distribution, alpha: f32, wi: Vec3, wo: Vec3) -> f32 {
    match reflection_half(wi, wo) {
        Some((h, woh)) => diff_pdf_abs_h(distribution, alpha, h) / (4.0 * woh),
        None => 0.0,
    }
}

/// Direction density of one signed part's sampler.
pub fn diff_pdf_part(distribution: Distribution, alpha: f32, positive: bool, wi: Vec3, wo: Vec3) -> f32 {
    match reflection_half(wi, wo) {
        Some((h, woh)) => diff_pdf_part_h(distribution, alpha, h, positive) / (4.0 * woh),
        None => 0.0,
    }
}

/// Rough conductor with roughness (α_u, α_v), isotropic or not: a direction reflected about a half
/// vector from one signed part ([`sample_diff_half_leaf`]); `None` as [`sample_diff_part`].
pub fn sample_diff_conductor(
    distribution: Distribution,
    alpha: Vec2,
    target_v: bool,
    wi: Vec3,
    positive: bool,
    u_piece: f32,
    u: Vec2,
) -> Option<Vec3> {
    if wi.z <= 0.0 {
        return None;
    }
    let h = sample_diff_half_leaf(distribution, alpha, target_v, positive, u_piece, u)?;
    let wih = wi.dot(h);
    let wo = 2.0 * wih * h - wi;
    (wo.z > 0.0 && wih > 0.0).then_some(wo)
}

/// Direction density of [`sample_diff_conductor`]'s coin mixture, ½p⁺ + ½p⁻ through 1/(4 wo·h).
pub fn diff_pdf_conductor(distribution: Distribution, alpha: Vec2, target_v: bool, wi: Vec3, wo: Vec3) -> f32 {
    match reflection_half(wi, wo) {
        Some((h, woh)) => diff_pdf_mixed_h_leaf(distribution, alpha, target_v, h) / (4.0 * woh),
        None => 0.0,
    }
}

/// Direction density of one signed part of [`sample_diff_conductor`], p±(h)/(4 wo·h).
pub fn diff_pdf_conductor_part(
    distribution: Distribution,
    alpha: Vec2,
    target_v: bool,
    positive: bool,
    wi: Vec3,
    wo: Vec3,
) -> f32 {
    match reflection_half(wi, wo) {
        Some((h, woh)) => diff_pdf_part_h_leaf(distribution, alpha, target_v, h, positive) / (4.0 * woh),
        None => 0.0,
    }
}

/// Rough dielectric: a microfacet normal m drawn from one signed part of ∂α[D(m) cos θm] in the
/// upper hemisphere (the hemisphere wi sees, mirrored when wi is below the surface), then
/// reflection about m with probability F(wi·m) or refraction through it, as the primal sampler
/// leaves through its visible normal (ALGORITHMS.md §4.2 carried to the dielectric's lobe
/// choice); `None` for a normal wi does not see or a direction on the wrong side. An anisotropic
/// leaf draws m from the derivative by α_v (`target_v`) or α_u, `u_piece` as
/// [`sample_diff_half_leaf`].
pub fn sample_diff_dielectric(
    leaf: &RoughDielectricLeaf,
    target_v: bool,
    wi: Vec3,
    positive: bool,
    u_piece: f32,
    u_lobe: f32,
    u: Vec2,
) -> Option<Vec3> {
    if wi.z == 0.0 {
        return None;
    }
    let alpha = Vec2::new(leaf.alpha, leaf.alpha_v);
    let m = sample_diff_half_leaf(leaf.distribution, alpha, target_v, positive, u_piece, u)?;
    let up = if wi.z > 0.0 { wi } else { -wi };
    if up.dot(m) <= 0.0 {
        return None;
    }
    leaf.scatter(wi, m, u_lobe)
}

/// Direction density of the rough dielectric's coin-mixed differential technique:
/// p_abs(m) · (F or 1 − F) · |∂m/∂wo| = ½ of each signed part's.
pub fn diff_pdf_dielectric(leaf: &RoughDielectricLeaf, target_v: bool, wi: Vec3, wo: Vec3) -> f32 {
    let alpha = Vec2::new(leaf.alpha, leaf.alpha_v);
    leaf.pdf_through(wi, wo, |m| diff_pdf_mixed_h_leaf(leaf.distribution, alpha, target_v, m))
}

/// Direction density of one signed part's rough-dielectric sampler.
pub fn diff_pdf_dielectric_part(leaf: &RoughDielectricLeaf, target_v: bool, positive: bool, wi: Vec3, wo: Vec3) -> f32 {
    let alpha = Vec2::new(leaf.alpha, leaf.alpha_v);
    leaf.pdf_through(wi, wo, |m| diff_pdf_part_h_leaf(leaf.distribution, alpha, target_v, m, positive))
}

/// Rough plastic: with the coating's probability P(cos θi) of its primal sampler, a reflection
/// about a half vector drawn from one signed part of ∂α[D cos θh] (the coating's lobe, as a
/// conductor's); otherwise the base by the cosine, as the primal sampler (the base depends on α
/// only through the coating's transmittance, smoothly in direction). `None` as the parts' sampler.
pub fn sample_diff_plastic(leaf: &PlasticLeaf, wi: Vec3, positive: bool, u_lobe: f32, u: Vec2) -> Option<Vec3> {
    if wi.z <= 0.0 {
        return None;
    }
    if u_lobe < leaf.coating_probability(wi.z) {
        sample_diff_part(leaf.distribution, leaf.alpha, wi, positive, u)
    } else {
        let wo = crate::sampling::sample_cosine_hemisphere(u);
        (wo.z > 0.0).then_some(wo)
    }
}

/// The rough plastic's differential density, with `coat` the coating part's density at (wi, wo):
/// P·coat + (1 − P)·cos θo/π.
fn plastic_mixture(leaf: &PlasticLeaf, wi: Vec3, wo: Vec3, coat: f32) -> f32 {
    if wi.z <= 0.0 || wo.z <= 0.0 {
        return 0.0;
    }
    let p = leaf.coating_probability(wi.z);
    p * coat + (1.0 - p) * wo.z * std::f32::consts::FRAC_1_PI
}

/// Direction density of the rough plastic's coin-mixed differential technique.
pub fn diff_pdf_plastic(leaf: &PlasticLeaf, wi: Vec3, wo: Vec3) -> f32 {
    plastic_mixture(leaf, wi, wo, diff_pdf(leaf.distribution, leaf.alpha, wi, wo))
}

/// Direction density of one signed part's rough-plastic sampler.
pub fn diff_pdf_plastic_part(leaf: &PlasticLeaf, positive: bool, wi: Vec3, wo: Vec3) -> f32 {
    plastic_mixture(leaf, wi, wo, diff_pdf_part(leaf.distribution, leaf.alpha, positive, wi, wo))
}

/// Whether the BSDF has a differential sampler: rough conductors, dielectrics and plastics and
/// blends do, the other leaves do not.
pub fn bsdf_diff_capable(b: &Bsdf) -> bool {
    b.blend || matches!(b.leaves[0], Leaf::RoughConductor { .. } | Leaf::RoughDielectric(_) | Leaf::RoughPlastic(_))
}

/// Density of the differential technique: ½(p_f0 + p_f1) for a blend, the coin-mixed roughness
/// density for a rough conductor, dielectric or plastic, and the primal density for the other
/// leaves (ALGORITHMS.md §4.1). `target_v`: an anisotropic conductor's or dielectric's target is
/// its α_v (else α_u; ignored by isotropic leaves).
pub fn bsdf_pdf_diff(b: &Bsdf, target_v: bool, wi: Vec3, wo: Vec3) -> f32 {
    if b.blend {
        return 0.5 * (leaf_pdf(&b.leaves[0], wi, wo) + leaf_pdf(&b.leaves[1], wi, wo));
    }
    match b.leaves[0] {
        Leaf::RoughConductor { distribution, alpha, alpha_v, .. } => {
            diff_pdf_conductor(distribution, Vec2::new(alpha, alpha_v), target_v, wi, wo)
        }
        Leaf::RoughDielectric(ref d) => diff_pdf_dielectric(d, target_v, wi, wo),
        Leaf::RoughPlastic(ref p) => diff_pdf_plastic(p, wi, wo),
        Leaf::Diffuse { .. }
        | Leaf::Smooth(_)
        | Leaf::SmoothPlastic(_)
        | Leaf::Principled(_)
        | Leaf::PrincipledThin(_) => leaf_pdf(&b.leaves[0], wi, wo),
    }
}

/// Samples the differential technique. Rough conductor, dielectric or plastic: the positive part
/// if `u_sign < 0.5`, else the negative one (the dielectric then reflects or refracts by `u_lobe`;
/// the plastic samples its coating so with its coating probability, else its base). Blend: child
/// 1 if `u_lobe ≤ ½`, else child 0, sampled with the child's primal sampler. Other leaves (not
/// capable): their primal sampler. The value is the whole BSDF's f̂ and the pdf
/// is [`bsdf_pdf_diff`] at the sampled direction; `None` for an invalid sample. An anisotropic
/// conductor or dielectric samples the derivative by α_v (`target_v`) or α_u, its negative part's
/// piece by [`diff_piece`]`(u_sign)`.
pub fn bsdf_sample_diff(b: &Bsdf, target_v: bool, wi: Vec3, u_sign: f32, u_lobe: f32, u: Vec2) -> Option<BsdfSample> {
    let wo = if b.blend {
        let (leaf, u_lobe) =
            if u_lobe <= 0.5 { (&b.leaves[1], u_lobe / 0.5) } else { (&b.leaves[0], (u_lobe - 0.5) / 0.5) };
        leaf_sample(leaf, wi, u_lobe, u)?
    } else {
        match b.leaves[0] {
            Leaf::RoughConductor { distribution, alpha, alpha_v, .. } => sample_diff_conductor(
                distribution,
                Vec2::new(alpha, alpha_v),
                target_v,
                wi,
                u_sign < 0.5,
                diff_piece(u_sign),
                u,
            )?,
            Leaf::RoughDielectric(ref d) => {
                sample_diff_dielectric(d, target_v, wi, u_sign < 0.5, diff_piece(u_sign), u_lobe, u)?
            }
            Leaf::RoughPlastic(ref p) => sample_diff_plastic(p, wi, u_sign < 0.5, u_lobe, u)?,
            Leaf::Diffuse { .. }
            | Leaf::Smooth(_)
            | Leaf::SmoothPlastic(_)
            | Leaf::Principled(_)
            | Leaf::PrincipledThin(_) => leaf_sample(&b.leaves[0], wi, u_lobe, u)?,
        }
    };
    let pdf = bsdf_pdf_diff(b, target_v, wi, wo);
    if !(pdf > 0.0) {
        return None;
    }
    Some(BsdfSample { wo, pdf, value: bsdf_eval(b, wi, wo), delta: false })
}

#[cfg(test)]
#[path = "differential_tests.rs"]
mod tests;

//! Differential samplers for anisotropic microfacet roughness (α_u, α_v): the α_u- or α_v-derivative
//! of D(h) cos θh split into two separable positive parts, each sampled exactly in stretched slopes.
//! Twin of the anisotropic section of `shaders/lib/differential.glsl`: same names, same f32
//! operation order.
//!
//! In stretched slopes (X, Y) = (h_x/(α_u h_z), h_y/(α_v h_z)), D(h) cos θh dω_h = P(X, Y) dX dY
//! with P = 1/(π(1 + r²)²) (GGX) or e^{−r²}/π (Beckmann), r² = X² + Y². Write A for the stretched
//! slope along the target's axis and B for the other (target α_u: A = X; target α_v: A = Y). Then
//! ∂_{α_t}[D cos θh] dω_h = (1/α_t)·(Λ⁺ − Λ⁻) dX dY with
//!
//! | distribution | Λ⁺                  | Λ⁻                     | mass of each |
//! |--------------|---------------------|------------------------|--------------|
//! | GGX          | 3A²/(π(1 + r²)³)    | (1 + B²)/(π(1 + r²)³)  | 3/4          |
//! | Beckmann     | 2A² e^{−r²}/π       | e^{−r²}/π              | 1            |
//!
//! (GGX: ∂_{α_t} P = P·(4A²/(1 + r²) − 1)/α_t; Beckmann: P·(2A² − 1)/α_t.) In polar form
//! (A, B) = ρ(cos φ, sin φ) each part is a mixture of separable pieces, an angular density
//! (cos²φ/π, sin²φ/π or 1/(2π)) times a radial one in v = ρ²:
//!
//! | piece                         | angular  | radial in v                     | v from u_b                        |
//! |-------------------------------|----------|---------------------------------|-----------------------------------|
//! | GGX Λ⁺                        | cos²φ    | 2v/(1 + v)³, F = (v/(1 + v))²   | √u/(1 − √u)                       |
//! | GGX Λ⁻, probability 2/3       | uniform  | 2/(1 + v)³, F = 1 − 1/(1 + v)²  | 1/√(1 − u) − 1                    |
//! | GGX Λ⁻, probability 1/3       | sin²φ    | 2v/(1 + v)³                     | as Λ⁺                             |
//! | Beckmann Λ⁺                   | cos²φ    | v e^{−v}, F = 1 − (1 + v)e^{−v} | −1 − W₋₁((u − 1)/e)               |
//! | Beckmann Λ⁻                   | uniform  | e^{−v}, F = 1 − e^{−v}          | −ln(1 − u)                        |
//!
//! The angular density cos²φ/π has the CDF (φ + sin φ cos φ)/π on [0, π]; it has no closed inverse
//! and is inverted on a quarter period by Newton's method with a fixed number of steps from a
//! starting point on the side where the steps converge monotonically ([`sample_cos2_quarter`]).
//! The separable parts are not |Λ|'s positive and negative parts (their supports overlap): their
//! coin mixture ½(p⁺ + p⁻) is a density that covers |Λ| everywhere (p⁺ + p⁻ ≥ |Λ|/mass). Their
//! masses are 3/4 + 3/4 against ∫|Λ| = 0.827 in stretched slopes (GGX, 1.81×) and 1 + 1 against
//! 0.968 (Beckmann, 2.07×), by quadrature, where the isotropic decomposition has exactly ∫|Λ|.

use std::f32::consts::{FRAC_PI_2, PI};

use glam::{Vec2, Vec3};

use crate::bsdf::differential::{DIFF_COS_EPSILON, diff_sample_x};
use crate::bsdf::rough_conductor::Distribution;

/// Newton steps of the quarter-period angular inversion (written out in GLSL).
const COS2_NEWTON_STEPS: usize = 4;
/// Below this δ, δ − sin δ is evaluated by its Taylor series (no cancellation).
const SIN_SERIES_BELOW: f32 = 0.5;

/// The mass of each signed part of ∂_{α_t}[D cos θh] over the hemisphere: 3/(4α_t) for GGX,
/// 1/α_t for Beckmann (the two parts have equal mass: ∫D cos θh = 1 for every α).
pub fn aniso_diff_norm(distribution: Distribution, alpha_target: f32) -> f32 {
    match distribution {
        Distribution::Beckmann => 1.0 / alpha_target,
        Distribution::Ggx => 0.75 / alpha_target,
    }
}

/// δ − sin δ for δ ∈ [0, π], by its series below 0.5.
fn delta_minus_sin(d: f32) -> f32 {
    if d < SIN_SERIES_BELOW {
        let d2 = d * d;
        d * d2 / 6.0 * (1.0 - d2 / 20.0 * (1.0 - d2 / 42.0 * (1.0 - d2 / 72.0 * (1.0 - d2 / 110.0))))
    } else {
        d - d.sin()
    }
}

/// φ ∈ [0, π/2] with density (4/π) cos²φ, i.e. ψ = 2φ solving ψ + sin ψ = π u_a. For u_a ≤ ½ the
/// steps run on ψ from ψ₀ = πu_a/2 (left of the root of a concave increasing function: monotone);
/// above, on δ = π − ψ solving δ − sin δ = π(1 − u_a) from δ₀ = (6π(1 − u_a))^{1/3}, left of the root
/// of a convex increasing function (one step overshoots, the rest descend monotonically). Each
/// iterate is clamped to [0, π].
pub fn sample_cos2_quarter(u_a: f32) -> f32 {
    if u_a <= 0.5 {
        let c = PI * u_a;
        let mut psi = 0.5 * c;
        for _ in 0..COS2_NEWTON_STEPS {
            let f = psi + psi.sin() - c;
            psi = (psi - f / (1.0 + psi.cos())).clamp(0.0, PI);
        }
        0.5 * psi
    } else {
        let d = PI * (1.0 - u_a);
        let mut delta = (6.0 * d).cbrt();
        for _ in 0..COS2_NEWTON_STEPS {
            let half = (0.5 * delta).sin();
            let slope = 2.0 * half * half;
            if slope > 0.0 {
                delta = (delta - (delta_minus_sin(delta) - d) / slope).clamp(0.0, PI);
            }
        }
        FRAC_PI_2 - 0.5 * delta
    }
}

/// φ ∈ [0, 2π) with density cos²φ/π: the quarter-period sample reflected into the quadrant
/// ⌊4u_a⌋, with the fraction of 4u_a as its uniform.
pub fn sample_cos2_angle(u_a: f32) -> f32 {
    let s = 4.0 * u_a;
    let quadrant = s.floor().min(3.0);
    let phi = sample_cos2_quarter((s - quadrant).min(1.0));
    match quadrant as u32 {
        0 => phi,
        1 => PI - phi,
        2 => PI + phi,
        _ => 2.0 * PI - phi,
    }
}

/// v = ρ² of one separable piece from `u_b` (module table): `weighted` is the piece whose angular
/// density is cos²φ or sin²φ, else the uniform one. May be +∞ at u_b = 1.
pub fn aniso_sample_radius2(distribution: Distribution, weighted: bool, u_b: f32) -> f32 {
    match (distribution, weighted) {
        (Distribution::Ggx, true) => {
            let s = u_b.max(0.0).sqrt();
            s * (1.0 + s) / (1.0 - u_b)
        }
        (Distribution::Ggx, false) => {
            let s = (1.0 - u_b).max(0.0).sqrt();
            u_b / (s * (1.0 + s))
        }
        (Distribution::Beckmann, true) => (diff_sample_x(Distribution::Beckmann, true, u_b) - 1.0).max(0.0),
        (Distribution::Beckmann, false) => -(1.0 - u_b).ln(),
    }
}

/// A half vector (upper hemisphere) from one signed part of the α_u- (`target_v` false) or
/// α_v-derivative (true), with density [`aniso_diff_pdf_part_h`]. `u_piece` picks the piece of
/// GGX's negative part (the uniform one below 2/3); u.x the angle, u.y the radius. `None` if
/// cos θh < 1e-9.
pub fn sample_aniso_diff_half(
    distribution: Distribution,
    alpha: Vec2,
    target_v: bool,
    positive: bool,
    u_piece: f32,
    u: Vec2,
) -> Option<Vec3> {
    // Which piece: the positive part's (cos²φ), GGX's negative sin²φ piece, or a uniform one.
    let weighted = positive || (distribution == Distribution::Ggx && u_piece >= 2.0 / 3.0);
    let v = aniso_sample_radius2(distribution, weighted, u.y);
    let rho = v.sqrt();
    let phi = if !weighted {
        2.0 * PI * u.x
    } else if positive {
        sample_cos2_angle(u.x)
    } else {
        sample_cos2_angle(u.x) + FRAC_PI_2
    };
    let (a, b) = (rho * phi.cos(), rho * phi.sin());
    let (x, y) = if target_v { (b, a) } else { (a, b) };
    let (sx, sy) = (alpha.x * x, alpha.y * y);
    let cos_h = 1.0 / (1.0 + sx * sx + sy * sy).sqrt();
    if !(cos_h >= DIFF_COS_EPSILON) {
        return None;
    }
    Some(Vec3::new(sx * cos_h, sy * cos_h, cos_h))
}

/// Half-vector density (per solid angle) of one signed part, Λ±(A, B)/mass · dXdY/dω_h with
/// dXdY/dω_h = 1/(α_u α_v cos³θh), in forms without overflow (S = h_z² + (h_x/α_u)² + (h_y/α_v)²):
/// GGX p⁺ = 4a²h_z/(π α_u α_v S³), p⁻ = (4/3)(h_z² + b²)h_z/(π α_u α_v S³) with a, b = h along the
/// target's and the other axis over its α; Beckmann p⁻ = e^{−r²}/(π α_u α_v h_z³), p⁺ = 2A²p⁻.
/// 0 if cos θh < 1e-9.
pub fn aniso_diff_pdf_part_h(distribution: Distribution, alpha: Vec2, target_v: bool, h: Vec3, positive: bool) -> f32 {
    let c = h.z;
    if c < DIFF_COS_EPSILON {
        return 0.0;
    }
    let (x, y) = (h.x / alpha.x, h.y / alpha.y);
    let (a, b) = if target_v { (y, x) } else { (x, y) };
    let (a2, b2, c2) = (a * a, b * b, c * c);
    let norm = PI * alpha.x * alpha.y;
    match distribution {
        Distribution::Ggx => {
            let s = c2 + a2 + b2;
            let s3 = s * s * s;
            if positive { 4.0 * a2 * c / (norm * s3) } else { 4.0 * (c2 + b2) * c / (3.0 * norm * s3) }
        }
        Distribution::Beckmann => {
            let g = (-(a2 + b2) / c2).exp();
            if g == 0.0 {
                return 0.0;
            }
            let neg = g / (norm * c2 * c);
            if positive { 2.0 * (a2 / c2) * neg } else { neg }
        }
    }
}

/// The coin-mixed half-vector density ½p⁺ + ½p⁻.
pub fn aniso_diff_pdf_mixed_h(distribution: Distribution, alpha: Vec2, target_v: bool, h: Vec3) -> f32 {
    0.5 * (aniso_diff_pdf_part_h(distribution, alpha, target_v, h, true)
        + aniso_diff_pdf_part_h(distribution, alpha, target_v, h, false))
}

#[cfg(test)]
#[path = "differential_aniso_tests.rs"]
mod tests;

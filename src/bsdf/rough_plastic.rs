//! Rough plastic (Mitsuba's `roughplastic`): a rough dielectric coating (Beckmann or GGX, Smith
//! masking, dielectric Fresnel) over a Lambertian base, with the base's light attenuated by the
//! coating's transmittance on the way in and out and renormalised by its internal reflectance.
//!
//! f̂(wi, wo) = F(wi·h) D(h) G(wi, wo) / (4 cos θi) · s
//!           + ρ / (1 − ρ̄ Rᵢ) · T(cos θi) T(cos θo) cos θo / (π η²)
//!
//! with η = int_ior / ext_ior, s the specular reflectance, ρ the diffuse reflectance, ρ̄ = ρ
//! (`nonlinear`) or 1, T(μ) the coating's directional transmittance and Rᵢ its internal diffuse
//! reflectance — both integrals over the microfacet distribution that [`CoatingTable`] tabulates
//! as Mitsuba does (64 values of μ, Gauss–Legendre quadrature over visible normals), here with
//! their derivatives by α as well: Mitsuba computes the table outside its autodiff, so its α
//! gradient lacks the base's share; pathgrad's includes it (the conformance matrix checks it
//! against Mitsuba's finite differences).
//!
//! Sampling picks the coating with probability p = (1 − T(cos θi)) w / ((1 − T(cos θi)) w +
//! T(cos θi)(1 − w)), w = s̄ / (ρ̄ + s̄) from the mean reflectances, and then a visible normal;
//! the base otherwise, by the cosine.

use std::f32::consts::FRAC_1_PI;

use glam::{Vec2, Vec3};

use super::rough_conductor::{
    Distribution, microfacet_d, microfacet_eval_scalar_parts, microfacet_g1, microfacet_visible_normal,
};
use crate::contract::{COATING_RES, COATING_TABLE_LEN};

/// Dielectric Fresnel reflectance for cos θi (the side by its sign) and relative index `eta`
/// (inside over outside), with total internal reflection giving 1 (Mitsuba's `fresnel`). Also the
/// transmitted cosine (sign opposite to cos θi) and the ratio of indices η_t/η_i... as `eta_ti`.
pub fn fresnel_dielectric(cos_i: f32, eta: f32) -> (f32, f32, f32) {
    let outside = cos_i >= 0.0;
    let (eta_it, eta_ti) = if outside { (eta, 1.0 / eta) } else { (1.0 / eta, eta) };
    let cos_t2 = 1.0 - (1.0 - cos_i * cos_i) * eta_ti * eta_ti;
    let ci = cos_i.abs();
    let ct = cos_t2.max(0.0).sqrt();
    let r = if eta == 1.0 {
        0.0
    } else if ci == 0.0 {
        1.0
    } else {
        let a_s = (ci - eta_it * ct) / (ci + eta_it * ct);
        let a_p = (ct - eta_it * ci) / (ct + eta_it * ci);
        0.5 * (a_s * a_s + a_p * a_p)
    };
    (r, if outside { -ct } else { ct }, eta_ti)
}

/// The coating's transmittance T(μ) at μ = max(10⁻⁶, k/63), k = 0..63, its internal diffuse
/// reflectance Rᵢ, and the derivatives of both by α.
///
/// ```
/// use pathgrad::bsdf::Distribution;
/// use pathgrad::bsdf::rough_plastic::CoatingTable;
/// let t = CoatingTable::new(Distribution::Ggx, 0.2, 1.5);
/// // Light enters best at normal incidence; a rougher coating lets less in there.
/// assert!(t.transmittance[63] > t.transmittance[0]);
/// assert!(t.dtransmittance[63] < 0.0 && t.internal > 0.0 && t.internal < 1.0);
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct CoatingTable {
    /// T at the 64 values of μ.
    pub transmittance: Vec<f32>,
    /// ∂T/∂α at the same μ.
    pub dtransmittance: Vec<f32>,
    /// Rᵢ.
    pub internal: f32,
    /// ∂Rᵢ/∂α.
    pub dinternal: f32,
}

/// Gauss–Legendre nodes and weights on [−1, 1] (weights sum to 2), by Newton's method on the
/// Legendre polynomial.
fn gauss_legendre(n: usize) -> Vec<(f64, f64)> {
    (0..n)
        .map(|i| {
            let mut x = (std::f64::consts::PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
            let mut dp = 1.0;
            for _ in 0..100 {
                let (mut p0, mut p1) = (1.0f64, x);
                for k in 2..=n {
                    let p2 = ((2 * k - 1) as f64 * x * p1 - (k - 1) as f64 * p0) / k as f64;
                    p0 = p1;
                    p1 = p2;
                }
                dp = n as f64 * (x * p1 - p0) / (x * x - 1.0);
                let step = p1 / dp;
                x -= step;
                if step.abs() < 1e-15 {
                    break;
                }
            }
            (x, 2.0 / ((1.0 - x * x) * dp * dp))
        })
        .collect()
}

/// ∫ over visible normals m of G1(wo, m) times the Fresnel share that leaves wi for wo: the
/// transmitted share into the other hemisphere (`transmit`) or the reflected one, quadrature as
/// Mitsuba's `eval_transmittance` / `eval_reflectance` (n × n nodes mapped to [0, 1]²).
fn coating_integral(distribution: Distribution, alpha: f32, wi: Vec3, eta: f32, transmit: bool) -> f64 {
    let nodes = gauss_legendre(if eta > 1.0 { 32 } else { 128 });
    let mut sum = 0.0f64;
    for &(x, wx) in &nodes {
        for &(y, wy) in &nodes {
            let u = Vec2::new((0.5 * x + 0.5) as f32, (0.5 * y + 0.5) as f32);
            let Some(m) = microfacet_visible_normal(distribution, Vec2::splat(alpha), wi, u) else { continue };
            let (f, cos_t, eta_ti) = fresnel_dielectric(wi.dot(m), eta);
            let (wo, share) = if transmit {
                (m * (wi.dot(m) * eta_ti + cos_t) - wi * eta_ti, 1.0 - f)
            } else {
                (2.0 * wi.dot(m) * m - wi, f)
            };
            let valid = if transmit { wo.z * wi.z < 0.0 } else { wo.z > 0.0 && wi.z > 0.0 };
            if valid {
                sum += f64::from(microfacet_g1(distribution, alpha, wo, m) * share) * wx * wy * 0.25;
            }
        }
    }
    sum
}

/// The μ of table entry k.
fn table_mu(k: usize) -> f32 {
    (k as f32 / (COATING_RES - 1) as f32).max(1e-6)
}

/// T and Rᵢ for one α.
fn coating_values(distribution: Distribution, alpha: f32, eta: f32) -> (Vec<f32>, f32) {
    let dir = |mu: f32| Vec3::new((1.0 - mu * mu).max(0.0).sqrt(), 0.0, mu);
    use rayon::prelude::*;
    let transmittance = (0..COATING_RES as usize)
        .into_par_iter()
        .map(|k| coating_integral(distribution, alpha, dir(table_mu(k)), eta, true) as f32)
        .collect();
    // Summed in index order after the parallel map, so the value does not depend on the threads.
    let internal = (0..COATING_RES as usize)
        .into_par_iter()
        .map(|k| coating_integral(distribution, alpha, dir(table_mu(k)), 1.0 / eta, false) * f64::from(table_mu(k)))
        .collect::<Vec<f64>>()
        .iter()
        .sum::<f64>()
        / f64::from(COATING_RES)
        * 2.0;
    (transmittance, internal as f32)
}

impl CoatingTable {
    /// The table of a coating of roughness `alpha` and relative index `eta`; the derivatives by
    /// central differences of the (deterministic) quadrature, step 1 % of α.
    pub fn new(distribution: Distribution, alpha: f32, eta: f32) -> CoatingTable {
        let (transmittance, internal) = coating_values(distribution, alpha, eta);
        let h = 0.01 * alpha;
        let (t_plus, r_plus) = coating_values(distribution, alpha + h, eta);
        let (t_minus, r_minus) = coating_values(distribution, (alpha - h).max(1e-4), eta);
        let span = alpha + h - (alpha - h).max(1e-4);
        CoatingTable {
            transmittance,
            dtransmittance: t_plus.iter().zip(&t_minus).map(|(p, m)| (p - m) / span).collect(),
            internal,
            dinternal: (r_plus - r_minus) / span,
        }
    }

    /// The table as the kernels read it: T, ∂T/∂α, Rᵢ, ∂Rᵢ/∂α.
    pub fn flatten(&self) -> Vec<f32> {
        let mut v = self.transmittance.clone();
        v.extend_from_slice(&self.dtransmittance);
        v.push(self.internal);
        v.push(self.dinternal);
        v
    }
}

/// Linear interpolation in a flattened table's T (or, `offset` = 64, ∂T/∂α) at μ (Mitsuba's
/// `lerp_gather`).
pub fn table_lerp(table: &[f32], offset: usize, mu: f32) -> f32 {
    let x = mu * (COATING_RES - 1) as f32;
    let i = (x as u32).min(COATING_RES - 2) as usize;
    let (v0, v1) = (table[offset + i], table[offset + i + 1]);
    v0 + (v1 - v0) * (x - i as f32)
}

/// A rough plastic leaf's values.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlasticLeaf {
    /// Microfacet distribution.
    pub distribution: Distribution,
    /// Roughness α.
    pub alpha: f32,
    /// Diffuse reflectance ρ.
    pub diffuse: Vec3,
    /// Specular reflectance s.
    pub specular: Vec3,
    /// int_ior / ext_ior.
    pub eta: f32,
    /// Probability weight w of the coating in sampling.
    pub specular_weight: f32,
    /// Mitsuba's `nonlinear`.
    pub nonlinear: bool,
    /// The flattened [`CoatingTable`].
    pub table: [f32; COATING_TABLE_LEN as usize],
}

impl PlasticLeaf {
    fn internal(&self) -> f32 {
        self.table[2 * COATING_RES as usize]
    }

    /// 1 / (1 − ρ̄ Rᵢ) per channel.
    fn renormalisation(&self) -> Vec3 {
        let rbar = if self.nonlinear { self.diffuse } else { Vec3::ONE };
        Vec3::ONE / (Vec3::ONE - rbar * self.internal())
    }

    /// Probability of sampling the coating at cos θi.
    pub fn coating_probability(&self, cos_i: f32) -> f32 {
        let t_i = table_lerp(&self.table, 0, cos_i);
        let ps = (1.0 - t_i) * self.specular_weight;
        let pd = t_i * (1.0 - self.specular_weight);
        ps / (ps + pd)
    }

    /// f̂(wi, wo).
    pub fn eval(&self, wi: Vec3, wo: Vec3) -> Vec3 {
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return Vec3::ZERO;
        }
        let h = (wi + wo).normalize();
        let (f, _, _) = fresnel_dielectric(wi.dot(h), self.eta);
        let (scalar, _) = microfacet_eval_scalar_parts(self.distribution, Vec2::splat(self.alpha), wi, wo, h);
        let t_i = table_lerp(&self.table, 0, wi.z);
        let t_o = table_lerp(&self.table, 0, wo.z);
        let base = FRAC_1_PI / (self.eta * self.eta) * wo.z * t_i * t_o;
        self.specular * (f * scalar) + self.diffuse * self.renormalisation() * base
    }

    /// The sampling density of `wo`.
    pub fn pdf(&self, wi: Vec3, wo: Vec3) -> f32 {
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return 0.0;
        }
        let p = self.coating_probability(wi.z);
        let h = (wi + wo).normalize();
        let coat = microfacet_d(self.distribution, self.alpha, h) * microfacet_g1(self.distribution, self.alpha, wi, h)
            / (4.0 * wi.z);
        p * coat + (1.0 - p) * wo.z * FRAC_1_PI
    }

    /// A direction: the coating (a reflection about a visible normal) when `u_lobe` < the coating's
    /// probability, else the base by the cosine.
    pub fn sample(&self, wi: Vec3, u_lobe: f32, u: Vec2) -> Option<Vec3> {
        if wi.z <= 0.0 {
            return None;
        }
        if u_lobe < self.coating_probability(wi.z) {
            let m = microfacet_visible_normal(self.distribution, Vec2::splat(self.alpha), wi, u)?;
            let wo = 2.0 * wi.dot(m) * m - wi;
            (wo.z > 0.0).then_some(wo)
        } else {
            let wo = crate::sampling::sample_cosine_hemisphere(u);
            (wo.z > 0.0).then_some(wo)
        }
    }

    /// ∂f̂/∂ρ per channel, ∂f̂/∂α and ∂f̂/∂s per channel (s the specular reflectance).
    pub fn eval_grad(&self, wi: Vec3, wo: Vec3) -> (Vec3, Vec3, Vec3) {
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return (Vec3::ZERO, Vec3::ZERO, Vec3::ZERO);
        }
        let h = (wi + wo).normalize();
        let (f, _, _) = fresnel_dielectric(wi.dot(h), self.eta);
        let (scalar, dscalar) = microfacet_eval_scalar_parts(self.distribution, Vec2::splat(self.alpha), wi, wo, h);
        let (t_i, t_o) = (table_lerp(&self.table, 0, wi.z), table_lerp(&self.table, 0, wo.z));
        let (dt_i, dt_o) =
            (table_lerp(&self.table, COATING_RES as usize, wi.z), table_lerp(&self.table, COATING_RES as usize, wo.z));
        let k = FRAC_1_PI / (self.eta * self.eta) * wo.z;
        let n = self.renormalisation();
        let rbar = if self.nonlinear { self.diffuse } else { Vec3::ONE };
        let dinternal = self.table[2 * COATING_RES as usize + 1];
        // ∂/∂ρ of ρ/(1 − ρ̄Rᵢ): n, or n² when ρ̄ = ρ.
        let dn = if self.nonlinear { n * n } else { n };
        let d_diffuse = dn * (k * t_i * t_o);
        // ∂/∂α: the coating's lobe, the two transmittances and the renormalisation.
        let d_alpha = self.specular * (f * dscalar.element_sum())
            + self.diffuse * n * (k * (dt_i * t_o + t_i * dt_o))
            + self.diffuse * n * n * rbar * (dinternal * k * t_i * t_o);
        (d_diffuse, d_alpha, Vec3::splat(f * scalar))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The coating table against Mitsuba 3.9.1's own quadrature (GGX, α = 0.2, η of bk7 in air):
    /// T(μ) by `eval_transmittance`'s 32 × 32 Gauss–Legendre nodes over its visible-normal sampler
    /// (`mi.MicrofacetDistribution.sample`, `mi.fresnel`, `mi.refract`, `smith_g1` in Python) and
    /// Rᵢ by `mi.eval_reflectance` averaged as `roughplastic` does.
    #[test]
    fn the_coating_table_is_mitsubas() {
        let eta = 1.5046 / 1.000_277;
        let t = CoatingTable::new(Distribution::Ggx, 0.2, eta).flatten();
        let dir = |mu: f32| Vec3::new((1.0 - mu * mu).max(0.0).sqrt(), 0.0, mu);
        for (mu, mitsuba) in [(0.05f32, 0.681_571), (0.3, 0.819_782), (0.7, 0.937_176), (1.0, 0.956_685)] {
            let direct = coating_integral(Distribution::Ggx, 0.2, dir(mu), eta, true);
            assert!((direct - mitsuba).abs() < 2e-6, "T({mu}) = {direct}, Mitsuba {mitsuba}");
            // The table interpolates between its 64 nodes.
            assert!((f64::from(table_lerp(&t, 0, mu)) - mitsuba).abs() < 1e-3, "lerp T({mu})");
        }
        assert!((t[2 * COATING_RES as usize] - 0.488_809_4).abs() < 2e-6, "Rᵢ {}", t[128]);
        // ∂Rᵢ/∂α by Mitsuba's quadrature at α ± 0.002: −0.686 05.
        assert!((t[2 * COATING_RES as usize + 1] + 0.686_05).abs() < 2e-3, "∂Rᵢ/∂α {}", t[129]);
    }

    #[test]
    fn fresnel_dielectric_limits() {
        // Normal incidence ((η − 1)/(η + 1))², total internal reflection from inside, index-matched 0.
        let (r, cos_t, _) = fresnel_dielectric(1.0, 1.5);
        assert!((r - 0.04).abs() < 1e-6 && (cos_t + 1.0).abs() < 1e-6);
        assert_eq!(fresnel_dielectric(-0.1, 1.5).0, 1.0);
        assert_eq!(fresnel_dielectric(0.5, 1.0).0, 0.0);
    }
}

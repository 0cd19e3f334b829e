//! Smooth plastic (Mitsuba's `plastic`): a smooth dielectric coating over a Lambertian base. The
//! coating reflects a Dirac delta (weight F(cos θi) · s); the base's light is attenuated by the
//! coating on the way in and out and renormalised by its diffuse internal reflectance:
//!
//! f̂_base(wi, wo) = ρ / (1 − ρ̄ F_dr(1/η)) · (1 − F(cos θi)) (1 − F(cos θo)) cos θo / (π η²)
//!
//! with ρ̄ = ρ (`nonlinear`) or 1 and F_dr Mitsuba's fitted diffuse Fresnel reflectance. Sampling
//! picks the coating with probability p = F(cos θi) w / (F(cos θi) w + (1 − F(cos θi))(1 − w)),
//! w = s̄ / (ρ̄ + s̄); the base otherwise, by the cosine. Evaluation and density are the base's
//! alone (next-event estimation sees only it); a sample of the coating is a delta sample
//! (`BsdfSample::delta`). Only ρ is a parameter: the coating's colour is a constant.

use std::f32::consts::FRAC_1_PI;

use glam::{Vec2, Vec3};

use super::rough_plastic::fresnel_dielectric;
use super::specular::reflect;
use super::{BsdfSample, LeafGrad};

/// Mitsuba's `fresnel_diffuse_reflectance`: the hemispherical average of the dielectric Fresnel
/// reflectance for relative index `eta` (Egan and Hilgeman's fit below 1, d'Eon and Irving's above).
pub fn fresnel_diffuse_reflectance(eta: f32) -> f32 {
    let inv = 1.0 / eta;
    if eta < 1.0 {
        0.0636 * inv + eta * (eta * -1.4399 + 0.7099) + 0.6681
    } else {
        0.919_317 + inv * (-3.4793 + inv * (6.75335 + inv * (-7.80989 + inv * (4.98554 + inv * -1.36881))))
    }
}

/// A smooth plastic leaf's values.
///
/// ```
/// use glam::{Vec2, Vec3};
/// use pathgrad::bsdf::plastic::SmoothPlasticLeaf;
/// let p = SmoothPlasticLeaf {
///     diffuse: Vec3::splat(0.5),
///     specular: Vec3::ONE,
///     eta: 1.5,
///     specular_weight: 0.5,
///     nonlinear: false,
/// };
/// let wi = Vec3::new(0.6, 0.0, 0.8);
/// // A small u_lobe takes the coating: a mirror delta; a large one the base, which eval gives.
/// assert!(p.sample(wi, 0.0, Vec2::splat(0.5)).unwrap().delta);
/// let base = p.sample(wi, 0.99, Vec2::splat(0.5)).unwrap();
/// assert_eq!(base.value, p.eval(wi, base.wo));
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SmoothPlasticLeaf {
    /// Diffuse reflectance ρ of the base.
    pub diffuse: Vec3,
    /// Specular reflectance s of the coating.
    pub specular: Vec3,
    /// int_ior / ext_ior.
    pub eta: f32,
    /// The coating's sampling weight w.
    pub specular_weight: f32,
    /// Mitsuba's `nonlinear`.
    pub nonlinear: bool,
}

impl SmoothPlasticLeaf {
    /// F(cos θi) and the probability of sampling the coating.
    fn coating(&self, cos_i: f32) -> (f32, f32) {
        let f = fresnel_dielectric(cos_i, self.eta).0;
        let ps = f * self.specular_weight;
        let pd = (1.0 - f) * (1.0 - self.specular_weight);
        (f, ps / (ps + pd))
    }

    /// The base's f̂ per unit of ρ toward `wo`, before the renormalisation, given F(cos θi).
    fn base_factor(&self, f_i: f32, wo: Vec3) -> f32 {
        let f_o = fresnel_dielectric(wo.z, self.eta).0;
        wo.z * FRAC_1_PI / (self.eta * self.eta) * (1.0 - f_i) * (1.0 - f_o)
    }

    /// 1 / (1 − ρ̄ F_dr(1/η)).
    fn renormalisation(&self) -> Vec3 {
        let rbar = if self.nonlinear { self.diffuse } else { Vec3::ONE };
        Vec3::ONE / (Vec3::ONE - rbar * fresnel_diffuse_reflectance(1.0 / self.eta))
    }

    /// The base's f̂ (the coating's delta is never evaluated).
    pub fn eval(&self, wi: Vec3, wo: Vec3) -> Vec3 {
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return Vec3::ZERO;
        }
        self.diffuse * self.renormalisation() * self.base_factor(fresnel_dielectric(wi.z, self.eta).0, wo)
    }

    /// The density with which the base's sampling draws `wo`.
    pub fn pdf(&self, wi: Vec3, wo: Vec3) -> f32 {
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return 0.0;
        }
        (1.0 - self.coating(wi.z).1) * wo.z * FRAC_1_PI
    }

    /// The coating's mirror direction (a delta sample) when `u_lobe` < its probability, else the
    /// base's cosine-distributed one.
    pub fn sample(&self, wi: Vec3, u_lobe: f32, u: Vec2) -> Option<BsdfSample> {
        if wi.z <= 0.0 {
            return None;
        }
        let (f_i, p) = self.coating(wi.z);
        if u_lobe < p {
            return Some(BsdfSample { wo: reflect(wi), pdf: p, value: self.specular * f_i, delta: true });
        }
        let wo = crate::sampling::sample_cosine_hemisphere(u);
        let pdf = self.pdf(wi, wo);
        (pdf > 0.0).then(|| BsdfSample { wo, pdf, value: self.eval(wi, wo), delta: false })
    }

    /// ∂f̂/∂ρ per channel at `wo` (in `color`): the base's; toward the mirror direction (the
    /// coating's sample, whose value s·F(cos θi) does not depend on ρ) the value's derivative by
    /// the specular colour s instead (in `trans`).
    pub fn eval_grad(&self, wi: Vec3, wo: Vec3) -> LeafGrad {
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return LeafGrad::default();
        }
        if wo == reflect(wi) {
            return LeafGrad { trans: Vec3::splat(fresnel_dielectric(wi.z, self.eta).0), ..LeafGrad::default() };
        }
        let n = self.renormalisation();
        let base = self.base_factor(fresnel_dielectric(wi.z, self.eta).0, wo);
        LeafGrad { color: (if self.nonlinear { n * n } else { n }) * base, ..LeafGrad::default() }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Mitsuba 3.9.1's `mi.fresnel_diffuse_reflectance` at a few indices.
    #[test]
    fn diffuse_fresnel_is_mitsubas() {
        for (eta, mitsuba) in
            [(1.49f32 / 1.000_277, 0.090_238_94), (1.000_277 / 1.49, 0.590_478_96), (2.4, 0.210_191_58)]
        {
            assert!(
                (fresnel_diffuse_reflectance(eta) - mitsuba).abs() < 2e-6,
                "{eta}: {}",
                fresnel_diffuse_reflectance(eta)
            );
        }
    }

    fn leaf(nonlinear: bool) -> SmoothPlasticLeaf {
        SmoothPlasticLeaf {
            diffuse: Vec3::new(0.2, 0.5, 0.8),
            specular: Vec3::new(1.0, 0.9, 0.8),
            eta: 1.49 / 1.000_277,
            specular_weight: 0.6,
            nonlinear,
        }
    }

    /// Base samples report the base's density and value; coating samples are mirror deltas with
    /// weight F·s over their probability, whose derivative by s is F; the whole albedo stays below
    /// 1; ∂f̂/∂ρ matches finite differences of the base's value.
    #[test]
    fn samples_weights_and_derivatives() {
        use crate::rng::{PassTag, RngKey, Stream, uniform4};
        for nonlinear in [false, true] {
            let l = leaf(nonlinear);
            let wi = Vec3::new(0.6, 0.0, 0.8);
            let (mut albedo, n) = (Vec3::ZERO, 20_000);
            for i in 0..n {
                let u = uniform4(RngKey::new(77, 0, PassTag::Test), i, 0, 1, Stream::Main, 1, 0);
                let s = l.sample(wi, u[0], Vec2::new(u[1], u[2])).unwrap();
                if s.delta {
                    assert_eq!(s.wo, reflect(wi));
                    let f = fresnel_dielectric(wi.z, l.eta).0;
                    assert!((s.value - l.specular * f).abs().max_element() < 1e-6);
                    // The coating sample's value is linear in the specular colour: its derivative
                    // F is what eval_grad reports there (and nothing for ρ).
                    let g = l.eval_grad(wi, s.wo);
                    assert_eq!((g.trans, g.color), (Vec3::splat(f), Vec3::ZERO));
                } else {
                    assert_eq!((s.pdf, s.value), (l.pdf(wi, s.wo), l.eval(wi, s.wo)));
                }
                albedo += s.value / s.pdf;
            }
            assert!((albedo / n as f32).max_element() < 1.0, "{}", albedo / n as f32);
            let wo = Vec3::new(-0.3, 0.4, (0.75f32).sqrt());
            let g = l.eval_grad(wi, wo).color;
            for c in 0..3 {
                let at = |v: f32| {
                    let mut m = l;
                    m.diffuse[c] = v;
                    m.eval(wi, wo)[c]
                };
                let fd = (at(l.diffuse[c] + 1e-3) - at(l.diffuse[c] - 1e-3)) / 2e-3;
                assert!((fd - g[c]).abs() < 1e-4 * fd.abs().max(1.0), "{nonlinear} {c}: {fd} vs {}", g[c]);
            }
            assert_eq!(l.eval_grad(wi, reflect(wi)).color, Vec3::ZERO);
        }
    }
}

//! Rough dielectric (Mitsuba's `roughdielectric`, Walter et al. 2007): a rough interface between
//! two dielectrics that reflects and refracts through a Beckmann or GGX microfacet distribution,
//! with visible-normal sampling (twin of `rough_dielectric_*` in `shaders/lib/bsdf.glsl`).
//!
//! Light arrives from either side; η is the interior's index over the exterior's, and a
//! direction below the surface sees 1/η. For wi and wo on the same side the half vector is
//! m = normalize(wi + wo), otherwise the generalised one m = normalize(wi + η_rel·wo) (η_rel the
//! ratio for wi's side), turned to the upper hemisphere; both directions must see m from their
//! own side. With F = F(wi·m) the dielectric Fresnel term, D, and G the Smith product,
//!
//! - reflection: f̂ = s_r · F·D·G / (4 |cos θi|);
//! - transmission: f̂ = s_t · |(1 − F)·D·G·(wi·m)(wo·m) / (cos θi (wi·m + η_rel wo·m)²)| — Mitsuba's
//!   radiance form, whose (1/η_rel)² compression cancels the η_rel² of the Jacobian.
//!
//! Sampling draws m among the normals visible from wi (mirrored to the upper hemisphere), then
//! reflects with probability F or refracts; a sample that lands on the side its lobe does not
//! serve (a reflection below the surface) is invalid, so the density of the valid samples is
//! D_vis(m) · (F or 1 − F) · |∂m/∂wo| at the half vector of (wi, wo), which [`RoughDielectricLeaf::pdf`]
//! gives. Mitsuba weighs such a sample 0; the expectation is the same.
//!
//! The distribution may be anisotropic (α_u along the shading frame's x, α_v along y, as
//! Mitsuba's `alpha_u`/`alpha_v`); every term above reads both.
//!
//! Parameters: α_u and α_v (the gradient by each holds the D·G derivative), the specular
//! reflectance (of reflected directions) and transmittance (of transmitted ones); η gets no
//! gradient (it moves the directions: attached derivatives).

use glam::{Vec2, Vec3};

use super::rough_conductor::{
    Distribution, microfacet_d_aniso, microfacet_d_dalpha_aniso, microfacet_g1_aniso, microfacet_g1_dalpha_aniso,
    microfacet_visible_normal,
};
use super::rough_plastic::fresnel_dielectric;

/// A rough dielectric's values.
///
/// ```
/// use glam::{Vec2, Vec3};
/// use pathgrad::bsdf::Distribution;
/// use pathgrad::bsdf::rough_dielectric::RoughDielectricLeaf;
/// let glass = RoughDielectricLeaf {
///     distribution: Distribution::Ggx,
///     alpha: 0.1,
///     alpha_v: 0.1,
///     reflectance: Vec3::ONE,
///     transmittance: Vec3::ONE,
///     eta: 1.5,
/// };
/// let wi = Vec3::new(0.0, 0.6, 0.8);
/// // Most light at this angle is refracted: below the surface, weighted by the sampler's density.
/// let wo = glass.sample(wi, 0.9, Vec2::new(0.3, 0.7)).unwrap();
/// assert!(wo.z < 0.0 && glass.pdf(wi, wo) > 0.0 && glass.eval(wi, wo).x > 0.0);
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RoughDielectricLeaf {
    /// Microfacet distribution.
    pub distribution: Distribution,
    /// Roughness α (α_u, along the shading frame's x).
    pub alpha: f32,
    /// Roughness α_v along the shading frame's y: `alpha` when isotropic.
    pub alpha_v: f32,
    /// RGB specular reflectance (multiplies reflected light).
    pub reflectance: Vec3,
    /// RGB specular transmittance (multiplies transmitted light).
    pub transmittance: Vec3,
    /// int_ior / ext_ior.
    pub eta: f32,
}

/// The geometry of a pair (wi, wo): the half vector m (upper hemisphere), whether it reflects,
/// and the index ratio η_rel for wi's side.
#[derive(Clone, Copy, Debug)]
struct Pair {
    m: Vec3,
    reflect: bool,
    eta: f32,
}

impl RoughDielectricLeaf {
    /// The half vector of (wi, wo), or `None` where the BSDF is 0 (grazing wi, or a direction that
    /// sees m from its other side).
    fn pair(&self, wi: Vec3, wo: Vec3) -> Option<Pair> {
        if wi.z == 0.0 {
            return None;
        }
        let reflect = wi.z * wo.z > 0.0;
        let eta = if wi.z > 0.0 { self.eta } else { 1.0 / self.eta };
        let m = (wi + wo * if reflect { 1.0 } else { eta }).normalize();
        let m = if m.z < 0.0 { -m } else { m };
        (m.is_finite() && wi.dot(m) * wi.z > 0.0 && wo.dot(m) * wo.z > 0.0).then_some(Pair { m, reflect, eta })
    }

    /// |∂m/∂wo| of the pair (the Jacobian of the half-vector map).
    fn jacobian(p: &Pair, wi: Vec3, wo: Vec3) -> f32 {
        let (im, om) = (wi.dot(p.m), wo.dot(p.m));
        if p.reflect {
            (1.0 / (4.0 * om)).abs()
        } else {
            let d = im + p.eta * om;
            (p.eta * p.eta * om / (d * d)).abs()
        }
    }

    /// f̂ per unit of the lobe's colour, divided by D·G: F / (4 |cos θi|), or the transmission's
    /// (1 − F)·|(wi·m)(wo·m) / (cos θi (wi·m + η wo·m)²)|.
    fn unit_over_dg(p: &Pair, f: f32, wi: Vec3, wo: Vec3) -> f32 {
        if p.reflect {
            f / (4.0 * wi.z.abs())
        } else {
            let (im, om) = (wi.dot(p.m), wo.dot(p.m));
            let d = im + p.eta * om;
            (1.0 - f) * (im * om / (wi.z * d * d)).abs()
        }
    }

    /// (α_u, α_v).
    fn alphas(&self) -> Vec2 {
        Vec2::new(self.alpha, self.alpha_v)
    }

    /// D·G at m.
    fn dg(&self, wi: Vec3, wo: Vec3, m: Vec3) -> f32 {
        let a = self.alphas();
        let d = microfacet_d_aniso(self.distribution, a, m);
        if d == 0.0 {
            return 0.0;
        }
        d * microfacet_g1_aniso(self.distribution, a, wi, m) * microfacet_g1_aniso(self.distribution, a, wo, m)
    }

    /// f̂(wi, wo).
    pub fn eval(&self, wi: Vec3, wo: Vec3) -> Vec3 {
        let Some(p) = self.pair(wi, wo) else { return Vec3::ZERO };
        let f = fresnel_dielectric(wi.dot(p.m), self.eta).0;
        let colour = if p.reflect { self.reflectance } else { self.transmittance };
        colour * (self.dg(wi, wo, p.m) * Self::unit_over_dg(&p, f, wi, wo))
    }

    /// The solid-angle density of wo when the half vector m is drawn with density `pdf_m(m)` (per
    /// solid angle of m, in the upper hemisphere) and [`RoughDielectricLeaf::scatter`] leaves
    /// through it: pdf_m(m) · (F or 1 − F) · |∂m/∂wo| at the half vector of (wi, wo); 0 where
    /// the BSDF is.
    pub fn pdf_through(&self, wi: Vec3, wo: Vec3, pdf_m: impl Fn(Vec3) -> f32) -> f32 {
        let Some(p) = self.pair(wi, wo) else { return 0.0 };
        let f = fresnel_dielectric(wi.dot(p.m), self.eta).0;
        pdf_m(p.m) * if p.reflect { f } else { 1.0 - f } * Self::jacobian(&p, wi, wo)
    }

    /// The solid-angle density with which [`RoughDielectricLeaf::sample`] draws wo.
    pub fn pdf(&self, wi: Vec3, wo: Vec3) -> f32 {
        // The normals visible from wi's side.
        let up = if wi.z > 0.0 { wi } else { -wi };
        let a = self.alphas();
        self.pdf_through(wi, wo, |m| {
            let d = microfacet_d_aniso(self.distribution, a, m);
            d * microfacet_g1_aniso(self.distribution, a, up, m) * up.dot(m).max(0.0) / up.z
        })
    }

    /// A direction: a visible normal m from `u`, then reflection about m with probability F
    /// (`u_lobe` ≤ F) or refraction through it; `None` where the lobe's direction lands on the side
    /// it does not serve.
    pub fn sample(&self, wi: Vec3, u_lobe: f32, u: Vec2) -> Option<Vec3> {
        if wi.z == 0.0 {
            return None;
        }
        let up = if wi.z > 0.0 { wi } else { -wi };
        let m = microfacet_visible_normal(self.distribution, self.alphas(), up, u)?;
        self.scatter(wi, m, u_lobe)
    }

    /// The direction leaving through the microfacet normal m (upper hemisphere): reflected about
    /// m with probability F(wi·m) (`u_lobe` ≤ F), else refracted through it; `None` where the
    /// lobe's direction lands on the side it does not serve.
    pub fn scatter(&self, wi: Vec3, m: Vec3, u_lobe: f32) -> Option<Vec3> {
        let im = wi.dot(m);
        let (f, cos_t, eta_ti) = fresnel_dielectric(im, self.eta);
        let reflect = u_lobe <= f;
        let wo = if reflect { 2.0 * im * m - wi } else { m * (im * eta_ti + cos_t) - wi * eta_ti };
        let same_side = wi.z * wo.z > 0.0;
        (wo.is_finite() && same_side == reflect && wo.dot(m) * wo.z > 0.0).then_some(wo)
    }

    /// ∂f̂/∂(lobe colour) per channel, whether (wi, wo) transmits (the colour is then the
    /// transmittance), and ∂f̂/∂α_u and ∂f̂/∂α_v per channel (an isotropic leaf's ∂f̂/∂α is their
    /// sum).
    pub fn eval_grad(&self, wi: Vec3, wo: Vec3) -> (Vec3, bool, [Vec3; 2]) {
        let none = [Vec3::ZERO; 2];
        let Some(p) = self.pair(wi, wo) else { return (Vec3::ZERO, wi.z * wo.z < 0.0, none) };
        let (dist, a, m) = (self.distribution, self.alphas(), p.m);
        let d = microfacet_d_aniso(dist, a, m);
        if d == 0.0 {
            return (Vec3::ZERO, !p.reflect, none);
        }
        let (gi, go) = (microfacet_g1_aniso(dist, a, wi, m), microfacet_g1_aniso(dist, a, wo, m));
        let dgi = microfacet_g1_dalpha_aniso(dist, a, wi, m);
        let dgo = microfacet_g1_dalpha_aniso(dist, a, wo, m);
        let ddg = microfacet_d_dalpha_aniso(dist, a, m) * (gi * go) + d * (dgi * go + gi * dgo);
        let unit = Self::unit_over_dg(&p, fresnel_dielectric(wi.dot(m), self.eta).0, wi, wo);
        let colour = if p.reflect { self.reflectance } else { self.transmittance };
        (Vec3::splat(d * gi * go * unit), !p.reflect, [colour * (ddg.x * unit), colour * (ddg.y * unit)])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn glass(distribution: Distribution, alpha: f32) -> RoughDielectricLeaf {
        RoughDielectricLeaf {
            distribution,
            alpha,
            alpha_v: alpha,
            reflectance: Vec3::new(0.9, 0.8, 0.7),
            transmittance: Vec3::new(0.6, 0.5, 0.4),
            eta: 1.5,
        }
    }

    /// As α → 0 the lobes concentrate on the smooth dielectric's two directions with its Fresnel
    /// split: the sampled reflections' share tends to R(cos θi) and transmitted samples leave near
    /// Snell's direction.
    #[test]
    fn narrow_lobes_become_the_smooth_dielectric() {
        let g = glass(Distribution::Ggx, 1e-3);
        for wi in [Vec3::new(0.6, 0.0, 0.8), Vec3::new(0.3, 0.0, -(0.91f32).sqrt())] {
            let (r, cos_t, eta_ti) = fresnel_dielectric(wi.z, g.eta);
            let snell = Vec3::new(-eta_ti * wi.x, -eta_ti * wi.y, cos_t);
            let n = 4000;
            let mut reflected = 0;
            for i in 0..n {
                let u_lobe = (i as f32 + 0.5) / n as f32;
                let wo = g.sample(wi, u_lobe, Vec2::new(0.37, 0.61)).unwrap();
                if wo.z * wi.z > 0.0 {
                    reflected += 1;
                    assert!((wo - Vec3::new(-wi.x, -wi.y, wi.z)).length() < 1e-2);
                } else {
                    assert!((wo - snell).length() < 1e-2, "{wo} vs {snell}");
                }
            }
            assert!((reflected as f32 / n as f32 - r).abs() < 2e-3, "{reflected} of {n} vs R = {r}");
        }
    }

    /// A derivative and the leaf at its parameter moved by a step.
    type Move = (Vec3, Box<dyn Fn(f32) -> RoughDielectricLeaf>);

    /// ∂f̂/∂(colour), ∂f̂/∂α_u and ∂f̂/∂α_v against central differences, on both lobes and both
    /// sides, isotropic (α_u and α_v moved together) and anisotropic.
    #[test]
    fn gradients_match_finite_differences() {
        let cases =
            [(Distribution::Beckmann, 0.3, 0.3), (Distribution::Ggx, 0.3, 0.3), (Distribution::Ggx, 0.15, 0.45)];
        for (distribution, alpha_u, alpha_v) in cases {
            let g = RoughDielectricLeaf { alpha_v, ..glass(distribution, alpha_u) };
            let mut checked = 0;
            for wi in [Vec3::new(0.6, 0.0, 0.8), Vec3::new(0.3, 0.4, -(0.75f32).sqrt())] {
                for k in 0..64 {
                    let u = Vec2::new((k % 8) as f32 / 8.0 + 0.06, (k / 8) as f32 / 8.0 + 0.03);
                    let Some(wo) = g.sample(wi, if k % 3 == 0 { 0.01 } else { 0.99 }, u) else { continue };
                    let (dcolour, transmits, dalpha) = g.eval_grad(wi, wo);
                    assert_eq!(transmits, wi.z * wo.z < 0.0);
                    let f = g.eval(wi, wo);
                    let colour = if transmits { g.transmittance } else { g.reflectance };
                    assert!((dcolour * colour - f).abs().max_element() <= 1e-5 * f.max_element().max(1e-6));
                    let h = 1e-3;
                    let isotropic = g.alpha == g.alpha_v;
                    // (the derivative, the leaf at a moved α): α_u and α_v together when isotropic.
                    let moves: Vec<Move> = if isotropic {
                        vec![(
                            dalpha[0] + dalpha[1],
                            Box::new(move |e| RoughDielectricLeaf { alpha: g.alpha + e, alpha_v: g.alpha + e, ..g }),
                        )]
                    } else {
                        vec![
                            (dalpha[0], Box::new(move |e| RoughDielectricLeaf { alpha: g.alpha + e, ..g })),
                            (dalpha[1], Box::new(move |e| RoughDielectricLeaf { alpha_v: g.alpha_v + e, ..g })),
                        ]
                    };
                    for (analytic, at) in moves {
                        let fd = (at(h).eval(wi, wo) - at(-h).eval(wi, wo)) / (2.0 * h);
                        let tol = 3e-3 * fd.abs().max(analytic.abs()).max_element().max(f.max_element());
                        assert!((fd - analytic).abs().max_element() <= tol, "{wi} {wo}: fd {fd} vs {analytic}");
                    }
                    checked += 1;
                }
            }
            assert!(checked > 60, "{checked}");
        }
    }

    /// Veach's generalised reciprocity of the radiance-form BSDF: light arriving along wo and
    /// leaving along wi, f(wi, wo)·η_o² = f(wo, wi)·η_i² with η the index on each direction's side
    /// (radiance leaving the dense side is compressed by (η_i/η_o)²); reflection is plainly
    /// reciprocal.
    #[test]
    fn generalised_reciprocity() {
        let g = glass(Distribution::Beckmann, 0.25);
        let g = RoughDielectricLeaf { reflectance: Vec3::ONE, transmittance: Vec3::ONE, ..g };
        for g in [g, RoughDielectricLeaf { alpha_v: 0.08, ..g }] {
            let mut checked = 0;
            for wi in [Vec3::new(0.6, 0.0, 0.8), Vec3::new(0.2, -0.5, -(0.71f32).sqrt())] {
                for k in 0..200 {
                    let u = Vec2::new(((k * 37) % 200) as f32 / 200.0 + 1e-3, (k as f32 + 0.5) / 200.0);
                    let Some(wo) = g.sample(wi, (k % 2) as f32, u) else { continue };
                    let index = |v: Vec3| if v.z > 0.0 { 1.0 } else { g.eta };
                    let ab = g.eval(wi, wo).x / wo.z.abs() * index(wo).powi(2);
                    let ba = g.eval(wo, wi).x / wi.z.abs() * index(wi).powi(2);
                    assert!((ab - ba).abs() <= 1e-3 * ab.abs().max(ba.abs()).max(1e-6), "{wi} {wo}: {ab} vs {ba}");
                    checked += 1;
                }
            }
            assert!(checked > 300, "{:?}: {checked}", g.alpha_v);
        }
    }
}

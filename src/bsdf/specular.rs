//! Smooth BSDFs, whose lobes are Dirac deltas (Mitsuba's `conductor`, `dielectric` and
//! `thindielectric`): sampled only, never evaluated — f̂ and its density are 0 for every
//! direction a sampler did not produce, so next-event estimation skips their vertices (as
//! Mitsuba's path tracers do for BSDFs without a smooth lobe), and the emitter a sampled
//! direction reaches counts with MIS weight 1.
//!
//! A sample reports its lobe's choice probability as `pdf` and `value` = weight × pdf, so the
//! path loop's `value / pdf` is the lobe's weight (Mitsuba's sample weight) unchanged:
//! - conductor: the mirror direction, weight F_conductor(cos θi) · s;
//! - dielectric: the mirror direction with probability R = F(cos θi, η), weight s_r; or the
//!   refracted one with probability 1 − R, weight s_t η_ti² (radiance is compressed into the
//!   narrower solid angle on the denser side);
//! - thin dielectric: the mirror direction with probability R' = 2R/(1 + R) (the slab's inner
//!   reflections summed), weight s_r; or straight through, weight s_t.
//!
//! The derivative of `value` by the reflectance (or transmittance) is `value` over it: what
//! [`SmoothLeaf::value_grad`] reports in `LeafGrad::color` (or, for a transmitted sample,
//! `LeafGrad::trans`).

use glam::Vec3;

use super::rough_conductor::{fresnel_conductor, fresnel_conductor_dior};
use super::rough_plastic::fresnel_dielectric;
use super::{BsdfSample, LeafGrad};

/// Whether `b` has only delta lobes: its vertices get no next-event estimation.
pub fn is_smooth(b: &super::Bsdf) -> bool {
    !b.blend && matches!(b.leaves[0], super::Leaf::Smooth(_))
}

/// Which smooth BSDF a [`SmoothLeaf`] is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SmoothKind {
    /// A perfect mirror with a conductor's Fresnel reflectance.
    Conductor,
    /// A smooth interface between two dielectrics (glass, water).
    Dielectric,
    /// A thin dielectric sheet (a window pane): reflection, or straight through.
    ThinDielectric,
}

/// A smooth BSDF's values.
///
/// ```
/// use glam::Vec3;
/// use pathgrad::bsdf::specular::{SmoothKind, SmoothLeaf};
/// let glass = SmoothLeaf {
///     kind: SmoothKind::Dielectric,
///     reflectance: Vec3::ONE,
///     transmittance: Vec3::ONE,
///     eta: Vec3::new(1.5, 0.0, 0.0),
///     k: Vec3::ZERO,
/// };
/// // At normal incidence 4 % is reflected ((η − 1)/(η + 1))², the rest refracted straight down.
/// let wi = Vec3::Z;
/// let r = glass.sample(wi, 0.0).unwrap();
/// let t = glass.sample(wi, 0.5).unwrap();
/// assert!((r.pdf - 0.04).abs() < 1e-6 && r.wo == Vec3::Z && r.delta);
/// assert!(t.wo.z < 0.0 && (t.pdf - 0.96).abs() < 1e-6);
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SmoothLeaf {
    /// The kind.
    pub kind: SmoothKind,
    /// Specular reflectance (all kinds).
    pub reflectance: Vec3,
    /// Specular transmittance (dielectrics).
    pub transmittance: Vec3,
    /// Conductor: the real part of the complex index of refraction; dielectrics: η in `x`
    /// (int_ior / ext_ior).
    pub eta: Vec3,
    /// Conductor: the imaginary part of the complex index of refraction.
    pub k: Vec3,
}

/// The mirror direction of `wi` about the normal.
pub fn reflect(wi: Vec3) -> Vec3 {
    Vec3::new(-wi.x, -wi.y, wi.z)
}

/// The direction refracted from `wi` with transmitted cosine `cos_t` and index ratio `eta_ti`.
pub fn refract(wi: Vec3, cos_t: f32, eta_ti: f32) -> Vec3 {
    Vec3::new(-eta_ti * wi.x, -eta_ti * wi.y, cos_t)
}

impl SmoothLeaf {
    /// The lobe `u_lobe` chooses: its direction, choice probability, weight per unit of its
    /// colour, and whether it transmits; `None` where the BSDF has nothing to give (a conductor
    /// seen from below).
    fn lobe(&self, wi: Vec3, u_lobe: f32) -> Option<(Vec3, f32, Vec3, bool)> {
        let lobe = match self.kind {
            SmoothKind::Conductor => {
                if wi.z <= 0.0 {
                    return None;
                }
                (reflect(wi), 1.0, fresnel_conductor(wi.z, self.eta, self.k), false)
            }
            SmoothKind::Dielectric => {
                let (r, cos_t, eta_ti) = fresnel_dielectric(wi.z, self.eta.x);
                if u_lobe <= r {
                    (reflect(wi), r, Vec3::ONE, false)
                } else {
                    (refract(wi, cos_t, eta_ti), 1.0 - r, Vec3::splat(eta_ti * eta_ti), true)
                }
            }
            SmoothKind::ThinDielectric => {
                let r = fresnel_dielectric(wi.z.abs(), self.eta.x).0;
                let r = r * 2.0 / (1.0 + r);
                if u_lobe <= r { (reflect(wi), r, Vec3::ONE, false) } else { (-wi, 1.0 - r, Vec3::ONE, true) }
            }
        };
        (lobe.1 > 0.0).then_some(lobe)
    }

    /// The sampled direction, `u_lobe` choosing the lobe.
    pub fn sample(&self, wi: Vec3, u_lobe: f32) -> Option<BsdfSample> {
        let (wo, pdf, unit, transmitted) = self.lobe(wi, u_lobe)?;
        let colour = if transmitted { self.transmittance } else { self.reflectance };
        Some(BsdfSample { wo, pdf, value: unit * colour * pdf, delta: true })
    }

    /// ∂value/∂(colour parameter) per channel of the sample toward `wo` (see the module docs), and
    /// a conductor's by its eta and k (`LeafGrad::eta`, `LeafGrad::k`).
    pub fn value_grad(&self, wi: Vec3, wo: Vec3) -> LeafGrad {
        let transmitted = wi.z * wo.z < 0.0;
        let Some((_, pdf, unit, _)) = self.lobe(wi, if transmitted { 1.0 } else { 0.0 }) else {
            return LeafGrad::default();
        };
        let (color, trans) = if transmitted { (Vec3::ZERO, unit * pdf) } else { (unit * pdf, Vec3::ZERO) };
        if self.kind == SmoothKind::Conductor {
            // The weight F(cos θi)·reflectance by the Fresnel term's eta and k (pdf 1).
            let (_, d_eta, d_k) = fresnel_conductor_dior(wi.z, self.eta, self.k);
            let (eta, k) = (self.reflectance * d_eta, self.reflectance * d_k);
            return LeafGrad { color, trans, eta, k, ..LeafGrad::default() };
        }
        LeafGrad { color, trans, ..LeafGrad::default() }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn glass(kind: SmoothKind) -> SmoothLeaf {
        SmoothLeaf {
            kind,
            reflectance: Vec3::new(0.9, 0.8, 0.7),
            transmittance: Vec3::new(0.6, 0.5, 0.4),
            eta: Vec3::new(1.5, 0.0, 0.0),
            k: Vec3::ZERO,
        }
    }

    /// Snell's law and the lobes' probabilities: a refracted direction keeps the tangent
    /// component scaled by η_i/η_t, both lobes' probabilities sum to 1, and a mirror reflects.
    #[test]
    fn lobes_follow_snell_and_fresnel() {
        let wi = Vec3::new(0.6, 0.0, 0.8);
        let g = glass(SmoothKind::Dielectric);
        let r = g.sample(wi, 0.0).unwrap();
        let t = g.sample(wi, 1.0).unwrap();
        assert_eq!(r.wo, Vec3::new(-0.6, 0.0, 0.8));
        assert!((r.pdf + t.pdf - 1.0).abs() < 1e-6 && r.delta && t.delta);
        // sin θt = sin θi / η, below the surface.
        assert!((t.wo.x + 0.6 / 1.5).abs() < 1e-6 && t.wo.z < 0.0 && (t.wo.length() - 1.0).abs() < 1e-5);
        // The weight of the transmitted lobe carries (η_i/η_t)² for radiance.
        assert!(((t.value / t.pdf) - g.transmittance / (1.5 * 1.5)).abs().max_element() < 1e-6);
        // From inside, beyond the critical angle, all is reflected.
        let inside = Vec3::new(0.9, 0.0, -(1.0f32 - 0.81).sqrt());
        let s = g.sample(inside, 0.999).unwrap();
        assert!(s.wo.z < 0.0 && (s.pdf - 1.0).abs() < 1e-6);
        // A thin sheet lets light straight through.
        let thin = glass(SmoothKind::ThinDielectric).sample(wi, 1.0).unwrap();
        assert_eq!(thin.wo, -wi);
        // A conductor seen from below gives nothing.
        assert!(glass(SmoothKind::Conductor).sample(Vec3::new(0.0, 0.0, -1.0), 0.5).is_none());
    }

    /// ∂value/∂colour of every lobe against central differences of the sampled value.
    #[test]
    fn value_gradients_match_finite_differences() {
        for kind in [SmoothKind::Conductor, SmoothKind::Dielectric, SmoothKind::ThinDielectric] {
            for wi in [Vec3::new(0.6, 0.0, 0.8), Vec3::new(0.3, 0.4, -(0.75f32).sqrt())] {
                for u_lobe in [0.0, 1.0] {
                    let mut leaf = glass(kind);
                    leaf.k = Vec3::new(3.0, 2.0, 1.5);
                    let Some(s) = leaf.sample(wi, u_lobe) else { continue };
                    let g = leaf.value_grad(wi, s.wo);
                    let transmitted = g.trans != Vec3::ZERO;
                    let g_colour = if transmitted { g.trans } else { g.color };
                    let h = 1e-3;
                    for c in 0..3 {
                        let value_at = |v: f32| {
                            let mut l = leaf;
                            if transmitted {
                                l.transmittance[c] = v
                            } else {
                                l.reflectance[c] = v
                            }
                            l.sample(wi, u_lobe).unwrap().value[c]
                        };
                        let x = if transmitted { leaf.transmittance[c] } else { leaf.reflectance[c] };
                        let fd = (value_at(x + h) - value_at(x - h)) / (2.0 * h);
                        assert!((fd - g_colour[c]).abs() < 1e-3, "{kind:?} {wi} {u_lobe}: {fd} vs {}", g_colour[c]);
                    }
                }
            }
        }
    }
}

//! The attached rough-dielectric lobe: a microfacet normal reparameterised by α and the shading
//! frame, then reflection or refraction about it chosen by the Fresnel term.

use glam::{Mat3, Vec3};

use super::{MicroNormal, fresnel_dielectric_grad, ln_masking, micro_normal, outer, refract_jacobians};

/// What a rough dielectric's vertex contributes to the attached estimator. As
/// [`super::RoughLobe`], the microfacet normal h is drawn from D(h)·cos θh in the frame of
/// [`super::basis_jacobians`] around the normal turned to the side the ray arrives on, so it moves with
/// α and the normal and not with the incoming direction; the lobe is then chosen as the smooth
/// dielectric's is (reflection with probability F(c), c = −d·h, else refraction through h), a
/// discrete choice whose probability P (F or 1 − F) the estimator holds detached, so every row
/// below is a derivative of ln(w·P): ∂ ln F (or ∂ ln(1 − F)) comes in as the smooth lobe's does.
///
/// With G1 the Smith term, cos θi > 0 and cos θo the cosines to that normal, the weight is
/// w = G1(cos θi)·G1(cos θo)·c/(cos θi·cos θh), times η_ti² for a refraction (Mitsuba's radiance
/// form, η_ti the incident side's index over the transmitted side's); D and P cancel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RoughDielectricLobe {
    /// The outgoing direction (world space).
    pub wo: Vec3,
    /// Whether the lobe refracts.
    pub transmitted: bool,
    /// The weight w (value × |cos θo| over density), without the specular reflectance or
    /// transmittance.
    pub weight: f32,
    /// The lobe's choice probability P: F(c) for a reflection, 1 − F(c) for a refraction.
    pub choice: f32,
    /// The density of `wo` (solid angle), P included: D(h)·cos θh·P·|∂h/∂wo|.
    pub pdf: f32,
    /// ∂d′/∂d.
    pub t_d: Mat3,
    /// ∂d′/∂n (n the normal as passed, not turned).
    pub t_n: Mat3,
    /// ∂d′/∂α.
    pub t_alpha: Vec3,
    /// ∂d′/∂η (zero for a reflection).
    pub t_eta: Vec3,
    /// ∂ ln(w·P)/∂d.
    pub dlnw_dd: Vec3,
    /// ∂ ln(w·P)/∂n.
    pub dlnw_dn: Vec3,
    /// ∂ ln(w·P)/∂α.
    pub dlnw_dalpha: f32,
    /// ∂ ln(w·P)/∂η.
    pub dlnw_deta: f32,
}

/// The attached rough-dielectric lobe from incoming direction `d` at shading normal `n` (the
/// outward one: the ray may arrive from either side), isotropic roughness `alpha` (GGX, or
/// Beckmann with `beckmann`), uniforms `u` for the microfacet normal, `u_lobe` for the lobe
/// (reflection where `u_lobe` ≤ F, as [`crate::bsdf::rough_dielectric::RoughDielectricLeaf::scatter`])
/// and `eta` the interior's index over the exterior's; `None` where the sample leaves on the side
/// its lobe does not serve, hits total internal reflection on the refracted branch, or weighs
/// nothing.
pub fn rough_dielectric_lobe(
    d: Vec3,
    n: Vec3,
    alpha: f32,
    beckmann: bool,
    u: [f32; 2],
    u_lobe: f32,
    eta: f32,
) -> Option<RoughDielectricLobe> {
    // The normal turned to the incoming side: n′ = s·n.
    let s = if d.dot(n) <= 0.0 { 1.0 } else { -1.0 };
    let ns = s * n;
    let ci = -d.dot(ns);
    if !(ci > 0.0) || !(alpha > 0.0) || !(eta > 0.0) {
        return None;
    }
    let MicroNormal { h, local: hl, local_alpha: dhl, h_n, h_alpha } = micro_normal(ns, alpha, beckmann, u);
    // ∂h/∂n = s·∂h/∂n′.
    let hn = s * h_n;
    let c = -d.dot(h);
    if !(c > 0.0) {
        return None;
    }
    // c = −d·h: dc = −h·δd − d·δh.
    let (dc_dd, dc_dn, dc_dalpha) = (-h, -(hn.transpose() * d), -d.dot(h_alpha));
    // F at the microfacet with the side's sign (fresnel_dielectric_grad reads it), by c and by η.
    let (f, df_dsc, df_deta) = fresnel_dielectric_grad(s * c, eta);
    let df_dc = s * df_dsc;
    let transmitted = u_lobe > f;
    let outside = s > 0.0;
    // η_ti and its derivative by η.
    let (eta_ti, deta_ti) = if outside { (1.0 / eta, -1.0 / (eta * eta)) } else { (eta, 1.0) };
    let (wo, t_d, t_n, t_alpha, t_eta, choice, dlnp_df) = if transmitted {
        let (wo, r_d, r_h, r_eta) = refract_jacobians(d, h, eta_ti)?;
        (wo, r_d, r_h * hn, r_h * h_alpha, r_eta * deta_ti, 1.0 - f, -1.0 / (1.0 - f))
    } else {
        let wo = d + 2.0 * c * h;
        let t_d = Mat3::IDENTITY - 2.0 * outer(h, h);
        let t_n = 2.0 * outer(h, dc_dn) + 2.0 * c * hn;
        (wo, t_d, t_n, 2.0 * dc_dalpha * h + 2.0 * c * h_alpha, Vec3::ZERO, f, 1.0 / f)
    };
    let co = wo.dot(ns);
    if !(choice > 0.0) || !(co != 0.0) || (co < 0.0) != transmitted {
        return None;
    }
    let (ln_g, gi_c, go_c, g_alpha) = ln_masking(beckmann, alpha, ci, co);
    let hz = hl.z;
    let radiance = if transmitted { eta_ti * eta_ti } else { 1.0 };
    let weight = ln_g.exp() * c / (ci * hz) * radiance;
    // cos θi = −d·n′; cos θo = wo·n′ (∂n′/∂n = s).
    let (ci_d, ci_n) = (-ns, -s * d);
    let (co_d, co_n) = (t_d.transpose() * ns, t_n.transpose() * ns + s * wo);
    let (co_alpha, co_eta) = (ns.dot(t_alpha), ns.dot(t_eta));
    // ln P = ln F or ln(1 − F): its derivative is dlnp_df·dF.
    let dlnw_dd = dc_dd / c + gi_c * ci_d + go_c * co_d - ci_d / ci + dlnp_df * df_dc * dc_dd;
    let dlnw_dn = dc_dn / c + gi_c * ci_n + go_c * co_n - ci_n / ci + dlnp_df * df_dc * dc_dn;
    let dlnw_dalpha = dc_dalpha / c + go_c * co_alpha + g_alpha - dhl.z / hz + dlnp_df * df_dc * dc_dalpha;
    let dradiance = if transmitted { 2.0 * deta_ti / eta_ti } else { 0.0 };
    let dlnw_deta = go_c * co_eta + dlnp_df * df_deta + dradiance;
    let dist = if beckmann { crate::contract::Distribution::Beckmann } else { crate::contract::Distribution::Ggx };
    // |∂h/∂wo|: 1/(4c) reflected; η_rel²·|wo·h|/(c + η_rel·wo·h)² refracted (η_rel = 1/η_ti).
    let jacobian = if transmitted {
        let (eta_rel, om) = (1.0 / eta_ti, wo.dot(h));
        let den = c + eta_rel * om;
        eta_rel * eta_rel * om.abs() / (den * den)
    } else {
        1.0 / (4.0 * c)
    };
    let pdf = crate::bsdf::rough_conductor::microfacet_d(dist, alpha, hl) * hz * choice * jacobian;
    Some(RoughDielectricLobe {
        wo,
        transmitted,
        weight,
        choice,
        pdf,
        t_d,
        t_n,
        t_alpha,
        t_eta,
        dlnw_dd,
        dlnw_dn,
        dlnw_dalpha,
        dlnw_deta,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bsdf::rough_dielectric::RoughDielectricLeaf;
    use crate::contract::Distribution;

    /// The incoming directions the tests use: from outside and from inside a tilted normal.
    fn cases() -> (Vec3, [Vec3; 2]) {
        let n = Vec3::new(0.15, -0.25, 0.95).normalize();
        (n, [Vec3::new(0.35, 0.2, -0.9).normalize(), Vec3::new(-0.3, 0.25, 0.92).normalize()])
    }

    /// Every derivative the lobe reports — its direction's and ln(w·P)'s, by d, n, α and η —
    /// against central differences of the lobe itself, for both distributions, both lobes and both
    /// sides (f64-free: a step of 2·10⁻³ and a tolerance of 2 % plus 2·10⁻² absolute, as the rough
    /// conductor's test).
    #[test]
    fn rough_dielectric_lobe_derivatives_match_finite_differences() {
        let (n0, dirs) = cases();
        let eta0 = 1.5f32;
        let mut checked = [0usize; 2];
        for beckmann in [false, true] {
            for &alpha in &[0.05f32, 0.3] {
                for d0 in dirs {
                    for &u in &[[0.3f32, 0.2], [0.7, 0.6], [0.5, 0.9], [0.2, 0.45]] {
                        for u_lobe in [0.0f32, 0.999_999] {
                            let lobe = |d: Vec3, n: Vec3, a: f32, e: f32| {
                                rough_dielectric_lobe(d, n, a, beckmann, u, u_lobe, e)
                            };
                            let Some(l) = lobe(d0, n0, alpha, eta0) else { continue };
                            // Keep to samples whose lobe does not switch under the steps.
                            let lnw = |d, n, a, e| {
                                lobe(d, n, a, e)
                                    .filter(|x| x.transmitted == l.transmitted)
                                    .map(|x| (x.weight * x.choice).ln())
                            };
                            let wo =
                                |d, n, a, e| lobe(d, n, a, e).filter(|x| x.transmitted == l.transmitted).map(|x| x.wo);
                            let h = 2e-3f32;
                            let tol = |x: f32| 2e-2 * (1.0 + x.abs());
                            let vtol = |x: Vec3| 2e-2 * (1.0 + x.length());
                            let fd = |p: Option<f32>, m: Option<f32>, step: f32| Some((p? - m?) / (2.0 * step));
                            let fdv = |p: Option<Vec3>, m: Option<Vec3>, step: f32| Some((p? - m?) / (2.0 * step));
                            let what =
                                format!("beckmann {beckmann} α {alpha} d {d0} u {u:?} refracted {}", l.transmitted);
                            for axis in [Vec3::X, Vec3::Y, Vec3::Z] {
                                if let Some(f) =
                                    fd(lnw(d0 + h * axis, n0, alpha, eta0), lnw(d0 - h * axis, n0, alpha, eta0), h)
                                {
                                    let ours = l.dlnw_dd.dot(axis);
                                    assert!((f - ours).abs() < tol(f), "∂ln w/∂d ({what}): {f} vs {ours}");
                                }
                                if let Some(f) =
                                    fd(lnw(d0, n0 + h * axis, alpha, eta0), lnw(d0, n0 - h * axis, alpha, eta0), h)
                                {
                                    let ours = l.dlnw_dn.dot(axis);
                                    assert!((f - ours).abs() < tol(f), "∂ln w/∂n ({what}): {f} vs {ours}");
                                }
                                if let Some(f) =
                                    fdv(wo(d0 + h * axis, n0, alpha, eta0), wo(d0 - h * axis, n0, alpha, eta0), h)
                                {
                                    let ours = l.t_d * axis;
                                    assert!((f - ours).abs().max_element() < vtol(f), "∂d′/∂d ({what}): {f} vs {ours}");
                                }
                                if let Some(f) =
                                    fdv(wo(d0, n0 + h * axis, alpha, eta0), wo(d0, n0 - h * axis, alpha, eta0), h)
                                {
                                    let ours = l.t_n * axis;
                                    assert!((f - ours).abs().max_element() < vtol(f), "∂d′/∂n ({what}): {f} vs {ours}");
                                }
                            }
                            let ha = 1e-3 * alpha;
                            if let Some(f) = fd(lnw(d0, n0, alpha + ha, eta0), lnw(d0, n0, alpha - ha, eta0), ha) {
                                assert!(
                                    (f - l.dlnw_dalpha).abs() < tol(f),
                                    "∂ln w/∂α ({what}): {f} vs {}",
                                    l.dlnw_dalpha
                                );
                            }
                            if let Some(f) = fdv(wo(d0, n0, alpha + ha, eta0), wo(d0, n0, alpha - ha, eta0), ha) {
                                assert!(
                                    (f - l.t_alpha).abs().max_element() < vtol(f),
                                    "∂d′/∂α ({what}): {f} vs {}",
                                    l.t_alpha
                                );
                            }
                            if let Some(f) = fd(lnw(d0, n0, alpha, eta0 + h), lnw(d0, n0, alpha, eta0 - h), h) {
                                assert!((f - l.dlnw_deta).abs() < tol(f), "∂ln w/∂η ({what}): {f} vs {}", l.dlnw_deta);
                            }
                            if let Some(f) = fdv(wo(d0, n0, alpha, eta0 + h), wo(d0, n0, alpha, eta0 - h), h) {
                                assert!(
                                    (f - l.t_eta).abs().max_element() < vtol(f),
                                    "∂d′/∂η ({what}): {f} vs {}",
                                    l.t_eta
                                );
                            }
                            checked[l.transmitted as usize] += 1;
                        }
                    }
                }
            }
        }
        assert!(checked[0] >= 8 && checked[1] >= 8, "{checked:?} (reflected, refracted) lobes checked");
    }

    /// The lobe's weight times its density is the detached BSDF's value times |cos θo|
    /// ([`RoughDielectricLeaf::eval`]), and its density is the leaf's for a normal drawn from
    /// D(h)·cos θh ([`RoughDielectricLeaf::pdf_through`]), on both lobes and both sides.
    #[test]
    fn rough_dielectric_lobe_weight_is_value_over_density() {
        let n = Vec3::Z;
        let mut checked = [0usize; 2];
        for (beckmann, distribution) in [(false, Distribution::Ggx), (true, Distribution::Beckmann)] {
            let leaf = RoughDielectricLeaf {
                distribution,
                alpha: 0.2,
                alpha_v: 0.2,
                reflectance: Vec3::ONE,
                transmittance: Vec3::ONE,
                eta: 1.5,
            };
            for d in [Vec3::new(0.4, 0.1, -0.8).normalize(), Vec3::new(-0.2, 0.3, 0.9).normalize()] {
                for u in [[0.2f32, 0.3], [0.6, 0.1], [0.9, 0.8], [0.45, 0.55]] {
                    for u_lobe in [0.0f32, 0.999_999] {
                        let Some(l) = rough_dielectric_lobe(d, n, 0.2, beckmann, u, u_lobe, 1.5) else { continue };
                        let value = leaf.eval(-d, l.wo).x;
                        let pdf = leaf.pdf_through(-d, l.wo, |m| {
                            crate::bsdf::rough_conductor::microfacet_d(distribution, 0.2, m) * m.z
                        });
                        assert!((l.pdf - pdf).abs() < 1e-4 * (1.0 + pdf), "density {} vs {pdf}", l.pdf);
                        let ours = l.weight * l.pdf;
                        assert!(
                            (ours - value).abs() < 1e-4 * (1.0 + value),
                            "{ours} vs {value} (refracted {})",
                            l.transmitted
                        );
                        checked[l.transmitted as usize] += 1;
                    }
                }
            }
        }
        assert!(checked[0] >= 4 && checked[1] >= 4, "{checked:?} (reflected, refracted) lobes checked");
    }

    /// As the leaf's sampler: the reflected share of the lobe choice is F at the microfacet, and
    /// the refracted direction obeys Snell's law about h (tangential part scaled by η_ti).
    #[test]
    fn rough_dielectric_lobe_chooses_by_fresnel() {
        let (n, dirs) = cases();
        for d in dirs {
            let u = [0.4f32, 0.3];
            let r = rough_dielectric_lobe(d, n, 0.1, false, u, 0.0, 1.5).unwrap();
            let t = rough_dielectric_lobe(d, n, 0.1, false, u, 0.999_999, 1.5).unwrap();
            assert!(!r.transmitted && t.transmitted);
            assert!((r.choice + t.choice - 1.0).abs() < 1e-6);
            let below = rough_dielectric_lobe(d, n, 0.1, false, u, r.choice * 0.999, 1.5).unwrap();
            let above = rough_dielectric_lobe(d, n, 0.1, false, u, r.choice * 1.001 + 1e-6, 1.5).unwrap();
            assert!(!below.transmitted && above.transmitted);
            assert!((t.wo.length() - 1.0).abs() < 1e-5 && (r.wo.length() - 1.0).abs() < 1e-5);
        }
    }

    /// The lobe as an estimator: over a fixed 96×96 grid of uniforms, Σ over both lobes of
    /// P·w·g(wo) (the expected contribution of a smooth radiance g, lobe choice summed out) is a
    /// smooth function of α and η — every edge of the valid region weighs 0 (G1 → 0 at grazing
    /// wo, c → 0, 1 − F → 0 at total internal reflection) — so its central difference must equal
    /// the attached estimator's Σ P·w·(∂ln(w·P)·g + ∇g·∂wo): the weight's and the moving
    /// direction's terms together. Both sides, both distributions; f64 sums. The step is small
    /// (2·10⁻⁴) because from inside the sum has an edge where 1 − F vanishes like a square root
    /// (total internal reflection), and a central difference across it is off by O(√h): measured
    /// on GGX from inside, ∂/∂α by difference 0.553, 0.5916, 0.5949 at h = 2·10⁻³, 2·10⁻⁴, 2·10⁻⁵
    /// against 0.5974 from the lobe's rows (256² uniforms).
    #[test]
    fn rough_dielectric_lobe_estimates_the_derivative_of_its_integral() {
        let (n, dirs) = cases();
        let a = Vec3::new(0.8, -1.1, 0.6);
        let g = |wo: Vec3| f64::from((wo.dot(a)).exp());
        let k = 256;
        for beckmann in [false, true] {
            for d in dirs {
                // (Σ P·w·g, Σ P·w·(∂lnwP/∂α·g + ∇g·t_α), the same for η) at (α, η).
                let sums = |alpha: f32, eta: f32| {
                    let mut s = [0.0f64; 3];
                    for i in 0..k * k {
                        let u = [((i % k) as f32 + 0.5) / k as f32, ((i / k) as f32 + 0.5) / k as f32];
                        for u_lobe in [0.0f32, 1.0] {
                            let Some(l) = rough_dielectric_lobe(d, n, alpha, beckmann, u, u_lobe, eta) else {
                                continue;
                            };
                            // Each lobe once (under total internal reflection both u_lobe reflect).
                            if l.transmitted != (u_lobe > 0.5) {
                                continue;
                            }
                            let pw = f64::from(l.weight * l.choice);
                            let gv = g(l.wo);
                            s[0] += pw * gv;
                            s[1] += pw * (f64::from(l.dlnw_dalpha) * gv + gv * f64::from(a.dot(l.t_alpha)));
                            s[2] += pw * (f64::from(l.dlnw_deta) * gv + gv * f64::from(a.dot(l.t_eta)));
                        }
                    }
                    s.map(|x| x / (k * k) as f64)
                };
                let (alpha, eta) = (0.2f32, 1.5f32);
                let at = sums(alpha, eta);
                let (ha, he) = (2e-4f32, 2e-4f32);
                let fd_a = (sums(alpha + ha, eta)[0] - sums(alpha - ha, eta)[0]) / f64::from(2.0 * ha);
                let fd_e = (sums(alpha, eta + he)[0] - sums(alpha, eta - he)[0]) / f64::from(2.0 * he);
                let what = format!("beckmann {beckmann} d {d}");
                eprintln!("{what}: ∂/∂α FD {fd_a:.5} ours {:.5}; ∂/∂η FD {fd_e:.5} ours {:.5}", at[1], at[2]);
                assert!((fd_a - at[1]).abs() < 1e-2 * (0.1 + fd_a.abs()), "∂/∂α ({what}): {fd_a} vs {}", at[1]);
                assert!((fd_e - at[2]).abs() < 1e-2 * (0.1 + fd_e.abs()), "∂/∂η ({what}): {fd_e} vs {}", at[2]);
            }
        }
    }
}

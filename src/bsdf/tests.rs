//! BSDF tests: sample/pdf/eval consistency and chi-square goodness of fit of every sampler.

use glam::{Vec2, Vec3};

use super::*;
use crate::rng::{PassTag, RngKey, Stream, uniform4};
use crate::stats::{Chi2Config, chi2_directions, dump_table, sidak};

/// Every chi-square test in this file, for the Šidák correction of the 1 % family-wise level.
const CHI2_TESTS: usize = 1 + 2 * 3 * 3 + 3 + 2 * 3 + 2 * 2 * 4 + 2 * 3;
const FAMILY_ALPHA: f64 = 0.01;

fn uniforms(test: u32, i: usize) -> (f32, Vec2) {
    let u = uniform4(RngKey::new(test, 0, PassTag::Test), i as u32, 0, 1, Stream::Main, 1, 0);
    (u[0], Vec2::new(u[1], u[2]))
}

fn incident(cos_theta: f32) -> Vec3 {
    let sin = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
    Vec3::new(sin * 0.8, sin * 0.6, cos_theta)
}

/// A rough plastic (η of bk7 in air) with its coating table at `alpha`.
pub(crate) fn plastic(distribution: Distribution, alpha: f32, diffuse: Vec3, nonlinear: bool) -> Leaf {
    let eta = 1.5046 / 1.000_277;
    let mut table = [0.0; crate::contract::COATING_TABLE_LEN as usize];
    table.copy_from_slice(&rough_plastic::CoatingTable::new(distribution, alpha, eta).flatten());
    Leaf::RoughPlastic(rough_plastic::PlasticLeaf {
        distribution,
        alpha,
        diffuse,
        specular: Vec3::new(1.0, 0.9, 0.8),
        eta,
        specular_weight: 0.6,
        nonlinear,
        table,
    })
}

/// A rough dielectric (η of bk7 in air).
pub(crate) fn glass(distribution: Distribution, alpha: f32) -> Leaf {
    Leaf::RoughDielectric(rough_dielectric::RoughDielectricLeaf {
        distribution,
        alpha,
        alpha_v: alpha,
        reflectance: Vec3::new(0.9, 0.8, 0.7),
        transmittance: Vec3::new(0.6, 0.5, 0.4),
        eta: 1.5046 / 1.000_277,
    })
}

/// An anisotropic conductor: α_u along the frame's x, α_v along y.
fn anisotropic(distribution: Distribution, alpha_u: f32, alpha_v: f32) -> Leaf {
    Leaf::RoughConductor {
        distribution,
        alpha: alpha_u,
        alpha_v,
        specular: Vec3::new(0.9, 0.8, 0.7),
        eta: Vec3::new(0.2, 0.9, 1.1),
        k: Vec3::new(3.9, 2.4, 2.1),
    }
}

/// Anisotropic conductors, the long axis along x and along y, seen at three azimuth-bearing
/// incidences.
#[test]
fn chi2_anisotropic_conductors() {
    let mut test = 90;
    for (distribution, au, av) in [(Distribution::Beckmann, 0.1, 0.4), (Distribution::Ggx, 0.5, 0.08)] {
        let b = Bsdf::leaf(anisotropic(distribution, au, av));
        for cos_i in [0.95, 0.5, 0.1] {
            test += 1;
            check_chi2(&format!("anisotropic-{distribution:?}-{au}x{av}-cos{cos_i}"), test, &b, incident(cos_i));
        }
    }
}

fn conductor(distribution: Distribution, alpha: f32) -> Leaf {
    Leaf::RoughConductor { distribution, alpha, alpha_v: alpha, specular: Vec3::ONE, eta: Vec3::ZERO, k: Vec3::ONE }
}

fn check_chi2(name: &str, test: u32, bsdf: &Bsdf, wi: Vec3) {
    let cfg =
        Chi2Config { cos_bins: 16, phi_bins: 32, samples: 1_000_000, significance: sidak(FAMILY_ALPHA, CHI2_TESTS) };
    let r = chi2_directions(
        &cfg,
        |i| {
            let (ul, u) = uniforms(test, i);
            bsdf_sample(bsdf, wi, ul, u).map(|s| s.wo)
        },
        |wo| f64::from(bsdf_pdf(bsdf, wi, wo)),
    );
    if !r.passed(cfg.significance) {
        let path = dump_table(name, &r);
        panic!(
            "{name}: chi2 {} with {} dof, p = {:.3e} < {:.3e}; table in {}",
            r.statistic,
            r.dof,
            r.p_value,
            cfg.significance,
            path.display()
        );
    }
}

#[test]
fn chi2_diffuse() {
    check_chi2("diffuse", 1, &Bsdf::leaf(Leaf::Diffuse { albedo: Vec3::splat(0.5) }), incident(0.6));
}

#[test]
fn chi2_rough_conductors() {
    let mut test = 10;
    for distribution in [Distribution::Beckmann, Distribution::Ggx] {
        for alpha in [0.1, 0.3, 0.8] {
            for cos_i in [0.999, 0.5, 0.05] {
                test += 1;
                check_chi2(
                    &format!("{distribution:?}-alpha{alpha}-cos{cos_i}"),
                    test,
                    &Bsdf::leaf(conductor(distribution, alpha)),
                    incident(cos_i),
                );
            }
        }
    }
}

#[test]
fn chi2_blend() {
    for (i, w) in [0.1f32, 0.5, 0.9].into_iter().enumerate() {
        let b = Bsdf {
            leaves: [Leaf::Diffuse { albedo: Vec3::new(0.1, 0.6, 0.35) }, conductor(Distribution::Ggx, 0.2)],
            weight: w,
            blend: true,
            perturbed: None,
        };
        check_chi2(&format!("blend-w{w}"), 40 + i as u32, &b, incident(0.7));
    }
}

#[test]
fn chi2_rough_plastics() {
    let mut test = 60;
    for (distribution, alpha) in [(Distribution::Beckmann, 0.3), (Distribution::Ggx, 0.08)] {
        let b = Bsdf::leaf(plastic(distribution, alpha, Vec3::new(0.2, 0.5, 0.8), false));
        for cos_i in [0.95, 0.5, 0.08] {
            test += 1;
            check_chi2(&format!("plastic-{distribution:?}-alpha{alpha}-cos{cos_i}"), test, &b, incident(cos_i));
        }
    }
}

/// Both lobes of rough dielectrics, seen from outside and from inside (where total internal
/// reflection takes the grazing directions).
#[test]
fn chi2_rough_dielectrics() {
    let mut test = 70;
    for (distribution, alpha) in [(Distribution::Beckmann, 0.3), (Distribution::Ggx, 0.08)] {
        let b = Bsdf::leaf(glass(distribution, alpha));
        for cos_i in [0.9, 0.3, -0.9, -0.5] {
            test += 1;
            check_chi2(&format!("dielectric-{distribution:?}-alpha{alpha}-cos{cos_i}"), test, &b, incident(cos_i));
        }
    }
}

/// Anisotropic rough dielectrics (α_u along the frame's x, α_v along y), both lobes, from
/// outside and inside, at an azimuth between the axes.
#[test]
fn chi2_anisotropic_rough_dielectrics() {
    let mut test = 200;
    for (distribution, au, av) in [(Distribution::Ggx, 0.4, 0.1), (Distribution::Beckmann, 0.05, 0.3)] {
        let b = Bsdf::leaf(anisotropic_glass(distribution, au, av));
        for cos_i in [0.9, 0.3, -0.9, -0.5] {
            test += 1;
            check_chi2(&format!("dielectric-{distribution:?}-{au}x{av}-cos{cos_i}"), test, &b, incident(cos_i));
        }
    }
}

/// A rough dielectric (η of bk7 in air) with α_u along the frame's x and α_v along y.
fn anisotropic_glass(distribution: Distribution, alpha_u: f32, alpha_v: f32) -> Leaf {
    match glass(distribution, alpha_u) {
        Leaf::RoughDielectric(d) => Leaf::RoughDielectric(rough_dielectric::RoughDielectricLeaf { alpha_v, ..d }),
        _ => unreachable!("glass is a rough dielectric"),
    }
}

fn all_bsdfs() -> Vec<Bsdf> {
    let mut v = vec![Bsdf::leaf(Leaf::Diffuse { albedo: Vec3::new(0.2, 0.5, 0.9) })];
    for d in [Distribution::Beckmann, Distribution::Ggx] {
        for a in [0.01, 0.05, 0.3, 0.8] {
            v.push(Bsdf::leaf(conductor(d, a)));
        }
    }
    v.push(Bsdf {
        leaves: [Leaf::Diffuse { albedo: Vec3::splat(0.5) }, conductor(Distribution::Ggx, 0.1)],
        weight: 0.3,
        blend: true,
        perturbed: None,
    });
    v.push(Bsdf::leaf(plastic(Distribution::Beckmann, 0.3, Vec3::new(0.2, 0.5, 0.9), false)));
    v.push(Bsdf::leaf(plastic(Distribution::Ggx, 0.1, Vec3::new(0.7, 0.4, 0.1), true)));
    v.push(Bsdf {
        leaves: [plastic(Distribution::Ggx, 0.2, Vec3::splat(0.5), false), conductor(Distribution::Beckmann, 0.2)],
        weight: 0.4,
        blend: true,
        perturbed: None,
    });
    v.push(Bsdf::leaf(anisotropic(Distribution::Beckmann, 0.1, 0.4)));
    v.push(Bsdf::leaf(anisotropic(Distribution::Ggx, 0.5, 0.05)));
    v.push(Bsdf::leaf(glass(Distribution::Beckmann, 0.2)));
    v.push(Bsdf::leaf(glass(Distribution::Ggx, 0.05)));
    v.push(Bsdf::leaf(anisotropic_glass(Distribution::Ggx, 0.3, 0.07)));
    v
}

/// The pdf and value a sample reports are what `bsdf_pdf` and `bsdf_eval` give at its direction.
#[test]
fn sample_agrees_with_pdf_and_eval() {
    for (k, b) in all_bsdfs().iter().enumerate() {
        for cos_i in [1.0, 0.7, 0.2, 0.05] {
            let wi = incident(cos_i);
            for i in 0..2000 {
                let (ul, u) = uniforms(100 + k as u32, i);
                if let Some(s) = bsdf_sample(b, wi, ul, u) {
                    assert!(s.wo.is_finite() && (s.wo.length() - 1.0).abs() < 1e-4, "{b:?}: wo {:?}", s.wo);
                    assert_eq!(s.pdf, bsdf_pdf(b, wi, s.wo));
                    assert_eq!(s.value, bsdf_eval(b, wi, s.wo));
                    assert!(s.pdf > 0.0 && s.value.is_finite());
                }
            }
        }
    }
}

/// Reciprocity of f = f̂ / cos θo, and energy conservation ∫f̂ ≤ 1 (estimated by importance sampling).
#[test]
fn reciprocal_and_energy_conserving() {
    for (k, b) in all_bsdfs().iter().enumerate() {
        for cos_i in [0.9, 0.4] {
            let wi = incident(cos_i);
            let n = 20_000;
            let mut albedo = Vec3::ZERO;
            for i in 0..n {
                let (ul, u) = uniforms(200 + k as u32, i);
                if let Some(s) = bsdf_sample(b, wi, ul, u) {
                    albedo += s.value / s.pdf;
                    if s.wo.z < 0.0 {
                        // Transmission is reciprocal only in the generalised sense (η² factors):
                        // rough_dielectric's own test checks it.
                        continue;
                    }
                    let f_ab = bsdf_eval(b, wi, s.wo) / s.wo.z;
                    let f_ba = bsdf_eval(b, s.wo, wi) / wi.z;
                    assert!(
                        (f_ab - f_ba).abs().max_element() <= 1e-3 * f_ab.abs().max_element().max(1e-3),
                        "{b:?}: {f_ab} vs {f_ba}"
                    );
                }
            }
            albedo /= n as f32;
            // Monte Carlo estimate: allow 3 % for noise (the estimator's relative error at 20k samples).
            assert!(albedo.max_element() <= 1.03, "{b:?} at cos {cos_i}: albedo {albedo}");
        }
    }
}

/// With F ≡ 1 (eta 0, k 1) the conductor Fresnel term is exactly 1; for a real metal it is in (0, 1).
#[test]
fn fresnel_conductor_limits() {
    for c in [1.0, 0.5, 0.1] {
        assert!((rough_conductor::fresnel_conductor(c, Vec3::ZERO, Vec3::ONE) - Vec3::ONE).abs().max_element() < 1e-6);
        let gold =
            rough_conductor::fresnel_conductor(c, Vec3::new(0.143, 0.374, 1.442), Vec3::new(3.983, 2.385, 1.603));
        assert!(gold.min_element() > 0.0 && gold.max_element() < 1.0, "{gold}");
    }
}

/// One channel of the conductor Fresnel term in f64 (the formula of `fresnel_conductor`), for
/// finite differences free of f32 rounding.
fn fresnel_conductor_f64(c: f64, e: f64, k: f64) -> f64 {
    let (c2, s2) = (c * c, 1.0 - c * c);
    let t1 = e * e - k * k - s2;
    let q = (t1 * t1 + 4.0 * e * e * k * k).sqrt();
    let a = ((q + t1) * 0.5).max(0.0).sqrt();
    let rs = (q + c2 - 2.0 * c * a) / (q + c2 + 2.0 * c * a);
    let rp = rs * (q * c2 + s2 * s2 - 2.0 * c * a * s2) / (q * c2 + s2 * s2 + 2.0 * c * a * s2);
    0.5 * (rs + rp)
}

/// ∂F/∂eta and ∂F/∂k of the conductor Fresnel term against finite differences (f64, h = 1e-5:
/// central, or one-sided of second order at k = 0, the domain's edge) at several angles and (eta,
/// k): gold's, a dielectric-like k = 0 with eta > 1 and eta < 1 (total reflection past the
/// critical angle), Mitsuba's default eta = 0, and an eta below 1 with absorption. The channels
/// are independent: a change of channel 0 moves only F's channel 0.
#[test]
fn fresnel_conductor_ior_derivatives_match_finite_differences() {
    let cases = [
        (Vec3::new(0.143, 0.374, 1.442), Vec3::new(3.983, 2.385, 1.603)),
        (Vec3::new(1.5, 0.7, 0.2), Vec3::ZERO),
        (Vec3::new(0.0, 0.05, 0.3), Vec3::new(1.0, 0.0, 2.0)),
        (Vec3::new(0.4, 2.5, 0.9), Vec3::new(0.3, 0.02, 5.0)),
    ];
    let h = 1e-5f64;
    for (eta, k) in cases {
        for c in [1.0f32, 0.9, 0.6, 0.3, 0.05] {
            let (f, d_eta, d_k) = rough_conductor::fresnel_conductor_dior(c, eta, k);
            assert_eq!(f, rough_conductor::fresnel_conductor(c, eta, k));
            for ch in 0..3 {
                let (cc, e, kk) = (f64::from(c), f64::from(eta[ch]), f64::from(k[ch]));
                let fd_e = if e > h {
                    (fresnel_conductor_f64(cc, e + h, kk) - fresnel_conductor_f64(cc, e - h, kk)) / (2.0 * h)
                } else {
                    let f = |x: f64| fresnel_conductor_f64(cc, e + x, kk);
                    (-3.0 * f(0.0) + 4.0 * f(h) - f(2.0 * h)) / (2.0 * h)
                };
                let fd_k = if kk > h {
                    (fresnel_conductor_f64(cc, e, kk + h) - fresnel_conductor_f64(cc, e, kk - h)) / (2.0 * h)
                } else {
                    let f = |x: f64| fresnel_conductor_f64(cc, e, kk + x);
                    (-3.0 * f(0.0) + 4.0 * f(h) - f(2.0 * h)) / (2.0 * h)
                };
                for (what, got, want) in [("eta", d_eta[ch], fd_e), ("k", d_k[ch], fd_k)] {
                    let err = (f64::from(got) - want).abs();
                    assert!(
                        err <= 2e-3 * want.abs().max(1e-2),
                        "∂F/∂{what} at cos {c}, eta {e}, k {kk}: {got} against finite differences {want}"
                    );
                }
            }
        }
    }
}

/// A BSDF with one differentiable value replaced.
type Perturb = Box<dyn Fn(f32) -> Bsdf>;

/// Every parameter derivative against central finite differences of `bsdf_eval` (in f64 around
/// the f32 evaluation: h = 1e-3 of the value, so truncation error ~h² ≈ 1e-6 relative and f32
/// rounding ~1e-7/1e-3 = 1e-4 relative of the function's scale — tolerance 2e-3 relative to the
/// larger of the two derivatives' scale).
#[test]
fn derivatives_match_finite_differences() {
    let adj = Vec3::new(0.7, -0.3, 1.1);
    let objective = |b: &Bsdf, wi: Vec3, wo: Vec3| f64::from(adj.dot(bsdf_eval(b, wi, wo)));
    let mut checked = 0;
    for (k, b) in all_bsdfs().iter().enumerate() {
        for cos_i in [0.9, 0.5, 0.15] {
            let wi = incident(cos_i);
            for i in 0..40 {
                let (ul, u) = uniforms(300 + k as u32, i);
                let Some(s) = bsdf_sample(b, wi, ul, u) else { continue };
                let g = bsdf_eval_grad(b, wi, s.wo, adj);
                // (analytic derivative, function of a perturbation) per differentiable value.
                // (analytic, perturbation, value, relative FD step).
                let mut cases: Vec<(f32, Perturb, f32, f32)> = Vec::new();
                for leaf in 0..if b.blend { 2 } else { 1 } {
                    for c in 0..3 {
                        let base = *b;
                        let transmits = s.wo.z * wi.z < 0.0;
                        let value = match base.leaves[leaf] {
                            Leaf::RoughDielectric(d) if transmits => d.transmittance[c],
                            Leaf::RoughDielectric(d) => d.reflectance[c],
                            Leaf::Diffuse { albedo } => albedo[c],
                            Leaf::RoughConductor { specular, .. } => specular[c],
                            Leaf::RoughPlastic(p) => p.diffuse[c],
                            Leaf::Smooth(s) => s.reflectance[c],
                            Leaf::SmoothPlastic(p) => p.diffuse[c],
                            Leaf::Principled(p) => p.base_color[c],
                            Leaf::PrincipledThin(p) => p.base_color[c],
                        };
                        // A plastic's `trans` is its specular colour's derivative (checked below).
                        let coated = matches!(base.leaves[leaf], Leaf::RoughPlastic(_) | Leaf::SmoothPlastic(_));
                        cases.push((
                            g.leaves[leaf].color[c]
                                + if coated { 0.0 } else { g.leaves[leaf].trans[c] }
                                + g.leaves[leaf].principled.base_color[c].dot(Vec3::ONE),
                            Box::new(move |v| {
                                let mut x = base;
                                match &mut x.leaves[leaf] {
                                    Leaf::RoughDielectric(d) if transmits => d.transmittance[c] = v,
                                    Leaf::RoughDielectric(d) => d.reflectance[c] = v,
                                    Leaf::Diffuse { albedo } => albedo[c] = v,
                                    Leaf::RoughConductor { specular, .. } => specular[c] = v,
                                    Leaf::RoughPlastic(p) => p.diffuse[c] = v,
                                    Leaf::Smooth(s) => s.reflectance[c] = v,
                                    Leaf::SmoothPlastic(p) => p.diffuse[c] = v,
                                    Leaf::Principled(p) => p.base_color[c] = v,
                                    Leaf::PrincipledThin(p) => p.base_color[c] = v,
                                }
                                x
                            }),
                            value,
                            1e-3,
                        ));
                    }
                    // A rough plastic's specular colour, channel by channel.
                    if let Leaf::RoughPlastic(p) = b.leaves[leaf] {
                        for c in 0..3 {
                            let base = *b;
                            cases.push((
                                g.leaves[leaf].trans[c],
                                Box::new(move |v| {
                                    let mut x = base;
                                    if let Leaf::RoughPlastic(q) = &mut x.leaves[leaf] {
                                        q.specular[c] = v;
                                    }
                                    x
                                }),
                                p.specular[c],
                                1e-3,
                            ));
                        }
                    }
                    // A plastic's α moves its coating table too: rebuilt for each value (costly,
                    // so for the first samples only).
                    if let Leaf::RoughPlastic(p) = b.leaves[leaf]
                        && i < 3
                    {
                        let base = *b;
                        cases.push((
                            g.leaves[leaf].alpha.dot(Vec3::ONE),
                            Box::new(move |v| {
                                let mut x = base;
                                x.leaves[leaf] = plastic(p.distribution, v, p.diffuse, p.nonlinear);
                                x
                            }),
                            p.alpha,
                            // The table's f32 quadrature is noisy below about 10⁻³ of α.
                            1e-2,
                        ));
                    }
                    // α_u and α_v each alone, equal or not: separate parameters that hold the same
                    // value each take their own share (an isotropic α's is the sum of the two).
                    let rough = match b.leaves[leaf] {
                        Leaf::RoughDielectric(d) => Some((d.alpha, d.alpha_v)),
                        Leaf::RoughConductor { alpha, alpha_v, .. } => Some((alpha, alpha_v)),
                        _ => None,
                    };
                    if let Some((alpha_u, alpha_v)) = rough {
                        let gl = g.leaves[leaf];
                        for (v_axis, analytic, value) in [(false, gl.alpha, alpha_u), (true, gl.alpha_v, alpha_v)] {
                            let base = *b;
                            cases.push((
                                analytic.dot(Vec3::ONE),
                                Box::new(move |v| {
                                    let mut x = base;
                                    match &mut x.leaves[leaf] {
                                        Leaf::RoughDielectric(d) if v_axis => d.alpha_v = v,
                                        Leaf::RoughDielectric(d) => d.alpha = v,
                                        Leaf::RoughConductor { alpha_v, .. } if v_axis => *alpha_v = v,
                                        Leaf::RoughConductor { alpha, .. } => *alpha = v,
                                        _ => unreachable!("a rough leaf"),
                                    }
                                    x
                                }),
                                value,
                                1e-3,
                            ));
                        }
                    }
                }
                if b.blend {
                    let base = *b;
                    cases.push((
                        g.weight.dot(Vec3::ONE),
                        Box::new(move |v| Bsdf { weight: v, ..base }),
                        b.weight,
                        1e-3,
                    ));
                }
                let scale = objective(b, wi, s.wo).abs().max(1e-12);
                for (analytic, with, value, step) in &cases {
                    let h = step * value.abs().max(1e-2);
                    let fd = (objective(&with(value + h), wi, s.wo) - objective(&with(value - h), wi, s.wo))
                        / f64::from(2.0 * h);
                    let tol =
                        2e-3 * (fd.abs().max(f64::from(analytic.abs())).max(scale / f64::from(value.abs().max(1e-2))));
                    assert!(
                        (fd - f64::from(*analytic)).abs() <= tol,
                        "{b:?} wi {wi} wo {}: analytic {analytic} vs fd {fd}",
                        s.wo
                    );
                    checked += 1;
                }
            }
        }
    }
    assert!(checked > 1000, "only {checked} derivatives checked");
}

/// A blend of a diffuse leaf and a smooth conductor: the conductor's delta sample comes with the
/// blend's choice probability w, so E[value/pdf] is (1 − w)·albedo + w·F·reflectance (the diffuse
/// leaf's f̂ integrates to its albedo; the mirror's value is F·reflectance); its derivatives by the
/// weight and the conductor's reflectance are those of the sample's value (finite differences on
/// the same uniforms), and off the mirror direction the conductor has no value and no derivative.
#[test]
fn a_blend_with_a_smooth_conductor_weighs_its_delta_sample_by_the_blend() {
    use crate::bsdf::specular::{SmoothKind, SmoothLeaf};
    let mirror = SmoothLeaf {
        kind: SmoothKind::Conductor,
        reflectance: Vec3::new(0.9, 0.7, 0.5),
        transmittance: Vec3::ZERO,
        eta: Vec3::new(0.2, 0.9, 1.1),
        k: Vec3::new(3.9, 2.4, 2.2),
    };
    let albedo = Vec3::new(0.2, 0.6, 0.4);
    let w = 0.3;
    let blend = |w: f32, reflectance: Vec3| Bsdf {
        leaves: [Leaf::Diffuse { albedo }, Leaf::Smooth(SmoothLeaf { reflectance, ..mirror })],
        weight: w,
        blend: true,
        perturbed: None,
    };
    let b = blend(w, mirror.reflectance);
    let wi = incident(0.7);
    let fresnel = crate::bsdf::rough_conductor::fresnel_conductor(wi.z, mirror.eta, mirror.k);
    let n = 200_000;
    let (mut sum, mut sum2, mut deltas) = (Vec3::ZERO, Vec3::ZERO, 0usize);
    for i in 0..n {
        let (ul, u) = uniforms(900, i);
        let s = bsdf_sample(&b, wi, ul, u).expect("the diffuse leaf and the mirror sample every wi above");
        let weight = s.value / s.pdf;
        if s.delta {
            deltas += 1;
            assert_eq!(s.wo, specular::reflect(wi));
            assert!((s.pdf - w).abs() < 1e-6, "a delta sample's pdf is its choice probability: {}", s.pdf);
            assert!((weight - fresnel * mirror.reflectance).abs().max_element() < 1e-5);
        }
        sum += weight;
        sum2 += weight * weight;
    }
    let nf = n as f32;
    let p = deltas as f64 / n as f64;
    assert!((p - f64::from(w)).abs() < 4.0 * (f64::from(w * (1.0 - w)) / n as f64).sqrt(), "delta share {p}");
    let mean = sum / nf;
    let se = ((sum2 / nf - mean * mean) / nf).max(Vec3::ZERO).sqrt();
    let expected = albedo * (1.0 - w) + fresnel * mirror.reflectance * w;
    assert!(
        ((mean - expected).abs() - se * 4.0).max_element() < 0.0,
        "E[value/pdf] {mean} ± {se}, expected {expected}"
    );

    // Derivatives of a delta sample's value, against central differences on the same uniforms.
    let adj = Vec3::new(0.7, -0.3, 1.1);
    let (ul, u) = (0.1, Vec2::new(0.3, 0.6)); // u_lobe ≤ w: the mirror
    let s = bsdf_sample(&b, wi, ul, u).unwrap();
    assert!(s.delta);
    let g = bsdf_sample_grad(&b, wi, s.wo, true, adj);
    let value = |b: &Bsdf| adj.dot(bsdf_sample(b, wi, ul, u).unwrap().value);
    let h = 1e-3;
    let fd_w = (value(&blend(w + h, mirror.reflectance)) - value(&blend(w - h, mirror.reflectance))) / (2.0 * h);
    assert!((g.weight.dot(Vec3::ONE) - fd_w).abs() < 2e-3 * fd_w.abs().max(1.0), "weight {} vs {fd_w}", g.weight);
    for c in 0..3 {
        let with = |d: f32| {
            let mut r = mirror.reflectance;
            r[c] += d;
            value(&blend(w, r))
        };
        let fd = (with(h) - with(-h)) / (2.0 * h);
        assert!((g.leaves[1].color[c] - fd).abs() < 2e-3, "reflectance {c}: {} vs {fd}", g.leaves[1].color[c]);
    }
    assert_eq!(g.leaves[0], LeafGrad::default());
    // Off the mirror direction (a diffuse sample, or next-event estimation): no mirror term.
    let wo = Vec3::new(0.3, -0.2, 0.93).normalize();
    let g = bsdf_sample_grad(&b, wi, wo, false, adj);
    assert_eq!(g.leaves[1], LeafGrad::default());
    let f0 = diffuse::diffuse_eval(albedo, wi, wo);
    assert!((g.weight - adj * -f0).abs().max_element() < 1e-6, "{} vs {}", g.weight, adj * -f0);
}

/// Directions of a fixed pseudo-random set over the whole sphere (the principled, thin principled
/// and hair tests' direction pairs).
pub(crate) fn sphere_directions(n: usize, seed: u32) -> Vec<Vec3> {
    use crate::rng::{PassTag, RngKey, Stream, uniform4};
    (0..n)
        .map(|i| {
            let u = uniform4(RngKey::new(seed, 0, PassTag::Test), i as u32, 0, 1, Stream::Main, 1, 0);
            let z = 2.0 * u[0] - 1.0;
            let r = (1.0 - z * z).max(0.0).sqrt();
            let phi = 2.0 * std::f32::consts::PI * u[1];
            Vec3::new(r * phi.cos(), r * phi.sin(), z)
        })
        .collect()
}

/// A JSON array of 3-element arrays (a Mitsuba probe's directions) as vectors.
pub(crate) fn json_vec3s(v: &serde_json::Value) -> Vec<Vec3> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|p| {
            let a: Vec<f32> = p.as_array().unwrap().iter().map(|x| x.as_f64().unwrap() as f32).collect();
            Vec3::new(a[0], a[1], a[2])
        })
        .collect()
}

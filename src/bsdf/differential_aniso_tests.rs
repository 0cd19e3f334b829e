//! Tests of the anisotropic differential samplers: the angular inversion against an f64
//! reference, each part's normalisation and the parts' difference against the primal BSDF's
//! derivative by quadrature, chi-square of every signed part and of the coin mixture, edges.
//!
//! Significance budget: every chi-square test in this file shares one family at α = 0.01 with the
//! Šidák correction over `CHI2_TESTS` (its own family, apart from the isotropic samplers' file).

use glam::{Vec2, Vec3};

use super::*;
use crate::bsdf::differential::{diff_pdf_conductor, diff_pdf_conductor_part, sample_diff_conductor};
use crate::bsdf::rough_conductor::microfacet_d_dalpha_aniso;
use crate::rng::{PassTag, RngKey, Stream, uniform4};
use crate::stats::{Chi2Config, chi2_directions, dump_table, sidak};

const DISTRIBUTIONS: [Distribution; 2] = [Distribution::Beckmann, Distribution::Ggx];
/// (α_u, α_v, cos θi): strong anisotropy at a moderate angle, mild at near-normal incidence, rough
/// at grazing incidence.
const CASES: [(f32, f32, f32); 3] = [(0.05, 0.5, 0.5), (0.3, 0.15, 0.9), (0.8, 0.4, 0.2)];
/// Per distribution, case and target: the half vectors of p⁺, p⁻ and the mixture in stretched
/// half-vector space, and the mixture's reflected directions in direction space.
const CHI2_TESTS: usize = DISTRIBUTIONS.len() * 2 * CASES.len() * 4;
const FAMILY_ALPHA: f64 = 0.01;
const CHI2_SAMPLES: usize = 250_000;

fn uniforms(test: u32, i: usize) -> [f32; 4] {
    uniform4(RngKey::new(test, 0, PassTag::Test), i as u32, 0, 1, Stream::Main, 1, 0)
}

fn incident(cos_theta: f32) -> Vec3 {
    let sin = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
    Vec3::new(sin * 0.8, sin * 0.6, cos_theta)
}

// ---------------------------------------------------------------- the angular inversion

/// f64 reference of the quarter-period inversion: bisection of 2φ + sin 2φ = π u on [0, π/2] for
/// u ≤ ½, and above of δ − sin δ = π(1 − u) for δ = π − 2φ (by its series below 1: near φ = π/2
/// the first form is flat to third order, and f64 rounding alone moves its root by ~1e-5).
fn cos2_quarter_ref(u: f64) -> f64 {
    use std::f64::consts::PI;
    let (mut lo, mut hi) = (0.0f64, if u <= 0.5 { 0.5 * PI } else { PI });
    let below = |x: f64| {
        if u <= 0.5 {
            2.0 * x + (2.0 * x).sin() < PI * u
        } else {
            let dms = if x < 1.0 {
                // δ³/3! − δ⁵/5! + … to twelve terms.
                let (mut term, mut sum) = (x * x * x / 6.0, 0.0);
                for k in 0..12 {
                    sum += term;
                    let n = f64::from(2 * k + 3);
                    term *= -x * x / ((n + 1.0) * (n + 2.0));
                }
                sum
            } else {
                x - x.sin()
            };
            dms < PI * (1.0 - u)
        }
    };
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if below(mid) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let x = 0.5 * (lo + hi);
    if u <= 0.5 { x } else { 0.5 * PI - 0.5 * x }
}

/// |φ_f32(u) − φ_f64(u)| ≤ 2e-6 over [0, 1], dense near both ends and the branch switch at ½.
#[test]
fn cos2_inversion_matches_f64_reference() {
    let mut us: Vec<f32> = (0..=20_000).map(|k| k as f32 / 20_000.0).collect();
    for k in 0..=400 {
        let s = 10f32.powf(-7.0 + 6.5 * k as f32 / 400.0);
        us.extend([s, 1.0 - s, 0.5 - s, 0.5 + s]);
    }
    let mut worst = 0.0f64;
    for u in us.into_iter().filter(|u| (0.0..=1.0).contains(u)) {
        let phi = sample_cos2_quarter(u);
        let r = cos2_quarter_ref(f64::from(u));
        let err = (f64::from(phi) - r).abs();
        assert!(err <= 2e-6, "u {u:e}: φ = {phi} vs reference {r}: error {err:e}");
        worst = worst.max(err);
    }
    assert_eq!(sample_cos2_quarter(0.0), 0.0);
    assert_eq!(sample_cos2_quarter(1.0), FRAC_PI_2);
    for u in [0.0, 0.1, 0.25, 0.5, 0.75, 0.9, 1.0 - 1e-7, 1.0] {
        let phi = sample_cos2_angle(u);
        assert!((0.0..=2.0 * PI).contains(&phi), "u {u}: φ = {phi}");
    }
    eprintln!("cos² inversion worst error {worst:.2e}");
}

// ---------------------------------------------------------------- normalisation and the derivative

/// ∫ g over [a, b] by composite 5-point Gauss–Legendre on `panels` panels.
fn gauss(g: &dyn Fn(f64) -> f64, a: f64, b: f64, panels: usize) -> f64 {
    const NODES: [(f64, f64); 5] = [
        (0.0, 0.568_888_888_888_888_9),
        (-0.538_469_310_105_683_1, 0.478_628_670_499_366_5),
        (0.538_469_310_105_683_1, 0.478_628_670_499_366_5),
        (-0.906_179_845_938_664, 0.236_926_885_056_189_1),
        (0.906_179_845_938_664, 0.236_926_885_056_189_1),
    ];
    let h = (b - a) / panels as f64;
    (0..panels)
        .map(|p| {
            let mid = a + (p as f64 + 0.5) * h;
            NODES.iter().map(|&(t, w)| w * g(mid + 0.5 * h * t)).sum::<f64>() * 0.5 * h
        })
        .sum()
}

/// The unit half vector of the slopes (α_u X, α_v Y), and dω_h/dXdY = α_u α_v cos³θh, in f64
/// (independent of the densities' own Jacobian).
fn half_of(alpha: Vec2, x: f64, y: f64) -> (Vec3, f64) {
    let (sx, sy) = (f64::from(alpha.x) * x, f64::from(alpha.y) * y);
    let c = 1.0 / (1.0 + sx * sx + sy * sy).sqrt();
    let h = Vec3::new((sx * c) as f32, (sy * c) as f32, c as f32);
    (h, f64::from(alpha.x) * f64::from(alpha.y) * c * c * c)
}

/// ∫ over the hemisphere of f(h) dω_h, written over the stretched slope plane in polar form
/// (X, Y) = ρ(cos φ, sin φ), v = ρ² = s/(1 − s): dXdY = ½ dv dφ.
fn integrate_h(alpha: Vec2, f: &dyn Fn(Vec3) -> f64) -> f64 {
    let in_v = |v: f64| {
        let rho = v.sqrt();
        gauss(
            &|phi: f64| {
                let (h, jac) = half_of(alpha, rho * phi.cos(), rho * phi.sin());
                f(h) * jac
            },
            0.0,
            2.0 * std::f64::consts::PI,
            24,
        ) * 0.5
    };
    gauss(&|s: f64| in_v(s / (1.0 - s)) / ((1.0 - s) * (1.0 - s)), 0.0, 1.0, 400)
}

/// Each part integrates to 1 over the hemisphere, and (mass)·(p⁺ − p⁻) is ∂_{α_t}[D cos θh] from
/// the primal BSDF's derivative pointwise (independent of the closed forms).
#[test]
fn aniso_parts_are_normalised_and_differ_by_the_derivative() {
    for distribution in DISTRIBUTIONS {
        for (au, av, _) in CASES.into_iter().chain([(0.01, 0.2, 0.0), (1.0, 0.3, 0.0)]) {
            let alpha = Vec2::new(au, av);
            for target_v in [false, true] {
                for positive in [false, true] {
                    let mass = integrate_h(alpha, &|h| {
                        f64::from(aniso_diff_pdf_part_h(distribution, alpha, target_v, h, positive))
                    });
                    assert!(
                        (mass - 1.0).abs() < 1e-5,
                        "{distribution:?} α {alpha} target_v={target_v} positive={positive}: ∫p = {mass}"
                    );
                }
                let alpha_t = if target_v { av } else { au };
                let norm = f64::from(aniso_diff_norm(distribution, alpha_t));
                for k in 0..60 {
                    for j in 0..16 {
                        let theta = 1.55 * f64::from(k) / 60.0;
                        let phi = 2.0 * std::f64::consts::PI * (f64::from(j) + 0.3) / 16.0;
                        let h = Vec3::new(
                            (theta.sin() * phi.cos()) as f32,
                            (theta.sin() * phi.sin()) as f32,
                            theta.cos() as f32,
                        );
                        let d = microfacet_d_dalpha_aniso(distribution, alpha, h);
                        let lambda = f64::from(if target_v { d.y } else { d.x }) * f64::from(h.z);
                        if lambda == 0.0 {
                            continue; // the primal underflow guard
                        }
                        let p = f64::from(aniso_diff_pdf_part_h(distribution, alpha, target_v, h, true));
                        let m = f64::from(aniso_diff_pdf_part_h(distribution, alpha, target_v, h, false));
                        let ours = norm * (p - m);
                        let scale = norm * (p + m);
                        assert!(
                            (ours - lambda).abs() <= 2e-5 * scale + 1e-30,
                            "{distribution:?} α {alpha} target_v={target_v} h {h}: {ours} vs Λ {lambda}"
                        );
                    }
                }
            }
        }
    }
}

// ---------------------------------------------------------------- chi-square

fn check_chi2(name: &str, fine: bool, sample: impl Fn(usize) -> Option<Vec3> + Sync, pdf: impl Fn(Vec3) -> f64 + Sync) {
    let k = if fine { 2 } else { 1 };
    let cfg = Chi2Config {
        cos_bins: 16 * k,
        phi_bins: 32 * k,
        samples: CHI2_SAMPLES,
        significance: sidak(FAMILY_ALPHA, CHI2_TESTS),
    };
    let r = chi2_directions(&cfg, sample, pdf);
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

/// The chi-square of a half-vector sampler (`sample` gives h) against its density `pdf_h`, in
/// the space of v = normalize(h_x/α_u, h_y/α_v, h_z), where a lobe narrow along one axis spreads
/// over the hemisphere. With M = diag(1/α_u, 1/α_v, 1), dω_v/dω_h = 1/(α_u α_v |Mh|³) and
/// |Mh| = 1/|M⁻¹v|, so v has density pdf_h(h)·α_u α_v/|M⁻¹v|³ with h = normalize(M⁻¹v).
fn check_chi2_stretched(
    name: &str,
    alpha: Vec2,
    sample: impl Fn(usize) -> Option<Vec3> + Sync,
    pdf_h: impl Fn(Vec3) -> f64 + Sync,
) {
    let (au, av) = (f64::from(alpha.x), f64::from(alpha.y));
    check_chi2(
        name,
        false,
        |i| {
            let h = sample(i)?;
            Some(Vec3::new(h.x / alpha.x, h.y / alpha.y, h.z).normalize())
        },
        |v| {
            if v.z <= 0.0 {
                return 0.0;
            }
            let (x, y, z) = (au * f64::from(v.x), av * f64::from(v.y), f64::from(v.z));
            let len = (x * x + y * y + z * z).sqrt();
            let h = Vec3::new((x / len) as f32, (y / len) as f32, (z / len) as f32);
            pdf_h(h) * au * av / (len * len * len)
        },
    );
}

/// The coin-mixed technique as the BSDF-level sampler draws it: the positive part if `u_sign < ½`,
/// else the negative one with (u_sign − ½)/½ choosing its piece.
fn sample_mixed(d: Distribution, alpha: Vec2, target_v: bool, wi: Vec3, u: [f32; 4]) -> Option<Vec3> {
    let positive = u[0] < 0.5;
    let u_piece = if positive { 0.0 } else { (u[0] - 0.5) / 0.5 };
    sample_diff_conductor(d, alpha, target_v, wi, positive, u_piece, Vec2::new(u[2], u[3]))
}

/// The half vector of [`sample_mixed`].
fn sample_mixed_half(d: Distribution, alpha: Vec2, target_v: bool, u: [f32; 4]) -> Option<Vec3> {
    let positive = u[0] < 0.5;
    let u_piece = if positive { 0.0 } else { (u[0] - 0.5) / 0.5 };
    sample_aniso_diff_half(d, alpha, target_v, positive, u_piece, Vec2::new(u[2], u[3]))
}

/// Per case and target: each part's half vectors and the mixture's in stretched half-vector space
/// (no reflection: the densities themselves over the whole hemisphere), then the mixture's
/// reflected directions against [`diff_pdf_conductor`] (validity and the reflection Jacobian).
fn chi2_aniso(distribution: Distribution, first_test: u32) {
    let mut test = first_test;
    for (au, av, cos_i) in CASES {
        let alpha = Vec2::new(au, av);
        let wi = incident(cos_i);
        for target_v in [false, true] {
            let tag = format!("diff-aniso-{distribution:?}-au{au}-av{av}-{}", if target_v { "v" } else { "u" });
            for positive in [false, true] {
                test += 1;
                check_chi2_stretched(
                    &format!("{tag}-{}-h", if positive { "pos" } else { "neg" }),
                    alpha,
                    |i| {
                        let u = uniforms(test, i);
                        sample_aniso_diff_half(distribution, alpha, target_v, positive, u[1], Vec2::new(u[2], u[3]))
                    },
                    |h| f64::from(aniso_diff_pdf_part_h(distribution, alpha, target_v, h, positive)),
                );
            }
            test += 1;
            check_chi2_stretched(
                &format!("{tag}-mixed-h"),
                alpha,
                |i| sample_mixed_half(distribution, alpha, target_v, uniforms(test, i)),
                |h| f64::from(aniso_diff_pdf_mixed_h(distribution, alpha, target_v, h)),
            );
            test += 1;
            check_chi2(
                &format!("{tag}-cos{cos_i}-mixed"),
                au.min(av) < 0.1,
                |i| sample_mixed(distribution, alpha, target_v, wi, uniforms(test, i)),
                |wo| f64::from(diff_pdf_conductor(distribution, alpha, target_v, wi, wo)),
            );
        }
    }
}

#[test]
fn chi2_aniso_differential_beckmann() {
    chi2_aniso(Distribution::Beckmann, 1300);
}

#[test]
fn chi2_aniso_differential_ggx() {
    chi2_aniso(Distribution::Ggx, 1400);
}

// ---------------------------------------------------------------- consistency and edges

/// The mixture is the mean of the parts' densities, and the direction density is the half-vector
/// density through the reflection Jacobian 1/(4 wo·h).
#[test]
fn mixture_and_direction_densities_agree() {
    for d in DISTRIBUTIONS {
        for (au, av, cos_i) in CASES {
            let alpha = Vec2::new(au, av);
            let wi = incident(cos_i);
            for target_v in [false, true] {
                for i in 0..4000 {
                    let u = uniforms(1500, i);
                    let Some(wo) = sample_mixed(d, alpha, target_v, wi, u) else { continue };
                    assert!(wo.is_finite() && (wo.length() - 1.0).abs() < 1e-4 && wo.z > 0.0, "wo {wo}");
                    let p = diff_pdf_conductor(d, alpha, target_v, wi, wo);
                    let parts = 0.5
                        * (diff_pdf_conductor_part(d, alpha, target_v, true, wi, wo)
                            + diff_pdf_conductor_part(d, alpha, target_v, false, wi, wo));
                    assert!(p > 0.0 && p.is_finite() && (parts - p).abs() <= 1e-5 * p, "{p} vs ½(p⁺ + p⁻) {parts}");
                    let h = (wi + wo).normalize();
                    let through = aniso_diff_pdf_mixed_h(d, alpha, target_v, h) / (4.0 * wo.dot(h));
                    assert!((through - p).abs() <= 1e-5 * p, "{through} vs {p}");
                }
            }
        }
    }
}

/// Densities are finite at h = z and at the horizon; samplers give a finite direction or `None`
/// at the ends of every uniform.
#[test]
fn aniso_edges_are_finite() {
    let us = [0.0, f32::MIN_POSITIVE, 1e-7, 0.25, 0.5, 2.0 / 3.0, 0.75, 1.0 - 1.0 / 16_777_216.0, 1.0 - 1e-7, 1.0];
    for d in DISTRIBUTIONS {
        for alpha in [Vec2::new(1e-3, 0.5), Vec2::new(0.05, 0.5), Vec2::new(1.0, 0.01), Vec2::new(0.3, 0.2)] {
            for target_v in [false, true] {
                for h in [
                    Vec3::Z,
                    Vec3::X,
                    Vec3::Y,
                    Vec3::new(1.0, 0.0, 1e-10).normalize(),
                    Vec3::new(0.0, 1.0, 1e-8).normalize(),
                    Vec3::new(0.6, 0.0, 0.8),
                ] {
                    for positive in [false, true] {
                        let p = aniso_diff_pdf_part_h(d, alpha, target_v, h, positive);
                        assert!(p.is_finite() && p >= 0.0, "{d:?} α {alpha} h {h}: {p}");
                    }
                }
                for positive in [false, true] {
                    for weighted in [false, true] {
                        for &ub in &us {
                            let v = aniso_sample_radius2(d, weighted, ub);
                            assert!(!v.is_nan() && v >= 0.0, "{d:?} {weighted} u_b {ub}: v {v}");
                        }
                    }
                    for cos_i in [1.0, 0.5, 1e-4] {
                        let wi = incident(cos_i);
                        for &ua in &us {
                            for &ub in &us {
                                for piece in [0.0, 0.9] {
                                    let Some(wo) = sample_diff_conductor(
                                        d,
                                        alpha,
                                        target_v,
                                        wi,
                                        positive,
                                        piece,
                                        Vec2::new(ua, ub),
                                    ) else {
                                        continue;
                                    };
                                    assert!(wo.is_finite() && wo.z > 0.0, "{d:?} α {alpha} u ({ua}, {ub}): wo {wo}");
                                    let p = diff_pdf_conductor_part(d, alpha, target_v, positive, wi, wo);
                                    assert!(p.is_finite() && p >= 0.0, "{d:?} α {alpha} u ({ua}, {ub}): pdf {p}");
                                }
                            }
                        }
                    }
                }
            }
        }
    }
}

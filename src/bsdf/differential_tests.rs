//! Tests of the differential samplers (ALGORITHMS.md §10 "Samplers"): Lambert W against an f64
//! reference, Kolmogorov–Smirnov of the four inversions, normalisation by quadrature, chi-square of
//! every signed part, the coin-mixed sampler and the blend's differential sampler, edge finiteness.
//!
//! Significance budget: every statistical test in this file (chi-square and KS) shares one family
//! at α = 0.01 with the Šidák correction over `STAT_TESTS`.

use glam::{Vec2, Vec3};

use super::*;
use crate::bsdf::rough_conductor::{microfacet_d, microfacet_d_dalpha};
use crate::rng::{PassTag, RngKey, Stream, uniform4};
use crate::stats::{Chi2Config, chi2_directions, dump_table, sidak};

const DISTRIBUTIONS: [Distribution; 2] = [Distribution::Beckmann, Distribution::Ggx];
const ALPHAS: [f32; 3] = [0.05, 0.3, 0.8];
const COS_I: [f32; 3] = [0.999, 0.5, 0.05];
const BLEND_WEIGHTS: [f32; 3] = [0.1, 0.5, 0.9];
/// (α, cos θi) pairs whose chi-square runs in stretched half-vector space instead of direction
/// space: at α = 0.05 and cos θi = 0.05 the reflected lobe is a sliver at the horizon, narrower than
/// the starting grid of the harness's adaptive cell quadrature (which then integrates 0.68 of the
/// mass whatever the sampler does). In half-vector space stretched by 1/α the same samples spread
/// over the hemisphere, where the quadrature resolves them (`check_chi2_half_vector`).
const CHI2_IN_HALF_VECTOR_SPACE: [(f32, f32); 1] = [(0.05, 0.05)];
/// Rough dielectrics' differential samplers: (α, cos θi) per distribution, from outside and from
/// inside (where total internal reflection takes the grazing refractions).
const DIELECTRIC_CASES: [(f32, f32); 4] = [(0.1, 0.8), (0.4, 0.3), (0.1, -0.7), (0.4, -0.3)];
/// Chi-square: per configuration p⁺, p⁻ and the coin-mixed sampler (conductors and dielectrics);
/// three blends. KS: four inversions.
/// Rough plastics' differential samplers: (α, cos θi, nonlinear) per distribution.
const PLASTIC_CASES: [(f32, f32, bool); 3] = [(0.1, 0.8, false), (0.4, 0.3, true), (0.05, 0.95, false)];
const CHI2_TESTS: usize =
    DISTRIBUTIONS.len() * (ALPHAS.len() * COS_I.len() + DIELECTRIC_CASES.len() + PLASTIC_CASES.len()) * 3
        + BLEND_WEIGHTS.len();
const KS_TESTS: usize = 4;
const STAT_TESTS: usize = CHI2_TESTS + KS_TESTS;
const FAMILY_ALPHA: f64 = 0.01;
const CHI2_SAMPLES: usize = 250_000;
const KS_SAMPLES: usize = 200_000;

fn uniforms(test: u32, i: usize) -> [f32; 4] {
    uniform4(RngKey::new(test, 0, PassTag::Test), i as u32, 0, 1, Stream::Main, 1, 0)
}

fn incident(cos_theta: f32) -> Vec3 {
    let sin = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
    Vec3::new(sin * 0.8, sin * 0.6, cos_theta)
}

fn conductor(distribution: Distribution, alpha: f32) -> Bsdf {
    Bsdf::leaf(Leaf::RoughConductor {
        distribution,
        alpha,
        alpha_v: alpha,
        specular: Vec3::ONE,
        eta: Vec3::ZERO,
        k: Vec3::ONE,
    })
}

/// The rough dielectric of the BSDF tests (bk7 in air), as its leaf.
fn glass(distribution: Distribution, alpha: f32) -> RoughDielectricLeaf {
    match crate::bsdf::tests::glass(distribution, alpha) {
        Leaf::RoughDielectric(g) => g,
        other => unreachable!("{other:?}"),
    }
}

fn blend(w: f32) -> Bsdf {
    Bsdf {
        leaves: [Leaf::Diffuse { albedo: Vec3::new(0.1, 0.6, 0.35) }, conductor(Distribution::Ggx, 0.2).leaves[0]],
        weight: w,
        blend: true,
        perturbed: None,
    }
}

// ---------------------------------------------------------------- Lambert W

/// f64 reference: bisection on the monotone branch to a tight bracket, then Halley polish.
fn lambert_ref(x: f64, lower: bool) -> f64 {
    let (mut lo, mut hi) = if lower { (-200.0f64, -1.0f64) } else { (-1.0f64, 0.0f64) };
    // w e^w is increasing on [−1, 0] and decreasing on (−∞, −1].
    for _ in 0..80 {
        let mid = 0.5 * (lo + hi);
        let above = mid * mid.exp() > x;
        if above != lower {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    let mut w = 0.5 * (lo + hi);
    for _ in 0..4 {
        let ew = w.exp();
        let f = w * ew - x;
        let wp1 = w + 1.0;
        if wp1.abs() < 1e-6 || f == 0.0 {
            break;
        }
        let next = w - f / (ew * wp1 - (w + 2.0) * f / (2.0 * wp1));
        if next.is_finite() && next > lo - 1e-9 && next < hi + 1e-9 {
            w = next;
        }
    }
    w
}

/// Arguments on [−1/e, 0): dense near the branch point, log-spaced towards 0, and a uniform grid.
fn lambert_arguments() -> Vec<f32> {
    let inv_e = (-1.0f64).exp();
    let mut xs = Vec::new();
    for k in 0..=700 {
        let s = 10f64.powf(-8.0 + 8.0 * f64::from(k) / 700.0);
        xs.push((-inv_e * (1.0 - s)) as f32);
    }
    for k in 0..=700 {
        xs.push(-(10f64.powf(-30.0 + 29.6 * f64::from(k) / 700.0)) as f32);
    }
    for k in 1..2000 {
        xs.push((-inv_e * f64::from(k) / 2000.0) as f32);
    }
    xs.push((-inv_e) as f32);
    xs.into_iter().filter(|&x| f64::from(x) >= -inv_e && x < 0.0).collect()
}

/// |W_f32(x) − W_f64(x)| ≤ 1e-5 (1 + |W|) on both branches (ALGORITHMS.md §10; |W| is the sampled x).
#[test]
fn lambert_w_matches_f64_reference() {
    let mut worst = [0.0f64; 2];
    for x in lambert_arguments() {
        for (b, lower) in [false, true].into_iter().enumerate() {
            let w = if lower { lambert_wm1(x) } else { lambert_w0(x) };
            let r = lambert_ref(f64::from(x), lower);
            let err = (f64::from(w) - r).abs() / (1.0 + r.abs());
            assert!(
                err <= 1e-5,
                "W{} ({x:e}) = {w} vs reference {r}: scaled error {err:e}",
                if lower { "-1" } else { "0" }
            );
            worst[b] = worst[b].max(err);
        }
    }
    assert!(lambert_w0(0.0) == 0.0 && lambert_wm1(0.0) == f32::NEG_INFINITY);
    eprintln!("lambert W worst scaled error: W0 {:.2e}, W-1 {:.2e}", worst[0], worst[1]);
}

// ---------------------------------------------------------------- Kolmogorov–Smirnov of the inversions

/// Closed-form CDF of x = tan²θh/α² for one signed part (ALGORITHMS.md §4.2 table), in f64.
fn part_cdf(distribution: Distribution, positive: bool, x: f64) -> f64 {
    match (distribution, positive) {
        (Distribution::Beckmann, false) => (x * (1.0 - x).exp()).clamp(0.0, 1.0),
        (Distribution::Beckmann, true) => {
            if x <= 1.0 {
                0.0
            } else {
                1.0 - x * (1.0 - x).exp()
            }
        }
        (Distribution::Ggx, false) => (4.0 * x / ((1.0 + x) * (1.0 + x))).clamp(0.0, 1.0),
        (Distribution::Ggx, true) => {
            if x <= 1.0 {
                0.0
            } else {
                ((x - 1.0) / (x + 1.0)).powi(2)
            }
        }
    }
}

/// Kolmogorov's limiting survival function Q(λ) = 2 Σ (−1)^{k−1} e^{−2k²λ²}.
fn kolmogorov_q(lambda: f64) -> f64 {
    if lambda < 0.2 {
        return 1.0;
    }
    (1..=100).map(f64::from).map(|k| 2.0 * (-1f64).powf(k - 1.0) * (-2.0 * k * k * lambda * lambda).exp()).sum()
}

/// The critical value of the KS statistic D_n at significance `s`: Q((√n + 0.12 + 0.11/√n) D) = s
/// (Stephens' finite-n correction of Kolmogorov's limit), solved by bisection.
fn ks_critical(n: usize, s: f64) -> f64 {
    let (mut lo, mut hi) = (0.2f64, 5.0f64);
    for _ in 0..100 {
        let mid = 0.5 * (lo + hi);
        if kolmogorov_q(mid) > s {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let sn = (n as f64).sqrt();
    0.5 * (lo + hi) / (sn + 0.12 + 0.11 / sn)
}

#[test]
fn ks_of_the_four_inversions() {
    let significance = sidak(FAMILY_ALPHA, STAT_TESTS);
    let critical = ks_critical(KS_SAMPLES, significance);
    for (k, (distribution, positive)) in DISTRIBUTIONS.into_iter().flat_map(|d| [(d, false), (d, true)]).enumerate() {
        let mut xs: Vec<f64> = (0..KS_SAMPLES)
            .map(|i| f64::from(diff_sample_x(distribution, positive, uniforms(500 + k as u32, i)[1])))
            .collect();
        assert!(xs.iter().all(|x| x.is_finite() && *x >= 0.0), "{distribution:?} {positive}: x not finite");
        xs.sort_by(f64::total_cmp);
        let n = xs.len() as f64;
        let d = xs
            .iter()
            .enumerate()
            .map(|(i, &x)| {
                let f = part_cdf(distribution, positive, x);
                (f - i as f64 / n).max((i + 1) as f64 / n - f)
            })
            .fold(0.0f64, f64::max);
        assert!(d < critical, "{distribution:?} positive={positive}: KS D = {d:.3e} ≥ critical {critical:.3e}");
    }
}

// ---------------------------------------------------------------- normalisation by quadrature

/// ∫ g over [a, b] by composite 5-point Gauss–Legendre on `panels` panels (no endpoint evaluations).
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

/// ∫ over the hemisphere of a function of h that depends on θh only, written in x = tan²θh/α²:
/// dω = π α² cos³θh dx after the φ integral; [0, 1] directly and [1, ∞) through x = 1 + s/(1 − s).
fn integrate_h(alpha: f32, f: &dyn Fn(Vec3) -> f64) -> f64 {
    let a2 = f64::from(alpha) * f64::from(alpha);
    let in_x = |x: f64| {
        let c = 1.0 / (1.0 + a2 * x).sqrt();
        let s = (a2 * x).sqrt() * c;
        f(Vec3::new(s as f32, 0.0, c as f32)) * std::f64::consts::PI * a2 * c * c * c
    };
    let head = gauss(&in_x, 0.0, 1.0, 2000);
    let tail = gauss(&|s: f64| in_x(1.0 + s / (1.0 - s)) / ((1.0 - s) * (1.0 - s)), 0.0, 1.0, 20_000);
    head + tail
}

/// ∫p±(h) dh = 1, ∫Λ = 0 and ∫|Λ| = N_α (4/(eα) Beckmann, 1/α GGX), with Λ = ∂α[D cos θh] from the
/// primal BSDF's derivative (independent of the closed forms); and p_abs = |Λ|/N_α pointwise.
#[test]
fn differential_densities_are_normalised() {
    for distribution in DISTRIBUTIONS {
        for alpha in [0.01, 0.05, 0.3, 0.8] {
            for positive in [false, true] {
                let mass = integrate_h(alpha, &|h| f64::from(diff_pdf_part_h(distribution, alpha, h, positive)));
                assert!((mass - 1.0).abs() < 1e-6, "{distribution:?} α {alpha} positive={positive}: ∫p = {mass}");
            }
            let lambda = |h: Vec3| f64::from(microfacet_d_dalpha(distribution, alpha, h)) * f64::from(h.z);
            let norm = f64::from(diff_norm(distribution, alpha));
            let exact = match distribution {
                Distribution::Beckmann => 4.0 / (std::f64::consts::E * f64::from(alpha)),
                Distribution::Ggx => 1.0 / f64::from(alpha),
            };
            assert!((norm - exact).abs() <= 1e-6 * exact);
            let total = integrate_h(alpha, &lambda);
            let abs = integrate_h(alpha, &|h| lambda(h).abs());
            assert!(total.abs() < 1e-6 * exact, "{distribution:?} α {alpha}: ∫Λ = {total}");
            assert!((abs - exact).abs() < 1e-6 * exact, "{distribution:?} α {alpha}: ∫|Λ| = {abs} vs {exact}");
            for k in 0..200 {
                let theta = 1.5 * f64::from(k) / 200.0;
                let h = Vec3::new(theta.sin() as f32, 0.0, theta.cos() as f32);
                if microfacet_d(distribution, alpha, h) == 0.0 {
                    continue; // the primal underflow guard zeroes Λ there; p_abs has no such guard
                }
                let (p, l) = (f64::from(diff_pdf_abs_h(distribution, alpha, h)), lambda(h).abs() / exact);
                assert!((p - l).abs() <= 1e-5 * p.max(l) + 1e-30, "{distribution:?} α {alpha} θ {theta}: {p} vs {l}");
            }
        }
    }
}

// ---------------------------------------------------------------- chi-square

fn check_chi2(name: &str, alpha: f32, sample: impl Fn(usize) -> Option<Vec3> + Sync, pdf: impl Fn(Vec3) -> f64 + Sync) {
    // Narrow lobes (α < 0.1, as far as grazing reflection) need finer cells: the harness's adaptive
    // quadrature starts from a few points per cell and misses a peak narrower than a cell.
    let fine = if alpha < 0.1 { 2 } else { 1 };
    let cfg = Chi2Config {
        cos_bins: 16 * fine,
        phi_bins: 32 * fine,
        samples: CHI2_SAMPLES,
        significance: sidak(FAMILY_ALPHA, STAT_TESTS),
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

/// The chi-square of a reflection sampler (`sample` gives wo) against its half-vector density
/// `pdf_h` (per solid angle of h), in the space of v = normalize(h.x/α, h.y/α, h.z). The map h → v
/// has Jacobian dω_v/dω_h = α⁻²/|S h|³ (S = diag(1/α, 1/α, 1)), so v has density
/// pdf_h(h)·α²/|S⁻¹v|³ with h = normalize(S⁻¹v), restricted to the h that reflect wi above the horizon.
fn check_chi2_half_vector(
    name: &str,
    alpha: f32,
    wi: Vec3,
    sample: impl Fn(usize) -> Option<Vec3> + Sync,
    pdf_h: impl Fn(Vec3) -> f64 + Sync,
) {
    let a = f64::from(alpha);
    check_chi2(
        name,
        alpha,
        |i| {
            let h = (wi + sample(i)?).normalize();
            Some(Vec3::new(h.x / alpha, h.y / alpha, h.z).normalize())
        },
        |v| {
            let (x, y, z) = (a * f64::from(v.x), a * f64::from(v.y), f64::from(v.z));
            let len = (x * x + y * y + z * z).sqrt();
            let h = Vec3::new((x / len) as f32, (y / len) as f32, (z / len) as f32);
            let wih = wi.dot(h);
            let wo = 2.0 * wih * h - wi;
            if wo.z <= 0.0 || wih <= 0.0 {
                return 0.0;
            }
            pdf_h(h) * a * a / (len * len * len)
        },
    );
}

/// Each signed part's sampler against its own density, and the coin-mixed BSDF-level sampler
/// against `bsdf_pdf_diff`.
fn chi2_conductor(distribution: Distribution, first_test: u32) {
    let mut test = first_test;
    for alpha in ALPHAS {
        for cos_i in COS_I {
            if CHI2_IN_HALF_VECTOR_SPACE.contains(&(alpha, cos_i)) {
                let wi = incident(cos_i);
                for positive in [false, true] {
                    test += 1;
                    check_chi2_half_vector(
                        &format!(
                            "diff-{distribution:?}-alpha{alpha}-cos{cos_i}-{}-h",
                            if positive { "pos" } else { "neg" }
                        ),
                        alpha,
                        wi,
                        |i| {
                            let u = uniforms(test, i);
                            sample_diff_part(distribution, alpha, wi, positive, Vec2::new(u[2], u[3]))
                        },
                        |h| f64::from(diff_pdf_part_h(distribution, alpha, h, positive)),
                    );
                }
                test += 1;
                let b = conductor(distribution, alpha);
                check_chi2_half_vector(
                    &format!("diff-{distribution:?}-alpha{alpha}-cos{cos_i}-mixed-h"),
                    alpha,
                    wi,
                    |i| {
                        let u = uniforms(test, i);
                        bsdf_sample_diff(&b, false, wi, u[0], u[1], Vec2::new(u[2], u[3])).map(|s| s.wo)
                    },
                    |h| f64::from(diff_pdf_abs_h(distribution, alpha, h)),
                );
                continue;
            }
            let wi = incident(cos_i);
            for positive in [false, true] {
                test += 1;
                check_chi2(
                    &format!("diff-{distribution:?}-alpha{alpha}-cos{cos_i}-{}", if positive { "pos" } else { "neg" }),
                    alpha,
                    |i| {
                        let u = uniforms(test, i);
                        sample_diff_part(distribution, alpha, wi, positive, Vec2::new(u[2], u[3]))
                    },
                    |wo| f64::from(diff_pdf_part(distribution, alpha, positive, wi, wo)),
                );
            }
            test += 1;
            let b = conductor(distribution, alpha);
            check_chi2(
                &format!("diff-{distribution:?}-alpha{alpha}-cos{cos_i}-mixed"),
                alpha,
                |i| {
                    let u = uniforms(test, i);
                    bsdf_sample_diff(&b, false, wi, u[0], u[1], Vec2::new(u[2], u[3])).map(|s| s.wo)
                },
                |wo| f64::from(bsdf_pdf_diff(&b, false, wi, wo)),
            );
        }
    }
}

#[test]
fn chi2_differential_beckmann() {
    chi2_conductor(Distribution::Beckmann, 600);
}

#[test]
fn chi2_differential_ggx() {
    chi2_conductor(Distribution::Ggx, 700);
}

/// Each signed part's rough-dielectric sampler against its own density, and the coin-mixed
/// sampler against `bsdf_pdf_diff`, over the whole sphere of directions (reflected and refracted).
#[test]
fn chi2_differential_dielectric() {
    let mut test = 1000;
    for distribution in DISTRIBUTIONS {
        for (alpha, cos_i) in DIELECTRIC_CASES {
            let leaf = glass(distribution, alpha);
            let wi = incident(cos_i);
            for positive in [false, true] {
                test += 1;
                check_chi2(
                    &format!(
                        "diff-dielectric-{distribution:?}-alpha{alpha}-cos{cos_i}-{}",
                        if positive { "pos" } else { "neg" }
                    ),
                    alpha,
                    |i| {
                        let u = uniforms(test, i);
                        sample_diff_dielectric(&leaf, false, wi, positive, 0.0, u[1], Vec2::new(u[2], u[3]))
                    },
                    |wo| f64::from(diff_pdf_dielectric_part(&leaf, false, positive, wi, wo)),
                );
            }
            test += 1;
            let b = Bsdf::leaf(Leaf::RoughDielectric(leaf));
            check_chi2(
                &format!("diff-dielectric-{distribution:?}-alpha{alpha}-cos{cos_i}-mixed"),
                alpha,
                |i| {
                    let u = uniforms(test, i);
                    bsdf_sample_diff(&b, false, wi, u[0], u[1], Vec2::new(u[2], u[3])).map(|s| s.wo)
                },
                |wo| f64::from(bsdf_pdf_diff(&b, false, wi, wo)),
            );
        }
    }
}

fn plastic(distribution: Distribution, alpha: f32, nonlinear: bool) -> PlasticLeaf {
    match crate::bsdf::tests::plastic(distribution, alpha, Vec3::new(0.2, 0.5, 0.8), nonlinear) {
        Leaf::RoughPlastic(p) => p,
        other => unreachable!("{other:?}"),
    }
}

/// Each signed part's rough-plastic sampler (coating by the part, base by the cosine) against its
/// own density, and the coin-mixed sampler against `bsdf_pdf_diff`.
#[test]
fn chi2_differential_plastic() {
    let mut test = 1100;
    for distribution in DISTRIBUTIONS {
        for (alpha, cos_i, nonlinear) in PLASTIC_CASES {
            let leaf = plastic(distribution, alpha, nonlinear);
            let wi = incident(cos_i);
            for positive in [false, true] {
                test += 1;
                check_chi2(
                    &format!(
                        "diff-plastic-{distribution:?}-alpha{alpha}-cos{cos_i}-{}",
                        if positive { "pos" } else { "neg" }
                    ),
                    alpha,
                    |i| {
                        let u = uniforms(test, i);
                        sample_diff_plastic(&leaf, wi, positive, u[1], Vec2::new(u[2], u[3]))
                    },
                    |wo| f64::from(diff_pdf_plastic_part(&leaf, positive, wi, wo)),
                );
            }
            test += 1;
            let b = Bsdf::leaf(Leaf::RoughPlastic(leaf));
            check_chi2(
                &format!("diff-plastic-{distribution:?}-alpha{alpha}-cos{cos_i}-mixed"),
                alpha,
                |i| {
                    let u = uniforms(test, i);
                    bsdf_sample_diff(&b, false, wi, u[0], u[1], Vec2::new(u[2], u[3])).map(|s| s.wo)
                },
                |wo| f64::from(bsdf_pdf_diff(&b, false, wi, wo)),
            );
        }
    }
}

#[test]
fn chi2_differential_blend() {
    for (k, w) in BLEND_WEIGHTS.into_iter().enumerate() {
        let b = blend(w);
        let wi = incident(0.7);
        check_chi2(
            &format!("diff-blend-w{w}"),
            0.2,
            |i| {
                let u = uniforms(800 + k as u32, i);
                bsdf_sample_diff(&b, false, wi, u[0], u[1], Vec2::new(u[2], u[3])).map(|s| s.wo)
            },
            |wo| f64::from(bsdf_pdf_diff(&b, false, wi, wo)),
        );
    }
}

// ---------------------------------------------------------------- consistency and edges

#[test]
fn capability_flags() {
    assert!(!bsdf_diff_capable(&Bsdf::leaf(Leaf::Diffuse { albedo: Vec3::ONE })));
    assert!(bsdf_diff_capable(&conductor(Distribution::Beckmann, 0.3)));
    assert!(bsdf_diff_capable(&conductor(Distribution::Ggx, 0.3)));
    assert!(bsdf_diff_capable(&blend(0.5)));
    assert!(bsdf_diff_capable(&Bsdf::leaf(Leaf::RoughDielectric(glass(Distribution::Ggx, 0.3)))));
    assert!(bsdf_diff_capable(&Bsdf::leaf(Leaf::RoughPlastic(plastic(Distribution::Ggx, 0.3, false)))));
}

/// The pdf and value a differential sample reports are `bsdf_pdf_diff` and `bsdf_eval` at its
/// direction; the coin-mixed density is the mean of the two parts' densities.
#[test]
fn sample_diff_agrees_with_pdf_and_eval() {
    let mut bsdfs = vec![Bsdf::leaf(Leaf::Diffuse { albedo: Vec3::splat(0.5) }), blend(0.3)];
    for d in DISTRIBUTIONS {
        for a in [0.01, 0.05, 0.3, 0.8] {
            bsdfs.push(conductor(d, a));
            bsdfs.push(Bsdf::leaf(Leaf::RoughDielectric(glass(d, a))));
            bsdfs.push(Bsdf::leaf(Leaf::RoughPlastic(plastic(d, a, a > 0.1))));
        }
    }
    for (k, b) in bsdfs.iter().enumerate() {
        for cos_i in [1.0, 0.7, 0.2, 0.05, -0.3, -0.9] {
            let wi = incident(cos_i);
            for i in 0..2000 {
                let u = uniforms(900 + k as u32, i);
                if let Some(s) = bsdf_sample_diff(b, false, wi, u[0], u[1], Vec2::new(u[2], u[3])) {
                    assert!(s.wo.is_finite() && (s.wo.length() - 1.0).abs() < 1e-4, "{b:?}: wo {:?}", s.wo);
                    assert_eq!(s.pdf, bsdf_pdf_diff(b, false, wi, s.wo));
                    assert_eq!(s.value, bsdf_eval(b, wi, s.wo));
                    assert!(s.pdf > 0.0 && s.pdf.is_finite() && s.value.is_finite());
                    if let Leaf::RoughConductor { distribution, alpha, .. } = b.leaves[0]
                        && !b.blend
                    {
                        let parts = 0.5
                            * (diff_pdf_part(distribution, alpha, true, wi, s.wo)
                                + diff_pdf_part(distribution, alpha, false, wi, s.wo));
                        assert!((parts - s.pdf).abs() <= 1e-5 * s.pdf, "{b:?}: ½(p⁺ + p⁻) = {parts} vs {}", s.pdf);
                    }
                    if let Leaf::RoughPlastic(ref p) = b.leaves[0] {
                        let parts = 0.5
                            * (diff_pdf_plastic_part(p, true, wi, s.wo) + diff_pdf_plastic_part(p, false, wi, s.wo));
                        assert!((parts - s.pdf).abs() <= 1e-5 * s.pdf, "{b:?}: ½(p⁺ + p⁻) = {parts} vs {}", s.pdf);
                    }
                    if let Leaf::RoughDielectric(ref d) = b.leaves[0] {
                        let parts = 0.5
                            * (diff_pdf_dielectric_part(d, false, true, wi, s.wo)
                                + diff_pdf_dielectric_part(d, false, false, wi, s.wo));
                        assert!((parts - s.pdf).abs() <= 1e-5 * s.pdf, "{b:?}: ½(p⁺ + p⁻) = {parts} vs {}", s.pdf);
                    }
                }
            }
        }
    }
}

/// Every density is finite at h = z, at grazing incidence, and at the ends u_b → 0, 1 of every
/// inversion; samplers return a finite direction or `None`.
#[test]
fn edges_are_finite() {
    let z = Vec3::Z;
    let us = [0.0, f32::MIN_POSITIVE, 1e-7, 0.5 / 16_777_216.0, 0.5, 1.0 - 1.0 / 16_777_216.0, 1.0 - 1e-7, 1.0];
    for d in DISTRIBUTIONS {
        for alpha in [1e-3, 0.01, 0.05, 0.3, 0.8, 1.0] {
            for h in [z, Vec3::new(1.0, 0.0, 0.0), Vec3::new(1.0, 0.0, 1e-10).normalize(), Vec3::new(0.6, 0.0, 0.8)] {
                let p = diff_pdf_abs_h(d, alpha, h);
                assert!(p.is_finite() && p >= 0.0, "{d:?} α {alpha} h {h}: {p}");
                for positive in [false, true] {
                    let q = diff_pdf_part_h(d, alpha, h, positive);
                    assert!(q.is_finite() && q >= 0.0, "{d:?} α {alpha} h {h}: {q}");
                }
            }
            let p = diff_pdf(d, alpha, z, z);
            assert!(p.is_finite() && p > 0.0, "{d:?} α {alpha}: pdf at normal incidence {p}");
            for cos_i in [1.0, 0.05, 1e-4, 1e-7] {
                let wi = incident(cos_i);
                for positive in [false, true] {
                    for &ub in &us {
                        let x = diff_sample_x(d, positive, ub);
                        assert!(!x.is_nan() && x >= 0.0, "{d:?} {positive} u_b {ub}: x {x}");
                        for ua in [0.0, 0.3, 1.0] {
                            if let Some(wo) = sample_diff_part(d, alpha, wi, positive, Vec2::new(ua, ub)) {
                                assert!(wo.is_finite() && wo.z > 0.0, "{d:?} α {alpha} u_b {ub}: wo {wo}");
                                for p in [diff_pdf(d, alpha, wi, wo), diff_pdf_part(d, alpha, positive, wi, wo)] {
                                    assert!(p.is_finite() && p >= 0.0, "{d:?} α {alpha} u_b {ub}: pdf {p}");
                                }
                                let b = conductor(d, alpha);
                                let s = bsdf_sample_diff(
                                    &b,
                                    false,
                                    wi,
                                    if positive { 0.0 } else { 1.0 },
                                    0.0,
                                    Vec2::new(ua, ub),
                                );
                                if let Some(s) = s {
                                    assert!(s.pdf.is_finite() && s.value.is_finite());
                                }
                            }
                        }
                    }
                }
            }
        }
    }
}

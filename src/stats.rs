//! Statistical tests: chi-square goodness of fit of direction samplers against their densities
//! and of discrete samplers against their probabilities, and the special functions they need.
//!
//! The harness bins sampled directions on the sphere over (cos θ, φ) — cells of equal solid angle —
//! integrates the density over each cell with adaptive Simpson quadrature, adds one cell for invalid
//! samples (expected mass 1 − ∫p), pools cells expecting fewer than 5 samples, and converts the
//! statistic into a p-value with the regularised incomplete gamma function.

use std::f64::consts::PI;
use std::fmt::Write as _;

use glam::Vec3;

/// Cells expecting fewer samples than this are pooled into one (the chi-square approximation needs
/// about 5 per cell).
pub const MIN_EXPECTED: f64 = 5.0;

/// Discrete probabilities that sum to 1 in exact arithmetic may fall short by this much after f64
/// summation; a shortfall below it is not a cell of its own.
const MASS_ROUNDING: f64 = 1e-12;

/// Settings of one chi-square test.
#[derive(Clone, Copy, Debug)]
pub struct Chi2Config {
    /// Bins over cos θ ∈ [−1, 1].
    pub cos_bins: usize,
    /// Bins over φ ∈ [0, 2π).
    pub phi_bins: usize,
    /// Number of samples drawn.
    pub samples: usize,
    /// Reject when the p-value is below this (already corrected for multiple tests).
    pub significance: f64,
}

/// The outcome of a chi-square test.
#[derive(Clone, Debug)]
pub struct Chi2Result {
    /// The chi-square statistic.
    pub statistic: f64,
    /// Degrees of freedom after pooling.
    pub dof: usize,
    /// Probability of a statistic at least this large if the sampler follows the density.
    pub p_value: f64,
    /// Total density mass found by integration (≤ 1; the rest is expected as invalid samples).
    pub integrated_mass: f64,
    /// A table of observed and expected counts, for failure reports.
    pub table: String,
}

impl Chi2Result {
    /// Whether the test passed at `significance`.
    pub fn passed(&self, significance: f64) -> bool {
        self.p_value >= significance
    }
}

/// Per-test significance that keeps the family-wise false-alarm rate at `alpha` over `tests`
/// independent tests (Šidák correction).
pub fn sidak(alpha: f64, tests: usize) -> f64 {
    1.0 - (1.0 - alpha).powf(1.0 / tests as f64)
}

/// ln Γ(x) for x > 0 (Lanczos approximation, g = 7, 9 terms; relative error ~1e-15).
pub fn ln_gamma(x: f64) -> f64 {
    const C: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    if x < 0.5 {
        return (PI / (PI * x).sin()).ln() - ln_gamma(1.0 - x);
    }
    let x = x - 1.0;
    let mut a = C[0];
    let t = x + 7.5;
    for (i, c) in C.iter().enumerate().skip(1) {
        a += c / (x + i as f64);
    }
    0.5 * (2.0 * PI).ln() + (x + 0.5) * t.ln() - t + a.ln()
}

/// The regularised upper incomplete gamma function Q(a, x) = Γ(a, x) / Γ(a): a series for
/// x < a + 1, a continued fraction (modified Lentz) otherwise.
pub fn gamma_q(a: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 1.0;
    }
    let ln_prefix = a * x.ln() - x - ln_gamma(a);
    if x < a + 1.0 {
        let (mut sum, mut term, mut n) = (1.0 / a, 1.0 / a, a);
        for _ in 0..10_000 {
            n += 1.0;
            term *= x / n;
            sum += term;
            if term.abs() < sum.abs() * 1e-16 {
                break;
            }
        }
        1.0 - sum * ln_prefix.exp()
    } else {
        let tiny = 1e-300;
        let mut b = x + 1.0 - a;
        let mut c = 1.0 / tiny;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..10_000 {
            let an = -(i as f64) * (i as f64 - a);
            b += 2.0;
            d = an * d + b;
            if d.abs() < tiny {
                d = tiny;
            }
            c = b + an / c;
            if c.abs() < tiny {
                c = tiny;
            }
            d = 1.0 / d;
            let delta = d * c;
            h *= delta;
            if (delta - 1.0).abs() < 1e-16 {
                break;
            }
        }
        ln_prefix.exp() * h
    }
}

/// The regularised incomplete beta function I_x(a, b) (continued fraction, modified Lentz, on
/// the side of x where it converges fast).
pub fn beta_i(a: f64, b: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 0.0;
    }
    if x >= 1.0 {
        return 1.0;
    }
    let ln_front = ln_gamma(a + b) - ln_gamma(a) - ln_gamma(b) + a * x.ln() + b * (1.0 - x).ln();
    if x > (a + 1.0) / (a + b + 2.0) {
        return 1.0 - beta_i(b, a, 1.0 - x);
    }
    let tiny = 1e-300;
    let clamp = |v: f64| if v.abs() < tiny { tiny } else { v };
    let mut c = 1.0;
    let mut d = 1.0 / clamp(1.0 - (a + b) * x / (a + 1.0));
    let mut h = d;
    for m in 1..10_000 {
        let m = f64::from(m);
        let even = m * (b - m) * x / ((a + 2.0 * m - 1.0) * (a + 2.0 * m));
        d = 1.0 / clamp(1.0 + even * d);
        c = clamp(1.0 + even / c);
        h *= d * c;
        let odd = -(a + m) * (a + b + m) * x / ((a + 2.0 * m) * (a + 2.0 * m + 1.0));
        d = 1.0 / clamp(1.0 + odd * d);
        c = clamp(1.0 + odd / c);
        let delta = d * c;
        h *= delta;
        if (delta - 1.0).abs() < 1e-15 {
            break;
        }
    }
    ln_front.exp() * h / a
}

/// P(|T| ≥ t) for Student's t with `dof` degrees of freedom (real, > 0): I_{ν/(ν+t²)}(ν/2, 1/2).
pub fn student_t_two_sided(t: f64, dof: f64) -> f64 {
    beta_i(0.5 * dof, 0.5, dof / (dof + t * t))
}

fn direction(cos_theta: f64, phi: f64) -> Vec3 {
    let sin = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
    Vec3::new((sin * phi.cos()) as f32, (sin * phi.sin()) as f32, cos_theta as f32)
}

/// ∫∫ f over [x0, x1] × [y0, y1] by 2-D Simpson on a 3×3 grid.
fn simpson_cell(f: &dyn Fn(f64, f64) -> f64, x0: f64, x1: f64, y0: f64, y1: f64) -> f64 {
    // Written out rather than as loops over the weights: debug builds call core's iterators out of
    // line, which cost the chi-square tests a tenth of their time (see `rng::philox4x32_10`).
    let (xs, ys) = ([x0, x0 + (x1 - x0) * 0.5, x0 + (x1 - x0)], [y0, y0 + (y1 - y0) * 0.5, y0 + (y1 - y0)]);
    // Summed row-major, left to right, term by term.
    let row = |s: f64, x: f64, wi: f64| s + wi * f(x, ys[0]) + wi * 4.0 * f(x, ys[1]) + wi * f(x, ys[2]);
    let s = row(row(row(0.0, xs[0], 1.0), xs[1], 4.0), xs[2], 1.0);
    s * (x1 - x0) * (y1 - y0) / 36.0
}

/// Adaptive 2-D Simpson: splits into quarters until the estimate stops changing.
fn integrate(f: &dyn Fn(f64, f64) -> f64, cell: [f64; 4], whole: f64, tol: f64, depth: u32) -> f64 {
    let [x0, x1, y0, y1] = cell;
    let (xm, ym) = (0.5 * (x0 + x1), 0.5 * (y0 + y1));
    let quarters = [
        simpson_cell(f, x0, xm, y0, ym),
        simpson_cell(f, xm, x1, y0, ym),
        simpson_cell(f, x0, xm, ym, y1),
        simpson_cell(f, xm, x1, ym, y1),
    ];
    let sum: f64 = quarters.iter().sum();
    if depth == 0 || (sum - whole).abs() <= 15.0 * tol {
        return sum + (sum - whole) / 15.0;
    }
    let boxes = [(x0, xm, y0, ym), (xm, x1, y0, ym), (x0, xm, ym, y1), (xm, x1, ym, y1)];
    boxes.iter().zip(quarters).map(|(&(a, b, c, d), q)| integrate(f, [a, b, c, d], q, tol * 0.25, depth - 1)).sum()
}

/// Chi-square test of a direction sampler against its solid-angle density.
///
/// `sample(i)` returns the i-th sampled direction (unit) or `None` for an invalid sample; `pdf(v)`
/// is the density the sampler claims.
///
/// ```
/// use pathgrad::stats::{chi2_directions, Chi2Config};
/// use glam::{Vec2, Vec3};
/// let cfg = Chi2Config { cos_bins: 10, phi_bins: 20, samples: 100_000, significance: 0.01 };
/// let u = |i: usize| Vec2::new(((i * 7919) % 1000) as f32 / 1000.0 + 5e-4, ((i * 104_729) % 997) as f32 / 997.0 + 5e-4);
/// let r = chi2_directions(&cfg, |i| Some(pathgrad::sampling::sample_cosine_hemisphere(u(i))),
///     |v| pathgrad::sampling::cosine_hemisphere_pdf(v) as f64);
/// assert!(r.integrated_mass > 0.999);
/// ```
pub fn chi2_directions(
    cfg: &Chi2Config,
    sample: impl Fn(usize) -> Option<Vec3> + Sync,
    pdf: impl Fn(Vec3) -> f64 + Sync,
) -> Chi2Result {
    use rayon::prelude::*;
    let cells = cfg.cos_bins * cfg.phi_bins;
    let observed: Vec<u64> = (0..cfg.samples)
        .into_par_iter()
        .fold(
            || vec![0u64; cells + 1],
            |mut hist, i| {
                let idx = match sample(i) {
                    Some(v) if v.is_finite() => {
                        let c = f64::from(v.z).clamp(-1.0, 1.0);
                        let mut phi = f64::from(v.y).atan2(f64::from(v.x));
                        if phi < 0.0 {
                            phi += 2.0 * PI;
                        }
                        let ci = (((c + 1.0) * 0.5 * cfg.cos_bins as f64) as usize).min(cfg.cos_bins - 1);
                        let pi = ((phi / (2.0 * PI) * cfg.phi_bins as f64) as usize).min(cfg.phi_bins - 1);
                        ci * cfg.phi_bins + pi
                    }
                    _ => cells,
                };
                hist[idx] += 1;
                hist
            },
        )
        .reduce(|| vec![0u64; cells + 1], |a, b| a.iter().zip(&b).map(|(x, y)| x + y).collect());
    let density = |c: f64, phi: f64| pdf(direction(c, phi));
    let mut expected: Vec<f64> = (0..cells)
        .into_par_iter()
        .map(|cell| {
            let (ci, pi) = (cell / cfg.phi_bins, cell % cfg.phi_bins);
            let (c0, c1) =
                (-1.0 + 2.0 * ci as f64 / cfg.cos_bins as f64, -1.0 + 2.0 * (ci + 1) as f64 / cfg.cos_bins as f64);
            let (p0, p1) =
                (2.0 * PI * pi as f64 / cfg.phi_bins as f64, 2.0 * PI * (pi + 1) as f64 / cfg.phi_bins as f64);
            let whole = simpson_cell(&density, c0, c1, p0, p1);
            integrate(&density, [c0, c1, p0, p1], whole, 1e-7, 10).max(0.0)
        })
        .collect();
    let integrated_mass: f64 = expected.iter().sum();
    expected.push((1.0 - integrated_mass).max(0.0));
    let n = cfg.samples as f64;
    let (mut statistic, mut dof) = (0.0, 0usize);
    let (mut pooled_obs, mut pooled_exp) = (0.0, 0.0);
    let mut table = String::new();
    for (i, (&o, &e)) in observed.iter().zip(&expected).enumerate() {
        let (o, e) = (o as f64, e * n);
        if i % cfg.phi_bins == 0 {
            table.push('\n');
        }
        let _ = write!(table, "{o:.0}/{e:.1} ");
        if e < MIN_EXPECTED {
            pooled_obs += o;
            pooled_exp += e;
        } else {
            statistic += (o - e) * (o - e) / e;
            dof += 1;
        }
    }
    if pooled_exp > 0.0 || pooled_obs > 0.0 {
        // A pooled cell that expects nothing but received samples is an outright failure.
        statistic += if pooled_exp > 0.0 { (pooled_obs - pooled_exp).powi(2) / pooled_exp } else { f64::INFINITY };
        dof += 1;
    }
    let dof = dof.saturating_sub(1).max(1);
    let p_value = if statistic.is_finite() { gamma_q(dof as f64 * 0.5, statistic * 0.5) } else { 0.0 };
    Chi2Result { statistic, dof, p_value, integrated_mass, table }
}

/// Chi-square test of counts `observed[i]` of a discrete sampler against the probabilities
/// `expected[i]` it claims (summing to at most 1; the rest is expected nowhere, so a shortfall shows
/// as missing counts). Cells expecting fewer than [`MIN_EXPECTED`] samples are pooled; a pooled
/// cell that expects nothing but received samples fails outright. `integrated_mass` is Σ expected.
///
/// ```
/// use pathgrad::stats::chi2_discrete;
/// let r = chi2_discrete(&[260, 240, 500], &[0.25, 0.25, 0.5]);
/// assert!(r.passed(0.01) && r.dof == 2);
/// assert!(!chi2_discrete(&[400, 100, 500], &[0.25, 0.25, 0.5]).passed(0.01));
/// ```
///
/// # Panics
/// If the slices differ in length (a caller's invariant).
pub fn chi2_discrete(observed: &[u64], expected: &[f64]) -> Chi2Result {
    assert_eq!(observed.len(), expected.len(), "one expected probability per observed count");
    let n: f64 = observed.iter().map(|&o| o as f64).sum();
    let integrated_mass: f64 = expected.iter().sum();
    let (mut statistic, mut dof) = (0.0, 0usize);
    let (mut pooled_obs, mut pooled_exp) = (0.0, 0.0);
    let mut table = String::new();
    for (i, (&o, &p)) in observed.iter().zip(expected).enumerate() {
        let (o, e) = (o as f64, p * n);
        if i % 16 == 0 {
            table.push('\n');
        }
        let _ = write!(table, "{o:.0}/{e:.1} ");
        if e < MIN_EXPECTED {
            pooled_obs += o;
            pooled_exp += e;
        } else {
            statistic += (o - e) * (o - e) / e;
            dof += 1;
        }
    }
    // Whatever the probabilities leave out is expected nowhere: pool it (beyond f64 summation
    // rounding of probabilities that add up to 1).
    if integrated_mass < 1.0 - MASS_ROUNDING {
        pooled_exp += (1.0 - integrated_mass) * n;
    }
    if pooled_exp > 0.0 || pooled_obs > 0.0 {
        statistic += if pooled_exp > 0.0 { (pooled_obs - pooled_exp).powi(2) / pooled_exp } else { f64::INFINITY };
        dof += 1;
    }
    let dof = dof.saturating_sub(1).max(1);
    let p_value = if statistic.is_finite() { gamma_q(dof as f64 * 0.5, statistic * 0.5) } else { 0.0 };
    Chi2Result { statistic, dof, p_value, integrated_mass, table }
}

/// Writes a failed test's table under `target/chi2/{name}.txt` and returns the path.
pub fn dump_table(name: &str, result: &Chi2Result) -> std::path::PathBuf {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("target").join("chi2");
    let _ = std::fs::create_dir_all(&dir);
    let path = dir.join(format!("{name}.txt"));
    let _ = std::fs::write(
        &path,
        format!(
            "statistic {} dof {} p {} mass {}\nobserved/expected per cell (rows: cos θ from −1; last: invalid){}\n",
            result.statistic, result.dof, result.p_value, result.integrated_mass, result.table
        ),
    );
    path
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gamma_q_matches_known_values() {
        // Q(1, x) = e^{-x}; chi-square with 2 dof at statistic 2x.
        for x in [0.1, 1.0, 5.0, 20.0] {
            assert!((gamma_q(1.0, x) - (-x).exp()).abs() < 1e-12);
        }
        // chi-square 0.95 quantiles: dof 10 → 18.307, dof 100 → 124.342.
        assert!((gamma_q(5.0, 18.307 / 2.0) - 0.05).abs() < 1e-4);
        assert!((gamma_q(50.0, 124.342 / 2.0) - 0.05).abs() < 1e-4);
        assert!((ln_gamma(5.0) - 24f64.ln()).abs() < 1e-12);
    }

    #[test]
    fn student_t_matches_closed_forms() {
        // ν = 1 (Cauchy): 1 − 2/π atan t; ν = 2: 1 − t/√(2 + t²); large ν: the normal, 2 Q(1/2, t²/2)/2.
        for t in [0.0, 0.3, 1.0, 2.5, 10.0, 300.0] {
            let cauchy = 1.0 - 2.0 / PI * f64::atan(t);
            assert!((student_t_two_sided(t, 1.0) - cauchy).abs() < 1e-12 * cauchy.max(1e-3), "t {t}");
            let two = 1.0 - t / (2.0 + t * t).sqrt();
            assert!((student_t_two_sided(t, 2.0) - two).abs() < 1e-10 * two.max(1e-3), "t {t}");
        }
        let normal = gamma_q(0.5, 0.5 * 4.0 * 4.0);
        assert!((student_t_two_sided(4.0, 1e7) / normal - 1.0).abs() < 1e-4);
        // The 0.975 quantile of t with 7 dof is 2.364624.
        assert!((student_t_two_sided(2.364_624, 7.0) - 0.05).abs() < 1e-6);
    }

    /// The harness has power: a cosine-weighted sampler tested against the uniform-hemisphere
    /// density, or with a tenth of its samples declared invalid, must fail.
    #[test]
    fn chi2_rejects_a_wrong_density_or_missing_mass() {
        use crate::rng::{PassTag, RngKey, Stream, uniform4};
        use crate::sampling::{cosine_hemisphere_pdf, sample_cosine_hemisphere};
        let cfg = Chi2Config { cos_bins: 16, phi_bins: 32, samples: 200_000, significance: 0.01 };
        let u = |i: usize| {
            let r = uniform4(RngKey::new(9, 0, PassTag::Test), i as u32, 0, 0, Stream::Main, 0, 0);
            (r[0], glam::Vec2::new(r[1], r[2]))
        };
        let right =
            chi2_directions(&cfg, |i| Some(sample_cosine_hemisphere(u(i).1)), |v| f64::from(cosine_hemisphere_pdf(v)));
        assert!(right.passed(cfg.significance), "p = {}", right.p_value);
        let uniform = |v: Vec3| if v.z > 0.0 { 0.5 / PI } else { 0.0 };
        let wrong = chi2_directions(&cfg, |i| Some(sample_cosine_hemisphere(u(i).1)), uniform);
        assert!(!wrong.passed(cfg.significance), "p = {}", wrong.p_value);
        let lossy = chi2_directions(
            &cfg,
            |i| {
                let (a, b) = u(i);
                (a > 0.1).then(|| sample_cosine_hemisphere(b))
            },
            |v| f64::from(cosine_hemisphere_pdf(v)),
        );
        assert!(!lossy.passed(cfg.significance), "p = {}", lossy.p_value);
    }
}

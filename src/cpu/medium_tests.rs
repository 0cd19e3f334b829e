//! Tests of the phase function's differential sampler (ALGORITHMS.md §8.4): the mass of ∂p/∂g's
//! signed parts, and a chi-square test of each part's sampler and of the coin-mixed technique.

use glam::Vec3;

use super::*;
use crate::rng::{PassTag, RngKey, Stream, uniform4};
use crate::stats::{Chi2Config, chi2_directions, dump_table, sidak};

/// g values: both signs, isotropic, strongly forward (a part crowded near μ = 1).
const GS: [f32; 6] = [-0.7, -0.2, 0.0, 0.3, 0.8, 0.95];
/// Per g: the positive part, the negative part, the coin-mixed technique.
const CHI2_TESTS: usize = GS.len() * 3;
const FAMILY_ALPHA: f64 = 0.01;
const CHI2_SAMPLES: usize = 250_000;

fn uniforms(test: u32, i: usize) -> [f32; 4] {
    uniform4(RngKey::new(test, 0, PassTag::Test), i as u32, 0, 1, Stream::Main, 1, 0)
}

/// A direction about +z with cos θ = `mu` and azimuth 2π`u`.
fn about_z(mu: f32, u: f32) -> Vec3 {
    let sin = (1.0 - mu * mu).max(0.0).sqrt();
    let phi = 2.0 * std::f32::consts::PI * u;
    Vec3::new(sin * phi.cos(), sin * phi.sin(), mu)
}

/// ∫ of ±∂p/∂g over the sphere in f64 (midpoint rule in μ, 2π in φ): the masses of both parts.
fn masses_f64(g: f64) -> (f64, f64) {
    let n = 400_000;
    let (mut pos, mut neg) = (0.0, 0.0);
    for i in 0..n {
        let mu = -1.0 + 2.0 * (f64::from(i) + 0.5) / f64::from(n);
        let delta = 1.0 + g * g - 2.0 * g * mu;
        let v = ((g * g + 3.0) * mu + g * g * g - 5.0 * g) / (4.0 * std::f64::consts::PI * delta.powf(2.5));
        let w = v * 2.0 * std::f64::consts::PI * 2.0 / f64::from(n);
        if v > 0.0 { pos += w } else { neg -= w }
    }
    (pos, neg)
}

/// Each signed part holds M(g), the closed form, to 1e-4 relative (f32 against f64 quadrature).
#[test]
fn signed_parts_hold_the_closed_form_mass() {
    for g in GS {
        let (pos, neg) = masses_f64(f64::from(g));
        let m = f64::from(hg_dg_mass(g));
        assert!((pos - m).abs() <= 1e-4 * m && (neg - m).abs() <= 1e-4 * m, "g = {g}: +{pos} −{neg} vs M = {m}");
    }
}

/// ∂p/∂g is the derivative of the phase function: central differences of its value.
#[test]
fn hg_dg_is_the_derivative_of_the_phase_function() {
    let p = |g: f64, mu: f64| (1.0 - g * g) / (4.0 * std::f64::consts::PI * (1.0 + g * g - 2.0 * g * mu).powf(1.5));
    for g in GS {
        for mu in [-0.9f32, -0.3, 0.0, 0.4, 0.97] {
            let h = 1e-5;
            let fd = (p(f64::from(g) + h, f64::from(mu)) - p(f64::from(g) - h, f64::from(mu))) / (2.0 * h);
            let v = f64::from(hg_dg(g, mu));
            assert!((v - fd).abs() <= 1e-4 * fd.abs().max(1e-2), "g = {g}, μ = {mu}: {v} vs {fd}");
        }
    }
}

fn check(name: &str, sample: impl Fn(usize) -> Option<Vec3> + Sync, pdf: impl Fn(Vec3) -> f64 + Sync) {
    let cfg =
        Chi2Config { cos_bins: 32, phi_bins: 16, samples: CHI2_SAMPLES, significance: sidak(FAMILY_ALPHA, CHI2_TESTS) };
    let r = chi2_directions(&cfg, sample, pdf);
    assert!(r.integrated_mass > 0.999, "{name}: the density integrates to {}", r.integrated_mass);
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

/// Each signed part's sampler draws |∂p/∂g|/M on its support, and the coin between them
/// |∂p/∂g|/(2M), for g of both signs and g = 0.
#[test]
fn chi2_phase_function_differential_parts() {
    let mut test = 900;
    for g in GS {
        for positive in [true, false] {
            test += 1;
            check(
                &format!("hg-diff-g{g}-{}", if positive { "pos" } else { "neg" }),
                |i| {
                    let u = uniforms(test, i);
                    Some(about_z(hg_diff_sample_cos(g, positive, u[0], u[1]), u[2]))
                },
                |v| f64::from(phase_pdf_diff_part(g, positive, v.z)),
            );
        }
        test += 1;
        check(
            &format!("hg-diff-g{g}-mixed"),
            |i| {
                let u = uniforms(test, i);
                Some(about_z(hg_diff_sample_cos(g, u[3] < 0.5, u[0], u[1]), u[2]))
            },
            |v| f64::from(hg_dg(g, v.z).abs() / (2.0 * hg_dg_mass(g))),
        );
    }
}

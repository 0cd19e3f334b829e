//! Tests of the hair BSDF: values, densities and derivatives against Mitsuba 3.9.1's own,
//! chi-square of its sampler against its density (and the density's 5 % sensitivity), energy
//! conservation of a fibre that absorbs nothing, and its sampler's albedo against Mitsuba's
//! integral of its value.

use glam::{Vec2, Vec3};

use super::*;
use crate::bsdf::tests::json_vec3s;
use crate::rng::{PassTag, RngKey, Stream, uniform4};
use crate::stats::{Chi2Config, chi2_directions, dump_table, sidak};

/// Chi-square tests in this file (parameter sets × incidences), for the Šidák correction.
const CHI2_TESTS: usize = 5 * 3;

fn uniforms(test: u32, i: usize) -> (f32, Vec2) {
    let u = uniform4(RngKey::new(3100 + test, 0, PassTag::Test), i as u32, 0, 1, Stream::Main, 1, 0);
    (u[0], Vec2::new(u[1], u[2]))
}

/// An incidence with sin θ = `sin_theta` along the fibre (y), off the normal around it.
fn incident(sin_theta: f32) -> Vec3 {
    let cos = circ(sin_theta);
    Vec3::new(cos * 0.6, sin_theta, cos * 0.8)
}

fn json() -> serde_json::Value {
    serde_json::from_str(include_str!("../../../tests/data/hair/mitsuba_bsdf.json")).unwrap()
}

/// The leaf of Mitsuba's properties (as `tests/data/hair/mitsuba_bsdf.py` writes them), and the
/// factor `scale` of `sigma_a`.
fn leaf_from_props(props: &serde_json::Value) -> (HairLeaf, f32) {
    let get = |k: &str, default: f32| props.get(k).and_then(serde_json::Value::as_f64).map_or(default, |v| v as f32);
    let scale = get("scale", 1.0);
    let sigma_a = match props.get("sigma_a") {
        Some(v) => {
            let a: Vec<f32> = v.as_array().unwrap().iter().map(|x| x.as_f64().unwrap() as f32).collect();
            scale * Vec3::new(a[0], a[1], a[2])
        }
        None => pigment_sigma_a(get("eumelanin", 1.3), get("pheomelanin", 0.2)),
    };
    let leaf = HairLeaf {
        sigma_a,
        eta: get("int_ior", 1.55) / 1.000_277,
        longitudinal_roughness: get("longitudinal_roughness", 0.3),
        azimuthal_roughness: get("azimuthal_roughness", 0.3),
        scale_tilt: get("scale_tilt", 2.0),
    };
    (leaf, scale)
}

/// The cases of the JSON as leaves: (name, leaf).
pub(crate) fn cases() -> Vec<(String, HairLeaf)> {
    json()["cases"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| (c["name"].as_str().unwrap().to_owned(), leaf_from_props(&c["props"]).0))
        .collect()
}

/// Values, densities and the derivatives by every parameter against Mitsuba 3.9.1's hair at 256
/// direction pairs (a quarter near the specular cone) for five parameter sets.
#[test]
fn hair_matches_mitsuba() {
    let data = json();
    let (wis, wos) = (json_vec3s(&data["pairs"]["wi"]), json_vec3s(&data["pairs"]["wo"]));
    let channels = |v: &serde_json::Value, i: usize| {
        Vec3::new(v[0][i].as_f64().unwrap() as f32, v[1][i].as_f64().unwrap() as f32, v[2][i].as_f64().unwrap() as f32)
    };
    let near = |a: f32, b: f32, scale: f32| (a - b).abs() <= 2e-3 * a.abs().max(b.abs()) + 1e-5 * scale;
    let (mut compared, mut nonzero, mut values) = (0, 0, 0);
    for case in data["cases"].as_array().unwrap() {
        let name = case["name"].as_str().unwrap();
        let (leaf, scale) = leaf_from_props(&case["props"]);
        for (i, (&wi, &wo)) in wis.iter().zip(&wos).enumerate() {
            let (value, g) = leaf.eval_grad(wi, wo);
            let expected = channels(&case["value"], i);
            let top = expected.max_element().max(1.0);
            values += usize::from(expected.max_element() > 1e-3);
            for c in 0..3 {
                assert!(
                    near(value[c], expected[c], top),
                    "{name} pair {i}: f̂_{c} = {} against Mitsuba's {}",
                    value[c],
                    expected[c]
                );
            }
            let pdf = case["pdf"][i].as_f64().unwrap() as f32;
            assert!(
                near(leaf.pdf(wi, wo), pdf, pdf.max(1.0)),
                "{name} pair {i}: pdf {} against Mitsuba's {pdf}",
                leaf.pdf(wi, wo)
            );
            let grads = case["grad"].as_object().unwrap();
            for (param, theirs) in grads {
                let ours = match param.as_str() {
                    "eumelanin" => g.sigma_a * EUMELANIN_SIGMA_A,
                    "pheomelanin" => g.sigma_a * PHEOMELANIN_SIGMA_A,
                    "longitudinal_roughness" => g.longitudinal_roughness,
                    "azimuthal_roughness" => g.azimuthal_roughness,
                    "scale_tilt" => g.scale_tilt,
                    s => {
                        let k: usize = s["sigma_a".len()..].parse().unwrap();
                        let mut v = Vec3::ZERO;
                        v[k] = scale * g.sigma_a[k];
                        v
                    }
                };
                let theirs = channels(theirs, i);
                let gscale = top * 10.0;
                for c in 0..3 {
                    compared += 1;
                    nonzero += usize::from(theirs[c].abs() > 1e-4);
                    assert!(
                        near(ours[c], theirs[c], gscale),
                        "{name} pair {i} (wi {wi}, wo {wo}): ∂f̂_{c}/∂{param} = {} against Mitsuba's {}",
                        ours[c],
                        theirs[c]
                    );
                }
            }
        }
    }
    assert!(values > 5 * 256 / 4, "only {values} of the values are above 1e-3");
    assert!(nonzero > compared / 4, "{nonzero} of {compared} of Mitsuba's derivatives above 1e-4");
}

/// ln I₀(x) in f64 to ~1e-8: the series scaled by e^(−x) up to 50, the asymptotic series beyond.
fn log_i0_exact(x: f64) -> f64 {
    if x > 50.0 {
        let r = 1.0 / x;
        return x - 0.5 * (std::f64::consts::TAU * x).ln()
            + (1.0 + r / 8.0 + 9.0 * r * r / 128.0 + 225.0 * r * r * r / 3072.0).ln();
    }
    let (mut term, mut sum) = ((-x).exp(), 0.0);
    for i in 1..400 {
        sum += term;
        term *= x * x / 4.0 / f64::from(i * i);
    }
    x + sum.ln()
}

/// The exact density of the sampler: [`HairLeaf::pdf`] with d'Eon's longitudinal lobe evaluated
/// exactly (Mitsuba's, which `pdf` keeps, truncates I₀'s series at 11 terms and takes
/// 1/(16x) for the 1/(8x) of log I₀'s asymptote: its lobes integrate to 0.9966 at κ = 11.8 and
/// 0.9986 at κ = 47, which 10⁶ samples see).
fn sampler_density(leaf: &HairLeaf, wi: Vec3, wo: Vec3) -> f64 {
    let lobes = Lobes::new(leaf);
    let inc = Incidence::new(leaf, wi);
    let (sin_o, _, phi_o) = angles(wo);
    let delta_phi = phi_o - inc.phi_i;
    let mut pdf = 0.0f64;
    for p in 0..4 {
        let (sin_ip, _) = lobes.tilted(inc.sin_i, inc.cos_i, p);
        let (si, so) = (f64::from(sin_ip), f64::from(sin_o));
        let (ci, co) = ((1.0 - si * si).max(0.0).sqrt(), (1.0 - so * so).max(0.0).sqrt());
        let kappa = 1.0 / f64::from(lobes.v[p]);
        // κ/(2 sinh κ) = κ e^(−κ)/(1 − e^(−2κ)).
        let log_m =
            -si * so * kappa + log_i0_exact(ci * co * kappa) - kappa + (kappa / (1.0 - (-2.0 * kappa).exp())).ln();
        let m = log_m.exp() / std::f64::consts::TAU;
        let n = if p < 3 {
            std::f64::consts::TAU * f64::from(azimuthal(delta_phi, p, lobes.s, inc.gamma_i, inc.gamma_t).0)
        } else {
            1.0
        };
        pdf += m * n * f64::from(inc.a_pdf[p]);
    }
    pdf
}

#[test]
fn mitsubas_longitudinal_lobe_is_short_of_the_exact_one() {
    let mass = |kappa: f32, exact: bool| {
        let n = 20_000;
        (0..n)
            .map(|j| {
                let t = -0.5 * PI + (j as f32 + 0.5) * PI / n as f32;
                let so = t.sin();
                let m = if exact {
                    let (co, k) = (f64::from(t.cos()), f64::from(kappa));
                    (log_i0_exact(co * k) - k + (k / (1.0 - (-2.0 * k).exp())).ln()).exp()
                } else {
                    f64::from(longitudinal(0.0, so, 1.0 / kappa).0) * std::f64::consts::TAU
                };
                m * f64::from(t.cos()) * f64::from(PI) / n as f64
            })
            .sum::<f64>()
    };
    for kappa in [3.0, 11.8, 47.0, 1000.0] {
        assert!((mass(kappa, true) - 1.0).abs() < 1e-4, "exact lobe at κ {kappa}: {}", mass(kappa, true));
    }
    assert!((mass(11.8, false) - 0.9966).abs() < 5e-4, "Mitsuba's lobe at κ 11.8: {}", mass(11.8, false));
    assert!((mass(47.0, false) - 0.9986).abs() < 5e-4, "Mitsuba's lobe at κ 47: {}", mass(47.0, false));
}

fn chi2(leaf: &HairLeaf, test: u32, wi: Vec3, pdf_scale: impl Fn(Vec3) -> f64 + Sync) -> crate::stats::Chi2Result {
    let cfg = Chi2Config { cos_bins: 16, phi_bins: 32, samples: 1_000_000, significance: sidak(0.01, CHI2_TESTS) };
    chi2_directions(
        &cfg,
        |i| {
            let (ul, u) = uniforms(test, i);
            leaf.sample(wi, ul, u)
        },
        |wo| sampler_density(leaf, wi, wo) * pdf_scale(wo),
    )
}

/// The sampler follows its exact density ([`sampler_density`]): five parameter sets (down to
/// β_m = 0.08) at three incidences each, one of them along the fibre's other direction.
#[test]
fn chi2_hair() {
    let mut test = 0;
    let mut failed = Vec::new();
    for (name, leaf) in cases() {
        for sin_i in [0.0, 0.5, -0.8] {
            test += 1;
            let r = chi2(&leaf, test, incident(sin_i), |_| 1.0);
            eprintln!(
                "hair {name} sin θi {sin_i}: chi2 {:.1} with {} dof, p = {:.3e}, mass {:.4}",
                r.statistic, r.dof, r.p_value, r.integrated_mass
            );
            if !r.passed(sidak(0.01, CHI2_TESTS)) {
                let path = dump_table(&format!("hair-{name}-sin{sin_i}"), &r);
                failed.push(format!("{name} sin θi {sin_i}: p = {:.3e}; table in {}", r.p_value, path.display()));
            }
        }
    }
    assert!(failed.is_empty(), "{}", failed.join("\n"));
}

/// The chi-square test sees a 5 % error of the density toward one side of the fibre.
#[test]
fn chi2_hair_sees_a_five_percent_density_error() {
    let leaf = HairLeaf::default();
    let r = chi2(&leaf, 50, incident(0.3), |wo| if wo.y > 0.0 { 1.05 } else { 1.0 });
    assert!(!r.passed(sidak(0.01, CHI2_TESTS)), "p = {:.3e}: a 5 % error went unseen", r.p_value);
}

/// A fibre that absorbs nothing conserves energy: ∫ f̂ dω = 1 (uniform directions, 2^20 each,
/// within 4 standard errors), and then f̂ equals the density, so each sample weighs exactly 1.
#[test]
fn hair_without_absorption_conserves_energy() {
    for (t, (beta_m, beta_n, tilt)) in [(0.3, 0.3, 2.0), (0.1, 0.8, -3.0), (0.7, 0.2, 0.0)].into_iter().enumerate() {
        let leaf = HairLeaf {
            sigma_a: Vec3::ZERO,
            longitudinal_roughness: beta_m,
            azimuthal_roughness: beta_n,
            scale_tilt: tilt,
            ..HairLeaf::default()
        };
        for (j, sin_i) in [0.0f32, 0.6, -0.9].into_iter().enumerate() {
            let wi = incident(sin_i);
            let n = 1 << 20;
            let (mut sum, mut sum2) = (0.0f64, 0.0f64);
            for i in 0..n {
                let (_, u) = uniforms(60 + 10 * t as u32 + j as u32, i);
                let wo = crate::sampling::sample_uniform_sphere(u);
                let f = f64::from(leaf.eval(wi, wo).x) / f64::from(crate::sampling::UNIFORM_SPHERE_PDF);
                sum += f;
                sum2 += f * f;
            }
            let mean = sum / n as f64;
            let sigma = ((sum2 / n as f64 - mean * mean).max(0.0) / n as f64).sqrt();
            assert!(
                (mean - 1.0).abs() < 4.0 * sigma + 1e-3,
                "β ({beta_m}, {beta_n}), sin θi {sin_i}: ∫ f̂ = {mean} ± {sigma}"
            );
            for i in 0..1000 {
                let (ul, u) = uniforms(90, i);
                let Some(wo) = leaf.sample(wi, ul, u) else { continue };
                let (f, pdf) = (leaf.eval(wi, wo), leaf.pdf(wi, wo));
                assert!((f.x - pdf).abs() <= 1e-4 * pdf, "f̂ {f} against pdf {pdf}");
            }
        }
    }
}

/// The mean weight f̂/pdf of this sampler equals Mitsuba's integral of its value by uniform
/// directions (2^22, in the JSON) within 4.5 standard errors of the two, each channel.
#[test]
fn hair_albedo_matches_mitsubas_integral() {
    let data = json();
    for (t, case) in data["cases"].as_array().unwrap().iter().enumerate() {
        let name = case["name"].as_str().unwrap();
        let (leaf, _) = leaf_from_props(&case["props"]);
        for (j, a) in case["albedo"].as_array().unwrap().iter().enumerate() {
            let wi = json_vec3s(&serde_json::json!([a["wi"]]))[0];
            let n = 1 << 20;
            let (mut sum, mut sum2) = ([0.0f64; 3], [0.0f64; 3]);
            for i in 0..n {
                let (ul, u) = uniforms(200 + 10 * t as u32 + j as u32, i);
                let Some(wo) = leaf.sample(wi, ul, u) else { continue };
                let pdf = leaf.pdf(wi, wo);
                if !(pdf > 0.0) {
                    continue;
                }
                let w = leaf.eval(wi, wo) / pdf;
                for c in 0..3 {
                    sum[c] += f64::from(w[c]);
                    sum2[c] += f64::from(w[c]) * f64::from(w[c]);
                }
            }
            for c in 0..3 {
                let mean = sum[c] / n as f64;
                let sigma = ((sum2[c] / n as f64 - mean * mean).max(0.0) / n as f64).sqrt();
                let theirs = a["integral"][c].as_f64().unwrap();
                let their_sigma = a["integral_sigma"][c].as_f64().unwrap();
                let tol = 4.5 * (sigma * sigma + their_sigma * their_sigma).sqrt() + 1e-4;
                assert!(
                    (mean - theirs).abs() < tol,
                    "{name} wi {wi} channel {c}: {mean} ± {sigma} against Mitsuba's {theirs} ± {their_sigma}"
                );
            }
        }
    }
}

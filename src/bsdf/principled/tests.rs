//! Tests of the principled BSDF: chi-square of its sampler against its density, the density's
//! 5 % sensitivity, derivatives against finite differences, reciprocity of its reflection,
//! energy, and values, densities and derivatives against Mitsuba 3.9.1's own.

use glam::{Vec2, Vec3};

use super::*;
use crate::bsdf::tests::{json_vec3s, sphere_directions};
use crate::rng::{PassTag, RngKey, Stream, uniform4};
use crate::stats::{Chi2Config, chi2_directions, dump_table, sidak};

/// Chi-square tests in this file (parameter sets × incidences), for the Šidák correction.
const CHI2_TESTS: usize = 5 * 3 + 2 * 2;

fn uniforms(test: u32, i: usize) -> (f32, Vec2) {
    let u = uniform4(RngKey::new(1000 + test, 0, PassTag::Test), i as u32, 0, 1, Stream::Main, 1, 0);
    (u[0], Vec2::new(u[1], u[2]))
}

fn incident(cos_theta: f32) -> Vec3 {
    let sin = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
    Vec3::new(sin * 0.8, sin * 0.6, cos_theta)
}

/// Parameter sets that exercise every lobe: (name, leaf).
pub(crate) fn cases() -> Vec<(&'static str, PrincipledLeaf)> {
    let base = Vec3::new(0.8, 0.4, 0.2);
    vec![
        ("default", PrincipledLeaf::default()),
        (
            "general",
            PrincipledLeaf {
                base_color: base,
                roughness: 0.4,
                metallic: 0.3,
                spec_trans: 0.4,
                spec_tint: 0.5,
                sheen: 0.6,
                sheen_tint: 0.4,
                clearcoat: 0.7,
                clearcoat_gloss: 0.6,
                flatness: 0.3,
                ..PrincipledLeaf::default()
            },
        ),
        (
            "anisotropic-metal",
            PrincipledLeaf {
                base_color: base,
                roughness: 0.6,
                anisotropic: 0.8,
                metallic: 0.9,
                ..PrincipledLeaf::default()
            },
        ),
        (
            "glass",
            PrincipledLeaf {
                base_color: Vec3::new(0.9, 0.95, 1.0),
                roughness: 0.25,
                spec_trans: 1.0,
                eta: 1.33,
                ..PrincipledLeaf::default()
            },
        ),
        (
            "rated",
            PrincipledLeaf {
                base_color: base,
                roughness: 0.15,
                spec_trans: 0.5,
                clearcoat: 1.0,
                clearcoat_gloss: 0.2,
                anisotropic: 0.3,
                rates: Vec3::new(0.5, 2.0, 1.5),
                ..PrincipledLeaf::default()
            },
        ),
    ]
}

fn chi2(
    leaf: &PrincipledLeaf,
    test: u32,
    wi: Vec3,
    pdf_scale: impl Fn(Vec3) -> f64 + Sync,
) -> crate::stats::Chi2Result {
    let cfg = Chi2Config { cos_bins: 16, phi_bins: 32, samples: 1_000_000, significance: sidak(0.01, CHI2_TESTS) };
    chi2_directions(
        &cfg,
        |i| {
            let (ul, u) = uniforms(test, i);
            leaf.sample(wi, ul, u)
        },
        |wo| f64::from(leaf.pdf(wi, wo)) * pdf_scale(wo),
    )
}

fn significance() -> f64 {
    sidak(0.01, CHI2_TESTS)
}

fn check_chi2(name: &str, leaf: &PrincipledLeaf, test: u32, wi: Vec3) {
    let r = chi2(leaf, test, wi, |_| 1.0);
    if !r.passed(significance()) {
        let path = dump_table(name, &r);
        panic!("{name}: chi2 {} with {} dof, p = {:.3e}; table in {}", r.statistic, r.dof, r.p_value, path.display());
    }
}

#[test]
fn chi2_principled_from_outside() {
    let mut test = 0;
    for (name, leaf) in cases() {
        for cos_i in [0.9, 0.5, 0.1] {
            test += 1;
            check_chi2(&format!("principled-{name}-cos{cos_i}"), &leaf, test, incident(cos_i));
        }
    }
}

/// From inside only the transmitting parameter sets sample anything.
#[test]
fn chi2_principled_from_inside() {
    let mut test = 100;
    for (name, leaf) in cases().into_iter().filter(|(n, _)| *n == "general" || *n == "glass") {
        for cos_i in [-0.8, -0.3] {
            test += 1;
            check_chi2(&format!("principled-{name}-cos{cos_i}"), &leaf, test, incident(cos_i));
        }
    }
    // Nothing transmits: no sample and no density from inside.
    let opaque = PrincipledLeaf::default();
    let wi = incident(-0.5);
    assert!((0..1000).all(|i| opaque.sample(wi, uniforms(200, i).0, uniforms(200, i).1).is_none()));
    assert_eq!(opaque.pdf(wi, Vec3::new(0.1, 0.2, -0.97).normalize()), 0.0);
}

/// The chi-square test sees a 5 % error in the density of one lobe's region (the same sampler,
/// its density 5 % high toward the reflected hemisphere's top, or toward transmitted directions).
#[test]
fn chi2_principled_sees_a_five_percent_density_error() {
    let cases = cases();
    let general = &cases[1].1;
    let r = chi2(general, 301, incident(0.5), |wo| if wo.z > 0.7 { 1.05 } else { 1.0 });
    assert!(!r.passed(significance()), "p = {:.3e}: a 5 % error near the normal went unseen", r.p_value);
    let glass = &cases[3].1;
    let r = chi2(glass, 302, incident(0.5), |wo| if wo.z < 0.0 { 1.05 } else { 1.0 });
    assert!(!r.passed(significance()), "p = {:.3e}: a 5 % error in transmission went unseen", r.p_value);
}

/// A scalar parameter with a derivative: its name, reader, writer and field of the gradient.
type ScalarParam =
    (&'static str, fn(&PrincipledLeaf) -> f32, fn(&mut PrincipledLeaf, f32), fn(&PrincipledGrad) -> Vec3);

/// Every scalar parameter with a derivative.
fn scalar_params() -> Vec<ScalarParam> {
    vec![
        ("roughness", |l| l.roughness, |l, v| l.roughness = v, |g| g.roughness),
        ("anisotropic", |l| l.anisotropic, |l, v| l.anisotropic = v, |g| g.anisotropic),
        ("metallic", |l| l.metallic, |l, v| l.metallic = v, |g| g.metallic),
        ("spec_trans", |l| l.spec_trans, |l, v| l.spec_trans = v, |g| g.spec_trans),
        ("spec_tint", |l| l.spec_tint, |l, v| l.spec_tint = v, |g| g.spec_tint),
        ("sheen", |l| l.sheen, |l, v| l.sheen = v, |g| g.sheen),
        ("sheen_tint", |l| l.sheen_tint, |l, v| l.sheen_tint = v, |g| g.sheen_tint),
        ("clearcoat", |l| l.clearcoat, |l, v| l.clearcoat = v, |g| g.clearcoat),
        ("clearcoat_gloss", |l| l.clearcoat_gloss, |l, v| l.clearcoat_gloss = v, |g| g.clearcoat_gloss),
        ("flatness", |l| l.flatness, |l, v| l.flatness = v, |g| g.flatness),
    ]
}

/// Central differences in f64 of the f32 value would be noisy; the step is large enough and the
/// comparison relative to the larger of the two and an absolute floor scaled by the value.
fn close(analytic: f32, fd: f32, value: f32) -> bool {
    (analytic - fd).abs() <= 2e-2 * analytic.abs().max(fd.abs()) + 2e-3 * value.abs().max(1e-3)
}

#[test]
fn principled_derivatives_match_finite_differences() {
    let (mut checked, mut nonzero) = (0, 0);
    for (name, leaf) in cases() {
        let dirs = sphere_directions(300, 7);
        for pair in dirs.chunks(2) {
            let (wi, wo) = (pair[0], pair[1]);
            let (value, g) = leaf.eval_grad(wi, wo);
            if value.max_element() <= 0.0 {
                continue;
            }
            let h = 1e-3;
            for (param, get, set, field) in scalar_params() {
                let x = get(&leaf);
                // Mitsuba's lobe masks (clearcoat > 0, sheen > 0, bsdf > 0, brdf > 0) keep a lobe's
                // derivative out where its weight is 0: the derivative there is the one from the
                // side where the lobe is off.
                let below = x == 0.0 && matches!(param, "clearcoat" | "sheen" | "spec_trans");
                let above = x == 1.0 && matches!(param, "spec_trans" | "metallic");
                let (mut lo, mut hi) = (leaf, leaf);
                set(&mut lo, if above { x } else { x - h });
                set(&mut hi, if below { x } else { x + h });
                let fd = (hi.eval(wi, wo) - lo.eval(wi, wo)) / if below || above { h } else { 2.0 * h };
                let an = field(&g);
                for c in 0..3 {
                    checked += 1;
                    nonzero += usize::from(an[c] != 0.0);
                    assert!(
                        close(an[c], fd[c], value[c]),
                        "{name}: ∂f̂_{c}/∂{param} = {} against finite differences {} (f̂ = {value}, wi {wi}, wo {wo})",
                        an[c],
                        fd[c]
                    );
                }
            }
            for k in 0..3 {
                let (mut lo, mut hi) = (leaf, leaf);
                lo.base_color[k] -= h;
                hi.base_color[k] += h;
                let fd = (hi.eval(wi, wo) - lo.eval(wi, wo)) / (2.0 * h);
                for c in 0..3 {
                    checked += 1;
                    nonzero += usize::from(g.base_color[k][c] != 0.0);
                    assert!(
                        close(g.base_color[k][c], fd[c], value[c]),
                        "{name}: ∂f̂_{c}/∂base_{k} = {} against finite differences {} (f̂ = {value}, wi {wi}, wo {wo})",
                        g.base_color[k][c],
                        fd[c]
                    );
                }
            }
        }
    }
    assert!(nonzero > checked / 3, "{nonzero} of {checked} derivatives non-zero");
}

/// Mitsuba's principled reflection is reciprocal (f̂/|cos θo| symmetric in the two directions);
/// its transmission is not (the radiance form) — the test checks that it is not, too.
#[test]
fn principled_reflection_is_reciprocal_and_transmission_is_not() {
    for (name, leaf) in cases() {
        let dirs = sphere_directions(200, 11);
        for pair in dirs.chunks(2) {
            let (wi, wo) = (pair[0], Vec3::new(pair[1].x, pair[1].y, pair[1].z.abs()));
            let wi = Vec3::new(wi.x, wi.y, wi.z.abs());
            let a = leaf.eval(wi, wo) / wo.z;
            let b = leaf.eval(wo, wi) / wi.z;
            assert!(
                (a - b).abs().max_element() <= 1e-4 * a.max_element().max(1e-2),
                "{name}: f({wi}, {wo}) = {a}, reversed {b}"
            );
        }
    }
    let glass = cases()[3].1;
    let (wi, wo) = (incident(0.8), Vec3::new(-0.3, -0.2, -0.93).normalize());
    let (a, b) = (glass.eval(wi, wo) / wo.z.abs(), glass.eval(wo, wi) / wi.z.abs());
    assert!(a.x > 0.0 && ((a.x / b.x) - 1.0).abs() > 0.1, "transmission reciprocal: {a} {b}");
}

/// The directional albedo ∫ f̂ dwo by the sampler: a white metal and a clear glass lose only what
/// masking takes (between 0.9 and 1 at low roughness; the glass's transmitted radiance counted
/// times η², undoing the radiance form's (1/η)² compression). Mitsuba's sheen adds energy, so it is
/// not bounded, and is not tested.
#[test]
fn principled_albedo_of_white_metal_and_glass() {
    for (name, leaf) in [
        ("metal", PrincipledLeaf { base_color: Vec3::ONE, metallic: 1.0, roughness: 0.2, ..PrincipledLeaf::default() }),
        (
            "glass",
            PrincipledLeaf { base_color: Vec3::ONE, spec_trans: 1.0, roughness: 0.2, ..PrincipledLeaf::default() },
        ),
    ] {
        for cos_i in [0.9, 0.4] {
            let wi = incident(cos_i);
            let n = 200_000;
            let (mut sum, mut sum2) = (0.0f64, 0.0f64);
            for i in 0..n {
                let (ul, u) = uniforms(400, i);
                if let Some(wo) = leaf.sample(wi, ul, u) {
                    let energy = if wo.z < 0.0 { leaf.eta * leaf.eta } else { 1.0 };
                    let x = f64::from(leaf.eval(wi, wo).x / leaf.pdf(wi, wo) * energy);
                    sum += x;
                    sum2 += x * x;
                }
            }
            let mean = sum / n as f64;
            let sigma = ((sum2 / n as f64 - mean * mean) / n as f64).sqrt();
            assert!(mean > 0.9 && mean < 1.0 + 4.0 * sigma, "{name} at cos {cos_i}: albedo {mean} ± {sigma}");
        }
    }
}

/// A leaf from the properties of a case of `tests/data/principled/mitsuba_bsdf.py`.
fn leaf_from_props(props: &serde_json::Value) -> PrincipledLeaf {
    let get = |k: &str, default: f32| props.get(k).and_then(serde_json::Value::as_f64).map_or(default, |v| v as f32);
    let base = props.get("base_color").map_or(Vec3::splat(0.5), |v| {
        let a: Vec<f32> = v.as_array().unwrap().iter().map(|x| x.as_f64().unwrap() as f32).collect();
        Vec3::new(a[0], a[1], a[2])
    });
    let eta = match props.get("eta") {
        Some(e) => e.as_f64().unwrap() as f32,
        None => eta_from_specular(get("specular", 0.5)),
    };
    PrincipledLeaf {
        base_color: base,
        roughness: get("roughness", 0.5),
        anisotropic: get("anisotropic", 0.0),
        metallic: get("metallic", 0.0),
        spec_trans: get("spec_trans", 0.0),
        eta,
        spec_tint: get("spec_tint", 0.0),
        sheen: get("sheen", 0.0),
        sheen_tint: get("sheen_tint", 0.0),
        clearcoat: get("clearcoat", 0.0),
        clearcoat_gloss: get("clearcoat_gloss", 0.0),
        flatness: get("flatness", 0.0),
        rates: Vec3::new(
            get("main_specular_sampling_rate", 1.0),
            get("clearcoat_sampling_rate", 1.0),
            get("diffuse_reflectance_sampling_rate", 1.0),
        ),
    }
}

/// Values, densities and every derivative against Mitsuba 3.9.1's principled at 256 direction
/// pairs for five parameter sets (`tests/data/principled/mitsuba_bsdf.json`). Mitsuba's `pdf` is
/// not 0 from inside a BSDF that does not transmit (its reflection's probability is then F / F),
/// where its sampler draws nothing and its value is 0; there only the value is compared.
#[test]
fn principled_matches_mitsuba() {
    let data: serde_json::Value =
        serde_json::from_str(include_str!("../../../tests/data/principled/mitsuba_bsdf.json")).unwrap();
    let (wis, wos) = (json_vec3s(&data["pairs"]["wi"]), json_vec3s(&data["pairs"]["wo"]));
    let channels = |v: &serde_json::Value, i: usize| {
        Vec3::new(v[0][i].as_f64().unwrap() as f32, v[1][i].as_f64().unwrap() as f32, v[2][i].as_f64().unwrap() as f32)
    };
    let near = |a: f32, b: f32, scale: f32| (a - b).abs() <= 2e-3 * a.abs().max(b.abs()) + 1e-5 * scale.max(1.0);
    let (mut compared, mut nonzero) = (0, 0);
    for case in data["cases"].as_array().unwrap() {
        let name = case["name"].as_str().unwrap();
        let leaf = leaf_from_props(&case["props"]);
        for (i, (&wi, &wo)) in wis.iter().zip(&wos).enumerate() {
            let (value, g) = leaf.eval_grad(wi, wo);
            let expected = channels(&case["value"], i);
            let scale = expected.max_element();
            for c in 0..3 {
                assert!(
                    near(value[c], expected[c], 0.0),
                    "{name} pair {i}: f̂_{c} = {} against Mitsuba's {}",
                    value[c],
                    expected[c]
                );
            }
            let pdf = case["pdf"][i].as_f64().unwrap() as f32;
            if wi.z > 0.0 || leaf.spec_trans > 0.0 && leaf.metallic < 1.0 {
                assert!(
                    near(leaf.pdf(wi, wo), pdf, 0.0),
                    "{name} pair {i}: pdf {} against Mitsuba's {pdf}",
                    leaf.pdf(wi, wo)
                );
            }
            let mut check = |param: &str, ours: Vec3| {
                let theirs = channels(&case["grad"][param], i);
                for c in 0..3 {
                    compared += 1;
                    nonzero += usize::from(theirs[c] != 0.0);
                    assert!(
                        near(ours[c], theirs[c], scale),
                        "{name} pair {i} (wi {wi}, wo {wo}): ∂f̂_{c}/∂{param} = {} against Mitsuba's {}",
                        ours[c],
                        theirs[c]
                    );
                }
            };
            for (param, _, _, field) in scalar_params() {
                check(param, field(&g));
            }
            for k in 0..3 {
                check(&format!("base_color{k}"), g.base_color[k]);
            }
        }
    }
    assert!(nonzero > compared / 4, "{nonzero} of {compared} of Mitsuba's derivatives non-zero");
}

/// The directional albedo by this sampler agrees with Mitsuba's by its own sampler (the mean of
/// its sample weights, 2^20 samples, in the JSON): the two samplers estimate the same integral
/// within 4.5 standard errors of their difference, each channel, from outside and from inside.
#[test]
fn principled_albedo_matches_mitsubas_sampler() {
    let data: serde_json::Value =
        serde_json::from_str(include_str!("../../../tests/data/principled/mitsuba_bsdf.json")).unwrap();
    for (t, case) in data["cases"].as_array().unwrap().iter().enumerate() {
        let name = case["name"].as_str().unwrap();
        let leaf = leaf_from_props(&case["props"]);
        for (j, a) in case["albedo"].as_array().unwrap().iter().enumerate() {
            let wi = incident(a["cos_i"].as_f64().unwrap() as f32);
            let n = 1 << 20;
            let (mut sum, mut sum2) = ([0.0f64; 3], [0.0f64; 3]);
            for i in 0..n {
                let (ul, u) = uniforms(500 + 10 * t as u32 + j as u32, i);
                if let Some(wo) = leaf.sample(wi, ul, u) {
                    let w = leaf.eval(wi, wo) / leaf.pdf(wi, wo);
                    for c in 0..3 {
                        sum[c] += f64::from(w[c]);
                        sum2[c] += f64::from(w[c] * w[c]);
                    }
                }
            }
            for c in 0..3 {
                let mean = sum[c] / n as f64;
                let var = (sum2[c] / n as f64 - mean * mean) / n as f64;
                let (theirs, sigma) = (a["mean"][c].as_f64().unwrap(), a["sigma"][c].as_f64().unwrap());
                let tol = 4.5 * (var + sigma * sigma).sqrt() + 1e-6;
                assert!(
                    (mean - theirs).abs() <= tol,
                    "{name} at cos {}: albedo_{c} {mean} against Mitsuba's {theirs} (± {tol})",
                    a["cos_i"]
                );
            }
        }
    }
}

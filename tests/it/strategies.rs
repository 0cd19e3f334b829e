//! Sampling strategies (ALGORITHMS.md §5): the differential strategy's GPU kernels against the CPU
//! twin per path, and every strategy unbiased against plain BSDF sampling over independent seeds.

use pathgrad::backend::Backend;
use pathgrad::gpu::Renderer;
use pathgrad::gpu::renderer::GradMode;
use pathgrad::image::Image;
use pathgrad::integrator::{PlacementMis, RenderOptions, Strategy};
use pathgrad::loss::{Loss, loss_and_adjoint};
use pathgrad::scene::{Scene, builtin};

use crate::support::{TestGpu, scenes};

/// (scene, the parameter that drives the differential sampler, another parameter of the scene).
fn cases() -> Vec<(Scene, &'static str, &'static str)> {
    vec![
        (builtin::load("cornell-box").unwrap(), "sphere.bsdf.alpha.value", "white.reflectance.value"),
        (builtin::load("blend").unwrap(), "object.weight.value", "base.reflectance.value"),
        (scenes::textured_environment(), "ball.alpha.value", "environment.radiance.value"),
        // A frosted (rough dielectric) pane: the differential vertex reflects or refracts.
        (scenes::frosted_pane(), "pane.alpha.value", "environment.radiance.value"),
        // A rough plastic panel: the coating by the derivative's parts, the base by the cosine.
        (scenes::data_scene("diff_plastic_panel"), "panel.bsdf.alpha", "panel.bsdf.diffuse_reflectance.value"),
        // A brushed (anisotropic) conductor, each roughness the target with the other as the
        // parameter the differential strategy samples by the BSDF.
        (scenes::data_scene("diff_aniso_panel"), "panel.bsdf.alpha_u.value", "panel.bsdf.alpha_v.value"),
        (scenes::data_scene("diff_aniso_panel"), "panel.bsdf.alpha_v.value", "panel.bsdf.alpha_u.value"),
    ]
}

fn diff(scene: &Scene, target: &str, q: f32) -> Strategy {
    Strategy::Diff { target: scene.params.find(target).unwrap(), q, placement: PlacementMis::Balance }
}

#[test]
fn differential_strategy_gpu_equals_cpu_per_path() {
    let gpu = TestGpu::new();
    for (scene, target, other) in cases() {
        let mut renderer = Renderer::new(&gpu.ctx, &scene).unwrap();
        for (nee, placement) in
            [(true, PlacementMis::Balance), (false, PlacementMis::Balance), (true, PlacementMis::Power)]
        {
            let opts = RenderOptions {
                width: 48,
                height: 48,
                spp: 1,
                seed: 3,
                nee,
                strategy: diff(&scene, target, 0.5).with_placement(placement),
                ..RenderOptions::for_scene(&scene)
            };
            let images = [
                ("radiance", renderer.render(&opts).unwrap(), pathgrad::cpu::render(&scene, &opts).unwrap()),
                (
                    target,
                    renderer.image_gradient(&opts, target).unwrap(),
                    pathgrad::cpu::image_gradient(&scene, &opts, target).unwrap(),
                ),
                (
                    other,
                    renderer.image_gradient(&opts, other).unwrap(),
                    pathgrad::cpu::image_gradient(&scene, &opts, other).unwrap(),
                ),
            ];
            for (what, g, c) in &images {
                assert!(c.as_slice().iter().any(|v| *v != 0.0), "{} {what}: all zero", scene.source);
                // A gradient pixel sums terms of both signs: floor 1e-4 of the largest value; budget 1e-3 of
                // the values (a few-ulp difference crossing a threshold).
                let mismatched = crate::support::count_mismatches(g, c, 1e-4);
                println!(
                    "{} (NEE {nee}, {} placements) {what}: {mismatched} of {} values differ",
                    scene.source,
                    placement.name(),
                    g.as_slice().len()
                );
                assert!(
                    mismatched as f64 <= 1e-3 * g.as_slice().len() as f64,
                    "{} (NEE {nee}, {} placements) {what}: {mismatched} mismatches",
                    scene.source,
                    placement.name()
                );
            }
        }
    }
}

/// Summary statistics of one estimate, all of which every strategy must estimate without bias.
struct Estimate {
    /// Σ of the forward-mode image gradient ∂I/∂θ over each quadrant of the image.
    quadrants: [f64; 4],
    /// Reverse-mode gradient of a fixed L2 adjoint, for the target and another parameter.
    loss_target: f64,
    loss_other: f64,
    /// Σ of the rendered radiance.
    radiance: f64,
}

impl Estimate {
    fn values(&self) -> Vec<(&'static str, f64)> {
        vec![
            ("∂I/∂θ top left", self.quadrants[0]),
            ("∂I/∂θ top right", self.quadrants[1]),
            ("∂I/∂θ bottom left", self.quadrants[2]),
            ("∂I/∂θ bottom right", self.quadrants[3]),
            ("∂loss/∂θ", self.loss_target),
            ("∂loss/∂other", self.loss_other),
            ("radiance", self.radiance),
        ]
    }
}

fn quadrant_sums(image: &Image) -> [f64; 4] {
    let (w, h) = (image.width(), image.height());
    let mut q = [0.0f64; 4];
    for (i, px) in image.as_slice().chunks(3).enumerate() {
        let (x, y) = (i as u32 % w, i as u32 / w);
        let slot = usize::from(x >= w / 2) + 2 * usize::from(y >= h / 2);
        q[slot] += px.iter().map(|&v| f64::from(v)).sum::<f64>();
    }
    q
}

fn mean_and_variance(v: &[f64]) -> (f64, f64) {
    let m = v.iter().sum::<f64>() / v.len() as f64;
    (m, v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (v.len() as f64 - 1.0))
}

/// For each scene and NEE on or off, the differential strategy (q = 0.5; balance-heuristic
/// placements, and power-heuristic ones at q = 0.75, ALGORITHMS.md §5.7) and BSDF sampling without
/// NEE estimate the same image gradients (by image quadrant), loss gradients (of the driving
/// parameter and of another one, which the differential strategy samples by the BSDF) and radiance
/// as plain PRB with NEE; the loss is L2 against a render at a perturbed value, its adjoint fixed.
/// Each comparison is Welch's t over 24 independent seeds per configuration (≥ 23 degrees of
/// freedom): |t| < 5 has a false-alarm rate ≤ 4.7e-5 per value, ≤ 1.2e-2 over the 245 values here;
/// never a tuned tolerance. The first scene is direct lighting only (one bounce).
#[test]
fn every_strategy_is_unbiased_against_plain_prb() {
    const SEEDS: u32 = 24;
    const T_LIMIT: f64 = 5.0;
    let gpu = TestGpu::new();
    let mut runs: Vec<(Scene, &str, &str, Option<u32>)> = Vec::new();
    for (i, (scene, target, other)) in cases().into_iter().enumerate() {
        if i == 0 {
            runs.push((scene.clone(), target, other, Some(2)));
        }
        if i != 2 {
            runs.push((scene, target, other, None));
        }
    }
    for (scene, target, other, max_depth) in runs {
        let mut renderer = Renderer::new(&gpu.ctx, &scene).unwrap();
        let base = RenderOptions {
            width: 32,
            height: 32,
            spp: 4,
            max_depth: max_depth.or(Some(scene.max_depth)),
            ..RenderOptions::for_scene(&scene)
        };
        // A fixed adjoint image: L2 loss of a render against a target at a perturbed value (relative
        // MSE would make the noise of dark pixels dominate every estimate).
        let id = scene.params.find(target).unwrap();
        let value = scene.params.get(id)[0];
        let mut perturbed = scene.params.clone();
        perturbed.set(target, &[(value * 1.5).min(1.0)]).unwrap();
        renderer.set_params(&perturbed).unwrap();
        let reference = renderer.render(&RenderOptions { seed: 1_000_001, spp: 32, ..base }).unwrap();
        renderer.set_params(&scene.params).unwrap();
        let image = renderer.render(&RenderOptions { seed: 1_000_000, spp: 32, ..base }).unwrap();
        let (_, adjoint) = loss_and_adjoint(&image, &reference, Loss::L2).unwrap();

        let configs = [
            ("bsdf", Strategy::Bsdf, true),
            ("diff", diff(&scene, target, 0.5), true),
            ("bsdf --no-nee", Strategy::Bsdf, false),
            ("diff --no-nee", diff(&scene, target, 0.5), false),
            ("diff power q=0.75", diff(&scene, target, 0.75).with_placement(PlacementMis::Power), true),
            ("diff power q=0.75 --no-nee", diff(&scene, target, 0.75).with_placement(PlacementMis::Power), false),
        ];
        let mut all: Vec<Vec<Estimate>> = Vec::new();
        for (_, strategy, nee) in configs {
            let mut estimates = Vec::new();
            for seed in 0..SEEDS {
                let opts = RenderOptions { seed, strategy, nee, ..base };
                let grads = renderer.backward(&opts, &adjoint, GradMode::Float).unwrap();
                let sum = |name: &str| grads.get(name).unwrap().iter().map(|&v| f64::from(v)).sum::<f64>();
                estimates.push(Estimate {
                    quadrants: quadrant_sums(&renderer.image_gradient(&opts, target).unwrap()),
                    loss_target: sum(target),
                    loss_other: sum(other),
                    radiance: renderer.render(&opts).unwrap().as_slice().iter().map(|&v| f64::from(v)).sum(),
                });
            }
            all.push(estimates);
        }
        let column = |c: usize, k: usize| all[c].iter().map(|e| e.values()[k].1).collect::<Vec<f64>>();
        let names: Vec<&str> = all[0][0].values().iter().map(|(n, _)| *n).collect();
        for (k, name) in names.iter().enumerate() {
            let (m0, v0) = mean_and_variance(&column(0, k));
            let se0 = (v0 / f64::from(SEEDS)).sqrt();
            if *name == "∂loss/∂θ" || *name == "radiance" {
                assert!(m0.abs() > 3.0 * se0, "{} {name}: baseline {m0} ± {se0} — no power", scene.source);
            }
            for (c, (label, _, _)) in configs.iter().enumerate().skip(1) {
                let (m, v) = mean_and_variance(&column(c, k));
                if v == 0.0 && v0 == 0.0 {
                    // The parameter does not reach this quadrant: both are exactly 0 on every seed.
                    assert_eq!(m, m0, "{} {name}: {label}", scene.source);
                    continue;
                }
                let t = (m - m0) / ((v + v0) / f64::from(SEEDS)).sqrt();
                println!(
                    "{} depth {max_depth:?} {name}: bsdf {m0:.5} ± {se0:.5}, {label} {m:.5} ± {:.5} (t = {t:.2}, variance ratio {:.3})",
                    scene.source,
                    (v / f64::from(SEEDS)).sqrt(),
                    v / v0
                );
                assert!(t.abs() < T_LIMIT, "{} {name}: {label} {m} vs bsdf {m0} (t = {t:.2})", scene.source);
            }
        }
    }
}

/// The hero strategy's scene: two rough metal spheres and a blended floor (three parameters with
/// differential samplers), and its two hero sets: two roughnesses, a roughness and a blend weight.
fn hero_scene() -> Scene {
    scenes::data_scene("hero_spheres")
}

const LEFT: &str = "left.bsdf.alpha.value";
const RIGHT: &str = "right.bsdf.alpha.value";
const WEIGHT: &str = "floor.bsdf.weight.value";

fn hero(scene: &Scene, targets: &[&str], weights: Option<&[f32]>) -> Strategy {
    Strategy::hero(scene, targets, 0.5, weights).unwrap()
}

/// The hero strategy (ALGORITHMS.md §5.8) on the GPU equals the CPU reference path by path (1 spp):
/// radiance and the image gradient of every target and of a parameter outside the set, for both hero
/// sets, uniform and skewed probabilities, NEE on and off.
#[test]
fn hero_strategy_gpu_equals_cpu_per_path() {
    let gpu = TestGpu::new();
    let scene = hero_scene();
    let mut renderer = Renderer::new(&gpu.ctx, &scene).unwrap();
    let sets: [(&[&str], Option<&[f32]>); 3] =
        [(&[LEFT, RIGHT], None), (&[LEFT, RIGHT], Some(&[0.2, 0.8])), (&[LEFT, WEIGHT], None)];
    for (targets, weights) in sets {
        for nee in [true, false] {
            let opts = RenderOptions {
                width: 48,
                height: 48,
                spp: 1,
                seed: 5,
                nee,
                strategy: hero(&scene, targets, weights),
                ..RenderOptions::for_scene(&scene)
            };
            let mut images =
                vec![("radiance", renderer.render(&opts).unwrap(), pathgrad::cpu::render(&scene, &opts).unwrap())];
            for name in [LEFT, RIGHT, WEIGHT, "floor.bsdf.bsdf_1.alpha.value"] {
                images.push((
                    name,
                    renderer.image_gradient(&opts, name).unwrap(),
                    pathgrad::cpu::image_gradient(&scene, &opts, name).unwrap(),
                ));
            }
            for (what, g, c) in &images {
                assert!(c.as_slice().iter().any(|v| *v != 0.0), "{targets:?} {what}: all zero");
                let mismatched = crate::support::count_mismatches(g, c, 1e-4);
                println!(
                    "{targets:?} {weights:?} NEE {nee} {what}: {mismatched} of {} values differ",
                    g.as_slice().len()
                );
                assert!(
                    mismatched as f64 <= 1e-3 * g.as_slice().len() as f64,
                    "{targets:?} {weights:?} NEE {nee} {what}: {mismatched} mismatches"
                );
            }
        }
    }
}

/// One target given to [`Strategy::hero`] is today's differential strategy, bit for bit; a hero
/// set refuses, by name, a parameter without a differential sampler.
#[test]
fn hero_strategy_with_one_target_is_the_differential_strategy() {
    let scene = hero_scene();
    let one = Strategy::hero(&scene, &[LEFT], 0.5, None).unwrap();
    assert_eq!(one, diff(&scene, LEFT, 0.5));
    let opts = RenderOptions { width: 16, height: 16, spp: 2, strategy: one, ..RenderOptions::for_scene(&scene) };
    let today = RenderOptions { strategy: diff(&scene, LEFT, 0.5), ..opts };
    let a = pathgrad::cpu::image_gradient(&scene, &opts, LEFT).unwrap();
    let b = pathgrad::cpu::image_gradient(&scene, &today, LEFT).unwrap();
    assert!(a.as_slice().iter().zip(b.as_slice()).all(|(x, y)| x.to_bits() == y.to_bits()));
    let e = Strategy::hero(&scene, &[LEFT, "left.bsdf.specular_reflectance.value"], 0.5, None).unwrap_err();
    assert!(e.to_string().contains("left.bsdf.specular_reflectance.value"), "{e}");
    assert!(e.to_string().contains("no differential sampler"), "{e}");
}

/// Every parameter's gradient under the hero strategy is unbiased: over independent seeds, the
/// loss gradients of both hero sets' targets and of a parameter outside them, each target's
/// forward-mode image gradient (projected on a fixed reference of it) and the radiance agree with
/// plain PRB's (Welch's t, |t| < 5: a false-alarm rate ≤ 1e-4 per value at these degrees of
/// freedom), paired by seed with plain PRB of the same NEE setting. The adjoint is fixed: the sum
/// of the targets' reference image gradients (each normalised), so that each target's loss
/// gradient is clearly nonzero. Power check (the configurations with NEE): on each target's loss
/// and image gradient, a bias of `INJECTED` (20 %) of the baseline's mean would give |t| ≥ 5 in
/// expectation; without NEE the estimates are noisier and the same seeds see about 30–50 %. Runs
/// on the CPU reference, which the test above holds to the kernels path by path.
#[test]
fn hero_strategy_is_unbiased_for_every_parameter() {
    const SEEDS: u32 = 96;
    const T_LIMIT: f64 = 5.0;
    const INJECTED: f64 = 0.2;
    // Rougher spheres than the scene's: the estimates' spread is then small enough for the power
    // check at this many seeds.
    let mut scene = hero_scene();
    scene.params.set(LEFT, &[0.3]).unwrap();
    scene.params.set(RIGHT, &[0.45]).unwrap();
    let base = RenderOptions { width: 24, height: 24, spp: 2, ..RenderOptions::for_scene(&scene) };
    let targets = [LEFT, RIGHT, WEIGHT];
    let reference: Vec<Vec<f64>> = targets
        .iter()
        .map(|name| {
            let g = pathgrad::cpu::image_gradient(&scene, &RenderOptions { seed: 1_000_000, spp: 64, ..base }, name)
                .unwrap();
            let norm = g.as_slice().iter().map(|&v| f64::from(v).powi(2)).sum::<f64>().sqrt();
            g.as_slice().iter().map(|&v| f64::from(v) / norm).collect()
        })
        .collect();
    let adjoint_values: Vec<f32> =
        (0..reference[0].len()).map(|i| reference.iter().map(|r| r[i]).sum::<f64>() as f32).collect();
    let adjoint = Image::from_rgb(base.width, base.height, adjoint_values).unwrap();
    let other = "floor.bsdf.bsdf_1.alpha.value";
    // Each configuration is paired with plain PRB of the same NEE setting (the first two rows);
    // BSDF sampling without NEE is itself held to plain PRB with NEE here and by the test above.
    let configs = [
        ("bsdf", Strategy::Bsdf, true),
        ("bsdf --no-nee", Strategy::Bsdf, false),
        ("hero L,R", hero(&scene, &[LEFT, RIGHT], None), true),
        ("hero L,R p=0.2,0.8 --no-nee", hero(&scene, &[LEFT, RIGHT], Some(&[0.2, 0.8])), false),
        ("hero L,W", hero(&scene, &[LEFT, WEIGHT], None), true),
        ("hero L,W p=0.7,0.3 --no-nee", hero(&scene, &[LEFT, WEIGHT], Some(&[0.7, 0.3])), false),
    ];
    let mut names: Vec<String> = Vec::new();
    let mut all: Vec<Vec<Vec<f64>>> = Vec::new();
    for (_, strategy, nee) in configs {
        let mut rows = Vec::new();
        for seed in 0..SEEDS {
            let opts = RenderOptions { seed, strategy, nee, ..base };
            let grads = pathgrad::cpu::backward(&scene, &opts, &adjoint).unwrap();
            let value = |name: &str| {
                let e = scene.params.entry(scene.params.find(name).unwrap());
                grads[e.offset as usize..(e.offset + e.len) as usize].iter().sum::<f64>()
            };
            let mut row = Vec::new();
            names.clear();
            for name in targets {
                row.push(value(name));
                names.push(format!("∂loss/∂{name}"));
            }
            for (name, r) in targets.iter().zip(&reference) {
                let g = pathgrad::cpu::image_gradient(&scene, &opts, name).unwrap();
                row.push(g.as_slice().iter().zip(r).map(|(&v, &w)| f64::from(v) * w).sum());
                names.push(format!("∂I/∂{name} · reference"));
            }
            row.push(value(other));
            names.push(format!("∂loss/∂{other}"));
            row.push(pathgrad::cpu::render(&scene, &opts).unwrap().as_slice().iter().map(|&v| f64::from(v)).sum());
            names.push("radiance".into());
            rows.push(row);
        }
        all.push(rows);
    }
    // Paired by seed: a strategy and plain PRB share their random numbers (camera rays, NEE, the
    // directions of every vertex but the differential one), so their difference is far less noisy
    // than either; the pairs are independent across seeds, so the paired t applies.
    let column = |c: usize, k: usize| all[c].iter().map(|r| r[k]).collect::<Vec<f64>>();
    let mut weak = Vec::new();
    for (k, name) in names.iter().enumerate() {
        for (c, (label, _, nee)) in configs.iter().enumerate().skip(1) {
            let b = if *nee || c == 1 { 0 } else { 1 };
            let (m0, v0) = mean_and_variance(&column(b, k));
            let (m, v) = mean_and_variance(&column(c, k));
            let d: Vec<f64> = column(c, k).iter().zip(column(b, k)).map(|(a, b)| a - b).collect();
            let (md, vd) = mean_and_variance(&d);
            let se = (vd / f64::from(SEEDS)).sqrt();
            let t = md / se;
            println!(
                "{name}: {} {m0:.5}, {label} {m:.5} (paired t = {t:.2}, power: {INJECTED} of the mean is {:.1} standard errors; variance ratio {:.3})",
                configs[b].0,
                INJECTED * m0.abs() / se,
                v / v0
            );
            assert!(t.abs() < T_LIMIT, "{name}: {label} {m} vs bsdf {m0} (t = {t:.2})");
            if k < 6 && *nee && c != 1 && INJECTED * m0.abs() < T_LIMIT * se {
                weak.push(format!("{name}: {label}"));
            }
        }
    }
    assert!(
        weak.is_empty(),
        "a bias of {INJECTED} of the mean is below {T_LIMIT} standard errors (no power): {weak:?}"
    );
}

/// The command line refuses, by name, a hero set with a parameter that has no differential
/// sampler, power-heuristic placements with several targets, `--hero-weights` without several
/// targets or of the wrong count, and `auto` with several targets.
#[test]
fn hero_flags_are_checked_by_name() {
    let scene = format!("{}/tests/data/scenes/hero_spheres.xml", env!("CARGO_MANIFEST_DIR"));
    let base = ["grad", &scene, "--cpu", "--image-gradient", LEFT, "--width", "8", "--height", "8", "--spp", "1"];
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("g.exr");
    let refused = |extra: &[&str], expected: &str| {
        let o = crate::cli::pathgrad().args(base).args(["-o", out.to_str().unwrap()]).args(extra).output().unwrap();
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success() && stderr.contains(expected), "{extra:?}: {stderr}");
    };
    let set = format!("{LEFT},{RIGHT}");
    refused(
        &["--strategy", "diff", "--diff-param", &format!("{LEFT},left.bsdf.specular_reflectance.value")],
        "left.bsdf.specular_reflectance.value: has no differential sampler",
    );
    refused(
        &["--strategy", "diff", "--diff-param", &set, "--placement-mis", "power"],
        "--placement-mis power is not built",
    );
    refused(&["--strategy", "diff", "--diff-param", LEFT, "--hero-weights", "1,2"], "--hero-weights 1,2 applies only");
    refused(&["--strategy", "diff", "--diff-param", &set, "--hero-weights", "1,2,3"], "3 weights for 2 targets");
    refused(&["--strategy", "auto", "--diff-param", &set], "--strategy auto takes one --diff-param");
    let o = crate::cli::pathgrad()
        .args(base)
        .args(["-o", out.to_str().unwrap(), "--strategy", "diff", "--diff-param", &set, "--hero-weights", "1,3"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

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
/// freedom): |t| < 5 has a false-alarm rate ≤ 4.7e-5 per value, ≤ 9e-3 over the 175 values here;
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

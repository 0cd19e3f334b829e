//! Variance protocols (`pathgrad::variance`, ALGORITHMS.md §7.4): the statistics are those of the
//! independent estimates they stand for, seed by seed, in both modes and with adaptive sampling.

use pathgrad::adaptive::{AdaptiveEstimator, PixelSampling};
use pathgrad::backend::Backend;
use pathgrad::gpu::Renderer;
use pathgrad::gpu::renderer::GradMode;
use pathgrad::integrator::{PlacementMis, RenderOptions, Strategy};
use pathgrad::loss::{Loss, loss_and_adjoint};
use pathgrad::scene::builtin;
use pathgrad::variance::{self, LossGradientSetup, Moments, PilotBudget, WEIGHTS_SEED_OFFSET, choose_strategy};

use crate::support::TestGpu;

/// `a` equals `b` up to float atomics' reordering: 1e-4 relative to the largest |b|, 1e-4 relative
/// to each value.
fn close(a: &[f64], b: &[f64], what: &str) {
    assert_eq!(a.len(), b.len(), "{what}: lengths");
    let scale = b.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(scale > 0.0, "{what}: all zero, the comparison has no power");
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        assert!((x - y).abs() <= 1e-4 * (y.abs() + scale), "{what}[{i}]: {x} vs {y}");
    }
}

#[test]
fn image_gradient_variance_is_the_sample_variance_of_seeded_estimates() {
    let gpu = TestGpu::new();
    let scene = builtin::load("blend").unwrap();
    let mut renderer = Renderer::new(&gpu.ctx, &scene).unwrap();
    let weight = scene.params.find("object.weight.value").unwrap();
    let param = "object.weight.value";
    for strategy in [Strategy::Bsdf, Strategy::Diff { target: weight, q: 0.5, placement: PlacementMis::Balance }] {
        let opts =
            RenderOptions { width: 24, height: 18, spp: 1, seed: 40, strategy, ..RenderOptions::for_scene(&scene) };
        let mut calls = 0;
        let r = variance::image_gradient_variance(&mut renderer, &opts, param, 3, &mut |done| {
            calls += 1;
            assert_eq!(done, calls, "progress counts runs");
        })
        .unwrap();
        assert_eq!(calls, 3);
        let mut m = Moments::new(24 * 18 * 3);
        for seed in 40..43 {
            let g = renderer.image_gradient(&RenderOptions { seed, ..opts }, param).unwrap();
            m.add(g.as_slice().iter().map(|&v| f64::from(v)));
        }
        let to_f64 = |s: &[f32]| s.iter().map(|&v| f64::from(v)).collect::<Vec<_>>();
        close(&to_f64(r.mean.as_slice()), m.mean(), "mean");
        close(&to_f64(r.variance.as_slice()), &m.variance(), "variance");
        let mean_variance = m.variance().iter().sum::<f64>() / m.variance().len() as f64;
        assert!((r.mean_variance - mean_variance).abs() <= 1e-4 * mean_variance);
        assert!(r.seconds_per_estimate > 0.0);
    }
}

#[test]
fn loss_gradient_variance_is_that_of_seeded_estimates_uniform_and_adaptive() {
    let gpu = TestGpu::new();
    let scene = builtin::load("cornell-box").unwrap();
    let mut renderer = Renderer::new(&gpu.ctx, &scene).unwrap();
    let alpha = scene.params.find("sphere.bsdf.alpha.value").unwrap();
    let white = scene.params.find("white.reflectance.value").unwrap();
    let opts = RenderOptions { width: 24, height: 24, spp: 1, seed: 7, ..RenderOptions::for_scene(&scene) };
    // The target: the same scene rendered rougher.
    let mut table = scene.params.clone();
    table.set("sphere.bsdf.alpha.value", &[0.3]).unwrap();
    renderer.set_params(&table).unwrap();
    let target = renderer.render(&RenderOptions { spp: 16, seed: 99, ..opts }).unwrap();
    renderer.set_params(&scene.params).unwrap();
    let params = [alpha, white];
    for adaptive in [None, Some(AdaptiveEstimator::Importance)] {
        let setup = LossGradientSetup { target: &target, loss: Loss::RelMse, spp_primal: 3, adaptive, params: &params };
        let r = variance::loss_gradient_variance(&mut renderer, &opts, &setup, 4, &mut |_| {}).unwrap();
        assert_eq!(r.mean.len(), 4, "one α and three albedo values");
        let pass1 = RenderOptions { spp: 3, ..opts };
        let sampling = adaptive.map(|estimator| {
            let image = renderer.render_reference(&RenderOptions { seed: 7 + WEIGHTS_SEED_OFFSET, ..pass1 }).unwrap();
            PixelSampling::from_adjoint(&loss_and_adjoint(&image, &target, Loss::RelMse).unwrap().1, estimator).unwrap()
        });
        let mut m = Moments::new(4);
        let mut loss_sum = 0.0;
        for seed in 7..11 {
            let image = renderer.render(&RenderOptions { seed, ..pass1 }).unwrap();
            let (loss, adjoint) = loss_and_adjoint(&image, &target, Loss::RelMse).unwrap();
            loss_sum += loss;
            let run = RenderOptions { seed, ..opts };
            let g = match &sampling {
                None => renderer.backward(&run, &adjoint, GradMode::Float).unwrap(),
                Some(s) => renderer.backward_adaptive(&run, &adjoint, s, GradMode::Float).unwrap(),
            };
            let a = g.get("sphere.bsdf.alpha.value").unwrap();
            let w = g.get("white.reflectance.value").unwrap();
            m.add(a.iter().chain(w).map(|&v| f64::from(v)));
        }
        let what = if adaptive.is_some() { "adaptive" } else { "uniform" };
        close(&r.mean, m.mean(), &format!("{what} mean"));
        close(&r.variance, &m.variance(), &format!("{what} variance"));
        assert!((r.total_variance - m.variance().iter().sum::<f64>()).abs() <= 1e-4 * r.total_variance);
        assert!((r.mean_loss - loss_sum / 4.0).abs() <= 1e-12 * r.mean_loss, "pass 1 is deterministic");
    }
}

#[test]
fn variance_protocols_reject_bad_settings() {
    let gpu = TestGpu::new();
    let scene = builtin::load("blend").unwrap();
    let mut renderer = Renderer::new(&gpu.ctx, &scene).unwrap();
    let opts = RenderOptions { width: 8, height: 6, spp: 1, ..RenderOptions::for_scene(&scene) };
    let e = variance::image_gradient_variance(&mut renderer, &opts, "object.weight.value", 1, &mut |_| {});
    assert!(e.unwrap_err().to_string().contains("variance::runs"));
    let e = variance::image_gradient_variance(&mut renderer, &opts, "nope", 2, &mut |_| {});
    assert!(e.unwrap_err().to_string().contains("nope"));
    let target = pathgrad::image::Image::new(8, 6);
    let weight = [scene.params.find("object.weight.value").unwrap()];
    let bad = [
        (
            LossGradientSetup { target: &target, loss: Loss::L2, spp_primal: 0, adaptive: None, params: &weight },
            "LossGradientSetup::spp_primal",
        ),
        (
            LossGradientSetup { target: &target, loss: Loss::L2, spp_primal: 1, adaptive: None, params: &[] },
            "LossGradientSetup::params",
        ),
    ];
    for (setup, flag) in bad {
        let e = variance::loss_gradient_variance(&mut renderer, &opts, &setup, 2, &mut |_| {}).unwrap_err();
        assert!(e.to_string().contains(flag), "{e}");
    }
    let small = pathgrad::image::Image::new(4, 3);
    let setup = LossGradientSetup { target: &small, loss: Loss::L2, spp_primal: 1, adaptive: None, params: &weight };
    let e = variance::loss_gradient_variance(&mut renderer, &opts, &setup, 2, &mut |_| {}).unwrap_err();
    assert!(e.to_string().contains("4×3"), "{e}");
}

#[test]
fn cli_variance_writes_maps_and_a_summary_with_the_baseline_at_one() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("v");
    let o = crate::cli::pathgrad()
        .args(["variance", "builtin:blend", "--param", "object.weight.value", "--strategy", "bsdf,diff"])
        .args(["--q", "0.3,0.7", "--runs", "3", "--spp", "1", "--width", "16", "--json", "-o"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let on_disk: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(v, on_disk, "--json prints summary.json");
    assert_eq!(v["mode"], "image");
    assert_eq!(v["baseline"], "bsdf");
    let rows = v["techniques"].as_array().unwrap();
    let names: Vec<_> = rows.iter().map(|r| r["technique"].as_str().unwrap()).collect();
    assert_eq!(names, ["bsdf", "diff q=0.3", "diff q=0.7"]);
    assert_eq!(rows[0]["variance_ratio"], 1.0);
    assert_eq!(rows[0]["efficiency_ratio"], 1.0);
    for r in rows {
        assert!(r["variance"].as_f64().unwrap() > 0.0, "{r}");
        assert!(r["seconds_per_estimate"].as_f64().unwrap() > 0.0, "{r}");
    }
    for stem in ["bsdf", "diff-q0.3", "diff-q0.7"] {
        let map = pathgrad::image::Image::read_exr(out.join(format!("variance-{stem}.exr"))).unwrap();
        assert_eq!((map.width(), map.height()), (16, 12));
        assert!(map.as_slice().iter().all(|&v| v >= 0.0));
        for file in [format!("variance-{stem}.png"), format!("mean-{stem}.exr"), format!("mean-{stem}.png")] {
            assert!(out.join(&file).exists(), "{file}");
        }
    }
}

#[test]
fn cli_variance_of_the_loss_gradient_with_adaptive_rows() {
    let dir = tempfile::tempdir().unwrap();
    let o = crate::cli::pathgrad()
        .current_dir(dir.path())
        .args(["variance", "builtin:cornell-box", "--param", "sphere.bsdf.alpha.value", "--strategy", "bsdf"])
        .args([
            "--target-set",
            "sphere.bsdf.alpha.value=0.3",
            "--adaptive",
            "--runs",
            "3",
            "--spp",
            "1",
            "--width",
            "12",
        ])
        .arg("--json")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["mode"], "loss");
    assert_eq!(v["spp_primal"], 3, "the default budget is 3:1");
    let rows = v["techniques"].as_array().unwrap();
    assert_eq!(rows.iter().map(|r| r["technique"].as_str().unwrap()).collect::<Vec<_>>(), ["bsdf", "bsdf adaptive"]);
    assert_eq!(rows[1]["adaptive"], true);
    assert_eq!(rows[0]["mean_gradient"].as_array().unwrap().len(), 1);
    assert!(dir.path().join("variance-out/summary.json").exists(), "the default -o is variance-out");
}

#[test]
fn cli_variance_errors_name_the_flag_and_leave_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let base = ["variance", "builtin:blend", "--spp", "1", "--width", "8"];
    let cases: [(&[&str], &str); 6] = [
        (&["--param", "nope"], "invalid --param nope: no such parameter"),
        (&["--param", "object.weight.value", "--runs", "1"], "invalid --runs 1"),
        (&["--param", "object.weight.value", "--strategy", "bsdf,magic"], "unknown strategy 'magic'"),
        (&["--param", "object.weight.value", "--q", "1.5"], "--q"),
        (&["--param", "object.weight.value", "--adaptive"], "--adaptive are for loss-gradient mode"),
        (&["--param", "object.weight.value", "--strategy", "bsdf,bsdf"], "twice"),
    ];
    for (args, message) in cases {
        let o = crate::cli::pathgrad().current_dir(dir.path()).args(base).args(args).output().unwrap();
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{args:?} should fail");
        assert!(stderr.contains(message), "{args:?}: expected '{message}' in: {stderr}");
    }
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0, "no output was left behind");
}

/// `--strategy auto`'s pilot ([`choose_strategy`]): each candidate's variance is that of its seeded
/// estimates (as [`variance::image_gradient_variance`] measures it), the pick is the candidate of
/// least variance × time, the same seed picks the same strategy, and a parameter without a
/// differential sampler has `bsdf` alone.
#[test]
fn the_pilot_measures_every_candidate_and_the_same_seed_picks_the_same_strategy() {
    let gpu = TestGpu::new();
    let scene = builtin::load("blend").unwrap();
    let mut renderer = Renderer::new(&gpu.ctx, &scene).unwrap();
    let param = "object.weight.value";
    let opts = RenderOptions { width: 24, height: 18, spp: 4, seed: 11, ..RenderOptions::for_scene(&scene) };
    let budget = PilotBudget { runs: 3, spp: 1 };
    let a = choose_strategy(&mut renderer, &opts, param, PlacementMis::Balance, budget, None).unwrap();
    let qs: Vec<Option<f32>> = a
        .candidates
        .iter()
        .map(|c| match c.strategy {
            Strategy::Diff { q, .. } | Strategy::Hero { q, .. } => Some(q),
            Strategy::Bsdf => None,
        })
        .collect();
    assert_eq!(qs, [None, Some(0.5), Some(0.75), Some(0.9)]);
    assert_eq!((a.renders, a.samples_per_pixel), (2 + 3 * 4, 2 + 3 * 4));
    for c in &a.candidates {
        let r = variance::image_gradient_variance(
            &mut renderer,
            &RenderOptions { spp: 1, strategy: c.strategy, ..opts },
            param,
            3,
            &mut |_| {},
        )
        .unwrap();
        assert!(r.mean_variance > 0.0);
        assert!(
            (c.variance - r.mean_variance).abs() <= 1e-4 * r.mean_variance,
            "{:?}: {} vs {}",
            c.strategy,
            c.variance,
            r.mean_variance
        );
    }
    // The pick: the first candidate, displaced only by one better by more than PILOT_MARGIN.
    let mut pick = &a.candidates[0];
    for c in &a.candidates[1..] {
        if c.efficiency < (1.0 - variance::PILOT_MARGIN) * pick.efficiency {
            pick = c;
        }
    }
    assert_eq!(a.strategy, pick.strategy);
    let b = choose_strategy(&mut renderer, &opts, param, PlacementMis::Balance, budget, None).unwrap();
    assert_eq!(b.strategy, a.strategy, "the same seed: {:?} then {:?}", a.candidates, b.candidates);

    // On the loss gradient: each candidate's figure is loss_gradient_variance's, pass 1 shared.
    let target = renderer.render(&RenderOptions { seed: 99, ..opts }).unwrap();
    let ids = [scene.params.find(param).unwrap()];
    let measure = variance::PilotLoss { target: &target, loss: Loss::L2, spp_primal: 2, params: &ids };
    let l = choose_strategy(&mut renderer, &opts, param, PlacementMis::Balance, budget, Some(&measure)).unwrap();
    assert_eq!((l.renders, l.samples_per_pixel), (3 + 3 * 5, (2 + 2) + 3 * (2 + 4)));
    for c in &l.candidates {
        let setup = LossGradientSetup { target: &target, loss: Loss::L2, spp_primal: 2, adaptive: None, params: &ids };
        let run = RenderOptions { spp: 1, strategy: c.strategy, ..opts };
        let r = variance::loss_gradient_variance(&mut renderer, &run, &setup, 3, &mut |_| {}).unwrap();
        assert!(r.total_variance > 0.0);
        let (a, b) = (c.variance, r.total_variance);
        assert!((a - b).abs() <= 1e-4 * b, "{:?}: {a} vs {b}", c.strategy);
    }

    let c =
        choose_strategy(&mut renderer, &opts, "base.reflectance.value", PlacementMis::Balance, budget, None).unwrap();
    assert_eq!((c.strategy, c.candidates.len()), (Strategy::Bsdf, 1));
    let e = choose_strategy(&mut renderer, &opts, param, PlacementMis::Balance, PilotBudget { runs: 1, spp: 1 }, None);
    assert!(e.unwrap_err().to_string().contains("PilotBudget::runs"));
}

/// `--strategy attached`: bsdf sampled attached, a row beside detached bsdf (here a rough
/// conductor's roughness, which both differentiate), and the only row an index of refraction
/// takes (detached rows are refused by name).
#[test]
fn cli_variance_takes_an_attached_row() {
    let dir = tempfile::tempdir().unwrap();
    let scenes = format!("{}/tests/data/scenes", env!("CARGO_MANIFEST_DIR"));
    let run = |scene: &str, param: &str, strategy: &str| {
        crate::cli::pathgrad()
            .args(["variance", &format!("{scenes}/{scene}.xml"), "--param", param, "--strategy", strategy])
            .args(["--runs", "3", "--spp", "1", "--width", "12", "--height", "12", "--json", "-o"])
            .arg(dir.path().join(scene))
            .output()
            .unwrap()
    };
    let o = run("attached_rough", "ball.bsdf.alpha.value", "bsdf,attached");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let rows = v["techniques"].as_array().unwrap();
    let names: Vec<_> =
        rows.iter().map(|r| (r["technique"].as_str().unwrap(), r["sampling"].as_str().unwrap())).collect();
    assert_eq!(names, [("bsdf", "detached"), ("attached", "attached")]);
    assert_eq!(v["baseline"], "bsdf");
    assert!(rows.iter().all(|r| r["variance"].as_f64().unwrap() > 0.0), "{v}");
    // The same seeds: were the row's sampling not applied, it would repeat bsdf's figures exactly.
    assert_ne!(rows[0]["variance"], rows[1]["variance"]);

    let o = run("attached_sphere", "glass.bsdf.eta", "attached");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(v["techniques"][0]["variance"].as_f64().unwrap() > 0.0, "{v}");
    let o = run("attached_sphere", "glass.bsdf.eta", "attached,bsdf");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("--strategy bsdf") && err.contains("no detached derivative"), "{err}");

    // Loss-gradient mode, uniform and adaptive pixels: η's loss gradient against a target at 1.3.
    let o = crate::cli::pathgrad()
        .args(["variance", &format!("{scenes}/attached_sphere.xml"), "--param", "glass.bsdf.eta"])
        .args(["--strategy", "attached", "--target-set", "glass.bsdf.eta=1.3", "--adaptive", "--loss", "l2"])
        .args(["--runs", "3", "--spp", "1", "--width", "12", "--height", "12", "--json", "-o"])
        .arg(dir.path().join("loss"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["mode"], "loss");
    let rows = v["techniques"].as_array().unwrap();
    let names: Vec<_> =
        rows.iter().map(|r| (r["technique"].as_str().unwrap(), r["sampling"].as_str().unwrap())).collect();
    assert_eq!(names, [("attached", "attached"), ("attached adaptive", "attached")]);
    for r in rows {
        let g = r["mean_gradient"][0].as_f64().unwrap();
        assert!(g.is_finite() && g != 0.0 && r["variance"].as_f64().unwrap() > 0.0, "{r}");
    }
}

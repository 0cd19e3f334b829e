//! Inverse rendering end to end (`pathgrad::optim`): an iteration is pass 1 at spp_primal and the
//! gradient pass at spp_grad with seed base + t; short optimisations on small scenes recover a
//! roughness and a blend weight, and a negative control with the gradient's sign flipped fails
//! the same criterion. With control variates (`IterationOptions::control_variates`): the warm-up
//! iterations equal the plain run bit for bit, and the running estimate is unbiased along a fixed
//! trajectory (a z-test over seeds) and less noisy than a plain pass 1. With gradient reuse
//! (`IterationOptions::gradient_reuse`) the same holds for the running gradient estimate against
//! plain gradients.

use pathgrad::adaptive::AdaptiveEstimator;
use pathgrad::backend::Backend;
use pathgrad::gpu::Renderer;
use pathgrad::gpu::renderer::GradMode;
use pathgrad::image::Image;
use pathgrad::integrator::RenderOptions;
use pathgrad::integrator::View;
use pathgrad::loss::{Loss, loss_and_adjoint};
use pathgrad::optim::{
    AdamOptions, ControlVariateOptions, ControlVariateState, IterationOptions, Optimization, RunningEstimate,
    gradient_reuse,
};
use pathgrad::params::{Gradients, ParamId, ParamTable};
use pathgrad::scene::builtin;

use crate::support::TestGpu;

/// Adam's learning rate of the recovery runs.
const LR: f64 = 0.01;
/// The criterion is on the mean of the last this many iterates.
const TAIL: usize = 20;
/// The stated tolerance on that mean: 3η. Adam moves an iterate by about η per step at most
/// (|m̂| ≲ √v̂), so once the gradient's mean no longer dominates its noise the iterate wanders
/// within a few η of the optimum; the mean of the last 20 averages most of the wander out, and
/// what is left, plus the bias from the target's own noise (512 spp, a tenth of the render's
/// relative noise), stays within 3η. The start is 7η (roughness) and 40η (weight) away; a
/// gradient of the wrong sign runs to the far bound instead (checked below).
const TOLERANCE: f64 = 3.0 * LR;
/// Samples per pixel of the target: 512, against pass 1's 16 (relative noise √(16/512) ≈ 0.18×).
const TARGET_SPP: u32 = 512;
/// The target's seed; the iterations use seeds 0, 1, … (fewer than this), so no pass shares a key.
const TARGET_SEED: u32 = 1_000;

/// The built-in blend scene on a 16×12 render (1 spp, seed 7), its 8-spp target at seed 99 and
/// the parameters with the blend weight moved to 0.8 (its id returned).
fn blend_from_weight_08(gpu: &TestGpu) -> (Renderer, RenderOptions, Image, ParamTable, ParamId) {
    let scene = builtin::load("blend").unwrap();
    let mut renderer = Renderer::new(&gpu.ctx, &scene).unwrap();
    let render = RenderOptions { width: 16, height: 12, spp: 1, seed: 7, ..RenderOptions::for_scene(&scene) };
    let target = renderer.render(&RenderOptions { spp: 8, seed: 99, ..render }).unwrap();
    let mut start = scene.params.clone();
    start.set("object.weight.value", &[0.8]).unwrap();
    let id = start.find("object.weight.value").unwrap();
    (renderer, render, target, start, id)
}

/// Iteration t of [`Optimization`] is, bit for bit (fixed-point gradients), pass 1 rendered with
/// spp_primal samples and seed base + t, the loss and adjoint on the host, and the gradient pass
/// with spp_grad samples and the same seed — also after a step changed the parameters.
#[test]
fn an_iteration_is_pass_one_at_spp_primal_then_the_gradient_at_spp_grad_with_seed_base_plus_t() {
    let gpu = TestGpu::new();
    if !gpu.ctx.info().int64_atomics {
        return;
    }
    let (mut renderer, render, target, start, id) = blend_from_weight_08(&gpu);
    let mode = GradMode::Deterministic;
    let options = IterationOptions {
        render,
        spp_primal: 3,
        adaptive: None,
        loss: Loss::RelMse,
        mode,
        control_variates: None,
        gradient_reuse: None,
    };
    let mut run = Optimization::new(start, &[id], AdamOptions::default(), options).unwrap();
    for t in 0..2u32 {
        let (loss, gradients) = run.gradient(&mut renderer, &target).unwrap();
        renderer.set_params(run.params()).unwrap();
        let at_t = RenderOptions { seed: 7 + t, ..render };
        let image = renderer.render(&RenderOptions { spp: 3, ..at_t }).unwrap();
        let (want_loss, adjoint) = loss_and_adjoint(&image, &target, Loss::RelMse).unwrap();
        let want = renderer.backward(&at_t, &adjoint, mode).unwrap();
        assert_eq!(loss, want_loss, "iteration {t}: pass 1 renders 3 spp with seed 7 + {t}");
        assert_eq!(gradients.values(), want.values(), "iteration {t}: the gradient pass");
        // Another seed gives another loss: the seed really is per iteration.
        let other = renderer.render(&RenderOptions { spp: 3, seed: 7 + t + 1, ..render }).unwrap();
        assert_ne!(loss_and_adjoint(&other, &target, Loss::RelMse).unwrap().0, loss);
        run.apply(loss, &gradients).unwrap();
    }
    assert_eq!(run.iteration(), 2);
}

/// Optimises `param` of built-in `scene` from `init` towards a target rendered at `truth`; returns
/// every iterate. `sign` multiplies the gradient (−1: the negative control).
fn optimise(scene: &str, param: &str, init: f32, truth: f32, iterations: usize, sign: f32) -> Vec<f32> {
    let gpu = TestGpu::new();
    let scene = builtin::load(scene).unwrap();
    let mut renderer = Renderer::new(&gpu.ctx, &scene).unwrap();
    let mode = if gpu.ctx.info().int64_atomics { GradMode::Deterministic } else { GradMode::Float };
    // 32 pixels wide, the scene's aspect ratio; 16 + 8 spp (2:1) keeps the gradient's noise low
    // enough for a short run.
    let width = 32;
    let height = width * scene.camera.height / scene.camera.width;
    let render = RenderOptions { width, height, spp: 8, ..RenderOptions::for_scene(&scene) };
    let mut at_truth = scene.params.clone();
    at_truth.set(param, &[truth]).unwrap();
    renderer.set_params(&at_truth).unwrap();
    let target = renderer.render(&RenderOptions { spp: TARGET_SPP, seed: TARGET_SEED, ..render }).unwrap();
    let mut start = scene.params.clone();
    start.set(param, &[init]).unwrap();
    let id = start.find(param).unwrap();
    let options = IterationOptions {
        render,
        spp_primal: 16,
        adaptive: None,
        loss: Loss::RelMse,
        mode,
        control_variates: None,
        gradient_reuse: None,
    };
    let mut run = Optimization::new(start, &[id], AdamOptions::with_learning_rate(LR), options).unwrap();
    let mut iterates = Vec::new();
    for _ in 0..iterations {
        let (loss, gradients) = run.gradient(&mut renderer, &target).unwrap();
        let flipped = Gradients::new(run.params(), gradients.values().iter().map(|g| sign * g).collect());
        run.apply(loss, &flipped).unwrap();
        iterates.push(run.params().get(id)[0]);
    }
    iterates
}

fn tail_mean(iterates: &[f32]) -> f64 {
    iterates[iterates.len() - TAIL..].iter().map(|&v| f64::from(v)).sum::<f64>() / TAIL as f64
}

/// The Cornell box's sphere roughness from 0.3 to a target rendered at 0.1 in 60 iterations.
#[test]
fn a_short_optimisation_recovers_the_sphere_roughness() {
    let iterates = optimise("cornell-box", "sphere.bsdf.alpha.value", 0.3, 0.1, 60, 1.0);
    let mean = tail_mean(&iterates);
    println!("alpha iterates {iterates:?}; mean of the last {TAIL}: {mean}");
    assert!((mean - 0.1).abs() <= TOLERANCE, "alpha ended at {mean} (target 0.1 ± {TOLERANCE})");
}

/// The blend scene's weight from 0.8 to a target rendered at 0.4 in 80 iterations; and the
/// negative control: the same run with the gradient's sign flipped ends far outside the
/// tolerance (at the bound 1), so the criterion can fail.
#[test]
fn a_short_optimisation_recovers_the_blend_weight_and_a_wrong_sign_does_not() {
    let iterates = optimise("blend", "object.weight.value", 0.8, 0.4, 80, 1.0);
    let mean = tail_mean(&iterates);
    println!("weight iterates {iterates:?}; mean of the last {TAIL}: {mean}");
    assert!((mean - 0.4).abs() <= TOLERANCE, "the weight ended at {mean} (target 0.4 ± {TOLERANCE})");
    let wrong = optimise("blend", "object.weight.value", 0.8, 0.4, 40, -1.0);
    let wrong_mean = tail_mean(&wrong);
    println!("sign-flipped weight iterates {wrong:?}");
    assert!((wrong_mean - 0.4).abs() > 10.0 * TOLERANCE, "ascending the loss ended at {wrong_mean}");
}

/// With control variates, iterations 0–2 are the plain run's bit for bit (fixed-point gradients;
/// with uniform and with adaptive pixel sampling of the gradient pass):
/// the first iteration's estimate is its G, and the weight v is 0 through the warm-up (step 1)
/// and at step 2 (one update of the statistics: zero variance). From iteration 3 on v > 0 and
/// the runs part — which shows that the comparison can fail.
#[test]
fn control_variates_equal_the_plain_run_while_the_weight_is_zero() {
    let gpu = TestGpu::new();
    if !gpu.ctx.info().int64_atomics {
        return;
    }
    let (mut renderer, render, target, start, id) = blend_from_weight_08(&gpu);
    let mode = GradMode::Deterministic;
    for adaptive in [None, Some(AdaptiveEstimator::default())] {
        let plain = IterationOptions {
            render,
            spp_primal: 3,
            adaptive,
            loss: Loss::RelMse,
            mode,
            control_variates: None,
            gradient_reuse: None,
        };
        let with_cv = IterationOptions { control_variates: Some(ControlVariateOptions::default()), ..plain };
        let mut a = Optimization::new(start.clone(), &[id], AdamOptions::with_learning_rate(0.05), plain).unwrap();
        let mut b = Optimization::new(start.clone(), &[id], AdamOptions::with_learning_rate(0.05), with_cv).unwrap();
        for t in 0..5 {
            let (la, ga) = a.gradient(&mut renderer, &target).unwrap();
            let (lb, gb) = b.gradient(&mut renderer, &target).unwrap();
            if t <= 2 {
                assert_eq!((la, ga.values()), (lb, gb.values()), "iteration {t}: v = 0, the plain estimate");
                assert!(b.control_variates().state.as_ref().is_none_or(|s| s.running.weight.iter().all(|&w| w == 0.0)));
            } else {
                assert_ne!(la, lb, "iteration {t}: v > 0 changes the loss image");
            }
            a.apply(la, &ga).unwrap();
            b.apply(lb, &gb).unwrap();
        }
        let state = b.control_variates().state.as_ref().unwrap();
        assert_eq!((state.running.steps, state.running.updates), (5, 4));
        assert!(state.running.weight.iter().any(|&w| w > 0.0));
        // The previous parameters are the last iteration's: where iteration 5 renders H.
        assert_ne!(b.control_variates().previous.as_ref().unwrap().get(id), b.params().get(id));
    }
}

/// Per-pixel mean and variance over runs.
fn moments(images: &[Vec<f32>]) -> (Vec<f64>, Vec<f64>) {
    let n = images.len() as f64;
    let len = images[0].len();
    let mean: Vec<f64> = (0..len).map(|k| images.iter().map(|i| f64::from(i[k])).sum::<f64>() / n).collect();
    let var =
        (0..len).map(|k| images.iter().map(|i| (f64::from(i[k]) - mean[k]).powi(2)).sum::<f64>() / (n - 1.0)).collect();
    (mean, var)
}

/// Images per step, per run.
type PerStep = Vec<Vec<Vec<f32>>>;

/// Runs of the control-variate estimate along a fixed trajectory of the blend weight
/// (θ_i = 0.8 − δ·i), G_i and H_i rendered by the kernels with seed base + i: returns, per run,
/// the estimate F_i after each of `steps` steps and a plain render at θ_i with seed base + 500 + i.
fn control_variate_runs(delta: f32, runs: u32, steps: usize) -> (PerStep, PerStep) {
    let gpu = TestGpu::new();
    let scene = builtin::load("blend").unwrap();
    let mut renderer = Renderer::new(&gpu.ctx, &scene).unwrap();
    let cv = ControlVariateOptions::default();
    let (mut estimates, mut plain) = (vec![Vec::new(); steps], vec![Vec::new(); steps]);
    for run in 0..runs {
        let render =
            RenderOptions { width: 12, height: 9, spp: 4, seed: 1000 * run, ..RenderOptions::for_scene(&scene) };
        let mut state = ControlVariateState::new(render.width, render.height, 1);
        let mut table = scene.params.clone();
        for i in 0..steps {
            let at = RenderOptions { seed: render.seed + i as u32, ..render };
            let h = if i > 0 {
                table.set("object.weight.value", &[0.8 - delta * (i - 1) as f32]).unwrap();
                renderer.set_params(&table).unwrap();
                Some(vec![renderer.render(&at).unwrap()])
            } else {
                None
            };
            table.set("object.weight.value", &[0.8 - delta * i as f32]).unwrap();
            renderer.set_params(&table).unwrap();
            let g = renderer.render(&at).unwrap();
            let f = state.step(&cv, std::slice::from_ref(&g), h.as_deref()).unwrap().remove(0);
            estimates[i].push(f.into_rgb());
            // A plain render at θ_i on paths of its own (independent of every F).
            let independent = RenderOptions { seed: at.seed + 500, ..at };
            plain[i].push(renderer.render(&independent).unwrap().into_rgb());
        }
    }
    (estimates, plain)
}

/// The estimate F_k after k = 8 steps along a fixed trajectory has the expectation of a plain
/// render at θ_k: per pixel, the mean of F_k over 64 runs (seeds 1000·r + i, 4 spp) against the mean
/// of the 64 runs' independent plain renders G_k at θ_k, Welch's t with a Bonferroni level (0.001
/// over the pixels and channels), for a still (δ = 0, H ≡ G) and a moving (δ = 0.02, 0.16 in
/// all) trajectory. Power check: the standard error of the image mean of F_k is below 1 % of it,
/// so a bias of a few percent (e.g. F ← v(F + H) + G) fails. And the estimate is less noisy:
/// its mean per-pixel variance at step 8 is below 0.8× plain's on the moving trajectory (printed
/// per step; BENCHMARKS.md).
#[test]
fn the_control_variate_estimate_is_unbiased_along_a_trajectory_and_less_noisy() {
    const RUNS: u32 = 64;
    const STEPS: usize = 9;
    for delta in [0.0f32, 0.02] {
        let (estimates, plain) = control_variate_runs(delta, RUNS, STEPS);
        let mut ratios = Vec::new();
        for i in 0..STEPS {
            let ((_, vf), (_, vg)) = (moments(&estimates[i]), moments(&plain[i]));
            ratios.push(vf.iter().sum::<f64>() / vg.iter().sum::<f64>());
        }
        println!("δ = {delta}: Var F_i / Var G_i for i = 0..{STEPS}: {ratios:.3?}");
        let k = STEPS - 1;
        let ((mf, vf), (mg, vg)) = (moments(&estimates[k]), moments(&plain[k]));
        let tests = mf.len();
        let alpha = 0.001 / tests as f64;
        let n = f64::from(RUNS);
        let mut worst = 1.0f64;
        for p in 0..tests {
            let se2 = vf[p] / n + vg[p] / n;
            if se2 == 0.0 {
                assert_eq!(mf[p], mg[p], "value {p}: no noise, equal means");
                continue;
            }
            let t = (mf[p] - mg[p]) / se2.sqrt();
            let dof = se2.powi(2) / ((vf[p] / n).powi(2) / (n - 1.0) + (vg[p] / n).powi(2) / (n - 1.0));
            let pv = pathgrad::stats::student_t_two_sided(t, dof);
            worst = worst.min(pv);
            assert!(pv > alpha, "δ = {delta}, value {p}: F {} vs plain {} (t = {t:.2}, p = {pv:.2e})", mf[p], mg[p]);
        }
        // Power: the image mean of F_k is known to 1 %.
        let means: Vec<f64> =
            estimates[k].iter().map(|i| i.iter().map(|&v| f64::from(v)).sum::<f64>() / i.len() as f64).collect();
        let m = means.iter().sum::<f64>() / n;
        let se = (means.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0) / n).sqrt();
        assert!(se < 0.01 * m, "δ = {delta}: the image mean {m} has standard error {se}: too weak a test");
        println!(
            "δ = {delta}: smallest p over {tests} values {worst:.3e} (level {alpha:.1e}); image mean {m:.4} ± {se:.4}"
        );
        if delta > 0.0 {
            assert!(ratios[k] < 0.8, "δ = {delta}: Var F / Var G = {} at step {k}", ratios[k]);
        }
    }
}

/// Runs of the gradient-reuse estimate along a fixed trajectory of the blend weight
/// (θ_i = 0.8 − δ·i; L2 loss against the scene at weight 0.2), G_i and H_i the kernels' loss
/// gradients (pass 1 and gradient pass, 4 spp each, 32×24) with seed base + i: returns, per run, the
/// estimate F_i after each of `steps` steps and a plain gradient at θ_i with seed base + 500 + i.
fn gradient_reuse_runs(delta: f32, runs: u32, steps: usize) -> (Vec<Vec<f64>>, Vec<Vec<f64>>) {
    let gpu = TestGpu::new();
    let scene = builtin::load("blend").unwrap();
    let mut renderer = Renderer::new(&gpu.ctx, &scene).unwrap();
    let options = ControlVariateOptions::default();
    let id = scene.params.find("object.weight.value").unwrap();
    let mut table = scene.params.clone();
    table.set("object.weight.value", &[0.2]).unwrap();
    renderer.set_params(&table).unwrap();
    let base = RenderOptions { width: 32, height: 24, spp: 4, ..RenderOptions::for_scene(&scene) };
    let target = renderer.render(&RenderOptions { spp: 64, seed: 99_999, ..base }).unwrap();
    let view = View::current(&scene);
    let mut gradient = |table: &ParamTable, seed: u32| -> Gradients {
        renderer.set_params(table).unwrap();
        let at = RenderOptions { seed, ..base };
        let views = [view];
        renderer
            .loss_and_gradient_views(&at, 4, &views, std::slice::from_ref(&target), Loss::L2, GradMode::Float)
            .unwrap()
            .1
    };
    let (mut estimates, mut plain) = (vec![Vec::new(); steps], vec![Vec::new(); steps]);
    for run in 0..runs {
        let mut state: Option<RunningEstimate> = None;
        for i in 0..steps {
            let seed = 1000 * run + i as u32;
            let h = (i > 0).then(|| {
                table.set("object.weight.value", &[0.8 - delta * (i - 1) as f32]).unwrap();
                gradient(&table, seed)
            });
            table.set("object.weight.value", &[0.8 - delta * i as f32]).unwrap();
            let g = gradient(&table, seed);
            let (f, next) = gradient_reuse::step(&options, state.as_ref(), &table, &[id], &g, h.as_ref()).unwrap();
            state = Some(next);
            estimates[i].push(f64::from(f.get("object.weight.value").unwrap()[0]));
            // A plain gradient at θ_i on paths of its own (independent of every F).
            plain[i].push(f64::from(gradient(&table, seed + 500).get("object.weight.value").unwrap()[0]));
        }
    }
    (estimates, plain)
}

/// The gradient-reuse estimate F_k after k = 8 steps along a fixed trajectory has the expectation
/// of a plain gradient at θ_k: the mean of F_k over 128 runs against the mean of the runs'
/// independent plain gradients at θ_k, Welch's t at level 0.001, for a still (δ = 0) and a moving
/// (δ = 0.02) trajectory. Power check: the standard error of the difference is below 5 % of the
/// plain mean, so a bias of a quarter (|t| > 5) fails, e.g. F ← v(F + H) + G. And the
/// estimate is less noisy: Var F_8 below 0.8× the plain gradient's on the moving trajectory
/// (ratios per step printed; BENCHMARKS.md).
#[test]
fn the_gradient_reuse_estimate_is_unbiased_along_a_trajectory_and_less_noisy() {
    const RUNS: u32 = 128;
    const STEPS: usize = 9;
    let moments = |x: &[f64]| {
        let n = x.len() as f64;
        let m = x.iter().sum::<f64>() / n;
        (m, x.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (n - 1.0))
    };
    for delta in [0.0f32, 0.02] {
        let (estimates, plain) = gradient_reuse_runs(delta, RUNS, STEPS);
        let ratios: Vec<f64> = (0..STEPS).map(|i| moments(&estimates[i]).1 / moments(&plain[i]).1).collect();
        println!("δ = {delta}: Var F_i / Var G_i for i = 0..{STEPS}: {ratios:.3?}");
        let k = STEPS - 1;
        let ((mf, vf), (mg, vg)) = (moments(&estimates[k]), moments(&plain[k]));
        let n = f64::from(RUNS);
        let se = (vf / n + vg / n).sqrt();
        let t = (mf - mg) / se;
        let dof = se.powi(4) / ((vf / n).powi(2) / (n - 1.0) + (vg / n).powi(2) / (n - 1.0));
        let p = pathgrad::stats::student_t_two_sided(t, dof);
        println!("δ = {delta}: F_8 {mf:.5e} vs plain {mg:.5e}, t = {t:.2}, p = {p:.3e}, se {se:.2e}");
        assert!(p > 0.001, "δ = {delta}: F_8 {mf} vs plain {mg} (t = {t:.2}, p = {p:.2e})");
        assert!(se < 0.05 * mg.abs(), "δ = {delta}: standard error {se} against a mean of {mg}: too weak a test");
        if delta > 0.0 {
            assert!(ratios[k] < 0.8, "δ = {delta}: Var F / Var G = {} at step {k}", ratios[k]);
        }
    }
}

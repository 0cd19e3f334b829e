//! Inverse rendering end to end (`pathgrad::optim`): an iteration is pass 1 at spp_primal and the
//! gradient pass at spp_grad with seed base + t; short optimisations on small scenes recover a
//! roughness and a blend weight, and a negative control with the gradient's sign flipped fails
//! the same criterion.

use pathgrad::backend::Backend;
use pathgrad::gpu::Renderer;
use pathgrad::gpu::renderer::GradMode;
use pathgrad::integrator::RenderOptions;
use pathgrad::loss::{Loss, loss_and_adjoint};
use pathgrad::optim::{AdamOptions, IterationOptions, Optimization};
use pathgrad::params::Gradients;
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

/// Iteration t of [`Optimization`] is, bit for bit (fixed-point gradients), pass 1 rendered with
/// spp_primal samples and seed base + t, the loss and adjoint on the host, and the gradient pass
/// with spp_grad samples and the same seed — also after a step changed the parameters.
#[test]
fn an_iteration_is_pass_one_at_spp_primal_then_the_gradient_at_spp_grad_with_seed_base_plus_t() {
    let gpu = TestGpu::new();
    if !gpu.ctx.info().int64_atomics {
        return;
    }
    let scene = builtin::load("blend").unwrap();
    let mut renderer = Renderer::new(&gpu.ctx, &scene).unwrap();
    let render = RenderOptions { width: 16, height: 12, spp: 1, seed: 7, ..RenderOptions::for_scene(&scene) };
    let target = renderer.render(&RenderOptions { spp: 8, seed: 99, ..render }).unwrap();
    let mut start = scene.params.clone();
    start.set("object.weight.value", &[0.8]).unwrap();
    let id = start.find("object.weight.value").unwrap();
    let mode = GradMode::Deterministic;
    let options = IterationOptions { render, spp_primal: 3, adaptive: None, loss: Loss::RelMse, mode };
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
    let options = IterationOptions { render, spp_primal: 16, adaptive: None, loss: Loss::RelMse, mode };
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

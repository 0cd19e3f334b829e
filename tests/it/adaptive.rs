//! Loss-aware adaptive pixel sampling (ALGORITHMS.md §6): the device's pixel draws against the
//! host's, adaptive gradients on the GPU against the CPU twin, and adaptive loss gradients
//! against uniform sampling.

use glam::Vec3;
use pathgrad::adaptive::{AdaptiveEstimator, AdaptiveOptions, PixelSampling, select_pixel};
use pathgrad::backend::Backend;
use pathgrad::contract::{AliasEntry, BINDING_ALIAS, BINDING_PROBE_OUT};
use pathgrad::cpu::path::{GradSink, trace_path};
use pathgrad::gpu::pipeline::groups_for;
use pathgrad::gpu::renderer::GradMode;
use pathgrad::gpu::{Buffer, Kernel, Renderer};
use pathgrad::image::Image;
use pathgrad::integrator::RenderOptions;
use pathgrad::loss::{Loss, loss_and_adjoint};
use pathgrad::rng::{PassTag, RngKey};
use pathgrad::scene::flat::FlatScene;
use pathgrad::scene::{Scene, builtin};

use crate::support::{TestGpu, scenes};

/// An adjoint image with structure: strong around one point, weak elsewhere, zero on every 7th
/// diagonal, both signs, so adaptive weights are far from uniform and some pixels cannot be drawn.
fn peaked_adjoint(w: u32, h: u32) -> Image {
    let mut data = Vec::new();
    for y in 0..h {
        for x in 0..w {
            let r = ((x as f32 - 0.3 * w as f32).powi(2) + (y as f32 - 0.6 * h as f32).powi(2)).sqrt();
            let v = if (x + y) % 7 == 0 { 0.0 } else { 2.0 * (-r / 4.0).exp() + 0.05 * (x as f32 * 0.7).sin() };
            data.extend_from_slice(&[v, -0.5 * v, 0.25 * v]);
        }
    }
    Image::from_rgb(w, h, data).unwrap()
}

/// `select_pixel` in `shaders/lib/alias.glsl` draws the same pixel as `src/adaptive.rs` for every
/// sample k, bit for bit, on a table whose size does not divide 2²³ (so the f32 column arithmetic
/// matters) and with zero-weight pixels.
#[test]
fn pixel_selection_gpu_equals_cpu_bitwise() {
    let gpu = TestGpu::new();
    let (w, h) = (37, 23);
    let sampling = PixelSampling::from_adjoint(&peaked_adjoint(w, h), AdaptiveEstimator::Importance).unwrap();
    let table = sampling.table();
    let entries: Vec<AliasEntry> =
        table.prob().iter().zip(table.alias()).map(|(&prob, &alias)| AliasEntry { prob, alias }).collect();
    let samples = w * h * 16;
    let key = RngKey::new(12_345, 7, PassTag::Gradient);
    let alias_buf = Buffer::storage_with(&gpu.ctx, "alias table", &entries).unwrap();
    let output = Buffer::storage(&gpu.ctx, "alias probe output", u64::from(samples) * 4).unwrap();
    let kernel = Kernel::new(&gpu.ctx, "alias_probe", &[BINDING_ALIAS, BINDING_PROBE_OUT], 16).unwrap();
    let group = kernel.bind(&[(BINDING_ALIAS, &alias_buf), (BINDING_PROBE_OUT, &output)]).unwrap();
    let push = pathgrad::contract::AliasProbePush {
        key: glam::UVec2::new(key.0[0], key.0[1]),
        table_size: w * h,
        sample_count: samples,
    };
    gpu.ctx
        .submit_and_wait("alias probe", |cmd| {
            kernel.record(cmd, &group, bytemuck::bytes_of(&push), groups_for(samples))
        })
        .unwrap();
    let got: Vec<u32> = output.download(samples as usize).unwrap();
    let mut zero_weight_hits = 0;
    for (k, &p) in got.iter().enumerate() {
        assert_eq!(p, select_pixel(table, key, k as u32), "sample {k}");
        if sampling.probability(p) == 0.0 {
            zero_weight_hits += 1;
        }
    }
    assert_eq!(zero_weight_hits, 0);
    let distinct = {
        let mut v = got.clone();
        v.sort_unstable();
        v.dedup();
        v.len()
    };
    println!("{samples} draws, {distinct} distinct pixels of {}", w * h);
}

/// Per sample k of an adaptive pass on the CPU, as `cpu::backward_adaptive` does it: its gradient
/// contribution, summed (the gradient) and summed in absolute value per parameter value (the scale
/// that rounding differences are measured against).
fn per_sample_sums(
    scene: &Scene,
    opts: &RenderOptions,
    adjoint: &Image,
    sampling: &PixelSampling,
) -> (Vec<f64>, Vec<f64>) {
    let flat = FlatScene::new(scene).unwrap();
    let mut globals = opts.globals(scene, &flat, PassTag::Gradient);
    globals.adjoint_scale = 1.0;
    let delta = sampling.sample_adjoint(opts, adjoint).unwrap();
    let key = RngKey([globals.key0, globals.key1]);
    let camera = opts.view_camera(&pathgrad::integrator::View::current(scene), PassTag::Gradient);
    let n = flat.params.len();
    let (mut sum, mut abs) = (vec![0.0f64; n], vec![0.0f64; n]);
    for k in 0..sampling.sample_count(opts).unwrap() {
        let p = select_pixel(sampling.table(), key, k);
        let adj = Vec3::from_slice(&delta.as_slice()[3 * p as usize..3 * p as usize + 3]);
        let total = trace_path::<false>(
            &flat,
            &globals,
            &camera,
            p,
            k,
            Vec3::ZERO,
            Vec3::ZERO,
            &mut GradSink::None,
            &mut Default::default(),
        );
        let mut term = vec![0.0f64; n];
        trace_path::<true>(
            &flat,
            &globals,
            &camera,
            p,
            k,
            adj,
            total,
            &mut GradSink::Backward(&mut term),
            &mut Default::default(),
        );
        for i in 0..n {
            sum[i] += term[i];
            abs[i] += term[i].abs();
        }
    }
    (sum, abs)
}

/// Adaptive gradients on the GPU (float atomics) equal the CPU twin's for both estimators on three
/// scenes. Tolerance as for uniform passes (`gradients.rs`): a sample's contribution agrees to
/// 1e-4 relative per term, 1e-3 of its own size after cancellation inside the sample, so a
/// parameter value's total agrees to 1e-3 · Σ_k |contribution_k|, computed here per sample.
#[test]
fn adaptive_gradients_gpu_equal_cpu() {
    let gpu = TestGpu::new();
    let cases =
        [builtin::load("cornell-box").unwrap(), builtin::load("blend").unwrap(), scenes::textured_environment()];
    for scene in &cases {
        let opts = RenderOptions { width: 40, height: 32, spp: 2, seed: 21, ..RenderOptions::for_scene(scene) };
        let adjoint = peaked_adjoint(opts.width, opts.height);
        let mut renderer = Renderer::new(&gpu.ctx, scene).unwrap();
        for estimator in [AdaptiveEstimator::Importance, AdaptiveEstimator::PixelMean] {
            let sampling = PixelSampling::from_adjoint(&adjoint, estimator).unwrap();
            let g = renderer.backward_adaptive(&opts, &adjoint, &sampling, GradMode::Float).unwrap();
            let c = pathgrad::cpu::backward_adaptive(scene, &opts, &adjoint, &sampling).unwrap();
            let (sum, abs) = per_sample_sums(scene, &opts, &adjoint, &sampling);
            let mut nonzero = 0;
            for (i, ((gv, cv), (s, a))) in g.values().iter().zip(&c).zip(sum.iter().zip(&abs)).enumerate() {
                // The twin and the per-sample loop differ only by the order of f64 sums.
                assert!((cv - s).abs() <= 1e-9 * a, "{} value {i}: cpu {cv} vs per-sample {s}", scene.source);
                assert!(
                    (f64::from(*gv) - cv).abs() <= 1e-3 * a,
                    "{} {} value {i}: GPU {gv} vs CPU {cv} (scale {a})",
                    scene.source,
                    estimator.name()
                );
                if cv.abs() > 1e-3 * a && *a > 0.0 {
                    nonzero += 1;
                }
            }
            println!("{} {}: {nonzero} of {} values nonzero and matched", scene.source, estimator.name(), c.len());
            assert!(nonzero >= 3, "{}: too few nonzero gradient values to compare", scene.source);
        }
    }
}

/// Deterministic mode works for adaptive passes: two runs are bitwise equal and agree with float
/// atomics to rounding (1e-4 of the largest value, as for uniform passes). A loss that is zero in
/// every pixel gives a zero gradient; a pixel sampling of another size is refused with a message
/// naming both sizes.
#[test]
fn adaptive_deterministic_gradients_are_bitwise_reproducible() {
    let gpu = TestGpu::new();
    let scene = builtin::load("cornell-box").unwrap();
    let opts = RenderOptions { width: 40, height: 40, spp: 4, seed: 2, ..RenderOptions::for_scene(&scene) };
    let mut renderer = Renderer::new(&gpu.ctx, &scene).unwrap();
    let adjoint = peaked_adjoint(opts.width, opts.height);
    let sampling = PixelSampling::from_adjoint(&adjoint, AdaptiveEstimator::Importance).unwrap();
    let a = renderer.backward_adaptive(&opts, &adjoint, &sampling, GradMode::Deterministic).unwrap();
    let b = renderer.backward_adaptive(&opts, &adjoint, &sampling, GradMode::Deterministic).unwrap();
    let bits = |g: &pathgrad::params::Gradients| g.values().iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&a), bits(&b));
    let f = renderer.backward_adaptive(&opts, &adjoint, &sampling, GradMode::Float).unwrap();
    let largest = a.values().iter().fold(0.0f32, |m, v| m.max(v.abs()));
    assert!(largest > 0.0);
    for (x, y) in a.values().iter().zip(f.values()) {
        assert!((x - y).abs() <= 1e-4 * largest, "fixed {x} vs float {y}");
    }
    // A target equal to pass 1's render: the adjoint is zero everywhere, so is the gradient.
    let adaptive = AdaptiveOptions { spp_primal: 3, estimator: AdaptiveEstimator::Importance };
    let target = renderer.render(&RenderOptions { spp: 3, ..opts }).unwrap();
    let (loss, g) =
        renderer.loss_and_gradient_adaptive(&opts, &adaptive, &target, Loss::RelMse, GradMode::Deterministic).unwrap();
    assert_eq!(loss, 0.0);
    assert!(g.values().iter().all(|&v| v == 0.0));
    let other = PixelSampling::uniform(40, 39, AdaptiveEstimator::Importance).unwrap();
    let e = renderer.backward_adaptive(&opts, &adjoint, &other, GradMode::Float).unwrap_err().to_string();
    assert!(e.contains("40×39") && e.contains("40×40"), "{e}");
}

/// Mean and variance (n − 1) of `v`.
fn mean_var(v: &[f64]) -> (f64, f64) {
    let m = v.iter().sum::<f64>() / v.len() as f64;
    (m, v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (v.len() as f64 - 1.0))
}

/// Adaptive loss gradients are unbiased against uniform sampling (ALGORITHMS.md §6, §10). On the
/// Cornell box at 32×32 the target is rendered with the white walls darker and the sphere rougher,
/// so the relative-MSE adjoint image A is far from uniform. Estimators of the loss gradient by
/// `white.reflectance` and by the light's radiance (each summed over channels), each over M seeds
/// independent of the others' (pass 1 at 2 spp, gradient pass at N = W·H·2 samples):
///   uniform   `loss_and_gradient`                                  seeds 0..M
///   adaptive  `loss_and_gradient_adaptive`, π ∝ Σ_c |A_pc|         seeds 1000..1000+M
///   flat      pass 1, then `backward_adaptive` with uniform weights seeds 2000..2000+M
/// have the same expectation. Test: the Welch statistic |m_a − m_b| / √(s_a²/M + s_b²/M) < 4 for
/// adaptive and for flat against uniform, per parameter (4 comparisons; with ~2(M−1) degrees of
/// freedom each has a false-alarm rate of about 3e-4).
/// Power: each uniform mean must lie at least 8 of the comparison's standard errors from 0 (a bias
/// of half the gradient would fail the test), and a negative control — adaptive draws whose δL
/// forgets the density, A_p/spp instead of A_p/(N·π_p), seeds 3000..3000+M — must fail it (Welch
/// above 4 for some parameter).
#[test]
fn adaptive_loss_gradients_are_unbiased_against_uniform() {
    const SEEDS: u32 = 24;
    const WELCH_LIMIT: f64 = 4.0;
    let gpu = TestGpu::new();
    let scene = builtin::load("cornell-box").unwrap();
    let params = ["white.reflectance.value", "light.emitter.radiance.value"];
    let opts = RenderOptions { width: 32, height: 32, spp: 2, ..RenderOptions::for_scene(&scene) };
    let adaptive = AdaptiveOptions { spp_primal: opts.spp, estimator: AdaptiveEstimator::Importance };
    let mut renderer = Renderer::new(&gpu.ctx, &scene).unwrap();
    let mut perturbed = scene.params.clone();
    perturbed.set("white.reflectance.value", &[0.45, 0.44, 0.42]).unwrap();
    perturbed.set("sphere.bsdf.alpha.value", &[0.5]).unwrap();
    renderer.set_params(&perturbed).unwrap();
    let target = renderer.render(&RenderOptions { spp: 64, seed: 777, ..opts }).unwrap();
    renderer.set_params(&scene.params).unwrap();
    let scalars = |g: &pathgrad::params::Gradients| -> Vec<f64> {
        params.iter().map(|n| g.get(n).unwrap().iter().map(|&v| f64::from(v)).sum()).collect()
    };
    let start = std::time::Instant::now();
    let (mut uniform, mut adapt, mut flat, mut wrong) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for i in 0..SEEDS {
        let (_, g) = renderer
            .loss_and_gradient(&RenderOptions { seed: i, ..opts }, &target, Loss::RelMse, GradMode::Float)
            .unwrap();
        uniform.push(scalars(&g));
        let o = RenderOptions { seed: 1000 + i, ..opts };
        let (_, g) =
            renderer.loss_and_gradient_adaptive(&o, &adaptive, &target, Loss::RelMse, GradMode::Float).unwrap();
        adapt.push(scalars(&g));
        let o = RenderOptions { seed: 2000 + i, ..opts };
        let (_, adjoint) = loss_and_adjoint(&renderer.render(&o).unwrap(), &target, Loss::RelMse).unwrap();
        let sampling = PixelSampling::uniform(opts.width, opts.height, AdaptiveEstimator::Importance).unwrap();
        flat.push(scalars(&renderer.backward_adaptive(&o, &adjoint, &sampling, GradMode::Float).unwrap()));
        // The negative control: an adjoint image pre-multiplied by N·π_p/spp makes δL = A_p/spp.
        let o = RenderOptions { seed: 3000 + i, ..opts };
        let (_, adjoint) = loss_and_adjoint(&renderer.render(&o).unwrap(), &target, Loss::RelMse).unwrap();
        let sampling = PixelSampling::from_adjoint(&adjoint, AdaptiveEstimator::Importance).unwrap();
        let n = f64::from(sampling.sample_count(&o).unwrap());
        let data = adjoint
            .as_slice()
            .iter()
            .enumerate()
            .map(|(v, &a)| (f64::from(a) * n * sampling.probability(v as u32 / 3) / f64::from(o.spp)) as f32)
            .collect();
        let forgetful = Image::from_rgb(o.width, o.height, data).unwrap();
        wrong.push(scalars(&renderer.backward_adaptive(&o, &forgetful, &sampling, GradMode::Float).unwrap()));
    }
    println!("{SEEDS} seeds × 4 estimators in {:.1} s", start.elapsed().as_secs_f64());
    let m = f64::from(SEEDS);
    let mut control_caught = false;
    for (j, name) in params.iter().enumerate() {
        let column = |v: &[Vec<f64>]| mean_var(&v.iter().map(|x| x[j]).collect::<Vec<_>>());
        let (mu, vu) = column(&uniform);
        for (label, other) in [("adaptive", &adapt), ("flat", &flat), ("negative control", &wrong)] {
            let (mo, vo) = column(other);
            let se = ((vu + vo) / m).sqrt();
            let welch = (mo - mu).abs() / se;
            println!(
                "{name}: uniform {mu:.4e} ± {:.2e}, {label} {mo:.4e} ± {:.2e}, Welch {welch:.2}, |uniform|/SE {:.1}",
                (vu / m).sqrt(),
                (vo / m).sqrt(),
                mu.abs() / se
            );
            if label == "negative control" {
                control_caught |= welch > WELCH_LIMIT;
                continue;
            }
            assert!(welch < WELCH_LIMIT, "{name}: {label} {mo} vs uniform {mu} ({welch:.1} standard errors)");
            assert!(
                mu.abs() > 8.0 * se,
                "{name}: the gradient is not clearly nonzero ({mu} ± {se}), the test has no power"
            );
        }
    }
    assert!(control_caught, "an adaptive pass that forgets its sampling density passed the test: it has no power");
}

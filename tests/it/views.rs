//! Multi-view requests: several sensors rendered and differentiated in one pass on one uploaded
//! scene, against the same sensors rendered one at a time.

use glam::Vec3;
use pathgrad::backend::Backend;
use pathgrad::cpu::Reference;
use pathgrad::gpu::Renderer;
use pathgrad::gpu::renderer::GradMode;
use pathgrad::image::Image;
use pathgrad::integrator::{RenderOptions, View};
use pathgrad::loss::Loss;
use pathgrad::params::Gradients;
use pathgrad::scene::{Scene, Sensor, builtin};

use crate::support::TestGpu;

/// The Cornell box with a second sensor beside the first, looking at the same point.
fn two_sensors() -> Scene {
    let mut scene = builtin::load("cornell-box").unwrap();
    let mut side = scene.camera;
    let offset = (side.target - side.position).length() * 0.3;
    side.position += Vec3::new(offset, 0.5 * offset, 0.0);
    scene.sensors.push(Sensor { name: "side".into(), camera: side });
    scene
}

/// `scene` with sensor `index` chosen, as `--sensor` loads it.
fn chosen(scene: &Scene, index: usize) -> Scene {
    let mut s = scene.clone();
    s.camera = s.sensors[index].camera;
    s.sensor = index;
    s
}

fn options(scene: &Scene) -> RenderOptions {
    RenderOptions { width: 24, height: 20, spp: 2, seed: 3, ..RenderOptions::for_scene(scene) }
}

fn views(scene: &Scene) -> Vec<View> {
    (0..2).map(|i| View::sensor(scene, i).unwrap()).collect()
}

/// Targets of both views at other albedos, rendered under the reference key.
fn targets(backend: &mut dyn Backend, opts: &RenderOptions) -> Vec<Image> {
    let scene = backend.scene().clone();
    let mut truth = scene.params.clone();
    truth.set("red.reflectance.value", &[0.3, 0.6, 0.2]).unwrap();
    truth.set("white.reflectance.value", &[0.5, 0.5, 0.5]).unwrap();
    backend.set_params(&truth).unwrap();
    let reference = RenderOptions { spp: 8, seed: 77, ..*opts };
    let images = backend.render_views(&reference, &views(&scene), pathgrad::rng::PassTag::Reference, &mut |_, _| {});
    backend.set_params(&scene.params).unwrap();
    images.unwrap()
}

fn bits(image: &Image) -> Vec<u32> {
    image.as_slice().iter().map(|v| v.to_bits()).collect()
}

/// Each view of a two-view render is, bit for bit, the render of its sensor alone (GPU and CPU);
/// the views differ from each other, and so does the same camera in another stream; the GPU's
/// views agree with the CPU's like single renders do (cpu_vs_gpu.rs: 1e-4 relative per value,
/// a budget of 1e-3 of the values for paths whose decisions a few ulps tip).
#[test]
fn views_render_like_their_sensors_alone() {
    let gpu = TestGpu::new();
    let scene = two_sensors();
    let opts = options(&scene);
    let mut renderer = Renderer::new(&gpu.ctx, &scene).unwrap();
    let mut cpu = Reference::new(&scene).unwrap();
    let pass = pathgrad::rng::PassTag::Primal;
    let both = renderer.render_views(&opts, &views(&scene), pass, &mut |_, _| {}).unwrap();
    let both_cpu = cpu.render_views(&opts, &views(&scene), pass, &mut |_, _| {}).unwrap();
    assert_eq!(both.len(), 2);
    for i in 0..2 {
        let alone = Renderer::new(&gpu.ctx, &chosen(&scene, i)).unwrap().render(&opts).unwrap();
        assert_eq!(bits(&both[i]), bits(&alone), "GPU view {i}");
        let alone_cpu = Reference::new(&chosen(&scene, i)).unwrap().render(&opts).unwrap();
        assert_eq!(bits(&both_cpu[i]), bits(&alone_cpu), "CPU view {i}");
        let mismatched = both[i]
            .as_slice()
            .iter()
            .zip(both_cpu[i].as_slice())
            .filter(|(a, b)| (*a - *b).abs() > 1e-4 * a.abs().max(b.abs()) + 1e-6)
            .count();
        assert!(
            mismatched as f64 <= 1e-3 * both[i].as_slice().len() as f64,
            "view {i}: {mismatched} GPU/CPU mismatches"
        );
    }
    assert_ne!(bits(&both[0]), bits(&both[1]), "the two sensors see different images");
    let other_stream = View { stream: 5, ..View::sensor(&scene, 0).unwrap() };
    let streamed = renderer.render_views(&opts, &[other_stream], pass, &mut |_, _| {}).unwrap();
    assert_ne!(bits(&streamed[0]), bits(&both[0]), "a view's stream is in its paths' key");
}

/// A two-view step's loss is the mean of the views' losses, and its gradient the mean of the
/// single-view gradients of the same sensors: bit for bit in deterministic mode (fixed-point sums
/// on the GPU, f64 fixed-order sums on the CPU), to float-atomic rounding otherwise (1e-4 of the
/// largest value, as deterministic vs float in gradients.rs).
#[test]
fn a_two_view_gradient_is_the_mean_of_single_view_gradients() {
    let gpu = TestGpu::new();
    let scene = two_sensors();
    let opts = options(&scene);
    // (a backend on both sensors, one backend per sensor chosen alone)
    type Cases = Vec<(Box<dyn Backend>, Vec<Box<dyn Backend>>)>;
    let mut backends: Cases = vec![
        (
            Box::new(Renderer::new(&gpu.ctx, &scene).unwrap()),
            (0..2)
                .map(|i| Box::new(Renderer::new(&gpu.ctx, &chosen(&scene, i)).unwrap()) as Box<dyn Backend>)
                .collect(),
        ),
        (
            Box::new(Reference::new(&scene).unwrap()),
            (0..2).map(|i| Box::new(Reference::new(&chosen(&scene, i)).unwrap()) as Box<dyn Backend>).collect(),
        ),
    ];
    for (both, alone) in &mut backends {
        let targets = targets(both.as_mut(), &opts);
        for mode in [GradMode::Deterministic, GradMode::Float] {
            let (loss, gradient) =
                both.loss_and_gradient_views(&opts, 3, &views(&scene), &targets, Loss::RelMse, mode).unwrap();
            let singles: Vec<(f64, Gradients)> = alone
                .iter_mut()
                .zip(&targets)
                .map(|(b, t)| b.loss_and_gradient_split(&opts, 3, t, Loss::RelMse, mode).unwrap())
                .collect();
            let what = format!("{} {mode:?}", both.describe());
            assert_eq!(loss, (singles[0].0 + singles[1].0) / 2.0, "{what}: loss");
            assert_ne!(singles[0].1.values(), singles[1].1.values(), "{what}: the views' gradients differ");
            let mean = Gradients::mean(&[singles[0].1.clone(), singles[1].1.clone()]).unwrap();
            if mode == GradMode::Deterministic || both.describe() == "CPU reference" {
                assert_eq!(gradient, mean, "{what}: gradient");
            } else {
                let largest = mean.values().iter().fold(0.0f32, |m, v| m.max(v.abs()));
                assert!(largest > 0.0);
                for (a, b) in gradient.values().iter().zip(mean.values()) {
                    assert!((a - b).abs() <= 1e-4 * largest, "{what}: {a} vs {b}");
                }
            }
        }
    }
}

/// Adaptive pixel sampling over two views: the GPU's deterministic gradient agrees with the CPU
/// twin's, which draws the same (view, pixel) for every sample (1e-3 of the largest value: the
/// per-path agreement of gradients.rs), and the samples land in both views.
#[test]
fn adaptive_sampling_draws_over_every_view() {
    use pathgrad::adaptive::{AdaptiveEstimator, AdaptiveOptions, PixelSampling};
    let gpu = TestGpu::new();
    let scene = two_sensors();
    let opts = options(&scene);
    let mut renderer = Renderer::new(&gpu.ctx, &scene).unwrap();
    let mut cpu = Reference::new(&scene).unwrap();
    let targets = targets(&mut renderer, &opts);
    let adaptive = AdaptiveOptions { spp_primal: 3, estimator: AdaptiveEstimator::Importance };
    let (loss_g, g) = renderer
        .loss_and_gradient_views_adaptive(
            &opts,
            &adaptive,
            &views(&scene),
            &targets,
            Loss::RelMse,
            GradMode::Deterministic,
        )
        .unwrap();
    let (loss_c, c) = cpu
        .loss_and_gradient_views_adaptive(
            &opts,
            &adaptive,
            &views(&scene),
            &targets,
            Loss::RelMse,
            GradMode::Deterministic,
        )
        .unwrap();
    assert!((loss_g - loss_c).abs() <= 1e-4 * loss_c.abs(), "loss GPU {loss_g} vs CPU {loss_c}");
    let largest = c.values().iter().fold(0.0f32, |m, v| m.max(v.abs()));
    assert!(largest > 0.0);
    for (a, b) in g.values().iter().zip(c.values()) {
        assert!((a - b).abs() <= 1e-3 * largest, "GPU {a} vs CPU {b}");
    }
    // Both views' pixels carry weight, so the alias table draws from both halves of the stack.
    let (_, adjoints) = cpu.loss_images(&opts, 3, &views(&scene), &targets, Loss::RelMse).unwrap();
    let sampling = PixelSampling::from_adjoint(&Image::stack(&adjoints).unwrap(), adaptive.estimator).unwrap();
    let pixels = opts.width * opts.height;
    let half = |range: std::ops::Range<u32>| range.map(|p| sampling.probability(p)).sum::<f64>();
    assert!(half(0..pixels) > 0.05 && half(pixels..2 * pixels) > 0.05);
}

/// Bad requests name what is wrong: no views, targets not one per view, a sensor past the list.
#[test]
fn bad_view_requests_are_refused() {
    let scene = two_sensors();
    let opts = options(&scene);
    let mut cpu = Reference::new(&scene).unwrap();
    let pass = pathgrad::rng::PassTag::Primal;
    let e = cpu.render_views(&opts, &[], pass, &mut |_, _| {}).unwrap_err().to_string();
    assert!(e.contains("at least one view"), "{e}");
    let target = Image::new(opts.width, opts.height);
    let e = cpu
        .loss_and_gradient_views(&opts, 2, &views(&scene), &[target], Loss::L2, GradMode::Float)
        .unwrap_err()
        .to_string();
    assert!(e.contains("1 given for 2 views"), "{e}");
    let e = View::sensor(&scene, 2).unwrap_err().to_string();
    assert!(e.contains("sensor 2 does not exist"), "{e}");
}

const TWO_SIDED: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/two-sided/scene.xml");
const TRUTH: [&str; 4] =
    ["--target-set", "front.reflectance.value=0.7,0.3,0.2", "--target-set", "back.reflectance.value=0.2,0.4,0.7"];

fn run_json(args: &[&str]) -> serde_json::Value {
    let o = crate::cli::pathgrad().args(args).output().unwrap();
    assert!(o.status.success(), "{args:?}: {}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_slice(&o.stdout).unwrap()
}

/// `grad --view A --view B` reports the mean of `grad --sensor A` and `grad --sensor B`: the loss
/// to f64 rounding, the gradients to the f32 rounding of the printed values (deterministic mode).
#[test]
fn grad_over_two_views_is_the_mean_of_each_sensor_alone() {
    let common = ["grad", TWO_SIDED, "--width", "12", "--height", "12", "--spp", "2", "--deterministic", "--json"];
    let with = |extra: &[&str]| run_json(&[&common[..], &TRUTH[..], extra].concat());
    let both = with(&["--view", "front_camera", "--view", "back_camera"]);
    let alone = [with(&["--sensor", "front_camera"]), with(&["--sensor", "1"])];
    let loss = |v: &serde_json::Value| v["loss"].as_f64().unwrap();
    let mean = (loss(&alone[0]) + loss(&alone[1])) / 2.0;
    assert!((loss(&both) - mean).abs() <= 1e-12 * mean, "{} vs {mean}", loss(&both));
    for name in ["front.reflectance.value", "back.reflectance.value"] {
        let values = |v: &serde_json::Value| -> Vec<f64> {
            v["gradients"][name].as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect()
        };
        let (a, b) = (values(&alone[0]), values(&alone[1]));
        for (i, g) in values(&both).iter().enumerate() {
            let m = (a[i] + b[i]) / 2.0;
            assert!((g - m).abs() <= 1e-6 * m.abs().max(1e-6), "{name}[{i}]: {g} vs {m}");
        }
        // Each panel is seen by one camera only.
        assert!(a.iter().all(|&v| v == 0.0) != b.iter().all(|&v| v == 0.0), "{name}: {a:?} {b:?}");
    }
}

/// Two views recover both panels' albedos; one view leaves the panel it cannot see where it was.
#[test]
fn optimize_over_two_views_recovers_what_one_view_cannot() {
    let dir = tempfile::tempdir().unwrap();
    let common = [
        "optimize",
        TWO_SIDED,
        "--param",
        "front.reflectance.value=0.5",
        "--param",
        "back.reflectance.value=0.5",
        "--iters",
        "60",
        "--lr",
        "0.03",
        "--width",
        "16",
        "--height",
        "16",
        "--json",
        "-o",
    ];
    let two_dir = dir.path().join("two");
    let two = run_json(
        &[&common[..], &[two_dir.to_str().unwrap()], &TRUTH[..], &["--view", "front_camera", "--view", "back_camera"]]
            .concat(),
    );
    let one_dir = dir.path().join("one");
    let one = run_json(&[&common[..], &[one_dir.to_str().unwrap()], &TRUTH[..]].concat());
    println!("param error: two views {}, one view {}", two["param_error"], one["param_error"]);
    assert!(two["param_error"].as_f64().unwrap() < 0.01, "{two}");
    assert_eq!(one["params"]["back.reflectance.value"], serde_json::json!([0.5, 0.5, 0.5]));
    assert!(one["param_error"].as_f64().unwrap() > 0.3, "{one}");
    // The views are part of the run: a resume with other views is refused.
    let o = crate::cli::pathgrad()
        .args(["optimize", "--resume", two_dir.to_str().unwrap(), "--iters", "61", "--view", "back_camera"])
        .output()
        .unwrap();
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && e.contains("--view back_camera (the run has front_camera back_camera)"), "{e}");
}

/// Bad `--view`s name the flag and what is wrong, before anything renders.
#[test]
fn bad_views_are_refused_by_name() {
    let cases: [(&[&str], &str); 5] = [
        (&["--view", "nope", "--target-set", "front.reflectance.value=0.5"], "no sensor 'nope'"),
        (&["--view", "0", "--view", "front_camera", "--target-set", "front.reflectance.value=0.5"], "given twice"),
        (&["--view", "front_camera"], "give its target as --view front_camera=TARGET.exr"),
        (&["--view", "0", "--sensor", "1", "--target-set", "front.reflectance.value=0.5"], "--sensor 1 and --view"),
        (&["--view", "0=/nonexistent/t.exr"], "/nonexistent/t.exr"),
    ];
    for (args, expected) in cases {
        let o = crate::cli::pathgrad().args([&["grad", TWO_SIDED][..], args].concat()).output().unwrap();
        let e = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success() && e.contains(expected), "{args:?}: {e}");
    }
}

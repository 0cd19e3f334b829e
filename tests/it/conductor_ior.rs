//! A conductor's eta and k as parameters (issue 34 item 2): they act on the weight only (the
//! conductor Fresnel term), so their derivative is an ordinary detached weight derivative, valid
//! with attached sampling too. Against finite differences with common random numbers (CPU and
//! device; smooth and rough, isotropic and anisotropic, NEE and MIS under an area light), and the
//! device against the CPU reference sample for sample.

use pathgrad::backend::Backend;
use pathgrad::gpu::Renderer;
use pathgrad::gpu::renderer::GradMode;
use pathgrad::integrator::{RenderOptions, Sampling};
use pathgrad::scene::Scene;

use crate::attached::{objective, weights};
use crate::support::scenes;

/// The conformance row's scene: a GGX ball, an anisotropic Beckmann bead and a smooth cube, each a
/// conductor of explicit RGB eta and k, under an area light and a constant sky.
fn row_scene() -> Scene {
    let path = format!("{}/tests/conformance/scenes/bsdf_conductor_eta_k.xml", env!("CARGO_MANIFEST_DIR"));
    pathgrad::scene::load(&path, &[]).unwrap_or_else(|e| panic!("{path}: {e}"))
}

/// `values` with `d` added to every element.
fn shifted(values: &[f32], d: f32) -> Vec<f32> {
    values.iter().map(|v| v + d).collect()
}

/// The step of the finite differences: every channel of the RGB parameter moves by it, so the
/// objective's derivative is the sum of the three channels' gradients.
const H: f32 = 0.01;

/// The CPU reference's gradient of RGB parameter `name` (summed over its channels) against
/// central differences of its renders with the same seeds: the Welch test with a power check.
fn check_cpu(scene: &Scene, name: &str, seeds: u32, opts: RenderOptions) {
    let a = weights(opts.width, opts.height);
    let id = scene.params.find(name).unwrap_or_else(|| panic!("{}: no {name}", scene.source));
    let (offset, value) = (scene.params.entry(id).offset as usize, scene.params.get(id).to_vec());
    let (mut fd, mut prb) = (Vec::new(), Vec::new());
    for seed in 0..seeds {
        let o = RenderOptions { seed, ..opts };
        let at = |d: f32| {
            let mut s = scene.clone();
            s.params.set(name, &shifted(&value, d)).unwrap();
            objective(&pathgrad::cpu::render(&s, &o).unwrap(), &a)
        };
        fd.push((at(H) - at(-H)) / (2.0 * f64::from(H)));
        let g = pathgrad::cpu::backward(scene, &o, &a).unwrap();
        prb.push(g[offset..offset + 3].iter().sum());
    }
    let mode = opts.sampling.name();
    crate::support::assert_fd_matches(&format!("{} {name} (CPU, {mode})", scene.source), &fd, &prb);
}

/// eta and k of the smooth cube, the GGX ball and the anisotropic Beckmann bead (next-event
/// estimation and BSDF sampling under MIS on the rough ones), detached, on the CPU reference.
#[test]
fn conductor_ior_matches_finite_differences_on_the_cpu() {
    let scene = row_scene();
    let opts = RenderOptions { width: 32, height: 24, spp: 4, ..RenderOptions::for_scene(&scene) };
    for name in [
        "marker.bsdf.eta.value",
        "marker.bsdf.k.value",
        "ball.bsdf.eta.value",
        "ball.bsdf.k.value",
        "bead.bsdf.eta.value",
        "bead.bsdf.k.value",
    ] {
        check_cpu(&scene, name, 16, opts);
    }
}

/// With attached sampling the same derivative (eta and k move no direction): a gold mirror ball
/// beside a glass sphere and a gold GGX ball (`material="Au"`: a preset's values are parameters
/// too), each in front of a smooth environment map.
#[test]
fn conductor_ior_matches_finite_differences_with_attached_sampling() {
    for (scene, name) in [("attached_mirror", "mirror"), ("attached_rough", "ball")] {
        let scene = scenes::data_scene(scene);
        let opts = RenderOptions {
            width: 24,
            height: 24,
            spp: 4,
            sampling: Sampling::attached(),
            ..RenderOptions::for_scene(&scene)
        };
        check_cpu(&scene, &format!("{name}.bsdf.eta.value"), 16, opts);
        check_cpu(&scene, &format!("{name}.bsdf.k.value"), 16, opts);
    }
}

/// The device's gradient (detached) against central differences of the device's renders.
#[test]
fn conductor_ior_matches_finite_differences_on_the_device() {
    let gpu = crate::support::TestGpu::new();
    let scene = row_scene();
    let opts = RenderOptions { width: 32, height: 24, spp: 4, ..RenderOptions::for_scene(&scene) };
    let a = weights(opts.width, opts.height);
    let mut renderer = Renderer::new(&gpu.ctx, &scene).unwrap();
    for name in ["marker.bsdf.eta.value", "ball.bsdf.k.value", "bead.bsdf.eta.value"] {
        let value = scene.params.get(scene.params.find(name).unwrap()).to_vec();
        let (mut fd, mut prb) = (Vec::new(), Vec::new());
        for seed in 0..16 {
            let o = RenderOptions { seed, ..opts };
            let mut at = |d: f32| {
                let mut table = scene.params.clone();
                table.set(name, &shifted(&value, d)).unwrap();
                renderer.set_params(&table).unwrap();
                objective(&renderer.render(&o).unwrap(), &a)
            };
            fd.push((at(H) - at(-H)) / (2.0 * f64::from(H)));
            renderer.set_params(&scene.params).unwrap();
            let g = renderer.backward(&o, &a, GradMode::Float).unwrap();
            prb.push(g.get(name).unwrap().iter().map(|&v| f64::from(v)).sum());
        }
        crate::support::assert_fd_matches(&format!("{} {name} (device)", scene.source), &fd, &prb);
    }
}

/// The device against the CPU reference, sample for sample (the same keys), per channel: eta and k
/// of every conductor of the row's scene (detached) and of the attached scenes (attached).
#[test]
fn conductor_ior_gradients_on_the_device_equal_the_cpu_reference() {
    let gpu = crate::support::TestGpu::new();
    let row = row_scene();
    let cases: Vec<(Scene, &str, Sampling)> = vec![
        (row.clone(), "marker", Sampling::Detached),
        (row.clone(), "ball", Sampling::Detached),
        (row, "bead", Sampling::Detached),
        (scenes::data_scene("attached_mirror"), "mirror", Sampling::attached()),
        (scenes::data_scene("attached_rough"), "ball", Sampling::attached()),
    ];
    for (scene, shape, sampling) in cases {
        let mut renderer = Renderer::new(&gpu.ctx, &scene).unwrap();
        let opts =
            RenderOptions { width: 32, height: 24, spp: 2, seed: 5, sampling, ..RenderOptions::for_scene(&scene) };
        let a = weights(opts.width, opts.height);
        let g = renderer.backward(&opts, &a, GradMode::Float).unwrap();
        let c = pathgrad::cpu::backward(&scene, &opts, &a).unwrap();
        for part in ["eta", "k"] {
            let name = format!("{shape}.bsdf.{part}.value");
            let offset = scene.params.entry(scene.params.find(&name).unwrap()).offset as usize;
            let gv = g.get(&name).unwrap();
            let cv = &c[offset..offset + 3];
            let scale = cv.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            println!("{}: {name} ({}) GPU {gv:?} CPU {cv:?}", scene.source, sampling.name());
            assert!(scale > 0.0, "{name}: the CPU gradient is 0, the comparison has no power");
            for (gc, cc) in gv.iter().zip(cv) {
                assert!((f64::from(*gc) - cc).abs() <= 1e-3 * scale, "{name}: GPU {gv:?} vs CPU {cv:?}");
            }
        }
    }
}

//! Attached derivatives (issue 34): the index of refraction of smooth dielectrics against finite
//! differences with common random numbers, on the CPU reference and on the device, and the two
//! back ends against each other.

use pathgrad::image::Image;
use pathgrad::integrator::{RenderOptions, Sampling};
use pathgrad::scene::Scene;

use crate::support::scenes;

/// An adjoint image: a fixed smooth weighting of the pixels and channels, so the loss J = Σ A·I
/// reacts to every pixel.
fn weights(width: u32, height: u32) -> Image {
    let mut data = Vec::with_capacity((3 * width * height) as usize);
    for y in 0..height {
        for x in 0..width {
            let (u, v) = (x as f32 / width as f32, y as f32 / height as f32);
            data.extend_from_slice(&[0.5 + u, 1.5 - v, 0.8 + 0.4 * (u * v)]);
        }
    }
    Image::from_rgb(width, height, data).unwrap()
}

fn objective(img: &Image, a: &Image) -> f64 {
    img.as_slice().iter().zip(a.as_slice()).map(|(i, w)| f64::from(*i) * f64::from(*w)).sum()
}

/// The CPU reference's attached gradient of `name` against central differences of its renders
/// with the same seeds: the Welch test over `seeds` with a power check.
fn check_cpu(scene: &Scene, name: &str, seeds: u32, opts: RenderOptions) {
    let a = weights(opts.width, opts.height);
    let id = scene.params.find(name).unwrap();
    let value = scene.params.get(id)[0];
    let h = 0.01 * value;
    let (mut fd, mut prb) = (Vec::new(), Vec::new());
    for seed in 0..seeds {
        let o = RenderOptions { seed, ..opts };
        let at = |v: f32| {
            let mut s = scene.clone();
            s.params.set(name, &[v]).unwrap();
            objective(&pathgrad::cpu::render(&s, &o).unwrap(), &a)
        };
        fd.push((at(value + h) - at(value - h)) / (2.0 * f64::from(h)));
        let g = pathgrad::cpu::backward(scene, &RenderOptions { sampling: Sampling::attached(), ..o }, &a).unwrap();
        prb.push(g[scene.params.entry(id).offset as usize]);
    }
    crate::support::assert_fd_matches(&format!("{} {name} (CPU, attached)", scene.source), &fd, &prb);
}

/// The index of refraction of a glass sphere, a glass slab and a thin pane, each alone in front
/// of a smooth environment map (no visibility edge moves), against finite differences.
#[test]
fn ior_matches_finite_differences_on_the_cpu() {
    for name in ["attached_sphere", "attached_slab", "attached_pane"] {
        let scene = scenes::data_scene(name);
        let opts = RenderOptions { width: 24, height: 24, spp: 4, ..RenderOptions::for_scene(&scene) };
        check_cpu(&scene, "glass.bsdf.eta", 16, opts);
    }
}

/// The device's attached kernel against the CPU reference, sample for sample (the same keys): the
/// η gradient of every scene, and the other parameters' (detached terms) unchanged by attaching.
#[test]
fn the_device_equals_the_cpu_reference() {
    use pathgrad::backend::Backend;
    use pathgrad::gpu::Renderer;
    use pathgrad::gpu::renderer::GradMode;
    let gpu = crate::support::TestGpu::new();
    for name in ["attached_sphere", "attached_slab", "attached_pane"] {
        let scene = scenes::data_scene(name);
        let opts = RenderOptions {
            width: 32,
            height: 32,
            spp: 2,
            seed: 5,
            sampling: Sampling::attached(),
            ..RenderOptions::for_scene(&scene)
        };
        let a = weights(opts.width, opts.height);
        let mut renderer = Renderer::new(&gpu.ctx, &scene).unwrap();
        let g = renderer.backward(&opts, &a, GradMode::Float).unwrap();
        let c = pathgrad::cpu::backward(&scene, &opts, &a).unwrap();
        let e = scene.params.entry(scene.params.find("glass.bsdf.eta").unwrap()).clone();
        let (gv, cv) = (g.get("glass.bsdf.eta").unwrap()[0], c[e.offset as usize]);
        println!("{name}: η gradient GPU {gv} CPU {cv}");
        assert!((f64::from(gv) - cv).abs() <= 1e-3 * cv.abs(), "{name}: GPU {gv} vs CPU {cv}");
    }
}

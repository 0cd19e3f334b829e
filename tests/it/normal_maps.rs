//! Normal maps (Mitsuba's `normalmap`): a map of constant (0.5, 0.5, 1) — the unperturbed normal —
//! renders and differentiates as no map at all, on both back ends; the nested BSDF's parameters
//! keep their derivatives through a map.

use pathgrad::backend::Backend;
use pathgrad::gpu::Renderer;
use pathgrad::gpu::renderer::GradMode;
use pathgrad::image::Image;
use pathgrad::integrator::RenderOptions;
use pathgrad::scene::{Material, MaterialId, NormalMapTexture, Scene, Wrap};

use crate::support::{TestGpu, scenes};

/// The anisotropic conductors' scene with the ball's and the floor's BSDFs wrapped in a 1×1 normal
/// map of `rgb`, read by nearest lookup (a bilinear one sums four weights that need not round to
/// exactly 1). Anisotropic leaves already shade in the frame of ∂p/∂u, so with the identity map
/// (n = (0, 0, 1) exactly: s = x, t = y, the terminator's α² = 0, its factor 1) every path takes
/// the same decisions with the same values as without the map.
fn mapped(rgb: [f32; 3]) -> Scene {
    let mut scene = scenes::conformance("bsdf_roughconductor_anisotropic");
    scene.normal_maps.push(NormalMapTexture {
        width: 1,
        height: 1,
        texels: rgb.to_vec(),
        nearest: true,
        wrap: Wrap::Repeat,
    });
    for name in ["ball", "floor"] {
        let mesh = scene.meshes.iter().position(|m| m.name == name).unwrap_or_else(|| panic!("no mesh {name}"));
        let nested = scene.meshes[mesh].material;
        scene.materials.push(Material::NormalMap { nested, map: 0 });
        scene.meshes[mesh].material = MaterialId(scene.materials.len() as u32 - 1);
    }
    scene
}

/// Per pixel, `a` equals `b` to the twins' per-path tolerance (tests/it/cpu_vs_gpu.rs): the GPU
/// kernels of the two scenes differ in their feature bits, so the driver may contract a product
/// differently; on the CPU the two are the same operations and must be equal bit for bit.
fn assert_same(what: &str, a: &Image, b: &Image, exact: bool) {
    let mut differ = 0;
    for (x, y) in a.as_slice().iter().zip(b.as_slice()) {
        let ok = if exact { x.to_bits() == y.to_bits() } else { (x - y).abs() <= 1e-4 * x.abs().max(y.abs()) + 1e-6 };
        differ += usize::from(!ok);
    }
    println!("{what}: {differ} of {} values differ", a.as_slice().len());
    assert!(
        if exact { differ == 0 } else { differ as f64 <= 1e-3 * a.as_slice().len() as f64 },
        "{what}: {differ} differ"
    );
}

#[test]
fn issue_31_an_identity_normal_map_changes_nothing() {
    let gpu = TestGpu::new();
    let plain = scenes::conformance("bsdf_roughconductor_anisotropic");
    let identity = mapped([0.5, 0.5, 1.0]);
    let opts = RenderOptions { width: 48, height: 48, spp: 2, seed: 3, ..RenderOptions::for_scene(&plain) };
    let params = ["ball.bsdf.alpha_v.value", "floor.bsdf.alpha_u.value"];
    let (mut rp, mut ri) = (Renderer::new(&gpu.ctx, &plain).unwrap(), Renderer::new(&gpu.ctx, &identity).unwrap());
    assert_same("GPU primal", &rp.render(&opts).unwrap(), &ri.render(&opts).unwrap(), false);
    let cpu = pathgrad::cpu::render(&identity, &opts).unwrap();
    assert_same("CPU primal", &pathgrad::cpu::render(&plain, &opts).unwrap(), &cpu, true);
    for name in params {
        let g = |r: &mut Renderer| r.image_gradient(&opts, name).unwrap();
        assert_same(&format!("GPU ∂/∂{name}"), &g(&mut rp), &g(&mut ri), false);
        let c = |s: &Scene| pathgrad::cpu::image_gradient(s, &opts, name).unwrap();
        assert_same(&format!("CPU ∂/∂{name}"), &c(&plain), &c(&identity), true);
    }
    // The negative control: a tilted map changes the image (the comparison can fail).
    let tilted = pathgrad::cpu::render(&mapped([0.7, 0.5, 0.9]), &opts).unwrap();
    let moved = tilted.as_slice().iter().zip(cpu.as_slice()).filter(|(a, b)| a != b).count();
    assert!(moved > cpu.as_slice().len() / 4, "a tilted normal map moved only {moved} values");
    // Reverse mode through the map (GPU against CPU is `gradients.rs`'s; here: equal to no map).
    let adjoint = Image::from_rgb(opts.width, opts.height, vec![1.0; (3 * opts.width * opts.height) as usize]).unwrap();
    let (a, b) = (
        rp.backward(&opts, &adjoint, GradMode::Float).unwrap(),
        ri.backward(&opts, &adjoint, GradMode::Float).unwrap(),
    );
    for name in params {
        let (x, y) = (a.get(name).unwrap()[0], b.get(name).unwrap()[0]);
        assert!((x - y).abs() <= 1e-3 * x.abs().max(y.abs()), "{name}: {x} without the map, {y} with it");
    }
}

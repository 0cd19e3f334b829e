//! Scene files against each other: the XML twin of the built-in Cornell box, and one scene written
//! both as Mitsuba XML and as glTF.

use pathgrad::backend::Backend;
use pathgrad::gpu::Renderer;
use pathgrad::integrator::RenderOptions;
use pathgrad::scene;

use crate::support::TestGpu;

fn root(path: &str) -> String {
    format!("{}/{path}", env!("CARGO_MANIFEST_DIR"))
}

/// The XML twin builds the same triangles, materials, light and camera, so for the same seed the
/// image is the same, bit for bit.
#[test]
fn builtin_cornell_box_and_its_xml_twin_render_identically() {
    let gpu = TestGpu::new();
    let builtin = scene::builtin::load("cornell-box").unwrap();
    let xml = scene::load(&root("scenes/cornell-box/cornell-box.xml"), &[]).unwrap();
    let opts = RenderOptions { width: 64, height: 64, spp: 4, seed: 3, ..RenderOptions::for_scene(&builtin) };
    let a = Renderer::new(&gpu.ctx, &builtin).unwrap().render(&opts).unwrap();
    let b = Renderer::new(&gpu.ctx, &xml).unwrap().render(&opts).unwrap();
    assert_eq!(a.as_slice(), b.as_slice());
}

/// `scenes/twin/twin.xml` and `twin.gltf` describe the same scene; their triangles are built in a
/// different order and by different arithmetic (Mitsuba transforms vs glTF node matrices), so the
/// comparison is per path (one sample per pixel) with the tolerance and mismatch budget of the
/// GPU-vs-CPU test: 1e-4 relative (a few ulp of vertex positions, amplified along the path), and
/// 1e-3 of the paths allowed to take a different decision at a threshold.
#[test]
fn the_same_scene_as_xml_and_gltf_renders_the_same() {
    let gpu = TestGpu::new();
    let xml = scene::load(&root("scenes/twin/twin.xml"), &[]).unwrap();
    let gltf = scene::load(&root("scenes/twin/twin.gltf"), &[]).unwrap();
    let opts = RenderOptions { width: 96, height: 96, spp: 1, seed: 8, ..RenderOptions::for_scene(&xml) };
    let a = Renderer::new(&gpu.ctx, &xml).unwrap().render(&opts).unwrap();
    let b = Renderer::new(&gpu.ctx, &gltf).unwrap().render(&opts).unwrap();
    let mismatched = a
        .as_slice()
        .chunks(3)
        .zip(b.as_slice().chunks(3))
        .filter(|(x, y)| x.iter().zip(*y).any(|(p, q)| (p - q).abs() > 1e-4 * p.abs().max(q.abs()) + 1e-6))
        .count();
    println!("{mismatched} of {} paths differ", 96 * 96);
    assert!(mismatched as f64 <= 1e-3 * 96.0 * 96.0, "{mismatched} paths differ");
}

/// `-D name=value` overrides an XML `<default>`.
#[test]
fn defines_override_xml_defaults() {
    let path = root("scenes/blend/blend.xml");
    let plain = scene::load(&path, &[]).unwrap();
    let changed = scene::load(&path, &[("weight".into(), "0.25".into()), ("spp".into(), "7".into())]).unwrap();
    assert_eq!(plain.params.get(plain.params.find("object.weight.value").unwrap()), &[0.5]);
    assert_eq!(changed.params.get(changed.params.find("object.weight.value").unwrap()), &[0.25]);
    assert_eq!(changed.default_spp, Some(7));
}

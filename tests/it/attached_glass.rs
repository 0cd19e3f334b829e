//! Attached derivatives of a rough dielectric (issue 34): its roughness and its index of
//! refraction through the attached microfacet sampler (`pathgrad::attached::rough_dielectric_lobe`)
//! against finite differences with common random numbers, against the detached roughness
//! derivative, and the device against the CPU reference.

use pathgrad::integrator::{RenderOptions, Sampling};

use crate::attached::{attached, check_cpu, weights};
use crate::support::scenes;

/// The rough glass spheres (GGX α 0.2 η 1.5; Beckmann α 0.1 η 1.33), each alone in front of a
/// smooth environment map: their roughness and their η against central differences of the CPU's
/// renders with the same seeds.
#[test]
fn rough_glass_matches_finite_differences_on_the_cpu() {
    for name in ["attached_rough_sphere", "attached_rough_sphere_beckmann"] {
        let scene = scenes::data_scene(name);
        let opts = RenderOptions { width: 24, height: 24, spp: 4, ..RenderOptions::for_scene(&scene) };
        check_cpu(&scene, "glass.bsdf.alpha.value", 16, opts);
        check_cpu(&scene, "glass.bsdf.eta", 16, opts);
    }
}

/// Attached and detached sampling estimate the same roughness derivative of the rough glass
/// sphere (a z-test over seeds), each from its own paths.
#[test]
fn attached_and_detached_rough_glass_roughness_agree() {
    for name in ["attached_rough_sphere", "attached_rough_sphere_beckmann"] {
        crate::attached::assert_attached_agrees_with_detached(name, "glass.bsdf.alpha.value");
    }
}

/// The device's attached kernel against the CPU reference, seed for seed (the same keys), for
/// the roughness and the η of both spheres, to 10⁻³ of the larger of two seeds' sums (the bound
/// of `attached::the_device_equals_the_cpu_reference`).
#[test]
fn rough_glass_device_equals_the_cpu_reference() {
    use pathgrad::backend::Backend;
    use pathgrad::gpu::Renderer;
    use pathgrad::gpu::renderer::GradMode;
    let gpu = crate::support::TestGpu::new();
    for name in ["attached_rough_sphere", "attached_rough_sphere_beckmann"] {
        let scene = scenes::data_scene(name);
        let mut renderer = Renderer::new(&gpu.ctx, &scene).unwrap();
        for param in ["glass.bsdf.alpha.value", "glass.bsdf.eta"] {
            let e = scene.params.entry(scene.params.find(param).unwrap()).clone();
            let pairs: Vec<(f32, f64)> = [5, 6]
                .into_iter()
                .map(|seed| {
                    let opts = RenderOptions { seed, ..attached(&scene, 32, 2) };
                    let a = weights(opts.width, opts.height);
                    let g = renderer.backward(&opts, &a, GradMode::Float).unwrap();
                    let c = pathgrad::cpu::backward(&scene, &opts, &a).unwrap();
                    (g.get(param).unwrap()[0], c[e.offset as usize])
                })
                .collect();
            let scale = pairs.iter().map(|p| p.1.abs()).fold(0.0, f64::max);
            for (gv, cv) in pairs {
                println!("{name}: {param} gradient GPU {gv} CPU {cv}");
                assert!((f64::from(gv) - cv).abs() <= 1e-3 * scale, "{name} {param}: GPU {gv} vs CPU {cv}");
            }
        }
    }
}

/// The device's attached gradient of the GGX sphere's roughness and η against central
/// differences of the device's renders.
#[test]
fn rough_glass_matches_finite_differences_on_the_device() {
    use pathgrad::backend::Backend;
    use pathgrad::gpu::Renderer;
    use pathgrad::gpu::renderer::GradMode;
    let gpu = crate::support::TestGpu::new();
    let scene = scenes::data_scene("attached_rough_sphere");
    let opts = RenderOptions { width: 32, height: 32, spp: 4, ..RenderOptions::for_scene(&scene) };
    let a = weights(opts.width, opts.height);
    let mut renderer = Renderer::new(&gpu.ctx, &scene).unwrap();
    for param in ["glass.bsdf.alpha.value", "glass.bsdf.eta"] {
        let value = scene.params.get(scene.params.find(param).unwrap())[0];
        let h = 0.01 * value;
        let (mut fd, mut prb) = (Vec::new(), Vec::new());
        for seed in 0..24 {
            let o = RenderOptions { seed, ..opts };
            let mut at = |v: f32| {
                let mut table = scene.params.clone();
                table.set(param, &[v]).unwrap();
                renderer.set_params(&table).unwrap();
                crate::attached::objective(&renderer.render(&o).unwrap(), &a)
            };
            fd.push((at(value + h) - at(value - h)) / (2.0 * f64::from(h)));
            renderer.set_params(&scene.params).unwrap();
            let g =
                renderer.backward(&RenderOptions { sampling: Sampling::attached(), ..o }, &a, GradMode::Float).unwrap();
            prb.push(f64::from(g.get(param).unwrap()[0]));
        }
        crate::support::assert_fd_matches(&format!("{} {param} (device, attached)", scene.source), &fd, &prb);
    }
}

/// Attached sampling refuses a rough dielectric whose roughness is a texture, by name (its
/// sampler would need the texture's derivative along the surface), and a detached pass takes it.
#[test]
fn attached_sampling_refuses_a_textured_rough_dielectric() {
    let data = format!("{}/tests/data/scenes", env!("CARGO_MANIFEST_DIR"));
    let xml = std::fs::read_to_string(format!("{data}/attached_rough_sphere.xml")).unwrap().replace(
        r#"<float name="alpha" value="0.2"/>"#,
        r#"<texture type="checkerboard" name="alpha"><float name="color0" value="0.2"/><float name="color1" value="0.3"/></texture>"#,
    );
    let dir = tempfile::tempdir().unwrap();
    std::fs::copy(format!("{data}/attached_sky.exr"), dir.path().join("attached_sky.exr")).unwrap();
    let path = dir.path().join("textured.xml");
    std::fs::write(&path, xml).unwrap();
    let textured = pathgrad::scene::load(path.to_str().unwrap(), &[]).unwrap();
    let a = weights(8, 8);
    let err = pathgrad::cpu::backward(&textured, &attached(&textured, 8, 1), &a).unwrap_err().to_string();
    assert!(err.contains("Sampling::Attached"), "{err}");
    assert!(err.contains("anisotropic or texture-roughened `roughdielectric`"), "{err}");
    let detached = RenderOptions { sampling: Sampling::Detached, ..attached(&textured, 8, 1) };
    assert!(pathgrad::cpu::backward(&textured, &detached, &a).is_ok());
}

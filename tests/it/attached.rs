//! Attached derivatives (issue 34): the index of refraction of smooth dielectrics against finite
//! differences with common random numbers, on the CPU reference and on the device, and the two
//! back ends against each other.

use pathgrad::image::Image;
use pathgrad::integrator::{RenderOptions, Sampling};
use pathgrad::scene::Scene;

use crate::support::scenes;

/// An adjoint image: a fixed smooth weighting of the pixels and channels, so the loss J = Σ A·I
/// reacts to every pixel.
pub(crate) fn weights(width: u32, height: u32) -> Image {
    let mut data = Vec::with_capacity((3 * width * height) as usize);
    for y in 0..height {
        for x in 0..width {
            let (u, v) = (x as f32 / width as f32, y as f32 / height as f32);
            data.extend_from_slice(&[0.5 + u, 1.5 - v, 0.8 + 0.4 * (u * v)]);
        }
    }
    Image::from_rgb(width, height, data).unwrap()
}

/// `scene`'s options at `size`² and `spp`, with attached sampling (default noise).
pub(crate) fn attached(scene: &Scene, size: u32, spp: u32) -> RenderOptions {
    RenderOptions { width: size, height: size, spp, sampling: Sampling::attached(), ..RenderOptions::for_scene(scene) }
}

pub(crate) fn objective(img: &Image, a: &Image) -> f64 {
    img.as_slice().iter().zip(a.as_slice()).map(|(i, w)| f64::from(*i) * f64::from(*w)).sum()
}

/// The CPU reference's attached gradient of `name` against central differences of its renders
/// with the same seeds: the Welch test over `seeds` with a power check.
pub(crate) fn check_cpu(scene: &Scene, name: &str, seeds: u32, opts: RenderOptions) {
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
/// of a smooth environment map (no visibility edge moves), and of a glass sphere beside a gold
/// mirror ball (a conductor's Fresnel weight in the Jacobians), against finite differences.
#[test]
fn ior_matches_finite_differences_on_the_cpu() {
    for name in ["attached_sphere", "attached_slab", "attached_pane", "attached_mirror"] {
        let scene = scenes::data_scene(name);
        let opts = RenderOptions { width: 24, height: 24, spp: 4, ..RenderOptions::for_scene(&scene) };
        check_cpu(&scene, "glass.bsdf.eta", 16, opts);
    }
}

/// Diffuse vertices against finite differences of η: before the moving directions (a diffuse
/// floor lit through a glass sphere, where the replay recovers the derivative by the ray leaving
/// the floor through its noise-regularised Jacobian), and after them (a textured, emitting
/// floor under a glass slab, whose hit points move with η: the radiance's and the albedo's
/// slopes along the floor, and the floor's noise on the paths that bounce back into the slab).
/// Without the radiance's slope the slab's gradient is 4.6 standard errors off; the albedo's
/// share is too small to see here, and `crate::cpu::slope`'s unit test checks it against the
/// lookups.
#[test]
fn diffuse_vertices_match_finite_differences_on_the_cpu() {
    // The slab's η acts mostly through its Fresnel weights; the slopes' share needs more seeds
    // to stand out of the finite differences' noise.
    for (name, seeds) in [("attached_floor", 24), ("attached_slab_table", 48)] {
        let scene = scenes::data_scene(name);
        let opts = RenderOptions { width: 24, height: 24, spp: 8, ..RenderOptions::for_scene(&scene) };
        check_cpu(&scene, "glass.bsdf.eta", seeds, opts);
    }
}

/// Next-event estimation at diffuse vertices against finite differences of η: a floor seen
/// through a glass sphere and lit by a small lamp (`attached_lamp.xml`), whose points move with η
/// under the lamp's fixed sample points — the distance, both cosines, the MIS weight and the
/// textured albedo there (`HitGeometry::nee_gradient`); the same under a large panel whose
/// light BSDF samples share (`attached_panel.xml`); and under a point, a directional and a spot
/// light whose transition zone covers the floor the lens shows and a spot projecting a bilinear
/// bitmap onto it (`attached_point.xml`, `HitGeometry::delta_light_gradient`,
/// `spot_falloff_gradient`, `light_texture_slope`: without the falloff's slope this fails).
#[test]
fn next_event_estimation_matches_finite_differences_on_the_cpu() {
    for name in ["attached_lamp", "attached_panel", "attached_point"] {
        let scene = scenes::data_scene(name);
        let opts = RenderOptions { width: 24, height: 24, spp: 8, ..RenderOptions::for_scene(&scene) };
        check_cpu(&scene, "glass.bsdf.eta", 24, opts);
    }
}

/// The regularisation noise moves the variance, not the mean (ALGORITHMS.md §9 test (c)): on a
/// glass sphere above a diffuse table, where diffuse vertices follow the directions η moves and
/// their noise reaches η's gradient, the default (diffuse amplitude 1, smooth vertices exact)
/// and noise of amplitude 0.2 at every vertex estimate the same gradient (independent seeds).
#[test]
fn the_jacobian_noise_leaves_the_mean_alone() {
    let scene = scenes::data_scene("attached_table");
    let offset = scene.params.entry(scene.params.find("glass.bsdf.eta").unwrap()).offset as usize;
    let a = weights(24, 24);
    let gradient = |noise: f32, seed: u32| {
        let o = RenderOptions { seed, sampling: Sampling::Attached { noise }, ..attached(&scene, 24, 64) };
        pathgrad::cpu::backward(&scene, &o, &a).unwrap()[offset]
    };
    let default: Vec<f64> = (0..24).map(|seed| gradient(0.0, seed)).collect();
    let everywhere: Vec<f64> = (100..124).map(|seed| gradient(0.2, seed)).collect();
    crate::support::assert_fd_matches("attached_table glass.bsdf.eta: noise 0.2 vs default", &everywhere, &default);
}

/// The roughness of rough conductors (GGX and Beckmann) alone in front of the environment map and
/// seen through a glass slab, differentiated through the attached microfacet sampler, against
/// finite differences. (The slab's own η moves its rays little here — a flat slab only shifts
/// them — so the η tests are the scenes above.)
#[test]
fn roughness_matches_finite_differences_on_the_cpu() {
    for name in ["attached_rough", "attached_rough_beckmann", "attached_rough_glass"] {
        let scene = scenes::data_scene(name);
        let opts = RenderOptions { width: 24, height: 24, spp: 4, ..RenderOptions::for_scene(&scene) };
        check_cpu(&scene, "ball.bsdf.alpha.value", 16, opts);
    }
}

/// Attached and detached sampling estimate the same roughness derivative (the issue's z-test over
/// seeds), each from its own paths: the attached one through its sampler, the detached one
/// through the BSDF's value at fixed directions.
#[test]
fn attached_and_detached_roughness_agree() {
    for name in ["attached_rough", "attached_rough_glass"] {
        assert_attached_agrees_with_detached(name, "ball.bsdf.alpha.value");
    }
}

/// The z-test of [`attached_and_detached_roughness_agree`] on the data scene `name` for the
/// parameter `param`: 16 seeds of the CPU reference's gradient sampled each way, 24² at 4 spp.
pub(crate) fn assert_attached_agrees_with_detached(name: &str, param: &str) {
    let scene = scenes::data_scene(name);
    let opts = RenderOptions { width: 24, height: 24, spp: 4, ..RenderOptions::for_scene(&scene) };
    let a = weights(opts.width, opts.height);
    let offset = scene.params.entry(scene.params.find(param).unwrap()).offset as usize;
    let (mut detached, mut attached_g) = (Vec::new(), Vec::new());
    for seed in 0..16 {
        let o = RenderOptions { seed, ..opts };
        detached.push(pathgrad::cpu::backward(&scene, &o, &a).unwrap()[offset]);
        let o = RenderOptions { sampling: Sampling::attached(), ..o };
        attached_g.push(pathgrad::cpu::backward(&scene, &o, &a).unwrap()[offset]);
    }
    crate::support::assert_fd_matches(&format!("{name} {param}: detached vs attached"), &detached, &attached_g);
}

/// The same on the device: the attached kernel's gradient against central differences of the
/// device's renders.
#[test]
fn ior_matches_finite_differences_on_the_device() {
    use pathgrad::backend::Backend;
    use pathgrad::gpu::Renderer;
    use pathgrad::gpu::renderer::GradMode;
    let gpu = crate::support::TestGpu::new();
    for name in ["attached_sphere", "attached_slab", "attached_pane"] {
        let scene = scenes::data_scene(name);
        let opts = RenderOptions { width: 32, height: 32, spp: 4, ..RenderOptions::for_scene(&scene) };
        let a = weights(opts.width, opts.height);
        let mut renderer = Renderer::new(&gpu.ctx, &scene).unwrap();
        let value = scene.params.get(scene.params.find("glass.bsdf.eta").unwrap())[0];
        let h = 0.01 * value;
        let (mut fd, mut prb) = (Vec::new(), Vec::new());
        for seed in 0..24 {
            let o = RenderOptions { seed, ..opts };
            let mut at = |v: f32| {
                let mut table = scene.params.clone();
                table.set("glass.bsdf.eta", &[v]).unwrap();
                renderer.set_params(&table).unwrap();
                objective(&renderer.render(&o).unwrap(), &a)
            };
            fd.push((at(value + h) - at(value - h)) / (2.0 * f64::from(h)));
            renderer.set_params(&scene.params).unwrap();
            let g =
                renderer.backward(&RenderOptions { sampling: Sampling::attached(), ..o }, &a, GradMode::Float).unwrap();
            prb.push(f64::from(g.get("glass.bsdf.eta").unwrap()[0]));
        }
        crate::support::assert_fd_matches(&format!("{} glass.bsdf.eta (device, attached)", scene.source), &fd, &prb);
    }
}

/// The device's attached kernel against the CPU reference, sample for sample (the same keys): the
/// η gradient of every scene.
#[test]
fn the_device_equals_the_cpu_reference() {
    use pathgrad::backend::Backend;
    use pathgrad::gpu::Renderer;
    use pathgrad::gpu::renderer::GradMode;
    let gpu = crate::support::TestGpu::new();
    for (name, param) in [
        ("attached_sphere", "glass.bsdf.eta"),
        ("attached_slab", "glass.bsdf.eta"),
        ("attached_pane", "glass.bsdf.eta"),
        ("attached_mirror", "glass.bsdf.eta"),
        ("attached_rough", "ball.bsdf.alpha.value"),
        ("attached_rough_glass", "ball.bsdf.alpha.value"),
        ("attached_rough_glass", "glass.bsdf.eta"),
        ("attached_rough_beckmann", "ball.bsdf.alpha.value"),
        ("attached_floor", "glass.bsdf.eta"),
        ("attached_table", "glass.bsdf.eta"),
        ("attached_slab_table", "glass.bsdf.eta"),
        ("attached_slab_albedo", "glass.bsdf.eta"),
        ("attached_ball", "glass.bsdf.eta"),
        ("attached_lamp", "glass.bsdf.eta"),
        ("attached_panel", "glass.bsdf.eta"),
        ("attached_point", "glass.bsdf.eta"),
    ] {
        let scene = scenes::data_scene(name);
        let mut renderer = Renderer::new(&gpu.ctx, &scene).unwrap();
        let e = scene.params.entry(scene.params.find(param).unwrap()).clone();
        // Two seeds, each to 10⁻³ of the larger: a seed's sum can cancel to near 0 (the Beckmann
        // ball at seed 5: 1.28 of per-seed sums near ±100), where float rounding is not 10⁻³ of it.
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
    // The Jacobian noise (stream `Jacobian`, block 0 of each vertex) is drawn alike on both.
    let scene = scenes::data_scene("attached_sphere");
    let opts = RenderOptions { seed: 5, sampling: Sampling::Attached { noise: 0.2 }, ..attached(&scene, 32, 2) };
    let a = weights(32, 32);
    let g = Renderer::new(&gpu.ctx, &scene).unwrap().backward(&opts, &a, GradMode::Float).unwrap();
    let c = pathgrad::cpu::backward(&scene, &opts, &a).unwrap();
    let e = scene.params.entry(scene.params.find("glass.bsdf.eta").unwrap()).clone();
    let (gv, cv) = (g.get("glass.bsdf.eta").unwrap()[0], c[e.offset as usize]);
    println!("attached_sphere, noise 0.2: η gradient GPU {gv} CPU {cv}");
    assert!((f64::from(gv) - cv).abs() <= 1e-3 * cv.abs(), "noise 0.2: GPU {gv} vs CPU {cv}");
}

/// Forward-mode image gradients with attached sampling (one fused sample per channel, δL = e_c):
/// on the CPU reference, Σ A ⊙ ∂I/∂θ equals the reverse-mode gradient with adjoint A for the same
/// seed (A weighs the channels differently, so channels mixed up fail: rotating them fails on the
/// first scene already) — a glass sphere's η over
/// a diffuse floor, η lit by next-event estimation from point and directional lights, a rough
/// glass's α; and the device's image gradient equals the CPU reference's pixel for pixel.
#[test]
fn forward_mode_equals_reverse_mode_and_the_device() {
    use pathgrad::backend::Backend;
    use pathgrad::gpu::Renderer;
    let gpu = crate::support::TestGpu::new();
    for (name, param) in [
        ("attached_floor", "glass.bsdf.eta"),
        ("attached_point", "glass.bsdf.eta"),
        ("attached_rough_glass", "ball.bsdf.alpha.value"),
    ] {
        let scene = scenes::data_scene(name);
        let opts = RenderOptions { seed: 3, ..attached(&scene, 16, 2) };
        let a = weights(opts.width, opts.height);
        let forward = pathgrad::cpu::image_gradient(&scene, &opts, param).unwrap();
        let e = scene.params.entry(scene.params.find(param).unwrap()).clone();
        let reverse = pathgrad::cpu::backward(&scene, &opts, &a).unwrap()[e.offset as usize];
        let magnitude = crate::support::assert_forward_equals_reverse(name, &forward, &a, reverse);
        assert!(reverse.abs() > 0.05 * magnitude, "{name}: a gradient that cancels tests little");

        let device = Renderer::new(&gpu.ctx, &scene).unwrap().image_gradient(&opts, param).unwrap();
        let scale = forward.as_slice().iter().fold(0.0f32, |m, v| m.max(v.abs()));
        let differ = device.as_slice().iter().zip(forward.as_slice()).filter(|(g, c)| (*g - *c).abs() > 1e-3 * scale);
        let differ = differ.count();
        println!("{name} {param}: {differ} of {} values differ between the device and the CPU", a.as_slice().len());
        assert_eq!(differ, 0, "{name} {param}: the device's forward-mode image gradient differs from the CPU's");
    }
}

/// Loss-aware adaptive pixel sampling with attached sampling: for an adjoint image peaked around
/// one point (so the pixels' probabilities are far from uniform), the device's adaptive attached
/// gradient equals the CPU reference's per seed (10⁻³), and over seeds its mean equals uniform
/// attached sampling's (Welch < 4, with the power check that the uniform mean lies 8 of the
/// comparison's standard errors from 0) — a glass sphere's η over a diffuse floor (next-event
/// estimation at the floor).
#[test]
fn adaptive_pixel_sampling_takes_attached_sampling() {
    use pathgrad::adaptive::{AdaptiveEstimator, PixelSampling};
    use pathgrad::backend::Backend;
    use pathgrad::gpu::Renderer;
    use pathgrad::gpu::renderer::GradMode;
    let gpu = crate::support::TestGpu::new();
    let scene = scenes::data_scene("attached_floor");
    let opts = attached(&scene, 24, 2);
    let w = weights(opts.width, opts.height);
    let peaked: Vec<f32> = w
        .as_slice()
        .iter()
        .enumerate()
        .map(|(i, &v)| {
            let p = (i / 3) as f32;
            let (x, y) = (p % 24.0 - 9.0, (p / 24.0).floor() - 14.0);
            v * (0.2 + 8.0 * (-(x * x + y * y) / 18.0).exp())
        })
        .collect();
    let a = Image::from_rgb(opts.width, opts.height, peaked).unwrap();
    let sampling = PixelSampling::from_adjoint(&a, AdaptiveEstimator::Importance).unwrap();
    let e = scene.params.entry(scene.params.find("glass.bsdf.eta").unwrap()).clone();
    let mut renderer = Renderer::new(&gpu.ctx, &scene).unwrap();
    let (mut uniform, mut adaptive) = (Vec::new(), Vec::new());
    for seed in 0..16 {
        let o = RenderOptions { seed, ..opts };
        let g = renderer.backward_adaptive(&o, &a, &sampling, GradMode::Float).unwrap();
        let gv = f64::from(g.get("glass.bsdf.eta").unwrap()[0]);
        if seed < 2 {
            let c = pathgrad::cpu::backward_adaptive(&scene, &o, &a, &sampling).unwrap()[e.offset as usize];
            println!("seed {seed}: adaptive attached η gradient GPU {gv} CPU {c}");
            assert!((gv - c).abs() <= 1e-3 * c.abs(), "seed {seed}: GPU {gv} vs CPU {c}");
        }
        adaptive.push(gv);
        let u = renderer.backward(&RenderOptions { seed: 100 + seed, ..opts }, &a, GradMode::Float).unwrap();
        uniform.push(f64::from(u.get("glass.bsdf.eta").unwrap()[0]));
    }
    let stats = |v: &[f64]| {
        let m = v.iter().sum::<f64>() / v.len() as f64;
        (m, v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (v.len() as f64 - 1.0))
    };
    let ((mu, vu), (ma, va)) = (stats(&uniform), stats(&adaptive));
    let se = ((vu + va) / 16.0).sqrt();
    println!(
        "η: uniform {mu:.3} ± {:.3}, adaptive {ma:.3} ± {:.3}, Welch {:.2}",
        (vu / 16.0).sqrt(),
        (va / 16.0).sqrt(),
        (ma - mu).abs() / se
    );
    assert!(mu.abs() > 8.0 * se, "no power: uniform {mu} with the comparison's standard error {se}");
    assert!((ma - mu).abs() < 4.0 * se, "adaptive attached {ma} vs uniform attached {mu} (standard error {se})");
    // Deterministic mode (the fixed-point attached kernel): the same bits twice, float's value
    // to rounding.
    let fixed = renderer.backward_adaptive(&opts, &a, &sampling, GradMode::Deterministic).unwrap();
    let again = renderer.backward_adaptive(&opts, &a, &sampling, GradMode::Deterministic).unwrap();
    let float = renderer.backward_adaptive(&opts, &a, &sampling, GradMode::Float).unwrap();
    crate::support::assert_fixed_matches_float(&fixed, &again, &float);
}

/// `optimize` with attached sampling recovers the index of refraction of a glass sphere (1.5,
/// Mitsuba's bk7 over air) from 1.3, a parameter detached sampling refuses by name.
#[test]
fn optimize_recovers_the_ior_of_a_glass_sphere() {
    let out = tempfile::tempdir().unwrap();
    let dir = out.path().join("run");
    let scene = format!("{}/tests/data/scenes/attached_sphere.xml", env!("CARGO_MANIFEST_DIR"));
    let args =
        ["--param", "glass.bsdf.eta=1.3", "--target-set", "glass.bsdf.eta=1.5", "--width", "32", "--height", "32"];
    let run = crate::cli::pathgrad()
        .args(["optimize", &scene])
        .args(args)
        .args(["--sampling", "attached", "--iters", "80", "--lr", "0.01", "-o"])
        .arg(&dir)
        .output()
        .unwrap();
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    let params: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("params.json")).unwrap()).unwrap();
    let eta = params["glass.bsdf.eta"][0].as_f64().unwrap();
    // The target's η is 1.5 / 1.000277 (air); 80 steps of 0.01 from 1.3 end within 0.01 of it.
    assert!((eta - 1.4996).abs() < 0.01, "recovered η {eta}");
    let detached = crate::cli::pathgrad()
        .args(["optimize", &scene])
        .args(args)
        .args(["--iters", "2", "-o"])
        .arg(out.path().join("detached"))
        .output()
        .unwrap();
    assert!(!detached.status.success());
    assert!(String::from_utf8_lossy(&detached.stderr).contains("differentiate it with --sampling attached"));
}

/// Attached sampling is refused, by name, where its Jacobians are not built: a textured diffuse
/// albedo, a spot's nearest-filtered texture, a projector, a point light beside a rough conductor or without next-event
/// estimation, a plastic (in reverse and forward mode), and an index of refraction's image
/// gradient under detached sampling. Deterministic mode is not refused: it gives the same bits
/// twice and the float kernel's value to rounding.
#[test]
fn attached_sampling_refuses_what_it_does_not_cover() {
    use pathgrad::backend::Backend;
    use pathgrad::gpu::Renderer;
    use pathgrad::gpu::renderer::GradMode;
    let gpu = crate::support::TestGpu::new();
    let a = weights(8, 8);
    let data = format!("{}/tests/data/scenes", env!("CARGO_MANIFEST_DIR"));
    let dir = tempfile::tempdir().unwrap();
    std::fs::copy(format!("{data}/attached_sky.exr"), dir.path().join("attached_sky.exr")).unwrap();
    // `name` with `from` replaced by `to`, loaded from a scratch copy beside the environment map.
    let variant = |name: &str, from: &str, to: &str| {
        let xml = std::fs::read_to_string(format!("{data}/{name}.xml")).unwrap();
        assert!(xml.contains(from), "{name} has no {from}");
        let path = dir.path().join(format!("{name}-variant.xml"));
        std::fs::write(&path, xml.replace(from, to)).unwrap();
        pathgrad::scene::load(path.to_str().unwrap(), &[]).unwrap()
    };
    // A diffuse floor whose albedo jumps along it (a checkerboard), an emitter whose radiance
    // does (a nearest-filtered bitmap), and a plastic floor (no attached sampler).
    let floor = r#"<rgb name="reflectance" value="0.5"/>"#;
    let checker = r#"<texture type="checkerboard" name="reflectance"/>"#;
    let textured = variant("attached_floor", floor, checker);
    let opts = attached(&textured, 8, 1);
    let err = pathgrad::cpu::backward(&textured, &opts, &a).unwrap_err().to_string();
    assert!(
        err.contains("Sampling::Attached") && err.contains("`diffuse` material whose albedo is a checkerboard"),
        "{err}"
    );
    let mut renderer = Renderer::new(&gpu.ctx, &textured).unwrap();
    let err = renderer.backward(&opts, &a, GradMode::Float).unwrap_err().to_string();
    assert!(err.contains("albedo is a checkerboard"), "{err}");
    std::fs::copy(format!("{data}/attached_ramp.exr"), dir.path().join("attached_ramp.exr")).unwrap();
    let nearest = variant(
        "attached_slab_table",
        r#"<texture type="bitmap" name="radiance">"#,
        r#"<texture type="bitmap" name="radiance"><string name="filter_type" value="nearest"/>"#,
    );
    let err = pathgrad::cpu::backward(&nearest, &attached(&nearest, 8, 1), &a).unwrap_err().to_string();
    assert!(err.contains("area emitter whose radiance is a nearest-filtered bitmap"), "{err}");
    // A glass whose reflectance is a texture: its weight would vary with the hit point.
    let tinted = variant(
        "attached_sphere",
        r#"<float name="int_ior" value="1.5"/>"#,
        r#"<float name="int_ior" value="1.5"/><texture type="bitmap" name="specular_reflectance"><string name="filename" value="attached_ramp.exr"/></texture>"#,
    );
    let err = pathgrad::cpu::backward(&tinted, &attached(&tinted, 8, 1), &a).unwrap_err().to_string();
    assert!(err.contains("`dielectric` with a textured reflectance or transmittance"), "{err}");
    // Spot lights: plain and with a bilinear texture, taken; a texture read by nearest texels
    // (jumps between them), and a projector (its frame's edges), refused.
    let spot =
        r#"<emitter type="spot"><transform name="to_world"><lookat origin="0, 1, 0" target="0, 0, 0"/></transform>"#;
    let floor_shape = r#"<shape type="rectangle" id="floor">"#;
    let ramp = r#"<texture type="bitmap" name="texture"><string name="filename" value="attached_ramp.exr"/>"#;
    for taken in [format!("{spot}</emitter>"), format!("{spot}{ramp}</texture></emitter>")] {
        let lit = variant("attached_floor", floor_shape, &format!("{taken}{floor_shape}"));
        pathgrad::cpu::backward(&lit, &attached(&lit, 8, 1), &a).unwrap();
    }
    let nearest =
        format!(r#"{spot}{ramp}<string name="filter_type" value="nearest"/></texture></emitter>{floor_shape}"#);
    let lit = variant("attached_floor", floor_shape, &nearest);
    let err = pathgrad::cpu::backward(&lit, &attached(&lit, 8, 1), &a).unwrap_err().to_string();
    assert!(err.contains("read by nearest texels (it jumps between them): light 1 of its 1"), "{err}");
    let projector = r#"<emitter type="projector"><transform name="to_world"><lookat origin="0, 1, 0" target="0, 0, 0"/></transform><texture type="bitmap" name="irradiance"><string name="filename" value="attached_ramp.exr"/></texture></emitter>"#;
    let lit = variant("attached_floor", floor_shape, &format!("{projector}{floor_shape}"));
    let err = pathgrad::cpu::backward(&lit, &attached(&lit, 8, 1), &a).unwrap_err().to_string();
    assert!(err.contains("a projector (its light jumps to 0 at its frame's edges)"), "{err}");
    // A point light beside a rough conductor (no next-event estimation at its vertices), and a
    // point light without next-event estimation: its light would be missing.
    let point = r#"<emitter type="point"><point name="position" x="0" y="3" z="0"/></emitter>"#;
    let sky = r#"<emitter type="envmap">"#;
    let lit = variant("attached_rough", sky, &format!("{point}{sky}"));
    let err = pathgrad::cpu::backward(&lit, &attached(&lit, 8, 1), &a).unwrap_err().to_string();
    assert!(err.contains("a light without area and a `roughconductor`"), "{err}");
    let lit = variant("attached_floor", sky, &format!("{point}{sky}"));
    let no_nee = RenderOptions { nee: false, ..attached(&lit, 8, 1) };
    let err = pathgrad::cpu::backward(&lit, &no_nee, &a).unwrap_err().to_string();
    assert!(err.contains("next-event estimation is off"), "{err}");
    pathgrad::cpu::backward(&lit, &attached(&lit, 8, 1), &a).unwrap();
    let plastic = variant("attached_floor", r#"<bsdf type="diffuse">"#, r#"<bsdf type="roughplastic">"#);
    let err = pathgrad::cpu::backward(&plastic, &attached(&plastic, 8, 1), &a).unwrap_err().to_string();
    assert!(err.contains("`roughplastic` material"), "{err}");
    let sphere = scenes::data_scene("attached_sphere");
    let opts = attached(&sphere, 8, 1);
    let mut renderer = Renderer::new(&gpu.ctx, &sphere).unwrap();
    // Deterministic mode takes attached sampling (its fixed-point kernel): the same bits twice,
    // float's value to rounding.
    let fixed = renderer.backward(&opts, &a, GradMode::Deterministic).unwrap();
    let again = renderer.backward(&opts, &a, GradMode::Deterministic).unwrap();
    let float = renderer.backward(&opts, &a, GradMode::Float).unwrap();
    crate::support::assert_fixed_matches_float(&fixed, &again, &float);
    // Detached, the index of refraction's image gradient would be zeros: refused by name.
    let detached = RenderOptions { sampling: Sampling::Detached, ..opts };
    let err = renderer.image_gradient(&detached, "glass.bsdf.eta").unwrap_err().to_string();
    assert!(err.contains("glass.bsdf.eta") && err.contains("--sampling attached"), "{err}");
    let err = pathgrad::cpu::image_gradient(&sphere, &detached, "glass.bsdf.eta").unwrap_err().to_string();
    assert!(err.contains("glass.bsdf.eta") && err.contains("--sampling attached"), "{err}");
    let err = pathgrad::cpu::image_gradient(&plastic, &attached(&plastic, 8, 1), "glass.bsdf.eta").unwrap_err();
    assert!(err.to_string().contains("`roughplastic` material"), "{err}");
    // An anisotropic rough conductor: its sampler's frame would follow ∂p/∂u, whose Jacobians are
    // not built.
    let aniso = variant(
        "attached_rough",
        r#"<float name="alpha" value="0.1"/>"#,
        r#"<float name="alpha_u" value="0.1"/><float name="alpha_v" value="0.3"/>"#,
    );
    let err = pathgrad::cpu::backward(&aniso, &attached(&aniso, 8, 1), &a).unwrap_err().to_string();
    assert!(err.contains("anisotropic or texture-roughened `roughconductor`"), "{err}");
    // The differential strategy samples its vertex by ∂f/∂α: not an attached sampler.
    let rough = scenes::data_scene("attached_rough");
    let id = rough.params.find("ball.bsdf.alpha.value").unwrap();
    let strategy = pathgrad::integrator::Strategy::Diff {
        target: id,
        q: 0.5,
        placement: pathgrad::integrator::PlacementMis::Balance,
    };
    let diff = RenderOptions { strategy, ..attached(&rough, 8, 1) };
    let err = pathgrad::cpu::backward(&rough, &diff, &a).unwrap_err().to_string();
    assert!(err.contains("bsdf strategy only"), "{err}");
    let err = Renderer::new(&gpu.ctx, &rough).unwrap().backward(&diff, &a, GradMode::Float).unwrap_err().to_string();
    assert!(err.contains("bsdf strategy only"), "{err}");
}

/// The replay returns Φ to zero as it returns the radiance to zero (ALGORITHMS.md §9 test (d)):
/// after the last vertex every term of Γ has been removed, on every path of the ten scenes,
/// up to rounding amplified by the completed Jacobians' inverses (10⁻³ of Γ's largest entry).
#[test]
fn the_replay_returns_gamma_to_zero() {
    use glam::Vec3;
    use pathgrad::attached::Row6;
    use pathgrad::cpu::path::{GradSink, trace_path};
    use pathgrad::rng::PassTag;
    use pathgrad::scene::flat::FlatScene;
    for name in [
        "attached_sphere",
        "attached_slab",
        "attached_pane",
        "attached_mirror",
        "attached_rough_sphere",
        "attached_rough_sphere_beckmann",
        "attached_floor",
        "attached_slab_table",
        "attached_slab_albedo",
        "attached_ball",
        "attached_lamp",
        "attached_panel",
        "attached_point",
    ] {
        let scene = scenes::data_scene(name);
        let opts = attached(&scene, 24, 2);
        let flat = FlatScene::new(&scene).unwrap();
        let globals = opts.globals(&scene, &flat, PassTag::Gradient);
        let camera = opts.view_camera(&pathgrad::integrator::View::current(&scene), PassTag::Gradient);
        let (mut worst, mut nonzero) = (0.0f32, 0);
        for pixel in 0..opts.width * opts.height {
            for sample in 0..opts.spp {
                let adj = Vec3::new(0.7, 1.0, 1.3);
                let mut gamma = Row6::default();
                let total = trace_path::<false>(
                    &flat,
                    &globals,
                    &camera,
                    pixel,
                    sample,
                    adj,
                    Vec3::ZERO,
                    &mut GradSink::None,
                    &mut gamma,
                );
                let start = gamma.max_abs();
                let mut grads = vec![0.0f64; flat.params.len()];
                trace_path::<true>(
                    &flat,
                    &globals,
                    &camera,
                    pixel,
                    sample,
                    adj,
                    total,
                    &mut GradSink::Backward(&mut grads),
                    &mut gamma,
                );
                if start > 0.0 {
                    nonzero += 1;
                    worst = worst.max(gamma.max_abs() / start);
                }
            }
        }
        println!("{name}: {nonzero} paths with a derivative by the camera ray; worst residual {worst:.2e} of Γ");
        assert!(nonzero > 0 && worst < 1e-3, "{name}: residual {worst}");
    }
}

//! The GPU renderer against the CPU reference: same scene, same seed, per path and per pixel.

use pathgrad::backend::Backend;
use pathgrad::gpu::Renderer;
use pathgrad::integrator::RenderOptions;
use pathgrad::scene::builtin::{self, BUILTIN_SCENES};

use crate::support::TestGpu;

/// Per-channel relative tolerance on paths that took the same decisions (ALGORITHMS.md §10): the
/// twins run the same f32 operations in the same order, but GLSL's transcendentals (exp, log, sin,
/// cos, pow) and normalize differ from Rust's by a few ulp, which the path's products amplify by at
/// most its length (≤ 6 vertices × a handful of operations each).
const REL_TOL: f32 = 1e-4;
/// Absolute floor for channels near zero.
const ABS_TOL: f32 = 1e-6;
/// Paths may take different discrete decisions when a few-ulp difference moves a value across a
/// threshold (a roulette uniform, a grazing visibility test); ALGORITHMS.md §10 budgets 0.1 % of
/// paths. With one sample per pixel a pixel *is* a path.
const MISMATCH_BUDGET: f64 = 1e-3;

#[test]
fn gpu_equals_cpu_per_path_on_every_builtin_and_test_scene() {
    let gpu = TestGpu::new();
    let mut scenes: Vec<_> = BUILTIN_SCENES.iter().map(|(name, _)| builtin::load(name).unwrap()).collect();
    scenes.push(crate::support::scenes::textured_environment());
    scenes.push(crate::support::scenes::open_furnace());
    scenes.push(crate::support::scenes::deep_meshes());
    for name in [
        "texture_checkerboard",
        "texture_filter_wrap",
        "emitter_envmap",
        "emitter_point_spot_directional",
        "bsdf_roughplastic",
        "bsdf_smooth",
        "bsdf_plastic",
        "bsdf_roughdielectric",
        "medium_in_dielectric",
        "sensor_orthographic",
        "sensor_thinlens",
        "bsdf_roughconductor_anisotropic",
        "bsdf_roughdielectric_anisotropic",
        "shape_instance",
        "bsdf_normalmap",
        "bsdf_bumpmap",
        "texture_roughness",
        "texture_blend_weight",
        "texture_specular_reflectance",
        "bsdf_mask",
        "texture_mask_opacity",
        "bsdf_blend_conductor",
        "texture_mesh_attribute",
        "emitter_area_texture",
        "emitter_area_texture_uv",
    ] {
        scenes.push(crate::support::scenes::conformance(name));
    }
    for scene in &scenes {
        primal_agrees_per_path(&gpu, scene);
    }
}

/// The principled material (issue 31), constant and textured, textured specular colours
/// (`bsdf_smooth_textured`) and `volume` textures (`texture_volume`, `texture_volume_colours`), as
/// [`gpu_equals_cpu_per_path_on_every_builtin_and_test_scene`] compares the rest.
#[test]
fn issue_31_principled_gpu_equals_cpu_per_path() {
    let gpu = TestGpu::new();
    for name in [
        "bsdf_principled",
        "bsdf_principled_textured",
        "bsdf_principled_textured_scalars",
        "bsdf_smooth_textured",
        "texture_volume",
        "texture_volume_colours",
    ] {
        primal_agrees_per_path(&gpu, &crate::support::scenes::conformance(name));
    }
}

/// Depth counting (Mitsuba's volpath family: a thindielectric's transmission and a mask's
/// pass-through are no bounce) and `hide_emitters` (issue 31), in their conformance scenes and
/// with the other counting (path), as the rest are compared.
#[test]
fn issue_31_depth_counting_and_hide_emitters_gpu_equals_cpu_per_path() {
    let gpu = TestGpu::new();
    for name in ["integrator_volpath_thin_depth", "integrator_hide_emitters"] {
        let mut scene = crate::support::scenes::conformance(name);
        assert!(scene.null_uncounted, "{name}: a volpath-family scene");
        primal_agrees_per_path(&gpu, &scene);
        scene.null_uncounted = false;
        scene.source = format!("{name} counted as path");
        primal_agrees_per_path(&gpu, &scene);
    }
}

/// The thin principled material (issue 31): every lobe with constants (the conformance row) and
/// every kind of texture it takes (`tests/data/scenes/principledthin_textured.xml`).
#[test]
fn issue_31_principledthin_gpu_equals_cpu_per_path() {
    let gpu = TestGpu::new();
    primal_agrees_per_path(&gpu, &crate::support::scenes::conformance("bsdf_principledthin"));
    primal_agrees_per_path(&gpu, &crate::support::scenes::data_scene("principledthin_textured"));
}

/// Issue 38: a renderer's flattened scene has the CPU reference's BVH without its leaf-order
/// positions, which the upload writes from the meshes chunk by chunk. A bumpy grid of more
/// triangles than one staging chunk holds, behind a light mesh (so its triangle ids do not start
/// at 0), renders path by path as the CPU reference's copy of the positions does.
#[test]
fn issue_38_leaf_positions_made_by_the_upload_agree_across_chunks() {
    use glam::Vec3;
    use pathgrad::scene::flat::FlatScene;
    use pathgrad::scene::shapes::{Geometry, quad};
    use pathgrad::scene::{Camera, PixelFilter, Scene};
    const N: u32 = 470;
    let camera = Camera {
        position: Vec3::new(0.0, 1.2, 2.2),
        target: Vec3::ZERO,
        up: Vec3::Y,
        fov_y_degrees: 45.0,
        width: 96,
        height: 96,
        filter: PixelFilter::Box,
        lens: pathgrad::scene::Lens::Pinhole,
        window: pathgrad::scene::FilmWindow::default(),
    };
    let mut s = Scene::new("test:issue-38-grid", camera);
    let grey = s.add_diffuse("grey", Vec3::splat(0.6)).unwrap();
    let black = s.add_diffuse("light", Vec3::ZERO).unwrap();
    // Facing down (`u × v` = −y), above the grid.
    s.add_mesh("light", quad(Vec3::new(0.0, 2.0, 0.0), Vec3::X * 0.5, Vec3::Z * 0.5), black, Some(Vec3::splat(8.0)))
        .unwrap();
    let positions = (0..=N)
        .flat_map(|j| {
            (0..=N).map(move |i| {
                let (x, z) = (2.0 * i as f32 / N as f32 - 1.0, 2.0 * j as f32 / N as f32 - 1.0);
                Vec3::new(x, 0.05 * (17.0 * x).sin() * (13.0 * z).cos(), z)
            })
        })
        .collect();
    let indices = (0..N)
        .flat_map(|j| {
            (0..N).flat_map(move |i| {
                let v = j * (N + 1) + i;
                [[v, v + N + 1, v + 1], [v + 1, v + N + 1, v + N + 2]]
            })
        })
        .collect();
    s.add_mesh("grid", Geometry { positions, normals: None, uvs: None, indices, ..Default::default() }, grey, None)
        .unwrap();
    let per_chunk = pathgrad::gpu::buffer::UPLOAD_CHUNK_BYTES / size_of::<pathgrad::contract::TriPositions>();
    assert!(s.triangle_count() > per_chunk, "{} triangles fit one chunk of {per_chunk}", s.triangle_count());
    let full = FlatScene::new(&s).unwrap();
    let device = FlatScene::for_device_reporting(&s, &mut pathgrad::phases::PhaseReport::new()).unwrap();
    assert!(device.bvh.tris.is_empty() && full.bvh.tris.len() == s.triangle_count());
    assert_eq!((&device.bvh.nodes, &device.bvh.prim_ids), (&full.bvh.nodes, &full.bvh.prim_ids), "the same tree");
    drop((full, device));
    primal_agrees_per_path(&TestGpu::new(), &s);
}

/// One path per pixel of `scene` on the GPU and the CPU reference: within [`REL_TOL`] and
/// [`ABS_TOL`], all but [`MISMATCH_BUDGET`] of them.
fn primal_agrees_per_path(gpu: &TestGpu, scene: &pathgrad::scene::Scene) {
    let name = &scene.source;
    let opts = RenderOptions { width: 96, height: 96, spp: 1, seed: 7, ..RenderOptions::for_scene(scene) };
    let mut renderer = Renderer::new(&gpu.ctx, scene).unwrap();
    let g = renderer.render(&opts).unwrap();
    let c = pathgrad::cpu::render(scene, &opts).unwrap();
    let mut mismatched = 0;
    let mut worst = 0.0f32;
    for (a, b) in g.as_slice().chunks(3).zip(c.as_slice().chunks(3)) {
        let ok = a.iter().zip(b).all(|(x, y)| (x - y).abs() <= REL_TOL * x.abs().max(y.abs()) + ABS_TOL);
        if !ok {
            mismatched += 1;
        } else {
            for (x, y) in a.iter().zip(b) {
                if x.abs().max(y.abs()) > 1e-3 {
                    worst = worst.max((x - y).abs() / x.abs().max(y.abs()));
                }
            }
        }
    }
    let paths = (opts.width * opts.height) as f64;
    println!(
        "{name}: {mismatched} of {paths} paths differ beyond tolerance; worst relative difference on the rest {worst:.2e}"
    );
    assert!(f64::from(mismatched) <= MISMATCH_BUDGET * paths, "{name}: {mismatched} mismatched paths");
}

/// A reference render draws other paths than a plain render of the same seed (its key's pass tag
/// differs), is deterministic, and estimates the same image: the two means over the image agree
/// within 5 standard errors derived from the per-pixel differences.
#[test]
fn reference_renders_are_independent_of_plain_renders_of_any_seed() {
    let gpu = TestGpu::new();
    let scene = builtin::load("cornell-box").unwrap();
    let mut renderer = Renderer::new(&gpu.ctx, &scene).unwrap();
    let opts = RenderOptions { width: 32, height: 32, spp: 4, seed: 11, ..RenderOptions::for_scene(&scene) };
    let plain = renderer.render(&opts).unwrap();
    let reference = renderer.render_reference(&opts).unwrap();
    assert_eq!(reference.as_slice(), renderer.render_reference(&opts).unwrap().as_slice(), "deterministic");
    let same = plain.as_slice().iter().zip(reference.as_slice()).filter(|(a, b)| a == b && **a != 0.0).count();
    assert!(same < 10, "{same} lit values are bitwise equal: the reference replays the plain render's paths");
    let d: Vec<f64> = plain.as_slice().iter().zip(reference.as_slice()).map(|(a, b)| f64::from(a - b)).collect();
    let n = d.len() as f64;
    let mean = d.iter().sum::<f64>() / n;
    let se = (d.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0) / n).sqrt();
    assert!(mean.abs() < 5.0 * se, "mean difference {mean} ± {se}");
}

/// Any valid mesh builds and renders: the fan-triangulated 1000-gon and the capped 1000-segment
/// cylinder of `deep_meshes` get a tree that fits the traversal stack, and their GPU render (in
/// `gpu_equals_cpu_per_path_on_every_builtin_and_test_scene`) raises no stack overflow.
#[test]
fn deep_meshes_fit_the_traversal_stack() {
    let scene = crate::support::scenes::deep_meshes();
    let flat = pathgrad::scene::flat::FlatScene::new(&scene).unwrap();
    println!("deep meshes: {} nodes, depth {}", flat.bvh.nodes.len(), flat.bvh.depth);
    assert!(flat.bvh.depth < pathgrad::contract::BVH_STACK_SIZE, "depth {}", flat.bvh.depth);
    assert_eq!(flat.bvh.prim_ids.len(), scene.triangle_count());
    let mut ids = flat.bvh.prim_ids.clone();
    ids.sort_unstable();
    assert!(ids.iter().enumerate().all(|(i, &id)| i as u32 == id), "every triangle sits in exactly one leaf");
}

/// Both schedules of the kernels give the same bits: lanes taking work until none is left
/// (the default) and one path per invocation (drivers with a loop budget), for the image, the
/// forward-mode image gradient and deterministic gradients, uniform and adaptive — which lane
/// traces an item never changes its result.
#[test]
fn both_schedules_give_the_same_bits() {
    let gpu = TestGpu::new();
    let scene = builtin::load("cornell-box").unwrap();
    let mut renderer = Renderer::new(&gpu.ctx, &scene).unwrap();
    let opts = RenderOptions { width: 40, height: 28, spp: 3, seed: 5, ..RenderOptions::for_scene(&scene) };
    let adjoint = pathgrad::image::Image::from_rgb(40, 28, vec![1e-2; 40 * 28 * 3]).unwrap();
    let mode = pathgrad::gpu::renderer::GradMode::Deterministic;
    let sampling = pathgrad::adaptive::PixelSampling::from_adjoint(&adjoint, Default::default()).unwrap();
    let mut run = |one_path: bool| {
        renderer.set_one_path_per_invocation(one_path);
        let image = renderer.render(&opts).unwrap();
        let forward = renderer.image_gradient(&opts, "sphere.bsdf.alpha.value").unwrap();
        let grads = renderer.backward(&opts, &adjoint, mode).unwrap();
        let adaptive = renderer.backward_adaptive(&opts, &adjoint, &sampling, mode).unwrap();
        [image.as_slice().to_vec(), forward.as_slice().to_vec(), grads.values().to_vec(), adaptive.values().to_vec()]
    };
    let a = run(false);
    let b = run(true);
    for (what, (x, y)) in ["images", "image gradients", "gradients", "adaptive gradients"].iter().zip(a.iter().zip(&b))
    {
        assert!(x.iter().any(|&v| v != 0.0), "{what}: all zero");
        assert_eq!(x, y, "{what}");
    }
}

/// Linear curves (issue 31), tessellated into cones and joint spheres, as
/// [`gpu_equals_cpu_per_path_on_every_builtin_and_test_scene`] compares the rest.
#[test]
fn issue_31_linearcurve_gpu_equals_cpu_per_path() {
    let gpu = TestGpu::new();
    primal_agrees_per_path(&gpu, &crate::support::scenes::conformance("shape_linearcurve"));
}

/// B-spline curves (issue 31), tessellated into rings along each segment.
#[test]
fn issue_31_bsplinecurve_gpu_equals_cpu_per_path() {
    let gpu = TestGpu::new();
    primal_agrees_per_path(&gpu, &crate::support::scenes::conformance("shape_bsplinecurve"));
}

/// SDF grids (issue 31), tessellated into the zero set of the trilinear interpolant with
/// Mitsuba's smooth and analytic normals.
#[test]
fn issue_31_sdfgrid_gpu_equals_cpu_per_path() {
    let gpu = TestGpu::new();
    primal_agrees_per_path(&gpu, &crate::support::scenes::conformance("shape_sdfgrid"));
}

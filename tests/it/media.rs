//! Participating media: closed forms (a slab's transmittance, a white furnace), a constant grid
//! against the homogeneous medium, ratio-tracked NEE against delta-tracked emitter hits on the
//! CPU reference; the kernels against it path by path, in the primal and in both gradient modes;
//! the primal against Mitsuba 3 `volpath`; differential path sampling in media (its vertex in a
//! medium by the phase function's g, or on a surface), per path and unbiased.

use std::path::Path;

use glam::UVec3;
use pathgrad::backend::Backend;
use pathgrad::cpu::Reference;
use pathgrad::image::Image;
use pathgrad::integrator::RenderOptions;
use pathgrad::scene::Scene;
use pathgrad::scene::volume::Grid;

use crate::support::TestGpu;

fn scene(dir: &Path, body: &str) -> Scene {
    let path = dir.join("scene.xml");
    std::fs::write(&path, format!(r#"<scene version="3.0.0">{body}</scene>"#)).unwrap();
    pathgrad::scene::load(path.to_str().unwrap(), &[]).unwrap()
}

fn sensor(origin: &str, fov: f32, size: u32) -> String {
    format!(
        r#"<sensor type="perspective"><float name="fov" value="{fov}"/><transform name="to_world"><lookat origin="{origin}" target="0, 0, 0" up="0, 1, 0"/></transform><film type="hdrfilm"><integer name="width" value="{size}"/><integer name="height" value="{size}"/></film></sensor>"#
    )
}

/// Mean and standard error of the pixel values of channel 0.
fn mean_and_error(image: &Image) -> (f64, f64) {
    let v: Vec<f64> = image.as_slice().iter().step_by(3).map(|&x| f64::from(x)).collect();
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, (var / n).sqrt())
}

/// A camera looking through a purely absorbing cube (σ_t = 0.7, thickness 2 along the view) at
/// a large emitter of radiance 2: each pixel is 2·exp(−1.4) in expectation (delta tracking keeps
/// a path with probability exp(−σ_t d)). A z-test over the pixels, |z| < 4.
#[test]
fn a_slab_transmits_exp_minus_sigma_d() {
    let dir = tempfile::tempdir().unwrap();
    let s = scene(
        dir.path(),
        &format!(
            r#"{}<integrator type="volpath"/>
            <shape type="cube" id="slab"><bsdf type="null"/><medium type="homogeneous" name="interior"><float name="sigma_t" value="0.7"/><float name="albedo" value="0"/></medium></shape>
            <shape type="rectangle" id="light"><emitter type="area"><rgb name="radiance" value="2, 2, 2"/></emitter><transform name="to_world"><scale value="20"/><translate z="-4"/></transform></shape>"#,
            sensor("0, 0, 6", 2.0, 16)
        ),
    );
    let mut cpu = Reference::new(&s).unwrap();
    let image = cpu.render(&RenderOptions { spp: 64, seed: 1, ..RenderOptions::for_scene(&s) }).unwrap();
    let (mean, error) = mean_and_error(&image);
    let expected = 2.0 * (-0.7f64 * 2.0).exp();
    // Every ray crosses within 0.02 % of 2 units (fov 2°): the closed form holds to 1e-4.
    println!("slab: {mean} ± {error}, expected {expected}");
    assert!((mean - expected).abs() < 4.0 * error, "{mean} ± {error} vs {expected}");
    assert!(error < 0.02 * expected, "the test has the power to see a 2 % error");
}

/// One voxel of 3e38 in a grid of density 0.7 slows tracking only near itself: each medium has a
/// majorant grid (`MajorantGrid`, 8 voxels a cell), so rays through the slab's middle, far from
/// the hot corner, step at the majorant of their own cells. With one majorant for the whole grid
/// every flight would end at `MAX_TRACKING_STEPS` with weight 0 (a black image). The slab is the
/// one of `a_slab_transmits_exp_minus_sigma_d`, so each pixel is 2·exp(−1.4) in expectation, on
/// the CPU reference and on the GPU.
#[test]
fn a_hot_voxel_slows_tracking_only_near_itself() {
    let gpu = TestGpu::new();
    let dir = tempfile::tempdir().unwrap();
    let mut density = vec![0.7f32; 32 * 32 * 4];
    density[(3 * 32 + 31) * 32 + 31] = 3e38;
    std::fs::write(dir.path().join("hot.vol"), Grid::new(UVec3::new(32, 32, 4), 1, density).unwrap().to_bytes())
        .unwrap();
    let s = scene(
        dir.path(),
        &format!(
            r#"{}<integrator type="volpath"/>
            <shape type="cube" id="slab"><bsdf type="null"/><medium type="heterogeneous" name="interior">
                <volume type="gridvolume" name="sigma_t"><string name="filename" value="hot.vol"/><transform name="to_world"><scale value="2"/><translate x="-1" y="-1" z="-1"/></transform></volume>
                <float name="albedo" value="0"/></medium></shape>
            <shape type="rectangle" id="light"><emitter type="area"><rgb name="radiance" value="2, 2, 2"/></emitter><transform name="to_world"><scale value="20"/><translate z="-4"/></transform></shape>"#,
            sensor("0, 0, 6", 2.0, 16)
        ),
    );
    let flat = pathgrad::scene::flat::FlatScene::new(&s).unwrap();
    assert_eq!((flat.media[0].grid_x, flat.media[0].grid_y, flat.media[0].grid_z), (4, 4, 1));
    let expected = 2.0 * (-0.7f64 * 2.0).exp();
    let options = RenderOptions { spp: 64, seed: 1, ..RenderOptions::for_scene(&s) };
    let cpu = Reference::new(&s).unwrap().render(&options).unwrap();
    let gpu_image = pathgrad::gpu::Renderer::new(&gpu.ctx, &s).unwrap().render(&options).unwrap();
    for (backend, image) in [("CPU", &cpu), ("GPU", &gpu_image)] {
        let (mean, error) = mean_and_error(image);
        println!("hot voxel, {backend}: {mean} ± {error}, expected {expected}");
        assert!((mean - expected).abs() < 4.0 * error, "{backend}: {mean} ± {error} vs {expected}");
        assert!(error < 0.02 * expected, "{backend}: the test has the power to see a 2 % error");
    }
}

/// A heterogeneous grid of constant density whose box holds its shape renders bit for bit like
/// the homogeneous medium of that density: the same majorant, the same extinction at every point
/// of the shape, so the same decisions on every path.
#[test]
fn a_constant_grid_renders_like_the_homogeneous_medium() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("flat.vol"), Grid::new(UVec3::new(2, 3, 2), 1, vec![0.9; 12]).unwrap().to_bytes())
        .unwrap();
    let body = |sigma: &str| {
        format!(
            r#"{}<integrator type="volpath"><integer name="max_depth" value="8"/></integrator><emitter type="constant"><rgb name="radiance" value="0.5, 0.6, 0.7"/></emitter>
            <shape type="rectangle" id="floor"><bsdf type="diffuse"/><transform name="to_world"><scale value="5"/><rotate x="1" angle="-90"/><translate y="-1"/></transform></shape>
            <shape type="sphere" id="ball"><bsdf type="null"/>{sigma}<rgb name="albedo" value="0.8, 0.7, 0.6"/><phase type="hg"><float name="g" value="0.4"/></phase></medium></shape>"#,
            sensor("0, 1, 5", 40.0, 24)
        )
    };
    let grid = scene(
        dir.path(),
        &body(
            r#"<medium type="heterogeneous" name="interior"><volume type="gridvolume" name="sigma_t"><string name="filename" value="flat.vol"/><transform name="to_world"><scale value="2"/><translate x="-1" y="-1" z="-1"/></transform></volume>"#,
        ),
    );
    let constant =
        scene(dir.path(), &body(r#"<medium type="homogeneous" name="interior"><float name="sigma_t" value="0.9"/>"#));
    let opts = RenderOptions { spp: 4, seed: 3, ..RenderOptions::for_scene(&grid) };
    let a = Reference::new(&grid).unwrap().render(&opts).unwrap();
    let b = Reference::new(&constant).unwrap().render(&opts).unwrap();
    let bits = |i: &Image| i.as_slice().iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&a), bits(&b));
    assert!(a.mean()[0] > 0.0);
}

/// A heterogeneous medium exists only inside its σ_t volume's box, as in Mitsuba 3: in a cube
/// [−1, 1]³ holding an absorbing medium of constant σ_t = 0.7, a plain `<float>` σ_t fills only
/// [0, 1]³ (Mitsuba's `constvolume` over the unit cube), and a `constvolume` moved by its
/// `to_world` fills only its own box. Looking along −z at an emitter of radiance 2 through a
/// narrow field of view: rays through x, y ∈ (0, 1) cross one unit of medium (2·e^{−0.7}), rays
/// through x, y ∈ (−1, 0) none (2), and a box pushed half out of the cube along z is crossed over
/// half a unit (2·e^{−0.35}). The same medium declared `homogeneous` fills the cube (2·e^{−1.4}).
/// CPU reference and kernels, z-tests over the pixels, |z| < 4.
#[test]
fn a_heterogeneous_medium_exists_only_in_its_volume_box() {
    let gpu = TestGpu::new();
    let dir = tempfile::tempdir().unwrap();
    let narrow = |x: f32, y: f32| {
        format!(
            r#"<sensor type="perspective"><float name="fov" value="2"/><transform name="to_world"><lookat origin="{x}, {y}, 6" target="{x}, {y}, 0" up="0, 1, 0"/></transform><film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/></film></sensor>"#
        )
    };
    let cases = [
        ("heterogeneous", r#"<float name="sigma_t" value="0.7"/>"#, (0.5, 0.5), 2.0 * (-0.7f64).exp()),
        ("heterogeneous", r#"<float name="sigma_t" value="0.7"/>"#, (-0.5, -0.5), 2.0),
        (
            "heterogeneous",
            r#"<volume type="constvolume" name="sigma_t"><float name="value" value="0.7"/><transform name="to_world"><translate x="-0.8" y="-0.8" z="0.5"/></transform></volume>"#,
            (-0.3, -0.3),
            2.0 * (-0.35f64).exp(),
        ),
        ("homogeneous", r#"<float name="sigma_t" value="0.7"/>"#, (0.5, 0.5), 2.0 * (-1.4f64).exp()),
    ];
    for (kind, sigma, (x, y), expected) in cases {
        let s = scene(
            dir.path(),
            &format!(
                r#"{}<integrator type="volpath"/>
                <shape type="cube" id="slab"><bsdf type="null"/><medium type="{kind}" name="interior">{sigma}<float name="albedo" value="0"/></medium></shape>
                <shape type="rectangle" id="light"><emitter type="area"><rgb name="radiance" value="2, 2, 2"/></emitter><transform name="to_world"><scale value="20"/><translate z="-4"/></transform></shape>"#,
                narrow(x, y)
            ),
        );
        let opts = RenderOptions { spp: 64, seed: 1, ..RenderOptions::for_scene(&s) };
        let cpu = Reference::new(&s).unwrap().render(&opts).unwrap();
        let kernels = pathgrad::gpu::Renderer::new(&gpu.ctx, &s).unwrap().render(&opts).unwrap();
        for (what, image) in [("cpu", &cpu), ("gpu", &kernels)] {
            let (mean, error) = mean_and_error(image);
            println!("{kind} {sigma} at ({x}, {y}), {what}: {mean} ± {error}, expected {expected}");
            assert!(
                (mean - expected).abs() < 4.0 * error.max(1e-6 * expected),
                "{what}: {mean} ± {error} vs {expected}"
            );
            assert!(error < 0.02 * expected, "the test has the power to see a 2 % error");
        }
    }
}

/// An albedo-1 medium in a white furnace (environment 1, nothing else): light is neither lost
/// nor gained, so every pixel is 1 in expectation, whatever the scattering — behind a null
/// boundary, or behind smooth glass (whose refractions scale radiance by η² going in and 1/η²
/// coming out, and trap some of it by total internal reflection for a while). z-test, |z| < 4.
///
/// Behind glass the extinction is grey: with an RGB σ_t, trapped paths scatter so often that the
/// spectral tracking's weights make the 64-sample mean too noisy to test (Mitsuba's own volpath
/// is off by 4 % at 4096 samples there). Rough glass is no furnace: a single-scattering microfacet
/// interface loses energy at every crossing (GGX α 0.3 around this medium: 0.773 in pathgrad,
/// 0.772 in Mitsuba 3.9.1's volpath, 4096 samples); the conformance matrix compares it instead.
#[test]
fn an_albedo_one_medium_in_a_white_furnace_is_white() {
    for (boundary, sigma_t) in [
        (r#"<bsdf type="null"/>"#, r#"<rgb name="sigma_t" value="2, 3, 4"/>"#),
        (r#"<bsdf type="dielectric"/>"#, r#"<float name="sigma_t" value="3"/>"#),
    ] {
        furnace_is_white(boundary, sigma_t);
    }
}

fn furnace_is_white(boundary: &str, sigma_t: &str) {
    let dir = tempfile::tempdir().unwrap();
    let s = scene(
        dir.path(),
        &format!(
            r#"{}<integrator type="volpath"><integer name="max_depth" value="-1"/></integrator><emitter type="constant"><rgb name="radiance" value="1, 1, 1"/></emitter>
            <shape type="sphere" id="cloud">{boundary}<medium type="homogeneous" name="interior">{sigma_t}<float name="albedo" value="1"/><phase type="hg"><float name="g" value="0.5"/></phase></medium></shape>"#,
            sensor("0, 0, 4", 30.0, 16)
        ),
    );
    let image = Reference::new(&s).unwrap().render(&RenderOptions { spp: 64, seed: 5, ..RenderOptions::for_scene(&s) });
    println!("{boundary}");
    for c in 0..3 {
        let channel: Vec<f32> = image.as_ref().unwrap().as_slice().iter().skip(c).step_by(3).copied().collect();
        let n = channel.len() as f64;
        let mean = channel.iter().map(|&v| f64::from(v)).sum::<f64>() / n;
        let var = channel.iter().map(|&v| (f64::from(v) - mean).powi(2)).sum::<f64>() / (n - 1.0);
        let error = (var / n).sqrt();
        println!("furnace channel {c}: {mean} ± {error}");
        assert!((mean - 1.0).abs() < 4.0 * error.max(1e-6), "channel {c}: {mean} ± {error}");
    }
}

/// Light reaching a floor through an absorbing slab, estimated with next-event estimation
/// (ratio-tracked transmittance along shadow rays) and without it (emitter hits that survive
/// delta tracking), agrees: two unbiased estimators of one image, Welch z-test on the mean.
#[test]
fn ratio_tracked_nee_agrees_with_delta_tracked_hits() {
    let dir = tempfile::tempdir().unwrap();
    let s = scene(
        dir.path(),
        &format!(
            r#"{}<integrator type="volpath"><integer name="max_depth" value="2"/></integrator>
            <shape type="rectangle" id="floor"><bsdf type="diffuse"><rgb name="reflectance" value="0.8, 0.8, 0.8"/></bsdf><transform name="to_world"><scale value="3"/></transform></shape>
            <shape type="cube" id="slab"><bsdf type="null"/><medium type="homogeneous" name="interior"><float name="sigma_t" value="0.8"/><float name="albedo" value="0"/></medium><transform name="to_world"><scale x="4" y="4" z="0.5"/><translate z="2"/></transform></shape>
            <shape type="rectangle" id="light"><emitter type="area"><rgb name="radiance" value="4, 4, 4"/></emitter><transform name="to_world"><rotate x="1" angle="180"/><translate z="4"/></transform></shape>"#,
            sensor("0.3, 0.2, 1.2", 60.0, 16)
        ),
    );
    let mut cpu = Reference::new(&s).unwrap();
    let base = RenderOptions { spp: 64, seed: 7, ..RenderOptions::for_scene(&s) };
    let with = cpu.render(&base).unwrap();
    let without = cpu.render(&RenderOptions { nee: false, seed: 8, ..base }).unwrap();
    let (a, ea) = mean_and_error(&with);
    let (b, eb) = mean_and_error(&without);
    let z = (a - b) / (ea * ea + eb * eb).sqrt();
    println!("NEE {a} ± {ea}, hits {b} ± {eb}, z = {z}");
    assert!(a > 0.01, "the floor is lit through the slab");
    assert!(z.abs() < 4.0, "NEE {a} ± {ea} vs hits {b} ± {eb}");
    // Without the slab the floor is brighter: the transmittance is not 1.
    let clear = RenderOptions { seed: 9, ..base };
    let mut table = s.params.clone();
    table.set("slab.interior_medium.scale", &[0.0]).unwrap();
    cpu.set_params(&table).unwrap();
    let (c, ec) = mean_and_error(&cpu.render(&clear).unwrap());
    assert!(c > a + 4.0 * (ea + ec), "clear {c} vs through the slab {a}");
}

/// A fog sphere (homogeneous, HG g = 0.6) beside a rough metal ball under an area light and a dim
/// sky, over a diffuse floor: the differential strategy's scene with media (ALGORITHMS.md §8.4).
fn diff_media(dir: &Path) -> Scene {
    scene(
        dir,
        &format!(
            r#"{}<integrator type="volpath"><integer name="max_depth" value="8"/></integrator><emitter type="constant"><rgb name="radiance" value="0.1, 0.12, 0.15"/></emitter>
            <shape type="rectangle" id="light"><emitter type="area"><rgb name="radiance" value="8, 8, 7"/></emitter><transform name="to_world"><rotate x="1" angle="90"/><translate y="3"/></transform></shape>
            <shape type="rectangle" id="floor"><bsdf type="diffuse"/><transform name="to_world"><scale value="4"/><rotate x="1" angle="-90"/><translate y="-1"/></transform></shape>
            <shape type="sphere" id="ball"><bsdf type="roughconductor"><string name="distribution" value="ggx"/><float name="alpha" value="0.2"/></bsdf><transform name="to_world"><scale value="0.45"/><translate x="-0.9" y="-0.5"/></transform></shape>
            <shape type="sphere" id="fog"><bsdf type="null"/><medium type="homogeneous" name="interior"><float name="sigma_t" value="2"/><rgb name="albedo" value="0.95, 0.9, 0.85"/><phase type="hg"><float name="g" value="0.6"/></phase></medium>
                <transform name="to_world"><scale value="0.8"/><translate x="0.6" y="-0.1"/></transform></shape>"#,
            sensor("0, 0.5, 4", 40.0, 24)
        ),
    )
}

const FOG_G: &str = "fog.interior_medium.phase_function.g";
const BALL_ALPHA: &str = "ball.bsdf.alpha.value";

fn diff_strategy(s: &Scene, target: &str, q: f32) -> pathgrad::integrator::Strategy {
    pathgrad::integrator::Strategy::from_name(s, "diff", q, target).unwrap()
}

/// Differential path sampling in a scene with media, its vertex placed in the fog (g the target)
/// or on the ball (the roughness the target; every medium vertex then not capable): the kernels
/// equal the CPU twin per path (1 spp, the per-path budget of the differential strategy's surface
/// scenes widened to the media budget above: 1 % of the values), for the radiance and the image
/// gradients of g, the roughness and the fog's density, with and without NEE.
#[test]
fn differential_sampling_in_media_gpu_equals_cpu_per_path() {
    let gpu = TestGpu::new();
    let dir = tempfile::tempdir().unwrap();
    let s = diff_media(dir.path());
    let mut renderer = pathgrad::gpu::Renderer::new(&gpu.ctx, &s).unwrap();
    for (target, nee) in [(FOG_G, true), (FOG_G, false), (BALL_ALPHA, true)] {
        let opts = RenderOptions {
            spp: 1,
            seed: 5,
            nee,
            strategy: diff_strategy(&s, target, 0.5),
            ..RenderOptions::for_scene(&s)
        };
        let mut images = vec![("radiance", renderer.render(&opts).unwrap(), pathgrad::cpu::render(&s, &opts).unwrap())];
        for name in [FOG_G, BALL_ALPHA, "fog.interior_medium.scale"] {
            images.push((
                name,
                renderer.image_gradient(&opts, name).unwrap(),
                pathgrad::cpu::image_gradient(&s, &opts, name).unwrap(),
            ));
        }
        for (what, g, c) in &images {
            assert!(c.as_slice().iter().any(|v| *v != 0.0), "{target} {what}: all zero");
            let mismatched = crate::support::count_mismatches(g, c, 1e-4);
            println!("diff by {target} (NEE {nee}) {what}: {mismatched} of {} values differ", g.as_slice().len());
            assert!(mismatched as f64 <= 0.01 * g.as_slice().len() as f64, "{target} {what}: {mismatched}");
        }
    }
}

/// The differential strategy by g (q = 0.5 with and without NEE, q = 0.75 with power-heuristic
/// placements) and by the ball's roughness estimate the same image gradients of g (Σ per image
/// half), of the roughness and the radiance as plain PRB: Welch's t over 24 seeds each, |t| < 5
/// (false-alarm rate ≤ 4.7e-5 per value, ≤ 1e-3 over the 20 here), with a power check on the
/// baseline where the fog (right half) and the ball (left half) are.
#[test]
fn differential_sampling_in_media_is_unbiased() {
    const SEEDS: u32 = 24;
    let gpu = TestGpu::new();
    let dir = tempfile::tempdir().unwrap();
    let s = diff_media(dir.path());
    let mut renderer = pathgrad::gpu::Renderer::new(&gpu.ctx, &s).unwrap();
    let base = RenderOptions { width: 24, height: 24, spp: 8, ..RenderOptions::for_scene(&s) };
    let power = diff_strategy(&s, FOG_G, 0.75).with_placement(pathgrad::integrator::PlacementMis::Power);
    let configs = [
        ("bsdf", pathgrad::integrator::Strategy::Bsdf, true),
        ("diff g", diff_strategy(&s, FOG_G, 0.5), true),
        ("diff g --no-nee", diff_strategy(&s, FOG_G, 0.5), false),
        ("diff g power q=0.75", power, true),
        ("diff alpha", diff_strategy(&s, BALL_ALPHA, 0.5), true),
    ];
    let halves = |img: &Image| {
        let w = img.width() as usize;
        let mut h = [0.0f64; 2];
        for (i, px) in img.as_slice().chunks(3).enumerate() {
            h[usize::from(i % w >= w / 2)] += px.iter().map(|&v| f64::from(v)).sum::<f64>();
        }
        h
    };
    let mut columns: Vec<Vec<[f64; 5]>> = Vec::new();
    for (_, strategy, nee) in configs {
        let mut rows = Vec::new();
        for seed in 0..SEEDS {
            let opts = RenderOptions { seed, strategy, nee, ..base };
            let g = halves(&renderer.image_gradient(&opts, FOG_G).unwrap());
            let a = halves(&renderer.image_gradient(&opts, BALL_ALPHA).unwrap());
            let r = renderer.render(&opts).unwrap().as_slice().iter().map(|&v| f64::from(v)).sum::<f64>();
            rows.push([g[0], g[1], a[0], a[1], r]);
        }
        columns.push(rows);
    }
    let stats = |rows: &[[f64; 5]], k: usize| {
        let n = rows.len() as f64;
        let m = rows.iter().map(|r| r[k]).sum::<f64>() / n;
        (m, rows.iter().map(|r| (r[k] - m).powi(2)).sum::<f64>() / (n - 1.0))
    };
    let names = ["∂I/∂g left", "∂I/∂g right", "∂I/∂α left", "∂I/∂α right", "radiance"];
    for (k, name) in names.iter().enumerate() {
        let (m0, v0) = stats(&columns[0], k);
        let se0 = (v0 / f64::from(SEEDS)).sqrt();
        // The fog fills the right half, the ball the left: those halves' gradients must be
        // resolved by the baseline (the other halves hold only what reflections carry).
        if [1, 2, 4].contains(&k) {
            assert!(m0.abs() > 3.0 * se0, "{name}: baseline {m0} ± {se0}: no power");
        }
        for (c, (label, _, _)) in configs.iter().enumerate().skip(1) {
            let (m, v) = stats(&columns[c], k);
            let t = (m - m0) / ((v + v0) / f64::from(SEEDS)).sqrt();
            println!("{name}: bsdf {m0:.5} ± {se0:.5}, {label} {m:.5} (t = {t:.2}, variance ratio {:.3})", v / v0);
            assert!(t.abs() < 5.0, "{name}: {label} {m} vs bsdf {m0} (t = {t:.2})");
        }
    }
}

/// A scene with a heterogeneous RGB medium (grid extinction and albedo, HG phase) whose σ_t box
/// covers only part of its cube (the rest of the cube is vacuum; its indices wrap by repeat, which
/// inside the box blends the far face in at the faces) and whose albedo grid is smaller than the
/// cube and mirrored over the rest of it (`wrap_mode` mirror), a homogeneous one (constant
/// extinction, constant RGB albedo), null boundaries, surfaces and both emitter kinds, in `dir`.
fn mixed_media(dir: &Path) -> Scene {
    // 12×9×10 voxels: a majorant grid of 2×2×2 cells, the half x ≥ 6 three times denser, so the
    // tracking walks cells of different majorants.
    let density: Vec<f32> = (0..12 * 9 * 10 * 3)
        .map(|i| (0.2 + 0.8 * ((i * 37 % 11) as f32 / 10.0)) * if (i / 3) % 12 >= 6 { 3.0 } else { 1.0 })
        .collect();
    std::fs::write(dir.join("density.vol"), Grid::new(UVec3::new(12, 9, 10), 3, density).unwrap().to_bytes()).unwrap();
    let albedo: Vec<f32> = (0..4 * 4 * 4 * 3).map(|i| 0.6 + 0.35 * ((i * 23 % 7) as f32 / 6.0)).collect();
    std::fs::write(dir.join("albedo.vol"), Grid::new(UVec3::splat(4), 3, albedo).unwrap().to_bytes()).unwrap();
    scene(
        dir,
        &format!(
            r#"{}<integrator type="volpath"><integer name="max_depth" value="12"/></integrator><emitter type="constant"><rgb name="radiance" value="0.3, 0.4, 0.5"/></emitter>
            <shape type="rectangle" id="light"><emitter type="area"><rgb name="radiance" value="6, 6, 5"/></emitter><transform name="to_world"><rotate x="1" angle="90"/><translate y="3"/></transform></shape>
            <shape type="rectangle" id="floor"><bsdf type="diffuse"/><transform name="to_world"><scale value="4"/><rotate x="1" angle="-90"/><translate y="-1.05"/></transform></shape>
            <shape type="cube" id="smoke"><bsdf type="null"/><medium type="heterogeneous" name="interior">
                <volume type="gridvolume" name="sigma_t"><string name="filename" value="density.vol"/><string name="wrap_mode" value="repeat"/><transform name="to_world"><scale value="1.5"/><translate x="-0.9" y="-0.6" z="-0.7"/></transform></volume>
                <volume type="gridvolume" name="albedo"><string name="filename" value="albedo.vol"/><string name="wrap_mode" value="mirror"/><transform name="to_world"><scale value="0.7"/><translate x="-0.45" y="-0.2" z="-0.3"/></transform></volume>
                <float name="scale" value="2"/><phase type="hg"><float name="g" value="0.5"/></phase></medium>
                <transform name="to_world"><translate x="-0.6"/><scale value="0.8"/></transform></shape>
            <shape type="sphere" id="fog"><bsdf type="null"/><medium type="homogeneous" name="interior"><float name="sigma_t" value="1.5"/><rgb name="albedo" value="0.95, 0.9, 0.85"/></medium>
                <transform name="to_world"><scale value="0.6"/><translate x="1"/></transform></shape>"#,
            sensor("0, 0.5, 4", 45.0, 32)
        ),
    )
}

/// The kernels' media code is the CPU twin's: one path per pixel of `mixed_media` agrees value by
/// value like surface-only renders do
/// (cpu_vs_gpu.rs: 1e-4 relative; a path may take another branch where logarithms round
/// differently, so a budget of 1 % of the values may differ), and so do the means of 16 spp.
#[test]
fn gpu_media_equal_the_cpu_per_path() {
    let gpu = TestGpu::new();
    let dir = tempfile::tempdir().unwrap();
    let s = mixed_media(dir.path());
    let mut renderer = pathgrad::gpu::Renderer::new(&gpu.ctx, &s).unwrap();
    let mut cpu = Reference::new(&s).unwrap();
    for spp in [1, 16] {
        let opts = RenderOptions { spp, seed: 4, ..RenderOptions::for_scene(&s) };
        let g = renderer.render(&opts).unwrap();
        let c = cpu.render(&opts).unwrap();
        let mismatched = crate::support::count_mismatches(&g, &c, 1e-6);
        println!(
            "media, {spp} spp: {mismatched} of {} values differ; means {:?} vs {:?}",
            g.as_slice().len(),
            g.mean(),
            c.mean()
        );
        assert!(c.mean()[0] > 0.01);
        assert!(mismatched as f64 <= 0.01 * g.as_slice().len() as f64, "{spp} spp: {mismatched} mismatches");
        for ch in 0..3 {
            assert!((g.mean()[ch] - c.mean()[ch]).abs() <= 1e-3 * c.mean()[ch], "{spp} spp channel {ch}");
        }
    }
    // The media are in view: without them the image is another.
    let mut clear = s.params.clone();
    clear.set("smoke.interior_medium.scale", &[0.0]).unwrap();
    clear.set("fog.interior_medium.scale", &[0.0]).unwrap();
    renderer.set_params(&clear).unwrap();
    let opts = RenderOptions { spp: 16, seed: 4, ..RenderOptions::for_scene(&s) };
    let without = renderer.render(&opts).unwrap();
    let with = cpu.render(&opts).unwrap();
    let changed = without.as_slice().iter().zip(with.as_slice()).filter(|(a, b)| (*a - *b).abs() > 0.05).count();
    println!("{changed} of {} values change without the media", with.as_slice().len());
    assert!(changed > with.as_slice().len() / 10, "{changed}");
}

/// The kernels' media gradients are the CPU twin's (whose gradients the finite-difference test
/// below checks): forward mode per pixel with the per-path tolerances of the primal above (a path
/// may branch elsewhere where logarithms round differently: 1 % of the values), reverse mode per
/// parameter value within 1e-3 of Σ_p |A_p ∂I_p/∂θ| as the surface tests (gradients.rs), for every medium parameter kind and the surfaces' parameters in
/// the same scene; and on the CPU twin, forward mode equals reverse mode for a tangent of 1 on
/// every value of each parameter, to 1e-5 of that scale, as for surfaces
/// (`support::assert_forward_equals_reverse`). The replay of every path returns to zero (both
/// backends check it), and the backward pass's memory does not grow with spp or depth.
#[test]
fn gpu_media_gradients_equal_the_cpu() {
    use pathgrad::gpu::renderer::GradMode;
    let gpu = TestGpu::new();
    let dir = tempfile::tempdir().unwrap();
    let s = mixed_media(dir.path());
    let mut renderer = pathgrad::gpu::Renderer::new(&gpu.ctx, &s).unwrap();
    let names = [
        "smoke.interior_medium.sigma_t.data",
        "smoke.interior_medium.scale",
        "smoke.interior_medium.phase_function.g",
        "smoke.interior_medium.albedo.data",
        "fog.interior_medium.sigma_t.value.value",
        "fog.interior_medium.albedo.value.value",
        "floor.bsdf.reflectance.value",
        "light.emitter.radiance.value",
    ];
    let opts = RenderOptions { width: 24, height: 24, spp: 1, seed: 6, ..RenderOptions::for_scene(&s) };
    for name in [
        "smoke.interior_medium.sigma_t.data",
        "smoke.interior_medium.albedo.data",
        "smoke.interior_medium.phase_function.g",
        "fog.interior_medium.albedo.value.value",
    ] {
        let g = renderer.image_gradient(&opts, name).unwrap();
        let c = pathgrad::cpu::image_gradient(&s, &opts, name).unwrap();
        let scale = c.as_slice().iter().fold(0.0f32, |m, v| m.max(v.abs()));
        assert!(scale > 0.0, "{name}: the image gradient is zero everywhere");
        let mismatched = crate::support::count_mismatches(&g, &c, 1e-4);
        println!("{name}: {mismatched} of {} forward-mode values differ", g.as_slice().len());
        assert!(mismatched as f64 <= 0.01 * g.as_slice().len() as f64, "{name}: {mismatched} mismatches");
    }
    let opts = RenderOptions { spp: 2, ..opts };
    let adjoint = Image::from_rgb(
        opts.width,
        opts.height,
        (0..opts.width * opts.height * 3).map(|i| ((i as f32 * 0.37).sin() + 0.3) * 0.5).collect(),
    )
    .unwrap();
    let c = pathgrad::cpu::backward(&s, &opts, &adjoint).unwrap();
    // Float atomics only: fixed-point accumulation differs from it in param_grad alone, which the
    // surface tests cover, and each mode is another cold kernel build in the suite.
    for mode in [GradMode::Float] {
        let g = renderer.backward(&opts, &adjoint, mode).unwrap();
        for name in names {
            let e = s.params.entry(s.params.find(name).unwrap_or_else(|| panic!("{name}"))).clone();
            let cv = &c[e.offset as usize..(e.offset + e.len) as usize];
            let forward = pathgrad::cpu::image_gradient(&s, &opts, name).unwrap();
            let magnitude = crate::support::assert_forward_equals_reverse(name, &forward, &adjoint, cv.iter().sum());
            assert!(magnitude > 0.0, "{name}: no derivative in view");
            for (a, b) in g.get(name).unwrap().iter().zip(cv) {
                assert!(
                    (f64::from(*a) - b).abs() <= 1e-3 * magnitude,
                    "{mode:?} {name}: GPU {a} vs CPU {b} (scale {magnitude})"
                );
            }
        }
    } // PRB's memory is flat through media too: the buffers a backward pass allocates do not grow
    // with the samples per pixel or the depth (paths are replayed, never stored).
    let mut peak = |o: RenderOptions| {
        renderer.context().reset_peak_buffer_bytes();
        renderer.backward(&o, &adjoint, GradMode::Float).unwrap();
        renderer.context().peak_buffer_bytes()
    };
    let base = peak(RenderOptions { spp: 1, max_depth: Some(2), ..opts });
    for (spp, depth) in [(16, 2), (1, 48), (16, 48)] {
        let bytes = peak(RenderOptions { spp, max_depth: Some(depth), ..opts });
        assert_eq!(bytes, base, "{spp} spp, depth {depth}: {bytes} bytes against {base} at 1 spp, depth 2");
    }
}

/// The closed forms hold on the GPU too (the slab and the furnace of the CPU tests above).
#[test]
fn gpu_media_pass_the_closed_forms() {
    let gpu = TestGpu::new();
    let dir = tempfile::tempdir().unwrap();
    let slab = scene(
        dir.path(),
        &format!(
            r#"{}<integrator type="volpath"/>
            <shape type="cube" id="slab"><bsdf type="null"/><medium type="homogeneous" name="interior"><float name="sigma_t" value="0.7"/><float name="albedo" value="0"/></medium></shape>
            <shape type="rectangle" id="light"><emitter type="area"><rgb name="radiance" value="2, 2, 2"/></emitter><transform name="to_world"><scale value="20"/><translate z="-4"/></transform></shape>"#,
            sensor("0, 0, 6", 2.0, 16)
        ),
    );
    let image = pathgrad::gpu::Renderer::new(&gpu.ctx, &slab)
        .unwrap()
        .render(&RenderOptions { spp: 64, seed: 1, ..RenderOptions::for_scene(&slab) })
        .unwrap();
    let (mean, error) = mean_and_error(&image);
    let expected = 2.0 * (-0.7f64 * 2.0).exp();
    assert!((mean - expected).abs() < 4.0 * error, "slab {mean} ± {error} vs {expected}");
    let furnace = scene(
        dir.path(),
        &format!(
            r#"{}<integrator type="volpath"><integer name="max_depth" value="-1"/></integrator><emitter type="constant"><rgb name="radiance" value="1, 1, 1"/></emitter>
            <shape type="sphere" id="cloud"><bsdf type="null"/><medium type="homogeneous" name="interior"><rgb name="sigma_t" value="2, 3, 4"/><float name="albedo" value="1"/><phase type="hg"><float name="g" value="0.5"/></phase></medium></shape>"#,
            sensor("0, 0, 4", 30.0, 16)
        ),
    );
    let image = pathgrad::gpu::Renderer::new(&gpu.ctx, &furnace)
        .unwrap()
        .render(&RenderOptions { spp: 64, seed: 5, ..RenderOptions::for_scene(&furnace) })
        .unwrap();
    let (mean, error) = mean_and_error(&image);
    assert!((mean - 1.0).abs() < 4.0 * error.max(1e-6), "furnace {mean} ± {error}");
}

/// Gradients through media on the CPU reference against central finite differences with common
/// random numbers, by the surface test's protocol (gradients.rs): J(θ) = Σ_p A_p·I_p(θ) with A an
/// independent render, 64 seeds, Welch statistic < 4 and a power check. Extinction and RGB albedo
/// grid texels (tangent 1 on every texel), a homogeneous RGB extinction (its largest channel is
/// the density the majorant is made of: without `MAJORANT_MARGIN` its null weights are exactly 0
/// and its derivative is lost), a constant grey albedo, scale, g, a surface's parameter in the
/// media scene (the floor's reflectance, seen and lit through the media), and a flat block of grid
/// density at the maximum; the majorants follow the shifted parameters in the finite differences
/// and are detached in PRB.
#[test]
fn media_gradients_match_finite_differences_on_the_cpu() {
    const SEEDS: u32 = 64;
    let dir = tempfile::tempdir().unwrap();
    // 12×9×10 voxels, a majorant grid of 2×2×2 cells (the half x ≥ 6 twice as dense): its
    // derivatives are taken against cell majorants.
    let density: Vec<f32> =
        (0..12 * 9 * 10).map(|i| (0.5 + ((i * 29 % 13) as f32) / 12.0) * if i % 12 >= 6 { 2.0 } else { 1.0 }).collect();
    std::fs::write(dir.path().join("density.vol"), Grid::new(UVec3::new(12, 9, 10), 1, density).unwrap().to_bytes())
        .unwrap();
    let albedo: Vec<f32> = (0..64 * 3).map(|i| 0.5 + 0.4 * ((i * 23 % 7) as f32 / 6.0)).collect();
    std::fs::write(dir.path().join("albedo.vol"), Grid::new(UVec3::splat(4), 3, albedo).unwrap().to_bytes()).unwrap();
    // A flat block: every voxel at the grid's maximum, the density the majorant is made of.
    std::fs::write(dir.path().join("block.vol"), Grid::new(UVec3::splat(2), 1, vec![3.0; 8]).unwrap().to_bytes())
        .unwrap();
    let s = scene(
        dir.path(),
        &format!(
            r#"{}<integrator type="volpath"><integer name="max_depth" value="8"/></integrator>
            <shape type="cube" id="block"><bsdf type="null"/><medium type="heterogeneous" name="interior">
                <volume type="gridvolume" name="sigma_t"><string name="filename" value="block.vol"/><transform name="to_world"><scale value="0.7"/><translate x="-0.35" y="0.95" z="-0.35"/></transform></volume>
                <float name="albedo" value="0.2"/></medium>
                <transform name="to_world"><scale value="0.35"/><translate y="1.3"/></transform></shape><emitter type="constant"><rgb name="radiance" value="0.3, 0.4, 0.5"/></emitter>
            <shape type="rectangle" id="light"><emitter type="area"><rgb name="radiance" value="6, 6, 5"/></emitter><transform name="to_world"><rotate x="1" angle="90"/><translate y="3"/></transform></shape>
            <shape type="rectangle" id="floor"><bsdf type="diffuse"/><transform name="to_world"><scale value="4"/><rotate x="1" angle="-90"/><translate y="-1.05"/></transform></shape>
            <shape type="cube" id="smoke"><bsdf type="null"/><medium type="heterogeneous" name="interior">
                <volume type="gridvolume" name="sigma_t"><string name="filename" value="density.vol"/><transform name="to_world"><scale value="2"/><translate x="-1" y="-1" z="-1"/></transform></volume>
                <volume type="gridvolume" name="albedo"><string name="filename" value="albedo.vol"/><transform name="to_world"><scale value="2"/><translate x="-1" y="-1" z="-1"/></transform></volume>
                <float name="scale" value="1.5"/><phase type="hg"><float name="g" value="0.3"/></phase></medium>
                <transform name="to_world"><translate x="-0.6"/><scale value="0.8"/></transform></shape>
            <shape type="sphere" id="fog"><bsdf type="null"/><medium type="homogeneous" name="interior"><rgb name="sigma_t" value="0.8, 1.0, 1.2"/><float name="albedo" value="0.3"/></medium>
                <transform name="to_world"><scale value="0.6"/><translate x="1"/></transform></shape>"#,
            sensor("0, 0.5, 4", 45.0, 16)
        ),
    );
    let mut cpu = Reference::new(&s).unwrap();
    let base = RenderOptions { spp: 4, ..RenderOptions::for_scene(&s) };
    let adjoint = cpu.render(&RenderOptions { seed: 1_000_000, spp: 16, ..base }).unwrap();
    let objective = |img: &Image| -> f64 {
        img.as_slice().iter().zip(adjoint.as_slice()).map(|(i, a)| f64::from(*i) * f64::from(*a)).sum()
    };
    for name in [
        "smoke.interior_medium.sigma_t.data",
        "smoke.interior_medium.albedo.data",
        "smoke.interior_medium.scale",
        "smoke.interior_medium.phase_function.g",
        "fog.interior_medium.sigma_t.value.value",
        "fog.interior_medium.albedo.value.value",
        "floor.bsdf.reflectance.value",
        "block.interior_medium.sigma_t.data",
    ] {
        let values = s.params.get(s.params.find(name).unwrap()).to_vec();
        let h = 0.01 * values.iter().fold(0.0f32, |m, v| m.max(v.abs())).max(0.01);
        let (mut fd, mut prb) = (Vec::new(), Vec::new());
        for seed in 0..SEEDS {
            let opts = RenderOptions { seed, ..base };
            let mut shifted = |dx: f32| {
                let mut table = s.params.clone();
                table.set(name, &values.iter().map(|v| v + dx).collect::<Vec<_>>()).unwrap();
                cpu.set_params(&table).unwrap();
                objective(&cpu.render(&opts).unwrap())
            };
            fd.push((shifted(h) - shifted(-h)) / (2.0 * f64::from(h)));
            cpu.set_params(&s.params).unwrap();
            let g = cpu.backward(&opts, &adjoint, pathgrad::gpu::renderer::GradMode::Float).unwrap();
            prb.push(g.get(name).unwrap().iter().map(|&v| f64::from(v)).sum::<f64>());
        }
        crate::support::assert_fd_matches(name, &fd, &prb);
    }
}

/// A 2×2×2 density grid `truth` (written as truth.vol in `dir`) in a cube of scattering medium
/// under a white sky, seen by three 24×24 cameras (front, side, top), and one target per view
/// rendered on the CPU reference at `target_spp`: the scene file and the `--view` arguments.
fn grid_recovery_scene(dir: &Path, truth: &[f32; 8], target_spp: u32) -> (String, Vec<String>) {
    std::fs::write(dir.join("truth.vol"), Grid::new(UVec3::splat(2), 1, truth.to_vec()).unwrap().to_bytes()).unwrap();
    let camera = |id: &str, origin: &str, up: &str| {
        format!(
            r#"<sensor type="perspective" id="{id}"><float name="fov" value="35"/><transform name="to_world"><lookat origin="{origin}" target="0, 0.5, 0" up="{up}"/></transform><film type="hdrfilm"><integer name="width" value="24"/><integer name="height" value="24"/></film></sensor>"#
        )
    };
    let body = format!(
        r#"{}{}{}<integrator type="volpath"><integer name="max_depth" value="6"/></integrator><emitter type="constant"><rgb name="radiance" value="1, 1, 1"/></emitter>
        <shape type="cube" id="smoke"><bsdf type="null"/><medium type="heterogeneous" name="interior">
            <volume type="gridvolume" name="sigma_t"><string name="filename" value="truth.vol"/><transform name="to_world"><translate x="-0.5" z="-0.5"/></transform></volume>
            <float name="albedo" value="0.5"/><float name="scale" value="4"/></medium>
            <transform name="to_world"><scale value="0.5"/><translate y="0.5"/></transform></shape>"#,
        camera("front", "0, 0.5, 3.5", "0, 1, 0"),
        camera("side", "3.5, 0.5, 0", "0, 1, 0"),
        camera("top", "0.3, 4, 0.2", "0, 0, -1")
    );
    let path = dir.join("scene.xml");
    std::fs::write(&path, format!(r#"<scene version="3.0.0">{body}</scene>"#)).unwrap();
    let scene_arg = path.to_str().unwrap().to_string();
    let mut views = Vec::new();
    for view in ["front", "side", "top"] {
        let target = dir.join(format!("{view}.exr"));
        let o = crate::cli::pathgrad()
            .args([
                "render",
                &scene_arg,
                "--cpu",
                "--sensor",
                view,
                "--spp",
                &target_spp.to_string(),
                "--no-preview",
                "-o",
            ])
            .arg(&target)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        views.push(format!("{view}={}", target.display()));
    }
    (scene_arg, views)
}

/// Runs `pathgrad optimize --cpu` on `scene` over `views` with `extra` arguments and returns its
/// JSON summary and the final density grid.
fn optimize_grid(scene: &str, views: &[String], out: &Path, extra: &[&str]) -> (serde_json::Value, Vec<f64>) {
    let mut args = vec!["optimize", scene, "--cpu", "--spp", "4", "--json", "-o", out.to_str().unwrap()];
    args.extend(extra);
    for v in views {
        args.extend(["--view", v.as_str()]);
    }
    let o = crate::cli::pathgrad().args(&args).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let values = summary["params"]["smoke.interior_medium.sigma_t.data"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    (summary, values)
}

/// `optimize --cpu` recovers a 2×2×2 density grid from renders of three views (front, side,
/// top; a white sky lights a scattering medium): from a uniform 0.4 (RMSE 0.29 against the
/// truth) to an RMSE below 0.1 in 600 iterations (0.054 with plain steps when this test was
/// written; it runs `optimize`'s default, adaptive pixels and control variates, since). The
/// targets are rendered at 1024 spp; the CPU reference is deterministic, so the run is too.
#[test]
fn optimize_recovers_a_small_density_grid_over_three_views() {
    let dir = tempfile::tempdir().unwrap();
    let truth = [0.2f32, 0.9, 0.5, 0.1, 0.7, 0.3, 0.05, 0.6];
    let (scene, views) = grid_recovery_scene(dir.path(), &truth, 1024);
    let grid = "smoke.interior_medium.sigma_t.data=0.4";
    let extra = ["--param", grid, "--iters", "600", "--lr", "0.05", "--spp-primal", "8", "--spp-grad", "8"];
    let (_, values) = optimize_grid(&scene, &views, &dir.path().join("run"), &extra);
    let rmse = |a: &[f64]| (a.iter().zip(truth).map(|(x, t)| (x - f64::from(t)).powi(2)).sum::<f64>() / 8.0).sqrt();
    let start = rmse(&[0.4; 8]);
    let end = rmse(&values);
    println!("density grid RMSE {start:.3} -> {end:.3}: {values:?}");
    assert!(end < 0.1 && end < start / 2.5, "RMSE {start} -> {end}");
}

/// `optimize --smooth` adds its prior to the gradient: started at the truth (where the images
/// pull nowhere), a strong prior flattens the grid — its spread falls below a third of the
/// truth's in 60 iterations — while without it the grid stays near the truth. The summary
/// reports the prior's value; a prior on parameters that are not grids, and a changed weight on
/// `--resume`, are refused by name.
#[test]
fn optimize_smooth_pulls_a_grid_towards_its_neighbours() {
    let dir = tempfile::tempdir().unwrap();
    let truth = [0.2f32, 0.9, 0.5, 0.1, 0.7, 0.3, 0.05, 0.6];
    let (scene, views) = grid_recovery_scene(dir.path(), &truth, 64);
    let spread = |a: &[f64]| {
        let mean = a.iter().sum::<f64>() / a.len() as f64;
        (a.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / a.len() as f64).sqrt()
    };
    let truth64: Vec<f64> = truth.iter().map(|&t| f64::from(t)).collect();
    let common =
        ["--param", "smoke.interior_medium.sigma_t.data", "--iters", "60", "--lr", "0.05", "--spp-primal", "2"];
    let (plain, free) = optimize_grid(&scene, &views, &dir.path().join("plain"), &common);
    assert!(plain["prior"].is_null(), "{plain}");
    let mut smoothed = common.to_vec();
    smoothed.extend(["--smooth", "50"]);
    let (summary, flat) = optimize_grid(&scene, &views, &dir.path().join("smooth"), &smoothed);
    println!("spread: truth {:.3}, free {:.3}, smoothed {:.3}", spread(&truth64), spread(&free), spread(&flat));
    assert!(spread(&free) > 0.6 * spread(&truth64), "{free:?}");
    assert!(spread(&flat) < spread(&truth64) / 3.0, "{flat:?}");
    assert!(summary["prior"].as_f64().unwrap() > 0.0, "{summary}");

    let not_a_grid = crate::cli::pathgrad()
        .args(["optimize", &scene, "--cpu", "--param", "smoke.interior_medium.scale", "--smooth", "1", "--iters", "1"])
        .args(["--view", &views[0], "-o"])
        .arg(dir.path().join("scalar"))
        .output()
        .unwrap();
    let e = String::from_utf8_lossy(&not_a_grid.stderr);
    assert!(!not_a_grid.status.success() && e.contains("--smooth") && e.contains("nothing to smooth"), "{e}");
    assert!(!dir.path().join("scalar").exists(), "a refused run leaves no directory");

    let changed = crate::cli::pathgrad()
        .args(["optimize", "--resume"])
        .arg(dir.path().join("smooth"))
        .args(["--smooth", "5", "--iters", "61"])
        .output()
        .unwrap();
    let e = String::from_utf8_lossy(&changed.stderr);
    assert!(!changed.status.success() && e.contains("--smooth 5 (the run has 50)"), "{e}");
}

/// The primal agrees with Mitsuba 3 `volpath` on a scene nobody here tuned for it: the smoke
/// scene (scenes/smoke/smoke.xml: HG smoke over a floor, an area light, a sky) with an 8³ grid, at
/// 32×32 and 256 spp over 16 seeds a side. The reference's per-seed block means come from
/// benches/mitsuba_media_reference.py (tests/data/mitsuba/smoke8/). Per 8×8 block and channel,
/// z = (mean_p − mean_m) / √(se_p² + se_m² + (1e-4 mean_m)²) over the seeds: every |z| < 4 (48 values) and the mean
/// z² below 2 (1 expected, standard deviation 0.2 under agreement). Rendered on the CPU reference;
/// the kernels equal it path by path (`gpu_media_equal_the_cpu_per_path`).
#[test]
fn primal_agrees_with_mitsuba_volpath() {
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/mitsuba/smoke8");
    let dir = tempfile::tempdir().unwrap();
    std::fs::copy(Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/smoke/smoke.xml"), dir.path().join("smoke.xml"))
        .unwrap();
    std::fs::copy(data.join("smoke.vol"), dir.path().join("smoke.vol")).unwrap();
    let reference: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(data.join("blocks.json")).unwrap()).unwrap();
    let (res, spp, block) = (32u32, reference["spp"].as_u64().unwrap() as u32, 8u32);
    assert_eq!(reference["res"].as_u64(), Some(u64::from(res)));
    let theirs: Vec<Vec<f64>> = reference["blocks"]
        .as_array()
        .unwrap()
        .iter()
        .map(|seed| {
            seed.as_array()
                .unwrap()
                .iter()
                .flat_map(|b| b.as_array().unwrap().iter().map(|v| v.as_f64().unwrap()))
                .collect()
        })
        .collect();
    let defines = [("res".to_string(), res.to_string())];
    let s = pathgrad::scene::load(dir.path().join("smoke.xml").to_str().unwrap(), &defines).unwrap();
    let mut cpu = Reference::new(&s).unwrap();
    let per_side = (res / block) as usize;
    let mine: Vec<Vec<f64>> = (0..theirs.len() as u32)
        .map(|seed| {
            let img = cpu.render(&RenderOptions { spp, seed: 100 + seed, ..RenderOptions::for_scene(&s) }).unwrap();
            assert_eq!((img.width(), img.height()), (res, res));
            let mut sums = vec![0.0f64; per_side * per_side * 3];
            for (i, v) in img.as_slice().iter().enumerate() {
                let (pixel, c) = (i / 3, i % 3);
                let (x, y) = (pixel as u32 % res, pixel as u32 / res);
                let b = (y / block) as usize * per_side + (x / block) as usize;
                sums[b * 3 + c] += f64::from(*v) / f64::from(block * block);
            }
            sums
        })
        .collect();
    let stats = |side: &[Vec<f64>], k: usize| {
        let n = side.len() as f64;
        let mean = side.iter().map(|s| s[k]).sum::<f64>() / n;
        let var = side.iter().map(|s| (s[k] - mean).powi(2)).sum::<f64>() / (n - 1.0);
        (mean, var / n)
    };
    let z: Vec<f64> = (0..mine[0].len())
        .map(|k| {
            let ((mp, vp), (mm, vm)) = (stats(&mine, k), stats(&theirs, k));
            // Blocks of sky alone have no variance: a floor of 1e-4 of the value (f32 rounding).
            (mp - mm) / (vp + vm + (1e-4 * mm).powi(2)).sqrt()
        })
        .collect();
    let largest = z.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let mean_sq = z.iter().map(|v| v * v).sum::<f64>() / z.len() as f64;
    println!("Mitsuba volpath agreement: max |z| {largest:.2}, mean z² {mean_sq:.2} over {} blocks", z.len());
    assert!(largest < 4.0 && mean_sq < 2.0, "z per block and channel: {z:?}");
}

/// `render`, `grad --image-gradient` (tangent 1 on every voxel) and `variance` (which compares
/// the BSDF and the differential strategy by default, in media as on surfaces) work on
/// a media scene from the command line.
#[test]
fn cli_commands_work_on_a_media_scene() {
    let dir = tempfile::tempdir().unwrap();
    let density: Vec<f32> = (0..27).map(|i| 0.5 + (i % 5) as f32 * 0.3).collect();
    std::fs::write(dir.path().join("d.vol"), Grid::new(UVec3::splat(3), 1, density).unwrap().to_bytes()).unwrap();
    scene(
        dir.path(),
        &format!(
            r#"{}<emitter type="constant"/><shape type="cube" id="smoke"><bsdf type="null"/><medium type="heterogeneous" name="interior">
            <volume type="gridvolume" name="sigma_t"><string name="filename" value="d.vol"/><transform name="to_world"><scale value="2"/><translate x="-1" y="-1" z="-1"/></transform></volume>
            <float name="albedo" value="0.7"/><float name="scale" value="2"/></medium></shape>"#,
            sensor("0, 1, 4", 40.0, 12)
        ),
    );
    let path = dir.path().join("scene.xml");
    let run = |args: &[&str]| {
        let o = crate::cli::pathgrad().current_dir(dir.path()).args(args).output().unwrap();
        assert!(o.status.success(), "{args:?}: {}", String::from_utf8_lossy(&o.stderr));
        o.stdout
    };
    let scene_arg = path.to_str().unwrap();
    run(&["render", scene_arg, "--cpu", "--spp", "4", "-o", "r.exr"]);
    assert!(dir.path().join("r.exr").exists() && dir.path().join("r.png").exists());
    run(&[
        "grad",
        scene_arg,
        "--cpu",
        "--spp",
        "4",
        "--image-gradient",
        "smoke.interior_medium.sigma_t.data",
        "-o",
        "g.exr",
    ]);
    let g = Image::read_exr(dir.path().join("g.exr")).unwrap();
    // Denser smoke in front of a white sky darkens the image.
    assert!(g.mean()[0] < 0.0, "{:?}", g.mean());
    let v: serde_json::Value = serde_json::from_slice(&run(&[
        "variance",
        scene_arg,
        "--cpu",
        "--param",
        "smoke.interior_medium.scale",
        "--runs",
        "3",
        "--spp",
        "1",
        "--json",
        "-o",
        "v",
    ]))
    .unwrap();
    let names: Vec<_> = v["techniques"].as_array().unwrap().iter().map(|r| r["technique"].as_str().unwrap()).collect();
    assert_eq!(names, ["bsdf", "diff q=0.5"]);
}

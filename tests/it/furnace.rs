//! White furnace: albedo-1 diffuse objects (a sphere and a box that see each other) inside a closed
//! box emitting radiance 1 with black walls. With unbounded depth every path carries exactly the
//! walls' radiance in expectation, so every pixel's expected value is 1 — a check of NEE densities,
//! MIS weights, BSDF sampling and Russian roulette.

use pathgrad::backend::Backend;
use pathgrad::gpu::Renderer;
use pathgrad::image::Image;
use pathgrad::integrator::RenderOptions;
use pathgrad::scene::builtin::{self, FURNACE_RADIANCE};

use crate::support::{TestGpu, scenes};

/// Checks that the pixel values average to the furnace radiance within a confidence interval
/// derived from the image itself: pixels are independent estimates of the same value, so their mean
/// has standard error s/√N; 4 standard errors give a false-alarm rate below 1e-4 per check.
fn assert_furnace(label: &str, image: &Image) {
    // One value per pixel: the three channels of a grey scene are the same estimate, not three
    // independent ones (counting them separately would shrink the standard error by √3).
    let values: Vec<f64> =
        image.as_slice().chunks(3).map(|c| c.iter().map(|&v| f64::from(v)).sum::<f64>() / 3.0).collect();
    assert!(values.iter().all(|v| v.is_finite() && *v >= 0.0), "{label}: non-finite or negative pixel");
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
    let se = (var / n).sqrt();
    println!("{label}: mean {mean:.5} ± {se:.5} (expected {FURNACE_RADIANCE})");
    assert!(
        (mean - f64::from(FURNACE_RADIANCE)).abs() <= 4.0 * se + 1e-6,
        "{label}: mean {mean} is {:.1} standard errors from {FURNACE_RADIANCE}",
        (mean - 1.0).abs() / se
    );
}

#[test]
fn white_furnace_gpu_and_cpu() {
    let gpu = TestGpu::new();
    let scene = builtin::load("furnace").unwrap();
    let mut renderer = Renderer::new(&gpu.ctx, &scene).unwrap();
    for (max_depth, rr_depth) in [(None, Some(1)), (None, Some(5)), (Some(1000), None)] {
        let opts = RenderOptions {
            width: 64,
            height: 64,
            spp: 16,
            max_depth,
            rr_depth,
            seed: 3,
            ..RenderOptions::for_scene(&scene)
        };
        assert_furnace(
            &format!("GPU, max depth {max_depth:?}, roulette from {rr_depth:?}"),
            &renderer.render(&opts).unwrap(),
        );
        assert_furnace(
            &format!("CPU, max depth {max_depth:?}, roulette from {rr_depth:?}"),
            &pathgrad::cpu::render(&scene, &opts).unwrap(),
        );
    }
}

/// The open furnace: emitted radiance 1 reaches every point through area emitters and the
/// environment alike; textured and two-sided albedo-1 surfaces reflect all of it.
#[test]
fn open_furnace_with_environment_texture_and_two_sided_card() {
    let gpu = TestGpu::new();
    let scene = scenes::open_furnace();
    let mut renderer = Renderer::new(&gpu.ctx, &scene).unwrap();
    let opts = RenderOptions {
        width: 48,
        height: 48,
        spp: 16,
        max_depth: None,
        rr_depth: Some(5),
        seed: 11,
        ..RenderOptions::for_scene(&scene)
    };
    assert_furnace("GPU, open furnace", &renderer.render(&opts).unwrap());
    assert_furnace("CPU, open furnace", &pathgrad::cpu::render(&scene, &opts).unwrap());
}

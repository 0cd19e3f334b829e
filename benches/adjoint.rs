//! Gradient step cost with Path Replay Backpropagation: the primal render (pass 1) plus the fused
//! adjoint (passes 2+3) on `builtin:cornell-box` at 256×256, 16 spp, depth 6; then time and peak
//! buffer memory of the fused adjoint as spp grows 1→256 and as max depth grows 2→64 (on a closed
//! variant of the box without Russian roulette, so every path really has that many vertices).
//! Prints figures; asserts nothing about time. Run: `cargo bench --bench adjoint`.

use pathgrad::backend::Backend;
use std::time::Instant;

use glam::Vec3;
use pathgrad::gpu::renderer::GradMode;
use pathgrad::gpu::{Context, ContextDesc, Renderer};
use pathgrad::image::Image;
use pathgrad::integrator::RenderOptions;
use pathgrad::loss::{Loss, loss_and_adjoint};

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn time<T>(runs: usize, mut f: impl FnMut() -> pathgrad::Result<T>) -> pathgrad::Result<f64> {
    let mut times = Vec::new();
    for _ in 0..runs {
        let t = Instant::now();
        f()?;
        times.push(t.elapsed().as_secs_f64());
    }
    Ok(median(times))
}

fn mib(bytes: u64) -> f64 {
    bytes as f64 / (1024.0 * 1024.0)
}

fn main() -> pathgrad::Result<()> {
    let ctx = Context::new(&ContextDesc::default())?;
    println!("device: {} ({})", ctx.info().name, ctx.info().driver);
    let scene = pathgrad::scene::builtin::load("cornell-box")?;
    let mut renderer = Renderer::new(&ctx, &scene)?;
    let opts = RenderOptions {
        width: 256,
        height: 256,
        spp: 16,
        max_depth: Some(6),
        seed: 1,
        ..RenderOptions::for_scene(&scene)
    };
    let mut target_table = scene.params.clone();
    target_table.set("sphere.bsdf.alpha.value", &[0.4])?;
    renderer.set_params(&target_table)?;
    let target = renderer.render(&RenderOptions { seed: 99, ..opts })?;
    renderer.set_params(&scene.params)?;
    let (_, adjoint) = loss_and_adjoint(&renderer.render(&RenderOptions { spp: 1, ..opts })?, &target, Loss::RelMse)?;
    // Warm-up: the driver compiles each kernel at its first dispatch.
    renderer.backward(&RenderOptions { spp: 1, ..opts }, &adjoint, GradMode::Float)?;
    renderer.backward(&RenderOptions { spp: 1, ..opts }, &adjoint, GradMode::Deterministic)?;
    let runs = 3;
    let primal = time(runs, || renderer.render(&opts))?;
    let adjoint_float = time(runs, || renderer.backward(&opts, &adjoint, GradMode::Float))?;
    let adjoint_fixed = time(runs, || renderer.backward(&opts, &adjoint, GradMode::Deterministic))?;
    let step = time(runs, || renderer.loss_and_gradient(&opts, &target, Loss::RelMse, GradMode::Float))?;
    let loss_host = time(runs, || loss_and_adjoint(&target, &target, Loss::RelMse))?;
    pathgrad::loss::loss_and_adjoint_gpu(&ctx, &target, &target, Loss::RelMse)?;
    let loss_gpu = time(runs, || pathgrad::loss::loss_and_adjoint_gpu(&ctx, &target, &target, Loss::RelMse))?;
    println!("builtin:cornell-box 256x256, 16 spp, max depth 6, median of {runs}:");
    println!("  primal render (pass 1)          {primal:8.3} s");
    println!(
        "  fused adjoint, float atomics    {adjoint_float:8.3} s   (adjoint/primal {:.2})",
        adjoint_float / primal
    );
    println!(
        "  fused adjoint, deterministic    {adjoint_fixed:8.3} s   (adjoint/primal {:.2})",
        adjoint_fixed / primal
    );
    println!("  gradient step (loss_and_gradient) {step:6.3} s");
    println!("  relMSE loss + adjoint image on the host {:.2} ms", loss_host * 1e3);
    println!("  relMSE loss + adjoint image on the device {:.2} ms (upload, dispatch, read-back)", loss_gpu * 1e3);

    // Sweeps on a 64x64 image to keep the run short on lavapipe.
    let small = RenderOptions { width: 64, height: 64, ..opts };
    let small_adjoint = Image::from_rgb(64, 64, vec![1e-3; 64 * 64 * 3])?;
    println!("spp sweep (64x64, depth 6): spp, adjoint time, peak buffer MiB during the adjoint");
    for spp in [1, 4, 16, 64, 256] {
        ctx.reset_peak_buffer_bytes();
        let t = time(1, || renderer.backward(&RenderOptions { spp, ..small }, &small_adjoint, GradMode::Float))?;
        println!("  {spp:4}  {t:8.3} s  {:8.3} MiB", mib(ctx.peak_buffer_bytes()));
    }
    let mut closed = scene.clone();
    let white = pathgrad::scene::MaterialId(0);
    closed.add_mesh("front", pathgrad::scene::shapes::quad(Vec3::new(0.0, 0.0, 1.0), Vec3::Y, Vec3::X), white, None)?;
    // The camera sits inside the closed box now.
    closed.camera.position = Vec3::new(0.0, 0.0, 0.95);
    closed.camera.fov_y_degrees = 70.0;
    let mut closed_renderer = Renderer::new(&ctx, &closed)?;
    println!("depth sweep (closed box, no Russian roulette, 64x64, 4 spp): depth, adjoint time, peak buffer MiB");
    for depth in [2, 4, 8, 16, 32, 64] {
        let o = RenderOptions { spp: 4, max_depth: Some(depth), rr_depth: None, ..small };
        closed_renderer.backward(&RenderOptions { spp: 1, ..o }, &small_adjoint, GradMode::Float)?;
        ctx.reset_peak_buffer_bytes();
        let t = time(1, || closed_renderer.backward(&o, &small_adjoint, GradMode::Float))?;
        println!("  {depth:4}  {t:8.3} s  {:8.3} MiB", mib(ctx.peak_buffer_bytes()));
    }
    Ok(())
}

//! Primal throughput: `builtin:cornell-box` at 256×256, 16 spp, max depth 6, on the chosen Vulkan
//! device (`PATHGRAD_DEVICE`, default: the best one) and on the CPU reference. Prints figures; asserts
//! nothing about time. Run: `cargo bench --bench primal`.

use pathgrad::backend::Backend;
use std::time::Instant;

use pathgrad::gpu::{Context, ContextDesc, Renderer};
use pathgrad::integrator::RenderOptions;

const RUNS: usize = 5;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() -> pathgrad::Result<()> {
    let scene = pathgrad::scene::builtin::load("cornell-box")?;
    let opts = RenderOptions {
        width: 256,
        height: 256,
        spp: 16,
        max_depth: Some(6),
        seed: 1,
        ..RenderOptions::for_scene(&scene)
    };
    let samples = f64::from(opts.width * opts.height * opts.spp);
    let ctx = Context::new(&ContextDesc::default())?;
    let info = ctx.info().clone();
    let mut renderer = Renderer::new(&ctx, &scene)?;
    // Warm-up: the driver compiles the kernel at its first dispatch.
    renderer.render(&RenderOptions { spp: 1, ..opts })?;
    let mut times = Vec::new();
    for _ in 0..RUNS {
        let t = Instant::now();
        renderer.render(&opts)?;
        times.push(t.elapsed().as_secs_f64());
    }
    let (med, min) = (median(times.clone()), times.iter().copied().fold(f64::INFINITY, f64::min));
    println!("device: {} ({})", info.name, info.driver);
    println!(
        "scene: builtin:cornell-box {}x{} spp {} max_depth 6, {} runs after warm-up",
        opts.width, opts.height, opts.spp, RUNS
    );
    println!(
        "gpu primal: median {med:.3} s ({:.3} M samples/s), min {min:.3} s ({:.3} M samples/s)",
        samples / med / 1e6,
        samples / min / 1e6
    );
    let mut cpu_times = Vec::new();
    for _ in 0..3 {
        let t = Instant::now();
        pathgrad::cpu::render(&scene, &opts)?;
        cpu_times.push(t.elapsed().as_secs_f64());
    }
    let cmed = median(cpu_times);
    println!(
        "cpu reference ({} threads): median {cmed:.3} s ({:.3} M samples/s)",
        rayon::current_num_threads(),
        samples / cmed / 1e6
    );
    Ok(())
}

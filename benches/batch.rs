//! Throughput of many views and many items (issue "High-throughput batch"): views per second of a
//! multi-view gradient step against the same views one request at a time and one renderer (scene
//! upload, BVH, kernels) per view; items per second of `pathgrad batch` against one `pathgrad`
//! process per item. Prints figures; asserts nothing about time. Run: `cargo bench --bench batch`.

use std::process::Command;
use std::time::Instant;

use glam::Vec3;
use pathgrad::backend::Backend;
use pathgrad::gpu::renderer::GradMode;
use pathgrad::gpu::{Context, ContextDesc, Renderer};
use pathgrad::integrator::{RenderOptions, View};
use pathgrad::loss::Loss;
use pathgrad::scene::{Scene, Sensor};

const VIEWS: usize = 8;
const ITEMS: usize = 12;
const ROUNDS: usize = 3;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// The Cornell box with `VIEWS` sensors on an arc around its centre.
fn orbit() -> pathgrad::Result<Scene> {
    let mut scene = pathgrad::scene::builtin::load("cornell-box")?;
    let base = scene.camera;
    let radius = (base.position - base.target).length();
    scene.sensors.clear();
    for i in 0..VIEWS {
        let angle = (i as f32 / (VIEWS - 1) as f32 - 0.5) * 1.0;
        let offset = Vec3::new(angle.sin(), 0.0, angle.cos()) * radius;
        let camera = pathgrad::scene::Camera { position: base.target + offset, ..base };
        scene.sensors.push(Sensor { name: format!("orbit_{i}"), camera });
    }
    scene.camera = scene.sensors[0].camera;
    Ok(scene)
}

fn views_per_second(ctx: &std::sync::Arc<Context>) -> pathgrad::Result<()> {
    let scene = orbit()?;
    let opts = RenderOptions { width: 64, height: 64, spp: 4, seed: 1, ..RenderOptions::for_scene(&scene) };
    let views: Vec<View> = (0..VIEWS).map(|i| View::sensor(&scene, i)).collect::<pathgrad::Result<_>>()?;
    let mut renderer = Renderer::new(ctx, &scene)?;
    let mut truth = scene.params.clone();
    truth.set("sphere.bsdf.alpha.value", &[0.3])?;
    renderer.set_params(&truth)?;
    let targets = renderer.render_views(
        &RenderOptions { spp: 32, seed: 9, ..opts },
        &views,
        pathgrad::rng::PassTag::Reference,
        &mut |_, _| {},
    )?;
    renderer.set_params(&scene.params)?;
    let step = |r: &mut Renderer, v: &[View], t: &[pathgrad::image::Image]| {
        r.loss_and_gradient_views(&opts, 4, v, t, Loss::RelMse, GradMode::Float).map(|_| ())
    };
    step(&mut renderer, &views, &targets)?; // warm-up: kernel builds
    let (mut batched, mut one_by_one, mut fresh) = (Vec::new(), Vec::new(), Vec::new());
    for _ in 0..ROUNDS {
        let t = Instant::now();
        step(&mut renderer, &views, &targets)?;
        batched.push(t.elapsed().as_secs_f64());
        let t = Instant::now();
        for (v, target) in views.iter().zip(&targets) {
            step(&mut renderer, std::slice::from_ref(v), std::slice::from_ref(target))?;
        }
        one_by_one.push(t.elapsed().as_secs_f64());
        let t = Instant::now();
        for (i, target) in targets.iter().enumerate() {
            let mut alone = scene.clone();
            alone.camera = alone.sensors[i].camera;
            alone.sensor = i;
            let mut r = Renderer::new(ctx, &alone)?;
            step(&mut r, &[View::current(&alone)], std::slice::from_ref(target))?;
        }
        fresh.push(t.elapsed().as_secs_f64());
    }
    let (b, o, f) = (median(batched), median(one_by_one), median(fresh));
    println!("gradient steps over {VIEWS} views, 64×64, 4 + 4 spp (median of {ROUNDS}):");
    println!("  one multi-view step           {b:7.3} s  {:7.1} views/s", VIEWS as f64 / b);
    println!(
        "  {VIEWS} single-view steps          {o:7.3} s  {:7.1} views/s  ({:.2}× slower)",
        VIEWS as f64 / o,
        o / b
    );
    println!(
        "  {VIEWS} renderers, one view each   {f:7.3} s  {:7.1} views/s  ({:.2}× slower)",
        VIEWS as f64 / f,
        f / b
    );
    Ok(())
}

fn items_per_second() -> Result<(), Box<dyn std::error::Error>> {
    let exe = env!("CARGO_BIN_EXE_pathgrad");
    let dir = tempfile_dir()?;
    let target = dir.join("target.exr");
    let size = ["--width", "64", "--height", "64"];
    run(Command::new(exe)
        .args(["render", "builtin:cornell-box", "--spp", "32", "--no-preview", "-o"])
        .arg(&target)
        .args(size))?;
    let mut lines = Vec::new();
    for i in 0..ITEMS {
        let common = format!(r#""scene": "builtin:cornell-box", "width": 64, "height": 64, "spp": 4, "seed": {i}"#);
        lines.push(if i % 2 == 0 {
            format!(r#"{{{common}, "produce": ["image"]}}"#)
        } else {
            format!(r#"{{{common}, "produce": ["loss", "gradients"], "target": "target.exr"}}"#)
        });
    }
    std::fs::write(dir.join("m.jsonl"), lines.join("\n"))?;
    // Warm-up: the shader cache holds every kernel after this.
    run(Command::new(exe).arg("batch").arg(dir.join("m.jsonl")).arg("-o").arg(dir.join("warm")))?;
    let (mut batched, mut processes) = (Vec::new(), Vec::new());
    for round in 0..ROUNDS {
        let out = dir.join(format!("batch-{round}"));
        let t = Instant::now();
        run(Command::new(exe).arg("batch").arg(dir.join("m.jsonl")).arg("-o").arg(&out))?;
        batched.push(t.elapsed().as_secs_f64());
        let t = Instant::now();
        for i in 0..ITEMS {
            let seed = i.to_string();
            let mut c = Command::new(exe);
            if i % 2 == 0 {
                c.args(["render", "builtin:cornell-box", "--spp", "4", "--seed", &seed, "--no-preview", "-o"])
                    .arg(dir.join(format!("p{round}-{i}.exr")));
            } else {
                c.args(["grad", "builtin:cornell-box", "--spp", "4", "--seed", &seed, "--json", "--target"])
                    .arg(&target);
            }
            run(c.args(size))?;
        }
        processes.push(t.elapsed().as_secs_f64());
    }
    let (b, p) = (median(batched), median(processes));
    println!("{ITEMS} items (renders and loss gradients), 64×64, 4 spp (median of {ROUNDS}, whole processes):");
    println!("  pathgrad batch, one process   {b:7.3} s  {:7.2} items/s", ITEMS as f64 / b);
    println!("  one process per item          {p:7.3} s  {:7.2} items/s  ({:.2}× slower)", ITEMS as f64 / p, p / b);
    std::fs::remove_dir_all(&dir)?;
    Ok(())
}

fn tempfile_dir() -> std::io::Result<std::path::PathBuf> {
    let dir = std::env::temp_dir().join(format!("pathgrad-bench-batch-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    Ok(dir)
}

fn run(c: &mut Command) -> Result<(), Box<dyn std::error::Error>> {
    let o = c.output()?;
    if !o.status.success() {
        return Err(format!("{c:?}: {}", String::from_utf8_lossy(&o.stderr)).into());
    }
    Ok(())
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let ctx = Context::new(&ContextDesc::default())?;
    println!("device: {} ({})", ctx.info().name, ctx.info().driver);
    views_per_second(&ctx)?;
    items_per_second()
}

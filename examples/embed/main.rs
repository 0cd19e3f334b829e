//! An engine embeds pathgrad: it creates its own Vulkan instance, device and queue (`host.rs`),
//! hands them to pathgrad, renders and differentiates a scene on them, and goes on using its device
//! after pathgrad is gone.
//!
//!     cargo run --release --example embed
//!
//! With `EMBED_VALIDATION=1` the host enables the validation layer and its own messenger counts
//! every message; the example fails if there is any.

mod host;

use std::sync::Arc;

use pathgrad::gpu::renderer::GradMode;
use pathgrad::gpu::{Context, Renderer};
use pathgrad::integrator::RenderOptions;
use pathgrad::loss::Loss;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let validation = std::env::var("EMBED_VALIDATION").is_ok_and(|v| v == "1");
    let host = host::Host::new(&host::HostOptions { validation, ..Default::default() })?;

    {
        // SAFETY: the host's handles are valid, were created with everything pathgrad requires,
        // and outlive this block, in which every pathgrad object is dropped.
        let ctx: Arc<Context> = unsafe { Context::from_raw(host.borrowed()) }?;
        println!("pathgrad on the host's device: {}", ctx.info().name);
        let scene = pathgrad::scene::builtin::load("cornell-box")?;
        let mut renderer = Renderer::new(&ctx, &scene)?;
        let options = RenderOptions { width: 64, height: 64, spp: 4, ..RenderOptions::for_scene(&scene) };
        let image = renderer.render(&options)?;
        println!("rendered {}x{}, mean {:.4?}", image.width(), image.height(), image.mean());

        // A gradient against a target with a rougher sphere.
        let mut target_scene = scene.clone();
        target_scene.params.set("sphere.bsdf.alpha.value", &[0.3])?;
        let target = Renderer::new(&ctx, &target_scene)?.render(&RenderOptions { spp: 16, ..options })?;
        let (loss, gradients) = renderer.loss_and_gradient(&options, &target, Loss::RelMse, GradMode::Float)?;
        println!("loss {loss:.4}, d loss / d alpha = {:?}", gradients.get("sphere.bsdf.alpha.value"));
    }

    // pathgrad is gone; the engine's device and queue go on working.
    let words = host.fill_and_read(0x5EED, 256)?;
    assert!(words.iter().all(|&w| w == 0x5EED), "the host's own work after pathgrad");
    let messages = host.close();
    println!("the host's device still works; validation messages: {messages}");
    if messages > 0 {
        return Err("the validation layer reported messages".into());
    }
    Ok(())
}

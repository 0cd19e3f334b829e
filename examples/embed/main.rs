//! An engine embeds pathgrad: it creates its own Vulkan instance, device and queue (`host.rs`),
//! hands them to pathgrad, records a render and a gradient pass into its own command buffers,
//! reads pathgrad's image and gradient buffers itself, and goes on using its device after
//! pathgrad is gone.
//!
//!     cargo run --release --example embed
//!
//! With `EMBED_VALIDATION=1` the host enables the validation layer and its own messenger counts
//! every message; the example fails if there is any.

mod host;

use pathgrad::backend::Backend;
use pathgrad::gpu::renderer::GradMode;
use pathgrad::gpu::{BufferLayout, Context, Renderer};
use pathgrad::image::Image;
use pathgrad::integrator::RenderOptions;
use pathgrad::loss::{Loss, loss_and_adjoint};

fn floats(bytes: &[u8]) -> Vec<f32> {
    bytemuck::pod_collect_to_vec(bytes)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let validation = std::env::var("EMBED_VALIDATION").is_ok_and(|v| v == "1");
    let host = host::Host::new(&host::HostOptions { validation, ..Default::default() })?;

    {
        // SAFETY: the host's handles are valid, were created with everything pathgrad requires,
        // and outlive this block, in which every pathgrad object is dropped.
        let ctx = unsafe { Context::from_raw(host.borrowed()) }?;
        println!("pathgrad on the host's device: {}", ctx.info().name);
        let scene = pathgrad::scene::builtin::load("cornell-box")?;
        let options = RenderOptions { width: 64, height: 64, spp: 4, ..RenderOptions::for_scene(&scene) };
        // The target: the same box with a rougher sphere (pathgrad's blocking call, for brevity).
        let mut target_scene = scene.clone();
        target_scene.params.set("sphere.bsdf.alpha.value", &[0.3])?;
        let target = Renderer::new(&ctx, &target_scene)?.render(&RenderOptions { spp: 16, ..options })?;

        let mut renderer = Renderer::new(&ctx, &scene)?;
        let frame = renderer.frame(&options, GradMode::Float)?; // builds the kernels now
        let image = frame.image();
        assert_eq!(image.layout, BufferLayout::RgbSums);

        // Frame 1: clear and render, recorded into the host's command buffer; the host copies the
        // image out in the same command buffer.
        let sums = host.read_after(
            |cmd| {
                renderer.record_clear(&frame, cmd);
                renderer.record_render(&frame, cmd, 0..options.spp).expect("a valid range");
            },
            image.buffer,
            image.offset,
            image.size,
        )?;
        let spp = options.spp as f32;
        let rendered = Image::from_rgb(options.width, options.height, floats(&sums).iter().map(|v| v / spp).collect())?;
        println!("rendered {}x{}, mean {:.4?}", rendered.width(), rendered.height(), rendered.mean());

        // The host's loss and its adjoint image, written into pathgrad's adjoint buffer by the host.
        let (loss, adjoint) = loss_and_adjoint(&rendered, &target, Loss::RelMse)?;
        let view = frame.adjoint();
        host.write(view.buffer, view.offset, bytemuck::cast_slice(adjoint.as_slice()))?;

        // Frame 2: the gradient pass, split in two ranges; the host reads the gradient buffer.
        let gradient = frame.gradient();
        let half = options.spp / 2;
        let bytes = host.read_after(
            |cmd| {
                renderer.record_backward(&frame, cmd, 0..half).expect("a valid range");
                renderer.record_backward(&frame, cmd, half..options.spp).expect("a valid range");
            },
            gradient.buffer,
            gradient.offset,
            gradient.size,
        )?;
        frame.check_status()?;
        let alpha = scene.params.entry(scene.params.find("sphere.bsdf.alpha.value").ok_or("no alpha")?).offset;
        println!(
            "loss {loss:.4}, d loss / d alpha = {:.5} (read from pathgrad's buffer by the host)",
            floats(&bytes)[alpha as usize]
        );
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

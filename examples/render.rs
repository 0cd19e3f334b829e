//! The smallest use of pathgrad: load a scene, render it, save it, and take one gradient.
//!
//!     cargo run --release --example render [SCENE] [OUT.exr]

use pathgrad::backend::Backend;
use pathgrad::gpu::{Context, ContextDesc, Renderer, renderer::GradMode};
use pathgrad::{integrator::RenderOptions, loss::Loss};

fn main() -> pathgrad::Result<()> {
    let mut args = std::env::args().skip(1);
    let scene = pathgrad::scene::load(&args.next().unwrap_or_else(|| "builtin:cornell-box".into()), &[])?;
    let out = args.next().unwrap_or_else(|| "render.exr".into());
    let ctx = Context::new(&ContextDesc::default())?;
    let mut renderer = Renderer::new(&ctx, &scene)?;
    let options = RenderOptions { spp: 16, ..RenderOptions::for_scene(&scene) };
    let image = renderer.render(&options)?;
    image.save(&out)?;
    // The loss against the render itself is 0, and so is its gradient by every parameter.
    let (loss, gradients) = renderer.loss_and_gradient(&options, &image, Loss::L2, GradMode::Float)?;
    println!("{out}: {}x{}; loss {loss}, {} gradient values", image.width(), image.height(), gradients.values().len());
    Ok(())
}

//! Renders the built-in Cornell box small on the default Vulkan device (validation on where the
//! layer is installed) and on pathgrad's CPU reference, and fails unless both means agree: the
//! two run the same estimator on the same random numbers, so they differ by float rounding only.

use pathgrad::backend::Backend;
use pathgrad::gpu::{Context, ContextDesc, Renderer};
use pathgrad::integrator::RenderOptions;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let scene = pathgrad::scene::load("builtin:cornell-box", &[])?;
    let ctx = Context::new(&ContextDesc { validation: true, ..ContextDesc::default() })?;
    let mut renderer = Renderer::new(&ctx, &scene)?;
    let options = RenderOptions { width: 32, height: 32, spp: 8, ..RenderOptions::for_scene(&scene) };
    let gpu = renderer.render(&options)?.mean();
    let cpu = pathgrad::cpu::render(&scene, &options)?.mean();
    println!("device {}: mean {gpu:.5?}; CPU reference {cpu:.5?}", ctx.info().name);
    for c in 0..3 {
        // A lit scene: a black or non-finite image is a failure, not agreement.
        if !(gpu[c] > 0.01) || !((gpu[c] - cpu[c]).abs() <= 1e-4 * cpu[c]) {
            return Err(
                format!("channel {c}: the device's mean {} and the CPU reference's {} differ", gpu[c], cpu[c]).into()
            );
        }
    }
    if ctx.validation_errors() > 0 {
        return Err(format!("{} validation messages", ctx.validation_errors()).into());
    }
    Ok(())
}

//! pathgrad on a device it did not create (`Context::from_raw`): the same results as on its own,
//! refusal of a device without what it needs, and nothing of the host's destroyed or leaked.

use pathgrad::gpu::renderer::GradMode;
use pathgrad::gpu::{Context, Renderer};
use pathgrad::integrator::RenderOptions;
use pathgrad::loss::Loss;

use crate::host::{Host, HostOptions};
use crate::support::TestGpu;

fn bits(values: &[f32]) -> Vec<u32> {
    values.iter().map(|v| v.to_bits()).collect()
}

/// Renders the Cornell box and takes a deterministic gradient on `ctx`.
fn image_and_gradient(ctx: &std::sync::Arc<Context>) -> (Vec<u32>, Vec<u32>) {
    let scene = pathgrad::scene::builtin::load("cornell-box").unwrap();
    let options = RenderOptions { width: 24, height: 24, spp: 4, ..RenderOptions::for_scene(&scene) };
    let mut renderer = Renderer::new(ctx, &scene).unwrap();
    let image = renderer.render(&options).unwrap();
    let mut target_scene = scene.clone();
    target_scene.params.set("sphere.bsdf.alpha.value", &[0.3]).unwrap();
    let target = Renderer::new(ctx, &target_scene).unwrap().render(&options).unwrap();
    let mode = if ctx.info().int64_atomics { GradMode::Deterministic } else { GradMode::Float };
    let (_, gradients) = renderer.loss_and_gradient(&options, &target, Loss::RelMse, mode).unwrap();
    (bits(image.as_slice()), bits(gradients.values()))
}

/// On the host's device pathgrad renders bit for bit the image it renders on its own device, and
/// the same deterministic gradient; afterwards the host's device, queue and memory still work and
/// its validation layer has reported nothing, not even at `vkDestroyDevice` (where any object
/// pathgrad leaked would be reported).
#[test]
fn a_borrowed_device_gives_the_owned_results_and_is_left_intact() {
    let owned = image_and_gradient(&TestGpu::new().ctx);
    let host = Host::new(&HostOptions { validation: true, ..Default::default() }).unwrap();
    let borrowed = {
        // SAFETY: the host's handles are valid and outlive this block.
        let ctx = unsafe { Context::from_raw(host.borrowed()) }.unwrap();
        assert!(!ctx.validation_enabled(), "pathgrad installs no layer or messenger on a borrowed device");
        let results = image_and_gradient(&ctx);
        assert_eq!(ctx.live_objects(), 0);
        results
    };
    assert_eq!(borrowed.0, owned.0, "image");
    assert_eq!(borrowed.1, owned.1, "gradient");
    assert!(borrowed.1.iter().any(|&b| f32::from_bits(b) != 0.0));
    let words = host.fill_and_read(0xC0FFEE, 1024).unwrap();
    assert!(words.iter().all(|&w| w == 0xC0FFEE));
    assert_eq!(host.close(), 0, "the host's validation layer reported messages");
}

/// A device created without something pathgrad needs is refused, naming what is missing.
#[test]
fn a_device_without_a_required_feature_is_refused_by_name() {
    for (leave_out, named) in [
        (vec!["shaderInt64"], vec!["shaderInt64"]),
        (vec!["bufferDeviceAddress", "scalarBlockLayout"], vec!["bufferDeviceAddress", "scalarBlockLayout"]),
        (vec!["VK_EXT_shader_atomic_float"], vec!["VK_EXT_shader_atomic_float", "shaderBufferFloat32AtomicAdd"]),
    ] {
        let host = Host::new(&HostOptions { validation: true, leave_out: leave_out.clone() }).unwrap();
        // SAFETY: as above.
        let e = unsafe { Context::from_raw(host.borrowed()) }.unwrap_err().to_string();
        for name in named {
            assert!(e.contains(name), "{leave_out:?}: {e}");
        }
        assert!(e.contains("Context::requirements()"), "{e}");
        assert_eq!(host.close(), 0);
    }
}

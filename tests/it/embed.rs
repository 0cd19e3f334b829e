//! pathgrad on a device it did not create (`Context::from_raw`): the same results as on its own,
//! refusal of a device without what it needs, and nothing of the host's destroyed or leaked.

use pathgrad::backend::Backend;
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
    // A buffer of the host's that lives across pathgrad's whole life, filled before it comes.
    let (kept, kept_memory) = host.staging(64).unwrap();
    // SAFETY: the host's own buffer, alive until freed below.
    host.run(|cmd| unsafe { host.device.cmd_fill_buffer(cmd, kept, 0, 64, 0xABCD) }).unwrap();
    let borrowed = {
        // SAFETY: the host's handles are valid and outlive this block.
        let ctx = unsafe { Context::from_raw(host.borrowed()) }.unwrap();
        assert!(!ctx.validation_enabled(), "pathgrad installs no layer or messenger on a borrowed device");
        let results = image_and_gradient(&ctx);
        assert_eq!(ctx.live_objects(), 0);
        results
    };
    // The engine writes a parameter into pathgrad's parameter buffer itself; a render then sees it.
    {
        // SAFETY: as above.
        let ctx = unsafe { Context::from_raw(host.borrowed()) }.unwrap();
        let scene = pathgrad::scene::builtin::load("cornell-box").unwrap();
        let options = RenderOptions { width: 16, height: 16, spp: 2, ..RenderOptions::for_scene(&scene) };
        let mut rougher = scene.clone();
        rougher.params.set("sphere.bsdf.alpha.value", &[0.3]).unwrap();
        let want = Renderer::new(&ctx, &rougher).unwrap().render(&options).unwrap();
        let mut renderer = Renderer::new(&ctx, &scene).unwrap();
        let params = renderer.params_buffer();
        let offset = scene.params.entry(scene.params.find("sphere.bsdf.alpha.value").unwrap()).offset;
        host.write(params.buffer, params.offset + 4 * u64::from(offset), bytemuck::bytes_of(&0.3f32)).unwrap();
        let got = renderer.render(&options).unwrap();
        assert_eq!(bits(got.as_slice()), bits(want.as_slice()), "a parameter written by the host");
    }
    assert_eq!(borrowed.0, owned.0, "image");
    assert_eq!(borrowed.1, owned.1, "gradient");
    assert!(borrowed.1.iter().any(|&b| f32::from_bits(b) != 0.0));
    let words = host.fill_and_read(0xC0FFEE, 1024).unwrap();
    assert!(words.iter().all(|&w| w == 0xC0FFEE));
    let kept_words: Vec<u32> = bytemuck::pod_collect_to_vec(&host.read_after(|_| {}, kept, 0, 64).unwrap());
    assert_eq!(kept_words, vec![0xABCD; 16], "the host's buffer from before pathgrad");
    host.free(kept, kept_memory);
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

/// The recorded path gives the blocking path's results bit for bit: a frame's render recorded in
/// one range is the image `render` gives, its deterministic gradient recorded in two ranges is the
/// one `backward` gives, and the same work submitted with timeline semaphores (the gradient pass
/// waiting on the render's signal) gives them again and signals its values.
#[test]
fn the_recorded_path_equals_the_blocking_path() {
    use ash::vk;
    use pathgrad::gpu::{BufferLayout, SubmitSync};
    let gpu = TestGpu::new();
    let ctx = &gpu.ctx;
    assert!(ctx.info().int64_atomics && ctx.info().timeline_semaphores, "lavapipe has both");
    let scene = pathgrad::scene::builtin::load("cornell-box").unwrap();
    let options = RenderOptions { width: 24, height: 16, spp: 4, ..RenderOptions::for_scene(&scene) };
    let mut renderer = Renderer::new(ctx, &scene).unwrap();
    let image = renderer.render(&options).unwrap();
    let mut target_scene = scene.clone();
    target_scene.params.set("sphere.bsdf.alpha.value", &[0.3]).unwrap();
    let target = Renderer::new(ctx, &target_scene).unwrap().render(&options).unwrap();
    let (_, adjoint) = pathgrad::loss::loss_and_adjoint(&image, &target, Loss::RelMse).unwrap();
    let gradient = renderer.backward(&options, &adjoint, GradMode::Deterministic).unwrap();

    let frame = renderer.frame(&options, GradMode::Deterministic).unwrap();
    assert!(matches!(frame.gradient().layout, BufferLayout::GradientFixed { .. }));
    assert_eq!(frame.image().size, 24 * 16 * 12);
    frame.write_adjoint(&adjoint).unwrap();
    ctx.submit_and_wait("recorded", |cmd| {
        renderer.record_clear(&frame, cmd);
        renderer.record_render(&frame, cmd, 0..4).unwrap();
        renderer.record_backward(&frame, cmd, 0..2).unwrap();
        renderer.record_backward(&frame, cmd, 2..4).unwrap();
    })
    .unwrap();
    frame.check_status().unwrap();
    assert_eq!(bits(frame.read_image(4).unwrap().as_slice()), bits(image.as_slice()), "recorded image");
    let recorded = frame.read_gradients(&renderer).unwrap();
    assert_eq!(bits(recorded.values()), bits(gradient.values()), "recorded gradient");
    assert!(renderer.record_render(&frame, vk::CommandBuffer::null(), 3..5).is_err(), "a range past spp");

    let d = ctx.device();
    let mut kind = vk::SemaphoreTypeCreateInfo::default().semaphore_type(vk::SemaphoreType::TIMELINE);
    // SAFETY: a semaphore of the test's, destroyed below after every wait.
    let semaphore =
        unsafe { d.create_semaphore(&vk::SemaphoreCreateInfo::default().push_next(&mut kind), None) }.unwrap();
    ctx.submit_and_wait("clear", |cmd| renderer.record_clear(&frame, cmd)).unwrap();
    let render =
        renderer.submit_render(&frame, 0..4, &SubmitSync { wait: vec![], signal: vec![(semaphore, 1)] }).unwrap();
    let wait = vec![(semaphore, 1, vk::PipelineStageFlags::COMPUTE_SHADER)];
    let backward = renderer.submit_backward(&frame, 0..4, &SubmitSync { wait, signal: vec![(semaphore, 2)] }).unwrap();
    let semaphores = [semaphore];
    let values = [2u64];
    // SAFETY: the semaphore is alive; a finite timeout.
    unsafe {
        d.wait_semaphores(&vk::SemaphoreWaitInfo::default().semaphores(&semaphores).values(&values), 60_000_000_000)
    }
    .unwrap();
    render.wait().unwrap();
    backward.wait().unwrap();
    // SAFETY: no submission uses the semaphore any more.
    unsafe { d.destroy_semaphore(semaphore, None) };
    frame.check_status().unwrap();
    assert_eq!(bits(frame.read_image(4).unwrap().as_slice()), bits(image.as_slice()), "submitted image");
    assert_eq!(bits(frame.read_gradients(&renderer).unwrap().values()), bits(gradient.values()), "submitted gradient");
    drop(frame);
    drop(renderer);
    assert_eq!(ctx.validation_errors(), 0);
}

/// A frame takes attached gradients too (the index of refraction of a glass sphere over a diffuse
/// floor, which detached sampling cannot differentiate): recorded in two sample ranges, its
/// gradient is the one `backward` gives (float atomics: equal up to the order of their sums), its
/// image the render's bit for bit; in deterministic mode (the fixed-point attached kernel) the
/// recorded gradient is `backward`'s bit for bit.
#[test]
fn a_frame_takes_attached_gradients() {
    use pathgrad::integrator::Sampling;
    let gpu = TestGpu::new();
    let ctx = &gpu.ctx;
    let scene = crate::support::scenes::data_scene("attached_floor");
    let options = RenderOptions {
        width: 24,
        height: 24,
        spp: 4,
        sampling: Sampling::attached(),
        ..RenderOptions::for_scene(&scene)
    };
    let adjoint = crate::attached::weights(24, 24);
    let mut renderer = Renderer::new(ctx, &scene).unwrap();
    let image = renderer.render(&options).unwrap();
    let gradient = renderer.backward(&options, &adjoint, GradMode::Float).unwrap();
    let eta = gradient.get("glass.bsdf.eta").unwrap()[0];
    assert!(eta.abs() > 1.0, "the η gradient is {eta}: attached sampling gives one");

    // A frame of `mode`, rendered in one range and differentiated in two split at `split`, then
    // its image (after spp samples) and gradient.
    let mut record = |mode: GradMode, split: u32| {
        let frame = renderer.frame(&options, mode).unwrap();
        frame.write_adjoint(&adjoint).unwrap();
        ctx.submit_and_wait("recorded", |cmd| {
            renderer.record_clear(&frame, cmd);
            renderer.record_render(&frame, cmd, 0..4).unwrap();
            renderer.record_backward(&frame, cmd, 0..split).unwrap();
            renderer.record_backward(&frame, cmd, split..4).unwrap();
        })
        .unwrap();
        frame.check_status().unwrap();
        (frame.read_image(4).unwrap(), frame.read_gradients(&renderer).unwrap())
    };
    let (_, fixed_frame) = record(GradMode::Deterministic, 3);
    let (recorded_image, recorded) = record(GradMode::Float, 1);
    let fixed = renderer.backward(&options, &adjoint, GradMode::Deterministic).unwrap();
    assert_eq!(bits(fixed_frame.values()), bits(fixed.values()), "recorded deterministic gradient");
    assert!(fixed.get("glass.bsdf.eta").unwrap()[0].abs() > 1.0, "the deterministic η gradient");
    assert_eq!(bits(recorded_image.as_slice()), bits(image.as_slice()), "recorded image");
    let scale = gradient.values().iter().fold(0.0f32, |m, v| m.max(v.abs()));
    for (i, (a, b)) in recorded.values().iter().zip(gradient.values()).enumerate() {
        assert!((a - b).abs() <= 1e-4 * scale, "gradient value {i}: frame {a}, backward {b}");
    }
    drop(renderer);
    assert_eq!(ctx.validation_errors(), 0);
}

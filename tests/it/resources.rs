//! Vulkan objects own themselves: everything a render creates is gone when its owner is dropped.

use pathgrad::backend::Backend;
use pathgrad::gpu::Renderer;
use pathgrad::integrator::RenderOptions;
use pathgrad::scene::builtin;

use crate::support::TestGpu;

#[test]
fn render_leaves_no_live_objects_behind() {
    let gpu = TestGpu::new();
    assert_eq!(gpu.ctx.live_objects(), 0);
    let scene = builtin::load("blend").unwrap();
    let mut renderer = Renderer::new(&gpu.ctx, &scene).unwrap();
    // 17 scene buffers (some of them empty here, as the media's three); kernels are built on
    // first use.
    assert_eq!(gpu.ctx.live_objects(), 17);
    let opts = RenderOptions { width: 16, height: 12, spp: 2, ..RenderOptions::for_scene(&scene) };
    renderer.render(&opts).unwrap();
    // + the primal kernel variant, cached for the renderer's life.
    assert_eq!(gpu.ctx.live_objects(), 18);
    renderer.render(&RenderOptions { seed: 3, ..opts }).unwrap();
    assert_eq!(gpu.ctx.live_objects(), 18, "a render keeps nothing alive, and reuses its variant");
    drop(renderer);
    assert_eq!(gpu.ctx.live_objects(), 0);
}

#[test]
fn parameter_changes_reach_the_gpu() {
    let gpu = TestGpu::new();
    let scene = builtin::load("cornell-box").unwrap();
    let mut renderer = Renderer::new(&gpu.ctx, &scene).unwrap();
    let opts = RenderOptions { width: 24, height: 24, spp: 2, ..RenderOptions::for_scene(&scene) };
    let before = renderer.render(&opts).unwrap();
    let mut params = scene.params.clone();
    params.set("light.emitter.radiance.value", &[34.0, 24.0, 8.0]).unwrap();
    renderer.set_params(&params).unwrap();
    let after = renderer.render(&opts).unwrap();
    // Doubling the only emitter doubles every path's radiance: the same random numbers take the same
    // paths, so the images differ by exactly a factor of two up to rounding.
    for (a, b) in before.as_slice().iter().zip(after.as_slice()) {
        assert!((2.0 * a - b).abs() <= 1e-5 * b.abs() + 1e-7, "{a} vs {b}");
    }
}

/// Issue 38: uploads cross the staging buffer's chunk boundaries intact, whether copied from a
/// slice or made chunk by chunk, with an element size that does not divide the chunk (72 bytes,
/// the per-triangle shading record of before; the vertex normals' 12 do not divide it either).
#[test]
fn issue_38_uploads_cross_chunk_boundaries() {
    use pathgrad::gpu::Buffer;
    use pathgrad::gpu::buffer::UPLOAD_CHUNK_BYTES;
    let gpu = TestGpu::new();
    let per_chunk = UPLOAD_CHUNK_BYTES / 72;
    let count = 2 * per_chunk + 5;
    let word = |i: usize, k: usize| (i * 18 + k) as u32;
    let data: Vec<[u32; 18]> = (0..count).map(|i| std::array::from_fn(|k| word(i, k))).collect();
    let copied = Buffer::storage_with(&gpu.ctx, "copied", &data).unwrap();
    assert_eq!(copied.download::<[u32; 18]>(count).unwrap(), data);
    drop(copied);
    let made = Buffer::storage(&gpu.ctx, "made", (count * 72) as u64).unwrap();
    let (mut next, mut sizes) = (0, Vec::new());
    made.upload_with(count, |chunk: &mut [[u32; 18]]| {
        sizes.push(chunk.len());
        for slot in chunk {
            *slot = std::array::from_fn(|k| word(next, k));
            next += 1;
        }
    })
    .unwrap();
    assert_eq!(sizes, [per_chunk, per_chunk, 5]);
    assert_eq!(made.download::<[u32; 18]>(count).unwrap(), data);
    assert!(made.upload_with(count + 1, |_: &mut [[u32; 18]]| ()).is_err(), "more than the buffer holds");
}

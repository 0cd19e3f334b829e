//! GLSL twins pinned to their Rust originals by running both on the same inputs.

use pathgrad::gpu::abi::{BINDING_PROBE_IN, BINDING_PROBE_OUT};
use pathgrad::gpu::pipeline::groups_for;
use pathgrad::gpu::{Buffer, Kernel};
use pathgrad::rng::{philox4x32_10, u32_to_unit_f32};

use crate::support::TestGpu;

/// The Philox known answers, plus a grid over every counter field (small and large values, all
/// streams and blocks), agree bit for bit between `shaders/lib/rng.glsl` and `src/rng.rs`.
#[test]
fn rng_gpu_equals_cpu_bitwise() {
    let gpu = TestGpu::new();
    let mut cases: Vec<[u32; 6]> = vec![
        [0, 0, 0, 0, 0, 0],
        [u32::MAX, u32::MAX, u32::MAX, u32::MAX, u32::MAX, u32::MAX],
        [0x243f6a88, 0x85a308d3, 0x13198a2e, 0x03707344, 0xa4093822, 0x299f31d0],
    ];
    let values = [0u32, 1, 7, 255, 65_535, 1 << 24, 0x8000_0000, u32::MAX];
    for (i, &a) in values.iter().enumerate() {
        for (j, &b) in values.iter().enumerate() {
            for stream in 0..5u32 {
                let c2 = (a & 0xFFFF) | (stream << 16) | ((j as u32 % 3) << 24);
                cases.push([a, b, c2, i as u32, 42, (3 << 8) | (stream % 3 + 1)]);
            }
        }
    }
    let flat: Vec<u32> = cases.iter().flatten().copied().collect();
    let input = Buffer::storage_with(&gpu.ctx, "rng probe input", &flat).unwrap();
    let output = Buffer::storage(&gpu.ctx, "rng probe output", (cases.len() * 8 * 4) as u64).unwrap();
    let kernel = Kernel::new(&gpu.ctx, "rng_probe", &[BINDING_PROBE_IN, BINDING_PROBE_OUT], 4).unwrap();
    let group = kernel.bind(&[(BINDING_PROBE_IN, &input), (BINDING_PROBE_OUT, &output)]).unwrap();
    let n = cases.len() as u32;
    gpu.ctx
        .submit_and_wait("rng probe", |cmd| kernel.record(cmd, &group, bytemuck::bytes_of(&n), groups_for(n)))
        .unwrap();
    let got: Vec<u32> = output.download(cases.len() * 8).unwrap();
    for (i, case) in cases.iter().enumerate() {
        let want = philox4x32_10([case[0], case[1], case[2], case[3]], [case[4], case[5]]);
        assert_eq!(&got[8 * i..8 * i + 4], &want, "case {i}: {case:08x?}");
        let want_f: Vec<u32> = want.iter().map(|&w| u32_to_unit_f32(w).to_bits()).collect();
        assert_eq!(&got[8 * i + 4..8 * i + 8], &want_f[..], "case {i} floats");
    }
}

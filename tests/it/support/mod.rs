//! Test harness: a validated device per test, temporary directories, the Embree reference.

pub mod bvh_probe;
pub mod embree;
pub mod scenes;

use std::sync::Arc;

use pathgrad::gpu::{Context, ContextDesc, DeviceChoice};

/// A device for one test: lavapipe unless `PATHGRAD_TEST_DEVICE` names another, validation on.
/// Dropping it fails the test if the validation layer reported anything.
pub struct TestGpu {
    /// The context under test.
    pub ctx: Arc<Context>,
}

impl TestGpu {
    /// Creates the device; panics with the library's error message if there is none.
    pub fn new() -> TestGpu {
        let device = match std::env::var("PATHGRAD_TEST_DEVICE") {
            Ok(v) if !v.trim().is_empty() => DeviceChoice::parse(&v),
            _ => DeviceChoice::PreferCpu,
        };
        let ctx = Context::new(&ContextDesc { device, validation: true }).unwrap_or_else(|e| panic!("{e}"));
        assert!(ctx.validation_enabled(), "tests need the validation layer: apt-get install vulkan-validationlayers");
        TestGpu { ctx }
    }
}

impl Drop for TestGpu {
    fn drop(&mut self) {
        let n = self.ctx.validation_errors();
        if n != 0 && !std::thread::panicking() {
            panic!("the validation layer reported {n} message(s); see the log above");
        }
    }
}

/// Values of a GPU image that differ from the CPU twin's beyond rounding: paths that took the same
/// decisions agree to 1e-4 relative per value (`cpu_vs_gpu.rs`); `floor` is a fraction of the CPU
/// image's largest |value| below which a difference is ignored (terms of both signs cancel in a
/// gradient pixel; near-black pixels of a render). Callers budget how many may differ.
pub fn count_mismatches(gpu: &pathgrad::image::Image, cpu: &pathgrad::image::Image, floor: f32) -> usize {
    let scale = cpu.as_slice().iter().fold(0.0f32, |m, v| m.max(v.abs()));
    gpu.as_slice()
        .iter()
        .zip(cpu.as_slice())
        .filter(|(a, b)| (*a - *b).abs() > 1e-4 * a.abs().max(b.abs()) + floor * scale)
        .count()
}

/// Deterministic gradients (64-bit fixed point): `fixed` and `again`, two runs of the same
/// request, are bitwise equal, not all zero, and each value agrees with the float kernel's
/// `float` to rounding — 1e-4 of the largest |value|, as `adaptive.rs` checks the plain kernels.
pub fn assert_fixed_matches_float(
    fixed: &pathgrad::params::Gradients,
    again: &pathgrad::params::Gradients,
    float: &pathgrad::params::Gradients,
) {
    let bits = |g: &pathgrad::params::Gradients| g.values().iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(fixed), bits(again), "two deterministic runs");
    let largest = fixed.values().iter().fold(0.0f32, |m, v| m.max(v.abs()));
    assert!(largest > 0.0, "the deterministic gradient is all zero");
    for (i, (x, y)) in fixed.values().iter().zip(float.values()).enumerate() {
        assert!((x - y).abs() <= 1e-4 * largest, "value {i}: fixed point {x}, float {y}");
    }
}

/// Forward against reverse mode (ALGORITHMS.md §10, forward/reverse consistency): for a tangent
/// of 1 on every value of a parameter, `reverse` (its reverse-mode gradient for `adjoint`, summed
/// over those values) equals Σ_p A_p · ∂I_p/∂θ from its forward-mode image `forward`. The two
/// differ only by f32 rounding of per-pixel means (≤ 1e-6 relative each), so they must agree to
/// 1e-5 of Σ_p |A_p · ∂I_p/∂θ|, which is returned as the scale of other comparisons.
pub fn assert_forward_equals_reverse(
    what: &str,
    forward: &pathgrad::image::Image,
    adjoint: &pathgrad::image::Image,
    reverse: f64,
) -> f64 {
    let terms: Vec<f64> =
        forward.as_slice().iter().zip(adjoint.as_slice()).map(|(f, a)| f64::from(*f) * f64::from(*a)).collect();
    let magnitude: f64 = terms.iter().map(|t| t.abs()).sum();
    let forward_total: f64 = terms.iter().sum();
    assert!(
        (reverse - forward_total).abs() <= 1e-5 * magnitude,
        "{what}: reverse {reverse} vs forward {forward_total}"
    );
    magnitude
}

/// The finite-difference test's verdict (gradients.rs, media.rs): over the seeds, the Welch
/// statistic |mean_fd − mean_prb| / √(s²_fd/M + s²_prb/M) is below 4, and the PRB mean is more
/// than two standard errors from 0 (the test has the power to see a wrong gradient). Prints both
/// estimates under `what`.
pub fn assert_fd_matches(what: &str, fd: &[f64], prb: &[f64]) {
    let seeds = fd.len() as f64;
    let stats = |v: &[f64]| {
        let m = v.iter().sum::<f64>() / v.len() as f64;
        (m, v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (v.len() as f64 - 1.0))
    };
    let ((mf, vf), (mp, vp)) = (stats(fd), stats(prb));
    let welch = (mf - mp).abs() / ((vf + vp) / seeds).sqrt();
    println!(
        "{what}: finite differences {mf:.5} ± {:.5}, PRB {mp:.5} ± {:.5}, Welch {welch:.2}",
        (vf / seeds).sqrt(),
        (vp / seeds).sqrt()
    );
    assert!(welch < 4.0, "{what}: FD {mf} vs PRB {mp} ({welch:.1} standard errors)");
    assert!(
        mp.abs() > 2.0 * (vp / seeds).sqrt(),
        "{what}: the gradient is not distinguishable from 0, the test has no power"
    );
}

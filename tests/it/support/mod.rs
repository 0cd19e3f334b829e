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

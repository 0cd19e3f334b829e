//! pathgrad: a differentiable path tracer on Vulkan compute shaders.

pub mod bsdf;
pub mod bvh;
pub mod cpu;
pub mod error;
pub mod gpu;
pub mod image;
pub mod integrator;
pub mod params;
pub mod rng;
pub mod sampling;
pub mod scene;
pub mod stats;

pub use error::{Error, Result};

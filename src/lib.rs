//! pathgrad: a differentiable path tracer on Vulkan compute shaders.

pub mod bsdf;
pub mod error;
pub mod gpu;
pub mod image;
pub mod rng;
pub mod sampling;
pub mod stats;

pub use error::{Error, Result};

//! The Vulkan back end: context, buffers, pipelines, scene upload and the renderer.

pub mod buffer;
pub mod context;
pub mod device;
mod instance;
pub mod pipeline;
pub mod renderer;
pub mod requirements;
pub mod shaders;
pub mod variant;

pub use buffer::Buffer;
pub use context::{BorrowedDevice, Context, ContextDesc};
pub use device::{DeviceChoice, DeviceInfo, list_devices};
pub use pipeline::{BindGroup, Kernel};
pub use renderer::Renderer;
pub use requirements::{DeviceFeatures, Requirements};

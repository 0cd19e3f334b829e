//! The Vulkan back end: context, buffers, pipelines, scene upload and the renderer.

pub mod buffer;
pub mod context;
pub mod pipeline;
pub mod renderer;
pub mod shaders;
pub mod variant;

pub use buffer::Buffer;
pub use context::{Context, ContextDesc, DeviceChoice, DeviceInfo};
pub use pipeline::{BindGroup, Kernel};
pub use renderer::Renderer;

//! The Vulkan back end: context, buffers, pipelines, scene upload and the renderer.

pub mod buffer;
pub mod context;
pub mod device;
mod dispatch;
pub mod frame;
mod instance;
mod kernels;
pub mod pipeline;
pub mod renderer;
pub mod requirements;
pub mod shaders;
mod upload;
pub mod variant;

pub use buffer::Buffer;
pub use context::{BorrowedDevice, Context, ContextDesc, Pending, SubmitSync};
pub use device::{DeviceChoice, DeviceInfo, list_devices};
pub use frame::{BufferLayout, BufferView, Frame};
pub use pipeline::{BindGroup, Kernel};
pub use renderer::Renderer;
pub use requirements::{DeviceFeatures, Requirements};

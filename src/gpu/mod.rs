//! The Vulkan back end: the context (owned or borrowed), the renderer and its frames.
//!
//! The supported surface is [`Context`], [`Renderer`] (through [`crate::Backend`]), [`Frame`] and
//! what they take and return. `buffer`, `pipeline`, `shaders` and `variant` are public for the
//! test probes that run single kernels, and hidden from the documentation: they are not part of
//! the API and change without notice.

#[doc(hidden)]
pub mod buffer;
pub mod context;
pub mod device;
mod dispatch;
pub mod frame;
mod instance;
mod kernels;
#[doc(hidden)]
pub mod pipeline;
pub mod renderer;
pub mod requirements;
#[doc(hidden)]
pub mod shaders;
mod specialise;
mod upload;
#[doc(hidden)]
pub mod variant;

#[doc(hidden)]
pub use buffer::Buffer;
pub use context::{BorrowedDevice, Context, ContextDesc, Pending, SubmitSync};
pub use device::{
    DeviceChoice, DeviceInfo, lavapipe_environment, lavapipe_shader_cache_dir, lavapipe_vector_width, list_devices,
};
pub use frame::{BufferLayout, BufferView, Frame};
#[doc(hidden)]
pub use pipeline::{BindGroup, Kernel};
pub use renderer::Renderer;
pub use requirements::{DeviceFeatures, Requirements};

//! pathgrad: a differentiable path tracer on Vulkan compute shaders.
//!
//! A scene ([`scene::Scene`]: meshes, materials, area emitters, a pinhole camera and the
//! [`params::ParamTable`] of every differentiable value) is flattened once ([`scene::flat::FlatScene`]),
//! uploaded, and rendered by one GLSL megakernel ([`gpu::Renderer`]) on any Vulkan 1.2 device,
//! including lavapipe. [`cpu`] is the reference implementation of the same estimators with the same
//! counter-based random numbers ([`rng`]); tests hold the two together. [`optim`] recovers
//! parameters from a target image: Adam on loss gradients, optionally with loss-aware adaptive
//! pixel sampling ([`adaptive`]).
//!
//! The front door is re-exported here: [`Backend`] (what the GPU [`Renderer`] and the CPU
//! [`Reference`] both do), [`Context`] (a device of pathgrad's own, or an engine's through
//! [`Context::from_raw`]), [`Frame`] (work recorded into an engine's command buffers),
//! [`RenderOptions`], [`Image`], [`Loss`] and [`Gradients`]. [`contract`] is everything that
//! crosses the host/GPU boundary. Thread safety: the plain data types (scenes, images, options,
//! parameter tables, gradients) are `Send + Sync`; each handle type states its own.
//!
//! Cargo features: `cli` (on by default) builds the `pathgrad` program and the crates only it uses;
//! an engine depends on `pathgrad = { …, default-features = false }` for the library alone. The
//! build runs shaderc's `glslc` on the kernels (`PATHGRAD_GLSLC` names another) and needs
//! SPIRV-Tools' static libraries and a C++ compiler for the kernel specialiser: see docs/library.md,
//! "As a dependency".
//!
//! ```no_run
//! use pathgrad::backend::Backend;
//! use pathgrad::gpu::{Context, ContextDesc, Renderer};
//! use pathgrad::integrator::RenderOptions;
//!
//! let scene = pathgrad::scene::builtin::load("cornell-box")?;
//! let ctx = Context::new(&ContextDesc::default())?;
//! let mut renderer = Renderer::new(&ctx, &scene)?;
//! let options = RenderOptions { spp: 64, ..RenderOptions::for_scene(&scene) };
//! let image = renderer.render(&options)?;
//! image.save("cornell.exr")?;
//! // The CPU reference renders the same image up to float rounding.
//! let reference = pathgrad::cpu::render(&scene, &options)?;
//! assert_eq!(reference.width(), image.width());
//!
//! // Gradients: the loss against a target, differentiated by Path Replay Backpropagation.
//! use pathgrad::gpu::renderer::GradMode;
//! use pathgrad::loss::Loss;
//! let target = pathgrad::image::Image::read_exr("target.exr")?;
//! let (loss, gradients) = renderer.loss_and_gradient(&options, &target, Loss::RelMse, GradMode::Float)?;
//! println!("loss {loss}: d/d alpha = {:?}", gradients.get("sphere.bsdf.alpha.value"));
//! // Forward mode: how every pixel changes with the sphere's roughness.
//! let d_image = renderer.image_gradient(&options, "sphere.bsdf.alpha.value")?;
//! d_image.write_signed_png("d_alpha.png", None)?;
//! # Ok::<(), pathgrad::Error>(())
//! ```

pub mod adaptive;
pub mod alias;
pub mod attached;
pub mod backend;
pub mod bsdf;
pub mod bvh;
pub mod contract;
pub mod cpu;
pub mod error;
pub mod gpu;
pub mod image;
pub mod integrator;
pub mod loss;
pub mod optim;
pub mod output;
pub mod params;
pub mod phases;
pub mod prior;
pub mod rng;
pub mod sampling;
pub mod scene;
pub mod stats;
#[cfg(test)]
mod testing;
pub mod variance;

pub use error::{Error, Result};

// The front door: what a program that renders and differentiates needs, at the crate root.
pub use backend::Backend;
pub use cpu::Reference;
pub use gpu::renderer::GradMode;
pub use gpu::{
    BorrowedDevice, BufferLayout, BufferView, Context, ContextDesc, DeviceChoice, DeviceFeatures, Frame, Pending,
    Renderer, Requirements, SubmitSync,
};
pub use image::Image;
pub use integrator::{RenderOptions, Strategy};
pub use loss::Loss;
pub use params::{Gradients, ParamTable};
pub use scene::Scene;

/// The plain data types are `Send + Sync` (the crate docs' thread-safety note).
const _: fn() = || {
    fn send_sync<T: Send + Sync>() {}
    send_sync::<Scene>();
    send_sync::<Image>();
    send_sync::<RenderOptions>();
    send_sync::<ParamTable>();
    send_sync::<Gradients>();
};

/// The Rust examples of `docs/library.md`, compiled and run by `cargo test --doc`.
#[cfg(doctest)]
#[doc = include_str!("../docs/library.md")]
pub struct LibraryDocs;

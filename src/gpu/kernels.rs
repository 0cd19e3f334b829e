//! The kernel table and the variant cache: which render kernels exist, their bindings, and each
//! specialised variant built once per renderer on first use (its compile timed and reported).

use std::collections::HashMap;
use std::sync::Arc;
use std::time::Instant;

use ash::vk;

use crate::contract::*;
use crate::error::Result;
use crate::gpu::buffer::Buffer;
use crate::gpu::context::Context;
use crate::gpu::pipeline::Kernel;
use crate::gpu::variant;

/// A first compile that takes longer than this is reported to the compile observer.
pub const COMPILE_NOTICE_MS: u128 = 300;

/// The render kernels.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub(crate) enum KernelKind {
    Primal,
    Adjoint,
    AdjointFixed,
    AdjointAdaptive,
    AdjointAdaptiveFixed,
    ImageGradient,
}

impl KernelKind {
    /// The kernel table: each kernel's `shaders/*.comp` name and the bindings it adds to
    /// [`SCENE_BINDINGS`]. Adding a kernel is one entry here.
    pub(crate) fn layout(self) -> (&'static str, &'static [u32]) {
        match self {
            KernelKind::Primal => ("primal", &[BINDING_ACCUM]),
            KernelKind::Adjoint => ("adjoint", &[BINDING_ADJOINT, BINDING_GRADS]),
            KernelKind::AdjointFixed => ("adjoint_fixed", &[BINDING_ADJOINT, BINDING_GRADS_FIXED]),
            KernelKind::AdjointAdaptive => ("adjoint_adaptive", &[BINDING_ADJOINT, BINDING_GRADS, BINDING_ALIAS]),
            KernelKind::AdjointAdaptiveFixed => {
                ("adjoint_adaptive_fixed", &[BINDING_ADJOINT, BINDING_GRADS_FIXED, BINDING_ALIAS])
            }
            KernelKind::ImageGradient => ("image_gradient", &[BINDING_ADJOINT, BINDING_ACCUM]),
        }
    }

    /// The kernel's name.
    pub(crate) fn name(self) -> &'static str {
        self.layout().0
    }
}

/// The bindings every render kernel has: the per-render constants (a uniform buffer that also
/// holds the scene arrays' device addresses), the status word and the work counter.
pub(crate) const SCENE_BINDINGS: [u32; 3] = [BINDING_GLOBALS, BINDING_STATUS, BINDING_WORK];

/// A kernel variant: which kernel, and the value of its `FEATURES` specialisation constant.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub(crate) struct Variant {
    pub kind: KernelKind,
    pub features: u32,
}

/// What a compile observer is told (see [`Renderer::set_compile_observer`](super::Renderer::set_compile_observer)).
#[derive(Clone, Debug)]
pub enum CompileEvent {
    /// A kernel variant is about to be built (the driver compiles it now, or loads it from its
    /// shader cache).
    Started {
        /// The kernel's name.
        kernel: &'static str,
        /// Its features, as [`variant::describe`] writes them.
        features: String,
    },
    /// The variant is ready.
    Finished {
        /// The kernel's name.
        kernel: &'static str,
        /// Time spent building it, first dispatch included.
        seconds: f64,
    },
}

/// Receives [`CompileEvent`]s.
pub type CompileObserver = Box<dyn FnMut(&CompileEvent) + Send>;

/// The variants one renderer has built.
pub(crate) struct KernelCache {
    ctx: Arc<Context>,
    kernels: HashMap<Variant, Kernel>,
    pub observer: Option<CompileObserver>,
}

impl KernelCache {
    pub(crate) fn new(ctx: &Arc<Context>) -> KernelCache {
        KernelCache { ctx: ctx.clone(), kernels: HashMap::new(), observer: None }
    }

    /// The variant `v`, built first if this cache has not built it yet: warmed up with an empty
    /// dispatch so the driver's compile (or shader-cache load) happens here and is timed.
    pub(crate) fn get(&mut self, v: Variant) -> Result<&Kernel> {
        if !self.kernels.contains_key(&v) {
            self.build(v)?;
        }
        Ok(&self.kernels[&v])
    }

    /// The variant `v` if it is built.
    pub(crate) fn built(&self, v: Variant) -> Option<&Kernel> {
        self.kernels.get(&v)
    }

    fn build(&mut self, v: Variant) -> Result<()> {
        let (name, extra) = v.kind.layout();
        let features = variant::describe(v.features);
        let started = Instant::now();
        if let Some(observer) = self.observer.as_mut() {
            observer(&CompileEvent::Started { kernel: name, features: features.clone() });
        }
        let bindings: Vec<(u32, vk::DescriptorType)> = SCENE_BINDINGS
            .iter()
            .chain(extra)
            .map(|&b| {
                let ty = if b == BINDING_GLOBALS {
                    vk::DescriptorType::UNIFORM_BUFFER
                } else {
                    vk::DescriptorType::STORAGE_BUFFER
                };
                (b, ty)
            })
            .collect();
        let kernel = Kernel::specialised(
            &self.ctx,
            name,
            &bindings,
            std::mem::size_of::<KernelPush>() as u32,
            Some(v.features),
        )?;
        warm_up(&self.ctx, v, &kernel)?;
        self.kernels.insert(v, kernel);
        let seconds = started.elapsed().as_secs_f64();
        tracing::info!(kernel = name, features = %features, seconds, "kernel variant built");
        if let Some(observer) = self.observer.as_mut() {
            observer(&CompileEvent::Finished { kernel: name, seconds });
        }
        Ok(())
    }
}

/// One dispatch of `kernel` with no work: lavapipe compiles a pipeline at its first dispatch.
fn warm_up(ctx: &Arc<Context>, v: Variant, kernel: &Kernel) -> Result<()> {
    let (name, extra) = v.kind.layout();
    let scratch = Buffer::storage(ctx, "warm-up scratch", 16)?;
    let globals =
        Buffer::uniform_with(ctx, "globals", std::slice::from_ref(&<Globals as bytemuck::Zeroable>::zeroed()))?;
    let bindings: Vec<(u32, &Buffer)> = SCENE_BINDINGS
        .iter()
        .chain(extra)
        .map(|&b| (b, if b == BINDING_GLOBALS { &globals } else { &scratch }))
        .collect();
    let group = kernel.bind(&bindings)?;
    let push = KernelPush { sample_begin: 0, sample_count: 0, item_count: 0, lane_items: 0 };
    ctx.submit_and_wait(name, |cmd| {
        kernel.record(cmd, &group, bytemuck::bytes_of(&push), [1, 1, 1]);
    })
}

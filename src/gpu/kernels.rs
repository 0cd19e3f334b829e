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
    /// The float reverse-mode kernel with attached sampling (issue 34).
    AdjointAttached,
    /// The forward-mode kernel with attached sampling, run once per channel.
    ImageGradientAttached,
    /// The float reverse-mode kernel with adaptive pixel sampling and attached sampling.
    AdjointAdaptiveAttached,
    /// [`KernelKind::AdjointAttached`] in 64-bit fixed point (deterministic mode).
    AdjointAttachedFixed,
    /// [`KernelKind::AdjointAdaptiveAttached`] in 64-bit fixed point (deterministic mode).
    AdjointAdaptiveAttachedFixed,
}

impl KernelKind {
    /// The kernel table: each kernel's `shaders/*.comp` name and the bindings it adds to
    /// [`SCENE_BINDINGS`]. Adding a kernel is one entry here.
    pub(crate) fn layout(self) -> (&'static str, &'static [u32]) {
        match self {
            KernelKind::Primal => ("primal", &[BINDING_ACCUM]),
            // The accumulation image is written only in `primal_only` mode (a gradient step's pass 1).
            KernelKind::Adjoint => ("adjoint", &[BINDING_ADJOINT, BINDING_GRADS, BINDING_ACCUM]),
            KernelKind::AdjointFixed => ("adjoint_fixed", &[BINDING_ADJOINT, BINDING_GRADS_FIXED, BINDING_ACCUM]),
            KernelKind::AdjointAdaptive => ("adjoint_adaptive", &[BINDING_ADJOINT, BINDING_GRADS, BINDING_ALIAS]),
            KernelKind::AdjointAdaptiveFixed => {
                ("adjoint_adaptive_fixed", &[BINDING_ADJOINT, BINDING_GRADS_FIXED, BINDING_ALIAS])
            }
            KernelKind::ImageGradient => ("image_gradient", &[BINDING_ADJOINT, BINDING_ACCUM]),
            KernelKind::AdjointAttached => ("adjoint_attached", &[BINDING_ADJOINT, BINDING_GRADS, BINDING_ACCUM]),
            KernelKind::ImageGradientAttached => ("image_gradient_attached", &[BINDING_ADJOINT, BINDING_ACCUM]),
            KernelKind::AdjointAdaptiveAttached => {
                ("adjoint_adaptive_attached", &[BINDING_ADJOINT, BINDING_GRADS, BINDING_ALIAS])
            }
            KernelKind::AdjointAttachedFixed => {
                ("adjoint_attached_fixed", &[BINDING_ADJOINT, BINDING_GRADS_FIXED, BINDING_ACCUM])
            }
            KernelKind::AdjointAdaptiveAttachedFixed => {
                ("adjoint_adaptive_attached_fixed", &[BINDING_ADJOINT, BINDING_GRADS_FIXED, BINDING_ALIAS])
            }
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

/// A kernel variant: which kernel, and the values of its feature specialisation constants
/// (`FEATURES` in the low 32 bits, `FEATURES2` in the high: [`variant`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub(crate) struct Variant {
    pub kind: KernelKind,
    pub features: u64,
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

    /// Builds every variant of `variants` that this cache has not built yet, all at once: the
    /// pipelines are created on threads of their own (a driver compiles each pipeline on one
    /// thread, so a pass-1 kernel and a gradient kernel compile side by side instead of one after
    /// the other), then warmed up in order. Events are reported as for single builds, each
    /// variant's `Finished` when it is ready.
    pub(crate) fn prepare(&mut self, variants: &[Variant]) -> Result<()> {
        let mut missing: Vec<Variant> = Vec::with_capacity(variants.len());
        for &v in variants {
            if !self.kernels.contains_key(&v) && !missing.contains(&v) {
                missing.push(v);
            }
        }
        if missing.len() < 2 {
            return missing.first().map_or(Ok(()), |&v| self.build(v));
        }
        let started = Instant::now();
        for &v in &missing {
            self.report_start(v);
        }
        let ctx = &self.ctx;
        let created: Vec<Result<Kernel>> = std::thread::scope(|scope| {
            let handles: Vec<_> = missing.iter().map(|&v| scope.spawn(move || create(ctx, v))).collect();
            handles.into_iter().map(|h| h.join().unwrap_or_else(|panic| std::panic::resume_unwind(panic))).collect()
        });
        let create_seconds = started.elapsed().as_secs_f64();
        for (v, kernel) in missing.into_iter().zip(created) {
            self.finish(v, kernel?, started, create_seconds)?;
        }
        Ok(())
    }

    fn build(&mut self, v: Variant) -> Result<()> {
        let started = Instant::now();
        self.report_start(v);
        let kernel = create(&self.ctx, v)?;
        let create_seconds = started.elapsed().as_secs_f64();
        self.finish(v, kernel, started, create_seconds)
    }

    fn report_start(&mut self, v: Variant) {
        if let Some(observer) = self.observer.as_mut() {
            observer(&CompileEvent::Started { kernel: v.kind.name(), features: variant::describe(v.features) });
        }
    }

    /// Warms up `kernel` (variant `v`, whose build began at `started` and whose pipeline took
    /// `create_seconds` to create), keeps it and reports it built.
    fn finish(&mut self, v: Variant, kernel: Kernel, started: Instant, create_seconds: f64) -> Result<()> {
        warm_up(&self.ctx, v, &kernel)?;
        self.kernels.insert(v, kernel);
        let seconds = started.elapsed().as_secs_f64();
        let name = v.kind.name();
        tracing::info!(
            kernel = name,
            features = %variant::describe(v.features),
            seconds,
            create_seconds,
            "kernel variant built"
        );
        if let Some(observer) = self.observer.as_mut() {
            observer(&CompileEvent::Finished { kernel: name, seconds });
        }
        Ok(())
    }
}

/// Creates the pipeline of variant `v` (where Mesa 25's lavapipe compiles it, or loads it from
/// its shader cache).
fn create(ctx: &Arc<Context>, v: Variant) -> Result<Kernel> {
    let (name, extra) = v.kind.layout();
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
    Kernel::specialised(ctx, name, &bindings, std::mem::size_of::<KernelPush>() as u32, Some(v.features))
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

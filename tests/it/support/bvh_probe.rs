//! Runs `shaders/bvh_probe.comp`: the GLSL traversal (`shaders/lib/bvh.glsl`) on a list of rays.

use ash::vk;
use bytemuck::{Pod, Zeroable};
use pathgrad::bvh::Bvh;
use pathgrad::contract::{BINDING_GLOBALS, BINDING_PROBE_IN, BINDING_PROBE_OUT, BINDING_STATUS, BvhProbePush, Globals};
use pathgrad::gpu::pipeline::groups_for;
use pathgrad::gpu::{Buffer, Kernel};

use super::TestGpu;

/// `queries` bit: run the closest-hit query.
pub const CLOSEST: u32 = 1;
/// `queries` bit: run the occlusion query.
pub const OCCLUDED: u32 = 2;

/// One probe ray; both queries use `tmin < t < tmax`. Layout of the probe's input (8 floats).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct ProbeRay {
    /// Origin.
    pub origin: [f32; 3],
    /// Lower end of the ray interval (exclusive).
    pub tmin: f32,
    /// Direction, not necessarily unit.
    pub dir: [f32; 3],
    /// Upper end of the ray interval (exclusive); may be infinite.
    pub tmax: f32,
}

/// One probe answer. Layout of the probe's output (8 words); flags are 0 or 1.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct ProbeHit {
    /// Closest-hit distance (0 on a miss).
    pub t: f32,
    /// Leaf slot of the closest hit (0 on a miss).
    pub slot: u32,
    /// Barycentric coordinate of vertex 1.
    pub b1: f32,
    /// Barycentric coordinate of vertex 2.
    pub b2: f32,
    /// 1 if the closest-hit query found a hit.
    pub hit: u32,
    /// 1 if the occlusion query found a blocker.
    pub occluded: u32,
    _burn_state: u32,
    _pad: u32,
}

/// The probe kernel with a BVH uploaded.
pub struct BvhProbe<'a> {
    gpu: &'a TestGpu,
    kernel: Kernel,
    /// The per-render constants: the node count and the arrays' device addresses.
    globals: Buffer,
    _nodes: Buffer,
    _tris: Buffer,
}

impl<'a> BvhProbe<'a> {
    /// Uploads `bvh` and builds the kernel.
    pub fn new(gpu: &'a TestGpu, bvh: &Bvh) -> BvhProbe<'a> {
        let storage = vk::DescriptorType::STORAGE_BUFFER;
        let bindings = [
            (BINDING_GLOBALS, vk::DescriptorType::UNIFORM_BUFFER),
            (BINDING_STATUS, storage),
            (BINDING_PROBE_IN, storage),
            (BINDING_PROBE_OUT, storage),
        ];
        let nodes = Buffer::storage_with(&gpu.ctx, "probe nodes", &bvh.nodes).unwrap();
        let tris = Buffer::storage_with(&gpu.ctx, "probe tris", &bvh.tris).unwrap();
        let globals = Globals {
            node_count: bvh.nodes.len() as u32,
            addr_nodes: nodes.device_address(),
            addr_tris: tris.device_address(),
            ..Globals::default()
        };
        BvhProbe {
            gpu,
            kernel: Kernel::specialised(&gpu.ctx, "bvh_probe", &bindings, 12, None).unwrap(),
            globals: Buffer::uniform_with(&gpu.ctx, "probe globals", &[globals]).unwrap(),
            _nodes: nodes,
            _tris: tris,
        }
    }

    /// Traces `rays` with the queries selected by `queries` (`CLOSEST | OCCLUDED`), after spending
    /// `burn` loop iterations per invocation: one answer per ray, and the status word raised.
    pub fn trace(&self, rays: &[ProbeRay], queries: u32, burn: u32) -> (Vec<ProbeHit>, u32) {
        let ctx = &self.gpu.ctx;
        let status = Buffer::storage_with(ctx, "probe status", &[0u32]).unwrap();
        let input = Buffer::storage_with(ctx, "probe rays", rays).unwrap();
        let output = Buffer::storage(ctx, "probe hits", (rays.len() * size_of::<ProbeHit>()) as u64).unwrap();
        let group = self
            .kernel
            .bind(&[
                (BINDING_GLOBALS, &self.globals),
                (BINDING_STATUS, &status),
                (BINDING_PROBE_IN, &input),
                (BINDING_PROBE_OUT, &output),
            ])
            .unwrap();
        let n = rays.len() as u32;
        let push = BvhProbePush { ray_count: n, queries, burn };
        ctx.submit_and_wait("bvh probe", |cmd| {
            self.kernel.record(cmd, &group, bytemuck::bytes_of(&push), groups_for(n))
        })
        .unwrap();
        (output.download(rays.len()).unwrap(), status.download::<u32>(1).unwrap()[0])
    }

    /// Traces one `ray` once per value of `burns`, reusing every buffer: (answer, status) each.
    pub fn trace_burning(
        &self,
        ray: ProbeRay,
        queries: u32,
        burns: impl IntoIterator<Item = u32>,
    ) -> Vec<(ProbeHit, u32)> {
        let ctx = &self.gpu.ctx;
        let status = Buffer::storage(ctx, "probe status", 4).unwrap();
        let input = Buffer::storage_with(ctx, "probe ray", &[ray]).unwrap();
        let output = Buffer::storage(ctx, "probe hit", size_of::<ProbeHit>() as u64).unwrap();
        let group = self
            .kernel
            .bind(&[
                (BINDING_GLOBALS, &self.globals),
                (BINDING_STATUS, &status),
                (BINDING_PROBE_IN, &input),
                (BINDING_PROBE_OUT, &output),
            ])
            .unwrap();
        burns
            .into_iter()
            .map(|burn| {
                status.clear().unwrap();
                let push = BvhProbePush { ray_count: 1, queries, burn };
                ctx.submit_and_wait("bvh probe", |cmd| {
                    self.kernel.record(cmd, &group, bytemuck::bytes_of(&push), [1, 1, 1])
                })
                .unwrap();
                (output.download::<ProbeHit>(1).unwrap()[0], status.download::<u32>(1).unwrap()[0])
            })
            .collect()
    }
}

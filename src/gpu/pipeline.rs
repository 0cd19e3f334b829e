//! `Kernel`: a compute pipeline built from an embedded SPIR-V module, with its descriptor layout;
//! `BindGroup`: one descriptor set naming the buffer at each binding.

use std::io::Cursor;
use std::sync::Arc;

use ash::vk;

use crate::error::{Error, Result, VkResultExt};
use crate::gpu::buffer::Buffer;
use crate::gpu::context::Context;
use crate::gpu::{shaders, specialise};

/// A compute pipeline over storage (and uniform) buffers, optionally specialised.
pub struct Kernel {
    ctx: Arc<Context>,
    name: &'static str,
    set_layout: vk::DescriptorSetLayout,
    layout: vk::PipelineLayout,
    pipeline: vk::Pipeline,
    bindings: Vec<(u32, vk::DescriptorType)>,
    push_size: u32,
}

impl std::fmt::Debug for Kernel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Kernel").field("name", &self.name).finish()
    }
}

impl Kernel {
    /// Builds the kernel compiled from `shaders/{name}.comp`, whose storage buffers sit at
    /// `bindings` of set 0 and whose push constants take `push_size` bytes.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for an unknown kernel; Vulkan failures.
    pub fn new(ctx: &Arc<Context>, name: &'static str, bindings: &[u32], push_size: u32) -> Result<Kernel> {
        let typed: Vec<_> = bindings.iter().map(|&b| (b, vk::DescriptorType::STORAGE_BUFFER)).collect();
        Kernel::specialised(ctx, name, &typed, push_size, None)
    }

    /// Builds the kernel compiled from `shaders/{name}.comp` with descriptors of the given types
    /// at `bindings` of set 0, `push_size` bytes of push constants and, if given, `features` as
    /// the values of its `FEATURES` (low 32 bits) and `FEATURES2` (high 32 bits) specialisation
    /// constants (`shaders/lib/features.glsl`), applied on
    /// the host where it can be (`crate::gpu::specialise`: the module shrinks to what the value
    /// keeps before the driver sees it) and by the driver otherwise.
    ///
    /// # Errors
    /// As [`Kernel::new`].
    pub fn specialised(
        ctx: &Arc<Context>,
        name: &'static str,
        bindings: &[(u32, vk::DescriptorType)],
        push_size: u32,
        features: Option<u64>,
    ) -> Result<Kernel> {
        let bytes = shaders::spirv(name).ok_or_else(|| Error::InvalidArgument {
            parameter: "kernel".into(),
            message: format!("no kernel named {name}"),
        })?;
        let mut words = ash::util::read_spv(&mut Cursor::new(bytes)).map_err(|e| Error::InvalidArgument {
            parameter: "kernel".into(),
            message: format!("{name}: bad SPIR-V: {e}"),
        })?;
        // A specialised module carries its value frozen in: the driver is given no constant then.
        let host = features.and_then(|f| specialise::specialised_module(name, &words, f));
        let host_specialised = host.is_some();
        if let Some(specialised) = host {
            words = specialised;
        }
        let device = ctx.device();
        let layout_bindings: Vec<_> = bindings
            .iter()
            .map(|&(b, ty)| {
                vk::DescriptorSetLayoutBinding::default()
                    .binding(b)
                    .descriptor_type(ty)
                    .descriptor_count(1)
                    .stage_flags(vk::ShaderStageFlags::COMPUTE)
            })
            .collect();
        // Objects are created in order and destroyed by `Kernel::drop`; a failure part-way destroys
        // what exists through this partially filled value.
        let mut kernel = Kernel {
            ctx: ctx.clone(),
            name,
            set_layout: vk::DescriptorSetLayout::null(),
            layout: vk::PipelineLayout::null(),
            pipeline: vk::Pipeline::null(),
            bindings: bindings.to_vec(),
            push_size,
        };
        ctx.object_created();
        // SAFETY: valid device and create-infos; each handle is owned by `kernel` as soon as it exists.
        unsafe {
            kernel.set_layout = device
                .create_descriptor_set_layout(
                    &vk::DescriptorSetLayoutCreateInfo::default().bindings(&layout_bindings),
                    None,
                )
                .vk("vkCreateDescriptorSetLayout")?;
            let ranges = [vk::PushConstantRange::default().stage_flags(vk::ShaderStageFlags::COMPUTE).size(push_size)];
            let set_layouts = [kernel.set_layout];
            let mut layout_info = vk::PipelineLayoutCreateInfo::default().set_layouts(&set_layouts);
            if push_size > 0 {
                layout_info = layout_info.push_constant_ranges(&ranges);
            }
            kernel.layout = device.create_pipeline_layout(&layout_info, None).vk("vkCreatePipelineLayout")?;
            let module = device
                .create_shader_module(&vk::ShaderModuleCreateInfo::default().code(&words), None)
                .vk("vkCreateShaderModule")?;
            // Two words: `FEATURES` (the low 32 bits) then `FEATURES2`.
            let f = features.unwrap_or(0);
            let words2 = [f as u32, (f >> 32) as u32];
            let feature_bytes: &[u8] = bytemuck::cast_slice(&words2);
            let entries = [
                vk::SpecializationMapEntry::default().constant_id(crate::contract::SPEC_FEATURES).offset(0).size(4),
                vk::SpecializationMapEntry::default().constant_id(crate::contract::SPEC_FEATURES2).offset(4).size(4),
            ];
            let spec = vk::SpecializationInfo::default().map_entries(&entries).data(feature_bytes);
            let mut stage = vk::PipelineShaderStageCreateInfo::default()
                .stage(vk::ShaderStageFlags::COMPUTE)
                .module(module)
                .name(c"main");
            if features.is_some() && !host_specialised {
                stage = stage.specialization_info(&spec);
            }
            let info = [vk::ComputePipelineCreateInfo::default().stage(stage).layout(kernel.layout)];
            let created = device.create_compute_pipelines(ctx.pipeline_cache(), &info, None);
            device.destroy_shader_module(module, None);
            kernel.pipeline =
                created.map_err(|(_, result)| Error::Vulkan { call: "vkCreateComputePipelines", result })?[0];
        }
        ctx.set_name(kernel.pipeline, name);
        Ok(kernel)
    }

    /// The kernel's name.
    pub fn name(&self) -> &'static str {
        self.name
    }

    /// Makes a descriptor set with `buffers[i].1` at binding `buffers[i].0`; every binding of the
    /// kernel must be given exactly once.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for a missing or unknown binding; Vulkan failures.
    pub fn bind(&self, buffers: &[(u32, &Buffer)]) -> Result<BindGroup> {
        for &(b, _) in &self.bindings {
            if buffers.iter().filter(|(x, _)| *x == b).count() != 1 {
                return Err(Error::InvalidArgument {
                    parameter: format!("{} binding {b}", self.name),
                    message: "must be given exactly once".into(),
                });
            }
        }
        if let Some((x, _)) = buffers.iter().find(|(x, _)| !self.bindings.iter().any(|(b, _)| b == x)) {
            return Err(Error::InvalidArgument {
                parameter: format!("{} binding {x}", self.name),
                message: "the kernel has no such binding".into(),
            });
        }
        let device = self.ctx.device();
        let count = |ty| self.bindings.iter().filter(|(_, t)| *t == ty).count().max(1) as u32;
        let sizes = [
            vk::DescriptorPoolSize::default()
                .ty(vk::DescriptorType::STORAGE_BUFFER)
                .descriptor_count(count(vk::DescriptorType::STORAGE_BUFFER)),
            vk::DescriptorPoolSize::default()
                .ty(vk::DescriptorType::UNIFORM_BUFFER)
                .descriptor_count(count(vk::DescriptorType::UNIFORM_BUFFER)),
        ];
        // SAFETY: valid device and create-info.
        let pool = unsafe {
            device.create_descriptor_pool(&vk::DescriptorPoolCreateInfo::default().max_sets(1).pool_sizes(&sizes), None)
        }
        .vk("vkCreateDescriptorPool")?;
        self.ctx.object_created();
        let mut group = BindGroup { ctx: self.ctx.clone(), pool, set: vk::DescriptorSet::null() };
        let layouts = [self.set_layout];
        // SAFETY: the pool has room for one set of this layout.
        let set = unsafe {
            device.allocate_descriptor_sets(
                &vk::DescriptorSetAllocateInfo::default().descriptor_pool(pool).set_layouts(&layouts),
            )
        }
        .vk("vkAllocateDescriptorSets")?[0];
        group.set = set;
        let infos: Vec<[vk::DescriptorBufferInfo; 1]> = buffers
            .iter()
            .map(|(_, b)| [vk::DescriptorBufferInfo::default().buffer(b.raw()).offset(0).range(vk::WHOLE_SIZE)])
            .collect();
        let writes: Vec<_> = buffers
            .iter()
            .zip(&infos)
            .map(|((binding, _), info)| {
                let ty = self
                    .bindings
                    .iter()
                    .find(|(b, _)| b == binding)
                    .map_or(vk::DescriptorType::STORAGE_BUFFER, |b| b.1);
                vk::WriteDescriptorSet::default()
                    .dst_set(set)
                    .dst_binding(*binding)
                    .descriptor_type(ty)
                    .buffer_info(info)
            })
            .collect();
        // SAFETY: every buffer is alive; the set is not in use yet.
        unsafe { device.update_descriptor_sets(&writes, &[]) };
        Ok(group)
    }

    /// Records a dispatch of `groups` workgroups with `push` as push constants.
    pub fn record(&self, cmd: vk::CommandBuffer, group: &BindGroup, push: &[u8], groups: [u32; 3]) {
        debug_assert_eq!(push.len() as u32, self.push_size, "{}: push-constant size", self.name);
        let device = self.ctx.device();
        // SAFETY: `cmd` is recording; pipeline, layout and set are alive until the submission is waited on.
        unsafe {
            device.cmd_bind_pipeline(cmd, vk::PipelineBindPoint::COMPUTE, self.pipeline);
            device.cmd_bind_descriptor_sets(cmd, vk::PipelineBindPoint::COMPUTE, self.layout, 0, &[group.set], &[]);
            if !push.is_empty() {
                device.cmd_push_constants(cmd, self.layout, vk::ShaderStageFlags::COMPUTE, 0, push);
            }
            device.cmd_dispatch(cmd, groups[0], groups[1], groups[2]);
        }
    }
}

/// Records a global memory barrier: `src_access` in `src_stage` before `dst_access` in `dst_stage`.
pub fn memory_barrier(
    ctx: &Context,
    cmd: vk::CommandBuffer,
    (src_stage, src_access): (vk::PipelineStageFlags, vk::AccessFlags),
    (dst_stage, dst_access): (vk::PipelineStageFlags, vk::AccessFlags),
) {
    let barrier = [vk::MemoryBarrier::default().src_access_mask(src_access).dst_access_mask(dst_access)];
    // SAFETY: `cmd` is recording.
    unsafe {
        ctx.device().cmd_pipeline_barrier(cmd, src_stage, dst_stage, vk::DependencyFlags::empty(), &barrier, &[], &[]);
    }
}

/// Records a barrier that makes earlier compute writes visible to later compute reads and writes.
pub fn compute_barrier(ctx: &Context, cmd: vk::CommandBuffer) {
    let shader_rw = vk::AccessFlags::SHADER_READ | vk::AccessFlags::SHADER_WRITE;
    memory_barrier(
        ctx,
        cmd,
        (vk::PipelineStageFlags::COMPUTE_SHADER, vk::AccessFlags::SHADER_WRITE),
        (vk::PipelineStageFlags::COMPUTE_SHADER, shader_rw),
    );
}

/// Workgroup counts covering `invocations` 1-D invocations of `WORKGROUP_SIZE`, folded into a 2-D
/// grid when they exceed the 65 535 groups one dimension allows. Kernels compute their linear index
/// as `gl_GlobalInvocationID.y * gl_NumWorkGroups.x * WORKGROUP_SIZE + gl_GlobalInvocationID.x`.
pub fn groups_for(invocations: u32) -> [u32; 3] {
    let groups = invocations.div_ceil(crate::contract::WORKGROUP_SIZE).max(1);
    let x = groups.min(65_535);
    [x, groups.div_ceil(x), 1]
}

impl Drop for Kernel {
    fn drop(&mut self) {
        let device = self.ctx.device();
        // SAFETY: every submission using the kernel was waited on; null handles are ignored.
        unsafe {
            device.destroy_pipeline(self.pipeline, None);
            device.destroy_pipeline_layout(self.layout, None);
            device.destroy_descriptor_set_layout(self.set_layout, None);
        }
        self.ctx.object_destroyed();
    }
}

/// A descriptor set (and the pool it lives in), freed on drop.
pub struct BindGroup {
    ctx: Arc<Context>,
    pool: vk::DescriptorPool,
    set: vk::DescriptorSet,
}

impl Drop for BindGroup {
    fn drop(&mut self) {
        // SAFETY: every submission using the set was waited on.
        unsafe { self.ctx.device().destroy_descriptor_pool(self.pool, None) };
        self.ctx.object_destroyed();
    }
}

//! `Buffer`: a storage buffer with its named allocation, freed on drop; uploads and read-backs go
//! through staging buffers, so device-local memory is never mapped (PLATFORM.md §6.6).

use std::sync::Arc;

use ash::vk;
use gpu_allocator::MemoryLocation;
use gpu_allocator::vulkan::{Allocation, AllocationCreateDesc, AllocationScheme};

use crate::error::{Error, Result, VkResultExt};
use crate::gpu::context::Context;
use crate::gpu::pipeline::memory_barrier;

/// The largest staging buffer [`Buffer::upload`] creates: a bigger upload goes through it chunk
/// by chunk, so an upload never doubles its data in host memory (issue 38: a 2 M-triangle scene's
/// 137 MiB shading array took as much again in staging). One wait per 16 MiB costs nothing
/// measurable next to the copy.
pub const UPLOAD_CHUNK_BYTES: usize = 16 << 20;

/// A transfer's writes, as the source side of a barrier.
const TRANSFER_WRITE: (vk::PipelineStageFlags, vk::AccessFlags) =
    (vk::PipelineStageFlags::TRANSFER, vk::AccessFlags::TRANSFER_WRITE);
/// Compute reads and writes, as the destination side of a barrier.
const SHADER_READ_WRITE: (vk::PipelineStageFlags, vk::AccessFlags) = (
    vk::PipelineStageFlags::COMPUTE_SHADER,
    vk::AccessFlags::from_raw(vk::AccessFlags::SHADER_READ.as_raw() | vk::AccessFlags::SHADER_WRITE.as_raw()),
);

/// Vulkan forbids empty buffers; empty arrays (a scene without emitters) get this many bytes.
const MIN_BUFFER_BYTES: u64 = 16;

/// A buffer and its memory.
pub struct Buffer {
    ctx: Arc<Context>,
    raw: vk::Buffer,
    allocation: Option<Allocation>,
    size: u64,
    name: String,
}

impl std::fmt::Debug for Buffer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Buffer").field("name", &self.name).field("size", &self.size).finish()
    }
}

impl Buffer {
    /// Creates a buffer of `size` bytes (at least 16) in `location`, named `name` for allocation
    /// tracking and validation messages.
    ///
    /// # Errors
    /// Vulkan or allocation failures, naming the buffer.
    pub fn new(
        ctx: &Arc<Context>,
        name: &str,
        size: u64,
        usage: vk::BufferUsageFlags,
        location: MemoryLocation,
    ) -> Result<Buffer> {
        let size = size.max(MIN_BUFFER_BYTES);
        let info = vk::BufferCreateInfo::default().size(size).usage(usage).sharing_mode(vk::SharingMode::EXCLUSIVE);
        let device = ctx.device();
        // SAFETY: valid device and create-info.
        let raw = unsafe { device.create_buffer(&info, None) }.vk("vkCreateBuffer")?;
        // SAFETY: `raw` was just created.
        let requirements = unsafe { device.get_buffer_memory_requirements(raw) };
        let allocation = ctx.with_allocator(|a| {
            a.allocate(&AllocationCreateDesc {
                name,
                requirements,
                location,
                linear: true,
                allocation_scheme: AllocationScheme::GpuAllocatorManaged,
            })
        });
        let allocation = match allocation {
            Ok(a) => a,
            Err(e) => {
                // SAFETY: the buffer has no memory and is not in use.
                unsafe { device.destroy_buffer(raw, None) };
                return Err(Error::Allocation { name: name.to_string(), size, message: e.to_string() });
            }
        };
        // SAFETY: the allocation satisfies the buffer's requirements.
        if let Err(result) = unsafe { device.bind_buffer_memory(raw, allocation.memory(), allocation.offset()) } {
            ctx.with_allocator(|a| a.free(allocation)).ok();
            // SAFETY: not in use.
            unsafe { device.destroy_buffer(raw, None) };
            return Err(Error::Vulkan { call: "vkBindBufferMemory", result });
        }
        ctx.set_name(raw, name);
        ctx.object_created();
        ctx.buffer_allocated(size);
        Ok(Buffer { ctx: ctx.clone(), raw, allocation: Some(allocation), size, name: name.to_string() })
    }

    /// A device-local storage buffer that can be copied to and from.
    ///
    /// # Errors
    /// As [`Buffer::new`].
    pub fn storage(ctx: &Arc<Context>, name: &str, size: u64) -> Result<Buffer> {
        let usage = vk::BufferUsageFlags::STORAGE_BUFFER
            | vk::BufferUsageFlags::SHADER_DEVICE_ADDRESS
            | vk::BufferUsageFlags::TRANSFER_SRC
            | vk::BufferUsageFlags::TRANSFER_DST;
        Buffer::new(ctx, name, size, usage, MemoryLocation::GpuOnly)
    }

    /// A device-local storage buffer holding `data`.
    ///
    /// # Errors
    /// As [`Buffer::new`] and [`Buffer::upload`].
    pub fn storage_with<T: bytemuck::Pod>(ctx: &Arc<Context>, name: &str, data: &[T]) -> Result<Buffer> {
        let buffer = Buffer::storage(ctx, name, std::mem::size_of_val(data) as u64)?;
        buffer.upload(data)?;
        Ok(buffer)
    }

    /// A device-local uniform buffer holding `data` (per-render constants).
    ///
    /// # Errors
    /// As [`Buffer::new`] and [`Buffer::upload`].
    pub fn uniform_with<T: bytemuck::Pod>(ctx: &Arc<Context>, name: &str, data: &[T]) -> Result<Buffer> {
        let usage = vk::BufferUsageFlags::UNIFORM_BUFFER | vk::BufferUsageFlags::TRANSFER_DST;
        let buffer = Buffer::new(ctx, name, std::mem::size_of_val(data) as u64, usage, MemoryLocation::GpuOnly)?;
        buffer.upload(data)?;
        Ok(buffer)
    }

    /// The buffer's device address (`GL_EXT_buffer_reference`), as the two 32-bit halves a shader
    /// turns back into a reference (low word first).
    pub fn device_address(&self) -> glam::UVec2 {
        let info = vk::BufferDeviceAddressInfo::default().buffer(self.raw);
        // SAFETY: storage buffers are created with SHADER_DEVICE_ADDRESS usage on a device with
        // the bufferDeviceAddress feature enabled.
        let address = unsafe { self.ctx.device().get_buffer_device_address(&info) };
        glam::UVec2::new(address as u32, (address >> 32) as u32)
    }

    /// The Vulkan handle.
    pub fn raw(&self) -> vk::Buffer {
        self.raw
    }

    /// Size in bytes.
    pub fn size(&self) -> u64 {
        self.size
    }

    /// The allocation's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    fn mapped_mut(&mut self) -> Option<&mut [u8]> {
        self.allocation.as_mut().and_then(Allocation::mapped_slice_mut)
    }

    /// Copies `data` to the start of the buffer through a staging buffer of at most
    /// [`UPLOAD_CHUNK_BYTES`], reused chunk after chunk, and waits.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] if `data` is larger than the buffer; Vulkan failures.
    pub fn upload<T: bytemuck::Pod>(&self, data: &[T]) -> Result<()> {
        let mut rest = data;
        self.upload_with(data.len(), |chunk: &mut [T]| {
            let (part, after) = rest.split_at(chunk.len());
            chunk.copy_from_slice(part);
            rest = after;
        })
    }

    /// Writes `count` elements to the start of the buffer as `fill` makes them: `fill` is called
    /// with successive slices of a staging buffer of at most [`UPLOAD_CHUNK_BYTES`], reused chunk
    /// after chunk, and must fill each slice it is given (the next elements in order); waits.
    /// Data generated this way never exists whole in host memory (issue 38: the shading data).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] if `count` elements are larger than the buffer; Vulkan failures.
    pub fn upload_with<T: bytemuck::Pod>(&self, count: usize, mut fill: impl FnMut(&mut [T])) -> Result<()> {
        let size = size_of::<T>();
        let total = count * size;
        if total == 0 {
            return Ok(());
        }
        if total as u64 > self.size {
            return Err(Error::InvalidArgument {
                parameter: self.name.clone(),
                message: format!("{total} bytes do not fit in {}", self.size),
            });
        }
        // Whole elements per chunk, so that each chunk can be handed to `fill` as a `[T]`.
        let per_chunk = (UPLOAD_CHUNK_BYTES / size).max(1).min(count);
        let mut staging = Buffer::new(
            &self.ctx,
            &format!("{} (upload)", self.name),
            (per_chunk * size) as u64,
            vk::BufferUsageFlags::TRANSFER_SRC,
            MemoryLocation::CpuToGpu,
        )?;
        // Used only where the mapped memory is not aligned for `T` (Vulkan promises no alignment
        // for it beyond the allocation's): a chunk is filled here and copied.
        let mut aligned: Vec<T> = Vec::new();
        let device = self.ctx.device();
        let mut first = 0;
        while first < count {
            let len = per_chunk.min(count - first);
            let mapped = &mut staging.mapped_mut().expect("CpuToGpu memory is host visible")[..len * size];
            match bytemuck::try_cast_slice_mut::<u8, T>(mapped) {
                Ok(chunk) => fill(chunk),
                Err(_) => {
                    aligned.resize(len, T::zeroed());
                    fill(&mut aligned);
                    mapped.copy_from_slice(bytemuck::cast_slice(&aligned));
                }
            }
            self.ctx.submit_and_wait(&format!("upload {}", self.name), |cmd| {
                let region = [vk::BufferCopy::default().dst_offset((first * size) as u64).size((len * size) as u64)];
                // SAFETY: both buffers are alive until the submission is waited on, and the region
                // lies inside both (`len` elements fit the staging buffer and end within
                // `self.size`, checked above).
                unsafe { device.cmd_copy_buffer(cmd, staging.raw, self.raw, &region) };
                memory_barrier(&self.ctx, cmd, TRANSFER_WRITE, SHADER_READ_WRITE);
            })?;
            first += len;
        }
        Ok(())
    }

    /// Fills the whole buffer with zeros and waits.
    ///
    /// # Errors
    /// Vulkan failures.
    pub fn clear(&self) -> Result<()> {
        let device = self.ctx.device();
        self.ctx.submit_and_wait(&format!("clear {}", self.name), |cmd| {
            // SAFETY: the buffer is alive until the submission is waited on.
            unsafe { device.cmd_fill_buffer(cmd, self.raw, 0, vk::WHOLE_SIZE, 0) };
            memory_barrier(&self.ctx, cmd, TRANSFER_WRITE, SHADER_READ_WRITE);
        })
    }

    /// Reads the first `count` elements back through a staging buffer.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] if the buffer holds fewer; Vulkan failures.
    pub fn download<T: bytemuck::Pod>(&self, count: usize) -> Result<Vec<T>> {
        let len = (count * size_of::<T>()) as u64;
        if len > self.size {
            return Err(Error::InvalidArgument {
                parameter: self.name.clone(),
                message: format!("{len} bytes requested from {}", self.size),
            });
        }
        if len == 0 {
            return Ok(Vec::new());
        }
        let staging = Buffer::new(
            &self.ctx,
            &format!("{} (read-back)", self.name),
            len,
            vk::BufferUsageFlags::TRANSFER_DST,
            MemoryLocation::GpuToCpu,
        )?;
        let device = self.ctx.device();
        self.ctx.submit_and_wait(&format!("read back {}", self.name), |cmd| {
            let region = [vk::BufferCopy::default().size(len)];
            memory_barrier(
                &self.ctx,
                cmd,
                (vk::PipelineStageFlags::COMPUTE_SHADER, vk::AccessFlags::SHADER_WRITE),
                (vk::PipelineStageFlags::TRANSFER, vk::AccessFlags::TRANSFER_READ),
            );
            // SAFETY: both buffers are alive until the submission is waited on.
            unsafe { device.cmd_copy_buffer(cmd, self.raw, staging.raw, &region) };
            memory_barrier(&self.ctx, cmd, TRANSFER_WRITE, (vk::PipelineStageFlags::HOST, vk::AccessFlags::HOST_READ));
        })?;
        let bytes =
            staging.allocation.as_ref().and_then(Allocation::mapped_slice).expect("GpuToCpu memory is host visible");
        let mut out = vec![T::zeroed(); count];
        bytemuck::cast_slice_mut(&mut out).copy_from_slice(&bytes[..len as usize]);
        Ok(out)
    }
}

impl Drop for Buffer {
    fn drop(&mut self) {
        if let Some(allocation) = self.allocation.take()
            && let Err(e) = self.ctx.with_allocator(|a| a.free(allocation))
        {
            tracing::error!(buffer = %self.name, "freeing buffer memory failed: {e}");
        }
        // SAFETY: every submission using this buffer was waited on before the owner let it go.
        unsafe { self.ctx.device().destroy_buffer(self.raw, None) };
        self.ctx.object_destroyed();
        self.ctx.buffer_freed(self.size);
    }
}

//! A stand-in for an engine: its own ash instance, device and queue, made the way an engine makes
//! them, with what `pathgrad::gpu::Context::requirements()` lists merged into its device's
//! create-info. `examples/embed/main.rs` hands it to pathgrad; `tests/it/embed.rs` uses it too.

use std::ffi::{CStr, CString, c_void};
use std::sync::atomic::{AtomicU64, Ordering};

use ash::vk;
use pathgrad::gpu::{BorrowedDevice, Context, DeviceFeatures};

/// How to build the host.
#[derive(Clone, Debug, Default)]
pub struct HostOptions {
    /// Enable the Khronos validation layer and count its messages in the host's own messenger.
    pub validation: bool,
    /// Required features or extensions (Vulkan names) to leave off the device (to see pathgrad refuse it).
    pub leave_out: Vec<&'static str>,
}

/// The engine's Vulkan objects. Dropping it destroys them, in the engine's order.
pub struct Host {
    pub entry: ash::Entry,
    pub instance: ash::Instance,
    pub physical_device: vk::PhysicalDevice,
    pub device: ash::Device,
    pub queue_family: u32,
    pub queue: vk::Queue,
    enabled: DeviceFeatures,
    extensions: Vec<CString>,
    messenger: Option<(ash::ext::debug_utils::Instance, vk::DebugUtilsMessengerEXT)>,
    messages: Box<AtomicU64>,
    closed: bool,
}

unsafe extern "system" fn count_message(
    severity: vk::DebugUtilsMessageSeverityFlagsEXT,
    types: vk::DebugUtilsMessageTypeFlagsEXT,
    data: *const vk::DebugUtilsMessengerCallbackDataEXT<'_>,
    user: *mut c_void,
) -> vk::Bool32 {
    let serious = severity
        .intersects(vk::DebugUtilsMessageSeverityFlagsEXT::WARNING | vk::DebugUtilsMessageSeverityFlagsEXT::ERROR);
    if serious && types.contains(vk::DebugUtilsMessageTypeFlagsEXT::VALIDATION) {
        // SAFETY: `user` is the host's counter, alive until the messenger is destroyed; `data` is
        // valid for the call.
        unsafe {
            (*(user as *const AtomicU64)).fetch_add(1, Ordering::SeqCst);
            if let Some(d) = data.as_ref().filter(|d| !d.p_message.is_null()) {
                eprintln!("host validation: {}", CStr::from_ptr(d.p_message).to_string_lossy());
            }
        }
    }
    vk::FALSE
}

impl Host {
    /// Creates the instance (Vulkan 1.2), picks a device (a CPU implementation first, as tests
    /// want; an engine would pick its GPU) and creates the device with one queue of a compute family.
    pub fn new(options: &HostOptions) -> Result<Host, String> {
        // SAFETY: loading the system Vulkan loader.
        let entry = unsafe { ash::Entry::load() }.map_err(|e| format!("no Vulkan loader: {e}"))?;
        let layer = c"VK_LAYER_KHRONOS_validation";
        let layers: Vec<*const i8> = if options.validation { vec![layer.as_ptr()] } else { vec![] };
        let instance_extensions: Vec<*const i8> =
            if options.validation { vec![ash::ext::debug_utils::NAME.as_ptr()] } else { vec![] };
        let app = vk::ApplicationInfo::default().application_name(c"embedding host").api_version(vk::API_VERSION_1_2);
        let info = vk::InstanceCreateInfo::default()
            .application_info(&app)
            .enabled_layer_names(&layers)
            .enabled_extension_names(&instance_extensions);
        // SAFETY: the create-info lives across the call.
        let instance = unsafe { entry.create_instance(&info, None) }.map_err(|e| format!("vkCreateInstance: {e}"))?;
        let messages = Box::new(AtomicU64::new(0));
        let messenger = if options.validation {
            let loader = ash::ext::debug_utils::Instance::new(&entry, &instance);
            let info = vk::DebugUtilsMessengerCreateInfoEXT::default()
                .message_severity(
                    vk::DebugUtilsMessageSeverityFlagsEXT::WARNING | vk::DebugUtilsMessageSeverityFlagsEXT::ERROR,
                )
                .message_type(vk::DebugUtilsMessageTypeFlagsEXT::VALIDATION)
                .pfn_user_callback(Some(count_message))
                .user_data(&*messages as *const AtomicU64 as *mut c_void);
            // SAFETY: the counter is boxed and outlives the messenger.
            let m =
                unsafe { loader.create_debug_utils_messenger(&info, None) }.map_err(|e| format!("messenger: {e}"))?;
            Some((loader, m))
        } else {
            None
        };
        // SAFETY: valid instance.
        let devices = unsafe { instance.enumerate_physical_devices() }.map_err(|e| e.to_string())?;
        let props = |pd| unsafe { instance.get_physical_device_properties(pd) };
        let physical_device = *devices
            .iter()
            .min_by_key(|&&pd| props(pd).device_type != vk::PhysicalDeviceType::CPU)
            .ok_or("no physical device")?;
        // SAFETY: valid physical device.
        let families = unsafe { instance.get_physical_device_queue_family_properties(physical_device) };
        let queue_family =
            families.iter().position(|f| f.queue_flags.contains(vk::QueueFlags::COMPUTE)).ok_or("no compute queue")?
                as u32;

        // What pathgrad needs, merged into what the engine wants (here: nothing else).
        let requirements = Context::requirements();
        let mut extensions: Vec<CString> = requirements
            .device_extensions
            .iter()
            .filter(|e| !options.leave_out.contains(&e.to_str().unwrap_or("")))
            .map(|e| (*e).to_owned())
            .collect();
        extensions.dedup();
        let mut enabled = DeviceFeatures::default();
        enabled.enable_required(true);
        for name in &options.leave_out {
            match *name {
                "shaderInt64" => enabled.core.shader_int64 = vk::FALSE,
                "scalarBlockLayout" => enabled.vulkan12.scalar_block_layout = vk::FALSE,
                "bufferDeviceAddress" => enabled.vulkan12.buffer_device_address = vk::FALSE,
                "shaderBufferFloat32AtomicAdd" | "VK_EXT_shader_atomic_float" => {
                    enabled.atomic_float.shader_buffer_float32_atomic_add = vk::FALSE
                }
                other => return Err(format!("unknown feature {other}")),
            }
        }
        let with_atomic_float = extensions.iter().any(|e| e.as_c_str() == ash::ext::shader_atomic_float::NAME);
        let mut vulkan12 = enabled.vulkan12;
        let mut atomic_float = enabled.atomic_float;
        let mut features2 = vk::PhysicalDeviceFeatures2::default().features(enabled.core).push_next(&mut vulkan12);
        if with_atomic_float {
            features2 = features2.push_next(&mut atomic_float);
        }
        let priorities = [1.0f32];
        let queues =
            [vk::DeviceQueueCreateInfo::default().queue_family_index(queue_family).queue_priorities(&priorities)];
        let extension_ptrs: Vec<*const i8> = extensions.iter().map(|e| e.as_ptr()).collect();
        let device_info = vk::DeviceCreateInfo::default()
            .queue_create_infos(&queues)
            .enabled_extension_names(&extension_ptrs)
            .push_next(&mut features2);
        // What the device really gets, read back from the create-info as an engine would.
        // SAFETY: the create-info and its chain are valid.
        let enabled = unsafe { DeviceFeatures::from_create_info(&device_info) };
        // SAFETY: the create-info lives across the call.
        let device = unsafe { instance.create_device(physical_device, &device_info, None) }
            .map_err(|e| format!("vkCreateDevice: {e}"))?;
        // SAFETY: the device has one queue in that family.
        let queue = unsafe { device.get_device_queue(queue_family, 0) };
        Ok(Host {
            entry,
            instance,
            physical_device,
            device,
            queue_family,
            queue,
            enabled,
            extensions,
            messenger,
            messages,
            closed: false,
        })
    }

    /// The handles pathgrad borrows (clones of the function tables; the handles stay the host's).
    pub fn borrowed(&self) -> BorrowedDevice {
        BorrowedDevice {
            entry: self.entry.clone(),
            instance: self.instance.clone(),
            physical_device: self.physical_device,
            device: self.device.clone(),
            queue_family: self.queue_family,
            queue_index: 0,
            enabled: self.enabled,
            enabled_extensions: self.extensions.clone(),
            api_version: vk::API_VERSION_1_2,
        }
    }

    /// Validation messages (WARNING or ERROR) the host's messenger has seen.
    pub fn validation_messages(&self) -> u64 {
        self.messages.load(Ordering::SeqCst)
    }

    /// Records commands with `record` into a command buffer of the host's own, submits them on its
    /// queue and waits: how this engine runs a frame.
    pub fn run(&self, record: impl FnOnce(vk::CommandBuffer)) -> Result<(), vk::Result> {
        let d = &self.device;
        // SAFETY: plain Vulkan on the host's own device; the pool is destroyed after the wait.
        unsafe {
            let pool = d.create_command_pool(
                &vk::CommandPoolCreateInfo::default().queue_family_index(self.queue_family),
                None,
            )?;
            let result = (|| {
                let cmd = d.allocate_command_buffers(
                    &vk::CommandBufferAllocateInfo::default().command_pool(pool).command_buffer_count(1),
                )?[0];
                d.begin_command_buffer(cmd, &vk::CommandBufferBeginInfo::default())?;
                record(cmd);
                d.end_command_buffer(cmd)?;
                let fence = d.create_fence(&vk::FenceCreateInfo::default(), None)?;
                let cmds = [cmd];
                let submitted = d.queue_submit(self.queue, &[vk::SubmitInfo::default().command_buffers(&cmds)], fence);
                let waited = submitted.and_then(|()| d.wait_for_fences(&[fence], true, u64::MAX));
                d.destroy_fence(fence, None);
                waited
            })();
            d.destroy_command_pool(pool, None);
            result
        }
    }

    /// A host-visible buffer of the host's own (`TRANSFER_SRC | TRANSFER_DST`) and its memory;
    /// [`Host::free`] releases them.
    pub fn staging(&self, size: u64) -> Result<(vk::Buffer, vk::DeviceMemory), vk::Result> {
        let d = &self.device;
        let usage = vk::BufferUsageFlags::TRANSFER_SRC | vk::BufferUsageFlags::TRANSFER_DST;
        // SAFETY: plain Vulkan on the host's own device.
        unsafe {
            let buffer = d.create_buffer(&vk::BufferCreateInfo::default().size(size).usage(usage), None)?;
            let needs = d.get_buffer_memory_requirements(buffer);
            let kinds = self.instance.get_physical_device_memory_properties(self.physical_device);
            let wanted = vk::MemoryPropertyFlags::HOST_VISIBLE | vk::MemoryPropertyFlags::HOST_COHERENT;
            let kind = (0..kinds.memory_type_count)
                .find(|&i| {
                    needs.memory_type_bits & (1 << i) != 0
                        && kinds.memory_types[i as usize].property_flags.contains(wanted)
                })
                .ok_or(vk::Result::ERROR_FEATURE_NOT_PRESENT)?;
            let memory = d.allocate_memory(
                &vk::MemoryAllocateInfo::default().allocation_size(needs.size).memory_type_index(kind),
                None,
            )?;
            d.bind_buffer_memory(buffer, memory, 0)?;
            Ok((buffer, memory))
        }
    }

    /// Copies `size` bytes at `offset` of any buffer on the device (one of pathgrad's, say) into
    /// host memory through a staging buffer of the host's, after `record` has run in the same
    /// command buffer.
    pub fn read_after(
        &self,
        record: impl FnOnce(vk::CommandBuffer),
        buffer: vk::Buffer,
        offset: u64,
        size: u64,
    ) -> Result<Vec<u8>, vk::Result> {
        let d = &self.device;
        let (staging, memory) = self.staging(size)?;
        let result = self.run(|cmd| {
            record(cmd);
            let region = [vk::BufferCopy::default().src_offset(offset).size(size)];
            // SAFETY: both buffers live until the submission is waited on; pathgrad's recorded
            // calls end with a barrier that makes their writes visible to later commands.
            unsafe {
                d.cmd_copy_buffer(cmd, buffer, staging, &region);
                host_barrier(d, cmd);
            }
        });
        // SAFETY: the work is done; the memory is host-visible and coherent.
        let bytes = result.and_then(|()| unsafe {
            let ptr = d.map_memory(memory, 0, size, vk::MemoryMapFlags::empty())? as *const u8;
            let bytes = std::slice::from_raw_parts(ptr, size as usize).to_vec();
            d.unmap_memory(memory);
            Ok(bytes)
        });
        self.free(staging, memory);
        bytes
    }

    /// Writes `bytes` at `offset` of any buffer on the device through a staging buffer of the
    /// host's, and waits.
    pub fn write(&self, buffer: vk::Buffer, offset: u64, bytes: &[u8]) -> Result<(), vk::Result> {
        let d = &self.device;
        let size = bytes.len() as u64;
        let (staging, memory) = self.staging(size)?;
        // SAFETY: host-visible, coherent memory of the staging buffer, not in use.
        let result = unsafe {
            d.map_memory(memory, 0, size, vk::MemoryMapFlags::empty()).map(|ptr| {
                std::slice::from_raw_parts_mut(ptr as *mut u8, bytes.len()).copy_from_slice(bytes);
                d.unmap_memory(memory);
            })
        }
        .and_then(|()| {
            self.run(|cmd| {
                let region = [vk::BufferCopy::default().dst_offset(offset).size(size)];
                // SAFETY: both buffers live until the submission is waited on.
                unsafe { d.cmd_copy_buffer(cmd, staging, buffer, &region) };
            })
        });
        self.free(staging, memory);
        result
    }

    /// Destroys a buffer made by [`Host::staging`] and frees its memory.
    pub fn free(&self, buffer: vk::Buffer, memory: vk::DeviceMemory) {
        // SAFETY: the host's own objects, no longer in use.
        unsafe {
            self.device.destroy_buffer(buffer, None);
            self.device.free_memory(memory, None);
        }
    }

    /// Uses the device for the engine's own work: fills a buffer of its own with `value` on the
    /// GPU and reads it back. Returns the words read.
    pub fn fill_and_read(&self, value: u32, words: usize) -> Result<Vec<u32>, vk::Result> {
        let size = (words * 4) as u64;
        let (buffer, memory) = self.staging(size)?;
        // SAFETY: the host's own buffer, alive until the submission is waited on.
        let bytes =
            self.read_after(|cmd| unsafe { self.device.cmd_fill_buffer(cmd, buffer, 0, size, value) }, buffer, 0, size);
        self.free(buffer, memory);
        Ok(bytes?.chunks_exact(4).map(|w| u32::from_ne_bytes([w[0], w[1], w[2], w[3]])).collect())
    }
}

/// Makes transfer writes visible to the host.
///
/// # Safety
/// `cmd` is recording.
unsafe fn host_barrier(d: &ash::Device, cmd: vk::CommandBuffer) {
    let barrier = [vk::MemoryBarrier::default()
        .src_access_mask(vk::AccessFlags::TRANSFER_WRITE)
        .dst_access_mask(vk::AccessFlags::HOST_READ)];
    // SAFETY: as the caller guarantees.
    unsafe {
        d.cmd_pipeline_barrier(
            cmd,
            vk::PipelineStageFlags::TRANSFER,
            vk::PipelineStageFlags::HOST,
            vk::DependencyFlags::empty(),
            &barrier,
            &[],
            &[],
        )
    };
}

impl Host {
    /// Destroys the device, the messenger and the instance, and returns the validation messages
    /// counted up to the end, those about objects still alive at `vkDestroyDevice` included.
    pub fn close(mut self) -> u64 {
        self.destroy();
        self.validation_messages()
    }

    fn destroy(&mut self) {
        if self.closed {
            return;
        }
        self.closed = true;
        // SAFETY: the engine's teardown: nothing of pathgrad's may be alive by now.
        unsafe {
            let _ = self.device.device_wait_idle();
            self.device.destroy_device(None);
            if let Some((loader, messenger)) = self.messenger.take() {
                loader.destroy_debug_utils_messenger(messenger, None);
            }
            self.instance.destroy_instance(None);
        }
    }
}

impl Drop for Host {
    fn drop(&mut self) {
        self.destroy();
    }
}

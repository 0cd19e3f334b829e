//! `Context`: the Vulkan device, queue and allocator, created here or borrowed from an engine.
//!
//! [`Context::new`] creates an instance and device of its own, enabling only what pathgrad needs
//! ([`Context::requirements`]), with the validation layer on request. [`Context::from_raw`] takes
//! an engine's instance, device and queue instead: it checks what the engine enabled against the
//! same list, installs no layer or messenger, and destroys only what it created itself (its
//! allocator's memory, command pool and pipeline cache).
//!
//! Thread safety: `Context` is `Send + Sync` and shared as `Arc<Context>`. Its queue and command
//! pool sit behind mutexes, so pathgrad's own calls from several threads serialise their
//! submissions. Vulkan also requires the queue to be externally synchronised against the engine: on
//! a borrowed queue, the engine must not submit to it from another thread while a pathgrad call
//! runs (or should hand over a queue of its own for pathgrad).

use std::ffi::CString;
use std::sync::atomic::{AtomicI64, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

use ash::vk;
use gpu_allocator::vulkan::{Allocator, AllocatorCreateDesc};

use super::DeviceChoice;
use super::device::{DeviceInfo, choose, describe};
use super::instance::{ValidationCounter, create_instance, load_entry, messenger_create_info};
use super::requirements::{self, DeviceFeatures, Requirements};
use crate::error::{Error, Result, VkResultExt};

mod submit;

pub use submit::{Pending, SubmitSync};

/// How long a fence wait may take before [`Error::Timeout`] (lavapipe has no watchdog, so a hung
/// shader would otherwise hang the process). Work is submitted in chunks far shorter than this.
pub const FENCE_TIMEOUT_SECONDS: u64 = 600;

/// Options for [`Context::new`].
#[derive(Clone, Debug, Default)]
pub struct ContextDesc {
    /// Which device to pick.
    pub device: DeviceChoice,
    /// Enable the Khronos validation layer (when installed) and count its messages.
    pub validation: bool,
}

/// The Vulkan instance, device, queue, allocator and command pool that everything else uses.
///
/// Shared as `Arc<Context>`; every buffer and pipeline holds one and frees itself on drop.
pub struct Context {
    _entry: ash::Entry,
    instance: ash::Instance,
    owner: Owner,
    debug_names: Option<ash::ext::debug_utils::Device>,
    physical_device: vk::PhysicalDevice,
    device: ash::Device,
    queue_family: u32,
    queue: Mutex<vk::Queue>,
    command_pool: Mutex<vk::CommandPool>,
    /// Shared by every pipeline this context builds: a kernel variant built twice in one process
    /// (two renderers of the same scene) is compiled once where the driver's cache is real.
    pipeline_cache: vk::PipelineCache,
    allocator: Mutex<Option<Allocator>>,
    info: DeviceInfo,
    validation: Arc<ValidationCounter>,
    live_objects: AtomicI64,
    buffer_bytes: AtomicU64,
    peak_buffer_bytes: AtomicU64,
}

type Messenger = (ash::ext::debug_utils::Instance, vk::DebugUtilsMessengerEXT);

/// Who created the instance and device, and so who destroys them.
enum Owner {
    /// [`Context::new`]: pathgrad, with its debug messenger if validation is on.
    Pathgrad { debug: Option<Messenger> },
    /// [`Context::from_raw`]: the engine.
    Engine,
}

/// An engine's Vulkan objects for [`Context::from_raw`], and what it enabled on its device.
/// Plain data (`Send + Sync`, as ash's handles and feature structs are).
pub struct BorrowedDevice {
    /// The loader the engine's instance was created with.
    pub entry: ash::Entry,
    /// The engine's instance.
    pub instance: ash::Instance,
    /// The physical device of `device`.
    pub physical_device: vk::PhysicalDevice,
    /// The engine's logical device.
    pub device: ash::Device,
    /// The queue family of the queue pathgrad submits to (it must support compute).
    pub queue_family: u32,
    /// The queue's index within its family.
    pub queue_index: u32,
    /// The features the device was created with ([`DeviceFeatures::from_create_info`] reads them
    /// from the engine's create-info).
    pub enabled: DeviceFeatures,
    /// The device extensions it was created with.
    pub enabled_extensions: Vec<CString>,
    /// The `apiVersion` the engine's instance was created with.
    pub api_version: u32,
}

/// What [`Context::assemble`] builds a context from.
struct Parts {
    entry: ash::Entry,
    instance: ash::Instance,
    physical_device: vk::PhysicalDevice,
    device: ash::Device,
    queue_family: u32,
    queue_index: u32,
    info: DeviceInfo,
    owner: Owner,
    debug_names: Option<ash::ext::debug_utils::Device>,
    validation: Arc<ValidationCounter>,
}

impl std::fmt::Debug for Context {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Context").field("device", &self.info.name).finish_non_exhaustive()
    }
}

impl Context {
    /// Creates an instance and a device of its own.
    ///
    /// # Errors
    /// [`Error::NoDevice`] without a loader or driver, [`Error::DeviceNotFound`] for a bad choice,
    /// [`Error::MissingFeature`] when the chosen device lacks something pathgrad needs.
    pub fn new(desc: &ContextDesc) -> Result<Arc<Context>> {
        let entry = load_entry()?;
        let validation = Arc::new(ValidationCounter::default());
        let (instance, use_validation, has_debug_utils) = create_instance(&entry, desc.validation, &validation)?;
        let result = Self::with_instance(entry, instance, use_validation, has_debug_utils, validation, desc);
        result.map(Arc::new)
    }

    fn with_instance(
        entry: ash::Entry,
        instance: ash::Instance,
        use_validation: bool,
        has_debug_utils: bool,
        validation: Arc<ValidationCounter>,
        desc: &ContextDesc,
    ) -> Result<Context> {
        // Destroys the messenger and the instance if anything below fails.
        struct InstanceGuard(Option<(ash::Instance, Option<Messenger>)>);
        impl Drop for InstanceGuard {
            fn drop(&mut self) {
                if let Some((instance, debug)) = self.0.take() {
                    // SAFETY: no child object of the instance survives a failed construction.
                    unsafe {
                        if let Some((loader, messenger)) = debug {
                            loader.destroy_debug_utils_messenger(messenger, None);
                        }
                        instance.destroy_instance(None);
                    }
                }
            }
        }
        let mut guard = InstanceGuard(Some((instance.clone(), None)));
        let debug = if use_validation {
            let loader = ash::ext::debug_utils::Instance::new(&entry, &instance);
            // SAFETY: the counter outlives the messenger (both are owned by the context).
            let messenger = unsafe { loader.create_debug_utils_messenger(&messenger_create_info(&validation), None) }
                .vk("vkCreateDebugUtilsMessengerEXT")?;
            Some((loader, messenger))
        } else {
            None
        };
        guard.0 = Some((instance.clone(), debug.clone()));
        // SAFETY: valid instance.
        let pds = unsafe { instance.enumerate_physical_devices() }.vk("vkEnumeratePhysicalDevices")?;
        if pds.is_empty() {
            return Err(Error::NoDevice { reason: "the driver reports no physical device".into() });
        }
        let infos: Vec<DeviceInfo> = pds.iter().enumerate().map(|(i, &pd)| describe(&instance, i, pd)).collect();
        let chosen = choose(&infos, &desc.device)?;
        let physical_device = pds[chosen];
        let info = infos[chosen].clone();
        // SAFETY: valid physical device.
        let families = unsafe { instance.get_physical_device_queue_family_properties(physical_device) };
        let queue_family =
            families.iter().position(|f| f.queue_flags.contains(vk::QueueFlags::COMPUTE)).ok_or_else(|| {
                Error::MissingFeature {
                    device: info.name.clone(),
                    feature: "a compute queue".into(),
                    hint: "choose another device (DeviceChoice)".into(),
                }
            })? as u32;
        let priorities = [1.0f32];
        let queue_info =
            [vk::DeviceQueueCreateInfo::default().queue_family_index(queue_family).queue_priorities(&priorities)];
        let ext_ptrs: Vec<*const std::ffi::c_char> =
            requirements::DEVICE_EXTENSIONS.iter().map(|e| e.as_ptr()).collect();
        // Everything required; 64-bit integer atomics (deterministic gradients) and timeline
        // semaphores where the device has them.
        let mut enabled = DeviceFeatures::default();
        enabled.enable_required(false);
        enabled.vulkan12.shader_buffer_int64_atomics = info.int64_atomics.into();
        enabled.vulkan12.timeline_semaphore = info.timeline_semaphores.into();
        let mut v12 = enabled.vulkan12;
        let mut atomic = enabled.atomic_float;
        let mut features =
            vk::PhysicalDeviceFeatures2::default().features(enabled.core).push_next(&mut v12).push_next(&mut atomic);
        let device_info = vk::DeviceCreateInfo::default()
            .queue_create_infos(&queue_info)
            .enabled_extension_names(&ext_ptrs)
            .push_next(&mut features);
        // SAFETY: every feature and extension requested was checked by `describe`.
        let device = unsafe { instance.create_device(physical_device, &device_info, None) }.vk("vkCreateDevice")?;
        let debug_names = has_debug_utils.then(|| ash::ext::debug_utils::Device::new(&instance, &device));
        let parts = Parts {
            entry,
            instance,
            physical_device,
            device: device.clone(),
            queue_family,
            queue_index: 0,
            info,
            owner: Owner::Pathgrad { debug },
            debug_names,
            validation,
        };
        match Context::assemble(parts) {
            Ok(ctx) => {
                guard.0 = None;
                Ok(ctx)
            }
            Err(e) => {
                // SAFETY: `assemble` destroyed what it created; nothing else was made from the device.
                unsafe { device.destroy_device(None) };
                Err(e)
            }
        }
    }

    /// What an engine must enable before it hands its device to [`Context::from_raw`]: API
    /// version, device extensions, features (by Vulkan name; [`DeviceFeatures::enable_required`]
    /// sets them), the subgroup operations the device must support and the queue's capabilities.
    pub fn requirements() -> Requirements {
        requirements::requirements()
    }

    /// Wraps an engine's Vulkan objects without taking them over: pathgrad allocates its buffers
    /// through its own allocator on the engine's device, records and submits on the given queue,
    /// and on drop destroys only what it created. No validation layer or debug messenger is
    /// installed, and [`Context::validation_errors`] stays 0 (the engine's own messenger sees
    /// pathgrad's calls).
    ///
    /// Every extension and feature of [`Context::requirements`] is checked against
    /// `borrowed.enabled` and `borrowed.enabled_extensions`, and the device's properties
    /// (API version, subgroup operations, the queue family's flags) against the physical device.
    ///
    /// ```no_run
    /// # fn engine() -> pathgrad::gpu::BorrowedDevice { unimplemented!() }
    /// // The engine created its instance and device with everything `Context::requirements()` lists.
    /// let borrowed: pathgrad::gpu::BorrowedDevice = engine();
    /// // SAFETY: the engine's handles are valid and outlive the context (see # Safety).
    /// let ctx = unsafe { pathgrad::gpu::Context::from_raw(borrowed) }?;
    /// # Ok::<(), pathgrad::Error>(())
    /// ```
    ///
    /// # Errors
    /// [`Error::NotEnabled`] naming every required extension or feature that `borrowed` does not
    /// enable; [`Error::MissingFeature`] when the physical device lacks an API version, subgroup
    /// operation or compute queue; allocation failures.
    ///
    /// # Safety
    /// The instance, physical device, device and queue must be valid, belong together, and stay
    /// alive until this context and everything made from it (renderers, buffers, kernels) are
    /// dropped; the device must have been created with a queue at `queue_family`/`queue_index` and
    /// with exactly the features and extensions `borrowed` reports; the engine must not submit to
    /// that queue from another thread while a pathgrad call runs on it.
    pub unsafe fn from_raw(borrowed: BorrowedDevice) -> Result<Arc<Context>> {
        let BorrowedDevice {
            entry,
            instance,
            physical_device,
            device,
            queue_family,
            queue_index,
            enabled,
            enabled_extensions,
            api_version,
        } = borrowed;
        let mut info = describe(&instance, 0, physical_device);
        let mut missing: Vec<String> = Vec::new();
        if api_version < requirements::API_VERSION {
            missing.push(format!(
                "Vulkan {}.{} (the engine created it for {}.{})",
                vk::api_version_major(requirements::API_VERSION),
                vk::api_version_minor(requirements::API_VERSION),
                vk::api_version_major(api_version),
                vk::api_version_minor(api_version)
            ));
        }
        missing.extend(requirements::missing_extensions(&enabled_extensions));
        missing.extend(enabled.missing().into_iter().map(String::from));
        if !missing.is_empty() {
            return Err(Error::NotEnabled { device: info.name, missing });
        }
        // What the physical device itself lacks (the subgroup operations are properties, not switches).
        if !info.missing.is_empty() {
            return Err(Error::MissingFeature {
                device: info.name.clone(),
                feature: info.missing.join(", "),
                hint: "hand pathgrad another device".into(),
            });
        }
        // SAFETY: the caller guarantees the physical device.
        let families = unsafe { instance.get_physical_device_queue_family_properties(physical_device) };
        let compute =
            families.get(queue_family as usize).is_some_and(|f| f.queue_flags.contains(vk::QueueFlags::COMPUTE));
        if !compute {
            return Err(Error::MissingFeature {
                device: info.name.clone(),
                feature: format!("compute on queue family {queue_family}"),
                hint: "hand pathgrad a queue of a family with VK_QUEUE_COMPUTE_BIT".into(),
            });
        }
        info.int64_atomics = info.int64_atomics && enabled.int64_atomics();
        info.timeline_semaphores = info.timeline_semaphores && enabled.vulkan12.timeline_semaphore == vk::TRUE;
        let parts = Parts {
            entry,
            instance,
            physical_device,
            device,
            queue_family,
            queue_index,
            info,
            owner: Owner::Engine,
            debug_names: None,
            validation: Arc::new(ValidationCounter::default()),
        };
        Context::assemble(parts).map(Arc::new)
    }

    /// Creates pathgrad's own objects on a device (command pool, allocator, pipeline cache); on
    /// failure destroys those and nothing else.
    fn assemble(parts: Parts) -> Result<Context> {
        let Parts {
            entry,
            instance,
            physical_device,
            device,
            queue_family,
            queue_index,
            info,
            owner,
            debug_names,
            validation,
        } = parts;
        // SAFETY: the device was created with this queue (by us, or as the engine guarantees).
        let queue = unsafe { device.get_device_queue(queue_family, queue_index) };
        let pool_info = vk::CommandPoolCreateInfo::default()
            .queue_family_index(queue_family)
            .flags(vk::CommandPoolCreateFlags::RESET_COMMAND_BUFFER);
        // SAFETY: valid device.
        let command_pool = unsafe { device.create_command_pool(&pool_info, None) }.vk("vkCreateCommandPool")?;
        let allocator = Allocator::new(&AllocatorCreateDesc {
            instance: instance.clone(),
            device: device.clone(),
            physical_device,
            debug_settings: Default::default(),
            buffer_device_address: true,
            allocation_sizes: Default::default(),
        })
        .map_err(|e| Error::Allocation { name: "allocator".into(), size: 0, message: e.to_string() });
        let allocator = match allocator {
            Ok(a) => a,
            Err(e) => {
                // SAFETY: only the pool was created here.
                unsafe { device.destroy_command_pool(command_pool, None) };
                return Err(e);
            }
        };
        // SAFETY: valid device; an empty cache. A failure only costs compile time: go without.
        let pipeline_cache = unsafe { device.create_pipeline_cache(&vk::PipelineCacheCreateInfo::default(), None) }
            .unwrap_or(vk::PipelineCache::null());
        let borrowed = matches!(owner, Owner::Engine);
        let validation_on = matches!(&owner, Owner::Pathgrad { debug: Some(_) });
        tracing::info!(device = %info.name, driver = %info.driver, validation = validation_on, borrowed, "Vulkan device ready");
        Ok(Context {
            _entry: entry,
            instance,
            owner,
            debug_names,
            physical_device,
            device,
            queue_family,
            queue: Mutex::new(queue),
            command_pool: Mutex::new(command_pool),
            pipeline_cache,
            allocator: Mutex::new(Some(allocator)),
            info,
            validation,
            live_objects: AtomicI64::new(0),
            buffer_bytes: AtomicU64::new(0),
            peak_buffer_bytes: AtomicU64::new(0),
        })
    }

    /// The pipeline cache every kernel of this context is built with.
    pub fn pipeline_cache(&self) -> vk::PipelineCache {
        self.pipeline_cache
    }

    /// The logical device.
    pub fn device(&self) -> &ash::Device {
        &self.device
    }

    /// The instance.
    pub fn instance(&self) -> &ash::Instance {
        &self.instance
    }

    /// The physical device.
    pub fn physical_device(&self) -> vk::PhysicalDevice {
        self.physical_device
    }

    /// The queue family used for compute.
    pub fn queue_family(&self) -> u32 {
        self.queue_family
    }

    /// The chosen device.
    pub fn info(&self) -> &DeviceInfo {
        &self.info
    }

    /// Validation messages (VALIDATION type, WARNING or ERROR) counted so far; 0 without validation.
    pub fn validation_errors(&self) -> u64 {
        self.validation.count()
    }

    /// Whether the validation layer is active on this context.
    pub fn validation_enabled(&self) -> bool {
        matches!(&self.owner, Owner::Pathgrad { debug: Some(_) })
    }

    /// Buffers, pipelines and descriptor sets created from this context and not yet dropped.
    pub fn live_objects(&self) -> i64 {
        self.live_objects.load(Ordering::SeqCst)
    }

    /// Bytes of buffer memory alive now (scene, parameters, gradients, images, staging).
    pub fn buffer_bytes(&self) -> u64 {
        self.buffer_bytes.load(Ordering::SeqCst)
    }

    /// The most buffer memory alive at once since the context was created or the peak was reset.
    pub fn peak_buffer_bytes(&self) -> u64 {
        self.peak_buffer_bytes.load(Ordering::SeqCst)
    }

    /// Starts a new peak measurement from the current level.
    pub fn reset_peak_buffer_bytes(&self) {
        self.peak_buffer_bytes.store(self.buffer_bytes(), Ordering::SeqCst);
    }

    pub(crate) fn buffer_allocated(&self, bytes: u64) {
        let now = self.buffer_bytes.fetch_add(bytes, Ordering::SeqCst) + bytes;
        self.peak_buffer_bytes.fetch_max(now, Ordering::SeqCst);
    }

    pub(crate) fn buffer_freed(&self, bytes: u64) {
        self.buffer_bytes.fetch_sub(bytes, Ordering::SeqCst);
    }

    pub(crate) fn object_created(&self) {
        self.live_objects.fetch_add(1, Ordering::SeqCst);
    }

    pub(crate) fn object_destroyed(&self) {
        self.live_objects.fetch_sub(1, Ordering::SeqCst);
    }

    /// Runs `f` with the allocator.
    pub(crate) fn with_allocator<T>(&self, f: impl FnOnce(&mut Allocator) -> T) -> T {
        let mut guard = self.allocator.lock().unwrap_or_else(|p| p.into_inner());
        f(guard.as_mut().expect("the allocator lives until the context drops"))
    }

    /// Gives a Vulkan object a debug name (shown by validation messages), when debug utils exist.
    pub(crate) fn set_name<H: vk::Handle>(&self, handle: H, name: &str) {
        if let (Some(names), Ok(cname)) = (&self.debug_names, CString::new(name)) {
            let info = vk::DebugUtilsObjectNameInfoEXT::default().object_handle(handle).object_name(&cname);
            // SAFETY: `handle` is a live object of this device; naming is advisory.
            let _ = unsafe { names.set_debug_utils_object_name(&info) };
        }
    }
}

impl Drop for Context {
    fn drop(&mut self) {
        // SAFETY: teardown in the order gpu-allocator requires: allocator, pool, cache, then (if
        // pathgrad created them) device, messenger, instance. Children hold an `Arc<Context>`, so
        // none is alive any more, and every pathgrad submission was waited for before it returned.
        unsafe {
            if matches!(self.owner, Owner::Pathgrad { .. }) {
                let _ = self.device.device_wait_idle();
            }
            drop(self.allocator.lock().unwrap_or_else(|p| p.into_inner()).take());
            self.device.destroy_command_pool(*self.command_pool.get_mut().unwrap_or_else(|p| p.into_inner()), None);
            self.device.destroy_pipeline_cache(self.pipeline_cache, None);
            if let Owner::Pathgrad { debug } = &mut self.owner {
                self.device.destroy_device(None);
                if let Some((loader, messenger)) = debug.take() {
                    loader.destroy_debug_utils_messenger(messenger, None);
                }
                self.instance.destroy_instance(None);
            }
        }
    }
}

/// `Context` is shared across threads as `Arc<Context>` (the module's thread-safety note).
const _: fn() = || {
    fn send_sync<T: Send + Sync>() {}
    send_sync::<Context>();
    send_sync::<BorrowedDevice>();
};

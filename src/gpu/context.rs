//! `Context`: the Vulkan instance, device, queue and allocator, created here or borrowed from an engine.
//!
//! Device choice: `DeviceChoice::Auto` takes a discrete GPU over an integrated one over a CPU
//! implementation (lavapipe); an index or UUID (from `pathgrad devices`) or the `PATHGRAD_DEVICE`
//! variable picks one explicitly. Only what pathgrad needs is enabled: scalar block layout, float
//! atomic add on storage buffers (gradients) and compute subgroup arithmetic (their reduction).
//! With validation on, every message of type VALIDATION at WARNING or above is counted; tests fail on
//! a non-zero count.

use std::ffi::{CStr, CString, c_void};
use std::sync::atomic::{AtomicI64, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

use ash::vk;
use gpu_allocator::vulkan::{Allocator, AllocatorCreateDesc};

use crate::error::{Error, Result, VkResultExt};

/// The validation layer's name.
const VALIDATION_LAYER: &CStr = c"VK_LAYER_KHRONOS_validation";

/// How long a fence wait may take before [`Error::Timeout`] (lavapipe has no watchdog, so a hung
/// shader would otherwise hang the process). Work is submitted in chunks far shorter than this.
pub const FENCE_TIMEOUT_SECONDS: u64 = 600;

/// Which physical device to use.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub enum DeviceChoice {
    /// `PATHGRAD_DEVICE` if set, else discrete > integrated > virtual > CPU.
    #[default]
    Auto,
    /// Prefer a CPU implementation (lavapipe): what tests use, so results do not depend on the box.
    PreferCpu,
    /// The device at this index of `pathgrad devices`.
    Index(usize),
    /// The device with this UUID (32 hex digits, dashes allowed).
    Uuid(String),
}

impl DeviceChoice {
    /// Parses `--device` / `PATHGRAD_DEVICE`: an index, a UUID, or `cpu`.
    pub fn parse(text: &str) -> Self {
        let t = text.trim();
        if t.eq_ignore_ascii_case("cpu") || t.eq_ignore_ascii_case("lavapipe") {
            DeviceChoice::PreferCpu
        } else if let Ok(i) = t.parse::<usize>() {
            DeviceChoice::Index(i)
        } else {
            DeviceChoice::Uuid(t.to_string())
        }
    }
}

/// Options for [`Context::new`].
#[derive(Clone, Debug, Default)]
pub struct ContextDesc {
    /// Which device to pick.
    pub device: DeviceChoice,
    /// Enable the Khronos validation layer (when installed) and count its messages.
    pub validation: bool,
}

/// What pathgrad knows about a physical device.
#[derive(Clone, Debug)]
pub struct DeviceInfo {
    /// Index in the instance's enumeration order.
    pub index: usize,
    /// Device name, e.g. `llvmpipe (LLVM 15.0.6, 256 bits)`.
    pub name: String,
    /// Discrete, integrated, CPU, …
    pub device_type: vk::PhysicalDeviceType,
    /// Driver name and version string.
    pub driver: String,
    /// Driver id (`MESA_LLVMPIPE` for lavapipe).
    pub driver_id: vk::DriverId,
    /// Device UUID as 32 hex digits.
    pub uuid: String,
    /// Vulkan API version the device supports.
    pub api_version: u32,
    /// Subgroup size.
    pub subgroup_size: u32,
    /// Everything pathgrad needs that the device lacks (empty when usable).
    pub missing: Vec<String>,
    /// Whether 64-bit integer atomics on buffers exist (deterministic gradients need them).
    pub int64_atomics: bool,
    /// Whether the driver silently cuts loops short after a per-invocation iteration budget
    /// (lavapipe before Mesa 25, PLATFORM.md §6.1): kernels then trace one path per invocation.
    pub loop_budget: bool,
}

impl DeviceInfo {
    /// A one-line human-readable summary.
    pub fn summary(&self) -> String {
        format!(
            "[{}] {} ({:?}, driver {}, Vulkan {}.{}.{}, subgroup {}) uuid {}{}",
            self.index,
            self.name,
            self.device_type,
            self.driver,
            vk::api_version_major(self.api_version),
            vk::api_version_minor(self.api_version),
            vk::api_version_patch(self.api_version),
            self.subgroup_size,
            self.uuid,
            if self.missing.is_empty() {
                String::new()
            } else {
                format!(" — unusable: lacks {}", self.missing.join(", "))
            }
        )
    }

    fn rank(&self) -> u32 {
        match self.device_type {
            vk::PhysicalDeviceType::DISCRETE_GPU => 0,
            vk::PhysicalDeviceType::INTEGRATED_GPU => 1,
            vk::PhysicalDeviceType::VIRTUAL_GPU => 2,
            vk::PhysicalDeviceType::CPU => 3,
            _ => 4,
        }
    }
}

/// Counts validation messages; shared with the debug messenger callback.
#[derive(Debug, Default)]
pub struct ValidationCounter {
    errors: AtomicU64,
}

impl ValidationCounter {
    /// VALIDATION-type messages of severity WARNING or ERROR seen so far.
    pub fn count(&self) -> u64 {
        self.errors.load(Ordering::SeqCst)
    }
}

unsafe extern "system" fn debug_callback(
    severity: vk::DebugUtilsMessageSeverityFlagsEXT,
    types: vk::DebugUtilsMessageTypeFlagsEXT,
    data: *const vk::DebugUtilsMessengerCallbackDataEXT<'_>,
    user: *mut c_void,
) -> vk::Bool32 {
    // SAFETY: the loader passes a valid callback-data pointer for the duration of the call.
    let message = unsafe { data.as_ref() }
        .and_then(|d| (!d.p_message.is_null()).then(|| unsafe { CStr::from_ptr(d.p_message) }))
        .map(|m| m.to_string_lossy().into_owned())
        .unwrap_or_default();
    let counts = severity
        .intersects(vk::DebugUtilsMessageSeverityFlagsEXT::WARNING | vk::DebugUtilsMessageSeverityFlagsEXT::ERROR)
        && types.contains(vk::DebugUtilsMessageTypeFlagsEXT::VALIDATION);
    if counts {
        // SAFETY: `user` is the counter that the context keeps alive until the messenger is destroyed.
        if let Some(counter) = unsafe { (user as *const ValidationCounter).as_ref() } {
            counter.errors.fetch_add(1, Ordering::SeqCst);
        }
        tracing::error!(target: "vulkan", "{message}");
    } else if severity.contains(vk::DebugUtilsMessageSeverityFlagsEXT::WARNING) {
        tracing::warn!(target: "vulkan", "{message}");
    } else {
        tracing::debug!(target: "vulkan", "{message}");
    }
    vk::FALSE
}

/// The Vulkan instance, device, queue, allocator and command pool that everything else uses.
///
/// Shared as `Arc<Context>`; every buffer and pipeline holds one and frees itself on drop.
pub struct Context {
    _entry: ash::Entry,
    instance: ash::Instance,
    debug: Option<(ash::ext::debug_utils::Instance, vk::DebugUtilsMessengerEXT)>,
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

impl std::fmt::Debug for Context {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Context").field("device", &self.info.name).finish_non_exhaustive()
    }
}

fn load_entry() -> Result<ash::Entry> {
    // SAFETY: loading the system Vulkan loader; ash keeps the library alive inside `Entry`.
    unsafe { ash::Entry::load() }.map_err(|e| Error::NoDevice { reason: format!("cannot load libvulkan.so.1: {e}") })
}

fn create_instance(
    entry: &ash::Entry,
    validation: bool,
    counter: &Arc<ValidationCounter>,
) -> Result<(ash::Instance, bool, bool)> {
    // SAFETY: plain queries of the loader.
    let version = unsafe { entry.try_enumerate_instance_version() }
        .vk("vkEnumerateInstanceVersion")?
        .unwrap_or(vk::API_VERSION_1_0);
    if version < vk::API_VERSION_1_2 {
        return Err(Error::NoDevice { reason: "the Vulkan loader is older than 1.2".into() });
    }
    // SAFETY: plain query of the loader.
    let layers = unsafe { entry.enumerate_instance_layer_properties() }.vk("vkEnumerateInstanceLayerProperties")?;
    let has_layer = layers.iter().any(|l| l.layer_name_as_c_str().is_ok_and(|n| n == VALIDATION_LAYER));
    // SAFETY: plain query of the loader.
    let extensions =
        unsafe { entry.enumerate_instance_extension_properties(None) }.vk("vkEnumerateInstanceExtensionProperties")?;
    let has_debug_utils =
        extensions.iter().any(|e| e.extension_name_as_c_str().is_ok_and(|n| n == ash::ext::debug_utils::NAME));
    let use_validation = validation && has_layer && has_debug_utils;
    if validation && !use_validation {
        tracing::warn!(
            "validation requested but VK_LAYER_KHRONOS_validation is not installed (apt-get install vulkan-validationlayers)"
        );
    }
    let layer_ptrs: Vec<*const i8> = if use_validation { vec![VALIDATION_LAYER.as_ptr()] } else { vec![] };
    let ext_ptrs: Vec<*const i8> = if has_debug_utils { vec![ash::ext::debug_utils::NAME.as_ptr()] } else { vec![] };
    let app = vk::ApplicationInfo::default()
        .application_name(c"pathgrad")
        .engine_name(c"pathgrad")
        .api_version(vk::API_VERSION_1_2);
    let mut messenger_info = messenger_create_info(counter);
    let mut info = vk::InstanceCreateInfo::default()
        .application_info(&app)
        .enabled_layer_names(&layer_ptrs)
        .enabled_extension_names(&ext_ptrs);
    if use_validation {
        info = info.push_next(&mut messenger_info);
    }
    // SAFETY: the create-info and everything it points to live across the call.
    let instance = unsafe { entry.create_instance(&info, None) }.map_err(|result| match result {
        vk::Result::ERROR_INCOMPATIBLE_DRIVER => Error::NoDevice { reason: "the Vulkan loader found no driver".into() },
        result => Error::Vulkan { call: "vkCreateInstance", result },
    })?;
    Ok((instance, use_validation, has_debug_utils))
}

fn messenger_create_info(counter: &Arc<ValidationCounter>) -> vk::DebugUtilsMessengerCreateInfoEXT<'static> {
    vk::DebugUtilsMessengerCreateInfoEXT::default()
        .message_severity(
            vk::DebugUtilsMessageSeverityFlagsEXT::ERROR
                | vk::DebugUtilsMessageSeverityFlagsEXT::WARNING
                | vk::DebugUtilsMessageSeverityFlagsEXT::INFO,
        )
        .message_type(
            vk::DebugUtilsMessageTypeFlagsEXT::GENERAL
                | vk::DebugUtilsMessageTypeFlagsEXT::VALIDATION
                | vk::DebugUtilsMessageTypeFlagsEXT::PERFORMANCE,
        )
        .pfn_user_callback(Some(debug_callback))
        .user_data(Arc::as_ptr(counter) as *mut c_void)
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// Queries one physical device: identity and whatever pathgrad needs that it lacks.
fn describe(instance: &ash::Instance, index: usize, pd: vk::PhysicalDevice) -> DeviceInfo {
    let mut driver = vk::PhysicalDeviceDriverProperties::default();
    let mut id = vk::PhysicalDeviceIDProperties::default();
    let mut subgroup = vk::PhysicalDeviceSubgroupProperties::default();
    let props = {
        let mut p2 =
            vk::PhysicalDeviceProperties2::default().push_next(&mut driver).push_next(&mut id).push_next(&mut subgroup);
        // SAFETY: `pd` came from this instance; the chain lives across the call.
        unsafe { instance.get_physical_device_properties2(pd, &mut p2) };
        p2.properties
    };
    let mut v12 = vk::PhysicalDeviceVulkan12Features::default();
    let mut atomic = vk::PhysicalDeviceShaderAtomicFloatFeaturesEXT::default();
    let core = {
        let mut f2 = vk::PhysicalDeviceFeatures2::default().push_next(&mut v12).push_next(&mut atomic);
        // SAFETY: as above.
        unsafe { instance.get_physical_device_features2(pd, &mut f2) };
        f2.features
    };
    // SAFETY: as above.
    let extensions = unsafe { instance.enumerate_device_extension_properties(pd) }.unwrap_or_default();
    let has_atomic_ext =
        extensions.iter().any(|e| e.extension_name_as_c_str().is_ok_and(|n| n == ash::ext::shader_atomic_float::NAME));
    let mut missing = Vec::new();
    if props.api_version < vk::API_VERSION_1_2 {
        missing.push("Vulkan 1.2".to_string());
    }
    if v12.scalar_block_layout == vk::FALSE {
        missing.push("scalarBlockLayout".to_string());
    }
    if v12.buffer_device_address == vk::FALSE {
        missing.push("bufferDeviceAddress".to_string());
    }
    // The BVH traversal reads its nodes and triangles as 64-bit words (shaders/lib/bvh.glsl).
    if core.shader_int64 == vk::FALSE {
        missing.push("shaderInt64".to_string());
    }
    if !has_atomic_ext || atomic.shader_buffer_float32_atomic_add == vk::FALSE {
        missing.push("VK_EXT_shader_atomic_float (shaderBufferFloat32AtomicAdd)".to_string());
    }
    let needed_ops =
        vk::SubgroupFeatureFlags::BASIC | vk::SubgroupFeatureFlags::ARITHMETIC | vk::SubgroupFeatureFlags::VOTE;
    if !subgroup.supported_stages.contains(vk::ShaderStageFlags::COMPUTE)
        || !subgroup.supported_operations.contains(needed_ops)
    {
        missing.push("compute subgroup basic/vote/arithmetic operations".to_string());
    }
    let name = props.device_name_as_c_str().map(|c| c.to_string_lossy().into_owned()).unwrap_or_default();
    let driver_name = driver.driver_name_as_c_str().map(|c| c.to_string_lossy().into_owned()).unwrap_or_default();
    let driver_info = driver.driver_info_as_c_str().map(|c| c.to_string_lossy().into_owned()).unwrap_or_default();
    DeviceInfo {
        index,
        name,
        device_type: props.device_type,
        driver: format!("{driver_name} {driver_info}").trim().to_string(),
        driver_id: driver.driver_id,
        uuid: hex(&id.device_uuid),
        api_version: props.api_version,
        subgroup_size: subgroup.subgroup_size,
        missing,
        int64_atomics: core.shader_int64 == vk::TRUE && v12.shader_buffer_int64_atomics == vk::TRUE,
        loop_budget: has_loop_budget(driver.driver_id, &driver_info),
    }
}

/// Whether a driver has llvmpipe's loop limiter: Mesa 22.3 (Debian 12) has it, Mesa 25.0
/// (bookworm-backports) does not (PLATFORM.md §14). Versions between were not measured and are
/// treated as limited, and so is a lavapipe whose version cannot be read. lavapipe reports
/// `driverVersion` 0.0.1; its Mesa version is in `driverInfo`, e.g. `Mesa 25.0.7-2~bpo12+1 (LLVM 15.0.6)`.
pub fn has_loop_budget(driver_id: vk::DriverId, driver_info: &str) -> bool {
    if driver_id != vk::DriverId::MESA_LLVMPIPE {
        return false;
    }
    let major = driver_info
        .split_once("Mesa ")
        .and_then(|(_, v)| v.split(|c: char| !c.is_ascii_digit()).next())
        .and_then(|m| m.parse::<u32>().ok());
    major.is_none_or(|m| m < 25)
}

/// Lists every Vulkan device with what pathgrad needs that it lacks (the `devices` subcommand).
///
/// # Errors
/// [`Error::NoDevice`] when there is no loader or no driver.
pub fn list_devices() -> Result<Vec<DeviceInfo>> {
    let entry = load_entry()?;
    let counter = Arc::new(ValidationCounter::default());
    let (instance, _, _) = create_instance(&entry, false, &counter)?;
    // SAFETY: the instance is valid; it is destroyed right after the query.
    let result = unsafe { instance.enumerate_physical_devices() }
        .vk("vkEnumeratePhysicalDevices")
        .map(|pds| pds.iter().enumerate().map(|(i, &pd)| describe(&instance, i, pd)).collect());
    // SAFETY: nothing else refers to this instance.
    unsafe { instance.destroy_instance(None) };
    result
}

fn choose(devices: &[DeviceInfo], choice: &DeviceChoice) -> Result<usize> {
    let available = || devices.iter().map(DeviceInfo::summary).collect::<Vec<_>>().join("; ");
    let usable = |d: &DeviceInfo| -> Result<usize> {
        if d.missing.is_empty() {
            Ok(d.index)
        } else {
            Err(Error::MissingFeature {
                device: d.name.clone(),
                feature: d.missing.join(", "),
                hint: "update the driver (Mesa ≥ 22 for lavapipe) or choose another device (DeviceChoice)".into(),
            })
        }
    };
    let choice = match choice {
        DeviceChoice::Auto => match std::env::var("PATHGRAD_DEVICE") {
            Ok(v) if !v.trim().is_empty() => DeviceChoice::parse(&v),
            _ => DeviceChoice::Auto,
        },
        other => other.clone(),
    };
    match &choice {
        DeviceChoice::Index(i) => devices
            .get(*i)
            .ok_or_else(|| Error::DeviceNotFound { selector: i.to_string(), available: available() })
            .and_then(usable),
        DeviceChoice::Uuid(u) => {
            let want = u.replace('-', "").to_ascii_lowercase();
            devices
                .iter()
                .find(|d| d.uuid == want)
                .ok_or_else(|| Error::DeviceNotFound { selector: u.clone(), available: available() })
                .and_then(usable)
        }
        DeviceChoice::Auto | DeviceChoice::PreferCpu => {
            let prefer_cpu = choice == DeviceChoice::PreferCpu;
            let best = devices.iter().filter(|d| d.missing.is_empty()).min_by_key(|d| {
                let cpu_first = u32::from(
                    !(d.device_type == vk::PhysicalDeviceType::CPU || d.driver_id == vk::DriverId::MESA_LLVMPIPE),
                );
                if prefer_cpu { (cpu_first, d.rank(), d.index) } else { (0, d.rank(), d.index) }
            });
            match best {
                Some(d) => Ok(d.index),
                None => match devices.first() {
                    Some(d) => usable(d),
                    None => Err(Error::NoDevice { reason: "the driver reports no physical device".into() }),
                },
            }
        }
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
        // Destroys the instance if anything below fails.
        struct InstanceGuard(Option<ash::Instance>);
        impl Drop for InstanceGuard {
            fn drop(&mut self) {
                if let Some(i) = self.0.take() {
                    // SAFETY: no child object of the instance survives a failed construction.
                    unsafe { i.destroy_instance(None) };
                }
            }
        }
        let mut guard = InstanceGuard(Some(instance.clone()));
        let debug = if use_validation {
            let loader = ash::ext::debug_utils::Instance::new(&entry, &instance);
            // SAFETY: the counter outlives the messenger (both are owned by the context).
            let messenger = unsafe { loader.create_debug_utils_messenger(&messenger_create_info(&validation), None) }
                .vk("vkCreateDebugUtilsMessengerEXT")?;
            Some((loader, messenger))
        } else {
            None
        };
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
        let ext_ptrs = [ash::ext::shader_atomic_float::NAME.as_ptr()];
        // 64-bit integers are required (the BVH traversal's loads); deterministic gradients also
        // need 64-bit integer atomics: enabled where the device has them.
        let int64 = info.int64_atomics;
        let mut v12 = vk::PhysicalDeviceVulkan12Features::default()
            .scalar_block_layout(true)
            .buffer_device_address(true)
            .shader_buffer_int64_atomics(int64);
        let mut atomic =
            vk::PhysicalDeviceShaderAtomicFloatFeaturesEXT::default().shader_buffer_float32_atomic_add(true);
        let core = vk::PhysicalDeviceFeatures::default().shader_int64(true);
        let mut features =
            vk::PhysicalDeviceFeatures2::default().features(core).push_next(&mut v12).push_next(&mut atomic);
        let device_info = vk::DeviceCreateInfo::default()
            .queue_create_infos(&queue_info)
            .enabled_extension_names(&ext_ptrs)
            .push_next(&mut features);
        // SAFETY: every feature and extension requested was checked by `describe`.
        let device = unsafe { instance.create_device(physical_device, &device_info, None) }.vk("vkCreateDevice")?;
        // SAFETY: the queue family was created with one queue.
        let queue = unsafe { device.get_device_queue(queue_family, 0) };
        let pool_info = vk::CommandPoolCreateInfo::default()
            .queue_family_index(queue_family)
            .flags(vk::CommandPoolCreateFlags::RESET_COMMAND_BUFFER);
        // SAFETY: valid device.
        let command_pool = match unsafe { device.create_command_pool(&pool_info, None) } {
            Ok(p) => p,
            Err(result) => {
                // SAFETY: nothing was created from the device yet.
                unsafe { device.destroy_device(None) };
                return Err(Error::Vulkan { call: "vkCreateCommandPool", result });
            }
        };
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
                // SAFETY: only the pool was created from the device.
                unsafe {
                    device.destroy_command_pool(command_pool, None);
                    device.destroy_device(None);
                }
                return Err(e);
            }
        };
        let debug_names = has_debug_utils.then(|| ash::ext::debug_utils::Device::new(&instance, &device));
        guard.0 = None;
        // SAFETY: valid device; an empty cache. A failure only costs compile time: go without.
        let pipeline_cache = unsafe { device.create_pipeline_cache(&vk::PipelineCacheCreateInfo::default(), None) }
            .unwrap_or(vk::PipelineCache::null());
        tracing::info!(device = %info.name, driver = %info.driver, validation = use_validation, "Vulkan device ready");
        Ok(Context {
            _entry: entry,
            instance,
            debug,
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
        self.debug.is_some()
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

    /// Records commands with `record`, submits them and waits (with a finite timeout).
    ///
    /// # Errors
    /// Vulkan failures, or [`Error::Timeout`] if the GPU does not finish in [`FENCE_TIMEOUT_SECONDS`].
    pub fn submit_and_wait(&self, what: &str, record: impl FnOnce(vk::CommandBuffer)) -> Result<()> {
        let pool = self.command_pool.lock().unwrap_or_else(|p| p.into_inner());
        let alloc = vk::CommandBufferAllocateInfo::default()
            .command_pool(*pool)
            .level(vk::CommandBufferLevel::PRIMARY)
            .command_buffer_count(1);
        // SAFETY: the pool belongs to this device and is guarded by the mutex.
        let cmd = unsafe { self.device.allocate_command_buffers(&alloc) }.vk("vkAllocateCommandBuffers")?[0];
        let result = self.record_submit(cmd, what, record);
        // SAFETY: the submission finished or failed; the buffer is not in use.
        unsafe { self.device.free_command_buffers(*pool, &[cmd]) };
        result
    }

    fn record_submit(&self, cmd: vk::CommandBuffer, what: &str, record: impl FnOnce(vk::CommandBuffer)) -> Result<()> {
        let begin = vk::CommandBufferBeginInfo::default().flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT);
        // SAFETY: fresh command buffer.
        unsafe { self.device.begin_command_buffer(cmd, &begin) }.vk("vkBeginCommandBuffer")?;
        record(cmd);
        // SAFETY: recording started above.
        unsafe { self.device.end_command_buffer(cmd) }.vk("vkEndCommandBuffer")?;
        // SAFETY: valid device.
        let fence = unsafe { self.device.create_fence(&vk::FenceCreateInfo::default(), None) }.vk("vkCreateFence")?;
        let cmds = [cmd];
        let submit = [vk::SubmitInfo::default().command_buffers(&cmds)];
        let result = {
            let queue = self.queue.lock().unwrap_or_else(|p| p.into_inner());
            // SAFETY: the queue is externally synchronised by the mutex.
            unsafe { self.device.queue_submit(*queue, &submit, fence) }.vk("vkQueueSubmit")
        }
        .and_then(|()| {
            // SAFETY: the fence was submitted above.
            match unsafe { self.device.wait_for_fences(&[fence], true, FENCE_TIMEOUT_SECONDS * 1_000_000_000) } {
                Ok(()) => Ok(()),
                Err(vk::Result::TIMEOUT) => {
                    Err(Error::Timeout { what: what.to_string(), seconds: FENCE_TIMEOUT_SECONDS })
                }
                Err(result) => Err(Error::Vulkan { call: "vkWaitForFences", result }),
            }
        });
        if matches!(result, Err(Error::Timeout { .. })) {
            // The GPU may still use the command buffer: wait for it before the fence and buffer go.
            // SAFETY: valid device.
            let _ = unsafe { self.device.device_wait_idle() };
        }
        // SAFETY: the fence is signalled or the device idle.
        unsafe { self.device.destroy_fence(fence, None) };
        result
    }
}

impl Drop for Context {
    fn drop(&mut self) {
        // SAFETY: teardown in the order gpu-allocator requires: wait, allocator, pool, device,
        // messenger, instance. Children hold an `Arc<Context>`, so none is alive any more.
        unsafe {
            let _ = self.device.device_wait_idle();
            drop(self.allocator.lock().unwrap_or_else(|p| p.into_inner()).take());
            self.device.destroy_command_pool(*self.command_pool.get_mut().unwrap_or_else(|p| p.into_inner()), None);
            self.device.destroy_pipeline_cache(self.pipeline_cache, None);
            self.device.destroy_device(None);
            if let Some((loader, messenger)) = self.debug.take() {
                loader.destroy_debug_utils_messenger(messenger, None);
            }
            self.instance.destroy_instance(None);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn loop_budget_follows_the_mesa_version_of_lavapipe_only() {
        let lvp = vk::DriverId::MESA_LLVMPIPE;
        assert!(has_loop_budget(lvp, "Mesa 22.3.6"));
        assert!(!has_loop_budget(lvp, "Mesa 25.0.7-2~bpo12+1 (LLVM 15.0.6)"));
        assert!(!has_loop_budget(lvp, "Mesa 26.1.0-devel (git-1234)"));
        assert!(has_loop_budget(lvp, "something else"), "unknown versions are treated as limited");
        assert!(!has_loop_budget(vk::DriverId::NVIDIA_PROPRIETARY, "580.95.05"));
    }
}

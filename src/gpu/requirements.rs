//! What pathgrad needs of a Vulkan device, as a list an engine enables and the checks against it.
//!
//! [`Context::requirements`](super::Context::requirements) is the list; [`DeviceFeatures`] holds
//! the feature flags in the three Vulkan structs they live in, so an engine can merge them into the
//! create-info of its own device. The same table checks a physical device (`pathgrad devices`,
//! [`Context::new`](super::Context::new)) and a borrowed device's enabled state
//! ([`Context::from_raw`](super::Context::from_raw)).

use std::ffi::{CStr, CString};

use ash::vk;

/// The Vulkan version pathgrad's instance and device must have (core 1.2: descriptor indexing is
/// not used, but `bufferDeviceAddress`, `scalarBlockLayout` and 64-bit atomics are 1.2 features).
pub const API_VERSION: u32 = vk::API_VERSION_1_2;

/// Device extensions pathgrad needs enabled.
pub const DEVICE_EXTENSIONS: &[&CStr] = &[ash::ext::shader_atomic_float::NAME];

/// Subgroup operations the compute stage must support (the gradient reduction): a property, not
/// something to enable.
pub const SUBGROUP_OPERATIONS: vk::SubgroupFeatureFlags = vk::SubgroupFeatureFlags::from_raw(
    vk::SubgroupFeatureFlags::BASIC.as_raw()
        | vk::SubgroupFeatureFlags::VOTE.as_raw()
        | vk::SubgroupFeatureFlags::ARITHMETIC.as_raw(),
);

/// Device feature flags, in the structs Vulkan keeps them in. `p_next` of each is null.
#[derive(Clone, Copy, Debug, Default)]
pub struct DeviceFeatures {
    /// Vulkan 1.0 features (`shaderInt64`).
    pub core: vk::PhysicalDeviceFeatures,
    /// Vulkan 1.2 features (`scalarBlockLayout`, `bufferDeviceAddress`, `shaderBufferInt64Atomics`).
    pub vulkan12: vk::PhysicalDeviceVulkan12Features<'static>,
    /// `VK_EXT_shader_atomic_float` features (`shaderBufferFloat32AtomicAdd`).
    pub atomic_float: vk::PhysicalDeviceShaderAtomicFloatFeaturesEXT<'static>,
}

type Flag = (&'static str, fn(&DeviceFeatures) -> bool, fn(&mut DeviceFeatures));

/// Every feature pathgrad needs: (Vulkan name, is it set, set it).
const REQUIRED: &[Flag] = &[
    ("shaderInt64", |f| f.core.shader_int64 == vk::TRUE, |f| f.core.shader_int64 = vk::TRUE),
    (
        "scalarBlockLayout",
        |f| f.vulkan12.scalar_block_layout == vk::TRUE,
        |f| f.vulkan12.scalar_block_layout = vk::TRUE,
    ),
    (
        "bufferDeviceAddress",
        |f| f.vulkan12.buffer_device_address == vk::TRUE,
        |f| f.vulkan12.buffer_device_address = vk::TRUE,
    ),
    (
        "shaderBufferFloat32AtomicAdd",
        |f| f.atomic_float.shader_buffer_float32_atomic_add == vk::TRUE,
        |f| f.atomic_float.shader_buffer_float32_atomic_add = vk::TRUE,
    ),
];

/// Features pathgrad uses where enabled: 64-bit integer atomics give deterministic gradients,
/// timeline semaphores let submissions wait on and signal an engine's semaphores.
const OPTIONAL: &[Flag] = &[
    (
        "shaderBufferInt64Atomics",
        |f| f.vulkan12.shader_buffer_int64_atomics == vk::TRUE,
        |f| f.vulkan12.shader_buffer_int64_atomics = vk::TRUE,
    ),
    ("timelineSemaphore", |f| f.vulkan12.timeline_semaphore == vk::TRUE, |f| f.vulkan12.timeline_semaphore = vk::TRUE),
];

impl DeviceFeatures {
    /// What a physical device supports.
    pub(crate) fn supported(instance: &ash::Instance, pd: vk::PhysicalDevice) -> DeviceFeatures {
        let mut vulkan12 = vk::PhysicalDeviceVulkan12Features::default();
        let mut atomic_float = vk::PhysicalDeviceShaderAtomicFloatFeaturesEXT::default();
        let core = {
            let mut f2 = vk::PhysicalDeviceFeatures2::default().push_next(&mut vulkan12).push_next(&mut atomic_float);
            // SAFETY: `pd` came from this instance; the chain lives across the call.
            unsafe { instance.get_physical_device_features2(pd, &mut f2) };
            f2.features
        };
        vulkan12.p_next = std::ptr::null_mut();
        atomic_float.p_next = std::ptr::null_mut();
        DeviceFeatures { core, vulkan12, atomic_float }
    }

    /// The features enabled by a device create-info: its `pEnabledFeatures` and the feature structs
    /// of its `pNext` chain that pathgrad reads (`VkPhysicalDeviceFeatures2`, Vulkan 1.2 features,
    /// the scalar-block-layout, buffer-device-address, 64-bit-atomic and float-atomic structs).
    ///
    /// # Safety
    /// `info` and everything its pointers reach must be valid, as for `vkCreateDevice`.
    pub unsafe fn from_create_info(info: &vk::DeviceCreateInfo<'_>) -> DeviceFeatures {
        let mut f = DeviceFeatures::default();
        // SAFETY: the caller guarantees the pointers, as vkCreateDevice needs them.
        unsafe {
            if let Some(core) = info.p_enabled_features.as_ref() {
                f.core = *core;
            }
            let mut next = info.p_next as *const vk::BaseInStructure<'_>;
            while let Some(s) = next.as_ref() {
                let any = next as *const std::ffi::c_void;
                match s.s_type {
                    vk::StructureType::PHYSICAL_DEVICE_FEATURES_2 => {
                        f.core = (*(any as *const vk::PhysicalDeviceFeatures2<'_>)).features;
                    }
                    vk::StructureType::PHYSICAL_DEVICE_VULKAN_1_2_FEATURES => {
                        f.vulkan12 = *(any as *const vk::PhysicalDeviceVulkan12Features<'static>);
                    }
                    vk::StructureType::PHYSICAL_DEVICE_SCALAR_BLOCK_LAYOUT_FEATURES => {
                        let s = &*(any as *const vk::PhysicalDeviceScalarBlockLayoutFeatures<'_>);
                        f.vulkan12.scalar_block_layout |= s.scalar_block_layout;
                    }
                    vk::StructureType::PHYSICAL_DEVICE_BUFFER_DEVICE_ADDRESS_FEATURES => {
                        let s = &*(any as *const vk::PhysicalDeviceBufferDeviceAddressFeatures<'_>);
                        f.vulkan12.buffer_device_address |= s.buffer_device_address;
                    }
                    vk::StructureType::PHYSICAL_DEVICE_TIMELINE_SEMAPHORE_FEATURES => {
                        let s = &*(any as *const vk::PhysicalDeviceTimelineSemaphoreFeatures<'_>);
                        f.vulkan12.timeline_semaphore |= s.timeline_semaphore;
                    }
                    vk::StructureType::PHYSICAL_DEVICE_SHADER_ATOMIC_INT64_FEATURES => {
                        let s = &*(any as *const vk::PhysicalDeviceShaderAtomicInt64Features<'_>);
                        f.vulkan12.shader_buffer_int64_atomics |= s.shader_buffer_int64_atomics;
                    }
                    vk::StructureType::PHYSICAL_DEVICE_SHADER_ATOMIC_FLOAT_FEATURES_EXT => {
                        f.atomic_float = *(any as *const vk::PhysicalDeviceShaderAtomicFloatFeaturesEXT<'static>);
                    }
                    _ => {}
                }
                next = s.p_next;
            }
        }
        f.vulkan12.p_next = std::ptr::null_mut();
        f.atomic_float.p_next = std::ptr::null_mut();
        f
    }

    /// Sets every feature pathgrad needs (and, with `optional`, those it uses where present),
    /// leaving the others as they are: merge into the engine's own flags before `vkCreateDevice`.
    pub fn enable_required(&mut self, optional: bool) {
        for (_, _, set) in REQUIRED.iter().chain(if optional { OPTIONAL } else { &[] }) {
            set(self);
        }
    }

    /// Vulkan names of the required features that are not set here.
    pub fn missing(&self) -> Vec<&'static str> {
        REQUIRED.iter().filter(|(_, has, _)| !has(self)).map(|(name, _, _)| *name).collect()
    }

    /// Whether 64-bit integer atomics on buffers are set (deterministic gradients need them).
    pub fn int64_atomics(&self) -> bool {
        self.vulkan12.shader_buffer_int64_atomics == vk::TRUE && self.core.shader_int64 == vk::TRUE
    }
}

/// Everything an engine must provide before it hands its device to
/// [`Context::from_raw`](super::Context::from_raw).
///
/// ```
/// let requirements = pathgrad::gpu::Context::requirements();
/// assert!(requirements.device_extensions.iter().any(|e| e.to_str() == Ok("VK_EXT_shader_atomic_float")));
/// assert!(requirements.feature_names.contains(&"bufferDeviceAddress"));
/// let mut features = pathgrad::gpu::DeviceFeatures::default();
/// features.enable_required(true);
/// assert!(features.missing().is_empty());
/// ```
#[derive(Clone, Debug)]
pub struct Requirements {
    /// The lowest `apiVersion` of the instance and device.
    pub api_version: u32,
    /// Device extensions to enable.
    pub device_extensions: &'static [&'static CStr],
    /// Features to enable, by their Vulkan names ([`DeviceFeatures::enable_required`] sets them).
    pub feature_names: Vec<&'static str>,
    /// Features pathgrad uses where enabled (`shaderBufferInt64Atomics`: deterministic gradients;
    /// `timelineSemaphore`: submissions synchronised with the engine's timeline semaphores).
    pub optional_feature_names: Vec<&'static str>,
    /// Subgroup operations the compute stage must support (a device property).
    pub subgroup_operations: vk::SubgroupFeatureFlags,
    /// The queue family handed over must support this.
    pub queue_flags: vk::QueueFlags,
}

pub(crate) fn requirements() -> Requirements {
    Requirements {
        api_version: API_VERSION,
        device_extensions: DEVICE_EXTENSIONS,
        feature_names: REQUIRED.iter().map(|(n, _, _)| *n).collect(),
        optional_feature_names: OPTIONAL.iter().map(|(n, _, _)| *n).collect(),
        subgroup_operations: SUBGROUP_OPERATIONS,
        queue_flags: vk::QueueFlags::COMPUTE,
    }
}

/// The names in `required` that `present` lacks.
pub(crate) fn missing_extensions(present: &[CString]) -> Vec<String> {
    DEVICE_EXTENSIONS
        .iter()
        .filter(|want| !present.iter().any(|have| have.as_c_str() == **want))
        .map(|e| e.to_string_lossy().into_owned())
        .collect()
}

/// What a physical device lacks of the list (empty when usable): API version, extensions,
/// features, subgroup operations.
pub(crate) fn unsupported(instance: &ash::Instance, pd: vk::PhysicalDevice, api_version: u32) -> Vec<String> {
    let mut missing = Vec::new();
    if api_version < API_VERSION {
        missing.push("Vulkan 1.2".to_string());
    }
    // SAFETY: `pd` came from this instance.
    let extensions: Vec<CString> = unsafe { instance.enumerate_device_extension_properties(pd) }
        .unwrap_or_default()
        .iter()
        .filter_map(|e| e.extension_name_as_c_str().ok().map(CStr::to_owned))
        .collect();
    missing.extend(missing_extensions(&extensions));
    missing.extend(DeviceFeatures::supported(instance, pd).missing().into_iter().map(String::from));
    let mut subgroup = vk::PhysicalDeviceSubgroupProperties::default();
    let mut p2 = vk::PhysicalDeviceProperties2::default().push_next(&mut subgroup);
    // SAFETY: as above; the chain lives across the call.
    unsafe { instance.get_physical_device_properties2(pd, &mut p2) };
    if !subgroup.supported_stages.contains(vk::ShaderStageFlags::COMPUTE)
        || !subgroup.supported_operations.contains(SUBGROUP_OPERATIONS)
    {
        missing.push("compute subgroup basic/vote/arithmetic operations".to_string());
    }
    missing
}

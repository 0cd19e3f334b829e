//! Contexts: pathgrad's own Vulkan instance and device, or an engine's lent to it.

use std::ffi::{CStr, CString, c_char, c_void};
use std::sync::Arc;

use ash::vk;
use ash::vk::Handle;
use pathgrad::gpu::{BorrowedDevice, Context, ContextDesc, DeviceChoice, DeviceFeatures};

use crate::error::{Failure, PgStatus, arg, arg_mut, guard, string};

/// `VkInstance` (vulkan.h's type in the header).
pub type VkInstance = *mut c_void;
/// `VkPhysicalDevice` (vulkan.h's type in the header).
pub type VkPhysicalDevice = *mut c_void;
/// `VkDevice` (vulkan.h's type in the header).
pub type VkDevice = *mut c_void;
/// `VkCommandBuffer` (vulkan.h's type in the header).
pub type VkCommandBuffer = *mut c_void;
/// `VkBuffer` (vulkan.h's type in the header: a pointer on 64-bit targets, `uint64_t` on 32-bit;
/// both are 8 bytes passed as an integer).
pub type VkBuffer = u64;
/// `VkDeviceCreateInfo` (vulkan.h's type in the header).
pub type VkDeviceCreateInfo = vk::DeviceCreateInfo<'static>;
/// `PFN_vkGetInstanceProcAddr` (vulkan.h's type in the header; null is `None`).
#[allow(non_camel_case_types)]
pub type PFN_vkGetInstanceProcAddr = Option<vk::PFN_vkGetInstanceProcAddr>;

/// A Vulkan device that pathgrad uses: its own, or an engine's. Shared by everything made from it;
/// destroying the handle releases the caller's share.
pub struct PgContext {
    pub(crate) ctx: Arc<Context>,
    name: CString,
}

impl PgContext {
    fn boxed(ctx: Arc<Context>) -> *mut PgContext {
        let name = CString::new(ctx.info().name.replace('\0', " ")).unwrap_or_default();
        Box::into_raw(Box::new(PgContext { ctx, name }))
    }
}

/// Options for `pg_context_create`; all zero is the default.
#[repr(C)]
pub struct PgContextDesc {
    /// Which device: null for the default choice, else as `pathgrad devices` and `PATHGRAD_DEVICE`
    /// take it: an index, a UUID, or "cpu" for lavapipe.
    pub device: *const c_char,
    /// Nonzero: enable the Khronos validation layer (where installed) and count its messages
    /// (`pg_context_validation_messages`).
    pub validation: u32,
}

/// An engine's Vulkan objects, lent to `pg_context_from_vulkan`.
#[repr(C)]
pub struct PgVulkanDevice {
    /// The loader's `vkGetInstanceProcAddr` that the engine created `instance` with.
    pub get_instance_proc_addr: PFN_vkGetInstanceProcAddr,
    /// The engine's instance, created for `api_version`.
    pub instance: VkInstance,
    /// The physical device of `device`.
    pub physical_device: VkPhysicalDevice,
    /// The engine's device.
    pub device: VkDevice,
    /// The family of the queue pathgrad submits its own work to; it must support compute.
    pub queue_family: u32,
    /// The queue's index within its family.
    pub queue_index: u32,
    /// `VkApplicationInfo::apiVersion` of the engine's instance (at least Vulkan 1.2).
    pub api_version: u32,
    /// The create-info the engine created `device` with: pathgrad reads its enabled extensions
    /// and features (`pEnabledFeatures` and the feature structs of its `pNext` chain) during the
    /// call only.
    pub device_create_info: *const VkDeviceCreateInfo,
}

/// Creates a context with an instance and device of pathgrad's own. `desc` may be null (the
/// defaults).
///
/// # Safety
/// `desc`, when not null, points to a valid `PgContextDesc` whose `device` is null or a
/// NUL-terminated string; `out` is a valid place for the handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pg_context_create(desc: *const PgContextDesc, out: *mut *mut PgContext) -> PgStatus {
    guard("pg_context_create", || {
        // SAFETY: the caller's guarantees.
        let out = unsafe { arg_mut(out, "out") }?;
        *out = std::ptr::null_mut();
        let mut options = ContextDesc::default();
        // SAFETY: the caller's guarantees.
        if let Some(desc) = unsafe { desc.as_ref() } {
            options.validation = desc.validation != 0;
            if !desc.device.is_null() {
                // SAFETY: non-null, NUL-terminated.
                options.device = DeviceChoice::parse(unsafe { string(desc.device, "desc->device") }?);
            }
        }
        *out = PgContext::boxed(Context::new(&options)?);
        Ok(())
    })
}

/// Creates a context on an engine's instance, device and queue, which pathgrad borrows and never
/// destroys. Every extension and feature pathgrad needs
/// (`pg_required_device_extension`, README: "Lending a device") is checked against
/// `lent->device_create_info`; the failure (`PG_STATUS_NOT_ENABLED`) names each one missing.
///
/// # Safety
/// The handles are valid, belong together, and outlive the context and every handle made from it
/// (scenes aside); `device_create_info` is the create-info `device` was made with, valid during
/// the call; the engine does not submit to the queue from another thread while a pathgrad call
/// runs on it; `out` is a valid place for the handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pg_context_from_vulkan(lent: *const PgVulkanDevice, out: *mut *mut PgContext) -> PgStatus {
    guard("pg_context_from_vulkan", || {
        // SAFETY: the caller's guarantees.
        let (lent, out) = unsafe { (arg(lent, "lent")?, arg_mut(out, "out")?) };
        *out = std::ptr::null_mut();
        let null = |what: &str| Failure::new(PgStatus::NullPointer, format!("`lent->{what}` is null"));
        let get_instance_proc_addr = lent.get_instance_proc_addr.ok_or_else(|| null("get_instance_proc_addr"))?;
        for (handle, what) in
            [(lent.instance, "instance"), (lent.physical_device, "physical_device"), (lent.device, "device")]
        {
            if handle.is_null() {
                return Err(null(what));
            }
        }
        // SAFETY: the caller's guarantees.
        let create_info = unsafe { arg(lent.device_create_info, "lent->device_create_info") }?;
        // SAFETY: the create-info and what it points to are valid during the call.
        let enabled = unsafe { DeviceFeatures::from_create_info(create_info) };
        let mut enabled_extensions = Vec::new();
        if create_info.enabled_extension_count > 0 && create_info.pp_enabled_extension_names.is_null() {
            return Err(null("device_create_info->ppEnabledExtensionNames"));
        }
        for i in 0..create_info.enabled_extension_count as usize {
            // SAFETY: `enabledExtensionCount` valid NUL-terminated names, as vkCreateDevice required.
            let name = unsafe { *create_info.pp_enabled_extension_names.add(i) };
            if name.is_null() {
                return Err(null("device_create_info->ppEnabledExtensionNames[i]"));
            }
            // SAFETY: as above.
            enabled_extensions.push(unsafe { CStr::from_ptr(name) }.to_owned());
        }
        let static_fn = ash::StaticFn { get_instance_proc_addr };
        let instance = vk::Instance::from_raw(lent.instance as u64);
        let physical_device = vk::PhysicalDevice::from_raw(lent.physical_device as u64);
        let device = vk::Device::from_raw(lent.device as u64);
        // SAFETY: the loader's entry point and the engine's live instance and device; ash only
        // loads function pointers here.
        let borrowed = unsafe {
            let entry = ash::Entry::from_static_fn(static_fn);
            let instance = ash::Instance::load(entry.static_fn(), instance);
            let device = ash::Device::load(instance.fp_v1_0(), device);
            BorrowedDevice {
                entry,
                instance,
                physical_device,
                device,
                queue_family: lent.queue_family,
                queue_index: lent.queue_index,
                enabled,
                enabled_extensions,
                api_version: lent.api_version,
            }
        };
        // SAFETY: the caller guarantees validity and lifetimes (this function's contract).
        *out = PgContext::boxed(unsafe { Context::from_raw(borrowed) }?);
        Ok(())
    })
}

/// The name of the context's device; valid as long as the context.
///
/// # Safety
/// `context` is null or a live context.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pg_context_device_name(context: *const PgContext) -> *const c_char {
    // SAFETY: the caller's guarantee.
    unsafe { context.as_ref() }.map_or(c"".as_ptr(), |c| c.name.as_ptr())
}

/// Validation messages (warnings and errors) counted on a context of pathgrad's own with
/// validation on; 0 otherwise (on a lent device the engine's own messenger sees pathgrad's calls).
///
/// # Safety
/// `context` is null or a live context.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pg_context_validation_messages(context: *const PgContext) -> u64 {
    // SAFETY: the caller's guarantee.
    unsafe { context.as_ref() }.map_or(0, |c| c.ctx.validation_errors())
}

/// Releases the caller's share of a context (null: nothing). Renderers and frames made from it
/// keep it alive until they are destroyed too; a lent device is never destroyed by pathgrad.
///
/// # Safety
/// `context` is null or a live context, not used again.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pg_context_destroy(context: *mut PgContext) {
    if !context.is_null() {
        // SAFETY: made by `Box::into_raw` and not used again (the caller's guarantee).
        let _ = guard("pg_context_destroy", || {
            drop(unsafe { Box::from_raw(context) });
            Ok(())
        });
    }
}

/// The number of device extensions pathgrad needs enabled on a lent device.
#[unsafe(no_mangle)]
pub extern "C" fn pg_required_device_extension_count() -> usize {
    pathgrad::gpu::requirements::DEVICE_EXTENSIONS.len()
}

/// The name of required device extension `index` (static storage), or null past the end.
/// The required features are listed in README.md; the required API version is 1.2.
#[unsafe(no_mangle)]
pub extern "C" fn pg_required_device_extension(index: usize) -> *const c_char {
    pathgrad::gpu::requirements::DEVICE_EXTENSIONS.get(index).map_or(std::ptr::null(), |e| e.as_ptr())
}

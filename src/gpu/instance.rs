//! The Vulkan instance pathgrad creates for itself: the loader, the validation layer and its message counter.
//!
//! With validation on, every message of type VALIDATION at WARNING or above is counted; tests fail
//! on a non-zero count. A borrowed device (`Context::from_raw`) gets none of this: pathgrad installs
//! no layer or messenger on an engine's instance.

use std::ffi::{CStr, c_void};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use ash::vk;

use crate::error::{Error, Result, VkResultExt};

/// The validation layer's name.
const VALIDATION_LAYER: &CStr = c"VK_LAYER_KHRONOS_validation";

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

pub(crate) fn load_entry() -> Result<ash::Entry> {
    // SAFETY: loading the system Vulkan loader; ash keeps the library alive inside `Entry`.
    unsafe { ash::Entry::load() }.map_err(|e| Error::NoDevice { reason: format!("cannot load libvulkan.so.1: {e}") })
}

pub(crate) fn create_instance(
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

pub(crate) fn messenger_create_info(counter: &Arc<ValidationCounter>) -> vk::DebugUtilsMessengerCreateInfoEXT<'static> {
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

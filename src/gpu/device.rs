//! Physical devices: what pathgrad knows of each, which one to pick, and the `devices` listing.
//!
//! Device choice: `DeviceChoice::Auto` takes a discrete GPU over an integrated one over a CPU
//! implementation (lavapipe); an index or UUID (from `pathgrad devices`) or the `PATHGRAD_DEVICE`
//! variable picks one explicitly.

use std::sync::Arc;

use ash::vk;

use super::instance::{ValidationCounter, create_instance, load_entry};
use super::requirements;
use crate::error::{Error, Result, VkResultExt};

/// Which physical device to use.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub enum DeviceChoice {
    /// `PATHGRAD_DEVICE` if set, else the GPU whose UUID a scheduler put first in
    /// `CUDA_VISIBLE_DEVICES`/`NVIDIA_VISIBLE_DEVICES`, else discrete > integrated > virtual > CPU.
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
    /// Whether timeline semaphores exist (submissions that wait on and signal an engine's
    /// semaphores, `Context::submit`).
    pub timeline_semaphores: bool,
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

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// Queries one physical device: identity and whatever pathgrad needs that it lacks.
pub(crate) fn describe(instance: &ash::Instance, index: usize, pd: vk::PhysicalDevice) -> DeviceInfo {
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
    let missing = requirements::unsupported(instance, pd, props.api_version);
    let supported = requirements::DeviceFeatures::supported(instance, pd);
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
        int64_atomics: supported.int64_atomics(),
        timeline_semaphores: supported.vulkan12.timeline_semaphore == vk::TRUE,
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

/// The vector width, in bits, that pathgrad's own programs ask lavapipe to build its kernels for
/// (`LP_NATIVE_VECTOR_WIDTH`, read when the driver starts) when the variable is not set: 512 on an
/// x86-64 CPU with AVX-512F, 128 elsewhere.
///
/// On the 2-core AVX-512 machine measured (BENCHMARKS.md, "lavapipe's vector width"), 16-lane
/// kernels run 8–17 % faster than 4-lane ones and a process that must compile one first takes
/// 0.2–0.7 s longer (once per kernel and machine: the code is cached); on an AVX2 host 4-lane
/// kernels compile in about 60 % of the time of the driver's 8-lane default and render as fast.
/// Results are the same bit for bit at every width. The `pathgrad` command and the Python module
/// set the variable to this before any Vulkan call ([`lavapipe_environment`]); an engine embedding
/// the library keeps its own environment. Other drivers ignore the variable.
///
/// ```
/// let bits = pathgrad::gpu::lavapipe_vector_width();
/// assert!(bits == 128 || bits == 512);
/// ```
pub fn lavapipe_vector_width() -> u32 {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx512f") {
        return 512;
    }
    128
}

/// The folder for Mesa's shader cache (`MESA_SHADER_CACHE_DIR`) that goes with lavapipe's vector
/// width `bits`, made if missing: `mesa-BITS-bit` in pathgrad's cache folder
/// (`$XDG_CACHE_HOME/pathgrad`, else `$HOME/.cache/pathgrad`, absolute paths only) for a width
/// other than 128; `None` for 128 (Mesa's own folder) or when no folder can be made.
///
/// lavapipe's cache does not key its machine code on the vector width (Mesa 25.0.7): a process at
/// 512 bits is handed the 128-bit code that an earlier process cached for the same kernel, and
/// keeps its speed. A folder per width keeps each width's code apart.
pub fn lavapipe_shader_cache_dir(bits: u32) -> Option<std::path::PathBuf> {
    if bits == 128 {
        return None;
    }
    let dir = super::specialise::pathgrad_cache()?.join(format!("mesa-{bits}-bit"));
    std::fs::create_dir_all(&dir).ok()?;
    Some(dir)
}

/// The variables the `pathgrad` command and the Python module set before any Vulkan call, as
/// (name, value) pairs, from the process's environment:
/// - `LP_NATIVE_VECTOR_WIDTH`, when unset: [`lavapipe_vector_width`];
/// - `MESA_SHADER_CACHE_DIR`, when unset and the width (chosen here or by the environment) is not
///   128: [`lavapipe_shader_cache_dir`]. Where that folder cannot be made (or its path is not
///   UTF-8), a width chosen here falls back to 128 bits rather than share Mesa's folder.
///
/// The cache folder moves the cache of any Mesa driver the process loads, which only splits it.
///
/// ```
/// for (name, value) in pathgrad::gpu::lavapipe_environment() {
///     assert!(name == "LP_NATIVE_VECTOR_WIDTH" || name == "MESA_SHADER_CACHE_DIR", "{name}={value}");
/// }
/// ```
pub fn lavapipe_environment() -> Vec<(&'static str, String)> {
    let given = std::env::var_os("LP_NATIVE_VECTOR_WIDTH");
    let chosen = given.is_none();
    let mut bits = match given {
        None => lavapipe_vector_width(),
        Some(v) => v.to_str().and_then(|v| v.trim().parse::<u32>().ok()).unwrap_or(128),
    };
    let mut out = Vec::new();
    if std::env::var_os("MESA_SHADER_CACHE_DIR").is_none() && bits != 128 {
        match lavapipe_shader_cache_dir(bits).and_then(|d| d.into_os_string().into_string().ok()) {
            Some(dir) => out.push(("MESA_SHADER_CACHE_DIR", dir)),
            None if chosen => bits = 128,
            None => {}
        }
    }
    if chosen {
        out.push(("LP_NATIVE_VECTOR_WIDTH", bits.to_string()));
    }
    out
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

pub(crate) fn choose(devices: &[DeviceInfo], choice: &DeviceChoice) -> Result<usize> {
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
            _ => scheduled_device(|name| std::env::var(name).ok()).unwrap_or(DeviceChoice::Auto),
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

/// The GPU a scheduler gave this process, by UUID: the first entry of `CUDA_VISIBLE_DEVICES`,
/// else of `NVIDIA_VISIBLE_DEVICES` (Slurm's GRES and Kubernetes' NVIDIA device plugin set them),
/// when it is a `GPU-<uuid>`. NVIDIA's Vulkan driver reports the same UUID as `deviceUUID`. An
/// index there counts CUDA devices, not Vulkan ones, so it is not used.
pub(crate) fn scheduled_device(var: impl Fn(&str) -> Option<String>) -> Option<DeviceChoice> {
    ["CUDA_VISIBLE_DEVICES", "NVIDIA_VISIBLE_DEVICES"].iter().find_map(|name| {
        let value = var(name)?;
        let first = value.split(',').next()?.trim();
        let uuid = first.get(..4).filter(|p| p.eq_ignore_ascii_case("GPU-")).map(|_| &first[4..])?;
        (uuid.chars().filter(char::is_ascii_hexdigit).count() == 32).then(|| DeviceChoice::Uuid(uuid.to_string()))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scheduler_gpu_uuids_choose_the_device() {
        let env = |pairs: &'static [(&'static str, &'static str)]| {
            move |name: &str| pairs.iter().find(|(n, _)| *n == name).map(|(_, v)| v.to_string())
        };
        let uuid = "GPU-5b2c1f3a-9e7d-4c11-8a0b-2f6e4d3c1b0a";
        assert_eq!(
            scheduled_device(env(&[("CUDA_VISIBLE_DEVICES", "GPU-5b2c1f3a-9e7d-4c11-8a0b-2f6e4d3c1b0a,GPU-x")])),
            Some(DeviceChoice::Uuid(uuid[4..].to_string()))
        );
        assert_eq!(
            scheduled_device(env(&[("NVIDIA_VISIBLE_DEVICES", "GPU-5b2c1f3a-9e7d-4c11-8a0b-2f6e4d3c1b0a")])),
            Some(DeviceChoice::Uuid(uuid[4..].to_string()))
        );
        // Indices, `all` and `none` say nothing about Vulkan's order.
        assert_eq!(scheduled_device(env(&[("CUDA_VISIBLE_DEVICES", "0,1")])), None);
        assert_eq!(scheduled_device(env(&[("NVIDIA_VISIBLE_DEVICES", "all")])), None);
        assert_eq!(scheduled_device(env(&[])), None);
    }

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

//! The SPIR-V of every kernel, compiled by build.rs from `shaders/*.comp` and embedded.

include!(concat!(env!("OUT_DIR"), "/shaders.rs"));

/// The SPIR-V bytes of the kernel compiled from `shaders/{name}.comp`, if there is one.
pub fn spirv(name: &str) -> Option<&'static [u8]> {
    SHADERS.iter().find(|(n, _)| *n == name).map(|(_, bytes)| *bytes)
}

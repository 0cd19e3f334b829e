//! BSDFs: evaluation, sampling and densities (twin of `shaders/lib/bsdf.glsl`).

/// Microfacet distribution (placeholder until the BSDF module lands).
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Distribution {
    /// Beckmann.
    Beckmann = 0,
    /// GGX.
    Ggx = 1,
}

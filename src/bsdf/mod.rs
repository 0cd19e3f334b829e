//! BSDFs: evaluation, sampling and densities (twin of `shaders/lib/bsdf.glsl`).

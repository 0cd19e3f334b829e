//! Warps from the unit square to directions and points (twin of `shaders/lib/sampling.glsl`).

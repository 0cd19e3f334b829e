// Adjoint kernel with adaptive pixel sampling and attached sampling (issue 34), deterministic:
// adjoint_adaptive_attached.comp, its gradients in 64-bit fixed point.
#version 460
#extension GL_EXT_scalar_block_layout : require
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require
#extension GL_EXT_shader_atomic_int64 : require
#define GRAD_MODE GRAD_MODE_FIXED
#define PIXEL_SELECT 1
#define ATTACHED 1
#include "kernel.glsl"

// Adjoint kernel with adaptive pixel sampling and attached sampling (issue 34): adjoint_adaptive.comp's
// pixels from the alias table, adjoint_attached.comp's sums (Γ in the primal pass, Φ in the replay).
#version 460
#extension GL_EXT_scalar_block_layout : require
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_vote : require
#extension GL_KHR_shader_subgroup_arithmetic : require
#define GRAD_MODE GRAD_MODE_FLOAT
#define PIXEL_SELECT 1
#define ATTACHED 1
#include "kernel.glsl"

// Adjoint kernel with attached sampling (issue 34): fused primal + replay as adjoint.comp, the
// primal pass also summing Γ and the replay recovering each vertex's outgoing-ray derivative.
#version 460
#extension GL_EXT_scalar_block_layout : require
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_vote : require
#extension GL_KHR_shader_subgroup_arithmetic : require
#define GRAD_MODE GRAD_MODE_FLOAT
#define ATTACHED 1
#include "kernel.glsl"

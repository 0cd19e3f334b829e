// Adjoint kernel: fused primal + replay, gradients by float compare-and-swap with subgroup reduction.
#version 460
#extension GL_EXT_scalar_block_layout : require
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_vote : require
#extension GL_KHR_shader_subgroup_arithmetic : require
#define GRAD_MODE GRAD_MODE_FLOAT
#include "kernel.glsl"

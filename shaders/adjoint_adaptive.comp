// Adjoint kernel with adaptive pixel sampling (ALGORITHMS.md §6): float atomics, pixels from the alias table.
#version 460
#extension GL_EXT_scalar_block_layout : require
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_vote : require
#extension GL_KHR_shader_subgroup_arithmetic : require
#define GRAD_MODE GRAD_MODE_FLOAT
#define PIXEL_SELECT 1
#include "kernel.glsl"

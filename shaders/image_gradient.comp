// Forward-mode kernel: fused primal + replay, ∂(pixel)/∂θ for one parameter, accumulated per pixel.
#version 460
#extension GL_EXT_scalar_block_layout : require
#define GRAD_MODE GRAD_MODE_FORWARD
#include "kernel.glsl"

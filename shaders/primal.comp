// Primal kernel: paths of pixels × samples, added to the accumulation image (shaders/kernel.glsl).
#version 460
#extension GL_EXT_scalar_block_layout : require
#define GRAD_MODE GRAD_MODE_NONE
#include "kernel.glsl"

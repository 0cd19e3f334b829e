// Forward-mode kernel with attached sampling (issue 34): image_gradient.comp's fused primal +
// replay carrying adjoint_attached.comp's sums (Γ, Φ). Those sum the channels weighted by δL, so
// the host runs it once per channel c with the adjoint image e_c: channel c's derivative is the
// sum of the three components this kernel accumulates.
#version 460
#extension GL_EXT_scalar_block_layout : require
#define GRAD_MODE GRAD_MODE_FORWARD
#define ATTACHED 1
#include "kernel.glsl"

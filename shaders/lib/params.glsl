// Gradient scatter: every GRAD term of the replay goes through param_grad (ARCHITECTURE decision 5).
//
// The including kernel defines GRAD_MODE: GRAD_MODE_FLOAT reduces across the subgroup when all
// lanes target the same value (one atomic per subgroup) and adds per lane otherwise;
// GRAD_MODE_FIXED adds 64-bit fixed-point integers, so any order gives the same bits;
// GRAD_MODE_FORWARD keeps the derivative of this sample's radiance by the parameter values in
// [forward_begin, forward_end) (tangent 1 on each) in `forward_derivative`.
#ifndef PATHGRAD_PARAMS_GLSL
#define PATHGRAD_PARAMS_GLSL

#include "abi.glsl"

#if GRAD_MODE == GRAD_MODE_FLOAT
layout(set = 0, binding = BINDING_GRADS, scalar) buffer GradBuf { float grads[]; };
#elif GRAD_MODE == GRAD_MODE_FIXED
layout(set = 0, binding = BINDING_GRADS_FIXED, scalar) buffer GradFixedBuf { int64_t grads_fixed[]; };
#endif

// Forward mode: ∂L/∂θ of the sample being replayed, per image channel.
vec3 forward_derivative = vec3(0.0);

// Adds Σ_c by_channel[c] to the gradient of parameter value `offset` (by_channel keeps the image
// channel each part came from, for forward mode).
void param_grad(uint offset, vec3 by_channel) {
#if GRAD_MODE == GRAD_MODE_FORWARD
    if (offset >= globals.forward_begin && offset < globals.forward_end) forward_derivative += by_channel;
#elif GRAD_MODE == GRAD_MODE_FLOAT || GRAD_MODE == GRAD_MODE_FIXED
    float value = by_channel.x + by_channel.y + by_channel.z;
    if (value == 0.0) return;
#if GRAD_MODE == GRAD_MODE_FLOAT
    if (subgroupAllEqual(offset)) {
        float total = subgroupAdd(value);
        if (subgroupElect()) atomicAdd(grads[offset], total);
    } else {
        atomicAdd(grads[offset], value);
    }
#else
    int64_t add = int64_t(round(value * globals.fixed_scale));
    int64_t before = atomicAdd(grads_fixed[offset], add);
    int64_t after = before + add;
    // Two's-complement overflow: the operands agree in sign and the result does not.
    if (((before ^ after) & (add ^ after)) < 0l) raise_status(STATUS_FIXED_OVERFLOW);
#endif
#endif
}

// An RGB parameter at `offset`: channel c of the image depends only on value c.
void param_grad_rgb(uint offset, vec3 by_channel) {
    param_grad(offset, vec3(by_channel.x, 0.0, 0.0));
    param_grad(offset + 1u, vec3(0.0, by_channel.y, 0.0));
    param_grad(offset + 2u, vec3(0.0, 0.0, by_channel.z));
}

#endif

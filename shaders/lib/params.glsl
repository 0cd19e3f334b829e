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
// The float gradient's bits: added to by compare-and-swap (atomic_add_float below).
layout(set = 0, binding = BINDING_GRADS, scalar) buffer GradBuf { uint grad_bits[]; };
#elif GRAD_MODE == GRAD_MODE_FIXED
layout(set = 0, binding = BINDING_GRADS_FIXED, scalar) buffer GradFixedBuf { int64_t grads_fixed[]; };
#endif

// Forward mode: ∂L/∂θ of the sample being replayed, per image channel.
vec3 forward_derivative = vec3(0.0);

#if GRAD_MODE == GRAD_MODE_FLOAT
// atomicAdd on a float by compare-and-swap. Native float atomics (SPV_EXT_shader_atomic_float_add)
// are an extension that Debian's SPIRV-Tools 2023.1 optimiser does not know, and it then skips
// most of its passes for the whole module: the specialised adjoint kept 6 000 unpromoted
// variables and was 3× the size of the fixed-point one. lavapipe lowers a float atomicAdd to a
// compare-and-swap loop anyway.
void atomic_add_float(uint offset, float value) {
    uint expected = grad_bits[offset];
    for (uint attempt = 0u; attempt < 0xFFFFFFFFu; attempt++) {
        uint seen = atomicCompSwap(grad_bits[offset], expected, floatBitsToUint(uintBitsToFloat(expected) + value));
        if (seen == expected) break;
        expected = seen;
    }
}
#endif

// Adds Σ_c by_channel[c] to the gradient of parameter value `offset` (by_channel keeps the image
// channel each part came from, for forward mode).
void param_grad(uint offset, vec3 by_channel) {
#if GRAD_MODE == GRAD_MODE_FORWARD
    if (offset >= globals.forward_begin && offset < globals.forward_end) forward_derivative += by_channel;
#elif GRAD_MODE == GRAD_MODE_FLOAT || GRAD_MODE == GRAD_MODE_FIXED
    float value = by_channel.x + by_channel.y + by_channel.z;
    if (value == 0.0) return;
#if GRAD_MODE == GRAD_MODE_FLOAT
    // When the whole subgroup adds to one value, one lane adds the subgroup's sum; either way the
    // adds go through one compare-and-swap loop (one inlined copy for the driver to compile).
    float amount = value;
    bool adds = true;
    if (subgroupAllEqual(offset)) {
        amount = subgroupAdd(value);
        adds = subgroupElect();
    }
    if (adds) atomic_add_float(offset, amount);
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

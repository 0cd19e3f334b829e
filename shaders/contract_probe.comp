// Test probe: every contract value as the kernels see it (the macros build.rs defines from
// src/contract/), read back and compared bit for bit with the Rust constants (tests/it/twins.rs).
#version 460
#extension GL_EXT_scalar_block_layout : require
#include <generated/contract.glsl>

layout(local_size_x = 1) in;
// Output: CONTRACT_UINT_COUNT words, then the bits of CONTRACT_FLOAT_COUNT floats.
layout(set = 0, binding = BINDING_PROBE_OUT, scalar) writeonly buffer ProbeOut { uint probe_out[]; };

void main() {
    const uint uints[CONTRACT_UINT_COUNT] = CONTRACT_UINTS;
    const float floats[CONTRACT_FLOAT_COUNT] = CONTRACT_FLOATS;
    for (uint i = 0u; i < CONTRACT_UINT_COUNT; i++) probe_out[i] = uints[i];
    for (uint i = 0u; i < CONTRACT_FLOAT_COUNT; i++) probe_out[CONTRACT_UINT_COUNT + i] = floatBitsToUint(floats[i]);
}

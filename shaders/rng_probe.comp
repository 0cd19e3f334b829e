// Test probe: Philox outputs for a list of (counter, key) inputs, read back and compared with src/rng.rs.
#version 460
#extension GL_EXT_scalar_block_layout : require
#include <generated/contract.glsl>
#include "lib/rng.glsl"

layout(local_size_x = WORKGROUP_SIZE) in;
// Input: 6 words per case (counter c0..c3, key k0, k1). Output: 4 raw words then 4 floats' bits.
layout(set = 0, binding = BINDING_PROBE_IN, scalar) readonly buffer ProbeIn { uint probe_in[]; };
layout(set = 0, binding = BINDING_PROBE_OUT, scalar) writeonly buffer ProbeOut { uint probe_out[]; };
PUSH_CasePush;

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= case_count) return;
    uvec4 c = uvec4(probe_in[6 * i], probe_in[6 * i + 1], probe_in[6 * i + 2], probe_in[6 * i + 3]);
    uvec2 k = uvec2(probe_in[6 * i + 4], probe_in[6 * i + 5]);
    uvec4 r = philox4x32_10(c, k);
    for (uint j = 0u; j < 4u; j++) {
        probe_out[8 * i + j] = r[j];
        probe_out[8 * i + 4 + j] = floatBitsToUint(u32_to_unit_f32(r[j]));
    }
}

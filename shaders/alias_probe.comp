// Test probe: the pixels adaptive sampling draws for samples k = 0..n−1, compared with src/adaptive.rs.
#version 460
#extension GL_EXT_scalar_block_layout : require
#include <generated/contract.glsl>
#include "lib/alias.glsl"

layout(local_size_x = WORKGROUP_SIZE) in;
layout(set = 0, binding = BINDING_PROBE_OUT, scalar) writeonly buffer ProbeOut { uint probe_out[]; };
// The gradient key, the table's size and the number of samples.
PUSH_AliasProbePush;

void main() {
    uint k = gl_GlobalInvocationID.y * gl_NumWorkGroups.x * WORKGROUP_SIZE + gl_GlobalInvocationID.x;
    if (k >= sample_count) return;
    probe_out[k] = select_pixel(key, table_size, k);
}

// Primal kernel: one path per pixel for one sample index, added to the accumulation image.
#version 460
#extension GL_EXT_scalar_block_layout : require
#include "integrator.glsl"

layout(local_size_x = WORKGROUP_SIZE) in;
layout(set = 0, binding = BINDING_ACCUM, scalar) buffer AccumBuf { float accum[]; };
layout(push_constant) uniform Push { uint sample_index; };

void main() {
    uint pixel = gl_GlobalInvocationID.y * gl_NumWorkGroups.x * WORKGROUP_SIZE + gl_GlobalInvocationID.x;
    if (pixel >= globals.width * globals.height) return;
    vec3 radiance = trace_path(false, pixel, sample_index, vec3(0.0), vec3(0.0));
    accum[3u * pixel] += radiance.x;
    accum[3u * pixel + 1u] += radiance.y;
    accum[3u * pixel + 2u] += radiance.z;
}

// Test probe: closest hit and shadow any-hit of a list of rays through lib/bvh.glsl, read back by
// tests/it/bvh_embree.rs and compared with src/bvh.rs (its twin) and Embree.
#version 460
#extension GL_EXT_scalar_block_layout : require
#include "lib/bvh.glsl"

// Bindings used: GLOBALS (node count, node and triangle addresses), STATUS, PROBE_IN, PROBE_OUT.

layout(local_size_x = WORKGROUP_SIZE) in;
// Input, 8 floats per ray: origin.xyz, tmin, dir.xyz, tmax (both queries use [tmin, tmax]).
// Output, 8 words per ray: t, slot, b1, b2 (floats' bits except slot), closest-hit flag,
// occluded flag, burn state, 0. A miss writes t = b1 = b2 = 0 and slot = 0.
layout(set = 0, binding = BINDING_PROBE_IN, scalar) readonly buffer ProbeIn { float probe_in[]; };
layout(set = 0, binding = BINDING_PROBE_OUT, scalar) writeonly buffer ProbeOut { uint probe_out[]; };
// `queries`: bit 0 runs the closest-hit query, bit 1 the occlusion query (a query not run reports 0).
// `burn`: loop iterations spent before tracing, so a test can make lavapipe's loop budget
// (PLATFORM.md §6.1) run out at any chosen step of a traversal; 0 in ordinary use.
PUSH_BvhProbePush;

void main() {
    bvh_init();
    uint i = gl_GlobalInvocationID.y * gl_NumWorkGroups.x * WORKGROUP_SIZE + gl_GlobalInvocationID.x;
    if (i >= ray_count) return;
    vec3 origin = vec3(probe_in[8u * i], probe_in[8u * i + 1u], probe_in[8u * i + 2u]);
    float tmin = probe_in[8u * i + 3u];
    vec3 dir = vec3(probe_in[8u * i + 4u], probe_in[8u * i + 5u], probe_in[8u * i + 6u]);
    float tmax = probe_in[8u * i + 7u];
    // xorshift32: its state is written out, so the loop cannot be removed.
    uint x = i + 1u;
    for (uint k = 0u; k < burn; k++) {
        x ^= x << 13;
        x ^= x >> 17;
        x ^= x << 5;
    }
    Ray ray = make_ray(origin, dir);
    Hit hit = Hit(0.0, 0u, 0.0, 0.0, false);
    if ((queries & 1u) != 0u) hit = bvh_closest_hit(ray, tmin, tmax);
    bool occluded = (queries & 2u) != 0u && bvh_occluded(ray, tmin, tmax);
    probe_out[8u * i] = floatBitsToUint(hit.t);
    probe_out[8u * i + 1u] = hit.slot;
    probe_out[8u * i + 2u] = floatBitsToUint(hit.b1);
    probe_out[8u * i + 3u] = floatBitsToUint(hit.b2);
    probe_out[8u * i + 4u] = hit.valid ? 1u : 0u;
    probe_out[8u * i + 5u] = occluded ? 1u : 0u;
    probe_out[8u * i + 6u] = x;
    probe_out[8u * i + 7u] = 0u;
}

// Body of the fused adjoint kernels (ARCHITECTURE decision 6): each invocation runs one path in
// primal mode for its radiance L, then replays it in adjoint mode from L. Nothing per path is
// stored, so memory is independent of path length and spp. The including .comp sets GRAD_MODE.
#ifndef PATHGRAD_REPLAY_GLSL
#define PATHGRAD_REPLAY_GLSL

#include "integrator.glsl"

layout(local_size_x = WORKGROUP_SIZE) in;
layout(set = 0, binding = BINDING_ADJOINT, scalar) readonly buffer AdjointBuf { float adjoint_image[]; };
#if GRAD_MODE == GRAD_MODE_FORWARD
layout(set = 0, binding = BINDING_ACCUM, scalar) buffer AccumBuf { float accum[]; };
#endif
layout(push_constant) uniform Push { uint sample_index; };

// A replay may leave this much radiance (relative to the path's, plus a floor): the primal sums
// its terms and the replay subtracts the same terms in the same order (ALGORITHMS.md §3.3).
#define REPLAY_RESIDUAL_TOLERANCE 1e-5

void main() {
    uint pixel = gl_GlobalInvocationID.y * gl_NumWorkGroups.x * WORKGROUP_SIZE + gl_GlobalInvocationID.x;
    if (pixel >= globals.width * globals.height) return;
    vec3 total = trace_path(false, pixel, sample_index, vec3(0.0), vec3(0.0));
    vec3 adj = vec3(adjoint_image[3u * pixel], adjoint_image[3u * pixel + 1u], adjoint_image[3u * pixel + 2u]) * globals.adjoint_scale;
    vec3 left = trace_path(true, pixel, sample_index, adj, total);
    if (any(greaterThan(abs(left), REPLAY_RESIDUAL_TOLERANCE * (abs(total) + vec3(1e-6))))) raise_status(STATUS_REPLAY_RESIDUAL);
#if GRAD_MODE == GRAD_MODE_FORWARD
    accum[3u * pixel] += forward_derivative.x;
    accum[3u * pixel + 1u] += forward_derivative.y;
    accum[3u * pixel + 2u] += forward_derivative.z;
#endif
}

#endif

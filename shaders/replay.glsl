// Body of the fused adjoint kernels (ARCHITECTURE decision 6): each invocation runs one path in
// primal mode for its radiance L, then replays it in adjoint mode from L. Nothing per path is
// stored, so memory is independent of path length and spp. The including .comp sets GRAD_MODE,
// and PIXEL_SELECT = 1 for adaptive pixel sampling (ALGORITHMS.md §6): invocation i of dispatch s
// is then the global sample k = s·W·H + i, whose pixel p(k) is drawn from the alias table and whose
// path uses k as its sample index, so paths landing in the same pixel have distinct counters.
#ifndef PATHGRAD_REPLAY_GLSL
#define PATHGRAD_REPLAY_GLSL

#ifndef PIXEL_SELECT
#define PIXEL_SELECT 0
#endif

#include "integrator.glsl"
#if PIXEL_SELECT
#if GRAD_MODE == GRAD_MODE_FORWARD
#error "adaptive pixel selection serves the reverse-mode kernels only"
#endif
#include "lib/alias.glsl"
#endif

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
    uint index = gl_GlobalInvocationID.y * gl_NumWorkGroups.x * WORKGROUP_SIZE + gl_GlobalInvocationID.x;
    uint pixels = globals.width * globals.height;
    if (index >= pixels) return;
#if PIXEL_SELECT
    uint path_sample = sample_index * pixels + index;
    uint pixel = select_pixel(uvec2(globals.key0, globals.key1), pixels, path_sample);
#else
    uint path_sample = sample_index;
    uint pixel = index;
#endif
    vec3 total = trace_path(false, pixel, path_sample, vec3(0.0), vec3(0.0));
    vec3 adj = vec3(adjoint_image[3u * pixel], adjoint_image[3u * pixel + 1u], adjoint_image[3u * pixel + 2u]) * globals.adjoint_scale;
    vec3 left = trace_path(true, pixel, path_sample, adj, total);
    if (any(greaterThan(abs(left), REPLAY_RESIDUAL_TOLERANCE * (abs(total) + vec3(1e-6))))) raise_status(STATUS_REPLAY_RESIDUAL);
#if GRAD_MODE == GRAD_MODE_FORWARD
    accum[3u * pixel] += forward_derivative.x;
    accum[3u * pixel + 1u] += forward_derivative.y;
    accum[3u * pixel + 2u] += forward_derivative.z;
#endif
}

#endif

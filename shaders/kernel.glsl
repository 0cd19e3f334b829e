// The scheduler of every render kernel: which paths a lane traces, in which order, and where
// their results go. The including .comp sets GRAD_MODE (lib/params.glsl) and PIXEL_SELECT.
//
// Work comes in items taken from a counter (`work_next`), one lane at a time, so no lane or
// thread idles while another has work left (lavapipe's thread pool splits a dispatch in fixed
// halves; GPUs retire lanes unevenly). An item is one pixel of one view and `sample_count`
// consecutive samples from `sample_begin` — the views one after another, pixels walking each in
// TILE_SIZE² tiles, so a SIMD batch traces neighbouring pixels — or, with PIXEL_SELECT = 1
// (adaptive pixel sampling, ALGORITHMS.md §6), one global sample k = sample_begin + item whose
// (view, pixel) is drawn from the alias table over every view's pixels and whose path uses k as
// its sample index. The image and adjoint buffers hold the views' pixels one view after another.
// A lane's next path takes its first step in the iteration right after its current one ends (path
// regeneration), so a batch no longer waits for its longest path. Each item is traced by one lane
// in sample order and written only by it, so the result is bitwise the same whichever lane takes
// it: the same seed gives the same image.
//
// Fused adjoint kernels (ARCHITECTURE decision 6) run each sample's primal path for its radiance
// L, then replay it in adjoint mode from L; nothing per path is stored, so memory is independent
// of path length and spp. On a driver with a loop budget (lavapipe before Mesa 25, PLATFORM.md
// §6.1) the host sets `lane_items` = 1 and `sample_count` = 1: one path per invocation, as the
// budget needs.
#ifndef PATHGRAD_KERNEL_GLSL
#define PATHGRAD_KERNEL_GLSL

#ifndef PIXEL_SELECT
#define PIXEL_SELECT 0
#endif

#include "integrator.glsl"
#if PIXEL_SELECT
#if GRAD_MODE != GRAD_MODE_FLOAT && GRAD_MODE != GRAD_MODE_FIXED
#error "adaptive pixel selection serves the reverse-mode kernels only"
#endif
#include "lib/alias.glsl"
#endif

// Reverse-mode kernels over pixels can also render a gradient step's pass 1: with
// `globals.primal_only` set, each primal path's radiance goes to the accumulation image and no
// path is replayed — the same loop and the same sums as the primal kernel, so a first gradient
// compiles one kernel instead of two.
#if (GRAD_MODE == GRAD_MODE_FLOAT || GRAD_MODE == GRAD_MODE_FIXED) && !PIXEL_SELECT
#define PRIMAL_ON_REVERSE 1
#else
#define PRIMAL_ON_REVERSE 0
#endif

layout(local_size_x = WORKGROUP_SIZE) in;
#if ADJOINT_KERNEL
layout(set = 0, binding = BINDING_ADJOINT, scalar) readonly buffer AdjointBuf { float adjoint_image[]; };
#endif
#if GRAD_MODE == GRAD_MODE_NONE || GRAD_MODE == GRAD_MODE_FORWARD || PRIMAL_ON_REVERSE
layout(set = 0, binding = BINDING_ACCUM, scalar) buffer AccumBuf { float accum[]; };
#endif
layout(set = 0, binding = BINDING_WORK, scalar) coherent buffer WorkBuf { uint work_next; };
PUSH_KernelPush;  // sample_begin, sample_count, item_count, lane_items (src/contract/structs.rs)


// The view and pixel (row-major within the view) of item `item`, false for a tile position
// outside the image.
bool item_pixel(uint item, out uint view, out uint pixel) {
    uint pixels = globals.width * globals.height;
#if PIXEL_SELECT
    uint drawn = select_pixel(uvec2(globals.key0, globals.key1), globals.view_count * pixels, sample_begin + item);
    view = drawn / pixels;
    pixel = drawn % pixels;
    return true;
#else
    uint tiles_x = (globals.width + TILE_SIZE - 1u) / TILE_SIZE;
    uint per_view = tiles_x * ((globals.height + TILE_SIZE - 1u) / TILE_SIZE) * TILE_SIZE * TILE_SIZE;
    view = item / per_view;
    item %= per_view;
    uint tile = item / (TILE_SIZE * TILE_SIZE);
    uint within = item % (TILE_SIZE * TILE_SIZE);
    uint x = (tile % tiles_x) * TILE_SIZE + within % TILE_SIZE;
    uint y = (tile / tiles_x) * TILE_SIZE + within / TILE_SIZE;
    pixel = y * globals.width + x;
    return x < globals.width && y < globals.height;
#endif
}

void main() {
    bvh_init();
    PathState st;
    uint sample_index = 0u;   // of the path in flight
    uint samples_left = 0u;   // of the item in flight, the one in flight included
    uint taken = 0u;
    bool in_flight = false;
    vec3 sum = vec3(0.0);     // the item's radiance (primal) or derivative (forward), in sample order
    vec3 total = vec3(0.0);   // the primal radiance of the path being replayed (adjoint kernels)
#if ATTACHED
    Row6 total_gamma = ROW6_ZERO;   // the primal path's Γ, where its replay starts (attached kernels)
#endif
    // Every path starts at the top of an iteration, from these: one inlined path_begin (its camera
    // loads and random numbers) serves a new item, its next sample and a replay alike.
    bool begin = false;
    bool begin_adjoint = false;
    uint begin_view = 0u;
    uint begin_pixel = 0u;
    vec3 begin_adj = vec3(0.0);
    // The flag is set only where the loop ends for its own reason, so a driver's silent loop
    // truncation (PLATFORM.md §6.1) is reported; the bound is never reached otherwise.
    bool finished = false;
    for (uint iteration = 0u; iteration < 0xFFFFFFFFu; iteration++) {
        if (!in_flight) {
            if (taken >= lane_items) { finished = true; break; }
            uint item = atomicAdd(work_next, 1u);
            if (item >= item_count) { finished = true; break; }
            taken++;
            if (!item_pixel(item, begin_view, begin_pixel)) continue;
#if PIXEL_SELECT
            sample_index = sample_begin + item;
#else
            sample_index = sample_begin;
#endif
            samples_left = sample_count;
            sum = vec3(0.0);
            begin = true;
            begin_adjoint = false;
            in_flight = true;
        }
        if (begin) {
#if ATTACHED
            // The primal pass weights Γ by δL: it reads the pixel's adjoint radiance too.
            uint at_begin = 3u * (begin_view * globals.width * globals.height + begin_pixel);
            // (A gradient step's pass 1 on this kernel binds no adjoint image: δL is not read there.)
            vec3 adj_begin = begin_adjoint ? begin_adj
                : (globals.primal_only != 0u ? vec3(0.0)
                   : vec3(adjoint_image[at_begin], adjoint_image[at_begin + 1u], adjoint_image[at_begin + 2u]) * globals.adjoint_scale);
            st = path_begin(begin_view, begin_pixel, sample_index, begin_adjoint, adj_begin, total);
            if (begin_adjoint) st.gamma = total_gamma;
#else
            st = path_begin(begin_view, begin_pixel, sample_index, begin_adjoint, begin_adjoint ? begin_adj : vec3(0.0), total);
#endif
            begin = false;
        }
        if (!path_step(st)) continue;
        uint view = st.view;
        uint pixel = st.pixel;
        uint at = 3u * (view * globals.width * globals.height + pixel);  // in the image buffers
#if ADJOINT_KERNEL
        if (!st.adjoint && !(PRIMAL_ON_REVERSE != 0 && globals.primal_only != 0u)) {
            total = st.radiance;
#if ATTACHED
            total_gamma = st.gamma;
#endif
            begin_adj = vec3(adjoint_image[at], adjoint_image[at + 1u], adjoint_image[at + 2u]) * globals.adjoint_scale;
            begin_adjoint = true;
            begin_view = view;
            begin_pixel = pixel;
            begin = true;
            continue;
        }
        if (st.adjoint && any(greaterThan(abs(st.radiance), REPLAY_RESIDUAL_TOLERANCE * (abs(total) + vec3(1e-6))))) raise_status(STATUS_REPLAY_RESIDUAL);
#endif
#if GRAD_MODE == GRAD_MODE_NONE
        sum += st.radiance;
#elif GRAD_MODE == GRAD_MODE_FORWARD
        sum += forward_derivative;
        forward_derivative = vec3(0.0);
#elif PRIMAL_ON_REVERSE
        if (!st.adjoint) sum += st.radiance;
#endif
        samples_left--;
        if (samples_left > 0u) {
            sample_index++;
            begin_adjoint = false;
            begin_view = view;
            begin_pixel = pixel;
            begin = true;
            continue;
        }
        in_flight = false;
#if GRAD_MODE == GRAD_MODE_NONE || GRAD_MODE == GRAD_MODE_FORWARD
        accum[at] += sum.x;
        accum[at + 1u] += sum.y;
        accum[at + 2u] += sum.z;
#elif PRIMAL_ON_REVERSE
        if (globals.primal_only != 0u) {
            accum[at] += sum.x;
            accum[at + 1u] += sum.y;
            accum[at + 2u] += sum.z;
        }
#endif
    }
    if (!finished) raise_status(STATUS_LOOP_BUDGET);
}

#endif

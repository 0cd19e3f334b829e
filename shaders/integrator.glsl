// The one path loop (ALGORITHMS.md §3.1, §5.4): BSDF sampling, next-event estimation on area
// emitters, the environment (constant or a map) and lights without area, MIS and Russian
// roulette, in two strategies that share every line but the technique choice and the MIS
// denominators. Twin: src/cpu/path.rs, phase by phase.
//
// Strategy BSDF (plain PRB) samples directions from the BSDF and weights emitter hits and NEE with
// the power heuristic. Strategy DIFF (Su & Gkioulekas) makes one capable vertex — a material whose
// roughness or blend weight is the target parameter — the differential vertex with probability q,
// sampling the BSDF's derivative there; every contribution is divided by the mixture density of
// all placements, carried as the running sums w1, w2 (§5.2) with the Appendix-B NEE weights (§5.3),
// or (PLACEMENT_POWER) weighted by the power heuristic over the placements, which needs two more
// scalars, v1 and the chosen vertex's term (§5.7). After each update β, w1, w2 and the previous
// vertex's sum are divided by w1 + w2 (§5.6), so a vertex starts with w1 + w2 = 1. With no capable
// vertex DIFF is BSDF sampling with the balance heuristic (power placements: the power heuristic).
// With several targets (F2_HERO, §5.8) each path draws a hero target at its camera vertex and only
// vertices capable for it may become the differential vertex; w1 and the per-target w2 sums cover
// every target weighted by its probability, so the mixture is over all heroes' placements.
//
// The loop is written as one step per vertex on a `PathState` (path_begin, path_step), so the
// kernel's scheduler (shaders/kernel.glsl) can start a lane's next path the moment its current one
// ends instead of idling until the longest path of its SIMD batch is done.
//
// Primal mode gathers the path's radiance L. Adjoint mode (PRB, ALGORITHMS.md §3.3) replays the
// same path starting from that L and subtracts each contribution where the primal added it, so
// `radiance` always holds the radiance still to arrive along the suffix; the GRAD terms of a step
// are gathered into GradTerms and scattered δL-weighted through the one param_grad site. What is
// left at the end must be 0 up to rounding. Adjoint-only work sits in `if (adjoint)`; in kernels
// without a gradient (GRAD_MODE_NONE) it is compiled out. Optional parts (NEE, environment,
// strategies, material kinds, parameter kinds) are guarded by HAS(F_…), see lib/features.glsl.
//
// Random numbers are addressed, never consumed: vertex v reads block 0 (emitter choice and point),
// block 1 (lobe, direction, technique) and block 2 (signed part, roulette) of stream MAIN
// (ALGORITHMS.md §2.3), so a replay of the path recomputes exactly the same draws.
#ifndef PATHGRAD_INTEGRATOR_GLSL
#define PATHGRAD_INTEGRATOR_GLSL

#ifndef GRAD_MODE
#define GRAD_MODE GRAD_MODE_NONE
#endif

#include "lib/rng.glsl"
#include "lib/surface.glsl"
#include "lib/emitter.glsl"
#include "lib/differential.glsl"
#include "lib/medium.glsl"

// Attached sampling (issue 34, src/attached.rs): the kernels that define ATTACHED 1 also carry,
// per path, the primal pass's Jacobian J̃ from the camera ray, the log-weight rows S per channel
// and Γ (the replay: Φ) — constant memory whatever the path's length and the spp.
#ifndef ATTACHED
#define ATTACHED 0
#endif
#if ATTACHED
#include "lib/attached.glsl"
#endif


// Whether the differential vertex on material `m` samples the derivative by α_v: `m` is a rough
// conductor or dielectric whose α_v, a parameter apart from its α_u, is the target.
bool material_target_v(uint m) {
    uint tag = materials[m].tag;
    uint pv = materials[m].p_alpha_v;
    return HAS(F_ANISOTROPIC) && (tag == MAT_ROUGH_CONDUCTOR || tag == MAT_ROUGH_DIELECTRIC)
        && pv != materials[m].p_alpha && pv >= globals.diff_begin && pv < globals.diff_end;
}

// Whether the differential strategy may place its differential vertex on material `m`: its
// roughness (rough conductor, dielectric or plastic; an anisotropic one's α_u or α_v) or weight
// (blend) is the target parameter.
bool material_capable(uint m) {
    uint tag = materials[m].tag;
    uint p = (tag == MAT_ROUGH_CONDUCTOR || tag == MAT_ROUGH_DIELECTRIC || tag == MAT_ROUGH_PLASTIC) ? materials[m].p_alpha
        : (tag == MAT_BLEND ? materials[m].p_weight : NO_PARAM);
    return (p >= globals.diff_begin && p < globals.diff_end) || material_target_v(m);
}

// Several targets (F2_HERO, ALGORITHMS.md §5.8): the index of the hero-set target whose parameter
// values hold parameter p, or MAX_HEROES if none does.
uint param_hero(uint p) {
    uvec2 r[MAX_HEROES] = uvec2[MAX_HEROES](globals.hero_range0, globals.hero_range1, globals.hero_range2, globals.hero_range3);
    for (uint k = 0u; k < globals.hero_count; k++) {
        if (p >= r[k].x && p < r[k].y) return k;
    }
    return MAX_HEROES;
}

// Several targets: the target material `m`'s roughness or blend weight belongs to, or MAX_HEROES.
uint material_hero(uint m) {
    uint tag = materials[m].tag;
    uint p = (tag == MAT_ROUGH_CONDUCTOR || tag == MAT_ROUGH_DIELECTRIC || tag == MAT_ROUGH_PLASTIC) ? materials[m].p_alpha
        : (tag == MAT_BLEND ? materials[m].p_weight : NO_PARAM);
    return param_hero(p);
}

// Whether the differential strategy may place its differential vertex in medium `m`: its
// Henyey-Greenstein g is the target parameter (ALGORITHMS.md §8.4).
bool medium_capable(uint m) {
    return media[m].phase == PHASE_HG && media[m].p_g >= globals.diff_begin && media[m].p_g < globals.diff_end;
}

// Several targets: the target medium `m`'s g belongs to, or MAX_HEROES.
uint medium_hero(uint m) {
    return media[m].phase == PHASE_HG ? param_hero(media[m].p_g) : MAX_HEROES;
}

// The differential strategy's running state (ALGORITHMS.md §5.2, §5.7): constant per path,
// whatever its length. After each update everything is rescaled so that w1 + w2 = 1 (§5.6).
struct Mixture {
    bool power;        // power-heuristic placements (PLACEMENT_POWER); else the balance heuristic
    float w1;          // Σ over the capable vertices so far of their placement terms q·w2·p_∂f/p_f
    float w2;          // the density factor of "no differential vertex yet", (1 − q)^(capable vertices)
    float v1;          // Σ of the squared placement terms (power heuristic)
    float chosen;      // the placement term of the chosen differential vertex (power heuristic)
    bool dx_taken;     // the differential vertex has been chosen
    float prev_sum;    // w1 + w2 at the previous vertex before its update, in this vertex's units
    float prev_sq;     // v1 + w2² at the previous vertex before its update, in this vertex's units
    // Several targets (F2_HERO, §5.8): w1 sums the terms of every target weighted by its
    // probability p_k; hero_w2[k] = p_k (1 − q)^(vertices capable for k) and w2 = Σ_k hero_w2[k].
    uint hero;         // the path's hero: index of its target
    vec4 hero_w2;
};

Mixture mixture_new(bool power) {
    return Mixture(power, 0.0, 1.0, 0.0, 0.0, false, 1.0, 1.0, 0u, vec4(0.0));
}

// Several targets: the path's hero, drawn with probabilities hero_p (camera vertex, DIM_HERO),
// and the sums' start, w2 = Σ_k p_k.
void mixture_pick_hero(inout Mixture m, float u) {
    vec4 p = vec4(globals.hero_p0, globals.hero_p1, globals.hero_p2, globals.hero_p3);
    m.hero = globals.hero_count - 1u;
    float cdf = 0.0;
    for (uint k = 0u; k + 1u < globals.hero_count; k++) {
        cdf += p[k];
        if (u < cdf) { m.hero = k; break; }
    }
    m.hero_w2 = p;
    m.w2 = ((p.x + p.y) + p.z) + p.w;
}

// Several targets: next-event estimation's weight at a vertex capable for target `k` (MAX_HEROES:
// none) before its update (§5.8).
float mixture_nee_weight_hero(Mixture m, uint k, float q, float pdf_f, float pdf_d, float p_e, bool delta) {
    if (delta) return 1.0 / (m.w1 + m.w2);
    float a = k < MAX_HEROES ? m.hero_w2[k] : 0.0;
    float qa = k < MAX_HEROES ? q * a : 0.0;
    return 1.0 / (m.w1 + m.w2 + (m.w1 * pdf_f + qa * pdf_d + (a - qa) * pdf_f + (m.w2 - a) * pdf_f) / p_e);
}

// Several targets: the update after a direction was sampled at a vertex capable for target `k`
// (MAX_HEROES: none), as mixture_update.
float mixture_update_hero(inout Mixture m, uint k, float q, float pdf_f, float pdf_d) {
    m.prev_sum = m.w1 + m.w2;
    if (k >= MAX_HEROES) return 1.0;
    float a = m.hero_w2[k];
    m.w1 += q * a * pdf_d / pdf_f;
    m.hero_w2[k] = a * (1.0 - q);
    vec4 h = m.hero_w2;
    m.w2 = ((h.x + h.y) + h.z) + h.w;
    float sum = m.w1 + m.w2;
    if (!(sum > 0.0)) return 0.0;
    m.w1 /= sum;
    m.w2 /= sum;
    m.hero_w2 /= sum;
    m.prev_sum /= sum;
    return sum;
}

// The placement factor of the technique that produced the path so far: the chosen vertex's term,
// or w2 (no differential vertex yet).
float mixture_technique(Mixture m) {
    return m.dx_taken ? m.chosen : m.w2;
}

// v1 + w2²: Σ of the squared placement factors of the path so far.
float mixture_squares(Mixture m) {
    return m.v1 + m.w2 * m.w2;
}

// Next-event estimation's weight at a vertex (before its update) whose BSDF has densities pdf_f,
// pdf_d (p_∂f; pdf_f where not capable) toward an emitter sampled with density p_e (`delta`: a
// light without area), q_here the vertex's decision probability (§5.3, §5.7).
float mixture_nee_weight(Mixture m, float q_here, float pdf_f, float pdf_d, float p_e, bool delta) {
    if (!m.power) {
        if (delta) return 1.0 / (m.w1 + m.w2);
        return 1.0 / (m.w1 + m.w2 + (m.w1 * pdf_f + q_here * m.w2 * pdf_d + (1.0 - q_here) * m.w2 * pdf_f) / p_e);
    }
    if (delta) return mixture_technique(m) / mixture_squares(m);
    float f = pdf_f / p_e;
    float d = q_here * m.w2 * pdf_d / p_e;
    float b = (1.0 - q_here) * m.w2 * pdf_f / p_e;
    return mixture_technique(m) / (mixture_squares(m) + m.v1 * f * f + d * d + b * b);
}

// The update after a direction was sampled at a vertex (`capable`: it may be the differential
// one; `use_dx`: it is) with densities pdf_f, pdf_d: returns the factor w1 + w2 by which the
// throughput must be divided (1 at a vertex that is not capable), or 0 if the sums vanished.
float mixture_update(inout Mixture m, bool capable, bool use_dx, float q, float pdf_f, float pdf_d) {
    m.prev_sum = m.w1 + m.w2;
    m.prev_sq = mixture_squares(m);
    if (!capable) return 1.0;
    float term = q * m.w2 * pdf_d / pdf_f;
    m.w1 += term;
    m.v1 += term * term;
    if (use_dx) m.chosen = term;
    m.w2 *= 1.0 - q;
    float sum = m.w1 + m.w2;
    if (!(sum > 0.0)) return 0.0;
    m.w1 /= sum;
    m.w2 /= sum;
    m.chosen /= sum;
    m.v1 /= sum * sum;
    m.prev_sum /= sum;
    m.prev_sq /= sum * sum;
    return sum;
}

// MIS weight of radiance reached by BSDF sampling from the previous vertex, whose direction had
// density `pdf_f` there and would have had density `pdf_e` under NEE (ALGORITHMS.md §3.1, §5.3,
// §5.7).
float hit_weight(bool diff, bool prev_nee, float pdf_f, float pdf_e, Mixture m) {
    if (m.power) {
        float nee = prev_nee ? m.prev_sq * (pdf_e / pdf_f) * (pdf_e / pdf_f) : 0.0;
        return mixture_technique(m) / (mixture_squares(m) + nee);
    }
    if (!prev_nee) return 1.0;
    if (!diff) return mis_power(pdf_f, pdf_e);
    return 1.0 / (1.0 + m.prev_sum * pdf_e / pdf_f);
}

// Block `block` of the main stream of a path's vertex, under its view's key word `key1`.
vec4 draw_block(uint key1, uint pixel, uint sample_index, uint vertex, uint block) {
    return uniform4(uvec2(globals.key0, key1), pixel, sample_index, vertex, STREAM_MAIN, block, 0u);
}

// Next-event estimation's two uniforms for an environment map's cell at vertex `vertex` (block 2);
// unused, and not drawn, without a map.
vec2 env_cell_uniforms(uint key1, uint pixel, uint sample_index, uint vertex) {
    if (!HAS(F_ENV_MAP)) return vec2(0.0);
    vec4 u = draw_block(key1, pixel, sample_index, vertex, DIM_ENV_CELL / 4u);
    return vec2(u[DIM_ENV_CELL % 4u], u[DIM_ENV_CELL % 4u + 1u]);
}

// What a path segment reaches (path_step).
#define EVENT_ESCAPE 0u
#define EVENT_SURFACE 1u
#define EVENT_MEDIUM 2u
#define EVENT_LOST 3u

// Whether this kernel replays paths at all.
#define ADJOINT_KERNEL (GRAD_MODE != GRAD_MODE_NONE)

// Everything one camera path carries from one vertex to the next.
struct PathState {
    Ray ray;
    vec3 throughput;   // β (ALGORITHMS.md §3.1)
    vec3 radiance;     // L gathered so far (adjoint: the suffix still to arrive)
    vec3 adj;          // δL, the adjoint radiance (adjoint mode)
    uint view;         // index of the request's view
    uint key1;         // the view's Philox key word 1
    uint pixel;        // row-major pixel index within the view
    uint medium;       // the medium the path is in, or NO_MEDIUM (cameras are in vacuum)
    uint sample_index;
    uint vertex;       // index of the vertex the next step finds, from 1 (the random numbers' key)
    uint depth;        // counted interactions before it (Mitsuba's depth, which max_depth caps)
    float prev_pdf_f;  // density with which the previous vertex sampled ray.dir
    Mixture mix;       // the differential strategy's running sums (ALGORITHMS.md §5.2, §5.7)
    bool prev_nee;     // whether NEE at the previous vertex could have found this emitter
    bool adjoint;      // this is the replay of the path (adjoint mode)
#if ATTACHED
    Jac6 jac;          // J̃: the camera ray's perturbation → this ray's (primal)
    Row6 log_r;        // S per channel: Σ ∂ln w·J̃ over the vertices so far (primal)
    Row6 log_g;
    Row6 log_b;
    Row6 gamma;        // Γ (primal), Φ (replay): the derivative by the camera ray / by this ray
    vec3 prev_normal;  // the plane this ray leaves (the camera ray: its own direction)
#endif
};

#if ATTACHED
// A vertex's completed Jacobian for an outgoing direction d_out with ∂/∂d = t_d, ∂/∂n = t_n,
// regularised, with Jacobian noise, from the vertex's STREAM_JACOBIAN block (vertex_jacobian in
// src/cpu/path.rs).
Jac6 attached_vertex_jacobian(PathState st, HitGeometry g, mat3 t_d, mat3 t_n, vec3 ng, vec3 d_out, uint vertex) {
    Jac6 a = jac_completed(hit_jacobian(g, t_d, t_n), st.prev_normal, st.ray.dir, ng, d_out);
    if (globals.jac_noise > 0.0) {
        vec4 u = uniform4(uvec2(globals.key0, st.key1), st.pixel, st.sample_index, vertex, STREAM_JACOBIAN, 0u, 0u);
        a = jac_plus_identity(a, jac_regularisation(globals.jac_noise, u.x, u.y));
    }
    return a;
}
#endif

#if ATTACHED
// Γ plus one contribution: `own` (its derivative by the camera ray) and c (δL ⊙ β ⊙ the
// contribution) times the log-weight rows of the vertices before it.
void attached_contribution(inout PathState st, Row6 own, vec3 c) {
    st.gamma = row_add_scaled(st.gamma, own, 1.0);
    st.gamma = row_add_scaled(st.gamma, st.log_r, c.x);
    st.gamma = row_add_scaled(st.gamma, st.log_g, c.y);
    st.gamma = row_add_scaled(st.gamma, st.log_b, c.z);
}
#endif

// The camera ray of `pixel` of view `view` for sample `sample_index`: a primal path, or (adjoint)
// its replay from the path's radiance `radiance_total` with adjoint radiance `adj_radiance`.
// The camera ray through film point (sx, sy) ∈ [−1, 1]² (+y up), u_lens placing it on a thin
// lens's aperture (twin: camera_ray of src/cpu/path.rs).
Ray camera_ray(ViewCamera cam, float sx, float sy, vec2 u_lens) {
    vec3 through = cam.forward + sx * cam.right + sy * cam.up;
    if (cam.lens == LENS_ORTHOGRAPHIC) return make_ray(cam.origin + sx * cam.right + sy * cam.up, cam.forward);
    if (cam.lens == LENS_THIN) {
        // The pinhole ray meets the plane in focus at through · focus_distance (its forward
        // component is 1); the ray leaves a point of the aperture for that point.
        vec2 disk = sample_concentric_disk(u_lens) * cam.aperture_radius;
        vec3 lens = cam.origin + disk.x * normalize(cam.right) + disk.y * normalize(cam.up);
        vec3 focus = cam.origin + through * cam.focus_distance;
        return make_ray(lens, normalize(focus - lens));
    }
    return make_ray(cam.origin, normalize(through));
}

PathState path_begin(uint view, uint pixel, uint sample_index, bool adjoint, vec3 adj_radiance, vec3 radiance_total) {
    ViewCamera cam = views[view];
    vec4 u_cam = draw_block(cam.key1, pixel, sample_index, 0u, DIM_PIXEL_JITTER / 4u);
    uint px = pixel % globals.width;
    uint py = pixel / globals.width;
    float fx = filter_sample(cam.filter_kind, cam.filter_radius, cam.filter_alpha, px, globals.width, u_cam.x);
    float fy = filter_sample(cam.filter_kind, cam.filter_radius, cam.filter_alpha, py, globals.height, u_cam.y);
    float sx = 2.0 * fx / float(globals.width) - 1.0;
    float sy = 1.0 - 2.0 * fy / float(globals.height);
    PathState st;
    st.ray = camera_ray(cam, sx, sy, u_cam.zw);
    st.throughput = vec3(1.0);
    st.radiance = adjoint ? radiance_total : vec3(0.0);
    st.adj = adj_radiance;
    st.view = view;
    st.key1 = cam.key1;
    st.pixel = pixel;
    st.medium = NO_MEDIUM;
    st.sample_index = sample_index;
    st.vertex = 1u;
    st.depth = 0u;
    st.prev_pdf_f = 0.0;
    st.mix = mixture_new(HAS(F_DIFF) && globals.strategy == STRATEGY_DIFF && globals.diff_placement == PLACEMENT_POWER);
    if (HAS2(F2_HERO) && globals.strategy == STRATEGY_DIFF && globals.hero_count > 0u)
        mixture_pick_hero(st.mix, draw_block(cam.key1, pixel, sample_index, 0u, DIM_HERO / 4u)[DIM_HERO % 4u]);
    st.prev_nee = false;
    st.adjoint = adjoint;
#if ATTACHED
    st.jac = jac_identity();
    st.log_r = ROW6_ZERO;
    st.log_g = ROW6_ZERO;
    st.log_b = ROW6_ZERO;
    st.gamma = ROW6_ZERO;   // the replay's Φ is set by the scheduler (kernel.glsl)
    st.prev_normal = st.ray.dir;
#endif
    return st;
}

// Russian roulette at vertex `vertex` — from depth ≥ rr_depth, the depth being the counted
// interactions before it (ALGORITHMS.md §3.1; vertex − 1 unless null events go uncounted),
// surviving with p = min(max β, 0.95) and β divided by it — then the end of a path whose throughput
// is zero. True if the path goes on. Surface and medium vertices share it.
bool path_survives(inout PathState st, uint vertex) {
    if (st.depth >= globals.rr_depth) {
        float u_rr = draw_block(st.key1, st.pixel, st.sample_index, vertex, DIM_ROULETTE / 4u)[DIM_ROULETTE % 4u];
        float p_rr = min(max_component(st.throughput), 0.95);
        if (!(u_rr < p_rr)) return false;
        st.throughput /= p_rr;
    }
    return max_component(st.throughput) > 0.0;
}

// One vertex of the path: intersection, emitter or environment hit, NEE, BSDF or differential
// sampling, Russian roulette. Returns true when the path has ended.
bool path_step(inout PathState st) {
    bool adjoint = ADJOINT_KERNEL && st.adjoint;
    float sign = adjoint ? -1.0 : 1.0;
    // The strategy is also read at run time, so a kernel with the differential strategy can render a
    // gradient step's pass 1, which uses plain BSDF sampling (kernel.glsl, PRIMAL_ON_REVERSE).
    bool diff = HAS(F_DIFF) && globals.strategy == STRATEGY_DIFF;
    bool hero = diff && HAS2(F2_HERO) && globals.hero_count > 0u;
    bool nee = HAS(F_NEE);
    uint vertex = st.vertex;
    st.vertex = vertex + 1u;
    // Depth counting (Globals::path_flags): st.depth, the counted interactions before this vertex,
    // is what max_depth caps; the random numbers stay keyed by `vertex`. Every interaction counts
    // (path, prb) unless null events go uncounted (volpath): a thindielectric's straight-through
    // transmission or a mask's pass-through. st.depth advances at the end of the step.
    // (Only a kernel with masks, thin dielectrics or media can meet a null event.)
    bool null_free = (HAS(F_MASK) || HAS(F_DELTA) || HAS(F_MEDIA)) && (globals.path_flags & PATH_NULL_UNCOUNTED) != 0u;
    // No counted interaction may follow this vertex: it only gathers what it hits.
    bool last = st.depth + 1u >= globals.max_depth || vertex >= MAX_PATH_VERTICES;
    // An uncounted (null) event may still follow it.
    bool null_ok = null_free && vertex < MAX_PATH_VERTICES;
    // hide_emitters: before the first counted interaction, rays pass through emitting shapes and
    // the environment adds nothing. Only a kernel of such a scene (F2_HIDE_EMITTERS) carries it.
    bool hidden = HAS2(F2_HIDE_EMITTERS) && (globals.path_flags & PATH_HIDE_EMITTERS) != 0u && st.depth == 0u;
    bool counted = true;      // whether this vertex is a bounce
    GradTerms gt = no_grad_terms();
    // BSDF derivative terms of this vertex: (direction, adjoint weight) of NEE and of the sample.
    vec3 grad_wo[2] = vec3[2](vec3(0.0, 0.0, 1.0), vec3(0.0, 0.0, 1.0));
    vec3 grad_adj[2] = vec3[2](vec3(0.0), vec3(0.0));
    // Whether the sampled direction (grad_wo[1]) is a delta lobe's: its value is the sample's.
    bool grad_delta = false;
    bool ended = false;
    Bsdf bsdf;
    vec3 wi = vec3(0.0, 0.0, 1.0);

    // What a surface vertex carries from its NEE query, across the shadow ray's traversal, to the
    // rest of its shading: the vertex, the NEE sample and its unoccluded terms.
    Surface s;
    ShadingFrame frame;
    bool shade = false;       // a surface vertex below the maximum depth
    bool capable = false;
    bool target_v = false;    // an anisotropic roughness's target is α_v (a hero set holds none)
    uint hero_here = MAX_HEROES;  // several targets: the one this vertex is capable for
    EmitterSample es;
    vec3 nee_wo = vec3(0.0, 0.0, 1.0);
    vec3 nee_f = vec3(0.0);
    float nee_w = 0.0;
    float nee_pdf = 0.0;
    vec3 tr = vec3(0.0);      // NEE's transmittance: 0 (occluded or no sample) or 1 (surfaces), ratio tracking (media)
    Ray shadow_ray;
    float shadow_tmax = 0.0;
    uint shadow_medium = NO_MEDIUM;   // where the shadow ray starts: the path's medium, or across a dielectric boundary its shape's
    bool shadow_query = false;
    bool nee_here = false;    // whether this surface vertex estimates next events
    // A medium vertex below the maximum depth carries its NEE sample the same way: the phase
    // function's value, and (both kinds of vertex, kernels with media) the replay's weight of the
    // transmittance, so that one ratio-tracking site serves both.
    bool scatter = false;
    float nee_phase = 0.0;
    vec3 nee_w_tr = vec3(0.0);

    float mask_opacity = 1.0;   // a masked surface's opacity (1: no mask)

    Hit hit;
    uint event;
    float travelled = 0.0;    // from the last vertex to the ray's origin, across null boundaries
    vec3 x_medium = vec3(0.0);
    // Both rays of a vertex go through one traversal site, so the kernel holds one inlined copy of
    // the traversal: pass 0 traces the path's ray and shades up to NEE's shadow query, pass 1 (if
    // the vertex made a query) answers it. In kernels with media both passes cross null boundaries
    // and track through media at the same site (delta tracking for the path, ratio tracking for
    // the shadow ray), and a replay that differentiates media runs pass 2: the shadow ray's nested
    // replay, which needs pass 1's whole transmittance first (ALGORITHMS.md §8).
    [[dont_unroll]] for (uint pass = 0u; pass < 3u; pass++) {
        // ---- intersection: through null boundaries and null collisions to the next event ----
        if (HAS(F_MEDIA)) {
            bool shadow = pass != 0u;
            Ray ray = shadow ? shadow_ray : st.ray;
            uint m = shadow ? shadow_medium : st.medium;
            float remaining = shadow ? shadow_tmax : FLOAT_MAX;
            vec3 end_point = ray.origin + shadow_tmax * ray.dir;
            uint stream = shadow ? STREAM_RATIO_TRACKING : STREAM_DELTA_TRACKING;
            bool replay = shadow ? pass == 2u : adjoint;
            vec3 gw = shadow ? nee_w_tr * tr : st.adj * st.radiance;
            vec3 transmitted = vec3(1.0);
            uint step = 0u;      // tracking steps of this ray
            bool crossed_null = false;   // path counting: an emitter behind a null boundary is seen
            event = EVENT_LOST;
            [[dont_unroll]] for (uint crossings = 0u; crossings <= MAX_NULL_CROSSINGS; crossings++) {
                hit = bvh_closest_hit(ray, 0.0, remaining);
                if (m != NO_MEDIUM) {
                    // A shadow ray's segments each start at 1 and multiply its transmittance.
                    vec3 w = shadow ? vec3(1.0) : st.throughput;
                    float t = track(m, ray, hit.valid ? hit.t : remaining, uvec2(globals.key0, st.key1), st.pixel, st.sample_index, vertex, stream, shadow, step, w, replay, gw);
                    if (shadow) transmitted *= w; else st.throughput = w;
                    if (t >= 0.0) { event = EVENT_MEDIUM; x_medium = ray.origin + t * ray.dir; break; }
                }
                if (!hit.valid) { event = EVENT_ESCAPE; break; }
                Surface sn = surface_at(hit);
                bool skip = !shadow && hidden && (null_free || !crossed_null) && sn.emitter != NO_EMITTER;
                if (materials[sn.material].tag != MAT_NULL && !skip) { event = EVENT_SURFACE; break; }
                // (A hidden emitter's shape is passed as Mitsuba passes it: no medium changes.)
                if (!skip) { m = medium_crossed(sn.interior, sn.ng, ray.dir, m); crossed_null = true; }
                vec3 o = offset_origin(sn.p, sn.ng, ray.dir);
                if (!shadow) travelled += hit.t;
                ray = make_ray(o, ray.dir);
                if (shadow && shadow_tmax < FLOAT_MAX) {
                    remaining = dot(end_point - o, ray.dir);
                    if (!(remaining > 0.0)) { event = EVENT_ESCAPE; break; }
                }
            }
            if (shadow) {
                // Unoccluded: what the media let through; an opaque surface or too many null
                // boundaries: nothing.
                if (pass == 1u) tr = event == EVENT_ESCAPE ? transmitted : vec3(0.0);
                if (pass == 2u || !(adjoint && HAS(G_MEDIUM)) || !(max_component(tr) > 0.0)) break;
                continue;
            }
            st.medium = m;
            shadow_medium = m;
            st.ray = ray;
        } else {
            bool shadow = pass != 0u;
            Ray ray = shadow ? shadow_ray : st.ray;
            Hit h;
            bool lost = false;
            if (HAS2(F2_HIDE_EMITTERS)) {
                // hide_emitters: the path's ray passes through emitting shapes (one traversal site).
                [[dont_unroll]] for (uint crossings = 0u; crossings <= MAX_NULL_CROSSINGS; crossings++) {
                    h = bvh_traverse(ray, 0.0, shadow ? shadow_tmax : FLOAT_MAX, shadow);
                    if (shadow || !hidden || !h.valid) break;
                    Surface se = surface_at(h);
                    if (se.emitter == NO_EMITTER) break;
                    lost = crossings == MAX_NULL_CROSSINGS;
                    travelled += h.t;
                    ray = make_ray(offset_origin(se.p, se.ng, ray.dir), ray.dir);
                }
            } else {
                h = bvh_traverse(ray, 0.0, shadow ? shadow_tmax : FLOAT_MAX, shadow);
            }
            if (shadow) {
                if (!h.valid) tr = vec3(1.0);
                break;
            }
            hit = h;
            st.ray = ray;
            event = lost ? EVENT_LOST : (hit.valid ? EVENT_SURFACE : EVENT_ESCAPE);
        }
        if (event == EVENT_LOST) {
            ended = true;
        } else if (HAS(F_MEDIA) && event == EVENT_MEDIUM) {
            // ---- a real collision in the medium: NEE through media, phase sampling, roulette ----
            if (last || !(max_component(st.throughput) > 0.0)) {
                ended = true;
            } else {
                scatter = true;
                // The differential strategy may place its vertex here if g is its target (§8.4).
                capable = diff && medium_capable(st.medium);
                if (hero) {
                    hero_here = medium_hero(st.medium);
                    capable = hero_here < MAX_HEROES;
                }
                if (nee) {
                    vec4 u_em = draw_block(st.key1, st.pixel, st.sample_index, vertex, DIM_EMITTER_SELECT / 4u);
                    es = sample_emitter(u_em[DIM_EMITTER_SELECT % 4u], vec2(u_em[DIM_EMITTER_POS % 4u], u_em[DIM_EMITTER_POS % 4u + 1u]), env_cell_uniforms(st.key1, st.pixel, st.sample_index, vertex), x_medium);
                    if (es.valid) {
                        vec3 wl;
                        if (HAS(F_LIGHTS) && es.delta) {
                            wl = es.distant ? es.point : normalize(es.point - x_medium);
                            shadow_tmax = es.distant ? FLOAT_MAX : length(es.point - x_medium) * (1.0 - SHADOW_EPSILON);
                            nee_pdf = es.pdf;
                        } else if (HAS(F_ENV) && es.environment) {
                            wl = es.point;
                            nee_pdf = environment_pdf(wl);
                            shadow_tmax = FLOAT_MAX;
                        } else {
                            vec3 to_light = es.point - x_medium;
                            float dist = length(to_light);
                            wl = to_light / dist;
                            nee_pdf = emitter_pdf_solid_angle(dist, dot(es.normal, -wl));
                            shadow_tmax = dist * (1.0 - SHADOW_EPSILON);
                        }
                        nee_phase = phase_eval(st.medium, st.ray.dir, wl);
                        if (nee_pdf > 0.0 && nee_phase > 0.0) {
                            // No phase sample reaches a light without area: NEE alone finds it.
                            if (!diff) {
                                nee_w = (HAS(F_LIGHTS) && es.delta) ? 1.0 : mis_power(nee_pdf, nee_phase);
                            } else if (HAS(F_LIGHTS) && es.delta) {
                                nee_w = hero ? mixture_nee_weight_hero(st.mix, MAX_HEROES, 0.0, 0.0, 0.0, 0.0, true)
                                             : mixture_nee_weight(st.mix, 0.0, 0.0, 0.0, 0.0, true);
                            } else {
                                // Appendix B with the phase function as the vertex's BSDF (§8.4).
                                float pdf_d = capable ? phase_pdf_diff(st.medium, st.ray.dir, wl) : nee_phase;
                                float q_here = capable ? globals.diff_q : 0.0;
                                nee_w = hero ? mixture_nee_weight_hero(st.mix, hero_here, globals.diff_q, nee_phase, pdf_d, nee_pdf, false)
                                             : mixture_nee_weight(st.mix, q_here, nee_phase, pdf_d, nee_pdf, false);
                            }
                            nee_w_tr = st.adj * st.throughput * nee_w * nee_phase * es.radiance / nee_pdf;
                            shadow_ray = make_ray(x_medium, wl);
                            shadow_query = true;
                        }
                    }
                }
            }
        } else if (event == EVENT_ESCAPE) {
            // ---- environment hit ----
            if (HAS(F_ENV) && globals.env_param != NO_PARAM && !hidden) {
                // Attached sampling's NEE leaves the environment to BSDF samples (src/cpu/path.rs).
                float w_b = hit_weight(diff, st.prev_nee && ATTACHED == 0, st.prev_pdf_f, environment_pdf(st.ray.dir), st.mix);
                vec3 le = env_radiance(st.ray.dir);
                st.radiance += sign * (st.throughput * w_b * le);
#if ATTACHED
                {
                    // The environment's own row: δL·β·∂L_e/∂d.
                    vec3 weight = st.adj * st.throughput * w_b;
                    Row6 own = Row6(vec3(0.0), transpose(env_radiance_gradient(st.ray.dir)) * weight);
                    if (adjoint) st.gamma = row_add_scaled(st.gamma, own, -1.0);
                    else attached_contribution(st, row_through(own, st.jac), weight * le);
                }
#endif
                if (HAS(G_ENV)) {
                    gt.hit_param = globals.env_param;
                    gt.hit = st.adj * st.throughput * w_b;
                    gt.env_dir = st.ray.dir;
                }
            }
            ended = true;
        } else {
            s = surface_at(hit);
            vec3 wi_world = -st.ray.dir;

            // ---- emitter hit ----
            float cos_emit = dot(s.ng, wi_world);
            if (HAS(F_EMITTERS) && s.emitter != NO_EMITTER && cos_emit > 0.0) {
                float w_b = hit_weight(diff, st.prev_nee, st.prev_pdf_f, emitter_pdf_solid_angle(travelled + hit.t, cos_emit), st.mix);
                uint p_radiance = emitters[s.emitter].p_radiance;
                st.radiance += sign * (st.throughput * w_b * area_radiance(p_radiance, s.uv));
                if (HAS(G_EMISSION)) { gt.hit_param = p_radiance; gt.hit = st.adj * st.throughput * w_b; gt.hit_uv = s.uv; }
#if ATTACHED
                {
                    // The emitter's own row, δL·β·∂L_e/∂r: a textured radiance varies with the hit
                    // point; the weights of the vertices before depend on the ray.
                    // After a diffuse vertex that sampled emitters, the MIS weight moves with the
                    // ray too: ∂ln w_b = −2(1 − w_b)·∂ln p_e.
                    vec3 weight = st.adj * st.throughput * w_b;
                    vec3 le = area_radiance(p_radiance, s.uv);
                    HitGeometry at = HitGeometry(travelled + hit.t, st.ray.dir, s.ng, s.ng, mat3(0.0));
                    Row6 own = ROW6_ZERO;
                    if (area_textured(p_radiance)) {
                        mat3 slope = area_radiance_slope(p_radiance, s.uv, surface_gradients(hit));
                        own = hit_position_row(at, slope[0] * weight.x + slope[1] * weight.y + slope[2] * weight.z);
                    }
                    if (st.prev_nee) {
                        vec3 c = weight * le;
                        own = row_add_scaled(own, hit_emitter_mis_row(at, w_b), c.x + c.y + c.z);
                    }
                    if (adjoint) st.gamma = row_add_scaled(st.gamma, own, -1.0);
                    else attached_contribution(st, row_through(own, st.jac), weight * le);
                }
#endif
            }
            // ---- mask: the nested BSDF with probability `opacity`, else straight through ----
            // Mitsuba's `mask` samples its null transmission as a delta lobe that counts as a
            // bounce in its `path` and `prb` and not in its volpath family (null_free); the choice
            // is drawn first (u_lobe, rescaled for the nested BSDF as Mitsuba rescales it). In the
            // replay the attached weight opacity or 1 − opacity over its detached value gives the
            // opacity its derivative.
            bool passes = false;
            if (HAS(F_MASK) && (!last || null_ok) && materials[s.material].p_opacity != NO_PARAM) {
                gt.mask = materials[s.material].p_opacity;
                gt.at = tex_at(s);
                mask_opacity = mask_opacity_at(gt.mask, gt.at);
                passes = !(draw_block(st.key1, st.pixel, st.sample_index, vertex, DIM_LOBE / 4u)[DIM_LOBE % 4u] < mask_opacity);
                if (adjoint) gt.opacity = st.adj * st.radiance * (passes ? -1.0 / (1.0 - mask_opacity) : 1.0 / mask_opacity);
            }
            // At the last depth a thindielectric still samples under volpath counting: its
            // straight-through transmission is no bounce (its reflection ends the path below).
            bool thin = materials[s.material].tag == MAT_THIN_DIELECTRIC;
            if (passes) {
                counted = !null_free;
                // An emitter found through the pass counts whole: NEE could not have sampled it.
                st.prev_nee = false;
                if (!path_survives(st, vertex)) {
                    ended = true;
                } else {
                    if (HAS(F_MEDIA)) st.medium = medium_crossed(s.interior, s.ng, st.ray.dir, st.medium);
                    st.ray = make_ray(offset_origin(s.p, s.ng, st.ray.dir), st.ray.dir);
                }
            } else if (last && !(null_ok && thin)) {
                ended = true;
            } else {
                shade = true;
                bsdf = resolve_bsdf(s.material, tex_at(s));
                // A two-sided material seen from the back shades with the flipped normal.
                bool mirrored = HAS(F_TWO_SIDED) && materials[s.material].two_sided != 0u && dot(s.ns, wi_world) < 0.0;
                vec3 ns = mirrored ? -s.ns : s.ns;
                bool mapped = HAS(F_NORMAL_MAP) && materials[s.material].nmap_width > 0u;
                frame = (mapped || (HAS(F_ANISOTROPIC) && material_anisotropic(s.material))) ? tangent_frame(ns, s.ng, s.dpdu)
                                                                                            : shading_frame(ns);
                if (mapped) frame = normal_map_frame(materials[s.material], s, frame, mirrored, wi_world, bsdf);
                wi = to_local(frame, wi_world);
                gt.material = s.material;
                gt.at = tex_at(s);

                capable = diff && material_capable(s.material);
                target_v = diff && !hero && material_target_v(s.material);
                if (hero) {
                    hero_here = material_hero(s.material);
                    capable = hero_here < MAX_HEROES;
                }

                // ---- emitter sampling: the sample and its unoccluded terms; the shadow ray is pass 1's ----
                // A BSDF of delta lobes only gets no next-event estimation: no emitter sample meets them.
                // Attached sampling estimates it at diffuse vertices alone, not toward the
                // environment (src/cpu/path.rs).
                nee_here = nee && !bsdf_is_smooth(bsdf);
#if ATTACHED
                nee_here = nee_here && HAS(F_DIFFUSE) && !bsdf.blend && is_diffuse(bsdf.leaf0.kind);
#endif
                if (nee_here) {
                    vec4 u_em = draw_block(st.key1, st.pixel, st.sample_index, vertex, DIM_EMITTER_SELECT / 4u);
                    es = sample_emitter(u_em[DIM_EMITTER_SELECT % 4u], vec2(u_em[DIM_EMITTER_POS % 4u], u_em[DIM_EMITTER_POS % 4u + 1u]), env_cell_uniforms(st.key1, st.pixel, st.sample_index, vertex), s.p);
                    if (es.valid && !(ATTACHED != 0 && es.environment)) {
                        vec3 wl;
                        vec3 origin;
                        if (HAS(F_LIGHTS) && es.delta && es.distant) {
                            wl = es.point;
                            origin = offset_origin(s.p, s.ng, wl);
                            nee_pdf = es.pdf;
                            shadow_tmax = FLOAT_MAX;
                        } else if (HAS(F_LIGHTS) && es.delta) {
                            origin = offset_origin(s.p, s.ng, es.point - s.p);
                            vec3 to_light = es.point - origin;
                            float dist = length(to_light);
                            wl = to_light / dist;
                            nee_pdf = es.pdf;
                            shadow_tmax = dist * (1.0 - SHADOW_EPSILON);
                        } else if (HAS(F_ENV) && es.environment) {
                            wl = es.point;
                            origin = offset_origin(s.p, s.ng, wl);
                            nee_pdf = environment_pdf(wl);
                            shadow_tmax = FLOAT_MAX;
                        } else {
                            origin = offset_origin(s.p, s.ng, es.point - s.p);
                            vec3 to_light = es.point - origin;
                            float dist = length(to_light);
                            wl = to_light / dist;
                            nee_pdf = emitter_pdf_solid_angle(dist, dot(es.normal, -wl));
                            shadow_tmax = dist * (1.0 - SHADOW_EPSILON);
                        }
                        nee_wo = to_local(frame, wl);
                        if (HAS(F_MEDIA)) shadow_medium = medium_crossed(s.interior, s.ng, wl, st.medium);
                        float pdf_f;
                        nee_f = bsdf_eval_pdf(bsdf, wi, nee_wo, pdf_f);
                        // The adjoint also traces it where f is zero on the upper hemisphere (a black
                        // BSDF): f's derivative there is not zero (Mitsuba's prb differentiates it too).
                        bool upper = wi.z > 0.0 && nee_wo.z > 0.0;
                        if (nee_pdf > 0.0 && (max_component(nee_f) > 0.0 || (adjoint && upper))) {
                            if (HAS(F_LIGHTS) && es.delta) {
                                // No BSDF sample reaches a light without area: NEE alone finds it.
                                nee_w = hero ? mixture_nee_weight_hero(st.mix, MAX_HEROES, 0.0, 0.0, 0.0, 0.0, true)
                                      : diff ? mixture_nee_weight(st.mix, 0.0, 0.0, 0.0, 0.0, true) : 1.0;
                            } else if (!diff) {
                                nee_w = mis_power(nee_pdf, pdf_f);
                            } else {
                                // Appendix B: the NEE direction as produced by BSDF or differential sampling here.
                                float q_here = capable ? globals.diff_q : 0.0;
                                float pdf_d = capable ? bsdf_pdf_diff(bsdf, target_v, wi, nee_wo) : pdf_f;
                                nee_w = hero ? mixture_nee_weight_hero(st.mix, hero_here, globals.diff_q, pdf_f, pdf_d, nee_pdf, false)
                                             : mixture_nee_weight(st.mix, q_here, pdf_f, pdf_d, nee_pdf, false);
                            }
                            if (HAS(F_MEDIA)) nee_w_tr = st.adj * st.throughput * nee_w * nee_f * es.radiance / nee_pdf;
                            shadow_ray = make_ray(origin, wl);
                            shadow_query = true;
                        }
                    }
                }
            }
        }
        if (!shadow_query) break;
    }

    if (HAS(F_MEDIA) && scatter) {
        // ---- a medium vertex: NEE's contribution, phase sampling, roulette ----
        uint m = st.medium;
        vec3 d = st.ray.dir;
        if (shadow_query) {
            st.radiance += sign * (st.throughput * tr * nee_w * nee_phase * es.radiance / nee_pdf);
            if (adjoint && max_component(tr) > 0.0) {
                phase_grad(m, d, shadow_ray.dir, nee_w_tr * tr / nee_phase);
                if (es.environment ? HAS(G_ENV) : HAS(G_EMISSION)) {
                    gt.nee_param = es.param;
                    gt.nee = st.adj * st.throughput * tr * nee_w * nee_phase * es.factor / nee_pdf;
                    gt.env_dir = (HAS(F_LIGHT_TEXTURE) && es.delta) ? es.normal : es.point;
                    gt.nee_uv = es.uv;
                }
            }
        }
        vec4 u_ph = draw_block(st.key1, st.pixel, st.sample_index, vertex, DIM_LOBE / 4u);
        vec2 u_dir = vec2(u_ph[DIM_DIRECTION % 4u], u_ph[DIM_DIRECTION % 4u + 1u]);
        // Several targets: only the path's hero samples its derivative.
        bool use_dx = capable && (!hero || hero_here == st.mix.hero) && !st.mix.dx_taken && u_ph[DIM_TECHNIQUE % 4u] < globals.diff_q;
        vec3 wo;
        if (use_dx) {
            float u_sign = draw_block(st.key1, st.pixel, st.sample_index, vertex, DIM_DIFF_SIGN / 4u)[DIM_DIFF_SIGN % 4u];
            wo = phase_sample_diff(m, d, u_sign, u_ph[DIM_LOBE % 4u], u_dir);
        } else {
            wo = phase_sample(m, d, u_dir);
        }
        float pdf = phase_eval(m, d, wo);
        if (!(pdf > 0.0)) {
            ended = true;
        } else {
            // The sample's density is the phase function itself: the weight f/pdf is 1; its
            // attached numerator f still has a derivative (through g).
            if (adjoint) phase_grad(m, d, wo, st.adj * st.radiance / pdf);
            st.prev_pdf_f = pdf;
            st.prev_nee = nee;
            if (diff) {
                // The phase function's value is its density: β is unchanged before the division.
                float pdf_d = capable ? phase_pdf_diff(m, d, wo) : 0.0;
                float sum = hero ? mixture_update_hero(st.mix, hero_here, globals.diff_q, pdf, pdf_d)
                                 : mixture_update(st.mix, capable, use_dx, globals.diff_q, pdf, pdf_d);
                if (!(sum > 0.0)) ended = true; else st.throughput /= sum;
                st.mix.dx_taken = st.mix.dx_taken || use_dx;
            } else {
                st.mix.prev_sum = 1.0;
                st.mix.prev_sq = mixture_squares(st.mix);
            }
            if (ended || !path_survives(st, vertex)) ended = true; else st.ray = make_ray(x_medium, wo);
        }
    }

    if (shade) {
#if ATTACHED
        // Attached sampling: where the ray meets this vertex (its Jacobians, below) and, at a
        // diffuse vertex, the albedo's slopes ∂ln a_c/∂x where it is textured (src/cpu/path.rs).
        // `hit` is still the path's: only a kernel with media writes it in the shadow ray's pass,
        // and attached sampling refuses media.
        Material am = materials[s.material];
        bool mirrored = HAS(F_TWO_SIDED) && am.two_sided != 0u && dot(s.ns, -st.ray.dir) < 0.0;
        HitGeometry geometry = HitGeometry(travelled + hit.t, st.ray.dir, s.ng, frame.n,
                                           shading_normal_gradient(hit) * (mirrored ? -1.0 : 1.0));
        bool diffuse_attached = HAS(F_DIFFUSE) && !bsdf.blend && is_diffuse(bsdf.leaf0.kind);
        vec3 dln_albedo[3] = vec3[3](vec3(0.0), vec3(0.0), vec3(0.0));
        if (diffuse_attached && am.tex_width > 0u) {
            mat3 slope = albedo_slope(am, tex_at(s), surface_gradients(hit));
            vec3 albedo = bsdf.leaf0.color;
            if (albedo.x > 0.0) dln_albedo[0] = slope[0] / albedo.x;
            if (albedo.y > 0.0) dln_albedo[1] = slope[1] / albedo.y;
            if (albedo.z > 0.0) dln_albedo[2] = slope[2] / albedo.z;
        }
#endif
        // ---- NEE's contribution, now that its transmittance is known ----
        if (max_component(tr) > 0.0) {
            st.radiance += sign * (st.throughput * tr * nee_w * nee_f * es.radiance / nee_pdf);
#if ATTACHED
            {
                // Its own row: δL·C·∂ln C/∂r, through the hit point, the shading normal, a
                // spot's falloff and the albedo's and a textured spot's slopes (src/cpu/path.rs).
                vec3 c = st.adj * st.throughput * tr * nee_w * nee_f * es.radiance / nee_pdf;
                float dist = length(es.point - shadow_ray.origin);
                vec3 by_light = es.delta ? hit_delta_light_gradient(geometry, shadow_ray.dir, es.distant ? 0.0 : 1.0 / dist) + es.dln_falloff
                                         : hit_nee_gradient(geometry, shadow_ray.dir, dist, es.normal, nee_w);
                vec3 g = by_light * (c.x + c.y + c.z) + dln_albedo[0] * c.x + dln_albedo[1] * c.y + dln_albedo[2] * c.z;
                if (HAS(F_LIGHT_TEXTURE) && es.delta && (es.param & LIGHT_SLOT) != 0u) {
                    // A textured spot (projectors are refused): c_k·∂ln texture_k/∂x; `normal`
                    // holds the shading point of its lookup.
                    vec3 tex_value;
                    mat3 rows = light_texture_slope(lights[es.param & ~LIGHT_SLOT], es.normal, tex_value);
                    for (int k = 0; k < 3; k++) {
                        if (tex_value[k] > 0.0) g += rows[k] * (c[k] / tex_value[k]);
                    }
                }
                Row6 own = hit_position_row(geometry, g);
                if (adjoint) st.gamma = row_add_scaled(st.gamma, own, -1.0);
                else attached_contribution(st, row_through(own, st.jac), c);
            }
#endif
            grad_wo[0] = nee_wo;
            grad_adj[0] = st.adj * st.throughput * tr * nee_w * es.radiance / nee_pdf;
            if (es.environment ? HAS(G_ENV) : HAS(G_EMISSION)) {
                gt.nee_param = es.param;
                gt.nee = st.adj * st.throughput * tr * nee_w * nee_f * es.factor / nee_pdf;
                gt.env_dir = (HAS(F_LIGHT_TEXTURE) && es.delta) ? es.normal : es.point;
                gt.nee_uv = es.uv;
            }
        }

        // ---- BSDF or differential sampling ----
        vec4 u_bs = draw_block(st.key1, st.pixel, st.sample_index, vertex, DIM_LOBE / 4u);
        // A mask chose its nested BSDF with u_lobe < opacity: rescaled to [0, 1) for it (kernels
        // without masks keep no division).
        float u_lobe = HAS(F_MASK) ? u_bs[DIM_LOBE % 4u] / mask_opacity : u_bs[DIM_LOBE % 4u];
        vec2 u_dir = vec2(u_bs[DIM_DIRECTION % 4u], u_bs[DIM_DIRECTION % 4u + 1u]);
        // Several targets: only the path's hero samples its derivative.
        bool use_dx = capable && (!hero || hero_here == st.mix.hero) && !st.mix.dx_taken && u_bs[DIM_TECHNIQUE % 4u] < globals.diff_q;
        BsdfSample bs;
        float pdf_f;
        float pdf_d = 0.0;
#if ATTACHED
        // Attached sampling at a rough conductor: its own sampler (RoughLobe, src/attached.rs).
        bool rough_attached = HAS(F_CONDUCTOR) && !bsdf.blend && is_conductor(bsdf.leaf0.kind);
        RoughLobe rlobe;
        // At an isotropic rough dielectric: its own sampler too (RoughGlassLobe,
        // src/attached/rough_dielectric.rs), whose density holds the lobe's choice.
        bool glass_attached = HAS(F_ROUGH_DIELECTRIC) && !bsdf.blend && is_rough_dielectric(bsdf.leaf0.kind);
        RoughGlassLobe globe;
        if (rough_attached) {
            bool rough_ok = rough_conductor_lobe(st.ray.dir, frame.n, bsdf.leaf0.alpha,
                                                 is_beckmann(bsdf.leaf0.distribution), u_dir, bsdf.leaf0.eta,
                                                 bsdf.leaf0.k, rlobe);
            bs = BsdfSample(to_local(frame, rlobe.wo), rlobe.pdf, rlobe.weight * bsdf.leaf0.color * rlobe.pdf,
                            rough_ok, false);
            pdf_f = bs.pdf;
        } else if (glass_attached) {
            bool glass_ok = rough_dielectric_lobe(st.ray.dir, frame.n, bsdf.leaf0.alpha,
                                                  is_beckmann(bsdf.leaf0.distribution), u_dir, u_lobe,
                                                  bsdf.leaf0.eta.x, globe);
            bs = BsdfSample(to_local(frame, globe.wo), globe.pdf,
                            globe.weight * globe.pdf * (globe.transmitted ? bsdf.leaf0.k : bsdf.leaf0.color),
                            glass_ok, false);
            pdf_f = bs.pdf;
        } else
#endif
        if (use_dx) {
            float u_sign = draw_block(st.key1, st.pixel, st.sample_index, vertex, DIM_DIFF_SIGN / 4u)[DIM_DIFF_SIGN % 4u];
            bs = bsdf_sample_diff(bsdf, target_v, wi, u_sign, u_lobe, u_dir);
            pdf_d = bs.pdf;
            pdf_f = bs.valid ? bsdf_pdf(bsdf, wi, bs.wo) : 0.0;
        } else {
            bs = bsdf_sample(bsdf, wi, u_lobe, u_dir);
            pdf_f = bs.pdf;
            if (capable && bs.valid) pdf_d = bsdf_pdf_diff(bsdf, target_v, wi, bs.wo);
        }
        // An invalid differential sample ends the path unmarked (ALGORITHMS.md §5.5 ruling 3).
        if (!bs.valid || !(pdf_f > 0.0)) {
            ended = true;
        } else {
            st.throughput *= bs.value / pdf_f;
            st.prev_pdf_f = pdf_f;
            // An emitter found through a delta lobe counts whole: NEE could not have sampled it.
            st.prev_nee = nee_here && !bs.delta;
            float sum = hero ? mixture_update_hero(st.mix, hero_here, globals.diff_q, pdf_f, pdf_d)
                             : mixture_update(st.mix, capable, use_dx, globals.diff_q, pdf_f, pdf_d);
            if (!(sum > 0.0)) ended = true; else st.throughput /= sum;
            st.mix.dx_taken = st.mix.dx_taken || use_dx;
            // A thindielectric's straight-through transmission: Mitsuba's null lobe.
            bool null_lobe = null_free && materials[s.material].tag == MAT_THIN_DIELECTRIC && wi.z * bs.wo.z < 0.0;
            counted = !null_lobe;
            if (last && !null_lobe) ended = true;

            // ---- Russian roulette ----
            if (!ended && !path_survives(st, vertex)) ended = true;
            if (!ended) {
                // The path continues: everything later in `radiance` carries the factor f̂(wi, wo).
                grad_wo[1] = bs.wo;
                grad_adj[1] = st.adj * safe_div(st.radiance, bs.value);
                grad_delta = bs.delta;
                vec3 wo_world = to_world(frame, bs.wo);
#if ATTACHED
                {
                    if (rough_attached) {
                        Jac6 a = attached_vertex_jacobian(st, geometry, rlobe.t_d, rlobe.t_n, s.ng, rlobe.wo, vertex);
                        // ∂ln w/∂r per channel = a row shared by the channels + (F′/F)_c · ∂c/∂r.
                        Row6 shared_row = hit_row(geometry, rlobe.dlnw_dd, rlobe.dlnw_dn);
                        Row6 c_row = hit_row(geometry, rlobe.dc_dd, rlobe.dc_dn);
                        if (adjoint) {
                            // h = δL·(∂ln w/∂r ⊙ L_after); Φ′ = (Φ − h)·Ã⁻¹; α's two terms.
                            vec3 after = st.adj * st.radiance;
                            float total = after.x + after.y + after.z;
                            float by_f = dot(after, rlobe.dlnf_dc);
                            Row6 next;
                            bool solved = jac_solve_row(
                                a, row_add_scaled(row_add_scaled(st.gamma, shared_row, -total), c_row, -by_f), next);
                            float direction = solved ? dot(next.d, rlobe.t_alpha) : 0.0;
                            if (am.p_alpha != NO_PARAM)
                                param_grad(am.p_alpha, vec3(total * rlobe.dlnw_dalpha + by_f * rlobe.dc_dalpha
                                                            + direction, 0.0, 0.0));
                            st.gamma = solved ? next : ROW6_ZERO;
                        } else {
                            Row6 shared_j = row_through(shared_row, st.jac);
                            Row6 c_j = row_through(c_row, st.jac);
                            st.log_r = row_add_scaled(row_add_scaled(st.log_r, shared_j, 1.0), c_j, rlobe.dlnf_dc.x);
                            st.log_g = row_add_scaled(row_add_scaled(st.log_g, shared_j, 1.0), c_j, rlobe.dlnf_dc.y);
                            st.log_b = row_add_scaled(row_add_scaled(st.log_b, shared_j, 1.0), c_j, rlobe.dlnf_dc.z);
                            st.jac = jac_compose(a, st.jac);
                        }
                    }
                    if (glass_attached) {
                        Jac6 a = attached_vertex_jacobian(st, geometry, globe.t_d, globe.t_n, s.ng, globe.wo, vertex);
                        // ∂ln(w·P)/∂r, one row for the three channels.
                        Row6 row = hit_row(geometry, globe.dlnw_dd, globe.dlnw_dn);
                        if (adjoint) {
                            // h = δL·(∂ln w/∂r ⊙ L_after); Φ′ = (Φ − h)·Ã⁻¹; α's and η's two terms each.
                            vec3 after = st.adj * st.radiance;
                            float total = after.x + after.y + after.z;
                            Row6 next;
                            bool solved = jac_solve_row(a, row_add_scaled(st.gamma, row, -total), next);
                            float by_alpha = solved ? dot(next.d, globe.t_alpha) : 0.0;
                            float by_eta = solved ? dot(next.d, globe.t_eta) : 0.0;
                            if (am.p_alpha != NO_PARAM)
                                param_grad(am.p_alpha, vec3(total * globe.dlnw_dalpha + by_alpha, 0.0, 0.0));
                            // A rough dielectric's η parameter sits in `table` (src/scene/flat.rs).
                            if (am.table != NO_PARAM)
                                param_grad(am.table, vec3(total * globe.dlnw_deta + by_eta, 0.0, 0.0));
                            st.gamma = solved ? next : ROW6_ZERO;
                        } else {
                            Row6 row_j = row_through(row, st.jac);
                            st.log_r = row_add_scaled(st.log_r, row_j, 1.0);
                            st.log_g = row_add_scaled(st.log_g, row_j, 1.0);
                            st.log_b = row_add_scaled(st.log_b, row_j, 1.0);
                            st.jac = jac_compose(a, st.jac);
                        }
                    }
                    // A diffuse vertex: its sample follows the shading normal's frame alone and its
                    // weight, the albedo, varies with the hit point only where it is textured; direction
                    // noise regularises its singular direction block (src/cpu/path.rs).
                    if (diffuse_attached) {
                        // Rows ∂ln a_c/∂r where the albedo is textured (src/cpu/slope.rs).
                        Row6 row_r = hit_position_row(geometry, dln_albedo[0]);
                        Row6 row_g = hit_position_row(geometry, dln_albedo[1]);
                        Row6 row_b = hit_position_row(geometry, dln_albedo[2]);
                        vec4 u = uniform4(uvec2(globals.key0, st.key1), st.pixel, st.sample_index, vertex,
                                          STREAM_JACOBIAN, 0u, 0u);
                        float amplitude = globals.jac_noise > 0.0 ? globals.jac_noise : DIFFUSE_JACOBIAN_NOISE;
                        Jac6 a = jac_plus_direction_noise(
                            jac_completed(hit_jacobian(geometry, mat3(0.0), diffuse_direction_jacobian(frame.n, bs.wo)),
                                          st.prev_normal, st.ray.dir, s.ng, wo_world),
                            jac_regularisation(amplitude, u.x, u.y), st.ray.dir, wo_world);
                        if (adjoint) {
                            // h = δL·(∂ln w/∂r ⊙ L_after); Φ′ = (Φ − h)·Ã⁻¹.
                            vec3 after = st.adj * st.radiance;
                            Row6 phi_h = row_add_scaled(row_add_scaled(row_add_scaled(st.gamma, row_r, -after.x), row_g,
                                                                       -after.y), row_b, -after.z);
                            Row6 next;
                            bool solved = jac_solve_row(a, phi_h, next);
                            st.gamma = solved ? next : ROW6_ZERO;
                        } else {
                            st.log_r = row_add_scaled(st.log_r, row_through(row_r, st.jac), 1.0);
                            st.log_g = row_add_scaled(st.log_g, row_through(row_g, st.jac), 1.0);
                            st.log_b = row_add_scaled(st.log_b, row_through(row_b, st.jac), 1.0);
                            st.jac = jac_compose(a, st.jac);
                        }
                    }
                    SmoothLobe lobe;
                    bool lobe_ok = !rough_attached && !glass_attached && !diffuse_attached
                        && (am.tag == MAT_CONDUCTOR
                            ? conductor_lobe(st.ray.dir, frame.n, bsdf.leaf0.eta, bsdf.leaf0.k, lobe)
                            : smooth_lobe(am.tag == MAT_THIN_DIELECTRIC, st.ray.dir, frame.n, bsdf.leaf0.eta.x,
                                          wi.z * bs.wo.z < 0.0, lobe));
                    if (lobe_ok) {
                        Jac6 a = attached_vertex_jacobian(st, geometry, lobe.t_d, lobe.t_n, s.ng, wo_world, vertex);
                        Row6 cos_row = hit_cos_row(geometry);
                        if (adjoint) {
                            // h = δL·(∂ln w/∂r ⊙ L_after); Φ′ = (Φ − h)·Ã⁻¹; η's two terms.
                            vec3 after = st.adj * st.radiance;
                            Row6 next;
                            bool solved = jac_solve_row(a, row_add_scaled(st.gamma, cos_row, -dot(after, lobe.dlnw_dcos)), next);
                            float direction = solved ? dot(next.d, lobe.t_eta) : 0.0;
                            if (am.tag != MAT_CONDUCTOR && am.p_weight != NO_PARAM)
                                param_grad(am.p_weight, vec3(dot(after, vec3(lobe.dlnw_deta)) + direction, 0.0, 0.0));
                            st.gamma = next;
                        } else {
                            Row6 row = row_through(cos_row, st.jac);
                            st.log_r = row_add_scaled(st.log_r, row, lobe.dlnw_dcos.x);
                            st.log_g = row_add_scaled(st.log_g, row, lobe.dlnw_dcos.y);
                            st.log_b = row_add_scaled(st.log_b, row, lobe.dlnw_dcos.z);
                            st.jac = jac_compose(a, st.jac);
                        }
                    }
                    st.prev_normal = s.ng;
                }
#endif
                // A direction through a dielectric boundary enters or leaves its shape's medium.
                if (HAS(F_MEDIA)) st.medium = medium_crossed(s.interior, s.ng, wo_world, st.medium);
                st.ray = make_ray(offset_origin(s.p, s.ng, wo_world), wo_world);
            }
        }
    }
    if (adjoint) {
        // GRAD(f̂(wi, wo), adj) of NEE and of the sampled direction: one evaluation site, one sum.
        if ((HAS(G_COLOR) || HAS(G_TEXTURE) || HAS(G_ALPHA) || HAS(G_WEIGHT)) && gt.material != NO_PARAM) {
            if (HAS(F_PRINCIPLED) || HAS2(F2_PRINCIPLED_THIN)) pr_terms_reset();
            [[dont_unroll]] for (uint k = 0u; k < 2u; k++) {
                if (grad_adj[k] == vec3(0.0)) continue;
                BsdfGrad g = bsdf_sample_grad(bsdf, wi, grad_wo[k], k == 1u && grad_delta, grad_adj[k]);
                gt.bsdf.leaf0.color += g.leaf0.color;
                gt.bsdf.leaf0.trans += g.leaf0.trans;
                gt.bsdf.leaf0.eta += g.leaf0.eta;
                gt.bsdf.leaf0.k += g.leaf0.k;
#if !ATTACHED
                // (Attached kernels differentiate a rough conductor's roughness in its lobe.)
                gt.bsdf.leaf0.alpha += g.leaf0.alpha;
                gt.bsdf.leaf0.alpha_v += g.leaf0.alpha_v;
#endif
                gt.bsdf.leaf1.color += g.leaf1.color;
                gt.bsdf.leaf1.alpha += g.leaf1.alpha;
                gt.bsdf.leaf1.trans += g.leaf1.trans;
                gt.bsdf.leaf1.alpha_v += g.leaf1.alpha_v;
                gt.bsdf.leaf1.eta += g.leaf1.eta;
                gt.bsdf.leaf1.k += g.leaf1.k;
                gt.bsdf.weight += g.weight;
            }
        } else {
            gt.material = NO_PARAM;
        }
        scatter_terms(gt);
    }
    if (counted) st.depth += 1u;
    return ended;
}

#endif

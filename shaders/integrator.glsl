// The one path loop (ALGORITHMS.md §3.1, §5.4): BSDF sampling, next-event estimation on area
// emitters and a constant environment, MIS and Russian roulette, in two strategies that share every
// line but the technique choice and the MIS denominators. Twin: src/cpu/path.rs, phase by phase.
//
// Strategy BSDF (plain PRB) samples directions from the BSDF and weights emitter hits and NEE with
// the power heuristic. Strategy DIFF (Su & Gkioulekas) makes one capable vertex — a material whose
// roughness or blend weight is the target parameter — the differential vertex with probability q,
// sampling the BSDF's derivative there; every contribution is divided by the mixture density of
// all placements, carried as the running sums w1, w2 (§5.2) with the Appendix-B NEE weights (§5.3).
// After each update β, w1, w2 and the previous vertex's sum are divided by w1 + w2 (§5.6), so a
// vertex starts with w1 + w2 = 1. With no capable vertex DIFF is BSDF sampling with the balance
// heuristic.
//
// Primal mode returns the path's radiance L. Adjoint mode (PRB, ALGORITHMS.md §3.3) replays the
// same path starting from that L and subtracts each contribution where the primal added it, so
// `radiance` always holds the radiance still to arrive along the suffix; the GRAD terms scatter
// δL-weighted parameter derivatives through param_grad. It returns what is left, which must be 0
// up to rounding. Adjoint-only work sits in `if (adjoint)`, so both modes compile in every kernel.
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

#define FLOAT_MAX 3.402823466e38

// Whether the differential strategy may place its differential vertex on material `m`: its
// roughness (rough conductor) or weight (blend) is the target parameter.
bool material_capable(uint m) {
    uint tag = materials[m].tag;
    uint p = tag == MAT_ROUGH_CONDUCTOR ? materials[m].p_alpha : (tag == MAT_BLEND ? materials[m].p_weight : NO_PARAM);
    return p >= globals.diff_begin && p < globals.diff_end;
}

// MIS weight of radiance reached by BSDF sampling from the previous vertex, whose direction had
// density `pdf_f` there and would have had density `pdf_e` under NEE (ALGORITHMS.md §3.1, §5.3).
float hit_weight(bool diff, bool prev_nee, float pdf_f, float pdf_e, float prev_sum) {
    if (!prev_nee) return 1.0;
    if (!diff) return mis_power(pdf_f, pdf_e);
    return 1.0 / (1.0 + prev_sum * pdf_e / pdf_f);
}

vec4 draw_block(uint pixel, uint sample_index, uint vertex, uint block) {
    return uniform4(uvec2(globals.key0, globals.key1), pixel, sample_index, vertex, STREAM_MAIN, block, 0u);
}

// One camera path through `pixel` (row-major index) for sample `sample_index`: its radiance
// (primal), or, replaying from `radiance_total` with adjoint radiance `adj_radiance` (δL), what is
// left of it at the end (adjoint).
vec3 trace_path(bool adjoint, uint pixel, uint sample_index, vec3 adj_radiance, vec3 radiance_total) {
    // ---- camera ray ----
    vec4 u_cam = draw_block(pixel, sample_index, 0u, DIM_PIXEL_JITTER / 4u);
    uint px = pixel % globals.width;
    uint py = pixel / globals.width;
    float sx = 2.0 * (float(px) + u_cam.x) / float(globals.width) - 1.0;
    float sy = 1.0 - 2.0 * (float(py) + u_cam.y) / float(globals.height);
    Ray ray = make_ray(globals.cam_origin, normalize(globals.cam_forward + sx * globals.cam_right + sy * globals.cam_up));

    vec3 throughput = vec3(1.0);  // β (ALGORITHMS.md §3.1)
    vec3 radiance = adjoint ? radiance_total : vec3(0.0);  // L (adjoint: the suffix still to arrive)
    float sign = adjoint ? -1.0 : 1.0;
    bool diff = globals.strategy == STRATEGY_DIFF;
    bool nee = globals.nee != 0u;
    float prev_pdf_f = 0.0;       // density with which the previous vertex sampled ray.dir
    bool prev_nee = false;        // whether NEE at the previous vertex could have found this emitter
    float prev_sum = 1.0;         // w1 + w2 at the previous vertex before its update, rescaled
    float w1 = 0.0;               // mixture sums of the differential strategy (ALGORITHMS.md §5.2)
    float w2 = 1.0;
    bool dx_taken = false;        // the differential vertex has been chosen
    bool finished = false;
    for (uint vertex = 1u; vertex <= globals.max_depth; vertex++) {
        // ---- intersection ----
        Hit hit = bvh_closest_hit(ray, 0.0, FLOAT_MAX);
        if (!hit.valid) {
            // ---- environment hit ----
            if (globals.env_param != NO_PARAM) {
                float w_b = hit_weight(diff, prev_nee, prev_pdf_f, environment_pdf(), prev_sum);
                radiance += sign * (throughput * w_b * param_rgb(globals.env_param));
                if (adjoint) param_grad_rgb(globals.env_param, adj_radiance * throughput * w_b);
            }
            finished = true;
            break;
        }
        Surface s = surface_at(hit);
        vec3 wi_world = -ray.dir;

        // ---- emitter hit ----
        float cos_emit = dot(s.ng, wi_world);
        if (s.emitter != NO_EMITTER && cos_emit > 0.0) {
            float w_b = hit_weight(diff, prev_nee, prev_pdf_f, emitter_pdf_solid_angle(hit.t, cos_emit), prev_sum);
            uint p_radiance = emitters[s.emitter].p_radiance;
            radiance += sign * (throughput * w_b * param_rgb(p_radiance));
            if (adjoint) param_grad_rgb(p_radiance, adj_radiance * throughput * w_b);
        }
        if (vertex >= globals.max_depth) { finished = true; break; }

        Bsdf bsdf = resolve_bsdf(s.material, s.uv);
        // A two-sided material seen from the back shades with the flipped normal.
        if (materials[s.material].two_sided != 0u && dot(s.ns, wi_world) < 0.0) s.ns = -s.ns;
        ShadingFrame frame = shading_frame(s.ns);
        vec3 wi = to_local(frame, wi_world);

        bool capable = diff && material_capable(s.material);

        // ---- emitter sampling ----
        vec4 u_em = draw_block(pixel, sample_index, vertex, DIM_EMITTER_SELECT / 4u);
        EmitterSample es = EmitterSample(vec3(0.0), vec3(0.0), vec3(0.0), NO_PARAM, false, false);
        if (nee) es = sample_emitter(u_em[DIM_EMITTER_SELECT % 4u], vec2(u_em[DIM_EMITTER_POS % 4u], u_em[DIM_EMITTER_POS % 4u + 1u]));
        if (es.valid) {
            vec3 wl;
            float p_e;
            float shadow_tmax;
            vec3 origin;
            if (es.environment) {
                wl = es.point;
                origin = offset_origin(s.p, s.ng, wl);
                p_e = environment_pdf();
                shadow_tmax = FLOAT_MAX;
            } else {
                origin = offset_origin(s.p, s.ng, es.point - s.p);
                vec3 to_light = es.point - origin;
                float dist = length(to_light);
                wl = to_light / dist;
                p_e = emitter_pdf_solid_angle(dist, dot(es.normal, -wl));
                shadow_tmax = dist * (1.0 - SHADOW_EPSILON);
            }
            vec3 wo = to_local(frame, wl);
            vec3 f = bsdf_eval(bsdf, wi, wo);
            if (p_e > 0.0 && max_component(f) > 0.0 && !bvh_occluded(make_ray(origin, wl), 0.0, shadow_tmax)) {
                float pdf_f = bsdf_pdf(bsdf, wi, wo);
                float w_n;
                if (!diff) {
                    w_n = mis_power(p_e, pdf_f);
                } else {
                    // Appendix B: the NEE direction as produced by BSDF or differential sampling here.
                    float q_here = capable ? globals.diff_q : 0.0;
                    float pdf_d = capable ? bsdf_pdf_diff(bsdf, wi, wo) : pdf_f;
                    w_n = 1.0 / (w1 + w2 + (w1 * pdf_f + q_here * w2 * pdf_d + (1.0 - q_here) * w2 * pdf_f) / p_e);
                }
                radiance += sign * (throughput * w_n * f * es.radiance / p_e);
                if (adjoint) {
                    bsdf_backward(s.material, s.uv, bsdf, wi, wo, adj_radiance * throughput * w_n * es.radiance / p_e);
                    param_grad_rgb(es.param, adj_radiance * throughput * w_n * f / p_e);
                }
            }
        }

        // ---- BSDF or differential sampling ----
        vec4 u_bs = draw_block(pixel, sample_index, vertex, DIM_LOBE / 4u);
        float u_lobe = u_bs[DIM_LOBE % 4u];
        vec2 u_dir = vec2(u_bs[DIM_DIRECTION % 4u], u_bs[DIM_DIRECTION % 4u + 1u]);
        bool use_dx = capable && !dx_taken && u_bs[DIM_TECHNIQUE % 4u] < globals.diff_q;
        BsdfSample bs;
        float pdf_f;
        float pdf_d = 0.0;
        if (use_dx) {
            float u_sign = draw_block(pixel, sample_index, vertex, DIM_DIFF_SIGN / 4u)[DIM_DIFF_SIGN % 4u];
            bs = bsdf_sample_diff(bsdf, wi, u_sign, u_lobe, u_dir);
            pdf_d = bs.pdf;
            pdf_f = bs.valid ? bsdf_pdf(bsdf, wi, bs.wo) : 0.0;
        } else {
            bs = bsdf_sample(bsdf, wi, u_lobe, u_dir);
            pdf_f = bs.pdf;
            if (capable && bs.valid) pdf_d = bsdf_pdf_diff(bsdf, wi, bs.wo);
        }
        // An invalid differential sample ends the path unmarked (ALGORITHMS.md §5.5 ruling 3).
        if (!bs.valid || !(pdf_f > 0.0)) { finished = true; break; }
        throughput *= bs.value / pdf_f;
        prev_pdf_f = pdf_f;
        prev_nee = nee;
        prev_sum = w1 + w2;
        if (capable) {
            w1 += globals.diff_q * w2 * pdf_d / pdf_f;
            w2 *= 1.0 - globals.diff_q;
            float sum = w1 + w2;
            if (!(sum > 0.0)) { finished = true; break; }
            w1 /= sum;
            w2 /= sum;
            throughput /= sum;
            prev_sum /= sum;
        }
        dx_taken = dx_taken || use_dx;

        // ---- Russian roulette ----
        // vertex - 1 >= rr_depth (ALGORITHMS.md §3.1), written without the subtraction.
        if (vertex > globals.rr_depth) {
            float u_rr = draw_block(pixel, sample_index, vertex, DIM_ROULETTE / 4u)[DIM_ROULETTE % 4u];
            float p_rr = min(max_component(throughput), 0.95);
            if (!(u_rr < p_rr)) { finished = true; break; }
            throughput /= p_rr;
        }
        if (!(max_component(throughput) > 0.0)) { finished = true; break; }
        // The path continues: everything later in `radiance` carries the factor f̂(wi, wo).
        if (adjoint) bsdf_backward(s.material, s.uv, bsdf, wi, bs.wo, adj_radiance * safe_div(radiance, bs.value));

        vec3 wo_world = to_world(frame, bs.wo);
        ray = make_ray(offset_origin(s.p, s.ng, wo_world), wo_world);
    }
    if (!finished) raise_status(STATUS_LOOP_BUDGET);
    return radiance;
}

#endif

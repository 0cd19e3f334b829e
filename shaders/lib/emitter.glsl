// Area emitters on triangles: area-proportional sampling and densities (twin of src/cpu/emitter.rs).
#ifndef PATHGRAD_EMITTER_GLSL
#define PATHGRAD_EMITTER_GLSL

#include "abi.glsl"
#include "sampling.glsl"
#include "features.glsl"

// A next-event sample: a point on an area emitter, or (environment) a direction in `point`.
struct EmitterSample { vec3 point; vec3 normal; vec3 radiance; uint param; bool environment; bool valid; };

// With probability env_select_prob (u_select below it) a uniform direction toward the constant
// environment; otherwise an emissive triangle with probability proportional to its area, then a
// uniform point on it (u_pos). The area density is (1 - env_select_prob) / total emissive area.
EmitterSample sample_emitter(float u_select, vec2 u_pos) {
    EmitterSample s = EmitterSample(vec3(0.0), vec3(0.0), vec3(0.0), NO_PARAM, false, false);
    if (HAS(F_ENV) && u_select < globals.env_select_prob) {
        s.point = sample_uniform_sphere(u_pos);
        s.radiance = param_rgb(globals.env_param);
        s.param = globals.env_param;
        s.environment = true;
        s.valid = true;
        return s;
    }
    uint count = globals.emitter_count;
    if (!HAS(F_EMITTERS) || count == 0u) return s;
    u_select = (u_select - globals.env_select_prob) / (1.0 - globals.env_select_prob);
    uint lo = 0u;
    uint hi = count - 1u;
    // Binary search for the first cdf > u_select. The flag, set only where the search ends for its
    // own reason, detects lavapipe's silent loop truncation (a re-check of `lo < hi` after the loop
    // would be optimised away); 32 steps bound any u32 range.
    bool found = false;
    for (uint step = 0u; step < 32u; step++) {
        if (lo >= hi) { found = true; break; }
        uint mid = (lo + hi) / 2u;
        if (emitters[mid].cdf > u_select) hi = mid; else lo = mid + 1u;
    }
    if (!found) { raise_status(STATUS_LOOP_BUDGET); return s; }
    EmitterTri e = emitters[lo];
    vec2 b = sample_uniform_triangle(u_pos);
    s.point = (1.0 - b.x - b.y) * e.v0 + b.x * e.v1 + b.y * e.v2;
    s.normal = normalize(cross(e.v1 - e.v0, e.v2 - e.v0));
    s.radiance = param_rgb(e.p_radiance);
    s.param = e.p_radiance;
    s.valid = true;
    return s;
}

// Solid-angle density of reaching an emitter point at distance `dist` whose normal makes cosine
// `cos_emitter` with the direction back to the shading point.
float emitter_pdf_solid_angle(float dist, float cos_emitter) {
    return cos_emitter > 0.0 ? (1.0 - globals.env_select_prob) * dist * dist / (cos_emitter * globals.emitter_total_area) : 0.0;
}

// Solid-angle density with which next-event estimation samples a direction toward the environment.
float environment_pdf() {
    return globals.env_select_prob * (0.25 * INV_PI);
}

#endif

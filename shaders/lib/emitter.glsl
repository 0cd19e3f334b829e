// Area emitters on triangles and the environment (constant or a map): sampling, radiance and
// densities (twin of src/cpu/emitter.rs; the map's functions twin src/scene/envmap.rs).
#ifndef PATHGRAD_EMITTER_GLSL
#define PATHGRAD_EMITTER_GLSL

#include "abi.glsl"
#include "sampling.glsl"
#include "features.glsl"

layout(buffer_reference, scalar, buffer_reference_align = 4) readonly buffer EnvCellArray { EnvCell v[]; };
#define env_cells (EnvCellArray(globals.addr_env_cells).v)
layout(buffer_reference, scalar, buffer_reference_align = 4) readonly buffer LightArray { DeltaLight v[]; };
#define lights (LightArray(globals.addr_lights).v)

// ---- the environment map (src/scene/envmap.rs states the conventions) ----

// atan2(y, x) by the polynomial of envmap::atan2_poly (lavapipe's atan and acos differ from the
// CPU twin's by about 1e-5).
float atan2_poly(float y, float x) {
    float ax = abs(x);
    float ay = abs(y);
    float hi = max(ax, ay);
    float a = hi > 0.0 ? min(ax, ay) / hi : 0.0;
    float s = a * a;
    float p = -0.0040733092;
    p = p * s + 0.02194661;
    p = p * s - 0.056063175;
    p = p * s + 0.096562564;
    p = p * s - 0.13915803;
    p = p * s + 0.1994851;
    p = p * s - 0.33330107;
    p = p * s + 0.99999946;
    float r = p * a;
    if (ay > ax) r = 0.5 * PI - r;
    if (x < 0.0) r = PI - r;
    return y < 0.0 ? -r : r;
}

// The map's (u, v) of world direction `dir` (unit).
vec2 env_uv(vec3 dir) {
    vec3 d = vec3(dot(globals.env_rot0, dir), dot(globals.env_rot1, dir), dot(globals.env_rot2, dir));
    float u = atan2_poly(d.x, -d.z) * (0.5 * INV_PI);
    return vec2(u - floor(u), atan2_poly(sqrt(d.x * d.x + d.z * d.z), d.y) * INV_PI);
}

// The cell (i, j) that `dir` lies in and the bilinear weights (fx, fy) of its corners there.
uvec2 env_cell_at(vec3 dir, out vec2 f) {
    vec2 uv = env_uv(dir);
    float x = uv.x * float(globals.env_width) - 0.5;
    float x0 = floor(x);
    int w = int(globals.env_width);
    float y = clamp(uv.y, 0.0, 1.0) * float(globals.env_height - 1u);
    float y0 = min(floor(y), float(globals.env_height - 2u));
    f = vec2(x - x0, y - y0);
    // x ∈ [−½, W − ½): x0 is −1 (the last column, wrapped) up to W − 1. No % of a negative
    // number: GLSL leaves its result undefined.
    return uvec2(x0 < 0.0 ? uint(w - 1) : min(uint(x0), uint(w - 1)), uint(y0));
}

// The parameter offsets of the four texels around `dir` and their bilinear weights.
void env_footprint(vec3 dir, out uint texel[4], out float weight[4]) {
    vec2 f;
    uvec2 c = env_cell_at(dir, f);
    uint w = globals.env_width;
    uint i1 = (c.x + 1u) % w;
    uint base = globals.env_param;
    texel = uint[4](base + 3u * (c.y * w + c.x), base + 3u * (c.y * w + i1), base + 3u * ((c.y + 1u) * w + c.x),
                    base + 3u * ((c.y + 1u) * w + i1));
    weight = float[4]((1.0 - f.x) * (1.0 - f.y), f.x * (1.0 - f.y), (1.0 - f.x) * f.y, f.x * f.y);
}

// The environment's radiance toward `dir`.
vec3 env_radiance(vec3 dir) {
    if (!HAS(F_ENV_MAP)) return param_rgb(globals.env_param);
    uint texel[4];
    float weight[4];
    env_footprint(dir, texel, weight);
    return globals.env_scale * (param_rgb(texel[0]) * weight[0] + param_rgb(texel[1]) * weight[1]
        + param_rgb(texel[2]) * weight[2] + param_rgb(texel[3]) * weight[3]);
}

// A direction toward the environment: a cell by its alias table (u_cell: column and coin), then
// uniform in longitude and cos θ within the cell (u_pos); the constant environment is uniform.
vec3 env_sample(vec2 u_cell, vec2 u_pos) {
    if (!HAS(F_ENV_MAP)) return sample_uniform_sphere(u_pos);
    uint w = globals.env_width;
    uint count = w * (globals.env_height - 1u);
    precise float scaled = u_cell.x * float(count);
    uint column = min(uint(floor(scaled)), count - 1u);
    EnvCell e = env_cells[column];
    uint cell = u_cell.y < e.prob ? column : e.alias;
    uint i = cell % w;
    uint j = cell / w;
    float phi = 2.0 * PI * (float(i) + 0.5 + u_pos.x) / float(w);
    float step = PI / float(globals.env_height - 1u);
    float cos0 = cos(float(j) * step);
    float cos1 = cos(float(j + 1u) * step);
    float cos_theta = cos0 + u_pos.y * (cos1 - cos0);
    float sin_theta = sqrt(max(1.0 - cos_theta * cos_theta, 0.0));
    vec3 l = vec3(sin(phi) * sin_theta, cos_theta, -cos(phi) * sin_theta);
    return l.x * globals.env_rot0 + l.y * globals.env_rot1 + l.z * globals.env_rot2;
}

// A next-event sample: a point on an area emitter, a direction toward the environment (`point`),
// or a light without area (`delta`): its position, or (`distant`, a directional light) the
// direction toward it in `point`; its radiance is already divided by the distance² and weighted
// by a spot's falloff, `factor` being that weight, and `pdf` is the light's selection probability.
// A textured light or projector (F_LIGHT_TEXTURE) has `param` LIGHT_SLOT | its index and `normal`
// the shading point it was sampled from (its texture lookup).
struct EmitterSample {
    vec3 point; vec3 normal; vec3 radiance; uint param; bool environment; bool valid;
    bool delta; bool distant; float factor; float pdf;
    vec2 uv;    // a textured area emitter's texture coordinates at `point`
    vec3 dln_falloff;   // a spot: ∇ ln falloff by the shading point (0 otherwise)
};

// A spot's falloff toward unit direction `d` from its position (Mitsuba's falloff_curve).
float spot_falloff(DeltaLight l, vec3 d) {
    float c = dot(l.axis, d);
    float beam = c >= l.cos_beam ? 1.0 : (l.cutoff - atan2_poly(sqrt(max(1.0 - c * c, 0.0)), c)) * l.inv_transition;
    return c > l.cos_cutoff ? beam : 0.0;
}

// The gradient by the shading point of ln `falloff` (> 0) for a spot seen along unit `d` at
// distance `dist`: (axis − cos θ·d)/(transition·sin θ·dist·falloff) in the transition zone, 0 in
// the beam (twin: spot_falloff_gradient in src/cpu/emitter.rs).
vec3 spot_falloff_gradient(DeltaLight l, vec3 d, float dist, float falloff) {
    float c = dot(l.axis, d);
    float s = sqrt(max(1.0 - c * c, 0.0));
    if (c >= l.cos_beam || c <= l.cos_cutoff || s <= 0.0) return vec3(0.0);
    return (l.axis - c * d) * (l.inv_transition / (s * dist * falloff));
}

// What a textured spot or a projector `l` sends toward point `x`, apart from its parameters: the
// texture coordinates of its lookup, and in `factor` a spot's falloff / distance² or a
// projector's π / (z² cos θ); a factor of 0 where it sends nothing (twin: light_lookup in
// src/cpu/emitter.rs).
vec2 light_lookup(DeltaLight l, vec3 x, out float factor) {
    vec3 d = x - l.position;
    vec3 local = vec3(dot(l.row0, d), dot(l.row1, d), dot(l.row2, d));
    vec2 uv = vec2(0.5) + l.uv_scale * vec2(local.x, local.y) / local.z;
    float d2 = dot(d, d);
    if (l.kind == LIGHT_PROJECTOR) {
        bool inside = local.z > 0.0 && uv.x >= 0.0 && uv.x <= 1.0 && uv.y >= 0.0 && uv.y <= 1.0;
        float cos_theta = dot(l.axis, d) / sqrt(d2);
        factor = inside ? PI / (local.z * local.z * cos_theta) : 0.0;
        return inside ? uv : vec2(0.0);
    }
    float falloff = spot_falloff(l, d * inversesqrt(d2));
    factor = falloff / d2;
    return falloff > 0.0 ? uv : vec2(0.0);
}

// Its intensity (or 1) × texture at uv (or 1) × scale (or 1); defined in surface.glsl, beside the
// texture lookup.
vec3 light_tint(DeltaLight l, vec2 uv);

// A textured area emitter's radiance at its texture coordinates uv, and the texture coordinates
// of a point of a triangle; defined in surface.glsl, beside the texture lookup.
bool area_textured(uint p);
vec3 area_radiance(uint p, vec2 uv);
vec2 triangle_uv(uint tri, vec2 b);

// With probability env_select_prob (u_select below it) a direction toward the environment
// (env_sample); with light_select_prob one of the lights without area, each equally likely, as
// seen from shading point x; otherwise an emissive triangle with probability proportional to its
// area, then a uniform point on it (u_pos). The area density is the rest of the probability over
// the total emissive area.
EmitterSample sample_emitter(float u_select, vec2 u_pos, vec2 u_cell, vec3 x) {
    EmitterSample s = EmitterSample(vec3(0.0), vec3(0.0), vec3(0.0), NO_PARAM, false, false, false, false, 1.0, 0.0,
                                    vec2(0.0), vec3(0.0));
    if (HAS(F_ENV) && u_select < globals.env_select_prob) {
        s.point = env_sample(u_cell, u_pos);
        s.radiance = env_radiance(s.point);
        s.param = globals.env_param;
        s.environment = true;
        s.valid = true;
        return s;
    }
    if (HAS(F_LIGHTS) && u_select < globals.env_select_prob + globals.light_select_prob) {
        uint n = globals.light_count;
        float t = (u_select - globals.env_select_prob) / globals.light_select_prob;
        uint index = min(uint(t * float(n)), n - 1u);
        DeltaLight l = lights[index];
        s.delta = true;
        s.param = l.p_intensity;
        s.pdf = globals.light_select_prob / float(n);
        if (HAS(F_LIGHT_TEXTURE) && (l.tex != NO_PARAM || l.kind == LIGHT_PROJECTOR)) {
            vec2 uv = light_lookup(l, x, s.factor);
            s.point = l.position;
            s.normal = x;
            s.param = LIGHT_SLOT | index;
            s.valid = s.factor > 0.0 && s.factor < FLOAT_MAX;
            s.radiance = s.valid ? light_tint(l, uv) * s.factor : vec3(0.0);
            if (l.kind == LIGHT_SPOT && s.valid) {
                vec3 d = x - l.position;
                float d2 = dot(d, d);
                vec3 u = d * inversesqrt(d2);
                s.dln_falloff = spot_falloff_gradient(l, u, sqrt(d2), spot_falloff(l, u));
            }
            return s;
        }
        if (l.kind == LIGHT_DIRECTIONAL) {
            s.distant = true;
            s.point = -l.axis;
        } else {
            s.point = l.position;
            vec3 d = x - l.position;
            float d2 = dot(d, d);
            s.factor = 1.0 / d2;
            if (l.kind == LIGHT_SPOT) {
                vec3 u = d * inversesqrt(d2);
                float falloff = spot_falloff(l, u);
                s.factor *= falloff;
                if (falloff > 0.0) s.dln_falloff = spot_falloff_gradient(l, u, sqrt(d2), falloff);
            }
        }
        s.radiance = param_rgb(l.p_intensity) * s.factor;
        s.valid = s.factor > 0.0 && s.factor < FLOAT_MAX;
        return s;
    }
    uint count = globals.emitter_count;
    if (!HAS(F_EMITTERS) || count == 0u) return s;
    float taken = globals.env_select_prob + globals.light_select_prob;
    u_select = (u_select - taken) / (1.0 - taken);
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
    // A textured emitter is sampled by area too (Mitsuba samples its texture): the same
    // expectation, its radiance read at the point's texture coordinates.
    if (area_textured(e.p_radiance)) s.uv = triangle_uv(e.tri, b);
    s.radiance = area_radiance(e.p_radiance, s.uv);
    s.param = e.p_radiance;
    s.valid = true;
    return s;
}

// Solid-angle density of reaching an emitter point at distance `dist` whose normal makes cosine
// `cos_emitter` with the direction back to the shading point.
float emitter_pdf_solid_angle(float dist, float cos_emitter) {
    float p = 1.0 - globals.env_select_prob - globals.light_select_prob;
    return cos_emitter > 0.0 ? p * dist * dist / (cos_emitter * globals.emitter_total_area) : 0.0;
}

// Solid-angle density with which next-event estimation samples direction `dir` toward the
// environment: its map cell's density, or uniform.
float environment_pdf(vec3 dir) {
    if (!HAS(F_ENV_MAP)) return globals.env_select_prob * (0.25 * INV_PI);
    vec2 f;
    uvec2 c = env_cell_at(dir, f);
    return globals.env_select_prob * env_cells[c.y * globals.env_width + c.x].pdf;
}

#endif

// Participating media in the path loop (ALGORITHMS.md §8): field lookups, the phase function,
// delta tracking of free flights and ratio tracking of shadow rays through media and null
// boundaries; twin of src/cpu/medium.rs, which says how RGB extinction is tracked (spectral
// tracking against one grey majorant). Compiled only into kernels with F_MEDIA.
#ifndef PATHGRAD_MEDIUM_GLSL
#define PATHGRAD_MEDIUM_GLSL

// a + (b − a)·w, as the Rust twin writes its lerp (GLSL's mix may round otherwise).
float lerp_exact(float a, float b, float w) {
    return a + (b - a) * w;
}

// Channel c of field `f` at world point p (trilinear at p·res − 0.5 with clamping, as Mitsuba).
float field_at(uint f, vec3 p, uint c) {
    FieldDesc d = fields[f];
    c = min(c, d.channels - 1u);
    if (d.kind == FIELD_CONSTANT) return params[d.offset + c];
    vec3 local = vec3(dot(d.row0, p), dot(d.row1, p), dot(d.row2, p)) + d.shift;
    uvec3 res = uvec3(d.res_x, d.res_y, d.res_z);
    vec3 r = vec3(res);
    vec3 u = clamp(local * r - 0.5, vec3(0.0), r - 1.0);
    uvec3 lo = uvec3(floor(u));
    uvec3 hi = min(lo + 1u, res - 1u);
    vec3 t = u - vec3(lo);
#define VOXEL(VX, VY, VZ) params[d.offset + (((VZ) * res.y + (VY)) * res.x + (VX)) * d.channels + c]
    float x00 = lerp_exact(VOXEL(lo.x, lo.y, lo.z), VOXEL(hi.x, lo.y, lo.z), t.x);
    float x10 = lerp_exact(VOXEL(lo.x, hi.y, lo.z), VOXEL(hi.x, hi.y, lo.z), t.x);
    float x01 = lerp_exact(VOXEL(lo.x, lo.y, hi.z), VOXEL(hi.x, lo.y, hi.z), t.x);
    float x11 = lerp_exact(VOXEL(lo.x, hi.y, hi.z), VOXEL(hi.x, hi.y, hi.z), t.x);
#undef VOXEL
    return lerp_exact(lerp_exact(x00, x10, t.y), lerp_exact(x01, x11, t.y), t.z);
}

vec3 field_rgb(uint f, vec3 p) {
    return vec3(field_at(f, p, 0u), field_at(f, p, 1u), field_at(f, p, 2u));
}

// The extinction scale · sigma_t(p) per channel.
vec3 medium_extinction(uint m, vec3 p) {
    return params[media[m].p_scale] * field_rgb(media[m].sigma_t, p);
}

float medium_g(uint m) {
    return media[m].phase == PHASE_HG ? params[media[m].p_g] : 0.0;
}

// The phase function for light travelling along d scattered into wo (both unit).
float phase_eval(uint m, vec3 d, vec3 wo) {
    float g = medium_g(m);
    float denom = 1.0 + g * g - 2.0 * g * dot(d, wo);
    return (1.0 - g * g) / (4.0 * PI * denom * sqrt(max(denom, 0.0)));
}

// A direction drawn from the phase function around d; its density is phase_eval.
vec3 phase_sample(uint m, vec3 d, vec2 u) {
    float g = medium_g(m);
    float c;
    if (abs(g) < 1e-3) {
        c = 1.0 - 2.0 * u.x;
    } else {
        float s = (1.0 - g * g) / (1.0 - g + 2.0 * g * u.x);
        c = clamp((1.0 + g * g - s * s) / (2.0 * g), -1.0, 1.0);
    }
    float sn = sqrt(max(1.0 - c * c, 0.0));
    float phi = 2.0 * PI * u.y;
    return to_world(shading_frame(d), vec3(sn * cos(phi), sn * sin(phi), c));
}

// Delta tracking of the flight along `ray` in medium m up to t_max: the distance of a real
// collision, or -1 if the flight reaches t_max; its spectral-tracking weight multiplies `weight`.
// Draws stream DT of `vertex` from step `step` on.
float delta_track(uint m, Ray ray, float t_max, uvec2 key, uint pixel, uint sample_index, uint vertex, inout uint step, inout vec3 weight) {
    float majorant = media[m].majorant;
    if (!(majorant > 0.0)) return -1.0;
    float t = 0.0;
    [[dont_unroll]] while (step < MAX_TRACKING_STEPS) {
        vec4 u = uniform4(key, pixel, sample_index, vertex, STREAM_DELTA_TRACKING, 0u, step);
        step++;
        t += -log(1.0 - u.x) / majorant;
        if (!(t < t_max)) return -1.0;
        vec3 x = ray.origin + t * ray.dir;
        vec3 sigma = medium_extinction(m, x);
        float p_real = clamp((sigma.x + sigma.y + sigma.z) / (3.0 * majorant), 0.0, 1.0);
        if (u.y < p_real) {
            weight *= field_rgb(media[m].albedo, x) * sigma / (majorant * p_real);
            return t;
        }
        weight *= (vec3(majorant) - sigma) / (majorant * (1.0 - p_real));
    }
    weight = vec3(0.0);
    return -1.0;
}

// Ratio-tracking transmittance of medium m along origin + t·dir over [0, t_max), stream RT.
vec3 ratio_track(uint m, vec3 origin, vec3 dir, float t_max, uvec2 key, uint pixel, uint sample_index, uint vertex, inout uint step) {
    float majorant = media[m].majorant;
    if (!(majorant > 0.0)) return vec3(1.0);
    vec3 tr = vec3(1.0);
    float t = 0.0;
    [[dont_unroll]] while (step < MAX_TRACKING_STEPS) {
        float u = uniform4(key, pixel, sample_index, vertex, STREAM_RATIO_TRACKING, 0u, step).x;
        step++;
        t += -log(1.0 - u) / majorant;
        if (!(t < t_max)) return tr;
        tr *= (vec3(majorant) - medium_extinction(m, origin + t * dir)) / majorant;
    }
    return vec3(0.0);
}

// The medium after crossing a boundary of `interior` (winding normal ng) along dir from `current`.
uint medium_crossed(uint interior, vec3 ng, vec3 dir, uint current) {
    if (interior == NO_MEDIUM) return current;
    return dot(ng, dir) < 0.0 ? interior : NO_MEDIUM;
}

// Transmittance from origin along dir over [0, t_max) starting in medium m, through null
// boundaries; 0 past an opaque surface or MAX_NULL_CROSSINGS boundaries.
vec3 shadow_transmittance(uint m, vec3 origin, vec3 dir, float t_max, uvec2 key, uint pixel, uint sample_index, uint vertex) {
    vec3 o = origin;
    float remaining = t_max;
    vec3 end_point = origin + t_max * dir;
    vec3 tr = vec3(1.0);
    uint step = 0u;
    [[dont_unroll]] for (uint k = 0u; k <= MAX_NULL_CROSSINGS; k++) {
        Hit hit = bvh_closest_hit(make_ray(o, dir), 0.0, remaining);
        float segment = hit.valid ? hit.t : remaining;
        if (m != NO_MEDIUM) tr *= ratio_track(m, o, dir, segment, key, pixel, sample_index, vertex, step);
        if (!hit.valid) return tr;
        Surface s = surface_at(hit);
        if (materials[s.material].tag != MAT_NULL) return vec3(0.0);
        m = medium_crossed(s.interior, s.ng, dir, m);
        o = offset_origin(s.p, s.ng, dir);
        if (t_max < FLOAT_MAX) {
            remaining = dot(end_point - o, dir);
            if (!(remaining > 0.0)) return tr;
        }
    }
    return vec3(0.0);
}

#endif

// Participating media in the path loop (ALGORITHMS.md §8): field lookups, the phase function,
// and one tracking body for delta tracking of free flights and ratio tracking of shadow rays
// (`path_step`'s pass loop in integrator.glsl crosses the null boundaries between media); twin of
// src/cpu/medium.rs, which says how RGB extinction is tracked (spectral tracking against one grey
// majorant). Compiled only into kernels with F_MEDIA.
#ifndef PATHGRAD_MEDIUM_GLSL
#define PATHGRAD_MEDIUM_GLSL

#include "field.glsl"

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

// The phase function's differential sampler (ALGORITHMS.md §8.4; twin of src/cpu/medium.rs, same
// names and operation order). |g| below HG_DIFF_SMALL_G takes ∂p/∂g's limit 3 cos θ/(4π).
#define HG_DIFF_SMALL_G 1e-6

// ∂p/∂g at cos θ = mu: ((g² + 3)μ + g³ − 5g) / (4π Δ^{5/2}), Δ = 1 + g² − 2gμ.
float hg_dg(float g, float mu) {
    float delta = 1.0 + g * g - 2.0 * g * mu;
    return ((g * g + 3.0) * mu + g * g * g - 5.0 * g) / (4.0 * PI * delta * delta * sqrt(max(delta, 0.0)));
}

// The signed parts in s = Δ^{-1/2} for a = |g| > 0: (s0, s0 − 1, L−, L+).
vec4 hg_parts(float a) {
    float c = 1.0 - a * a;
    float s0 = sqrt((3.0 + a * a) / (3.0 * c * c));
    float s0m1 = a * a * (7.0 - 3.0 * a * a) / (3.0 * c * c) / (s0 + 1.0);
    return vec4(s0, s0m1, s0m1 + a / (1.0 + a), a / (1.0 - a) - s0m1);
}

// The mass M(g) of each signed part of ∂p/∂g.
float hg_dg_mass(float g) {
    float a = abs(g);
    if (a < HG_DIFF_SMALL_G) return 0.75;
    vec4 p = hg_parts(a);
    float c = 1.0 - a * a;
    float k = p.x + 1.0 / (1.0 + a);
    float l = p.z;
    return 3.0 * c * c / (4.0 * a * a) * (k * l * l / 2.0 + l * l * l / 6.0);
}

// cos θ drawn from one signed part of ∂p/∂g (u_comp: the component, u: its inverse CDF).
float hg_diff_sample_cos(float g, bool positive, float u_comp, float u) {
    float a = abs(g);
    bool up = positive == (g >= 0.0);
    float mu;
    if (a < HG_DIFF_SMALL_G) {
        mu = sqrt(u) * (up ? 1.0 : -1.0);
    } else {
        vec4 p = hg_parts(a);
        float sm1;
        if (up) {
            float l = p.w;
            float wa = p.x * l * l;
            float wb = l * l * l / 3.0;
            sm1 = p.y + (u_comp * (wa + wb) < wa ? l * sqrt(u) : l * pow(u, 1.0 / 3.0));
        } else {
            float l = p.z;
            float k = p.x + 1.0 / (1.0 + a);
            float wa = k * l * l / 2.0;
            float wb = l * l * l / 6.0;
            float beta22 = 0.5 - sin(asin(clamp(1.0 - 2.0 * u, -1.0, 1.0)) / 3.0);
            sm1 = p.y - (u_comp * (wa + wb) < wa ? l * sqrt(u) : l * beta22);
        }
        float s = sm1 + 1.0;
        mu = clamp((sm1 * (s + 1.0) + a * a * s * s) / (2.0 * a * s * s), -1.0, 1.0);
    }
    return g >= 0.0 ? mu : -mu;
}

// Direction density of the phase function's differential technique: |∂p/∂g| / (2M(g)).
float phase_pdf_diff(uint m, vec3 d, vec3 wo) {
    float g = medium_g(m);
    return abs(hg_dg(g, dot(d, wo))) / (2.0 * hg_dg_mass(g));
}

// The differential technique: the positive part if u_sign < 0.5, else the negative one, around d.
vec3 phase_sample_diff(uint m, vec3 d, float u_sign, float u_comp, vec2 u) {
    float c = hg_diff_sample_cos(medium_g(m), u_sign < 0.5, u_comp, u.x);
    float sn = sqrt(max(1.0 - c * c, 0.0));
    float phi = 2.0 * PI * u.y;
    return to_world(shading_frame(d), vec3(sn * cos(phi), sn * sin(phi), c));
}

// GRAD of the medium's fields at x (ALGORITHMS.md §8): weight `w_sigma` per channel through the
// extinction scale · sigma_t(x) (its scale and its voxels; `field_sigma` is sigma_t(x), which the
// caller has looked up), `w_albedo` through the albedo's voxels.
// Channel c of an RGB field reaches image channel c only; a grey field reaches all three. Twin of
// extinction_grad and albedo_grad in src/cpu/medium.rs; one param_grad site for every voxel.
void medium_grad(uint m, vec3 x, vec3 field_sigma, vec3 w_sigma, vec3 w_albedo) {
    if (!HAS(G_MEDIUM)) return;
    MediumDesc md = media[m];
    float scale = params[md.p_scale];
    param_grad(md.p_scale, w_sigma * field_sigma);
    [[dont_unroll]] for (uint k = 0u; k < 2u; k++) {
        uint f = k == 0u ? md.sigma_t : md.albedo;
        vec3 w = k == 0u ? w_sigma * scale : w_albedo;
        if (w == vec3(0.0)) continue;
        field_grad(f, x, w);
    }
}

// GRAD of the phase function's value for (d, wo) with weight w per channel: through g.
void phase_grad(uint m, vec3 d, vec3 wo, vec3 w) {
    if (!HAS(G_MEDIUM) || media[m].phase != PHASE_HG) return;
    float g = params[media[m].p_g];
    float c = dot(d, wo);
    float denom = 1.0 + g * g - 2.0 * g * c;
    // d/dg of (1 − g²)/(4π D^{3/2}), D = 1 + g² − 2gc.
    float dfdg = (-2.0 * g * denom - 3.0 * (1.0 - g * g) * (g - c)) / (4.0 * PI * denom * denom * sqrt(max(denom, 0.0)));
    param_grad(media[m].p_g, w * dfdg);
}

// The part (t0, t1) of the segment ray(t), t in [0, t_max), where medium m exists: all of it for
// an unbounded medium, else its intersection with the medium's box (Mitsuba's heterogeneous
// medium lives only inside its sigma_t volume's bounding box); t0 >= t1 when the segment misses
// it. Twin of medium_span in src/cpu/medium.rs, axis by axis in the same order.
vec2 medium_span(uint m, Ray ray, float t_max) {
    float t0 = 0.0;
    float t1 = t_max;
    if (media[m].bounded == 0u) return vec2(t0, t1);
    vec3 lo = media[m].lo;
    vec3 hi = media[m].hi;
    [[dont_unroll]] for (uint axis = 0u; axis < 3u; axis++) {
        float o = ray.origin[axis];
        float d = ray.dir[axis];
        if (d == 0.0) {
            if (o < lo[axis] || o > hi[axis]) return vec2(1.0, 0.0);
            continue;
        }
        float a = (lo[axis] - o) / d;
        float b = (hi[axis] - o) / d;
        t0 = max(t0, min(a, b));
        t1 = min(t1, max(a, b));
    }
    return vec2(t0, t1);
}

// The majorant along a ray through medium m: its grid's cells one after another (a 3D DDA over
// the unit cube of the sigma_t field, whose transform maps the ray there affinely, so distances
// along it stay world distances), or the one majorant of a medium without a grid (cells 0).
// Border cells extend beyond the cube, where lookups clamp. Twin of MajorantWalk in
// src/cpu/medium.rs, operation for operation (`precise`: no fused multiply-adds the twin lacks).
struct MajorantWalk {
    uint base;      // the grid's offset in the majorant array
    uvec3 cells;    // cells along each axis (x 0: no grid)
    vec3 o;         // the ray's origin in the unit cube
    vec3 d;         // its direction there
    uvec3 cell;     // the current cell
    float t;        // where the walk stands
    float t_end;    // the end of the medium's span
    float mu;       // the majorant without a grid
};

MajorantWalk majorant_walk(uint m, vec3 origin, vec3 dir, vec2 span) {
    MediumDesc md = media[m];
    MajorantWalk w = MajorantWalk(md.grid, uvec3(0u), vec3(0.0), vec3(0.0), uvec3(0u), span.x, span.y, md.majorant);
    if (md.grid == NO_PARAM) return w;
    FieldDesc f = load_field(md.sigma_t);
    precise vec3 o = vec3(dot(f.row0, origin), dot(f.row1, origin), dot(f.row2, origin)) + f.shift;
    precise vec3 d = vec3(dot(f.row0, dir), dot(f.row1, dir), dot(f.row2, dir));
    w.cells = uvec3(md.grid_x, md.grid_y, md.grid_z);
    w.o = o;
    w.d = d;
    precise vec3 p = o + span.x * d;
    vec3 n = vec3(w.cells);
    w.cell = uvec3(clamp(floor(p * n), vec3(0.0), n - 1.0));
    return w;
}

// Where the ray leaves the current cell across an inner face of the grid along `axis`
// (FLOAT_MAX when it never does).
float walk_plane(MajorantWalk w, uint axis) {
    uint c = w.cell[axis];
    uint n = w.cells[axis];
    float d = w.d[axis];
    precise float t = FLOAT_MAX;
    if (d > 0.0 && c + 1u < n) {
        t = (float(c + 1u) / float(n) - w.o[axis]) / d;
    } else if (d < 0.0 && c > 0u) {
        t = (float(c) / float(n) - w.o[axis]) / d;
    }
    return t;
}

// Spends optical depth `tau` from where the walk stands: the tentative collision's distance (and
// the majorant there in `mu`), or -1 when the span ends first.
float walk_collide(inout MajorantWalk w, float tau, out float mu) {
    mu = w.mu;
    if (w.cells.x == 0u) {
        float t = w.t + tau / w.mu;
        if (!(t < w.t_end)) return -1.0;
        w.t = t;
        return t;
    }
    // Each pass leaves one cell, and a ray leaves at most this many.
    uint passes = w.cells.x + w.cells.y + w.cells.z + 3u;
    precise float left = tau;
    [[dont_unroll]] for (uint i = 0u; i < passes; i++) {
        float tx = walk_plane(w, 0u);
        float ty = walk_plane(w, 1u);
        float tz = walk_plane(w, 2u);
        float t_exit = min(min(tx, ty), min(tz, w.t_end));
        mu = FloatArray(globals.addr_majorants).v[w.base + (w.cell.z * w.cells.y + w.cell.y) * w.cells.x + w.cell.x];
        if (mu > 0.0) {
            precise float t = w.t + left / mu;
            if (t < t_exit) {
                w.t = t;
                return t;
            }
            left -= max(t_exit - w.t, 0.0) * mu;
        }
        if (!(t_exit < w.t_end)) return -1.0;
        w.t = max(w.t, t_exit);
        uint axis = tx == t_exit ? 0u : (ty == t_exit ? 1u : 2u);
        if (w.d[axis] > 0.0) {
            w.cell[axis] += 1u;
        } else {
            w.cell[axis] -= 1u;
        }
    }
    return -1.0;
}

// Tracking along `ray` in medium m up to t_max, only where the medium exists (medium_span), one sample per step from stream `stream` of
// `vertex`, from step `step` on; the steps' weights multiply `weight`. Delta tracking (`ratio`
// false) stops at a real collision and returns its distance; ratio tracking (true: shadow rays)
// takes every collision as null, so `weight` becomes the transmittance. Returns -1 when the
// flight reaches t_max; past MAX_TRACKING_STEPS the weight is 0. In a replay (`replay`, with
// gw = δL·L for the radiance L the weights multiply) each weight w scatters gw·∂w/w: a null weight
// (σ̄ − σ_t,c)/(σ̄(1 − P)) through σ_t, a real one a_c σ_t,c/(σ̄ P) through a and σ_t, P detached
// (P = 0 in ratio tracking: the nested replay of ALGORITHMS.md §8). One body for both, so a
// kernel inlines one copy of the field lookups and of medium_grad; twin of delta_track and
// ratio_track in src/cpu/medium.rs.
float track(uint m, Ray ray, float t_max, uvec2 key, uint pixel, uint sample_index, uint vertex, uint stream, bool ratio, inout uint step, inout vec3 weight, bool replay, vec3 gw) {
    if (!(media[m].majorant > 0.0)) return -1.0;
    vec2 span = medium_span(m, ray, t_max);
    if (!(span.x < span.y)) return -1.0;
    MajorantWalk walk = majorant_walk(m, ray.origin, ray.dir, span);
    [[dont_unroll]] while (step < MAX_TRACKING_STEPS) {
        vec4 u = uniform4(key, pixel, sample_index, vertex, stream, 0u, step);
        step++;
        float majorant;
        float t = walk_collide(walk, -log(1.0 - u.x), majorant);
        if (t < 0.0) return -1.0;
        vec3 x = ray.origin + t * ray.dir;
        vec3 field_sigma = field_rgb(media[m].sigma_t, x);
        vec3 sigma = params[media[m].p_scale] * field_sigma;   // the extinction: medium_extinction of the twin
        float p_real = ratio ? 0.0 : clamp((sigma.x + sigma.y + sigma.z) / (3.0 * majorant), 0.0, 1.0);
        bool real = !ratio && u.y < p_real;
        vec3 w_sigma;
        vec3 w_albedo = vec3(0.0);
        if (real) {
            vec3 a = field_rgb(media[m].albedo, x);
            weight *= a * sigma / (majorant * p_real);
            w_sigma = safe_div(gw, sigma);
            w_albedo = safe_div(gw, a);
        } else {
            vec3 null_density = vec3(majorant) - sigma;
            weight *= null_density / (majorant * (1.0 - p_real));
            w_sigma = -safe_div(gw, null_density);
        }
        if (replay) medium_grad(m, x, field_sigma, w_sigma, w_albedo);
        if (real) return t;
    }
    weight = vec3(0.0);
    return -1.0;
}

// The medium after crossing a boundary of `interior` (winding normal ng) along dir from `current`.
uint medium_crossed(uint interior, vec3 ng, vec3 dir, uint current) {
    if (interior == NO_MEDIUM) return current;
    return dot(ng, dir) < 0.0 ? interior : NO_MEDIUM;
}

#endif

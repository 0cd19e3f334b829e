// Warps, shading frames and the shared erf/erfinv polynomials (twin of src/sampling.rs).
#ifndef PATHGRAD_SAMPLING_GLSL
#define PATHGRAD_SAMPLING_GLSL

// Orthonormal frame around a unit normal (Duff et al. 2017); the normal is +z in local coordinates.
struct ShadingFrame { vec3 t; vec3 b; vec3 n; };

ShadingFrame shading_frame(vec3 n) {
    float sign_z = n.z >= 0.0 ? 1.0 : -1.0;
    float a = -1.0 / (sign_z + n.z);
    float b = n.x * n.y * a;
    return ShadingFrame(vec3(1.0 + sign_z * n.x * n.x * a, sign_z * b, -sign_z * n.x), vec3(b, sign_z + n.y * n.y * a, -n.y), n);
}

vec3 to_local(ShadingFrame f, vec3 v) { return vec3(dot(v, f.t), dot(v, f.b), dot(v, f.n)); }
vec3 to_world(ShadingFrame f, vec3 v) { return f.t * v.x + f.b * v.y + f.n * v.z; }

// Shirley–Chiu concentric map of the unit square onto the unit disk.
vec2 sample_concentric_disk(vec2 u) {
    vec2 a = 2.0 * u - vec2(1.0);
    if (a.x == 0.0 && a.y == 0.0) return vec2(0.0);
    float r, theta;
    if (abs(a.x) > abs(a.y)) { r = a.x; theta = PI_OVER_4 * (a.y / a.x); }
    else { r = a.y; theta = PI_OVER_2 - PI_OVER_4 * (a.x / a.y); }
    return vec2(r * cos(theta), r * sin(theta));
}

vec3 sample_cosine_hemisphere(vec2 u) {
    vec2 d = sample_concentric_disk(u);
    return vec3(d.x, d.y, sqrt(max(1.0 - d.x * d.x - d.y * d.y, 0.0)));
}

float cosine_hemisphere_pdf(vec3 v) { return max(v.z, 0.0) * INV_PI; }

// Uniform direction on the unit sphere; density 1 / (4π).
vec3 sample_uniform_sphere(vec2 u) {
    float z = 1.0 - 2.0 * u.x;
    float r = sqrt(max(1.0 - z * z, 0.0));
    float phi = 2.0 * PI * u.y;
    return vec3(r * cos(phi), r * sin(phi), z);
}

// Uniform point on a triangle as barycentrics (b1, b2) of vertices 1 and 2.
vec2 sample_uniform_triangle(vec2 u) {
    float su = sqrt(u.x);
    return vec2(u.y * su, su * (1.0 - u.y));
}

// erf_approx of x ≥ 0 given e = exp(−x·x), for callers that need that exponential themselves (the
// Beckmann terms): one exp instead of two, and the same value.
float erf_nonnegative(float x, float e) {
    float t = 1.0 / (1.0 + 0.3275911 * x);
    float poly = t * (0.2548296 + t * (-0.28449674 + t * (1.4214138 + t * (-1.453152 + t * 1.0614054))));
    return 1.0 - poly * e;
}

// Abramowitz & Stegun 7.1.26 (absolute error below 1.5e-7).
float erf_approx(float x) {
    float ax = abs(x);
    float y = erf_nonnegative(ax, exp(-ax * ax));
    return x < 0.0 ? -y : y;
}

// ∫ from −radius to x of the 1D reconstruction filter `kind` (FILTER_TENT or FILTER_GAUSSIAN,
// alpha = −1/(2σ²)); twin of filter_cdf in src/sampling.rs, which derives it.
float filter_cdf(uint kind, float radius, float alpha, float x) {
    if (kind == FILTER_TENT) {
        float r = radius;
        return x <= 0.0 ? (x + r) * (x + r) / (2.0 * r) : r - (r - x) * (r - x) / (2.0 * r);
    }
    float s = sqrt(-1.0 / alpha);
    float bias = exp(alpha * radius * radius);
    return 0.5 * sqrt(PI) * s * (erf_approx(x / s) - erf_approx(-radius / s)) - bias * (x + radius);
}

// The film coordinate along one axis of a sample of pixel `pixel` on a film `extent` pixels long,
// drawn with u from the reconstruction filter around the pixel's centre, truncated to the film
// (bisection on filter_cdf); the box filter is pixel + u. Twin of filter_sample in src/sampling.rs.
float filter_sample(uint kind, float radius, float alpha, uint pixel, uint extent, float u) {
    if (kind == FILTER_BOX) return float(pixel) + u;
    float c = float(pixel) + 0.5;
    float a = max(-radius, -c);
    float b = min(radius, float(extent) - c);
    float ca = filter_cdf(kind, radius, alpha, a);
    float cb = filter_cdf(kind, radius, alpha, b);
    float target = ca + u * (cb - ca);
    float lo = a;
    float hi = b;
    [[dont_unroll]] for (uint step = 0u; step < FILTER_BISECTIONS; step++) {
        float mid = 0.5 * (lo + hi);
        if (filter_cdf(kind, radius, alpha, mid) < target) lo = mid; else hi = mid;
    }
    return c + 0.5 * (lo + hi);
}

// Giles' single-precision inverse error function (2010), x in (-1, 1).
float erfinv_approx(float x) {
    float w = -log((1.0 - x) * (1.0 + x));
    float p;
    if (w < 5.0) {
        w = w - 2.5;
        p = 2.8102264e-8;
        p = 3.4327394e-7 + p * w;
        p = -3.5233877e-6 + p * w;
        p = -4.3915065e-6 + p * w;
        p = 2.1858087e-4 + p * w;
        p = -1.253725e-3 + p * w;
        p = -4.1776816e-3 + p * w;
        p = 0.24664073 + p * w;
        p = 1.5014094 + p * w;
    } else {
        w = sqrt(w) - 3.0;
        p = -2.0021426e-4;
        p = 1.0095056e-4 + p * w;
        p = 1.3493432e-3 + p * w;
        p = -3.6734284e-3 + p * w;
        p = 5.7395077e-3 + p * w;
        p = -7.6224613e-3 + p * w;
        p = 9.4388705e-3 + p * w;
        p = 1.0016741 + p * w;
        p = 2.8329768 + p * w;
    }
    return p * x;
}

#endif

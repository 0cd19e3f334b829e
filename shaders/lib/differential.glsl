// Differential samplers (ALGORITHMS.md §4.2–4.3): signed parts of the α-derivative of the microfacet
// half-vector density with exact inverse-CDF samplers, and the BSDF-level differential technique.
// Twin of src/bsdf/differential.rs: same names, same f32 operation order. No data-dependent loops.
#ifndef PATHGRAD_DIFFERENTIAL_GLSL
#define PATHGRAD_DIFFERENTIAL_GLSL

#include "bsdf.glsl"


// ---- Lambert W on [−1/e, 0): branch-point series start, three Halley steps ----
float lambert_branch_offset(float x) {
    precise float q = fma(x, EULER_E, 1.0);
    return max(q + EULER_E_LO * x, 0.0);
}

float lambert_series(float p) {
    return -1.0 + p * (1.0 + p * (-1.0 / 3.0 + p * (11.0 / 72.0 + p * (-43.0 / 540.0 + p * (769.0 / 17280.0)))));
}

float lambert_halley(float w, float x) {
    float ew = exp(w);
    float f = w * ew - x;
    float wp1 = w + 1.0;
    return w - f / (ew * wp1 - (w + 2.0) * f / (2.0 * wp1));
}

float lambert_w0(float x) {
    float p = sqrt(2.0 * lambert_branch_offset(x));
    float series = lambert_series(p);
    if (p < LAMBERT_SERIES_ONLY) return series;
    float w = x > LAMBERT_W0_SMALL ? x * (1.0 - x) : series;
    w = lambert_halley(w, x);
    w = lambert_halley(w, x);
    w = lambert_halley(w, x);
    return w;
}

float lambert_wm1(float x) {
    if (x >= 0.0) return uintBitsToFloat(0xff800000u);
    float p = sqrt(2.0 * lambert_branch_offset(x));
    float series = lambert_series(-p);
    if (p < LAMBERT_SERIES_ONLY) return series;
    float w = series;
    if (x > LAMBERT_WM1_SMALL) {
        float l1 = log(-x);
        float l2 = log(-l1);
        w = l1 - l2 + l2 / l1;
    }
    w = lambert_halley(w, x);
    w = lambert_halley(w, x);
    w = lambert_halley(w, x);
    return w;
}

// ---- densities ----
float diff_norm(uint distribution, float alpha) {
    return is_beckmann(distribution) ? 4.0 / (EULER_E * alpha) : 1.0 / alpha;
}

// p_abs(h) = |∂α[D cos θh]| / N_α (NaN-free closed forms); 0 if cos θh < 1e-9.
float diff_pdf_abs_h(uint distribution, float alpha, vec3 h) {
    float c = h.z;
    if (c < DIFF_COS_EPSILON) return 0.0;
    float t = (h.x * h.x + h.y * h.y) / (c * c);
    float a2 = alpha * alpha;
    if (is_beckmann(distribution)) {
        float g = exp(-t / a2);
        if (g == 0.0) return 0.0;
        return EULER_E * g * abs(t - a2) / (2.0 * PI * a2 * a2 * c * c * c);
    }
    float cs = c * (a2 + t);
    return 2.0 * a2 * abs(t - a2) / (PI * cs * cs * cs);
}

// p⁺ (tan²θh > α²) or p⁻: 2·p_abs on its support.
float diff_pdf_part_h(uint distribution, float alpha, vec3 h, bool positive) {
    float c = h.z;
    if (c < DIFF_COS_EPSILON) return 0.0;
    float t = (h.x * h.x + h.y * h.y) / (c * c);
    if ((t > alpha * alpha) != positive) return 0.0;
    return 2.0 * diff_pdf_abs_h(distribution, alpha, h);
}

// x = tan²θh/α² by inverting one part's closed-form CDF (+∞ for the positive parts at u_b = 1).
float diff_sample_x(uint distribution, bool positive, float u_b) {
    if (is_beckmann(distribution)) return positive ? -lambert_wm1((u_b - 1.0) / EULER_E) : -lambert_w0(-u_b / EULER_E);
    if (!positive) {
        float s = sqrt(max(1.0 - u_b, 0.0));
        return u_b / ((1.0 + s) * (1.0 + s));
    }
    float r = sqrt(max(u_b, 0.0));
    return (1.0 + r) * (1.0 + r) / (1.0 - u_b);
}

// A half vector (upper hemisphere) from one signed part; false if cos θh < 1e-9.
bool sample_diff_half(uint distribution, float alpha, bool positive, vec2 u, out vec3 h) {
    h = vec3(0.0, 0.0, 1.0);
    float x = diff_sample_x(distribution, positive, u.y);
    float t = alpha * alpha * x;
    float cos_h = 1.0 / sqrt(1.0 + t);
    if (!(cos_h >= DIFF_COS_EPSILON)) return false;
    float sin_h = sqrt(t) * cos_h;
    float phi = 2.0 * PI * u.x;
    h = vec3(sin_h * cos(phi), sin_h * sin(phi), cos_h);
    return true;
}

// Reflection about a half vector from one signed part; false if cos θo ≤ 0, wi·h ≤ 0 or cos θh < 1e-9.
bool sample_diff_part(uint distribution, float alpha, vec3 wi, bool positive, vec2 u, out vec3 wo) {
    wo = vec3(0.0);
    if (wi.z <= 0.0) return false;
    vec3 h;
    if (!sample_diff_half(distribution, alpha, positive, u, h)) return false;
    float wih = dot(wi, h);
    wo = 2.0 * wih * h - wi;
    return wo.z > 0.0 && wih > 0.0;
}

// Half vector and wo·h of a valid reflection configuration (cos θi, cos θo, wi·h, wo·h > 0).
bool reflection_half(vec3 wi, vec3 wo, out vec3 h, out float woh) {
    h = vec3(0.0, 0.0, 1.0);
    woh = 0.0;
    if (wi.z <= 0.0 || wo.z <= 0.0) return false;
    h = normalize(wi + wo);
    woh = dot(wo, h);
    return dot(wi, h) > 0.0 && woh > 0.0;
}

// Coin-mixed direction density p_abs(h)/(4 wo·h) = ½p⁺ + ½p⁻.
float diff_pdf(uint distribution, float alpha, vec3 wi, vec3 wo) {
    vec3 h;
    float woh;
    if (!reflection_half(wi, wo, h, woh)) return 0.0;
    return diff_pdf_abs_h(distribution, alpha, h) / (4.0 * woh);
}

float diff_pdf_part(uint distribution, float alpha, bool positive, vec3 wi, vec3 wo) {
    vec3 h;
    float woh;
    if (!reflection_half(wi, wo, h, woh)) return 0.0;
    return diff_pdf_part_h(distribution, alpha, h, positive) / (4.0 * woh);
}

// ---- rough dielectric (twin: sample_diff_dielectric, diff_pdf_dielectric) ----
// A microfacet normal from one signed part in the hemisphere wi sees, then reflection with
// probability F(wi·m) or refraction, as the primal sampler leaves its visible normal.
bool sample_diff_dielectric(Leaf l, vec3 wi, bool positive, float u_lobe, vec2 u, out vec3 wo) {
    wo = vec3(0.0, 0.0, 1.0);
    if (wi.z == 0.0) return false;
    vec3 m;
    if (!sample_diff_half(l.distribution, l.alpha, positive, u, m)) return false;
    vec3 up = wi.z > 0.0 ? wi : -wi;
    if (dot(up, m) <= 0.0) return false;
    return rdielectric_scatter(l, wi, m, u_lobe, wo);
}

// p_abs(m) · (F or 1 − F) · |∂m/∂wo|: the coin-mixed density.
float diff_pdf_dielectric(Leaf l, vec3 wi, vec3 wo) {
    vec3 m;
    bool refl;
    float eta;
    if (!rdielectric_pair(l, wi, wo, m, refl, eta)) return 0.0;
    float f = fresnel_dielectric(dot(wi, m), l.eta.x);
    return diff_pdf_abs_h(l.distribution, l.alpha, m) * (refl ? f : 1.0 - f) * rdielectric_jacobian(refl, eta, wi, wo, m);
}

// ---- rough plastic (twin: sample_diff_plastic, diff_pdf_plastic) ----
// The coating's lobe by a signed part with the coating's probability, else the base by the cosine.
bool sample_diff_plastic(Leaf l, vec3 wi, bool positive, float u_lobe, vec2 u, out vec3 wo) {
    wo = vec3(0.0);
    if (wi.z <= 0.0) return false;
    if (u_lobe < plastic_coating_probability(l, wi.z)) return sample_diff_part(l.distribution, l.alpha, wi, positive, u, wo);
    wo = sample_cosine_hemisphere(u);
    return wo.z > 0.0;
}

float diff_pdf_plastic(Leaf l, vec3 wi, vec3 wo) {
    if (wi.z <= 0.0 || wo.z <= 0.0) return 0.0;
    float p = plastic_coating_probability(l, wi.z);
    return p * diff_pdf(l.distribution, l.alpha, wi, wo) + (1.0 - p) * wo.z * INV_PI;
}

// ---- BSDF level (ALGORITHMS.md §4.1, §4.3) ----
bool bsdf_diff_capable(Bsdf b) {
    return (HAS(F_BLEND) && b.blend) || is_conductor(b.leaf0.kind) || is_rough_dielectric(b.leaf0.kind)
        || is_plastic(b.leaf0.kind);
}

float bsdf_pdf_diff(Bsdf b, vec3 wi, vec3 wo) {
    if (HAS(F_BLEND) && b.blend) return 0.5 * (leaf_pdf(b.leaf0, wi, wo) + leaf_pdf(b.leaf1, wi, wo));
    if (is_rough_dielectric(b.leaf0.kind)) return diff_pdf_dielectric(b.leaf0, wi, wo);
    if (is_plastic(b.leaf0.kind)) return diff_pdf_plastic(b.leaf0, wi, wo);
    if (!is_conductor(b.leaf0.kind)) return leaf_pdf(b.leaf0, wi, wo);
    return diff_pdf(b.leaf0.distribution, b.leaf0.alpha, wi, wo);
}

// Rough conductor, dielectric or plastic: positive part if u_sign < 0.5 (the dielectric then
// reflects or refracts by u_lobe; the plastic takes its coating so with the coating's
// probability). Blend: child 1 if u_lobe ≤ ½, else child 0, with the child's primal sampler.
// Other leaves: their primal sampler. Value f̂ and pdf bsdf_pdf_diff of the whole BSDF.
BsdfSample bsdf_sample_diff(Bsdf b, vec3 wi, float u_sign, float u_lobe, vec2 u) {
    BsdfSample s = BsdfSample(vec3(0.0), 0.0, vec3(0.0), false, false);
    vec3 wo;
    bool ok;
    if (HAS(F_BLEND) && b.blend) {
        bool second = u_lobe <= 0.5;
        ok = leaf_sample(second ? b.leaf1 : b.leaf0, wi, second ? u_lobe / 0.5 : (u_lobe - 0.5) / 0.5, u, wo);
    } else if (is_rough_dielectric(b.leaf0.kind)) {
        ok = sample_diff_dielectric(b.leaf0, wi, u_sign < 0.5, u_lobe, u, wo);
    } else if (is_plastic(b.leaf0.kind)) {
        ok = sample_diff_plastic(b.leaf0, wi, u_sign < 0.5, u_lobe, u, wo);
    } else if (!is_conductor(b.leaf0.kind)) {
        ok = leaf_sample(b.leaf0, wi, u_lobe, u, wo);
    } else {
        ok = sample_diff_part(b.leaf0.distribution, b.leaf0.alpha, wi, u_sign < 0.5, u, wo);
    }
    if (!ok) return s;
    s.wo = wo;
    s.pdf = bsdf_pdf_diff(b, wi, wo);
    s.value = bsdf_eval(b, wi, wo);
    s.valid = s.pdf > 0.0;
    return s;
}

#endif

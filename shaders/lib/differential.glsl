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

// ---- anisotropic roughness (twin: src/bsdf/differential_aniso.rs) ----
// ∂_{α_t}[D cos θh] in stretched slopes as two separable positive parts, each a mixture of pieces
// (angular cos²φ, sin²φ or uniform) × (radial closed-form inverse); the module doc has the tables.
float aniso_diff_norm(uint distribution, float alpha_target) {
    return is_beckmann(distribution) ? 1.0 / alpha_target : 0.75 / alpha_target;
}

// δ − sin δ on [0, π], by its series below 0.5.
float delta_minus_sin(float d) {
    if (d < 0.5) {
        float d2 = d * d;
        return d * d2 / 6.0 * (1.0 - d2 / 20.0 * (1.0 - d2 / 42.0 * (1.0 - d2 / 72.0 * (1.0 - d2 / 110.0))));
    }
    return d - sin(d);
}

// One Newton step of ψ + sin ψ = c, clamped to [0, π].
float cos2_step_low(float psi, float c) {
    float f = psi + sin(psi) - c;
    return clamp(psi - f / (1.0 + cos(psi)), 0.0, PI);
}

// One Newton step of δ − sin δ = d (skipped where the slope 2 sin²(δ/2) is 0), clamped to [0, π].
float cos2_step_high(float delta, float d) {
    float half_s = sin(0.5 * delta);
    float slope = 2.0 * half_s * half_s;
    return slope > 0.0 ? clamp(delta - (delta_minus_sin(delta) - d) / slope, 0.0, PI) : delta;
}

// φ ∈ [0, π/2] with density (4/π) cos²φ: four Newton steps on ψ = 2φ (u_a ≤ ½) or δ = π − ψ.
float sample_cos2_quarter(float u_a) {
    if (u_a <= 0.5) {
        float c = PI * u_a;
        float psi = 0.5 * c;
        psi = cos2_step_low(psi, c);
        psi = cos2_step_low(psi, c);
        psi = cos2_step_low(psi, c);
        psi = cos2_step_low(psi, c);
        return 0.5 * psi;
    }
    float d = PI * (1.0 - u_a);
    float delta = pow(6.0 * d, 1.0 / 3.0);
    delta = cos2_step_high(delta, d);
    delta = cos2_step_high(delta, d);
    delta = cos2_step_high(delta, d);
    delta = cos2_step_high(delta, d);
    return 0.5 * PI - 0.5 * delta;
}

// φ ∈ [0, 2π) with density cos²φ/π: the quarter sample reflected into quadrant ⌊4u_a⌋.
float sample_cos2_angle(float u_a) {
    float s = 4.0 * u_a;
    float quadrant = min(floor(s), 3.0);
    float phi = sample_cos2_quarter(min(s - quadrant, 1.0));
    if (quadrant == 0.0) return phi;
    if (quadrant == 1.0) return PI - phi;
    if (quadrant == 2.0) return PI + phi;
    return 2.0 * PI - phi;
}

// v = ρ² of one piece (`weighted`: the cos²φ/sin²φ piece); +∞ at u_b = 1.
float aniso_sample_radius2(uint distribution, bool weighted, float u_b) {
    if (is_beckmann(distribution)) {
        return weighted ? max(diff_sample_x(distribution, true, u_b) - 1.0, 0.0) : -log(1.0 - u_b);
    }
    if (weighted) {
        float s = sqrt(max(u_b, 0.0));
        return s * (1.0 + s) / (1.0 - u_b);
    }
    float s = sqrt(max(1.0 - u_b, 0.0));
    return u_b / (s * (1.0 + s));
}

// A half vector from one signed part of the α_u- (target_v false) or α_v-derivative; u_piece picks
// GGX's negative piece (uniform below 2/3). False if cos θh < 1e-9.
bool sample_aniso_diff_half(uint distribution, vec2 alpha, bool target_v, bool positive, float u_piece, vec2 u,
                            out vec3 h) {
    h = vec3(0.0, 0.0, 1.0);
    bool weighted = positive || (!is_beckmann(distribution) && u_piece >= 2.0 / 3.0);
    float v = aniso_sample_radius2(distribution, weighted, u.y);
    float rho = sqrt(v);
    float phi = !weighted ? 2.0 * PI * u.x : (positive ? sample_cos2_angle(u.x) : sample_cos2_angle(u.x) + 0.5 * PI);
    float a = rho * cos(phi);
    float b = rho * sin(phi);
    float sx = alpha.x * (target_v ? b : a);
    float sy = alpha.y * (target_v ? a : b);
    float cos_h = 1.0 / sqrt(1.0 + sx * sx + sy * sy);
    if (!(cos_h >= DIFF_COS_EPSILON)) return false;
    h = vec3(sx * cos_h, sy * cos_h, cos_h);
    return true;
}

// Half-vector density of one signed part (overflow-free forms of the module doc); 0 if cos θh < 1e-9.
float aniso_diff_pdf_part_h(uint distribution, vec2 alpha, bool target_v, vec3 h, bool positive) {
    float c = h.z;
    if (c < DIFF_COS_EPSILON) return 0.0;
    float x = h.x / alpha.x;
    float y = h.y / alpha.y;
    float a = target_v ? y : x;
    float b = target_v ? x : y;
    float a2 = a * a;
    float b2 = b * b;
    float c2 = c * c;
    float norm = PI * alpha.x * alpha.y;
    if (!is_beckmann(distribution)) {
        float s = c2 + a2 + b2;
        float s3 = s * s * s;
        return positive ? 4.0 * a2 * c / (norm * s3) : 4.0 * (c2 + b2) * c / (3.0 * norm * s3);
    }
    float g = exp(-(a2 + b2) / c2);
    if (g == 0.0) return 0.0;
    float neg = g / (norm * c2 * c);
    return positive ? 2.0 * (a2 / c2) * neg : neg;
}

float aniso_diff_pdf_mixed_h(uint distribution, vec2 alpha, bool target_v, vec3 h) {
    return 0.5 * (aniso_diff_pdf_part_h(distribution, alpha, target_v, h, true)
        + aniso_diff_pdf_part_h(distribution, alpha, target_v, h, false));
}

// ---- isotropic or anisotropic: the leaf's roughness picks the sampler (isotropic when equal) ----
// The negative part's piece uniform from u_sign ∈ [½, 1).
float diff_piece(float u_sign) { return (u_sign - 0.5) / 0.5; }

bool sample_diff_half_leaf(uint distribution, vec2 alpha, bool target_v, bool positive, float u_piece, vec2 u,
                           out vec3 h) {
    if (HAS(F_ANISOTROPIC) && alpha.x != alpha.y)
        return sample_aniso_diff_half(distribution, alpha, target_v, positive, u_piece, u, h);
    return sample_diff_half(distribution, alpha.x, positive, u, h);
}

float diff_pdf_part_h_leaf(uint distribution, vec2 alpha, bool target_v, vec3 h, bool positive) {
    if (HAS(F_ANISOTROPIC) && alpha.x != alpha.y) return aniso_diff_pdf_part_h(distribution, alpha, target_v, h, positive);
    return diff_pdf_part_h(distribution, alpha.x, h, positive);
}

float diff_pdf_mixed_h_leaf(uint distribution, vec2 alpha, bool target_v, vec3 h) {
    if (HAS(F_ANISOTROPIC) && alpha.x != alpha.y) return aniso_diff_pdf_mixed_h(distribution, alpha, target_v, h);
    return diff_pdf_abs_h(distribution, alpha.x, h);
}

// ---- rough conductor, isotropic or anisotropic (twin: sample_diff_conductor, diff_pdf_conductor) ----
bool sample_diff_conductor(Leaf l, bool target_v, vec3 wi, bool positive, float u_piece, vec2 u, out vec3 wo) {
    wo = vec3(0.0);
    if (wi.z <= 0.0) return false;
    vec3 h;
    if (!sample_diff_half_leaf(l.distribution, vec2(l.alpha, l.alpha_v), target_v, positive, u_piece, u, h)) return false;
    float wih = dot(wi, h);
    wo = 2.0 * wih * h - wi;
    return wo.z > 0.0 && wih > 0.0;
}

float diff_pdf_conductor(Leaf l, bool target_v, vec3 wi, vec3 wo) {
    vec3 h;
    float woh;
    if (!reflection_half(wi, wo, h, woh)) return 0.0;
    return diff_pdf_mixed_h_leaf(l.distribution, vec2(l.alpha, l.alpha_v), target_v, h) / (4.0 * woh);
}

// ---- rough dielectric (twin: sample_diff_dielectric, diff_pdf_dielectric) ----
// A microfacet normal from one signed part in the hemisphere wi sees, then reflection with
// probability F(wi·m) or refraction, as the primal sampler leaves its visible normal.
bool sample_diff_dielectric(Leaf l, bool target_v, vec3 wi, bool positive, float u_piece, float u_lobe, vec2 u,
                            out vec3 wo) {
    wo = vec3(0.0, 0.0, 1.0);
    if (wi.z == 0.0) return false;
    vec3 m;
    if (!sample_diff_half_leaf(l.distribution, vec2(l.alpha, l.alpha_v), target_v, positive, u_piece, u, m)) return false;
    vec3 up = wi.z > 0.0 ? wi : -wi;
    if (dot(up, m) <= 0.0) return false;
    return rdielectric_scatter(l, wi, m, u_lobe, wo);
}

// p_abs(m) · (F or 1 − F) · |∂m/∂wo|: the coin-mixed density.
float diff_pdf_dielectric(Leaf l, bool target_v, vec3 wi, vec3 wo) {
    vec3 m;
    bool refl;
    float eta;
    if (!rdielectric_pair(l, wi, wo, m, refl, eta)) return 0.0;
    float f = fresnel_dielectric(dot(wi, m), l.eta.x);
    return diff_pdf_mixed_h_leaf(l.distribution, vec2(l.alpha, l.alpha_v), target_v, m) * (refl ? f : 1.0 - f)
        * rdielectric_jacobian(refl, eta, wi, wo, m);
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

// target_v: an anisotropic conductor's or dielectric's target is α_v (else α_u).
float bsdf_pdf_diff(Bsdf b, bool target_v, vec3 wi, vec3 wo) {
    if (HAS(F_BLEND) && b.blend) return 0.5 * (leaf_pdf(b.leaf0, wi, wo) + leaf_pdf(b.leaf1, wi, wo));
    if (is_rough_dielectric(b.leaf0.kind)) return diff_pdf_dielectric(b.leaf0, target_v, wi, wo);
    if (is_plastic(b.leaf0.kind)) return diff_pdf_plastic(b.leaf0, wi, wo);
    if (!is_conductor(b.leaf0.kind)) return leaf_pdf(b.leaf0, wi, wo);
    return diff_pdf_conductor(b.leaf0, target_v, wi, wo);
}

// Rough conductor, dielectric or plastic: positive part if u_sign < 0.5 (the dielectric then
// reflects or refracts by u_lobe; the plastic takes its coating so with the coating's
// probability). Blend: child 1 if u_lobe ≤ ½, else child 0, with the child's primal sampler.
// Other leaves: their primal sampler. Value f̂ and pdf bsdf_pdf_diff of the whole BSDF. An
// anisotropic conductor or dielectric takes its negative part's piece by diff_piece(u_sign).
BsdfSample bsdf_sample_diff(Bsdf b, bool target_v, vec3 wi, float u_sign, float u_lobe, vec2 u) {
    BsdfSample s = BsdfSample(vec3(0.0), 0.0, vec3(0.0), false, false);
    vec3 wo;
    bool ok;
    if (HAS(F_BLEND) && b.blend) {
        bool second = u_lobe <= 0.5;
        ok = leaf_sample(second ? b.leaf1 : b.leaf0, wi, second ? u_lobe / 0.5 : (u_lobe - 0.5) / 0.5, u, wo);
    } else if (is_rough_dielectric(b.leaf0.kind)) {
        ok = sample_diff_dielectric(b.leaf0, target_v, wi, u_sign < 0.5, diff_piece(u_sign), u_lobe, u, wo);
    } else if (is_plastic(b.leaf0.kind)) {
        ok = sample_diff_plastic(b.leaf0, wi, u_sign < 0.5, u_lobe, u, wo);
    } else if (!is_conductor(b.leaf0.kind)) {
        ok = leaf_sample(b.leaf0, wi, u_lobe, u, wo);
    } else {
        ok = sample_diff_conductor(b.leaf0, target_v, wi, u_sign < 0.5, diff_piece(u_sign), u, wo);
    }
    if (!ok) return s;
    s.wo = wo;
    s.pdf = bsdf_pdf_diff(b, target_v, wi, wo);
    s.value = bsdf_eval(b, wi, wo);
    s.valid = s.pdf > 0.0;
    return s;
}

#endif

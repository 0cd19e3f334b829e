// Microfacet BSDFs' building blocks and the rough conductor (twin of src/bsdf/rough_conductor.rs):
// Beckmann and GGX distributions, Smith masking and their α-derivatives, conductor Fresnel,
// visible-normal sampling. Included by bsdf.glsl, which declares Leaf.
#ifndef PATHGRAD_MICROFACET_GLSL
#define PATHGRAD_MICROFACET_GLSL

// ---- rough conductor (ALGORITHMS.md §4.2) ----
float tan2_theta(vec3 v) { return (v.x * v.x + v.y * v.y) / (v.z * v.z); }

// D(h) for roughness a = (α_u, α_v): with T = (h_x²/α_u² + h_y²/α_v²)/h_z², Beckmann
// e^{−T}/(π α_u α_v h_z⁴), GGX 1/(π α_u α_v h_z⁴ (1 + T)²) (twin: microfacet_d_aniso).
// Isotropic roughness (α_u = α_v, always in kernels without anisotropic BSDFs) takes the
// isotropic formulas: fewer operations, and the derivative's sign change at tan²θ = α² exact.
bool isotropic(vec2 a) { return !HAS(F_ANISOTROPIC) || a.x == a.y; }

float microfacet_d(uint distribution, vec2 a, vec3 h) {
    float c = h.z;
    if (c <= 0.0) return 0.0;
    float c2 = c * c;
    float d;
    if (isotropic(a)) {
        float t = (h.x * h.x + h.y * h.y) / c2;
        float a2 = a.x * a.x;
        if (is_beckmann(distribution)) {
            d = exp(-t / a2) / (PI * a2 * c2 * c2);
        } else {
            float s = a2 + t;
            d = a2 / (PI * c2 * c2 * s * s);
        }
    } else {
        float t = (h.x * h.x / (a.x * a.x) + h.y * h.y / (a.y * a.y)) / c2;
        float norm = PI * a.x * a.y * c2 * c2;
        d = is_beckmann(distribution) ? exp(-t) / norm : 1.0 / (norm * (1.0 + t) * (1.0 + t));
    }
    return d * c > D_UNDERFLOW ? d : 0.0;
}
float microfacet_d(uint distribution, float alpha, vec3 h) { return microfacet_d(distribution, vec2(alpha), h); }

// Smith's G1 and its derivatives by α_u and α_v (ALGORITHMS.md §4.2) from one evaluation, through
// the projected roughness s² = (α_u² v_x² + α_v² v_y²)/v_z²: 0 where G1 is constant (masked, or at
// normal incidence). Twin: microfacet_g1_aniso and microfacet_g1_dalpha_aniso of
// src/bsdf/rough_conductor.rs, the same values.
void microfacet_g1_and_dalpha(uint distribution, vec2 a, vec3 v, vec3 h, out float g1, out vec2 dg1) {
    g1 = 0.0;
    dg1 = vec2(0.0);
    if (dot(v, h) * v.z <= 0.0) return;
    if (tan2_theta(v) == 0.0) {
        g1 = 1.0;
        return;
    }
    if (isotropic(a)) {
        // The isotropic derivative whole: in x where the kernel has no anisotropic material (the
        // callers sum the two); else split as ∂s²/∂α_u : ∂s²/∂α_v = v_x² : v_y², as separate α_u
        // and α_v parameters of equal value need.
        float alpha = a.x;
        float tan2 = tan2_theta(v);
        float s2 = alpha * alpha * tan2;
        float whole;
        if (is_beckmann(distribution)) {
            float b = 1.0 / sqrt(s2);
            float e = exp(-b * b);
            float lambda = 0.5 * (erf_nonnegative(b, e) - 1.0) + e / (2.0 * b * sqrt(PI));
            g1 = 1.0 / (1.0 + lambda);
            whole = -g1 * g1 * e / (2.0 * b * alpha * sqrt(PI));
        } else {
            float root = sqrt(1.0 + s2);
            g1 = 2.0 / (1.0 + root);
            whole = -2.0 * (alpha * tan2 / root) / ((1.0 + root) * (1.0 + root));
        }
        vec2 xy2 = v.xy * v.xy;
        dg1 = HAS(F_ANISOTROPIC) ? xy2 * (whole / (xy2.x + xy2.y)) : vec2(whole, 0.0);
        return;
    }
    // precise: G1 must round the same whether or not a kernel also takes its derivative (which
    // shares these values: the driver fused them differently when it was live), so kernels that
    // differentiate fewer parameter kinds give the same bits.
    precise float z2 = v.z * v.z;
    precise float s2 = (a.x * a.x * v.x * v.x + a.y * a.y * v.y * v.y) / z2;
    float dg_ds2;
    if (is_beckmann(distribution)) {
        // Exact Smith Λ (not the rational fit): see src/bsdf/rough_conductor.rs. b > 0, so erf
        // takes the exponential that Λ and the derivative use.
        precise float b = 1.0 / sqrt(s2);
        precise float e = exp(-b * b);
        precise float lambda = 0.5 * (erf_nonnegative(b, e) - 1.0) + e / (2.0 * b * sqrt(PI));
        g1 = 1.0 / (1.0 + lambda);
        dg_ds2 = -g1 * g1 * e / (4.0 * b * s2 * sqrt(PI));
    } else {
        precise float root = sqrt(1.0 + s2);
        g1 = 2.0 / (1.0 + root);
        dg_ds2 = -1.0 / (root * (1.0 + root) * (1.0 + root));
    }
    dg1 = vec2(dg_ds2 * 2.0 * a.x * v.x * v.x / z2, dg_ds2 * 2.0 * a.y * v.y * v.y / z2);
}

float microfacet_g1(uint distribution, vec2 a, vec3 v, vec3 h) {
    float g1;
    vec2 dg1;
    microfacet_g1_and_dalpha(distribution, a, v, h, g1, dg1);
    return g1;
}
float microfacet_g1(uint distribution, float alpha, vec3 v, vec3 h) { return microfacet_g1(distribution, vec2(alpha), v, h); }

vec3 fresnel_conductor(float c, vec3 eta, vec3 k) {
    float c2 = c * c;
    float s2 = 1.0 - c2;
    float s4 = s2 * s2;
    vec3 t1 = eta * eta - k * k - vec3(s2);
    vec3 q = sqrt(t1 * t1 + 4.0 * eta * eta * k * k);
    vec3 a = sqrt(max((q + t1) * 0.5, vec3(0.0)));
    vec3 rs = (q + vec3(c2) - 2.0 * c * a) / (q + vec3(c2) + 2.0 * c * a);
    vec3 rp = rs * (q * c2 + vec3(s4) - 2.0 * c * a * s2) / (q * c2 + vec3(s4) + 2.0 * c * a * s2);
    return (rs + rp) * 0.5;
}

// (∂F/∂eta, ∂F/∂k) of one channel of fresnel_conductor along (ee, kk) = (1, 0) or (0, 1)
// (twin: fresnel_conductor_dior_channel of src/bsdf/rough_conductor.rs, the same expressions): where
// t1 < 0, a = eta·k·√(2/(q − t1)), cancellation-free, so the derivative stays finite at eta = 0
// and k = 0 (there the right derivative).
float fresnel_conductor_dior_along(float c, float e, float k, float ee, float kk) {
    float c2 = c * c;
    float s2 = 1.0 - c2;
    float s4 = s2 * s2;
    float t1 = e * e - k * k - s2;
    float q = sqrt(t1 * t1 + 4.0 * e * e * k * k);
    float u = q - t1;
    float root = t1 < 0.0 ? sqrt(2.0 / u) : 0.0;
    float a = t1 < 0.0 ? e * k * root : sqrt(max((q + t1) * 0.5, 0.0));
    float dt1 = 2.0 * e * ee - 2.0 * k * kk;
    float dq = q > 0.0 ? (t1 * dt1 + 4.0 * e * k * (e * kk + k * ee)) / q : 0.0;
    float da = 0.0;
    if (t1 < 0.0) da = (ee * k + e * kk) * root - e * k * root / (2.0 * u) * (dq - dt1);
    else if (a > 0.0) da = (dq + dt1) / (4.0 * a);
    float n = q + c2 - 2.0 * c * a;
    float d = q + c2 + 2.0 * c * a;
    float dn = dq - 2.0 * c * da;
    float dd = dq + 2.0 * c * da;
    float rs = n / d;
    float drs = (dn * d - n * dd) / (d * d);
    float m = q * c2 + s4 - 2.0 * c * a * s2;
    float m2 = q * c2 + s4 + 2.0 * c * a * s2;
    float dm = dq * c2 - 2.0 * c * s2 * da;
    float dm2 = dq * c2 + 2.0 * c * s2 * da;
    float r = m / m2;
    float dr = (dm * m2 - m * dm2) / (m2 * m2);
    return 0.5 * (drs + drs * r + rs * dr);
}

// ∂F/∂eta and ∂F/∂k per channel of fresnel_conductor (twin: fresnel_conductor_dior).
void fresnel_conductor_dior(float c, vec3 eta, vec3 k, out vec3 d_eta, out vec3 d_k) {
    vec3 d[2];
    // One inlined copy: the six (channel, direction) pairs in a loop.
    [[dont_unroll]] for (int i = 0; i < 6; i++) {
        int ch = i % 3;
        d[i / 3][ch] = fresnel_conductor_dior_along(c, eta[ch], k[ch], i < 3 ? 1.0 : 0.0, i < 3 ? 0.0 : 1.0);
    }
    d_eta = d[0];
    d_k = d[1];
}

// f̂ and the solid-angle density of wo, sharing D and G1(wi): one evaluation where the path needs
// both (NEE's direction, a sampled direction). Twin: microfacet_eval and microfacet_pdf of
// src/bsdf/rough_conductor.rs, the same values.
vec3 microfacet_eval_pdf(Leaf l, vec3 wi, vec3 wo, out float pdf) {
    pdf = 0.0;
    if (wi.z <= 0.0 || wo.z <= 0.0) return vec3(0.0);
    vec3 h = normalize(wi + wo);
    vec2 a = vec2(l.alpha, l.alpha_v);
    float d = microfacet_d(l.distribution, a, h);
    float gi = microfacet_g1(l.distribution, a, wi, h);
    if (dot(wi, h) > 0.0 && dot(wo, h) > 0.0) pdf = d * gi / (4.0 * wi.z);
    if (d == 0.0) return vec3(0.0);
    float g = gi * microfacet_g1(l.distribution, a, wo, h);
    return fresnel_conductor(dot(wi, h), l.eta, l.k) * l.color * (d * g / (4.0 * wi.z));
}

// (∂D/∂α_u, ∂D/∂α_v) given d = D(h); 0 where the underflow guard zeroes D (twin:
// microfacet_d_dalpha_aniso, which computes D itself; microfacet_d_dalpha the whole, in x).
vec2 microfacet_d_dalpha_of(uint distribution, vec2 a, vec3 h, float d) {
    if (d == 0.0) return vec2(0.0);
    // Whole in x only where no material is anisotropic: separate α_u and α_v parameters of equal
    // value take the general split below.
    if (!HAS(F_ANISOTROPIC)) {
        float t = (h.x * h.x + h.y * h.y) / (h.z * h.z);
        float a2 = a.x * a.x;
        if (is_beckmann(distribution)) return vec2(d * 2.0 * (t - a2) / (a2 * a.x), 0.0);
        return vec2(d * 2.0 * (t - a2) / (a.x * (a2 + t)), 0.0);
    }
    float x2 = h.x * h.x;
    float y2 = h.y * h.y;
    float z2 = h.z * h.z;
    float scale = is_beckmann(distribution) ? 2.0 / z2 : 4.0 / (x2 / (a.x * a.x) + y2 / (a.y * a.y) + z2);
    vec2 a3 = a * a * a;
    return vec2(d * (scale * x2 / a3.x - 1.0 / a.x), d * (scale * y2 / a3.y - 1.0 / a.y));
}

// The scalar D(h)·G1(wi, h)·G1(wo, h)/(4 cos θi) and its derivatives by α_u and α_v (wi, wo in
// the upper hemisphere); 0 where D underflows. Twin: microfacet_eval_scalar_parts of
// rough_conductor.rs. f̂ of a conductor is F · specular · scalar.
void microfacet_scalar_parts(uint distribution, vec2 a, vec3 wi, vec3 wo, vec3 h, out float scalar, out vec2 dscalar) {
    scalar = 0.0;
    dscalar = vec2(0.0);
    float d = microfacet_d(distribution, a, h);
    if (d == 0.0) return;
    float gi, go;
    vec2 dgi, dgo;
    microfacet_g1_and_dalpha(distribution, a, wi, h, gi, dgi);
    microfacet_g1_and_dalpha(distribution, a, wo, h, go, dgo);
    vec2 dd = microfacet_d_dalpha_of(distribution, a, h, d);
    float inv = 1.0 / (4.0 * wi.z);
    scalar = d * gi * go * inv;
    dscalar = (dd * gi * go + d * (dgi * go + gi * dgo)) * inv;
}

void microfacet_eval_parts(Leaf l, vec3 wi, vec3 wo, out vec3 f, out float scalar, out vec2 dscalar) {
    f = vec3(0.0);
    scalar = 0.0;
    dscalar = vec2(0.0);
    if (wi.z <= 0.0 || wo.z <= 0.0) return;
    vec3 h = normalize(wi + wo);
    microfacet_scalar_parts(l.distribution, vec2(l.alpha, l.alpha_v), wi, wo, h, scalar, dscalar);
    f = fresnel_conductor(dot(wi, h), l.eta, l.k);
}

vec2 sample_ggx_slopes(float cos_theta, vec2 u) {
    vec2 p = sample_concentric_disk(u);
    float s = 0.5 * (1.0 + cos_theta);
    p.y = (1.0 - s) * sqrt(max(1.0 - p.x * p.x, 0.0)) + s * p.y;
    float z = sqrt(max(1.0 - p.x * p.x - p.y * p.y, 0.0));
    float sin_theta = sqrt(max(1.0 - cos_theta * cos_theta, 0.0));
    float norm = 1.0 / (sin_theta * p.y + cos_theta * z);
    return vec2((cos_theta * p.y - sin_theta * z) * norm, p.x * norm);
}

vec2 sample_beckmann_slopes(float cos_theta, vec2 u) {
    u = clamp(u, vec2(BECKMANN_U_CLAMP), vec2(1.0 - BECKMANN_U_CLAMP));
    if (cos_theta > BECKMANN_NORMAL_INCIDENCE) {
        float r = sqrt(-log(1.0 - u.x));
        float phi = 2.0 * PI * u.y;
        return vec2(r * cos(phi), r * sin(phi));
    }
    float inv_sqrt_pi = sqrt(INV_PI);
    float tan_theta = sqrt(max(1.0 - cos_theta * cos_theta, 0.0)) / cos_theta;
    float cot_theta = 1.0 / tan_theta;
    float e = exp(-cot_theta * cot_theta);   // cot θ > 0: erf takes this exponential
    float m = erf_nonnegative(cot_theta, e);
    float x = m - (m + 1.0) * erf_approx(sqrt(-log(u.x)));
    float target = u.x * (1.0 + m + inv_sqrt_pi * tan_theta * e);
    // Three Newton steps, then the slope at the result: a loop, so lavapipe compiles one copy of
    // the inverse erf and the exponential instead of four and three (four iterations a sample are
    // nothing to the loop budget of a driver that has one, PLATFORM.md §6.1).
    float slope;
    [[dont_unroll]] for (uint step = 0u; step < 4u; step++) {
        slope = erfinv_approx(x);
        if (step == 3u) break;
        x -= (1.0 + x + inv_sqrt_pi * tan_theta * exp(-slope * slope) - target) / (1.0 - slope * tan_theta);
    }
    return vec2(slope, erfinv_approx(2.0 * u.y - 1.0));
}

// A microfacet normal drawn from the normals visible from wi (upper hemisphere).
bool microfacet_visible_normal(uint distribution, vec2 a, vec3 wi, vec2 u, out vec3 h) {
    h = vec3(0.0, 0.0, 1.0);
    if (wi.z <= 0.0) return false;
    vec3 ws = normalize(vec3(a.x * wi.x, a.y * wi.y, wi.z));
    float sin2 = ws.x * ws.x + ws.y * ws.y;
    float sin_phi = 0.0;
    float cos_phi = 1.0;
    if (sin2 > AZIMUTH_EPSILON * AZIMUTH_EPSILON) {
        float inv = 1.0 / sqrt(sin2);
        sin_phi = clamp(ws.y * inv, -1.0, 1.0);
        cos_phi = clamp(ws.x * inv, -1.0, 1.0);
    }
    vec2 slope = is_beckmann(distribution) ? sample_beckmann_slopes(ws.z, u) : sample_ggx_slopes(ws.z, u);
    float mx = (cos_phi * slope.x - sin_phi * slope.y) * a.x;
    float my = (sin_phi * slope.x + cos_phi * slope.y) * a.y;
    if (isnan(mx) || isinf(mx) || isnan(my) || isinf(my)) return false;
    h = normalize(vec3(-mx, -my, 1.0));
    return true;
}

// A reflected direction about a visible normal; valid = false when it falls below the surface.
bool microfacet_sample(uint distribution, vec2 a, vec3 wi, vec2 u, out vec3 wo) {
    wo = vec3(0.0);
    vec3 h;
    if (!microfacet_visible_normal(distribution, a, wi, u, h)) return false;
    wo = 2.0 * dot(wi, h) * h - wi;
    return wo.z > 0.0 && dot(wi, h) > 0.0;
}

#endif

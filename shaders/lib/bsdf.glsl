// BSDFs: Lambertian, rough conductor (Beckmann/GGX, VNDF sampling), rough plastic, rough and
// smooth dielectrics, smooth conductor and plastic, blend (twin
// of src/bsdf/).
// Local frame, normal +z; eval returns f̂ = f·max(0, cos θo); pdfs are solid-angle densities of wo.
#ifndef PATHGRAD_BSDF_GLSL
#define PATHGRAD_BSDF_GLSL

#extension GL_EXT_control_flow_attributes : require
#include "sampling.glsl"
#include "features.glsl"


// A rough plastic keeps (η, coating sampling weight, nonlinear) in `eta`, its specular
// reflectance in `k` and its coating table's offset in `table` (Material's layout).
// A rough conductor's roughness is (alpha, alpha_v) (α_u along the frame's x, α_v along y); other
// leaves read alpha only.
struct Leaf { uint kind; uint distribution; float alpha; vec3 color; vec3 eta; vec3 k; uint table; float alpha_v; };
// A normal map's wrapper (`mapped`; twin: Perturbed of src/bsdf/mod.rs): the local frame is the
// perturbed one; base_n is the unperturbed normal in it, nmap_alpha2 the shadow terminator's α².
struct Bsdf { Leaf leaf0; Leaf leaf1; float weight; bool blend; bool mapped; vec3 base_n; float nmap_alpha2; };
// A delta lobe's sample (`delta`) has its choice probability as `pdf` and its weight × pdf as
// `value` (src/bsdf/specular.rs).
struct BsdfSample { vec3 wo; float pdf; vec3 value; bool valid; bool delta; };
// ∂ by the colour (albedo or reflectance), the roughness and a dielectric's transmittance, per
// image channel.
struct LeafGrad { vec3 color; vec3 alpha; vec3 trans; vec3 alpha_v; };
struct BsdfGrad { LeafGrad leaf0; LeafGrad leaf1; vec3 weight; };

// Whether `distribution` is Beckmann, folded to a constant when the kernel has only one of the two.
bool is_beckmann(uint distribution) {
    return !HAS(F_GGX) || (HAS(F_BECKMANN) && distribution == DIST_BECKMANN);
}

// The leaf kinds' feature bits; a kind test folds to a constant when the kernel has no other kind.
#define LEAF_KIND_BITS (F_DIFFUSE | F_CONDUCTOR | F_PLASTIC | F_DELTA | F_SMOOTH_PLASTIC | F_ROUGH_DIELECTRIC)
bool only_kind(uint bit) { return (FEATURES & uint(LEAF_KIND_BITS)) == uint(bit); }

// Whether leaf `kind` is a rough plastic.
bool is_plastic(uint kind) {
    return HAS(F_PLASTIC) && (only_kind(F_PLASTIC) || kind == LEAF_ROUGH_PLASTIC);
}

// Whether leaf `kind` is purely smooth (conductor, dielectric, thin dielectric).
bool is_delta(uint kind) {
    return HAS(F_DELTA) && (only_kind(F_DELTA) || (kind >= LEAF_CONDUCTOR && kind <= LEAF_THIN_DIELECTRIC));
}

// Whether leaf `kind` is a smooth plastic.
bool is_smooth_plastic(uint kind) {
    return HAS(F_SMOOTH_PLASTIC) && (only_kind(F_SMOOTH_PLASTIC) || kind == LEAF_PLASTIC);
}

// Whether leaf `kind` is a rough dielectric.
bool is_rough_dielectric(uint kind) {
    return HAS(F_ROUGH_DIELECTRIC) && (only_kind(F_ROUGH_DIELECTRIC) || kind == LEAF_ROUGH_DIELECTRIC);
}

// Whether leaf `kind` is Lambertian.
bool is_diffuse(uint kind) {
    return (FEATURES & uint(F_CONDUCTOR | F_PLASTIC | F_DELTA | F_SMOOTH_PLASTIC | F_ROUGH_DIELECTRIC)) == 0u
        || (HAS(F_DIFFUSE) && kind == LEAF_DIFFUSE);
}

// Whether leaf `kind` is a rough conductor.
bool is_conductor(uint kind) {
    return !is_plastic(kind) && !is_delta(kind) && !is_smooth_plastic(kind) && !is_rough_dielectric(kind)
        && !is_diffuse(kind);
}

// ---- Lambertian (ALGORITHMS.md §4.1) ----
vec3 diffuse_eval(vec3 albedo, vec3 wi, vec3 wo) {
    return (wi.z > 0.0 && wo.z > 0.0) ? albedo * (wo.z * INV_PI) : vec3(0.0);
}
float diffuse_pdf(vec3 wi, vec3 wo) {
    return (wi.z > 0.0 && wo.z > 0.0) ? wo.z * INV_PI : 0.0;
}

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
        // The isotropic derivative whole, in x (callers sum the two).
        float alpha = a.x;
        float tan2 = tan2_theta(v);
        float s2 = alpha * alpha * tan2;
        if (is_beckmann(distribution)) {
            float b = 1.0 / sqrt(s2);
            float e = exp(-b * b);
            float lambda = 0.5 * (erf_nonnegative(b, e) - 1.0) + e / (2.0 * b * sqrt(PI));
            g1 = 1.0 / (1.0 + lambda);
            dg1 = vec2(-g1 * g1 * e / (2.0 * b * alpha * sqrt(PI)), 0.0);
            return;
        }
        float root = sqrt(1.0 + s2);
        g1 = 2.0 / (1.0 + root);
        dg1 = vec2(-2.0 * (alpha * tan2 / root) / ((1.0 + root) * (1.0 + root)), 0.0);
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
// microfacet_d_dalpha_aniso, which computes D itself).
vec2 microfacet_d_dalpha_of(uint distribution, vec2 a, vec3 h, float d) {
    if (d == 0.0) return vec2(0.0);
    if (isotropic(a)) {
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

// ---- rough plastic (src/bsdf/rough_plastic.rs states the model) ----
// The coating tables, read through the scene's addresses in the render kernels (lib/abi.glsl,
// included before this file there); the BSDF probes have no scene, no rough plastic, and read 0.
#ifdef PATHGRAD_ABI_GLSL
layout(buffer_reference, scalar, buffer_reference_align = 4) readonly buffer TableArray { float v[]; };
#define coating_table(i) (TableArray(globals.addr_tables).v[i])
#else
#define coating_table(i) 0.0
#endif

// Linear interpolation at μ in the table's T (offset 0) or ∂T/∂α (offset COATING_RES).
float coating_lerp(uint table, uint offset, float mu) {
    float x = mu * float(COATING_RES - 1u);
    uint i = min(uint(x), COATING_RES - 2u);
    float v0 = coating_table(table + offset + i);
    float v1 = coating_table(table + offset + i + 1u);
    return v0 + (v1 - v0) * (x - float(i));
}

// Dielectric Fresnel reflectance (total internal reflection gives 1).
float fresnel_dielectric(float cos_i, float eta) {
    bool outside = cos_i >= 0.0;
    float eta_it = outside ? eta : 1.0 / eta;
    float eta_ti = outside ? 1.0 / eta : eta;
    float cos_t2 = 1.0 - (1.0 - cos_i * cos_i) * eta_ti * eta_ti;
    float ci = abs(cos_i);
    float ct = sqrt(max(cos_t2, 0.0));
    if (eta == 1.0) return 0.0;
    if (ci == 0.0) return 1.0;
    float a_s = (ci - eta_it * ct) / (ci + eta_it * ct);
    float a_p = (ct - eta_it * ci) / (ct + eta_it * ci);
    return 0.5 * (a_s * a_s + a_p * a_p);
}

float plastic_coating_probability(Leaf l, float cos_i) {
    float t_i = coating_lerp(l.table, 0u, cos_i);
    float ps = (1.0 - t_i) * l.eta.y;
    float pd = t_i * (1.0 - l.eta.y);
    return ps / (ps + pd);
}

// 1 / (1 − ρ̄ Rᵢ) per channel.
vec3 plastic_renormalisation(Leaf l) {
    vec3 rbar = l.eta.z != 0.0 ? l.color : vec3(1.0);
    return vec3(1.0) / (vec3(1.0) - rbar * coating_table(l.table + 2u * COATING_RES));
}

vec3 plastic_eval_pdf(Leaf l, vec3 wi, vec3 wo, out float pdf) {
    pdf = 0.0;
    if (wi.z <= 0.0 || wo.z <= 0.0) return vec3(0.0);
    vec3 h = normalize(wi + wo);
    float d = microfacet_d(l.distribution, l.alpha, h);
    float gi = microfacet_g1(l.distribution, l.alpha, wi, h);
    float p = plastic_coating_probability(l, wi.z);
    pdf = p * (d * gi / (4.0 * wi.z)) + (1.0 - p) * wo.z * INV_PI;
    float scalar = d == 0.0 ? 0.0 : d * gi * microfacet_g1(l.distribution, l.alpha, wo, h) / (4.0 * wi.z);
    float t_i = coating_lerp(l.table, 0u, wi.z);
    float t_o = coating_lerp(l.table, 0u, wo.z);
    float base = INV_PI / (l.eta.x * l.eta.x) * wo.z * t_i * t_o;
    return l.k * (fresnel_dielectric(dot(wi, h), l.eta.x) * scalar) + l.color * plastic_renormalisation(l) * base;
}

bool plastic_sample(Leaf l, vec3 wi, float u_lobe, vec2 u, out vec3 wo) {
    wo = vec3(0.0);
    if (wi.z <= 0.0) return false;
    if (u_lobe < plastic_coating_probability(l, wi.z)) {
        vec3 m;
        if (!microfacet_visible_normal(l.distribution, vec2(l.alpha), wi, u, m)) return false;
        wo = 2.0 * dot(wi, m) * m - wi;
    } else {
        wo = sample_cosine_hemisphere(u);
    }
    return wo.z > 0.0;
}

// ---- rough dielectric (src/bsdf/rough_dielectric.rs states the model): color = reflectance,
// k = transmittance, eta.x = η ----

// The half vector m of (wi, wo) (upper hemisphere), whether the pair reflects (refl), and η for wi's
// side; false where the BSDF is 0 (grazing wi, or a direction seeing m from its other side).
bool rdielectric_pair(Leaf l, vec3 wi, vec3 wo, out vec3 m, out bool refl, out float eta) {
    refl = wi.z * wo.z > 0.0;
    eta = wi.z > 0.0 ? l.eta.x : 1.0 / l.eta.x;
    m = normalize(wi + wo * (refl ? 1.0 : eta));
    if (m.z < 0.0) m = -m;
    return wi.z != 0.0 && !any(isnan(m)) && dot(wi, m) * wi.z > 0.0 && dot(wo, m) * wo.z > 0.0;
}

// f̂ per unit of the lobe's colour divided by D·G (twin: unit_over_dg).
float rdielectric_unit(bool refl, float eta, float f, vec3 wi, vec3 wo, vec3 m) {
    if (refl) return f / (4.0 * abs(wi.z));
    float im = dot(wi, m);
    float om = dot(wo, m);
    float d = im + eta * om;
    return (1.0 - f) * abs(im * om / (wi.z * d * d));
}

vec3 rdielectric_eval_pdf(Leaf l, vec3 wi, vec3 wo, out float pdf) {
    pdf = 0.0;
    vec3 m;
    bool refl;
    float eta;
    if (!rdielectric_pair(l, wi, wo, m, refl, eta)) return vec3(0.0);
    vec3 up = wi.z > 0.0 ? wi : -wi;
    float d = microfacet_d(l.distribution, l.alpha, m);
    float gi = microfacet_g1(l.distribution, l.alpha, wi, m);
    float f = fresnel_dielectric(dot(wi, m), l.eta.x);
    float om = dot(wo, m);
    float jacobian;
    if (refl) {
        jacobian = abs(1.0 / (4.0 * om));
    } else {
        float s = dot(wi, m) + eta * om;
        jacobian = abs(eta * eta * om / (s * s));
    }
    // G1 of the mirrored wi equals G1 of wi (it depends on tan²θ and the side test only).
    pdf = d * gi * max(dot(up, m), 0.0) / up.z * (refl ? f : 1.0 - f) * jacobian;
    if (d == 0.0) return vec3(0.0);
    float dg = d * gi * microfacet_g1(l.distribution, l.alpha, wo, m);
    return (refl ? l.color : l.k) * (dg * rdielectric_unit(refl, eta, f, wi, wo, m));
}

bool rdielectric_sample(Leaf l, vec3 wi, float u_lobe, vec2 u, out vec3 wo) {
    wo = vec3(0.0, 0.0, 1.0);
    if (wi.z == 0.0) return false;
    vec3 up = wi.z > 0.0 ? wi : -wi;
    vec3 m;
    if (!microfacet_visible_normal(l.distribution, vec2(l.alpha), up, u, m)) return false;
    float im = dot(wi, m);
    float f = fresnel_dielectric(im, l.eta.x);
    bool refl = u_lobe <= f;
    if (refl) {
        wo = 2.0 * im * m - wi;
    } else {
        // Mitsuba's refract through m: η_t/η_i and the transmitted cosine for wi's side.
        bool outside = im >= 0.0;
        float eta_ti = outside ? 1.0 / l.eta.x : l.eta.x;
        float ct = sqrt(max(1.0 - (1.0 - im * im) * eta_ti * eta_ti, 0.0));
        wo = m * (im * eta_ti + (outside ? -ct : ct)) - wi * eta_ti;
    }
    return (wi.z * wo.z > 0.0) == refl && dot(wo, m) * wo.z > 0.0 && !any(isnan(wo));
}

// ∂f̂/∂(lobe colour) (in color, or in trans for a transmitted pair) and ∂f̂/∂α, times adj.
LeafGrad rdielectric_eval_grad(Leaf l, vec3 wi, vec3 wo, vec3 adj) {
    LeafGrad g = LeafGrad(vec3(0.0), vec3(0.0), vec3(0.0), vec3(0.0));
    vec3 m;
    bool refl;
    float eta;
    if (!rdielectric_pair(l, wi, wo, m, refl, eta)) return g;
    float d = microfacet_d(l.distribution, l.alpha, m);
    if (d == 0.0) return g;
    float gi, go;
    vec2 dgi, dgo;
    microfacet_g1_and_dalpha(l.distribution, vec2(l.alpha), wi, m, gi, dgi);
    microfacet_g1_and_dalpha(l.distribution, vec2(l.alpha), wo, m, go, dgo);
    vec2 dd = microfacet_d_dalpha_of(l.distribution, vec2(l.alpha), m, d);
    float ddg = (dd.x + dd.y) * gi * go + d * ((dgi.x + dgi.y) * go + gi * (dgo.x + dgo.y));
    float unit = rdielectric_unit(refl, eta, fresnel_dielectric(dot(wi, m), l.eta.x), wi, wo, m);
    vec3 dcolour = adj * (d * gi * go * unit);
    if (refl) g.color = dcolour; else g.trans = dcolour;
    g.alpha = adj * (refl ? l.color : l.k) * (ddg * unit);
    return g;
}

// ---- smooth leaves (src/bsdf/specular.rs): color = reflectance, k = transmittance (dielectrics)
// or the conductor's k, eta = the conductor's η or (η, –, –) ----

// The lobe u_lobe chooses: direction, choice probability, weight per unit of its colour, and
// whether it transmits; false where the leaf has nothing to give (a conductor seen from below).
bool smooth_lobe(Leaf l, vec3 wi, float u_lobe, out vec3 wo, out float pdf, out vec3 unit, out bool transmitted) {
    wo = vec3(-wi.x, -wi.y, wi.z);
    pdf = 1.0;
    unit = vec3(1.0);
    transmitted = false;
    if (l.kind == LEAF_CONDUCTOR) {
        if (wi.z <= 0.0) return false;
        unit = fresnel_conductor(wi.z, l.eta, l.k);
        return true;
    }
    bool thin = l.kind == LEAF_THIN_DIELECTRIC;
    float cos_i = thin ? abs(wi.z) : wi.z;
    float r = fresnel_dielectric(cos_i, l.eta.x);
    if (thin) r = r * 2.0 / (1.0 + r);
    if (u_lobe <= r) {
        pdf = r;
    } else {
        pdf = 1.0 - r;
        transmitted = true;
        if (thin) {
            wo = -wi;
        } else {
            // Mitsuba's fresnel: the transmitted cosine and η_t/η_i for wi's side.
            bool outside = wi.z >= 0.0;
            float eta_ti = outside ? 1.0 / l.eta.x : l.eta.x;
            float ct = sqrt(max(1.0 - (1.0 - wi.z * wi.z) * eta_ti * eta_ti, 0.0));
            wo = vec3(-eta_ti * wi.x, -eta_ti * wi.y, outside ? -ct : ct);
            unit = vec3(eta_ti * eta_ti);
        }
    }
    return pdf > 0.0;
}

// Whether b has only delta lobes (its vertices get no next-event estimation).
bool bsdf_is_smooth(Bsdf b) {
    return HAS(F_DELTA) && !(HAS(F_BLEND) && b.blend) && is_delta(b.leaf0.kind);
}

BsdfSample smooth_sample(Leaf l, vec3 wi, float u_lobe) {
    BsdfSample s = BsdfSample(vec3(0.0), 0.0, vec3(0.0), false, true);
    vec3 unit;
    bool transmitted;
    s.valid = smooth_lobe(l, wi, u_lobe, s.wo, s.pdf, unit, transmitted);
    s.value = unit * (transmitted ? l.k : l.color) * s.pdf;
    return s;
}

// ∂value/∂colour per channel of the sample toward wo, times adj: in `color` for the reflectance,
// in `trans` for the transmittance (a transmitted sample).
LeafGrad smooth_value_grad(Leaf l, vec3 wi, vec3 wo, vec3 adj) {
    bool transmitted = wi.z * wo.z < 0.0;
    vec3 w;
    float pdf;
    vec3 unit;
    bool t;
    if (!smooth_lobe(l, wi, transmitted ? 1.0 : 0.0, w, pdf, unit, t)) return LeafGrad(vec3(0.0), vec3(0.0), vec3(0.0), vec3(0.0));
    vec3 g = adj * unit * pdf;
    return transmitted ? LeafGrad(vec3(0.0), vec3(0.0), g, vec3(0.0)) : LeafGrad(g, vec3(0.0), vec3(0.0), vec3(0.0));
}

// ---- smooth plastic (src/bsdf/plastic.rs): color = ρ, k = the coating's colour, eta = (η, w,
// nonlinear) ----

// Mitsuba's fitted diffuse Fresnel reflectance.
float fresnel_diffuse_reflectance(float eta) {
    float inv = 1.0 / eta;
    if (eta < 1.0) return 0.0636 * inv + eta * (eta * -1.4399 + 0.7099) + 0.6681;
    return 0.919317 + inv * (-3.4793 + inv * (6.75335 + inv * (-7.80989 + inv * (4.98554 + inv * -1.36881))));
}

// The probability of sampling the coating at cos θi (and F(cos θi) in f_i).
float splastic_coating(Leaf l, float cos_i, out float f_i) {
    f_i = fresnel_dielectric(cos_i, l.eta.x);
    float ps = f_i * l.eta.y;
    float pd = (1.0 - f_i) * (1.0 - l.eta.y);
    return ps / (ps + pd);
}

// 1 / (1 − ρ̄ F_dr(1/η)) per channel.
vec3 splastic_renormalisation(Leaf l) {
    vec3 rbar = l.eta.z != 0.0 ? l.color : vec3(1.0);
    return vec3(1.0) / (vec3(1.0) - rbar * fresnel_diffuse_reflectance(1.0 / l.eta.x));
}

// The base's f̂ per unit of ρ toward wo before the renormalisation, given F(cos θi).
float splastic_base(Leaf l, float f_i, vec3 wo) {
    float f_o = fresnel_dielectric(wo.z, l.eta.x);
    return wo.z * INV_PI / (l.eta.x * l.eta.x) * (1.0 - f_i) * (1.0 - f_o);
}

vec3 splastic_eval_pdf(Leaf l, vec3 wi, vec3 wo, out float pdf) {
    pdf = 0.0;
    if (wi.z <= 0.0 || wo.z <= 0.0) return vec3(0.0);
    float f_i;
    pdf = (1.0 - splastic_coating(l, wi.z, f_i)) * wo.z * INV_PI;
    return l.color * splastic_renormalisation(l) * splastic_base(l, f_i, wo);
}

BsdfSample splastic_sample(Leaf l, vec3 wi, float u_lobe, vec2 u) {
    BsdfSample s = BsdfSample(vec3(0.0), 0.0, vec3(0.0), false, false);
    if (wi.z <= 0.0) return s;
    float f_i;
    float p = splastic_coating(l, wi.z, f_i);
    if (u_lobe < p) return BsdfSample(vec3(-wi.x, -wi.y, wi.z), p, l.k * f_i, true, true);
    s.wo = sample_cosine_hemisphere(u);
    s.value = splastic_eval_pdf(l, wi, s.wo, s.pdf);
    s.valid = s.pdf > 0.0;
    return s;
}

// ∂f̂/∂ρ per channel, times adj: the base's, or 0 toward the mirror direction (the coating's sample).
LeafGrad splastic_eval_grad(Leaf l, vec3 wi, vec3 wo, vec3 adj) {
    if (wi.z <= 0.0 || wo.z <= 0.0 || wo == vec3(-wi.x, -wi.y, wi.z)) return LeafGrad(vec3(0.0), vec3(0.0), vec3(0.0), vec3(0.0));
    vec3 n = splastic_renormalisation(l);
    return LeafGrad(adj * (l.eta.z != 0.0 ? n * n : n) * splastic_base(l, fresnel_dielectric(wi.z, l.eta.x), wo), vec3(0.0), vec3(0.0), vec3(0.0));
}

// ---- leaves ----
vec3 leaf_eval_pdf(Leaf l, vec3 wi, vec3 wo, out float pdf) {
    if (is_smooth_plastic(l.kind)) return splastic_eval_pdf(l, wi, wo, pdf);
    if (is_delta(l.kind)) {
        pdf = 0.0;
        return vec3(0.0);
    }
    if (is_plastic(l.kind)) return plastic_eval_pdf(l, wi, wo, pdf);
    if (is_rough_dielectric(l.kind)) return rdielectric_eval_pdf(l, wi, wo, pdf);
    if (is_diffuse(l.kind)) {
        pdf = diffuse_pdf(wi, wo);
        return diffuse_eval(l.color, wi, wo);
    }
    return microfacet_eval_pdf(l, wi, wo, pdf);
}
vec3 leaf_eval(Leaf l, vec3 wi, vec3 wo) {
    float pdf;
    return leaf_eval_pdf(l, wi, wo, pdf);
}
float leaf_pdf(Leaf l, vec3 wi, vec3 wo) {
    float pdf;
    leaf_eval_pdf(l, wi, wo, pdf);
    return pdf;
}
// u_lobe picks a lobe of a leaf of several (rescaled by the blend's choice, bsdf_sample).
bool leaf_sample(Leaf l, vec3 wi, float u_lobe, vec2 u, out vec3 wo) {
    wo = vec3(0.0, 0.0, 1.0);
    // A leaf with a delta lobe samples itself whole: bsdf_sample takes its sample.
    if (is_delta(l.kind) || is_smooth_plastic(l.kind)) return false;
    if (is_plastic(l.kind)) return plastic_sample(l, wi, u_lobe, u, wo);
    if (is_rough_dielectric(l.kind)) return rdielectric_sample(l, wi, u_lobe, u, wo);
    if (is_diffuse(l.kind)) {
        wo = vec3(0.0);
        if (wi.z <= 0.0) return false;
        wo = sample_cosine_hemisphere(u);
        return wo.z > 0.0;
    }
    return microfacet_sample(l.distribution, vec2(l.alpha, l.alpha_v), wi, u, wo);
}

// ---- parameter derivatives, kept per image channel (twin of bsdf_eval_grad in src/bsdf/mod.rs) ----

// ∂f̂/∂ρ and ∂f̂/∂α of a rough plastic (twin of PlasticLeaf::eval_grad).
LeafGrad plastic_eval_grad(Leaf l, vec3 wi, vec3 wo, vec3 adj) {
    if (wi.z <= 0.0 || wo.z <= 0.0) return LeafGrad(vec3(0.0), vec3(0.0), vec3(0.0), vec3(0.0));
    vec3 h = normalize(wi + wo);
    float f = fresnel_dielectric(dot(wi, h), l.eta.x);
    float scalar;
    vec2 dscalar2;
    microfacet_scalar_parts(l.distribution, vec2(l.alpha), wi, wo, h, scalar, dscalar2);
    float dscalar = dscalar2.x + dscalar2.y;
    float t_i = coating_lerp(l.table, 0u, wi.z);
    float t_o = coating_lerp(l.table, 0u, wo.z);
    float dt_i = coating_lerp(l.table, COATING_RES, wi.z);
    float dt_o = coating_lerp(l.table, COATING_RES, wo.z);
    float k = INV_PI / (l.eta.x * l.eta.x) * wo.z;
    vec3 n = plastic_renormalisation(l);
    bool nonlinear = l.eta.z != 0.0;
    vec3 rbar = nonlinear ? l.color : vec3(1.0);
    float dinternal = coating_table(l.table + 2u * COATING_RES + 1u);
    vec3 d_diffuse = (nonlinear ? n * n : n) * (k * t_i * t_o);
    vec3 d_alpha = l.k * (f * dscalar) + l.color * n * (k * (dt_i * t_o + t_i * dt_o))
        + l.color * n * n * rbar * (dinternal * k * t_i * t_o);
    return LeafGrad(adj * d_diffuse, adj * d_alpha, vec3(0.0), vec3(0.0));
}

LeafGrad leaf_eval_grad(Leaf l, vec3 wi, vec3 wo, vec3 adj) {
    if (is_delta(l.kind)) return smooth_value_grad(l, wi, wo, adj);
    if (is_smooth_plastic(l.kind)) return splastic_eval_grad(l, wi, wo, adj);
    if (is_plastic(l.kind)) return plastic_eval_grad(l, wi, wo, adj);
    if (is_rough_dielectric(l.kind)) return rdielectric_eval_grad(l, wi, wo, adj);
    if (is_diffuse(l.kind)) return LeafGrad(adj * diffuse_eval(vec3(1.0), wi, wo), vec3(0.0), vec3(0.0), vec3(0.0));
    vec3 f;
    float scalar;
    vec2 dscalar;
    microfacet_eval_parts(l, wi, wo, f, scalar, dscalar);
    return LeafGrad(adj * f * scalar, adj * f * l.color * dscalar.x, vec3(0.0), adj * f * l.color * dscalar.y);
}

// ---- blend (ALGORITHMS.md §4.3) and the whole BSDF ----
float blend_weight(Bsdf b) { return clamp(b.weight, 0.0, 1.0); }

// A normal map's factor of f̂ toward wo (perturbed frame): Estevez et al.'s shadow terminator
// 2 / (1 + √(1 + α² tan²θo)) with θo from the unperturbed normal, 0 where wo crosses one horizon
// but not the other; 1 without a map (twin: Perturbed::factor).
float perturbed_factor(Bsdf b, vec3 wo) {
    if (!HAS(F_NORMAL_MAP) || !b.mapped) return 1.0;
    float c = dot(wo, b.base_n);
    if (!(c * wo.z > 0.0)) return 0.0;
    float c2 = c * c;
    float tan2 = max(1.0 - c2, 0.0) / c2;
    return 2.0 / (1.0 + sqrt(1.0 + b.nmap_alpha2 * tan2));
}

// f̂ and density of the leaves (or blend) without a normal map's wrapper: one evaluation of each
// leaf for both (twin: unperturbed_eval and unperturbed_pdf).
vec3 unperturbed_eval_pdf(Bsdf b, vec3 wi, vec3 wo, out float pdf) {
    float pdf0;
    vec3 f0 = leaf_eval_pdf(b.leaf0, wi, wo, pdf0);
    if (!HAS(F_BLEND) || !b.blend) {
        pdf = pdf0;
        return f0;
    }
    float w = blend_weight(b);
    float pdf1;
    vec3 f1 = leaf_eval_pdf(b.leaf1, wi, wo, pdf1);
    pdf = pdf0 * (1.0 - w) + pdf1 * w;
    return f0 * (1.0 - w) + f1 * w;
}

// f̂ at (wi, wo) and, in `pdf`, the density with which bsdf_sample draws wo (twin: bsdf_eval and
// bsdf_pdf).
vec3 bsdf_eval_pdf(Bsdf b, vec3 wi, vec3 wo, out float pdf) {
    vec3 f = unperturbed_eval_pdf(b, wi, wo, pdf);
    if (HAS(F_NORMAL_MAP) && b.mapped) {
        float factor = perturbed_factor(b, wo);
        f *= factor;
        if (factor == 0.0) pdf = 0.0;
    }
    return f;
}

vec3 bsdf_eval(Bsdf b, vec3 wi, vec3 wo) {
    float pdf;
    return bsdf_eval_pdf(b, wi, wo, pdf);
}

float bsdf_pdf(Bsdf b, vec3 wi, vec3 wo) {
    float pdf;
    bsdf_eval_pdf(b, wi, wo, pdf);
    return pdf;
}

// ∂(adj · f̂)/∂(every value of b) at (wi, wo); the weight's derivative is f̂1 − f̂0 inside (0, 1).
BsdfGrad bsdf_eval_grad(Bsdf b, vec3 wi, vec3 wo, vec3 adj) {
    LeafGrad none = LeafGrad(vec3(0.0), vec3(0.0), vec3(0.0), vec3(0.0));
    if (HAS(F_NORMAL_MAP) && b.mapped) adj *= perturbed_factor(b, wo);
    if (!HAS(F_BLEND) || !b.blend) return BsdfGrad(leaf_eval_grad(b.leaf0, wi, wo, adj), none, vec3(0.0));
    float w = blend_weight(b);
    vec3 weight = (b.weight > 0.0 && b.weight < 1.0) ? adj * (leaf_eval(b.leaf1, wi, wo) - leaf_eval(b.leaf0, wi, wo)) : vec3(0.0);
    return BsdfGrad(leaf_eval_grad(b.leaf0, wi, wo, adj * (1.0 - w)), leaf_eval_grad(b.leaf1, wi, wo, adj * w), weight);
}

// bsdf_sample without a normal map's wrapper (twin: unperturbed_sample).
BsdfSample unperturbed_sample(Bsdf b, vec3 wi, float u_lobe, vec2 u) {
    if (!(HAS(F_BLEND) && b.blend) && is_delta(b.leaf0.kind)) return smooth_sample(b.leaf0, wi, u_lobe);
    if (!(HAS(F_BLEND) && b.blend) && is_smooth_plastic(b.leaf0.kind)) return splastic_sample(b.leaf0, wi, u_lobe, u);
    BsdfSample s = BsdfSample(vec3(0.0), 0.0, vec3(0.0), false, false);
    // The blend's choice, and u_lobe rescaled within it for the leaf's own (twin: pick_leaf).
    Leaf leaf = b.leaf0;
    if (HAS(F_BLEND) && b.blend) {
        float w = blend_weight(b);
        if (u_lobe <= w) {
            leaf = b.leaf1;
            u_lobe = u_lobe / w;
        } else {
            u_lobe = (u_lobe - w) / (1.0 - w);
        }
    }
    vec3 wo;
    if (!leaf_sample(leaf, wi, u_lobe, u, wo)) return s;
    s.wo = wo;
    s.value = unperturbed_eval_pdf(b, wi, wo, s.pdf);
    s.valid = s.pdf > 0.0;
    return s;
}

// u_lobe picks the blend child (RNG dim 4); u drives the direction (dims 5, 6). A normal map's
// wrapper invalidates a wo that crosses one horizon only and weighs the rest by its factor.
BsdfSample bsdf_sample(Bsdf b, vec3 wi, float u_lobe, vec2 u) {
    BsdfSample s = unperturbed_sample(b, wi, u_lobe, u);
    if (HAS(F_NORMAL_MAP) && b.mapped && s.valid) {
        float factor = perturbed_factor(b, s.wo);
        s.value *= factor;
        s.valid = factor != 0.0;
    }
    return s;
}

#endif

// Plastics and dielectrics, rough and smooth (twins in src/bsdf/rough_plastic.rs,
// rough_dielectric.rs, specular.rs and plastic.rs). Included by bsdf.glsl after microfacet.glsl.
#ifndef PATHGRAD_DIELECTRIC_GLSL
#define PATHGRAD_DIELECTRIC_GLSL

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
// k = transmittance, eta.x = η, (alpha, alpha_v) = (α_u, α_v) ----

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

// |∂m/∂wo| of the pair (twin: jacobian).
float rdielectric_jacobian(bool refl, float eta, vec3 wi, vec3 wo, vec3 m) {
    float om = dot(wo, m);
    if (refl) return abs(1.0 / (4.0 * om));
    float s = dot(wi, m) + eta * om;
    return abs(eta * eta * om / (s * s));
}

vec3 rdielectric_eval_pdf(Leaf l, vec3 wi, vec3 wo, out float pdf) {
    pdf = 0.0;
    vec3 m;
    bool refl;
    float eta;
    if (!rdielectric_pair(l, wi, wo, m, refl, eta)) return vec3(0.0);
    vec3 up = wi.z > 0.0 ? wi : -wi;
    vec2 a = vec2(l.alpha, l.alpha_v);
    float d = microfacet_d(l.distribution, a, m);
    float gi = microfacet_g1(l.distribution, a, wi, m);
    float f = fresnel_dielectric(dot(wi, m), l.eta.x);
    float jacobian = rdielectric_jacobian(refl, eta, wi, wo, m);
    // G1 of the mirrored wi equals G1 of wi (it depends on tan²θ and the side test only).
    pdf = d * gi * max(dot(up, m), 0.0) / up.z * (refl ? f : 1.0 - f) * jacobian;
    if (d == 0.0) return vec3(0.0);
    float dg = d * gi * microfacet_g1(l.distribution, a, wo, m);
    return (refl ? l.color : l.k) * (dg * rdielectric_unit(refl, eta, f, wi, wo, m));
}

// Leaves through microfacet normal m: reflected with probability F(wi·m) (u_lobe ≤ F), else
// refracted; false where the direction lands on the side its lobe does not serve (twin: scatter).
bool rdielectric_scatter(Leaf l, vec3 wi, vec3 m, float u_lobe, out vec3 wo) {
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

bool rdielectric_sample(Leaf l, vec3 wi, float u_lobe, vec2 u, out vec3 wo) {
    wo = vec3(0.0, 0.0, 1.0);
    if (wi.z == 0.0) return false;
    vec3 up = wi.z > 0.0 ? wi : -wi;
    vec3 m;
    if (!microfacet_visible_normal(l.distribution, vec2(l.alpha, l.alpha_v), up, u, m)) return false;
    return rdielectric_scatter(l, wi, m, u_lobe, wo);
}

// ∂f̂/∂(lobe colour) (in color, or in trans for a transmitted pair), ∂f̂/∂α_u (alpha) and
// ∂f̂/∂α_v (alpha_v; an isotropic leaf's ∂f̂/∂α is their sum), times adj.
LeafGrad rdielectric_eval_grad(Leaf l, vec3 wi, vec3 wo, vec3 adj) {
    LeafGrad g = LeafGrad(vec3(0.0), vec3(0.0), vec3(0.0), vec3(0.0), vec3(0.0), vec3(0.0));
    vec3 m;
    bool refl;
    float eta;
    if (!rdielectric_pair(l, wi, wo, m, refl, eta)) return g;
    vec2 a = vec2(l.alpha, l.alpha_v);
    float d = microfacet_d(l.distribution, a, m);
    if (d == 0.0) return g;
    float gi, go;
    vec2 dgi, dgo;
    microfacet_g1_and_dalpha(l.distribution, a, wi, m, gi, dgi);
    microfacet_g1_and_dalpha(l.distribution, a, wo, m, go, dgo);
    vec2 dd = microfacet_d_dalpha_of(l.distribution, a, m, d);
    vec2 ddg = dd * (gi * go) + d * (dgi * go + gi * dgo);
    float unit = rdielectric_unit(refl, eta, fresnel_dielectric(dot(wi, m), l.eta.x), wi, wo, m);
    vec3 dcolour = adj * (d * gi * go * unit);
    if (refl) g.color = dcolour; else g.trans = dcolour;
    vec3 colour = adj * (refl ? l.color : l.k);
    g.alpha = colour * (ddg.x * unit);
    g.alpha_v = colour * (ddg.y * unit);
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
    if (!smooth_lobe(l, wi, transmitted ? 1.0 : 0.0, w, pdf, unit, t)) return LeafGrad(vec3(0.0), vec3(0.0), vec3(0.0), vec3(0.0), vec3(0.0), vec3(0.0));
    vec3 g = adj * unit * pdf;
    if (l.kind == LEAF_CONDUCTOR) {
        // The weight F(cos θi)·reflectance by the Fresnel term's eta and k (pdf 1; twin:
        // SmoothLeaf::value_grad).
        vec3 d_eta = vec3(0.0), d_k = vec3(0.0);
        if (HAS(G_COLOR)) fresnel_conductor_dior(wi.z, l.eta, l.k, d_eta, d_k);
        return LeafGrad(g, vec3(0.0), vec3(0.0), vec3(0.0), adj * l.color * d_eta, adj * l.color * d_k);
    }
    return transmitted ? LeafGrad(vec3(0.0), vec3(0.0), g, vec3(0.0), vec3(0.0), vec3(0.0)) : LeafGrad(g, vec3(0.0), vec3(0.0), vec3(0.0), vec3(0.0), vec3(0.0));
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

// ∂f̂/∂ρ per channel, times adj: the base's; toward the mirror direction (the coating's sample)
// the value's derivative by the specular colour instead, in `trans` (twin: SmoothPlasticLeaf::eval_grad).
LeafGrad splastic_eval_grad(Leaf l, vec3 wi, vec3 wo, vec3 adj) {
    if (wi.z <= 0.0 || wo.z <= 0.0) return LeafGrad(vec3(0.0), vec3(0.0), vec3(0.0), vec3(0.0), vec3(0.0), vec3(0.0));
    if (wo == vec3(-wi.x, -wi.y, wi.z)) return LeafGrad(vec3(0.0), vec3(0.0), adj * fresnel_dielectric(wi.z, l.eta.x), vec3(0.0), vec3(0.0), vec3(0.0));
    vec3 n = splastic_renormalisation(l);
    return LeafGrad(adj * (l.eta.z != 0.0 ? n * n : n) * splastic_base(l, fresnel_dielectric(wi.z, l.eta.x), wo), vec3(0.0), vec3(0.0), vec3(0.0), vec3(0.0), vec3(0.0));
}

#endif

// BSDFs: Lambertian, the leaves of microfacet.glsl (rough conductor) and dielectric.glsl (plastics,
// dielectrics, smooth conductor), blend and the normal-map wrapper, and their derivatives (twin of
// src/bsdf/).
// Local frame, normal +z; eval returns f̂ = f·max(0, cos θo); pdfs are solid-angle densities of wo.
#ifndef PATHGRAD_BSDF_GLSL
#define PATHGRAD_BSDF_GLSL

#extension GL_EXT_control_flow_attributes : require
#include "sampling.glsl"
#include "features.glsl"


// A rough plastic keeps (η, coating sampling weight, nonlinear) in `eta`, its specular
// reflectance in `k` and its coating table's offset in `table` (Material's layout).
// A rough conductor's roughness is (alpha, alpha_v) (α_u along the frame's x, α_v along y); other
// leaves read alpha only. A principled leaf: base colour in color, roughness in alpha, anisotropic
// in alpha_v, η in eta.x, sampling rates in k, (metallic, spec_tint, spec_trans, sheen) in pr0 and
// (sheen_tint, clearcoat, clearcoat_gloss, flatness) in pr1.
struct Leaf { uint kind; uint distribution; float alpha; vec3 color; vec3 eta; vec3 k; uint table; float alpha_v;
              vec4 pr0; vec4 pr1; };
// A normal map's wrapper (`mapped`; twin: Perturbed of src/bsdf/mod.rs): the local frame is the
// perturbed one; base_n is the unperturbed normal in it, nmap_alpha2 the shadow terminator's α².
struct Bsdf { Leaf leaf0; Leaf leaf1; float weight; bool blend; bool mapped; vec3 base_n; float nmap_alpha2; };
// A delta lobe's sample (`delta`) has its choice probability as `pdf` and its weight × pdf as
// `value` (src/bsdf/specular.rs).
struct BsdfSample { vec3 wo; float pdf; vec3 value; bool valid; bool delta; };
// ∂ by the colour (albedo or reflectance), the roughness and a dielectric's transmittance (a
// plastic's specular reflectance), per image channel.
// eta, k: by channel c of a conductor's eta and k (component c the whole derivative, as color's).
struct LeafGrad { vec3 color; vec3 alpha; vec3 trans; vec3 alpha_v; vec3 eta; vec3 k; };
struct BsdfGrad { LeafGrad leaf0; LeafGrad leaf1; vec3 weight; };

// Whether `distribution` is Beckmann, folded to a constant when the kernel has only one of the two.
bool is_beckmann(uint distribution) {
    return !HAS(F_GGX) || (HAS(F_BECKMANN) && distribution == DIST_BECKMANN);
}

// The leaf kinds' feature bits; a kind test folds to a constant when the kernel has no other kind.
#define LEAF_KIND_BITS (F_DIFFUSE | F_CONDUCTOR | F_PLASTIC | F_DELTA | F_SMOOTH_PLASTIC | F_ROUGH_DIELECTRIC | F_PRINCIPLED)
// A thin principled leaf's bit is in the second word (F2_PRINCIPLED_THIN): a kernel without it
// folds these tests as before.
bool only_kind(uint bit) { return (FEATURES & uint(LEAF_KIND_BITS)) == uint(bit) && !HAS2(F2_PRINCIPLED_THIN); }

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

// Whether leaf `kind` is principled.
bool is_principled(uint kind) {
    return HAS(F_PRINCIPLED) && (only_kind(F_PRINCIPLED) || kind == LEAF_PRINCIPLED);
}

// Whether leaf `kind` is thin principled.
bool is_principled_thin(uint kind) {
    return HAS2(F2_PRINCIPLED_THIN) && ((FEATURES & uint(LEAF_KIND_BITS)) == 0u || kind == LEAF_PRINCIPLED_THIN);
}

// Whether leaf `kind` is Lambertian.
bool is_diffuse(uint kind) {
    return ((FEATURES & uint(F_CONDUCTOR | F_PLASTIC | F_DELTA | F_SMOOTH_PLASTIC | F_ROUGH_DIELECTRIC | F_PRINCIPLED)) == 0u
            && !HAS2(F2_PRINCIPLED_THIN))
        || (HAS(F_DIFFUSE) && kind == LEAF_DIFFUSE);
}

// Whether leaf `kind` is a rough conductor.
bool is_conductor(uint kind) {
    return !is_plastic(kind) && !is_delta(kind) && !is_smooth_plastic(kind) && !is_rough_dielectric(kind)
        && !is_principled(kind) && !is_principled_thin(kind) && !is_diffuse(kind);
}

// ---- Lambertian (ALGORITHMS.md §4.1) ----
vec3 diffuse_eval(vec3 albedo, vec3 wi, vec3 wo) {
    return (wi.z > 0.0 && wo.z > 0.0) ? albedo * (wo.z * INV_PI) : vec3(0.0);
}
float diffuse_pdf(vec3 wi, vec3 wo) {
    return (wi.z > 0.0 && wo.z > 0.0) ? wo.z * INV_PI : 0.0;
}

#include "microfacet.glsl"
#include "dielectric.glsl"
#include "principled.glsl"
#include "principled_thin.glsl"

// A principled leaf's values as principled.glsl takes them.
Principled principled_of(Leaf l) {
    return Principled(l.color, l.alpha, l.alpha_v, l.pr0.x, l.pr0.z, l.eta.x, l.pr0.y, l.pr0.w, l.pr1.x, l.pr1.y,
                      l.pr1.z, l.pr1.w, l.k);
}

// The adj-weighted derivatives of the principled leaf of the vertex being replayed, summed over
// its gradient terms (NEE and the sampled direction); leaf_eval_grad adds to it, scatter_terms
// reads it. A global, as a principled leaf's 13 derivatives would triple LeafGrad for every
// kernel; a blend holds no principled leaf (the loader refuses it), so one leaf's suffice.
PrincipledGrad pr_terms;

void pr_terms_reset() {
    pr_terms.base[0] = vec3(0.0);
    pr_terms.base[1] = vec3(0.0);
    pr_terms.base[2] = vec3(0.0);
    pr_terms.roughness = vec3(0.0);
    pr_terms.anisotropic = vec3(0.0);
    pr_terms.metallic = vec3(0.0);
    pr_terms.spec_trans = vec3(0.0);
    pr_terms.spec_tint = vec3(0.0);
    pr_terms.sheen = vec3(0.0);
    pr_terms.sheen_tint = vec3(0.0);
    pr_terms.clearcoat = vec3(0.0);
    pr_terms.clearcoat_gloss = vec3(0.0);
    pr_terms.flatness = vec3(0.0);
}

// Adds adj × ∂f̂(wi, wo) of principled leaf l to pr_terms (twin: Leaf::Principled of
// leaf_eval_grad).
void principled_add_grad(Leaf l, vec3 wi, vec3 wo, vec3 adj) {
    PrincipledGrad g;
    principled_eval_grad(principled_of(l), wi, wo, g);
    pr_terms.base[0] += adj * g.base[0];
    pr_terms.base[1] += adj * g.base[1];
    pr_terms.base[2] += adj * g.base[2];
    pr_terms.roughness += adj * g.roughness;
    pr_terms.anisotropic += adj * g.anisotropic;
    pr_terms.metallic += adj * g.metallic;
    pr_terms.spec_trans += adj * g.spec_trans;
    pr_terms.spec_tint += adj * g.spec_tint;
    pr_terms.sheen += adj * g.sheen;
    pr_terms.sheen_tint += adj * g.sheen_tint;
    pr_terms.clearcoat += adj * g.clearcoat;
    pr_terms.clearcoat_gloss += adj * g.clearcoat_gloss;
    pr_terms.flatness += adj * g.flatness;
}

// A thin principled leaf's values as principled_thin.glsl takes them: the record's words
// (MAT_PRINCIPLED_THIN) put diff_trans in pr0.x and η in pr1.y; the fourth sampling rate is eta.x.
PrincipledThin principled_thin_of(Leaf l) {
    return PrincipledThin(l.color, l.alpha, l.alpha_v, l.pr0.z, l.pr1.y, l.pr0.y, l.pr0.w, l.pr1.x, l.pr1.w, l.pr0.x,
                          vec4(l.k, l.eta.x));
}

// Adds adj × ∂f̂(wi, wo) of thin principled leaf l to pr_terms, each derivative in the field of
// its record word (diff_trans as metallic, η as clearcoat; twin: by_record_slot).
void principled_thin_add_grad(Leaf l, vec3 wi, vec3 wo, vec3 adj) {
    PrincipledThinGrad g;
    principled_thin_eval_grad(principled_thin_of(l), wi, wo, g);
    pr_terms.base[0] += adj * g.base[0];
    pr_terms.base[1] += adj * g.base[1];
    pr_terms.base[2] += adj * g.base[2];
    pr_terms.roughness += adj * g.roughness;
    pr_terms.anisotropic += adj * g.anisotropic;
    pr_terms.metallic += adj * g.diff_trans;
    pr_terms.spec_trans += adj * g.spec_trans;
    pr_terms.spec_tint += adj * g.spec_tint;
    pr_terms.sheen += adj * g.sheen;
    pr_terms.sheen_tint += adj * g.sheen_tint;
    pr_terms.clearcoat += adj * g.eta;
    pr_terms.flatness += adj * g.flatness;
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
    if (is_principled(l.kind)) {
        Principled p = principled_of(l);
        pdf = principled_pdf(p, wi, wo);
        return principled_eval(p, wi, wo);
    }
    if (is_principled_thin(l.kind)) {
        PrincipledThin p = principled_thin_of(l);
        pdf = principled_thin_pdf(p, wi, wo);
        PrincipledThinGrad g;
        return principled_thin_eval_grad(p, wi, wo, g);
    }
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
    if (is_principled(l.kind)) return principled_sample(principled_of(l), wi, u_lobe, u, wo);
    if (is_principled_thin(l.kind)) return principled_thin_sample(principled_thin_of(l), wi, u_lobe, u, wo);
    if (is_diffuse(l.kind)) {
        wo = vec3(0.0);
        if (wi.z <= 0.0) return false;
        wo = sample_cosine_hemisphere(u);
        return wo.z > 0.0;
    }
    return microfacet_sample(l.distribution, vec2(l.alpha, l.alpha_v), wi, u, wo);
}

// ---- parameter derivatives, kept per image channel (twin of bsdf_eval_grad in src/bsdf/mod.rs) ----

// ∂f̂/∂ρ, ∂f̂/∂α and ∂f̂/∂s (in `trans`) of a rough plastic (twin of PlasticLeaf::eval_grad).
LeafGrad plastic_eval_grad(Leaf l, vec3 wi, vec3 wo, vec3 adj) {
    if (wi.z <= 0.0 || wo.z <= 0.0) return LeafGrad(vec3(0.0), vec3(0.0), vec3(0.0), vec3(0.0), vec3(0.0), vec3(0.0));
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
    return LeafGrad(adj * d_diffuse, adj * d_alpha, adj * (f * scalar), vec3(0.0), vec3(0.0), vec3(0.0));
}

LeafGrad leaf_eval_grad(Leaf l, vec3 wi, vec3 wo, vec3 adj) {
    if (is_delta(l.kind)) return smooth_value_grad(l, wi, wo, adj);
    if (is_smooth_plastic(l.kind)) return splastic_eval_grad(l, wi, wo, adj);
    if (is_plastic(l.kind)) return plastic_eval_grad(l, wi, wo, adj);
    if (is_rough_dielectric(l.kind)) return rdielectric_eval_grad(l, wi, wo, adj);
    if (is_principled(l.kind)) {
        principled_add_grad(l, wi, wo, adj);
        return LeafGrad(vec3(0.0), vec3(0.0), vec3(0.0), vec3(0.0), vec3(0.0), vec3(0.0));
    }
    if (is_principled_thin(l.kind)) {
        principled_thin_add_grad(l, wi, wo, adj);
        return LeafGrad(vec3(0.0), vec3(0.0), vec3(0.0), vec3(0.0), vec3(0.0), vec3(0.0));
    }
    if (is_diffuse(l.kind)) return LeafGrad(adj * diffuse_eval(vec3(1.0), wi, wo), vec3(0.0), vec3(0.0), vec3(0.0), vec3(0.0), vec3(0.0));
    vec3 f;
    float scalar;
    vec2 dscalar;
    microfacet_eval_parts(l, wi, wo, f, scalar, dscalar);
    // ∂F/∂eta, ∂F/∂k at the half vector's cosine (twin: leaf_eval_grad's rough conductor).
    vec3 d_eta = vec3(0.0), d_k = vec3(0.0);
    if (HAS(G_COLOR) && scalar != 0.0) fresnel_conductor_dior(dot(wi, normalize(wi + wo)), l.eta, l.k, d_eta, d_k);
    return LeafGrad(adj * f * scalar, adj * f * l.color * dscalar.x, vec3(0.0), adj * f * l.color * dscalar.y,
                    adj * l.color * d_eta * scalar, adj * l.color * d_k * scalar);
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
    LeafGrad none = LeafGrad(vec3(0.0), vec3(0.0), vec3(0.0), vec3(0.0), vec3(0.0), vec3(0.0));
    if (HAS(F_NORMAL_MAP) && b.mapped) adj *= perturbed_factor(b, wo);
    if (!HAS(F_BLEND) || !b.blend) return BsdfGrad(leaf_eval_grad(b.leaf0, wi, wo, adj), none, vec3(0.0));
    float w = blend_weight(b);
    vec3 weight = (b.weight > 0.0 && b.weight < 1.0) ? adj * (leaf_eval(b.leaf1, wi, wo) - leaf_eval(b.leaf0, wi, wo)) : vec3(0.0);
    // A smooth leaf has no value off its delta directions (bsdf_delta_grad takes those).
    LeafGrad g0 = is_delta(b.leaf0.kind) ? none : leaf_eval_grad(b.leaf0, wi, wo, adj * (1.0 - w));
    LeafGrad g1 = is_delta(b.leaf1.kind) ? none : leaf_eval_grad(b.leaf1, wi, wo, adj * w);
    return BsdfGrad(g0, g1, weight);
}

// bsdf_sample_grad of a blend's delta sample toward wo: its smooth leaf, chosen with probability
// c (w for leaf1, 1 − w for leaf0), has the value c·v; the colours' derivatives are c·∂v, the
// weight's ±v inside (0, 1) (twin: bsdf_delta_grad).
BsdfGrad bsdf_delta_grad(Bsdf b, vec3 wi, vec3 wo, vec3 adj) {
    LeafGrad none = LeafGrad(vec3(0.0), vec3(0.0), vec3(0.0), vec3(0.0), vec3(0.0), vec3(0.0));
    BsdfGrad g = BsdfGrad(none, none, vec3(0.0));
    float w = blend_weight(b);
    bool inside = b.weight > 0.0 && b.weight < 1.0;
    if (is_delta(b.leaf0.kind)) {
        LeafGrad unit = smooth_value_grad(b.leaf0, wi, wo, vec3(1.0));
        g.leaf0 = LeafGrad(adj * (1.0 - w) * unit.color, vec3(0.0), adj * (1.0 - w) * unit.trans, vec3(0.0),
                           adj * (1.0 - w) * unit.eta, adj * (1.0 - w) * unit.k);
        if (inside) g.weight = -adj * (b.leaf0.color * unit.color + b.leaf0.k * unit.trans);
    }
    if (is_delta(b.leaf1.kind)) {
        LeafGrad unit = smooth_value_grad(b.leaf1, wi, wo, vec3(1.0));
        g.leaf1 = LeafGrad(adj * w * unit.color, vec3(0.0), adj * w * unit.trans, vec3(0.0), adj * w * unit.eta,
                           adj * w * unit.k);
        if (inside) g.weight = adj * (b.leaf1.color * unit.color + b.leaf1.k * unit.trans);
    }
    return g;
}

// ∂(adj · value)/∂(every value of b) of a sample toward wo: a delta sample's value where `delta`,
// else f̂ (twin: bsdf_sample_grad).
BsdfGrad bsdf_sample_grad(Bsdf b, vec3 wi, vec3 wo, bool delta, vec3 adj) {
    if (HAS(F_BLEND) && HAS(F_DELTA) && delta && b.blend) return bsdf_delta_grad(b, wi, wo, adj);
    return bsdf_eval_grad(b, wi, wo, adj);
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
        float c;
        if (u_lobe <= w) {
            leaf = b.leaf1;
            u_lobe = u_lobe / w;
            c = w;
        } else {
            u_lobe = (u_lobe - w) / (1.0 - w);
            c = 1.0 - w;
        }
        // A smooth leaf: its delta sample, weighted by the blend's choice probability (the other
        // leaf has no value in a delta direction).
        if (is_delta(leaf.kind)) {
            BsdfSample d = smooth_sample(leaf, wi, u_lobe);
            d.pdf *= c;
            d.value *= c;
            return d;
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

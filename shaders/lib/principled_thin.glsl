// Mitsuba 3.9.1's principledthin BSDF (twin of src/bsdf/principled_thin.rs, whose module
// documentation gives the lobes, the sampler and the density): value with its derivatives by every
// parameter, density and sampler. Include after principled.glsl (it reuses its helpers);
// shaders/principled_thin_probe.comp compares it with the CPU's.
#ifndef PATHGRAD_PRINCIPLED_THIN_GLSL
#define PATHGRAD_PRINCIPLED_THIN_GLSL

// One thin principled BSDF's values at a shading point; diff_trans in Mitsuba's 0..2; rates =
// (specular reflection, specular transmission, diffuse reflection, diffuse transmission).
struct PrincipledThin {
    vec3 base;
    float roughness;
    float anisotropic;
    float spec_trans;
    float eta;
    float spec_tint;
    float sheen;
    float sheen_tint;
    float flatness;
    float diff_trans;
    vec4 rates;
};

// ∂f̂/∂(each parameter), per image channel; base[k] is by base colour channel k.
struct PrincipledThinGrad {
    vec3 base[3];
    vec3 roughness;
    vec3 anisotropic;
    vec3 spec_trans;
    vec3 eta;
    vec3 spec_tint;
    vec3 sheen;
    vec3 sheen_tint;
    vec3 flatness;
    vec3 diff_trans;
};

// ∂F/∂η of the dielectric Fresnel term seen from outside (c ≥ 0).
float pt_fresnel_deta(float c, float eta) {
    float sin2 = 1.0 - c * c;
    float ct2 = 1.0 - sin2 / (eta * eta);
    if (ct2 <= 0.0 || eta == 1.0) return 0.0;
    float ct = sqrt(ct2);
    float dct = sin2 / (eta * eta * eta * ct);
    float a = eta * ct;
    float da = ct + eta * dct;
    float a_s = (c - a) / (c + a);
    float da_s = -2.0 * c * da / ((c + a) * (c + a));
    float b = eta * c;
    float a_p = (ct - b) / (ct + b);
    float da_p = 2.0 * (b * dct - ct * c) / ((ct + b) * (ct + b));
    return a_s * da_s + a_p * da_p;
}

// ∂w/∂η of calc_schlick's weight seen from outside (c ≥ 0).
float pt_calc_schlick_weight_deta(float c, float eta) {
    if (eta > 1.0) return 0.0;
    float sin2 = 1.0 - c * c;
    float ct2 = 1.0 - sin2 / (eta * eta);
    if (ct2 <= 0.0) return 0.0;
    float ct = sqrt(ct2);
    float m = 1.0 - ct;
    if (m < 0.0 || m > 1.0) return 0.0;
    return -5.0 * m * m * m * m * sin2 / (eta * eta * eta * ct);
}

// (α_x, α_y) of GGX at roughness r with their derivatives by r (dr) and anisotropic (da).
vec2 pt_alphas(float r, float anisotropic, out vec2 dr, out vec2 da) {
    float r2 = r * r;
    float aspect = sqrt(1.0 - 0.9 * anisotropic);
    float ax = r2 / aspect;
    float ay = r2 * aspect;
    vec2 keep = vec2(ax > 0.001 ? 1.0 : 0.0, ay > 0.001 ? 1.0 : 0.0);
    dr = vec2(2.0 * r / aspect, 2.0 * r * aspect) * keep;
    da = vec2(0.45 * r2 / (aspect * aspect * aspect), -0.45 * r2 / aspect) * keep;
    return vec2(max(ax, 0.001), max(ay, 0.001));
}

// D·G1(wi)·G1(wo) of GGX at α and its derivative by (α_x, α_y).
float pt_ggx_dg(vec2 alpha, vec3 wi, vec3 wo, vec3 h, out vec2 ddg) {
    float d = microfacet_d(DIST_GGX, alpha, h);
    float gi = microfacet_g1(DIST_GGX, alpha, wi, h);
    float go = microfacet_g1(DIST_GGX, alpha, wo, h);
    ddg = d > 0.0 ? pr_ggx_d_dalpha(alpha, h) * gi * go
                        + d * (pr_ggx_g1_dalpha(alpha, wi, h) * go + gi * pr_ggx_g1_dalpha(alpha, wo, h))
                  : vec2(0.0);
    return d * gi * go;
}

float pt_visible_pdf(vec2 alpha, vec3 wi, vec3 h) {
    return microfacet_d(DIST_GGX, alpha, h) * microfacet_g1(DIST_GGX, alpha, wi, h) * abs(dot(wi, h)) / wi.z;
}

float pt_transmission_roughness(PrincipledThin p) { return (0.65 * p.eta - 0.35) * p.roughness; }

// Lobe probabilities: specular reflection, specular transmission, cosine reflection, cosine
// transmission.
vec4 pt_lobe_probs(PrincipledThin p) {
    float s = p.spec_trans;
    float d = 0.5 * p.diff_trans;
    vec4 q = vec4(s * p.rates.x * 0.5, s * p.rates.y * 0.5, p.rates.z * (1.0 - s) * (1.0 - d),
                  p.rates.w * (1.0 - s) * d);
    return q / (q.x + q.y + q.z + q.w);
}

// The pair turned to wi's upper side, its half vector and the masks eval and pdf share; false where
// wi is grazing.
bool pt_pair(inout vec3 wi, inout vec3 wo, out vec3 h, out bool refl_ok, out bool refr_ok) {
    float cos_i = wi.z;
    h = vec3(0.0, 0.0, 1.0);
    refl_ok = false;
    refr_ok = false;
    if (cos_i == 0.0) return false;
    wi = pr_mulsign(wi, cos_i);
    wo = pr_mulsign(wo, cos_i);
    h = normalize(wi + vec3(wo.xy, abs(wo.z)));
    if (any(isnan(h)) || any(isinf(h))) return false;
    refl_ok = pr_compatible(h, wi, wo, wi.z, true);
    refr_ok = pr_compatible(h, wi, wo, wi.z, false);
    return true;
}

// f̂(wi, wo) and its derivatives by every parameter.
vec3 principled_thin_eval_grad(PrincipledThin p, vec3 wi, vec3 wo, out PrincipledThinGrad g) {
    g.base[0] = vec3(0.0);
    g.base[1] = vec3(0.0);
    g.base[2] = vec3(0.0);
    g.roughness = vec3(0.0);
    g.anisotropic = vec3(0.0);
    g.spec_trans = vec3(0.0);
    g.eta = vec3(0.0);
    g.spec_tint = vec3(0.0);
    g.sheen = vec3(0.0);
    g.sheen_tint = vec3(0.0);
    g.flatness = vec3(0.0);
    g.diff_trans = vec3(0.0);
    vec3 h;
    bool refl_ok, refr_ok;
    if (!pt_pair(wi, wo, h, refl_ok, refr_ok)) return vec3(0.0);
    float cos_i = wi.z;
    float cos_o = wo.z;
    bool refl = cos_o > 0.0;
    bool refr = cos_o < 0.0;
    float s = p.spec_trans;
    float d = 0.5 * p.diff_trans;
    vec3 b = p.base;
    float eta = p.eta;
    float lum = dot(b, PRINCIPLED_LUMINANCE);
    vec3 c_tint = lum > 0.0 ? b / lum : vec3(1.0);
    vec3 value = vec3(0.0);
    float k = 1.0 / (4.0 * cos_i);
    float cos_hi = dot(wi, h);
    float f = fresnel_dielectric(cos_hi, eta);
    float df = pt_fresnel_deta(cos_hi, eta);

    // Specular reflection.
    if (s > 0.0 && refl && refl_ok) {
        vec2 da_dr, da_dan, ddg;
        vec2 alpha = pt_alphas(p.roughness, p.anisotropic, da_dr, da_dan);
        float dg = pt_ggx_dg(alpha, wi, wo, h, ddg);
        float t = p.spec_tint;
        float q = (eta - 1.0) / (eta + 1.0);
        float r0 = q * q;
        float dr0 = 4.0 * (eta - 1.0) / ((eta + 1.0) * (eta + 1.0) * (eta + 1.0));
        float w = pr_calc_schlick_weight(cos_hi, eta);
        float dw = pt_calc_schlick_weight_deta(cos_hi, eta);
        vec3 f_schlick = c_tint * r0 * (1.0 - w) + vec3(w);
        vec3 df_schlick = c_tint * (dr0 * (1.0 - w) - r0 * dw) + vec3(dw);
        vec3 f_thin = vec3(f) + t * (f_schlick - vec3(f));
        value += s * f_thin * dg * k;
        g.spec_trans += f_thin * dg * k;
        g.spec_tint += s * (f_schlick - vec3(f)) * dg * k;
        g.eta += s * (vec3((1.0 - t) * df) + t * df_schlick) * dg * k;
        for (int kk = 0; kk < 3; ++kk) g.base[kk] += s * t * r0 * (1.0 - w) * pr_tint_column(b, lum, kk) * dg * k;
        g.roughness += s * f_thin * k * dot(ddg, da_dr);
        g.anisotropic += s * f_thin * k * dot(ddg, da_dan);
    }

    // Specular transmission, at the scaled distribution.
    if (s > 0.0 && refr && refr_ok) {
        vec2 da_drs, da_dan, ddg;
        vec2 alpha = pt_alphas(pt_transmission_roughness(p), p.anisotropic, da_drs, da_dan);
        float dg = pt_ggx_dg(alpha, wi, wo, h, ddg);
        float unit = (1.0 - f) * k;
        value += s * b * unit * dg;
        g.spec_trans += b * unit * dg;
        for (int kk = 0; kk < 3; ++kk) g.base[kk][kk] += s * unit * dg;
        float ddg_drs = dot(ddg, da_drs);
        g.roughness += s * b * unit * ddg_drs * (0.65 * eta - 0.35);
        g.anisotropic += s * b * unit * dot(ddg, da_dan);
        g.eta += s * b * k * (-df * dg + (1.0 - f) * ddg_drs * 0.65 * p.roughness);
    }

    float cos_d = dot(h, wo);
    // Diffuse, retro-reflection, fake subsurface and sheen.
    if (s < 1.0 && d < 1.0 && refl) {
        float fo = pr_schlick_weight(abs(cos_o));
        float fi = pr_schlick_weight(cos_i);
        float f_diff = (1.0 - 0.5 * fi) * (1.0 - 0.5 * fo);
        float rr = 2.0 * p.roughness * cos_d * cos_d;
        float f_retro = rr * (fo + fi + fo * fi * (rr - 1.0));
        float fss90 = 0.5 * rr;
        float lo = 1.0 + (fss90 - 1.0) * fo;
        float li = 1.0 + (fss90 - 1.0) * fi;
        float inv_sum = 1.0 / (abs(cos_o) + cos_i);
        float f_ss = 1.25 * (lo * li * (inv_sum - 0.5) + 0.5);
        float fl = p.flatness;
        float shape = f_diff + f_retro + fl * (f_ss - f_diff - f_retro);
        float unit = cos_o * INV_PI;
        float weight = (1.0 - s) * (1.0 - d);
        value += weight * unit * b * shape;
        for (int kk = 0; kk < 3; ++kk) g.base[kk][kk] += weight * unit * shape;
        g.spec_trans -= (1.0 - d) * unit * b * shape;
        g.diff_trans -= 0.5 * (1.0 - s) * unit * b * shape;
        g.flatness += weight * unit * b * (f_ss - f_diff - f_retro);
        float dretro = fo + fi + fo * fi * (2.0 * rr - 1.0);
        float dss = 1.25 * (inv_sum - 0.5) * 0.5 * (fo * li + fi * lo);
        float dshape_drr = (1.0 - fl) * dretro + fl * dss;
        g.roughness += weight * unit * b * dshape_drr * 2.0 * cos_d * cos_d;

        float sheen_unit = pr_schlick_weight(abs(cos_d)) * abs(cos_o);
        vec3 c_sheen = vec3(1.0) + p.sheen_tint * (c_tint - vec3(1.0));
        value += p.sheen * weight * sheen_unit * c_sheen;
        g.sheen += weight * sheen_unit * c_sheen;
        g.spec_trans -= p.sheen * (1.0 - d) * sheen_unit * c_sheen;
        g.diff_trans -= 0.5 * p.sheen * (1.0 - s) * sheen_unit * c_sheen;
        g.sheen_tint += p.sheen * weight * sheen_unit * (c_tint - vec3(1.0));
        for (int kk = 0; kk < 3; ++kk)
            g.base[kk] += p.sheen * weight * sheen_unit * p.sheen_tint * pr_tint_column(b, lum, kk);
    }

    // Diffuse transmission.
    if (s < 1.0 && d > 0.0 && refr) {
        float unit = INV_PI * abs(cos_o);
        value += (1.0 - s) * d * b * unit;
        for (int kk = 0; kk < 3; ++kk) g.base[kk][kk] += (1.0 - s) * d * unit;
        g.spec_trans -= d * b * unit;
        g.diff_trans += 0.5 * (1.0 - s) * b * unit;
    }
    return value;
}

// The density of wo under principled_thin_sample (Mitsuba's pdf).
float principled_thin_pdf(PrincipledThin p, vec3 wi, vec3 wo) {
    vec3 h;
    bool refl_ok, refr_ok;
    if (!pt_pair(wi, wo, h, refl_ok, refr_ok)) return 0.0;
    vec4 q = pt_lobe_probs(p);
    float jacobian = abs(1.0 / (4.0 * dot(vec3(wo.xy, abs(wo.z)), h)));
    vec2 dr, da;
    float pdf = 0.0;
    if (wo.z > 0.0 && refl_ok && q.x > 0.0)
        pdf += q.x * pt_visible_pdf(pt_alphas(p.roughness, p.anisotropic, dr, da), wi, h) * jacobian;
    if (wo.z < 0.0 && refr_ok && q.y > 0.0)
        pdf += q.y * pt_visible_pdf(pt_alphas(pt_transmission_roughness(p), p.anisotropic, dr, da), wi, h) * jacobian;
    if (wo.z > 0.0) pdf += q.z * wo.z * INV_PI;
    if (wo.z < 0.0 && q.w > 0.0) pdf += q.w * -wo.z * INV_PI;
    return pdf;
}

// A direction drawn as Mitsuba draws it; false where it lands on a side its lobe does not serve.
bool principled_thin_sample(PrincipledThin p, vec3 wi, float u_lobe, vec2 u, out vec3 wo) {
    wo = vec3(0.0);
    float cos_i = wi.z;
    if (cos_i == 0.0) return false;
    vec3 up = pr_mulsign(wi, cos_i);
    vec4 q = pt_lobe_probs(p);
    if (u_lobe < q.x + q.y) {
        bool reflection = u_lobe < q.x;
        vec2 dr, da;
        vec2 alpha = pt_alphas(reflection ? p.roughness : pt_transmission_roughness(p), p.anisotropic, dr, da);
        vec3 m;
        if (!microfacet_visible_normal(DIST_GGX, alpha, up, u, m)) return false;
        vec3 r = 2.0 * dot(up, m) * m - up;
        wo = reflection ? r : vec3(r.xy, -r.z);
        bool side = reflection ? wo.z > 0.0 : wo.z < 0.0;
        if (any(isnan(wo)) || any(isinf(wo)) || !side || !pr_compatible(m, up, wo, up.z, reflection)) return false;
    } else if (u_lobe < q.x + q.y + q.z) {
        wo = sample_cosine_hemisphere(u);
    } else if (q.w > 0.0) {
        wo = -sample_cosine_hemisphere(u);
    } else {
        return false;
    }
    wo = pr_mulsign(wo, cos_i);
    return true;
}

#endif

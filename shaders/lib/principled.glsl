// Mitsuba 3.9.1's principled BSDF (twin of src/bsdf/principled.rs, whose module documentation
// gives the lobes, the sampler and the density): value with its derivatives by every parameter,
// density and sampler; bsdf.glsl includes it after microfacet.glsl and dielectric.glsl and
// dispatches principled leaves to it; shaders/principled_probe.comp compares it with the CPU's.
#ifndef PATHGRAD_PRINCIPLED_GLSL
#define PATHGRAD_PRINCIPLED_GLSL

// One principled BSDF's values at a shading point; rates = (main specular, clearcoat, diffuse)
// sampling rates.
struct Principled {
    vec3 base;
    float roughness;
    float anisotropic;
    float metallic;
    float spec_trans;
    float eta;
    float spec_tint;
    float sheen;
    float sheen_tint;
    float clearcoat;
    float clearcoat_gloss;
    float flatness;
    vec3 rates;
};

// ∂f̂/∂(each parameter), per image channel; base[k] is by base colour channel k.
struct PrincipledGrad {
    vec3 base[3];
    vec3 roughness;
    vec3 anisotropic;
    vec3 metallic;
    vec3 spec_trans;
    vec3 spec_tint;
    vec3 sheen;
    vec3 sheen_tint;
    vec3 clearcoat;
    vec3 clearcoat_gloss;
    vec3 flatness;
};

const vec3 PRINCIPLED_LUMINANCE = vec3(0.212671, 0.715160, 0.072169);

float pr_schlick_weight(float c) {
    float m = clamp(1.0 - c, 0.0, 1.0);
    return m * m * m * m * m;
}

// The weight w of Mitsuba's calc_schlick(R0, cos, η) = R0 + (1 − R0)·w.
float pr_calc_schlick_weight(float cos_i, float eta) {
    bool outside = cos_i >= 0.0;
    float eta_it = outside ? eta : 1.0 / eta;
    float eta_ti = outside ? 1.0 / eta : eta;
    float cos_t = sqrt(max(1.0 - (1.0 - cos_i * cos_i) * eta_ti * eta_ti, 0.0));
    return eta_it > 1.0 ? pr_schlick_weight(abs(cos_i)) : pr_schlick_weight(cos_t);
}

// 1 + (α² − 1) cos²θ as sin²θ + α² cos²θ (no cancellation near the normal).
float pr_gtr1_denominator(float a2, vec3 h) { return h.x * h.x + h.y * h.y + a2 * h.z * h.z; }

float pr_gtr1_d(float alpha, vec3 h) {
    float a2 = alpha * alpha;
    float d = (a2 - 1.0) / (PI * log(a2) * pr_gtr1_denominator(a2, h));
    return d * h.z > D_UNDERFLOW ? d : 0.0;
}

float pr_gtr1_d_dalpha(float alpha, vec3 h) {
    float d = pr_gtr1_d(alpha, h);
    if (d == 0.0) return 0.0;
    float c2 = h.z * h.z;
    float a2 = alpha * alpha;
    float dln_da2 = 1.0 / (a2 - 1.0) - 1.0 / (a2 * log(a2)) - c2 / pr_gtr1_denominator(a2, h);
    return d * dln_da2 * 2.0 * alpha;
}

vec3 pr_gtr1_sample(float alpha, vec2 u) {
    float phi = 2.0 * PI * u.x;
    float a2 = alpha * alpha;
    float cos2 = (1.0 - pow(a2, 1.0 - u.y)) / (1.0 - a2);
    float sin_t = sqrt(max(1.0 - cos2, 0.0));
    return vec3(cos(phi) * sin_t, sin(phi) * sin_t, sqrt(max(cos2, 0.0)));
}

float pr_smith_ggx1(vec3 v, vec3 h, float alpha) {
    if (dot(v, h) * v.z <= 0.0) return 0.0;
    if (v.z == 1.0) return 1.0;
    float c2 = v.z * v.z;
    float tan2 = (1.0 - c2) / c2;
    return 2.0 / (1.0 + sqrt(1.0 + alpha * alpha * tan2));
}

// GGX's (∂D/∂α_x, ∂D/∂α_y) and Smith's (∂G1/∂α_x, ∂G1/∂α_y), split even where α_x = α_y.
vec2 pr_ggx_d_dalpha(vec2 a, vec3 h) {
    float d = microfacet_d(DIST_GGX, a, h);
    if (d == 0.0) return vec2(0.0);
    vec2 a2 = a * a;
    float s = h.x * h.x / a2.x + h.y * h.y / a2.y + h.z * h.z;
    return vec2(d * (4.0 * h.x * h.x / (a2.x * a.x * s) - 1.0 / a.x),
                d * (4.0 * h.y * h.y / (a2.y * a.y * s) - 1.0 / a.y));
}

vec2 pr_ggx_g1_dalpha(vec2 a, vec3 v, vec3 h) {
    if (dot(v, h) * v.z <= 0.0 || v.x * v.x + v.y * v.y == 0.0) return vec2(0.0);
    float z2 = v.z * v.z;
    float s2 = (a.x * a.x * v.x * v.x + a.y * a.y * v.y * v.y) / z2;
    float root = sqrt(1.0 + s2);
    float dg_ds2 = -1.0 / (root * (1.0 + root) * (1.0 + root));
    return vec2(dg_ds2 * 2.0 * a.x * v.x * v.x / z2, dg_ds2 * 2.0 * a.y * v.y * v.y / z2);
}

vec3 pr_mulsign(vec3 v, float s) { return s < 0.0 || (s == 0.0 && (floatBitsToUint(s) >> 31) != 0u) ? -v : v; }

bool pr_compatible(vec3 m, vec3 wi, vec3 wo, float cos_i, bool reflection) {
    vec3 mm = pr_mulsign(m, cos_i);
    return dot(wi, mm) > 0.0 && (reflection ? dot(wo, mm) > 0.0 : dot(wo, -mm) > 0.0);
}

// (α_x, α_y) of the specular lobes and their derivatives by roughness (dr) and anisotropic (da).
vec2 pr_alphas(Principled p, out vec2 dr, out vec2 da) {
    float r2 = p.roughness * p.roughness;
    float aspect = sqrt(1.0 - 0.9 * p.anisotropic);
    float ax = r2 / aspect;
    float ay = r2 * aspect;
    vec2 keep = vec2(ax > 0.001 ? 1.0 : 0.0, ay > 0.001 ? 1.0 : 0.0);
    dr = vec2(2.0 * p.roughness / aspect, 2.0 * p.roughness * aspect) * keep;
    da = vec2(0.45 * r2 / (aspect * aspect * aspect), -0.45 * r2 / aspect) * keep;
    return vec2(max(ax, 0.001), max(ay, 0.001));
}

// Lobe probabilities (diffuse, clearcoat, transmission, reflection) given F at the specular
// lobes' microfacet normal.
vec4 pr_lobe_probs(Principled p, bool front, float f) {
    float brdf = (1.0 - p.metallic) * (1.0 - p.spec_trans);
    float bsdf = (1.0 - p.metallic) * p.spec_trans;
    vec4 q = front ? vec4(brdf * p.rates.z, 0.25 * p.clearcoat * p.rates.y, p.rates.x * bsdf * (1.0 - f),
                          p.rates.x * (1.0 - bsdf * (1.0 - f)))
                   : vec4(0.0, 0.0, 1.0 - f, f);
    return q / (q.x + q.y + q.z + q.w);
}

// The half vector of (wi, wo) (upper hemisphere), F there, and the masks Mitsuba's eval and pdf
// share; false where wi is grazing.
bool pr_pair(Principled p, vec3 wi, vec3 wo, out bool front, out bool refl, out bool refr, out float eta_path,
             out vec3 h, out float f, out bool refl_ok, out bool refr_ok) {
    float cos_i = wi.z;
    front = cos_i > 0.0;
    refl = cos_i * wo.z > 0.0;
    refr = cos_i * wo.z < 0.0;
    eta_path = front ? p.eta : 1.0 / p.eta;
    h = normalize(wi + wo * (refl ? 1.0 : eta_path));
    h = pr_mulsign(h, h.z);
    f = 0.0;
    refl_ok = false;
    refr_ok = false;
    if (cos_i == 0.0 || any(isnan(h)) || any(isinf(h))) return false;
    f = fresnel_dielectric(dot(wi, h), p.eta);
    refl_ok = pr_compatible(h, wi, wo, cos_i, true);
    refr_ok = pr_compatible(h, wi, wo, cos_i, false);
    return true;
}

// ∂(base/lum)/∂base_k (0 where lum ≤ 0, where the tint is 1).
vec3 pr_tint_column(vec3 b, float lum, int k) {
    if (!(lum > 0.0)) return vec3(0.0);
    vec3 e = vec3(0.0);
    e[k] = 1.0 / lum;
    return e - b * (PRINCIPLED_LUMINANCE[k] / (lum * lum));
}

// f̂(wi, wo) and its derivatives by every parameter (η excepted).
vec3 principled_eval_grad(Principled p, vec3 wi, vec3 wo, out PrincipledGrad g) {
    g.base[0] = vec3(0.0);
    g.base[1] = vec3(0.0);
    g.base[2] = vec3(0.0);
    g.roughness = vec3(0.0);
    g.anisotropic = vec3(0.0);
    g.metallic = vec3(0.0);
    g.spec_trans = vec3(0.0);
    g.spec_tint = vec3(0.0);
    g.sheen = vec3(0.0);
    g.sheen_tint = vec3(0.0);
    g.clearcoat = vec3(0.0);
    g.clearcoat_gloss = vec3(0.0);
    g.flatness = vec3(0.0);
    bool front, refl, refr, refl_ok, refr_ok;
    float eta_path, f;
    vec3 h;
    if (!pr_pair(p, wi, wo, front, refl, refr, eta_path, h, f, refl_ok, refr_ok)) return vec3(0.0);
    float cos_i = wi.z;
    float cos_o = wo.z;
    float m = p.metallic;
    float st = p.spec_trans;
    vec3 b = p.base;
    float brdf = (1.0 - m) * (1.0 - st);
    float bsdf = (1.0 - m) * st;
    vec2 da_dr, da_dan;
    vec2 alpha = pr_alphas(p, da_dr, da_dan);
    float lum = dot(b, PRINCIPLED_LUMINANCE);
    vec3 c_tint = lum > 0.0 ? b / lum : vec3(1.0);
    vec3 value = vec3(0.0);

    float d = microfacet_d(DIST_GGX, alpha, h);
    float gi = microfacet_g1(DIST_GGX, alpha, wi, h);
    float go = microfacet_g1(DIST_GGX, alpha, wo, h);
    float dg = d * gi * go;
    vec2 ddg = d > 0.0 ? pr_ggx_d_dalpha(alpha, h) * gi * go
                             + d * (pr_ggx_g1_dalpha(alpha, wi, h) * go + gi * pr_ggx_g1_dalpha(alpha, wo, h))
                       : vec2(0.0);
    vec3 dlobes = vec3(0.0);
    float cos_hi = dot(wi, h);

    // Specular reflection.
    if (refl && refl_ok && f > 0.0) {
        float k = 1.0 / (4.0 * abs(cos_i));
        if (front) {
            float t = p.spec_tint;
            float w = pr_calc_schlick_weight(cos_hi, p.eta);
            float eta_it = cos_hi >= 0.0 ? p.eta : 1.0 / p.eta;
            float r0 = (eta_it - 1.0) / (eta_it + 1.0);
            r0 *= r0;
            vec3 s_base = b * (1.0 - w) + vec3(w);
            vec3 s_tint = c_tint * r0 * (1.0 - w) + vec3(w);
            vec3 fp = vec3((1.0 - m) * (1.0 - t) * f) + m * s_base + (1.0 - m) * t * s_tint;
            value += fp * dg * k;
            dlobes += fp * k;
            g.metallic += (vec3(-(1.0 - t) * f) + s_base - t * s_tint) * dg * k;
            g.spec_tint += (vec3(-(1.0 - m) * f) + (1.0 - m) * s_tint) * dg * k;
            for (int kk = 0; kk < 3; kk++) {
                vec3 e = vec3(0.0);
                e[kk] = m * (1.0 - w);
                g.base[kk] += (e + (1.0 - m) * t * r0 * (1.0 - w) * pr_tint_column(b, lum, kk)) * dg * k;
            }
        } else {
            value += vec3(bsdf * f * dg * k);
            dlobes += vec3(bsdf * f * k);
            g.metallic -= vec3(st * f * dg * k);
            g.spec_trans += vec3((1.0 - m) * f * dg * k);
        }
    }

    // Specular transmission.
    if (bsdf > 0.0 && refr && refr_ok && f < 1.0) {
        float om = dot(wo, h);
        float den = cos_hi + eta_path * om;
        float unit = (1.0 - f) * abs(cos_hi * om / (cos_i * den * den));
        vec3 sb = sqrt(max(b, vec3(0.0)));
        value += sb * bsdf * unit * dg;
        dlobes += sb * bsdf * unit;
        g.metallic -= sb * st * unit * dg;
        g.spec_trans += sb * (1.0 - m) * unit * dg;
        for (int kk = 0; kk < 3; kk++) {
            if (sb[kk] > 0.0) g.base[kk][kk] += bsdf * unit * dg / (2.0 * sb[kk]);
        }
    }
    g.roughness += dlobes * dot(ddg, da_dr);
    g.anisotropic += dlobes * dot(ddg, da_dan);

    // Clearcoat.
    if (p.clearcoat > 0.0 && refl && refl_ok && front) {
        float fcc = 0.04 + 0.96 * pr_calc_schlick_weight(cos_hi, p.eta);
        float acc = 0.1 + p.clearcoat_gloss * (0.001 - 0.1);
        float gcc = pr_smith_ggx1(wi, h, 0.25) * pr_smith_ggx1(wo, h, 0.25);
        float unit = 0.25 * fcc * gcc * abs(cos_o);
        float dcc = pr_gtr1_d(acc, h);
        value += vec3(p.clearcoat * unit * dcc);
        g.clearcoat += vec3(unit * dcc);
        g.clearcoat_gloss += vec3(p.clearcoat * unit * pr_gtr1_d_dalpha(acc, h) * (0.001 - 0.1));
    }

    float cos_d = dot(h, wo);
    // Diffuse, retro-reflection and fake subsurface.
    if (brdf > 0.0 && refl && front) {
        float fo = pr_schlick_weight(abs(cos_o));
        float fi = pr_schlick_weight(abs(cos_i));
        float f_diff = (1.0 - 0.5 * fi) * (1.0 - 0.5 * fo);
        float rr = 2.0 * p.roughness * cos_d * cos_d;
        float f_retro = rr * (fo + fi + fo * fi * (rr - 1.0));
        float fss90 = 0.5 * rr;
        float lo = 1.0 + (fss90 - 1.0) * fo;
        float li = 1.0 + (fss90 - 1.0) * fi;
        float inv_sum = 1.0 / (abs(cos_o) + abs(cos_i));
        float f_ss = 1.25 * (lo * li * (inv_sum - 0.5) + 0.5);
        float fl = p.flatness;
        float shape = f_diff + f_retro + fl * (f_ss - f_diff - f_retro);
        float unit = abs(cos_o) * INV_PI;
        value += brdf * unit * b * shape;
        for (int kk = 0; kk < 3; kk++) g.base[kk][kk] += brdf * unit * shape;
        g.metallic -= (1.0 - st) * unit * b * shape;
        g.spec_trans -= (1.0 - m) * unit * b * shape;
        g.flatness += brdf * unit * b * (f_ss - f_diff - f_retro);
        float dretro = fo + fi + fo * fi * (2.0 * rr - 1.0);
        float dss = 1.25 * (inv_sum - 0.5) * 0.5 * (fo * li + fi * lo);
        g.roughness += brdf * unit * b * ((1.0 - fl) * dretro + fl * dss) * 2.0 * cos_d * cos_d;
    }

    // Sheen.
    if (p.sheen > 0.0 && refl && 1.0 - m > 0.0 && front) {
        float unit = pr_schlick_weight(abs(cos_d)) * abs(cos_o);
        vec3 c_sheen = vec3(1.0) + p.sheen_tint * (c_tint - vec3(1.0));
        value += p.sheen * (1.0 - m) * unit * c_sheen;
        g.sheen += (1.0 - m) * unit * c_sheen;
        g.metallic -= p.sheen * unit * c_sheen;
        g.sheen_tint += p.sheen * (1.0 - m) * unit * (c_tint - vec3(1.0));
        for (int kk = 0; kk < 3; kk++) {
            g.base[kk] += p.sheen * (1.0 - m) * unit * p.sheen_tint * pr_tint_column(b, lum, kk);
        }
    }
    return value;
}

vec3 principled_eval(Principled p, vec3 wi, vec3 wo) {
    PrincipledGrad g;
    return principled_eval_grad(p, wi, wo, g);
}

// The density of wo under principled_sample (Mitsuba's pdf).
float principled_pdf(Principled p, vec3 wi, vec3 wo) {
    bool front, refl, refr, refl_ok, refr_ok;
    float eta_path, f;
    vec3 h;
    if (!pr_pair(p, wi, wo, front, refl, refr, eta_path, h, f, refl_ok, refr_ok)) return 0.0;
    if (!front && !((1.0 - p.metallic) * p.spec_trans > 0.0)) return 0.0;
    vec4 q = pr_lobe_probs(p, front, f);
    float cos_hi = dot(wi, h);
    float cos_ho = dot(wo, h);
    float den = cos_hi + eta_path * cos_ho;
    float jacobian = refl ? abs(1.0 / (4.0 * cos_ho)) : abs(eta_path * eta_path * cos_ho / (den * den));
    vec2 dr, da;
    vec2 alpha = pr_alphas(p, dr, da);
    vec3 up = pr_mulsign(wi, wi.z);
    float visible = microfacet_d(DIST_GGX, alpha, h) * microfacet_g1(DIST_GGX, alpha, up, h) * abs(dot(up, h)) / up.z;
    float pdf = 0.0;
    if (refl && refl_ok) {
        pdf += q.w * visible * jacobian;
        if (q.y > 0.0) {
            float acc = 0.1 + p.clearcoat_gloss * (0.001 - 0.1);
            float pm = h.z < 0.0 ? 0.0 : h.z * pr_gtr1_d(acc, h);
            pdf += q.y * pm * jacobian;
        }
    }
    if (refl) pdf += q.x * cosine_hemisphere_pdf(wo);
    if (refr && refr_ok && q.z > 0.0) pdf += q.z * visible * jacobian;
    return pdf;
}

// A direction drawn as Mitsuba draws it; false where it lands on a side its lobe does not serve.
bool principled_sample(Principled p, vec3 wi, float u_lobe, vec2 u, out vec3 wo) {
    wo = vec3(0.0);
    float cos_i = wi.z;
    if (cos_i == 0.0) return false;
    bool front = cos_i > 0.0;
    if (!front && !((1.0 - p.metallic) * p.spec_trans > 0.0)) return false;
    vec2 dr, da;
    vec2 alpha = pr_alphas(p, dr, da);
    vec3 up = pr_mulsign(wi, cos_i);
    vec3 m_spec;
    if (!microfacet_visible_normal(DIST_GGX, alpha, up, u, m_spec)) return false;
    float im = dot(wi, m_spec);
    float f = fresnel_dielectric(im, p.eta);
    vec4 q = pr_lobe_probs(p, front, f);
    if (u_lobe < q.x) {
        wo = sample_cosine_hemisphere(u);
        return cos_i * wo.z > 0.0;
    }
    vec3 m = m_spec;
    bool reflection = true;
    if (u_lobe < q.x + q.y) {
        m = pr_gtr1_sample(0.1 + p.clearcoat_gloss * (0.001 - 0.1), u);
    } else if (u_lobe < q.x + q.y + q.z) {
        reflection = false;
    }
    float imm = dot(wi, m);
    if (reflection) {
        wo = 2.0 * imm * m - wi;
    } else {
        bool outside = imm >= 0.0;
        float eta_ti = outside ? 1.0 / p.eta : p.eta;
        float ct = sqrt(max(1.0 - (1.0 - imm * imm) * eta_ti * eta_ti, 0.0));
        float cos_t = outside ? -ct : ct;
        wo = m * (imm * eta_ti + cos_t) - wi * eta_ti;
    }
    bool side = reflection ? cos_i * wo.z > 0.0 : cos_i * wo.z < 0.0;
    return !any(isnan(wo)) && !any(isinf(wo)) && side && pr_compatible(m, wi, wo, cos_i, reflection);
}

#endif

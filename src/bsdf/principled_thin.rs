//! Mitsuba 3.9.1's `principledthin` BSDF (Burley's thin-surface Disney BSDF as
//! `src/bsdfs/principledthin.cpp` and `principlehelpers.h` define it): value, sampler, density and
//! detached derivatives of the value by every parameter, η included. Its GLSL twin is
//! `shaders/lib/principled_thin.glsl` (compared in `tests/it/twins.rs` through
//! `shaders/principled_thin_probe.comp`); the loader's `principledthin` material
//! (`crate::scene::Material::PrincipledThin`) resolves to it in both back ends.
//!
//! A thin sheet has no inside: Mitsuba turns wi to the upper side (wo with it) and evaluates there.
//! With wo_r = wo with |z|, the half vector h = normalize(wi + wo_r) serves reflection and
//! transmission alike (transmission is a microfacet reflection mirrored through the sheet, no
//! bending). With s = spec_trans, d = diff_trans/2, F = F(wi·h, η) the dielectric Fresnel term,
//! GGX at (α_x, α_y) = max(0.001, r²/a, r²·a), a = √(1 − 0.9·anisotropic), and the scaled GGX of
//! transmission at roughness (0.65η − 0.35)·r (Burley 2015, figure 15):
//!
//! - specular reflection (s > 0), s·F_thin·D·G/(4 cos θi), F_thin = lerp(F, S(c_tint·R0(η)),
//!   spec_tint), S Mitsuba's `calc_schlick`, c_tint = base/lum(base);
//! - specular transmission (s > 0), s·base·(1 − F)·D_s·G_s/(4 cos θi);
//! - diffuse (s < 1, d < 1), (1 − s)(1 − d)·cos θo·base/π·lerp(f_diff + f_retro, f_ss, flatness),
//!   as principled's;
//! - sheen (sheen > 0, s < 1, d < 1), sheen·(1 − s)(1 − d)·w(|h·wo|)·lerp(1, c_tint,
//!   sheen_tint)·|cos θo|;
//! - diffuse transmission (s < 1, d > 0), (1 − s)·d·base/π·|cos θo|.
//!
//! Sampling is Mitsuba's: the lobe uniform picks specular reflection (∝ s·s_sr/2), specular
//! transmission (∝ s·s_st/2), cosine reflection (∝ s_dr(1 − s)(1 − d)) or cosine transmission
//! (∝ s_dt(1 − s)·d); the specular lobes draw a visible GGX normal of their distribution. The
//! probabilities do not depend on the direction, so [`PrincipledThinLeaf::pdf`] — Mitsuba's `pdf`
//! — is exactly the sampler's density.
//!
//! Mitsuba skips a lobe whose parameter the XML leaves at 0 (`get_flag`); every skipped term is
//! also zero in the general formula, so the values agree without flags. The derivatives are the
//! general formula's, which are Mitsuba's once a parameter is differentiated (`params.update()`
//! switches its flag on); with the flag still off Mitsuba's derivative by that parameter would be
//! the one of the branch it kept (by `spec_tint`, −F instead of S − F; by `anisotropic`,
//! `flatness` and `sheen_tint`, 0).

use std::f32::consts::FRAC_1_PI;

use glam::{Vec2, Vec3};

use super::principled::{
    LUMINANCE, calc_schlick_weight, compatible, ggx_d_dalpha, ggx_g1_dalpha, mulsign, schlick_weight,
};
use super::rough_conductor::{Distribution, microfacet_d_aniso, microfacet_g1_aniso, microfacet_visible_normal};
use super::rough_plastic::fresnel_dielectric;
use crate::sampling::{cosine_hemisphere_pdf, sample_cosine_hemisphere};

/// The values of one thin principled BSDF at a shading point (textures already looked up).
///
/// ```
/// use glam::{Vec2, Vec3};
/// use pathgrad::bsdf::principled_thin::PrincipledThinLeaf;
/// let sheet = PrincipledThinLeaf { spec_trans: 0.8, diff_trans: 0.6, ..PrincipledThinLeaf::default() };
/// let wi = Vec3::new(0.0, 0.6, 0.8);
/// // The second lobe (specular transmission) goes through the sheet, unbent.
/// let wo = sheet.sample(wi, 0.6, Vec2::new(0.3, 0.7)).unwrap();
/// assert!(wo.z < 0.0 && sheet.pdf(wi, wo) > 0.0 && sheet.eval(wi, wo).x > 0.0);
/// // A thin sheet looks the same from both sides.
/// assert_eq!(sheet.eval(-wi, -wo), sheet.eval(wi, wo));
/// // The derivative by η of the value at that direction (the transmission's roughness scales with η).
/// let (_, grad) = sheet.eval_grad(wi, wo);
/// assert!(grad.eta.x != 0.0);
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PrincipledThinLeaf {
    /// `base_color` (RGB).
    pub base_color: Vec3,
    /// `roughness` r: α = r² (before anisotropy and the 0.001 floor).
    pub roughness: f32,
    /// `anisotropic`: α_x = r²/√(1 − 0.9·a), α_y = r²·√(1 − 0.9·a).
    pub anisotropic: f32,
    /// `spec_trans`: the share of the specular lobes.
    pub spec_trans: f32,
    /// `eta`: the sheet's relative index of refraction (its Fresnel term and the transmission's
    /// roughness scale; it bends nothing).
    pub eta: f32,
    /// `spec_tint`.
    pub spec_tint: f32,
    /// `sheen`.
    pub sheen: f32,
    /// `sheen_tint`.
    pub sheen_tint: f32,
    /// `flatness`: blend of the diffuse lobe toward the fake subsurface term.
    pub flatness: f32,
    /// `diff_trans` in Mitsuba's range 0..2: half of it is the diffuse part's transmitted share.
    pub diff_trans: f32,
    /// Sampling rates (`specular_reflectance_sampling_rate`, `specular_transmittance_sampling_rate`,
    /// `diffuse_reflectance_sampling_rate`, `diffuse_transmittance_sampling_rate`), 1 by default.
    pub rates: [f32; 4],
}

impl Default for PrincipledThinLeaf {
    /// Mitsuba's defaults: base colour 0.5, roughness 0.5, η 1.5, every other weight 0.
    fn default() -> PrincipledThinLeaf {
        PrincipledThinLeaf {
            base_color: Vec3::splat(0.5),
            roughness: 0.5,
            anisotropic: 0.0,
            spec_trans: 0.0,
            eta: 1.5,
            spec_tint: 0.0,
            sheen: 0.0,
            sheen_tint: 0.0,
            flatness: 0.0,
            diff_trans: 0.0,
            rates: [1.0; 4],
        }
    }
}

/// ∂f̂/∂(every parameter) at (wi, wo), each per image channel.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PrincipledThinGrad {
    /// `base_color[k]`: ∂f̂/∂(base colour channel k); channel k reaches the other image channels
    /// through the luminance of the tints.
    pub base_color: [Vec3; 3],
    /// ∂f̂/∂roughness.
    pub roughness: Vec3,
    /// ∂f̂/∂anisotropic.
    pub anisotropic: Vec3,
    /// ∂f̂/∂spec_trans.
    pub spec_trans: Vec3,
    /// ∂f̂/∂eta.
    pub eta: Vec3,
    /// ∂f̂/∂spec_tint.
    pub spec_tint: Vec3,
    /// ∂f̂/∂sheen.
    pub sheen: Vec3,
    /// ∂f̂/∂sheen_tint.
    pub sheen_tint: Vec3,
    /// ∂f̂/∂flatness.
    pub flatness: Vec3,
    /// ∂f̂/∂diff_trans (Mitsuba's 0..2 parameter).
    pub diff_trans: Vec3,
}

impl PrincipledThinGrad {
    /// Every derivative multiplied (per image channel) by `adj`.
    pub fn weighted(&self, adj: Vec3) -> PrincipledThinGrad {
        PrincipledThinGrad {
            base_color: self.base_color.map(|c| c * adj),
            roughness: self.roughness * adj,
            anisotropic: self.anisotropic * adj,
            spec_trans: self.spec_trans * adj,
            eta: self.eta * adj,
            spec_tint: self.spec_tint * adj,
            sheen: self.sheen * adj,
            sheen_tint: self.sheen_tint * adj,
            flatness: self.flatness * adj,
            diff_trans: self.diff_trans * adj,
        }
    }
}

impl PrincipledThinGrad {
    /// The derivatives in principled's [`super::principled::PrincipledGrad`], each in the field
    /// whose word of the material record (`PRINCIPLED_SCALARS`) holds its parameter's slot in a
    /// thin material (`MAT_PRINCIPLED_THIN`): diff_trans as metallic, eta as clearcoat,
    /// clearcoat_gloss (eta's slot again) 0 — so both BSDFs scatter through one function.
    ///
    /// ```
    /// use glam::Vec3;
    /// use pathgrad::bsdf::principled_thin::PrincipledThinGrad;
    /// let g = PrincipledThinGrad { diff_trans: Vec3::X, eta: Vec3::Y, ..PrincipledThinGrad::default() };
    /// let r = g.by_record_slot();
    /// assert_eq!((r.metallic, r.clearcoat, r.clearcoat_gloss), (Vec3::X, Vec3::Y, Vec3::ZERO));
    /// ```
    pub fn by_record_slot(&self) -> super::principled::PrincipledGrad {
        super::principled::PrincipledGrad {
            base_color: self.base_color,
            roughness: self.roughness,
            anisotropic: self.anisotropic,
            metallic: self.diff_trans,
            spec_trans: self.spec_trans,
            spec_tint: self.spec_tint,
            sheen: self.sheen,
            sheen_tint: self.sheen_tint,
            clearcoat: self.eta,
            clearcoat_gloss: Vec3::ZERO,
            flatness: self.flatness,
        }
    }
}

/// ∂F/∂η of the dielectric Fresnel term F(c, η) seen from outside (c ≥ 0): with
/// cos θt = √(1 − (1 − c²)/η²), a_s = (c − η cos θt)/(c + η cos θt) and
/// a_p = (cos θt − η c)/(cos θt + η c), F = (a_s² + a_p²)/2; 0 under total internal reflection.
fn fresnel_deta(c: f32, eta: f32) -> f32 {
    let sin2 = 1.0 - c * c;
    let ct2 = 1.0 - sin2 / (eta * eta);
    if ct2 <= 0.0 || eta == 1.0 {
        return 0.0;
    }
    let ct = ct2.sqrt();
    let dct = sin2 / (eta * eta * eta * ct);
    let (a, da) = (eta * ct, ct + eta * dct);
    let a_s = (c - a) / (c + a);
    let da_s = -2.0 * c * da / ((c + a) * (c + a));
    let b = eta * c;
    let a_p = (ct - b) / (ct + b);
    let da_p = 2.0 * (b * dct - ct * c) / ((ct + b) * (ct + b));
    a_s * da_s + a_p * da_p
}

/// ∂w/∂η of Mitsuba's `calc_schlick` weight seen from outside (c ≥ 0): 0 where η > 1 (the weight
/// of c), else −5(1 − cos θt)⁴·∂cos θt/∂η.
fn calc_schlick_weight_deta(c: f32, eta: f32) -> f32 {
    if eta > 1.0 {
        return 0.0;
    }
    let sin2 = 1.0 - c * c;
    let ct2 = 1.0 - sin2 / (eta * eta);
    if ct2 <= 0.0 {
        return 0.0;
    }
    let ct = ct2.sqrt();
    let m = 1.0 - ct;
    if !(0.0..=1.0).contains(&m) {
        return 0.0;
    }
    -5.0 * m * m * m * m * sin2 / (eta * eta * eta * ct)
}

/// (α_x, α_y) of GGX at roughness `r` and the leaf's anisotropy, with their derivatives by r and by
/// anisotropic (0 where the 0.001 floor holds).
fn alphas(r: f32, anisotropic: f32) -> (Vec2, Vec2, Vec2) {
    let r2 = r * r;
    let aspect = (1.0 - 0.9 * anisotropic).sqrt();
    let (ax, ay) = (r2 / aspect, r2 * aspect);
    let dr = Vec2::new(2.0 * r / aspect, 2.0 * r * aspect);
    let da = Vec2::new(0.45 * r2 / (aspect * aspect * aspect), -0.45 * r2 / aspect);
    let keep = Vec2::new(if ax > 0.001 { 1.0 } else { 0.0 }, if ay > 0.001 { 1.0 } else { 0.0 });
    (Vec2::new(ax.max(0.001), ay.max(0.001)), dr * keep, da * keep)
}

/// D·G1(wi)·G1(wo) of GGX at α and its derivative by (α_x, α_y).
fn ggx_dg(alpha: Vec2, wi: Vec3, wo: Vec3, h: Vec3) -> (f32, Vec2) {
    let ggx = Distribution::Ggx;
    let d = microfacet_d_aniso(ggx, alpha, h);
    let (gi, go) = (microfacet_g1_aniso(ggx, alpha, wi, h), microfacet_g1_aniso(ggx, alpha, wo, h));
    let ddg = if d > 0.0 {
        ggx_d_dalpha(alpha, h) * gi * go + d * (ggx_g1_dalpha(alpha, wi, h) * go + gi * ggx_g1_dalpha(alpha, wo, h))
    } else {
        Vec2::ZERO
    };
    (d * gi * go, ddg)
}

/// The density of GGX's visible normals h seen from `wi` (upper side): D(h)·G1(wi, h)·|wi·h|/cos θi.
fn visible_pdf(alpha: Vec2, wi: Vec3, h: Vec3) -> f32 {
    let ggx = Distribution::Ggx;
    microfacet_d_aniso(ggx, alpha, h) * microfacet_g1_aniso(ggx, alpha, wi, h) * wi.dot(h).abs() / wi.z
}

/// The pair (wi, wo) turned to wi's upper side, as Mitsuba's `eval` and `pdf` see it.
struct ThinPair {
    wi: Vec3,
    wo: Vec3,
    reflect: bool,
    refract: bool,
    /// normalize(wi + wo with |z|).
    h: Vec3,
    reflect_ok: bool,
    refract_ok: bool,
}

fn thin_pair(wi: Vec3, wo: Vec3) -> Option<ThinPair> {
    let cos_i = wi.z;
    if cos_i == 0.0 {
        return None;
    }
    let (wi, wo) = (mulsign(wi, cos_i), mulsign(wo, cos_i));
    let wo_r = Vec3::new(wo.x, wo.y, wo.z.abs());
    let h = (wi + wo_r).normalize();
    if !h.is_finite() {
        return None;
    }
    Some(ThinPair {
        wi,
        wo,
        reflect: wo.z > 0.0,
        refract: wo.z < 0.0,
        h,
        reflect_ok: compatible(h, wi, wo, wi.z, true),
        refract_ok: compatible(h, wi, wo, wi.z, false),
    })
}

impl PrincipledThinLeaf {
    /// The roughness of the transmission's scaled distribution, (0.65η − 0.35)·r.
    fn transmission_roughness(&self) -> f32 {
        (0.65 * self.eta - 0.35) * self.roughness
    }

    /// The lobes' probabilities: specular reflection, specular transmission, cosine reflection,
    /// cosine transmission.
    fn lobe_probs(&self) -> [f32; 4] {
        let (s, d) = (self.spec_trans, 0.5 * self.diff_trans);
        let p = [
            s * self.rates[0] * 0.5,
            s * self.rates[1] * 0.5,
            self.rates[2] * (1.0 - s) * (1.0 - d),
            self.rates[3] * (1.0 - s) * d,
        ];
        let inv = 1.0 / (p[0] + p[1] + p[2] + p[3]);
        p.map(|x| x * inv)
    }

    /// f̂(wi, wo) = f·|cos θo| (Mitsuba's `eval`).
    pub fn eval(&self, wi: Vec3, wo: Vec3) -> Vec3 {
        self.eval_grad(wi, wo).0
    }

    /// f̂(wi, wo) and its derivatives by every parameter.
    pub fn eval_grad(&self, wi: Vec3, wo: Vec3) -> (Vec3, PrincipledThinGrad) {
        let mut g = PrincipledThinGrad::default();
        let Some(p) = thin_pair(wi, wo) else { return (Vec3::ZERO, g) };
        let (wi, wo, h) = (p.wi, p.wo, p.h);
        let (cos_i, cos_o) = (wi.z, wo.z);
        let (s, d, b, eta) = (self.spec_trans, 0.5 * self.diff_trans, self.base_color, self.eta);
        let lum = b.dot(LUMINANCE);
        let c_tint = if lum > 0.0 { b / lum } else { Vec3::ONE };
        // ∂c_tint/∂base_k (0 where lum ≤ 0, where c_tint is 1).
        let dtint = [0, 1, 2].map(|k| {
            if lum > 0.0 {
                let mut e = Vec3::ZERO;
                e[k] = 1.0 / lum;
                e - b * (LUMINANCE[k] / (lum * lum))
            } else {
                Vec3::ZERO
            }
        });
        let mut value = Vec3::ZERO;
        let k = 1.0 / (4.0 * cos_i);
        let cos_hi = wi.dot(h);
        let f = fresnel_dielectric(cos_hi, eta).0;
        let df = fresnel_deta(cos_hi, eta);

        // Specular reflection.
        if s > 0.0 && p.reflect && p.reflect_ok {
            let (alpha, da_dr, da_dan) = alphas(self.roughness, self.anisotropic);
            let (dg, ddg) = ggx_dg(alpha, wi, wo, h);
            let t = self.spec_tint;
            let r0 = ((eta - 1.0) / (eta + 1.0)).powi(2);
            let dr0 = 4.0 * (eta - 1.0) / (eta + 1.0).powi(3);
            let w = calc_schlick_weight(cos_hi, eta);
            let dw = calc_schlick_weight_deta(cos_hi, eta);
            let f_schlick = c_tint * r0 * (1.0 - w) + Vec3::splat(w);
            let df_schlick = c_tint * (dr0 * (1.0 - w) - r0 * dw) + Vec3::splat(dw);
            let f_thin = Vec3::splat(f) + t * (f_schlick - Vec3::splat(f));
            value += s * f_thin * dg * k;
            g.spec_trans += f_thin * dg * k;
            g.spec_tint += s * (f_schlick - Vec3::splat(f)) * dg * k;
            g.eta += s * (Vec3::splat((1.0 - t) * df) + t * df_schlick) * dg * k;
            for (kk, col) in g.base_color.iter_mut().enumerate() {
                *col += s * t * r0 * (1.0 - w) * dtint[kk] * dg * k;
            }
            g.roughness += s * f_thin * k * ddg.dot(da_dr);
            g.anisotropic += s * f_thin * k * ddg.dot(da_dan);
        }

        // Specular transmission, at the scaled distribution.
        if s > 0.0 && p.refract && p.refract_ok {
            let rs = self.transmission_roughness();
            let (alpha, da_drs, da_dan) = alphas(rs, self.anisotropic);
            let (dg, ddg) = ggx_dg(alpha, wi, wo, h);
            let unit = (1.0 - f) * k;
            value += s * b * unit * dg;
            g.spec_trans += b * unit * dg;
            for (kk, col) in g.base_color.iter_mut().enumerate() {
                col[kk] += s * unit * dg;
            }
            let ddg_drs = ddg.dot(da_drs);
            g.roughness += s * b * unit * ddg_drs * (0.65 * eta - 0.35);
            g.anisotropic += s * b * unit * ddg.dot(da_dan);
            g.eta += s * b * k * (-df * dg + (1.0 - f) * ddg_drs * 0.65 * self.roughness);
        }

        let cos_d = h.dot(wo);
        // Diffuse, retro-reflection and fake subsurface.
        if s < 1.0 && d < 1.0 && p.reflect {
            let (fo, fi) = (schlick_weight(cos_o.abs()), schlick_weight(cos_i));
            let f_diff = (1.0 - 0.5 * fi) * (1.0 - 0.5 * fo);
            let rr = 2.0 * self.roughness * cos_d * cos_d;
            let f_retro = rr * (fo + fi + fo * fi * (rr - 1.0));
            let fss90 = 0.5 * rr;
            let (lo, li) = (1.0 + (fss90 - 1.0) * fo, 1.0 + (fss90 - 1.0) * fi);
            let inv_sum = 1.0 / (cos_o.abs() + cos_i);
            let f_ss = 1.25 * (lo * li * (inv_sum - 0.5) + 0.5);
            let fl = self.flatness;
            let shape = f_diff + f_retro + fl * (f_ss - f_diff - f_retro);
            let unit = cos_o * FRAC_1_PI;
            let weight = (1.0 - s) * (1.0 - d);
            value += weight * unit * b * shape;
            for (kk, col) in g.base_color.iter_mut().enumerate() {
                col[kk] += weight * unit * shape;
            }
            g.spec_trans -= (1.0 - d) * unit * b * shape;
            g.diff_trans -= 0.5 * (1.0 - s) * unit * b * shape;
            g.flatness += weight * unit * b * (f_ss - f_diff - f_retro);
            let dretro = fo + fi + fo * fi * (2.0 * rr - 1.0);
            let dss = 1.25 * (inv_sum - 0.5) * 0.5 * (fo * li + fi * lo);
            let dshape_drr = (1.0 - fl) * dretro + fl * dss;
            g.roughness += weight * unit * b * dshape_drr * 2.0 * cos_d * cos_d;

            // Sheen (Mitsuba's `any_or<true>(sheen > 0)` is true in its JIT variants: the
            // derivative by sheen stays where sheen is 0).
            {
                let unit = schlick_weight(cos_d.abs()) * cos_o.abs();
                let c_sheen = Vec3::ONE + self.sheen_tint * (c_tint - Vec3::ONE);
                value += self.sheen * weight * unit * c_sheen;
                g.sheen += weight * unit * c_sheen;
                g.spec_trans -= self.sheen * (1.0 - d) * unit * c_sheen;
                g.diff_trans -= 0.5 * self.sheen * (1.0 - s) * unit * c_sheen;
                g.sheen_tint += self.sheen * weight * unit * (c_tint - Vec3::ONE);
                for (kk, col) in g.base_color.iter_mut().enumerate() {
                    *col += self.sheen * weight * unit * self.sheen_tint * dtint[kk];
                }
            }
        }

        // Diffuse transmission.
        if s < 1.0 && d > 0.0 && p.refract {
            let unit = FRAC_1_PI * cos_o.abs();
            value += (1.0 - s) * d * b * unit;
            for (kk, col) in g.base_color.iter_mut().enumerate() {
                col[kk] += (1.0 - s) * d * unit;
            }
            g.spec_trans -= d * b * unit;
            g.diff_trans += 0.5 * (1.0 - s) * b * unit;
        }
        (value, g)
    }

    /// The density of `wo` under [`PrincipledThinLeaf::sample`] (Mitsuba's `pdf`).
    pub fn pdf(&self, wi: Vec3, wo: Vec3) -> f32 {
        let Some(p) = thin_pair(wi, wo) else { return 0.0 };
        let [psr, pst, pdr, pdt] = self.lobe_probs();
        let wo_r = Vec3::new(p.wo.x, p.wo.y, p.wo.z.abs());
        let jacobian = (1.0 / (4.0 * wo_r.dot(p.h))).abs();
        let mut pdf = 0.0;
        if p.reflect && p.reflect_ok && psr > 0.0 {
            let (alpha, _, _) = alphas(self.roughness, self.anisotropic);
            pdf += psr * visible_pdf(alpha, p.wi, p.h) * jacobian;
        }
        if p.refract && p.refract_ok && pst > 0.0 {
            let (alpha, _, _) = alphas(self.transmission_roughness(), self.anisotropic);
            pdf += pst * visible_pdf(alpha, p.wi, p.h) * jacobian;
        }
        if p.reflect {
            pdf += pdr * cosine_hemisphere_pdf(p.wo);
        }
        if p.refract && pdt > 0.0 {
            pdf += pdt * cosine_hemisphere_pdf(-p.wo);
        }
        pdf
    }

    /// A direction drawn as Mitsuba draws it (the lobe by `u_lobe`, the direction by `u`), or
    /// `None` where it lands on a side its lobe does not serve.
    pub fn sample(&self, wi: Vec3, u_lobe: f32, u: Vec2) -> Option<Vec3> {
        let cos_i = wi.z;
        if cos_i == 0.0 {
            return None;
        }
        let up = mulsign(wi, cos_i);
        let [psr, pst, pdr, pdt] = self.lobe_probs();
        let specular = |roughness: f32, reflection: bool| {
            let (alpha, _, _) = alphas(roughness, self.anisotropic);
            let m = microfacet_visible_normal(Distribution::Ggx, alpha, up, u)?;
            let r = 2.0 * up.dot(m) * m - up;
            let wo = if reflection { r } else { Vec3::new(r.x, r.y, -r.z) };
            let side = if reflection { wo.z > 0.0 } else { wo.z < 0.0 };
            (wo.is_finite() && side && compatible(m, up, wo, up.z, reflection)).then_some(wo)
        };
        let wo = if u_lobe < psr {
            specular(self.roughness, true)?
        } else if u_lobe < psr + pst {
            specular(self.transmission_roughness(), false)?
        } else if u_lobe < psr + pst + pdr {
            sample_cosine_hemisphere(u)
        } else if pdt > 0.0 {
            -sample_cosine_hemisphere(u)
        } else {
            return None;
        };
        Some(mulsign(wo, cos_i))
    }
}

#[cfg(test)]
mod tests;

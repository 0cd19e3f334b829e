//! Mitsuba 3.9.1's `principled` BSDF (Burley's Disney BSDF as `src/bsdfs/principled.cpp` and
//! `principledhelpers.h` define it): value, sampler, density and detached derivatives of the value
//! by every parameter. Its GLSL twin is `shaders/lib/principled.glsl` (compared by
//! `tests/it/twins.rs` through `shaders/principled_probe.comp`); the loader's `principled`
//! material (`crate::scene::Material::Principled`) resolves to it in both back ends.
//!
//! Lobes, with brdf = (1 − metallic)(1 − spec_trans), bsdf = (1 − metallic)·spec_trans, the GGX
//! distribution at (α_x, α_y) = max(0.001, r²/a, r²·a), a = √(1 − 0.9·anisotropic), the dielectric
//! Fresnel term F = F(wi·h, η) (scalar: Mitsuba's RGB variants take the real dielectric formula
//! once, not per channel), and Schlick's weight w(c) = (1 − c)⁵:
//!
//! - specular reflection, F_p·D·G/(4|cos θi|): seen from outside F_p = (1 − m)(1 − t)·F +
//!   m·S(base) + (1 − m)·t·S(c_tint·R0(η)), S Mitsuba's `calc_schlick`, c_tint = base/lum(base);
//!   from inside F_p = bsdf·F;
//! - specular transmission, √base·bsdf·|(1 − F)·D·G·(wi·h)(wo·h) / (cos θi (wi·h + η wo·h)²)| (the
//!   radiance form, whose (1/η)² cancels the η² of the Jacobian);
//! - clearcoat (outside only), 0.25·clearcoat·S₀.₀₄·D_GTR1(h)·G_cc·|cos θo| with GTR1 at
//!   α = lerp(0.1, 0.001, clearcoat_gloss) and the separable GGX masking at α = 0.25 — Mitsuba
//!   writes no 1/(4 cos θi cos θo) in this lobe, and neither do we;
//! - diffuse (outside only), brdf·|cos θo|·base/π·lerp(f_diff + f_retro, f_ss, flatness): Burley's
//!   diffuse with retro-reflection and Hanrahan–Krueger's fake subsurface (`flatness`);
//! - sheen (outside only), sheen·(1 − m)·w(|h·wo|)·lerp(1, c_tint, sheen_tint)·|cos θo|, without
//!   1/π and not scaled by (1 − spec_trans), as in Mitsuba.
//!
//! Sampling is Mitsuba's: a visible GGX normal m is drawn first; the lobe uniform then picks
//! diffuse (probability ∝ s_d·brdf), clearcoat (∝ 0.25·s_c·clearcoat), transmission
//! (∝ s_s·bsdf·(1 − F(wi·m))) or reflection (∝ s_s·(1 − bsdf·(1 − F(wi·m))); from inside F and
//! 1 − F alone). The two specular probabilities sum to s_s whatever m is, so the normaliser does not
//! depend on m and [`PrincipledLeaf::pdf`] — Mitsuba's `pdf` — is exactly the sampler's density.
//!
//! Mitsuba skips a lobe whose parameter the XML leaves at 0 (`get_flag`); every skipped term is
//! also zero in the general formula, so this module has no such flags. η gets no derivative (it
//! moves refracted directions: an attached derivative).

use std::f32::consts::{FRAC_1_PI, PI};

use glam::{Vec2, Vec3};

use super::rough_conductor::{Distribution, microfacet_d_aniso, microfacet_g1_aniso, microfacet_visible_normal};
use super::rough_plastic::fresnel_dielectric;
use crate::contract::D_UNDERFLOW;
use crate::sampling::{cosine_hemisphere_pdf, sample_cosine_hemisphere};

/// Mitsuba's RGB luminance weights (`mitsuba::luminance` in RGB variants).
pub const LUMINANCE: Vec3 = Vec3::new(0.212_671, 0.715_160, 0.072_169);

/// The values of one principled BSDF at a shading point (textures already looked up).
///
/// ```
/// use glam::{Vec2, Vec3};
/// use pathgrad::bsdf::principled::PrincipledLeaf;
/// let glass = PrincipledLeaf { spec_trans: 1.0, roughness: 0.2, ..PrincipledLeaf::default() };
/// let wi = Vec3::new(0.0, 0.6, 0.8);
/// // Toward the normal, most of a glass's light is refracted, weighted by the sampler's density.
/// let wo = glass.sample(wi, 0.9, Vec2::new(0.3, 0.7)).unwrap();
/// assert!(wo.z < 0.0 && glass.pdf(wi, wo) > 0.0 && glass.eval(wi, wo).x > 0.0);
/// // The derivative by roughness of the value at that direction.
/// let (_, grad) = glass.eval_grad(wi, wo);
/// assert!(grad.roughness.x != 0.0);
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PrincipledLeaf {
    /// `base_color` (RGB).
    pub base_color: Vec3,
    /// `roughness` r: α = r² (before anisotropy and the 0.001 floor).
    pub roughness: f32,
    /// `anisotropic`: α_x = r²/√(1 − 0.9·a), α_y = r²·√(1 − 0.9·a).
    pub anisotropic: f32,
    /// `metallic`.
    pub metallic: f32,
    /// `spec_trans`: the share of the dielectric part that transmits.
    pub spec_trans: f32,
    /// Relative index of refraction η (`eta`, or from `specular` by [`eta_from_specular`]).
    pub eta: f32,
    /// `spec_tint`.
    pub spec_tint: f32,
    /// `sheen`.
    pub sheen: f32,
    /// `sheen_tint`.
    pub sheen_tint: f32,
    /// `clearcoat`.
    pub clearcoat: f32,
    /// `clearcoat_gloss`.
    pub clearcoat_gloss: f32,
    /// `flatness`: blend of the diffuse lobe toward the fake subsurface term.
    pub flatness: f32,
    /// Sampling rates (`main_specular_sampling_rate`, `clearcoat_sampling_rate`,
    /// `diffuse_reflectance_sampling_rate`), 1 by default.
    pub rates: Vec3,
}

impl Default for PrincipledLeaf {
    /// Mitsuba's defaults: base colour 0.5, roughness 0.5, specular 0.5, every other weight 0.
    fn default() -> PrincipledLeaf {
        PrincipledLeaf {
            base_color: Vec3::splat(0.5),
            roughness: 0.5,
            anisotropic: 0.0,
            metallic: 0.0,
            spec_trans: 0.0,
            eta: eta_from_specular(0.5),
            spec_tint: 0.0,
            sheen: 0.0,
            sheen_tint: 0.0,
            clearcoat: 0.0,
            clearcoat_gloss: 0.0,
            flatness: 0.0,
            rates: Vec3::ONE,
        }
    }
}

/// Mitsuba's `specular` → η: 2/(1 − √(0.08·specular)) − 1 (specular 0.5 gives η ≈ 1.5).
pub fn eta_from_specular(specular: f32) -> f32 {
    2.0 / (1.0 - (0.08 * specular).sqrt()) - 1.0
}

/// ∂f̂/∂(every parameter) at (wi, wo), each per image channel.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PrincipledGrad {
    /// `base_color[k]`: ∂f̂/∂(base colour channel k); channel k reaches the other image channels
    /// through the luminance of the tints.
    pub base_color: [Vec3; 3],
    /// ∂f̂/∂roughness.
    pub roughness: Vec3,
    /// ∂f̂/∂anisotropic.
    pub anisotropic: Vec3,
    /// ∂f̂/∂metallic.
    pub metallic: Vec3,
    /// ∂f̂/∂spec_trans.
    pub spec_trans: Vec3,
    /// ∂f̂/∂spec_tint.
    pub spec_tint: Vec3,
    /// ∂f̂/∂sheen.
    pub sheen: Vec3,
    /// ∂f̂/∂sheen_tint.
    pub sheen_tint: Vec3,
    /// ∂f̂/∂clearcoat.
    pub clearcoat: Vec3,
    /// ∂f̂/∂clearcoat_gloss.
    pub clearcoat_gloss: Vec3,
    /// ∂f̂/∂flatness.
    pub flatness: Vec3,
}

impl PrincipledGrad {
    /// Every derivative multiplied (per image channel) by `adj`.
    pub fn weighted(&self, adj: Vec3) -> PrincipledGrad {
        PrincipledGrad {
            base_color: self.base_color.map(|c| c * adj),
            roughness: self.roughness * adj,
            anisotropic: self.anisotropic * adj,
            metallic: self.metallic * adj,
            spec_trans: self.spec_trans * adj,
            spec_tint: self.spec_tint * adj,
            sheen: self.sheen * adj,
            sheen_tint: self.sheen_tint * adj,
            clearcoat: self.clearcoat * adj,
            clearcoat_gloss: self.clearcoat_gloss * adj,
            flatness: self.flatness * adj,
        }
    }

    /// The derivatives of the eight scalars in `Material::table`'s order (`PRINCIPLED_SCALARS`):
    /// metallic, spec_tint, spec_trans, sheen, sheen_tint, clearcoat, clearcoat_gloss, flatness.
    pub fn scalars(&self) -> [Vec3; 8] {
        [
            self.metallic,
            self.spec_tint,
            self.spec_trans,
            self.sheen,
            self.sheen_tint,
            self.clearcoat,
            self.clearcoat_gloss,
            self.flatness,
        ]
    }
}

/// Schlick's weight (1 − c)⁵, c clipped to [0, 1] as Mitsuba's `schlick_weight`.
pub(super) fn schlick_weight(c: f32) -> f32 {
    let m = (1.0 - c).clamp(0.0, 1.0);
    m * m * m * m * m
}

/// The weight w of Mitsuba's `calc_schlick(R0, cos, η) = R0 + (1 − R0)·w`: Schlick's weight of
/// |cos| where the incident side is the denser one's outside (η_it > 1), else of the refracted
/// cosine.
pub(super) fn calc_schlick_weight(cos_i: f32, eta: f32) -> f32 {
    let outside = cos_i >= 0.0;
    let (eta_it, eta_ti) = if outside { (eta, 1.0 / eta) } else { (1.0 / eta, eta) };
    let cos_t = (1.0 - (1.0 - cos_i * cos_i) * eta_ti * eta_ti).max(0.0).sqrt();
    if eta_it > 1.0 { schlick_weight(cos_i.abs()) } else { schlick_weight(cos_t) }
}

/// 1 + (α² − 1) cos²θ of GTR1 written as sin²θ + α² cos²θ (h a unit vector), which does not cancel
/// near the normal, where a glossy clearcoat's D lives.
fn gtr1_denominator(a2: f32, h: Vec3) -> f32 {
    h.x * h.x + h.y * h.y + a2 * h.z * h.z
}

/// Clearcoat's GTR1 distribution D(h) at α (Burley 2012): (α² − 1)/(π ln α² (1 + (α² − 1) cos²θ)),
/// 0 where D·cos θ underflows.
fn gtr1_d(alpha: f32, h: Vec3) -> f32 {
    let a2 = alpha * alpha;
    let d = (a2 - 1.0) / (PI * a2.ln() * gtr1_denominator(a2, h));
    if d * h.z > D_UNDERFLOW { d } else { 0.0 }
}

/// ∂D_GTR1/∂α.
fn gtr1_d_dalpha(alpha: f32, h: Vec3) -> f32 {
    let d = gtr1_d(alpha, h);
    if d == 0.0 {
        return 0.0;
    }
    let (c2, a2) = (h.z * h.z, alpha * alpha);
    let dln_da2 = 1.0 / (a2 - 1.0) - 1.0 / (a2 * a2.ln()) - c2 / gtr1_denominator(a2, h);
    d * dln_da2 * 2.0 * alpha
}

/// A GTR1 normal from `u`, with density D_GTR1(m)·cos θm.
fn gtr1_sample(alpha: f32, u: Vec2) -> Vec3 {
    let (sin_phi, cos_phi) = (2.0 * PI * u.x).sin_cos();
    let a2 = alpha * alpha;
    let cos2 = (1.0 - a2.powf(1.0 - u.y)) / (1.0 - a2);
    let sin_t = (1.0 - cos2).max(0.0).sqrt();
    Vec3::new(cos_phi * sin_t, sin_phi * sin_t, cos2.max(0.0).sqrt())
}

/// Mitsuba's `smith_ggx1`: the separable GGX masking of v at α (clearcoat), 0 where v sees h from
/// its back.
fn smith_ggx1(v: Vec3, h: Vec3, alpha: f32) -> f32 {
    if v.dot(h) * v.z <= 0.0 {
        return 0.0;
    }
    if v.z == 1.0 {
        return 1.0;
    }
    let c2 = v.z * v.z;
    let tan2 = (1.0 - c2) / c2;
    2.0 / (1.0 + (1.0 + alpha * alpha * tan2).sqrt())
}

/// (∂D/∂α_x, ∂D/∂α_y) of GGX, split between the two even where α_x = α_y (the derivative by
/// `anisotropic` needs the parts): with S = h_x²/α_x² + h_y²/α_y² + h_z², ∂ ln D/∂α_x = 4h_x²/(α_x³ S) − 1/α_x.
pub(super) fn ggx_d_dalpha(alpha: Vec2, h: Vec3) -> Vec2 {
    let d = microfacet_d_aniso(Distribution::Ggx, alpha, h);
    if d == 0.0 {
        return Vec2::ZERO;
    }
    let a2 = alpha * alpha;
    let s = h.x * h.x / a2.x + h.y * h.y / a2.y + h.z * h.z;
    Vec2::new(
        d * (4.0 * h.x * h.x / (a2.x * alpha.x * s) - 1.0 / alpha.x),
        d * (4.0 * h.y * h.y / (a2.y * alpha.y * s) - 1.0 / alpha.y),
    )
}

/// (∂G1/∂α_x, ∂G1/∂α_y) of GGX's Smith masking, split as [`ggx_d_dalpha`]: ∂G1/∂s² · 2α_x v_x²/v_z²,
/// s² = (α_x² v_x² + α_y² v_y²)/v_z².
pub(super) fn ggx_g1_dalpha(alpha: Vec2, v: Vec3, h: Vec3) -> Vec2 {
    if v.dot(h) * v.z <= 0.0 || v.x * v.x + v.y * v.y == 0.0 {
        return Vec2::ZERO;
    }
    let z2 = v.z * v.z;
    let s2 = (alpha.x * alpha.x * v.x * v.x + alpha.y * alpha.y * v.y * v.y) / z2;
    let root = (1.0 + s2).sqrt();
    let dg_ds2 = -1.0 / (root * (1.0 + root) * (1.0 + root));
    Vec2::new(dg_ds2 * 2.0 * alpha.x * v.x * v.x / z2, dg_ds2 * 2.0 * alpha.y * v.y * v.y / z2)
}

/// `v` with the sign of `s` (Mitsuba's `mulsign`; `s` is never 0 here).
pub(super) fn mulsign(v: Vec3, s: f32) -> Vec3 {
    if s.is_sign_negative() { -v } else { v }
}

/// Mitsuba's `mac_mic_compatibility`: both directions see m (turned to wi's side) from the sides
/// their lobe needs.
pub(super) fn compatible(m: Vec3, wi: Vec3, wo: Vec3, cos_i: f32, reflection: bool) -> bool {
    let m = mulsign(m, cos_i);
    wi.dot(m) > 0.0 && if reflection { wo.dot(m) > 0.0 } else { wo.dot(-m) > 0.0 }
}

/// The geometry of a pair (wi, wo) that Mitsuba's `eval` and `pdf` share.
struct Pair {
    front: bool,
    reflect: bool,
    refract: bool,
    /// η for wi's side.
    eta_path: f32,
    /// The half vector, turned to the upper hemisphere.
    h: Vec3,
    /// F(wi·h, η).
    f: f32,
    reflect_ok: bool,
    refract_ok: bool,
}

impl PrincipledLeaf {
    /// (α_x, α_y) of the specular lobes and their derivatives by roughness and by anisotropic
    /// (0 where the 0.001 floor holds).
    fn alphas(&self) -> (Vec2, Vec2, Vec2) {
        let r2 = self.roughness * self.roughness;
        let aspect = (1.0 - 0.9 * self.anisotropic).sqrt();
        let (ax, ay) = (r2 / aspect, r2 * aspect);
        let dr = Vec2::new(2.0 * self.roughness / aspect, 2.0 * self.roughness * aspect);
        let da = Vec2::new(0.45 * r2 / (aspect * aspect * aspect), -0.45 * r2 / aspect);
        let keep = Vec2::new(if ax > 0.001 { 1.0 } else { 0.0 }, if ay > 0.001 { 1.0 } else { 0.0 });
        (Vec2::new(ax.max(0.001), ay.max(0.001)), dr * keep, da * keep)
    }

    /// The lobes' probabilities (diffuse, clearcoat, transmission, reflection) given F at the
    /// specular lobes' microfacet normal.
    fn lobe_probs(&self, front: bool, f: f32) -> [f32; 4] {
        let m = self.metallic;
        let (brdf, bsdf) = ((1.0 - m) * (1.0 - self.spec_trans), (1.0 - m) * self.spec_trans);
        let p = if front {
            [
                brdf * self.rates.z,
                0.25 * self.clearcoat * self.rates.y,
                self.rates.x * bsdf * (1.0 - f),
                self.rates.x * (1.0 - bsdf * (1.0 - f)),
            ]
        } else {
            [0.0, 0.0, 1.0 - f, f]
        };
        let inv = 1.0 / (p[0] + p[1] + p[2] + p[3]);
        p.map(|x| x * inv)
    }

    fn pair(&self, wi: Vec3, wo: Vec3) -> Option<Pair> {
        let cos_i = wi.z;
        if cos_i == 0.0 {
            return None;
        }
        let front = cos_i > 0.0;
        let (reflect, refract) = (cos_i * wo.z > 0.0, cos_i * wo.z < 0.0);
        let eta_path = if front { self.eta } else { 1.0 / self.eta };
        let h = (wi + wo * if reflect { 1.0 } else { eta_path }).normalize();
        let h = mulsign(h, h.z);
        if !h.is_finite() {
            return None;
        }
        let f = fresnel_dielectric(wi.dot(h), self.eta).0;
        Some(Pair {
            front,
            reflect,
            refract,
            eta_path,
            h,
            f,
            reflect_ok: compatible(h, wi, wo, cos_i, true),
            refract_ok: compatible(h, wi, wo, cos_i, false),
        })
    }

    /// f̂(wi, wo) = f·|cos θo| (Mitsuba's `eval`).
    pub fn eval(&self, wi: Vec3, wo: Vec3) -> Vec3 {
        self.eval_grad(wi, wo).0
    }

    /// ∂c_tint/∂base: column k is ∂(base/lum)/∂base_k (0 where lum ≤ 0, where c_tint is 1).
    fn tint_jacobian(&self, lum: f32) -> [Vec3; 3] {
        if lum > 0.0 {
            let b = self.base_color;
            [0, 1, 2].map(|k| {
                let mut e = Vec3::ZERO;
                e[k] = 1.0 / lum;
                e - b * (LUMINANCE[k] / (lum * lum))
            })
        } else {
            [Vec3::ZERO; 3]
        }
    }

    /// f̂(wi, wo) and its derivatives by every parameter (η excepted).
    pub fn eval_grad(&self, wi: Vec3, wo: Vec3) -> (Vec3, PrincipledGrad) {
        let mut g = PrincipledGrad::default();
        let Some(p) = self.pair(wi, wo) else { return (Vec3::ZERO, g) };
        let (cos_i, cos_o) = (wi.z, wo.z);
        let (m, st, b) = (self.metallic, self.spec_trans, self.base_color);
        let (brdf, bsdf) = ((1.0 - m) * (1.0 - st), (1.0 - m) * st);
        let (alpha, da_dr, da_dan) = self.alphas();
        let h = p.h;
        let lum = b.dot(LUMINANCE);
        let c_tint = if lum > 0.0 { b / lum } else { Vec3::ONE };
        let dtint = self.tint_jacobian(lum);
        let mut value = Vec3::ZERO;

        // D·G of the specular lobes and its derivative by (α_x, α_y).
        let ggx = Distribution::Ggx;
        let d = microfacet_d_aniso(ggx, alpha, h);
        let (gi, go) = (microfacet_g1_aniso(ggx, alpha, wi, h), microfacet_g1_aniso(ggx, alpha, wo, h));
        let dg = d * gi * go;
        let ddg = if d > 0.0 {
            ggx_d_dalpha(alpha, h) * gi * go + d * (ggx_g1_dalpha(alpha, wi, h) * go + gi * ggx_g1_dalpha(alpha, wo, h))
        } else {
            Vec2::ZERO
        };
        let mut dlobes = Vec3::ZERO; // ∂f̂/∂(D·G)-weighted: Σ lobe colour × d(lobe)/d(DG)
        let cos_hi = wi.dot(h);

        // Specular reflection.
        if p.reflect && p.reflect_ok && p.f > 0.0 {
            let k = 1.0 / (4.0 * cos_i.abs());
            if p.front {
                let t = self.spec_tint;
                let w = calc_schlick_weight(cos_hi, self.eta);
                let eta_it = if cos_hi >= 0.0 { self.eta } else { 1.0 / self.eta };
                let r0 = ((eta_it - 1.0) / (eta_it + 1.0)).powi(2);
                let s_base = b * (1.0 - w) + Vec3::splat(w);
                let s_tint = c_tint * r0 * (1.0 - w) + Vec3::splat(w);
                let fp = Vec3::splat((1.0 - m) * (1.0 - t) * p.f) + m * s_base + (1.0 - m) * t * s_tint;
                value += fp * dg * k;
                dlobes += fp * k;
                g.metallic += (Vec3::splat(-(1.0 - t) * p.f) + s_base - t * s_tint) * dg * k;
                g.spec_tint += (Vec3::splat(-(1.0 - m) * p.f) + (1.0 - m) * s_tint) * dg * k;
                for (kk, col) in g.base_color.iter_mut().enumerate() {
                    let mut e = Vec3::ZERO;
                    e[kk] = m * (1.0 - w);
                    *col += (e + (1.0 - m) * t * r0 * (1.0 - w) * dtint[kk]) * dg * k;
                }
            } else {
                value += Vec3::splat(bsdf * p.f * dg * k);
                dlobes += Vec3::splat(bsdf * p.f * k);
                g.metallic -= Vec3::splat(st * p.f * dg * k);
                g.spec_trans += Vec3::splat((1.0 - m) * p.f * dg * k);
            }
        }

        // Specular transmission.
        if bsdf > 0.0 && p.refract && p.refract_ok && p.f < 1.0 {
            let om = wo.dot(h);
            let den = cos_hi + p.eta_path * om;
            let unit = (1.0 - p.f) * (cos_hi * om / (cos_i * den * den)).abs();
            let sb = Vec3::new(b.x.max(0.0).sqrt(), b.y.max(0.0).sqrt(), b.z.max(0.0).sqrt());
            value += sb * bsdf * unit * dg;
            dlobes += sb * bsdf * unit;
            g.metallic -= sb * st * unit * dg;
            g.spec_trans += sb * (1.0 - m) * unit * dg;
            for (kk, col) in g.base_color.iter_mut().enumerate() {
                if sb[kk] > 0.0 {
                    col[kk] += bsdf * unit * dg / (2.0 * sb[kk]);
                }
            }
        }
        let dvalue_dalpha = |dir: Vec2| dlobes * ddg.dot(dir);
        g.roughness += dvalue_dalpha(da_dr);
        g.anisotropic += dvalue_dalpha(da_dan);

        // Clearcoat.
        if self.clearcoat > 0.0 && p.reflect && p.reflect_ok && p.front {
            let fcc = 0.04 + 0.96 * calc_schlick_weight(cos_hi, self.eta);
            let acc = 0.1 + self.clearcoat_gloss * (0.001 - 0.1);
            let gcc = smith_ggx1(wi, h, 0.25) * smith_ggx1(wo, h, 0.25);
            let unit = 0.25 * fcc * gcc * cos_o.abs();
            value += Vec3::splat(self.clearcoat * unit * gtr1_d(acc, h));
            g.clearcoat += Vec3::splat(unit * gtr1_d(acc, h));
            g.clearcoat_gloss += Vec3::splat(self.clearcoat * unit * gtr1_d_dalpha(acc, h) * (0.001 - 0.1));
        }

        let cos_d = h.dot(wo);
        // Diffuse, retro-reflection and fake subsurface.
        if brdf > 0.0 && p.reflect && p.front {
            let (fo, fi) = (schlick_weight(cos_o.abs()), schlick_weight(cos_i.abs()));
            let f_diff = (1.0 - 0.5 * fi) * (1.0 - 0.5 * fo);
            let rr = 2.0 * self.roughness * cos_d * cos_d;
            let f_retro = rr * (fo + fi + fo * fi * (rr - 1.0));
            let fss90 = 0.5 * rr;
            let (lo, li) = (1.0 + (fss90 - 1.0) * fo, 1.0 + (fss90 - 1.0) * fi);
            let fss = lo * li;
            let inv_sum = 1.0 / (cos_o.abs() + cos_i.abs());
            let f_ss = 1.25 * (fss * (inv_sum - 0.5) + 0.5);
            let fl = self.flatness;
            let shape = f_diff + f_retro + fl * (f_ss - f_diff - f_retro);
            let unit = cos_o.abs() * FRAC_1_PI;
            value += brdf * unit * b * shape;
            for (kk, col) in g.base_color.iter_mut().enumerate() {
                col[kk] += brdf * unit * shape;
            }
            g.metallic -= (1.0 - st) * unit * b * shape;
            g.spec_trans -= (1.0 - m) * unit * b * shape;
            g.flatness += brdf * unit * b * (f_ss - f_diff - f_retro);
            let dretro = fo + fi + fo * fi * (2.0 * rr - 1.0);
            let dss = 1.25 * (inv_sum - 0.5) * 0.5 * (fo * li + fi * lo);
            let dshape_drr = (1.0 - fl) * dretro + fl * dss;
            g.roughness += brdf * unit * b * dshape_drr * 2.0 * cos_d * cos_d;
        }

        // Sheen.
        if self.sheen > 0.0 && p.reflect && 1.0 - m > 0.0 && p.front {
            let unit = schlick_weight(cos_d.abs()) * cos_o.abs();
            let c_sheen = Vec3::ONE + self.sheen_tint * (c_tint - Vec3::ONE);
            value += self.sheen * (1.0 - m) * unit * c_sheen;
            g.sheen += (1.0 - m) * unit * c_sheen;
            g.metallic -= self.sheen * unit * c_sheen;
            g.sheen_tint += self.sheen * (1.0 - m) * unit * (c_tint - Vec3::ONE);
            for (kk, col) in g.base_color.iter_mut().enumerate() {
                *col += self.sheen * (1.0 - m) * unit * self.sheen_tint * dtint[kk];
            }
        }
        (value, g)
    }

    /// The density of `wo` under [`PrincipledLeaf::sample`] (Mitsuba's `pdf`).
    pub fn pdf(&self, wi: Vec3, wo: Vec3) -> f32 {
        let Some(p) = self.pair(wi, wo) else { return 0.0 };
        if !p.front && self.bsdf_weight() <= 0.0 {
            return 0.0;
        }
        let [pd, pc, pt, pr] = self.lobe_probs(p.front, p.f);
        let (cos_hi, cos_ho) = (wi.dot(p.h), wo.dot(p.h));
        let jacobian = if p.reflect {
            (1.0 / (4.0 * cos_ho)).abs()
        } else {
            let den = cos_hi + p.eta_path * cos_ho;
            (p.eta_path * p.eta_path * cos_ho / (den * den)).abs()
        };
        let (alpha, _, _) = self.alphas();
        let up = mulsign(wi, wi.z);
        let visible = || {
            let d = microfacet_d_aniso(Distribution::Ggx, alpha, p.h);
            d * microfacet_g1_aniso(Distribution::Ggx, alpha, up, p.h) * up.dot(p.h).abs() / up.z
        };
        let mut pdf = 0.0;
        if p.reflect && p.reflect_ok {
            pdf += pr * visible() * jacobian;
            if pc > 0.0 {
                let acc = 0.1 + self.clearcoat_gloss * (0.001 - 0.1);
                let pm = if p.h.z < 0.0 { 0.0 } else { p.h.z * gtr1_d(acc, p.h) };
                pdf += pc * pm * jacobian;
            }
        }
        if p.reflect {
            pdf += pd * cosine_hemisphere_pdf(wo);
        }
        if p.refract && p.refract_ok && pt > 0.0 {
            pdf += pt * visible() * jacobian;
        }
        pdf
    }

    fn bsdf_weight(&self) -> f32 {
        (1.0 - self.metallic) * self.spec_trans
    }

    /// A direction drawn as Mitsuba draws it (the lobe by `u_lobe`, the direction by `u`), or
    /// `None` where it lands on a side its lobe does not serve.
    pub fn sample(&self, wi: Vec3, u_lobe: f32, u: Vec2) -> Option<Vec3> {
        let cos_i = wi.z;
        if cos_i == 0.0 {
            return None;
        }
        let front = cos_i > 0.0;
        if !front && self.bsdf_weight() <= 0.0 {
            return None;
        }
        let (alpha, _, _) = self.alphas();
        let up = mulsign(wi, cos_i);
        let m_spec = microfacet_visible_normal(Distribution::Ggx, alpha, up, u)?;
        let (f, cos_t, eta_ti) = fresnel_dielectric(wi.dot(m_spec), self.eta);
        let [pd, pc, pt, _] = self.lobe_probs(front, f);
        let (m, reflection) = if u_lobe < pd {
            let wo = sample_cosine_hemisphere(u);
            return (cos_i * wo.z > 0.0).then_some(wo);
        } else if u_lobe < pd + pc {
            let acc = 0.1 + self.clearcoat_gloss * (0.001 - 0.1);
            (gtr1_sample(acc, u), true)
        } else if u_lobe < pd + pc + pt {
            (m_spec, false)
        } else {
            (m_spec, true)
        };
        let wo = if reflection { 2.0 * wi.dot(m) * m - wi } else { m * (wi.dot(m) * eta_ti + cos_t) - wi * eta_ti };
        let side = if reflection { cos_i * wo.z > 0.0 } else { cos_i * wo.z < 0.0 };
        (wo.is_finite() && side && compatible(m, wi, wo, cos_i, reflection)).then_some(wo)
    }
}

#[cfg(test)]
mod tests;

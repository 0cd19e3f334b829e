//! Mitsuba 3.9.1's `hair` BSDF (Chiang et al. 2016, as pbrt-v3 and `src/bsdfs/hair.cpp` define
//! it): value, density, sampler and detached derivatives of the value by the absorption and both
//! roughnesses and the scales' tilt. Not yet a scene material: neither loader nor kernel reads it.
//!
//! Local frame (Mitsuba's hair): y along the fibre, z the shading normal, x = y × z around the
//! fibre. On Mitsuba's curves u runs around the fibre, so ∂p/∂u (the shading frame's x) is
//! circumferential and y = n × x follows the curve; the azimuthal offset is
//! h = sin γ with γ the angle between the normal and wi projected onto the normal plane (Mitsuba
//! takes h from wi and the shading normal, not from the hit's v as pbrt-v3 does).
//!
//! With θ the longitudinal angle (sin θ = w.y), φ = atan2(w.z, w.x) and Δφ = φo − φi, the value
//! (Mitsuba writes no cosine, so it is this module's f̂) is
//! `Σ_{p<3} M_p(θi', θo)·A_p·N_p(Δφ) + M_3(θi, θo)·A_3/(2π)` with
//! - M_p the d'Eon et al. longitudinal lobe of variance v_p (v₀ = (0.726β_m + 0.812β_m² +
//!   3.7β_m²⁰)², v₁ = v₀/4, v₂ = v₃ = 4v₀) at the incidence θi' tilted by the scales (−2α, α, 4α),
//! - A_p the attenuations (f, (1 − f)²T, (1 − f)²T²f, (1 − f)²T³f²/(1 − Tf)) with f the
//!   dielectric Fresnel term at cos θi·cos γi and T = exp(−σ_a·2 cos γt / cos θt),
//! - N_p the logistic of scale s = √(π/8)(0.265β_n + 1.194β_n² + 5.372β_n²²) trimmed to [−π, π]
//!   about the perfect Δφ = 2pγt − 2γi + pπ.
//!
//! The sampler picks p with probability ∝ luminance(A_p), as Mitsuba's. Mitsuba's sampler draws
//! its residual lobe (p = 3) with sin θo = 0 (its loop that tilts the incidence stops before p = 3
//! and leaves sin θi' = cos θi' = 0), while its density counts that lobe as M_3: there this module
//! samples M_3 at θi, as pbrt-v3 does, so its samples follow its density (the chi-square tests).

use std::f32::consts::{PI, TAU};

use glam::{Vec2, Vec3};

use super::principled::LUMINANCE;
use super::rough_plastic::fresnel_dielectric;

/// Absorption of one unit of eumelanin per unit of fibre radius (d'Eon et al. 2011; Mitsuba's RGB).
pub const EUMELANIN_SIGMA_A: Vec3 = Vec3::new(0.419, 0.697, 1.37);
/// Absorption of one unit of pheomelanin per unit of fibre radius.
pub const PHEOMELANIN_SIGMA_A: Vec3 = Vec3::new(0.187, 0.4, 1.05);
/// Mitsuba's default relative index: amber (1.55) over air (1.000277).
pub const DEFAULT_ETA: f32 = 1.55 / 1.000_277;

/// The absorption coefficient of the pigment concentrations (Mitsuba's `use_pigmentation`).
pub fn pigment_sigma_a(eumelanin: f32, pheomelanin: f32) -> Vec3 {
    eumelanin * EUMELANIN_SIGMA_A + pheomelanin * PHEOMELANIN_SIGMA_A
}

/// The values of one hair BSDF (Mitsuba's parameters, the absorption already combined).
///
/// ```
/// use glam::{Vec2, Vec3};
/// use pathgrad::bsdf::hair::{HairLeaf, pigment_sigma_a};
/// let blonde = HairLeaf { sigma_a: pigment_sigma_a(0.2, 0.4), ..HairLeaf::default() };
/// // Light arriving across the fibre (y is the fibre's direction).
/// let wi = Vec3::new(0.6, 0.3, 0.74).normalize();
/// let wo = blonde.sample(wi, 0.4, Vec2::new(0.3, 0.7)).unwrap();
/// assert!(blonde.pdf(wi, wo) > 0.0 && blonde.eval(wi, wo).x > 0.0);
/// // The derivative of the value by the absorption of its red channel is negative.
/// let (_, grad) = blonde.eval_grad(wi, wo);
/// assert!(grad.sigma_a.x <= 0.0);
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HairLeaf {
    /// Absorption coefficient σ_a per unit of fibre radius (RGB): `scale`·`sigma_a`, or
    /// [`pigment_sigma_a`] of `eumelanin` and `pheomelanin`.
    pub sigma_a: Vec3,
    /// Relative index of refraction η (`int_ior`/`ext_ior`).
    pub eta: f32,
    /// `longitudinal_roughness` β_m ∈ [0, 1].
    pub longitudinal_roughness: f32,
    /// `azimuthal_roughness` β_n ∈ [0, 1].
    pub azimuthal_roughness: f32,
    /// `scale_tilt` α, the scales' angle in degrees.
    pub scale_tilt: f32,
}

impl Default for HairLeaf {
    /// Mitsuba's defaults: eumelanin 1.3, pheomelanin 0.2, amber in air, roughnesses 0.3, tilt 2°.
    fn default() -> HairLeaf {
        HairLeaf {
            sigma_a: pigment_sigma_a(1.3, 0.2),
            eta: DEFAULT_ETA,
            longitudinal_roughness: 0.3,
            azimuthal_roughness: 0.3,
            scale_tilt: 2.0,
        }
    }
}

/// Derivatives of the value f̂ (per image channel) by a hair leaf's parameters.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct HairGrad {
    /// ∂f̂_c/∂σ_a,c: channel c of the absorption reaches image channel c only (the eumelanin's
    /// derivative is `sigma_a * EUMELANIN_SIGMA_A`, the pheomelanin's likewise).
    pub sigma_a: Vec3,
    /// ∂f̂/∂β_m.
    pub longitudinal_roughness: Vec3,
    /// ∂f̂/∂β_n.
    pub azimuthal_roughness: Vec3,
    /// ∂f̂/∂α (per degree).
    pub scale_tilt: Vec3,
}

/// What the roughnesses and the tilt fix: the lobes' variances, the logistic scale, the tilts'
/// sines and cosines (sin 2^k α, cos 2^k α) and the derivatives of each.
struct Lobes {
    v: [f32; 4],
    dv: [f32; 4],
    s: f32,
    ds: f32,
    sin2k: [f32; 3],
    cos2k: [f32; 3],
}

impl Lobes {
    fn new(leaf: &HairLeaf) -> Lobes {
        let bm = leaf.longitudinal_roughness;
        let bn = leaf.azimuthal_roughness;
        let root = 0.726 * bm + 0.812 * bm * bm + 3.7 * bm.powi(20);
        let droot = 0.726 + 1.624 * bm + 74.0 * bm.powi(19);
        let v0 = root * root;
        let dv0 = 2.0 * root * droot;
        let k = (PI / 8.0).sqrt();
        let s = k * (0.265 * bn + 1.194 * bn * bn + 5.372 * bn.powi(22));
        let ds = k * (0.265 + 2.388 * bn + 118.184 * bn.powi(21));
        let mut sin2k = [leaf.scale_tilt.to_radians().sin(), 0.0, 0.0];
        let mut cos2k = [(1.0 - sin2k[0] * sin2k[0]).max(0.0).sqrt(), 0.0, 0.0];
        for i in 1..3 {
            sin2k[i] = 2.0 * cos2k[i - 1] * sin2k[i - 1];
            cos2k[i] = cos2k[i - 1] * cos2k[i - 1] - sin2k[i - 1] * sin2k[i - 1];
        }
        Lobes {
            v: [v0, 0.25 * v0, 4.0 * v0, 4.0 * v0],
            dv: [dv0, 0.25 * dv0, 4.0 * dv0, 4.0 * dv0],
            s,
            ds,
            sin2k,
            cos2k,
        }
    }

    /// sin θi' of lobe p (the incidence tilted by the scales; Mitsuba's `reframe_with_scales`)
    /// and its derivative by α in radians. The cosine is √(1 − sin²).
    fn tilted(&self, sin_i: f32, cos_i: f32, p: usize) -> (f32, f32) {
        let (s, c) = (self.sin2k, self.cos2k);
        match p {
            0 => (sin_i * c[1] - cos_i * s[1], -2.0 * (sin_i * s[1] + cos_i * c[1])),
            1 => (sin_i * c[0] + cos_i * s[0], -sin_i * s[0] + cos_i * c[0]),
            2 => (sin_i * c[2] + cos_i * s[2], 4.0 * (-sin_i * s[2] + cos_i * c[2])),
            _ => (sin_i, 0.0),
        }
    }
}

/// Mitsuba's modified Bessel function I₀ (its truncated series, 11 terms) and its derivative.
fn i0(x: f32) -> (f32, f32) {
    let (mut value, mut deriv) = (1.0f32, 0.0f32);
    let x2 = x * x;
    let (mut xi, mut xi_d) = (x2, x);
    let mut denom = 4.0f32;
    for i in 1..=10 {
        value += xi / denom;
        deriv += 2.0 * i as f32 * xi_d / denom;
        xi *= x2;
        xi_d *= x2;
        denom *= 4.0 * ((i + 1) as f32).powi(2);
    }
    (value, deriv)
}

/// log I₀ (Mitsuba's `log_i0`: its asymptote above 12) and its derivative.
fn log_i0(x: f32) -> (f32, f32) {
    if x > 12.0 {
        (x + 0.5 * ((1.0 / (TAU * x)).ln() + 1.0 / (8.0 * x)), 1.0 + 0.5 * (-1.0 / x - 1.0 / (8.0 * x * x)))
    } else {
        let (v, d) = i0(x);
        (v.ln(), d / v)
    }
}

/// √(1 − x²), 0 outside [−1, 1] (Mitsuba's `circ` and `safe_sqrt`).
fn circ(x: f32) -> f32 {
    (1.0 - x * x).max(0.0).sqrt()
}

/// ln 2 as Mitsuba 3.9.1's `square_to_rough_fiber_pdf` writes it (truncated to 0.6931): kept so that
/// the lobe's values are Mitsuba's (`f32::consts::LN_2` would move them by 5·10⁻⁵ relative).
#[allow(clippy::approx_constant)]
const MITSUBA_LN_2: f32 = 0.6931;

/// The longitudinal lobe M(θi, θo)/(2π) of variance v (Mitsuba's `square_to_rough_fiber_pdf`
/// with κ = 1/v) from sin θi and sin θo, and the derivatives of its logarithm by v and by sin θi.
fn longitudinal(sin_i: f32, sin_o: f32, v: f32) -> (f32, f32, f32) {
    let kappa = 1.0 / v;
    let (cos_i, cos_o) = (circ(sin_i), circ(sin_o));
    let c = cos_i * cos_o * kappa;
    let s = sin_i * sin_o * kappa;
    let (value, dlog_dkappa, dlog_i0) = if kappa > 10.0 {
        let (li0, dli0) = log_i0(c);
        let value = (-s + li0 - kappa + MITSUBA_LN_2 + (0.5 * kappa).ln()).exp() / TAU;
        (value, -sin_i * sin_o + cos_i * cos_o * dli0 - 1.0 + 1.0 / kappa, dli0)
    } else {
        let (i, di) = i0(c);
        let value = (-s).exp() * i * kappa / (2.0 * kappa.sinh()) / TAU;
        (value, -sin_i * sin_o + cos_i * cos_o * di / i + 1.0 / kappa - 1.0 / kappa.tanh(), di / i)
    };
    // d cos θi / d sin θi = −sin θi / cos θi (0 at grazing, where the lobe is flat in θi).
    let dcos = if cos_i > 0.0 { -sin_i / cos_i } else { 0.0 };
    let dlog_dsin = -sin_o * kappa + dlog_i0 * cos_o * kappa * dcos;
    (value, dlog_dkappa * (-kappa * kappa), dlog_dsin)
}

/// The logistic density of scale s at x (Mitsuba's `logistic`).
fn logistic(x: f32, s: f32) -> f32 {
    let x = x.abs();
    (-x / s).exp() / (s * (1.0 + (-x / s).exp()).powi(2))
}

/// The logistic's distribution function.
fn logistic_cdf(x: f32, s: f32) -> f32 {
    1.0 / (1.0 + (-x / s).exp())
}

/// The trimmed logistic's sample at u ∈ [0, 1] (Mitsuba's `trimmed_logistic_sample`).
fn trimmed_logistic_sample(u: f32, s: f32) -> f32 {
    let k = logistic_cdf(PI, s) - logistic_cdf(-PI, s);
    let x = -s * (1.0 / (u * k + logistic_cdf(-PI, s)) - 1.0).ln();
    x.clamp(-PI, PI)
}

/// The azimuthal lobe N_p(Δφ) (the logistic of scale s trimmed to [−π, π] about the perfect
/// offset 2pγt − 2γi + pπ; Mitsuba's `azimuthal_scattering`) and its derivative by s.
fn azimuthal(delta_phi: f32, p: usize, s: f32, gamma_i: f32, gamma_t: f32) -> (f32, f32) {
    let pf = p as f32;
    let perfect = 2.0 * pf * gamma_t - 2.0 * gamma_i + pf * PI;
    let mut phi = (delta_phi - perfect) % TAU;
    if phi < PI {
        phi += TAU;
    }
    if phi > PI {
        phi -= TAU;
    }
    let l = logistic(phi, s);
    let k = logistic_cdf(PI, s) - logistic_cdf(-PI, s);
    let a = phi.abs();
    let t = (-a / s).exp();
    let dl = l * ((a / (s * s)) * (1.0 - t) / (1.0 + t) - 1.0 / s);
    let e = (-PI / s).exp();
    let dk = -2.0 * PI / (s * s) * e / ((1.0 + e) * (1.0 + e));
    (l / k, dl / k - l * dk / (k * k))
}

/// The angles of a direction in the hair's frame: sin θ, cos θ, φ.
fn angles(w: Vec3) -> (f32, f32, f32) {
    (w.y, circ(w.y), w.z.atan2(w.x))
}

/// γ of wi: the angle between the normal and wi projected onto the normal plane (Mitsuba's
/// `gamma`), positive for wi.x < 0.
fn gamma(w: Vec3) -> f32 {
    let proj = (w.x * w.x + w.z * w.z).max(0.0).sqrt();
    let g = if proj == 0.0 { 0.0 } else { (w.z / proj).clamp(-1.0, 1.0).acos() };
    if w.x < 0.0 { g } else { -g }
}

/// What the incidence fixes: γi, γt, the attenuations A_p (RGB), their derivatives by T, T
/// itself, the transmitted length and the lobe choice probabilities.
struct Incidence {
    gamma_i: f32,
    gamma_t: f32,
    sin_i: f32,
    cos_i: f32,
    phi_i: f32,
    a: [Vec3; 4],
    da_dt: [Vec3; 4],
    transmittance: Vec3,
    length: f32,
    a_pdf: [f32; 4],
}

impl Incidence {
    fn new(leaf: &HairLeaf, wi: Vec3) -> Incidence {
        let gamma_i = gamma(wi);
        let h = gamma_i.sin();
        let (sin_i, cos_i, phi_i) = angles(wi);
        let eta = leaf.eta;
        let cos_t = circ(sin_i / eta);
        let eta_p = (eta * eta - sin_i * sin_i).max(0.0).sqrt() / cos_i;
        let sin_gamma_t = h / eta_p;
        let cos_gamma_t = circ(sin_gamma_t);
        let gamma_t = sin_gamma_t.clamp(-1.0, 1.0).asin();
        let length = 2.0 * cos_gamma_t / cos_t;
        let t = (-leaf.sigma_a * length).exp();
        let f = fresnel_dielectric(cos_i * circ(h), eta).0;
        let g = (1.0 - f) * (1.0 - f);
        let a3_den = Vec3::ONE - t * f;
        let a = [Vec3::splat(f), g * t, g * t * t * f, g * t * t * t * f * f / a3_den];
        let da_dt = [
            Vec3::ZERO,
            Vec3::splat(g),
            2.0 * g * f * t,
            g * f * f * (3.0 * t * t * a3_den + t * t * t * f) / (a3_den * a3_den),
        ];
        let lum = a.map(|x| x.dot(LUMINANCE));
        let sum: f32 = lum.iter().sum();
        Incidence {
            gamma_i,
            gamma_t,
            sin_i,
            cos_i,
            phi_i,
            a,
            da_dt,
            transmittance: t,
            length,
            a_pdf: lum.map(|l| l / sum),
        }
    }
}

/// Zero for a NaN or infinite value (Mitsuba's masking of its value and density).
fn finite_or_zero(x: f32) -> f32 {
    if x.is_finite() { x } else { 0.0 }
}

impl HairLeaf {
    /// f̂(wi, wo), the density of wo and the derivatives of f̂ (one pass over the lobes).
    fn eval_all(&self, wi: Vec3, wo: Vec3) -> (Vec3, f32, HairGrad) {
        let lobes = Lobes::new(self);
        let inc = Incidence::new(self, wi);
        let (sin_o, _, phi_o) = angles(wo);
        let delta_phi = phi_o - inc.phi_i;
        let (mut value, mut pdf) = (Vec3::ZERO, 0.0f32);
        let mut g = HairGrad::default();
        let mut dvalue_dt = Vec3::ZERO;
        for p in 0..4 {
            let (sin_ip, dsin_dalpha) = lobes.tilted(inc.sin_i, inc.cos_i, p);
            let (m, dlog_dv, dlog_dsin) = longitudinal(sin_ip, sin_o, lobes.v[p]);
            let (n, dn_ds) = if p < 3 {
                let (n, dn) = azimuthal(delta_phi, p, lobes.s, inc.gamma_i, inc.gamma_t);
                (TAU * n, TAU * dn)
            } else {
                (1.0, 0.0)
            };
            let w = m * n;
            value += w * inc.a[p];
            pdf += w * inc.a_pdf[p];
            dvalue_dt += w * inc.da_dt[p];
            g.longitudinal_roughness += w * dlog_dv * lobes.dv[p] * inc.a[p];
            g.azimuthal_roughness += m * dn_ds * lobes.ds * inc.a[p];
            g.scale_tilt += w * dlog_dsin * dsin_dalpha * (PI / 180.0) * inc.a[p];
        }
        g.sigma_a = dvalue_dt * (-inc.length * inc.transmittance);
        if !value.is_finite() {
            return (value.map(finite_or_zero), finite_or_zero(pdf), HairGrad::default());
        }
        (value, finite_or_zero(pdf), g)
    }

    /// f̂(wi, wo) (Mitsuba's `eval`, which writes no cosine).
    pub fn eval(&self, wi: Vec3, wo: Vec3) -> Vec3 {
        self.eval_all(wi, wo).0
    }

    /// The density of [`HairLeaf::sample`] at wo (Mitsuba's `pdf`).
    pub fn pdf(&self, wi: Vec3, wo: Vec3) -> f32 {
        self.eval_all(wi, wo).1
    }

    /// f̂(wi, wo) and its derivatives by the parameters (detached: the density's dependence on
    /// them is not differentiated).
    pub fn eval_grad(&self, wi: Vec3, wo: Vec3) -> (Vec3, HairGrad) {
        let (value, _, g) = self.eval_all(wi, wo);
        (value, g)
    }

    /// A direction drawn with Mitsuba's sampler: `u_lobe` picks the lobe p (∝ luminance(A_p))
    /// and, rescaled, the azimuthal offset; `u` the longitudinal angle. The residual lobe is drawn
    /// at the untilted incidence (see the module's docs).
    pub fn sample(&self, wi: Vec3, u_lobe: f32, u: Vec2) -> Option<Vec3> {
        let lobes = Lobes::new(self);
        let inc = Incidence::new(self, wi);
        let mut rest = u_lobe;
        let mut p = 0;
        let mut u_phi = u_lobe / inc.a_pdf[0];
        for i in 0..3 {
            let take = inc.a_pdf[i] < rest;
            rest -= inc.a_pdf[i];
            if take {
                p = i + 1;
                u_phi = rest / inc.a_pdf[i + 1];
            }
        }
        let u_phi = u_phi.clamp(0.0, 1.0);
        let (sin_ip, _) = lobes.tilted(inc.sin_i, inc.cos_i, p);
        let cos_ip = circ(sin_ip);
        let v = lobes.v[p];
        let cos_theta = (1.0 + v * (u.x + (1.0 - u.x) * (-2.0 / v).exp()).ln()).clamp(-1.0, 1.0);
        let sin_theta = circ(cos_theta);
        let cos_phi = (TAU * u.y).cos();
        let sin_o = -cos_theta * sin_ip + sin_theta * cos_phi * cos_ip;
        let cos_o = circ(sin_o);
        let delta_phi = if p < 3 {
            let pf = p as f32;
            2.0 * pf * inc.gamma_t - 2.0 * inc.gamma_i + pf * PI + trimmed_logistic_sample(u_phi, lobes.s)
        } else {
            TAU * u_phi
        };
        let phi_o = inc.phi_i + delta_phi;
        let wo = Vec3::new(cos_o * phi_o.cos(), sin_o, cos_o * phi_o.sin());
        let wo = wo.normalize_or_zero();
        (wo != Vec3::ZERO && wo.is_finite()).then_some(wo)
    }
}

#[cfg(test)]
mod tests;

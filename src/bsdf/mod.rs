//! BSDFs: evaluation, sampling and densities (twin of `shaders/lib/bsdf.glsl`).
//!
//! Conventions (ALGORITHMS.md §0): local frame with the shading normal on +z; `wi` points back
//! toward the camera side, `wo` toward the light side; `eval` returns the cosine-weighted value
//! f̂ = f·max(0, cos θo); densities are solid-angle densities of `wo`. Reflecting BSDFs are
//! one-sided: zero when cos θi ≤ 0 or cos θo ≤ 0. The dielectrics ([`specular`],
//! [`rough_dielectric`]) take light from either side; the smooth ones are sampled only, as is a smooth plastic's coating ([`plastic`]): their samples
//! are marked `BsdfSample::delta`.

pub mod blend;
pub mod differential;
pub mod differential_aniso;
pub mod diffuse;
pub mod hair;
pub mod plastic;
pub mod principled;
pub mod principled_thin;
pub mod rough_conductor;
pub mod rough_dielectric;
pub mod rough_plastic;
pub mod specular;

use glam::{Vec2, Vec3};

pub use rough_conductor::Distribution;

/// A BSDF without children: what one material of the scene resolves to.
#[derive(Clone, Copy, Debug, PartialEq)]
#[allow(
    clippy::large_enum_variant,
    reason = "a rough plastic carries its coating table by value (520 bytes), so a leaf stays Copy like its \
              GLSL twin; the CPU reference copies one per vertex, nothing next to its traversal"
)]
pub enum Leaf {
    /// Lambertian diffuse.
    Diffuse {
        /// RGB albedo.
        albedo: Vec3,
    },
    /// Rough conductor, isotropic (`alpha_v` = `alpha`) or not.
    RoughConductor {
        /// Microfacet distribution.
        distribution: Distribution,
        /// Roughness α (α_u: along the shading frame's x).
        alpha: f32,
        /// Roughness α_v along the shading frame's y.
        alpha_v: f32,
        /// RGB specular reflectance (multiplies the Fresnel term).
        specular: Vec3,
        /// Real part of the complex index of refraction.
        eta: Vec3,
        /// Imaginary part of the complex index of refraction.
        k: Vec3,
    },
    /// Rough plastic: a rough dielectric coating on a Lambertian base.
    RoughPlastic(rough_plastic::PlasticLeaf),
    /// Rough dielectric: a rough interface that reflects and refracts ([`rough_dielectric`]).
    RoughDielectric(rough_dielectric::RoughDielectricLeaf),
    /// A smooth BSDF: lobes that are Dirac deltas, sampled only ([`specular`]).
    Smooth(specular::SmoothLeaf),
    /// Smooth plastic: a delta coating over a Lambertian base ([`plastic`]).
    SmoothPlastic(plastic::SmoothPlasticLeaf),
    /// Mitsuba's principled BSDF ([`principled`]).
    Principled(principled::PrincipledLeaf),
    /// Mitsuba's thin principled BSDF ([`principled_thin`]).
    PrincipledThin(principled_thin::PrincipledThinLeaf),
}

/// A resolved BSDF: one leaf, or the blend `(1 − w)·leaves[0] + w·leaves[1]`, perhaps in a
/// perturbed frame (a normal map).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bsdf {
    /// The leaves; only `leaves[0]` is used unless `blend`.
    pub leaves: [Leaf; 2],
    /// Blend weight w of `leaves[1]` (clamped to [0, 1] when used).
    pub weight: f32,
    /// Whether this is a blend.
    pub blend: bool,
    /// A normal map's wrapper: the local frame (of `wi`, `wo`) is the perturbed one.
    pub perturbed: Option<Perturbed>,
}

impl Bsdf {
    /// A single-leaf BSDF.
    pub fn leaf(leaf: Leaf) -> Bsdf {
        Bsdf { leaves: [leaf, leaf], weight: 0.0, blend: false, perturbed: None }
    }
}

/// What Mitsuba's `normalmap` adds to the BSDF it wraps, whose local frame is the perturbed one
/// (`crate::cpu::surface::normal_map_frame`): f̂ and the density are zero toward a `wo` on
/// different sides of the perturbed and the unperturbed horizons, and f̂ is multiplied by Estevez
/// et al.'s shadow terminator (Ray Tracing Gems, 2019; Mitsuba's `normalmap_helpers.h`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Perturbed {
    /// The unperturbed shading normal in the perturbed local frame.
    pub base_n: Vec3,
    /// The terminator's α² = min(tan²θ/8, 1) of the perturbed normal in the unperturbed frame.
    pub alpha2: f32,
}

impl Perturbed {
    /// The factor of f̂ toward `wo` (perturbed frame): 2 / (1 + √(1 + α² tan²θo)) with θo
    /// measured from the unperturbed normal, 0 where `wo` crosses one horizon but not the other.
    pub fn factor(&self, wo: Vec3) -> f32 {
        let c = wo.dot(self.base_n);
        if !(c * wo.z > 0.0) {
            return 0.0;
        }
        let c2 = c * c;
        let tan2 = (1.0 - c2).max(0.0) / c2;
        2.0 / (1.0 + (1.0 + self.alpha2 * tan2).sqrt())
    }
}

/// A sampled direction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BsdfSample {
    /// The sampled direction (local frame).
    pub wo: Vec3,
    /// Density of the whole BSDF's sampling at `wo`.
    pub pdf: f32,
    /// f̂(wi, wo) of the whole BSDF, so the throughput weight is `value / pdf`; for a delta lobe,
    /// its weight times `pdf`.
    pub value: Vec3,
    /// A delta lobe's sample: `pdf` is the lobe's choice probability, and no other technique
    /// (next-event estimation) can produce the direction.
    pub delta: bool,
}

/// The gradient of Σ_c adj_c · f̂_c with respect to one leaf's differentiable values, kept per
/// image channel c (the backward pass sums the channels; forward-mode image gradients keep them).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LeafGrad {
    /// With respect to colour channel c (albedo or specular reflectance): only image channel c
    /// depends on it, so component c is the whole derivative.
    pub color: Vec3,
    /// With respect to the roughness α (α_u of an anisotropic conductor or dielectric), per image
    /// channel.
    pub alpha: Vec3,
    /// With respect to an anisotropic conductor's or dielectric's α_v, per image channel (0 for
    /// other leaves; an isotropic conductor's or dielectric's total α-derivative is
    /// `alpha + alpha_v`).
    pub alpha_v: Vec3,
    /// With respect to colour channel c of the transmittance (dielectrics: transmitted
    /// directions), as `color` is for the reflectance.
    pub trans: Vec3,
    /// With respect to channel c of a conductor's eta (the real part of its complex index of
    /// refraction, in its Fresnel term), as `color` is: component c is the whole derivative.
    pub eta: Vec3,
    /// With respect to channel c of a conductor's k (the imaginary part), as `eta`.
    pub k: Vec3,
    /// A principled leaf's derivatives by each of its parameters, adj-weighted per image channel
    /// (its base colour's channels reach every image channel: `color` is unused).
    pub principled: principled::PrincipledGrad,
}

/// The gradient of Σ_c adj_c · f̂_c with respect to every differentiable value of a BSDF.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BsdfGrad {
    /// Per leaf (only `leaves[0]` unless a blend).
    pub leaves: [LeafGrad; 2],
    /// With respect to the blend weight, per image channel.
    pub weight: Vec3,
}

/// ∂(adj · f̂)/∂(leaf values) at (wi, wo) (ALGORITHMS.md §4.1–4.2).
pub fn leaf_eval_grad(leaf: &Leaf, wi: Vec3, wo: Vec3, adj: Vec3) -> LeafGrad {
    match *leaf {
        Leaf::Diffuse { .. } => {
            LeafGrad { color: adj * diffuse::diffuse_eval(Vec3::ONE, wi, wo), ..LeafGrad::default() }
        }
        Leaf::RoughConductor { distribution, alpha, alpha_v, specular, eta, k } => {
            let a = Vec2::new(alpha, alpha_v);
            let (f, scalar, dscalar) = rough_conductor::microfacet_eval_parts(distribution, a, eta, k, wi, wo);
            // ∂F/∂eta, ∂F/∂k at the half vector's cosine (F's other factors do not move).
            let (d_eta, d_k) = if scalar != 0.0 {
                let (_, d_eta, d_k) = rough_conductor::fresnel_conductor_dior(wi.dot((wi + wo).normalize()), eta, k);
                (d_eta, d_k)
            } else {
                (Vec3::ZERO, Vec3::ZERO)
            };
            LeafGrad {
                color: adj * f * scalar,
                alpha: adj * f * specular * dscalar.x,
                alpha_v: adj * f * specular * dscalar.y,
                eta: adj * specular * d_eta * scalar,
                k: adj * specular * d_k * scalar,
                ..LeafGrad::default()
            }
        }
        Leaf::RoughPlastic(p) => {
            let (color, alpha, specular) = p.eval_grad(wi, wo);
            LeafGrad { color: adj * color, alpha: adj * alpha, trans: adj * specular, ..LeafGrad::default() }
        }
        Leaf::RoughDielectric(d) => {
            let (colour, transmits, alpha) = d.eval_grad(wi, wo);
            let (color, trans) = if transmits { (Vec3::ZERO, adj * colour) } else { (adj * colour, Vec3::ZERO) };
            LeafGrad { color, alpha: adj * alpha[0], alpha_v: adj * alpha[1], trans, ..LeafGrad::default() }
        }
        Leaf::Smooth(s) => {
            let g = s.value_grad(wi, wo);
            LeafGrad {
                color: adj * g.color,
                trans: adj * g.trans,
                eta: adj * g.eta,
                k: adj * g.k,
                ..LeafGrad::default()
            }
        }
        Leaf::SmoothPlastic(p) => {
            let g = p.eval_grad(wi, wo);
            LeafGrad { color: adj * g.color, trans: adj * g.trans, ..LeafGrad::default() }
        }
        Leaf::Principled(p) => LeafGrad { principled: p.eval_grad(wi, wo).1.weighted(adj), ..LeafGrad::default() },
        Leaf::PrincipledThin(p) => {
            LeafGrad { principled: p.eval_grad(wi, wo).1.weighted(adj).by_record_slot(), ..LeafGrad::default() }
        }
    }
}

/// ∂(adj · f̂)/∂(every value of `b`) at (wi, wo); the blend weight's derivative is f̂1 − f̂0 inside
/// (0, 1) and 0 where its clamp is active (ALGORITHMS.md §4.3).
pub fn bsdf_eval_grad(b: &Bsdf, wi: Vec3, wo: Vec3, adj: Vec3) -> BsdfGrad {
    let adj = b.perturbed.map_or(adj, |p| adj * p.factor(wo));
    if !b.blend {
        return BsdfGrad {
            leaves: [leaf_eval_grad(&b.leaves[0], wi, wo, adj), LeafGrad::default()],
            weight: Vec3::ZERO,
        };
    }
    let w = blend::blend_weight(b);
    let weight = if b.weight > 0.0 && b.weight < 1.0 {
        adj * (leaf_eval(&b.leaves[1], wi, wo) - leaf_eval(&b.leaves[0], wi, wo))
    } else {
        Vec3::ZERO
    };
    // A smooth leaf has no value off its delta directions ([`bsdf_delta_grad`] takes those).
    let leaf_grad = |leaf: &Leaf, adj: Vec3| match leaf {
        Leaf::Smooth(_) => LeafGrad::default(),
        _ => leaf_eval_grad(leaf, wi, wo, adj),
    };
    BsdfGrad { leaves: [leaf_grad(&b.leaves[0], adj * (1.0 - w)), leaf_grad(&b.leaves[1], adj * w)], weight }
}

/// ∂(adj · value)/∂(every value of `b`) of a sample toward `wo`: a delta sample's value (its
/// lobe's weight × choice probability) where `delta`, else f̂ ([`bsdf_eval_grad`]). A blend's
/// smooth leaf, chosen with probability c (w for `leaves[1]`, 1 − w for `leaves[0]`), has the
/// value c·v: its colours' derivatives are c·∂v, the weight's ±v inside (0, 1).
pub fn bsdf_sample_grad(b: &Bsdf, wi: Vec3, wo: Vec3, delta: bool, adj: Vec3) -> BsdfGrad {
    if !(delta && b.blend) {
        return bsdf_eval_grad(b, wi, wo, adj);
    }
    bsdf_delta_grad(b, wi, wo, adj)
}

/// [`bsdf_sample_grad`] of a blend's delta sample (the blend holds one smooth leaf).
fn bsdf_delta_grad(b: &Bsdf, wi: Vec3, wo: Vec3, adj: Vec3) -> BsdfGrad {
    let w = blend::blend_weight(b);
    let mut g = BsdfGrad::default();
    for (i, (leaf, c, sign)) in [(&b.leaves[0], 1.0 - w, -1.0), (&b.leaves[1], w, 1.0)].into_iter().enumerate() {
        let Leaf::Smooth(s) = leaf else { continue };
        let unit = s.value_grad(wi, wo);
        g.leaves[i] = LeafGrad {
            color: adj * c * unit.color,
            trans: adj * c * unit.trans,
            eta: adj * c * unit.eta,
            k: adj * c * unit.k,
            ..LeafGrad::default()
        };
        if b.weight > 0.0 && b.weight < 1.0 {
            g.weight = adj * sign * (s.reflectance * unit.color + s.transmittance * unit.trans);
        }
    }
    g
}

/// f̂ of one leaf.
pub fn leaf_eval(leaf: &Leaf, wi: Vec3, wo: Vec3) -> Vec3 {
    match *leaf {
        Leaf::Diffuse { albedo } => diffuse::diffuse_eval(albedo, wi, wo),
        Leaf::RoughConductor { distribution, alpha, alpha_v, specular, eta, k } => {
            rough_conductor::microfacet_eval(distribution, Vec2::new(alpha, alpha_v), specular, eta, k, wi, wo)
        }
        Leaf::RoughPlastic(p) => p.eval(wi, wo),
        Leaf::RoughDielectric(d) => d.eval(wi, wo),
        Leaf::Smooth(_) => Vec3::ZERO,
        Leaf::SmoothPlastic(p) => p.eval(wi, wo),
        Leaf::Principled(p) => p.eval(wi, wo),
        Leaf::PrincipledThin(p) => p.eval(wi, wo),
    }
}

/// Sampling density of one leaf.
pub fn leaf_pdf(leaf: &Leaf, wi: Vec3, wo: Vec3) -> f32 {
    match *leaf {
        Leaf::Diffuse { .. } => diffuse::diffuse_pdf(wi, wo),
        Leaf::RoughConductor { distribution, alpha, alpha_v, .. } => {
            rough_conductor::microfacet_pdf(distribution, Vec2::new(alpha, alpha_v), wi, wo)
        }
        Leaf::RoughPlastic(p) => p.pdf(wi, wo),
        Leaf::RoughDielectric(d) => d.pdf(wi, wo),
        Leaf::Smooth(_) => 0.0,
        Leaf::SmoothPlastic(p) => p.pdf(wi, wo),
        Leaf::Principled(p) => p.pdf(wi, wo),
        Leaf::PrincipledThin(p) => p.pdf(wi, wo),
    }
}

/// A direction sampled from one leaf with the lobe uniform `u_lobe` (a leaf of several lobes
/// picks one with it) and the direction uniforms `u`, or `None` if invalid.
pub fn leaf_sample(leaf: &Leaf, wi: Vec3, u_lobe: f32, u: Vec2) -> Option<Vec3> {
    match *leaf {
        Leaf::Diffuse { .. } => diffuse::diffuse_sample(wi, u),
        Leaf::RoughConductor { distribution, alpha, alpha_v, .. } => {
            rough_conductor::microfacet_sample(distribution, Vec2::new(alpha, alpha_v), wi, u)
        }
        Leaf::RoughPlastic(p) => p.sample(wi, u_lobe, u),
        Leaf::RoughDielectric(d) => d.sample(wi, u_lobe, u),
        Leaf::Principled(p) => p.sample(wi, u_lobe, u),
        Leaf::PrincipledThin(p) => p.sample(wi, u_lobe, u),
        // A leaf with a delta lobe samples itself whole: bsdf_sample takes its sample.
        Leaf::Smooth(_) | Leaf::SmoothPlastic(_) => None,
    }
}

/// f̂(wi, wo) of the leaves (or blend), without a normal map's factor.
fn unperturbed_eval(b: &Bsdf, wi: Vec3, wo: Vec3) -> Vec3 {
    if b.blend { blend::blend_eval(b, wi, wo) } else { leaf_eval(&b.leaves[0], wi, wo) }
}

/// Sampling density of the leaves (or blend) at `wo`, without a normal map's mask.
fn unperturbed_pdf(b: &Bsdf, wi: Vec3, wo: Vec3) -> f32 {
    if b.blend { blend::blend_pdf(b, wi, wo) } else { leaf_pdf(&b.leaves[0], wi, wo) }
}

/// f̂(wi, wo) of the whole BSDF.
pub fn bsdf_eval(b: &Bsdf, wi: Vec3, wo: Vec3) -> Vec3 {
    let f = unperturbed_eval(b, wi, wo);
    b.perturbed.map_or(f, |p| f * p.factor(wo))
}

/// Sampling density of the whole BSDF at `wo` (0 where a normal map's wrapper refuses `wo`).
pub fn bsdf_pdf(b: &Bsdf, wi: Vec3, wo: Vec3) -> f32 {
    match b.perturbed {
        Some(p) if p.factor(wo) == 0.0 => 0.0,
        _ => unperturbed_pdf(b, wi, wo),
    }
}

/// The leaf that `u_lobe` picks (a blend's child 1 when u_lobe ≤ w) and `u_lobe` rescaled to
/// [0, 1) within that choice, for the leaf's own lobe choice.
pub fn pick_leaf(b: &Bsdf, u_lobe: f32) -> (&Leaf, f32) {
    if !b.blend {
        return (&b.leaves[0], u_lobe);
    }
    let w = blend::blend_weight(b);
    if u_lobe <= w { (&b.leaves[1], u_lobe / w) } else { (&b.leaves[0], (u_lobe - w) / (1.0 - w)) }
}

/// Samples a direction: `u_lobe` picks the blend child (RNG dim 4), `u` drives the direction
/// (dims 5, 6). Returns `None` for an invalid sample (the path ends). The returned value and pdf
/// are the whole BSDF's, re-evaluated at the sampled direction.
pub fn bsdf_sample(b: &Bsdf, wi: Vec3, u_lobe: f32, u: Vec2) -> Option<BsdfSample> {
    let s = unperturbed_sample(b, wi, u_lobe, u)?;
    let Some(p) = b.perturbed else { return Some(s) };
    // A normal map's wrapper: the sample is invalid where wo crosses one horizon only.
    let factor = p.factor(s.wo);
    if factor == 0.0 {
        return None;
    }
    Some(BsdfSample { value: s.value * factor, ..s })
}

/// [`bsdf_sample`] of the leaves (or blend), without a normal map's wrapper.
fn unperturbed_sample(b: &Bsdf, wi: Vec3, u_lobe: f32, u: Vec2) -> Option<BsdfSample> {
    match (b.blend, &b.leaves[0]) {
        (false, Leaf::Smooth(s)) => return s.sample(wi, u_lobe),
        (false, Leaf::SmoothPlastic(p)) => return p.sample(wi, u_lobe, u),
        _ => {}
    }
    let (leaf, u_lobe) = pick_leaf(b, u_lobe);
    // A blend's smooth leaf: its delta sample, weighted by the blend's choice probability (the
    // blend's other leaf has no value in a delta direction).
    if let Leaf::Smooth(smooth) = leaf {
        let w = blend::blend_weight(b);
        let c = if std::ptr::eq(leaf, &b.leaves[1]) { w } else { 1.0 - w };
        let s = smooth.sample(wi, u_lobe)?;
        return Some(BsdfSample { pdf: s.pdf * c, value: s.value * c, ..s });
    }
    let wo = leaf_sample(leaf, wi, u_lobe, u)?;
    let pdf = unperturbed_pdf(b, wi, wo);
    if !(pdf > 0.0) {
        return None;
    }
    Some(BsdfSample { wo, pdf, value: unperturbed_eval(b, wi, wo), delta: false })
}

#[cfg(test)]
pub(crate) mod tests;

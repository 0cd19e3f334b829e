//! Attached derivatives (PRB supplemental §1–2, ALGORITHMS.md §9): the ray-state Jacobians of
//! smooth vertices, their regularisation, and the row vectors the attached estimator carries.
//!
//! A ray's state is r = (o, d), its origin and direction (six numbers). With every uniform fixed,
//! a vertex maps the ray that reaches it to the ray that leaves it, r′ = F(r), and its Jacobian
//! A = ∂r′/∂r is a [`Jac6`]. The attached estimator needs, at each vertex v, the derivative of
//! the radiance that follows v by the ray leaving v; it gets it as PRB does:
//!
//! - the primal pass sums Γ = Σ_k h_k·J̃_k, the derivative of the sample's (adjoint-weighted)
//!   radiance by the camera ray, where J̃_k = Ã_{k−1}⋯Ã_1 and Ã = A + Y·I with Y a zero-mean
//!   random scalar per vertex (stream `Jacobian`, so the replay draws the same Y);
//! - the replay starts from Φ₁ = Γ and at each vertex sets Φ_{v+1} = (Φ_v − h_v)·Ã_v⁻¹, the
//!   derivative of what follows v by the ray leaving v, unbiased whatever Y is (supplemental §2:
//!   the inverses undo exactly the noisy factors the primal pass multiplied).
//!
//! h_k is vertex k's own row: δL·β_k·∂c_k/∂r_k (what vertex k emits) plus δL·(∂ ln w_k/∂r_k ⊙
//! L_after) (its sample weight w_k times everything after it). The primal pass cannot know
//! L_after, so it carries S = Σ_{j<k} ∂ ln w_j/∂r_j·J̃_j per channel and adds δL·β_k·c_k ⊙ S_k at
//! each contribution instead: the same sum, ordered by contribution. Next-event estimation at a
//! diffuse vertex, toward a point on an area emitter that stays fixed while the vertex moves (or a
//! point, directional or spot light), is one more contribution of that vertex
//! ([`HitGeometry::nee_gradient`], [`HitGeometry::delta_light_gradient`]); the emitter hit the
//! vertex's own sample may make carries its MIS weight's row ([`HitGeometry::emitter_mis_row`]).
//!
//! Geometry is fixed: the hit point moves only along its triangle's plane, and no term for a
//! visibility change is built (a moving direction that crosses an edge is not differentiated, nor
//! a shadow ray that a moving vertex sends across a shadow's edge).

pub mod rough_dielectric;

use glam::{Mat3, Vec3};

pub use rough_dielectric::{RoughDielectricLobe, rough_dielectric_lobe};

use crate::contract::{
    LIGHT_PROJECTOR, LIGHT_SPOT, MAT_CONDUCTOR, MAT_DIELECTRIC, MAT_DIFFUSE, MAT_ROUGH_CONDUCTOR, MAT_ROUGH_DIELECTRIC,
    MAT_THIN_DIELECTRIC, NO_PARAM, SCALAR_TEXTURE, TEX_ATTR_FACE, TEX_CHECKER, TEX_NEAREST, TEX_VOLUME,
};
use crate::integrator::{RenderOptions, Sampling};
use crate::scene::flat::FlatScene;

/// Refuses attached sampling (`options.sampling`) where its vertex Jacobians are not built: every
/// material must be a `diffuse` one whose albedo is constant or varies continuously along the
/// surface (a bilinear bitmap, a per-vertex attribute), a smooth `dielectric`,
/// `thindielectric` or `conductor` or an isotropic `roughconductor` or `roughdielectric` with
/// untextured roughness (no normal map, no mask), without media; light comes from the
/// environment, from area emitters whose radiance is constant or a bilinear bitmap, or from
/// point, directional and spot lights (a spot's texture bilinear; no projector).
///
/// # Errors
/// [`crate::Error::InvalidArgument`] naming `Sampling::Attached` and what the scene or request has.
pub fn refuse_unsupported(flat: &FlatScene, options: &RenderOptions) -> crate::Result<()> {
    if options.sampling == Sampling::Detached {
        return Ok(());
    }
    let refuse = |what: String| {
        Err(crate::Error::InvalidArgument {
            parameter: "Sampling::Attached".into(),
            message: format!(
                "{what}: attached derivatives are built for scenes of smooth `dielectric`, `thindielectric` and \
                 `conductor` surfaces, isotropic `roughconductor`s and `roughdielectric`s with untextured \
                 roughness and `diffuse` surfaces with a constant or smoothly textured albedo, lit by the \
                 environment, by area emitters or by point, directional and spot lights (use detached \
                 sampling)"
            ),
        })
    };
    let names = [
        "diffuse",
        "roughconductor",
        "blendbsdf",
        "null (a medium boundary)",
        "roughplastic",
        "conductor",
        "dielectric",
        "thindielectric",
        "plastic",
        "roughdielectric",
        "principled",
        "principledthin",
    ];
    for m in &flat.materials {
        if !matches!(
            m.tag,
            MAT_DIFFUSE
                | MAT_DIELECTRIC
                | MAT_THIN_DIELECTRIC
                | MAT_CONDUCTOR
                | MAT_ROUGH_CONDUCTOR
                | MAT_ROUGH_DIELECTRIC
        ) {
            let name = names.get(m.tag as usize).copied().unwrap_or("another BSDF");
            return refuse(format!("the scene has a `{name}` material"));
        }
        if m.tag == MAT_ROUGH_CONDUCTOR && (m.p_alpha != m.p_alpha_v || m.p_alpha & SCALAR_TEXTURE != 0) {
            return refuse("the scene has an anisotropic or texture-roughened `roughconductor`".into());
        }
        if m.tag == MAT_ROUGH_DIELECTRIC && (m.p_alpha != m.p_alpha_v || m.p_alpha & SCALAR_TEXTURE != 0) {
            return refuse("the scene has an anisotropic or texture-roughened `roughdielectric`".into());
        }
        // A textured specular colour would vary with the hit point too; only the diffuse albedo's
        // slope is built (crate::cpu::slope).
        let textured_colour = (m.tag != MAT_DIFFUSE && m.tex_width > 0)
            || crate::gpu::variant::specular_colour_slots(m).into_iter().any(crate::gpu::variant::colour_textured);
        if textured_colour {
            let name = names.get(m.tag as usize).copied().unwrap_or("another BSDF");
            return refuse(format!("the scene has a `{name}` with a textured reflectance or transmittance"));
        }
        if m.tag == MAT_DIFFUSE && m.tex_width > 0 && !smooth_read(m.tex_mode) {
            return refuse(
                "the scene has a `diffuse` material whose albedo is a checkerboard, a nearest-filtered bitmap, a \
                 per-face attribute or a volume (reads that jump along the surface)"
                    .into(),
            );
        }
        if m.nmap_width > 0 || m.p_opacity != NO_PARAM {
            return refuse("the scene has a normal-mapped, bump-mapped or masked material".into());
        }
    }
    if !flat.media.is_empty() {
        return refuse("the scene has participating media".into());
    }
    // Next-event estimation's rows are built for area emitters' points, point, directional and
    // spot lights (HitGeometry::nee_gradient, HitGeometry::delta_light_gradient,
    // crate::cpu::emitter::spot_falloff_gradient, crate::cpu::slope::light_texture_slope), at
    // diffuse vertices:
    // a light without area, which only next-event estimation reaches, would be missing from the
    // rough vertices' light, or from all of it without next-event estimation.
    // A projector's frame has edges where its light jumps to 0 (a boundary term that is not
    // built); a spot's texture read by nearest texels jumps between them.
    let unsupported = |l: &crate::contract::DeltaLight| {
        l.kind == LIGHT_PROJECTOR || (l.kind == LIGHT_SPOT && l.tex != NO_PARAM && !smooth_read(l.tex_mode))
    };
    if let Some(k) = flat.lights.iter().position(unsupported) {
        let what = if flat.lights[k].kind == LIGHT_PROJECTOR {
            "a projector (its light jumps to 0 at its frame's edges)"
        } else {
            "a spot light whose texture is read by nearest texels (it jumps between them)"
        };
        return refuse(format!(
            "the scene has {what}: light {} of its {} lights without area",
            k + 1,
            flat.lights.len()
        ));
    }
    if !flat.lights.is_empty() {
        if !options.nee {
            return refuse(
                "the scene has a light without area (point, directional or spot) and next-event estimation is off \
                 (only it reaches such a light)"
                    .into(),
            );
        }
        if flat.materials.iter().any(|m| matches!(m.tag, MAT_ROUGH_CONDUCTOR | MAT_ROUGH_DIELECTRIC)) {
            return refuse(
                "the scene has a light without area and a `roughconductor` or `roughdielectric` (attached \
                 sampling estimates next events at diffuse vertices only, and only they reach such a light)"
                    .into(),
            );
        }
    }
    let jumps = |p: u32| {
        crate::cpu::emitter::area_textured(p) && {
            let d = (p & !SCALAR_TEXTURE) as usize;
            !smooth_read(flat.tables[d + 3].to_bits())
        }
    };
    if flat.emitters.iter().any(|e| jumps(e.p_radiance)) {
        return refuse(
            "the scene has an area emitter whose radiance is a nearest-filtered bitmap or a checkerboard".into(),
        );
    }
    Ok(())
}

/// Whether a texture read of mode `mode` varies continuously along the surface (a bilinear
/// bitmap, a per-vertex attribute): its slope is the whole of its derivative by the hit point
/// (`crate::cpu::slope`).
fn smooth_read(mode: u32) -> bool {
    mode & (TEX_CHECKER | TEX_NEAREST | TEX_ATTR_FACE | TEX_VOLUME) == 0
}

/// A row vector over the ray state: ∂(something)/∂o and ∂(something)/∂d.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Row6 {
    /// By the origin.
    pub o: Vec3,
    /// By the direction.
    pub d: Vec3,
}

impl Row6 {
    /// Zero.
    pub const ZERO: Row6 = Row6 { o: Vec3::ZERO, d: Vec3::ZERO };

    /// A row over the direction only.
    pub fn direction(d: Vec3) -> Row6 {
        Row6 { o: Vec3::ZERO, d }
    }

    /// This row times `j`: the same derivative by the ray *before* the map `j`.
    pub fn through(self, j: &Jac6) -> Row6 {
        Row6 {
            o: j.oo.transpose() * self.o + j.dob.transpose() * self.d,
            d: j.od.transpose() * self.o + j.dd.transpose() * self.d,
        }
    }

    /// The directional derivative along the ray perturbation (δo, δd).
    pub fn dot(self, o: Vec3, d: Vec3) -> f32 {
        self.o.dot(o) + self.d.dot(d)
    }

    /// `self + s·other`.
    pub fn add_scaled(self, other: Row6, s: f32) -> Row6 {
        Row6 { o: self.o + s * other.o, d: self.d + s * other.d }
    }

    /// Whether every entry is finite.
    pub fn is_finite(self) -> bool {
        self.o.is_finite() && self.d.is_finite()
    }

    /// The largest magnitude of an entry.
    pub fn max_abs(self) -> f32 {
        self.o.abs().max_element().max(self.d.abs().max_element())
    }
}

/// A 6×6 Jacobian between ray states in 3×3 blocks: δo′ = oo·δo + od·δd, δd′ = dob·δo + dd·δd.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Jac6 {
    /// ∂o′/∂o.
    pub oo: Mat3,
    /// ∂o′/∂d.
    pub od: Mat3,
    /// ∂d′/∂o.
    pub dob: Mat3,
    /// ∂d′/∂d.
    pub dd: Mat3,
}

impl Jac6 {
    /// The identity.
    pub const IDENTITY: Jac6 = Jac6 { oo: Mat3::IDENTITY, od: Mat3::ZERO, dob: Mat3::ZERO, dd: Mat3::IDENTITY };

    /// `self ∘ inner`: the map `inner` then `self`.
    pub fn compose(&self, inner: &Jac6) -> Jac6 {
        Jac6 {
            oo: self.oo * inner.oo + self.od * inner.dob,
            od: self.oo * inner.od + self.od * inner.dd,
            dob: self.dob * inner.oo + self.dd * inner.dob,
            dd: self.dob * inner.od + self.dd * inner.dd,
        }
    }

    /// The completion that makes a vertex's Jacobian invertible without changing what it does to
    /// a ray moved along its manifold: A maps perturbations of the incoming ray with δo ⊥
    /// `prev_normal` (the plane the ray leaves; the camera ray's own direction for the first) and
    /// δd ⊥ `d` onto those of the outgoing ray (δx ⊥ `ng`, δd′ ⊥ `d_out`), and is singular in
    /// the other two directions (the origin along the ray, the direction's length). Adding
    /// (ng, 0)⊗(prev_normal, 0) + (0, d_out)⊗(0, d) maps those two onto the two the vertex cannot
    /// reach and is zero on the manifold, so products of completed factors act on manifold
    /// perturbations exactly as the factors do, and their inverses exist wherever the ray does
    /// not leave its previous surface at a grazing angle (ALGORITHMS.md §9's regularisation
    /// without noise: the attached estimator stays exact and adds no variance).
    pub fn completed(&self, prev_normal: Vec3, d: Vec3, ng: Vec3, d_out: Vec3) -> Jac6 {
        Jac6 { oo: self.oo + outer(ng, prev_normal), od: self.od, dob: self.dob, dd: self.dd + outer(d_out, d) }
    }

    /// `self + y·I`: the regularised factor Ã of the supplemental's §2.
    pub fn plus_identity(&self, y: f32) -> Jac6 {
        let yi = Mat3::from_diagonal(Vec3::splat(y));
        Jac6 { oo: self.oo + yi, od: self.od, dob: self.dob, dd: self.dd + yi }
    }

    /// `self + y·R` in the direction block, R = t_out⊗t_in + b_out⊗b_in mapping the plane across
    /// `d` onto the plane across `d_out` (the tangents of their [`crate::sampling::Frame`]s):
    /// the regularisation of a vertex whose outgoing direction ignores the incoming one. A
    /// diffuse vertex's completed direction block is d_out⊗d (plus the normal's variation), so
    /// the derivative of what follows it by the outgoing direction reaches Γ only through Y;
    /// with |Y| ≥ amplitude/2 the block stays invertible with condition ≤ 2/amplitude, and
    /// a zero-mean Y keeps the expectation of Ã equal to A (ALGORITHMS.md §9's claim (1)).
    pub fn plus_direction_noise(&self, y: f32, d: Vec3, d_out: Vec3) -> Jac6 {
        let (fi, fo) = (crate::sampling::Frame::from_normal(d), crate::sampling::Frame::from_normal(d_out));
        Jac6 { dd: self.dd + y * (outer(fo.t, fi.t) + outer(fo.b, fi.b)), ..*self }
    }

    /// The row x with x·self = b (block elimination on the transposed system: the origin block
    /// first, then its Schur complement), or `None` where a block is singular or the result is
    /// not finite.
    pub fn solve_row(&self, b: Row6) -> Option<Row6> {
        let (a, bb, c, d) = (self.oo.transpose(), self.dob.transpose(), self.od.transpose(), self.dd.transpose());
        if a.determinant() == 0.0 {
            return None;
        }
        let a_inv = a.inverse();
        let s = d - c * a_inv * bb;
        if s.determinant() == 0.0 {
            return None;
        }
        let x_d = s.inverse() * (b.d - c * (a_inv * b.o));
        let x_o = a_inv * (b.o - bb * x_d);
        let x = Row6 { o: x_o, d: x_d };
        x.is_finite().then_some(x)
    }
}

/// The regularisation scalar Y of one vertex from its uniforms: magnitude uniform in
/// [amplitude/2, amplitude], sign from `u_sign` — zero mean, and |Y| bounded away from 0 so that
/// a vertex whose own Jacobian is singular (a plane's hit point, a unit direction) keeps
/// Ã = A + Y·I invertible with condition bounded by 2/amplitude in those directions.
pub fn regularisation(amplitude: f32, u_sign: f32, u_size: f32) -> f32 {
    let size = amplitude * (0.5 + 0.5 * u_size);
    if u_sign < 0.5 { -size } else { size }
}

/// The parameters only attached sampling differentiates: the `eta` of every smooth `dielectric`
/// and `thindielectric` and of every `roughdielectric` (detached gradients of them are 0: a
/// smooth one's η acts only through its directions, and pathgrad's detached rough-dielectric
/// derivatives leave η out).
pub fn attached_only_params(scene: &crate::scene::Scene) -> Vec<crate::params::ParamId> {
    scene
        .materials
        .iter()
        .filter_map(|m| match m {
            crate::scene::Material::Smooth { eta_param, kind, .. }
                if *kind != crate::bsdf::specular::SmoothKind::Conductor =>
            {
                *eta_param
            }
            crate::scene::Material::RoughDielectric { eta_param, .. } => *eta_param,
            _ => None,
        })
        .collect()
}

/// Where a ray meets a triangle, as the Jacobians need it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HitGeometry {
    /// Distance along the (unit) direction.
    pub t: f32,
    /// The incoming direction.
    pub d: Vec3,
    /// The triangle's geometric normal (the plane the hit point moves in).
    pub ng: Vec3,
    /// The shading normal the BSDF used (flipped where a two-sided material is seen from behind).
    pub n: Vec3,
    /// ∂n/∂x along the triangle (zero for a flat-shaded one).
    pub dn_dx: Mat3,
}

impl HitGeometry {
    /// P = I − d·ngᵀ/(d·ng): ∂x/∂o (and ∂x/∂d = t·P) for a hit point x = o + t·d on a plane.
    pub fn projection(&self) -> Mat3 {
        let denom = self.d.dot(self.ng);
        Mat3::IDENTITY - outer(self.d, self.ng / denom)
    }

    /// ∂cos θi/∂r with cos θi = −d·n: the incoming cosine's row over the ray that reaches the hit.
    pub fn cos_row(&self) -> Row6 {
        let p = self.projection();
        // δcos = −(n·δd + d·N·δx), δx = P·δo + t·P·δd.
        let w = p.transpose() * (self.dn_dx.transpose() * self.d);
        Row6 { o: -w, d: -(self.n + self.t * w) }
    }

    /// The vertex's Jacobian A = ∂(x, d′)/∂(o, d) for an outgoing direction d′ = T(d, n) whose
    /// derivatives are `t_d` = ∂T/∂d and `t_n` = ∂T/∂n.
    pub fn jacobian(&self, t_d: Mat3, t_n: Mat3) -> Jac6 {
        let p = self.projection();
        let np = t_n * self.dn_dx * p;
        Jac6 { oo: p, od: self.t * p, dob: np, dd: t_d + self.t * np }
    }
}

/// u·vᵀ.
pub fn outer(u: Vec3, v: Vec3) -> Mat3 {
    Mat3::from_cols(u * v.x, u * v.y, u * v.z)
}

/// ∂n/∂x of the normalised interpolation of vertex normals `normals` over the triangle
/// `v` (along its plane), at the unnormalised interpolated normal `n_raw`.
pub fn normal_derivative(v: [Vec3; 3], normals: [Vec3; 3], n_raw: Vec3) -> Mat3 {
    let (grad_b1, grad_b2) = barycentric_gradients(v);
    let len = n_raw.length();
    if (grad_b1 == Vec3::ZERO && grad_b2 == Vec3::ZERO) || len == 0.0 {
        return Mat3::ZERO;
    }
    let raw = outer(normals[1] - normals[0], grad_b1) + outer(normals[2] - normals[0], grad_b2);
    let n = n_raw / len;
    (Mat3::IDENTITY - outer(n, n)) * raw / len
}

/// ∇b1 and ∇b2 along the triangle `v`: the barycentric coordinates' gradients in its plane (the
/// dual basis of its edges v1 − v0, v2 − v0); zero for a degenerate one.
pub fn barycentric_gradients(v: [Vec3; 3]) -> (Vec3, Vec3) {
    let (e0, e1) = (v[1] - v[0], v[2] - v[0]);
    let (g00, g01, g11) = (e0.dot(e0), e0.dot(e1), e1.dot(e1));
    let det = g00 * g11 - g01 * g01;
    if det == 0.0 {
        return (Vec3::ZERO, Vec3::ZERO);
    }
    ((g11 * e0 - g01 * e1) / det, (g00 * e1 - g01 * e0) / det)
}

/// ∂/∂d and ∂/∂n of the mirror direction d′ = d − 2(d·n)n.
pub fn reflect_jacobians(d: Vec3, n: Vec3) -> (Mat3, Mat3) {
    let t_d = Mat3::IDENTITY - 2.0 * outer(n, n);
    let t_n = -2.0 * (outer(n, d) + Mat3::from_diagonal(Vec3::splat(d.dot(n))));
    (t_d, t_n)
}

/// The direction refracted from incoming direction `d` at normal `n` (cos θi = −d·n, either
/// side) with index ratio η_ti (`eta_ti`), and its derivatives ∂/∂d, ∂/∂n and ∂/∂η_ti:
/// d′ = η_ti·d + (cos θt + η_ti·cos θi)·n with cos θt = −sign(cos θi)·√(1 − η_ti²(1 − cos² θi)).
/// `None` under total internal reflection.
pub fn refract_jacobians(d: Vec3, n: Vec3, eta_ti: f32) -> Option<(Vec3, Mat3, Mat3, Vec3)> {
    let c = -d.dot(n);
    let root2 = 1.0 - eta_ti * eta_ti * (1.0 - c * c);
    if !(root2 > 0.0) {
        return None;
    }
    let root = root2.sqrt();
    let sign = if c >= 0.0 { 1.0 } else { -1.0 };
    let cos_t = -sign * root;
    let dct_dc = -sign * eta_ti * eta_ti * c / root;
    let dct_deta = sign * eta_ti * (1.0 - c * c) / root;
    let out = eta_ti * d + (cos_t + eta_ti * c) * n;
    // ∂c/∂d = −n, ∂c/∂n = −d.
    let k = dct_dc + eta_ti;
    let t_d = eta_ti * Mat3::IDENTITY - k * outer(n, n);
    let t_n = (cos_t + eta_ti * c) * Mat3::IDENTITY - k * outer(n, d);
    let t_eta = d + (dct_deta + c) * n;
    Some((out, t_d, t_n, t_eta))
}

/// Mitsuba's dielectric Fresnel reflectance ([`crate::bsdf::rough_plastic::fresnel_dielectric`])
/// and its derivatives by cos θi and by η (inside over outside): (F, ∂F/∂cos θi, ∂F/∂η), zero
/// derivatives under total internal reflection and at η = 1.
pub fn fresnel_dielectric_grad(cos_i: f32, eta: f32) -> (f32, f32, f32) {
    let (r, _, _) = crate::bsdf::rough_plastic::fresnel_dielectric(cos_i, eta);
    let outside = cos_i >= 0.0;
    // e = η_it; de/dη.
    let (e, de_deta) = if outside { (eta, 1.0) } else { (1.0 / eta, -1.0 / (eta * eta)) };
    let c = cos_i.abs();
    let ct2 = 1.0 - (1.0 - c * c) / (e * e);
    if eta == 1.0 || c == 0.0 || !(ct2 > 0.0) {
        return (r, 0.0, 0.0);
    }
    let ct = ct2.sqrt();
    let dct_dc = c / (e * e * ct);
    let dct_de = (1.0 - c * c) / (e * e * e * ct);
    // a_s = (c − e·ct)/(c + e·ct), a_p = (ct − e·c)/(ct + e·c).
    let quotient = |n: f32, d: f32, dn: f32, dd: f32| (n / d, (dn * d - n * dd) / (d * d));
    let (a_s, das_dc) = quotient(c - e * ct, c + e * ct, 1.0 - e * dct_dc, 1.0 + e * dct_dc);
    let (_, das_de) = quotient(c - e * ct, c + e * ct, -ct - e * dct_de, ct + e * dct_de);
    let (a_p, dap_dc) = quotient(ct - e * c, ct + e * c, dct_dc - e, dct_dc + e);
    let (_, dap_de) = quotient(ct - e * c, ct + e * c, dct_de - c, dct_de + c);
    let dr_dc = a_s * das_dc + a_p * dap_dc;
    let dr_de = a_s * das_de + a_p * dap_de;
    let sign = if outside { 1.0 } else { -1.0 };
    (r, sign * dr_dc, dr_de * de_deta)
}

/// What a smooth vertex's sampled lobe contributes to the attached estimator, in world space:
/// the outgoing direction's derivatives by the incoming direction, the normal and η, and the
/// derivatives of the log of the lobe's weight by cos θi and by η (per image channel).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SmoothLobe {
    /// ∂d′/∂d.
    pub t_d: Mat3,
    /// ∂d′/∂n.
    pub t_n: Mat3,
    /// ∂d′/∂η (zero for a mirror and for a thin sheet's straight transmission).
    pub t_eta: Vec3,
    /// ∂ ln w/∂cos θi, w the weight value/pdf of the lobe with its choice probability attached.
    pub dlnw_dcos: Vec3,
    /// ∂ ln w/∂η.
    pub dlnw_deta: Vec3,
}

/// Mitsuba's conductor Fresnel reflectance ([`crate::bsdf::rough_conductor::fresnel_conductor`])
/// and its derivative by cos θi, per channel.
pub fn fresnel_conductor_grad(c: f32, eta: Vec3, k: Vec3) -> (Vec3, Vec3) {
    let f = crate::bsdf::rough_conductor::fresnel_conductor(c, eta, k);
    let mut df = Vec3::ZERO;
    for ch in 0..3 {
        let (e, kk) = (eta[ch], k[ch]);
        let (c2, s2) = (c * c, 1.0 - c * c);
        let s4 = s2 * s2;
        let (ds2, ds4) = (-2.0 * c, -4.0 * c * s2);
        let t1 = e * e - kk * kk - s2;
        let dt1 = -ds2;
        let q = (t1 * t1 + 4.0 * e * e * kk * kk).sqrt();
        let dq = if q > 0.0 { t1 * dt1 / q } else { 0.0 };
        let a = ((q + t1) * 0.5).max(0.0).sqrt();
        let da = if a > 0.0 { (dq + dt1) / (4.0 * a) } else { 0.0 };
        let (n, d) = (q + c2 - 2.0 * c * a, q + c2 + 2.0 * c * a);
        let (dn, dd) = (dq + 2.0 * c - 2.0 * a - 2.0 * c * da, dq + 2.0 * c + 2.0 * a + 2.0 * c * da);
        let rs = n / d;
        let drs = (dn * d - n * dd) / (d * d);
        let cross = a * s2 + c * da * s2 + c * a * ds2;
        let (m, e2) = (q * c2 + s4 - 2.0 * c * a * s2, q * c2 + s4 + 2.0 * c * a * s2);
        let (dm, de2) = (dq * c2 + 2.0 * q * c + ds4 - 2.0 * cross, dq * c2 + 2.0 * q * c + ds4 + 2.0 * cross);
        let r = m / e2;
        let dr = (dm * e2 - m * de2) / (e2 * e2);
        df[ch] = 0.5 * (drs + drs * r + rs * dr);
    }
    (f, df)
}

/// The attached derivatives of a smooth `conductor`'s mirror lobe sampled from incoming
/// direction `d` at normal `n`: its weight is F_conductor(cos θi)·s, whose log's derivative by
/// cos θi is per channel; its direction depends on no parameter.
pub fn conductor_lobe(d: Vec3, n: Vec3, eta: Vec3, k: Vec3) -> Option<SmoothLobe> {
    let cos_i = -d.dot(n);
    let (f, df) = fresnel_conductor_grad(cos_i, eta, k);
    if !(cos_i > 0.0) || !(f.min_element() > 0.0) {
        return None;
    }
    let (t_d, t_n) = reflect_jacobians(d, n);
    Some(SmoothLobe { t_d, t_n, t_eta: Vec3::ZERO, dlnw_dcos: df / f, dlnw_deta: Vec3::ZERO })
}

/// The attached derivatives of a smooth `dielectric` (`thin` false) or `thindielectric` lobe
/// sampled from incoming direction `d` at shading normal `n` with index ratio `eta` (inside over
/// outside): reflected or (`transmitted`) refracted. The lobe's choice probability (F, or 1 − F)
/// is attached in the weight's numerator, as PRB's detached weights are, so ∂ ln w carries
/// ∂ ln F (or ∂ ln(1 − F)); a refracted lobe's radiance factor η_ti² adds 2·∂ ln η_ti/∂η.
/// `None` where the lobe cannot have been sampled (zero probability, total internal reflection).
pub fn smooth_lobe(thin: bool, d: Vec3, n: Vec3, eta: f32, transmitted: bool) -> Option<SmoothLobe> {
    let cos_i = -d.dot(n);
    if thin {
        // R′ = 2R/(1 + R) of R = F(|cos θi|).
        let sign = if cos_i >= 0.0 { 1.0 } else { -1.0 };
        let (r, dr_dc, dr_deta) = fresnel_dielectric_grad(cos_i.abs(), eta);
        let r2 = 2.0 * r / (1.0 + r);
        let g = 2.0 / ((1.0 + r) * (1.0 + r));
        let (p, sgn) = if transmitted { (1.0 - r2, -1.0) } else { (r2, 1.0) };
        if !(p > 0.0) {
            return None;
        }
        let (t_d, t_n) = if transmitted { (Mat3::IDENTITY, Mat3::ZERO) } else { reflect_jacobians(d, n) };
        return Some(SmoothLobe {
            t_d,
            t_n,
            t_eta: Vec3::ZERO,
            dlnw_dcos: Vec3::splat(sgn * g * dr_dc * sign / p),
            dlnw_deta: Vec3::splat(sgn * g * dr_deta / p),
        });
    }
    let (f, df_dc, df_deta) = fresnel_dielectric_grad(cos_i, eta);
    if !transmitted {
        if !(f > 0.0) {
            return None;
        }
        let (t_d, t_n) = reflect_jacobians(d, n);
        return Some(SmoothLobe {
            t_d,
            t_n,
            t_eta: Vec3::ZERO,
            dlnw_dcos: Vec3::splat(df_dc / f),
            dlnw_deta: Vec3::splat(df_deta / f),
        });
    }
    if !(f < 1.0) {
        return None;
    }
    let outside = cos_i >= 0.0;
    let (eta_ti, deta_ti) = if outside { (1.0 / eta, -1.0 / (eta * eta)) } else { (eta, 1.0) };
    let (_, t_d, t_n, t_eta_ti) = refract_jacobians(d, n, eta_ti)?;
    Some(SmoothLobe {
        t_d,
        t_n,
        t_eta: t_eta_ti * deta_ti,
        dlnw_dcos: Vec3::splat(-df_dc / (1.0 - f)),
        dlnw_deta: Vec3::splat(-df_deta / (1.0 - f) + 2.0 * deta_ti / eta_ti),
    })
}

/// Duff et al.'s orthonormal basis (t, b) around the unit normal `n` and their derivatives by
/// n's three components, (∂t/∂n, ∂b/∂n): the frame a rough vertex samples its microfacet normal
/// in under attached sampling (the frame moves with n, so the sample does too).
pub fn basis_jacobians(n: Vec3) -> (Vec3, Vec3, Mat3, Mat3) {
    let s = if n.z >= 0.0 { 1.0 } else { -1.0 };
    let a = -1.0 / (s + n.z);
    let b = n.x * n.y * a;
    let t = Vec3::new(1.0 + s * n.x * n.x * a, s * b, -s * n.x);
    let bv = Vec3::new(b, s + n.y * n.y * a, -n.y);
    // ∂a/∂n = (0, 0, a²); ∂b/∂n = (y·a, x·a, x·y·a²). Rows are the gradients of the components.
    let db = Vec3::new(n.y * a, n.x * a, n.x * n.y * a * a);
    let t_n =
        Mat3::from_cols(Vec3::new(2.0 * s * n.x * a, 0.0, s * n.x * n.x * a * a), s * db, Vec3::new(-s, 0.0, 0.0))
            .transpose();
    let b_n =
        Mat3::from_cols(db, Vec3::new(0.0, 2.0 * n.y * a, n.y * n.y * a * a), Vec3::new(0.0, -1.0, 0.0)).transpose();
    (t, bv, t_n, b_n)
}

/// ∂d′/∂n of a diffuse vertex's outgoing direction d′ = x·t(n) + y·b(n) + z·n, the cosine
/// sample `local` = (x, y, z) in the frame of [`basis_jacobians`] around the shading normal `n`
/// (the frame [`crate::sampling::Frame::from_normal`] builds). It ignores the incoming direction
/// (∂d′/∂d = 0); its weight, the albedo, depends on the ray only through the hit point where it is
/// textured (`crate::cpu::slope`).
pub fn diffuse_direction_jacobian(n: Vec3, local: Vec3) -> Mat3 {
    let (_, _, t_n, b_n) = basis_jacobians(n);
    local.x * t_n + local.y * b_n + Mat3::from_diagonal(Vec3::splat(local.z))
}

/// The slope length factor g(u) of sampling D(h)·cos θh: tan θh = α·g(u) — GGX
/// g = √(u/(1 − u)), Beckmann g = √(−ln(1 − u)).
fn slope_factor(beckmann: bool, u: f32) -> f32 {
    let u = u.min(1.0 - 1e-7);
    if beckmann { (-(1.0 - u).ln()).max(0.0).sqrt() } else { (u / (1.0 - u)).sqrt() }
}

/// ln G1 and its derivative by s² = α² tan² θ (Smith, isotropic; as
/// [`crate::bsdf::rough_conductor::microfacet_g1`]).
fn ln_g1(beckmann: bool, s2: f32) -> (f32, f32) {
    if !(s2 > 0.0) {
        return (0.0, 0.0);
    }
    if beckmann {
        // G1 = 1/(1 + Λ(a)), a = 1/s: dΛ/da = −e^{−a²}/(2a²√π), da/ds² = −a/(2s²).
        let sqrt_pi = std::f32::consts::PI.sqrt();
        let a = 1.0 / s2.sqrt();
        let lambda = 0.5 * (crate::sampling::erf_approx(a) - 1.0) + (-a * a).exp() / (2.0 * a * sqrt_pi);
        let g1 = 1.0 / (1.0 + lambda);
        (g1.ln(), -g1 * (-a * a).exp() / (4.0 * a * s2 * sqrt_pi))
    } else {
        let root = (1.0 + s2).sqrt();
        ((2.0 / (1.0 + root)).ln(), -1.0 / (2.0 * root * (1.0 + root)))
    }
}

/// What a rough conductor's vertex contributes to the attached estimator: its microfacet normal is
/// sampled from D(h)·cos θh (not from the visible normals: this sampler's normal depends on the
/// incoming direction only through the frame, so its Jacobians stay short) in the frame of
/// [`basis_jacobians`], and the outgoing direction is the mirror of d about it. The weight is
/// w = F(c)·G1(cos θi)·G1(cos θo)·c/(cos θi·cos θh), c = −d·h (D cancels); rows of ln w are
/// split into a part common to the channels and F′/F (per channel) times the rows of c.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RoughLobe {
    /// The outgoing direction (world space).
    pub wo: Vec3,
    /// The weight w per channel, without the specular reflectance.
    pub weight: Vec3,
    /// The density of `wo` (solid angle): D(h)·cos θh/(4c).
    pub pdf: f32,
    /// ∂d′/∂d.
    pub t_d: Mat3,
    /// ∂d′/∂n.
    pub t_n: Mat3,
    /// ∂d′/∂α.
    pub t_alpha: Vec3,
    /// ∂ ln w/∂d, ∂ ln w/∂n and ∂ ln w/∂α without the Fresnel factor's part.
    pub dlnw_dd: Vec3,
    /// See `dlnw_dd`.
    pub dlnw_dn: Vec3,
    /// See `dlnw_dd`.
    pub dlnw_dalpha: f32,
    /// ∂c/∂d, ∂c/∂n and ∂c/∂α.
    pub dc_dd: Vec3,
    /// See `dc_dd`.
    pub dc_dn: Vec3,
    /// See `dc_dd`.
    pub dc_dalpha: f32,
    /// F′(c)/F(c) per channel.
    pub dlnf_dc: Vec3,
}

/// An attached lobe's microfacet normal: `u` mapped through the α-scaled slope distribution
/// (`slope_factor`) to a normal about `n`, with its derivatives by `n` and by α. Shared by
/// [`rough_conductor_lobe`] and [`rough_dielectric_lobe`].
pub(crate) struct MicroNormal {
    /// The normal in world space.
    pub h: Vec3,
    /// The normal in `n`'s frame (z along `n`).
    pub local: Vec3,
    /// ∂`local`/∂α.
    pub local_alpha: Vec3,
    /// ∂h/∂n.
    pub h_n: Mat3,
    /// ∂h/∂α.
    pub h_alpha: Vec3,
}

/// [`MicroNormal`] for the uniforms `u` about the unit normal `n`.
pub(crate) fn micro_normal(n: Vec3, alpha: f32, beckmann: bool, u: [f32; 2]) -> MicroNormal {
    let (t, b, t_n, b_n) = basis_jacobians(n);
    let g = slope_factor(beckmann, u[0]);
    let phi = 2.0 * std::f32::consts::PI * u[1];
    let (sin_p, cos_p) = phi.sin_cos();
    let m = Vec3::new(alpha * g * cos_p, alpha * g * sin_p, 1.0);
    let len = m.length();
    let hl = m / len;
    let dm = Vec3::new(g * cos_p, g * sin_p, 0.0);
    let dhl = (dm - hl * hl.dot(dm)) / len;
    MicroNormal {
        h: hl.x * t + hl.y * b + hl.z * n,
        local: hl,
        local_alpha: dhl,
        h_n: hl.x * t_n + hl.y * b_n + Mat3::from_diagonal(Vec3::splat(hl.z)),
        h_alpha: dhl.x * t + dhl.y * b + dhl.z * n,
    }
}

/// ln(G1(θi)·G1(θo)), Smith's masking of both directions at roughness α, and its derivatives by
/// cos θi, by cos θo and by α.
pub(crate) fn ln_masking(beckmann: bool, alpha: f32, ci: f32, co: f32) -> (f32, f32, f32, f32) {
    let tan2 = |cos: f32| (1.0 - cos * cos).max(0.0) / (cos * cos);
    let (lg_i, dg_i) = ln_g1(beckmann, alpha * alpha * tan2(ci));
    let (lg_o, dg_o) = ln_g1(beckmann, alpha * alpha * tan2(co));
    // ∂ ln G1/∂cos = ∂ ln G1/∂s² · α²·(−2/cos³); ∂ ln G1/∂α = ∂ ln G1/∂s² · 2α tan².
    let (gi_c, go_c) = (dg_i * alpha * alpha * -2.0 / (ci * ci * ci), dg_o * alpha * alpha * -2.0 / (co * co * co));
    let g_alpha = dg_i * 2.0 * alpha * tan2(ci) + dg_o * 2.0 * alpha * tan2(co);
    (lg_i + lg_o, gi_c, go_c, g_alpha)
}

/// The attached rough-conductor lobe from incoming direction `d` at shading normal `n` (the side
/// the ray arrives on), roughness `alpha` (GGX, or Beckmann with `beckmann`), uniforms `u` and the
/// conductor's complex index (`eta`, `k`); `None` where the sample leaves below the surface or
/// weighs nothing.
pub fn rough_conductor_lobe(
    d: Vec3,
    n: Vec3,
    alpha: f32,
    beckmann: bool,
    u: [f32; 2],
    eta: Vec3,
    k: Vec3,
) -> Option<RoughLobe> {
    let ci = -d.dot(n);
    if !(ci > 0.0) || !(alpha > 0.0) {
        return None;
    }
    let MicroNormal { h, local: hl, local_alpha: dhl, h_n: hn, h_alpha } = micro_normal(n, alpha, beckmann, u);
    let c = -d.dot(h);
    let wo = d + 2.0 * c * h;
    let co = wo.dot(n);
    if !(c > 0.0) || !(co > 0.0) {
        return None;
    }
    let (f, df) = fresnel_conductor_grad(c, eta, k);
    if !(f.min_element() > 0.0) {
        return None;
    }
    let (ln_g, gi_c, go_c, g_alpha) = ln_masking(beckmann, alpha, ci, co);
    let hz = hl.z;
    let weight = f * (ln_g.exp() * c / (ci * hz));
    // c = −d·h: dc = −h·δd − d·δh; δh = Hn·δn + h_α·δα.
    let dc_dd = -h;
    let dc_dn = -(hn.transpose() * d);
    let dc_dalpha = -d.dot(h_alpha);
    // wo = d + 2c·h.
    let t_d = Mat3::IDENTITY - 2.0 * outer(h, h);
    let t_n = 2.0 * outer(h, dc_dn) + 2.0 * c * hn;
    let t_alpha = 2.0 * dc_dalpha * h + 2.0 * c * h_alpha;
    // cos θi = −d·n; cos θo = wo·n.
    let (ci_d, ci_n) = (-n, -d);
    let (co_d, co_n, co_alpha) = (t_d.transpose() * n, t_n.transpose() * n + wo, n.dot(t_alpha));
    let dhz_dalpha = dhl.z;
    let dlnw_dd = dc_dd / c + gi_c * ci_d + go_c * co_d - ci_d / ci;
    let dlnw_dn = dc_dn / c + gi_c * ci_n + go_c * co_n - ci_n / ci;
    let dlnw_dalpha = dc_dalpha / c + go_c * co_alpha + g_alpha - dhz_dalpha / hz;
    let d_pdf = match beckmann {
        true => crate::contract::Distribution::Beckmann,
        false => crate::contract::Distribution::Ggx,
    };
    let pdf = crate::bsdf::rough_conductor::microfacet_d(d_pdf, alpha, hl) * hz / (4.0 * c);
    Some(RoughLobe {
        wo,
        weight,
        pdf,
        t_d,
        t_n,
        t_alpha,
        dlnw_dd,
        dlnw_dn,
        dlnw_dalpha,
        dc_dd,
        dc_dn,
        dc_dalpha,
        dlnf_dc: df / f,
    })
}

impl HitGeometry {
    /// The row over the ray reaching the hit of a quantity whose gradient along the surface, by
    /// the hit point, is `g`: δx = P·δo + t·P·δd.
    pub fn position_row(&self, g: Vec3) -> Row6 {
        let w = self.projection().transpose() * g;
        Row6 { o: w, d: self.t * w }
    }

    /// The row over the incoming ray of a quantity whose derivatives by the incoming direction
    /// and by the shading normal are `by_d` and `by_n` (the normal moves with the hit point).
    pub fn row(&self, by_d: Vec3, by_n: Vec3) -> Row6 {
        let w = self.projection().transpose() * (self.dn_dx.transpose() * by_n);
        Row6 { o: w, d: by_d + self.t * w }
    }

    /// At an emitter's hit after a diffuse vertex that estimated next events: the row over the
    /// ray that reaches it of ln w_b, its MIS weight w_b = p_f²/(p_f² + p_e²) (`w_b`), where the
    /// cosine sample's density p_f stays fixed and p_e moves: −2(1 − w_b)·∂ln p_e.
    pub fn emitter_mis_row(&self, w_b: f32) -> Row6 {
        let r = self.emitter_density_row();
        Row6 { o: r.o * (-2.0 * (1.0 - w_b)), d: r.d * (-2.0 * (1.0 - w_b)) }
    }

    /// At an emitter's hit: the row over the ray that reaches it of ln p_e, the solid-angle
    /// density with which next-event estimation samples the hit point (p_e ∝ t²/cos θe, the
    /// emitter flat): ∂ln p_e/∂o = −2·ng/(t·d·ng), ∂ln p_e/∂d = −3·ng/(d·ng).
    pub fn emitter_density_row(&self) -> Row6 {
        let dn = self.d.dot(self.ng);
        Row6 { o: self.ng * (-2.0 / (self.t * dn)), d: self.ng * (-3.0 / dn) }
    }

    /// Next-event estimation at a diffuse vertex, an area emitter's point y held fixed: the
    /// gradient by the hit point x of ln(cos θo/p_e)·(2w − 1), the share of the contribution
    /// a·cos θo·L_e·w/(π·p_e) that moves with x, where `wl` = (y − x)/`dist`, `light_normal` is
    /// y's, cos θo = n·wl with the shading normal n moving with x, p_e ∝ dist²/cos θy and
    /// w = p_e²/(p_e² + p_f²) the power heuristic against the cosine sample (p_f = cos θo/π):
    /// ∂ln w = 2(1 − w)(∂ln p_e − ∂ln cos θo). (Pass it to [`HitGeometry::position_row`].)
    pub fn nee_gradient(&self, wl: Vec3, dist: f32, light_normal: Vec3, w: f32) -> Vec3 {
        let cos_y = -light_normal.dot(wl);
        let dln_p_e = -2.0 * wl / dist - (light_normal + cos_y * wl) / (dist * cos_y);
        (2.0 * w - 1.0) * (self.ln_cos_gradient(wl, 1.0 / dist) - dln_p_e)
    }

    /// Next-event estimation at a diffuse vertex toward a light without area: the gradient by
    /// the hit point x of ln(cos θo/dist²) for a point light at distance 1/`inv_dist` along `wl`,
    /// or (`inv_dist` = 0) of ln cos θo for a directional light, whose `wl` stays fixed.
    pub fn delta_light_gradient(&self, wl: Vec3, inv_dist: f32) -> Vec3 {
        self.ln_cos_gradient(wl, inv_dist) + 2.0 * inv_dist * wl
    }

    /// ∂ln cos θo/∂x, cos θo = n·wl, for wl toward a fixed point at distance 1/`inv_dist` (0: a
    /// fixed direction): ∂wl/∂x = −(I − wl·wlᵀ)·`inv_dist`, and n turns with x.
    fn ln_cos_gradient(&self, wl: Vec3, inv_dist: f32) -> Vec3 {
        let cos_o = self.n.dot(wl);
        (-(self.n - cos_o * wl) * inv_dist + self.dn_dx.transpose() * wl) / cos_o
    }
}

/// The parameters a gradient pass sampled as `sampling` differentiates, out of `chosen`.
///
/// Attached sampling differentiates every parameter. Detached sampling holds the sampled
/// directions fixed, so a parameter that acts only through them ([`attached_only_params`]: a
/// dielectric's index of refraction) has no detached derivative: it is an error when the
/// caller named it (`named`: the ids asked for one by one, not through a wildcard or "all"), and
/// it is left out otherwise. The command line's `--param`, Python's `wrt` and the optimiser use it.
/// With attached sampling it logs a warning (once a process) when `chosen` holds a
/// `roughdielectric`'s η, whose attached derivative measured 1.5–3.1 % low against central
/// differences (BENCHMARKS.md).
///
/// ```
/// use pathgrad::integrator::Sampling;
/// // A glass sphere before a textured sky.
/// let scene = pathgrad::scene::load("tests/data/scenes/attached_sphere.xml", &[])?;
/// let eta = scene.params.find("glass.bsdf.eta").unwrap();
/// let all: Vec<_> = scene.params.select(&["*"])?;
/// // All of them, detached: the index of refraction is left out.
/// let detached = pathgrad::attached::differentiated(&scene, all.clone(), &[], Sampling::Detached)?;
/// assert!(!detached.contains(&eta) && detached.len() + 1 == all.len());
/// // Named, detached: an error that says what to do.
/// let e = pathgrad::attached::differentiated(&scene, vec![eta], &[eta], Sampling::Detached).unwrap_err();
/// assert!(e.to_string().contains("attached"));
/// // Attached: everything chosen.
/// assert_eq!(pathgrad::attached::differentiated(&scene, all.clone(), &[eta], Sampling::attached())?, all);
/// # Ok::<(), pathgrad::Error>(())
/// ```
///
/// # Errors
/// [`crate::Error::InvalidArgument`] naming the parameter, when `named` holds one that detached
/// sampling cannot differentiate.
pub fn differentiated(
    scene: &crate::scene::Scene,
    chosen: Vec<crate::params::ParamId>,
    named: &[crate::params::ParamId],
    sampling: Sampling,
) -> crate::Result<Vec<crate::params::ParamId>> {
    if sampling.is_attached() {
        let mut rough_eta = scene.materials.iter().filter_map(|m| match m {
            crate::scene::Material::RoughDielectric { eta_param, .. } => *eta_param,
            _ => None,
        });
        // Once a process: a frame loop calls this for every image gradient.
        static WARNED: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);
        if let Some(id) = rough_eta.find(|id| chosen.contains(id))
            && !WARNED.swap(true, std::sync::atomic::Ordering::Relaxed)
        {
            tracing::warn!(
                parameter = %scene.params.entry(id).name,
                "a rough dielectric's index of refraction under attached sampling: its derivative measured 1.5–3.1 % \
                 below central differences on a rough glass sphere, at 2.8–3.9 standard errors (BENCHMARKS.md, \
                 issue 34, 2026-12-08); the cause is not found"
            );
        }
        return Ok(chosen);
    }
    let only = attached_only_params(scene);
    if let Some(&id) = named.iter().find(|id| only.contains(id)) {
        return Err(crate::Error::InvalidArgument {
            parameter: scene.params.entry(id).name.clone(),
            message: "a dielectric's index of refraction, which detached sampling does not differentiate (a \
                      smooth dielectric's acts only through the directions it refracts into, which detached \
                      sampling holds fixed; pathgrad's detached derivative of a rough one leaves it out, \
                      where Mitsuba's includes it); differentiate it with --sampling attached (Python: \
                      sampling=\"attached\"; the library: Sampling::Attached)"
                .into(),
        });
    }
    Ok(chosen.into_iter().filter(|id| !only.contains(id)).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fd_vec(f: impl Fn(f32) -> Vec3, h: f32) -> Vec3 {
        (f(h) - f(-h)) / (2.0 * h)
    }

    /// Every derivative the rough lobe reports against central differences of the lobe itself
    /// (its direction and ln of its weight, Fresnel included per channel), by d, n and α, for both
    /// distributions; the basis's Jacobians likewise.
    #[test]
    fn rough_lobe_derivatives_match_finite_differences() {
        let (eta, k) = (Vec3::new(0.2, 0.9, 1.1), Vec3::new(3.9, 2.4, 2.2));
        let n0 = Vec3::new(0.15, -0.25, 0.95).normalize();
        let d0 = Vec3::new(0.35, 0.2, -0.9).normalize();
        let mut checked = 0;
        for beckmann in [false, true] {
            for &alpha in &[0.05f32, 0.3] {
                for &u in &[[0.3f32, 0.2], [0.7, 0.6], [0.5, 0.9]] {
                    let Some(l) = rough_conductor_lobe(d0, n0, alpha, beckmann, u, eta, k) else { continue };
                    let lnw = |d: Vec3, n: Vec3, a: f32| {
                        rough_conductor_lobe(d, n, a, beckmann, u, eta, k).map(|x| x.weight.x.ln())
                    };
                    let wo =
                        |d: Vec3, n: Vec3, a: f32| rough_conductor_lobe(d, n, a, beckmann, u, eta, k).map(|x| x.wo);
                    let h = 2e-3f32;
                    let tol = |x: f32| 2e-2 * (1.0 + x.abs());
                    let total = |dd: Vec3, dn: Vec3| {
                        dd.dot(l.dlnw_dd + l.dlnf_dc.x * l.dc_dd) + dn.dot(l.dlnw_dn + l.dlnf_dc.x * l.dc_dn)
                    };
                    for axis in [Vec3::X, Vec3::Y, Vec3::Z] {
                        let (Some(p), Some(m)) = (lnw(d0 + h * axis, n0, alpha), lnw(d0 - h * axis, n0, alpha)) else {
                            continue;
                        };
                        let fd = (p - m) / (2.0 * h);
                        assert!(
                            (fd - total(axis, Vec3::ZERO)).abs() < tol(fd),
                            "∂ln w/∂d: {fd} vs {}",
                            total(axis, Vec3::ZERO)
                        );
                        let (Some(p), Some(m)) = (lnw(d0, n0 + h * axis, alpha), lnw(d0, n0 - h * axis, alpha)) else {
                            continue;
                        };
                        let fd = (p - m) / (2.0 * h);
                        assert!(
                            (fd - total(Vec3::ZERO, axis)).abs() < tol(fd),
                            "∂ln w/∂n: {fd} vs {}",
                            total(Vec3::ZERO, axis)
                        );
                        let fd_d =
                            (wo(d0 + h * axis, n0, alpha).unwrap() - wo(d0 - h * axis, n0, alpha).unwrap()) / (2.0 * h);
                        assert!((fd_d - l.t_d * axis).abs().max_element() < 2e-2, "∂d′/∂d: {fd_d} vs {}", l.t_d * axis);
                        let fd_n =
                            (wo(d0, n0 + h * axis, alpha).unwrap() - wo(d0, n0 - h * axis, alpha).unwrap()) / (2.0 * h);
                        assert!((fd_n - l.t_n * axis).abs().max_element() < 2e-2, "∂d′/∂n: {fd_n} vs {}", l.t_n * axis);
                    }
                    let ha = 1e-3 * alpha;
                    let fd = (lnw(d0, n0, alpha + ha).unwrap() - lnw(d0, n0, alpha - ha).unwrap()) / (2.0 * ha);
                    let ours = l.dlnw_dalpha + l.dlnf_dc.x * l.dc_dalpha;
                    assert!((fd - ours).abs() < tol(fd), "∂ln w/∂α ({beckmann}, α {alpha}): {fd} vs {ours}");
                    let fd = (wo(d0, n0, alpha + ha).unwrap() - wo(d0, n0, alpha - ha).unwrap()) / (2.0 * ha);
                    assert!(
                        (fd - l.t_alpha).abs().max_element() < 2e-2 * (1.0 + fd.length()),
                        "∂d′/∂α: {fd} vs {}",
                        l.t_alpha
                    );
                    checked += 1;
                }
            }
        }
        assert!(checked >= 8, "{checked} lobes checked");
        let (t, b, t_n, b_n) = basis_jacobians(n0);
        assert!(t.dot(b).abs() < 1e-6 && t.dot(n0).abs() < 1e-6 && b.dot(n0).abs() < 1e-6);
        for axis in [Vec3::X, Vec3::Y, Vec3::Z] {
            let h = 1e-3;
            let (tp, bp, _, _) = basis_jacobians(n0 + h * axis);
            let (tm, bm, _, _) = basis_jacobians(n0 - h * axis);
            assert!(((tp - tm) / (2.0 * h) - t_n * axis).abs().max_element() < 1e-3);
            assert!(((bp - bm) / (2.0 * h) - b_n * axis).abs().max_element() < 1e-3);
        }
    }

    /// The rough lobe's sampler draws D(h)·cos θh: its weight times its density is the BSDF's
    /// value times cos θo (Mitsuba's rough conductor, [`crate::bsdf::rough_conductor`]).
    #[test]
    fn rough_lobe_weight_is_value_over_density() {
        use crate::bsdf::rough_conductor::microfacet_eval;
        use crate::contract::Distribution;
        let (eta, k) = (Vec3::new(0.2, 0.9, 1.1), Vec3::new(3.9, 2.4, 2.2));
        let n = Vec3::Z;
        let d = Vec3::new(0.4, 0.1, -0.8).normalize();
        for (beckmann, dist) in [(false, Distribution::Ggx), (true, Distribution::Beckmann)] {
            for u in [[0.2f32, 0.3], [0.6, 0.1], [0.9, 0.8]] {
                let Some(l) = rough_conductor_lobe(d, n, 0.2, beckmann, u, eta, k) else { continue };
                let value = microfacet_eval(dist, glam::Vec2::splat(0.2), Vec3::ONE, eta, k, -d, l.wo);
                let ours = l.weight * l.pdf;
                assert!((ours - value).abs().max_element() < 1e-4 * (1.0 + value.max_element()), "{ours} vs {value}");
            }
        }
    }

    #[test]
    fn fresnel_derivatives_match_finite_differences() {
        use crate::bsdf::rough_plastic::fresnel_dielectric;
        for &eta in &[1.5f32, 1.33, 0.7] {
            for &c in &[0.9f32, 0.5, 0.2, -0.95, -0.8, -0.5] {
                let (f, dc, de) = fresnel_dielectric_grad(c, eta);
                if f >= 1.0 {
                    continue;
                }
                let h = 1e-3;
                let fd_c = (fresnel_dielectric(c + h, eta).0 - fresnel_dielectric(c - h, eta).0) / (2.0 * h);
                let fd_e = (fresnel_dielectric(c, eta + h).0 - fresnel_dielectric(c, eta - h).0) / (2.0 * h);
                assert!((fd_c - dc).abs() < 2e-3 * (1.0 + dc.abs()), "η {eta} cos {c}: ∂F/∂cos {dc} vs {fd_c}");
                assert!((fd_e - de).abs() < 2e-3 * (1.0 + de.abs()), "η {eta} cos {c}: ∂F/∂η {de} vs {fd_e}");
            }
        }
    }

    #[test]
    fn conductor_fresnel_derivative_matches_finite_differences() {
        use crate::bsdf::rough_conductor::fresnel_conductor;
        for (eta, k) in [(Vec3::new(0.2, 0.9, 1.1), Vec3::new(3.9, 2.4, 2.2)), (Vec3::new(1.5, 0.5, 2.5), Vec3::ZERO)] {
            for c in [0.95f32, 0.6, 0.3, 0.1] {
                let (_, df) = fresnel_conductor_grad(c, eta, k);
                let h = 1e-3;
                let fd = (fresnel_conductor(c + h, eta, k) - fresnel_conductor(c - h, eta, k)) / (2.0 * h);
                assert!((fd - df).abs().max_element() < 2e-3 * (1.0 + df.abs().max_element()), "cos {c}: {df} vs {fd}");
            }
        }
    }

    #[test]
    fn refraction_derivatives_match_finite_differences() {
        let n = Vec3::new(0.1, 0.2, 0.97).normalize();
        for &(d, eta_ti) in &[
            (Vec3::new(0.3, -0.2, -0.9).normalize(), 1.0 / 1.5),
            (Vec3::new(-0.2, 0.4, 0.9).normalize(), 1.5),
            (Vec3::new(0.5, 0.1, -0.8).normalize(), 1.0 / 1.33),
        ] {
            let (out, t_d, t_n, t_eta) = refract_jacobians(d, n, eta_ti).unwrap();
            // Snell: unit length, tangential part scaled by η_ti.
            assert!((out.length() - 1.0).abs() < 1e-5);
            let h = 1e-3;
            for axis in [Vec3::X, Vec3::Y, Vec3::Z] {
                let fd_d = fd_vec(|s| refract_jacobians(d + s * axis, n, eta_ti).unwrap().0, h);
                let fd_n = fd_vec(|s| refract_jacobians(d, n + s * axis, eta_ti).unwrap().0, h);
                assert!((fd_d - t_d * axis).abs().max_element() < 2e-3, "{fd_d} vs {}", t_d * axis);
                assert!((fd_n - t_n * axis).abs().max_element() < 2e-3, "{fd_n} vs {}", t_n * axis);
            }
            let fd_e = fd_vec(|s| refract_jacobians(d, n, eta_ti + s).unwrap().0, h);
            assert!((fd_e - t_eta).abs().max_element() < 2e-3, "{fd_e} vs {t_eta}");
            let (r_d, r_n) = reflect_jacobians(d, n);
            let mirror = |d: Vec3, n: Vec3| d - 2.0 * d.dot(n) * n;
            for axis in [Vec3::X, Vec3::Y, Vec3::Z] {
                let fd_d = fd_vec(|s| mirror(d + s * axis, n), h);
                let fd_n = fd_vec(|s| mirror(d, n + s * axis), h);
                assert!((fd_d - r_d * axis).abs().max_element() < 1e-3);
                assert!((fd_n - r_n * axis).abs().max_element() < 1e-3);
            }
        }
    }

    /// The vertex Jacobian of a curved (interpolated-normal) triangle against moving the
    /// incoming ray and recomputing the hit, the normal and the refracted direction.
    #[test]
    fn vertex_jacobian_matches_finite_differences() {
        let v = [Vec3::new(-1.0, -1.0, 0.0), Vec3::new(1.0, -1.0, 0.2), Vec3::new(0.0, 1.0, -0.1)];
        let normals = [Vec3::new(-0.3, -0.2, 1.0).normalize(), Vec3::new(0.3, -0.1, 1.0).normalize(), Vec3::Z];
        let ng = (v[1] - v[0]).cross(v[2] - v[0]).normalize();
        let eta_ti = 1.0 / 1.5;
        // The refracted ray leaving the hit of ray (o, d).
        let trace = |o: Vec3, d: Vec3| -> (Vec3, Vec3) {
            let t = (v[0] - o).dot(ng) / d.dot(ng);
            let x = o + t * d;
            // Barycentrics of x.
            let (e0, e1, p) = (v[1] - v[0], v[2] - v[0], x - v[0]);
            let (g00, g01, g11) = (e0.dot(e0), e0.dot(e1), e1.dot(e1));
            let det = g00 * g11 - g01 * g01;
            let (p0, p1) = (p.dot(e0), p.dot(e1));
            let b1 = (g11 * p0 - g01 * p1) / det;
            let b2 = (g00 * p1 - g01 * p0) / det;
            let n = ((1.0 - b1 - b2) * normals[0] + b1 * normals[1] + b2 * normals[2]).normalize();
            (x, refract_jacobians(d, n, eta_ti).unwrap().0)
        };
        let o = Vec3::new(0.1, 0.2, 2.0);
        let d = Vec3::new(0.05, -0.1, -1.0).normalize();
        let t = (v[0] - o).dot(ng) / d.dot(ng);
        let x = o + t * d;
        let (e0, e1, p) = (v[1] - v[0], v[2] - v[0], x - v[0]);
        let (g00, g01, g11) = (e0.dot(e0), e0.dot(e1), e1.dot(e1));
        let det = g00 * g11 - g01 * g01;
        let b1 = (g11 * p.dot(e0) - g01 * p.dot(e1)) / det;
        let b2 = (g00 * p.dot(e1) - g01 * p.dot(e0)) / det;
        let n_raw = (1.0 - b1 - b2) * normals[0] + b1 * normals[1] + b2 * normals[2];
        let n = n_raw.normalize();
        let geometry = HitGeometry { t, d, ng, n, dn_dx: normal_derivative(v, normals, n_raw) };
        let (_, t_d, t_n, _) = refract_jacobians(d, n, eta_ti).unwrap();
        let a = geometry.jacobian(t_d, t_n);
        let h = 1e-3;
        for axis in [Vec3::X, Vec3::Y, Vec3::Z] {
            let plus = trace(o + h * axis, d);
            let minus = trace(o - h * axis, d);
            let (fx, fd) = ((plus.0 - minus.0) / (2.0 * h), (plus.1 - minus.1) / (2.0 * h));
            assert!((fx - a.oo * axis).abs().max_element() < 2e-3, "∂x/∂o {fx} vs {}", a.oo * axis);
            assert!((fd - a.dob * axis).abs().max_element() < 2e-3, "∂d′/∂o {fd} vs {}", a.dob * axis);
            let plus = trace(o, d + h * axis);
            let minus = trace(o, d - h * axis);
            let (fx, fd) = ((plus.0 - minus.0) / (2.0 * h), (plus.1 - minus.1) / (2.0 * h));
            assert!((fx - a.od * axis).abs().max_element() < 4e-3, "∂x/∂d {fx} vs {}", a.od * axis);
            assert!((fd - a.dd * axis).abs().max_element() < 4e-3, "∂d′/∂d {fd} vs {}", a.dd * axis);
        }
        // The incoming cosine's row.
        let cos_at = |o: Vec3, d: Vec3| {
            let t = (v[0] - o).dot(ng) / d.dot(ng);
            let x = o + t * d;
            let (p0, p1) = ((x - v[0]).dot(e0), (x - v[0]).dot(e1));
            let b1 = (g11 * p0 - g01 * p1) / det;
            let b2 = (g00 * p1 - g01 * p0) / det;
            -d.dot(((1.0 - b1 - b2) * normals[0] + b1 * normals[1] + b2 * normals[2]).normalize())
        };
        let row = geometry.cos_row();
        for axis in [Vec3::X, Vec3::Y, Vec3::Z] {
            let fo = (cos_at(o + h * axis, d) - cos_at(o - h * axis, d)) / (2.0 * h);
            let fdd = (cos_at(o, d + h * axis) - cos_at(o, d - h * axis)) / (2.0 * h);
            assert!((fo - row.o.dot(axis)).abs() < 2e-3, "{fo} vs {}", row.o.dot(axis));
            assert!((fdd - row.d.dot(axis)).abs() < 2e-3, "{fdd} vs {}", row.d.dot(axis));
        }
    }

    /// Row solves undo row products exactly enough: x·(A + Y·I) then solve gives x back, for a
    /// singular A (a plane's projection) and |Y| ≥ amplitude/2.
    /// Next-event estimation's rows against finite differences: the log-density of a flat
    /// emitter's hit point along a moved ray (unit directions, moved across themselves), and
    /// ln(cos θo·w/p_e) at a point moving along a curved triangle toward a fixed light point;
    /// ln(cos θo/dist²) toward a point light and ln cos θo along a directional light's fixed
    /// direction there.
    #[test]
    fn next_event_rows_match_finite_differences() {
        // An emitter's plane through y0 with normal ng, hit by (o, d).
        let (y0, ng) = (Vec3::new(0.3, 2.0, -0.2), Vec3::new(0.2, -1.0, 0.3).normalize());
        let ln_density = |o: Vec3, d: Vec3| {
            let t = (y0 - o).dot(ng) / d.dot(ng);
            2.0 * t.ln() - (-ng.dot(d)).ln()
        };
        let o = Vec3::new(-0.4, 0.1, 0.2);
        let d = Vec3::new(0.3, 1.0, -0.1).normalize();
        let t = (y0 - o).dot(ng) / d.dot(ng);
        let row = HitGeometry { t, d, ng, n: ng, dn_dx: Mat3::ZERO }.emitter_density_row();
        let h = 1e-3;
        let (b1, b2) = (d.cross(Vec3::X).normalize(), d.cross(Vec3::Z).normalize());
        for axis in [Vec3::X, Vec3::Y, Vec3::Z] {
            let fd = (ln_density(o + h * axis, d) - ln_density(o - h * axis, d)) / (2.0 * h);
            assert!((fd - row.o.dot(axis)).abs() < 2e-3, "∂ln p_e/∂o {fd} vs {}", row.o.dot(axis));
        }
        for axis in [b1, b2] {
            let moved = |s: f32| ln_density(o, (d + s * axis).normalize());
            let fd = (moved(h) - moved(-h)) / (2.0 * h);
            assert!((fd - row.d.dot(axis)).abs() < 2e-3, "∂ln p_e/∂d {fd} vs {}", row.d.dot(axis));
        }
        // The emitter hit's MIS weight ln w_b, w_b = p_f²/(p_f² + p_e²), p_f fixed (w_b ≈ 0.04
        // here, so the row is nearly −2·∂ln p_e and a wrong factor shows).
        let p_f = 0.2 * ln_density(o, d).exp();
        let ln_w_b = |o: Vec3, d: Vec3| {
            let p_e = ln_density(o, d).exp();
            (p_f * p_f / (p_f * p_f + p_e * p_e)).ln()
        };
        let p_e = ln_density(o, d).exp();
        let w_b = p_f * p_f / (p_f * p_f + p_e * p_e);
        let mis = HitGeometry { t, d, ng, n: ng, dn_dx: Mat3::ZERO }.emitter_mis_row(w_b);
        for axis in [Vec3::X, Vec3::Y, Vec3::Z] {
            let fd = (ln_w_b(o + h * axis, d) - ln_w_b(o - h * axis, d)) / (2.0 * h);
            let ours = mis.o.dot(axis);
            assert!((fd - ours).abs() < 2e-3 * (1.0 + fd.abs()), "∂ln w_b/∂o {fd} vs {ours}");
        }
        for axis in [b1, b2] {
            let moved = |s: f32| ln_w_b(o, (d + s * axis).normalize());
            let fd = (moved(h) - moved(-h)) / (2.0 * h);
            let ours = mis.d.dot(axis);
            assert!(fd.abs() > 1e-2 && (fd - ours).abs() < 2e-3 * (1.0 + fd.abs()), "∂ln w_b/∂d {fd} vs {ours}");
        }

        // A curved triangle (interpolated normals) lit from a fixed point y with normal ny.
        let v = [Vec3::new(-1.0, -1.0, 0.0), Vec3::new(1.0, -1.0, 0.2), Vec3::new(0.0, 1.0, -0.1)];
        let normals = [Vec3::new(-0.3, -0.2, 1.0).normalize(), Vec3::new(0.3, -0.1, 1.0).normalize(), Vec3::Z];
        let (y, ny) = (Vec3::new(0.8, 0.3, 1.5), Vec3::new(-0.4, 0.0, -1.0).normalize());
        let (e0, e1) = (v[1] - v[0], v[2] - v[0]);
        let (g00, g01, g11) = (e0.dot(e0), e0.dot(e1), e1.dot(e1));
        let det = g00 * g11 - g01 * g01;
        let normal_raw = |x: Vec3| {
            let p = x - v[0];
            let b1 = (g11 * p.dot(e0) - g01 * p.dot(e1)) / det;
            let b2 = (g00 * p.dot(e1) - g01 * p.dot(e0)) / det;
            (1.0 - b1 - b2) * normals[0] + b1 * normals[1] + b2 * normals[2]
        };
        // `scale`: the selection probability over the emitter's area (1: w near 1; 0.1: w near 0.5).
        let ln_contribution = |x: Vec3, scale: f32| {
            let n = normal_raw(x).normalize();
            let dist = (y - x).length();
            let wl = (y - x) / dist;
            let (cos_o, cos_y) = (n.dot(wl), -ny.dot(wl));
            let (p_e, p_f) = (scale * dist * dist / cos_y, cos_o / std::f32::consts::PI);
            let w = p_e * p_e / (p_e * p_e + p_f * p_f);
            (cos_o * w / p_e).ln()
        };
        let x = v[0] + 0.3 * e0 + 0.4 * e1;
        let n_raw = normal_raw(x);
        let geometry = HitGeometry {
            t: 1.0,
            d: -n_raw.normalize(),
            ng: e0.cross(e1).normalize(),
            n: n_raw.normalize(),
            dn_dx: normal_derivative(v, normals, n_raw),
        };
        let dist = (y - x).length();
        let wl = (y - x) / dist;
        let p_f = geometry.n.dot(wl) / std::f32::consts::PI;
        for (scale, w_range) in [(1.0, 0.9..1.0), (0.1, 0.3..0.7)] {
            let p_e = scale * dist * dist / -ny.dot(wl);
            let w = p_e * p_e / (p_e * p_e + p_f * p_f);
            assert!(w_range.contains(&w), "w {w}");
            let g = geometry.nee_gradient(wl, dist, ny, w);
            for axis in [e0.normalize(), e1.normalize()] {
                let fd = (ln_contribution(x + h * axis, scale) - ln_contribution(x - h * axis, scale)) / (2.0 * h);
                let ours = g.dot(axis);
                assert!((fd - ours).abs() < 2e-3 * (1.0 + fd.abs()), "∂ln C/∂x at w {w}: {fd} vs {ours}");
            }
        }
        // A point light at y: ln(cos θo/dist²); a directional light along a fixed wl: ln cos θo.
        let ln_point = |x: Vec3| {
            let dist = (y - x).length();
            (normal_raw(x).normalize().dot((y - x) / dist) / (dist * dist)).ln()
        };
        let fixed = Vec3::new(0.3, -0.2, 1.0).normalize();
        let ln_directional = |x: Vec3| normal_raw(x).normalize().dot(fixed).ln();
        let g_point = geometry.delta_light_gradient(wl, 1.0 / dist);
        let g_directional = geometry.delta_light_gradient(fixed, 0.0);
        for axis in [e0.normalize(), e1.normalize()] {
            let fd = (ln_point(x + h * axis) - ln_point(x - h * axis)) / (2.0 * h);
            assert!((fd - g_point.dot(axis)).abs() < 2e-3 * (1.0 + fd.abs()), "point {fd} vs {}", g_point.dot(axis));
            let fd = (ln_directional(x + h * axis) - ln_directional(x - h * axis)) / (2.0 * h);
            let ours = g_directional.dot(axis);
            assert!(fd.abs() > 1e-2 && (fd - ours).abs() < 2e-3 * (1.0 + fd.abs()), "directional {fd} vs {ours}");
        }
    }

    #[test]
    fn regularised_solve_inverts_the_product() {
        let g = HitGeometry {
            t: 2.0,
            d: Vec3::new(0.1, 0.0, -1.0).normalize(),
            ng: Vec3::Z,
            n: Vec3::Z,
            dn_dx: Mat3::ZERO,
        };
        let (t_d, t_n) = reflect_jacobians(g.d, g.n);
        let a = g.jacobian(t_d, t_n);
        // Singular as it stands: the hit point ignores moves along d.
        assert!(a.oo.determinant().abs() < 1e-6);
        for y in [-0.5f32, -0.25, 0.25, 0.5] {
            let reg = a.plus_identity(y);
            let x = Row6 { o: Vec3::new(0.3, -1.0, 2.0), d: Vec3::new(-0.7, 0.1, 0.4) };
            let back = reg.solve_row(x.through(&reg)).unwrap();
            assert!((back.o - x.o).abs().max_element() < 1e-4 && (back.d - x.d).abs().max_element() < 1e-4);
        }
        assert_eq!(regularisation(0.5, 0.2, 0.0), -0.25);
        assert_eq!(regularisation(0.5, 0.7, 1.0), 0.5);
    }

    /// A diffuse vertex: the cosine sample's direction by the normal against finite differences
    /// of the frame it is drawn in, and its completed Jacobian — singular in the direction block
    /// (the outgoing direction ignores the incoming one) — made invertible by direction noise,
    /// whose solve undoes the row product.
    #[test]
    fn diffuse_vertex_jacobian_and_its_noise() {
        let local = Vec3::new(0.3, -0.5, 0.81).normalize();
        let out = |n: Vec3| crate::sampling::Frame::from_normal(n).to_world(local);
        let h = 1e-3;
        for n in [Vec3::new(0.2, -0.3, 0.93).normalize(), Vec3::new(-0.4, 0.1, -0.9).normalize()] {
            let t_n = diffuse_direction_jacobian(n, local);
            for axis in [Vec3::X, Vec3::Y, Vec3::Z] {
                let fd = (out(n + h * axis) - out(n - h * axis)) / (2.0 * h);
                assert!((fd - t_n * axis).abs().max_element() < 2e-3, "∂d′/∂n {fd} vs {}", t_n * axis);
            }
        }
        let d = Vec3::new(0.2, 0.1, -1.0).normalize();
        let g = HitGeometry { t: 1.5, d, ng: Vec3::Z, n: Vec3::Z, dn_dx: Mat3::ZERO };
        let wo = out(Vec3::Z);
        let a = g.jacobian(Mat3::ZERO, diffuse_direction_jacobian(Vec3::Z, local)).completed(Vec3::X, d, Vec3::Z, wo);
        assert!(
            a.dd.determinant().abs() < 1e-6 && a.solve_row(Row6::direction(Vec3::X)).is_none_or(|x| x.max_abs() > 1e5)
        );
        for y in [-1.0f32, -0.5, 0.5, 1.0] {
            let reg = a.plus_direction_noise(y, d, wo);
            // Zero on the manifold's complement it adds nothing to: the incoming direction's length.
            assert!((reg.dd * d - a.dd * d).abs().max_element() < 1e-6);
            let x = Row6 { o: Vec3::new(0.3, -1.0, 2.0), d: Vec3::new(-0.7, 0.1, 0.4) };
            let back = reg.solve_row(x.through(&reg)).unwrap();
            assert!((back.o - x.o).abs().max_element() < 1e-4 && (back.d - x.d).abs().max_element() < 1e-4);
        }
    }

    /// The lobe's direction derivative by η and its log-weight derivatives against finite
    /// differences of `SmoothLeaf::sample` (the same lobe, u_lobe 0 or 1) in a local frame.
    #[test]
    fn smooth_lobe_matches_the_sampler() {
        use crate::bsdf::specular::{SmoothKind, SmoothLeaf};
        let leaf = |kind, eta: f32| SmoothLeaf {
            kind,
            reflectance: Vec3::ONE,
            transmittance: Vec3::ONE,
            eta: Vec3::new(eta, 0.0, 0.0),
            k: Vec3::ZERO,
        };
        let n = Vec3::Z;
        for (kind, thin) in [(SmoothKind::Dielectric, false), (SmoothKind::ThinDielectric, true)] {
            for wi in [Vec3::new(0.5, 0.2, 0.84), Vec3::new(-0.3, 0.1, -0.95), Vec3::new(0.1, -0.6, 0.79)] {
                let wi = wi.normalize();
                let d = -wi;
                for (u, transmitted) in [(0.0, false), (0.999_999, true)] {
                    let eta = 1.5;
                    let Some(lobe) = smooth_lobe(thin, d, n, eta, transmitted) else { continue };
                    let h = 1e-3;
                    let at = |e: f32, wi: Vec3| leaf(kind, e).sample(wi, u).unwrap();
                    // ln of the weight with the choice probability attached: ln(value) (pdf
                    // detached) — value = weight × probability in `SmoothLeaf::sample`.
                    let lnv = |b: crate::bsdf::BsdfSample| b.value.x.ln();
                    let fd_eta = (lnv(at(eta + h, wi)) - lnv(at(eta - h, wi))) / (2.0 * h);
                    assert!(
                        (fd_eta - lobe.dlnw_deta.x).abs() < 3e-3,
                        "{kind:?} {wi} {transmitted}: ∂lnw/∂η {} vs {fd_eta}",
                        lobe.dlnw_deta.x
                    );
                    let dir_eta = (at(eta + h, wi).wo - at(eta - h, wi).wo) / (2.0 * h);
                    assert!((dir_eta - lobe.t_eta).abs().max_element() < 3e-3, "∂d′/∂η {} vs {dir_eta}", lobe.t_eta);
                    // cos θi moved by tilting wi toward the normal.
                    let tilt = |c: f32| {
                        let t = Vec3::new(wi.x, wi.y, 0.0);
                        let sin = (1.0 - c * c).sqrt();
                        (t.normalize() * sin + Vec3::new(0.0, 0.0, c)).normalize()
                    };
                    let fd_cos = (lnv(at(eta, tilt(wi.z + h))) - lnv(at(eta, tilt(wi.z - h)))) / (2.0 * h);
                    assert!(
                        (fd_cos - lobe.dlnw_dcos.x).abs() < 3e-3,
                        "{kind:?} {wi}: ∂lnw/∂cos {} vs {fd_cos}",
                        lobe.dlnw_dcos.x
                    );
                }
            }
        }
    }
}

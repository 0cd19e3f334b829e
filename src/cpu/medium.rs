//! Participating media on the CPU: field lookups, phase functions, delta tracking of free flights
//! and ratio tracking of shadow rays through media and null boundaries (ALGORITHMS.md §8; twin of
//! `shaders/lib/medium.glsl`).
//!
//! RGB extinction is tracked spectrally against one grey majorant σ̄ ≥ max_c σ_t,c: a tentative
//! collision at x is real with probability P = mean_c σ_t,c(x)/σ̄ and weights each channel by
//! σ_s,c/(σ̄ P) (real) or (σ̄ − σ_t,c)/(σ̄ (1 − P)) (null), so every channel is unbiased; for a grey
//! medium the weights are the albedo and 1, plain delta tracking.
//!
//! σ̄ is piecewise constant along a ray: a medium with a majorant grid
//! ([`crate::scene::medium::MajorantGrid`]) walks its cells (`MajorantWalk`), drawing one optical
//! depth per tentative collision and spending it cell by cell at each cell's own σ̄.

use glam::Vec3;

use crate::bvh::{Ray, closest_hit};
use crate::contract::{
    FIELD_CONSTANT, FIELD_GRID_MIRROR, FIELD_GRID_REPEAT, FLOAT_MAX, FieldDesc, MAT_NULL, MAX_NULL_CROSSINGS,
    MAX_TRACKING_STEPS, MediumDesc, NO_MEDIUM, NO_PARAM, PHASE_HG,
};
use crate::cpu::path::GradSink;
use crate::cpu::surface::{offset_origin, surface_at};
use crate::rng::{RngKey, Stream, uniform4};
use crate::sampling::Frame;
use crate::scene::Wrap;
use crate::scene::flat::FlatScene;

/// Whether the scene needs the media code of the path loop (a medium or a null boundary).
pub fn has_media(flat: &FlatScene) -> bool {
    !flat.media.is_empty() || flat.materials.iter().any(|m| m.tag == MAT_NULL)
}

/// Channel `c` of field `f` at world point `p`.
fn field_at(flat: &FlatScene, f: &FieldDesc, p: Vec3, c: u32) -> f32 {
    let c = c.min(f.channels - 1);
    if f.kind == FIELD_CONSTANT {
        return flat.params[(f.offset + c) as usize];
    }
    let local = Vec3::new(f.row0.dot(p), f.row1.dot(p), f.row2.dot(p)) + f.shift;
    let res = glam::UVec3::new(f.res_x, f.res_y, f.res_z);
    let count = (f.res_x * f.res_y * f.res_z * f.channels) as usize;
    let values = &flat.params[f.offset as usize..f.offset as usize + count];
    crate::scene::volume::lookup(values, res, f.channels, local, c, grid_wrap(f))
}

/// How a grid field's voxel indices wrap, from its kind.
fn grid_wrap(f: &FieldDesc) -> Wrap {
    match f.kind {
        FIELD_GRID_REPEAT => Wrap::Repeat,
        FIELD_GRID_MIRROR => Wrap::Mirror,
        _ => Wrap::Clamp,
    }
}

/// Field `f` at world point `p` per channel (a grey field's one value in all three; twin:
/// `field_rgb` of shaders/lib/field.glsl).
pub(crate) fn field_rgb(flat: &FlatScene, f: &FieldDesc, p: Vec3) -> Vec3 {
    Vec3::new(field_at(flat, f, p, 0), field_at(flat, f, p, 1), field_at(flat, f, p, 2))
}

/// The extinction `scale · sigma_t(p)` per channel.
pub fn medium_extinction(flat: &FlatScene, m: &MediumDesc, p: Vec3) -> Vec3 {
    flat.params[m.p_scale as usize] * field_rgb(flat, &flat.fields[m.sigma_t as usize], p)
}

/// The albedo per channel.
pub fn albedo(flat: &FlatScene, m: &MediumDesc, p: Vec3) -> Vec3 {
    field_rgb(flat, &flat.fields[m.albedo as usize], p)
}

/// Henyey–Greenstein's g of `m` (0 for an isotropic medium).
fn hg_g(flat: &FlatScene, m: &MediumDesc) -> f32 {
    if m.phase == PHASE_HG { flat.params[m.p_g as usize] } else { 0.0 }
}

/// The phase function's value for light travelling along `d` scattered into `wo` (both unit):
/// (1 − g²) / (4π (1 + g² − 2g cos θ)^{3/2}) with cos θ = d·wo; g > 0 scatters forward.
pub fn phase_eval(flat: &FlatScene, m: &MediumDesc, d: Vec3, wo: Vec3) -> f32 {
    let g = hg_g(flat, m);
    let denom = 1.0 + g * g - 2.0 * g * d.dot(wo);
    (1.0 - g * g) / (4.0 * std::f32::consts::PI * denom * denom.max(0.0).sqrt())
}

/// A direction drawn from the phase function around `d` with two uniforms; its density equals
/// [`phase_eval`].
pub fn phase_sample(flat: &FlatScene, m: &MediumDesc, d: Vec3, u: [f32; 2]) -> Vec3 {
    let g = hg_g(flat, m);
    let cos = if g.abs() < 1e-3 {
        1.0 - 2.0 * u[0]
    } else {
        let s = (1.0 - g * g) / (1.0 - g + 2.0 * g * u[0]);
        ((1.0 + g * g - s * s) / (2.0 * g)).clamp(-1.0, 1.0)
    };
    let sin = (1.0 - cos * cos).max(0.0).sqrt();
    let phi = 2.0 * std::f32::consts::PI * u[1];
    Frame::from_normal(d).to_world(Vec3::new(sin * phi.cos(), sin * phi.sin(), cos))
}

/// |g| below which ∂p/∂g is taken at its g → 0 limit, 3 cos θ/(4π) (the closed forms divide by g²).
const HG_DIFF_SMALL_G: f32 = 1e-6;

/// ∂p/∂g of Henyey–Greenstein at cos θ = `mu`: ((g² + 3)μ + g³ − 5g) / (4π Δ^{5/2}), Δ = 1 + g² −
/// 2gμ (ALGORITHMS.md §8.4). Negative for μ < μ₀ = g(5 − g²)/(g² + 3), positive above.
pub fn hg_dg(g: f32, mu: f32) -> f32 {
    let delta = 1.0 + g * g - 2.0 * g * mu;
    ((g * g + 3.0) * mu + g * g * g - 5.0 * g) / (4.0 * std::f32::consts::PI * delta * delta * delta.max(0.0).sqrt())
}

/// The signed parts of ∂p/∂g for a = |g| > 0 in s = Δ^{-1/2} (in which HG itself is uniform): s₀ −
/// 1 (the sign change, s₀² = (3 + a²)/(3(1 − a²)²)), the negative part's length L⁻ = s₀ − 1/(1 + a)
/// and the positive part's L⁺ = 1/(1 − a) − s₀, written without cancellation for small a.
struct HgParts {
    s0: f32,
    s0m1: f32,
    len_neg: f32,
    len_pos: f32,
}

fn hg_parts(a: f32) -> HgParts {
    let c = 1.0 - a * a;
    let s0 = ((3.0 + a * a) / (3.0 * c * c)).sqrt();
    let s0m1 = a * a * (7.0 - 3.0 * a * a) / (3.0 * c * c) / (s0 + 1.0);
    HgParts { s0, s0m1, len_neg: s0m1 + a / (1.0 + a), len_pos: a / (1.0 - a) - s0m1 }
}

/// The mass of each signed part of ∂p/∂g, M(g) = ∫max(0, ±∂p/∂g) dω (the parts cancel):
/// 3(1 − a²)²/(4a²) · ((s₀ + s_min)L⁻²/2 + L⁻³/6), a = |g|; 3/4 at g = 0.
pub fn hg_dg_mass(g: f32) -> f32 {
    let a = g.abs();
    if a < HG_DIFF_SMALL_G {
        return 0.75;
    }
    let p = hg_parts(a);
    let c = 1.0 - a * a;
    let k = p.s0 + 1.0 / (1.0 + a);
    let l = p.len_neg;
    3.0 * c * c / (4.0 * a * a) * (k * l * l / 2.0 + l * l * l / 6.0)
}

/// cos θ drawn from one signed part of ∂p/∂g (`positive`: where it is > 0), with `u_comp` choosing
/// a component of the part's polynomial density in s and `u` inverting its CDF (ALGORITHMS.md
/// §8.4): in y = |s − s₀| the negative part is ∝ y·(s₀ + s_min) + y(L⁻ − y) (linear, Beta(2,2)), the
/// positive part ∝ 2s₀·y + y² (linear, quadratic). g < 0 mirrors g > 0: ∂p/∂g(μ; g) = −∂p/∂a(−μ; a).
pub fn hg_diff_sample_cos(g: f32, positive: bool, u_comp: f32, u: f32) -> f32 {
    let a = g.abs();
    let up = positive == (g >= 0.0); // the part of ∂p/∂a to sample
    let mu = if a < HG_DIFF_SMALL_G {
        u.sqrt() * if up { 1.0 } else { -1.0 }
    } else {
        let p = hg_parts(a);
        let sm1 = if up {
            let l = p.len_pos;
            let (wa, wb) = (p.s0 * l * l, l * l * l / 3.0);
            p.s0m1 + if u_comp * (wa + wb) < wa { l * u.sqrt() } else { l * u.powf(1.0 / 3.0) }
        } else {
            let l = p.len_neg;
            let k = p.s0 + 1.0 / (1.0 + a);
            let (wa, wb) = (k * l * l / 2.0, l * l * l / 6.0);
            let beta22 = 0.5 - ((1.0 - 2.0 * u).clamp(-1.0, 1.0).asin() / 3.0).sin();
            p.s0m1 - if u_comp * (wa + wb) < wa { l * u.sqrt() } else { l * beta22 }
        };
        // μ = (1 + a² − s⁻²)/(2a) = ((s − 1)(s + 1) + a²s²)/(2a s²).
        let s = sm1 + 1.0;
        ((sm1 * (s + 1.0) + a * a * s * s) / (2.0 * a * s * s)).clamp(-1.0, 1.0)
    };
    if g >= 0.0 { mu } else { -mu }
}

/// Whether the differential strategy may place its differential vertex in medium `m`: an HG
/// phase function whose g lies in the target's parameter values.
pub fn medium_capable(m: &MediumDesc, begin: u32, end: u32) -> bool {
    m.phase == PHASE_HG && m.p_g >= begin && m.p_g < end
}

/// Direction density of the differential technique of `m`'s phase function (a fair coin between
/// the signed parts of ∂p/∂g): |∂p/∂g| / (2M(g)), around `d` at `wo`.
pub fn phase_pdf_diff(flat: &FlatScene, m: &MediumDesc, d: Vec3, wo: Vec3) -> f32 {
    let g = hg_g(flat, m);
    hg_dg(g, d.dot(wo)).abs() / (2.0 * hg_dg_mass(g))
}

/// Direction density of one signed part's sampler: |∂p/∂g| / M(g) where its sign is the part's.
pub fn phase_pdf_diff_part(g: f32, positive: bool, mu: f32) -> f32 {
    let v = hg_dg(g, mu);
    if (v > 0.0) == positive && v != 0.0 { v.abs() / hg_dg_mass(g) } else { 0.0 }
}

/// The differential technique of `m`'s phase function: the positive part of ∂p/∂g if `u_sign <
/// 0.5`, else the negative one ([`hg_diff_sample_cos`] with `u_comp` and `u[0]`), φ = 2π `u[1]`,
/// around `d` as [`phase_sample`]; its density is [`phase_pdf_diff`].
pub fn phase_sample_diff(flat: &FlatScene, m: &MediumDesc, d: Vec3, u_sign: f32, u_comp: f32, u: [f32; 2]) -> Vec3 {
    let cos = hg_diff_sample_cos(hg_g(flat, m), u_sign < 0.5, u_comp, u[0]);
    let sin = (1.0 - cos * cos).max(0.0).sqrt();
    let phi = 2.0 * std::f32::consts::PI * u[1];
    Frame::from_normal(d).to_world(Vec3::new(sin * phi.cos(), sin * phi.sin(), cos))
}

/// The part [t0, t1) of the segment `origin + t·dir`, t in [0, `t_max`), where medium `m`
/// exists: all of it for an unbounded medium, else its intersection with the medium's box (a
/// slab test, Mitsuba's `intersect_aabb` clipped to the segment as its `sample_interaction`
/// does); `None` when the segment misses the box. Twin of `medium_span` in
/// `shaders/lib/medium.glsl`.
pub fn medium_span(m: &MediumDesc, origin: Vec3, dir: Vec3, t_max: f32) -> Option<(f32, f32)> {
    let (mut t0, mut t1) = (0.0f32, t_max);
    if m.bounded == 0 {
        return Some((t0, t1));
    }
    let axes =
        [(origin.x, dir.x, m.lo.x, m.hi.x), (origin.y, dir.y, m.lo.y, m.hi.y), (origin.z, dir.z, m.lo.z, m.hi.z)];
    for (o, d, lo, hi) in axes {
        if d == 0.0 {
            if o < lo || o > hi {
                return None;
            }
            continue;
        }
        let (a, b) = ((lo - o) / d, (hi - o) / d);
        t0 = t0.max(a.min(b));
        t1 = t1.min(a.max(b));
    }
    (t0 < t1).then_some((t0, t1))
}

/// The majorant along a ray through a medium: its grid's cells one after another (a 3D DDA over
/// the unit cube of the `sigma_t` field, whose transform maps the ray there affinely, so distances
/// along it stay world distances), or the one majorant of a medium without a grid. Twin of
/// `MajorantWalk` in `shaders/lib/medium.glsl`, operation for operation.
struct MajorantWalk<'a> {
    /// The grid's values (empty: `mu` everywhere).
    values: &'a [f32],
    /// Cells along each axis.
    cells: [u32; 3],
    /// The ray's origin in the unit cube.
    o: [f32; 3],
    /// Its direction there.
    d: [f32; 3],
    /// The current cell (border cells extend beyond the cube, where lookups clamp).
    cell: [u32; 3],
    /// Where the walk stands.
    t: f32,
    /// The end of the medium's span.
    t_end: f32,
    /// The majorant without a grid.
    mu: f32,
}

impl<'a> MajorantWalk<'a> {
    /// A walk over `(t0, t1)` of `origin + t·dir` in medium `m`.
    fn new(flat: &'a FlatScene, m: &MediumDesc, origin: Vec3, dir: Vec3, (t0, t1): (f32, f32)) -> MajorantWalk<'a> {
        let mut walk = MajorantWalk {
            values: &[],
            cells: [0; 3],
            o: [0.0; 3],
            d: [0.0; 3],
            cell: [0; 3],
            t: t0,
            t_end: t1,
            mu: m.majorant,
        };
        if m.grid == NO_PARAM {
            return walk;
        }
        let f = &flat.fields[m.sigma_t as usize];
        let o = Vec3::new(f.row0.dot(origin), f.row1.dot(origin), f.row2.dot(origin)) + f.shift;
        let d = Vec3::new(f.row0.dot(dir), f.row1.dot(dir), f.row2.dot(dir));
        walk.cells = [m.grid_x, m.grid_y, m.grid_z];
        walk.values = &flat.majorants[m.grid as usize..][..(m.grid_x * m.grid_y * m.grid_z) as usize];
        walk.o = o.to_array();
        walk.d = d.to_array();
        let p = o + t0 * d;
        for axis in 0..3 {
            let n = walk.cells[axis] as f32;
            walk.cell[axis] = (p[axis] * n).floor().clamp(0.0, n - 1.0) as u32;
        }
        walk
    }

    /// Where the ray leaves the current cell across an inner face of the grid along `axis`
    /// (`FLOAT_MAX` when it never does).
    fn plane(&self, axis: usize) -> f32 {
        let (c, n, o, d) = (self.cell[axis], self.cells[axis], self.o[axis], self.d[axis]);
        if d > 0.0 && c + 1 < n {
            ((c + 1) as f32 / n as f32 - o) / d
        } else if d < 0.0 && c > 0 {
            (c as f32 / n as f32 - o) / d
        } else {
            FLOAT_MAX
        }
    }

    /// Spends optical depth `tau` from where the walk stands: the tentative collision's distance
    /// and the majorant there, or `None` when the span ends first.
    fn collide(&mut self, mut tau: f32) -> Option<(f32, f32)> {
        if self.values.is_empty() {
            let t = self.t + tau / self.mu;
            if !(t < self.t_end) {
                return None;
            }
            self.t = t;
            return Some((t, self.mu));
        }
        // Each pass leaves one cell, and a ray leaves at most this many.
        for _ in 0..self.cells.iter().sum::<u32>() + 3 {
            let (tx, ty, tz) = (self.plane(0), self.plane(1), self.plane(2));
            let t_exit = tx.min(ty).min(tz.min(self.t_end));
            let [cx, cy, cz] = self.cell;
            let mu = self.values[((cz * self.cells[1] + cy) * self.cells[0] + cx) as usize];
            if mu > 0.0 {
                let t = self.t + tau / mu;
                if t < t_exit {
                    self.t = t;
                    return Some((t, mu));
                }
                tau -= (t_exit - self.t).max(0.0) * mu;
            }
            if !(t_exit < self.t_end) {
                return None;
            }
            self.t = self.t.max(t_exit);
            let axis = if tx == t_exit {
                0
            } else if ty == t_exit {
                1
            } else {
                2
            };
            if self.d[axis] > 0.0 {
                self.cell[axis] += 1;
            } else {
                self.cell[axis] -= 1;
            }
        }
        None
    }
}

/// Where a free flight along `ray` in medium `m` ends before `t_max`: `Some(t)` at a real
/// collision, `None` if it reaches `t_max`; the spectral-tracking weight of the flight is
/// multiplied into `weight`. Draws stream DT of `vertex` from step `*step` on, only over the part
/// of the ray where the medium exists ([`medium_span`]).
///
/// In a replay, `grad` is (sink, δL·L) with L the radiance the flight's weights multiply: each
/// weight w scatters δL·L·∂w/w (ALGORITHMS.md §8; a null weight (σ̄ − σ_t,c)/(σ̄(1 − P)) through
/// σ_t, a real one a_c σ_t,c/(σ̄ P) through a and σ_t, with P detached). A channel whose weight is
/// exactly 0 carries nothing after it, and its derivative is not recovered here.
#[allow(clippy::too_many_arguments)]
pub fn delta_track(
    flat: &FlatScene,
    key: RngKey,
    m: &MediumDesc,
    ray: &Ray,
    t_max: f32,
    (pixel, sample, vertex): (u32, u32, u32),
    step: &mut u32,
    weight: &mut Vec3,
    mut grad: Option<(&mut GradSink<'_>, Vec3)>,
) -> Option<f32> {
    if !(m.majorant > 0.0) {
        return None;
    }
    let span = medium_span(m, ray.origin, ray.dir, t_max)?;
    let mut walk = MajorantWalk::new(flat, m, ray.origin, ray.dir, span);
    while *step < MAX_TRACKING_STEPS {
        let u = uniform4(key, pixel, sample, vertex, Stream::DeltaTracking, 0, *step);
        *step += 1;
        let (t, majorant) = walk.collide(-(1.0 - u[0]).ln())?;
        let x = ray.origin + t * ray.dir;
        let sigma = medium_extinction(flat, m, x);
        let p_real = ((sigma.x + sigma.y + sigma.z) / (3.0 * majorant)).clamp(0.0, 1.0);
        if u[1] < p_real {
            let a = albedo(flat, m, x);
            *weight *= a * sigma / (majorant * p_real);
            if let Some((sink, w)) = grad.as_mut() {
                albedo_grad(flat, m, x, safe_ratio(*w, a), sink);
                extinction_grad(flat, m, x, safe_ratio(*w, sigma), sink);
            }
            return Some(t);
        }
        let null = Vec3::splat(majorant) - sigma;
        *weight *= null / (majorant * (1.0 - p_real));
        if let Some((sink, w)) = grad.as_mut() {
            extinction_grad(flat, m, x, -safe_ratio(*w, null), sink);
        }
    }
    // A flight that outlasts the step budget is cut off: it carries nothing.
    *weight = Vec3::ZERO;
    None
}

/// The ratio-tracking transmittance of `m` along `origin + t·dir` for t in [0, t_max), drawing
/// stream RT of `vertex` from step `*step` on.
///
/// In a replay, `grad` is (sink, δL·C) with C the contribution the transmittance multiplies: each
/// factor r = (σ̄ − σ_t)/σ̄ scatters δL·C·∂r/r through σ_t (the nested replay of ALGORITHMS.md §8).
fn ratio_track(
    flat: &FlatScene,
    key: RngKey,
    m: &MediumDesc,
    (origin, dir, t_max): (Vec3, Vec3, f32),
    (pixel, sample, vertex): (u32, u32, u32),
    step: &mut u32,
    grad: &mut Option<(&mut GradSink<'_>, Vec3)>,
) -> Vec3 {
    if !(m.majorant > 0.0) {
        return Vec3::ONE;
    }
    let Some(span) = medium_span(m, origin, dir, t_max) else { return Vec3::ONE };
    let mut walk = MajorantWalk::new(flat, m, origin, dir, span);
    let mut tr = Vec3::ONE;
    while *step < MAX_TRACKING_STEPS {
        let u = uniform4(key, pixel, sample, vertex, Stream::RatioTracking, 0, *step)[0];
        *step += 1;
        let Some((t, majorant)) = walk.collide(-(1.0 - u).ln()) else { return tr };
        let x = origin + t * dir;
        let null = Vec3::splat(majorant) - medium_extinction(flat, m, x);
        tr *= null / majorant;
        if let Some((sink, w)) = grad.as_mut() {
            extinction_grad(flat, m, x, -safe_ratio(*w, null), sink);
        }
    }
    Vec3::ZERO
}

/// a / b per channel, 0 where b is 0.
fn safe_ratio(a: Vec3, b: Vec3) -> Vec3 {
    Vec3::select(b.cmpeq(Vec3::ZERO), Vec3::ZERO, a / b)
}

/// The medium a ray along `dir` is in after crossing, from medium `current`, a triangle whose
/// mesh holds medium `interior` behind its winding normal `ng`.
pub fn medium_crossed(interior: u32, ng: Vec3, dir: Vec3, current: u32) -> u32 {
    if interior == NO_MEDIUM {
        current
    } else if ng.dot(dir) < 0.0 {
        interior
    } else {
        NO_MEDIUM
    }
}

/// The transmittance from `origin` along `dir` over [0, t_max) starting in medium `medium`:
/// ratio tracking through each medium, passing null boundaries; 0 if an opaque surface is in the
/// way or more than `MAX_NULL_CROSSINGS` boundaries are. In a replay (`grad`: sink and δL·C),
/// the same steps scatter their derivatives (see `ratio_track`). The kernels trace the same
/// segments in `path_step`'s pass loop (`shaders/integrator.glsl`: pass 1, and pass 2 for the
/// replay), through the traversal and tracking sites of the path's own ray.
pub fn shadow_transmittance(
    flat: &FlatScene,
    key: RngKey,
    medium: u32,
    (origin, dir, t_max): (Vec3, Vec3, f32),
    counters: (u32, u32, u32),
    mut grad: Option<(&mut GradSink<'_>, Vec3)>,
) -> Vec3 {
    let (mut m, mut o, mut remaining) = (medium, origin, t_max);
    // Measured from the end each time, so the origins' offsets past each boundary do not add up
    // to a segment that reaches the emitter itself.
    let end = origin + t_max * dir;
    let mut tr = Vec3::ONE;
    let mut step = 0u32;
    for _ in 0..=MAX_NULL_CROSSINGS {
        let hit = closest_hit(&flat.bvh, &Ray::new(o, dir), 0.0, remaining);
        let segment = hit.as_ref().map_or(remaining, |h| h.t);
        if m != NO_MEDIUM {
            tr *= ratio_track(flat, key, &flat.media[m as usize], (o, dir, segment), counters, &mut step, &mut grad);
        }
        let Some(hit) = hit else { return tr };
        let s = surface_at(flat, &hit);
        if flat.materials[s.material as usize].tag != MAT_NULL {
            return Vec3::ZERO;
        }
        m = medium_crossed(flat.mesh_of(hit.slot).interior, s.ng, dir, m);
        o = offset_origin(s.p, s.ng, dir);
        if t_max < f32::MAX {
            remaining = (end - o).dot(dir);
            if !(remaining > 0.0) {
                return tr;
            }
        }
    }
    Vec3::ZERO
}

/// The voxels and trilinear weights of a grid lookup at local point `local` (as
/// [`crate::scene::volume::lookup`] interpolates them).
fn trilinear(f: &FieldDesc, local: Vec3) -> [(u32, f32); 8] {
    let res = glam::UVec3::new(f.res_x, f.res_y, f.res_z);
    let (lo, hi, t) = crate::scene::volume::footprint(res, local, grid_wrap(f));
    let mut out = [(0u32, 0.0f32); 8];
    for (k, o) in out.iter_mut().enumerate() {
        let pick = |bit: usize, a: u32, b: u32| if k & bit == 0 { a } else { b };
        let (x, y, z) = (pick(1, lo.x, hi.x), pick(2, lo.y, hi.y), pick(4, lo.z, hi.z));
        let w = (if k & 1 == 0 { 1.0 - t.x } else { t.x })
            * (if k & 2 == 0 { 1.0 - t.y } else { t.y })
            * (if k & 4 == 0 { 1.0 - t.z } else { t.z });
        *o = ((z * res.y + y) * res.x + x, w);
    }
    out
}

/// GRAD of field `f` at `p` with weight `w` per image channel: each value's derivative
/// (channel c of an RGB field reaches image channel c only; a grey field reaches all three).
pub(crate) fn field_grad(f: &FieldDesc, p: Vec3, w: Vec3, sink: &mut GradSink<'_>) {
    let add = |sink: &mut GradSink<'_>, base: u32, scale: f32| {
        if f.channels == 1 {
            sink.add(base, w * scale);
        } else {
            sink.add_rgb(base, w * scale);
        }
    };
    if f.kind == FIELD_CONSTANT {
        add(sink, f.offset, 1.0);
        return;
    }
    let local = Vec3::new(f.row0.dot(p), f.row1.dot(p), f.row2.dot(p)) + f.shift;
    for (voxel, weight) in trilinear(f, local) {
        if weight != 0.0 {
            add(sink, f.offset + voxel * f.channels, weight);
        }
    }
}

/// GRAD of the extinction `scale · sigma_t(p)` with weight `w` per channel (through the scale and
/// the field's values).
pub fn extinction_grad(flat: &FlatScene, m: &MediumDesc, p: Vec3, w: Vec3, sink: &mut GradSink<'_>) {
    let field = &flat.fields[m.sigma_t as usize];
    sink.add(m.p_scale, w * field_rgb(flat, field, p));
    field_grad(field, p, w * flat.params[m.p_scale as usize], sink);
}

/// GRAD of the albedo at `p` with weight `w` per channel.
pub fn albedo_grad(flat: &FlatScene, m: &MediumDesc, p: Vec3, w: Vec3, sink: &mut GradSink<'_>) {
    field_grad(&flat.fields[m.albedo as usize], p, w, sink);
}

/// GRAD of the phase function's value for (d, wo) with weight `w` (per channel): through g.
pub fn phase_grad(flat: &FlatScene, m: &MediumDesc, d: Vec3, wo: Vec3, w: Vec3, sink: &mut GradSink<'_>) {
    if m.phase != PHASE_HG {
        return;
    }
    let g = flat.params[m.p_g as usize];
    let c = d.dot(wo);
    let denom = 1.0 + g * g - 2.0 * g * c;
    // d/dg of (1 − g²)/(4π D^{3/2}), D = 1 + g² − 2gc.
    let dfdg = (-2.0 * g * denom - 3.0 * (1.0 - g * g) * (g - c))
        / (4.0 * std::f32::consts::PI * denom * denom * denom.max(0.0).sqrt());
    sink.add(m.p_g, w * dfdg);
}

#[cfg(test)]
#[path = "medium_tests.rs"]
mod tests;

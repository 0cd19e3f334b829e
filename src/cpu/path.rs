//! The one path loop on the CPU (twin of `shaders/integrator.glsl`, phase by phase): BSDF or
//! differential sampling, next-event estimation, MIS, Russian roulette (ALGORITHMS.md §3.1, §5.4).

use glam::{Vec2, Vec3};

use crate::attached::{
    HitGeometry, Jac6, RoughDielectricLobe, RoughLobe, Row6, conductor_lobe, diffuse_direction_jacobian,
    regularisation, rough_conductor_lobe, rough_dielectric_lobe, smooth_lobe,
};
use crate::bsdf::Leaf;
use crate::bsdf::differential::{bsdf_pdf_diff, bsdf_sample_diff};
use crate::bsdf::specular::SmoothKind;
use crate::bsdf::specular::is_smooth;
use crate::bsdf::{Bsdf, BsdfSample, bsdf_eval, bsdf_pdf, bsdf_sample};
use crate::bvh::{Ray, closest_hit, occluded};
use crate::contract::{
    DIFFUSE_JACOBIAN_NOISE, DIM_DIFF_SIGN, DIM_DIRECTION, DIM_EMITTER_POS, DIM_EMITTER_SELECT, DIM_ENV_CELL, DIM_HERO,
    DIM_LOBE, DIM_PIXEL_JITTER, DIM_ROULETTE, DIM_TECHNIQUE, Distribution, Globals, LENS_ORTHOGRAPHIC, LENS_THIN,
    LIGHT_SLOT, MAT_BLEND, MAT_CONDUCTOR, MAT_NULL, MAT_ROUGH_CONDUCTOR, MAT_ROUGH_DIELECTRIC, MAT_ROUGH_PLASTIC,
    MAT_THIN_DIELECTRIC, MAX_HEROES, MAX_NULL_CROSSINGS, MAX_PATH_VERTICES, NO_EMITTER, NO_MEDIUM, NO_PARAM,
    PATH_HIDE_EMITTERS, PATH_NULL_UNCOUNTED, PLACEMENT_POWER, STRATEGY_DIFF, ViewCamera,
};
use crate::cpu::emitter::{
    EmitterSample, area_backward, area_radiance, area_textured, emitter_pdf_solid_angle, env_backward, env_radiance,
    env_radiance_gradient, environment_pdf, light_backward, sample_emitter,
};
use crate::cpu::medium;
use crate::cpu::slope::{albedo_slope, area_radiance_slope, surface_gradients};
use crate::cpu::surface::{
    SHADOW_EPSILON, bsdf_backward, bsdf_backward_but_alpha, mask_opacity_at, material_anisotropic,
    material_normal_mapped, mis_power, normal_map_frame, offset_origin, opacity_backward, resolve_bsdf, safe_div,
    shading_normal_gradient, surface_at, tangent_frame,
};
use crate::rng::{RngKey, Stream, uniform4};
use crate::sampling::Frame;
use crate::scene::flat::FlatScene;

fn draw_block(key: RngKey, pixel: u32, sample: u32, vertex: u32, block: u32) -> [f32; 4] {
    uniform4(key, pixel, sample, vertex, Stream::Main, block, 0)
}

/// Russian roulette at `vertex`, whose counted interactions before it are `depth` (vertex − 1
/// unless null events go uncounted) — from depth ≥ rr_depth (ALGORITHMS.md §3.1), surviving with
/// p = min(max β, 0.95) and β divided by it — then the end of a path whose throughput is zero.
/// True if the path goes on (twin of `path_survives` in the kernels).
fn path_survives(
    globals: &Globals,
    key: RngKey,
    (pixel, sample, vertex): (u32, u32, u32),
    depth: u32,
    throughput: &mut Vec3,
) -> bool {
    if depth >= globals.rr_depth {
        let u_rr = draw_block(key, pixel, sample, vertex, DIM_ROULETTE / 4)[(DIM_ROULETTE % 4) as usize];
        let p_rr = max_component(*throughput).min(0.95);
        if !(u_rr < p_rr) {
            return false;
        }
        *throughput /= p_rr;
    }
    max_component(*throughput) > 0.0
}

/// What a path segment reaches.
enum Event {
    /// Nothing: the environment.
    Escape,
    /// A surface that is not a null boundary.
    Surface(crate::bvh::Hit, crate::cpu::surface::Surface),
    /// A real collision in the current medium, at this point.
    Medium(Vec3),
    /// More null boundaries than `MAX_NULL_CROSSINGS` in a row: the path is cut off.
    Lost,
}

fn max_component(v: Vec3) -> f32 {
    v.x.max(v.y).max(v.z)
}

/// The camera ray through film point (sx, sy) ∈ [−1, 1]² (+y up), `u_lens` placing it on a thin
/// lens's aperture (block 0 of vertex 0, dims 2 and 3).
fn camera_ray(view: &ViewCamera, sx: f32, sy: f32, u_lens: Vec2) -> Ray {
    let through = view.forward + sx * view.right + sy * view.up;
    match view.lens {
        LENS_ORTHOGRAPHIC => Ray::new(view.origin + sx * view.right + sy * view.up, view.forward),
        LENS_THIN => {
            // The pinhole ray meets the plane in focus at `through · focus_distance` (its forward
            // component is 1); the ray leaves a point of the aperture for that point.
            let disk = crate::sampling::sample_concentric_disk(u_lens) * view.aperture_radius;
            let lens = view.origin + disk.x * view.right.normalize() + disk.y * view.up.normalize();
            let focus = view.origin + through * view.focus_distance;
            Ray::new(lens, (focus - lens).normalize())
        }
        _ => Ray::new(view.origin, through.normalize()),
    }
}

/// Whether the differential strategy may place its differential vertex on material `m`: its
/// roughness (rough conductor, dielectric or plastic; an anisotropic one's α_u or α_v) or weight
/// (blend) is the target parameter.
fn material_capable(flat: &FlatScene, globals: &Globals, m: u32) -> bool {
    let mat = &flat.materials[m as usize];
    let p = match mat.tag {
        MAT_ROUGH_CONDUCTOR | MAT_ROUGH_DIELECTRIC | MAT_ROUGH_PLASTIC => mat.p_alpha,
        MAT_BLEND => mat.p_weight,
        _ => NO_PARAM,
    };
    (p >= globals.diff_begin && p < globals.diff_end) || material_target_v(flat, globals, m)
}

/// Whether the differential vertex on material `m` samples the derivative by α_v: `m` is a rough
/// conductor or dielectric whose α_v, a parameter apart from its α_u, is the target.
fn material_target_v(flat: &FlatScene, globals: &Globals, m: u32) -> bool {
    let mat = &flat.materials[m as usize];
    matches!(mat.tag, MAT_ROUGH_CONDUCTOR | MAT_ROUGH_DIELECTRIC)
        && mat.p_alpha_v != mat.p_alpha
        && mat.p_alpha_v >= globals.diff_begin
        && mat.p_alpha_v < globals.diff_end
}

/// Several targets (ALGORITHMS.md §5.8): the index of the hero-set target whose parameter values
/// hold material `m`'s roughness or blend weight, or `MAX_HEROES` if none does.
fn material_hero(flat: &FlatScene, globals: &Globals, m: u32) -> u32 {
    let mat = &flat.materials[m as usize];
    let p = match mat.tag {
        MAT_ROUGH_CONDUCTOR | MAT_ROUGH_DIELECTRIC | MAT_ROUGH_PLASTIC => mat.p_alpha,
        MAT_BLEND => mat.p_weight,
        _ => NO_PARAM,
    };
    param_hero(globals, p)
}

/// Several targets: the index of the hero-set target whose parameter values hold parameter `p`,
/// or `MAX_HEROES` if none does.
fn param_hero(globals: &Globals, p: u32) -> u32 {
    let r = [globals.hero_range0, globals.hero_range1, globals.hero_range2, globals.hero_range3];
    (0..globals.hero_count).find(|&k| p >= r[k as usize].x && p < r[k as usize].y).unwrap_or(MAX_HEROES)
}

/// Several targets: the target medium `m`'s phase function is capable for (its HG g), or
/// `MAX_HEROES`.
fn medium_hero(globals: &Globals, m: &crate::contract::MediumDesc) -> u32 {
    if m.phase == crate::contract::PHASE_HG { param_hero(globals, m.p_g) } else { MAX_HEROES }
}

/// MIS weight of radiance reached by BSDF sampling from the previous vertex, whose direction had
/// density `pdf_f` there and would have had density `pdf_e` under NEE (ALGORITHMS.md §3.1, §5.3,
/// §5.7).
fn hit_weight(diff: bool, prev_nee: bool, pdf_f: f32, pdf_e: f32, mix: &Mixture) -> f32 {
    if mix.power {
        let nee = if prev_nee { mix.prev_sq * (pdf_e / pdf_f) * (pdf_e / pdf_f) } else { 0.0 };
        return mix.technique() / (mix.squares() + nee);
    }
    if !prev_nee {
        return 1.0;
    }
    if !diff {
        return mis_power(pdf_f, pdf_e);
    }
    1.0 / (1.0 + mix.prev_sum * pdf_e / pdf_f)
}

/// The differential strategy's running state (ALGORITHMS.md §5.2, §5.7): constant per path,
/// whatever its length. After each update everything is rescaled so that w₁ + w₂ = 1 (§5.6).
struct Mixture {
    /// Power-heuristic placements (`PLACEMENT_POWER`); else the balance heuristic.
    power: bool,
    /// w₁: Σ over the capable vertices so far of their placement terms q·w₂·p_∂f/p_f.
    w1: f32,
    /// w₂: the density factor of "no differential vertex yet", (1 − q)^(capable vertices).
    w2: f32,
    /// v₁: Σ of the squared placement terms (power heuristic).
    v1: f32,
    /// The placement term of the chosen differential vertex, once one is chosen (power heuristic).
    chosen: f32,
    /// The differential vertex has been chosen.
    dx_taken: bool,
    /// w₁ + w₂ at the previous vertex before its update, in the current vertex's units.
    prev_sum: f32,
    /// v₁ + w₂² at the previous vertex before its update, in the current vertex's units.
    prev_sq: f32,
    /// Several targets (§5.8): the path's hero, the index of its target. w₁ then sums the terms
    /// of every target weighted by its probability p_k, and w₂ = Σ_k `hero_w2[k]`.
    hero: u32,
    /// Several targets: p_k (1 − q)^(vertices capable for k so far), rescaled as w₁ and w₂.
    hero_w2: [f32; MAX_HEROES as usize],
}

impl Mixture {
    fn new(power: bool) -> Mixture {
        Mixture {
            power,
            w1: 0.0,
            w2: 1.0,
            v1: 0.0,
            chosen: 0.0,
            dx_taken: false,
            prev_sum: 1.0,
            prev_sq: 1.0,
            hero: 0,
            hero_w2: [0.0; MAX_HEROES as usize],
        }
    }

    /// Several targets: the path's hero, drawn with probabilities `hero_p` from `u` (camera vertex,
    /// `DIM_HERO`), and the sums' start, w₂ = Σ_k p_k.
    fn pick_hero(&mut self, globals: &Globals, u: f32) {
        let p = [globals.hero_p0, globals.hero_p1, globals.hero_p2, globals.hero_p3];
        self.hero = globals.hero_count - 1;
        let mut cdf = 0.0f32;
        for k in 0..globals.hero_count.saturating_sub(1) {
            cdf += p[k as usize];
            if u < cdf {
                self.hero = k;
                break;
            }
        }
        self.hero_w2 = p;
        self.w2 = ((p[0] + p[1]) + p[2]) + p[3];
    }

    /// Several targets: next-event estimation's weight at a vertex capable for target `k`
    /// (`MAX_HEROES`: none) before its update (§5.8; `None`: a light without area).
    fn nee_weight_hero(&self, k: u32, q: f32, pdf_f: f32, pdf_d: f32, p_e: Option<f32>) -> f32 {
        let (w1, w2) = (self.w1, self.w2);
        let Some(p_e) = p_e else {
            return 1.0 / (w1 + w2);
        };
        let a = if k < MAX_HEROES { self.hero_w2[k as usize] } else { 0.0 };
        let qa = if k < MAX_HEROES { q * a } else { 0.0 };
        1.0 / (w1 + w2 + (w1 * pdf_f + qa * pdf_d + (a - qa) * pdf_f + (w2 - a) * pdf_f) / p_e)
    }

    /// Several targets: the update after a direction was sampled at a vertex capable for target
    /// `k` (`MAX_HEROES`: none), as [`Mixture::update`].
    fn update_hero(&mut self, k: u32, q: f32, pdf_f: f32, pdf_d: f32) -> Option<f32> {
        self.prev_sum = self.w1 + self.w2;
        if k >= MAX_HEROES {
            return Some(1.0);
        }
        let a = self.hero_w2[k as usize];
        self.w1 += q * a * pdf_d / pdf_f;
        self.hero_w2[k as usize] = a * (1.0 - q);
        let h = self.hero_w2;
        self.w2 = ((h[0] + h[1]) + h[2]) + h[3];
        let sum = self.w1 + self.w2;
        if !(sum > 0.0) {
            return None;
        }
        self.w1 /= sum;
        self.w2 /= sum;
        for h in &mut self.hero_w2 {
            *h /= sum;
        }
        self.prev_sum /= sum;
        Some(sum)
    }

    /// The placement factor of the technique that produced the path so far: the chosen vertex's
    /// term, or w₂ (no differential vertex yet).
    fn technique(&self) -> f32 {
        if self.dx_taken { self.chosen } else { self.w2 }
    }

    /// v₁ + w₂²: Σ of the squared placement factors of the path so far.
    fn squares(&self) -> f32 {
        self.v1 + self.w2 * self.w2
    }

    /// Next-event estimation's weight at a vertex (before its update) whose BSDF has densities
    /// `pdf_f`, `pdf_d` (p_∂f; `pdf_f` where not capable) toward an emitter sampled with density
    /// `p_e` (`None`: a light without area), `q_here` the vertex's decision probability (§5.3, §5.7).
    fn nee_weight(&self, q_here: f32, pdf_f: f32, pdf_d: f32, p_e: Option<f32>) -> f32 {
        let (w1, w2) = (self.w1, self.w2);
        match (self.power, p_e) {
            (false, None) => 1.0 / (w1 + w2),
            (false, Some(p_e)) => {
                1.0 / (w1 + w2 + (w1 * pdf_f + q_here * w2 * pdf_d + (1.0 - q_here) * w2 * pdf_f) / p_e)
            }
            (true, None) => self.technique() / self.squares(),
            (true, Some(p_e)) => {
                let (f, d, b) = (pdf_f / p_e, q_here * w2 * pdf_d / p_e, (1.0 - q_here) * w2 * pdf_f / p_e);
                self.technique() / (self.squares() + self.v1 * f * f + d * d + b * b)
            }
        }
    }

    /// [`Mixture::update_hero`] (with several targets, `hero`; `hero_here` the vertex's) or
    /// [`Mixture::update`], then marks the differential vertex as taken if this one is it: the
    /// factor the throughput must be divided by, or `None` if the sums vanished.
    #[allow(clippy::too_many_arguments)]
    fn advance(
        &mut self,
        hero: bool,
        hero_here: u32,
        capable: bool,
        use_dx: bool,
        q: f32,
        pdf_f: f32,
        pdf_d: f32,
    ) -> Option<f32> {
        let sum = if hero {
            self.update_hero(hero_here, q, pdf_f, pdf_d)
        } else {
            self.update(capable, use_dx, q, pdf_f, pdf_d)
        }?;
        self.dx_taken = self.dx_taken || use_dx;
        Some(sum)
    }

    /// The update after a direction was sampled at a vertex (`capable`: the vertex may be the
    /// differential one; `use_dx`: it is) with densities `pdf_f`, `pdf_d`: returns the factor
    /// w₁ + w₂ by which the throughput must be divided (1 at a vertex that is not capable), or
    /// `None` if the sums vanished.
    fn update(&mut self, capable: bool, use_dx: bool, q: f32, pdf_f: f32, pdf_d: f32) -> Option<f32> {
        self.prev_sum = self.w1 + self.w2;
        self.prev_sq = self.squares();
        if !capable {
            return Some(1.0);
        }
        let term = q * self.w2 * pdf_d / pdf_f;
        self.w1 += term;
        self.v1 += term * term;
        if use_dx {
            self.chosen = term;
        }
        self.w2 *= 1.0 - q;
        let sum = self.w1 + self.w2;
        if !(sum > 0.0) {
            return None;
        }
        self.w1 /= sum;
        self.w2 /= sum;
        self.chosen /= sum;
        self.v1 /= sum * sum;
        self.prev_sum /= sum;
        self.prev_sq /= sum * sum;
        Some(sum)
    }
}

pub use crate::contract::REPLAY_RESIDUAL_TOLERANCE;

/// Whether what a replay left over (`left`) is rounding of the path's radiance `total`.
pub fn replay_returned_to_zero(total: Vec3, left: Vec3) -> bool {
    let bound = REPLAY_RESIDUAL_TOLERANCE * (total.abs() + Vec3::splat(1e-6));
    left.abs().cmple(bound).all()
}

/// Where the GRAD terms of a replay go (the twin of `param_grad` in `shaders/lib/params.glsl`).
#[derive(Debug)]
pub enum GradSink<'a> {
    /// Primal mode: nothing.
    None,
    /// Reverse mode: Σ_c of each term added to the gradient of its parameter value (f64).
    Backward(&'a mut [f64]),
    /// Forward mode: the per-channel derivative by the values in `begin..end` (tangent 1 each).
    Forward {
        /// First value with tangent 1.
        begin: u32,
        /// One past the last.
        end: u32,
        /// The accumulated derivative of the sample's radiance.
        derivative: Vec3,
    },
}

impl GradSink<'_> {
    /// Adds a term for parameter value `offset`, kept per image channel.
    pub fn add(&mut self, offset: u32, by_channel: Vec3) {
        match self {
            GradSink::None => {}
            GradSink::Backward(grads) => {
                grads[offset as usize] += f64::from(by_channel.x + by_channel.y + by_channel.z)
            }
            GradSink::Forward { begin, end, derivative } => {
                if offset >= *begin && offset < *end {
                    *derivative += by_channel;
                }
            }
        }
    }

    /// An RGB parameter: image channel c depends only on value c.
    pub fn add_rgb(&mut self, offset: u32, by_channel: Vec3) {
        self.add(offset, Vec3::new(by_channel.x, 0.0, 0.0));
        self.add(offset + 1, Vec3::new(0.0, by_channel.y, 0.0));
        self.add(offset + 2, Vec3::new(0.0, 0.0, by_channel.z));
    }
}

/// Next-event estimation's two uniforms for an environment map's cell at `vertex` (block 2); zero,
/// and not drawn, without a map.
fn env_cell_uniforms(globals: &Globals, key: RngKey, pixel: u32, sample: u32, vertex: u32) -> Vec2 {
    if globals.env_width == 0 {
        return Vec2::ZERO;
    }
    let u = draw_block(key, pixel, sample, vertex, DIM_ENV_CELL / 4);
    let d = (DIM_ENV_CELL % 4) as usize;
    Vec2::new(u[d], u[d + 1])
}

/// Adds `g` times the derivative of NEE's emitter sample's radiance to `sink`.
fn emitter_backward(flat: &FlatScene, globals: &Globals, es: &EmitterSample, g: Vec3, sink: &mut GradSink<'_>) {
    if es.environment {
        env_backward(globals, es.point, g, sink)
    } else if es.delta && es.param & LIGHT_SLOT != 0 {
        light_backward(flat, &flat.lights[(es.param & !LIGHT_SLOT) as usize], es.from, g * es.factor, sink)
    } else {
        area_backward(flat, es.param, es.uv, g * es.factor, sink)
    }
}

/// One camera path of `view` through `pixel` (row-major index) for sample `sample`: its radiance (primal,
/// `ADJOINT = false`), or — replaying from `radiance_total` with adjoint radiance `adj_radiance`
/// (δL) and scattering the GRAD terms into `sink` — what is left of it at the end, 0 up to
/// rounding (adjoint, ALGORITHMS.md §3.3).
///
/// With attached sampling (`Globals::jac_noise` > 0, `crate::attached`) the primal pass also
/// needs δL (`adj_radiance`) and writes Γ, the adjoint-weighted derivative of the path's radiance
/// by the camera ray, into `gamma`; the replay starts from that Γ and leaves its residual there
/// (0 up to rounding, like the radiance).
// The arguments are those of `path_begin` in the kernels, one for one.
#[allow(clippy::too_many_arguments)]
pub fn trace_path<const ADJOINT: bool>(
    flat: &FlatScene,
    globals: &Globals,
    view: &ViewCamera,
    pixel: u32,
    sample: u32,
    adj_radiance: Vec3,
    radiance_total: Vec3,
    sink: &mut GradSink<'_>,
    gamma: &mut Row6,
) -> Vec3 {
    // ---- camera ray ----
    let key = RngKey([globals.key0, view.key1]);
    let u_cam = draw_block(key, pixel, sample, 0, DIM_PIXEL_JITTER / 4);
    let (px, py) = (pixel % globals.width, pixel / globals.width);
    let (kind, radius, alpha) = (view.filter_kind, view.filter_radius, view.filter_alpha);
    let fx = crate::sampling::filter_sample(kind, radius, alpha, px, globals.width, u_cam[0]);
    let fy = crate::sampling::filter_sample(kind, radius, alpha, py, globals.height, u_cam[1]);
    let sx = 2.0 * fx / globals.width as f32 - 1.0;
    let sy = 1.0 - 2.0 * fy / globals.height as f32;
    let mut ray = camera_ray(view, sx, sy, Vec2::new(u_cam[2], u_cam[3]));

    let mut throughput = Vec3::ONE; // β (ALGORITHMS.md §3.1)
    let mut radiance = if ADJOINT { radiance_total } else { Vec3::ZERO }; // L (adjoint: the suffix)
    let sign = if ADJOINT { -1.0 } else { 1.0 };
    let diff = globals.strategy == STRATEGY_DIFF;
    let nee = globals.nee != 0;
    let mut prev_pdf_f = 0.0f32; // density with which the previous vertex sampled ray.dir
    let mut prev_nee = false; // whether NEE at the previous vertex could have found this emitter
    let mut mix = Mixture::new(diff && globals.diff_placement == PLACEMENT_POWER); // §5.2, §5.7
    let hero = diff && globals.hero_count > 0; // several targets, §5.8
    if hero {
        mix.pick_hero(globals, draw_block(key, pixel, sample, 0, DIM_HERO / 4)[(DIM_HERO % 4) as usize]);
    }
    let media = medium::has_media(flat);
    let mut current = NO_MEDIUM; // the medium the path is in (cameras are in vacuum)
    // Attached sampling (crate::attached): the primal pass's J̃ (camera ray → this vertex's
    // incoming ray), S per channel (Σ ∂ln w·J̃ so far) and Γ; the replay's Φ.
    let attached = globals.attached != 0;
    // The plane the current ray leaves (the camera ray's: the one across its own direction).
    let mut prev_normal = ray.dir;
    let mut jac = Jac6::IDENTITY;
    let mut log_rows = [Row6::ZERO; 3];
    let mut phi = if ADJOINT { *gamma } else { Row6::ZERO };
    // Depth counting (`Globals::path_flags`): `depth` is the number of counted interactions before
    // the vertex (Mitsuba's `depth`), which max_depth caps; the random numbers stay keyed by
    // `vertex`. Every interaction counts (path, prb) unless null events go uncounted (volpath):
    // a thindielectric's straight-through transmission or a mask's pass-through.
    let null_free = globals.path_flags & PATH_NULL_UNCOUNTED != 0;
    let hide = globals.path_flags & PATH_HIDE_EMITTERS != 0;
    let mut depth = 0u32;
    for vertex in 1..=MAX_PATH_VERTICES {
        // No counted interaction may follow this vertex: it only gathers what it hits.
        let last = depth + 1 >= globals.max_depth || vertex >= MAX_PATH_VERTICES;
        // An uncounted (null) event may still follow it.
        let null_ok = null_free && vertex < MAX_PATH_VERTICES;
        // hide_emitters: before the first counted interaction, rays pass through emitting shapes
        // and the environment adds nothing.
        let hidden = hide && depth == 0;
        // ---- intersection: through null boundaries and null collisions to the next event ----
        let mut travelled = 0.0f32; // from the last vertex to `ray.origin`, across null boundaries
        let mut step = 0u32; // delta-tracking steps of this vertex
        let mut crossings = 0u32;
        let mut crossed_null = false; // path counting: an emitter behind a null boundary is seen
        let event = loop {
            let hit = closest_hit(&flat.bvh, &ray, 0.0, f32::MAX);
            if media && current != NO_MEDIUM {
                let t_max = hit.as_ref().map_or(f32::MAX, |h| h.t);
                let m = &flat.media[current as usize];
                let counters = (pixel, sample, vertex);
                let grad = if ADJOINT { Some((&mut *sink, adj_radiance * radiance)) } else { None };
                if let Some(t) =
                    medium::delta_track(flat, key, m, &ray, t_max, counters, &mut step, &mut throughput, grad)
                {
                    break Event::Medium(ray.origin + t * ray.dir);
                }
            }
            let Some(hit) = hit else { break Event::Escape };
            let s = surface_at(flat, &hit);
            let skip = hidden && (null_free || !crossed_null) && s.emitter != NO_EMITTER;
            let null = media && flat.materials[s.material as usize].tag == MAT_NULL;
            if !(null || skip) {
                break Event::Surface(hit, s);
            }
            crossings += 1;
            if crossings > MAX_NULL_CROSSINGS {
                break Event::Lost;
            }
            if !skip {
                // (A hidden emitter's shape is passed as Mitsuba passes it: no medium changes.)
                let interior = flat.mesh_of(hit.slot).interior;
                current = medium::medium_crossed(interior, s.ng, ray.dir, current);
                crossed_null = true;
            }
            travelled += hit.t;
            ray = Ray::new(offset_origin(s.p, s.ng, ray.dir), ray.dir);
        };
        let (hit, s) = match event {
            Event::Lost => break,
            Event::Escape => {
                // ---- environment hit ----
                if globals.env_param != NO_PARAM && !hidden {
                    // Attached sampling's next-event estimation leaves the environment to BSDF
                    // samples (its density jumps between the map's cells).
                    let prev_nee = prev_nee && !attached;
                    let w_b = hit_weight(diff, prev_nee, prev_pdf_f, environment_pdf(flat, globals, ray.dir), &mix);
                    let le = env_radiance(flat, globals, ray.dir);
                    radiance += sign * (throughput * w_b * le);
                    if ADJOINT {
                        env_backward(globals, ray.dir, adj_radiance * throughput * w_b, sink);
                    }
                    if attached {
                        // The environment's own row: δL·β·∂L_e/∂d.
                        let weight = adj_radiance * throughput * w_b;
                        let own = Row6::direction(env_radiance_gradient(flat, globals, ray.dir).transpose() * weight);
                        if ADJOINT {
                            phi = phi.add_scaled(own, -1.0);
                        } else {
                            phi = add_contribution(phi, own.through(&jac), weight * le, &log_rows);
                        }
                    }
                }
                break;
            }
            Event::Medium(x) => {
                if last || !(max_component(throughput) > 0.0) {
                    break;
                }
                let m = &flat.media[current as usize];
                let d = ray.dir;
                // The differential strategy may place its vertex here if g is its target (§8.4).
                let hero_here = if hero { medium_hero(globals, m) } else { MAX_HEROES };
                let capable = if hero {
                    hero_here < MAX_HEROES
                } else {
                    diff && medium::medium_capable(m, globals.diff_begin, globals.diff_end)
                };
                // ---- emitter sampling from the medium ----
                let u_em = draw_block(key, pixel, sample, vertex, DIM_EMITTER_SELECT / 4);
                let pos = (DIM_EMITTER_POS % 4) as usize;
                let u_select = u_em[(DIM_EMITTER_SELECT % 4) as usize];
                let es = if nee {
                    let u_cell = env_cell_uniforms(globals, key, pixel, sample, vertex);
                    sample_emitter(flat, globals, u_select, (Vec2::new(u_em[pos], u_em[pos + 1]), u_cell), x)
                } else {
                    None
                };
                if let Some(es) = es {
                    let (wl, p_e, shadow_tmax) = if es.delta {
                        if es.distant {
                            (es.point, es.pdf, f32::MAX)
                        } else {
                            let dist = (es.point - x).length();
                            ((es.point - x).normalize(), es.pdf, dist * (1.0 - SHADOW_EPSILON))
                        }
                    } else if es.environment {
                        (es.point, environment_pdf(flat, globals, es.point), f32::MAX)
                    } else {
                        let to_light = es.point - x;
                        let dist = to_light.length();
                        let wl = to_light / dist;
                        (wl, emitter_pdf_solid_angle(globals, dist, es.normal.dot(-wl)), dist * (1.0 - SHADOW_EPSILON))
                    };
                    let f = medium::phase_eval(flat, m, d, wl);
                    if p_e > 0.0 && f > 0.0 {
                        let segment = (x, wl, shadow_tmax);
                        let counters = (pixel, sample, vertex);
                        let tr = medium::shadow_transmittance(flat, key, current, segment, counters, None);
                        // No phase sample reaches a light without area: NEE alone finds it.
                        let w_n = if !diff {
                            if es.delta { 1.0 } else { mis_power(p_e, f) }
                        } else if es.delta {
                            if hero {
                                mix.nee_weight_hero(MAX_HEROES, 0.0, 0.0, 0.0, None)
                            } else {
                                mix.nee_weight(0.0, 0.0, 0.0, None)
                            }
                        } else {
                            // Appendix B with the phase function as the vertex's BSDF (§8.4).
                            let pdf_d = if capable { medium::phase_pdf_diff(flat, m, d, wl) } else { f };
                            if hero {
                                mix.nee_weight_hero(hero_here, globals.diff_q, f, pdf_d, Some(p_e))
                            } else {
                                let q_here = if capable { globals.diff_q } else { 0.0 };
                                mix.nee_weight(q_here, f, pdf_d, Some(p_e))
                            }
                        };
                        let contribution = throughput * tr * w_n * f * es.radiance / p_e;
                        radiance += sign * contribution;
                        if ADJOINT && max_component(tr) > 0.0 {
                            let adj = adj_radiance * contribution;
                            medium::phase_grad(flat, m, d, wl, adj / f, sink);
                            medium::shadow_transmittance(
                                flat,
                                key,
                                current,
                                segment,
                                counters,
                                Some((&mut *sink, adj)),
                            );
                            emitter_backward(flat, globals, &es, adj_radiance * throughput * tr * w_n * f / p_e, sink);
                        }
                    }
                }
                // ---- phase or differential sampling ----
                let u_bs = draw_block(key, pixel, sample, vertex, DIM_LOBE / 4);
                let dir = (DIM_DIRECTION % 4) as usize;
                // Several targets: only the path's hero samples its derivative.
                let use_dx = capable
                    && (!hero || hero_here == mix.hero)
                    && !mix.dx_taken
                    && u_bs[(DIM_TECHNIQUE % 4) as usize] < globals.diff_q;
                let wo = if use_dx {
                    let u_sign =
                        draw_block(key, pixel, sample, vertex, DIM_DIFF_SIGN / 4)[(DIM_DIFF_SIGN % 4) as usize];
                    let u_comp = u_bs[(DIM_LOBE % 4) as usize];
                    medium::phase_sample_diff(flat, m, d, u_sign, u_comp, [u_bs[dir], u_bs[dir + 1]])
                } else {
                    medium::phase_sample(flat, m, d, [u_bs[dir], u_bs[dir + 1]])
                };
                let pdf = medium::phase_eval(flat, m, d, wo);
                if !(pdf > 0.0) {
                    break;
                }
                // The sample's density is the phase function itself: the weight f/pdf is 1; its
                // attached numerator f still has a derivative (through g).
                if ADJOINT {
                    medium::phase_grad(flat, m, d, wo, adj_radiance * radiance / pdf, sink);
                }
                prev_pdf_f = pdf;
                prev_nee = nee;
                if diff {
                    // The phase function's value is its density: β is unchanged before the division.
                    let pdf_d = if capable { medium::phase_pdf_diff(flat, m, d, wo) } else { 0.0 };
                    let Some(sum) = mix.advance(hero, hero_here, capable, use_dx, globals.diff_q, pdf, pdf_d) else {
                        break;
                    };
                    throughput /= sum;
                } else {
                    mix.prev_sum = 1.0;
                    mix.prev_sq = mix.squares();
                }
                if !path_survives(globals, key, (pixel, sample, vertex), depth, &mut throughput) {
                    break;
                }
                ray = Ray::new(x, wo);
                depth += 1;
                continue;
            }
            Event::Surface(hit, s) => (hit, s),
        };
        let wi_world = -ray.dir;

        // ---- emitter hit ----
        let cos_emit = s.ng.dot(wi_world);
        if s.emitter != NO_EMITTER && cos_emit > 0.0 {
            let distance = travelled + hit.t;
            let w_b =
                hit_weight(diff, prev_nee, prev_pdf_f, emitter_pdf_solid_angle(globals, distance, cos_emit), &mix);
            let p_radiance = flat.emitters[s.emitter as usize].p_radiance;
            radiance += sign * (throughput * w_b * area_radiance(flat, p_radiance, s.uv));
            if ADJOINT {
                area_backward(flat, p_radiance, s.uv, adj_radiance * throughput * w_b, sink);
            }
            if attached {
                // The emitter's own row, δL·β·∂L_e/∂r: a textured radiance varies with the hit
                // point (crate::cpu::slope); the weights of the vertices before depend on the ray.
                // After a diffuse vertex that sampled emitters, the MIS weight w_b = p_f²/(p_f² +
                // p_e²) moves with the ray too (p_f, the cosine sample's density, does not):
                // ∂ln w_b = −2(1 − w_b)·∂ln p_e.
                let weight = adj_radiance * throughput * w_b;
                let le = area_radiance(flat, p_radiance, s.uv);
                let at = HitGeometry { t: travelled + hit.t, d: ray.dir, ng: s.ng, n: s.ng, dn_dx: glam::Mat3::ZERO };
                let mut own = if area_textured(p_radiance) {
                    let slope = area_radiance_slope(flat, p_radiance, s.uv, &surface_gradients(flat, &hit));
                    at.position_row(slope[0] * weight.x + slope[1] * weight.y + slope[2] * weight.z)
                } else {
                    Row6::ZERO
                };
                if prev_nee {
                    let c = weight * le;
                    own = own.add_scaled(at.emitter_mis_row(w_b), c.x + c.y + c.z);
                }
                if ADJOINT {
                    phi = phi.add_scaled(own, -1.0);
                } else {
                    phi = add_contribution(phi, own.through(&jac), weight * le, &log_rows);
                }
            }
        }
        // ---- mask: the nested BSDF with probability `opacity`, else straight through ----
        // Mitsuba's `mask` samples its null transmission as a delta lobe that counts as a bounce
        // in its `path` and `prb` and not in its volpath family (null_free); the choice is drawn
        // first (u_lobe, rescaled for the nested BSDF as Mitsuba rescales it). In the replay the
        // attached weight opacity or 1 − opacity over its detached value gives the opacity its
        // derivative.
        let p_opacity = flat.materials[s.material as usize].p_opacity;
        let mut mask_opacity = 1.0f32; // a masked surface's opacity (1: no mask)
        if (!last || null_ok) && p_opacity != NO_PARAM {
            mask_opacity = mask_opacity_at(flat, p_opacity, s.tex_at());
            let u_mask = draw_block(key, pixel, sample, vertex, DIM_LOBE / 4)[(DIM_LOBE % 4) as usize];
            let passes = !(u_mask < mask_opacity);
            if ADJOINT {
                let g = adj_radiance * radiance * if passes { -1.0 / (1.0 - mask_opacity) } else { 1.0 / mask_opacity };
                opacity_backward(flat, p_opacity, s.tex_at(), g, sink);
            }
            if passes {
                // An emitter found through the pass counts whole: NEE could not have sampled it.
                prev_nee = false;
                if !path_survives(globals, key, (pixel, sample, vertex), depth, &mut throughput) {
                    break;
                }
                let interior = flat.mesh_of(hit.slot).interior;
                current = medium::medium_crossed(interior, s.ng, ray.dir, current);
                ray = Ray::new(offset_origin(s.p, s.ng, ray.dir), ray.dir);
                depth += u32::from(!null_free);
                continue;
            }
        }
        // At the last depth a thindielectric still samples under volpath counting: its
        // straight-through transmission is no bounce (its reflection ends the path below).
        let thin = flat.materials[s.material as usize].tag == MAT_THIN_DIELECTRIC;
        if last && !(null_ok && thin) {
            break;
        }

        let mut bsdf = resolve_bsdf(flat, s.material, s.tex_at());
        // A two-sided material seen from the back shades with the flipped normal.
        let mirrored = flat.materials[s.material as usize].two_sided != 0 && s.ns.dot(wi_world) < 0.0;
        let ns = if mirrored { -s.ns } else { s.ns };
        let mapped = material_normal_mapped(flat, s.material);
        let mut frame = if mapped || material_anisotropic(flat, s.material) {
            tangent_frame(ns, s.ng, s.dpdu)
        } else {
            Frame::from_normal(ns)
        };
        if mapped {
            let (perturbed, wrapper) =
                normal_map_frame(flat, &flat.materials[s.material as usize], &s, frame, mirrored, wi_world);
            frame = perturbed;
            bsdf.perturbed = Some(wrapper);
        }
        let wi = frame.to_local(wi_world);

        // Several targets: the one this vertex is capable for (MAX_HEROES: none).
        let hero_here = if hero { material_hero(flat, globals, s.material) } else { MAX_HEROES };
        let capable = if hero { hero_here < MAX_HEROES } else { diff && material_capable(flat, globals, s.material) };
        // An anisotropic roughness's target axis (a hero set holds no anisotropic roughness).
        let target_v = !hero && diff && material_target_v(flat, globals, s.material);

        // Attached sampling: where the ray meets this vertex (its Jacobians, below) and, at a
        // diffuse vertex, the albedo's slopes ∂ln a_c/∂x where it is textured (crate::cpu::slope).
        let geometry = attached.then(|| HitGeometry {
            t: travelled + hit.t, // from the vertex the ray left, across hidden emitters
            d: ray.dir,
            ng: s.ng,
            n: frame.n,
            dn_dx: shading_normal_gradient(flat, &hit) * if mirrored { -1.0 } else { 1.0 },
        });
        let diffuse_albedo = match (bsdf.blend, &bsdf.leaves[0]) {
            (false, Leaf::Diffuse { albedo }) if attached => Some(*albedo),
            _ => None,
        };
        let mut dln_albedo = [Vec3::ZERO; 3];
        if let Some(albedo) = diffuse_albedo {
            let m = &flat.materials[s.material as usize];
            if m.tex_width > 0 {
                let slope = albedo_slope(flat, m, s.tex_at(), &surface_gradients(flat, &hit));
                for c in 0..3 {
                    if albedo[c] > 0.0 {
                        dln_albedo[c] = slope[c] / albedo[c];
                    }
                }
            }
        }

        // ---- emitter sampling ----
        let u_em = draw_block(key, pixel, sample, vertex, DIM_EMITTER_SELECT / 4);
        let pos = (DIM_EMITTER_POS % 4) as usize;
        let u_select = u_em[(DIM_EMITTER_SELECT % 4) as usize];
        // A BSDF of delta lobes only gets no next-event estimation: no emitter sample can meet them.
        // Attached sampling estimates it at diffuse vertices alone, toward area emitters (their
        // point held fixed) and lights without area, not the environment (its density jumps
        // between cells).
        let nee_here = nee && !is_smooth(&bsdf) && (!attached || diffuse_albedo.is_some());
        let es = if nee_here {
            let u_cell = env_cell_uniforms(globals, key, pixel, sample, vertex);
            sample_emitter(flat, globals, u_select, (Vec2::new(u_em[pos], u_em[pos + 1]), u_cell), s.p)
                .filter(|es| !attached || !es.environment)
        } else {
            None
        };
        // The medium across this surface on each side: a shape's interior beyond a dielectric
        // boundary, else the path's current one.
        let interior = flat.mesh_of(hit.slot).interior;
        if let Some(es) = es {
            let (wl, p_e, shadow_tmax, origin) = if es.delta && es.distant {
                (es.point, es.pdf, f32::MAX, offset_origin(s.p, s.ng, es.point))
            } else if es.delta {
                let origin = offset_origin(s.p, s.ng, es.point - s.p);
                let to_light = es.point - origin;
                let dist = to_light.length();
                (to_light / dist, es.pdf, dist * (1.0 - SHADOW_EPSILON), origin)
            } else if es.environment {
                (es.point, environment_pdf(flat, globals, es.point), f32::MAX, offset_origin(s.p, s.ng, es.point))
            } else {
                let origin = offset_origin(s.p, s.ng, es.point - s.p);
                let to_light = es.point - origin;
                let dist = to_light.length();
                let wl = to_light / dist;
                (wl, emitter_pdf_solid_angle(globals, dist, es.normal.dot(-wl)), dist * (1.0 - SHADOW_EPSILON), origin)
            };
            let wo = frame.to_local(wl);
            let f = bsdf_eval(&bsdf, wi, wo);
            // The adjoint also traces the shadow ray where f is zero on the upper hemisphere (a
            // black BSDF): f's derivative there is not zero (Mitsuba's prb differentiates it too).
            let upper = wi.z > 0.0 && wo.z > 0.0;
            let tr = if !(p_e > 0.0 && (max_component(f) > 0.0 || (ADJOINT && upper))) {
                Vec3::ZERO
            } else if media {
                medium::shadow_transmittance(
                    flat,
                    key,
                    medium::medium_crossed(interior, s.ng, wl, current),
                    (origin, wl, shadow_tmax),
                    (pixel, sample, vertex),
                    None,
                )
            } else if occluded(&flat.bvh, &Ray::new(origin, wl), 0.0, shadow_tmax) {
                Vec3::ZERO
            } else {
                Vec3::ONE
            };
            if max_component(tr) > 0.0 {
                let pdf_f = bsdf_pdf(&bsdf, wi, wo);
                let w_n = if es.delta {
                    // No BSDF sample reaches a light without area: NEE alone finds it.
                    if hero {
                        mix.nee_weight_hero(MAX_HEROES, 0.0, 0.0, 0.0, None)
                    } else if diff {
                        mix.nee_weight(0.0, 0.0, 0.0, None)
                    } else {
                        1.0
                    }
                } else if !diff {
                    mis_power(p_e, pdf_f)
                } else {
                    // Appendix B: the NEE direction as produced by BSDF or differential sampling here.
                    let q_here = if capable { globals.diff_q } else { 0.0 };
                    let pdf_d = if capable { bsdf_pdf_diff(&bsdf, target_v, wi, wo) } else { pdf_f };
                    if hero {
                        mix.nee_weight_hero(hero_here, globals.diff_q, pdf_f, pdf_d, Some(p_e))
                    } else {
                        mix.nee_weight(q_here, pdf_f, pdf_d, Some(p_e))
                    }
                };
                radiance += sign * (throughput * tr * w_n * f * es.radiance / p_e);
                if let Some(geometry) = &geometry {
                    // Its own row: δL·C·∂ln C/∂r, through the hit point and the shading normal
                    // (crate::attached::HitGeometry::nee_gradient, delta_light_gradient, a
                    // spot's falloff) and the albedo's and a textured spot's slopes.
                    let c = adj_radiance * throughput * tr * w_n * f * es.radiance / p_e;
                    let dist = (es.point - origin).length();
                    let by_light = if es.delta {
                        geometry.delta_light_gradient(wl, if es.distant { 0.0 } else { 1.0 / dist }) + es.dln_falloff
                    } else {
                        geometry.nee_gradient(wl, dist, es.normal, w_n)
                    };
                    let mut g =
                        by_light * (c.x + c.y + c.z) + dln_albedo[0] * c.x + dln_albedo[1] * c.y + dln_albedo[2] * c.z;
                    if es.delta && es.param & LIGHT_SLOT != 0 {
                        // A textured spot (projectors are refused): c_k·∂ln texture_k/∂x.
                        let l = &flat.lights[(es.param & !LIGHT_SLOT) as usize];
                        let (rows, texture) = crate::cpu::slope::light_texture_slope(flat, l, es.from);
                        for k in 0..3 {
                            if texture[k] > 0.0 {
                                g += rows[k] * (c[k] / texture[k]);
                            }
                        }
                    }
                    let own = geometry.position_row(g);
                    if ADJOINT {
                        phi = phi.add_scaled(own, -1.0);
                    } else {
                        phi = add_contribution(phi, own.through(&jac), c, &log_rows);
                    }
                }
                if ADJOINT && media {
                    let segment = (origin, wl, shadow_tmax);
                    let weight = adj_radiance * throughput * tr * w_n * f * es.radiance / p_e;
                    let counters = (pixel, sample, vertex);
                    let start = medium::medium_crossed(interior, s.ng, wl, current);
                    medium::shadow_transmittance(flat, key, start, segment, counters, Some((&mut *sink, weight)));
                }
                if ADJOINT {
                    let adj = adj_radiance * throughput * tr * w_n * es.radiance / p_e;
                    bsdf_backward(flat, s.material, s.tex_at(), &bsdf, wi, wo, false, adj, sink);
                    emitter_backward(flat, globals, &es, adj_radiance * throughput * tr * w_n * f / p_e, sink);
                }
            }
        }

        // ---- BSDF or differential sampling ----
        let u_bs = draw_block(key, pixel, sample, vertex, DIM_LOBE / 4);
        let dir = (DIM_DIRECTION % 4) as usize;
        // A mask chose its nested BSDF with u_lobe < opacity: rescaled to [0, 1) for it.
        let u_lobe = u_bs[(DIM_LOBE % 4) as usize] / mask_opacity;
        let u_dir = Vec2::new(u_bs[dir], u_bs[dir + 1]);
        // Several targets: only the path's hero samples its derivative.
        let use_dx = capable
            && (!hero || hero_here == mix.hero)
            && !mix.dx_taken
            && u_bs[(DIM_TECHNIQUE % 4) as usize] < globals.diff_q;
        let mut rough_lobe = None; // attached sampling's rough-conductor lobe
        let mut glass_lobe = None; // attached sampling's rough-dielectric lobe
        let (bs, pdf_f, pdf_d) = if use_dx {
            let u_sign = draw_block(key, pixel, sample, vertex, DIM_DIFF_SIGN / 4)[(DIM_DIFF_SIGN % 4) as usize];
            let bs = bsdf_sample_diff(&bsdf, target_v, wi, u_sign, u_lobe, u_dir);
            let pdf_f = bs.as_ref().map_or(0.0, |b| bsdf_pdf(&bsdf, wi, b.wo));
            let pdf_d = bs.as_ref().map_or(0.0, |b| b.pdf);
            (bs, pdf_f, pdf_d)
        } else if let Some((lobe, specular)) =
            attached.then(|| rough_attached(&bsdf, ray.dir, frame.n, u_dir)).flatten()
        {
            // Attached sampling at a rough conductor: its own sampler (crate::attached::RoughLobe).
            let value = lobe.as_ref().map(|l| l.weight * specular * l.pdf);
            let bs = lobe.as_ref().zip(value).map(|(l, value)| BsdfSample {
                wo: frame.to_local(l.wo),
                pdf: l.pdf,
                value,
                delta: false,
            });
            rough_lobe = lobe;
            let pdf_f = bs.as_ref().map_or(0.0, |b| b.pdf);
            (bs, pdf_f, 0.0)
        } else if let Some((lobe, reflectance, transmittance)) =
            attached.then(|| rough_glass_attached(&bsdf, ray.dir, frame.n, u_dir, u_lobe)).flatten()
        {
            // Attached sampling at a rough dielectric: its own sampler
            // (crate::attached::RoughDielectricLobe); its density holds the lobe's choice.
            let bs = lobe.as_ref().map(|l| BsdfSample {
                wo: frame.to_local(l.wo),
                pdf: l.pdf,
                value: l.weight * l.pdf * if l.transmitted { transmittance } else { reflectance },
                delta: false,
            });
            glass_lobe = lobe;
            let pdf_f = bs.as_ref().map_or(0.0, |b| b.pdf);
            (bs, pdf_f, 0.0)
        } else {
            let bs = bsdf_sample(&bsdf, wi, u_lobe, u_dir);
            let pdf_f = bs.as_ref().map_or(0.0, |b| b.pdf);
            let pdf_d = match &bs {
                Some(b) if capable => bsdf_pdf_diff(&bsdf, target_v, wi, b.wo),
                _ => 0.0,
            };
            (bs, pdf_f, pdf_d)
        };
        // An invalid differential sample ends the path unmarked (ALGORITHMS.md §5.5 ruling 3).
        let Some(bs) = bs else {
            break;
        };
        if !(pdf_f > 0.0) {
            break;
        }
        throughput *= bs.value / pdf_f;
        prev_pdf_f = pdf_f;
        // An emitter found through a delta lobe counts whole: NEE could not have sampled it.
        prev_nee = nee_here && !bs.delta;
        let Some(sum) = mix.advance(hero, hero_here, capable, use_dx, globals.diff_q, pdf_f, pdf_d) else {
            break;
        };
        throughput /= sum;
        // A thindielectric's straight-through transmission: Mitsuba's null lobe.
        let null_lobe = null_free && thin && wi.z * bs.wo.z < 0.0;
        if last && !null_lobe {
            break;
        }

        // ---- Russian roulette ----
        if !path_survives(globals, key, (pixel, sample, vertex), depth, &mut throughput) {
            break;
        }
        // The path continues: everything later in `radiance` carries the factor f̂(wi, wo).
        if ADJOINT {
            let adj = adj_radiance * safe_div(radiance, bs.value);
            if rough_lobe.is_some() || glass_lobe.is_some() {
                // The roughness's derivative is the attached lobe's own (below).
                bsdf_backward_but_alpha(flat, s.material, s.tex_at(), &bsdf, wi, bs.wo, adj, sink);
            } else {
                bsdf_backward(flat, s.material, s.tex_at(), &bsdf, wi, bs.wo, bs.delta, adj, sink);
            }
        }
        // Attached sampling: the vertex's completed Jacobian for an outgoing direction d′ with
        // ∂d′/∂d = t_d, ∂d′/∂n = t_n — regularised, with Jacobian noise, from the vertex's
        // `Jacobian` stream.
        let vertex_jacobian = |g: &HitGeometry, t_d, t_n, d_out| {
            let a = g.jacobian(t_d, t_n).completed(prev_normal, ray.dir, s.ng, d_out);
            if globals.jac_noise > 0.0 {
                let u = uniform4(key, pixel, sample, vertex, Stream::Jacobian, 0, 0);
                a.plus_identity(regularisation(globals.jac_noise, u[0], u[1]))
            } else {
                a
            }
        };
        if let (Some(lobe), Some(geometry)) = (rough_lobe, &geometry) {
            let a = vertex_jacobian(geometry, lobe.t_d, lobe.t_n, lobe.wo);
            // ∂ln w/∂r per channel = common + (F′/F)_c · ∂c/∂r.
            let common = geometry.row(lobe.dlnw_dd, lobe.dlnw_dn);
            let c_row = geometry.row(lobe.dc_dd, lobe.dc_dn);
            if ADJOINT {
                let after = adj_radiance * radiance;
                // h = δL·(∂ln w/∂r ⊙ L_after); Φ′ = (Φ − h)·Ã⁻¹; α's two terms.
                let next = a.solve_row(
                    phi.add_scaled(common, -(after.x + after.y + after.z)).add_scaled(c_row, -after.dot(lobe.dlnf_dc)),
                );
                let direction = next.map_or(0.0, |n| n.d.dot(lobe.t_alpha));
                let by_alpha =
                    (after.x + after.y + after.z) * lobe.dlnw_dalpha + after.dot(lobe.dlnf_dc) * lobe.dc_dalpha;
                let m = &flat.materials[s.material as usize];
                if m.p_alpha != NO_PARAM {
                    sink.add(m.p_alpha, Vec3::new(by_alpha + direction, 0.0, 0.0));
                }
                phi = next.unwrap_or(Row6::ZERO);
            } else {
                let (common, c_row) = (common.through(&jac), c_row.through(&jac));
                for (c, log_row) in log_rows.iter_mut().enumerate() {
                    *log_row = log_row.add_scaled(common, 1.0).add_scaled(c_row, lobe.dlnf_dc[c]);
                }
                jac = a.compose(&jac);
            }
        }
        if let (Some(lobe), Some(geometry)) = (glass_lobe, &geometry) {
            let a = vertex_jacobian(geometry, lobe.t_d, lobe.t_n, lobe.wo);
            // ∂ln(w·P)/∂r, one row for the three channels (the colours are constants of the lobe).
            let row = geometry.row(lobe.dlnw_dd, lobe.dlnw_dn);
            if ADJOINT {
                let after = adj_radiance * radiance;
                let total = after.x + after.y + after.z;
                // h = δL·(∂ln w/∂r ⊙ L_after); Φ′ = (Φ − h)·Ã⁻¹; α's and η's two terms each.
                let next = a.solve_row(phi.add_scaled(row, -total));
                let along = |t: Vec3| next.map_or(0.0, |n| n.d.dot(t));
                let m = &flat.materials[s.material as usize];
                if m.p_alpha != NO_PARAM {
                    sink.add(m.p_alpha, Vec3::new(total * lobe.dlnw_dalpha + along(lobe.t_alpha), 0.0, 0.0));
                }
                // A rough dielectric's η parameter sits in `table` (crate::scene::flat).
                if m.table != NO_PARAM {
                    sink.add(m.table, Vec3::new(total * lobe.dlnw_deta + along(lobe.t_eta), 0.0, 0.0));
                }
                phi = next.unwrap_or(Row6::ZERO);
            } else {
                let row = row.through(&jac);
                for log_row in log_rows.iter_mut() {
                    *log_row = log_row.add_scaled(row, 1.0);
                }
                jac = a.compose(&jac);
            }
        }
        if let (Some(geometry), Some(_)) = (&geometry, diffuse_albedo) {
            // A diffuse vertex: its cosine sample follows the shading normal's frame alone and
            // its weight is the albedo, which varies with the hit point only where it is textured
            // (rows ∂ln a_c/∂r, crate::cpu::slope). The direction block of its Jacobian is
            // singular: direction noise regularises it, with the request's amplitude or
            // DIFFUSE_JACOBIAN_NOISE (crate::attached::Jac6::plus_direction_noise).
            let rows = dln_albedo.map(|g| geometry.position_row(g));
            let wo = frame.to_world(bs.wo);
            let u = uniform4(key, pixel, sample, vertex, Stream::Jacobian, 0, 0);
            let amplitude = if globals.jac_noise > 0.0 { globals.jac_noise } else { DIFFUSE_JACOBIAN_NOISE };
            let a = geometry
                .jacobian(glam::Mat3::ZERO, diffuse_direction_jacobian(frame.n, bs.wo))
                .completed(prev_normal, ray.dir, s.ng, wo)
                .plus_direction_noise(regularisation(amplitude, u[0], u[1]), ray.dir, wo);
            if ADJOINT {
                // h = δL·(∂ln w/∂r ⊙ L_after); Φ′ = (Φ − h)·Ã⁻¹.
                let after = adj_radiance * radiance;
                let phi_h =
                    phi.add_scaled(rows[0], -after.x).add_scaled(rows[1], -after.y).add_scaled(rows[2], -after.z);
                phi = a.solve_row(phi_h).unwrap_or(Row6::ZERO);
            } else {
                for (log_row, row) in log_rows.iter_mut().zip(rows) {
                    *log_row = log_row.add_scaled(row.through(&jac), 1.0);
                }
                jac = a.compose(&jac);
            }
        }
        if let (Some(geometry), Leaf::Smooth(leaf)) = (&geometry, &bsdf.leaves[0]) {
            let thin = leaf.kind == SmoothKind::ThinDielectric;
            let transmitted = wi.z * bs.wo.z < 0.0;
            let lobe = match leaf.kind {
                SmoothKind::Conductor => conductor_lobe(ray.dir, frame.n, leaf.eta, leaf.k),
                _ => smooth_lobe(thin, ray.dir, frame.n, leaf.eta.x, transmitted),
            };
            if let Some(lobe) = lobe {
                let a = vertex_jacobian(geometry, lobe.t_d, lobe.t_n, frame.to_world(bs.wo));
                let cos_row = geometry.cos_row();
                if ADJOINT {
                    // h_v = δL·(∂ln w/∂r ⊙ L_after); Φ_{v+1} = (Φ_v − h_v)·Ã⁻¹; η's two terms.
                    let after = adj_radiance * radiance;
                    let next = a.solve_row(phi.add_scaled(cos_row, -after.dot(lobe.dlnw_dcos)));
                    let m = &flat.materials[s.material as usize];
                    let p_eta = if m.tag == MAT_CONDUCTOR { NO_PARAM } else { m.p_weight };
                    let direction = next.map_or(0.0, |n| n.d.dot(lobe.t_eta));
                    if p_eta != NO_PARAM {
                        sink.add(p_eta, Vec3::new(after.dot(lobe.dlnw_deta) + direction, 0.0, 0.0));
                    }
                    phi = next.unwrap_or(Row6::ZERO);
                } else {
                    let row = cos_row.through(&jac);
                    for (c, log_row) in log_rows.iter_mut().enumerate() {
                        *log_row = log_row.add_scaled(row, lobe.dlnw_dcos[c]);
                    }
                    jac = a.compose(&jac);
                }
            }
        }

        let wo_world = frame.to_world(bs.wo);
        prev_normal = s.ng;
        // A direction through a dielectric boundary enters or leaves its shape's medium.
        current = medium::medium_crossed(interior, s.ng, wo_world, current);
        ray = Ray::new(offset_origin(s.p, s.ng, wo_world), wo_world);
        depth += u32::from(!null_lobe);
    }
    if attached {
        *gamma = phi;
    }
    radiance
}

/// Attached sampling's rough-conductor vertex: `Some` (the lobe, or `None` where its sample is
/// invalid, and the specular reflectance) where `bsdf` is one isotropic rough conductor, sampled
/// from incoming direction `d` at shading normal `n` with uniforms `u`.
fn rough_attached(bsdf: &Bsdf, d: Vec3, n: Vec3, u: Vec2) -> Option<(Option<RoughLobe>, Vec3)> {
    if bsdf.blend || bsdf.perturbed.is_some() {
        return None;
    }
    match bsdf.leaves[0] {
        Leaf::RoughConductor { distribution, alpha, alpha_v, specular, eta, k } if alpha == alpha_v => {
            let beckmann = distribution == Distribution::Beckmann;
            Some((rough_conductor_lobe(d, n, alpha, beckmann, [u.x, u.y], eta, k), specular))
        }
        _ => None,
    }
}

/// Attached sampling's rough-dielectric vertex: `Some` (the lobe, or `None` where its sample is
/// invalid, and the specular reflectance and transmittance) where `bsdf` is one isotropic rough
/// dielectric, sampled from incoming direction `d` at shading normal `n` with uniforms `u` (the
/// microfacet normal) and `u_lobe` (reflection or refraction).
fn rough_glass_attached(
    bsdf: &Bsdf,
    d: Vec3,
    n: Vec3,
    u: Vec2,
    u_lobe: f32,
) -> Option<(Option<RoughDielectricLobe>, Vec3, Vec3)> {
    if bsdf.blend || bsdf.perturbed.is_some() {
        return None;
    }
    match bsdf.leaves[0] {
        Leaf::RoughDielectric(ref l) if l.alpha == l.alpha_v => {
            let beckmann = l.distribution == Distribution::Beckmann;
            let lobe = rough_dielectric_lobe(d, n, l.alpha, beckmann, [u.x, u.y], u_lobe, l.eta);
            Some((lobe, l.reflectance, l.transmittance))
        }
        _ => None,
    }
}

/// Γ plus one contribution's row: `own` (its derivative by the camera ray) and `c` (δL ⊙ β ⊙ the
/// contribution) times the log-weight rows of the vertices before it.
fn add_contribution(gamma: Row6, own: Row6, c: Vec3, log_rows: &[Row6; 3]) -> Row6 {
    let mut g = Row6 { o: gamma.o + own.o, d: gamma.d + own.d };
    for (ch, row) in log_rows.iter().enumerate() {
        g = g.add_scaled(*row, c[ch]);
    }
    g
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The hero strategy's incremental sums (ALGORITHMS.md §5.8) against brute force: over random
    /// paths whose vertices are capable for target 0, 1 or neither, with random density ratios,
    /// probabilities p and q, the rescaled W₁ + W₂ times the product of the rescale factors equals
    /// Σ_k p_k (w₁ᵏ + w₂ᵏ) — the sum of every technique's density, each target's sums computed
    /// alone by §5.2 — and next-event estimation's weight at the last vertex is 1 over
    /// Σ_k p_k [w₁ᵏ + w₂ᵏ + (w₁ᵏ p_f + q_jᵏ w₂ᵏ p_∂f + (1 − q_jᵏ) w₂ᵏ p_f)/p_e], in the same units.
    #[test]
    fn hero_mixture_equals_the_sum_over_heroes_and_placements() {
        let mut next = crate::testing::xorshift64(0x2545_f491_4f6c_dd1d);
        let mut uniform = move || ((next() >> 40) as f64 + 0.5) / (1u64 << 24) as f64;
        for _ in 0..200 {
            let p0 = 0.05 + 0.9 * uniform();
            let q = (0.05 + 0.9 * uniform()) as f32;
            let globals =
                Globals { hero_count: 2, hero_p0: p0 as f32, hero_p1: (1.0 - p0) as f32, ..Globals::default() };
            let p = [f64::from(globals.hero_p0), f64::from(globals.hero_p1)];
            let mut mix = Mixture::new(false);
            mix.pick_hero(&globals, uniform() as f32);
            let mut scale = 1.0f64;
            let mut w = [(0.0f64, 1.0f64); 2];
            let vertices = 1 + (uniform() * 6.0) as usize;
            for _ in 0..vertices {
                let kind = (uniform() * 3.0) as u32;
                let k = if kind < 2 { kind } else { MAX_HEROES };
                let r = (0.01 + 20.0 * uniform().powi(3)) as f32;
                let pdf_f = (0.1 + uniform()) as f32;
                let sum = mix.update_hero(k, q, pdf_f, r * pdf_f).unwrap();
                scale *= f64::from(sum);
                if k < MAX_HEROES {
                    let (w1, w2) = &mut w[k as usize];
                    *w1 += f64::from(q) * *w2 * f64::from(r);
                    *w2 *= 1.0 - f64::from(q);
                }
            }
            let brute: f64 = (0..2).map(|k| p[k] * (w[k].0 + w[k].1)).sum();
            let incremental = f64::from(mix.w1 + mix.w2) * scale;
            assert!((incremental - brute).abs() <= 1e-5 * brute, "{incremental} vs {brute}");
            // Next-event estimation at one more vertex, capable for target `k` (or neither).
            let kind = (uniform() * 3.0) as u32;
            let k = if kind < 2 { kind } else { MAX_HEROES };
            let (pdf_f, pdf_d, p_e) =
                ((0.1 + uniform()) as f32, (0.1 + 3.0 * uniform()) as f32, (0.1 + uniform()) as f32);
            let (f, d, e) = (f64::from(pdf_f), f64::from(pdf_d), f64::from(p_e));
            let brute_d: f64 = (0..2)
                .map(|j| {
                    let qj = if k == j as u32 { f64::from(q) } else { 0.0 };
                    let (w1, w2) = w[j];
                    p[j] * (w1 + w2 + (w1 * f + qj * w2 * d + (1.0 - qj) * w2 * f) / e)
                })
                .sum();
            let weight = f64::from(mix.nee_weight_hero(k, q, pdf_f, pdf_d, Some(p_e))) / scale;
            assert!((weight * brute_d - 1.0).abs() <= 1e-5, "NEE weight {weight} vs 1/{brute_d}");
        }
    }
}

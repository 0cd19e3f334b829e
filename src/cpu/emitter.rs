//! Area emitters on triangles and the environment (constant or a map): sampling, radiance and
//! densities (twin of `shaders/lib/emitter.glsl`).

use glam::{Mat3, Vec2, Vec3};

use crate::contract::{
    DeltaLight, Globals, LIGHT_DIRECTIONAL, LIGHT_PROJECTOR, LIGHT_SLOT, LIGHT_SPOT, NO_PARAM, SCALAR_TEXTURE,
    TEXTURE_DESC_LEN,
};
use crate::cpu::path::GradSink;
use crate::cpu::surface::{param_color, texture_footprint};
use crate::sampling::{UNIFORM_SPHERE_PDF, sample_uniform_sphere, sample_uniform_triangle};
use crate::scene::envmap::{EnvMap, atan2_poly};
use crate::scene::flat::FlatScene;

/// A next-event sample: a point on an area emitter, or a direction toward the environment.
#[derive(Clone, Copy, Debug)]
pub struct EmitterSample {
    /// Position, or the direction when `environment`.
    pub point: Vec3,
    /// Unit normal of the emitting side.
    pub normal: Vec3,
    /// Emitted radiance.
    pub radiance: Vec3,
    /// Parameter offset of the radiance; for a textured light or projector, `LIGHT_SLOT` or-ed
    /// with its index ([`light_backward`] reaches its values).
    pub param: u32,
    /// Whether this samples the environment.
    pub environment: bool,
    /// Whether this is a light without area: `point` is its position, or (`distant`) the direction
    /// toward it; `radiance` is already divided by the distance² and weighted by a spot's falloff.
    pub delta: bool,
    /// A directional light.
    pub distant: bool,
    /// A light without area: the factor of its intensity in `radiance` (1 otherwise).
    pub factor: f32,
    /// A light without area: its selection probability.
    pub pdf: f32,
    /// A light without area: the shading point it was sampled from (its texture lookup).
    pub from: Vec3,
    /// A textured area emitter: the texture coordinates of `point`.
    pub uv: Vec2,
    /// A spot: the gradient of ln falloff by the shading point (0 in the beam and for every
    /// other light; attached sampling's next-event rows, [`spot_falloff_gradient`]).
    pub dln_falloff: Vec3,
}

/// Whether an area emitter's `p_radiance` is a texture's descriptor (`SCALAR_TEXTURE`).
pub fn area_textured(p: u32) -> bool {
    p != NO_PARAM && p & SCALAR_TEXTURE != 0
}

/// The texels (RGB at offset..offset+2) and weights of textured area radiance `p` at `uv` (its
/// `to_uv` applied; twin: `area_footprint` of shaders/lib/surface.glsl).
pub fn area_footprint(flat: &FlatScene, p: u32, uv: Vec2) -> ([u32; 4], [f32; 4]) {
    let d = (p & !SCALAR_TEXTURE) as usize;
    let desc = &flat.tables[d..d + TEXTURE_DESC_LEN as usize];
    let q = Vec3::new(uv.x, uv.y, 1.0);
    let t = Vec2::new(Vec3::new(desc[4], desc[5], desc[6]).dot(q), Vec3::new(desc[7], desc[8], desc[9]).dot(q));
    texture_footprint(desc[0].to_bits(), desc[1].to_bits(), desc[2].to_bits(), desc[3].to_bits(), t)
}

/// An area emitter's radiance at the texture coordinates `uv` of its point: its RGB parameter, or
/// its texture there.
pub fn area_radiance(flat: &FlatScene, p: u32, uv: Vec2) -> Vec3 {
    if !area_textured(p) {
        return param_color(flat, p);
    }
    let (texel, weight) = area_footprint(flat, p, uv);
    texel.into_iter().zip(weight).map(|(t, w)| param_color(flat, t) * w).sum()
}

/// Adds `g` times the derivative of area radiance `p` at `uv` to `sink`: its RGB parameter's,
/// or its texels' weighted as the lookup weighs them.
pub fn area_backward(flat: &FlatScene, p: u32, uv: Vec2, g: Vec3, sink: &mut GradSink<'_>) {
    if !area_textured(p) {
        sink.add_rgb(p, g);
        return;
    }
    let (texel, weight) = area_footprint(flat, p, uv);
    for (t, w) in texel.into_iter().zip(weight) {
        if w != 0.0 {
            sink.add_rgb(t, g * w);
        }
    }
}

/// The texture coordinates at barycentrics `b` = (b1, b2) of triangle `tri` (0 on a mesh without).
pub fn triangle_uv(flat: &FlatScene, tri: u32, b: Vec2) -> Vec2 {
    let tv = &flat.tri_vertices[tri as usize];
    let m = &flat.meshes[tv.mesh as usize];
    if m.uv_base == crate::contract::NO_ARRAY {
        return Vec2::ZERO;
    }
    let uv = |i: u32| flat.uvs[(m.uv_base + i) as usize];
    (1.0 - b.x - b.y) * uv(tv.i0) + b.x * uv(tv.i1) + b.y * uv(tv.i2)
}

/// A spot's falloff toward unit direction `d` from its position (Mitsuba's `falloff_curve`).
fn spot_falloff(l: &DeltaLight, d: Vec3) -> f32 {
    let c = l.axis.dot(d);
    let beam = if c >= l.cos_beam {
        1.0
    } else {
        (l.cutoff - atan2_poly((1.0 - c * c).max(0.0).sqrt(), c)) * l.inv_transition
    };
    if c > l.cos_cutoff { beam } else { 0.0 }
}

/// The gradient by the shading point x of ln falloff for a spot seen along unit `d` (from its
/// position toward x) at distance `dist`, where the falloff is `falloff` > 0. In the transition
/// zone falloff = (cutoff − θ)/transition with cos θ = axis·d, and ∂d/∂x = (I − d·dᵀ)/dist, so
/// ∂falloff/∂x = (axis − cos θ·d)/(transition·sin θ·dist); inside the beam it is 0.
pub fn spot_falloff_gradient(l: &DeltaLight, d: Vec3, dist: f32, falloff: f32) -> Vec3 {
    let c = l.axis.dot(d);
    let sin = (1.0 - c * c).max(0.0).sqrt();
    if c >= l.cos_beam || c <= l.cos_cutoff || sin <= 0.0 {
        return Vec3::ZERO;
    }
    (l.axis - c * d) * (l.inv_transition / (sin * dist * falloff))
}

/// What a textured spot or a projector `l` sends toward point `x`, apart from its parameters:
/// the texture coordinates of its lookup and its factor (a spot's falloff / distance², a
/// projector's π / (z² cos θ)); a factor of 0 where it sends nothing.
pub fn light_lookup(l: &DeltaLight, x: Vec3) -> (Vec2, f32) {
    let d = x - l.position;
    let local = Vec3::new(l.row0.dot(d), l.row1.dot(d), l.row2.dot(d));
    let uv = Vec2::splat(0.5) + l.uv_scale * Vec2::new(local.x, local.y) / local.z;
    let d2 = d.dot(d);
    if l.kind == LIGHT_PROJECTOR {
        let inside = local.z > 0.0 && uv.x >= 0.0 && uv.x <= 1.0 && uv.y >= 0.0 && uv.y <= 1.0;
        let cos_theta = l.axis.dot(d) / d2.sqrt();
        let factor = std::f32::consts::PI / (local.z * local.z * cos_theta);
        (if inside { uv } else { Vec2::ZERO }, if inside { factor } else { 0.0 })
    } else {
        let falloff = spot_falloff(l, d * (1.0 / d2.sqrt()));
        (if falloff > 0.0 { uv } else { Vec2::ZERO }, falloff / d2)
    }
}

/// The parameter part of what a textured spot or a projector sends at lookup `uv`: intensity (or
/// 1) × texture (or 1) × scale (or 1).
fn light_tint(flat: &FlatScene, l: &DeltaLight, uv: Vec2) -> Vec3 {
    let mut tint = if l.p_intensity != NO_PARAM { param_color(flat, l.p_intensity) } else { Vec3::ONE };
    if l.tex != NO_PARAM {
        tint *= texture_value(flat, l, uv);
    }
    if l.p_scale != NO_PARAM {
        tint *= flat.params[l.p_scale as usize];
    }
    tint
}

/// The bilinear (or nearest) read of a textured spot's or projector's texture at lookup `uv`.
pub(crate) fn texture_value(flat: &FlatScene, l: &DeltaLight, uv: Vec2) -> Vec3 {
    let (texel, weight) = texture_footprint(l.tex, l.tex_width, l.tex_height, l.tex_mode, uv);
    (0..4).fold(Vec3::ZERO, |acc, k| acc + param_color(flat, texel[k]) * weight[k])
}

/// Adds `g` times the derivative of what the textured spot or projector `l` sends toward `x`
/// (its factor included in `g`) by its intensity, texels and scale to `sink`.
pub fn light_backward(flat: &FlatScene, l: &DeltaLight, x: Vec3, g: Vec3, sink: &mut GradSink<'_>) {
    let (uv, _) = light_lookup(l, x);
    let intensity = if l.p_intensity != NO_PARAM { param_color(flat, l.p_intensity) } else { Vec3::ONE };
    let texture = if l.tex != NO_PARAM { texture_value(flat, l, uv) } else { Vec3::ONE };
    let scale = if l.p_scale != NO_PARAM { flat.params[l.p_scale as usize] } else { 1.0 };
    if l.p_intensity != NO_PARAM {
        sink.add_rgb(l.p_intensity, g * texture * scale);
    }
    if l.tex != NO_PARAM {
        let (texel, weight) = texture_footprint(l.tex, l.tex_width, l.tex_height, l.tex_mode, uv);
        for k in 0..4 {
            if weight[k] != 0.0 {
                sink.add_rgb(texel[k], g * intensity * (scale * weight[k]));
            }
        }
    }
    if l.p_scale != NO_PARAM {
        sink.add(l.p_scale, g * intensity * texture);
    }
}

/// The environment map that `globals` describe, if the environment is one.
pub fn env_map(globals: &Globals) -> Option<EnvMap> {
    (globals.env_width > 0).then(|| EnvMap {
        width: globals.env_width,
        height: globals.env_height,
        scale: globals.env_scale,
        to_local: Mat3::from_cols(globals.env_rot0, globals.env_rot1, globals.env_rot2).transpose(),
    })
}

/// The environment's radiance toward `dir`.
pub fn env_radiance(flat: &FlatScene, globals: &Globals, dir: Vec3) -> Vec3 {
    match env_map(globals) {
        None => param_color(flat, globals.env_param),
        Some(map) => {
            let (texels, weights) = map.footprint(dir);
            let sum = (0..4)
                .fold(Vec3::ZERO, |acc, k| acc + param_color(flat, globals.env_param + 3 * texels[k]) * weights[k]);
            map.scale * sum
        }
    }
}

/// The environment's radiance toward `dir` differentiated by the direction, channel by channel
/// (row c of the result is ∂L_c/∂d): zero for a constant environment.
pub fn env_radiance_gradient(flat: &FlatScene, globals: &Globals, dir: Vec3) -> Mat3 {
    match env_map(globals) {
        None => Mat3::ZERO,
        Some(map) => {
            let (texels, _, grads) = map.footprint_gradient(dir);
            // Σ_k texel_k (a column of channels) ⊗ ∇w_k, transposed into rows by channel.
            let sum = (0..4).fold(Mat3::ZERO, |acc, k| {
                acc + crate::attached::outer(param_color(flat, globals.env_param + 3 * texels[k]), grads[k])
            });
            map.scale * sum
        }
    }
}

/// Adds `g` times the derivative of the environment's radiance toward `dir` by its parameter
/// values (one RGB value, or the four texels of the map's lookup) to `sink`.
pub fn env_backward(globals: &Globals, dir: Vec3, g: Vec3, sink: &mut GradSink<'_>) {
    match env_map(globals) {
        None => sink.add_rgb(globals.env_param, g),
        Some(map) => {
            let (texels, weights) = map.footprint(dir);
            for k in 0..4 {
                if weights[k] != 0.0 {
                    sink.add_rgb(globals.env_param + 3 * texels[k], g * (map.scale * weights[k]));
                }
            }
        }
    }
}

/// A direction toward the environment: a map's cell drawn by its alias table (`u_cell`: column
/// and coin), then uniform in longitude and cos θ within it (`u_pos`); uniform for a constant.
pub fn env_sample(flat: &FlatScene, globals: &Globals, u_cell: Vec2, u_pos: Vec2) -> Vec3 {
    match env_map(globals) {
        None => sample_uniform_sphere(u_pos),
        Some(map) => map.sample(&flat.env_cells, u_cell, u_pos),
    }
}

/// With probability `env_select_prob` a direction toward the environment ([`env_sample`]); with
/// `light_select_prob` one of the lights without area, each equally likely, as seen from shading
/// point `x`; otherwise an emissive triangle with probability proportional to its area, then a
/// uniform point on it (area density: the rest of the probability over the total emissive area).
pub fn sample_emitter(
    flat: &FlatScene,
    globals: &Globals,
    u_select: f32,
    (u_pos, u_cell): (Vec2, Vec2),
    x: Vec3,
) -> Option<EmitterSample> {
    let none = EmitterSample {
        point: Vec3::ZERO,
        normal: Vec3::ZERO,
        radiance: Vec3::ZERO,
        param: globals.env_param,
        environment: false,
        delta: false,
        distant: false,
        factor: 1.0,
        pdf: 0.0,
        from: x,
        uv: Vec2::ZERO,
        dln_falloff: Vec3::ZERO,
    };
    if u_select < globals.env_select_prob {
        let dir = env_sample(flat, globals, u_cell, u_pos);
        return Some(EmitterSample {
            point: dir,
            radiance: env_radiance(flat, globals, dir),
            environment: true,
            ..none
        });
    }
    if u_select < globals.env_select_prob + globals.light_select_prob {
        let n = globals.light_count;
        let t = (u_select - globals.env_select_prob) / globals.light_select_prob;
        let index = ((t * n as f32) as u32).min(n - 1);
        let l = &flat.lights[index as usize];
        if l.tex != NO_PARAM || l.kind == LIGHT_PROJECTOR {
            let (uv, factor) = light_lookup(l, x);
            if !(factor > 0.0 && factor < f32::MAX) {
                return None;
            }
            let dln_falloff = if l.kind == LIGHT_SPOT {
                let d = x - l.position;
                let d2 = d.dot(d);
                let u = d * (1.0 / d2.sqrt());
                spot_falloff_gradient(l, u, d2.sqrt(), spot_falloff(l, u))
            } else {
                Vec3::ZERO
            };
            return Some(EmitterSample {
                point: l.position,
                radiance: light_tint(flat, l, uv) * factor,
                param: LIGHT_SLOT | index,
                delta: true,
                factor,
                pdf: globals.light_select_prob / n as f32,
                dln_falloff,
                ..none
            });
        }
        let (point, factor, dln_falloff) = if l.kind == LIGHT_DIRECTIONAL {
            (-l.axis, 1.0, Vec3::ZERO)
        } else {
            let d = x - l.position;
            let d2 = d.dot(d);
            let (falloff, slope) = if l.kind == LIGHT_SPOT {
                let (dist, u) = (d2.sqrt(), d * (1.0 / d2.sqrt()));
                let falloff = spot_falloff(l, u);
                let slope = if falloff > 0.0 { spot_falloff_gradient(l, u, dist, falloff) } else { Vec3::ZERO };
                (falloff, slope)
            } else {
                (1.0, Vec3::ZERO)
            };
            (l.position, falloff / d2, slope)
        };
        if !(factor > 0.0 && factor < f32::MAX) {
            return None;
        }
        return Some(EmitterSample {
            point,
            radiance: param_color(flat, l.p_intensity) * factor,
            param: l.p_intensity,
            delta: true,
            distant: l.kind == LIGHT_DIRECTIONAL,
            factor,
            pdf: globals.light_select_prob / n as f32,
            dln_falloff,
            ..none
        });
    }
    if flat.emitters.is_empty() {
        return None;
    }
    let taken = globals.env_select_prob + globals.light_select_prob;
    let u_select = (u_select - taken) / (1.0 - taken);
    let (mut lo, mut hi) = (0usize, flat.emitters.len() - 1);
    while lo < hi {
        let mid = (lo + hi) / 2;
        if flat.emitters[mid].cdf > u_select { hi = mid } else { lo = mid + 1 }
    }
    let e = &flat.emitters[lo];
    let b = sample_uniform_triangle(u_pos);
    let point = (1.0 - b.x - b.y) * e.v0 + b.x * e.v1 + b.y * e.v2;
    let normal = (e.v1 - e.v0).cross(e.v2 - e.v0).normalize();
    // A textured emitter is sampled by area too (Mitsuba samples its texture): the same
    // expectation, its radiance read at the point's texture coordinates.
    let uv = if area_textured(e.p_radiance) { triangle_uv(flat, e.tri, b) } else { Vec2::ZERO };
    Some(EmitterSample {
        point,
        normal,
        radiance: area_radiance(flat, e.p_radiance, uv),
        param: e.p_radiance,
        uv,
        ..none
    })
}

/// Solid-angle density of reaching an emitter point at `dist` whose normal makes cosine
/// `cos_emitter` with the direction back to the shading point.
pub fn emitter_pdf_solid_angle(globals: &Globals, dist: f32, cos_emitter: f32) -> f32 {
    if cos_emitter > 0.0 {
        let p = 1.0 - globals.env_select_prob - globals.light_select_prob;
        p * dist * dist / (cos_emitter * globals.emitter_total_area)
    } else {
        0.0
    }
}

/// Solid-angle density with which next-event estimation samples direction `dir` toward the
/// environment: its map cell's density, or uniform.
pub fn environment_pdf(flat: &FlatScene, globals: &Globals, dir: Vec3) -> f32 {
    match env_map(globals) {
        None => globals.env_select_prob * UNIFORM_SPHERE_PDF,
        Some(map) => globals.env_select_prob * map.pdf(&flat.env_cells, dir),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A spot's falloff slope against central differences of ln falloff, through the transition
    /// zone (both sides of the axis, near the beam and near the cutoff), and 0 inside the beam.
    #[test]
    fn spot_falloff_gradient_matches_central_differences() {
        let (cutoff, beam) = (30f32.to_radians(), 5f32.to_radians());
        let l = DeltaLight {
            kind: LIGHT_SPOT,
            position: Vec3::new(0.2, 1.5, -0.1),
            axis: Vec3::new(0.3, -1.0, 0.2).normalize(),
            cos_cutoff: cutoff.cos(),
            cos_beam: beam.cos(),
            cutoff,
            inv_transition: 1.0 / (cutoff - beam),
            ..DeltaLight::default()
        };
        let ln_falloff = |x: Vec3| {
            let d = x - l.position;
            f64::from(spot_falloff(&l, d / d.length())).ln()
        };
        let side = l.axis.cross(Vec3::Z).normalize();
        for (angle, turn) in [(7.0f32, 0.0f32), (12.0, 1.3), (20.0, 2.9), (27.0, 4.4), (15.0, 5.8)] {
            let off = glam::Quat::from_axis_angle(l.axis, turn) * side;
            let u = (l.axis * angle.to_radians().cos() + off * angle.to_radians().sin()).normalize();
            let x = l.position + 2.3 * u;
            let falloff = spot_falloff(&l, u);
            let g = spot_falloff_gradient(&l, u, 2.3, falloff);
            let h = 1e-3;
            for (axis, got) in [(Vec3::X, g.x), (Vec3::Y, g.y), (Vec3::Z, g.z)] {
                let fd = (ln_falloff(x + h * axis) - ln_falloff(x - h * axis)) / (2.0 * f64::from(h));
                let scale = f64::from(g.length());
                assert!(
                    (f64::from(got) - fd).abs() <= 0.01 * scale,
                    "{angle}° turn {turn}: gradient {got} vs central difference {fd} (|g| {scale})"
                );
            }
        }
        let inside = l.axis;
        assert_eq!(spot_falloff_gradient(&l, inside, 2.0, 1.0), Vec3::ZERO);
    }
}

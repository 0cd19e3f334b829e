//! `linearcurve`: Mitsuba's round linear curves (Embree's `ROUND_LINEAR_CURVE`) tessellated into
//! triangles to [`MAX_CHORD_ERROR_PX`](super::shapes::MAX_CHORD_ERROR_PX), with Mitsuba's UV.
//!
//! The surface, as Embree defines it (`kernels/geometry/roundline_intersector.h`) and Mitsuba
//! renders it in every variant: each segment from `p0`/`r0` to `p1`/`r1` is the cone that touches
//! the spheres `p0`/`r0` and `p1`/`r1` tangentially, plus the sphere at its end (and, for a curve's
//! first segment, the one at its start). The cone's normal at the angle φ is
//! `n(φ) = √(1 − s²)·ρ(φ) − s·a` with `a` the unit axis, `s = (r1 − r0)/|p1 − p0|` and ρ(φ) the
//! radial direction, and it touches sphere `i` at `p_i + r_i·n(φ)`: so a cone is exactly two rings
//! of vertices joined by straight lines, and only the angle is discretised.
//!
//! Mitsuba's UV (`linearcurve.cpp`, `compute_surface_interaction`): `u = φ/2π`, the angle about
//! the segment's axis from `u_rad = u_rot × a` towards `u_rot`, the part of +z (or +y, for an axis
//! along z) normal to the axis; `v = (v_local + segment)/segments` over all segments of the file,
//! where `v_local` runs 0 → 1 between the cone's tangent circles (Embree's `u`), and is 1 on a
//! segment's end sphere and 0 on a curve's start sphere. A joint's sphere is thus its incoming
//! segment's (Embree clips it where the outgoing cone begins, inside which it lies anyway), and
//! is tessellated about that segment's axis with constant `v`.

use std::f32::consts::TAU;

use glam::{Mat4, Vec2, Vec3, Vec4};

use super::shapes::{segments_for, unit_sphere};
use crate::scene::Camera;
use crate::scene::shapes::{Geometry, merge};

/// Mitsuba's frame about a segment's unit axis `a`: `(u_rad, u_rot)`, with `u_rot` the part of
/// +z normal to `a` (+y where `a` is ±z) and `u_rad = u_rot × a`.
fn local_frame(a: Vec3) -> (Vec3, Vec3) {
    let u_rot = if a.z.abs() == 1.0 { Vec3::Y } else { (Vec3::Z - a * a.z).normalize() };
    (u_rot.cross(a), u_rot)
}

/// The cone of one segment: `n` quads about the axis between the tangent circles, or nothing
/// where one sphere holds the other (`|p1 − p0| ≤ |r1 − r0|`, where Embree draws no cone either).
fn cone(c0: Vec4, c1: Vec4, n: u32, v: [f32; 2]) -> Option<Geometry> {
    let (p0, p1) = (c0.truncate(), c1.truncate());
    let d = p1 - p0;
    let length = d.length();
    let dr = c1.w - c0.w;
    if !(length > dr.abs()) {
        return None;
    }
    let a = d / length;
    let s = dr / length;
    let c = (1.0 - s * s).sqrt();
    let (u_rad, u_rot) = local_frame(a);
    let mut positions = Vec::new();
    let mut normals = Vec::new();
    let mut uvs = Vec::new();
    for j in 0..=n {
        let phi = TAU * j as f32 / n as f32;
        let normal = c * (phi.cos() * u_rad + phi.sin() * u_rot) - s * a;
        for (p, r, v) in [(p0, c0.w, v[0]), (p1, c1.w, v[1])] {
            positions.push(p + r * normal);
            normals.push(normal);
            uvs.push(Vec2::new(j as f32 / n as f32, v));
        }
    }
    let indices = (0..n).flat_map(|j| [[2 * j, 2 * j + 2, 2 * j + 3], [2 * j, 2 * j + 3, 2 * j + 1]]).collect();
    Some(Geometry { positions, normals: Some(normals), uvs: Some(uvs), indices, ..Default::default() })
}

/// The sphere at control point `c`, tessellated about the unit axis `a` of the segment it belongs
/// to (poles on ±a, `u = φ/2π` as that segment's cone), with constant `v`.
fn joint(c: Vec4, a: Vec3, n: u32, v: f32) -> Geometry {
    let (u_rad, u_rot) = local_frame(a);
    let m = Mat4::from_cols(
        (u_rad * c.w).extend(0.0),
        (u_rot * c.w).extend(0.0),
        (a * c.w).extend(0.0),
        c.truncate().extend(1.0),
    );
    let mut g = unit_sphere(n / 2, n).transformed(&m);
    if let Some(uvs) = &mut g.uvs {
        for uv in uvs {
            uv.y = v;
        }
    }
    g
}

/// The triangle mesh of `curves` (control points `(x, y, z, radius)` in world space: Mitsuba
/// transforms positions by `to_world` and leaves radii as they are), each segment's cone and
/// sphere divided into as many steps about the axis as [`segments_for`] asks of a circle of the
/// larger radius seen from `camera`. Zero-radius parts are left out (they have no area).
pub fn linear_curves(curves: &[Vec<Vec4>], camera: &Camera) -> Geometry {
    let total: usize = curves.iter().map(|c| c.len() - 1).sum();
    let mut parts = Vec::new();
    let mut segment = 0usize;
    for curve in curves {
        for (k, pair) in curve.windows(2).enumerate() {
            let (c0, c1) = (pair[0], pair[1]);
            let v0 = segment as f32 / total as f32;
            let v1 = (1.0 + segment as f32) / total as f32;
            let axis = (c1 - c0).truncate().normalize_or_zero();
            // A segment of coincident points has no axis: its spheres stand alone about +z.
            let axis = if axis == Vec3::ZERO { Vec3::Z } else { axis };
            let radius = c0.w.max(c1.w);
            if radius > 0.0 {
                let n = segments_for(camera, 0.5 * (c0 + c1).truncate(), radius, 1.0);
                parts.extend(cone(c0, c1, n, [v0, v1]));
            }
            if k == 0 && c0.w > 0.0 {
                parts.push(joint(c0, axis, segments_for(camera, c0.truncate(), c0.w, 2.0), v0));
            }
            if c1.w > 0.0 {
                parts.push(joint(c1, axis, segments_for(camera, c1.truncate(), c1.w, 2.0), v1));
            }
            segment += 1;
        }
    }
    merge(&parts)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn camera() -> Camera {
        Camera {
            position: Vec3::new(0.0, 0.0, 5.0),
            target: Vec3::ZERO,
            up: Vec3::Y,
            fov_y_degrees: 45.0,
            width: 64,
            height: 64,
            filter: crate::scene::PixelFilter::Box,
            lens: crate::scene::Lens::Pinhole,
            window: crate::scene::FilmWindow::default(),
        }
    }

    /// Mitsuba's `u` of a surface point `p` about axis point `c` (`linearcurve.cpp`).
    fn mitsuba_u(a: Vec3, c: Vec3, p: Vec3) -> f32 {
        let (u_rad, u_rot) = local_frame(a);
        let r = (p - c).normalize();
        let u = u_rot.dot(r).atan2(u_rad.dot(r));
        (if u < 0.0 { u + TAU } else { u }) / TAU
    }

    #[test]
    fn cone_vertices_lie_on_the_tangent_cone_with_mitsubas_uv() {
        let (c0, c1) = (Vec4::new(0.0, 0.0, 0.0, 0.2), Vec4::new(1.0, 2.0, 0.5, 0.5));
        let g = cone(c0, c1, 16, [0.25, 0.5]).unwrap();
        let a = (c1 - c0).truncate().normalize();
        for ((p, n), uv) in g.positions.iter().zip(g.normals.as_ref().unwrap()).zip(g.uvs.as_ref().unwrap()) {
            // On sphere 0 or 1, where the normal is the sphere's: the cone touches it there.
            let (c, r) = if uv.y == 0.25 { (c0.truncate(), c0.w) } else { (c1.truncate(), c1.w) };
            assert!(((*p - c).length() - r).abs() < 1e-5);
            assert!(((*p - c) / r - *n).length() < 1e-5);
            // Mitsuba's u is the angle of p − c about the axis (the seam's u = 1 is its 0).
            let u = mitsuba_u(a, c, *p);
            assert!((u - uv.x).abs() < 1e-4 || (u - uv.x).abs() > 1.0 - 1e-4, "{u} {}", uv.x);
        }
        // One sphere inside the other: no cone.
        assert!(cone(c0, Vec4::new(0.1, 0.0, 0.0, 0.4), 16, [0.0, 1.0]).is_none());
    }

    #[test]
    fn triangles_face_outwards() {
        let curves =
            vec![vec![Vec4::new(0.0, 0.0, 0.0, 0.1), Vec4::new(1.0, 0.0, 0.0, 0.2), Vec4::new(1.0, 0.0, 1.0, 0.1)]];
        let g = linear_curves(&curves, &camera());
        let normals = g.normals.as_ref().unwrap();
        for t in &g.indices {
            let [a, b, c] = t.map(|i| g.positions[i as usize]);
            let face = (b - a).cross(c - a);
            if face.length() > 1e-9 {
                let shading = normals[t[0] as usize] + normals[t[1] as usize] + normals[t[2] as usize];
                assert!(face.dot(shading) > 0.0, "triangle {t:?} faces inwards");
            }
        }
    }

    #[test]
    fn v_runs_over_all_segments_and_joints_take_the_incoming_segments_v() {
        let p = |x: f32, r: f32| Vec4::new(x, 0.0, 0.0, r);
        let curves = vec![vec![p(0.0, 0.1), p(1.0, 0.1)], vec![p(0.0, 0.1), p(1.0, 0.1), p(2.0, 0.1)]];
        let g = linear_curves(&curves, &camera());
        let uvs = g.uvs.as_ref().unwrap();
        let mut vs: Vec<f32> = uvs.iter().map(|uv| uv.y).collect();
        vs.sort_by(f32::total_cmp);
        vs.dedup();
        assert_eq!(vs, vec![0.0, 1.0 / 3.0, 2.0 / 3.0, 1.0]);
    }

    #[test]
    fn zero_radius_parts_are_left_out() {
        let curves = vec![vec![Vec4::new(0.0, 0.0, 0.0, 0.0), Vec4::new(1.0, 0.0, 0.0, 0.0)]];
        assert!(linear_curves(&curves, &camera()).indices.is_empty());
    }
}

//! `linearcurve` and `bsplinecurve`: Mitsuba's round linear and cubic B-spline curves (Embree's
//! `ROUND_LINEAR_CURVE`, `ROUND_BSPLINE_CURVE`) tessellated into triangles to
//! [`MAX_CHORD_ERROR_PX`](super::shapes::MAX_CHORD_ERROR_PX), with Mitsuba's UV.
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

use super::shapes::{MAX_CHORD_ERROR_PX, MAX_SEGMENTS, MIN_SEGMENTS, pixel_size, segments_for, unit_sphere};
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

/// One segment of a uniform cubic B-spline: control points `(x, y, z, radius)`.
#[derive(Clone, Copy)]
struct Spline([Vec4; 4]);

/// A point of a B-spline segment: the axis `c`, its first and second derivatives, the radius and
/// its derivative, all at the segment's parameter `t ∈ [0, 1]`.
struct SplinePoint {
    c: Vec3,
    dc: Vec3,
    ddc: Vec3,
    r: f32,
    dr: f32,
}

impl Spline {
    fn at(&self, t: f32) -> SplinePoint {
        let (t2, t3) = (t * t, t * t * t);
        let b = [
            (1.0 - 3.0 * t + 3.0 * t2 - t3) / 6.0,
            (4.0 - 6.0 * t2 + 3.0 * t3) / 6.0,
            (1.0 + 3.0 * t + 3.0 * t2 - 3.0 * t3) / 6.0,
            t3 / 6.0,
        ];
        let db = [(-1.0 + 2.0 * t - t2) / 2.0, (-4.0 * t + 3.0 * t2) / 2.0, (1.0 + 2.0 * t - 3.0 * t2) / 2.0, t2 / 2.0];
        let ddb = [1.0 - t, 3.0 * t - 2.0, 1.0 - 3.0 * t, t];
        let sum = |w: [f32; 4]| self.0.iter().zip(w).fold(Vec4::ZERO, |acc, (p, w)| acc + *p * w);
        let (p, dp, ddp) = (sum(b), sum(db), sum(ddb));
        SplinePoint { c: p.truncate(), dc: dp.truncate(), ddc: ddp.truncate(), r: p.w, dr: dp.w }
    }

    /// The surface point at `t` and angle `phi` about the tangent (Mitsuba's frame), with the
    /// unit normal of the surface Embree intersects: the circle of radius `r(t)` in the plane
    /// normal to the tangent. With `R = r·e` the radial vector, Mitsuba's normal
    /// `(|c′|² − R·c″)·R − r·r′·c′` (`bsplinecurve.cpp`) is taken divided by `r`, so it stays
    /// defined where the radius is 0.
    fn surface(&self, t: f32, phi: f32) -> (Vec3, Vec3) {
        let s = self.at(t);
        let (u_rad, u_rot) = local_frame(s.dc.normalize_or(Vec3::X));
        let e = phi.cos() * u_rad + phi.sin() * u_rot;
        let normal = ((s.dc.length_squared() - s.r * e.dot(s.ddc)) * e - s.dr * s.dc).normalize_or(e);
        (s.c + s.r * e, normal)
    }
}

/// The largest distance, in pixels, between a B-spline segment's surface and its tessellation
/// into `steps` × `around` cells, measured at the middle of every cell's diagonal (the point of a
/// triangle farthest from a smooth surface, to second order in the steps).
fn spline_error_px(spline: &Spline, steps: u32, around: u32, camera: &Camera) -> f32 {
    let mut worst = 0.0f32;
    for i in 0..steps {
        let (t0, t1) = (i as f32 / steps as f32, (i + 1) as f32 / steps as f32);
        let mid = spline.at(0.5 * (t0 + t1));
        let pixel = pixel_size(camera, mid.c, mid.r.max(0.0) + (spline.at(t0).c - mid.c).length());
        if !(pixel > 0.0) {
            return f32::INFINITY;
        }
        for j in 0..around {
            let (f0, f1) = (TAU * j as f32 / around as f32, TAU * (j + 1) as f32 / around as f32);
            let chord = 0.5 * (spline.surface(t0, f0).0 + spline.surface(t1, f1).0);
            let true_point = spline.surface(0.5 * (t0 + t1), 0.5 * (f0 + f1)).0;
            worst = worst.max((true_point - chord).length() / pixel);
        }
    }
    worst
}

/// Steps about a B-spline segment's axis: [`segments_for`]'s count for its largest radius with
/// half the error budget at the cells' diagonals (`cell = 4`), seen from the nearest point of the
/// ball that holds the segment (its control points' centroid, out to the farthest control point
/// plus the largest radius: a B-spline lies in its control points' convex hull).
fn spline_around(spline: &Spline, camera: &Camera) -> u32 {
    let radius = spline.0.iter().map(|p| p.w).fold(0.0f32, f32::max);
    let center = spline.0.iter().map(|p| p.truncate()).sum::<Vec3>() / 4.0;
    let reach = spline.0.iter().map(|p| (p.truncate() - center).length()).fold(0.0f32, f32::max);
    let pixel = pixel_size(camera, center, reach + radius);
    let delta = (8.0 * MAX_CHORD_ERROR_PX * pixel / (4.0 * radius)).sqrt();
    let n = if delta.is_finite() && delta > 0.0 { (TAU / delta).ceil() } else { MAX_SEGMENTS as f32 };
    let n = (n as u32).clamp(MIN_SEGMENTS, MAX_SEGMENTS);
    n + n % 2
}

/// Steps along a B-spline segment whose tessellation (with `around` steps about the axis) stays
/// within [`MAX_CHORD_ERROR_PX`]: the error of a step falls as its square, so each try scales the
/// count by the square root of the measured excess until the measurement is within the bound.
fn spline_steps(spline: &Spline, around: u32, camera: &Camera) -> u32 {
    let mut steps = 2u32;
    for _ in 0..12 {
        let error = spline_error_px(spline, steps, around, camera);
        if error <= MAX_CHORD_ERROR_PX || steps >= MAX_SEGMENTS {
            break;
        }
        let scale = if error.is_finite() { 1.1 * (error / MAX_CHORD_ERROR_PX).sqrt() } else { 4.0 };
        steps = ((steps as f32 * scale).ceil() as u32).max(steps + 1).min(MAX_SEGMENTS);
    }
    steps
}

/// The triangle mesh of `curves` as Mitsuba's `bsplinecurve` (control points `(x, y, z, radius)`
/// in world space: Mitsuba transforms positions by `to_world` and leaves radii as they are).
///
/// Every run of four consecutive control points is a segment of a uniform cubic B-spline of
/// positions and radii; the surface is what Embree's round B-spline intersector solves for, the
/// circle of radius `r(t)` normal to the tangent at every `t` (measured against Mitsuba 3.9.1:
/// its hit points lie on those circles to 2·10⁻⁷, not on the swept sphere's envelope), with
/// Mitsuba's normal and UV (`u` the angle about the tangent over 2π in Mitsuba's frame, `v =
/// (t + segment)/segments` over all segments of the file). The ends are open, as in Mitsuba.
/// A curve gets one count of steps about its axis (rings then match where its segments meet),
/// the largest [`spline_around`] of its segments; each segment then
/// gets as many steps along it as [`spline_steps`] measures. Segments of radius 0 throughout are
/// left out (they have no area).
pub fn bspline_curves(curves: &[Vec<Vec4>], camera: &Camera) -> Geometry {
    let total: usize = curves.iter().map(|c| c.len() - 3).sum();
    let mut parts = Vec::new();
    let mut segment = 0usize;
    for curve in curves {
        let splines: Vec<Spline> = curve.windows(4).map(|w| Spline([w[0], w[1], w[2], w[3]])).collect();
        let around = splines.iter().map(|s| spline_around(s, camera)).max().unwrap_or(MIN_SEGMENTS);
        for spline in &splines {
            let (k, total) = (segment as f32, total as f32);
            segment += 1;
            if spline.0.iter().all(|p| p.w == 0.0) {
                continue;
            }
            let steps = spline_steps(spline, around, camera);
            let mut positions = Vec::new();
            let mut normals = Vec::new();
            let mut uvs = Vec::new();
            for i in 0..=steps {
                let t = i as f32 / steps as f32;
                for j in 0..=around {
                    let (p, n) = spline.surface(t, TAU * j as f32 / around as f32);
                    positions.push(p);
                    normals.push(n);
                    uvs.push(Vec2::new(j as f32 / around as f32, (t + k) / total));
                }
            }
            let row = around + 1;
            // A ring of radius 0 is one point: the triangles with an edge on it have no area.
            let point: Vec<bool> = (0..=steps).map(|i| spline.at(i as f32 / steps as f32).r <= 0.0).collect();
            let point = &point;
            let indices = (0..steps)
                .flat_map(|i| {
                    (0..around).flat_map(move |j| {
                        let (a, b) = (i * row + j, (i + 1) * row + j);
                        let below = (!point[i as usize]).then_some([a, a + 1, b + 1]);
                        let above = (!point[i as usize + 1]).then_some([a, b + 1, b]);
                        below.into_iter().chain(above)
                    })
                })
                .collect();
            parts.push(Geometry { positions, normals: Some(normals), uvs: Some(uvs), indices, ..Default::default() });
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

    /// Every triangle of `g` with an area winds so that its face normal agrees with its vertices'
    /// shading normals.
    fn assert_faces_outwards(g: &Geometry) {
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
    fn triangles_face_outwards() {
        let curves =
            vec![vec![Vec4::new(0.0, 0.0, 0.0, 0.1), Vec4::new(1.0, 0.0, 0.0, 0.2), Vec4::new(1.0, 0.0, 1.0, 0.1)]];
        let g = linear_curves(&curves, &camera());
        assert_faces_outwards(&g);
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

    /// A curve whose radius varies fast: 0.05 → 0.6 → 0.05 over about one unit.
    fn wavy() -> Vec<Vec<Vec4>> {
        let p = |x: f32, y: f32, r: f32| Vec4::new(x, y, 0.0, r);
        vec![vec![p(-1.5, 0.0, 0.05), p(-0.5, 0.3, 0.6), p(0.5, -0.2, 0.05), p(1.5, 0.4, 0.6), p(2.5, 0.0, 0.05)]]
    }

    #[test]
    fn bspline_vertices_lie_on_circles_normal_to_the_tangent_with_mitsubas_uv_and_normal() {
        let curves = wavy();
        let g = bspline_curves(&curves, &camera());
        let splines: Vec<Spline> = curves[0].windows(4).map(|w| Spline([w[0], w[1], w[2], w[3]])).collect();
        for ((p, n), uv) in g.positions.iter().zip(g.normals.as_ref().unwrap()).zip(g.uvs.as_ref().unwrap()) {
            let v = uv.y * 2.0;
            let k = (v.floor() as usize).min(1);
            let s = splines[k].at(v - k as f32);
            let radial = *p - s.c;
            // On the circle of radius r(t) in the plane normal to c'(t) (Embree's surface).
            assert!((radial.length() - s.r).abs() < 1e-4, "{} {}", radial.length(), s.r);
            assert!(radial.dot(s.dc.normalize()).abs() < 1e-4);
            assert!((mitsuba_u(s.dc.normalize(), s.c, *p) - uv.x).abs() < 1e-3 || (uv.x - 1.0).abs() < 1e-6);
            // Mitsuba's normal: (|c'|² − R·c'')·R − r·r'·c', normalised.
            let mitsuba = ((s.dc.length_squared() - radial.dot(s.ddc)) * radial - s.r * s.dr * s.dc).normalize();
            assert!((mitsuba - *n).length() < 1e-3, "{mitsuba} {n}");
        }
        // v runs 0 → 1 over the file's two segments.
        let vs = g.uvs.as_ref().unwrap().iter().map(|uv| uv.y);
        assert_eq!(vs.clone().fold(f32::INFINITY, f32::min), 0.0);
        assert_eq!(vs.fold(0.0f32, f32::max), 1.0);
    }

    #[test]
    fn bspline_tips_of_radius_0_leave_no_degenerate_triangles() {
        let p = |x: f32, r: f32| Vec4::new(x, 0.2 * x * x, 0.0, r);
        let curves =
            vec![vec![p(-1.0, 0.0), p(-0.6, 0.0), p(-0.3, 0.0), p(0.0, 0.3), p(0.3, 0.0), p(0.6, 0.0), p(1.0, 0.0)]];
        let g = bspline_curves(&curves, &camera());
        assert!(!g.indices.is_empty());
        for t in &g.indices {
            let [a, b, c] = t.map(|i| g.positions[i as usize]);
            assert!((b - a).cross(c - a).length() > 0.0, "triangle {t:?} has no area");
        }
    }

    #[test]
    fn bspline_tessellation_stays_within_the_pixel_budget_and_faces_outwards() {
        let curves = wavy();
        let camera = camera();
        let g = bspline_curves(&curves, &camera);
        assert_faces_outwards(&g);
        // Measured independently on a finer grid of points inside the cells (not only the
        // diagonals' middles the step count was chosen by): within the budget, with 10 % for
        // the second-order estimate.
        for w in curves[0].windows(4) {
            let spline = Spline([w[0], w[1], w[2], w[3]]);
            let around = spline_around(&spline, &camera);
            let steps = spline_steps(&spline, around, &camera);
            assert!(spline_error_px(&spline, steps, around, &camera) <= MAX_CHORD_ERROR_PX);
            let mut worst = 0.0f32;
            for i in 0..steps {
                for j in 0..around {
                    for (a, b) in [(0.25, 0.5), (0.5, 0.25), (0.75, 0.5), (0.5, 0.75)] {
                        let (t, f) = ((i as f32 + a) / steps as f32, (j as f32 + b) / around as f32);
                        let corner = |di: u32, dj: u32| {
                            spline.surface((i + di) as f32 / steps as f32, TAU * (j + dj) as f32 / around as f32).0
                        };
                        // The point (a, b) of the cell on its triangles: below or above the diagonal.
                        let flat = if b <= a {
                            corner(0, 0) + (corner(1, 1) - corner(0, 0)) * b + (corner(1, 0) - corner(0, 0)) * (a - b)
                        } else {
                            corner(0, 0) + (corner(1, 1) - corner(0, 0)) * a + (corner(0, 1) - corner(0, 0)) * (b - a)
                        };
                        let truth = spline.surface(t, TAU * f).0;
                        let pixel = pixel_size(&camera, truth, 0.0);
                        worst = worst.max((truth - flat).length() / pixel);
                    }
                }
            }
            assert!(worst < 1.1 * MAX_CHORD_ERROR_PX, "{worst} px");
        }
    }
}

//! `sdfgrid`: Mitsuba's signed-distance grid, the zero set of the grid's trilinear interpolant,
//! tessellated to [`MAX_CHORD_ERROR_PX`] with Mitsuba's `smooth` or `analytic` normals.
//!
//! The surface, as Mitsuba 3.9.1 defines it (`src/shapes/sdfgrid.cpp`): the grid's `x·y·z` values
//! sit on the corners of `(x−1)·(y−1)·(z−1)` voxels filling the unit cube (object space, mapped by
//! `to_world`); inside a voxel the field is the trilinear interpolant of its eight corners, and
//! a ray hits the first root of that cubic along it in each voxel whose corners do not all share
//! one strict sign. So the surface is `{p : f(p) = 0}` of the piecewise-trilinear `f`, negative
//! inside. Its normals (`compute_surface_interaction`):
//! - `analytic`: `∇f` of the voxel holding the point (finite differences across the voxel, which
//!   are exact for a trilinear function), under `to_world`'s normal transform;
//! - `smooth` (the default): Hansson-Söderlund et al. 2022, the eight voxels around the point's
//!   nearest grid node each give their normalised `∇f` evaluated at the point (the grid's texture
//!   lookup, clamped at the edges), blended trilinearly by the point's offset from that node;
//!   voxels outside the grid's low end drop out.
//!
//! Mitsuba gives no UV (`(0, 0)` everywhere) and no area (no area emitters).
//!
//! The tessellation: every voxel with a sign change is cut into `k³` cells and each cell into the
//! six tetrahedra of the Kuhn triangulation (consistent between neighbours, so the mesh is
//! watertight); a tetrahedron whose corners change sign holds one or two triangles whose vertices
//! lie on its edges where the voxel's trilinear `f` is zero (solved on the edge, so every vertex
//! lies on Mitsuba's surface). One `k` serves the shape: starting from 2, each try scales it by
//! the square root of the measured excess until the largest distance between a triangle's
//! centroid or edge midpoints and the surface (`|f|/|∇f|` in world space, to first order) is
//! within [`MAX_CHORD_ERROR_PX`] of the pixel there. Vertex normals are Mitsuba's at the vertex,
//! interpolated across each triangle; with `analytic` normals a vertex is shared only within its
//! voxel (the gradient jumps between voxels).

use std::collections::HashMap;

use glam::{DVec3, Mat3, Mat4};

use super::shapes::{MAX_CHORD_ERROR_PX, pixel_size};
use crate::scene::Camera;
use crate::scene::shapes::Geometry;
use crate::scene::volume::Grid;

/// Most cells along a voxel's edge (a voxel then holds up to 2·32² triangles).
pub const MAX_CELLS: u32 = 32;

/// Mitsuba's two ways of shading an SDF grid (`normals`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Normals {
    /// The gradient of the voxel's trilinear interpolant at the point.
    Analytic,
    /// Hansson-Söderlund et al.'s blend of the eight neighbouring voxels' normals.
    Smooth,
}

/// A grid of signed distances over the unit cube: `res` nodes along each axis (at least 2), x
/// fastest.
#[derive(Clone, Debug)]
pub struct Sdf {
    res: [usize; 3],
    values: Vec<f64>,
}

impl Sdf {
    /// The SDF of a one-channel `.vol` grid, or why it cannot be one.
    ///
    /// # Errors
    /// A message for a grid of more than one channel, a resolution below 2 on an axis (no voxel),
    /// or a grid without a voxel the surface passes through (Mitsuba: "at least one non-empty
    /// voxel").
    pub fn new(grid: &Grid) -> std::result::Result<Sdf, String> {
        if grid.channels != 1 {
            return Err(format!("{} channels (an SDF grid has 1)", grid.channels));
        }
        let r = grid.resolution;
        if r.min_element() < 2 {
            return Err(format!(
                "resolution {}×{}×{}: an SDF grid needs at least 2 values on each axis",
                r.x, r.y, r.z
            ));
        }
        let sdf = Sdf {
            res: [r.x as usize, r.y as usize, r.z as usize],
            values: grid.values.iter().map(|&v| f64::from(v)).collect(),
        };
        if sdf.occupied().next().is_none() {
            return Err("no voxel's corners change sign: the surface is empty".into());
        }
        Ok(sdf)
    }

    fn at(&self, x: usize, y: usize, z: usize) -> f64 {
        self.values[x + self.res[0] * (y + self.res[1] * z)]
    }

    /// Voxels along each axis.
    fn voxels(&self) -> [usize; 3] {
        [self.res[0] - 1, self.res[1] - 1, self.res[2] - 1]
    }

    /// The corners of voxel `v`, index `x + 2y + 4z`.
    fn corners(&self, v: [usize; 3]) -> [f64; 8] {
        std::array::from_fn(|i| self.at(v[0] + (i & 1), v[1] + (i >> 1 & 1), v[2] + (i >> 2 & 1)))
    }

    /// The voxels whose corners do not all share one strict sign (Mitsuba's occupied voxels).
    fn occupied(&self) -> impl Iterator<Item = [usize; 3]> + '_ {
        let [nx, ny, nz] = self.voxels();
        (0..nz).flat_map(move |z| (0..ny).flat_map(move |y| (0..nx).map(move |x| [x, y, z]))).filter(|&v| {
            let c = self.corners(v);
            !(c.iter().all(|&f| f > 0.0) || c.iter().all(|&f| f < 0.0))
        })
    }

    /// Mitsuba's texture lookup: the trilinear interpolant at object-space `q`, clamped to the
    /// cube (the value at the nearest point of the grid beyond it).
    pub fn lookup(&self, q: DVec3) -> f64 {
        let mut base = [0usize; 3];
        let mut t = [0.0f64; 3];
        for a in 0..3 {
            let n = self.res[a] - 1;
            let x = (q[a] * n as f64).clamp(0.0, n as f64);
            let i = (x.floor() as usize).min(n - 1);
            base[a] = i;
            t[a] = x - i as f64;
        }
        trilinear(&self.corners(base), DVec3::from(t)).0
    }

    /// Mitsuba's `voxel_grad(p, v)`: the differences of [`Sdf::lookup`] across voxel `v`'s faces
    /// through `p`, over the voxel's size (object space; `v` may lie past the grid's high end).
    fn voxel_grad(&self, p: DVec3, v: [i64; 3]) -> DVec3 {
        let size =
            DVec3::new(1.0 / self.voxels()[0] as f64, 1.0 / self.voxels()[1] as f64, 1.0 / self.voxels()[2] as f64);
        let lo = DVec3::new(v[0] as f64, v[1] as f64, v[2] as f64) * size;
        let mut g = DVec3::ZERO;
        for a in 0..3 {
            let (mut p0, mut p1) = (p, p);
            p0[a] = lo[a];
            p1[a] = lo[a] + size[a];
            g[a] = (self.lookup(p1) - self.lookup(p0)) / size[a];
        }
        g
    }

    /// Mitsuba's `analytic` normal at object-space `p` in `voxel` (unnormalised, object space).
    pub fn analytic(&self, p: DVec3, voxel: [usize; 3]) -> DVec3 {
        self.voxel_grad(p, [voxel[0] as i64, voxel[1] as i64, voxel[2] as i64])
    }

    /// Mitsuba's `smooth` normal at object-space `p` (`smooth_sh`: unnormalised, object space).
    pub fn smooth(&self, p: DVec3) -> DVec3 {
        let n = self.voxels();
        let scaled = DVec3::new(p.x * n[0] as f64, p.y * n[1] as f64, p.z * n[2] as f64);
        let node = DVec3::new(scaled.x.round_ties_even(), scaled.y.round_ties_even(), scaled.z.round_ties_even());
        let v000 = [node.x as i64 - 1, node.y as i64 - 1, node.z as i64 - 1];
        let corner =
            |i: usize| [v000[0] + (i & 1) as i64, v000[1] + (i >> 1 & 1) as i64, v000[2] + (i >> 2 & 1) as i64];
        let valid: [bool; 8] = std::array::from_fn(|i| corner(i).iter().all(|&c| c >= 0));
        let normals: [DVec3; 8] =
            std::array::from_fn(
                |i| if valid[i] { self.voxel_grad(p, corner(i)).normalize_or_zero() } else { DVec3::ZERO },
            );
        let mut w = scaled - node + DVec3::splat(0.5);
        for a in 0..3 {
            let side = |s: usize| (0..8).filter(|&i| (i >> a & 1) == s).all(|i| !valid[i]);
            if side(0) {
                w[a] = 1.0;
            }
            if side(1) {
                w[a] = 0.0;
            }
        }
        (0..8)
            .map(|i| {
                let f = |a: usize| if i >> a & 1 == 1 { w[a] } else { 1.0 - w[a] };
                normals[i] * (f(0) * f(1) * f(2))
            })
            .sum()
    }
}

/// The trilinear interpolant of `c` (index `x + 2y + 4z`) at local `t` and its gradient in
/// local coordinates.
fn trilinear(c: &[f64; 8], t: DVec3) -> (f64, DVec3) {
    let lerp = |a: f64, b: f64, s: f64| a + (b - a) * s;
    let (x00, x10) = (lerp(c[0], c[1], t.x), lerp(c[2], c[3], t.x));
    let (x01, x11) = (lerp(c[4], c[5], t.x), lerp(c[6], c[7], t.x));
    let (y0, y1) = (lerp(x00, x10, t.y), lerp(x01, x11, t.y));
    let value = lerp(y0, y1, t.z);
    let dz = y1 - y0;
    let dy = lerp(x10 - x00, x11 - x01, t.z);
    let dx = lerp(lerp(c[1] - c[0], c[3] - c[2], t.y), lerp(c[5] - c[4], c[7] - c[6], t.y), t.z);
    (value, DVec3::new(dx, dy, dz))
}

/// The Kuhn triangulation of a cell: the six tetrahedra along its 0 → 7 diagonal, corners
/// indexed `x + 2y + 4z`.
const TETRAHEDRA: [[usize; 4]; 6] =
    [[0, 1, 3, 7], [0, 1, 5, 7], [0, 2, 3, 7], [0, 2, 6, 7], [0, 4, 5, 7], [0, 4, 6, 7]];

/// The tessellation of `sdf` with `cells` cells along each voxel edge, in object space, with
/// Mitsuba's `normals` (object space, unnormalised: [`Geometry::transformed`] applies the normal
/// transform and normalises).
pub fn tessellate(sdf: &Sdf, cells: u32, normals: Normals) -> Geometry {
    let k = cells as usize;
    let voxels = sdf.voxels();
    // Fine nodes along each axis, and a fine node's key.
    let fine = [voxels[0] * k + 1, voxels[1] * k + 1, voxels[2] * k + 1];
    let key = |g: [usize; 3]| (g[0] + fine[0] * (g[1] + fine[1] * g[2])) as u64;
    let to_object =
        |g: DVec3| DVec3::new(g.x / (voxels[0] * k) as f64, g.y / (voxels[1] * k) as f64, g.z / (voxels[2] * k) as f64);
    // A fine node's value, from the voxel it starts (the last one on the high faces): the same
    // number whichever voxel asks, so neighbours agree on signs.
    let node_value = |g: [usize; 3]| {
        let v: [usize; 3] = std::array::from_fn(|a| (g[a] / k).min(voxels[a] - 1));
        let t = DVec3::from(std::array::from_fn::<f64, 3, _>(|a| (g[a] - v[a] * k) as f64 / k as f64));
        trilinear(&sdf.corners(v), t).0
    };
    let mut crossings: HashMap<(u64, u64), DVec3> = HashMap::new();
    let mut vertices: HashMap<(u64, u64, u64), u32> = HashMap::new();
    let mut g = Geometry { normals: Some(Vec::new()), ..Default::default() };
    for voxel in sdf.occupied() {
        let c = sdf.corners(voxel);
        let voxel_key = if normals == Normals::Analytic { key(voxel) + 1 } else { 0 };
        for cell in 0..k * k * k {
            let cell = [cell % k, cell / k % k, cell / (k * k)];
            let nodes: [[usize; 3]; 8] =
                std::array::from_fn(|i| std::array::from_fn(|a| voxel[a] * k + cell[a] + (i >> a & 1)));
            let values: [f64; 8] = std::array::from_fn(|i| node_value(nodes[i]));
            if values.iter().all(|&f| f < 0.0) || values.iter().all(|&f| f >= 0.0) {
                continue;
            }
            for tet in TETRAHEDRA {
                let inside: Vec<usize> = tet.iter().copied().filter(|&i| values[i] < 0.0).collect();
                let outside: Vec<usize> = tet.iter().copied().filter(|&i| values[i] >= 0.0).collect();
                let quad: Vec<(usize, usize)> = match (inside.len(), outside.len()) {
                    (1, 3) => outside.iter().map(|&o| (inside[0], o)).collect(),
                    (3, 1) => inside.iter().map(|&i| (i, outside[0])).collect(),
                    (2, 2) => {
                        let ([a, b], [c, d]) = ([inside[0], inside[1]], [outside[0], outside[1]]);
                        vec![(a, c), (a, d), (b, d), (b, c)]
                    }
                    _ => continue,
                };
                let mut ids = Vec::with_capacity(4);
                for &(i, o) in &quad {
                    let (ki, ko) = (key(nodes[i]), key(nodes[o]));
                    let edge = (ki.min(ko), ki.max(ko));
                    let p = *crossings.entry(edge).or_insert_with(|| {
                        let local = |n: [usize; 3]| {
                            DVec3::from(std::array::from_fn::<f64, 3, _>(|a| (n[a] - voxel[a] * k) as f64 / k as f64))
                        };
                        let (a, b) = (local(nodes[i]), local(nodes[o]));
                        let t = edge_root(|s| trilinear(&c, a.lerp(b, s)).0, values[i], values[o]);
                        let fine_point = DVec3::from(std::array::from_fn::<f64, 3, _>(|ax| nodes[i][ax] as f64))
                            .lerp(DVec3::from(std::array::from_fn::<f64, 3, _>(|ax| nodes[o][ax] as f64)), t);
                        to_object(fine_point)
                    });
                    let id = *vertices.entry((edge.0, edge.1, voxel_key)).or_insert_with(|| {
                        let n = match normals {
                            Normals::Analytic => sdf.analytic(p, voxel),
                            Normals::Smooth => sdf.smooth(p),
                        };
                        g.positions.push(p.as_vec3());
                        g.normals.as_mut().expect("normals").push(n.as_vec3());
                        (g.positions.len() - 1) as u32
                    });
                    ids.push(id);
                }
                // Outward: from the inside corners towards the outside ones.
                let centroid = |s: &[usize]| {
                    s.iter()
                        .map(|&i| DVec3::new(cell[0] as f64, cell[1] as f64, cell[2] as f64) + corner(i))
                        .sum::<DVec3>()
                        / s.len() as f64
                };
                let out = centroid(&outside) - centroid(&inside);
                let tris: &[[usize; 3]] = if ids.len() == 3 { &[[0, 1, 2]] } else { &[[0, 1, 2], [0, 2, 3]] };
                for t in tris {
                    let [a, b, c] = t.map(|j| ids[j]);
                    let [pa, pb, pc] = [a, b, c].map(|v| g.positions[v as usize].as_dvec3());
                    let normal = (pb - pa).cross(pc - pa);
                    if normal == DVec3::ZERO || a == b || b == c || a == c {
                        continue;
                    }
                    // `out` in object space (the fine grid scaled by positive factors).
                    g.indices.push(if normal.dot(to_object(out)) > 0.0 { [a, b, c] } else { [a, c, b] });
                }
            }
        }
    }
    g
}

/// Corner `i` (`x + 2y + 4z`) of the unit cell.
fn corner(i: usize) -> DVec3 {
    DVec3::new((i & 1) as f64, (i >> 1 & 1) as f64, (i >> 2 & 1) as f64)
}

/// The zero of `f` on `[0, 1]`, where `f(0) = f0 < 0 ≤ f(1) = f1` (Illinois regula falsi, to
/// 10⁻¹² of the edge).
fn edge_root(f: impl Fn(f64) -> f64, f0: f64, f1: f64) -> f64 {
    let (mut a, mut b, mut fa, mut fb) = (0.0f64, 1.0f64, f0, f1);
    if fb == 0.0 {
        return 1.0;
    }
    let mut side = 0;
    for _ in 0..100 {
        let t = (a * fb - b * fa) / (fb - fa);
        let ft = f(t);
        if ft == 0.0 || b - a < 1e-12 {
            return t;
        }
        if (ft < 0.0) == (fa < 0.0) {
            a = t;
            fa = ft;
            if side == -1 {
                fb *= 0.5;
            }
            side = -1;
        } else {
            b = t;
            fb = ft;
            if side == 1 {
                fa *= 0.5;
            }
            side = 1;
        }
    }
    (a * fb - b * fa) / (fb - fa)
}

/// The largest distance, in pixels of `camera`'s film, between the tessellation `object` (object
/// space) of `sdf` under `to_world` and the surface: `|f|/|∇f|` (world space, first order) at each
/// triangle's centroid and edge midpoints, over the pixel size there.
pub fn error_px(sdf: &Sdf, object: &Geometry, to_world: &Mat4, camera: &Camera) -> f32 {
    let voxels = sdf.voxels();
    let normal_matrix = Mat3::from_mat4(*to_world).inverse().transpose().as_dmat3();
    let mut worst = 0.0f64;
    for t in &object.indices {
        let [a, b, c] = t.map(|v| object.positions[v as usize].as_dvec3());
        let reach = (b - a).length().max((c - a).length()) as f32;
        let world_reach = reach * Mat3::from_mat4(*to_world).to_cols_array().iter().map(|x| x * x).sum::<f32>().sqrt();
        let pixel =
            f64::from(pixel_size(camera, to_world.transform_point3(((a + b + c) / 3.0).as_vec3()), world_reach));
        if !(pixel > 0.0) {
            return f32::INFINITY;
        }
        for p in [(a + b + c) / 3.0, 0.5 * (a + b), 0.5 * (b + c), 0.5 * (c + a)] {
            let v: [usize; 3] =
                std::array::from_fn(|ax| ((p[ax] * voxels[ax] as f64).floor().max(0.0) as usize).min(voxels[ax] - 1));
            let local = DVec3::from(std::array::from_fn::<f64, 3, _>(|ax| p[ax] * voxels[ax] as f64 - v[ax] as f64));
            let (f, grad_local) = trilinear(&sdf.corners(v), local);
            let grad = DVec3::new(
                grad_local.x * voxels[0] as f64,
                grad_local.y * voxels[1] as f64,
                grad_local.z * voxels[2] as f64,
            );
            let world_grad = (normal_matrix * grad).length();
            let distance = if world_grad > 0.0 { f.abs() / world_grad } else { f64::INFINITY };
            worst = worst.max(distance / pixel);
        }
    }
    worst as f32
}

/// The mesh of `sdf` under `to_world` (world space) within [`MAX_CHORD_ERROR_PX`] on `camera`'s
/// film (see the module's notes), and the cells a voxel edge got.
pub fn sdf_mesh(sdf: &Sdf, normals: Normals, to_world: &Mat4, camera: &Camera) -> (Geometry, u32) {
    let mut cells = 2u32;
    let mut mesh = tessellate(sdf, cells, normals);
    for _ in 0..6 {
        let error = error_px(sdf, &mesh, to_world, camera);
        if error <= MAX_CHORD_ERROR_PX || cells >= MAX_CELLS {
            break;
        }
        let scale = if error.is_finite() { 1.1 * (error / MAX_CHORD_ERROR_PX).sqrt() } else { 4.0 };
        cells = ((cells as f32 * scale).ceil() as u32).max(cells + 1).min(MAX_CELLS);
        mesh = tessellate(sdf, cells, normals);
    }
    let mut mesh = mesh.transformed(to_world);
    // Where a crossing lands next to a cell's corner, a triangle can have no area left in 32-bit
    // world coordinates: it covers nothing, and is dropped here rather than warned about.
    let positions = std::mem::take(&mut mesh.positions);
    mesh.retain_triangles(|t| {
        let [a, b, c] = t.map(|i| positions[i as usize]);
        crate::scene::shapes::triangle_area(a, b, c) > 0.0
    });
    mesh.positions = positions;
    (mesh, cells)
}

/// Whether a shape's own `to_world` rotates (or mirrors): Mitsuba then warns that its voxel
/// boxes are misplaced (it transforms only their corners) and asks for an instance instead.
pub fn rotates(to_world: &Mat4) -> bool {
    let m = Mat3::from_mat4(*to_world);
    let scale = m.to_cols_array().iter().fold(0.0f32, |s, x| s.max(x.abs()));
    let t = m.transpose();
    let asymmetric = (0..3).any(|i| (m.col(i) - t.col(i)).abs().max_element() > 1e-6 * scale);
    asymmetric || m.determinant() < 0.0 || (0..3).any(|i| m.col(i)[i] <= 0.0)
}

#[cfg(test)]
mod tests {
    use glam::{UVec3, Vec3};

    use super::*;

    /// A sphere of radius `r` about the cube's centre sampled on `n³` nodes.
    fn sphere(n: u32, r: f32) -> Sdf {
        let values = (0..n * n * n)
            .map(|i| {
                let p = Vec3::new((i % n) as f32, (i / n % n) as f32, (i / (n * n)) as f32) / (n - 1) as f32;
                (p - Vec3::splat(0.5)).length() - r
            })
            .collect();
        Sdf::new(&Grid::new(UVec3::splat(n), 1, values).unwrap()).unwrap()
    }

    #[test]
    fn vertices_lie_on_the_trilinear_surface_and_triangles_face_outwards() {
        let sdf = sphere(6, 0.3);
        for normals in [Normals::Smooth, Normals::Analytic] {
            let g = tessellate(&sdf, 3, normals);
            assert!(g.indices.len() > 100, "{}", g.indices.len());
            for p in &g.positions {
                assert!(sdf.lookup(p.as_dvec3()).abs() < 1e-6, "{p}: {}", sdf.lookup(p.as_dvec3()));
            }
            for t in &g.indices {
                let [a, b, c] = t.map(|v| g.positions[v as usize]);
                let n = (b - a).cross(c - a);
                assert!(n.dot((a + b + c) / 3.0 - Vec3::splat(0.5)) > 0.0, "{t:?} faces inwards");
            }
            // Watertight: every edge is shared by exactly two triangles (by position).
            let mut edges: HashMap<([u32; 3], [u32; 3]), i32> = HashMap::new();
            for t in &g.indices {
                for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
                    let (pa, pb) = (
                        g.positions[a as usize].to_array().map(f32::to_bits),
                        g.positions[b as usize].to_array().map(f32::to_bits),
                    );
                    *edges.entry((pa.min(pb), pa.max(pb))).or_default() += if pa < pb { 1 } else { -1 };
                }
            }
            assert!(edges.values().all(|&c| c == 0), "open or misoriented edges");
        }
    }

    #[test]
    fn normals_are_mitsubas() {
        let sdf = sphere(6, 0.3);
        // Analytic: the voxel's exact gradient, here by central differences of the interpolant.
        let p = DVec3::new(0.47, 0.52, 0.79);
        let voxel = [2, 2, 3];
        let h = 1e-6;
        let fd = DVec3::new(
            sdf.lookup(p + DVec3::X * h) - sdf.lookup(p - DVec3::X * h),
            sdf.lookup(p + DVec3::Y * h) - sdf.lookup(p - DVec3::Y * h),
            sdf.lookup(p + DVec3::Z * h) - sdf.lookup(p - DVec3::Z * h),
        ) / (2.0 * h);
        assert!((sdf.analytic(p, voxel) - fd).length() < 1e-6 * fd.length(), "{} vs {fd}", sdf.analytic(p, voxel));
        // Smooth: at a grid node's centre offset (w = ½ on each axis), the mean of the eight
        // voxels' normalised gradients; near the grid's low corner only voxel (0, 0, 0) counts.
        let node = DVec3::splat(2.0 / 5.0);
        let mean: DVec3 = (0..8)
            .map(|i| {
                let v = [1 + (i & 1) as i64, 1 + (i >> 1 & 1) as i64, 1 + (i >> 2 & 1) as i64];
                sdf.voxel_grad(node, v).normalize() / 8.0
            })
            .sum();
        assert!((sdf.smooth(node) - mean).length() < 1e-12);
        let low = DVec3::splat(0.01);
        assert!((sdf.smooth(low) - sdf.voxel_grad(low, [0, 0, 0]).normalize()).length() < 1e-12);
        // Smooth normals are continuous where analytic ones jump (a voxel face).
        let face = DVec3::new(0.6, 0.43, 0.71);
        let e = DVec3::X * 1e-9;
        assert!((sdf.smooth(face - e) - sdf.smooth(face + e)).length() < 1e-6);
    }

    #[test]
    fn grids_without_a_surface_or_of_several_channels_are_refused() {
        let e = Sdf::new(&Grid::new(UVec3::splat(2), 1, vec![1.0; 8]).unwrap()).unwrap_err();
        assert_eq!(e, "no voxel's corners change sign: the surface is empty");
        let e = Sdf::new(&Grid::new(UVec3::new(1, 2, 2), 1, vec![-1.0, 1.0, 1.0, 1.0]).unwrap()).unwrap_err();
        assert_eq!(e, "resolution 1×2×2: an SDF grid needs at least 2 values on each axis");
        let e = Sdf::new(&Grid::new(UVec3::splat(2), 3, vec![-1.0; 24]).unwrap()).unwrap_err();
        assert_eq!(e, "3 channels (an SDF grid has 1)");
    }

    #[test]
    fn the_tessellation_is_refined_into_the_pixel_budget() {
        let camera = Camera {
            position: Vec3::new(0.5, 0.5, 3.0),
            target: Vec3::splat(0.5),
            up: Vec3::Y,
            fov_y_degrees: 40.0,
            width: 128,
            height: 128,
            filter: crate::scene::PixelFilter::Box,
            lens: crate::scene::Lens::Pinhole,
            window: crate::scene::FilmWindow::default(),
        };
        let sdf = sphere(5, 0.35);
        let (mesh, cells) = sdf_mesh(&sdf, Normals::Smooth, &Mat4::IDENTITY, &camera);
        assert!(cells > 2 && cells < MAX_CELLS, "{cells}");
        let object = tessellate(&sdf, cells, Normals::Smooth);
        assert!(error_px(&sdf, &object, &Mat4::IDENTITY, &camera) <= MAX_CHORD_ERROR_PX);
        assert!(
            error_px(&sdf, &tessellate(&sdf, cells - 1, Normals::Smooth), &Mat4::IDENTITY, &camera)
                > MAX_CHORD_ERROR_PX / 2.0
        );
        assert_eq!(mesh.indices.len(), object.indices.len());
        assert!(!rotates(&Mat4::from_scale(Vec3::new(3.0, 2.0, 1.0))));
        assert!(rotates(&Mat4::from_rotation_z(0.3)));
    }
}

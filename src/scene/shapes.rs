//! Triangle-mesh generators for the analytic shapes scenes use: quads, boxes, spheres.

use glam::{Vec2, Vec3};

/// Positions, normals, uvs and triangles of one generated shape.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Geometry {
    /// Vertex positions.
    pub positions: Vec<Vec3>,
    /// Unit vertex normals.
    pub normals: Option<Vec<Vec3>>,
    /// Texture coordinates.
    pub uvs: Option<Vec<Vec2>>,
    /// Triangles, counter-clockwise seen from the side the normals point to.
    pub indices: Vec<[u32; 3]>,
    /// Per-vertex and per-face attributes read from the file (a PLY's other properties), under
    /// Mitsuba's names (`vertex_color`, `face_weight`, …).
    pub attributes: Vec<MeshAttribute>,
}

/// One attribute of a mesh (Mitsuba's mesh attributes): `dim` values per vertex (`vertex_…`) or
/// per triangle (`face_…`; a polygon's values repeated for each of its fan's triangles).
#[derive(Clone, Debug, PartialEq)]
pub struct MeshAttribute {
    /// Mitsuba's name: `vertex_` or `face_` then the property's prefix (`vertex_color`).
    pub name: String,
    /// Values per vertex (true) or per triangle (false).
    pub per_vertex: bool,
    /// Values per vertex or triangle (1 or 3; 4 for an RGBA colour).
    pub dim: u32,
    /// The values, `dim` a vertex or triangle, in their order.
    pub values: Vec<f32>,
}

impl Geometry {
    /// Keeps the triangles for which `keep` holds, with their rows of the per-face attributes.
    ///
    /// ```
    /// use pathgrad::scene::shapes::{MeshAttribute, quad};
    /// use glam::Vec3;
    ///
    /// let mut g = quad(Vec3::ZERO, Vec3::X, Vec3::Y);
    /// g.attributes.push(MeshAttribute { name: "face_weight".into(), per_vertex: false, dim: 1, values: vec![0.25, 0.75] });
    /// g.retain_triangles(|t| t[2] == 3);
    /// assert_eq!(g.indices, [[0, 2, 3]]);
    /// assert_eq!(g.attribute("face_weight").unwrap().values, [0.75]);
    /// ```
    pub fn retain_triangles(&mut self, mut keep: impl FnMut(&[u32; 3]) -> bool) {
        let kept: Vec<bool> = self.indices.iter().map(&mut keep).collect();
        if kept.iter().all(|&k| k) {
            return;
        }
        let mut at = 0;
        self.indices.retain(|_| {
            at += 1;
            kept[at - 1]
        });
        for a in self.attributes.iter_mut().filter(|a| !a.per_vertex) {
            let dim = a.dim as usize;
            a.values =
                a.values.chunks(dim).zip(&kept).filter(|(_, k)| **k).flat_map(|(row, _)| row.iter().copied()).collect();
        }
    }

    /// The attribute named `name`, if the mesh has it.
    pub fn attribute(&self, name: &str) -> Option<&MeshAttribute> {
        self.attributes.iter().find(|a| a.name == name)
    }
}

impl Geometry {
    /// The geometry under the affine transform `m`: positions by `m`, normals by its inverse
    /// transpose (renormalised); a mirroring transform (negative determinant) also flips the
    /// winding so the front face stays on the normals' side.
    pub fn transformed(mut self, m: &glam::Mat4) -> Geometry {
        for p in &mut self.positions {
            *p = m.transform_point3(*p);
        }
        if let Some(normals) = &mut self.normals {
            let n_mat = glam::Mat3::from_mat4(*m).inverse().transpose();
            for n in normals.iter_mut() {
                *n = (n_mat * *n).normalize_or_zero();
            }
        }
        if m.determinant() < 0.0 {
            for t in &mut self.indices {
                t.swap(1, 2);
            }
        }
        self
    }
}

impl Geometry {
    /// Smooth vertex normals as Mitsuba 3 computes them for a mesh file without normals
    /// (`Mesh::recompute_vertex_normals`): each triangle's unit normal weighted by its angle at the
    /// vertex (Thürmer and Wüthrich 1998), summed and normalised; degenerate triangles add
    /// nothing, and a vertex left without a normal gets (1, 0, 0), as Mitsuba's does.
    pub fn with_angle_weighted_normals(mut self) -> Geometry {
        let mut normals = vec![Vec3::ZERO; self.positions.len()];
        for t in &self.indices {
            let v = t.map(|i| self.positions[i as usize]);
            let n = (v[1] - v[0]).cross(v[2] - v[0]);
            if !(n.length_squared() > 0.0) {
                continue;
            }
            let n = n.normalize();
            for j in 0..3 {
                let d0 = (v[(j + 1) % 3] - v[j]).normalize_or_zero();
                let d1 = (v[(j + 2) % 3] - v[j]).normalize_or_zero();
                normals[t[j] as usize] += n * d0.dot(d1).clamp(-1.0, 1.0).acos();
            }
        }
        for n in &mut normals {
            *n = if n.length() != 0.0 { n.normalize() } else { Vec3::X };
        }
        self.normals = Some(normals);
        self
    }
}

/// Area of the triangle (a, b, c).
pub fn triangle_area(a: Vec3, b: Vec3, c: Vec3) -> f32 {
    0.5 * (b - a).cross(c - a).length()
}

/// A parallelogram centred at `center` spanned by `u` and `v` (from −u−v to +u+v); its front face
/// and normals point along `u × v`.
pub fn quad(center: Vec3, u: Vec3, v: Vec3) -> Geometry {
    let n = u.cross(v).normalize();
    let positions = vec![center - u - v, center + u - v, center + u + v, center - u + v];
    Geometry {
        positions,
        normals: Some(vec![n; 4]),
        uvs: Some(vec![Vec2::new(0.0, 0.0), Vec2::new(1.0, 0.0), Vec2::new(1.0, 1.0), Vec2::new(0.0, 1.0)]),
        indices: vec![[0, 1, 2], [0, 2, 3]],
        attributes: Vec::new(),
    }
}

/// An axis-aligned box of half-extents `half` around `center` with outward faces and flat normals.
pub fn cuboid(center: Vec3, half: Vec3) -> Geometry {
    let (x, y, z) = (Vec3::X * half.x, Vec3::Y * half.y, Vec3::Z * half.z);
    let faces = [
        quad(center + x, y, z),
        quad(center - x, z, y),
        quad(center + y, z, x),
        quad(center - y, x, z),
        quad(center + z, x, y),
        quad(center - z, y, x),
    ];
    merge(&faces)
}

/// A UV sphere with `rings` latitude bands and `segments` longitude bands, smooth outward normals
/// (inward with `inward`, flipping the winding too).
pub fn sphere(center: Vec3, radius: f32, rings: u32, segments: u32, inward: bool) -> Geometry {
    let mut g = Geometry { normals: Some(Vec::new()), uvs: Some(Vec::new()), ..Default::default() };
    for r in 0..=rings {
        let theta = std::f32::consts::PI * r as f32 / rings as f32;
        for s in 0..=segments {
            let phi = 2.0 * std::f32::consts::PI * s as f32 / segments as f32;
            let n = Vec3::new(theta.sin() * phi.cos(), theta.cos(), theta.sin() * phi.sin());
            g.positions.push(center + radius * n);
            g.normals.as_mut().expect("set above").push(if inward { -n } else { n });
            g.uvs.as_mut().expect("set above").push(Vec2::new(s as f32 / segments as f32, r as f32 / rings as f32));
        }
    }
    let row = segments + 1;
    for r in 0..rings {
        for s in 0..segments {
            let (a, b, c, d) = (r * row + s, r * row + s + 1, (r + 1) * row + s + 1, (r + 1) * row + s);
            // Counter-clockwise seen from outside; the pole rows would give zero-area triangles.
            let tris = [[a, b, c], [a, c, d]];
            for (i, t) in tris.into_iter().enumerate() {
                if (r == 0 && i == 0) || (r == rings - 1 && i == 1) {
                    continue;
                }
                g.indices.push(if inward { [t[0], t[2], t[1]] } else { t });
            }
        }
    }
    g
}

/// Concatenates geometries into one.
pub fn merge(parts: &[Geometry]) -> Geometry {
    let mut g = Geometry { normals: Some(Vec::new()), uvs: Some(Vec::new()), ..Default::default() };
    for p in parts {
        let base = g.positions.len() as u32;
        g.positions.extend_from_slice(&p.positions);
        let n = p.positions.len();
        g.normals.as_mut().expect("set above").extend(p.normals.clone().unwrap_or_else(|| vec![Vec3::ZERO; n]));
        g.uvs.as_mut().expect("set above").extend(p.uvs.clone().unwrap_or_else(|| vec![Vec2::ZERO; n]));
        g.indices.extend(p.indices.iter().map(|t| t.map(|i| i + base)));
    }
    g
}

#[cfg(test)]
mod tests {
    use super::*;

    fn face_normal(g: &Geometry, t: [u32; 3]) -> Vec3 {
        let p = |i: u32| g.positions[i as usize];
        (p(t[1]) - p(t[0])).cross(p(t[2]) - p(t[0]))
    }

    #[test]
    fn winding_agrees_with_normals() {
        for g in [
            quad(Vec3::ZERO, Vec3::X, Vec3::Z),
            cuboid(Vec3::ONE, Vec3::splat(0.5)),
            sphere(Vec3::ZERO, 2.0, 16, 32, false),
            sphere(Vec3::ZERO, 2.0, 16, 32, true),
        ] {
            let normals = g.normals.as_ref().unwrap();
            for &t in &g.indices {
                let f = face_normal(&g, t);
                assert!(f.length() > 0.0, "degenerate triangle {t:?}");
                assert!(f.dot(normals[t[0] as usize]) > 0.0, "triangle {t:?} winds against its normal");
            }
        }
    }

    #[test]
    fn sphere_area_converges() {
        let g = sphere(Vec3::ZERO, 1.0, 64, 128, false);
        let area: f32 = g
            .indices
            .iter()
            .map(|t| triangle_area(g.positions[t[0] as usize], g.positions[t[1] as usize], g.positions[t[2] as usize]))
            .sum();
        assert!((area / (4.0 * std::f32::consts::PI) - 1.0).abs() < 2e-3, "area {area}");
    }
}

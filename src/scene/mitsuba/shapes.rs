//! `<shape>`: mesh files (obj, ply) and the analytic shapes (rectangle, cube, disk, sphere)
//! tessellated into triangles, with their BSDF and area emitter.
//!
//! Curved shapes are tessellated finely enough that, seen through the scene's camera at the film's
//! resolution, no point of the mesh lies more than [`MAX_CHORD_ERROR_PX`] pixels from the true
//! surface (see [`segments_for`]).

use super::plugins::{Category, names};
use std::f32::consts::{PI, TAU};

use glam::{Mat4, Vec2, Vec3, Vec4};

use super::loader::{Loader, MeshFormat};
use super::mesh_attribute::AttributeShape;
use super::xml::{El, Props};
use crate::error::Result;
use crate::scene::shapes::{Geometry, cuboid, merge, quad, triangle_area};
use crate::scene::{Camera, MaterialId, bounds};

/// Largest distance, in pixels of the scene's film, between a tessellated curved shape and the
/// true surface. A pixel straddling a silhouette of contrast C and coverage p has a 64-spp standard
/// error of at least C·√(p(1−p)/64) ≈ 0.06·C at p = ½; a boundary displaced by 0.02 px biases it
/// by at most 0.02·C, a third of that. Inside the silhouette, hit points move by the same distance
/// and interpolated normals are exact at vertices, so shading errors are smaller still.
pub const MAX_CHORD_ERROR_PX: f32 = 0.02;
/// Fewest segments around a curved shape (distant or tiny shapes).
pub const MIN_SEGMENTS: u32 = 32;
/// Most segments around a curved shape (a sphere then has 1024 × 512 × 2 ≈ 1 M triangles).
pub const MAX_SEGMENTS: u32 = 1024;

/// Segments around a circle of radius `radius` centred at `center` (world space) such that the
/// mesh stays within [`MAX_CHORD_ERROR_PX`] of the curve on `camera`'s film.
///
/// A step of Δ radians leaves a chord whose midpoint lies `r(1 − cos Δ/2) ≈ rΔ²/8` inside the
/// circle (`cell = 1`); a sphere's grid cell spans Δ in both directions, so the middle of its
/// diagonal lies `≈ rΔ²/4` inside (`cell = 2`). The circle is at least `d = |c − eye| − r` away, so
/// that distance covers at most `rΔ²k/8 / (d · θpx)` pixels, where θpx is the smallest angle a
/// pixel subtends (at the film's corner: `2 tan(fov/2)/h / (1 + tan²x + tan²y)`). Solving for the
/// bound gives `Δ = √(8ε·d·θpx / (k·r))`. Rendering at k× the film's resolution scales the error
/// by k. An orthographic camera's pixel is `2·half_height/h` wide at any distance, which takes the
/// place of `d·θpx`.
pub fn segments_for(camera: &Camera, center: Vec3, radius: f32, cell: f32) -> u32 {
    let pixel_size = pixel_size(camera, center, radius);
    let delta = (8.0 * MAX_CHORD_ERROR_PX * pixel_size / (cell * radius)).sqrt();
    let n = if delta.is_finite() && delta > 0.0 { (TAU / delta).ceil() } else { MAX_SEGMENTS as f32 };
    let n = (n as u32).clamp(MIN_SEGMENTS, MAX_SEGMENTS);
    n + n % 2
}

/// The smallest world-space size of one of `camera`'s pixels anywhere within `radius` of
/// `center` (see [`segments_for`]): `d·θpx` with `d = |center − eye| − radius`, or an orthographic
/// camera's pixel width. Not positive where the ball holds the eye.
pub fn pixel_size(camera: &Camera, center: Vec3, radius: f32) -> f32 {
    // The whole film's size (the image may be a crop of it).
    let (width, height) = camera.film_size(camera.width, camera.height);
    match camera.lens {
        crate::scene::Lens::Orthographic { half_height, stretch, .. } => 2.0 * half_height * stretch.min(1.0) / height,
        _ => {
            let tan_y = (camera.fov_y_degrees.to_radians() * 0.5).tan();
            let tan_x = tan_y * width / height;
            let pixel_angle = 2.0 * tan_y / height / (1.0 + tan_x * tan_x + tan_y * tan_y);
            ((center - camera.position).length() - radius) * pixel_angle
        }
    }
}

/// The unit sphere with Mitsuba's parametrisation: pole on +z, `u = φ/2π` from +x towards +y,
/// `v = θ/π` from +z; `rings` bands of θ and `segments` of φ, outward normals, counter-clockwise
/// seen from outside, no zero-area pole triangles.
pub fn unit_sphere(rings: u32, segments: u32) -> Geometry {
    let mut positions = Vec::new();
    let mut uvs = Vec::new();
    for i in 0..=rings {
        let theta = PI * i as f32 / rings as f32;
        for j in 0..=segments {
            let phi = TAU * j as f32 / segments as f32;
            positions.push(Vec3::new(theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos()));
            uvs.push(Vec2::new(j as f32 / segments as f32, i as f32 / rings as f32));
        }
    }
    let row = segments + 1;
    let mut indices = Vec::new();
    for i in 0..rings {
        for j in 0..segments {
            let (a, b, c, d) = (i * row + j, i * row + j + 1, (i + 1) * row + j + 1, (i + 1) * row + j);
            if i + 1 < rings {
                indices.push([a, d, c]);
            }
            if i > 0 {
                indices.push([a, c, b]);
            }
        }
    }
    Geometry { normals: Some(positions.clone()), positions, uvs: Some(uvs), indices, ..Default::default() }
}

/// Mitsuba's unit cylinder: the open tube of radius 1 about z from z = 0 to z = 1, outward normals
/// (radial, for smooth shading of the analytic surface), `u = φ/2π` from +x towards +y and
/// `v = z`, as `segments` quads split in two.
pub fn unit_cylinder(segments: u32) -> Geometry {
    let mut positions = Vec::new();
    let mut normals = Vec::new();
    let mut uvs = Vec::new();
    for j in 0..=segments {
        let phi = TAU * j as f32 / segments as f32;
        let n = Vec3::new(phi.cos(), phi.sin(), 0.0);
        for z in [0.0, 1.0] {
            positions.push(n + Vec3::Z * z);
            normals.push(n);
            uvs.push(Vec2::new(j as f32 / segments as f32, z));
        }
    }
    let indices = (0..segments).flat_map(|j| [[2 * j, 2 * j + 2, 2 * j + 3], [2 * j, 2 * j + 3, 2 * j + 1]]).collect();
    Geometry { positions, normals: Some(normals), uvs: Some(uvs), indices, ..Default::default() }
}

/// Mitsuba's unit disk in z = 0 facing +z, as a fan of `segments` triangles; `u` is the radius
/// and `v = φ/2π`.
pub fn unit_disk(segments: u32) -> Geometry {
    let mut positions = vec![Vec3::ZERO];
    let mut uvs = vec![Vec2::ZERO];
    for j in 0..=segments {
        let phi = TAU * j as f32 / segments as f32;
        positions.push(Vec3::new(phi.cos(), phi.sin(), 0.0));
        uvs.push(Vec2::new(1.0, j as f32 / segments as f32));
    }
    let indices = (1..=segments).map(|j| [0, j, j + 1]).collect();
    Geometry { normals: Some(vec![Vec3::Z; positions.len()]), positions, uvs: Some(uvs), indices, ..Default::default() }
}

/// Mitsuba's `rectangle` ([−1, 1]² in z = 0, facing +z) under `m`. For `det m > 0` this is
/// `quad(m·0, m·x, m·y)`, arithmetic for arithmetic, so a rectangle placed by an exact matrix
/// reproduces the built-in scenes' quads bit for bit.
pub fn rectangle(m: &Mat4) -> Geometry {
    let (c, x, y, z) = columns(m);
    if x.dot(y.cross(z)) > 0.0 { quad(c, x, y) } else { quad(Vec3::ZERO, Vec3::X, Vec3::Y).transformed(m) }
}

/// Mitsuba's `cube` ([−1, 1]³, outward faces) under `m`. For `det m > 0` the faces are built from
/// the transformed axes exactly as [`cuboid`] builds them, so `cube` under a diagonal scale and a
/// translation equals `cuboid(translation, scale)` bit for bit.
pub fn cube(m: &Mat4) -> Geometry {
    let (c, x, y, z) = columns(m);
    if x.dot(y.cross(z)) > 0.0 {
        merge(&[
            quad(c + x, y, z),
            quad(c - x, z, y),
            quad(c + y, z, x),
            quad(c - y, x, z),
            quad(c + z, x, y),
            quad(c - z, y, x),
        ])
    } else {
        cuboid(Vec3::ZERO, Vec3::ONE).transformed(m)
    }
}

/// An area emitter's radiance: one RGB value, or a texture (a bitmap's texels or a
/// checkerboard's colours, that parameter) looked up at the hit's texture coordinates.
enum AreaRadiance {
    Constant(Vec3),
    Texture(crate::params::ParamId, crate::scene::Albedo),
}

/// Translation and the three axes of an affine `m`.
fn columns(m: &Mat4) -> (Vec3, Vec3, Vec3, Vec3) {
    (m.w_axis.truncate(), m.x_axis.truncate(), m.y_axis.truncate(), m.z_axis.truncate())
}

/// Sum of triangle areas.
fn area(g: &Geometry) -> f32 {
    g.indices
        .iter()
        .map(|t| {
            let p = t.map(|i| g.positions.get(i as usize).copied().unwrap_or(Vec3::ZERO));
            triangle_area(p[0], p[1], p[2])
        })
        .filter(|a| a.is_finite())
        .sum()
}

/// Relative tolerance for "a sphere's to_world is a similarity" (as the sensor's).
const SIMILARITY_TOLERANCE: f32 = 1e-4;

impl<'a> Loader<'a> {
    /// Adds the mesh of one `<shape>`.
    pub(super) fn shape(&mut self, node: El<'a>) -> Result<()> {
        // A shape of a group, built by an instance: its key, under the instance's transform.
        let (name, instance) = match self.instancing.take() {
            Some((m, name)) => (name, m),
            None => (self.top_name(node)?, Mat4::IDENTITY),
        };
        let p = Props::parse(&self.x, node)?;
        let transform = p.transform(&self.x, "to_world")?;
        let (to_world, t_node) = match transform {
            Some((t, n)) => (instance * t.matrix, n),
            None => (instance, node),
        };
        let det = Mat4::from_mat3(glam::Mat3::from_mat4(to_world)).determinant();
        if !(det.abs() > 0.0) {
            return Err(self.x.err(t_node, "to_world is singular (it flattens the shape)"));
        }
        let mut geometry = match p.kind.as_str() {
            "obj" | "ply" | "serialized" => {
                let index = if p.kind == "serialized" {
                    match p.integer(&self.x, "shape_index")? {
                        None => 0,
                        Some((i, _)) if (0..=i64::from(u32::MAX)).contains(&i) => i as u32,
                        Some((i, n)) => return Err(self.x.err(n, format!("'shape_index' must be ≥ 0, got {i}"))),
                    }
                } else {
                    0
                };
                let (file, file_node) = p
                    .string(&self.x, "filename")?
                    .ok_or_else(|| self.x.err(node, format!("'{}' needs the property 'filename'", p.kind)))?;
                let path = self.scene_file(&file).map_err(|m| self.x.err(file_node, m))?;
                if !path.is_file() {
                    return Err(self
                        .x
                        .err(file_node, format!("mesh file '{file}' not found (looked for {})", path.display())));
                }
                // A serialized mesh's stored face-normals flag holds unless the scene says otherwise
                // (Mitsuba's rule).
                let (mut g, stored_face_normals) = match p.kind.as_str() {
                    "obj" => ((self.meshes)(MeshFormat::Obj, &path).map_err(|e| self.located(node, e))?, false),
                    "ply" => ((self.meshes)(MeshFormat::Ply, &path).map_err(|e| self.located(node, e))?, false),
                    _ => {
                        let m =
                            crate::scene::mesh_io::load_serialized(&path, index).map_err(|e| self.located(node, e))?;
                        (m.geometry, m.face_normals)
                    }
                };
                let face_normals = p.boolean(&self.x, "face_normals", stored_face_normals)?;
                if face_normals {
                    g.normals = None;
                }
                if to_world != Mat4::IDENTITY {
                    g = g.transformed(&to_world);
                }
                // A file without normals is shaded smoothly unless the scene asks for face
                // normals: Mitsuba computes vertex normals for it, in world space.
                if g.normals.is_none() && !face_normals { g.with_angle_weighted_normals() } else { g }
            }
            "rectangle" => rectangle(&to_world),
            "cube" => cube(&to_world),
            "disk" => {
                let (c, x, y, _) = columns(&to_world);
                let n = segments_for(&self.scene.camera, c, x.length().max(y.length()), 1.0);
                unit_disk(n).transformed(&to_world)
            }
            "cylinder" => {
                let p0 = p.point(&self.x, "p0")?.map_or(Vec3::ZERO, |c| c.0);
                let p1 = p.point(&self.x, "p1")?.map_or(Vec3::Z, |c| c.0);
                let radius = match p.float(&self.x, "radius")? {
                    None => 1.0,
                    Some((r, _)) if r > 0.0 => r,
                    Some((r, n)) => return Err(self.x.err(n, format!("'radius' must be positive, got {r}"))),
                };
                let axis = p1 - p0;
                if !(axis.length() > 0.0) {
                    return Err(self.x.err(node, "a cylinder's p0 and p1 must differ"));
                }
                // Mitsuba's placement: to_world · translate(p0) · frame(axis) · scale(r, r, |axis|),
                // the frame Mitsuba's `coordinate_system` builds (Duff et al.), as `Frame` does.
                let f = crate::sampling::Frame::from_normal(axis.normalize());
                let frame = Mat4::from_cols(f.t.extend(0.0), f.b.extend(0.0), f.n.extend(0.0), Vec4::W);
                let m = to_world
                    * Mat4::from_translation(p0)
                    * frame
                    * Mat4::from_scale(Vec3::new(radius, radius, axis.length()));
                let (c, x, y, _) = columns(&m);
                let n = segments_for(&self.scene.camera, c, x.length().max(y.length()), 1.0);
                unit_cylinder(n).transformed(&m)
            }
            "sphere" => {
                let center = p.point(&self.x, "center")?.map_or(Vec3::ZERO, |c| c.0);
                let radius = match p.float(&self.x, "radius")? {
                    None => 1.0,
                    Some((r, _)) if r > 0.0 => r,
                    Some((r, n)) => return Err(self.x.err(n, format!("'radius' must be positive, got {r}"))),
                };
                let m = to_world * Mat4::from_translation(center) * Mat4::from_scale(Vec3::splat(radius));
                let (c, x, y, z) = columns(&m);
                let (lx, ly, lz) = (x.length(), y.length(), z.length());
                let tol = SIMILARITY_TOLERANCE * lx.max(ly).max(lz);
                if (lx - ly).abs() > tol
                    || (lx - lz).abs() > tol
                    || x.dot(y).abs() > tol * ly
                    || x.dot(z).abs() > tol * lz
                    || y.dot(z).abs() > tol * lz
                {
                    return Err(self.x.err(
                        t_node,
                        "a sphere's to_world must be a rotation, uniform scale and translation (Mitsuba \
                         ignores the rest)",
                    ));
                }
                let n = segments_for(&self.scene.camera, c, lx, 2.0);
                unit_sphere(n / 2, n).transformed(&m)
            }
            kind @ ("linearcurve" | "bsplinecurve") => {
                let (file, file_node) = p
                    .string(&self.x, "filename")?
                    .ok_or_else(|| self.x.err(node, format!("'{kind}' needs the property 'filename'")))?;
                let path = self.scene_file(&file).map_err(|m| self.x.err(file_node, m))?;
                if !path.is_file() {
                    return Err(self
                        .x
                        .err(file_node, format!("curve file '{file}' not found (looked for {})", path.display())));
                }
                let min_points = if kind == "linearcurve" { 2 } else { 4 };
                let mut curves =
                    crate::scene::mesh_io::load_curves(&path, min_points).map_err(|e| self.located(node, e))?;
                // Positions move with to_world, radii do not (Mitsuba's rule).
                for c in curves.iter_mut().flatten() {
                    *c = to_world.transform_point3(c.truncate()).extend(c.w);
                }
                for name in ["flip_normals", "exterior", "interior"] {
                    if let Some(n) = p.node_of(name) {
                        return Err(self.x.err(n, format!("'{name}' is not supported on curves")));
                    }
                }
                if kind == "linearcurve" {
                    super::curves::linear_curves(&curves, &self.scene.camera)
                } else {
                    // A spline's end radius is its control points' (r0 + 4·r1 + r2)/6.
                    let end = |a: Vec4, b: Vec4, c: Vec4| (a.w + 4.0 * b.w + c.w) / 6.0;
                    if curves.iter().any(|c| {
                        let n = c.len();
                        end(c[0], c[1], c[2]) > 0.0 || end(c[n - 3], c[n - 2], c[n - 1]) > 0.0
                    }) {
                        let w = self.x.warning(
                            node,
                            "a 'bsplinecurve' with open ends (an end radius > 0): Mitsuba culls curves' back \
                             faces, so a ray into an open end sees what lies beyond the tube; pathgrad's \
                             tessellated tube shows its inner wall there",
                        );
                        self.scene.warn(w);
                    }
                    super::curves::bspline_curves(&curves, &self.scene.camera)
                }
            }
            "sdfgrid" => {
                let (file, file_node) = p
                    .string(&self.x, "filename")?
                    .ok_or_else(|| self.x.err(node, "'sdfgrid' needs the property 'filename' (a .vol grid)"))?;
                let path = self.scene_file(&file).map_err(|m| self.x.err(file_node, m))?;
                if !path.is_file() {
                    return Err(self
                        .x
                        .err(file_node, format!("SDF grid file '{file}' not found (looked for {})", path.display())));
                }
                let grid = crate::scene::volume::Grid::read(&path).map_err(|e| self.located(file_node, e))?;
                let sdf = super::sdfgrid::Sdf::new(&grid)
                    .map_err(|m| self.x.err(file_node, format!("SDF grid '{file}': {m}")))?;
                let normals = match p.string(&self.x, "normals")? {
                    None => super::sdfgrid::Normals::Smooth,
                    Some((s, _)) if s == "smooth" => super::sdfgrid::Normals::Smooth,
                    Some((s, _)) if s == "analytic" => super::sdfgrid::Normals::Analytic,
                    Some((s, n)) => {
                        return Err(self.x.err(n, format!("'normals' must be 'analytic' or 'smooth', got '{s}'")));
                    }
                };
                for name in ["flip_normals", "grid"] {
                    if let Some(n) = p.node_of(name) {
                        let why = if name == "grid" {
                            "inline grids are Python/C++ only in Mitsuba too"
                        } else {
                            "Mitsuba's sdfgrid ignores it"
                        };
                        return Err(self.x.err(n, format!("'{name}' is not supported on an sdfgrid ({why})")));
                    }
                }
                if let Some((_, n)) = transform.filter(|(t, _)| super::sdfgrid::rotates(&t.matrix)) {
                    let w = self.x.warning(
                        n,
                        "an 'sdfgrid' whose to_world rotates or mirrors: Mitsuba misplaces its voxels' bounding \
                         boxes then (and says to use an instance), so its image has holes; pathgrad renders \
                         the whole surface",
                    );
                    self.scene.warn(w);
                }
                super::sdfgrid::sdf_mesh(&sdf, normals, &to_world, &self.scene.camera).0
            }
            other => {
                return Err(self
                    .x
                    .err(node, format!("unsupported plugin '{other}' (supported: {})", names(Category::Shape))));
            }
        };
        if p.boolean(&self.x, "flip_normals", false)? {
            for t in &mut geometry.indices {
                t.swap(1, 2);
            }
            if let Some(normals) = &mut geometry.normals {
                for n in normals {
                    *n = -*n;
                }
            }
        }
        if let Some(bad) = geometry.positions.iter().find(|v| !v.is_finite()) {
            return Err(self.x.err(node, format!("a vertex position is not finite ({bad})")));
        }
        // Named first: a `<ref name="interior" id="…"/>` is not a BSDF reference.
        let interior = p.object("interior");
        if let Some(exterior) = p.object("exterior") {
            return Err(self.x.err(exterior, "exterior media are not supported (paths start in vacuum)"));
        }
        // A `<ref>` to an area emitter declared at scene level attaches it here, as Mitsuba does.
        let mut emitters = p.take_nested(&["emitter"]);
        let mut bsdfs = Vec::new();
        for b in p.take_nested(&["bsdf", "ref"]) {
            let target = self.deref(b)?;
            if target.has_tag_name("emitter") {
                if self.attached.contains(&target.id()) {
                    return Err(self.x.err(b, "this area emitter is attached to another shape already"));
                }
                self.attached.push(target.id());
                emitters.push(target);
            } else {
                bsdfs.push(b);
            }
        }
        self.finish(&p)?;
        let overflowed_before = self.scene.overflowed_triangles;
        // A BSDF may read the mesh's attributes (`mesh_attribute`): per-face ones follow the
        // triangles the mesh keeps.
        if !geometry.attributes.is_empty() {
            self.scene.prune_triangles(&name, &mut geometry);
        }
        self.attribute_shape = Some(AttributeShape {
            name: name.clone(),
            mesh: self.scene.meshes.len() as u32,
            attributes: std::mem::take(&mut geometry.attributes),
        });
        let material = match bsdfs[..] {
            [] => self.default_bsdf(node, &name, !emitters.is_empty()),
            [b] => self.bsdf(b, format!("{name}.bsdf"), 1),
            [_, second, ..] => Err(self.x.err(second, "a shape takes one BSDF")),
        };
        self.attribute_shape = None;
        let material = material?;
        if let (true, Some(e)) = (p.kind.ends_with("curve"), emitters.first()) {
            // Mitsuba cannot sample a point on a curve either (no `sample_position`).
            return Err(self.x.err(*e, "area emitters on curves are not supported"));
        }
        if let (true, Some(e)) = (p.kind == "sdfgrid", emitters.first()) {
            // Mitsuba's sdfgrid has no area and samples no position either.
            return Err(self.x.err(*e, "area emitters on an sdfgrid are not supported (Mitsuba's cannot emit)"));
        }
        let emitter = match emitters[..] {
            [] => None,
            [e] => Some(self.area_emitter(e, &name)?),
            [_, second, ..] => return Err(self.x.err(second, "a shape takes one emitter")),
        };
        // Paths enter the medium through the shape's boundary where it lets light through: a
        // null or dielectric BSDF (an opaque one keeps it out).
        let interior = match interior {
            Some(m) => Some(self.medium(m, format!("{name}.interior_medium"))?),
            None => None,
        };
        self.scene.add_mesh(&name, geometry, material, None).map_err(|e| self.located(node, e))?;
        if let Some(mesh) = self.scene.meshes.last_mut() {
            mesh.interior = interior;
        }
        if interior.is_some() {
            self.medium_shapes.push((self.scene.meshes.len() - 1, node));
        }
        if let Some((e, param, radiance)) = emitter {
            let mesh = self.scene.meshes.last().expect("add_mesh pushed a mesh");
            let g = Geometry { positions: mesh.positions.clone(), indices: mesh.indices.clone(), ..Default::default() };
            let total = area(&g);
            if total.is_infinite() || self.scene.overflowed_triangles > overflowed_before {
                return Err(self.x.err(
                    e,
                    format!(
                        "area emitter on shape '{name}' whose area overflows 32-bit floats (coordinates too large)"
                    ),
                ));
            }
            if !(total > 0.0) {
                return Err(self.x.err(e, format!("area emitter on shape '{name}' of zero area")));
            }
            let (id, texture) = match radiance {
                AreaRadiance::Constant(radiance) => {
                    let id = self.scene.params.add(&param, &radiance.to_array(), bounds::RADIANCE);
                    (id.map_err(|err| self.located(e, err))?, None)
                }
                AreaRadiance::Texture(id, texture) => (id, Some(texture)),
            };
            if let Some(mesh) = self.scene.meshes.last_mut() {
                mesh.emitter = Some(id);
                mesh.emitter_texture = texture;
            }
        }
        Ok(())
    }

    /// Mitsuba's BSDF for shapes without one: diffuse, named `SHAPE.bsdf`, of reflectance 0.5 —
    /// or 0 on an area emitter, which Mitsuba 3 makes black so that lights do not reflect.
    fn default_bsdf(&mut self, node: El<'a>, name: &str, emitter: bool) -> Result<MaterialId> {
        let reflectance = if emitter { 0.0 } else { 0.5 };
        self.scene.add_diffuse(&format!("{name}.bsdf"), Vec3::splat(reflectance)).map_err(|e| self.located(node, e))
    }

    /// Reads a shape's `<emitter type="area">`: its element, parameter name and radiance.
    fn area_emitter(&mut self, node: El<'a>, shape: &str) -> Result<(El<'a>, String, AreaRadiance)> {
        let p = Props::parse(&self.x, node)?;
        if p.kind != "area" {
            return Err(self.x.err(node, format!("unsupported plugin '{}' (supported on shapes: area)", p.kind)));
        }
        // Mitsuba names an emitter nested in a shape after the shape, whatever its own id; one
        // declared at scene level (and referred to) by its id.
        let top_level = node.parent().is_some_and(|n| n.parent().is_some_and(|d| d.is_root()));
        let prefix = match self.x.attr(node, "id")? {
            Some(id) if top_level => format!("{id}.radiance"),
            _ => format!("{shape}.emitter.radiance"),
        };
        if let Some(t) = p.object("radiance") {
            self.finish(&p)?;
            // A textured radiance: Mitsuba's keys `….radiance.data` (a bitmap) or
            // `….radiance.color0.value` and `….color1.value` (a checkerboard).
            let (id, texture) = self.area_texture(t, prefix)?;
            return Ok((node, String::new(), AreaRadiance::Texture(id, texture)));
        }
        let radiance = self.radiance_in(&p, "radiance", Vec3::ONE, bounds::RADIANCE)?;
        self.finish(&p)?;
        Ok((node, format!("{prefix}.value"), AreaRadiance::Constant(radiance)))
    }
}

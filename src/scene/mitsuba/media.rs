//! Mitsuba `<medium>`s: `homogeneous` and `heterogeneous`, their `sigma_t` and `albedo` as
//! constants, `constvolume` or `gridvolume` (`.vol` files), `scale`, and `isotropic` or `hg` phase
//! functions; and the check that no sensor sits inside a medium.

use super::plugins::{Category, names};
use glam::{DVec3, Mat4, Vec3};

use super::loader::Loader;
use super::xml::{El, Props};
use crate::error::Result;
use crate::scene::medium::{Field, Medium, MediumId, Phase, bounds, unit_cube_bounds};
use crate::scene::volume::Grid;
use crate::scene::{Albedo, Wrap};

impl<'a> Loader<'a> {
    /// The medium `node` is or refers to, built on first use; `name` (the parameter prefix,
    /// `SHAPE.interior_medium`) is used unless the scene level named it first
    /// ([`Loader::name_of`]).
    pub(super) fn medium(&mut self, node: El<'a>, name: String) -> Result<MediumId> {
        let target = self.deref(node)?;
        if !target.has_tag_name("medium") {
            return Err(self.x.err(node, format!("refers to a <{}>, expected a <medium>", target.tag_name().name())));
        }
        if let Some(&m) = self.media.get(&target.id()) {
            return Ok(m);
        }
        let name = self.name_of(target, name)?;
        let p = Props::parse(&self.x, target)?;
        let heterogeneous = match p.kind.as_str() {
            "homogeneous" => false,
            "heterogeneous" => true,
            other => {
                return Err(self.x.err(
                    target,
                    format!("unsupported plugin '{other}' (supported media: {})", names(Category::Medium)),
                ));
            }
        };
        let (sigma_t, sigma_t_to_world) = self.field(&p, "sigma_t", &name, 1.0, bounds::EXTINCTION)?;
        let (albedo, _) = self.field(&p, "albedo", &name, 0.75, bounds::ALBEDO)?;
        // Mitsuba's heterogeneous medium exists only inside its sigma_t volume's bounding box.
        let extent = heterogeneous.then(|| unit_cube_bounds(sigma_t_to_world));
        let scale = self.float_in(&p, "scale", Some(1.0), bounds::EXTINCTION)?;
        let phases = p.take_nested(&["phase", "ref"]);
        self.finish(&p)?;
        let scale = self
            .scene
            .params
            .add(&format!("{name}.scale"), &[scale], bounds::EXTINCTION)
            .map_err(|e| self.located(target, e))?;
        let phase = match phases[..] {
            [] => Phase::Isotropic,
            [ph] => self.phase(ph, &name)?,
            [_, second, ..] => return Err(self.x.err(second, "a medium takes one phase function")),
        };
        let id = MediumId(self.scene.media.len() as u32);
        self.scene.media.push(Medium { name, heterogeneous, extent, sigma_t, albedo, scale, phase });
        self.media.insert(target.id(), id);
        Ok(id)
    }

    /// Property `prop` of medium `p`: a `<float>` or `<rgb>`, a `constvolume` or a `gridvolume`
    /// (`default` when absent), its values in `range`; with the volume's `to_world` (the identity
    /// for a plain value, which Mitsuba makes a `constvolume` over the unit cube).
    fn field(
        &mut self,
        p: &Props<'a>,
        prop: &str,
        medium: &str,
        default: f32,
        range: (f32, f32),
    ) -> Result<(Field, Mat4)> {
        let constant = |loader: &mut Self, values: Vec<f32>, node: El<'a>| -> Result<Field> {
            let channels = values.len() as u32;
            let name = format!("{medium}.{prop}.value.value");
            let value = loader.scene.params.add(&name, &values, range).map_err(|e| loader.located(node, e))?;
            Ok(Field::Constant { value, channels })
        };
        let Some(volume) = p.object(prop) else {
            let field = match p.values(&self.x, prop)? {
                Some((values, node)) => constant(self, values, node),
                None => constant(self, vec![default], p.node),
            };
            return Ok((field?, Mat4::IDENTITY));
        };
        let volume = self.deref(volume)?;
        if !volume.has_tag_name("volume") {
            return Err(self.x.err(volume, format!("'{prop}' must be a <float>, an <rgb> or a <volume>")));
        }
        let v = Props::parse(&self.x, volume)?;
        match v.kind.as_str() {
            "constvolume" => {
                let (values, node) = v.values(&self.x, "value")?.unwrap_or((vec![1.0], volume));
                let to_world = v.transform(&self.x, "to_world")?.map_or(Mat4::IDENTITY, |(t, _)| t.matrix);
                self.finish(&v)?;
                Ok((constant(self, values, node)?, to_world))
            }
            "gridvolume" => {
                let (file, file_node) = v
                    .string(&self.x, "filename")?
                    .ok_or_else(|| self.x.err(volume, "'gridvolume' needs the property 'filename'"))?;
                let to_world = v.transform(&self.x, "to_world")?.map_or(Mat4::IDENTITY, |(t, _)| t.matrix);
                if let Some((filter, node)) = v.string(&self.x, "filter_type")?
                    && filter != "trilinear"
                {
                    return Err(self.x.err(node, format!("filter_type '{filter}' is not supported (only trilinear)")));
                }
                // Mitsuba's default is `clamp` (a bitmap's is `repeat`).
                let wrap = self.wrap_mode(&v, Wrap::Clamp)?;
                if v.boolean(&self.x, "use_grid_bbox", false)? {
                    return Err(self
                        .x
                        .err(volume, "use_grid_bbox is not supported: the grid fills the unit cube under to_world"));
                }
                self.finish(&v)?;
                if !(Mat4::from_mat3(glam::Mat3::from_mat4(to_world)).determinant().abs() > 0.0) {
                    return Err(self.x.err(volume, "to_world is singular (it flattens the grid)"));
                }
                let path = self.scene_file(&file).map_err(|m| self.x.err(file_node, m))?;
                let grid = Grid::read(&path).map_err(|e| self.located(file_node, e))?;
                let name = format!("{medium}.{prop}.data");
                let values =
                    self.scene.params.add(&name, &grid.values, range).map_err(|e| self.located(file_node, e))?;
                let field = Field::Grid {
                    resolution: grid.resolution,
                    channels: grid.channels,
                    values,
                    to_local: to_world.inverse(),
                    wrap,
                };
                Ok((field, to_world))
            }
            other => Err(self
                .x
                .err(volume, format!("unsupported plugin '{other}' (supported volumes: {})", names(Category::Volume)))),
        }
    }

    /// Mitsuba's `volume` texture `p` named `name`: its `volume` (a `<float>` or `<rgb>`, a
    /// `constvolume` or a `gridvolume`, values in [0, 1]) looked up at the world-space surface
    /// point, a field of [`crate::scene::Scene::volume_textures`]; its values are the parameter
    /// `NAME.volume.data` (a grid) or `NAME.volume.value.value` (a constant), as Mitsuba 3.9.1
    /// names them.
    ///
    /// # Errors
    /// No `volume` (Mitsuba has no default), or as a medium's field.
    pub(super) fn volume_texture(&mut self, p: &Props<'a>, name: &str) -> Result<Albedo> {
        if !p.has("volume") && p.object("volume").is_none() {
            return Err(self.x.err(p.node, "a 'volume' texture needs its 'volume' (a <volume>, <float> or <rgb>)"));
        }
        let (field, _) = self.field(p, "volume", name, 0.75, crate::scene::bounds::REFLECTANCE)?;
        self.finish(p)?;
        self.scene.volume_textures.push(field);
        Ok(Albedo::Volume(self.scene.volume_textures.len() as u32 - 1))
    }

    /// A `<phase>`: `isotropic`, or `hg` with `g` (parameter `MEDIUM.phase_function.g`).
    fn phase(&mut self, node: El<'a>, medium: &str) -> Result<Phase> {
        let node = self.deref(node)?;
        if !node.has_tag_name("phase") {
            return Err(self.x.err(node, "a medium's nested object must be a <phase>"));
        }
        let p = Props::parse(&self.x, node)?;
        let phase = match p.kind.as_str() {
            "isotropic" => Phase::Isotropic,
            "hg" => {
                let g = self.float_in(&p, "g", Some(0.8), (-1.0, 1.0))?;
                if g.abs() >= 1.0 {
                    return Err(self
                        .x
                        .err(p.node_of("g").unwrap_or(node), format!("'g' must lie in (-1, 1), got {g}")));
                }
                let name = format!("{medium}.phase_function.g");
                let g = self.scene.params.add(&name, &[g], bounds::HG_G).map_err(|e| self.located(node, e))?;
                Phase::HenyeyGreenstein { g }
            }
            other => {
                return Err(self.x.err(
                    node,
                    format!("unsupported plugin '{other}' (supported phases: {})", names(Category::Phase)),
                ));
            }
        };
        self.finish(&p)?;
        Ok(phase)
    }

    /// Refuses a sensor inside a closed shape with an interior medium (pathgrad's paths start in
    /// vacuum).
    pub(super) fn refuse_sensors_in_media(&self, sensors: &[El<'a>]) -> Result<()> {
        for (node, sensor) in sensors.iter().zip(&self.scene.sensors) {
            let origin = sensor.camera.position.as_dvec3();
            for mesh in self.scene.meshes.iter().filter(|m| m.interior.is_some()) {
                if inside(origin, &mesh.positions, &mesh.indices) {
                    return Err(self.x.err(
                        *node,
                        format!(
                            "sensor '{}' is inside the medium of shape '{}': a camera inside a medium is not supported",
                            sensor.name, mesh.name
                        ),
                    ));
                }
            }
        }
        Ok(())
    }

    /// Refuses two shapes with interior media that overlap or nest: a path leaving the inner
    /// one would be in vacuum, not in the outer medium (exterior media are not supported), so
    /// such a scene would render wrongly without a word.
    pub(super) fn refuse_overlapping_media(&self) -> Result<()> {
        let shapes = &self.medium_shapes;
        for (i, &(a, node_a)) in shapes.iter().enumerate() {
            for &(b, node_b) in &shapes[i + 1..] {
                let (ma, mb) = (&self.scene.meshes[a], &self.scene.meshes[b]);
                if reaches_into(ma, mb) || reaches_into(mb, ma) {
                    let at = self.x.loc(node_a);
                    return Err(self.x.err(
                        node_b,
                        format!(
                            "shape '{}' and shape '{}' ({at}) both have an interior medium and overlap: nested or \
                             intersecting media are not supported",
                            mb.name, ma.name
                        ),
                    ));
                }
            }
        }
        Ok(())
    }
}

/// At most this many vertices of a shape are tested against another shape in the overlap check
/// (evenly spaced): enough to find a nested shape (all its vertices are inside) or two shapes that
/// cut deeply into each other, without a quadratic cost on large meshes.
const OVERLAP_SAMPLE_VERTICES: usize = 4096;

/// Whether some vertex of mesh `a` lies inside closed mesh `b`. Each vertex is first moved by 10⁻⁴
/// of its distance towards `a`'s vertex centroid, so shapes that only touch (a shared face, a
/// vertex on the other's surface) do not count as overlapping.
fn reaches_into(a: &crate::scene::Mesh, b: &crate::scene::Mesh) -> bool {
    let centroid = a.positions.iter().map(|p| p.as_dvec3()).sum::<DVec3>() / a.positions.len().max(1) as f64;
    let (lo, hi) = bounds(&b.positions);
    let step = a.positions.len().div_ceil(OVERLAP_SAMPLE_VERTICES).max(1);
    a.positions.iter().step_by(step).any(|p| {
        let p = p.as_dvec3();
        let q = p + 1e-4 * (centroid - p);
        q.cmpgt(lo).all() && q.cmplt(hi).all() && inside(q, &b.positions, &b.indices)
    })
}

/// The bounding box of `positions`, in f64.
fn bounds(positions: &[Vec3]) -> (DVec3, DVec3) {
    positions.iter().fold((DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)), |(lo, hi), p| {
        (lo.min(p.as_dvec3()), hi.max(p.as_dvec3()))
    })
}

/// Whether `p` is inside the closed triangle mesh: a ray in a fixed direction that no axis or
/// diagonal is parallel to crosses it an odd number of times (in f64).
fn inside(p: DVec3, positions: &[Vec3], indices: &[[u32; 3]]) -> bool {
    let d = DVec3::new(0.5773, 0.6123, 0.5403).normalize();
    let mut crossings = 0u32;
    for t in indices {
        let [a, b, c] = t.map(|i| positions[i as usize].as_dvec3());
        let (e1, e2) = (b - a, c - a);
        let h = d.cross(e2);
        let det = e1.dot(h);
        if det.abs() < 1e-300 {
            continue;
        }
        let s = p - a;
        let u = s.dot(h) / det;
        let q = s.cross(e1);
        let v = d.dot(q) / det;
        let t = e2.dot(q) / det;
        if (0.0..=1.0).contains(&u) && v >= 0.0 && u + v <= 1.0 && t > 0.0 {
            crossings += 1;
        }
    }
    crossings % 2 == 1
}

//! The walk over a glTF document: nodes and their transforms, cameras and meshes.

use std::fmt::Display;

use ::gltf::json;
use glam::{Mat4, Quat, Vec2, Vec3};
use json::validation::Checked;

use crate::error::{Error, Result};

/// A spot light's beam width when glTF's inner cone angle is 0 (pathgrad's spot needs one > 0).
const MIN_BEAM_WIDTH_DEGREES: f32 = 1e-3;

/// The pinhole field of view an orthographic camera carries (unused by its lens; degrees).
const DEFAULT_ORTHOGRAPHIC_FOV: f32 = 45.0;
use crate::scene::Camera;
use crate::scene::shapes::Geometry;

use super::*;

impl Loader<'_> {
    pub(super) fn error(&self, element: impl Display, message: impl Into<String>) -> Error {
        located(self.path, element, message)
    }

    pub(super) fn run(&mut self) -> Result<()> {
        let root = self.root;
        for ext in &root.extensions_used {
            if !SUPPORTED_EXTENSIONS.contains(&ext.as_str()) {
                self.scene.warn(format!("extension '{ext}' is ignored"));
            }
        }
        let roots: Vec<usize> = match (root.scene, root.scenes.first()) {
            (Some(s), _) => root.scenes[s.value()].nodes.iter().map(|n| n.value()).collect(),
            (None, Some(first)) => first.nodes.iter().map(|n| n.value()).collect(),
            (None, None) => {
                let mut is_child = vec![false; root.nodes.len()];
                for n in &root.nodes {
                    for c in n.children.iter().flatten() {
                        is_child[c.value()] = true;
                    }
                }
                (0..root.nodes.len()).filter(|&i| !is_child[i]).collect()
            }
        };
        // Depth-first, children in order, with an explicit stack: a deep tree cannot overflow ours.
        let mut visited = vec![false; root.nodes.len()];
        let mut stack: Vec<(usize, Mat4)> = roots.into_iter().rev().map(|n| (n, Mat4::IDENTITY)).collect();
        while let Some((index, parent)) = stack.pop() {
            if std::mem::replace(&mut visited[index], true) {
                return Err(self.error(
                    format!("nodes[{index}]"),
                    "is reached twice: a node may have only one parent and the hierarchy must not have cycles",
                ));
            }
            let node = &root.nodes[index];
            let world = parent * self.local_transform(index)?;
            if let Some(camera) = node.camera {
                self.camera(index, camera.value(), &world)?;
            }
            if let Some(light) = node.extensions.as_ref().and_then(|e| e.khr_lights_punctual.as_ref()) {
                self.light(index, light.light.value(), &world)?;
            }
            if let Some(mesh) = node.mesh {
                self.mesh(index, mesh.value(), &world)?;
            }
            for child in node.children.iter().flatten().rev() {
                stack.push((child.value(), world));
            }
        }
        match self.cameras.first() {
            Some(first) => {
                self.scene.camera = first.camera;
                self.scene.sensors = std::mem::take(&mut self.cameras);
            }
            None => self.default_camera(),
        }
        Ok(())
    }

    pub(super) fn local_transform(&self, index: usize) -> Result<Mat4> {
        let root = self.root;
        let node = &root.nodes[index];
        let m = match node.matrix {
            Some(m) => Mat4::from_cols_array(&m),
            None => {
                let t = Vec3::from(node.translation.unwrap_or([0.0; 3]));
                let s = Vec3::from(node.scale.unwrap_or([1.0; 3]));
                let r = Quat::from_array(node.rotation.map(|q| q.0).unwrap_or([0.0, 0.0, 0.0, 1.0]));
                if !(r.length() > 0.0) {
                    return Err(self.error(format!("nodes[{index}]"), "rotation is not a unit quaternion"));
                }
                Mat4::from_scale_rotation_translation(s, r.normalize(), t)
            }
        };
        if !m.is_finite() {
            return Err(self.error(format!("nodes[{index}]"), "transform is not finite"));
        }
        Ok(m)
    }

    // ---- lights (KHR_lights_punctual) ----

    /// Light `index` of `KHR_lights_punctual` on node `node`: a point, spot or directional light
    /// (the module's "Lights").
    pub(super) fn light(&mut self, node: usize, index: usize, world: &Mat4) -> Result<()> {
        use crate::scene::{Light, LightShape, bounds};
        use json::extensions::scene::khr_lights_punctual::Type;
        let root = self.root;
        let at = format!("KHR_lights_punctual.lights[{index}]");
        let lights = root.extensions.as_ref().and_then(|e| e.khr_lights_punctual.as_ref()).map(|l| &l.lights);
        let Some(light) = lights.and_then(|l| l.get(index)) else {
            return Err(self.error(format!("nodes[{node}]"), format!("refers to {at}, which does not exist")));
        };
        let colour = Vec3::from(light.color);
        if !(colour.is_finite() && colour.min_element() >= 0.0 && light.intensity.is_finite() && light.intensity >= 0.0)
        {
            return Err(self.error(&at, "color and intensity must be finite and ≥ 0"));
        }
        if light.range.is_some() {
            self.scene.warn(format!("{at}: 'range' is ignored (the light falls off as 1/distance² everywhere)"));
        }
        if !self.light_units_warned {
            self.light_units_warned = true;
            self.scene.warn(
                "KHR_lights_punctual: intensities (candela; lux for directional lights) are used as pathgrad's \
                 radiometric units, times the colour (no 683 lm/W conversion)"
                    .to_string(),
            );
        }
        let position = world.transform_point3(Vec3::ZERO);
        let axis = world.transform_vector3(-Vec3::Z).normalize_or_zero();
        if axis == Vec3::ZERO {
            return Err(self.error(format!("nodes[{node}]"), "the light's transform is degenerate"));
        }
        let (shape, what) = match light.type_ {
            Checked::Valid(Type::Point) => (LightShape::Point { position }, "intensity"),
            Checked::Valid(Type::Spot) => {
                let spot = light.spot.as_ref().ok_or_else(|| self.error(&at, "a spot light needs 'spot'"))?;
                let (inner, outer) = (spot.inner_cone_angle, spot.outer_cone_angle);
                if !(inner >= 0.0 && inner < outer && outer <= std::f32::consts::FRAC_PI_2) {
                    return Err(self.error(
                        &at,
                        format!("spot angles need 0 ≤ innerConeAngle < outerConeAngle ≤ π/2, got {inner} and {outer}"),
                    ));
                }
                // Mitsuba's spot: full intensity within the inner cone, falling linearly in angle
                // to 0 at the outer one (glTF suggests a falloff in cos; documented).
                let cutoff = outer.to_degrees();
                let beam_width = inner.to_degrees().max(MIN_BEAM_WIDTH_DEGREES);
                // The frame matters only to a texture (glTF's lights have none): the node's axes,
                // z turned to the axis (the node's −z).
                let to_local =
                    glam::Mat3::from_diagonal(Vec3::new(1.0, 1.0, -1.0)) * glam::Mat3::from_mat4(*world).inverse();
                (LightShape::Spot { position, axis, cutoff, beam_width, to_local }, "intensity")
            }
            Checked::Valid(Type::Directional) => (LightShape::Directional { direction: axis }, "irradiance"),
            Checked::Invalid => return Err(self.error(&at, "unknown light type")),
        };
        let name = &self.node_names[node];
        let value = colour * light.intensity;
        let intensity = self.scene.params.add(&format!("{name}.{what}.value"), &value.to_array(), bounds::RADIANCE)?;
        self.scene.lights.push(Light { shape, intensity: Some(intensity), texture: None });
        Ok(())
    }

    // ---- camera ----

    pub(super) fn camera(&mut self, node: usize, index: usize, world: &Mat4) -> Result<()> {
        let root = self.root;
        let camera = &root.cameras[index];
        let at = format!("cameras[{index}]");
        // (vertical fov, height, lens): a pinhole, or parallel rays from a film of half extents
        // xmag × ymag on the plane znear ahead.
        let (yfov, height, lens) = match (&camera.type_, &camera.perspective, &camera.orthographic) {
            (Checked::Valid(json::camera::Type::Perspective), Some(perspective), _) => {
                let yfov = perspective.yfov;
                if !(yfov > 0.0 && yfov < std::f32::consts::PI) {
                    return Err(self.error(at, format!("yfov {yfov} must lie in (0, π)")));
                }
                let height = match perspective.aspect_ratio {
                    None => DEFAULT_WIDTH,
                    Some(a) if a > 0.0 && a.is_finite() => ((DEFAULT_WIDTH as f32 / a).round() as u32).max(1),
                    Some(a) => return Err(self.error(at, format!("aspectRatio {a} must be positive"))),
                };
                (yfov, height, crate::scene::Lens::Pinhole)
            }
            (Checked::Valid(json::camera::Type::Orthographic), _, Some(o)) => {
                let (x, y) = (o.xmag.abs(), o.ymag.abs());
                if !(x > 0.0 && y > 0.0 && x.is_finite() && y.is_finite()) {
                    return Err(self.error(at, format!("xmag {} and ymag {} must be non-zero", o.xmag, o.ymag)));
                }
                let height = ((DEFAULT_WIDTH as f32 * y / x).round() as u32).max(1);
                let aspect = DEFAULT_WIDTH as f32 / height as f32;
                let lens = crate::scene::Lens::Orthographic {
                    half_height: y,
                    stretch: x / y / aspect,
                    near_clip: o.znear.max(0.0),
                };
                (DEFAULT_ORTHOGRAPHIC_FOV.to_radians(), height, lens)
            }
            _ => {
                return Err(self.error(
                    at,
                    "needs type 'perspective' with a 'perspective' object, or 'orthographic' with an 'orthographic' one",
                ));
            }
        };
        let position = world.transform_point3(Vec3::ZERO);
        let forward = world.transform_vector3(-Vec3::Z).normalize_or_zero();
        let up = world.transform_vector3(Vec3::Y);
        if forward == Vec3::ZERO || forward.cross(up).length_squared() == 0.0 {
            return Err(self.error(format!("nodes[{node}]"), "the camera's transform is degenerate"));
        }
        let camera = Camera {
            position,
            target: position + forward,
            up: up.normalize(),
            fov_y_degrees: yfov.to_degrees(),
            width: DEFAULT_WIDTH,
            height,
            filter: crate::scene::PixelFilter::Box,
            lens,
            window: crate::scene::FilmWindow::default(),
        };
        // Named by its node (node names are unique: `unique_names`).
        self.cameras.push(crate::scene::Sensor { name: self.node_names[node].clone(), camera });
        Ok(())
    }

    pub(super) fn default_camera(&mut self) {
        let mut lo = Vec3::splat(f32::INFINITY);
        let mut hi = Vec3::splat(f32::NEG_INFINITY);
        for p in self.scene.meshes.iter().flat_map(|m| &m.positions) {
            lo = lo.min(*p);
            hi = hi.max(*p);
        }
        if lo.cmpgt(hi).any() {
            (lo, hi) = (Vec3::splat(-1.0), Vec3::splat(1.0));
        }
        let center = 0.5 * (lo + hi);
        let radius = (0.5 * (hi - lo).length()).max(1e-3);
        let distance = radius / (0.5 * DEFAULT_FOV_Y_DEGREES.to_radians()).sin();
        let position = center + Vec3::Z * distance;
        self.scene.camera = Camera { position, target: center, ..placeholder_camera() };
        self.scene.sensors = vec![crate::scene::Sensor { name: "default".into(), camera: self.scene.camera }];
        self.scene.warn(format!(
            "no perspective camera in the scene; using a default one at {position} looking down -z at {center} \
             (yfov {DEFAULT_FOV_Y_DEGREES}°, {DEFAULT_WIDTH}×{DEFAULT_WIDTH})"
        ));
    }

    // ---- meshes ----

    pub(super) fn mesh(&mut self, node: usize, index: usize, world: &Mat4) -> Result<()> {
        let root = self.root;
        let mesh = &root.meshes[index];
        if root.nodes[node].skin.is_some() {
            self.scene.warn(format!("nodes[{node}]: skin ignored (the bind pose is rendered)"));
        }
        for (j, primitive) in mesh.primitives.iter().enumerate() {
            let at = format!("meshes[{index}].primitives[{j}]");
            match primitive.mode {
                Checked::Valid(json::mesh::Mode::Triangles) => {}
                Checked::Valid(mode) => {
                    return Err(self.error(
                        at,
                        format!("mode {} ({mode:?}) is not supported (only TRIANGLES, mode 4)", mode.as_gl_enum()),
                    ));
                }
                Checked::Invalid => return Err(self.error(at, "invalid mode")),
            }
            if primitive.targets.as_ref().is_some_and(|t| !t.is_empty()) {
                self.scene.warn(format!("{at}: morph targets ignored"));
            }
            let material = self.material(primitive.material.map(|m| m.value()))?;
            let geometry = self.geometry(&at, primitive, material.tex_coord)?;
            if material.normal_mapped
                && primitive.attributes.contains_key(&Checked::Valid(json::mesh::Semantic::Tangents))
            {
                self.scene.warn(format!(
                    "{at}: TANGENT ignored: the normal texture's frame is ∂p/∂u of each triangle with bitangent n × t \
                     (glTF's frame without tangents; MikkTSpace's per-vertex tangents and their handedness are not read)"
                ));
            }
            let name = if mesh.primitives.len() > 1 {
                // One mesh per primitive: `node_j`, kept apart from every other node's name.
                let name = fresh_name(&self.taken_names, format!("{}_{j}", self.node_names[node]));
                self.taken_names.insert(name.clone());
                name
            } else {
                self.node_names[node].clone()
            };
            match material.emission {
                None => self.scene.add_mesh(&name, geometry.transformed(world), material.id, None)?,
                Some(Emission::Constant(radiance)) => {
                    self.scene.add_mesh(&name, geometry.transformed(world), material.id, Some(radiance))?;
                }
                Some(Emission::Texture { width, height, ref texels }) => {
                    // Each mesh's radiance is its own parameter, as a constant one is.
                    let param = format!("{name}.emitter.radiance.data");
                    let texture =
                        self.scene.add_texture_in(&param, width, height, texels, crate::scene::bounds::RADIANCE)?;
                    self.scene.add_mesh(&name, geometry.transformed(world), material.id, None)?;
                    let mesh = self.scene.meshes.last_mut().expect("add_mesh pushed a mesh");
                    mesh.emitter = Some(self.scene.textures[texture.0 as usize].texels);
                    mesh.emitter_texture = Some(crate::scene::Albedo::Bitmap(texture));
                }
            }
        }
        Ok(())
    }

    pub(super) fn geometry(
        &mut self,
        at: &str,
        primitive: &json::mesh::Primitive,
        tex_coord: Option<u32>,
    ) -> Result<Geometry> {
        use json::mesh::Semantic;
        let attribute = |semantic: Semantic| primitive.attributes.get(&Checked::Valid(semantic)).map(|a| a.value());
        let positions_accessor =
            attribute(Semantic::Positions).ok_or_else(|| self.error(at, "has no POSITION attribute"))?;
        let positions = self.read_floats(positions_accessor, 3, false, &format!("POSITION of {at}"))?;
        let n = positions.len() / 3;
        let mut g = Geometry {
            positions: positions.chunks_exact(3).map(|p| Vec3::new(p[0], p[1], p[2])).collect(),
            ..Default::default()
        };
        if let Some(normals) = attribute(Semantic::Normals) {
            let normals = self.read_floats(normals, 3, false, &format!("NORMAL of {at}"))?;
            if normals.len() != 3 * n {
                return Err(self.error(at, format!("NORMAL has {} elements but POSITION has {n}", normals.len() / 3)));
            }
            g.normals =
                Some(normals.chunks_exact(3).map(|v| Vec3::new(v[0], v[1], v[2]).normalize_or_zero()).collect());
        }
        let set = tex_coord.unwrap_or(0);
        match attribute(Semantic::TexCoords(set)) {
            Some(uvs) => {
                let uvs = self.read_floats(uvs, 2, true, &format!("TEXCOORD_{set} of {at}"))?;
                if uvs.len() != 2 * n {
                    return Err(
                        self.error(at, format!("TEXCOORD_{set} has {} elements but POSITION has {n}", uvs.len() / 2))
                    );
                }
                g.uvs = Some(uvs.chunks_exact(2).map(|t| Vec2::new(t[0], t[1])).collect());
            }
            None if tex_coord.is_some() => {
                return Err(self.error(
                    at,
                    format!("its material has a base-colour or normal texture but the primitive has no TEXCOORD_{set}"),
                ));
            }
            None => {}
        }
        let indices = match primitive.indices {
            Some(a) => self.read_indices(a.value(), &format!("indices of {at}"))?,
            None => (0..n as u32).collect(),
        };
        if indices.len() % 3 != 0 {
            return Err(self.error(at, format!("{} indices is not a multiple of 3", indices.len())));
        }
        if let Some(bad) = indices.iter().find(|&&i| i as usize >= n) {
            return Err(self.error(at, format!("index {bad} is out of range ({n} vertices)")));
        }
        g.indices = indices.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect();
        Ok(g)
    }

    // ---- buffers and accessors ----
}

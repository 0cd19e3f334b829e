//! glTF 2.0 scenes (`.gltf` with external or embedded resources, `.glb`) → [`Scene`].
//!
//! The `gltf` crate parses the JSON (and the GLB container) and `gltf-json`'s validator checks
//! references and enumerations; everything after that — buffers, accessors, images, the node tree —
//! is read here from the validated JSON with every offset and index checked, because the crate's
//! own readers slice and `unwrap` on malformed files.
//!
//! # What is read
//! - **Nodes**: the default scene's node trees (`scene`, else `scenes[0]`, else every root node),
//!   with each node's `matrix` or `translation`/`rotation`/`scale`, composed parent → child. A node
//!   reached twice (a cycle, or two parents) is an error. Skins and morph targets are ignored with a
//!   warning (the bind pose is rendered).
//! - **Meshes**: each primitive of mode `TRIANGLES` (4) becomes one pathgrad mesh — `POSITION`,
//!   optional `NORMAL`, optional `TEXCOORD_n` (the set the base-colour texture names, else 0),
//!   optional `indices` — transformed to world space. Other modes are rejected.
//! - **Camera**: the first node (depth-first, in scene order) carrying a perspective camera. glTF
//!   cameras look along their local −z with +y up; `yfov` is used, `znear`/`zfar` are ignored; the
//!   image is 512 pixels wide and `round(512 / aspectRatio)` high (512 × 512 without `aspectRatio`).
//!   **Without a perspective camera** the scene gets a default one, with a warning: yfov 45°,
//!   512 × 512, looking down −z at the centre of the meshes' bounding box from the distance at
//!   which their bounding sphere fills the view.
//!
//! # Materials
//! glTF's metallic-roughness BRDF (glTF 2.0 spec, appendix B) mixes a dielectric — a Fresnel-weighted
//! mix of a Lambertian base and a GGX lobe with F0 = 0.04 — and a metal whose GGX lobe is tinted by
//! the base colour through Schlick's Fresnel, by `metallic`. pathgrad's blend weights are constants,
//! so the mapping freezes every Fresnel term at its normal-incidence value; the result equals glTF's
//! BRDF at normal incidence, and at grazing angles — where glTF's Schlick terms rise toward 1 — its
//! specular lobes are dimmer and its diffuse part slightly brighter than glTF's.
//! With b = base colour, m = metallic, r = roughness:
//!
//! | glTF material | pathgrad material | parameters (names) |
//! |---|---|---|
//! | m = 1 | rough conductor, GGX, α = max(r², 10⁻³), specular reflectance b, η = 0, k = 1 (F ≡ 1) | `M.alpha.value`, `M.specular_reflectance.value` |
//! | m < 1 | blend (1 − w)·diffuse(b) + w·conductor, w = 0.04 + 0.96·m; the conductor is GGX with α = max(r², 10⁻³), η = 0, k = 1, specular reflectance s = (m·b + 0.04·(1 − m)) / w (white 1 for m = 0) | `M.weight.value`, `M.bsdf_0.reflectance.value`, `M.bsdf_1.alpha.value`, `M.bsdf_1.specular_reflectance.value` |
//! | base-colour texture | the diffuse albedo is the texture (sRGB bytes linearised, times `baseColorFactor`); the conductor uses the texture's mean colour (warned when m > 0) | `M.base_color.data` (texels, replaces `M.bsdf_0.reflectance.value`) |
//! | `emissiveFactor` × `KHR_materials_emissive_strength` | area emitter on each mesh using the material (front faces), linear radiance | `<mesh>.emitter.radiance.value` |
//! | `doubleSided: true` | the material wrapped in `TwoSided` (names unchanged) | — |
//! | no material | glTF's default material: b = 1, m = 1, r = 1 | as above with M = `default_material` |
//!
//! For m = 0 the blend is 0.96·diffuse(b) + 0.04·GGX — exactly glTF's dielectric with its Fresnel
//! held at F0 = 0.04; for 0 < m < 1 it is glTF's mix of the two at normal incidence, with the
//! dielectric's and the metal's GGX lobes (same α) merged into one conductor. Ignored, with a
//! warning: `metallicRoughnessTexture`, `normalTexture`, `occlusionTexture`, `emissiveTexture`,
//! alpha modes other than `OPAQUE`, and extensions other than `KHR_materials_emissive_strength`.
//! Texture samplers are ignored: pathgrad filters bilinearly with repeat wrapping. glTF texture
//! coordinates put v = 0 at the image's top row, which is pathgrad's row 0: no flip.
//!
//! # Names
//! A material is called by its `name` with every character other than ASCII letters, digits, `_`
//! and `-` replaced by `_`, or `material_<index>` if it has none; a mesh by its node's name the
//! same way, or `node_<index>`, with `_<primitive index>` appended when the glTF mesh has several
//! primitives. When several materials (or nodes) share a name, each of them gets `_<index>`
//! appended.
//!
//! # Errors
//! Every error names the file and the glTF element (`meshes[2].primitives[0]`, `materials[1]`,
//! `accessors[3]`); JSON syntax errors name the line and column. No input panics: the inputs that
//! `gltf` 1.4 is known to panic on are rejected first (a GLB header length below 12, which it
//! underflows on; a `POSITION` accessor index out of range, which `gltf-json`'s validator indexes
//! with before checking it), and parsing and validation still run under
//! [`std::panic::catch_unwind`] as a backstop.

use std::collections::{HashMap, HashSet};
use std::fmt::Display;
use std::path::Path;

use ::gltf::json;
use glam::{Mat4, Quat, Vec2, Vec3};
use json::validation::Checked;

use crate::bsdf::Distribution;
use crate::error::{Error, Result};
use crate::scene::mesh_io::{catch_panic, read_file};
use crate::scene::shapes::Geometry;
use crate::scene::{Albedo, Camera, LoadOptions, Material, MaterialId, Scene, bounds};

/// Width of the image when the camera does not say (pixels).
pub const DEFAULT_WIDTH: u32 = 512;
/// Vertical field of view of the default camera used when the file has none (degrees).
pub const DEFAULT_FOV_Y_DEGREES: f32 = 45.0;
/// glTF's dielectric reflectance at normal incidence (F0 for IOR 1.5).
pub const DIELECTRIC_F0: f32 = 0.04;
/// Extensions whose content is used; others named in `extensionsUsed` are reported as ignored.
const SUPPORTED_EXTENSIONS: &[&str] = &["KHR_materials_emissive_strength"];

/// Loads a `.gltf` or `.glb` file into a validated [`Scene`]; see the module docs for what is read
/// and how materials map.
///
/// # Errors
/// [`Error::Io`] if the file cannot be read; [`Error::Scene`] naming the file and the glTF element
/// for invalid JSON or GLB, references out of range, missing or short buffers, accessors that do
/// not fit their buffer view or have the wrong type, non-triangle primitives, indices out of range,
/// non-finite transforms or values, values outside glTF's ranges, undecodable images, node cycles,
/// and whatever [`Scene::validate`] rejects (e.g. a scene without triangles).
pub fn load(path: &Path) -> Result<Scene> {
    load_with(path, &LoadOptions::default())
}

/// Loads a `.gltf` or `.glb` file as [`load`], under `options`' folder rule (by default a buffer
/// or image URI must name a file inside the scene's folder).
///
/// # Errors
/// As [`load`].
pub fn load_with(path: &Path, options: &LoadOptions) -> Result<Scene> {
    let bytes = read_file(path)?;
    let gltf = parse(path, &bytes)?;
    let root = gltf.document.as_json();
    let mut loader = Loader {
        path,
        root,
        blob: gltf.blob.as_deref(),
        buffers: vec![None; root.buffers.len()],
        materials: vec![None; root.materials.len() + 1],
        material_names: unique_names(root.materials.iter().map(|m| m.name.as_deref()), "material"),
        node_names: unique_names(root.nodes.iter().map(|n| n.name.as_deref()), "node"),
        taken_names: HashSet::new(),
        allow_outside_folder: options.allow_outside_folder,
        scene: Scene::new(&path.display().to_string(), placeholder_camera()),
        camera: None,
    };
    loader.taken_names = loader.node_names.iter().cloned().collect();
    // Errors raised below the loader (a parameter defined twice, say) get the file's name too.
    let file = path.display().to_string();
    loader.run().map_err(|e| match e {
        Error::Scene { location, message } if !location.starts_with(&file) => {
            Error::Scene { location: format!("{file}: {location}"), message }
        }
        e => e,
    })?;
    let mut scene = loader.scene;
    if scene.meshes.iter().all(|m| m.emitter.is_none()) && scene.environment.is_none() {
        scene.warn("the scene has no emitters (no material has an emissiveFactor): it renders black".into());
    }
    scene.validate()?;
    Ok(scene)
}

/// Parses the JSON (and GLB container) with the `gltf` crate and validates it with `gltf-json`'s
/// validator.
fn parse(path: &Path, bytes: &[u8]) -> Result<::gltf::Gltf> {
    let at = |location: String, message: String| Error::Scene { location, message };
    let file = path.display();
    if bytes.is_empty() {
        return Err(at(file.to_string(), "the file is empty (0 bytes)".into()));
    }
    let is_glb_name = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("glb"));
    if is_glb_name && !bytes.starts_with(b"glTF") {
        let head: String = bytes.iter().take(4).map(|&b| if b.is_ascii_graphic() { b as char } else { '.' }).collect();
        return Err(at(
            file.to_string(),
            format!("not a GLB file: it does not begin with the magic 'glTF' (it begins with '{head}')"),
        ));
    }
    if bytes.starts_with(b"glTF") {
        // gltf 1.4 computes `length - 12` unchecked on the header's length field.
        let length = bytes.get(8..12).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]));
        if length.is_none_or(|l| l < 12) {
            return Err(at(
                file.to_string(),
                "not a valid GLB file: the header is truncated or its length is below 12".into(),
            ));
        }
    }
    let parsed = catch_panic(|| ::gltf::Gltf::from_slice_without_validation(bytes))
        .ok_or_else(|| at(file.to_string(), "the glTF parser panicked on this file".into()))?;
    let gltf = parsed.map_err(|e| match e {
        ::gltf::Error::Deserialize(e) if !bytes.starts_with(b"glTF") => {
            let text = e.to_string();
            let suffix = format!(" at line {} column {}", e.line(), e.column());
            let message = text.strip_suffix(&suffix).unwrap_or(&text);
            at(format!("{file}:{}:{}", e.line(), e.column()), format!("invalid glTF JSON: {message}"))
        }
        ::gltf::Error::Deserialize(e) => at(format!("{file}: GLB JSON chunk"), format!("invalid glTF JSON: {e}")),
        ::gltf::Error::Binary(e) => at(file.to_string(), format!("not a valid GLB file: {e}")),
        e => at(file.to_string(), e.to_string()),
    })?;
    // gltf-json 1.4's primitive validation indexes `accessors` with the POSITION index before
    // the index itself is checked, so that one is checked first.
    let root = gltf.document.as_json();
    for (i, mesh) in root.meshes.iter().enumerate() {
        for (j, primitive) in mesh.primitives.iter().enumerate() {
            let position = primitive.attributes.get(&Checked::Valid(json::mesh::Semantic::Positions));
            if position.is_some_and(|a| a.value() >= root.accessors.len()) {
                return Err(at(
                    format!("{file}: meshes[{i}].primitives[{j}].attributes[\"POSITION\"]"),
                    "Index out of bounds".into(),
                ));
            }
        }
    }
    let mut errors = Vec::new();
    catch_panic(|| {
        use json::validation::Validate;
        root.validate(root, json::Path::new, &mut |path, error| errors.push((path(), error)))
    })
    .ok_or_else(|| at(file.to_string(), "the glTF validator panicked on this file".into()))?;
    if let Some((first, error)) = errors.first() {
        let more = match errors.len() {
            1 => String::new(),
            n => format!(" (and {} more problem{})", n - 1, if n == 2 { "" } else { "s" }),
        };
        return Err(at(format!("{file}: {first}"), format!("{error}{more}")));
    }
    Ok(gltf)
}

fn placeholder_camera() -> Camera {
    Camera {
        position: Vec3::ZERO,
        target: -Vec3::Z,
        up: Vec3::Y,
        fov_y_degrees: DEFAULT_FOV_Y_DEGREES,
        width: DEFAULT_WIDTH,
        height: DEFAULT_WIDTH,
    }
}

/// `name` with characters other than ASCII letters, digits, `_` and `-` replaced by `_`.
fn sanitize(name: &str) -> String {
    name.chars().map(|c| if c.is_ascii_alphanumeric() || c == '_' || c == '-' { c } else { '_' }).collect()
}

/// The names of a list of glTF objects: sanitised, `<kind>_<index>` when missing or empty, and
/// `_<index>` appended to every name that occurs more than once.
fn unique_names<'a>(names: impl Iterator<Item = Option<&'a str>>, kind: &str) -> Vec<String> {
    let names: Vec<String> = names
        .enumerate()
        .map(|(i, n)| match n.map(sanitize) {
            Some(n) if !n.is_empty() => n,
            _ => format!("{kind}_{i}"),
        })
        .collect();
    let mut counts: HashMap<&str, usize> = HashMap::with_capacity(names.len());
    for n in &names {
        *counts.entry(n.as_str()).or_default() += 1;
    }
    // Names that occur once keep themselves; a repeated name gets its index, and a further
    // suffix if even that is taken (`m`, `m`, `m_1` → `m_0`, `m_1_1`, `m_1`).
    let mut taken: HashSet<String> = names.iter().filter(|n| counts[n.as_str()] == 1).cloned().collect();
    names
        .iter()
        .enumerate()
        .map(|(i, n)| {
            if counts[n.as_str()] == 1 {
                return n.clone();
            }
            let name = fresh_name(&taken, format!("{n}_{i}"));
            taken.insert(name.clone());
            name
        })
        .collect()
}

/// `candidate`, or `candidate_K` for the smallest K ≥ 1 that is not in `taken`.
fn fresh_name(taken: &HashSet<String>, candidate: String) -> String {
    if !taken.contains(&candidate) {
        return candidate;
    }
    (1..).map(|k| format!("{candidate}_{k}")).find(|c| !taken.contains(c)).expect("some suffix is free")
}

/// What a glTF material became.
#[derive(Clone, Debug)]
struct MappedMaterial {
    id: MaterialId,
    /// Emitted radiance (linear RGB), if any component is positive.
    radiance: Option<Vec3>,
    /// The `TEXCOORD_n` set the base-colour texture reads, if the material is textured.
    tex_coord: Option<u32>,
}

struct Loader<'a> {
    path: &'a Path,
    root: &'a json::Root,
    /// The GLB binary chunk.
    blob: Option<&'a [u8]>,
    /// Loaded buffers, by index.
    buffers: Vec<Option<Vec<u8>>>,
    /// Mapped materials by index; the last slot is glTF's default material.
    materials: Vec<Option<MappedMaterial>>,
    material_names: Vec<String>,
    node_names: Vec<String>,
    /// Whether URIs may name files outside the scene's folder.
    allow_outside_folder: bool,
    /// Node names and the mesh names made so far (a primitive of a multi-primitive mesh is `node_j`).
    taken_names: HashSet<String>,
    scene: Scene,
    /// The camera found so far.
    camera: Option<Camera>,
}

/// An [`Error::Scene`] at `file: element`.
fn located(path: &Path, element: impl Display, message: impl Into<String>) -> Error {
    Error::Scene { location: format!("{}: {element}", path.display()), message: message.into() }
}

impl Loader<'_> {
    fn error(&self, element: impl Display, message: impl Into<String>) -> Error {
        located(self.path, element, message)
    }

    fn run(&mut self) -> Result<()> {
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
            if let Some(mesh) = node.mesh {
                self.mesh(index, mesh.value(), &world)?;
            }
            for child in node.children.iter().flatten().rev() {
                stack.push((child.value(), world));
            }
        }
        match self.camera {
            Some(camera) => self.scene.camera = camera,
            None => self.default_camera(),
        }
        Ok(())
    }

    fn local_transform(&self, index: usize) -> Result<Mat4> {
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

    // ---- camera ----

    fn camera(&mut self, node: usize, index: usize, world: &Mat4) -> Result<()> {
        let root = self.root;
        let camera = &root.cameras[index];
        let at = format!("cameras[{index}]");
        let perspective = match (&camera.type_, &camera.perspective) {
            (Checked::Valid(json::camera::Type::Perspective), Some(p)) => p,
            (Checked::Valid(json::camera::Type::Orthographic), _) => {
                self.scene.warn(format!("{at}: orthographic cameras are not supported; ignored"));
                return Ok(());
            }
            _ => return Err(self.error(at, "needs type 'perspective' with a 'perspective' object")),
        };
        if self.camera.is_some() {
            return Ok(());
        }
        let yfov = perspective.yfov;
        if !(yfov > 0.0 && yfov < std::f32::consts::PI) {
            return Err(self.error(at, format!("yfov {yfov} must lie in (0, π)")));
        }
        let height = match perspective.aspect_ratio {
            None => DEFAULT_WIDTH,
            Some(a) if a > 0.0 && a.is_finite() => ((DEFAULT_WIDTH as f32 / a).round() as u32).max(1),
            Some(a) => return Err(self.error(at, format!("aspectRatio {a} must be positive"))),
        };
        let position = world.transform_point3(Vec3::ZERO);
        let forward = world.transform_vector3(-Vec3::Z).normalize_or_zero();
        let up = world.transform_vector3(Vec3::Y);
        if forward == Vec3::ZERO || forward.cross(up).length_squared() == 0.0 {
            return Err(self.error(format!("nodes[{node}]"), "the camera's transform is degenerate"));
        }
        self.camera = Some(Camera {
            position,
            target: position + forward,
            up: up.normalize(),
            fov_y_degrees: yfov.to_degrees(),
            width: DEFAULT_WIDTH,
            height,
        });
        Ok(())
    }

    fn default_camera(&mut self) {
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
        self.scene.warn(format!(
            "no perspective camera in the scene; using a default one at {position} looking down -z at {center} \
             (yfov {DEFAULT_FOV_Y_DEGREES}°, {DEFAULT_WIDTH}×{DEFAULT_WIDTH})"
        ));
    }

    // ---- meshes ----

    fn mesh(&mut self, node: usize, index: usize, world: &Mat4) -> Result<()> {
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
            let name = if mesh.primitives.len() > 1 {
                // One mesh per primitive: `node_j`, kept apart from every other node's name.
                let name = fresh_name(&self.taken_names, format!("{}_{j}", self.node_names[node]));
                self.taken_names.insert(name.clone());
                name
            } else {
                self.node_names[node].clone()
            };
            self.scene.add_mesh(&name, geometry.transformed(world), material.id, material.radiance)?;
        }
        Ok(())
    }

    fn geometry(&mut self, at: &str, primitive: &json::mesh::Primitive, tex_coord: Option<u32>) -> Result<Geometry> {
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
                    format!("its material has a base-colour texture but the primitive has no TEXCOORD_{set}"),
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

    /// The bytes of buffer `index`, loaded on first use.
    fn buffer(&mut self, index: usize) -> Result<&[u8]> {
        let root = self.root;
        if self.buffers[index].is_none() {
            let buffer = &root.buffers[index];
            let at = format!("buffers[{index}]");
            let data = match (&buffer.uri, self.blob) {
                (Some(uri), _) => self.read_uri(&at, uri)?,
                (None, Some(blob)) if index == 0 => blob.to_vec(),
                (None, _) => return Err(self.error(at, "has no uri and the file has no GLB binary chunk")),
            };
            if (data.len() as u64) < buffer.byte_length.0 {
                return Err(self
                    .error(at, format!("holds {} bytes but its byteLength is {}", data.len(), buffer.byte_length.0)));
            }
            self.buffers[index] = Some(data);
        }
        Ok(self.buffers[index].as_deref().expect("loaded above"))
    }

    /// The bytes a URI names: a base64 `data:` URI, or a file relative to the glTF file.
    fn read_uri(&self, at: &str, uri: &str) -> Result<Vec<u8>> {
        if let Some(rest) = uri.strip_prefix("data:") {
            let data = rest.split_once(";base64,").map(|(_, d)| d);
            return data
                .and_then(decode_base64)
                .ok_or_else(|| self.error(at, "data URI is not base64 ('data:<type>;base64,<data>')"));
        }
        if uri.split('/').next().is_some_and(|first| first.contains(':')) {
            return Err(self.error(at, format!("URI '{uri}': only relative paths and data: URIs are supported")));
        }
        let relative = percent_decode(uri)
            .ok_or_else(|| self.error(at, format!("URI '{uri}' is not valid percent-encoded UTF-8")))?;
        let dir = self.path.parent().unwrap_or(Path::new("."));
        let file = crate::scene::load::scene_file(dir, &relative, self.allow_outside_folder)
            .map_err(|m| self.error(at, format!("URI {m}")))?;
        std::fs::read(&file).map_err(|e| self.error(at, format!("cannot read '{relative}': {e}")))
    }

    /// The bytes of buffer view `index` and its stride.
    fn view(&mut self, index: usize, at: &str) -> Result<(&[u8], Option<usize>)> {
        let (root, path) = (self.root, self.path);
        let view = &root.buffer_views[index];
        let (offset, length) = (view.byte_offset.map_or(0, |o| o.0), view.byte_length.0);
        let stride = view.byte_stride.map(|s| s.0).filter(|&s| s > 0);
        let buffer_index = view.buffer.value();
        let data = self.buffer(buffer_index)?;
        let end = offset.checked_add(length).filter(|&e| e <= data.len() as u64).ok_or_else(|| {
            located(
                path,
                format!("bufferViews[{index}] ({at})"),
                format!(
                    "bytes {offset}..{} lie outside buffers[{buffer_index}], which has {} bytes",
                    offset.saturating_add(length),
                    data.len()
                ),
            )
        })?;
        Ok((&data[offset as usize..end as usize], stride))
    }

    /// The elements of accessor `index` as `count × dims` raw component bytes, with the component
    /// type. An accessor without a buffer view is all zeros (glTF 2.0 §3.6.2.1).
    fn accessor_components(
        &mut self,
        index: usize,
        dims: usize,
        what: &str,
    ) -> Result<(Vec<u8>, json::accessor::ComponentType, bool)> {
        let root = self.root;
        let accessor = &root.accessors[index];
        let at = format!("accessors[{index}] ({what})");
        if accessor.sparse.is_some() {
            return Err(self.error(at, "sparse accessors are not supported"));
        }
        let component = match accessor.component_type {
            Checked::Valid(json::accessor::GenericComponentType(c)) => c,
            Checked::Invalid => return Err(self.error(at, "invalid componentType")),
        };
        let actual_dims = match accessor.type_ {
            Checked::Valid(t) => t.multiplicity(),
            Checked::Invalid => return Err(self.error(at, "invalid type")),
        };
        if actual_dims != dims {
            let name =
                |n: usize| ["SCALAR", "VEC2", "VEC3", "VEC4"].get(n.wrapping_sub(1)).copied().unwrap_or("a matrix");
            return Err(self.error(at, format!("expected type {}, found {}", name(dims), name(actual_dims))));
        }
        let count = accessor.count.0 as usize;
        let size = component.size() * dims;
        let Some(view) = accessor.buffer_view else {
            return Ok((vec![0; count.saturating_mul(size)], component, accessor.normalized));
        };
        let offset = accessor.byte_offset.map_or(0, |o| o.0) as usize;
        let normalized = accessor.normalized;
        let path = self.path;
        let err = |message: String| located(path, &at, message);
        let (data, stride) = self.view(view.value(), &at)?;
        let stride = stride.unwrap_or(size);
        if stride < size {
            return Err(err(format!("byteStride {stride} is smaller than an element ({size} bytes)")));
        }
        let end = if count == 0 {
            Some(offset)
        } else {
            stride.checked_mul(count - 1).and_then(|s| s.checked_add(offset)).and_then(|s| s.checked_add(size))
        };
        match end {
            Some(end) if end <= data.len() => {}
            _ => {
                return Err(err(format!(
                    "{count} elements of {size} bytes from offset {offset} (stride {stride}) do not fit in bufferViews[{}], which has {} bytes",
                    view.value(),
                    data.len()
                )));
            }
        }
        let mut out = Vec::with_capacity(count * size);
        for i in 0..count {
            out.extend_from_slice(&data[offset + i * stride..offset + i * stride + size]);
        }
        Ok((out, component, normalized))
    }

    /// Accessor `index` as floats: FLOAT, or (when `allow_normalized`) normalized unsigned bytes/shorts.
    fn read_floats(&mut self, index: usize, dims: usize, allow_normalized: bool, what: &str) -> Result<Vec<f32>> {
        use json::accessor::ComponentType as C;
        let (bytes, component, normalized) = self.accessor_components(index, dims, what)?;
        let values: Vec<f32> = match component {
            C::F32 => bytes.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect(),
            C::U8 if allow_normalized && normalized => bytes.iter().map(|&b| f32::from(b) / 255.0).collect(),
            C::U16 if allow_normalized && normalized => {
                bytes.chunks_exact(2).map(|b| f32::from(u16::from_le_bytes([b[0], b[1]])) / 65535.0).collect()
            }
            other => {
                let allowed =
                    if allow_normalized { "FLOAT or normalized UNSIGNED_BYTE/UNSIGNED_SHORT" } else { "FLOAT" };
                return Err(self.error(
                    format!("accessors[{index}] ({what})"),
                    format!(
                        "componentType {other:?}{} is not supported here (expected {allowed})",
                        if normalized { " normalized" } else { "" }
                    ),
                ));
            }
        };
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            return Err(
                self.error(format!("accessors[{index}] ({what})"), format!("element {} is not finite", i / dims))
            );
        }
        Ok(values)
    }

    /// Accessor `index` as vertex indices (UNSIGNED_BYTE, UNSIGNED_SHORT or UNSIGNED_INT scalars).
    fn read_indices(&mut self, index: usize, what: &str) -> Result<Vec<u32>> {
        use json::accessor::ComponentType as C;
        let (bytes, component, _) = self.accessor_components(index, 1, what)?;
        Ok(match component {
            C::U8 => bytes.iter().map(|&b| u32::from(b)).collect(),
            C::U16 => bytes.chunks_exact(2).map(|b| u32::from(u16::from_le_bytes([b[0], b[1]]))).collect(),
            C::U32 => bytes.chunks_exact(4).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect(),
            other => {
                return Err(self.error(
                    format!("accessors[{index}] ({what})"),
                    format!("componentType {other:?} cannot hold indices (expected UNSIGNED_BYTE, UNSIGNED_SHORT or UNSIGNED_INT)"),
                ));
            }
        })
    }

    // ---- materials ----

    /// The pathgrad material of glTF material `index` (`None`: the default material), mapped once.
    fn material(&mut self, index: Option<usize>) -> Result<MappedMaterial> {
        let root = self.root;
        let slot = index.unwrap_or(root.materials.len());
        if let Some(mapped) = &self.materials[slot] {
            return Ok(mapped.clone());
        }
        let default = json::Material::default();
        let (m, name, at) = match index {
            Some(i) => (&root.materials[i], self.material_names[i].clone(), format!("materials[{i}]")),
            None => (&default, "default_material".to_string(), "default material".to_string()),
        };
        let pbr = &m.pbr_metallic_roughness;
        let factor = pbr.base_color_factor.0;
        let (metallic, roughness) = (pbr.metallic_factor.0, pbr.roughness_factor.0);
        let in_unit = |v: f32| (0.0..=1.0).contains(&v);
        if !factor.iter().all(|&v| in_unit(v)) {
            return Err(self.error(&at, format!("baseColorFactor {factor:?} must lie in [0, 1]")));
        }
        if !in_unit(metallic) || !in_unit(roughness) {
            return Err(self
                .error(&at, format!("metallicFactor {metallic} and roughnessFactor {roughness} must lie in [0, 1]")));
        }
        let mut ignored = Vec::new();
        if pbr.metallic_roughness_texture.is_some() {
            ignored.push("metallicRoughnessTexture");
        }
        if m.normal_texture.is_some() {
            ignored.push("normalTexture");
        }
        if m.occlusion_texture.is_some() {
            ignored.push("occlusionTexture");
        }
        if m.emissive_texture.is_some() {
            ignored.push("emissiveTexture");
        }
        if !matches!(m.alpha_mode, Checked::Valid(json::material::AlphaMode::Opaque)) {
            ignored.push("alphaMode (rendered as OPAQUE)");
        }
        if !ignored.is_empty() {
            self.scene.warn(format!("{at} ('{name}'): ignored {}", ignored.join(", ")));
        }

        let base = Vec3::new(factor[0], factor[1], factor[2]);
        let alpha = (roughness * roughness).max(bounds::ALPHA.0);
        // The base-colour texture, linear and multiplied by the factor.
        let mut texture = None;
        let mut mean = base;
        let mut tex_coord = None;
        if let Some(info) = &pbr.base_color_texture {
            let image = root.textures[info.index.value()].source.value();
            let (w, h, texels) = self.image_texels(image, base)?;
            let sum = texels.chunks_exact(3).fold(Vec3::ZERO, |s, t| s + Vec3::new(t[0], t[1], t[2]));
            mean = sum / (w as f32 * h as f32);
            if metallic > 0.0 {
                self.scene.warn(format!(
                    "{at} ('{name}'): the base-colour texture tints only the diffuse part; the metallic part uses its \
                     mean colour {mean}"
                ));
            }
            if metallic < 1.0 {
                texture = Some(self.scene.add_texture(&format!("{name}.base_color.data"), w, h, &texels)?);
            }
            tex_coord = Some(info.tex_coord);
        }
        let id = if metallic >= 1.0 {
            self.scene.add_rough_conductor(&name, Distribution::Ggx, alpha, mean, Vec3::ZERO, Vec3::ONE)?
        } else {
            let weight = DIELECTRIC_F0 + (1.0 - DIELECTRIC_F0) * metallic;
            let specular = ((metallic * mean + Vec3::splat(DIELECTRIC_F0 * (1.0 - metallic))) / weight).min(Vec3::ONE);
            let diffuse = match texture {
                Some(t) => self.scene.add_material(Material::Diffuse { albedo: Albedo::Bitmap(t) }),
                None => self.scene.add_diffuse(&format!("{name}.bsdf_0"), base)?,
            };
            let lobe = self.scene.add_rough_conductor(
                &format!("{name}.bsdf_1"),
                Distribution::Ggx,
                alpha,
                specular,
                Vec3::ZERO,
                Vec3::ONE,
            )?;
            self.scene.add_blend(&name, weight, [diffuse, lobe])?
        };
        let id = if m.double_sided { self.scene.add_material(Material::TwoSided(id)) } else { id };

        let strength =
            m.extensions.as_ref().and_then(|e| e.emissive_strength.as_ref()).map_or(1.0, |s| s.emissive_strength.0);
        let radiance = Vec3::from(m.emissive_factor.0) * strength;
        if !(radiance.is_finite() && radiance.min_element() >= 0.0) {
            return Err(self.error(
                &at,
                format!("emitted radiance {radiance} (emissiveFactor × emissiveStrength) must be finite and ≥ 0"),
            ));
        }
        let mapped = MappedMaterial { id, radiance: (radiance.max_element() > 0.0).then_some(radiance), tex_coord };
        self.materials[slot] = Some(mapped.clone());
        Ok(mapped)
    }

    /// Image `index` decoded to linear RGB texels (sRGB decoded, times `factor`), row 0 at the top.
    fn image_texels(&mut self, index: usize, factor: Vec3) -> Result<(u32, u32, Vec<f32>)> {
        let root = self.root;
        let image = &root.images[index];
        let at = format!("images[{index}]");
        let bytes = match (&image.buffer_view, &image.uri) {
            (Some(view), _) => self.view(view.value(), &at)?.0.to_vec(),
            (None, Some(uri)) => self.read_uri(&at, uri)?,
            (None, None) => return Err(self.error(at, "has neither a uri nor a bufferView")),
        };
        let decoded =
            crate::scene::load::decode_image(&bytes).map_err(|e| self.error(&at, format!("cannot decode: {e}")))?;
        let rgb = decoded.to_rgb32f();
        let texels = rgb
            .pixels()
            .flat_map(|p| [0, 1, 2].map(|c| (srgb_to_linear(p.0[c]) * factor[c]).clamp(0.0, 1.0)))
            .collect();
        Ok((rgb.width(), rgb.height(), texels))
    }
}

/// The sRGB transfer function's inverse (IEC 61966-2-1).
pub fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 { c / 12.92 } else { ((c + 0.055) / 1.055).powf(2.4) }
}

/// Decodes standard base64 (with optional `=` padding); `None` on any other character.
fn decode_base64(text: &str) -> Option<Vec<u8>> {
    let value = |c: u8| -> Option<u32> {
        Some(match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' => 62,
            b'/' => 63,
            _ => return None,
        } as u32)
    };
    let text = text.trim_end_matches('=').as_bytes();
    let mut out = Vec::with_capacity(text.len() * 3 / 4);
    for chunk in text.chunks(4) {
        if chunk.len() == 1 {
            return None;
        }
        let mut bits = 0u32;
        for (i, &c) in chunk.iter().enumerate() {
            bits |= value(c)? << (18 - 6 * i);
        }
        out.extend_from_slice(&bits.to_be_bytes()[1..chunk.len()]);
    }
    Some(out)
}

/// Decodes `%XX` escapes; `None` for a malformed escape or a result that is not UTF-8.
fn percent_decode(text: &str) -> Option<String> {
    let bytes = text.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'%' {
            let hex = std::str::from_utf8(bytes.get(i + 1..i + 3)?).ok()?;
            out.push(u8::from_str_radix(hex, 16).ok()?);
            i += 3;
        } else {
            out.push(bytes[i]);
            i += 1;
        }
    }
    String::from_utf8(out).ok()
}

#[cfg(test)]
#[path = "gltf_fixtures.rs"]
mod fixtures;

#[cfg(test)]
#[path = "gltf_tests.rs"]
mod tests;

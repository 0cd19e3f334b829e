//! The loader: parses the document, collects defines and ids, walks `<scene>`'s children in order
//! and builds the [`Scene`].

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use glam::Vec3;
use rayon::prelude::*;
use roxmltree::NodeId;

use super::xml::{El, Props, Xml, is_identifier};
use crate::error::{Error, Result};
use crate::scene::shapes::Geometry;
use crate::scene::{Albedo, Camera, LoadOptions, MaterialId, Scene, bounds};

/// Deepest nesting of BSDFs and textures (through nested elements and `<ref>`s together).
pub(super) const MAX_NESTING: usize = 16;

/// Most XML nodes (elements, attributes' owners, text) a scene file may have: a memory bound for
/// hostile input (a few hundred MB at most). Real scenes keep triangles in mesh files and stay far
/// below, even with tens of thousands of shapes.
pub(super) const MAX_NODES: u32 = 1 << 22;

/// Object tags that may carry an `id`.
const ID_TAGS: &[&str] = &[
    "bsdf",
    "emitter",
    "film",
    "integrator",
    "medium",
    "phase",
    "rfilter",
    "sampler",
    "sensor",
    "shape",
    "texture",
    "volume",
];

/// Mesh file formats of `<shape type="obj|ply">`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum MeshFormat {
    /// Wavefront OBJ.
    Obj,
    /// Stanford PLY.
    Ply,
}

/// Reads a mesh file (the loader checks that the file exists first).
pub(crate) type MeshLoader = fn(MeshFormat, &Path) -> Result<Geometry>;

/// The mesh reader the public entry points use.
pub(crate) fn load_mesh_file(format: MeshFormat, path: &Path) -> Result<Geometry> {
    match format {
        MeshFormat::Obj => crate::scene::mesh_io::load_obj(path),
        MeshFormat::Ply => crate::scene::mesh_io::load_ply(path),
    }
}

/// Reads `path` and loads it with [`super::load_str`].
pub(super) fn load_path(path: &Path, options: &LoadOptions, meshes: MeshLoader) -> Result<Scene> {
    let bytes = std::fs::read(path).map_err(|source| Error::Io { path: path.to_path_buf(), source })?;
    let text = String::from_utf8(bytes).map_err(|e| Error::Scene {
        location: path.display().to_string(),
        message: format!("not UTF-8 text (invalid byte at offset {})", e.utf8_error().valid_up_to()),
    })?;
    load_text_with(&text, path, options, meshes)
}

/// Parses `text` (read from `file`) into a scene, with `defines` and otherwise default options.
#[cfg(test)]
pub(super) fn load_text(text: &str, file: &Path, defines: &[(String, String)], meshes: MeshLoader) -> Result<Scene> {
    let options = LoadOptions { defines: defines.to_vec(), ..LoadOptions::default() };
    load_text_with(text, file, &options, meshes)
}

/// Parses `text` (read from `file`) into a scene.
pub(super) fn load_text_with(text: &str, file: &Path, options: &LoadOptions, meshes: MeshLoader) -> Result<Scene> {
    let name = file.display().to_string();
    let dir = file.parent().map(Path::to_path_buf).unwrap_or_default();
    // Malformed XML is reported here, in the file it is in; the spliced text parses.
    let sources = super::include::splice(&name, text, &dir, options.allow_outside_folder)?;
    let parsing = roxmltree::ParsingOptions { allow_dtd: false, nodes_limit: MAX_NODES, ..Default::default() };
    let doc = roxmltree::Document::parse_with_options(&sources.text, parsing).map_err(|e| Error::Scene {
        location: sources.location(0),
        message: format!("the scene with its includes spliced in is not well-formed XML: {e}"),
    })?;
    let placeholder = Camera {
        position: Vec3::ZERO,
        target: Vec3::Z,
        up: Vec3::Y,
        fov_y_degrees: 45.0,
        width: 1,
        height: 1,
        filter: crate::scene::PixelFilter::Box,
        lens: crate::scene::Lens::Pinhole,
        window: crate::scene::FilmWindow::default(),
    };
    let mut loader = Loader {
        x: Xml::new(name.clone(), &doc).with_sources(&sources),
        dir,
        search: sources.search.clone(),
        attached: Vec::new(),
        scene: Scene::new(&name, placeholder),
        ids: HashMap::new(),
        names: HashMap::new(),
        top_names: HashMap::new(),
        materials: HashMap::new(),
        textures: HashMap::new(),
        scalar_textures: HashMap::new(),
        media: HashMap::new(),
        medium_shapes: Vec::new(),
        in_progress: Vec::new(),
        clips: Vec::new(),
        meshes,
        options,
        direct_emitter_samples: None,
        volpath_integrator: None,
        ptracer_integrator: None,
        instancing: None,
        attribute_shape: None,
        attribute_reads: 0,
        attribute_owners: HashMap::new(),
    };
    loader.run(doc.root_element(), &options.defines)?;
    loader.scene.validate()?;
    Ok(loader.scene)
}

/// A sensor's clip distance waiting for the shapes ([`Loader::clip_warnings`]).
pub(super) struct PendingClip {
    /// The sensor's camera.
    pub camera: crate::scene::Camera,
    /// `near_clip` (else `far_clip`).
    pub near: bool,
    /// Its value.
    pub depth: f32,
    /// The warning, if it clips something.
    pub warning: String,
    /// Where in the scene's warnings it goes.
    pub at: usize,
}

/// State of one load.
pub(super) struct Loader<'a> {
    /// The document.
    pub x: Xml<'a>,
    /// Directory that relative file names resolve against.
    pub dir: PathBuf,
    /// The `<path>` folders, searched before `dir` (the latest first).
    pub search: Vec<PathBuf>,
    /// The scene-level area emitters that a shape has referred to.
    pub attached: Vec<NodeId>,
    /// The scene being built.
    pub scene: Scene,
    /// Every object with an `id`.
    ids: HashMap<String, El<'a>>,
    /// `_unnamed_N` names of the top-level objects Mitsuba names `object_<address>`: those without
    /// an id, and textures (whose ids Mitsuba's traverse does not use).
    names: HashMap<NodeId, String>,
    /// The scene-level name of each top-level object the walk of `<scene>`'s children has reached;
    /// an object first reached through a parent is named after that parent instead.
    top_names: HashMap<NodeId, String>,
    /// BSDFs already built, by element.
    pub materials: HashMap<NodeId, MaterialId>,
    /// Textures already built, by element.
    pub textures: HashMap<NodeId, Albedo>,
    /// Textures on scalar slots already built, by element: their texels' parameter.
    pub scalar_textures: HashMap<NodeId, crate::params::ParamId>,
    /// Media already built, by element.
    pub media: HashMap<NodeId, crate::scene::medium::MediumId>,
    /// The shapes with an interior medium: their mesh index and element (for the overlap check).
    pub medium_shapes: Vec<(usize, El<'a>)>,
    /// BSDFs and textures being built (cycle detection).
    pub in_progress: Vec<NodeId>,
    /// A sensor's `near_clip`/`far_clip`, which pathgrad's camera does not apply: decided once
    /// every shape is built, where the warning would have gone ([`Loader::clip_warnings`]).
    pub clips: Vec<PendingClip>,
    /// The mesh file reader.
    pub meshes: MeshLoader,
    /// The rendered size and the folder rule.
    pub options: &'a LoadOptions,
    /// A `direct` integrator's `emitter_samples` above 1, where it was given: Mitsuba 3.9.1 then
    /// over-weights lights without area ([`Loader::direct_delta_warning`]).
    pub direct_emitter_samples: Option<(i64, El<'a>)>,
    /// The `volpath`, `volpathmis` or `prbvolpath` integrator, if the scene names one.
    pub volpath_integrator: Option<El<'a>>,
    /// The `ptracer` integrator, if the scene names one ([`Loader::ptracer_checks`]).
    pub ptracer_integrator: Option<El<'a>>,
    /// While an `instance` builds its group's shapes: its `to_world` and the name (Mitsuba's key
    /// `GROUP.CHILD`) of the shape being built.
    pub instancing: Option<(glam::Mat4, String)>,
    /// The mesh shape whose BSDF is being built, for its `mesh_attribute` textures.
    pub attribute_shape: Option<super::mesh_attribute::AttributeShape>,
    /// `mesh_attribute` textures read so far (a BSDF that read one is built per shape).
    pub attribute_reads: usize,
    /// The BSDFs that read a mesh attribute, by element: the mesh whose attributes they read.
    pub attribute_owners: HashMap<NodeId, u32>,
}

impl<'a> Loader<'a> {
    fn run(&mut self, root: El<'a>, cli: &[(String, String)]) -> Result<()> {
        let x = &self.x;
        if root.tag_name().name() != "scene" {
            return Err(x.err(root, "the root element must be <scene>"));
        }
        x.check_attrs(root, &["version"])?;
        let version = root
            .attribute("version")
            .ok_or_else(|| x.err(root, "missing attribute 'version' (pathgrad reads Mitsuba 2.x and 3.x scenes)"))?;
        if !matches!(version.split('.').next(), Some("2" | "3")) {
            return Err(x.err(root, format!("unsupported scene version '{version}' (pathgrad reads 2.x and 3.x)")));
        }
        let children: Vec<El<'a>> = root.children().filter(|c| c.is_element()).collect();
        self.collect_defines(&children, cli)?;
        self.collect_ids(root)?;

        let mut unnamed = 0;
        for c in &children {
            let tag = c.tag_name().name();
            // Mitsuba 3.9.1 names a scene-level bitmap by its address whatever its id (a
            // checkerboard by its id).
            let bitmap = tag == "texture" && c.attribute("type") != Some("checkerboard");
            if matches!(tag, "shape" | "bsdf" | "texture" | "emitter" | "medium") && (!c.has_attribute("id") || bitmap)
            {
                self.names.insert(c.id(), format!("_unnamed_{unnamed}"));
                unnamed += 1;
            }
        }

        for &c in &children {
            self.check_scene_child(c)?;
        }
        let sensors: Vec<El<'a>> = children.iter().copied().filter(|c| c.has_tag_name("sensor")).collect();
        if sensors.is_empty() {
            return Err(self.x.err(
                root,
                "the scene has no <sensor>; pathgrad needs one (perspective, thinlens or orthographic: it has no default camera)",
            ));
        }
        // Every sensor, each with its own film and sampler; the chosen one is rendered.
        self.scene.sensors.clear();
        let mut spps = Vec::new();
        for (i, &s) in sensors.iter().enumerate() {
            self.scene.default_spp = None;
            self.sensor(s)?;
            spps.push(self.scene.default_spp);
            let name = s.attribute("id").map_or_else(|| format!("sensor_{i}"), str::to_string);
            if self.scene.sensors.iter().any(|other| other.name == name) {
                return Err(self.x.err(s, format!("a second sensor named '{name}'")));
            }
            self.scene.sensors.push(crate::scene::Sensor { name, camera: self.scene.camera });
        }
        let chosen = match &self.options.sensor {
            Some(selector) => self.scene.sensor_index(selector)?,
            None => 0,
        };
        self.scene.camera = self.scene.sensors[chosen].camera;
        self.scene.sensor = chosen;
        self.scene.default_spp = spps[chosen];
        // Curved shapes are tessellated for the size rendered, not the film's.
        let camera = &mut self.scene.camera;
        (camera.width, camera.height) = self.options.size_for((camera.width, camera.height));
        let integrators: Vec<El<'a>> = children.iter().copied().filter(|c| c.has_tag_name("integrator")).collect();
        match integrators[..] {
            [] => self.scene.max_depth = crate::integrator::UNBOUNDED_DEPTH_CAP,
            [i] => self.integrator(i)?,
            [_, second, ..] => return Err(self.x.err(second, "a scene has at most one <integrator>")),
        }

        // Built in the order Mitsuba 3.9.1's `load_file` traverses the scene, since an object is
        // named after the first path that reaches it: meshes last (see `traversal_order`).
        let mut mesh_children = Vec::new();
        for (i, c) in self.traversal_order(&children)? {
            if matches!(c.tag_name().name(), "shape" | "bsdf" | "texture" | "emitter" | "medium") {
                let name = self.top_name(c)?;
                self.top_names.insert(c.id(), name);
            }
            match c.tag_name().name() {
                "default" | "sensor" | "integrator" => {}
                // Built by each shape that refers to it, from that shape's attributes.
                "bsdf" | "texture" if self.reads_mesh_attribute(c) => {}
                "bsdf" => {
                    let name = self.top_name(c)?;
                    self.bsdf(c, name, 0)?;
                }
                "texture" => {
                    let name = self.top_name(c)?;
                    self.texture(c, name, 0)?;
                }
                "shape" => {
                    let before = self.scene.meshes.len();
                    match self.x.attr(c, "type")?.as_deref() {
                        // Built by the instances that refer to it.
                        Some("shapegroup") => {
                            self.shape_group_children(c)?;
                        }
                        Some("instance") => self.instance(c)?,
                        _ => self.shape(c)?,
                    }
                    // Each mesh built goes back to this child's place in the document.
                    mesh_children.extend(std::iter::repeat_n(i, self.scene.meshes.len() - before));
                }
                // Built by the shape that refers to it (checked below).
                "emitter" if self.x.attr(c, "type")?.as_deref() == Some("area") && c.has_attribute("id") => {}
                "emitter" => self.environment(c)?,
                // Built when a shape refers to it (its `interior`), under the name given above unless
                // an earlier shape reached it first; one nothing refers to is reported below.
                // `<path>`s took effect when the includes were spliced in.
                _ => {}
            }
        }
        self.meshes_in_document_order(&mesh_children);
        for t in root.children().filter(|c| c.is_text()) {
            if t.text().is_some_and(|s| !s.trim().is_empty()) {
                return Err(self.x.err(root, "unexpected text inside the element"));
            }
        }
        if self.scene.meshes.is_empty() {
            return Err(self.x.err(root, "the scene has no shapes"));
        }
        for &c in children.iter().filter(|c| c.has_tag_name("emitter") && c.has_attribute("id")) {
            if self.x.attr(c, "type")?.as_deref() == Some("area") && !self.attached.contains(&c.id()) {
                return Err(self.x.err(c, "an 'area' emitter must be nested in a <shape> or referred to by one"));
            }
        }
        for &c in children.iter().filter(|c| c.has_tag_name("medium")) {
            if !self.media.contains_key(&c.id()) {
                let w = self.x.warning(c, "no shape has this medium as its interior: it is ignored");
                self.scene.warn(w);
            }
        }
        self.clip_warnings();
        for w in self.x.take_warnings() {
            self.scene.warn(w);
        }
        self.direct_delta_warning();
        let integrator = children.iter().find(|c| c.has_tag_name("integrator")).copied().unwrap_or(root);
        self.null_outside_volpath_warning(integrator);
        self.ptracer_checks()?;
        self.refuse_sensors_in_media(&sensors)?;
        self.refuse_overlapping_media()?;
        super::super::load::apply_environments(&mut self.scene, self.options)?;
        if self.scene.meshes.iter().all(|m| m.emitter.is_none())
            && self.scene.environment.is_none()
            && self.scene.lights.is_empty()
        {
            let w = self.x.warning(
                root,
                "the scene has no emitters: it renders black unless lit by an environment (LoadOptions::environment)",
            );
            self.scene.warn(w);
        }
        // A set of the caller's names: one scan of them per unused define was quadratic (200 000
        // defines took 58 s).
        let given: std::collections::HashSet<&str> = cli.iter().map(|(n, _)| n.as_str()).collect();
        for name in self.x.unused_defines() {
            if given.contains(name.as_str()) {
                let w = format!("{}: -D {name} is not used by the scene", self.x.file);
                self.scene.warn(w);
            }
        }
        Ok(())
    }

    /// Warns about each sensor's `near_clip`/`far_clip` that would remove something from this
    /// scene: Mitsuba clips at camera-space depths below `near_clip` and above `far_clip`, which
    /// pathgrad's camera does not. One that removes nothing (no triangle reaches a depth in
    /// (0, near_clip), none beyond far_clip) renders the same, and is accepted silently. The
    /// warning goes where the sensor's other warnings are.
    fn clip_warnings(&mut self) {
        for clip in std::mem::take(&mut self.clips).into_iter().rev() {
            let c = clip.camera;
            let forward = (c.target - c.position).normalize();
            let right = forward.cross(c.up).normalize();
            let up = right.cross(forward);
            // The view pyramid's half-widths per unit depth, with a margin for the pixel filter.
            let tan_y = 1.5 * (0.5 * c.fov_y_degrees.to_radians()).tan();
            let tan_x = tan_y * c.width as f32 / c.height as f32;
            let clips_something = self.scene.meshes.iter().any(|m| {
                m.indices.par_iter().any(|t| {
                    let v = t.map(|i| m.positions[i as usize] - c.position);
                    let range = |axis: Vec3| {
                        let d = v.map(|p| p.dot(axis));
                        (d[0].min(d[1]).min(d[2]), d[0].max(d[1]).max(d[2]))
                    };
                    let (lo, hi) = range(forward);
                    if !clip.near {
                        return hi > clip.depth;
                    }
                    // Near: the triangle's box (in camera axes) must reach into the pyramid's
                    // part in front of the near plane, not only pass beside the camera.
                    let ((xl, xh), (yl, yh)) = (range(right), range(up));
                    let (wx, wy) = (clip.depth * tan_x, clip.depth * tan_y);
                    lo < clip.depth && hi > 0.0 && xl < wx && xh > -wx && yl < wy && yh > -wy
                })
            });
            if clips_something {
                self.scene.warn(clip.warning);
                let w = self.scene.warnings.pop().expect("just pushed");
                self.scene.warnings.insert(clip.at, w);
            }
        }
    }

    /// `children` (with their indices) in the order Mitsuba 3.9.1's default `load_file`
    /// (`optimize=True`) traverses them: every object but the mesh shapes in document order, then
    /// the meshes (`obj`, `ply`, `rectangle`, `cube`: Mitsuba turns rectangles into meshes and
    /// moves meshes after everything else; their order among themselves is Mitsuba's own, here
    /// the document's).
    fn traversal_order(&self, children: &[El<'a>]) -> Result<Vec<(usize, El<'a>)>> {
        let mut first = Vec::new();
        let mut meshes = Vec::new();
        for (i, &c) in children.iter().enumerate() {
            let mesh = c.has_tag_name("shape")
                && matches!(
                    self.x.attr(c, "type")?.as_deref(),
                    Some("obj" | "ply" | "serialized" | "rectangle" | "cube")
                );
            if mesh { meshes.push((i, c)) } else { first.push((i, c)) }
        }
        first.extend(meshes);
        Ok(first)
    }

    /// The shapes of `shapegroup` `group` with their names: Mitsuba's `traverse` keys them by
    /// their ids, or `shape`, `shape_1`, … for those without one.
    ///
    /// # Errors
    /// Anything but plain shapes in the group (Mitsuba refuses emitters, nested groups and
    /// instances too; pathgrad also media).
    fn shape_group_children(&self, group: El<'a>) -> Result<Vec<(El<'a>, String)>> {
        let mut seen = std::collections::HashMap::new();
        let mut shapes = Vec::new();
        for c in group.children().filter(|c| c.is_element()) {
            if c.has_tag_name("string") && c.attribute("name") == Some("id") {
                continue;
            }
            if !c.has_tag_name("shape") {
                return Err(self.x.err(c, "a 'shapegroup' holds only <shape>s"));
            }
            let kind = self.x.attr(c, "type")?.unwrap_or_default();
            if matches!(kind.as_str(), "shapegroup" | "instance") {
                return Err(self.x.err(c, "nested shape groups and instances are not permitted (as in Mitsuba)"));
            }
            if let Some(e) = c.children().find(|e| e.has_tag_name("emitter")) {
                return Err(self.x.err(e, "instancing of emitters is not supported (as in Mitsuba)"));
            }
            if let Some(m) = c.children().find(|e| e.has_tag_name("medium") || e.attribute("name") == Some("interior"))
            {
                return Err(self.x.err(m, "media inside a shape group are not supported"));
            }
            let key = match self.x.attr(c, "id")? {
                Some(id) if !id.starts_with("_unnamed_") => id,
                _ => "shape".to_string(),
            };
            let n = seen.entry(key.clone()).or_insert(0usize);
            let unique = if *n == 0 { key.clone() } else { format!("{key}_{n}") };
            *n += 1;
            shapes.push((c, unique));
        }
        Ok(shapes)
    }

    /// An `instance`: its group's shapes, each built again under the instance's `to_world`
    /// (pathgrad flattens instances into meshes; BSDFs are shared, so their parameters are the
    /// group's, named `GROUP.CHILD.bsdf.…` as Mitsuba's).
    ///
    /// # Errors
    /// No `<ref>` to a `shapegroup`, or what a shape of it refuses.
    fn instance(&mut self, node: El<'a>) -> Result<()> {
        let p = Props::parse(&self.x, node)?;
        let to_world = p.transform(&self.x, "to_world")?.map_or(glam::Mat4::IDENTITY, |(t, _)| t.matrix);
        let refs = p.take_nested(&["ref", "shape"]);
        let [group] = refs[..] else {
            return Err(self.x.err(node, "an 'instance' needs exactly one <ref> to a 'shapegroup'"));
        };
        let group = self.deref(group)?;
        if !(group.has_tag_name("shape") && self.x.attr(group, "type")?.as_deref() == Some("shapegroup")) {
            return Err(self.x.err(node, "an 'instance' refers only to a 'shapegroup'"));
        }
        self.finish(&p)?;
        let group_name = self.top_name(group)?;
        for (shape, key) in self.shape_group_children(group)? {
            self.instancing = Some((to_world, format!("{group_name}.{key}")));
            self.shape(shape)?;
        }
        Ok(())
    }

    /// Puts [`Scene::meshes`], built in traversal order from the children with indices
    /// `built_from`, back in document order (and the indices in `medium_shapes` with them).
    fn meshes_in_document_order(&mut self, built_from: &[usize]) {
        let mut order: Vec<usize> = (0..built_from.len()).collect();
        order.sort_by_key(|&m| built_from[m]);
        if order.iter().enumerate().all(|(new, &old)| new == old) {
            return;
        }
        let mut new_index = vec![0; order.len()];
        for (new, &old) in order.iter().enumerate() {
            new_index[old] = new;
        }
        let mut meshes: Vec<Option<crate::scene::Mesh>> =
            std::mem::take(&mut self.scene.meshes).into_iter().map(Some).collect();
        self.scene.meshes = order.iter().map(|&old| meshes[old].take().expect("each mesh is moved once")).collect();
        self.scene.renumber_attribute_meshes(&new_index);
        for (m, _) in &mut self.medium_shapes {
            *m = new_index[*m];
        }
        self.medium_shapes.sort_by_key(|(m, _)| *m);
    }

    /// The file a property names: along the `<path>` folders, then beside the scene, under the
    /// folder rule (the message when it breaks it).
    pub(super) fn scene_file(&self, name: &str) -> std::result::Result<PathBuf, String> {
        super::include::find(&self.search, &self.dir, name, self.options.allow_outside_folder)
    }

    /// Refuses a child of `<scene>` that pathgrad does not read, before anything else is
    /// reported about the scene.
    fn check_scene_child(&self, c: El<'a>) -> Result<()> {
        match c.tag_name().name() {
            "default" | "sensor" | "integrator" | "bsdf" | "texture" | "shape" | "emitter" | "medium" | "volume"
            | "phase" | "path" => Ok(()),
            // Declared here for a sensor to refer to.
            "sampler" if c.has_attribute("id") => Ok(()),
            tag @ ("film" | "sampler" | "rfilter") => {
                Err(self.x.err(c, format!("a <{tag}> must be inside a <sensor>")))
            }
            "ref" => Err(self.x.err(c, "a <ref> at scene level is not supported")),
            tag => Err(self.x.err(
                c,
                format!(
                    "unsupported element <{tag}> (supported in <scene>: default, path, include, bsdf, texture, shape, \
                     emitter, medium, volume, phase, sensor, integrator)"
                ),
            )),
        }
    }

    fn collect_defines(&mut self, children: &[El<'a>], cli: &[(String, String)]) -> Result<()> {
        let mut seen: std::collections::HashSet<&str> = std::collections::HashSet::new();
        for &d in children.iter().filter(|c| c.has_tag_name("default")) {
            self.x.check_attrs(d, &["name", "value"])?;
            let name = d.attribute("name").ok_or_else(|| self.x.err(d, "missing attribute 'name'"))?;
            let value = d.attribute("value").ok_or_else(|| self.x.err(d, "missing attribute 'value'"))?;
            if !is_identifier(name) {
                return Err(self.x.err(d, format!("'{name}' is not a valid parameter name ([A-Za-z_][A-Za-z0-9_]*)")));
            }
            // As Mitsuba: the first default of a name holds (an included file's may repeat it).
            if !seen.insert(name) {
                continue;
            }
            self.x.define(name, value);
        }
        for (name, value) in cli {
            if !is_identifier(name) {
                return Err(Error::InvalidArgument {
                    parameter: format!("-D {name}={value}"),
                    message: "the name must match [A-Za-z_][A-Za-z0-9_]*".into(),
                });
            }
            self.x.define(name, value);
        }
        Ok(())
    }

    fn collect_ids(&mut self, root: El<'a>) -> Result<()> {
        for n in root.descendants().filter(|n| n.is_element() && ID_TAGS.contains(&n.tag_name().name())) {
            let Some(id) = self.x.attr(n, "id")? else { continue };
            if id.is_empty() {
                return Err(self.x.err(n, "an id must not be empty"));
            }
            if let Some(first) = self.ids.get(&id) {
                return Err(self.x.err(n, format!("duplicate id '{id}' (first used at {})", self.x.loc(*first))));
            }
            self.ids.insert(id, n);
        }
        Ok(())
    }

    /// The name of a top-level object at scene level: its `_unnamed_N`, else its id.
    pub(super) fn top_name(&self, node: El<'a>) -> Result<String> {
        match self.names.get(&node.id()) {
            Some(name) => Ok(name.clone()),
            None => Ok(self.x.attr(node, "id")?.unwrap_or_default()),
        }
    }

    /// The name of `node`, being built on its first use through the path `fallback`
    /// (`SHAPE.bsdf`, `BLEND.bsdf_0`, …), as Mitsuba's `traverse` names an object after the first
    /// path that reaches it: its scene-level name if the walk of `<scene>`'s children has already
    /// passed it, else `fallback`. A nested object's own `id` plays no part.
    pub fn name_of(&self, node: El<'a>, fallback: String) -> Result<String> {
        Ok(self.top_names.get(&node.id()).cloned().unwrap_or(fallback))
    }

    /// The element a `<ref>` points to (any other element is returned as is).
    ///
    /// # Errors
    /// A reference to an unknown id.
    pub fn deref(&self, node: El<'a>) -> Result<El<'a>> {
        if !node.has_tag_name("ref") {
            return Ok(node);
        }
        self.x.check_attrs(node, &["id", "name"])?;
        let id = self.x.required(node, "id")?;
        self.ids.get(&id).copied().ok_or_else(|| self.x.err(node, format!("reference to unknown id '{id}'")))
    }

    /// Mitsuba 3.9.1's `direct` integrator adds each of its `emitter_samples` light samples with
    /// weight 1 when the light is a point, spot, directional or projector one (its MIS weight there
    /// omits the 1/`emitter_samples` factor it applies to area lights), so Mitsuba renders those lights
    /// `emitter_samples` times too bright. pathgrad renders the correct expectation; it says so.
    fn direct_delta_warning(&mut self) {
        let Some((n, node)) = self.direct_emitter_samples else { return };
        if self.scene.lights.is_empty() {
            return;
        }
        let w = self.x.warning(
            node,
            format!(
                "emitter_samples = {n}: Mitsuba 3.9.1's 'direct' integrator adds every sample of a point, spot, \
                 directional or projector light with weight 1 instead of 1/{n}, so Mitsuba renders their light {n}× \
                 too bright; pathgrad renders the correct image (not Mitsuba's)"
            ),
        );
        self.scene.warn(w);
    }

    /// A `null` BSDF is an index-matched boundary in pathgrad: crossing it is no bounce and shadow
    /// rays pass it — what Mitsuba's `volpath` family does. Mitsuba's `path` and `prb` (also its
    /// default integrator) instead count the crossing as a bounce and stop shadow rays at the
    /// surface, so next-event estimation misses the light behind it and their image is darker
    /// than pathgrad's. pathgrad keeps its rendering (the one with the light transport's
    /// expectation) and says so, at `node` (the integrator, or the scene when it names none).
    fn null_outside_volpath_warning(&mut self, node: El<'a>) {
        if self.volpath_integrator.is_some()
            || !self.scene.materials.iter().any(|m| matches!(m, crate::scene::Material::Null))
        {
            return;
        }
        let w = self.x.warning(
            node,
            "a 'null' BSDF under Mitsuba's path or prb integrator (or its default, path): Mitsuba stops shadow \
             rays at null surfaces and counts crossing one as a bounce, so its image misses light behind them; \
             pathgrad renders null surfaces as Mitsuba's volpath does (light passes them), so its image is \
             brighter there than Mitsuba's path render (use volpath or prbvolpath to compare)",
        );
        self.scene.warn(w);
    }

    /// Mitsuba's `ptracer` traces light paths and connects each vertex to the camera, so it
    /// renders no path whose vertex seen by the camera is a smooth (delta) surface — a mirror,
    /// glass — and renders no participating media. pathgrad renders `ptracer` scenes with its
    /// path tracer: it says so once, says where the images differ (smooth BSDFs present), and
    /// refuses media by name.
    ///
    /// # Errors
    /// A `ptracer` scene with a medium.
    fn ptracer_checks(&mut self) -> Result<()> {
        let Some(node) = self.ptracer_integrator else { return Ok(()) };
        if !self.scene.media.is_empty() {
            return Err(self.x.err(
                node,
                "'ptracer' with a participating medium: Mitsuba's particle tracer does not render media \
                 (use volpath)",
            ));
        }
        let w = self.x.warning(
            node,
            "'ptracer' integrator: rendered as a path tracer of the same max_depth (the same image, other noise)",
        );
        self.scene.warn(w);
        if self.scene.materials.iter().any(|m| matches!(m, crate::scene::Material::Smooth { .. })) {
            let w = self.x.warning(
                node,
                "'ptracer' with a smooth conductor or dielectric: Mitsuba's particle tracer cannot connect a \
                 smooth surface to the camera, so it renders what the camera sees in or through one black; \
                 pathgrad renders it (not Mitsuba's image there)",
            );
            self.scene.warn(w);
        }
        Ok(())
    }

    /// Reports the unread properties of `p` (warnings) and unclaimed nested objects (errors).
    ///
    /// # Errors
    /// An unclaimed nested object.
    pub fn finish(&mut self, p: &Props<'a>) -> Result<()> {
        let mut warnings = Vec::new();
        p.finish(&self.x, &mut warnings)?;
        warnings.extend(self.x.take_warnings());
        for w in warnings {
            self.scene.warn(w);
        }
        Ok(())
    }

    /// Turns an error of the scene model (parameter names, textures) into one located at `node`.
    pub fn located(&self, node: El<'a>, e: Error) -> Error {
        match e {
            Error::Scene { location, message } => self.x.err(node, format!("{location}: {message}")),
            other => other,
        }
    }

    /// A colour property `name` of `p` in `[lo, hi]`, `default` when absent.
    ///
    /// # Errors
    /// A value outside the range, or of the wrong type.
    pub fn color_in(&self, p: &Props<'a>, name: &str, default: Vec3, range: (f32, f32)) -> Result<Vec3> {
        // A colour that may exceed 1 (η, k) takes a spectrum unclamped, as Mitsuba does.
        let value = if range.1 > 1.0 { p.color_unbounded(&self.x, name)? } else { p.color(&self.x, name)? };
        self.in_range(name, value, default, range)
    }

    /// `value` if every channel lies in `range`, `default` when absent.
    fn in_range(&self, name: &str, value: Option<(Vec3, El<'a>)>, default: Vec3, range: (f32, f32)) -> Result<Vec3> {
        match value {
            None => Ok(default),
            Some((v, node)) => {
                if v.to_array().iter().any(|c| !(*c >= range.0 && *c <= range.1)) {
                    return Err(self.x.err(node, format!("'{name}' must lie in {}, got {v}", show_range(range))));
                }
                Ok(v)
            }
        }
    }

    /// Emitted radiance `name` of `p` ([`Props::radiance`]: a constant `<spectrum>` is a multiple
    /// of D65) in `range`, `default` when absent.
    ///
    /// # Errors
    /// A value outside the range, or of the wrong type.
    pub fn radiance_in(&self, p: &Props<'a>, name: &str, default: Vec3, range: (f32, f32)) -> Result<Vec3> {
        self.in_range(name, p.radiance(&self.x, name)?, default, range)
    }

    /// A float property `name` of `p` in `[lo, hi]`, `default` when absent (`None`: required).
    ///
    /// # Errors
    /// A missing required value, a value outside the range, or of the wrong type.
    pub fn float_in(&self, p: &Props<'a>, name: &str, default: Option<f32>, range: (f32, f32)) -> Result<f32> {
        match (p.float(&self.x, name)?, default) {
            (None, Some(d)) => Ok(d),
            (None, None) => Err(self.x.err(p.node, format!("'{}' needs the property '{name}'", p.kind))),
            (Some((v, node)), _) => {
                if !(v >= range.0 && v <= range.1) {
                    return Err(self.x.err(node, format!("'{name}' must lie in {}, got {v}", show_range(range))));
                }
                Ok(v)
            }
        }
    }

    /// The image `file` named at `file_node` (a `bitmap`'s or an `envmap`'s), found by the scene's
    /// folder rule and decoded to linear RGB ([`crate::scene::load::read_image_linear`]).
    ///
    /// # Errors
    /// A file outside the folder, missing, or undecodable, located at `file_node`.
    pub(super) fn image_file(&self, file: &str, file_node: El<'a>, raw: bool) -> Result<(u32, u32, Vec<f32>)> {
        let path = self.scene_file(file).map_err(|m| self.x.err(file_node, m))?;
        if !path.is_file() {
            return Err(self
                .x
                .err(file_node, format!("image file '{file}' not found (looked for {})", path.display())));
        }
        crate::scene::load::read_image_linear(&path, raw)
            .map_err(|m| self.x.err(file_node, format!("reading '{file}': {m}")))
    }

    /// A top-level `<emitter>`: the environment, constant or a map.
    fn environment(&mut self, node: El<'a>) -> Result<()> {
        let p = Props::parse(&self.x, node)?;
        match p.kind.as_str() {
            "constant" | "envmap" => {}
            "point" | "spot" | "directional" | "projector" => {
                let name = self.top_name(node)?;
                self.light(&p, &name)?;
                return self.finish(&p);
            }
            "area" => return Err(self.x.err(node, "an 'area' emitter must be nested in a <shape>")),
            other => {
                return Err(self.x.err(
                    node,
                    format!(
                        "unsupported plugin '{other}' (supported: constant, directional, envmap, point, projector, \
                         spot; area inside a <shape>)"
                    ),
                ));
            }
        }
        if self.scene.environment.is_some() {
            return Err(self.x.err(node, "a scene has at most one environment emitter (constant or envmap)"));
        }
        let name = self.top_name(node)?;
        if p.kind == "envmap" {
            self.envmap(&p, &name)?;
        } else {
            let radiance = self.radiance_in(&p, "radiance", Vec3::ONE, bounds::RADIANCE)?;
            let set = self.scene.set_environment(&format!("{name}.radiance.value"), radiance);
            set.map_err(|e| self.located(node, e))?;
        }
        self.finish(&p)
    }

    /// Mitsuba's `point` (`intensity`, `position` or `to_world`), `spot` (`intensity`,
    /// `cutoff_angle` 20°, `beam_width` ¾ of it, `to_world`: the cone looks along its +z) and
    /// `directional` (`irradiance`, `direction` or `to_world`: it shines along its +z). The
    /// intensity or irradiance is parameter `NAME.intensity.value` or `NAME.irradiance.value`.
    fn light(&mut self, p: &Props<'a>, name: &str) -> Result<()> {
        use crate::scene::{Light, LightShape};
        let kind = p.kind.as_str();
        if kind == "projector" {
            return self.projector(p, name);
        }
        let texture = match p.object("texture") {
            Some(t) if kind == "spot" => Some(self.light_texture(t, format!("{name}.texture"), kind)?),
            Some(t) => return Err(self.x.err(t, format!("a textured '{kind}' is not supported"))),
            None => None,
        };
        let to_world = p.transform(&self.x, "to_world")?;
        // `position` / `direction` and `to_world` are exclusive (Mitsuba refuses both).
        let exclusive = |other: &str| -> Result<()> {
            match (&to_world, p.node_of(other)) {
                (Some(_), Some(n)) => {
                    Err(self.x.err(n, format!("only one of '{other}' and 'to_world' may be given to '{kind}'")))
                }
                _ => Ok(()),
            }
        };
        let matrix = to_world.map_or(glam::Mat4::IDENTITY, |(t, _)| t.matrix);
        let axis = matrix.transform_vector3(Vec3::Z).normalize_or_zero();
        let shape = match kind {
            "point" => {
                exclusive("position")?;
                let position = match p.point(&self.x, "position")? {
                    Some((v, _)) => v,
                    None => matrix.w_axis.truncate(),
                };
                LightShape::Point { position }
            }
            "spot" => {
                let cutoff = self.float_in(p, "cutoff_angle", Some(20.0), (0.0, 90.0))?;
                let beam_width = self.float_in(p, "beam_width", Some(cutoff * 0.75), (0.0, 90.0))?;
                if !(cutoff > 0.0 && beam_width > 0.0 && beam_width <= cutoff) {
                    return Err(self.x.err(
                        p.node,
                        format!("'spot' needs 0 < beam_width ≤ cutoff_angle, got {beam_width} and {cutoff}"),
                    ));
                }
                let to_local = glam::Mat3::from_mat4(matrix).inverse();
                LightShape::Spot { position: matrix.w_axis.truncate(), axis, cutoff, beam_width, to_local }
            }
            _ => {
                exclusive("direction")?;
                let direction = match p.point(&self.x, "direction")? {
                    Some((v, n)) => {
                        let d = v.normalize_or_zero();
                        if d == Vec3::ZERO {
                            return Err(self.x.err(n, "'direction' must not be zero"));
                        }
                        d
                    }
                    None => axis,
                };
                LightShape::Directional { direction }
            }
        };
        if matches!(shape, LightShape::Spot { axis, .. } | LightShape::Directional { direction: axis } if axis == Vec3::ZERO)
        {
            return Err(self.x.err(p.node, format!("the 'to_world' of '{kind}' collapses its +z axis")));
        }
        let what = if kind == "directional" { "irradiance" } else { "intensity" };
        let value = self.radiance_in(p, what, Vec3::ONE, bounds::RADIANCE)?;
        let intensity = self.scene.params.add(&format!("{name}.{what}.value"), &value.to_array(), bounds::RADIANCE);
        let intensity = intensity.map_err(|e| self.located(p.node, e))?;
        self.scene.lights.push(Light { shape, intensity: Some(intensity), texture });
        Ok(())
    }

    /// Mitsuba's `projector`: `irradiance` (a constant, parameter `NAME.irradiance.value`, or a
    /// `bitmap`, texels `NAME.irradiance.data`), `scale` (1, parameter `NAME.scale`), `fov` with
    /// `fov_axis` or `focal_length` over the texture's aspect ratio (a constant's is 1), and
    /// `to_world` (it looks along its +z).
    fn projector(&mut self, p: &Props<'a>, name: &str) -> Result<()> {
        use crate::scene::{Light, LightShape};
        let (texture, intensity, (width, height)) = match p.object("irradiance") {
            Some(t) => {
                let t = self.light_texture(t, format!("{name}.irradiance"), "projector")?;
                let tex = &self.scene.textures[t.0 as usize];
                (Some(t), None, (tex.width, tex.height))
            }
            None => {
                let value = self.radiance_in(p, "irradiance", Vec3::ONE, bounds::RADIANCE)?;
                let irradiance =
                    self.scene.params.add(&format!("{name}.irradiance.value"), &value.to_array(), bounds::RADIANCE);
                (None, Some(irradiance.map_err(|e| self.located(p.node, e))?), (1, 1))
            }
        };
        let scale = self.float_in(p, "scale", Some(1.0), (0.0, f32::MAX))?;
        let scale = self.scene.params.add(&format!("{name}.scale"), &[scale], bounds::RADIANCE);
        let scale = scale.map_err(|e| self.located(p.node, e))?;
        // Mitsuba's perspective_projection over the texture's resolution: u = ½ − ½ cot x / z,
        // v = ½ − ½ aspect cot y / z, cot = 1 / tan(fov_x / 2).
        let fov_y = self.fov_y(p, width, height)?;
        let aspect = width as f32 / height as f32;
        let cot = 1.0 / ((fov_y * 0.5).to_radians().tan() * aspect);
        let uv_scale = glam::Vec2::new(-0.5 * cot, -0.5 * aspect * cot);
        let matrix = p.transform(&self.x, "to_world")?.map_or(glam::Mat4::IDENTITY, |(t, _)| t.matrix);
        let shape = LightShape::Projector {
            position: matrix.w_axis.truncate(),
            to_local: glam::Mat3::from_mat4(matrix).inverse(),
            normal: matrix.transform_vector3(Vec3::Z),
            uv_scale,
            scale,
        };
        self.scene.lights.push(Light { shape, intensity, texture });
        Ok(())
    }

    /// The texture `node` of a light (`kind`: a spot's `texture`, a projector's `irradiance`): a
    /// `bitmap` without `to_uv`, its texels (any value ≥ 0) the parameter `NAME.data`.
    ///
    /// # Errors
    /// Another plugin, a `to_uv`, a negative texel, and what [`Loader::bitmap`] refuses.
    pub(super) fn light_texture(&mut self, node: El<'a>, name: String, kind: &str) -> Result<crate::scene::TextureId> {
        let target = self.deref(node)?;
        if !target.has_tag_name("texture") {
            return Err(self.x.err(node, format!("refers to a <{}>, expected a <texture>", target.tag_name().name())));
        }
        let name = self.name_of(target, name)?;
        let p = Props::parse(&self.x, target)?;
        let (t, p) = self.light_bitmap(target, p, &name, kind)?;
        if let Some((_, n)) = p.transform(&self.x, "to_uv")? {
            return Err(self.x.err(n, format!("'to_uv' of the texture of a '{kind}' is not supported")));
        }
        self.finish(&p)?;
        Ok(t)
    }

    /// The texture `node` of an area emitter's `radiance` and the parameter its mesh's `emitter`
    /// names: a `bitmap` (with `to_uv`), its texels (any value ≥ 0) the parameter `NAME.data`,
    /// or a `checkerboard`, parameters `NAME.color0.value` (that one) and `NAME.color1.value`
    /// ([`Loader::checkerboard`]).
    ///
    /// # Errors
    /// Another plugin, a negative texel, what [`Loader::bitmap`] and [`Loader::checkerboard`]
    /// refuse.
    pub(super) fn area_texture(
        &mut self,
        node: El<'a>,
        name: String,
    ) -> Result<(crate::params::ParamId, crate::scene::Albedo)> {
        let target = self.deref(node)?;
        if !target.has_tag_name("texture") {
            return Err(self.x.err(node, format!("refers to a <{}>, expected a <texture>", target.tag_name().name())));
        }
        let name = self.name_of(target, name)?;
        let p = Props::parse(&self.x, target)?;
        if p.kind == "checkerboard" {
            let checker = self.checkerboard(&p, &name, bounds::RADIANCE)?;
            let crate::scene::Albedo::Checker { colors, .. } = checker else {
                return Err(self.x.err(target, "a checkerboard read as another texture (a pathgrad bug)"));
            };
            return Ok((colors, checker));
        }
        let (t, p) = self.light_bitmap(target, p, &name, "area")?;
        let to_uv = self.to_uv(&p)?;
        let texture = &mut self.scene.textures[t.0 as usize];
        texture.to_uv = to_uv;
        let texels = texture.texels;
        self.finish(&p)?;
        Ok((texels, crate::scene::Albedo::Bitmap(t)))
    }

    /// The `bitmap` `p` (element `target`, named `name`) of a light of `kind` as a texture of
    /// texels ≥ 0, parameter `NAME.data`; `p` returned to be finished by the caller.
    fn light_bitmap(
        &mut self,
        target: El<'a>,
        p: Props<'a>,
        name: &str,
        kind: &str,
    ) -> Result<(crate::scene::TextureId, Props<'a>)> {
        if p.kind != "bitmap" {
            let also = if kind == "area" { " or 'checkerboard'" } else { "" };
            return Err(self.x.err(
                target,
                format!(
                    "the texture of a '{kind}' must be a 'bitmap'{also} (pathgrad reads no other here), got '{}'",
                    p.kind
                ),
            ));
        }
        let bitmap = self.bitmap(&p, target, "")?;
        if let Some(i) = bitmap.texels.iter().position(|v| *v < 0.0) {
            let texel = i / 3;
            return Err(self.x.err(
                target,
                format!(
                    "texel ({}, {}) of the texture of a '{kind}' is negative ({})",
                    texel % bitmap.width as usize,
                    texel / bitmap.width as usize,
                    bitmap.texels[i]
                ),
            ));
        }
        let t = self
            .scene
            .add_texture_in(&format!("{name}.data"), bitmap.width, bitmap.height, &bitmap.texels, bounds::RADIANCE)
            .map_err(|e| self.located(target, e))?;
        let texture = &mut self.scene.textures[t.0 as usize];
        (texture.nearest, texture.wrap) = (bitmap.nearest, bitmap.wrap);
        Ok((t, p))
    }

    /// Mitsuba's `envmap`: a latitude-longitude image (EXR, HDR, or PNG and other 8-bit formats,
    /// sRGB-decoded), `scale`, and `to_world` (a rotation). Its texels are parameter `NAME.data`,
    /// `height × width × 3` values: Mitsuba's `data` without the two columns it repeats at the
    /// edges for its lookup.
    fn envmap(&mut self, p: &Props<'a>, name: &str) -> Result<()> {
        let (file, file_node) = p
            .string(&self.x, "filename")?
            .ok_or_else(|| self.x.err(p.node, "'envmap' needs the property 'filename'"))?;
        let scale = self.float_in(p, "scale", Some(1.0), (0.0, f32::MAX))?;
        let to_local = match p.transform(&self.x, "to_world")? {
            None => glam::Mat3::IDENTITY,
            Some((t, n)) => {
                crate::scene::envmap::to_local(glam::Mat3::from_mat4(t.matrix)).map_err(|m| self.x.err(n, m))?
            }
        };
        if p.boolean(&self.x, "mis_compensation", false)? {
            let w = self.x.warning(
                p.node,
                "'mis_compensation' of 'envmap' ignored: pathgrad samples the map by luminance (the same \
                 expectation, other noise)",
            );
            self.scene.warn(w);
        }
        let (width, height, texels) = self.image_file(&file, file_node, false)?;
        if height < 2 {
            return Err(self
                .x
                .err(file_node, format!("'{file}': an environment map needs at least 2 rows, it has {height}")));
        }
        if let Some((i, v)) = texels.iter().enumerate().find(|(_, v)| !(v.is_finite() && **v >= 0.0)) {
            let texel = i / 3;
            return Err(self.x.err(
                file_node,
                format!(
                    "'{file}': texel ({}, {}) has value {v} (radiance must be finite and ≥ 0)",
                    texel % width as usize,
                    texel / width as usize
                ),
            ));
        }
        let map = crate::scene::envmap::EnvMap { width, height, scale, to_local };
        let set = self.scene.set_environment_map(&format!("{name}.data"), map, &texels);
        set.map_err(|e| self.located(p.node, e))
    }
}

/// `[lo, hi]`, or `[lo, ∞)` for an open upper bound.
fn show_range(range: (f32, f32)) -> String {
    if range.1 == f32::MAX || range.1 == f32::INFINITY {
        format!("[{}, ∞)", range.0)
    } else {
        format!("[{}, {}]", range.0, range.1)
    }
}

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
//!   optional `NORMAL`, optional `TEXCOORD_n` (the set the base-colour and normal textures name, else 0),
//!   optional `indices` — transformed to world space. Other modes are rejected.
//! - **Camera**: the first node (depth-first, in scene order) carrying a camera. glTF cameras look
//!   along their local −z with +y up. Perspective: `yfov` is used, `znear`/`zfar` are ignored; the
//!   image is 512 pixels wide and `round(512 / aspectRatio)` high (512 × 512 without
//!   `aspectRatio`). Orthographic: a film of half extents `xmag` × `ymag` (512 wide, its aspect
//!   theirs), rays from `znear` ahead.
//! - **Lights** (`KHR_lights_punctual`): `point` at its node's position, `spot` and `directional`
//!   along its node's −z, with RGB intensity `color × intensity` (parameters
//!   `<node>.intensity.value`, directional `<node>.irradiance.value`). Photometric units are read
//!   as pathgrad's radiometric ones (no 683 lm/W conversion; one warning says so). A spot is
//!   Mitsuba's: full intensity inside `innerConeAngle`, falling linearly in angle to 0 at
//!   `outerConeAngle` (glTF suggests a falloff in cos). `range` is ignored with a warning.
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
//! specular lobes are dimmer and its diffuse part slightly brighter than glTF's. Every scene with
//! a mesh says so in a warning ([`FRESNEL_WARNING`]).
//! With b = base colour, m = metallic, r = roughness:
//!
//! | glTF material | pathgrad material | parameters (names) |
//! |---|---|---|
//! | m = 1 | rough conductor, GGX, α = max(r², 10⁻³), specular reflectance b, η = 0, k = 1 (F ≡ 1) | `M.alpha.value`, `M.specular_reflectance.value` |
//! | m < 1 | blend (1 − w)·diffuse(b) + w·conductor, w = 0.04 + 0.96·m; the conductor is GGX with α = max(r², 10⁻³), η = 0, k = 1, specular reflectance s = (m·b + 0.04·(1 − m)) / w (white 1 for m = 0) | `M.weight.value`, `M.bsdf_0.reflectance.value`, `M.bsdf_1.alpha.value`, `M.bsdf_1.specular_reflectance.value` |
//! | base-colour texture | the diffuse albedo is the texture (sRGB bytes linearised, times `baseColorFactor`); the conductor uses the texture's mean colour (warned when m > 0) | `M.base_color.data` (texels, replaces `M.bsdf_0.reflectance.value`) |
//! | metallic-roughness texture | roughness r = G × `roughnessFactor` and metallic m = B × `metallicFactor` per texel (stored values, no sRGB transfer): the conductor's (or dielectric's) α = max(r², 10⁻³) becomes a texture of the same size (bilinear α, where glTF interpolates r: they differ inside a texel where r varies); with `metallicFactor` > 0 (and no transmission) the material is always the blend, its weight w = F0 + (1 − F0)·m and the conductor's specular reflectance s = (m·b + F0·(1 − m))/w textures of that size, b the base colour at each texel (the base-colour texture's texel, or its bilinear lookup at the texel's centre when the two textures differ in size — warned) | `M.bsdf_1.alpha.data` (`M.alpha.data` for a conductor or dielectric alone), `M.weight.data`, `M.bsdf_1.specular_reflectance.data` |
//! | normal texture | a normal map (Mitsuba's `normalmap`) around the material: the texel's RGB (stored values, no sRGB transfer) mapped to (2·rgb − 1)·(scale, scale, 1) is the shading normal in the frame (t, n × t, n), t = ∂p/∂u of the triangle orthogonalised against the shading normal n — the frame glTF prescribes without a `TANGENT` attribute, up to MikkTSpace's per-vertex smoothing; a `TANGENT` attribute is ignored with a warning; the texels are constants | — |
//! | `emissiveFactor` × `KHR_materials_emissive_strength` | area emitter on each mesh using the material (front faces), linear radiance | `<mesh>.emitter.radiance.value` |
//! | emissive texture | the emitter's radiance is the texture (sRGB decoded) times `emissiveFactor` × `KHR_materials_emissive_strength`, each mesh its own texels (sampled as Mitsuba's textured `area`) | `<mesh>.emitter.radiance.data` |
//! | `KHR_materials_ior` η (1.5) | F0 = ((η − 1)/(η + 1))² replaces 0.04 above (w = F0 + (1 − F0)·m, s = (m·b + F0·(1 − m))/w) | — |
//! | `KHR_materials_transmission` t > 0, m < 1 | rough dielectric, GGX α = max(r², 10⁻³), η, transmittance b (its mean with a texture), reflectance 1; rendered as t = 1, m = 0 (warned when not so); never two-sided | `M.alpha.value`, `M.specular_transmittance.value` |
//! | `doubleSided: true` | the material wrapped in `TwoSided` (names unchanged) | — |
//! | no material | glTF's default material: b = 1, m = 1, r = 1 | as above with M = `default_material` |
//!
//! For m = 0 the blend is 0.96·diffuse(b) + 0.04·GGX — exactly glTF's dielectric with its Fresnel
//! held at F0 = 0.04; for 0 < m < 1 it is glTF's mix of the two at normal incidence, with the
//! dielectric's and the metal's GGX lobes (same α) merged into one conductor. Ignored, with a
//! warning: `occlusionTexture` (a path tracer computes occlusion itself),
//! `transmissionTexture`, alpha modes other than `OPAQUE`, and extensions other than
//! `KHR_materials_emissive_strength`, `KHR_materials_ior`, `KHR_materials_transmission` and
//! `KHR_lights_punctual`.
//! Every texture of a material must read the same `TEXCOORD_n` set (else an error naming both).
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
use glam::Vec3;
use json::validation::Checked;

use crate::error::{Error, Result};
use crate::scene::mesh_io::{catch_panic, read_file};
use crate::scene::{Camera, LoadOptions, MaterialId, Scene};

mod buffers;
mod loader;
mod materials;
/// Width of the image when the camera does not say (pixels).
pub const DEFAULT_WIDTH: u32 = 512;
/// Vertical field of view of the default camera used when the file has none (degrees).
pub const DEFAULT_FOV_Y_DEGREES: f32 = 45.0;
/// glTF's dielectric reflectance at normal incidence (F0 for IOR 1.5).
pub const DIELECTRIC_F0: f32 = 0.04;
/// The warning every glTF scene with a mesh carries: its materials are glTF's BRDF only at
/// normal incidence (the module's "Materials"); the conformance matrix checks the mapping it
/// documents against Mitsuba, not against glTF's own BRDF.
pub const FRESNEL_WARNING: &str = "materials: glTF's metallic-roughness BRDF is rendered with its Fresnel terms held \
     at normal incidence (F0), so reflections at grazing angles are dimmer, and diffuse parts slightly brighter, than \
     glTF's (see the pathgrad::scene::gltf docs)";
/// Extensions whose content is used; others named in `extensionsUsed` are reported as ignored.
const SUPPORTED_EXTENSIONS: &[&str] =
    &["KHR_materials_emissive_strength", "KHR_lights_punctual", "KHR_materials_transmission", "KHR_materials_ior"];

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
    let gltf = crate::scene::mesh_io::decoding(|| read_file(path).and_then(|bytes| parse(path, &bytes)))?;
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
        cameras: Vec::new(),
        light_units_warned: false,
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
    crate::scene::load::apply_environments(&mut scene, options)?;
    if scene.meshes.iter().all(|m| m.emitter.is_none()) && scene.environment.is_none() && scene.lights.is_empty() {
        scene.warn(
            "the scene has no emitters (no material has an emissiveFactor, no KHR_lights_punctual light): it renders \
             black unless lit by an environment (LoadOptions::environment)"
                .into(),
        );
    }
    if !scene.meshes.is_empty() {
        scene.warn(FRESNEL_WARNING.into());
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
        filter: crate::scene::PixelFilter::Box,
        lens: crate::scene::Lens::Pinhole,
        window: crate::scene::FilmWindow::default(),
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
    /// Emitted radiance, if any component is positive.
    emission: Option<Emission>,
    /// The `TEXCOORD_n` set the material's textures read, if it is textured.
    tex_coord: Option<u32>,
    /// Whether a normal texture perturbs the shading frame.
    normal_mapped: bool,
}

/// A material's emitted radiance (linear RGB).
#[derive(Clone, Debug)]
enum Emission {
    /// `emissiveFactor × emissiveStrength`.
    Constant(Vec3),
    /// The emissive texture's texels times `emissiveFactor × emissiveStrength`.
    Texture { width: u32, height: u32, texels: Vec<f32> },
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
    /// The perspective cameras found so far, in node order.
    cameras: Vec<crate::scene::Sensor>,
    /// Whether the scene has been told how light intensities are read.
    light_units_warned: bool,
}

/// An [`Error::Scene`] at `file: element`.
fn located(path: &Path, element: impl Display, message: impl Into<String>) -> Error {
    Error::Scene { location: format!("{}: {element}", path.display()), message: message.into() }
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
mod fixtures;

#[cfg(test)]
mod tests;

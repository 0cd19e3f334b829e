//! Triangle meshes from Wavefront OBJ (`tobj`) and PLY (`ply-rs-bw`) files, as [`Geometry`].
//!
//! Both loaders merge everything the file holds into one [`Geometry`]: every OBJ object and group,
//! every PLY face. Polygons are fan-triangulated. OBJ materials (`mtllib`, `usemtl`) are ignored —
//! the scene file assigns the BSDF, as in Mitsuba — and so are OBJ points and lines (`p`, `l`,
//! faces of fewer than three vertices).
//!
//! **Texture coordinates.** Mitsuba's `obj` plugin flips the vertical texture coordinate by default
//! (`flip_tex_coords = true`, "most OBJ files use this convention"), and pathgrad does the same:
//! an OBJ `vt u v` becomes `(u, 1 − v)`, so textures appear as they do in Mitsuba. PLY texture
//! coordinates are taken as they are, as Mitsuba's `ply` plugin does.
//!
//! **Normals.** Vertex normals are used as the file gives them (not renormalised: the renderer normalises the interpolated normal, and keeping the floats exact lets an OBJ twin of a built-in scene render bit for bit the same); without them the
//! geometry has `normals: None` and the renderer shades with face normals.
//!
//! **Errors** name the file and, where the format has lines, the line: an OBJ statement's line,
//! a PLY header line or, for ASCII PLY, the payload line of the element at fault (binary PLY errors
//! name the element and its 0-based index instead). Degenerate triangles are not errors here:
//! [`crate::scene::Scene::add_mesh`] drops them with a counted warning.
//!
//! **No panics.** OBJ files are checked statement by statement (`check_obj`) before `tobj` sees
//! them, because `tobj` 4 overflows — a panic in debug builds — on relative face indices that
//! point before the first element (e.g. `f 1/-5 …` with one `vt`). The PLY header's element counts
//! are checked against the file size before the payload is read, so a tiny file cannot ask for
//! billions of empty elements. Each third-party parse still runs under
//! [`std::panic::catch_unwind`] as a backstop: a panic we did not foresee becomes an error naming
//! the file (the panic message itself still reaches the default panic hook's stderr output).

use std::path::Path;

use glam::{Vec2, Vec3};
use ply_rs_bw::ply::{DefaultElement, ElementDef, Encoding, Property, PropertyType, ScalarType};

use crate::error::{Error, Result};
use crate::scene::shapes::Geometry;

/// An [`Error::Scene`] located at `path` (and `line`, 1-based, if known).
fn scene_error(path: &Path, line: Option<usize>, message: impl Into<String>) -> Error {
    let location = match line {
        Some(line) => format!("{}:{line}", path.display()),
        None => path.display().to_string(),
    };
    Error::Scene { location, message: message.into() }
}

/// Reads `path` whole; a missing file is an [`Error::Io`] naming it.
pub(crate) fn read_file(path: &Path) -> Result<Vec<u8>> {
    std::fs::read(path).map_err(|source| Error::Io { path: path.to_path_buf(), source })
}

/// Runs `f`, returning `None` if it panics. Only for calls into third-party parsers whose
/// freedom from panics on hostile input we cannot prove (see the module docs).
pub(crate) fn catch_panic<T>(f: impl FnOnce() -> T) -> Option<T> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)).ok()
}

// ---- OBJ ----

/// Loads a Wavefront OBJ file: all objects merged, polygons triangulated, one index per vertex.
///
/// Returns positions, normals if every face vertex has one (`None` if none has), texture
/// coordinates likewise with v flipped to `1 − v` (Mitsuba's convention, see the module docs), and
/// the triangles.
///
/// # Errors
/// [`Error::Io`] if the file cannot be read; [`Error::Scene`] at `file:line` for a statement that
/// does not parse, an index out of range, a non-finite number, or a face that gives a texture
/// coordinate or normal where others do not; [`Error::Scene`] at `file` for a file with no
/// vertices and faces ("not an OBJ mesh") or without faces.
pub fn load_obj(path: &Path) -> Result<Geometry> {
    let bytes = read_file(path)?;
    let text = std::str::from_utf8(&bytes).map_err(|e| {
        let line = bytes[..e.valid_up_to()].iter().filter(|&&b| b == b'\n').count() + 1;
        scene_error(path, Some(line), "not UTF-8 text (is this an OBJ file?)")
    })?;
    let counts = check_obj(text).map_err(|(line, message)| scene_error(path, Some(line), message))?;
    if counts.positions == 0 && counts.faces == 0 {
        return Err(scene_error(path, None, "not an OBJ mesh: it has no vertex ('v') or face ('f') statements"));
    }
    if counts.faces == 0 {
        return Err(scene_error(path, None, "has no faces ('f' statements with 3 or more vertices)"));
    }
    let options = tobj::LoadOptions { triangulate: true, single_index: true, ignore_points: true, ignore_lines: true };
    let loaded = catch_panic(|| {
        // Materials are not loaded: the scene file assigns the BSDF.
        tobj::load_obj_buf(&mut std::io::Cursor::new(text.as_bytes()), &options, |_| {
            Err(tobj::LoadError::OpenFileFailed)
        })
    })
    .ok_or_else(|| scene_error(path, None, "the OBJ parser (tobj) panicked on this file"))?;
    let (models, _materials) = loaded.map_err(|e| scene_error(path, None, format!("tobj: {e}")))?;

    let mut g = Geometry::default();
    let (mut normals, mut uvs) = (Vec::new(), Vec::new());
    for model in &models {
        let m = &model.mesh;
        let n = m.positions.len() / 3;
        let base = g.positions.len() as u32;
        g.positions.extend(m.positions.chunks_exact(3).map(|p| Vec3::new(p[0], p[1], p[2])));
        normals.extend(m.normals.chunks_exact(3).map(|v| Vec3::new(v[0], v[1], v[2])));
        uvs.extend(m.texcoords.chunks_exact(2).map(|t| Vec2::new(t[0], 1.0 - t[1])));
        if (!m.normals.is_empty() && m.normals.len() != 3 * n)
            || (!m.texcoords.is_empty() && m.texcoords.len() != 2 * n)
        {
            return Err(scene_error(
                path,
                None,
                format!("object '{}': normal or uv count differs from its vertex count", model.name),
            ));
        }
        g.indices.extend(m.indices.chunks_exact(3).map(|t| [t[0] + base, t[1] + base, t[2] + base]));
    }
    let n = g.positions.len();
    // check_obj guarantees all-or-none per attribute, so a partial array means a tobj surprise.
    g.normals = match normals.len() {
        0 => None,
        len if len == n => Some(normals),
        _ => return Err(scene_error(path, None, "some objects have normals and others do not")),
    };
    g.uvs = match uvs.len() {
        0 => None,
        len if len == n => Some(uvs),
        _ => return Err(scene_error(path, None, "some objects have texture coordinates and others do not")),
    };
    if g.indices.is_empty() {
        return Err(scene_error(path, None, "has no faces ('f' statements with 3 or more vertices)"));
    }
    Ok(g)
}

/// Statement counts of an OBJ file that passed [`check_obj`].
#[derive(Debug, Default)]
struct ObjCounts {
    positions: usize,
    faces: usize,
}

/// Whether the face vertices seen so far carry a texture coordinate / normal index.
#[derive(Clone, Copy, PartialEq)]
struct FaceLayout {
    texcoord: bool,
    normal: bool,
}

/// Checks every statement that `tobj` reads, with `tobj`'s semantics, and returns the first problem
/// as (1-based line, message). Positive indices are checked against the file's total counts and
/// relative (negative) ones against the counts before their line.
fn check_obj(text: &str) -> std::result::Result<ObjCounts, (usize, String)> {
    let mut totals = [0usize; 3];
    for line in text.lines() {
        match line.split_whitespace().next() {
            Some("v") => totals[0] += 1,
            Some("vt") => totals[1] += 1,
            Some("vn") => totals[2] += 1,
            _ => {}
        }
    }
    let mut seen = [0usize; 3];
    let mut counts = ObjCounts::default();
    let mut layout: Option<FaceLayout> = None;
    for (i, line) in text.lines().enumerate() {
        let at = |message: String| (i + 1, message);
        let mut words = line.split_whitespace();
        let Some(keyword) = words.next() else { continue };
        let rest: Vec<&str> = words.collect();
        match keyword {
            "v" => {
                let values = parse_numbers(&rest, "vertex ('v')").map_err(at)?;
                let p = match values.len() {
                    3 | 6 => [values[0], values[1], values[2]],
                    4 if values[3] == 0.0 => return Err(at("vertex weight w is 0".into())),
                    4 => [values[0] / values[3], values[1] / values[3], values[2] / values[3]],
                    n => {
                        return Err(at(format!(
                            "vertex ('v') has {n} numbers; expected x y z, x y z w, or x y z r g b"
                        )));
                    }
                };
                if p.iter().any(|c| !c.is_finite()) {
                    return Err(at("vertex coordinate is not finite (NaN or infinity)".into()));
                }
                seen[0] += 1;
                counts.positions += 1;
            }
            "vt" | "vn" => {
                let (what, needed, slot) =
                    if keyword == "vt" { ("texture coordinate ('vt')", 2, 1) } else { ("normal ('vn')", 3, 2) };
                let values = parse_numbers(&rest, what).map_err(at)?;
                if values.len() < needed {
                    return Err(at(format!("{what} needs {needed} numbers, found {}", values.len())));
                }
                if values[..needed].iter().any(|c| !c.is_finite()) {
                    return Err(at(format!("{what} is not finite (NaN or infinity)")));
                }
                seen[slot] += 1;
            }
            "f" if rest.len() >= 3 => {
                for word in &rest {
                    let parts: Vec<&str> = word.split('/').collect();
                    if parts.len() > 3 {
                        return Err(at(format!("face vertex '{word}' has more than three '/'-separated indices")));
                    }
                    let names = ["vertex", "texture coordinate", "normal"];
                    let mut present = [false; 3];
                    for (k, part) in parts.iter().enumerate() {
                        if part.is_empty() {
                            continue;
                        }
                        present[k] = true;
                        let index: i64 =
                            part.parse().map_err(|_| at(format!("face vertex '{word}': '{part}' is not an index")))?;
                        let (ok, defined) = match index {
                            0 => {
                                return Err(at(format!(
                                    "face vertex '{word}': index 0 is invalid (OBJ indices start at 1)"
                                )));
                            }
                            i if i > 0 => (i as u64 <= totals[k] as u64, format!("the file defines {}", totals[k])),
                            i => (i.unsigned_abs() <= seen[k] as u64, format!("{} defined before this line", seen[k])),
                        };
                        if !ok {
                            return Err(at(format!("{} index {index} is out of range ({defined})", names[k])));
                        }
                    }
                    if !present[0] {
                        return Err(at(format!("face vertex '{word}' has no vertex index")));
                    }
                    let this = FaceLayout { texcoord: present[1], normal: present[2] };
                    match layout {
                        None => layout = Some(this),
                        Some(first) if first != this => {
                            let (what, has) = if first.texcoord != this.texcoord {
                                ("texture coordinate", this.texcoord)
                            } else {
                                ("normal", this.normal)
                            };
                            return Err(at(format!(
                                "face vertex '{word}' {} a {what} index but earlier ones {} (give every face vertex one, or none)",
                                if has { "has" } else { "lacks" },
                                if has { "do not" } else { "do" },
                            )));
                        }
                        Some(_) => {}
                    }
                }
                counts.faces += 1;
            }
            "usemtl" if rest.is_empty() => return Err(at("'usemtl' needs a material name".into())),
            _ => {}
        }
    }
    Ok(counts)
}

/// Parses every word as an `f32` (as `tobj` does), naming `what` on failure.
fn parse_numbers(words: &[&str], what: &str) -> std::result::Result<Vec<f32>, String> {
    words.iter().map(|w| w.parse::<f32>().map_err(|_| format!("{what}: '{w}' is not a number"))).collect()
}

// ---- PLY ----

/// The vertex properties that may hold texture coordinates, in order of preference.
const PLY_UV_NAMES: [(&str, &str); 4] =
    [("u", "v"), ("s", "t"), ("texture_u", "texture_v"), ("texture_s", "texture_t")];
/// The face properties that may hold the vertex index lists.
const PLY_FACE_LISTS: [&str; 2] = ["vertex_indices", "vertex_index"];

/// Loads a PLY file (ASCII, binary little-endian or binary big-endian).
///
/// Reads the `vertex` element's `x y z` (any numeric type), optional `nx ny nz`, optional texture
/// coordinates (`u v`, `s t`, `texture_u texture_v` or `texture_s texture_t`, as they are), and the
/// `face` element's `vertex_indices` (or `vertex_index`) lists of 3 or more indices, fan-triangulated.
/// Other elements and properties are ignored.
///
/// # Errors
/// [`Error::Io`] if the file cannot be read; [`Error::Scene`] naming the file (and the line for the
/// header and ASCII payloads) for a file that is not PLY, a malformed or truncated header or payload,
/// a missing `vertex`/`face` element or `x`/`y`/`z`/index-list property, a partial normal or uv
/// property set, a face of fewer than 3 vertices, an index out of range, a non-finite value, or a
/// mesh without faces.
pub fn load_ply(path: &Path) -> Result<Geometry> {
    let bytes = read_file(path)?;
    if !(bytes.starts_with(b"ply\n") || bytes.starts_with(b"ply\r")) {
        return Err(scene_error(path, None, "not a PLY file (it does not start with the line 'ply')"));
    }
    catch_panic(|| parse_ply(path, &bytes))
        .unwrap_or_else(|| Err(scene_error(path, None, "the PLY parser (ply-rs-bw) panicked on this file")))
}

fn parse_ply(path: &Path, bytes: &[u8]) -> Result<Geometry> {
    let parser = ply_rs_bw::parser::Parser::<DefaultElement>::new();
    let mut reader = ply_rs_bw::parser::Reader::new(bytes);
    let header = parser.read_header(&mut reader).map_err(|e| {
        let (line, message) = ply_message(&e);
        scene_error(path, line, format!("PLY header: {message}"))
    })?;
    let payload = &bytes[bytes.len() - reader.get_ref().len()..];
    let first_line = bytes[..bytes.len() - payload.len()].iter().filter(|&&b| b == b'\n').count() + 1;
    let ascii = header.encoding == Encoding::Ascii;
    check_ply_sizes(path, &header.elements, payload, ascii)?;
    let data = parser.read_payload(&mut reader, &header).map_err(|e| {
        let (line, message) = ply_message(&e);
        scene_error(path, if ascii { line } else { None }, message)
    })?;

    // Where element `name` #index is reported: its payload line in ASCII files.
    let locate = |name: &str, index: usize| -> Option<usize> {
        if !ascii {
            return None;
        }
        let before: usize = header.elements.iter().take_while(|(k, _)| k.as_str() != name).map(|(_, e)| e.count).sum();
        Some(first_line + before + index)
    };
    let element_error = |name: &str, index: usize, message: String| {
        scene_error(path, locate(name, index), format!("{name} {index}: {message}"))
    };

    let vertex_def = header.elements.get("vertex").ok_or_else(|| scene_error(path, None, "has no 'vertex' element"))?;
    let face_def = header
        .elements
        .get("face")
        .ok_or_else(|| scene_error(path, None, "has no 'face' element (a point cloud is not a mesh)"))?;
    for name in ["x", "y", "z"] {
        scalar_property(path, vertex_def, name)?
            .ok_or_else(|| scene_error(path, None, format!("element 'vertex' has no property '{name}'")))?;
    }
    let has_normals = optional_group(path, vertex_def, &["nx", "ny", "nz"])?;
    let mut uv_names = None;
    for (u, v) in PLY_UV_NAMES {
        if optional_group(path, vertex_def, &[u, v])? {
            uv_names = Some((u, v));
            break;
        }
    }
    let list_name = PLY_FACE_LISTS
        .into_iter()
        .find(|n| face_def.properties.contains_key(*n))
        .ok_or_else(|| scene_error(path, None, "element 'face' has no 'vertex_indices' (or 'vertex_index') list"))?;
    match &face_def.properties[list_name].data_type {
        PropertyType::List(_, ScalarType::Float | ScalarType::Double) | PropertyType::Scalar(_) => {
            return Err(scene_error(path, None, format!("property 'face.{list_name}' must be a list of integers")));
        }
        PropertyType::List(..) => {}
    }

    let empty = Vec::new();
    let vertices = data.get("vertex").unwrap_or(&empty);
    let faces = data.get("face").unwrap_or(&empty);
    let mut g = Geometry::default();
    let mut normals = Vec::new();
    let mut uvs = Vec::new();
    let get = |e: &DefaultElement, i: usize, name: &str| -> Result<f32> {
        let value = e.get(name).and_then(number).map(|v| v as f32);
        match value {
            Some(v) if v.is_finite() => Ok(v),
            Some(_) => Err(element_error(
                "vertex",
                i,
                format!("'{name}' is not finite (NaN or infinity, or too large for f32)"),
            )),
            None => Err(element_error("vertex", i, format!("'{name}' is missing"))),
        }
    };
    for (i, e) in vertices.iter().enumerate() {
        g.positions.push(Vec3::new(get(e, i, "x")?, get(e, i, "y")?, get(e, i, "z")?));
        if has_normals {
            normals.push(Vec3::new(get(e, i, "nx")?, get(e, i, "ny")?, get(e, i, "nz")?));
        }
        if let Some((u, v)) = uv_names {
            uvs.push(Vec2::new(get(e, i, u)?, get(e, i, v)?));
        }
    }
    let n = g.positions.len();
    for (i, e) in faces.iter().enumerate() {
        let list = e
            .get(list_name)
            .and_then(index_list)
            .ok_or_else(|| element_error("face", i, format!("'{list_name}' is missing")))?;
        if list.len() < 3 {
            return Err(element_error("face", i, format!("has {} vertices; a face needs at least 3", list.len())));
        }
        if let Some(bad) = list.iter().find(|&&k| k < 0 || k as u64 >= n as u64) {
            return Err(element_error("face", i, format!("vertex index {bad} is out of range ({n} vertices)")));
        }
        for k in 1..list.len() - 1 {
            g.indices.push([list[0] as u32, list[k] as u32, list[k + 1] as u32]);
        }
    }
    if g.indices.is_empty() {
        return Err(scene_error(path, None, "has no faces"));
    }
    g.normals = has_normals.then_some(normals);
    g.uvs = uv_names.map(|_| uvs);
    Ok(g)
}

/// The line and the first line of the message of a `ply-rs-bw` error.
fn ply_message(e: &ply_rs_bw::parser::ParseError) -> (Option<usize>, String) {
    let text = e.to_string();
    let text = match e.line() {
        Some(line) => text.strip_prefix(&format!("Line {line}: ")).unwrap_or(&text).to_string(),
        None => text,
    };
    (e.line(), text.lines().next().unwrap_or("").trim().to_string())
}

/// Rejects element counts the payload cannot hold, before the parser allocates for them: in ASCII
/// each element takes a line; in binary at least the sizes of its scalars and list counts.
fn check_ply_sizes(
    path: &Path,
    elements: &ply_rs_bw::ply::KeyMap<ElementDef>,
    payload: &[u8],
    ascii: bool,
) -> Result<()> {
    if ascii {
        let mut lines = payload.iter().filter(|&&b| b == b'\n').count();
        if payload.last().is_some_and(|&b| b != b'\n') {
            lines += 1;
        }
        let mut needed = 0usize;
        for (name, e) in elements {
            let available = lines.saturating_sub(needed);
            needed = needed.saturating_add(e.count);
            if needed > lines {
                return Err(scene_error(
                    path,
                    None,
                    format!(
                        "element '{name}' declares {} items but the file ends after {available} of them (truncated?)",
                        e.count
                    ),
                ));
            }
        }
        return Ok(());
    }
    let mut needed = 0u64;
    for (name, e) in elements {
        let min_size: u64 = e
            .properties
            .values()
            .map(|p| match &p.data_type {
                PropertyType::Scalar(t) | PropertyType::List(t, _) => scalar_size(t),
            })
            .sum();
        if min_size == 0 && e.count > 0 {
            return Err(scene_error(
                path,
                None,
                format!("element '{name}' declares {} items but no properties", e.count),
            ));
        }
        needed = needed.saturating_add(min_size.saturating_mul(e.count as u64));
        if needed > payload.len() as u64 {
            return Err(scene_error(
                path,
                None,
                format!(
                    "element '{name}' declares {} items, which need more than the {} bytes left in the file (truncated?)",
                    e.count,
                    payload.len()
                ),
            ));
        }
    }
    Ok(())
}

fn scalar_size(t: &ScalarType) -> u64 {
    match t {
        ScalarType::Char | ScalarType::UChar => 1,
        ScalarType::Short | ScalarType::UShort => 2,
        ScalarType::Int | ScalarType::UInt | ScalarType::Float => 4,
        ScalarType::Double => 8,
    }
}

/// Whether `element` has the scalar property `name` (`None` if absent; an error if it is a list).
fn scalar_property(path: &Path, element: &ElementDef, name: &str) -> Result<Option<()>> {
    match element.properties.get(name).map(|p| &p.data_type) {
        None => Ok(None),
        Some(PropertyType::Scalar(_)) => Ok(Some(())),
        Some(PropertyType::List(..)) => {
            Err(scene_error(path, None, format!("property '{}.{name}' is a list; expected a number", element.name)))
        }
    }
}

/// Whether all of `names` are scalar properties of `element`; none is fine, some is an error.
fn optional_group(path: &Path, element: &ElementDef, names: &[&str]) -> Result<bool> {
    let mut present = 0;
    for name in names {
        if scalar_property(path, element, name)?.is_some() {
            present += 1;
        }
    }
    if present != 0 && present != names.len() {
        return Err(scene_error(
            path,
            None,
            format!("element '{}' has some of the properties {} but not all", element.name, names.join(", ")),
        ));
    }
    Ok(present == names.len())
}

fn number(p: &Property) -> Option<f64> {
    Some(match *p {
        Property::Char(v) => v.into(),
        Property::UChar(v) => v.into(),
        Property::Short(v) => v.into(),
        Property::UShort(v) => v.into(),
        Property::Int(v) => v.into(),
        Property::UInt(v) => v.into(),
        Property::Float(v) => v.into(),
        Property::Double(v) => v,
        _ => return None,
    })
}

fn index_list(p: &Property) -> Option<Vec<i64>> {
    Some(match p {
        Property::ListChar(v) => v.iter().map(|&x| x.into()).collect(),
        Property::ListUChar(v) => v.iter().map(|&x| x.into()).collect(),
        Property::ListShort(v) => v.iter().map(|&x| x.into()).collect(),
        Property::ListUShort(v) => v.iter().map(|&x| x.into()).collect(),
        Property::ListInt(v) => v.iter().map(|&x| x.into()).collect(),
        Property::ListUInt(v) => v.iter().map(|&x| x.into()).collect(),
        _ => return None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn data(name: &str) -> std::path::PathBuf {
        Path::new("tests/data/mesh").join(name)
    }

    fn error(result: Result<Geometry>) -> String {
        result.expect_err("the file is malformed").to_string()
    }

    #[test]
    fn obj_quad_with_normals_and_uvs() {
        let g = load_obj(&data("quad.obj")).unwrap();
        assert_eq!(g.positions.len(), 4);
        assert_eq!(g.indices, vec![[0, 1, 2], [0, 2, 3]]);
        assert_eq!(g.normals.as_ref().unwrap(), &vec![Vec3::Z; 4]);
        // vt 0 0, 1 0, 1 1, 0 1 with v flipped.
        let uvs = g.uvs.as_ref().unwrap();
        assert_eq!(uvs, &vec![Vec2::new(0.0, 1.0), Vec2::new(1.0, 1.0), Vec2::new(1.0, 0.0), Vec2::new(0.0, 0.0)]);
        assert_eq!(g.positions[2], Vec3::new(1.0, 1.0, 0.0));
    }

    #[test]
    fn obj_objects_are_merged_and_missing_normals_are_none() {
        let g = load_obj(&data("two_objects.obj")).unwrap();
        assert_eq!(g.positions.len(), 6);
        assert_eq!(g.indices, vec![[0, 1, 2], [3, 4, 5]]);
        assert!(g.normals.is_none() && g.uvs.is_none());
        // A pentagon with relative indices is fan-triangulated.
        let g = load_obj(&data("pentagon.obj")).unwrap();
        assert_eq!(g.indices, vec![[0, 1, 2], [0, 2, 3], [0, 3, 4]]);
    }

    #[test]
    fn ply_ascii_and_binary_give_identical_geometry() {
        let ascii = load_ply(&data("quad_ascii.ply")).unwrap();
        let binary = load_ply(&data("quad_binary.ply")).unwrap();
        assert_eq!(ascii, binary);
        assert_eq!(ascii.indices, vec![[0, 1, 2], [0, 2, 3]]);
        assert_eq!(ascii.normals.as_ref().unwrap(), &vec![Vec3::Z; 4]);
        assert_eq!(ascii.uvs.as_ref().unwrap()[2], Vec2::new(1.0, 1.0));
        // The same quad as OBJ, whose uvs are flipped: positions and triangles agree.
        let obj = load_obj(&data("quad.obj")).unwrap();
        assert_eq!(obj.positions, ascii.positions);
        assert_eq!(obj.indices, ascii.indices);
    }

    #[test]
    fn ply_with_double_coordinates_and_st_names() {
        let g = load_ply(&data("quad_double_st.ply")).unwrap();
        assert_eq!(g, Geometry { normals: None, ..load_ply(&data("quad_ascii.ply")).unwrap() });
    }

    /// Every malformed fixture gives exactly this message.
    #[test]
    fn malformed_meshes_give_pinned_messages() {
        let cases: &[(&str, &str)] = &[
            ("bad_index.obj", "tests/data/mesh/bad_index.obj:6: vertex index 9 is out of range (the file defines 4)"),
            ("nan.obj", "tests/data/mesh/nan.obj:3: vertex coordinate is not finite (NaN or infinity)"),
            (
                "not_a_mesh.obj",
                "tests/data/mesh/not_a_mesh.obj: not an OBJ mesh: it has no vertex ('v') or face ('f') statements",
            ),
            ("binary.obj", "tests/data/mesh/binary.obj:1: not UTF-8 text (is this an OBJ file?)"),
            ("no_faces.obj", "tests/data/mesh/no_faces.obj: has no faces ('f' statements with 3 or more vertices)"),
            ("bad_number.obj", "tests/data/mesh/bad_number.obj:3: vertex ('v'): '0,5' is not a number"),
            (
                "mixed_uvs.obj",
                "tests/data/mesh/mixed_uvs.obj:9: face vertex '4' lacks a texture coordinate index but earlier ones do \
                 (give every face vertex one, or none)",
            ),
            // tobj 4 would overflow (panic in debug builds) on this relative index.
            (
                "relative_underflow.obj",
                "tests/data/mesh/relative_underflow.obj:5: texture coordinate index -5 is out of range \
                 (1 defined before this line)",
            ),
            (
                "zero_index.obj",
                "tests/data/mesh/zero_index.obj:4: face vertex '0': index 0 is invalid (OBJ indices start at 1)",
            ),
        ];
        for (file, expected) in cases {
            assert_eq!(error(load_obj(&data(file))), *expected, "{file}");
        }
        let cases: &[(&str, &str)] = &[
            (
                "truncated.ply",
                "tests/data/mesh/truncated.ply: element 'face' declares 2 items but the file ends after 1 of them (truncated?)",
            ),
            (
                "truncated_binary.ply",
                "tests/data/mesh/truncated_binary.ply: Unexpected end of file while reading binary element 'face' \
                 (expected 2, got 1).",
            ),
            ("bad_face.ply", "tests/data/mesh/bad_face.ply:15: face 1: vertex index 7 is out of range (4 vertices)"),
            (
                "two_vertex_face.ply",
                "tests/data/mesh/two_vertex_face.ply:13: face 0: has 2 vertices; a face needs at least 3",
            ),
            (
                "not_a_mesh.ply",
                "tests/data/mesh/not_a_mesh.ply: not a PLY file (it does not start with the line 'ply')",
            ),
            ("point_cloud.ply", "tests/data/mesh/point_cloud.ply: has no 'face' element (a point cloud is not a mesh)"),
            (
                "partial_normals.ply",
                "tests/data/mesh/partial_normals.ply: element 'vertex' has some of the properties nx, ny, nz but not all",
            ),
            (
                "nan_binary.ply",
                "tests/data/mesh/nan_binary.ply: vertex 1: 'y' is not finite (NaN or infinity, or too large for f32)",
            ),
            ("bad_header.ply", "tests/data/mesh/bad_header.ply:3: PLY header: Couldn't parse line."),
            (
                "many_empty.ply",
                "tests/data/mesh/many_empty.ply: element 'junk' declares 4000000000 items but no properties",
            ),
        ];
        for (file, expected) in cases {
            assert_eq!(error(load_ply(&data(file))), *expected, "{file}");
        }
        let missing = error(load_obj(&data("missing.obj")));
        assert!(missing.starts_with("tests/data/mesh/missing.obj: No such file"), "{missing}");
        let missing = error(load_ply(&data("missing.ply")));
        assert!(missing.starts_with("tests/data/mesh/missing.ply: No such file"), "{missing}");
    }

    /// Random edits of the good fixtures never panic (a small in-tree stand-in for the fuzz targets).
    #[test]
    fn mutated_meshes_never_panic() {
        let mut state = 0x9e37_79b9_7f4a_7c15_u64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        let dir = tempfile::tempdir().unwrap();
        for (name, loader) in [
            ("quad.obj", load_obj as fn(&Path) -> Result<Geometry>),
            ("quad_ascii.ply", load_ply),
            ("quad_binary.ply", load_ply),
        ] {
            let original = std::fs::read(data(name)).unwrap();
            for round in 0..150 {
                let mut bytes = original.clone();
                for _ in 0..1 + round % 4 {
                    let at = next() as usize % bytes.len();
                    match next() % 3 {
                        0 => bytes[at] = next() as u8,
                        1 => bytes.truncate(at.max(1)),
                        _ => bytes.insert(at, b"-0123456789 /\nfvt"[next() as usize % 17]),
                    }
                }
                let path = dir.path().join(name);
                std::fs::write(&path, &bytes).unwrap();
                if let Err(e) = loader(&path) {
                    assert!(!e.to_string().contains("panicked"), "{name} round {round}: {e}");
                }
            }
        }
    }
}

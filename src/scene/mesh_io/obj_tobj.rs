//! The `tobj`-based OBJ reader that [`super::obj`] replaced, kept as the reference the tests and
//! `benches/obj_read.rs` compare the parallel reader with: every statement checked first (line
//! numbers in errors, no overflowing indices), then objects merged and polygons fan-triangulated.

use std::path::Path;

use glam::{Vec2, Vec3};

use super::{catch_panic, scene_error};
use crate::error::Result;
use crate::scene::shapes::Geometry;

/// The former [`load_obj`](super::load_obj), through `tobj` (serial): a reference for tests and
/// benchmarks only. It differs from [`load_obj`](super::load_obj) where that follows Mitsuba (see
/// [`super::obj`]'s module docs): each object has its own vertices, `v x y z w` is divided by `w`,
/// and `l` statements of three or more vertices become faces.
///
/// Loads a Wavefront OBJ file: all objects merged, polygons triangulated, one index per vertex.
///
/// Returns positions, normals if every face vertex has one (`None` if none has), texture
/// coordinates likewise with v flipped to `1 − v` (Mitsuba's convention, see the module docs), and
/// the triangles.
///
/// # Errors
/// [`Error::Io`](crate::Error::Io) if the file cannot be read; [`Error::Scene`](crate::Error::Scene) at `file:line` for a statement that
/// does not parse, an index out of range, a non-finite number, or a face that gives a texture
/// coordinate or normal where others do not; [`Error::Scene`](crate::Error::Scene) at `file` for a file with no
/// vertices and faces ("not an OBJ mesh") or without faces.
pub fn load_obj_tobj(path: &Path) -> Result<Geometry> {
    super::decoding(|| read_obj(path))
}

fn read_obj(path: &Path) -> Result<Geometry> {
    let text = super::obj::read_text(path)?;
    let text = text.as_str();
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

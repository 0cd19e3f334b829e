//! Wavefront OBJ read in parallel: the text cut into line-aligned chunks parsed on rayon's threads,
//! then relative indices resolved from the chunks' counts, one vertex per distinct `v/vt/vn`
//! triple, and polygons fan-triangulated.
//!
//! **Two passes.** The first parses each chunk on its own: numbers, and face indices as written
//! (a relative index is kept relative to the chunk's start), plus how many `v`, `vt` and `vn`
//! statements the chunk holds. The counts of the chunks before a chunk then place its relative
//! indices, and the file's totals bound its absolute ones, in a second parallel pass. The vertex
//! table is built last, serially, in the order in which the faces first name each triple, so the
//! result does not depend on how the text was cut.
//!
//! **Errors** are those of a serial reader: the first problem in the file, at its `file:line`
//! (each chunk finds its first; the earliest chunk with one wins).
//!
//! **Mitsuba's `obj` plugin** (`src/shapes/obj.cpp`, v3.9.1) is followed where the `tobj` crate,
//! which this reader replaced, differed from it:
//! * one vertex table for the whole file: a `v/vt/vn` triple named in two objects (`o`, `g`) is
//!   one vertex, not one per object;
//! * `v x y z w` is the point `x y z` (the weight `w` is ignored, and may be 0);
//! * `l` (line) statements make no triangles, however many vertices they list.
//!
//! Beyond Mitsuba, relative (negative) face indices are resolved as the OBJ format defines them.
//! Vertex colours (`v x y z r g b`), materials (`mtllib`, `usemtl`), smoothing groups (`s`) and
//! faces of fewer than three vertices are read past (their indices must still be numbers). There
//! are no line continuations (`\`), as in Mitsuba and `tobj`.

use std::collections::HashMap;
use std::path::Path;

use glam::{Vec2, Vec3};
use rayon::prelude::*;

use super::{read_file, scene_error};
use crate::error::Result;
use crate::scene::shapes::Geometry;

/// Loads a Wavefront OBJ file: all objects merged, polygons triangulated, one index per vertex.
///
/// Returns positions, normals if every face vertex has one (`None` if none has), texture
/// coordinates likewise with v flipped to `1 − v` (Mitsuba's convention, see the module docs), and
/// the triangles. Large files are parsed on rayon's threads (see [`crate::scene::mesh_io`]).
///
/// ```no_run
/// let mesh = pathgrad::scene::mesh_io::load_obj(std::path::Path::new("bunny.obj"))?;
/// println!("{} triangles", mesh.indices.len());
/// # Ok::<(), pathgrad::Error>(())
/// ```
///
/// # Errors
/// [`Error::Io`](crate::Error::Io) if the file cannot be read; [`Error::Scene`](crate::Error::Scene) at `file:line` for a statement that
/// does not parse, an index out of range, a non-finite number, or a face that gives a texture
/// coordinate or normal where others do not; [`Error::Scene`](crate::Error::Scene) at `file` for a file with no
/// vertices and faces ("not an OBJ mesh") or without faces.
pub fn load_obj(path: &Path) -> Result<Geometry> {
    // For timing whole renders with either reader from one binary (BENCHMARKS.md).
    #[cfg(feature = "obj-oracle")]
    if std::env::var_os("PATHGRAD_OBJ_TOBJ").is_some_and(|v| v == "1") {
        return super::load_obj_tobj(path);
    }
    super::decoding(|| read_obj(path))
}

fn read_obj(path: &Path) -> Result<Geometry> {
    let text = read_text(path)?;
    parse_obj(&text, chunk_count(text.len())).map_err(|(line, message)| scene_error(path, line, message))
}

/// The text of the OBJ file at `path`; an error at the line of its first byte that is not UTF-8.
pub(super) fn read_text(path: &Path) -> Result<String> {
    String::from_utf8(read_file(path)?).map_err(|e| {
        let valid = e.utf8_error().valid_up_to();
        let line = e.as_bytes()[..valid].iter().filter(|&&b| b == b'\n').count() + 1;
        scene_error(path, Some(line), "not UTF-8 text (is this an OBJ file?)")
    })
}

/// How many chunks a text of `len` bytes is cut into: about one per MiB, at most eight per thread.
fn chunk_count(len: usize) -> usize {
    (len >> 20).clamp(1, 8 * rayon::current_num_threads())
}

/// A problem found: its 1-based line (`None`: the whole file) and the message.
type Problem = (Option<usize>, String);

/// Where a problem lies within a chunk, in the order a serial reader meets them: (0-based line in
/// the chunk, face vertex (0 for other statements), step). Steps of a face vertex: 0 its `/` count,
/// `1 + k` the parse and range of index `k` (vertex, texture coordinate, normal), 4 a missing
/// vertex index, 5 its layout against the file's first face vertex.
type At = (usize, usize, usize);

/// What is wrong at an [`At`].
#[derive(Debug)]
enum Fault {
    /// The whole message.
    Message(String),
    /// Index `k` of the face vertex is out of range; the message needs the counts, so it is
    /// written by [`Chunk::describe`].
    Range(usize),
    /// The face vertex's layout differs from the file's first one; written by [`Chunk::describe`].
    Layout,
}

/// Whether a face vertex gives index `k` (bit `k`) and whether that index is relative (bit `3 + k`).
type Flags = u8;

/// One chunk's statements: the first pass's output and, after [`Chunk::resolve`], its face
/// vertices as absolute 0-based indices.
#[derive(Default)]
struct Chunk {
    /// Lines in the chunk.
    lines: usize,
    /// `v`, `vt` and `vn` statements, all of them (the totals that bound absolute indices count
    /// statements, parsed or not).
    counts: [usize; 3],
    positions: Vec<Vec3>,
    /// As written (`v` not flipped).
    texcoords: Vec<Vec2>,
    normals: Vec<Vec3>,
    /// Each face vertex's indices: absolute 0-based, or for a relative index its place counted from
    /// the chunk's first statement of its kind (negative: before the chunk). [`Chunk::resolve`]
    /// makes them absolute (`u32` bits, `u32::MAX` where absent).
    corners: Vec<[i32; 3]>,
    flags: Vec<Flags>,
    /// Faces of three or more vertices: (0-based line in the chunk, number of vertices).
    faces: Vec<(u32, u32)>,
    /// The first problem of the first pass; nothing after it is kept (but statements are counted).
    fault: Option<(At, Fault)>,
}

const NAMES: [&str; 3] = ["vertex", "texture coordinate", "normal"];

impl Chunk {
    /// The first pass over `text` (whole lines).
    fn scan(text: &str) -> Chunk {
        let mut chunk = Chunk::default();
        let mut words: Vec<&str> = Vec::new();
        for (i, line) in text.lines().enumerate() {
            chunk.lines = i + 1;
            let mut split = line.split_whitespace();
            let Some(keyword) = split.next() else { continue };
            let slot = match keyword {
                "v" => 0,
                "vt" => 1,
                "vn" => 2,
                _ => 3,
            };
            if slot < 3 {
                chunk.counts[slot] += 1;
            }
            if chunk.fault.is_some() {
                continue;
            }
            let result = match keyword {
                "v" => vertex(split).map(|p| chunk.positions.push(p)),
                "vt" => {
                    numbers(split, "texture coordinate ('vt')", 2).map(|t| chunk.texcoords.push(Vec2::new(t[0], t[1])))
                }
                "vn" => numbers(split, "normal ('vn')", 3).map(|n| chunk.normals.push(Vec3::from(n))),
                "f" => {
                    words.clear();
                    words.extend(split);
                    chunk.face(i, &words);
                    Ok(())
                }
                "usemtl" if split.next().is_none() => Err("'usemtl' needs a material name".to_string()),
                _ => Ok(()),
            };
            if let Err(message) = result {
                chunk.fault = Some(((i, 0, 0), Fault::Message(message)));
            }
        }
        chunk
    }

    /// Reads the face on line `line` whose vertices are `words`, or records its problem.
    fn face(&mut self, line: usize, words: &[&str]) {
        if words.len() < 3 {
            // A point or a line: no triangle, but its indices must be numbers.
            for (w, word) in words.iter().enumerate() {
                let parts = word.split('/');
                if parts.clone().count() > 3 {
                    self.fault = Some(((line, w, 0), Fault::Message(too_many_parts(word))));
                    return;
                }
                for (k, part) in parts.enumerate() {
                    if !part.is_empty() && part.parse::<i64>().is_err() {
                        self.fault = Some(((line, w, 1 + k), Fault::Message(not_an_index(word, part))));
                        return;
                    }
                }
            }
            return;
        }
        let start = self.corners.len();
        for (w, word) in words.iter().enumerate() {
            let seen = [self.positions.len(), self.texcoords.len(), self.normals.len()];
            let (indices, flags, fault) = corner(word, seen);
            self.corners.push(indices);
            self.flags.push(flags);
            if let Some((step, fault)) = fault {
                // The vertex's earlier indices are still range-checked by the second pass.
                self.faces.push((line as u32, (self.corners.len() - start) as u32));
                self.fault = Some(((line, w, step), fault));
                return;
            }
        }
        self.faces.push((line as u32, words.len() as u32));
    }

    /// The second pass: makes the face vertices' indices absolute, given the statements of each kind
    /// before the chunk (`before`) and in the file (`totals`), and returns the chunk's first problem
    /// (the first pass's, or an index out of range, or a face vertex whose layout differs from
    /// `layout`, the file's first face vertex's [`Flags`] `& 0b111`).
    fn resolve(&mut self, before: [usize; 3], totals: [usize; 3], layout: Flags) -> Option<(At, Fault)> {
        let mut first: Option<(At, Fault)> = None;
        let mut corner = 0;
        'faces: for &(line, len) in &self.faces {
            for w in 0..len as usize {
                let (indices, flags) = (&mut self.corners[corner], self.flags[corner]);
                corner += 1;
                for (k, index) in indices.iter_mut().enumerate() {
                    if flags & (1 << k) == 0 {
                        *index = u32::MAX as i32;
                        continue;
                    }
                    let absolute = if flags & (8 << k) != 0 { *index as i64 + before[k] as i64 } else { *index as i64 };
                    if absolute < 0 || absolute >= totals[k] as i64 {
                        first = Some(((line as usize, w, 1 + k), Fault::Range(k)));
                        break 'faces;
                    }
                    *index = absolute as u32 as i32;
                }
                if flags & 0b111 != layout {
                    first = Some(((line as usize, w, 5), Fault::Layout));
                    break 'faces;
                }
            }
        }
        match (first, self.fault.take()) {
            (Some(a), Some(b)) => Some(if a.0 <= b.0 { a } else { b }),
            (a, b) => a.or(b),
        }
    }

    /// The message for `fault` at `at` in this chunk's `text`, which starts `before` statements of
    /// each kind into the file.
    fn describe(text: &str, at: At, fault: Fault, before: [usize; 3], totals: [usize; 3], layout: Flags) -> String {
        let (line, w, _) = at;
        let word = text.lines().nth(line).and_then(|l| l.split_whitespace().nth(1 + w)).unwrap_or_default();
        match fault {
            Fault::Message(message) => message,
            Fault::Range(k) => {
                let part = word.split('/').nth(k).unwrap_or_default();
                let index: i64 = part.parse().unwrap_or_default();
                let defined = if index > 0 {
                    format!("the file defines {}", totals[k])
                } else {
                    let keyword = ["v", "vt", "vn"][k];
                    let here = text.lines().take(line).filter(|l| l.split_whitespace().next() == Some(keyword)).count();
                    format!("{} defined before this line", before[k] + here)
                };
                format!("{} index {index} is out of range ({defined})", NAMES[k])
            }
            Fault::Layout => {
                let (_, this, _) = corner(word, [0; 3]);
                let (what, has) = if (this ^ layout) & 0b010 != 0 {
                    ("texture coordinate", this & 0b010 != 0)
                } else {
                    ("normal", this & 0b100 != 0)
                };
                format!(
                    "face vertex '{word}' {} a {what} index but earlier ones {} (give every face vertex one, or none)",
                    if has { "has" } else { "lacks" },
                    if has { "do not" } else { "do" },
                )
            }
        }
    }
}

/// A face vertex `word` (`v`, `v/vt`, `v//vn` or `v/vt/vn`) with `seen` statements of each kind
/// before it in its chunk: its indices and [`Flags`] as [`Chunk::corners`] keeps them, and the
/// step and problem where it stops (its indices so far are kept).
fn corner(word: &str, seen: [usize; 3]) -> ([i32; 3], Flags, Option<(usize, Fault)>) {
    let (mut indices, mut flags) = ([0i32; 3], 0);
    if word.split('/').count() > 3 {
        return (indices, flags, Some((0, Fault::Message(too_many_parts(word)))));
    }
    for (k, part) in word.split('/').enumerate() {
        if part.is_empty() {
            continue;
        }
        let Ok(index) = part.parse::<i64>() else {
            return (indices, flags, Some((1 + k, Fault::Message(not_an_index(word, part)))));
        };
        let place = match index {
            0 => {
                let message = format!("face vertex '{word}': index 0 is invalid (OBJ indices start at 1)");
                return (indices, flags, Some((1 + k, Fault::Message(message))));
            }
            i if i > 0 => i - 1,
            i => {
                flags |= 8 << k;
                seen[k] as i64 + i
            }
        };
        // Out of `i32`'s range is out of the file's (it would need 2^31 statements).
        let Ok(place) = i32::try_from(place) else {
            return (indices, flags, Some((1 + k, Fault::Range(k))));
        };
        indices[k] = place;
        flags |= 1 << k;
    }
    if flags & 1 == 0 {
        return (indices, flags, Some((4, Fault::Message(format!("face vertex '{word}' has no vertex index")))));
    }
    (indices, flags, None)
}

fn too_many_parts(word: &str) -> String {
    format!("face vertex '{word}' has more than three '/'-separated indices")
}

fn not_an_index(word: &str, part: &str) -> String {
    format!("face vertex '{word}': '{part}' is not an index")
}

/// A `v` statement's point: `x y z`, `x y z w` (`w` ignored, as Mitsuba does) or `x y z r g b`.
fn vertex(words: std::str::SplitWhitespace) -> std::result::Result<Vec3, String> {
    let what = "vertex ('v')";
    let (p, n) = first_three(words, what)?;
    if !matches!(n, 3 | 4 | 6) {
        return Err(format!("{what} has {n} numbers; expected x y z, x y z w, or x y z r g b"));
    }
    if p.iter().any(|c| !c.is_finite()) {
        return Err("vertex coordinate is not finite (NaN or infinity)".into());
    }
    Ok(Vec3::from(p))
}

/// The first `needed` (2 or 3) of a `vt` or `vn` statement's numbers, all of which must parse.
fn numbers(words: std::str::SplitWhitespace, what: &str, needed: usize) -> std::result::Result<[f32; 3], String> {
    let (v, n) = first_three(words, what)?;
    if n < needed {
        return Err(format!("{what} needs {needed} numbers, found {n}"));
    }
    if v[..needed].iter().any(|c| !c.is_finite()) {
        return Err(format!("{what} is not finite (NaN or infinity)"));
    }
    Ok(v)
}

/// A statement's first three numbers (zero where fewer) and how many it has, all of which must parse.
fn first_three(words: std::str::SplitWhitespace, what: &str) -> std::result::Result<([f32; 3], usize), String> {
    let (mut v, mut n) = ([0.0f32; 3], 0);
    for word in words {
        let value = word.parse::<f32>().map_err(|_| format!("{what}: '{word}' is not a number"))?;
        if n < 3 {
            v[n] = value;
        }
        n += 1;
    }
    Ok((v, n))
}

/// Cuts `text` into at most `pieces` runs of whole lines (each but the last ends with `\n`).
fn split_lines(text: &str, pieces: usize) -> Vec<&str> {
    let mut out = Vec::with_capacity(pieces);
    let mut start = 0;
    for k in 1..pieces {
        let target = (text.len() * k / pieces).max(start);
        let Some(newline) = text.as_bytes()[target..].iter().position(|&b| b == b'\n') else { break };
        let end = target + newline + 1;
        if end < text.len() {
            out.push(&text[start..end]);
            start = end;
        }
    }
    out.push(&text[start..]);
    out
}

/// Parses a whole OBJ text cut into `pieces` chunks (the result does not depend on `pieces`).
fn parse_obj(text: &str, pieces: usize) -> std::result::Result<Geometry, Problem> {
    let texts = split_lines(text, pieces);
    let mut chunks: Vec<Chunk> = texts.par_iter().map(|t| Chunk::scan(t)).collect();

    // Statements of each kind before each chunk, and the file's first face vertex's layout.
    let mut before = Vec::with_capacity(chunks.len());
    let mut totals = [0usize; 3];
    for chunk in &chunks {
        before.push(totals);
        for (total, count) in totals.iter_mut().zip(chunk.counts) {
            *total += count;
        }
    }
    let layout = chunks.iter().find_map(|c| c.flags.first()).map_or(0b001, |f| f & 0b111);

    let faults: Vec<Option<(At, Fault)>> =
        chunks.par_iter_mut().zip(&before).map(|(chunk, &before)| chunk.resolve(before, totals, layout)).collect();
    let mut line = 0;
    for (c, fault) in faults.into_iter().enumerate() {
        if let Some((at, fault)) = fault {
            let message = Chunk::describe(texts[c], at, fault, before[c], totals, layout);
            return Err((Some(line + at.0 + 1), message));
        }
        line += chunks[c].lines;
    }

    let faces: usize = chunks.iter().map(|c| c.faces.len()).sum();
    if totals[0] == 0 && faces == 0 {
        return Err((None, "not an OBJ mesh: it has no vertex ('v') or face ('f') statements".into()));
    }
    if faces == 0 {
        return Err((None, "has no faces ('f' statements with 3 or more vertices)".into()));
    }
    let positions: Vec<Vec3> = chunks.iter_mut().flat_map(|c| std::mem::take(&mut c.positions)).collect();
    let texcoords: Vec<Vec2> = chunks.iter_mut().flat_map(|c| std::mem::take(&mut c.texcoords)).collect();
    let normals: Vec<Vec3> = chunks.iter_mut().flat_map(|c| std::mem::take(&mut c.normals)).collect();

    // One vertex per distinct (v, vt, vn), numbered as the faces first name them. Most positions
    // have a single triple: `first` holds it; further ones go to `more`.
    let mut first = vec![u32::MAX; positions.len()];
    let mut keys: Vec<[u32; 3]> = Vec::with_capacity(positions.len());
    let mut more: HashMap<[u32; 3], u32> = HashMap::new();
    let mut indices = Vec::with_capacity(faces);
    let mut ids = Vec::new();
    for chunk in &chunks {
        let mut corners = chunk.corners.iter();
        for &(_, len) in &chunk.faces {
            ids.clear();
            for corner in corners.by_ref().take(len as usize) {
                let key = corner.map(|i| i as u32);
                let slot = &mut first[key[0] as usize];
                let id = if *slot == u32::MAX {
                    *slot = keys.len() as u32;
                    keys.push(key);
                    *slot
                } else if keys[*slot as usize] == key {
                    *slot
                } else {
                    *more.entry(key).or_insert_with(|| {
                        keys.push(key);
                        keys.len() as u32 - 1
                    })
                };
                ids.push(id);
            }
            indices.extend(ids.windows(2).skip(1).map(|pair| [ids[0], pair[0], pair[1]]));
        }
    }
    Ok(Geometry {
        positions: keys.par_iter().map(|k| positions[k[0] as usize]).collect(),
        normals: (layout & 0b100 != 0).then(|| keys.par_iter().map(|k| normals[k[2] as usize]).collect()),
        uvs: (layout & 0b010 != 0).then(|| {
            keys.par_iter()
                .map(|k| {
                    let t = texcoords[k[1] as usize];
                    Vec2::new(t.x, 1.0 - t.y)
                })
                .collect()
        }),
        indices,
        attributes: Vec::new(),
    })
}

#[cfg(test)]
mod tests {
    use std::fmt::Write as _;
    use std::path::PathBuf;

    use super::super::obj_tobj::load_obj_tobj;
    use super::*;

    /// Every `.obj` file under `dir`, recursively.
    fn objs(dir: &Path, out: &mut Vec<PathBuf>) {
        for entry in std::fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                objs(&path, out);
            } else if path.extension().is_some_and(|e| e == "obj") {
                out.push(path);
            }
        }
    }

    /// Asserts that `a` and `b` hold the same floats bit for bit and the same triangles.
    fn assert_same(a: &Geometry, b: &Geometry, what: &str) {
        let v3 = |v: &Vec<Vec3>| v.iter().flat_map(|p| p.to_array().map(f32::to_bits)).collect::<Vec<_>>();
        let v2 = |v: &Vec<Vec2>| v.iter().flat_map(|p| p.to_array().map(f32::to_bits)).collect::<Vec<_>>();
        assert_eq!(v3(&a.positions), v3(&b.positions), "{what}: positions");
        assert_eq!(a.normals.as_ref().map(v3), b.normals.as_ref().map(v3), "{what}: normals");
        assert_eq!(a.uvs.as_ref().map(v2), b.uvs.as_ref().map(v2), "{what}: uvs");
        assert_eq!(a.indices, b.indices, "{what}: triangles");
        assert_eq!(a.attributes, b.attributes, "{what}: attributes");
    }

    /// `text` parsed whole, after asserting that every way of cutting it (2, 3, 5, 9 chunks, and one
    /// per line) gives the same geometry bit for bit, or the same error.
    fn parse_every_way(text: &str) -> std::result::Result<Geometry, Problem> {
        let whole = parse_obj(text, 1);
        for pieces in [2, 3, 5, 9, text.lines().count().max(1)] {
            match (&whole, parse_obj(text, pieces)) {
                (Ok(a), Ok(b)) => assert_same(a, &b, &format!("{pieces} chunks")),
                (Err(a), Err(b)) => assert_eq!(a, &b, "{pieces} chunks"),
                (a, b) => panic!("{pieces} chunks: {b:?}, whole: {a:?}"),
            }
        }
        whole
    }

    /// Writes `text` to `dir/name.obj` and returns the parallel and the `tobj` readers' results.
    fn both(dir: &Path, name: &str, text: &str) -> (Result<Geometry>, Result<Geometry>) {
        let path = dir.join(format!("{name}.obj"));
        std::fs::write(&path, text).unwrap();
        (load_obj(&path), load_obj_tobj(&path))
    }

    #[test]
    fn cuts_at_line_ends_only() {
        let text = "v 0 0 0\r\nv 1 0 0\nvt 1 1\nf 1 2 3";
        for pieces in 1..12 {
            let cut = split_lines(text, pieces);
            assert_eq!(cut.concat(), text);
            assert!(cut.len() <= pieces);
            assert!(cut[..cut.len() - 1].iter().all(|c| c.ends_with('\n')), "{cut:?}");
        }
        assert_eq!(split_lines("", 4), vec![""]);
        assert_eq!(chunk_count(10), 1);
        assert!(chunk_count(64 << 20) > 1);
    }

    /// The parallel reader gives the `tobj` reader's geometry, bit for bit, or its error message,
    /// for every OBJ file in the repository, however the text is cut.
    #[test]
    fn matches_tobj_on_every_obj_in_the_repository() {
        let mut files = Vec::new();
        for dir in ["tests", "benches", "scenes"] {
            objs(Path::new(dir), &mut files);
        }
        assert!(files.len() >= 25, "{files:?}");
        let mut meshes = 0;
        for file in &files {
            let what = file.display().to_string();
            match (load_obj(file), load_obj_tobj(file)) {
                (Ok(new), Ok(old)) => {
                    assert_same(&new, &old, &what);
                    meshes += 1;
                }
                (Err(new), Err(old)) => assert_eq!(new.to_string(), old.to_string(), "{what}"),
                (new, old) => panic!("{what}: parallel {new:?}, tobj {old:?}"),
            }
            if let Ok(text) = std::str::from_utf8(&std::fs::read(file).unwrap()) {
                let _ = parse_every_way(text);
            }
        }
        assert!(meshes >= 15, "{meshes} of {} files load", files.len());
    }

    /// A mesh of `objects` grids of `n` x `n` quads, each object with its own vertices, uvs and
    /// normals; faces alternate absolute and relative indices, quads and (split) triangles.
    fn grids(objects: usize, n: usize) -> String {
        let mut text = String::from("# generated\nmtllib none.mtl\n");
        let mut base = 0;
        for o in 0..objects {
            writeln!(text, "o grid{o}\nusemtl m{o}\ns 1").unwrap();
            for j in 0..=n {
                for i in 0..=n {
                    let (x, y) = (i as f32 / n as f32, j as f32 / n as f32);
                    writeln!(text, "v {x} {y} {}", 0.1 * o as f32 + x * y / 3.0).unwrap();
                    writeln!(text, "vt {x} {}", 1.0 - y / 7.0).unwrap();
                    writeln!(text, "vn {} {} 1", x / 9.0, -y / 11.0).unwrap();
                }
            }
            let count = (n + 1) * (n + 1);
            for j in 0..n {
                for i in 0..n {
                    let corner = |di: usize, dj: usize| base + (j + dj) * (n + 1) + i + di + 1;
                    let idx = [corner(0, 0), corner(1, 0), corner(1, 1), corner(0, 1)];
                    let word = |k: usize| {
                        if (i + j) % 3 == 0 {
                            let r = idx[k] as i64 - (base + count) as i64 - 1;
                            format!("{r}/{r}/{r}")
                        } else {
                            format!("{0}/{0}/{0}", idx[k])
                        }
                    };
                    if (i + 2 * j) % 4 == 1 {
                        writeln!(text, "f {} {} {}\nf {} {} {}", word(0), word(1), word(2), word(0), word(2), word(3))
                            .unwrap();
                    } else {
                        writeln!(text, "f {} {} {} {}", word(0), word(1), word(2), word(3)).unwrap();
                    }
                }
            }
            base += count;
        }
        text
    }

    #[test]
    fn matches_tobj_on_edge_cases() {
        let dir = tempfile::tempdir().unwrap();
        let quad = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 0 1\n";
        let cases: Vec<(&str, String)> = vec![
            ("grids", grids(3, 12)),
            ("relative", "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nvn 0 0 1\nf -3/-3/-1 -2/-2/-1 -1/-1/-1\nv 1 1 0\nvt 1 1\nf -4/-4/1 -2/-2/1 -1/-1/-1\n".into()),
            ("polygons", "v 1 0 0\nv 0.5 0.866 0\nv -0.5 0.866 0\nv -1 0 0\nv -0.5 -0.866 0\nv 0.5 -0.866 0\nv 0 0 1\nf 1 2 3 4 5 6\nf 1 2 7\nf 3 4 7 2\n".into()),
            ("v_vt", format!("{quad}f 1/1 2/2 3/3 4/4\n")),
            ("v_vn", format!("{quad}f 1//1 2//1 3//1 4//1\n")),
            ("v_vt_vn", format!("{quad}f 1/1/1 2/2/1 3/3/1\nf 1/1/1 3/3/1 4/4/1\n")),
            ("unused_vt_vn", format!("{quad}f 1 2 3 4\n")),
            ("crlf", format!("{quad}o quad\r\nf 1/1/1 2/2/1 3/3/1 4/4/1\r\n").replace('\n', "\r\n").replace("\r\r", "\r")),
            ("comments", format!("# a comment\n#another\n   # indented\n\n\t\n{quad}s off\ng group\nusemtl red\nmtllib a b.mtl\nfoo bar\nf 1 2 3 4\n# end")),
            ("no_trailing_newline", format!("{quad}f 1/1 2/2 3/3")),
            ("empty_objects", format!("o empty\n{quad}o\ng also_empty\nf 4 3 2 1\no trailing_empty\n")),
            ("shared_triples", format!("{quad}f 1//1 2//1 3//1\nf 1//1 3//1 4//1\nf 3//1 2//1 1//1\n")),
            ("one_position_two_normals", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nvn 0 0 1\nvn 0 1 0\nf 1//1 2//1 3//1\nf 1//2 4//2 2//2\nf 1//1 3//1 4//2\n".into()),
            ("colours_and_tabs", "v\t0 0 0 1 0 0\nv 1\t0 0 0 1 0\nv 0 1 0  0 0 1\n\tf 1 2\t3\n".into()),
            ("number_forms", "v 1e-3 -2.5E+2 .5\nv +1 -0 3.\nv 0.1 0.2 0.30000001\nf 1 2 3\n".into()),
            ("points_and_lines_as_short_faces", format!("{quad}f 1\nf 1 2\nf 1 2 3\n")),
            ("many_objects_one_line_each", (0..40).map(|i| format!("o o{i}\nv {i} 0 0\nv {i} 1 0\nv {i} 0 1\nf -3 -2 -1\n")).collect()),
        ];
        for (name, text) in &cases {
            let (new, old) = both(dir.path(), name, text);
            match (new, old) {
                (Ok(new), Ok(old)) => assert_same(&new, &old, name),
                (new, old) => panic!("{name}: parallel {new:?}, tobj {old:?}"),
            }
            parse_every_way(text).unwrap();
        }
        // Spot checks that the cases say what they claim.
        let g = parse_obj(&cases[0].1, 1).unwrap();
        assert_eq!((g.positions.len(), g.indices.len()), (3 * 13 * 13, 3 * 2 * 12 * 12));
        let g = parse_obj(&cases[6].1, 1).unwrap();
        assert!(g.uvs.is_none() && g.normals.is_none());
        let g = parse_obj(&cases[12].1, 1).unwrap();
        assert_eq!(g.positions.len(), 6);
    }

    /// Where `tobj` and Mitsuba's `obj` plugin differ, the reader does as Mitsuba does.
    #[test]
    fn follows_mitsuba_where_tobj_differs() {
        let dir = tempfile::tempdir().unwrap();
        // A triple named in two objects is one vertex (tobj: one per object).
        let text = "o a\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3\no b\nf 1 3 4\n";
        let (new, old) = both(dir.path(), "shared", text);
        let (new, old) = (new.unwrap(), old.unwrap());
        assert_eq!((new.positions.len(), old.positions.len()), (4, 6));
        assert_eq!(new.indices, vec![[0, 1, 2], [0, 2, 3]]);
        let corners = |g: &Geometry| g.indices.iter().flatten().map(|&i| g.positions[i as usize]).collect::<Vec<_>>();
        assert_eq!(corners(&new), corners(&old));
        // The weight w is ignored (tobj divides by it, and a 0 was an error).
        let text = "v 1 2 3 2\nv 0 0 0 0\nv 1 0 0\nf 1 2 3\n";
        let (new, old) = both(dir.path(), "weights", text);
        assert_eq!(new.unwrap().positions[..2], [Vec3::new(1.0, 2.0, 3.0), Vec3::ZERO]);
        assert!(old.is_err());
        // Line statements make no triangles (tobj made `l 1 2 3` a triangle).
        let text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nl 1 2 4\nf 1 2 3\n";
        let (new, old) = both(dir.path(), "lines", text);
        assert_eq!(new.unwrap().indices, vec![[0, 1, 2]]);
        assert_eq!(old.unwrap().indices.len(), 2);
    }

    /// Bad files give the messages the `tobj` reader's checks gave, at the same lines, wherever
    /// the text is cut; the first problem in the file is the one reported.
    #[test]
    fn errors_match_the_tobj_reader() {
        let dir = tempfile::tempdir().unwrap();
        let tri = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
        let pad = "# padding\n".repeat(30);
        let cases: Vec<(&str, String)> = vec![
            ("positive_range", format!("{tri}{pad}f 1 2 3\n{pad}f 1 2 9\nv 0 0 1\n")),
            ("counted_after_a_later_error", format!("{tri}f 1 2 6\n{pad}v x 0 0\nv 0 0 1\nv 0 0 2\n")),
            ("relative_underflow", format!("{tri}{pad}f -1 -2 -4\n")),
            ("relative_before_its_line", format!("{tri}{pad}f -1 -2 -3\nf 1 -4 2\nv 1 1 1\n")),
            ("uv_relative_underflow", format!("{tri}vt 0 0\n{pad}f 1/-1 2/-1 3/-2\n")),
            ("layout_against_an_earlier_chunk", format!("{tri}vt 0 0\nf 1/1 2/1 3/1\n{pad}f 1/1 2 3/1\n")),
            ("layout_normal", format!("{tri}vn 0 0 1\nf 1//1 2//1 3//1\n{pad}f 1 2 3\n")),
            ("layout_gains_uv", format!("{tri}vt 0 0\nf 1 2 3\n{pad}f 1 2/1 3\n")),
            ("too_many_parts", format!("{tri}{pad}f 1/1/1/1 2 3\n")),
            ("not_an_index", format!("{tri}{pad}f 1 b 3\n")),
            ("zero_index", format!("{tri}{pad}f 1 2 0\n")),
            ("range_before_parse_in_a_word", format!("{tri}{pad}f 9/x 1 2\n")),
            ("uv_range_before_missing_vertex", format!("{tri}{pad}f /5 1 2\n")),
            ("missing_vertex", format!("{tri}vt 0 0\n{pad}f /1 1/1 2/1\n")),
            ("huge_index", format!("{tri}{pad}f 1 2 99999999999\n")),
            ("huge_relative_index", format!("{tri}{pad}f 1 2 -99999999999\n")),
            ("vt_count", format!("{tri}{pad}vt 1\n")),
            ("vn_nan", format!("{tri}{pad}vn 0 0 nan\n")),
            ("v_inf", format!("{tri}{pad}v 0 inf 0\n")),
            ("v_count", format!("{tri}{pad}v 1 2\n")),
            ("v_five", format!("{tri}{pad}v 1 2 3 4 5\n")),
            ("vt_word", format!("{tri}{pad}vt 1 0,5\n")),
            ("usemtl", format!("{tri}{pad}usemtl\nf 1 2 3\n")),
            ("two_problems_first_wins", format!("{tri}{pad}f 1 2 4\n{pad}v 1 2\n")),
            ("not_a_mesh", format!("{pad}# nothing\n")),
            ("empty", String::new()),
            ("no_faces", format!("{tri}{pad}f 1 2\n")),
        ];
        for (name, text) in &cases {
            let (new, old) = both(dir.path(), name, text);
            let (new, old) = (new.unwrap_err().to_string(), old.unwrap_err().to_string());
            assert_eq!(new, old, "{name}");
            assert!(!new.contains("tobj"), "{name}: {new}");
            parse_every_way(text).unwrap_err();
        }
        // Problems of short faces (tobj: an error without a line) are found at their line.
        let text = format!("{tri}f 1 x\nf 1 2 3\n");
        assert_eq!(parse_every_way(&text).unwrap_err(), (Some(4), "face vertex 'x': 'x' is not an index".into()));
    }

    /// Random edits of a mesh with relative indices, polygons and several objects: however the text
    /// is cut, the same geometry or the same error (a stand-in for a fuzz target, and no panics).
    #[test]
    fn mutated_meshes_parse_the_same_in_any_chunks() {
        let mut next = crate::testing::xorshift64(0x2545_f491_4f6c_dd1d);
        let original = grids(2, 3).into_bytes();
        let (mut oks, mut errors) = (0, 0);
        for round in 0..300 {
            let mut bytes = original.clone();
            for _ in 0..1 + round % 3 {
                let at = next() as usize % bytes.len();
                match next() % 3 {
                    0 => bytes[at] = b"-0123456789 /\nfvtn#ol"[next() as usize % 21],
                    1 => {
                        bytes.remove(at);
                    }
                    _ => bytes.insert(at, b"-0123456789 /\nfvtn#ol"[next() as usize % 21]),
                }
            }
            let text = String::from_utf8(bytes).unwrap();
            match parse_every_way(&text) {
                Ok(_) => oks += 1,
                Err(_) => errors += 1,
            }
        }
        assert!(oks > 20 && errors > 20, "{oks} parsed, {errors} errors");
    }
}

//! PLY: the header through `ply-rs-bw`, counts checked against the file size; an ASCII payload
//! through `ply-rs-bw` too (the file read whole), a binary one streamed from the file in chunks and
//! decoded here straight into the geometry (`decode_binary`; vertices of fixed-size records in
//! parallel); then vertices (positions, normals, texture coordinates under their common names)
//! and faces.

use std::io::{BufRead, Read, Seek};
use std::path::Path;

use glam::{Vec2, Vec3};
use ply_rs_bw::ply::{DefaultElement, ElementDef, Encoding, Property, PropertyType, ScalarType};
use rayon::prelude::*;

use super::{catch_panic, read_file, scene_error};
use crate::error::{Error, Result};

/// Bytes a binary payload is read in (and the header's read buffer).
const STREAM_BYTES: usize = 1 << 20;
/// Vertices decoded at once (in parallel) when every vertex property is a scalar.
const VERTEX_BATCH: usize = 1 << 16;
use crate::scene::shapes::{Geometry, MeshAttribute};

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
/// The vertices' and faces' other scalar properties become [`MeshAttribute`]s under Mitsuba's
/// names (`attribute_specs`): `r g b` (or `red green blue`) as `vertex_color`/`face_color`, and
/// runs of `PREFIX_x y z`, `PREFIX_r g b`, `PREFIX_0 1 2` or `PREFIX_1 2 3` (1 or 3 of them) as
/// `vertex_PREFIX`/`face_PREFIX` (`PREFIX_color` for the `r g b` run); a polygon's face values are
/// repeated for each of its triangles. Other elements and properties are ignored.
///
/// # Errors
/// [`Error::Io`](crate::Error::Io) if the file cannot be read; [`Error::Scene`](crate::Error::Scene) naming the file (and the line for the
/// header and ASCII payloads) for a file that is not PLY, a malformed or truncated header or payload,
/// a missing `vertex`/`face` element or `x`/`y`/`z`/index-list property, a partial normal or uv
/// property set, a face of fewer than 3 vertices, an index out of range, a non-finite value, or a
/// mesh without faces.
pub fn load_ply(path: &Path) -> Result<Geometry> {
    super::decoding(|| read_ply(path))
}

fn read_ply(path: &Path) -> Result<Geometry> {
    let io = |source| Error::Io { path: path.to_path_buf(), source };
    let file = std::fs::File::open(path).map_err(io)?;
    let file_len = file.metadata().map_err(io)?.len();
    let mut input = std::io::BufReader::with_capacity(STREAM_BYTES, file);
    let start = input.fill_buf().map_err(io)?;
    if !(start.starts_with(b"ply\n") || start.starts_with(b"ply\r")) {
        return Err(scene_error(path, None, "not a PLY file (it does not start with the line 'ply')"));
    }
    catch_panic(|| parse_ply(path, input, file_len))
        .unwrap_or_else(|| Err(scene_error(path, None, "the PLY parser (ply-rs-bw) panicked on this file")))
}

/// Reads the header from `input` (the file from its start, `file_len` bytes); a binary payload
/// is then streamed from `input` (issue 38: the 477 MiB file of 20 M triangles is never held
/// whole), an ASCII one is read whole and parsed by `ply-rs-bw`.
fn parse_ply(path: &Path, mut input: std::io::BufReader<std::fs::File>, file_len: u64) -> Result<Geometry> {
    let io = |source| Error::Io { path: path.to_path_buf(), source };
    let parser = ply_rs_bw::parser::Parser::<DefaultElement>::new();
    let header = parser.read_header(&mut ply_rs_bw::parser::Reader::new(&mut input)).map_err(|e| {
        let (line, message) = ply_message(&e);
        scene_error(path, line, format!("PLY header: {message}"))
    })?;
    if header.encoding == Encoding::Ascii {
        return parse_ascii(path, &read_file(path)?);
    }
    let payload_len = file_len.saturating_sub(input.stream_position().map_err(io)?);
    check_binary_sizes(path, &header.elements, payload_len)?;
    let wanted = wanted_properties(path, &header.elements)?;
    let mut stream = Stream {
        reader: input,
        buf: vec![0; STREAM_BYTES],
        at: 0,
        end: 0,
        big_endian: header.encoding == Encoding::BinaryBigEndian,
        error: None,
    };
    let decoded = decode_binary(path, &header.elements, &wanted, &mut stream);
    // A read that failed ended the payload early: the error is the read's, not the file's.
    match stream.error {
        Some(source) if decoded.is_err() => Err(io(source)),
        _ => decoded,
    }
}

/// An ASCII PLY file, whole.
fn parse_ascii(path: &Path, bytes: &[u8]) -> Result<Geometry> {
    let parser = ply_rs_bw::parser::Parser::<DefaultElement>::new();
    let mut reader = ply_rs_bw::parser::Reader::new(bytes);
    let header = parser.read_header(&mut reader).map_err(|e| {
        let (line, message) = ply_message(&e);
        scene_error(path, line, format!("PLY header: {message}"))
    })?;
    let payload = &bytes[bytes.len() - reader.get_ref().len()..];
    let first_line = bytes[..bytes.len() - payload.len()].iter().filter(|&&b| b == b'\n').count() + 1;
    check_ascii_sizes(path, &header.elements, payload)?;
    let wanted = wanted_properties(path, &header.elements)?;
    let mut vertex_rows = AttrRows::new(&wanted.vertex_attrs);
    let mut face_rows = AttrRows::new(&wanted.face_attrs);
    let Wanted { has_normals, uv_names, list_name, .. } = wanted;
    let data = parser.read_payload(&mut reader, &header).map_err(|e| {
        let (line, message) = ply_message(&e);
        scene_error(path, line, message)
    })?;

    // Where element `name` #index is reported: its payload line in ASCII files.
    let locate = |name: &str, index: usize| -> Option<usize> {
        let before: usize = header.elements.iter().take_while(|(k, _)| k.as_str() != name).map(|(_, e)| e.count).sum();
        Some(first_line + before + index)
    };
    let element_error = |name: &str, index: usize, message: String| {
        scene_error(path, locate(name, index), format!("{name} {index}: {message}"))
    };

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
        for k in 0..vertex_rows.row.len() {
            vertex_rows.row[k] = get(e, i, &vertex_rows.columns[k])?;
        }
        vertex_rows.push(1);
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
        for k in 0..face_rows.row.len() {
            let value = e.get(&face_rows.columns[k]).and_then(number).map(|v| v as f32);
            face_rows.row[k] = match value {
                Some(v) if v.is_finite() => v,
                _ => {
                    let message = format!("'{}' is missing or not finite", face_rows.columns[k]);
                    return Err(element_error("face", i, message));
                }
            };
        }
        face_rows.push(list.len() - 2);
    }
    if g.indices.is_empty() {
        return Err(scene_error(path, None, "has no faces"));
    }
    g.normals = has_normals.then_some(normals);
    g.uvs = uv_names.map(|_| uvs);
    g.attributes = vertex_rows.finish(true);
    g.attributes.extend(face_rows.finish(false));
    Ok(g)
}

/// The values of an element's attributes as they are read: one row of every attribute's
/// properties at a time, appended per vertex or per triangle.
struct AttrRows {
    specs: Vec<AttrSpec>,
    /// The properties of the row, the attributes' columns one after the other.
    columns: Vec<String>,
    /// The row being read.
    row: Vec<f32>,
    /// The values so far, one vector per attribute.
    values: Vec<Vec<f32>>,
}

impl AttrRows {
    fn new(specs: &[AttrSpec]) -> AttrRows {
        let columns: Vec<String> = specs.iter().flat_map(|s| s.columns.iter().cloned()).collect();
        AttrRows {
            specs: specs.to_vec(),
            row: vec![0.0; columns.len()],
            columns,
            values: vec![Vec::new(); specs.len()],
        }
    }

    /// Appends the row `times` times (a vertex once, a face once per triangle).
    fn push(&mut self, times: usize) {
        let mut at = 0;
        for (spec, values) in self.specs.iter().zip(&mut self.values) {
            let n = spec.columns.len();
            for _ in 0..times {
                values.extend_from_slice(&self.row[at..at + n]);
            }
            at += n;
        }
    }

    /// The finished attributes.
    fn finish(self, per_vertex: bool) -> Vec<MeshAttribute> {
        self.specs
            .into_iter()
            .zip(self.values)
            .map(|(s, values)| MeshAttribute { name: s.name, per_vertex, dim: s.columns.len() as u32, values })
            .collect()
    }
}

/// The vertex and face properties the loader reads, checked against the header.
struct Wanted {
    /// `nx ny nz` are present.
    has_normals: bool,
    /// The texture coordinates' names, if present.
    uv_names: Option<(&'static str, &'static str)>,
    /// The face's index list.
    list_name: &'static str,
    /// The vertices' attributes.
    vertex_attrs: Vec<AttrSpec>,
    /// The faces' attributes.
    face_attrs: Vec<AttrSpec>,
}

/// One mesh attribute of a PLY element: its Mitsuba name and the properties it reads, in order.
#[derive(Clone, Debug, PartialEq)]
struct AttrSpec {
    name: String,
    columns: Vec<String>,
}

/// Mitsuba's grouping of an element's other scalar properties (`names`, in header order, less
/// the ones it reads itself) into mesh attributes named `KIND_…` (`kind` is `vertex` or `face`;
/// Mitsuba 3.9.1's `find_other_fields` of src/shapes/ply.h): `r g b` (or `red green blue`, each
/// with an optional alpha) make `KIND_color`; then consecutive properties `PREFIX_P` whose
/// postfixes P run through one of `x y z w`, `r g b a`, `0 1 2 3` or `1 2 3 4` make
/// `KIND_PREFIX` (`KIND_PREFIX_color` for `r g b a`) when there are 1 or 3 of them. Properties
/// that fit no run are ignored, as Mitsuba ignores them (with a warning).
fn attribute_specs(kind: &str, names: &[String]) -> Vec<AttrSpec> {
    const POSTFIXES: [&[u8; 4]; 4] = [b"xr01", b"yg12", b"zb23", b"wa34"];
    let has = |n: &str| names.iter().any(|m| m == n);
    let mut out = Vec::new();
    let mut reserved: Vec<&str> = vec!["r", "g", "b", "a"];
    for colour in [["r", "g", "b", "a"], ["red", "green", "blue", "alpha"]] {
        if colour[..3].iter().all(|n| has(n)) {
            let mut columns: Vec<String> = colour[..3].iter().map(|n| n.to_string()).collect();
            if has(colour[3]) {
                columns.push(colour[3].to_string());
            }
            out.push(AttrSpec { name: format!("{kind}_color"), columns });
            reserved.extend(colour);
            break;
        }
    }
    let mut seen: Vec<String> = Vec::new();
    // The run being read: prefix, postfix category, its properties.
    let mut run: Option<(String, usize, Vec<String>)> = None;
    let flush = |run: &mut Option<(String, usize, Vec<String>)>, out: &mut Vec<AttrSpec>, seen: &mut Vec<String>| {
        if let Some((prefix, category, columns)) = run.take()
            && (columns.len() == 1 || columns.len() == 3)
        {
            let suffix = if category == 1 { "_color" } else { "" };
            out.push(AttrSpec { name: format!("{kind}_{prefix}{suffix}"), columns });
            seen.push(prefix);
        }
    };
    let mut skip_prefix: Option<String> = None;
    for name in names.iter().filter(|n| !reserved.contains(&n.as_str())) {
        let Some((prefix, postfix)) = name.rsplit_once('_') else {
            flush(&mut run, &mut out, &mut seen);
            continue;
        };
        if postfix.len() != 1 {
            flush(&mut run, &mut out, &mut seen);
            continue;
        }
        if skip_prefix.as_deref() == Some(prefix) {
            continue;
        }
        skip_prefix = None;
        if run.as_ref().is_some_and(|r| r.0 != prefix) {
            flush(&mut run, &mut out, &mut seen);
        }
        let c = postfix.as_bytes()[0];
        match &mut run {
            None => {
                if seen.iter().any(|p| p == prefix) {
                    skip_prefix = Some(prefix.to_string());
                    continue;
                }
                if let Some(category) = POSTFIXES[0].iter().position(|&p| p == c) {
                    run = Some((prefix.to_string(), category, vec![name.clone()]));
                }
            }
            Some((_, category, columns)) => {
                if columns.len() < 4 && POSTFIXES[columns.len()][*category] == c {
                    columns.push(name.clone());
                } else {
                    run = None;
                    skip_prefix = Some(prefix.to_string());
                }
            }
        }
    }
    flush(&mut run, &mut out, &mut seen);
    out
}

/// Checks that `elements` has a `vertex` element with scalar `x y z` (and whole groups of normals
/// and texture coordinates) and a `face` element with an integer index list, and names them.
fn wanted_properties(path: &Path, elements: &ply_rs_bw::ply::KeyMap<ElementDef>) -> Result<Wanted> {
    let vertex_def = elements.get("vertex").ok_or_else(|| scene_error(path, None, "has no 'vertex' element"))?;
    let face_def = elements
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
    let scalars = |def: &ElementDef, skip: &[&str]| -> Vec<String> {
        def.properties
            .values()
            .filter(|p| matches!(p.data_type, PropertyType::Scalar(_)) && !skip.contains(&p.name.as_str()))
            .map(|p| p.name.clone())
            .collect()
    };
    let mut vertex_skip = vec!["x", "y", "z", "nx", "ny", "nz", "u", "v"];
    if let Some((u, v)) = uv_names {
        vertex_skip.extend([u, v]);
    }
    let vertex_attrs = attribute_specs("vertex", &scalars(vertex_def, &vertex_skip));
    let face_attrs = attribute_specs("face", &scalars(face_def, &[]));
    Ok(Wanted { has_normals, uv_names, list_name, vertex_attrs, face_attrs })
}

/// What the binary decoder does with one property of an element.
enum Action {
    /// A scalar read into slot `.1` of the vertex's values (x y z, nx ny nz, u v).
    Keep(ScalarType, usize),
    /// A scalar skipped.
    Skip(ScalarType),
    /// The face's index list.
    Indices(ScalarType, ScalarType),
    /// Another list, skipped.
    SkipList(ScalarType, ScalarType),
    /// A scalar read into slot `.1` of the element's attribute row ([`AttrRows`]).
    Attr(ScalarType, usize),
}

/// The scalar of type `t` in `b` (its size) as f64 (exact for every PLY type but double, which
/// is itself).
fn decode_scalar(b: &[u8], t: &ScalarType, big: bool) -> f64 {
    macro_rules! read {
        ($ty:ty) => {{
            let bytes = b.try_into().expect("the caller gives the type's size");
            if big { <$ty>::from_be_bytes(bytes) } else { <$ty>::from_le_bytes(bytes) }
        }};
    }
    match t {
        ScalarType::Char => f64::from(read!(i8)),
        ScalarType::UChar => f64::from(read!(u8)),
        ScalarType::Short => f64::from(read!(i16)),
        ScalarType::UShort => f64::from(read!(u16)),
        ScalarType::Int => f64::from(read!(i32)),
        ScalarType::UInt => f64::from(read!(u32)),
        ScalarType::Float => f64::from(read!(f32)),
        ScalarType::Double => read!(f64),
    }
}

/// A binary payload streamed front to back from the file through a buffer of `STREAM_BYTES` (or
/// more, for a larger request), refilled as it empties.
struct Stream<R: Read> {
    reader: R,
    buf: Vec<u8>,
    /// The unread bytes are `buf[at..end]`.
    at: usize,
    end: usize,
    big_endian: bool,
    /// The read that failed, if one did: the payload ends there.
    error: Option<std::io::Error>,
}

impl<R: Read> Stream<R> {
    /// The next `n` bytes; `None` at the end of the file (or of what could be read).
    fn take(&mut self, n: usize) -> Option<&[u8]> {
        if self.end - self.at < n {
            self.refill(n);
            if self.end - self.at < n {
                return None;
            }
        }
        let out = &self.buf[self.at..self.at + n];
        self.at += n;
        Some(out)
    }

    /// Skips `n` bytes without growing the buffer; `None` at the end of the file.
    fn skip(&mut self, mut n: usize) -> Option<()> {
        while n > 0 {
            let k = n.min(STREAM_BYTES);
            self.take(k)?;
            n -= k;
        }
        Some(())
    }

    /// The next scalar of type `t` as f64; `None` at the end of the file.
    fn scalar(&mut self, t: &ScalarType) -> Option<f64> {
        let big = self.big_endian;
        Some(decode_scalar(self.take(scalar_size(t) as usize)?, t, big))
    }

    /// Bytes that can still be read, as far as the buffer and the file allow (reads the rest of
    /// the file into the buffer up to its size; used to name where a payload ended).
    fn available(&mut self) -> usize {
        self.refill(self.buf.len());
        self.end - self.at
    }

    /// Moves the unread bytes to the front and reads until the buffer holds `n` bytes (growing it
    /// if needed) or is full, or the file ends.
    fn refill(&mut self, n: usize) {
        self.buf.copy_within(self.at..self.end, 0);
        self.end -= self.at;
        self.at = 0;
        if self.buf.len() < n {
            self.buf.resize(n, 0);
        }
        while self.end < self.buf.len() && self.error.is_none() {
            match self.reader.read(&mut self.buf[self.end..]) {
                Ok(0) => break,
                Ok(k) => self.end += k,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => self.error = Some(e),
            }
        }
    }
}

/// Appends one vertex's wanted values (slots as `Action::Keep` names them: position, then normal,
/// then texture coordinates) to the arrays; the message of the first value (of `names`) that is not
/// finite otherwise. Shared by the streamed binary records and the element-by-element reader.
fn push_vertex(
    values: &[f32; 8],
    names: &[&str],
    wanted: &Wanted,
    positions: &mut Vec<Vec3>,
    normals: &mut Vec<Vec3>,
    uvs: &mut Vec<Vec2>,
) -> std::result::Result<(), String> {
    if let Some(k) = values[..names.len()].iter().position(|v| !v.is_finite()) {
        return Err(format!("'{}' is not finite (NaN or infinity, or too large for f32)", names[k]));
    }
    positions.push(Vec3::new(values[0], values[1], values[2]));
    if wanted.has_normals {
        normals.push(Vec3::new(values[3], values[4], values[5]));
    }
    if wanted.uv_names.is_some() {
        let k = if wanted.has_normals { 6 } else { 3 };
        uvs.push(Vec2::new(values[k], values[k + 1]));
    }
    Ok(())
}

/// One fixed-size vertex record's wanted values (slots as `Action::Keep` names them).
fn decode_record(record: &[u8], actions: &[Action], big: bool) -> [f32; 8] {
    let (mut values, mut at) = ([0.0f32; 8], 0);
    for action in actions {
        match action {
            Action::Keep(t, slot) => {
                let size = scalar_size(t) as usize;
                values[*slot] = decode_scalar(&record[at..at + size], t, big) as f32;
                at += size;
            }
            Action::Skip(t) => at += scalar_size(t) as usize,
            Action::Indices(..) | Action::SkipList(..) | Action::Attr(..) => {
                unreachable!("a fixed-size record has no lists or attributes")
            }
        }
    }
    values
}

/// Decodes a binary payload straight into the geometry, one element after another, with the
/// same values, checks and messages as the ASCII path (without line numbers: binary errors name
/// the element and its 0-based index). Nothing per element is allocated, so memory is the
/// geometry's and the stream's buffer (ply-rs-bw's `DefaultElement`s, a map per vertex and per
/// face, took about 700 bytes a triangle; the whole file was read first: issue 38). Vertices
/// whose properties are all scalars (fixed-size records) are decoded `VERTEX_BATCH` at a time in
/// parallel.
fn decode_binary<R: Read>(
    path: &Path,
    elements: &ply_rs_bw::ply::KeyMap<ElementDef>,
    wanted: &Wanted,
    input: &mut Stream<R>,
) -> Result<Geometry> {
    let vertex_count = elements.get("vertex").map_or(0, |e| e.count);
    let mut names = vec!["x", "y", "z"];
    if wanted.has_normals {
        names.extend(["nx", "ny", "nz"]);
    }
    if let Some((u, v)) = wanted.uv_names {
        names.extend([u, v]);
    }
    let mut g = Geometry { positions: Vec::with_capacity(vertex_count), ..Geometry::default() };
    let mut normals = Vec::with_capacity(if wanted.has_normals { vertex_count } else { 0 });
    let mut uvs = Vec::with_capacity(if wanted.uv_names.is_some() { vertex_count } else { 0 });
    let big_endian = input.big_endian;
    let mut values = [0.0f32; 8];
    let mut list: Vec<i64> = Vec::new();
    let mut vertex_rows = AttrRows::new(&wanted.vertex_attrs);
    let mut face_rows = AttrRows::new(&wanted.face_attrs);
    for (name, def) in elements {
        let (is_vertex, is_face) = (name == "vertex", name == "face");
        let rows = if is_vertex { &mut vertex_rows } else { &mut face_rows };
        let attr_slot = |p: &str| if is_vertex || is_face { rows.columns.iter().position(|c| c == p) } else { None };
        let actions: Vec<Action> = def
            .properties
            .values()
            .map(|p| match (&p.data_type, names.iter().position(|n| *n == p.name)) {
                (PropertyType::Scalar(t), Some(slot)) if is_vertex => Action::Keep(t.clone(), slot),
                (PropertyType::Scalar(t), _) if attr_slot(&p.name).is_some() => {
                    Action::Attr(t.clone(), attr_slot(&p.name).expect("checked"))
                }
                (PropertyType::Scalar(t), _) => Action::Skip(t.clone()),
                (PropertyType::List(c, t), _) if is_face && p.name == wanted.list_name => {
                    Action::Indices(c.clone(), t.clone())
                }
                (PropertyType::List(c, t), _) => Action::SkipList(c.clone(), t.clone()),
            })
            .collect();
        let ended = |i: usize| {
            scene_error(
                path,
                None,
                format!(
                    "Unexpected end of file while reading binary element '{name}' (expected {}, got {i}).",
                    def.count
                ),
            )
        };
        let element_error = |i: usize, message: String| scene_error(path, None, format!("{name} {i}: {message}"));
        let fixed = actions.iter().all(|a| matches!(a, Action::Keep(..) | Action::Skip(..)));
        if is_vertex && fixed {
            let record: usize = actions
                .iter()
                .map(|a| match a {
                    Action::Keep(t, _) | Action::Skip(t) => scalar_size(t) as usize,
                    Action::Indices(..) | Action::SkipList(..) | Action::Attr(..) => 0,
                })
                .sum();
            let mut done = 0;
            while done < def.count {
                let k = (def.count - done).min(VERTEX_BATCH);
                let Some(bytes) = input.take(k * record) else {
                    return Err(ended(done + input.available() / record.max(1)));
                };
                let batch: Vec<[f32; 8]> =
                    bytes.par_chunks_exact(record).map(|r| decode_record(r, &actions, big_endian)).collect();
                for (j, values) in batch.iter().enumerate() {
                    push_vertex(values, &names, wanted, &mut g.positions, &mut normals, &mut uvs)
                        .map_err(|m| element_error(done + j, m))?;
                }
                done += k;
            }
            continue;
        }
        for i in 0..def.count {
            for (action, prop) in actions.iter().zip(def.properties.keys()) {
                match action {
                    Action::Keep(t, slot) => {
                        values[*slot] = input.scalar(t).ok_or_else(|| ended(i))? as f32;
                    }
                    Action::Skip(t) => {
                        input.skip(scalar_size(t) as usize).ok_or_else(|| ended(i))?;
                    }
                    Action::Attr(t, slot) => {
                        let v = input.scalar(t).ok_or_else(|| ended(i))? as f32;
                        if !v.is_finite() {
                            let message = format!("'{prop}' is not finite (NaN or infinity, or too large for f32)");
                            return Err(element_error(i, message));
                        }
                        rows.row[*slot] = v;
                    }
                    Action::Indices(c, t) | Action::SkipList(c, t) => {
                        let n = input.scalar(c).ok_or_else(|| ended(i))?;
                        if !(n >= 0.0 && n.fract() == 0.0) {
                            return Err(element_error(i, format!("list '{prop}' has the length {n}")));
                        }
                        let n = n as usize;
                        if matches!(action, Action::Indices(..)) {
                            list.clear();
                            for _ in 0..n {
                                list.push(input.scalar(t).ok_or_else(|| ended(i))? as i64);
                            }
                        } else {
                            let bytes = n.checked_mul(scalar_size(t) as usize).ok_or_else(|| ended(i))?;
                            input.skip(bytes).ok_or_else(|| ended(i))?;
                        }
                    }
                }
            }
            if is_vertex {
                push_vertex(&values, &names, wanted, &mut g.positions, &mut normals, &mut uvs)
                    .map_err(|m| element_error(i, m))?;
                rows.push(1);
            } else if is_face {
                if list.len() < 3 {
                    return Err(element_error(i, format!("has {} vertices; a face needs at least 3", list.len())));
                }
                if let Some(bad) = list.iter().find(|&&k| k < 0 || k as u64 >= vertex_count as u64) {
                    return Err(element_error(
                        i,
                        format!("vertex index {bad} is out of range ({vertex_count} vertices)"),
                    ));
                }
                for k in 1..list.len() - 1 {
                    g.indices.push([list[0] as u32, list[k] as u32, list[k + 1] as u32]);
                }
                rows.push(list.len() - 2);
            }
        }
    }
    if g.indices.is_empty() {
        return Err(scene_error(path, None, "has no faces"));
    }
    g.normals = wanted.has_normals.then_some(normals);
    g.uvs = wanted.uv_names.map(|_| uvs);
    g.attributes = vertex_rows.finish(true);
    g.attributes.extend(face_rows.finish(false));
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

/// Rejects element counts an ASCII payload cannot hold, before the parser allocates for them:
/// each element takes a line.
fn check_ascii_sizes(path: &Path, elements: &ply_rs_bw::ply::KeyMap<ElementDef>, payload: &[u8]) -> Result<()> {
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
    Ok(())
}

/// Rejects element counts a binary payload of `payload_len` bytes cannot hold, before anything
/// is allocated for them: each element takes at least the sizes of its scalars and list counts.
fn check_binary_sizes(path: &Path, elements: &ply_rs_bw::ply::KeyMap<ElementDef>, payload_len: u64) -> Result<()> {
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
        if needed > payload_len {
            return Err(scene_error(
                path,
                None,
                format!(
                    "element '{name}' declares {} items, which need more than the {} bytes left in the file (truncated?)",
                    e.count, payload_len
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

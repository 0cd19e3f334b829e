//! Mitsuba's `.serialized` meshes: a file of zlib-compressed triangle meshes with a table of
//! where each one starts, read as Mitsuba 3's `serialized` plugin reads them.
//!
//! The format (Mitsuba 3 documentation, "Serialized mesh loader"): each mesh is a little-endian
//! `u16` 0x041C, a `u16` version (3 or 4), then a zlib stream holding a `u32` of flags
//! (0x0001 vertex normals, 0x0002 texture coordinates, 0x0008 vertex colours, 0x0010 face
//! normals, 0x1000 single / 0x2000 double precision), in version 4 the mesh's name ending in a
//! 0 byte, a `u64` vertex count and a `u64` triangle count, then the positions, the normals, the
//! texture coordinates and the colours (3, 3, 2 and 3 values a vertex, each array only if its
//! flag is set) and the triangles' vertex indices (`u32`, or `u64` above 2³² vertices). The file
//! ends with the offset of every mesh (`u64` in version 4, `u32` in version 3) and their count
//! (`u32`). Colours are read past; texture coordinates are taken as they are (no flip).
//!
//! Every count is checked against the bytes the stream holds before anything is allocated, and
//! every index against the vertex count: a truncated or hostile file is an error naming the file,
//! the mesh and what is wrong, never a panic or an allocation of the file's fiction.

use std::io::Read;
use std::path::Path;

use glam::{Vec2, Vec3};

use super::{read_file, scene_error};
use crate::error::Result;
use crate::scene::shapes::Geometry;

const MAGIC: u16 = 0x041C;
const HAS_NORMALS: u32 = 0x0001;
const HAS_UVS: u32 = 0x0002;
const HAS_COLORS: u32 = 0x0008;
const FACE_NORMALS: u32 = 0x0010;
const SINGLE: u32 = 0x1000;
const DOUBLE: u32 = 0x2000;

/// What a mesh of the file says about itself besides its geometry.
#[derive(Clone, Debug, PartialEq)]
pub struct SerializedMesh {
    /// The triangles (normals `None` when the file has none or asks for face normals).
    pub geometry: Geometry,
    /// The mesh's name (version 4), empty otherwise.
    pub name: String,
    /// Whether the file asks for face normals (flag 0x0010).
    pub face_normals: bool,
}

/// Reads mesh `index` (0-based) of the `.serialized` file at `path`.
///
/// # Errors
/// [`crate::Error::Io`] for an unreadable file; [`crate::Error::Scene`] naming the file for
/// anything malformed, and for an index beyond the file's meshes.
pub fn load_serialized(path: &Path, index: u32) -> Result<SerializedMesh> {
    super::decoding(|| read_serialized(path, index))
}

fn read_serialized(path: &Path, index: u32) -> Result<SerializedMesh> {
    let bytes = read_file(path)?;
    let err = |m: String| scene_error(path, None, m);
    let (version, start) = mesh_start(&bytes, index).map_err(err)?;
    let end = bytes.len();
    let header = &bytes[start..end.min(start + 4)];
    let (magic, found) = (u16::from_le_bytes([header[0], header[1]]), u16::from_le_bytes([header[2], header[3]]));
    if magic != MAGIC || found != version {
        return Err(err(format!("mesh {index} does not start with the serialized header (0x041C, version {version})")));
    }
    let mut stream = Vec::new();
    flate2::read::ZlibDecoder::new(&bytes[start + 4..])
        .read_to_end(&mut stream)
        .map_err(|e| err(format!("mesh {index}: the compressed stream is broken ({e})")))?;
    read_mesh(&stream, version).map_err(|m| err(format!("mesh {index}: {m}")))
}

/// The format version and the byte offset of mesh `index`, from the table at the file's end.
fn mesh_start(bytes: &[u8], index: u32) -> std::result::Result<(u16, usize), String> {
    if bytes.len() < 8 {
        return Err("too short to be a serialized mesh file".into());
    }
    let version = u16::from_le_bytes([bytes[2], bytes[3]]);
    if u16::from_le_bytes([bytes[0], bytes[1]]) != MAGIC || !(version == 3 || version == 4) {
        return Err("not a serialized mesh file (it does not begin with 0x041C and version 3 or 4)".into());
    }
    let count = u32::from_le_bytes(bytes[bytes.len() - 4..].try_into().expect("4 bytes"));
    if index >= count {
        return Err(format!("shape_index {index} is out of range: the file holds {count} mesh(es)"));
    }
    let width = if version == 4 { 8 } else { 4 };
    let table = (count as usize).checked_mul(width).filter(|t| t + 4 <= bytes.len());
    let Some(table) = table else {
        return Err(format!("its table of {count} mesh offsets does not fit in the file"));
    };
    let at = bytes.len() - 4 - table + index as usize * width;
    let offset = if version == 4 {
        u64::from_le_bytes(bytes[at..at + 8].try_into().expect("8 bytes"))
    } else {
        u64::from(u32::from_le_bytes(bytes[at..at + 4].try_into().expect("4 bytes")))
    };
    match usize::try_from(offset) {
        Ok(o) if o + 4 <= bytes.len() - 4 - table => Ok((version, o)),
        _ => Err(format!("mesh {index}'s offset {offset} lies outside the file")),
    }
}

/// A little-endian reader over the decompressed stream.
struct Reader<'a> {
    data: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn take(&mut self, n: usize, what: &str) -> std::result::Result<&[u8], String> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.data.len());
        let Some(end) = end else {
            return Err(format!("the stream ends inside the {what}"));
        };
        let out = &self.data[self.at..end];
        self.at = end;
        Ok(out)
    }

    fn u32(&mut self, what: &str) -> std::result::Result<u32, String> {
        Ok(u32::from_le_bytes(self.take(4, what)?.try_into().expect("4 bytes")))
    }

    fn u64(&mut self, what: &str) -> std::result::Result<u64, String> {
        Ok(u64::from_le_bytes(self.take(8, what)?.try_into().expect("8 bytes")))
    }

    /// `n` floats (single or double precision, as f32), checked against the bytes left first.
    fn floats(&mut self, n: usize, double: bool, what: &str) -> std::result::Result<Vec<f32>, String> {
        let size = if double { 8 } else { 4 };
        let raw = self.take(n.checked_mul(size).ok_or_else(|| format!("too many {what}"))?, what)?;
        Ok(if double {
            raw.chunks_exact(8).map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")) as f32).collect()
        } else {
            raw.chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes"))).collect()
        })
    }
}

fn read_mesh(stream: &[u8], version: u16) -> std::result::Result<SerializedMesh, String> {
    let mut r = Reader { data: stream, at: 0 };
    let flags = r.u32("flags")?;
    let double = match (flags & SINGLE != 0, flags & DOUBLE != 0) {
        (true, false) => false,
        (false, true) => true,
        _ => return Err(format!("flags 0x{flags:04x} give neither single nor double precision (or both)")),
    };
    let mut name = String::new();
    if version == 4 {
        let rest = &stream[r.at..];
        let len = rest.iter().position(|&b| b == 0).ok_or("the mesh name has no terminating 0 byte")?;
        name = String::from_utf8_lossy(&rest[..len]).into_owned();
        r.at += len + 1;
    }
    let vertices = usize::try_from(r.u64("vertex count")?).map_err(|_| "too many vertices")?;
    let triangles = usize::try_from(r.u64("triangle count")?).map_err(|_| "too many triangles")?;
    let positions = r.floats(vertices.checked_mul(3).ok_or("too many vertices")?, double, "positions")?;
    let normals = if flags & HAS_NORMALS != 0 { Some(r.floats(vertices * 3, double, "normals")?) } else { None };
    let uvs = if flags & HAS_UVS != 0 { Some(r.floats(vertices * 2, double, "texture coordinates")?) } else { None };
    if flags & HAS_COLORS != 0 {
        r.floats(vertices * 3, double, "vertex colours")?;
    }
    let wide = vertices > u32::MAX as usize;
    let raw = r.take(triangles.checked_mul(if wide { 24 } else { 12 }).ok_or("too many triangles")?, "indices")?;
    let indices: Vec<u32> = if wide {
        raw.chunks_exact(8)
            .map(|c| u32::try_from(u64::from_le_bytes(c.try_into().expect("8 bytes"))).unwrap_or(u32::MAX))
            .collect()
    } else {
        raw.chunks_exact(4).map(|c| u32::from_le_bytes(c.try_into().expect("4 bytes"))).collect()
    };
    if let Some(bad) = indices.iter().find(|&&i| i as usize >= vertices) {
        return Err(format!("vertex index {bad} is out of range ({vertices} vertices)"));
    }
    let vec3s = |v: &[f32]| v.chunks_exact(3).map(|c| Vec3::new(c[0], c[1], c[2])).collect::<Vec<_>>();
    let face_normals = flags & FACE_NORMALS != 0;
    let geometry = Geometry {
        positions: vec3s(&positions),
        normals: normals.filter(|_| !face_normals).map(|n| vec3s(&n)),
        uvs: uvs.map(|t| t.chunks_exact(2).map(|c| Vec2::new(c[0], c[1])).collect()),
        indices: indices.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect(),
        attributes: Vec::new(),
    };
    Ok(SerializedMesh { geometry, name, face_normals })
}

#[cfg(test)]
mod tests {
    use std::io::Write;

    use super::*;

    /// A version-4 file of `meshes` (flags, vertices, triangles), each a unit quad in z = 0.
    fn file(meshes: &[(u32, &str)]) -> Vec<u8> {
        let mut out = Vec::new();
        let mut offsets = Vec::new();
        for &(flags, name) in meshes {
            offsets.push(out.len() as u64);
            let mut s = Vec::new();
            s.extend(flags.to_le_bytes());
            s.extend(name.as_bytes());
            s.push(0);
            s.extend(4u64.to_le_bytes());
            s.extend(2u64.to_le_bytes());
            let double = flags & DOUBLE != 0;
            let mut put = |v: &[f32]| {
                for &x in v {
                    if double { s.extend(f64::from(x).to_le_bytes()) } else { s.extend(x.to_le_bytes()) }
                }
            };
            put(&[0., 0., 0., 1., 0., 0., 1., 1., 0., 0., 1., 0.]);
            if flags & HAS_NORMALS != 0 {
                put(&[0., 0., 1., 0., 0., 1., 0., 0., 1., 0., 0., 1.]);
            }
            if flags & HAS_UVS != 0 {
                put(&[0., 0., 1., 0., 1., 1., 0., 1.]);
            }
            for i in [0u32, 1, 2, 0, 2, 3] {
                s.extend(i.to_le_bytes());
            }
            let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
            z.write_all(&s).unwrap();
            out.extend(MAGIC.to_le_bytes());
            out.extend(4u16.to_le_bytes());
            out.extend(z.finish().unwrap());
        }
        for o in &offsets {
            out.extend(o.to_le_bytes());
        }
        out.extend((offsets.len() as u32).to_le_bytes());
        out
    }

    fn load(bytes: &[u8], index: u32) -> Result<SerializedMesh> {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("m.serialized");
        std::fs::write(&path, bytes).unwrap();
        load_serialized(&path, index)
    }

    #[test]
    fn meshes_are_read_by_index_with_their_attributes() {
        let bytes = file(&[(SINGLE | HAS_NORMALS, "first"), (DOUBLE | HAS_UVS | FACE_NORMALS, "second")]);
        let a = load(&bytes, 0).unwrap();
        assert_eq!((a.name.as_str(), a.face_normals), ("first", false));
        assert_eq!(a.geometry.indices, [[0, 1, 2], [0, 2, 3]]);
        assert_eq!(a.geometry.positions[2], Vec3::new(1.0, 1.0, 0.0));
        assert_eq!(a.geometry.normals.as_deref(), Some(&[Vec3::Z; 4][..]));
        assert!(a.geometry.uvs.is_none());
        let b = load(&bytes, 1).unwrap();
        assert_eq!((b.name.as_str(), b.face_normals), ("second", true));
        assert_eq!(b.geometry.uvs.as_ref().unwrap()[2], Vec2::new(1.0, 1.0));
        assert!(b.geometry.normals.is_none());
    }

    #[test]
    fn malformed_files_are_refused_by_name() {
        let good = file(&[(SINGLE, "m")]);
        let message = |bytes: &[u8], index: u32| load(bytes, index).unwrap_err().to_string();
        assert!(message(&good, 1).contains("shape_index 1 is out of range: the file holds 1 mesh(es)"));
        assert!(message(b"nothing here", 0).contains("not a serialized mesh file"));
        // A table claiming more meshes than fit, and a truncated stream.
        let mut lying = good.clone();
        let n = lying.len();
        lying[n - 4..].copy_from_slice(&1000u32.to_le_bytes());
        assert!(message(&lying, 5).contains("table of 1000 mesh offsets does not fit"));
        let stream_end = good.len() - 12;
        let mut cut = good[..4 + (stream_end - 4) / 2].to_vec();
        cut.extend(0u64.to_le_bytes());
        cut.extend(1u32.to_le_bytes());
        assert!(message(&cut, 0).contains("mesh 0:"), "{}", message(&cut, 0));
        // Every truncation of the file fails cleanly.
        for len in 0..good.len() {
            assert!(load(&good[..len], 0).is_err());
        }
    }
}

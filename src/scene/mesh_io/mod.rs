//! Triangle meshes from Wavefront OBJ (pathgrad's own parallel reader), PLY (`ply-rs-bw` for the header and ASCII payloads) and Mitsuba `.serialized` files, as [`Geometry`](crate::scene::shapes::Geometry); Mitsuba's curve files as control points ([`load_curves`]).
//!
//! Both loaders merge everything the file holds into one [`Geometry`](crate::scene::shapes::Geometry): every OBJ object and group,
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
//! **No panics.** The OBJ reader checks every index it resolves (a relative one that points before
//! the first element, e.g. `f 1/-5 …` with one `vt`, is an error at its line). The PLY header's element counts
//! are checked against the file size before the payload is read, so a tiny file cannot ask for
//! billions of empty elements. Each third-party parse still runs under
//! [`std::panic::catch_unwind`] as a backstop: a panic we did not foresee becomes an error naming
//! the file (the panic message itself still reaches the default panic hook's stderr output).

use std::path::Path;

use crate::error::{Error, Result};

mod curves;
mod obj;
#[cfg(any(test, feature = "obj-oracle"))]
mod obj_tobj;
mod ply;
mod serialized;

pub use curves::load_curves;
pub use obj::load_obj;
#[cfg(feature = "obj-oracle")]
#[doc(hidden)]
pub use obj_tobj::load_obj_tobj;
pub use ply::load_ply;
pub use serialized::{SerializedMesh, load_serialized};

/// An [`Error::Scene`] located at `path` (and `line`, 1-based, if known).
pub(crate) fn scene_error(path: &Path, line: Option<usize>, message: impl Into<String>) -> Error {
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

thread_local! {
    /// Seconds spent reading and decoding mesh files on this thread since the last
    /// [`take_decode_time`], and the memory after the last one (see [`crate::phases`]).
    static DECODE: std::cell::Cell<(f64, Option<crate::phases::Memory>)> = const { std::cell::Cell::new((0.0, None)) };
}

/// Runs `f` (a mesh file's read and decode) and adds its wall time to this thread's count, which
/// [`crate::scene::load_reporting`] reports as the `parse` phase. A loader runs on the thread
/// that called it, so the count is that load's.
pub(crate) fn decoding<T>(f: impl FnOnce() -> T) -> T {
    let start = std::time::Instant::now();
    let out = f();
    let seconds = start.elapsed().as_secs_f64();
    DECODE.with(|d| d.set((d.get().0 + seconds, crate::phases::Memory::now())));
    out
}

/// The seconds counted by [`decoding`] since the last call, and the memory after the last decode;
/// resets the count.
pub(crate) fn take_decode_time() -> (f64, Option<crate::phases::Memory>) {
    DECODE.with(|d| d.replace((0.0, None)))
}

/// Runs `f`, returning `None` if it panics. Only for calls into third-party parsers whose
/// freedom from panics on hostile input we cannot prove (see the module docs).
pub(crate) fn catch_panic<T>(f: impl FnOnce() -> T) -> Option<T> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)).ok()
}

#[cfg(test)]
mod tests {
    use glam::{Vec2, Vec3};

    use super::*;
    use crate::scene::shapes::Geometry;

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

    /// Mitsuba's mesh attributes: the vertices' and faces' other properties grouped under its
    /// names, the same from ASCII and binary payloads; a quad's face values repeat for its two
    /// triangles; runs that fit no naming scheme are left out.
    #[test]
    fn ply_attributes_take_mitsubas_names() {
        let header = |format: &str| {
            format!(
                "ply\nformat {format} 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n\
                 property float red\nproperty float green\nproperty float blue\nproperty float temp_0\n\
                 property float odd_x\nproperty float odd_y\nelement face 2\nproperty list uchar int vertex_indices\n\
                 property float color_0\nproperty float color_1\nproperty float color_2\nproperty float weight_0\n\
                 property float dir_r\nproperty float dir_g\nproperty float dir_b\nend_header\n"
            )
        };
        let vertices: [[f32; 9]; 4] = [
            [0.0, 0.0, 0.0, 0.1, 0.2, 0.3, 5.0, 1.0, 1.0],
            [1.0, 0.0, 0.0, 0.4, 0.5, 0.6, 6.0, 1.0, 1.0],
            [1.0, 1.0, 0.0, 0.7, 0.8, 0.9, 7.0, 1.0, 1.0],
            [0.0, 1.0, 0.0, 1.0, 0.0, 0.5, 8.0, 1.0, 1.0],
        ];
        let faces: [(&[i32], [f32; 7]); 2] = [
            (&[0, 1, 2, 3], [0.25, 0.5, 0.75, 0.125, 1.0, 2.0, 3.0]),
            (&[0, 2, 1], [1.0, 0.0, 0.5, 0.875, 4.0, 5.0, 6.0]),
        ];
        let mut ascii = header("ascii");
        for v in &vertices {
            ascii += &format!("{}\n", v.map(|x| x.to_string()).join(" "));
        }
        for (list, values) in &faces {
            let list: Vec<String> = list.iter().map(|i| i.to_string()).collect();
            ascii += &format!("{} {} {}\n", list.len(), list.join(" "), values.map(|x| x.to_string()).join(" "));
        }
        let mut binary = header("binary_little_endian").into_bytes();
        for v in &vertices {
            v.iter().for_each(|x| binary.extend(x.to_le_bytes()));
        }
        for (list, values) in &faces {
            binary.push(list.len() as u8);
            list.iter().for_each(|i| binary.extend(i.to_le_bytes()));
            values.iter().for_each(|x| binary.extend(x.to_le_bytes()));
        }
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (dir.path().join("a.ply"), dir.path().join("b.ply"));
        std::fs::write(&a, ascii).unwrap();
        std::fs::write(&b, binary).unwrap();
        let g = load_ply(&a).unwrap();
        assert_eq!(g, load_ply(&b).unwrap());
        let names: Vec<&str> = g.attributes.iter().map(|a| a.name.as_str()).collect();
        // `odd_x odd_y` is a run of 2: Mitsuba ignores it.
        assert_eq!(names, ["vertex_color", "vertex_temp", "face_color", "face_weight", "face_dir_color"]);
        let color = g.attribute("vertex_color").unwrap();
        assert!(color.per_vertex && color.dim == 3);
        assert_eq!(color.values[3..6], [0.4, 0.5, 0.6]);
        assert_eq!(g.attribute("vertex_temp").unwrap().values, [5.0, 6.0, 7.0, 8.0]);
        // The quad fans into two triangles, each with the quad's values.
        assert_eq!(g.indices.len(), 3);
        let weight = g.attribute("face_weight").unwrap();
        assert!(!weight.per_vertex && weight.dim == 1);
        assert_eq!(weight.values, [0.125, 0.125, 0.875]);
        assert_eq!(g.attribute("face_color").unwrap().values[6..9], [1.0, 0.0, 0.5]);
        // Dropping a triangle drops its rows.
        let mut pruned = g.clone();
        pruned.retain_triangles(|t| t[2] != 3);
        assert_eq!(pruned.indices, [[0, 1, 2], [0, 2, 1]]);
        assert_eq!(pruned.attribute("face_weight").unwrap().values, [0.125, 0.875]);
        assert_eq!(pruned.attribute("vertex_temp").unwrap().values.len(), 4);
    }

    /// The binary decoder (issue 38) reads every scalar type in both byte orders, skips the
    /// properties and lists it does not use, and refuses a negative list length.
    #[test]
    fn ply_binary_of_every_type_and_order_matches_ascii() {
        let ascii = load_ply(&data("quad_ascii.ply")).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let vertices = [
            [0.0, 0.0, 0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0, 1.0, 0.0],
            [1.0, 1.0, 0.0, 1.0, 1.0],
            [0.0, 1.0, 0.0, 0.0, 1.0],
        ];
        for big in [false, true] {
            let mut bytes = format!(
                "ply\nformat binary_{}_endian 1.0\nelement vertex 4\nproperty double x\nproperty uchar junk\n\
                 property float y\nproperty short z\nproperty char nx\nproperty ushort ny\nproperty int nz\n\
                 property uint u\nproperty float v\nelement face 1\nproperty list ushort float texcoord\n\
                 property list uchar uint vertex_indices\nend_header\n",
                if big { "big" } else { "little" }
            )
            .into_bytes();
            let mut put = |b: &[u8]| {
                let mut b = b.to_vec();
                if big {
                    b.reverse();
                }
                bytes.extend(b);
            };
            for [x, y, z, u, v] in vertices {
                put(&f64::to_le_bytes(x));
                put(&[7]);
                put(&f32::to_le_bytes(y as f32));
                put(&i16::to_le_bytes(z as i16));
                put(&[0]);
                put(&u16::to_le_bytes(0));
                put(&i32::to_le_bytes(1));
                put(&u32::to_le_bytes(u as u32));
                put(&f32::to_le_bytes(v as f32));
            }
            put(&u16::to_le_bytes(2));
            put(&f32::to_le_bytes(0.5));
            put(&f32::to_le_bytes(0.25));
            put(&[4]);
            for i in [0u32, 1, 2, 3] {
                put(&u32::to_le_bytes(i));
            }
            let path = dir.path().join("typed.ply");
            std::fs::write(&path, &bytes).unwrap();
            assert_eq!(load_ply(&path).unwrap(), ascii, "big endian: {big}");
        }
        let negative = b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n\
            property float y\nproperty float z\nelement face 1\nproperty list char int vertex_indices\nend_header\n";
        let mut bytes = negative.to_vec();
        bytes.extend([0u8; 36]);
        bytes.push(0xff);
        bytes.extend([0u8; 12]);
        let path = dir.path().join("negative.ply");
        std::fs::write(&path, &bytes).unwrap();
        let message = error(load_ply(&path));
        assert!(message.ends_with("negative.ply: face 0: list 'vertex_indices' has the length -1"), "{message}");
    }

    /// The streamed binary decoder (issue 38) across its read buffer's refills (1 MiB) and its
    /// parallel vertex batches (65 536 vertices): an element of lists, then 70 000 vertices of
    /// 41-byte records and 50 000 faces (triangles and quads) give the geometry of the same mesh
    /// written as ASCII.
    #[test]
    fn ply_binary_streamed_across_chunks_matches_ascii() {
        let dir = tempfile::tempdir().unwrap();
        let (n, faces) = (70_000u32, 50_000u32);
        let value = |i: u32, k: u32| ((i * 7 + k * 13) % 1000) as f32 * 0.001 + k as f32;
        let header = |format: &str| {
            format!(
                "ply\nformat {format} 1.0\nelement junk 2\nproperty list uchar float values\n\
                 element vertex {n}\nproperty float x\nproperty float y\n\
                 property float z\nproperty uchar flag\nproperty float nx\nproperty float ny\nproperty float nz\n\
                 property double u\nproperty double v\nelement face {faces}\nproperty list uchar int vertex_indices\n\
                 end_header\n"
            )
        };
        let face = |f: u32| -> Vec<u32> {
            let a = (f * 3) % (n - 3);
            if f.is_multiple_of(5) { vec![a, a + 1, a + 2, a + 3] } else { vec![a, a + 2, a + 1] }
        };
        let mut ascii = header("ascii") + "2 0.5 0.25\n0\n";
        let mut binary = header("binary_little_endian").into_bytes();
        // An element read scalar by scalar before the vertices: the buffer is then full of
        // unread bytes when the first vertex batch asks for more than it holds.
        binary.extend([2u8]);
        binary.extend(0.5f32.to_le_bytes());
        binary.extend(0.25f32.to_le_bytes());
        binary.push(0);
        for i in 0..n {
            let v: Vec<f32> = (0..8).map(|k| value(i, k)).collect();
            ascii.push_str(&format!("{} {} {} 3 {} {} {} {} {}\n", v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7]));
            for (k, x) in v.iter().enumerate() {
                if k == 3 {
                    binary.push(3);
                }
                if k < 6 {
                    binary.extend(x.to_le_bytes());
                } else {
                    binary.extend(f64::from(*x).to_le_bytes());
                }
            }
        }
        for f in 0..faces {
            let list = face(f);
            ascii.push_str(&format!("{}", list.len()));
            binary.push(list.len() as u8);
            for i in list {
                ascii.push_str(&format!(" {i}"));
                binary.extend((i as i32).to_le_bytes());
            }
            ascii.push('\n');
        }
        let (a, b) = (dir.path().join("big_ascii.ply"), dir.path().join("big_binary.ply"));
        std::fs::write(&a, ascii).unwrap();
        std::fs::write(&b, binary).unwrap();
        let from_ascii = load_ply(&a).unwrap();
        assert_eq!(from_ascii.positions.len(), n as usize);
        assert_eq!(from_ascii.indices.len(), (faces + faces / 5) as usize);
        assert_eq!(load_ply(&b).unwrap(), from_ascii);
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
            // tobj 4 overflowed (a panic in debug builds) on this relative index.
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
        let mut next = crate::testing::xorshift64(0x9e37_79b9_7f4a_7c15);
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

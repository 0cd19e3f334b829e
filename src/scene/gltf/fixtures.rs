//! Test-only generator of the committed glTF scenes (`scenes/gltf/showcase.*`, `scenes/twin/twin.*`).
//!
//! The files are committed so that users and the README can use them; this generator is the record
//! of how they were made. `committed_files_match_the_generator` keeps the two in step, and
//! `cargo test --lib regenerate_gltf_scenes -- --ignored` rewrites them.

use std::path::Path;

use glam::{Mat4, Quat, Vec2, Vec3};
use serde_json::{Value, json};

use crate::scene::shapes::{Geometry, cuboid, quad};

/// A glTF document under construction with one binary buffer.
#[derive(Default)]
struct Builder {
    bin: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
    meshes: Vec<Value>,
}

impl Builder {
    /// Appends `bytes` as a buffer view (4-byte aligned) and returns its index.
    fn view(&mut self, bytes: &[u8]) -> usize {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        self.views.push(json!({ "buffer": 0, "byteOffset": self.bin.len(), "byteLength": bytes.len() }));
        self.bin.extend_from_slice(bytes);
        self.views.len() - 1
    }

    fn accessor(
        &mut self,
        bytes: &[u8],
        component: u32,
        count: usize,
        type_: &str,
        bounds: Option<(Vec3, Vec3)>,
    ) -> usize {
        let view = self.view(bytes);
        let mut a = json!({ "bufferView": view, "componentType": component, "count": count, "type": type_ });
        if let Some((lo, hi)) = bounds {
            a["min"] = json!(lo.to_array());
            a["max"] = json!(hi.to_array());
        }
        self.accessors.push(a);
        self.accessors.len() - 1
    }

    /// Accessors for `g`: (POSITION, NORMAL, TEXCOORD_0, indices).
    fn geometry(&mut self, g: &Geometry) -> Value {
        let lo = g.positions.iter().fold(Vec3::INFINITY, |a, &p| a.min(p));
        let hi = g.positions.iter().fold(Vec3::NEG_INFINITY, |a, &p| a.max(p));
        let n = g.positions.len();
        let position = self.accessor(bytemuck::cast_slice(&g.positions), 5126, n, "VEC3", Some((lo, hi)));
        let mut attributes = json!({ "POSITION": position });
        if let Some(normals) = &g.normals {
            attributes["NORMAL"] = json!(self.accessor(bytemuck::cast_slice(normals), 5126, n, "VEC3", None));
        }
        if let Some(uvs) = &g.uvs {
            attributes["TEXCOORD_0"] =
                json!(self.accessor(bytemuck::cast_slice::<Vec2, u8>(uvs), 5126, n, "VEC2", None));
        }
        let indices: Vec<u16> = g.indices.iter().flatten().map(|&i| i as u16).collect();
        let indices = self.accessor(bytemuck::cast_slice(&indices), 5123, indices.len(), "SCALAR", None);
        json!({ "attributes": attributes, "indices": indices })
    }

    /// Adds a mesh with one primitive per material, all sharing the geometry's accessors.
    fn mesh(&mut self, name: &str, g: &Geometry, materials: &[usize]) -> usize {
        let primitive = self.geometry(g);
        let primitives: Vec<Value> = materials
            .iter()
            .map(|&m| {
                let mut p = primitive.clone();
                p["material"] = json!(m);
                p
            })
            .collect();
        self.meshes.push(json!({ "name": name, "primitives": primitives }));
        self.meshes.len() - 1
    }

    /// The document: `.gltf` with `bin_uri`, or the GLB form (buffer without uri) when `None`.
    fn document(&self, rest: Value, bin_uri: Option<&str>) -> Value {
        let mut doc = rest;
        let mut buffer = json!({ "byteLength": self.bin.len() });
        if let Some(uri) = bin_uri {
            buffer["uri"] = json!(uri);
        }
        doc["asset"] = json!({ "version": "2.0", "generator": "pathgrad src/scene/gltf/fixtures.rs" });
        doc["buffers"] = json!([buffer]);
        doc["bufferViews"] = json!(self.views);
        doc["accessors"] = json!(self.accessors);
        doc["meshes"] = json!(self.meshes);
        doc
    }
}

/// Packs a GLB container (glTF 2.0 §4.4).
fn glb(json: &Value, bin: &[u8]) -> Vec<u8> {
    let mut text = serde_json::to_vec(json).expect("serialising a Value cannot fail");
    while !text.len().is_multiple_of(4) {
        text.push(b' ');
    }
    let mut bin = bin.to_vec();
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let total = 12 + 8 + text.len() + 8 + bin.len();
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(text.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&text);
    out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&bin);
    out
}

/// The 4×4 checker base-colour texture (sRGB bytes): (200, 60, 40) and (40, 90, 200); texel (0, 0)
/// — the image's top-left — is the first colour.
pub(super) const CHECKER: [[u8; 3]; 2] = [[200, 60, 40], [40, 90, 200]];

fn checker_png() -> Vec<u8> {
    let img = image::RgbImage::from_fn(4, 4, |x, y| image::Rgb(CHECKER[((x + y) % 2) as usize]));
    let mut png = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png).expect("encoding a PNG in memory");
    png
}

fn trs(t: Vec3, r: Quat, s: Vec3) -> Value {
    json!({ "translation": t.to_array(), "rotation": r.to_array(), "scale": s.to_array() })
}

/// `scenes/gltf/showcase`: (.gltf JSON, .bin, PNG, .glb).
pub(super) fn showcase() -> (Value, Vec<u8>, Vec<u8>, Vec<u8>) {
    let mut b = Builder::default();
    let floor = b.mesh("floor_quad", &quad(Vec3::ZERO, Vec3::Z, Vec3::X), &[0]);
    let cube = b.mesh("cube", &cuboid(Vec3::ZERO, Vec3::splat(0.5)), &[1]);
    let satin = b.mesh("satin_cube", &cuboid(Vec3::ZERO, Vec3::splat(0.5)), &[2]);
    let light = b.mesh("light_quad", &quad(Vec3::ZERO, Vec3::X * 0.5, Vec3::Z * 0.5), &[3]);
    let node = |name: &str, fields: Value| {
        let mut n = fields;
        n["name"] = json!(name);
        n
    };
    let satin_matrix = Mat4::from_translation(Vec3::new(0.8, 0.0, 0.0)) * Mat4::from_scale(Vec3::splat(0.6));
    let nodes = json!([
        node(
            "camera",
            json!({ "camera": 0, "translation": [0.0, 1.5, 5.0], "rotation": Quat::from_rotation_x(-15f32.to_radians()).to_array() })
        ),
        node("floor", json!({ "mesh": floor, "scale": [4.0, 1.0, 4.0] })),
        node("group", json!({ "translation": [0.0, 0.5, 0.0], "children": [3, 4] })),
        node("metal_box", {
            let mut n = trs(Vec3::new(-0.8, 0.0, 0.0), Quat::from_rotation_y(30f32.to_radians()), Vec3::ONE);
            n["mesh"] = json!(cube);
            n
        }),
        node("satin_box", json!({ "mesh": satin, "matrix": satin_matrix.to_cols_array() })),
        node("light", json!({ "mesh": light, "translation": [0.0, 3.0, 0.0] })),
    ]);
    let rest = json!({
        "scene": 0,
        "scenes": [{ "name": "showcase", "nodes": [0, 1, 2, 5] }],
        "nodes": nodes,
        "cameras": [{ "type": "perspective", "perspective": { "yfov": 0.6, "aspectRatio": 1.5, "znear": 0.1 } }],
        "extensionsUsed": ["KHR_materials_emissive_strength"],
        "materials": [
            { "name": "floor", "doubleSided": true,
              "pbrMetallicRoughness": { "baseColorTexture": { "index": 0 }, "baseColorFactor": [1.0, 1.0, 0.5, 1.0], "metallicFactor": 0.0, "roughnessFactor": 0.8 } },
            { "name": "metal", "pbrMetallicRoughness": { "baseColorFactor": [0.9, 0.6, 0.3, 1.0], "metallicFactor": 1.0, "roughnessFactor": 0.3 } },
            { "name": "satin", "pbrMetallicRoughness": { "baseColorFactor": [0.2, 0.4, 0.8, 1.0], "metallicFactor": 0.5, "roughnessFactor": 0.5 } },
            { "name": "light", "emissiveFactor": [1.0, 0.9, 0.8],
              "extensions": { "KHR_materials_emissive_strength": { "emissiveStrength": 40.0 } },
              "pbrMetallicRoughness": { "baseColorFactor": [0.0, 0.0, 0.0, 1.0], "metallicFactor": 0.0, "roughnessFactor": 1.0 } },
        ],
        "samplers": [{ "magFilter": 9729, "minFilter": 9729 }],
        "textures": [{ "sampler": 0, "source": 0 }],
    });
    let png = checker_png();
    let mut gltf = b.document(rest.clone(), Some("showcase.bin"));
    gltf["images"] = json!([{ "uri": "checker.png" }]);
    let bin = b.bin.clone();
    // The GLB carries the PNG in its binary chunk.
    let png_view = b.view(&png);
    let mut glb_json = b.document(rest, None);
    glb_json["images"] = json!([{ "bufferView": png_view, "mimeType": "image/png" }]);
    let glb = glb(&glb_json, &b.bin);
    (gltf, bin, png, glb)
}

/// `scenes/twin/twin`: (.gltf JSON, .bin). Its Mitsuba twin is `scenes/twin/twin.xml`; the values
/// below are the ones that file must match (see the module docs of `scene::gltf` for the mapping).
pub(super) fn twin() -> (Value, Vec<u8>) {
    let mut b = Builder::default();
    // Unit shapes, as Mitsuba's `rectangle` ([-1, 1]² in z = 0, normal +z) and `cube` ([-1, 1]³).
    let rectangle = b.mesh("rectangle", &quad(Vec3::ZERO, Vec3::X, Vec3::Y), &[0]);
    let diffuse_cube = b.mesh("diffuse_cube", &cuboid(Vec3::ZERO, Vec3::ONE), &[1]);
    let metal_cube = b.mesh("metal_cube", &cuboid(Vec3::ZERO, Vec3::ONE), &[2]);
    let emitter = b.mesh("emitter", &quad(Vec3::ZERO, Vec3::X, Vec3::Y), &[3]);
    let rotate_x = |deg: f32| Quat::from_rotation_x(deg.to_radians()).to_array();
    let rest = json!({
        "scene": 0,
        "scenes": [{ "name": "twin", "nodes": [0, 1, 2, 3, 4] }],
        "nodes": [
            { "name": "camera", "camera": 0, "translation": [0.0, 2.0, 6.0], "rotation": Quat::from_rotation_x(-(2f32 / 6.0).atan()).to_array() },
            { "name": "floor", "mesh": rectangle, "rotation": rotate_x(-90.0), "scale": [3.0, 3.0, 1.0] },
            { "name": "diffuse_box", "mesh": diffuse_cube, "translation": [-0.9, 0.5, 0.0], "scale": [0.5, 0.5, 0.5] },
            { "name": "metal_box", "mesh": metal_cube, "translation": [0.9, 0.4, 0.3], "scale": [0.4, 0.4, 0.4] },
            { "name": "light", "mesh": emitter, "translation": [0.0, 3.0, 0.0], "rotation": rotate_x(90.0), "scale": [0.5, 0.5, 1.0] },
        ],
        "cameras": [{ "type": "perspective", "perspective": { "yfov": 40f32.to_radians(), "aspectRatio": 1.0, "znear": 0.1 } }],
        "extensionsUsed": ["KHR_materials_emissive_strength"],
        "materials": [
            { "name": "floor", "pbrMetallicRoughness": { "baseColorFactor": [0.5, 0.5, 0.5, 1.0], "metallicFactor": 0.0, "roughnessFactor": 1.0 } },
            { "name": "diffuse", "pbrMetallicRoughness": { "baseColorFactor": [0.7, 0.3, 0.2, 1.0], "metallicFactor": 0.0, "roughnessFactor": 0.6 } },
            { "name": "metal", "pbrMetallicRoughness": { "baseColorFactor": [0.9, 0.8, 0.6, 1.0], "metallicFactor": 1.0, "roughnessFactor": 0.4 } },
            { "name": "light", "emissiveFactor": [1.0, 1.0, 1.0],
              "extensions": { "KHR_materials_emissive_strength": { "emissiveStrength": 30.0 } },
              "pbrMetallicRoughness": { "baseColorFactor": [0.0, 0.0, 0.0, 1.0], "metallicFactor": 1.0, "roughnessFactor": 1.0 } },
        ],
    });
    (b.document(rest, Some("twin.bin")), b.bin)
}

fn write_pretty(path: &Path, json: &Value) {
    let mut text = serde_json::to_string_pretty(json).expect("serialising a Value cannot fail");
    text.push('\n');
    std::fs::write(path, text).unwrap();
}

#[test]
#[ignore = "rewrites the committed scenes; run by hand after changing the generator"]
fn regenerate_gltf_scenes() {
    let (gltf, bin, png, glb) = showcase();
    std::fs::create_dir_all("scenes/gltf").unwrap();
    write_pretty(Path::new("scenes/gltf/showcase.gltf"), &gltf);
    std::fs::write("scenes/gltf/showcase.bin", bin).unwrap();
    std::fs::write("scenes/gltf/checker.png", png).unwrap();
    std::fs::write("scenes/gltf/showcase.glb", glb).unwrap();
    let (gltf, bin) = twin();
    std::fs::create_dir_all("scenes/twin").unwrap();
    write_pretty(Path::new("scenes/twin/twin.gltf"), &gltf);
    std::fs::write("scenes/twin/twin.bin", bin).unwrap();
}

/// `v` with every number rounded to `f32`: serde_json's default float parsing may be one f64 ulp
/// off the printed value.
fn rounded(v: Value) -> Value {
    match v {
        Value::Number(n) if n.is_f64() => json!(n.as_f64().unwrap() as f32),
        Value::Array(a) => Value::Array(a.into_iter().map(rounded).collect()),
        Value::Object(o) => Value::Object(o.into_iter().map(|(k, v)| (k, rounded(v))).collect()),
        v => v,
    }
}

#[test]
fn committed_files_match_the_generator() {
    let read_json = |p: &str| rounded(serde_json::from_slice(&std::fs::read(p).unwrap()).unwrap());
    let (gltf, bin, png, _) = showcase();
    assert_eq!(read_json("scenes/gltf/showcase.gltf"), rounded(gltf));
    assert_eq!(std::fs::read("scenes/gltf/showcase.bin").unwrap(), bin);
    let committed = image::load_from_memory(&std::fs::read("scenes/gltf/checker.png").unwrap()).unwrap();
    assert_eq!(committed.to_rgb8(), image::load_from_memory(&png).unwrap().to_rgb8());
    let (gltf, bin) = twin();
    assert_eq!(read_json("scenes/twin/twin.gltf"), rounded(gltf));
    assert_eq!(std::fs::read("scenes/twin/twin.bin").unwrap(), bin);
}

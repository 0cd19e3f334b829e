//! Tests of the glTF loader: the committed scenes, the documented default camera, and the
//! malformed fixtures under `tests/data/gltf/` with their pinned messages.

use glam::Vec2;

use super::*;
use crate::scene::{Albedo, Material};

#[test]
fn base64_and_percent_decoding() {
    assert_eq!(decode_base64("aGVsbG8=").unwrap(), b"hello");
    assert_eq!(decode_base64("aGVsbG8").unwrap(), b"hello");
    assert_eq!(decode_base64("AAECAw==").unwrap(), [0, 1, 2, 3]);
    assert!(decode_base64("a*bc").is_none());
    assert!(decode_base64("abcde").is_none());
    assert_eq!(percent_decode("my%20mesh.bin").unwrap(), "my mesh.bin");
    assert!(percent_decode("%FF").is_none());
    assert!(percent_decode("%4").is_none());
}

#[test]
fn names_are_sanitised_and_deduplicated() {
    let names = unique_names([Some("Metal Ball"), None, Some("a.b"), Some("a_b"), Some("")].into_iter(), "material");
    assert_eq!(names, ["Metal_Ball", "material_1", "a_b_2", "a_b_3", "material_4"]);
}

#[test]
fn repeated_names_get_unique_suffixes_even_when_a_suffix_is_taken() {
    let names = unique_names([Some("m"), Some("m"), Some("m_1")].into_iter(), "material");
    assert_eq!(names, ["m_0", "m_1_1", "m_1"]);
    let names = unique_names([Some("m_1"), Some("m"), Some("m"), Some("m_1_1")].into_iter(), "node");
    assert_eq!(names, ["m_1", "m_1_2", "m_2", "m_1_1"]);
    // Unnamed entries are named by kind and index, apart from a real name equal to that.
    let names = unique_names([None, Some("material_0")].into_iter(), "material");
    assert_eq!(names, ["material_0_0", "material_0_1"]);
}

/// A glTF scene of `n` emissive nodes named `m`, `m`, `m_1`, … (so every name repeats) and a node
/// `x` whose mesh has two primitives, beside a node `x_0`; each one triangle.
fn many_nodes_gltf(n: usize) -> String {
    let positions: [f32; 9] = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0];
    let bytes: Vec<u8> = positions.iter().flat_map(|v| v.to_le_bytes()).collect();
    let uri = format!("data:application/octet-stream;base64,{}", base64_for_tests(&bytes));
    let mut nodes: Vec<serde_json::Value> =
        (0..n).map(|i| serde_json::json!({"name": if i % 3 == 2 { "m_1" } else { "m" }, "mesh": 0})).collect();
    nodes.push(serde_json::json!({"name": "x", "mesh": 1}));
    nodes.push(serde_json::json!({"name": "x_0", "mesh": 0}));
    let primitive = serde_json::json!({"attributes": {"POSITION": 0}, "material": 0});
    serde_json::json!({
        "asset": {"version": "2.0"},
        "scenes": [{"nodes": (0..n + 2).collect::<Vec<_>>()}],
        "nodes": nodes,
        "meshes": [{"primitives": [primitive]}, {"primitives": [primitive, primitive]}],
        "materials": [{"name": "m", "emissiveFactor": [1.0, 1.0, 1.0]}, {"name": "m"}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                       "min": [0.0, 0.0, 0.0], "max": [1.0, 1.0, 0.0]}],
        "bufferViews": [{"buffer": 0, "byteLength": 36}],
        "buffers": [{"byteLength": 36, "uri": uri}],
    })
    .to_string()
}

/// Standard base64 with padding (the loader's decoder is the reference it is read back with).
fn base64_for_tests(bytes: &[u8]) -> String {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::new();
    for chunk in bytes.chunks(3) {
        let b = [chunk[0], *chunk.get(1).unwrap_or(&0), *chunk.get(2).unwrap_or(&0)];
        let v = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for k in 0..4 {
            out.push(if k <= chunk.len() { ALPHABET[(v >> (18 - 6 * k)) as usize & 63] as char } else { '=' });
        }
    }
    out
}

/// 100 000 nodes with repeated names load (in linear time: names are made unique through hash
/// sets, and parameters are found by a map), and every mesh and emitter parameter is distinct.
#[test]
fn a_hundred_thousand_nodes_with_repeated_names_load() {
    let n = 100_000;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("many.gltf");
    std::fs::write(&path, many_nodes_gltf(n)).unwrap();
    let s = load(&path).unwrap();
    assert_eq!(s.meshes.len(), n + 3);
    let names: HashSet<&str> = s.meshes.iter().map(|m| m.name.as_str()).collect();
    assert_eq!(names.len(), n + 3, "every mesh name is distinct");
    // `m` at 0, 1, 3; `m_1` (repeated too) at 2: its own index after it.
    assert!(["m_0", "m_1", "m_1_2", "m_3"].iter().all(|n| names.contains(n)), "{:?}", &s.meshes[..4]);
    assert!(names.contains("x_0") && names.contains("x_0_1") && names.contains("x_1"), "x's primitives keep apart");
    assert_eq!(s.meshes.iter().filter(|m| m.emitter.is_some()).count(), n + 3);
}

fn data(name: &str) -> std::path::PathBuf {
    Path::new("tests/data/gltf").join(name)
}

fn param(s: &Scene, name: &str) -> Vec<f32> {
    s.params.get(s.params.find(name).unwrap_or_else(|| panic!("no parameter {name}"))).to_vec()
}

fn assert_close(a: &[f32], b: &[f32]) {
    assert!(a.len() == b.len() && a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-5), "{a:?} != {b:?}");
}

#[test]
fn showcase_scene() {
    let s = load(Path::new("scenes/gltf/showcase.gltf")).unwrap();
    let names: Vec<&str> = s.meshes.iter().map(|m| m.name.as_str()).collect();
    assert_eq!(names, ["floor", "metal_box", "satin_box", "light"]);
    assert_eq!(s.triangle_count(), 2 + 12 + 12 + 2);
    assert_eq!(s.warnings, [FRESNEL_WARNING]);

    // Camera: translation (0, 1.5, 5), rotated −15° about x; yfov 0.6 rad; aspect 1.5.
    let c = s.camera;
    assert_eq!(c.position, Vec3::new(0.0, 1.5, 5.0));
    let forward = (c.target - c.position).normalize();
    let t = 15f32.to_radians();
    assert!(forward.abs_diff_eq(Vec3::new(0.0, -t.sin(), -t.cos()), 1e-6), "{forward}");
    assert!((c.fov_y_degrees - 0.6f32.to_degrees()).abs() < 1e-4);
    assert_eq!((c.width, c.height), (512, 341));

    // Transforms: the floor scaled ×4 in x and z; the boxes under "group" (+0.5 in y), one by
    // TRS (−0.8 in x, 30° about y), one by a matrix (+0.8 in x, scale 0.6).
    let bounds = |m: &crate::scene::Mesh| {
        let lo = m.positions.iter().fold(Vec3::INFINITY, |a, &p| a.min(p));
        let hi = m.positions.iter().fold(Vec3::NEG_INFINITY, |a, &p| a.max(p));
        (lo, hi)
    };
    assert_eq!(bounds(&s.meshes[0]), (Vec3::new(-4.0, 0.0, -4.0), Vec3::new(4.0, 0.0, 4.0)));
    let (lo, hi) = bounds(&s.meshes[1]);
    let half = 0.5 * (30f32.to_radians().cos() + 30f32.to_radians().sin());
    assert!(lo.abs_diff_eq(Vec3::new(-0.8 - half, 0.0, -half), 1e-5), "{lo}");
    assert!(hi.abs_diff_eq(Vec3::new(-0.8 + half, 1.0, half), 1e-5), "{hi}");
    let (lo, hi) = bounds(&s.meshes[2]);
    assert!(lo.abs_diff_eq(Vec3::new(0.5, 0.2, -0.3), 1e-6) && hi.abs_diff_eq(Vec3::new(1.1, 0.8, 0.3), 1e-6));
    // The light quad faces down after no rotation: its quad was built facing −y.
    assert!(s.meshes[3].normals.as_ref().unwrap().iter().all(|n| *n == -Vec3::Y));
    assert!(s.meshes[3].positions.iter().all(|p| p.y == 3.0));

    // Materials and parameters, in the order of first use.
    let names: Vec<&str> = s.params.entries().iter().map(|e| e.name.as_str()).collect();
    assert_eq!(
        names,
        [
            "floor.base_color.data",
            "floor.bsdf_1.alpha.value",
            "floor.bsdf_1.specular_reflectance.value",
            "floor.weight.value",
            "metal.alpha.value",
            "metal.specular_reflectance.value",
            "satin.bsdf_0.reflectance.value",
            "satin.bsdf_1.alpha.value",
            "satin.bsdf_1.specular_reflectance.value",
            "satin.weight.value",
            "light.bsdf_0.reflectance.value",
            "light.bsdf_1.alpha.value",
            "light.bsdf_1.specular_reflectance.value",
            "light.weight.value",
            "light.emitter.radiance.value",
        ]
    );
    assert_close(&param(&s, "floor.bsdf_1.alpha.value"), &[0.64]);
    assert_close(&param(&s, "floor.bsdf_1.specular_reflectance.value"), &[1.0; 3]);
    assert_close(&param(&s, "floor.weight.value"), &[0.04]);
    assert_close(&param(&s, "metal.alpha.value"), &[0.09]);
    assert_close(&param(&s, "metal.specular_reflectance.value"), &[0.9, 0.6, 0.3]);
    // m = 0.5: w = 0.04 + 0.96·0.5 = 0.52, s = (0.5·b + 0.02) / 0.52.
    assert_close(&param(&s, "satin.weight.value"), &[0.52]);
    assert_close(&param(&s, "satin.bsdf_0.reflectance.value"), &[0.2, 0.4, 0.8]);
    assert_close(&param(&s, "satin.bsdf_1.specular_reflectance.value"), &[0.12 / 0.52, 0.22 / 0.52, 0.42 / 0.52]);
    assert_close(&param(&s, "satin.bsdf_1.alpha.value"), &[0.25]);
    assert_close(&param(&s, "light.emitter.radiance.value"), &[40.0, 36.0, 32.0]);
    assert!(s.meshes[3].emitter.is_some() && s.meshes.iter().take(3).all(|m| m.emitter.is_none()));

    // The floor is double-sided and textured; its texels are the linearised checker × factor.
    let Material::TwoSided(inner) = s.materials[s.meshes[0].material.0 as usize] else { panic!("floor not two-sided") };
    let Material::Blend { children, .. } = &s.materials[inner.0 as usize] else { panic!("floor not a blend") };
    assert!(matches!(s.materials[children[0].0 as usize], Material::Diffuse { albedo: Albedo::Bitmap(_) }));
    assert_eq!((s.textures[0].width, s.textures[0].height), (4, 4));
    let texels = s.params.get(s.textures[0].texels);
    let expect = |c: [u8; 3]| [0, 1, 2].map(|k| srgb_to_linear(f32::from(c[k]) / 255.0) * [1.0, 1.0, 0.5][k]);
    assert_close(&texels[0..3], &expect(fixtures::CHECKER[0]));
    assert_close(&texels[3..6], &expect(fixtures::CHECKER[1]));
    assert_close(&texels[12..15], &expect(fixtures::CHECKER[1]));
    // glTF uvs are used as they are: v = 0 is the image's top row, pathgrad's row 0.
    assert_eq!(s.meshes[0].uvs.as_ref().unwrap()[0], Vec2::new(0.0, 0.0));
}

#[test]
fn glb_equals_gltf() {
    let gltf = load(Path::new("scenes/gltf/showcase.gltf")).unwrap();
    let glb = load(Path::new("scenes/gltf/showcase.glb")).unwrap();
    assert_eq!(Scene { source: gltf.source.clone(), ..glb }, gltf);
}

#[test]
fn twin_scene() {
    let s = load(Path::new("scenes/twin/twin.gltf")).unwrap();
    assert_eq!(s.warnings, [FRESNEL_WARNING]);
    assert_eq!(s.camera.position, Vec3::new(0.0, 2.0, 6.0));
    assert!((s.camera.target - s.camera.position).normalize().abs_diff_eq(-s.camera.position.normalize(), 1e-6));
    assert!((s.camera.fov_y_degrees - 40.0).abs() < 1e-4);
    let floor = &s.meshes[0];
    assert!(floor.positions.iter().all(|p| p.y.abs() < 1e-6 && p.x.abs() <= 3.0 + 1e-6));
    assert!(floor.normals.as_ref().unwrap().iter().all(|n| n.abs_diff_eq(Vec3::Y, 1e-6)));
    let light = &s.meshes[3];
    assert!(light.normals.as_ref().unwrap().iter().all(|n| n.abs_diff_eq(-Vec3::Y, 1e-6)));
    assert_close(&param(&s, "light.emitter.radiance.value"), &[30.0; 3]);
    assert_close(&param(&s, "light.specular_reflectance.value"), &[0.0; 3]);
    assert_close(&param(&s, "diffuse.bsdf_1.alpha.value"), &[0.36]);
    assert_close(&param(&s, "metal.alpha.value"), &[0.16]);
    s.validate().unwrap();
}

#[test]
fn no_camera_gives_the_documented_default() {
    let s = load(&data("no_camera.gltf")).unwrap();
    // The triangle (0,0,0), (1,0,0), (0,1,0): centre (0.5, 0.5, 0), bounding radius √2/2.
    let distance = 0.5f32.sqrt() / 22.5f32.to_radians().sin();
    assert!(s.camera.position.abs_diff_eq(Vec3::new(0.5, 0.5, distance), 1e-6));
    assert_eq!(s.camera.target, Vec3::new(0.5, 0.5, 0.0));
    assert_eq!((s.camera.fov_y_degrees, s.camera.width, s.camera.height), (45.0, 512, 512));
    assert_eq!(s.warnings.len(), 3);
    assert!(s.warnings[0].starts_with("no perspective camera"), "{:?}", s.warnings);
    assert!(s.warnings[1].starts_with("the scene has no emitters"), "{:?}", s.warnings);
    assert_eq!(s.warnings[2], FRESNEL_WARNING);
    // glTF's default material: white, metallic 1, roughness 1.
    assert_close(&param(&s, "default_material.alpha.value"), &[1.0]);
    assert_close(&param(&s, "default_material.specular_reflectance.value"), &[1.0; 3]);
}

/// Every malformed fixture gives exactly this message.
#[test]
fn malformed_files_give_pinned_messages() {
    let cases: &[(&str, &str)] = &[
        ("bad_json.gltf", "bad_json.gltf:4:3: invalid glTF JSON: trailing comma"),
        ("not_gltf.gltf", "not_gltf.gltf:1:1: invalid glTF JSON: expected value"),
        (
            "missing_buffer.gltf",
            "missing_buffer.gltf: buffers[0]: cannot read 'nowhere.bin': No such file or directory (os error 2)",
        ),
        ("short_buffer.gltf", "short_buffer.gltf: buffers[0]: holds 44 bytes but its byteLength is 100"),
        ("bad_uri.gltf", "bad_uri.gltf: buffers[0]: URI '%FF.bin' is not valid percent-encoded UTF-8"),
        ("empty.glb", "empty.glb: the file is empty (0 bytes)"),
        (
            "bad_magic.glb",
            "bad_magic.glb: not a GLB file: it does not begin with the magic 'glTF' (it begins with 'PK..')",
        ),
        (
            "climbing_uri.gltf",
            "climbing_uri.gltf: buffers[0]: URI '../../../../../../../../etc/passwd' climbs out of the scene's folder: \
             a scene reads only files inside its own folder (tests/data/gltf) unless reading outside is allowed \
             (LoadOptions::allow_outside_folder)",
        ),
        (
            "absolute_uri.gltf",
            "absolute_uri.gltf: buffers[0]: URI '/etc/passwd' is an absolute path: a scene reads only files inside \
             its own folder (tests/data/gltf) unless reading outside is allowed \
             (LoadOptions::allow_outside_folder)",
        ),
        (
            "accessor_overflow.gltf",
            "accessor_overflow.gltf: accessors[0] (POSITION of meshes[0].primitives[0]): 30 elements of 12 bytes from \
             offset 0 (stride 12) do not fit in bufferViews[0], which has 36 bytes",
        ),
        ("index_reference.gltf", "index_reference.gltf: meshes[0].primitives[0].indices: Index out of bounds"),
        ("index_value.gltf", "index_value.gltf: meshes[0].primitives[0]: index 5 is out of range (3 vertices)"),
        (
            "points.gltf",
            "points.gltf: meshes[0].primitives[0]: mode 0 (Points) is not supported (only TRIANGLES, mode 4)",
        ),
        (
            "wrong_type.gltf",
            "wrong_type.gltf: accessors[2] (NORMAL of meshes[0].primitives[0]): expected type VEC3, found VEC2",
        ),
        (
            "cycle.gltf",
            "cycle.gltf: nodes[0]: is reached twice: a node may have only one parent and the hierarchy must not have cycles",
        ),
        ("huge_translation.gltf", "huge_translation.gltf: nodes[0]: transform is not finite"),
        (
            "bad_roughness.gltf",
            "bad_roughness.gltf: materials[0]: metallicFactor 1 and roughnessFactor 1.5 must lie in [0, 1]",
        ),
        ("bad_image.gltf", "bad_image.gltf: images[0]: cannot decode: The image format could not be determined"),
        (
            "required_extension.gltf",
            "required_extension.gltf: extensionsRequired[0] = \"KHR_draco_mesh_compression\": Unsupported extension",
        ),
        ("empty.gltf", "empty.gltf: scene: has no triangles"),
        (
            "short_header.glb",
            "short_header.glb: not a valid GLB file: the header is truncated or its length is below 12",
        ),
        ("truncated.glb", "truncated.glb: not a valid GLB file: could not completely read the object"),
    ];
    for (file, expected) in cases {
        let message = load(&data(file)).expect_err(file).to_string();
        assert_eq!(message, format!("tests/data/gltf/{expected}"), "{file}");
    }
    let missing = load(&data("missing.gltf")).unwrap_err().to_string();
    assert!(missing.starts_with("tests/data/gltf/missing.gltf: No such file"), "{missing}");
}

/// Random byte edits of the showcase never panic.
#[test]
fn mutated_files_never_panic() {
    let mut next = crate::testing::xorshift64(0x2545_f491_4f6c_dd1d);
    let dir = tempfile::tempdir().unwrap();
    for name in ["showcase.gltf", "showcase.glb"] {
        let original = std::fs::read(Path::new("scenes/gltf").join(name)).unwrap();
        for dep in ["showcase.bin", "checker.png"] {
            std::fs::copy(Path::new("scenes/gltf").join(dep), dir.path().join(dep)).unwrap();
        }
        for round in 0..200 {
            let mut bytes = original.clone();
            for _ in 0..1 + round % 3 {
                let at = next() as usize % bytes.len();
                match next() % 4 {
                    0 => bytes[at] = next() as u8,
                    1 => bytes[at] = b"0123456789-.e"[next() as usize % 13],
                    2 => bytes.truncate(at.max(1)),
                    _ => bytes[at] = b'9',
                }
            }
            let path = dir.path().join(name);
            std::fs::write(&path, &bytes).unwrap();
            if let Err(e) = load(&path) {
                assert!(!e.to_string().contains("panicked"), "{name} round {round}: {e}");
            }
        }
    }
}

#[test]
fn srgb_decoding_endpoints() {
    assert_eq!(srgb_to_linear(0.0), 0.0);
    assert!((srgb_to_linear(1.0) - 1.0).abs() < 1e-6);
    assert!((srgb_to_linear(0.5) - 0.214_041).abs() < 1e-5);
}

#[test]
fn an_environment_lights_a_scene_without_emitters() {
    let options = LoadOptions { environment: Some([0.5, 1.0, 2.0]), ..LoadOptions::default() };
    let s = load_with(&data("no_camera.gltf"), &options).unwrap();
    assert_close(&param(&s, "env.radiance.value"), &[0.5, 1.0, 2.0]);
    assert!(!s.warnings.iter().any(|w| w.contains("no emitters")), "{:?}", s.warnings);
    let bad = LoadOptions { environment: Some([f32::NAN, 1.0, 1.0]), ..LoadOptions::default() };
    let e = load_with(&data("no_camera.gltf"), &bad).unwrap_err().to_string();
    assert!(e.contains("LoadOptions::environment") && e.contains("must be finite and ≥ 0"), "{e}");
}

/// An orthographic camera becomes an orthographic lens: the film's half extents are xmag × ymag
/// (its aspect ratio theirs), rays start on the plane znear ahead.
#[test]
fn an_orthographic_camera_maps_to_the_orthographic_lens() {
    let dir = tempfile::tempdir().unwrap();
    let mut doc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string("scenes/twin/twin.gltf").unwrap()).unwrap();
    doc["cameras"] = serde_json::json!([{ "type": "orthographic",
        "orthographic": { "xmag": 3.0, "ymag": 1.5, "znear": 0.25, "zfar": 100.0 } }]);
    std::fs::copy("scenes/twin/twin.bin", dir.path().join("twin.bin")).unwrap();
    let path = dir.path().join("ortho.gltf");
    std::fs::write(&path, doc.to_string()).unwrap();
    let s = load(&path).unwrap();
    assert_eq!((s.camera.width, s.camera.height), (512, 256));
    let crate::scene::Lens::Orthographic { half_height, stretch, near_clip } = s.camera.lens else {
        panic!("{:?}", s.camera.lens)
    };
    assert_eq!((half_height, stretch, near_clip), (1.5, 1.0, 0.25));
    s.validate().unwrap();
}

/// KHR_lights_punctual lights become point, spot and directional lights along their nodes' −z
/// (colour × intensity, one warning about units); KHR_materials_transmission a rough dielectric of
/// the material's ior; KHR_materials_ior the blend's F0.
#[test]
fn punctual_lights_transmission_and_ior() {
    use crate::scene::{LightShape, Material};
    let s = load(Path::new("tests/conformance/scenes/gltf_src/lights.gltf")).unwrap();
    assert_eq!(s.lights.len(), 3);
    assert!(s.warnings.iter().any(|w| w.contains("no 683 lm/W conversion")), "{:?}", s.warnings);
    assert_close(&param(&s, "bulb.intensity.value"), &[6.0, 5.4, 4.8]);
    assert_close(&param(&s, "spot.intensity.value"), &[15.0, 20.0, 25.0]);
    assert_close(&param(&s, "sun.irradiance.value"), &[0.8, 0.76, 0.68]);
    let LightShape::Spot { axis, cutoff, beam_width, .. } = s.lights[1].shape else { panic!("{:?}", s.lights[1]) };
    assert!((cutoff - 0.5f32.to_degrees()).abs() < 1e-4 && (beam_width - 0.25f32.to_degrees()).abs() < 1e-4);
    // The node turns −z 45° down.
    assert!(axis.abs_diff_eq(Vec3::new(0.0, -(0.5f32).sqrt(), -(0.5f32).sqrt()), 1e-5), "{axis}");
    let glass = s.materials.iter().find_map(|m| match m {
        Material::RoughDielectric { eta, .. } => Some(*eta),
        _ => None,
    });
    assert_eq!(glass, Some(1.45));
    assert_close(&param(&s, "glass.specular_transmittance.value"), &[0.9, 0.95, 0.8]);
    // ior 1.7: F0 = (0.7/2.7)².
    assert_close(&param(&s, "plastic.weight.value"), &[(0.7f32 / 2.7).powi(2)]);
    s.validate().unwrap();
}

/// A normal texture wraps the material (inside `doubleSided`'s two-sided wrapper) in a normal map
/// whose stored texels carry the texture's `scale` in x and y; a `TANGENT` attribute is ignored
/// with a warning; two texture-coordinate sets are refused.
#[test]
fn normal_textures_become_normal_maps() {
    let path = Path::new("tests/conformance/scenes/gltf_src/normalmap.gltf");
    let s = load(path).unwrap();
    s.validate().unwrap();
    assert_eq!(s.normal_maps.len(), 2);
    let maps: Vec<_> = s.materials.iter().filter(|m| matches!(m, Material::NormalMap { .. })).collect();
    assert_eq!(maps.len(), 2);
    assert!(
        s.materials.iter().any(
            |m| matches!(m, Material::TwoSided(id) if matches!(s.materials[id.0 as usize], Material::NormalMap { .. }))
        ),
        "bumpy is two-sided around its map"
    );
    // Texel (0, 0) is (0.6, 0.5, 1) normalised, stored as (n + 1)/2 in 8 bits; `bumpy` has scale
    // 0.7 on x and y, `brushed` 1.
    let n = Vec3::new(0.6, 0.5, 1.0).normalize();
    let stored = ((n + Vec3::ONE) * 0.5 * 255.0).round() / 255.0;
    let scaled = |c: f32, k: f32| ((2.0 * c - 1.0) * k + 1.0) * 0.5;
    let (bumpy, brushed) = (&s.normal_maps[0].texels[..3], &s.normal_maps[1].texels[..3]);
    assert_close(bumpy, &[scaled(stored.x, 0.7), scaled(stored.y, 0.7), stored.z]);
    assert_close(brushed, &stored.to_array());
    assert!(!s.warnings.iter().any(|w| w.contains("normalTexture")), "{:?}", s.warnings);

    let mut doc: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let write = |doc: &serde_json::Value| {
        let p = dir.path().join("n.gltf");
        std::fs::write(&p, doc.to_string()).unwrap();
        load(&p)
    };
    // The panel's NORMAL accessor stands in for a TANGENT (glTF's are VEC4; the loader does not
    // read it, so only the warning is checked).
    let normal = doc["meshes"][1]["primitives"][0]["attributes"]["NORMAL"].clone();
    doc["meshes"][1]["primitives"][0]["attributes"]["TANGENT"] = normal;
    let s = write(&doc).unwrap();
    assert!(s.warnings.iter().any(|w| w.contains("TANGENT ignored")), "{:?}", s.warnings);
    doc["materials"][1]["pbrMetallicRoughness"]["baseColorTexture"] = serde_json::json!({"index": 0, "texCoord": 1});
    let e = write(&doc).unwrap_err().to_string();
    assert!(e.contains("normalTexture reads TEXCOORD_0 but baseColorTexture TEXCOORD_1"), "{e}");
}

/// A metallic-roughness texture puts α = max(r², 10⁻³) (r from G times roughnessFactor) on the
/// conductor's roughness per texel and, with metallicFactor > 0, the blend weight
/// w = F0 + (1 − F0)·m (m from B times metallicFactor) and the specular colour
/// s = (m·b + F0·(1 − m))/w per texel, b the base colour there — resampled bilinearly when the
/// two textures differ in size, with a warning; an emissive texture is each emitting mesh's own
/// radiance parameter, sRGB decoded and times emissiveFactor × emissiveStrength.
#[test]
fn metallic_roughness_and_emissive_textures() {
    let s = load(Path::new("tests/conformance/scenes/gltf_src/textures.gltf")).unwrap();
    s.validate().unwrap();
    let stored = |v: u8| f32::from(v) / 255.0;
    // tiles: 8 × 8 textures of one size; texel (x, y) has roughness 0.15 + 0.1·x and metallic
    // 0.9·((x/2 + y/2) mod 2) (make_gltf.py `metal_rough_texture`).
    let alpha = param(&s, "tiles.bsdf_1.alpha.data");
    let weight = param(&s, "tiles.weight.data");
    let specular = param(&s, "tiles.bsdf_1.specular_reflectance.data");
    let base = param(&s, "tiles.base_color.data");
    for (i, (&a, &w)) in alpha.iter().zip(&weight).enumerate() {
        let (x, y) = (i % 8, i / 8);
        let r = stored((255.0 * (0.15 + 0.1 * x as f32)).round() as u8);
        assert!((a - (r * r).max(1e-3)).abs() < 1e-6, "alpha at {i}: {a} vs r = {r}");
        let m = stored((255.0 * 0.9 * ((x / 2 + y / 2) % 2) as f32).round() as u8);
        assert!((w - (0.04 + 0.96 * m)).abs() < 1e-6, "weight at {i}: {w}");
        for c in 0..3 {
            let expect = ((m * base[3 * i + c] + 0.04 * (1.0 - m)) / w).min(1.0);
            assert!((specular[3 * i + c] - expect).abs() < 1e-6, "specular at {i}.{c}");
        }
    }
    // worn: a 4 × 4 metallic-roughness texture over an 8 × 8 base colour: its texel (0, 0) sits
    // at uv (1/8, 1/8), between base texels 0, 1, 8 and 9 with weight 1/4 each.
    assert!(s.warnings.iter().any(|w| w.contains("'worn'") && w.contains("differ in size")), "{:?}", s.warnings);
    let (w, spec, base) = (
        param(&s, "worn.weight.data"),
        param(&s, "worn.bsdf_1.specular_reflectance.data"),
        param(&s, "worn.base_color.data"),
    );
    let m = stored((255.0f32 * 0.1).round() as u8) * 0.8;
    assert!((w[0] - (0.04 + 0.96 * m)).abs() < 1e-6);
    for c in 0..3 {
        let b = [0, 1, 8, 9].iter().map(|t| base[3 * t + c]).sum::<f32>() / 4.0;
        assert!((spec[c] - (m * b + 0.04 * (1.0 - m)) / w[0]).abs() < 1e-5, "worn specular {c}");
    }
    // The transmitting ball's roughness and the matte box's are textures; the box's weight is not.
    assert_eq!(param(&s, "frosted.alpha.data").len(), 16);
    assert_eq!(param(&s, "matte.bsdf_1.alpha.data").len(), 64);
    assert_close(&param(&s, "matte.weight.value"), &[0.04]);
    // The lamp: texel (0, 0) is sRGB (255, 200, 120) × 8.
    let lamp = s.meshes.iter().find(|m| m.name == "lamp").unwrap();
    let radiance = param(&s, "lamp.emitter.radiance.data");
    assert_eq!(lamp.emitter, s.params.find("lamp.emitter.radiance.data"));
    assert!(lamp.emitter_texture.is_some());
    let expect = [255u8, 200, 120].map(|v| srgb_to_linear(stored(v)) * 8.0);
    assert_close(&radiance[..3], &expect);
    assert!(!s.warnings.iter().any(|w| w.contains("ignored")), "{:?}", s.warnings);
}

/// Every texture of a material reads one set of texture coordinates.
#[test]
fn a_metallic_roughness_texture_on_another_uv_set_is_refused() {
    let path = Path::new("tests/conformance/scenes/gltf_src/textures.gltf");
    let mut doc: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    doc["materials"][0]["pbrMetallicRoughness"]["metallicRoughnessTexture"]["texCoord"] = serde_json::json!(1);
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("t.gltf");
    std::fs::write(&p, doc.to_string()).unwrap();
    let e = load(&p).unwrap_err().to_string();
    assert!(e.contains("materials[0]"), "{e}");
    assert!(e.contains("metallicRoughnessTexture reads TEXCOORD_1 but baseColorTexture TEXCOORD_0"), "{e}");
}

//! Scene files against each other: the XML twin of the built-in Cornell box, and one scene written
//! both as Mitsuba XML and as glTF.

use pathgrad::backend::Backend;
use pathgrad::gpu::Renderer;
use pathgrad::integrator::RenderOptions;
use pathgrad::scene;

use crate::support::TestGpu;

fn root(path: &str) -> String {
    format!("{}/{path}", env!("CARGO_MANIFEST_DIR"))
}

/// The XML twin builds the same triangles, materials, light and camera, so for the same seed the
/// image is the same, bit for bit.
#[test]
fn builtin_cornell_box_and_its_xml_twin_render_identically() {
    let gpu = TestGpu::new();
    let builtin = scene::builtin::load("cornell-box").unwrap();
    let xml = scene::load(&root("scenes/cornell-box/cornell-box.xml"), &[]).unwrap();
    let opts = RenderOptions { width: 64, height: 64, spp: 4, seed: 3, ..RenderOptions::for_scene(&builtin) };
    let a = Renderer::new(&gpu.ctx, &builtin).unwrap().render(&opts).unwrap();
    let b = Renderer::new(&gpu.ctx, &xml).unwrap().render(&opts).unwrap();
    assert_eq!(a.as_slice(), b.as_slice());
}

/// `scenes/twin/twin.xml` and `twin.gltf` describe the same scene; their triangles are built in a
/// different order and by different arithmetic (Mitsuba transforms vs glTF node matrices), so the
/// comparison is per path (one sample per pixel) with the tolerance and mismatch budget of the
/// GPU-vs-CPU test: 1e-4 relative (a few ulp of vertex positions, amplified along the path), and
/// 1e-3 of the paths allowed to take a different decision at a threshold.
#[test]
fn the_same_scene_as_xml_and_gltf_renders_the_same() {
    let gpu = TestGpu::new();
    let xml = scene::load(&root("scenes/twin/twin.xml"), &[]).unwrap();
    let gltf = scene::load(&root("scenes/twin/twin.gltf"), &[]).unwrap();
    let opts = RenderOptions { width: 96, height: 96, spp: 1, seed: 8, ..RenderOptions::for_scene(&xml) };
    let a = Renderer::new(&gpu.ctx, &xml).unwrap().render(&opts).unwrap();
    let b = Renderer::new(&gpu.ctx, &gltf).unwrap().render(&opts).unwrap();
    let mismatched = a
        .as_slice()
        .chunks(3)
        .zip(b.as_slice().chunks(3))
        .filter(|(x, y)| x.iter().zip(*y).any(|(p, q)| (p - q).abs() > 1e-4 * p.abs().max(q.abs()) + 1e-6))
        .count();
    println!("{mismatched} of {} paths differ", 96 * 96);
    assert!(mismatched as f64 <= 1e-3 * 96.0 * 96.0, "{mismatched} paths differ");
}

/// `-D name=value` overrides an XML `<default>`.
#[test]
fn defines_override_xml_defaults() {
    let path = root("scenes/blend/blend.xml");
    let plain = scene::load(&path, &[]).unwrap();
    let changed = scene::load(&path, &[("weight".into(), "0.25".into()), ("spp".into(), "7".into())]).unwrap();
    assert_eq!(plain.params.get(plain.params.find("object.weight.value").unwrap()), &[0.5]);
    assert_eq!(changed.params.get(changed.params.find("object.weight.value").unwrap()), &[0.25]);
    assert_eq!(changed.default_spp, Some(7));
}

/// A Mitsuba `<sensor>` with its own film and sampler.
fn xml_sensor(id: Option<&str>, origin: &str, size: (u32, u32), spp: u32) -> String {
    let id = id.map(|i| format!(r#" id="{i}""#)).unwrap_or_default();
    format!(
        r#"<sensor type="perspective"{id}><float name="fov" value="40"/><transform name="to_world"><lookat origin="{origin}" target="0, 0, 0" up="0, 1, 0"/></transform><sampler type="independent"><integer name="sample_count" value="{spp}"/></sampler><film type="hdrfilm"><integer name="width" value="{}"/><integer name="height" value="{}"/></film></sensor>"#,
        size.0, size.1
    )
}

fn xml_scene(dir: &std::path::Path, name: &str, sensors: &[String]) -> String {
    let path = dir.join(name);
    let text = format!(
        r#"<scene version="3.0.0">{}<shape type="cube"><bsdf type="diffuse"/></shape><shape type="rectangle"><emitter type="area"><rgb name="radiance" value="1, 1, 1"/></emitter><transform name="to_world"><translate z="3"/></transform></shape></scene>"#,
        sensors.concat()
    );
    std::fs::write(&path, text).unwrap();
    path.to_str().unwrap().to_string()
}

fn load(spec: &str, sensor: Option<&str>) -> pathgrad::Result<pathgrad::Scene> {
    scene::load_with(spec, &scene::LoadOptions { sensor: sensor.map(String::from), ..Default::default() })
}

/// A Mitsuba scene with several sensors loads all of them, each the camera (film size and sample
/// count included) that a file holding it alone gives; `LoadOptions::sensor` picks the one
/// rendered by name or index, the first by default, and an unknown one is refused with the list.
#[test]
fn several_xml_sensors_load_and_one_is_chosen() {
    let dir = tempfile::tempdir().unwrap();
    let front = xml_sensor(Some("front"), "0, 0, 5", (64, 48), 7);
    let side = xml_sensor(Some("side"), "4, 1, 3", (32, 40), 3);
    let unnamed = xml_sensor(None, "0, 4, 4", (16, 16), 2);
    let all = xml_scene(dir.path(), "all.xml", &[front.clone(), side.clone(), unnamed.clone()]);
    let alone = |name: &str, s: &String| load(&xml_scene(dir.path(), name, std::slice::from_ref(s)), None).unwrap();
    let (front_alone, side_alone, unnamed_alone) =
        (alone("front.xml", &front), alone("side.xml", &side), alone("unnamed.xml", &unnamed));

    let first = load(&all, None).unwrap();
    let names: Vec<&str> = first.sensors.iter().map(|s| s.name.as_str()).collect();
    assert_eq!(names, ["front", "side", "sensor_2"]);
    assert_eq!(first.camera, front_alone.camera);
    assert_eq!(first.default_spp, Some(7));
    for selector in ["side", "1"] {
        let s = load(&all, Some(selector)).unwrap();
        assert_eq!(s.camera, side_alone.camera, "{selector}");
        assert_eq!((s.camera.width, s.camera.height), (32, 40));
        assert_eq!(s.default_spp, Some(3));
        assert_eq!(s.meshes, first.meshes, "the geometry does not depend on the sensor");
    }
    assert_eq!(load(&all, Some("sensor_2")).unwrap().camera, unnamed_alone.camera);
    let e = load(&all, Some("top")).unwrap_err().to_string();
    assert!(e.contains("no sensor 'top'") && e.contains("0: front, 1: side, 2: sensor_2"), "{e}");
    let e = load(&all, Some("3")).unwrap_err().to_string();
    assert!(e.contains("no sensor '3'"), "{e}");
    // An unnamed second sensor would be `sensor_1`, which the first already is.
    let clash = xml_scene(dir.path(), "clash.xml", &[xml_sensor(Some("sensor_1"), "0, 0, 5", (8, 8), 1), unnamed]);
    let e = load(&clash, None).unwrap_err().to_string();
    assert!(e.contains("a second sensor named 'sensor_1'"), "{e}");
}

/// A glTF file with several cameras loads each under its node's name, in node order, with the
/// pose of its node (looking down the node's −z); the first is the default.
#[test]
fn several_gltf_cameras_load_and_one_is_chosen() {
    let dir = tempfile::tempdir().unwrap();
    let positions: [f32; 9] = [-1.0, -1.0, 0.0, 1.0, -1.0, 0.0, 0.0, 1.0, 0.0];
    std::fs::write(dir.path().join("tri.bin"), bytemuck::cast_slice::<f32, u8>(&positions)).unwrap();
    let doc = serde_json::json!({
        "asset": {"version": "2.0"},
        "buffers": [{"uri": "tri.bin", "byteLength": 36}],
        "bufferViews": [{"buffer": 0, "byteLength": 36}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                       "min": [-1.0, -1.0, 0.0], "max": [1.0, 1.0, 0.0]}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
        "cameras": [{"type": "perspective", "perspective": {"yfov": 0.7, "znear": 0.1, "aspectRatio": 2.0}},
                    {"type": "perspective", "perspective": {"yfov": 0.5, "znear": 0.1}}],
        "nodes": [{"mesh": 0, "name": "triangle"},
                  {"camera": 0, "name": "near", "translation": [0.0, 0.0, 3.0]},
                  {"camera": 1, "name": "far", "translation": [1.0, 2.0, 9.0]}],
        "scenes": [{"nodes": [0, 1, 2]}],
        "scene": 0
    });
    let path = dir.path().join("two.gltf");
    std::fs::write(&path, serde_json::to_string(&doc).unwrap()).unwrap();
    let spec = path.to_str().unwrap();
    let first = load(spec, None).unwrap();
    let names: Vec<&str> = first.sensors.iter().map(|s| s.name.as_str()).collect();
    assert_eq!(names, ["near", "far"]);
    assert_eq!(first.camera, first.sensors[0].camera);
    let far = load(spec, Some("far")).unwrap().camera;
    assert_eq!(far.position, glam::Vec3::new(1.0, 2.0, 9.0));
    assert_eq!(far.target, glam::Vec3::new(1.0, 2.0, 8.0));
    assert!((far.fov_y_degrees - 0.5f32.to_degrees()).abs() < 1e-5);
    assert_eq!(
        (first.camera.position, first.camera.width, first.camera.height),
        (glam::Vec3::new(0.0, 0.0, 3.0), 512, 256)
    );
    assert_eq!(load(spec, Some("1")).unwrap().camera, far);
}

/// `--sensor` renders the chosen sensor at its film's size, and `params --json` lists the sensors.
#[test]
fn the_cli_renders_the_chosen_sensor_and_lists_them() {
    let dir = tempfile::tempdir().unwrap();
    let spec = xml_scene(
        dir.path(),
        "all.xml",
        &[xml_sensor(Some("front"), "0, 0, 5", (24, 16), 1), xml_sensor(Some("side"), "4, 1, 3", (12, 20), 1)],
    );
    let out = dir.path().join("side.exr");
    let o = crate::cli::pathgrad().args(["render", &spec, "--sensor", "side", "-o"]).arg(&out).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let image = pathgrad::Image::read_exr(&out).unwrap();
    assert_eq!((image.width(), image.height()), (12, 20));
    let o = crate::cli::pathgrad().args(["render", &spec, "--sensor", "back", "-o"]).arg(&out).output().unwrap();
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("no sensor 'back': the scene has 2 sensors (0: front, 1: side)")
    );
    let o = crate::cli::pathgrad().args(["params", &spec, "--json"]).output().unwrap();
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let sensors = v["sensors"].as_array().unwrap();
    assert_eq!(sensors.len(), 2);
    assert_eq!((sensors[1]["name"].as_str(), sensors[1]["width"].as_u64()), (Some("side"), Some(12)));
    assert!(v["params"].as_array().is_some_and(|p| !p.is_empty()));
}

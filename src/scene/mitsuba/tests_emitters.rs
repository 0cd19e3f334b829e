//! Emitters outside shapes as Mitsuba 3.9.1 reads them: `envmap` (its image formats, `scale`,
//! `to_world`, its parameter) and what it refuses.

use std::path::Path;

use glam::{Mat3, Vec3};

use super::tests::SENSOR;
use crate::scene::{LoadOptions, Scene};

const SHAPE: &str = r#"<shape type="cube"/>"#;

/// Loads `main.xml` in `dir` holding `body` after a sensor, with `options`.
fn load(dir: &Path, body: &str, options: &LoadOptions) -> crate::Result<Scene> {
    let path = dir.join("main.xml");
    std::fs::write(&path, format!(r#"<scene version="3.0.0">{SENSOR}{body}{SHAPE}</scene>"#)).unwrap();
    super::load_with(&path, options)
}

fn err(dir: &Path, body: &str) -> String {
    match load(dir, body, &LoadOptions::default()) {
        Ok(_) => panic!("{body} loaded"),
        Err(e) => e.to_string(),
    }
}

/// A 4 × 3 Radiance HDR image whose texel (i, j) is (i, j, 0.5) + 1.
fn write_hdr(path: &Path) -> Vec<f32> {
    let texels: Vec<f32> =
        (0..3).flat_map(|j| (0..4).flat_map(move |i| [1.0 + i as f32, 1.0 + j as f32, 1.5])).collect();
    let pixels: Vec<image::Rgb<f32>> = texels.chunks(3).map(|c| image::Rgb([c[0], c[1], c[2]])).collect();
    let file = std::fs::File::create(path).unwrap();
    image::codecs::hdr::HdrEncoder::new(file).encode(&pixels, 4, 3).unwrap();
    texels
}

#[test]
fn an_envmap_is_its_texels_under_scale_and_a_rotation() {
    let dir = tempfile::tempdir().unwrap();
    let texels = write_hdr(&dir.path().join("sky.hdr"));
    let body = r#"<emitter type="envmap" id="sky"><string name="filename" value="sky.hdr"/>
        <float name="scale" value="2"/><transform name="to_world"><rotate y="1" angle="90"/></transform></emitter>"#;
    let scene = load(dir.path(), body, &LoadOptions::default()).unwrap();
    let id = scene.params.find("sky.data").unwrap();
    assert_eq!(scene.environment, Some(id));
    // HDR is linear: the values come back as written (RGBE keeps these small integers exactly).
    assert_eq!(scene.params.get(id), texels);
    let map = scene.env_map.unwrap();
    assert_eq!((map.width, map.height, map.scale), (4, 3, 2.0));
    let expected = Mat3::from_rotation_y(90f32.to_radians()).transpose();
    assert!(map.to_local.abs_diff_eq(expected, 1e-6), "{:?}", map.to_local);
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
}

#[test]
fn an_envmap_png_is_srgb_decoded() {
    let dir = tempfile::tempdir().unwrap();
    image::RgbImage::from_pixel(2, 2, image::Rgb([255, 128, 0])).save(dir.path().join("sky.png")).unwrap();
    let body = r#"<emitter type="envmap"><string name="filename" value="sky.png"/></emitter>"#;
    let scene = load(dir.path(), body, &LoadOptions::default()).unwrap();
    let values = scene.params.get(scene.environment.unwrap());
    let srgb = |c: f32| crate::scene::gltf::srgb_to_linear(c / 255.0);
    assert_eq!(&values[..3], &[1.0, srgb(128.0), 0.0]);
    assert!(Vec3::from_slice(&values[..3]).x > 0.99);
}

#[test]
fn bad_envmaps_are_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    write_hdr(&dir.path().join("sky.hdr"));
    image::RgbImage::from_pixel(4, 1, image::Rgb([9, 9, 9])).save(dir.path().join("row.png")).unwrap();
    let file = r#"<string name="filename" value="sky.hdr"/>"#;
    let cases = [
        (r#"<emitter type="envmap"/>"#.to_string(), "'envmap' needs the property 'filename'"),
        (
            format!(
                r#"<emitter type="envmap">{file}<transform name="to_world"><scale value="2"/></transform></emitter>"#
            ),
            "an envmap's 'to_world' must be a rotation (no scale, shear or mirroring)",
        ),
        (
            r#"<emitter type="envmap"><string name="filename" value="row.png"/></emitter>"#.into(),
            "an environment map needs at least 2 rows, it has 1",
        ),
        (
            r#"<emitter type="envmap"><string name="filename" value="none.exr"/></emitter>"#.into(),
            "image file 'none.exr' not found",
        ),
        (
            format!(r#"<emitter type="envmap">{file}</emitter><emitter type="constant"/>"#),
            "a scene has at most one environment emitter (constant or envmap)",
        ),
        (
            format!(r#"<emitter type="envmap">{file}<float name="scale" value="-1"/></emitter>"#),
            "'scale' must lie in [0, ∞), got -1",
        ),
    ];
    for (body, expected) in cases {
        let e = err(dir.path(), &body);
        assert!(e.contains(expected), "{body}: {e}");
    }
    // A constant radiance from the load options does not replace a map.
    let options = LoadOptions { environment: Some([1.0, 1.0, 1.0]), ..LoadOptions::default() };
    let e = load(dir.path(), &format!(r#"<emitter type="envmap" id="sky">{file}</emitter>"#), &options).unwrap_err();
    assert!(e.to_string().contains("the scene's own environment 'sky.data' is a map (envmap)"), "{e}");
}

#[test]
fn point_spot_and_directional_lights_take_mitsubas_properties() {
    use crate::scene::LightShape;
    let dir = tempfile::tempdir().unwrap();
    let body = r#"<emitter type="point" id="bulb"><point name="position" value="1, 2, 3"/><rgb name="intensity" value="4, 5, 6"/></emitter>
        <emitter type="point" id="moved"><transform name="to_world"><translate x="-1"/></transform></emitter>
        <emitter type="spot" id="lamp"><transform name="to_world"><lookat origin="0, 3, 0" target="0, 0, 0" up="0, 0, 1"/></transform>
            <float name="cutoff_angle" value="40"/></emitter>
        <emitter type="directional" id="sun"><vector name="direction" value="0, -2, 0"/></emitter>"#;
    let scene = load(dir.path(), body, &LoadOptions::default()).unwrap();
    assert_eq!(scene.lights.len(), 4);
    assert_eq!(scene.lights[0].shape, LightShape::Point { position: Vec3::new(1.0, 2.0, 3.0) });
    assert_eq!(scene.params.get(scene.params.find("bulb.intensity.value").unwrap()), [4.0, 5.0, 6.0]);
    assert_eq!(scene.lights[1].shape, LightShape::Point { position: Vec3::new(-1.0, 0.0, 0.0) });
    let LightShape::Spot { position, axis, cutoff, beam_width, .. } = scene.lights[2].shape else { panic!() };
    assert!(position.abs_diff_eq(Vec3::new(0.0, 3.0, 0.0), 1e-6) && axis.abs_diff_eq(-Vec3::Y, 1e-6));
    assert_eq!((cutoff, beam_width), (40.0, 30.0));
    assert_eq!(scene.lights[3].shape, LightShape::Directional { direction: -Vec3::Y });
    // Intensity 1 by default, as Mitsuba.
    assert_eq!(scene.params.get(scene.params.find("sun.irradiance.value").unwrap()), [1.0, 1.0, 1.0]);
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
}

#[test]
fn bad_lights_are_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let cases = [
        (
            r#"<emitter type="point"><point name="position" value="0, 1, 0"/><transform name="to_world"><translate x="1"/></transform></emitter>"#,
            "only one of 'position' and 'to_world' may be given to 'point'",
        ),
        (
            r#"<emitter type="spot"><float name="cutoff_angle" value="10"/><float name="beam_width" value="20"/></emitter>"#,
            "'spot' needs 0 < beam_width ≤ cutoff_angle, got 20 and 10",
        ),
        (
            r#"<emitter type="spot"><float name="cutoff_angle" value="120"/></emitter>"#,
            "'cutoff_angle' must lie in [0, 90], got 120",
        ),
        (
            r#"<emitter type="directional"><vector name="direction" value="0, 0, 0"/></emitter>"#,
            "'direction' must not be zero",
        ),
        (
            r#"<emitter type="point"><texture name="texture" type="bitmap"/></emitter>"#,
            "a textured 'point' is not supported",
        ),
        (
            r#"<emitter type="spot"><texture name="texture" type="checkerboard"/></emitter>"#,
            "the texture of a 'spot' must be a 'bitmap' (pathgrad reads no other here), got 'checkerboard'",
        ),
        (
            r#"<emitter type="projector"><texture name="irradiance" type="checkerboard"/></emitter>"#,
            "the texture of a 'projector' must be a 'bitmap' (pathgrad reads no other here), got 'checkerboard'",
        ),
        (
            r#"<emitter type="spot"><texture name="texture" type="bitmap"><string name="filename" value="sky.hdr"/>
                <transform name="to_uv"><scale x="2"/></transform></texture></emitter>"#,
            "'to_uv' of the texture of a 'spot' is not supported",
        ),
        (
            r#"<emitter type="projector"><texture name="irradiance" type="bitmap"><string name="filename" value="no.png"/></texture></emitter>"#,
            "image file 'no.png' not found",
        ),
        (
            r#"<emitter type="projector"><float name="fov" value="180"/></emitter>"#,
            "'fov' must lie in (0, 180) degrees, got 180",
        ),
        (r#"<emitter type="projector"><float name="scale" value="-1"/></emitter>"#, "'scale' must lie in [0, "),
        (
            r#"<emitter type="sunsky"/>"#,
            "unsupported plugin 'sunsky' (supported: constant, directional, envmap, point, projector, spot;",
        ),
    ];
    write_hdr(&dir.path().join("sky.hdr"));
    for (body, expected) in cases {
        let e = err(dir.path(), body);
        assert!(e.contains(expected), "{body}: {e}");
    }
}

#[test]
fn an_environment_map_from_the_load_options_lights_a_scene_without_one() {
    let dir = tempfile::tempdir().unwrap();
    let texels = write_hdr(&dir.path().join("sky.hdr"));
    let map = Some(dir.path().join("sky.hdr"));
    let options = LoadOptions { environment_map: map.clone(), ..LoadOptions::default() };
    let scene = load(dir.path(), "", &options).unwrap();
    let id = scene.params.find("env.data").unwrap();
    assert_eq!((scene.environment, scene.params.get(id)), (Some(id), &texels[..]));
    assert_eq!(scene.env_map.map(|m| (m.width, m.height, m.scale)), Some((4, 3, 1.0)));
    // Not with a constant too, nor over a scene's own environment.
    let both = LoadOptions { environment: Some([1.0; 3]), ..options.clone() };
    let e = load(dir.path(), "", &both).unwrap_err().to_string();
    assert!(e.contains("give a constant environment or a map, not both"), "{e}");
    let e = load(dir.path(), r#"<emitter type="constant" id="sky"/>"#, &options).unwrap_err().to_string();
    assert!(e.contains("the scene has an environment of its own ('sky.radiance.value')"), "{e}");
}

/// A textured spot and a projector (constant or textured): their parameters under Mitsuba's
/// `traverse` names and the frustum of the lookup.
#[test]
fn textured_spots_and_projectors_take_mitsubas_properties() {
    use crate::scene::LightShape;
    let dir = tempfile::tempdir().unwrap();
    let texels = write_hdr(&dir.path().join("sky.hdr"));
    let look = r#"<transform name="to_world"><lookat origin="0, 3, 0" target="0, 0, 0" up="0, 0, 1"/></transform>"#;
    let body = format!(
        r#"<emitter type="spot" id="lamp">{look}<float name="cutoff_angle" value="30"/>
            <texture name="texture" type="bitmap"><string name="filename" value="sky.hdr"/></texture></emitter>
        <emitter type="projector" id="flat">{look}<rgb name="irradiance" value="1, 2, 3"/><float name="fov" value="90"/></emitter>
        <emitter type="projector" id="slide">{look}<float name="scale" value="2.5"/><float name="fov" value="60"/>
            <texture name="irradiance" type="bitmap"><string name="filename" value="sky.hdr"/>
            <string name="filter_type" value="nearest"/></texture></emitter>"#
    );
    let scene = load(dir.path(), &body, &LoadOptions::default()).unwrap();
    let param = |name: &str| scene.params.get(scene.params.find(name).unwrap_or_else(|| panic!("{name}"))).to_vec();
    assert_eq!(param("lamp.intensity.value"), [1.0; 3]);
    assert_eq!(param("lamp.texture.data"), texels);
    assert_eq!(param("flat.irradiance.value"), [1.0, 2.0, 3.0]);
    assert_eq!(param("flat.scale"), [1.0]);
    assert_eq!(param("slide.irradiance.data"), texels);
    assert_eq!(param("slide.scale"), [2.5]);
    let LightShape::Spot { to_local, .. } = scene.lights[0].shape else { panic!("{:?}", scene.lights[0]) };
    // The spot's local +z is its axis, −y.
    assert!((to_local * -Vec3::Y).abs_diff_eq(Vec3::Z, 1e-6), "{to_local}");
    assert!(scene.lights[0].texture.is_some() && scene.lights[1].texture.is_none());
    assert!(scene.lights[2].intensity.is_none() && scene.textures[scene.lights[2].texture.unwrap().0 as usize].nearest);
    // A constant's aspect is 1: cot(45°) = 1 on both axes. The 4 × 3 slide's fov is along x.
    let LightShape::Projector { uv_scale, normal, position, .. } = scene.lights[1].shape else { panic!() };
    assert!(uv_scale.abs_diff_eq(glam::Vec2::new(-0.5, -0.5), 1e-6), "{uv_scale}");
    assert!(normal.abs_diff_eq(-Vec3::Y, 1e-6) && position.abs_diff_eq(Vec3::new(0.0, 3.0, 0.0), 1e-6));
    let LightShape::Projector { uv_scale, .. } = scene.lights[2].shape else { panic!() };
    let cot = 1.0 / 30f32.to_radians().tan();
    assert!(uv_scale.abs_diff_eq(glam::Vec2::new(-0.5 * cot, -0.5 * cot * 4.0 / 3.0), 1e-5), "{uv_scale}");
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
}

/// A BMP (Mitsuba's `flower.bmp` of `emitter_projector_textured.xml`) is decoded as sRGB like a PNG.
#[test]
fn a_bmp_texture_is_srgb_decoded() {
    let dir = tempfile::tempdir().unwrap();
    let pixels: [u8; 6] = [255, 0, 128, 64, 32, 0];
    let file = std::fs::File::create(dir.path().join("slide.bmp")).unwrap();
    let mut writer = std::io::BufWriter::new(file);
    image::codecs::bmp::BmpEncoder::new(&mut writer).encode(&pixels, 2, 1, image::ExtendedColorType::Rgb8).unwrap();
    drop(writer);
    let body = r#"<emitter type="projector" id="p"><texture name="irradiance" type="bitmap">
        <string name="filename" value="slide.bmp"/></texture></emitter>"#;
    let scene = load(dir.path(), body, &LoadOptions::default()).unwrap();
    let texels = scene.params.get(scene.params.find("p.irradiance.data").unwrap()).to_vec();
    let expected: Vec<f32> = pixels.iter().map(|&v| crate::scene::gltf::srgb_to_linear(f32::from(v) / 255.0)).collect();
    assert_eq!(texels.len(), 6);
    for (a, b) in texels.iter().zip(&expected) {
        assert!((a - b).abs() < 1e-6, "{texels:?} vs {expected:?}");
    }
}

/// An area emitter whose radiance is a bitmap (issue 31): its texels are the parameter
/// `SHAPE.emitter.radiance.data` (Mitsuba's key), and its triangles point the kernels at the
/// texture's descriptor.
#[test]
fn issue_31_a_textured_area_emitter_reads_its_bitmap() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/conformance/scenes/emitter_area_texture.xml");
    let s = crate::scene::load_with(path.to_str().unwrap(), &LoadOptions::default()).unwrap_or_else(|e| panic!("{e}"));
    let texels = s.params.find("panel.emitter.radiance.data").expect("the texels' parameter");
    assert_eq!(s.params.entry(texels).len, 8 * 8 * 3);
    let panel = s.meshes.iter().find(|m| m.name == "panel").unwrap();
    assert_eq!(panel.emitter, Some(texels));
    assert!(panel.emitter_texture.is_some());
    let flat = crate::scene::flat::FlatScene::new(&s).unwrap();
    assert!(!flat.emitters.is_empty());
    for e in &flat.emitters {
        assert!(crate::cpu::emitter::area_textured(e.p_radiance));
        let d = (e.p_radiance & !crate::contract::SCALAR_TEXTURE) as usize;
        assert_eq!(flat.tables[d].to_bits(), s.params.entry(texels).offset);
    }
}

/// Only the kernels of a scene with a textured area emitter carry the emitters' texture lookup
/// (issue 38): the feature bit `F2_AREA_TEXTURE` is set for the bitmap-lit panel and clear for
/// the sphere, whose area emitter has a plain RGB radiance.
#[test]
fn issue_38_only_a_textured_area_emitter_sets_its_feature_bit() {
    let area_texture = crate::gpu::variant::word2(crate::contract::F2_AREA_TEXTURE);
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    for (file, textured) in
        [("tests/conformance/scenes/emitter_area_texture.xml", true), ("benches/scenes/sphere/sphere.xml", false)]
    {
        let path = root.join(file);
        let s =
            crate::scene::load_with(path.to_str().unwrap(), &LoadOptions::default()).unwrap_or_else(|e| panic!("{e}"));
        let flat = crate::scene::flat::FlatScene::new(&s).unwrap();
        let features = crate::gpu::variant::scene_features(&flat, crate::contract::NO_PARAM);
        assert_ne!(features & u64::from(crate::contract::F_EMITTERS), 0, "{file}");
        assert_eq!(features & area_texture != 0, textured, "{file}");
    }
}

/// An area emitter's bitmap radiance under `to_uv` and a checkerboard radiance (issue 31): the
/// parameters take Mitsuba's keys, the descriptors carry `to_uv`'s rows (and `TEX_CHECKER`), and
/// the CPU lookup reads the colour Mitsuba's checkerboard shows there.
#[test]
fn issue_31_area_radiance_takes_to_uv_and_a_checkerboard() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/conformance/scenes/emitter_area_texture_uv.xml");
    let s = crate::scene::load_with(path.to_str().unwrap(), &LoadOptions::default()).unwrap_or_else(|e| panic!("{e}"));
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
    let texels = s.params.find("panel.emitter.radiance.data").expect("the panel's texels");
    assert_eq!(s.params.entry(texels).len, 6 * 4 * 3);
    let color0 = s.params.find("strip.emitter.radiance.color0.value").expect("color0");
    let color1 = s.params.find("strip.emitter.radiance.color1.value").expect("color1");
    assert_eq!(s.params.get(color0), &[0.9, 0.6, 0.3]);
    assert_eq!(s.params.entry(color1).offset, s.params.entry(color0).offset + 3);
    let mesh = |name: &str| s.meshes.iter().find(|m| m.name == name).unwrap();
    let Some(crate::scene::Albedo::Bitmap(t)) = mesh("panel").emitter_texture else { panic!("a bitmap radiance") };
    let t = &s.textures[t.0 as usize];
    assert!(t.nearest);
    assert_eq!(t.to_uv, [Vec3::new(1.5, 0.0, 0.25), Vec3::new(0.0, 2.0, 0.1)]);
    assert_eq!(mesh("strip").emitter, Some(color0));
    assert!(
        matches!(mesh("strip").emitter_texture, Some(crate::scene::Albedo::Checker { colors, .. }) if colors == color0)
    );

    let flat = crate::scene::flat::FlatScene::new(&s).unwrap();
    let (offset0, offset_texels) = (s.params.entry(color0).offset, s.params.entry(texels).offset);
    let mut seen = [false; 2];
    for e in &flat.emitters {
        assert!(crate::cpu::emitter::area_textured(e.p_radiance));
        let d = (e.p_radiance & !crate::contract::SCALAR_TEXTURE) as usize;
        let word = |i: usize| flat.tables[d + i].to_bits();
        if word(0) == offset0 {
            seen[0] = true;
            assert_eq!((word(1), word(2), word(3)), (2, 1, crate::contract::TEX_CHECKER));
            // uv (0.05, 0.05) maps to (0.154, 0.162): color0; (0.2, 0.05) to (0.717, 0.367): color1.
            let at = |u: f32, v: f32| crate::cpu::emitter::area_radiance(&flat, e.p_radiance, glam::Vec2::new(u, v));
            assert!((at(0.05, 0.05) - Vec3::new(0.9, 0.6, 0.3)).abs().max_element() < 1e-6);
            assert!((at(0.2, 0.05) - Vec3::new(0.2, 0.4, 0.8)).abs().max_element() < 1e-6);
        } else {
            seen[1] = true;
            assert_eq!((word(0), word(1), word(2)), (offset_texels, 6, 4));
            let row0 = [4, 5, 6].map(|i| flat.tables[d + i]);
            assert_eq!(row0, [1.5, 0.0, 0.25]);
        }
    }
    assert_eq!(seen, [true, true]);
}

//! Every loader error with its exact message, the malformed fixtures under `tests/data/xml/`, and
//! inputs built to break the parser (truncations, mutations, deep nesting) that must fail cleanly.

use std::path::Path;

use super::loader::{load_path, load_text};
use super::tests::{SENSOR, load, obj_for_tests, wrap};
use crate::scene::LoadOptions;

/// The message of the error `body` (inside a scene with a sensor, file `test.xml`) gives.
fn err(body: &str) -> String {
    match load(body) {
        Ok(_) => panic!("{body} loaded"),
        Err(e) => e.to_string(),
    }
}

/// The message of the error a whole document gives.
fn doc_err(text: &str) -> String {
    match load_text(text, Path::new("doc.xml"), &[], obj_for_tests) {
        Ok(_) => panic!("{text} loaded"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn fixtures_give_their_pinned_messages() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/xml");
    let d = dir.display().to_string();
    let cases: &[(&str, String)] = &[
        (
            "unsupported_plugin.xml",
            "5:5: <bsdf id=\"shiny\">: unsupported plugin 'pplastic' (supported: blendbsdf, bumpmap, conductor, dielectric, \
             diffuse, mask, normalmap, null, plastic, principled, principledthin, roughconductor, roughdielectric, roughplastic, thindielectric, twosided)"
                .into(),
        ),
        ("bad_rgb.xml", "7:13: <rgb name=\"reflectance\">: value: expected a number, got 'x'".into()),
        (
            "spot_texture_checkerboard.xml",
            "6:9: <texture name=\"texture\">: the texture of a 'spot' must be a 'bitmap' (pathgrad reads no other \
             here), got 'checkerboard'"
                .into(),
        ),
        (
            "projector_missing_image.xml",
            format!(
                "7:13: <string name=\"filename\">: image file 'textures/missing.png' not found (looked for \
                 {d}/textures/missing.png)"
            ),
        ),
        (
            "missing_mesh.xml",
            format!(
                "6:9: <string name=\"filename\">: mesh file 'meshes/missing.obj' not found (looked for {d}/meshes/missing.obj)"
            ),
        ),
        ("unknown_ref.xml", "6:9: <ref id=\"nope\">: reference to unknown id 'nope'".into()),
        ("nan_value.xml", "7:13: <float name=\"alpha\">: value: 'nan' is not a finite number".into()),
        ("no_shapes.xml", "1:1: <scene>: the scene has no shapes".into()),
        ("bad_version.xml", "1:1: <scene>: unsupported scene version '0.6.0' (pathgrad reads 2.x and 3.x)".into()),
        ("unclosed_tag.xml", "7:1: malformed XML: expected 'shape' tag, not 'scene'".into()),
        ("not_xml.xml", "1:1: malformed XML: unknown token".into()),
        (
            "negative_value.xml",
            "7:13: <rgb name=\"reflectance\">: 'reflectance' must lie in [0, 1], got [-0.5, -0.5, -0.5]".into(),
        ),
        ("zero_area_emitter.xml", "9:9: <emitter>: area emitter on shape '_unnamed_0' of zero area".into()),
        ("singular_transform.xml", "6:9: <transform name=\"to_world\">: to_world is singular (it flattens the shape)".into()),
        (
            "no_sensor.xml",
            "1:1: <scene>: the scene has no <sensor>; pathgrad needs one (perspective, thinlens or orthographic: it has no default camera)".into(),
        ),
        (
            "undefined_parameter.xml",
            "6:9: <float name=\"radius\">: undefined parameter '$radius' in attribute 'value' (define it with \
             <default name=\"radius\" value=\"…\"/> or -D radius=VALUE)"
                .into(),
        ),
        ("ref_cycle.xml", "8:9: <ref id=\"loop\">: reference cycle: this BSDF contains itself".into()),
        (
            "outside_filename.xml",
            format!(
                "6:9: <string name=\"filename\">: '../mesh/quad.obj' climbs out of the scene's folder: a scene reads \
                 only files inside its own folder ({d}) unless reading outside is allowed \
                 (LoadOptions::allow_outside_folder)"
            ),
        ),
        (
            "overflow_emitter.xml",
            "9:9: <emitter>: area emitter on shape '_unnamed_0' whose area overflows 32-bit floats (coordinates too \
             large)"
                .into(),
        ),
        (
            "bad_spectrum.xml",
            "7:13: <spectrum name=\"reflectance\">: wavelengths must increase (400 nm after 700 nm)"
                .into(),
        ),
        (
            "mirrored_camera.xml",
            "3:9: <transform name=\"to_world\">: the sensor's to_world mirrors the image (negative determinant); \
             pathgrad's camera cannot render mirrored images"
                .into(),
        ),
        ("duplicate_id.xml", format!("6:5: <shape id=\"a\">: duplicate id 'a' (first used at {d}/duplicate_id.xml:5:5)")),
        (
            "unsupported_element.xml",
            "5:5: <mesh id=\"fog\">: unsupported element <mesh> (supported in <scene>: default, path, include, bsdf, \
             texture, shape, emitter, medium, volume, phase, sensor, integrator)"
                .into(),
        ),
    ];
    for (file, tail) in cases {
        let path = dir.join(file);
        let e = load_path(&path, &LoadOptions::default(), obj_for_tests).map(|_| ()).unwrap_err().to_string();
        assert_eq!(e, format!("{}:{tail}", path.display()), "{file}");
    }
    // Every fixture is pinned (unknown_property.xml loads, with warnings: below).
    let mut files: Vec<String> =
        std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    files.retain(|f| f != "unknown_property.xml" && !cases.iter().any(|(c, _)| c == f));
    assert!(files.is_empty(), "fixtures without a pinned message: {files:?}");

    let path = dir.join("unknown_property.xml");
    let s = load_path(&path, &LoadOptions::default(), obj_for_tests).unwrap();
    let p = path.display();
    assert_eq!(
        s.warnings,
        [
            format!("{p}:6:9: unknown property 'radius' of 'cube' ignored"),
            format!("{p}:8:13: unknown property 'roughness' of 'diffuse' ignored"),
        ]
    );
}

#[test]
fn an_all_degenerate_shape_fails_validation() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/xml/zero_area_emitter.xml");
    let text = std::fs::read_to_string(&path).unwrap().replace("<emitter type=\"area\"/>", "");
    let s = load_text(&text, &path, &[], obj_for_tests).map(|s| s.warnings);
    // Without the emitter the shape is merely empty, so the scene has no triangles.
    assert_eq!(
        s.unwrap_err().to_string(),
        format!("{}: scene: has no triangles", path.display()),
        "validation catches an all-degenerate scene"
    );
}

#[test]
fn document_errors() {
    assert_eq!(
        doc_err(r#"<scene><shape type="cube"/></scene>"#),
        "doc.xml:1:1: <scene>: missing attribute 'version' (pathgrad reads Mitsuba 2.x and 3.x scenes)"
    );
    assert_eq!(doc_err(r#"<shape version="3.0.0"/>"#), "doc.xml:1:1: <shape>: the root element must be <scene>");
    assert_eq!(
        doc_err(r#"<scene version="3.0.0" foo="1"/>"#),
        "doc.xml:1:1: <scene>: unexpected attribute 'foo' (allowed: version)"
    );
    assert_eq!(
        doc_err(&format!("<scene version=\"3.0.0\">{SENSOR}\n  <film type=\"hdrfilm\"/></scene>")),
        "doc.xml:2:3: <film>: a <film> must be inside a <sensor>"
    );
    assert_eq!(
        doc_err(&format!(
            r#"<scene version="3.0.0">{SENSOR}<integrator type="path"/><integrator type="path"/><shape type="cube"/></scene>"#
        )),
        format!("doc.xml:1:{}: <integrator>: a scene has at most one <integrator>", SENSOR.len() + 49)
    );
    // An unsupported element is named before the missing sensor is.
    assert_eq!(
        doc_err(r#"<scene version="3.0.0"><mesh/></scene>"#),
        "doc.xml:1:24: <mesh>: unsupported element <mesh> (supported in <scene>: default, path, include, bsdf, \
         texture, shape, emitter, medium, volume, phase, sensor, integrator)"
    );
    assert_eq!(
        doc_err(r#"<scene version="3.0.0"><default name="2x" value="1"/></scene>"#),
        "doc.xml:1:24: <default name=\"2x\">: '2x' is not a valid parameter name ([A-Za-z_][A-Za-z0-9_]*)"
    );
    assert_eq!(
        doc_err(r#"<!DOCTYPE scene [<!ENTITY a "b">]><scene version="3.0.0"/>"#),
        "doc.xml:1:1: malformed XML: XML with DTD detected"
    );
    let ok =
        load_text(&wrap(r#"<shape type="cube"/><emitter type="constant"/>"#), Path::new("x.xml"), &[], obj_for_tests);
    let ok = ok.unwrap();
    assert_eq!(ok.warnings, Vec::<String>::new());
}

#[test]
fn element_and_property_errors() {
    let at = |e: String| e.split_once(": ").map(|(_, m)| m.to_string()).unwrap();
    // Positions are pinned above; here the messages.
    let cases: &[(&str, &str)] = &[
        (r#"<ref id="x"/>"#, "<ref id=\"x\">: a <ref> at scene level is not supported"),
        (r#"<bsdf type="diffuse" id=""/>"#, "<bsdf id=\"\">: an id must not be empty"),
        (r#"<bsdf type="diffuse" colour="red"/>"#, "<bsdf>: unexpected attribute 'colour' (allowed: type, id, name)"),
        (r#"<shape type="cube">oops</shape>"#, "<shape>: unexpected text inside the element"),
        (
            r#"<shape type="cube"><color name="c" value="1"/></shape>"#,
            "<color name=\"c\">: unsupported element <color> (supported inside an object: boolean, float, integer, point, rgb, spectrum, string, transform, vector, bsdf, emitter, film, integrator, medium, phase, ref, rfilter, sampler, sensor, shape, texture, volume)",
        ),
        (
            r#"<shape type="cube"><float name="a" value="1" unit="m"/></shape>"#,
            "<float name=\"a\">: unexpected attribute 'unit' (allowed: name, value)",
        ),
        (r#"<shape type="cube"><float value="1"/></shape>"#, "<float>: missing attribute 'name'"),
        (r#"<shape type="cube"><float name="a"/></shape>"#, "<float name=\"a\">: missing attribute 'value'"),
        (
            r#"<shape type="cube"><float name="a" value="1 2"/></shape>"#,
            "<float name=\"a\">: value: expected one number, got '1 2'",
        ),
        (
            r#"<shape type="cube"><integer name="a" value="1.5"/></shape>"#,
            "<integer name=\"a\">: expected an integer, got '1.5'",
        ),
        (
            r#"<shape type="cube"><boolean name="a" value="yes"/></shape>"#,
            "<boolean name=\"a\">: expected 'true' or 'false', got 'yes'",
        ),
        (
            r#"<shape type="cube"><rgb name="a" value="1 2"/></shape>"#,
            "<rgb name=\"a\">: value: expected 1 or 3 numbers, got '1 2'",
        ),
        (
            r#"<shape type="cube"><float name="a" value="inf"/></shape>"#,
            "<float name=\"a\">: value: 'inf' is not a finite number",
        ),
        (
            r#"<shape type="cube"><float name="a" value="1"/><float name="a" value="2"/></shape>"#,
            "<float name=\"a\">: property 'a' is given twice",
        ),
        (
            r#"<shape type="cube"><point name="p" value="1" x="2"/></shape>"#,
            "<point name=\"p\">: give either 'value' or 'x'/'y'/'z', not both",
        ),
        (
            r#"<shape type="cube"><rgb name="flip_normals" value="1"/></shape>"#,
            "<rgb name=\"flip_normals\">: property 'flip_normals' of 'cube' must be a <boolean>",
        ),
        (r#"<shape type="cube"><film type="hdrfilm"/></shape>"#, "<film>: a <film> is not expected inside 'cube'"),
        (r#"<shape/>"#, "<shape>: missing attribute 'type'"),
        (
            r#"<shape type="hair"/>"#,
            "<shape>: unsupported plugin 'hair' (supported: bsplinecurve, cube, cylinder, disk, linearcurve, obj, ply, rectangle, sdfgrid, serialized, sphere, shapegroup, instance)",
        ),
        (r#"<shape type="obj"/>"#, "<shape>: 'obj' needs the property 'filename'"),
        (
            r#"<shape type="cube"><bsdf type="diffuse"/><bsdf type="diffuse"/></shape>"#,
            "<bsdf>: a shape takes one BSDF",
        ),
        (
            r#"<shape type="cube"><emitter type="area"/><emitter type="area"/></shape>"#,
            "<emitter>: a shape takes one emitter",
        ),
        (
            r#"<shape type="cube"><emitter type="point"/></shape>"#,
            "<emitter>: unsupported plugin 'point' (supported on shapes: area)",
        ),
        (
            r#"<shape type="cube"><emitter type="area"><rgb name="radiance" value="-1"/></emitter></shape>"#,
            "<rgb name=\"radiance\">: 'radiance' must lie in [0, ∞), got [-1, -1, -1]",
        ),
        (
            r#"<shape type="cube"><emitter type="area"><texture type="volume" name="radiance"/></emitter></shape>"#,
            "<texture name=\"radiance\">: the texture of a 'area' must be a 'bitmap' or 'checkerboard' (pathgrad reads no other here), got 'volume'",
        ),
        (
            r#"<shape type="cube"><emitter type="area"><texture type="checkerboard" name="radiance">
                <rgb name="color1" value="2, 1, 1"/></texture></emitter></shape>"#,
            "<rgb name=\"color1\">: 'color1' must lie in [0, 1], got [2, 1, 1]",
        ),
        (
            r#"<shape type="cube"><emitter type="area"><texture type="checkerboard" name="radiance">
                <texture type="bitmap" name="color0"/></texture></emitter></shape>"#,
            "<texture name=\"color0\">: a textured 'color0' of a checkerboard is not supported (a colour is)",
        ),
        (
            r#"<shape type="sphere"><float name="radius" value="-1"/></shape>"#,
            "<float name=\"radius\">: 'radius' must be positive, got -1",
        ),
        (
            r#"<shape type="sphere"><transform name="to_world"><scale x="2"/></transform></shape>"#,
            "<transform name=\"to_world\">: a sphere's to_world must be a rotation, uniform scale and translation (Mitsuba ignores the rest)",
        ),
        (
            r#"<shape type="cube"><transform name="to_world"><shear/></transform></shape>"#,
            "<shear>: unsupported transform element <shear> (supported: translate, rotate, scale, matrix, lookat)",
        ),
        (
            r#"<shape type="cube"><transform name="to_world"><rotate angle="3"/></transform></shape>"#,
            "<rotate>: the rotation axis must be a non-zero vector",
        ),
        (
            r#"<shape type="cube"><transform name="to_world"><rotate x="1"/></transform></shape>"#,
            "<rotate>: missing attribute 'angle'",
        ),
        (
            r#"<shape type="cube"><transform name="to_world"><matrix value="1 2 3"/></transform></shape>"#,
            "<matrix>: a matrix needs 16 (or 9) numbers, got 3",
        ),
        (
            r#"<shape type="cube"><transform name="to_world"><matrix value="1 0 0 0 0 1 0 0 0 0 1 0 0 0 1 1"/></transform></shape>"#,
            "<transform name=\"to_world\">: projective transforms are not supported (the last row must be 0 0 0 1)",
        ),
        (
            r#"<shape type="cube"><transform name="to_world"><scale value="1e30"/><scale value="1e30"/></transform></shape>"#,
            "<transform name=\"to_world\">: the transform is not finite",
        ),
        (
            r#"<shape type="cube"><transform name="to_world"><lookat origin="1 1 1" target="1 1 1"/></transform></shape>"#,
            "<lookat>: lookat: origin and target coincide",
        ),
        (
            r#"<shape type="cube"><transform name="to_world"><lookat origin="0 0 0" target="0 1 0" up="0 2 0"/></transform></shape>"#,
            "<lookat>: lookat: 'up' is parallel to the viewing direction",
        ),
        (
            r#"<shape type="cube"><transform name="to_world">x</transform></shape>"#,
            "<transform name=\"to_world\">: unexpected text inside the element",
        ),
        (
            r#"<shape type="cube"><ref id="c"/></shape><shape type="cube" id="c"/>"#,
            "<ref id=\"c\">: refers to a <shape>, expected a <bsdf>",
        ),
        (r#"<shape type="cube"><ref/></shape>"#, "<ref>: missing attribute 'id'"),
        (
            r#"<bsdf type="diffuse"><ref name="reflectance" id="d"/></bsdf><bsdf type="diffuse" id="d"/>"#,
            "<ref id=\"d\">: refers to a <bsdf>, expected a <texture>",
        ),
        (
            r#"<bsdf type="diffuse"><rgb name="reflectance" value="1.5, 0, 0"/></bsdf>"#,
            "<rgb name=\"reflectance\">: 'reflectance' must lie in [0, 1], got [1.5, 0, 0]",
        ),
        (
            r#"<bsdf type="roughconductor"><float name="alpha" value="0"/></bsdf>"#,
            "<float name=\"alpha\">: 'alpha' must lie in [0.001, 1], got 0",
        ),
        (
            r#"<bsdf type="roughconductor"><rgb name="alpha" value="0.1"/></bsdf>"#,
            "<rgb name=\"alpha\">: property 'alpha' of 'roughconductor' must be a <float>",
        ),
        (
            r#"<bsdf type="roughplastic"><texture type="bitmap" name="alpha"/></bsdf>"#,
            "<texture name=\"alpha\">: a textured 'alpha' of 'roughplastic' is not supported (Mitsuba's is a number)",
        ),
        (
            r#"<bsdf type="roughdielectric"><float name="alpha_v" value="0.2"/></bsdf>"#,
            "<bsdf>: give both 'alpha_u' and 'alpha_v' (Mitsuba requires both)",
        ),
        (
            r#"<bsdf type="roughconductor"><float name="alpha_u" value="0.1"/><float name="alpha" value="0.2"/></bsdf>"#,
            "<bsdf>: give either 'alpha' or 'alpha_u'/'alpha_v', not both",
        ),
        (
            r#"<bsdf type="roughconductor"><string name="distribution" value="phong"/></bsdf>"#,
            "<string name=\"distribution\">: unsupported distribution 'phong' (supported: beckmann, ggx)",
        ),
        (
            r#"<bsdf type="roughconductor"><string name="material" value="Au"/><rgb name="eta" value="1"/></bsdf>"#,
            "<string name=\"material\">: give either 'material' or 'eta'/'k', not both",
        ),
        (
            r#"<bsdf type="roughconductor"><string name="material" value="Unobtainium"/></bsdf>"#,
            "<string name=\"material\">: unknown conductor material 'Unobtainium' (supported: none, Au, Ag, Cu, Al, Cr, a-C)",
        ),
        (
            r#"<bsdf type="roughconductor"><rgb name="k" value="-1"/></bsdf>"#,
            "<rgb name=\"k\">: 'k' must lie in [0, ∞), got [-1, -1, -1]",
        ),
        (
            r#"<bsdf type="blendbsdf"><bsdf type="diffuse"/><bsdf type="diffuse"/></bsdf>"#,
            "<bsdf>: 'blendbsdf' needs the property 'weight'",
        ),
        (
            r#"<bsdf type="blendbsdf"><float name="weight" value="2"/></bsdf>"#,
            "<float name=\"weight\">: 'weight' must lie in [0, 1], got 2",
        ),
        (
            r#"<bsdf type="blendbsdf"><float name="weight" value="0.5"/><bsdf type="diffuse"/></bsdf>"#,
            "<bsdf>: 'blendbsdf' needs 2 nested BSDFs, got 1",
        ),
        (
            r#"<bsdf type="blendbsdf"><texture type="checkerboard" name="weight"><float name="color1" value="2"/></texture><bsdf type="diffuse"/><bsdf type="diffuse"/></bsdf>"#,
            "<float name=\"color1\">: 'color1' must lie in [0, 1], got 2",
        ),
        (
            r#"<bsdf type="blendbsdf"><float name="weight" value="0.5"/><bsdf type="diffuse"/><bsdf type="twosided"><bsdf type="diffuse"/></bsdf></bsdf>"#,
            "<bsdf>: 'blendbsdf' children must both be diffuse/roughconductor/roughplastic, one of those and a smooth \
             'conductor', or both twosided wrappers of diffuse/roughconductor/roughplastic (pathgrad blends two leaf BSDFs)",
        ),
        (
            r#"<bsdf type="blendbsdf"><float name="weight" value="0.5"/><bsdf type="conductor"/><bsdf type="conductor"/></bsdf>"#,
            "<bsdf>: 'blendbsdf' children must both be diffuse/roughconductor/roughplastic, one of those and a smooth \
             'conductor', or both twosided wrappers of diffuse/roughconductor/roughplastic (pathgrad blends two leaf BSDFs)",
        ),
        (
            r#"<bsdf type="blendbsdf"><float name="weight" value="0.5"/><bsdf type="diffuse"/><bsdf type="dielectric"/></bsdf>"#,
            "<bsdf>: 'blendbsdf' children must both be diffuse/roughconductor/roughplastic, one of those and a smooth \
             'conductor', or both twosided wrappers of diffuse/roughconductor/roughplastic (pathgrad blends two leaf BSDFs)",
        ),
        (
            r#"<bsdf type="twosided"><bsdf type="blendbsdf"><float name="weight" value="0.5"/><bsdf type="diffuse"/><bsdf type="conductor"/></bsdf></bsdf>"#,
            "<bsdf>: a 'twosided' around a 'blendbsdf' holding a smooth 'conductor' is not supported",
        ),
        (r#"<bsdf type="twosided"/>"#, "<bsdf>: 'twosided' needs 1 nested BSDF, got 0"),
        (
            r#"<bsdf type="twosided"><bsdf type="diffuse"/><bsdf type="diffuse"/></bsdf>"#,
            "<bsdf>: 'twosided' with different front and back BSDFs is not supported (give one)",
        ),
        (
            r#"<bsdf type="twosided"><bsdf type="twosided"><bsdf type="diffuse"/></bsdf></bsdf>"#,
            "<bsdf>: a 'twosided' BSDF cannot wrap another twosided one",
        ),
        (
            r#"<texture type="wood"/>"#,
            "<texture>: unsupported plugin 'wood' (supported: bitmap, checkerboard, mesh_attribute, volume)",
        ),
        (r#"<texture type="bitmap"/>"#, "<texture>: 'bitmap' needs the property 'filename'"),
        (r#"<emitter type="area"/>"#, "<emitter>: an 'area' emitter must be nested in a <shape>"),
        (
            r#"<emitter type="sunsky"/>"#,
            "<emitter>: unsupported plugin 'sunsky' (supported: constant, directional, envmap, point, projector, \
             spot; area inside a <shape>)",
        ),
        (
            r#"<emitter type="constant"/><emitter type="constant"/>"#,
            "<emitter>: a scene has at most one environment emitter (constant or envmap)",
        ),
        (
            r#"<integrator type="depth"/>"#,
            "<integrator>: unsupported plugin 'depth' (supported: path, prb, prb_basic, volpath, volpathmis, prbvolpath, \
             direct, ptracer, prb_projective, direct_projective; moment and aov around one of them)",
        ),
        (
            r#"<integrator type="path"><integer name="max_depth" value="0"/></integrator>"#,
            "<integer name=\"max_depth\">: 'max_depth' must be at least 1, or -1 for unbounded, got 0",
        ),
    ];
    for (body, expected) in cases {
        assert_eq!(at(err(body)), *expected, "{body}");
    }
}

#[test]
fn sensor_errors() {
    let sensor = |inner: &str| {
        doc_err(&format!(
            r#"<scene version="3.0.0"><sensor type="perspective">{inner}</sensor><shape type="cube"/></scene>"#
        ))
    };
    let at = |e: String| e.splitn(4, ':').nth(3).unwrap().trim_start().to_string();
    let cases: &[(&str, &str)] = &[
        (r#"<float name="fov" value="180"/>"#, "<float name=\"fov\">: 'fov' must lie in (0, 180) degrees, got 180"),
        (
            r#"<float name="fov" value="40"/><string name="focal_length" value="35mm"/>"#,
            "<string name=\"focal_length\">: give either 'fov' or 'focal_length', not both",
        ),
        (
            r#"<string name="focal_length" value="wide"/>"#,
            "<string name=\"focal_length\">: 'focal_length' must be a positive length like '50mm', got 'wide'",
        ),
        (
            r#"<string name="fov_axis" value="z"/>"#,
            "<string name=\"fov_axis\">: unknown fov_axis 'z' (supported: x, y, diagonal, smaller, larger)",
        ),
        (r#"<film type="ldrfilm"/>"#, "<film>: unsupported plugin 'ldrfilm' (supported: hdrfilm)"),
        (r#"<film type="hdrfilm"/><film type="hdrfilm"/>"#, "<film>: a sensor has at most one <film>"),
        (
            r#"<film type="hdrfilm"><integer name="width" value="0"/></film>"#,
            "<integer name=\"width\">: 'width' must lie in [1, 16384], got 0",
        ),
        (
            r#"<film type="hdrfilm"><rfilter type="mitchell"/></film>"#,
            "<rfilter>: unsupported plugin 'mitchell' (supported: box, tent, gaussian; filters with negative lobes are not)",
        ),
        (
            r#"<film type="hdrfilm"><rfilter type="gaussian"><float name="stddev" value="-1"/></rfilter></film>"#,
            "<float name=\"stddev\">: 'stddev' must lie in (0, 64] pixels, got -1",
        ),
        (
            r#"<film type="hdrfilm"><integer name="width" value="64"/><integer name="crop_offset_x" value="40"/><integer name="crop_width" value="32"/></film>"#,
            "<integer name=\"crop_width\">: the crop window (crop_offset_x 40 + crop_width 32) must lie inside the film's width 64",
        ),
        (
            r#"<film type="hdrfilm"><integer name="height" value="64"/><integer name="crop_offset_y" value="64"/></film>"#,
            "<integer name=\"crop_offset_y\">: the crop window (crop_offset_y 64 + crop_height 0) must lie inside the film's height 64",
        ),
        (
            r#"<film type="hdrfilm"><integer name="crop_height" value="0"/></film>"#,
            "<integer name=\"crop_height\">: 'crop_height' must lie in [1, 16384], got 0",
        ),
        (
            r#"<film type="hdrfilm"><boolean name="sample_border" value="true"/></film>"#,
            "<boolean name=\"sample_border\">: sample_border is not supported (pathgrad samples inside the film only)",
        ),
        (
            r#"<sampler type="sobol"/>"#,
            "<sampler>: unsupported plugin 'sobol' (supported: independent; stratified, multijitter, orthogonal and \
             ldsampler as independent)",
        ),
        (
            r#"<sampler type="independent"><integer name="sample_count" value="0"/></sampler>"#,
            "<integer name=\"sample_count\">: 'sample_count' must be at least 1, got 0",
        ),
        (
            r#"<transform name="to_world"><scale x="2"/></transform>"#,
            "<transform name=\"to_world\">: the sensor's to_world must be a rotation, uniform scale and translation",
        ),
        (
            r#"<transform name="to_world"><scale value="0"/></transform>"#,
            "<transform name=\"to_world\">: the sensor's to_world is singular",
        ),
    ];
    for (inner, expected) in cases {
        assert_eq!(at(sensor(inner)), *expected, "{inner}");
    }
    assert_eq!(
        doc_err(r#"<scene version="3.0.0"><sensor type="thinlens"/></scene>"#),
        "doc.xml:1:24: <sensor>: 'thinlens' needs the property 'aperture_radius'"
    );
    assert_eq!(
        doc_err(r#"<scene version="3.0.0"><sensor type="radiancemeter"/></scene>"#),
        "doc.xml:1:24: <sensor>: unsupported plugin 'radiancemeter' (supported: perspective, thinlens, orthographic)"
    );
}

#[test]
fn clip_distances_are_warned_about_only_where_they_clip() {
    // The camera at z = 5 looks down −z at a unit cube around the origin: depths 4 to 6.
    let scene = |clips: &str| {
        let xml = format!(
            r#"<scene version="3.0.0"><sensor type="perspective">{clips}<transform name="to_world"><lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform><film type="hdrfilm"/></sensor>
<shape type="cube"><emitter type="area"/></shape></scene>"#
        );
        load_text(&xml, Path::new("c.xml"), &[], obj_for_tests).unwrap().warnings
    };
    let none: [&str; 0] = [];
    assert_eq!(scene(r#"<float name="near_clip" value="3.9"/><float name="far_clip" value="6.1"/>"#), none);
    assert_eq!(
        scene(r#"<float name="near_clip" value="4.5"/><float name="far_clip" value="5.5"/>"#),
        [
            "c.xml:1:51: property 'near_clip' of 'perspective' ignored: pathgrad's camera does not clip",
            "c.xml:1:88: property 'far_clip' of 'perspective' ignored: pathgrad's camera does not clip",
        ]
    );
    assert_eq!(
        scene(r#"<float name="far_clip" value="5.5"/>"#),
        ["c.xml:1:51: property 'far_clip' of 'perspective' ignored: pathgrad's camera does not clip"]
    );
    // Mitsuba's defaults (0.01 and 10⁴) clip too: a camera inside the cube sees a face at 0.005.
    assert_eq!(scene(""), none);
    let inside = r#"<scene version="3.0.0"><sensor type="perspective"><transform name="to_world"><lookat origin="0, 0, -0.995" target="0, 0, -2" up="0, 1, 0"/></transform><film type="hdrfilm"/></sensor>
<shape type="cube"><emitter type="area"/></shape></scene>"#;
    // Faces that pass beside the camera, outside its view, are not clipped where it looks.
    let beside = inside.replace("0, 0, -0.995", "0, 0, 0").replace("0, 0, -2", "0, 0, 1");
    assert_eq!(load_text(&beside, Path::new("c.xml"), &[], obj_for_tests).unwrap().warnings, none);
    assert_eq!(
        load_text(inside, Path::new("c.xml"), &[], obj_for_tests).unwrap().warnings,
        ["c.xml:1:24: Mitsuba's default near_clip (0.01) clips geometry that pathgrad's camera, which does not clip, \
             renders"]
    );
}

#[test]
fn ignored_settings_are_warned_about() {
    let xml = r#"<scene version="3.0.0">
<integrator type="path"><integer name="rr_depth" value="3"/><boolean name="hide_emitters" value="true"/></integrator>
<sensor type="perspective"><float name="near_clip" value="1.5"/>
<film type="hdrfilm"><rfilter type="gaussian"/><string name="pixel_format" value="rgb"/></film><sampler type="independent"><integer name="seed" value="3"/></sampler></sensor>
<shape type="cube"><bsdf type="diffuse"><texture type="bitmap" name="reflectance"><string name="filename" value="t.png"/><string name="format" value="uint8"/></texture></bsdf></shape>
</scene>"#;
    let dir = tempfile::tempdir().unwrap();
    image::RgbImage::from_raw(1, 1, vec![1, 2, 3]).unwrap().save(dir.path().join("t.png")).unwrap();
    let s = load_text(xml, &dir.path().join("w.xml"), &[], obj_for_tests).unwrap();
    let w: Vec<String> = s.warnings.iter().map(|w| w.split_once("w.xml:").unwrap().1.to_string()).collect();
    assert_eq!(
        w,
        [
            "4:124: property 'seed' of 'independent' ignored: pathgrad takes the seed from the render options",
            "3:28: property 'near_clip' of 'perspective' ignored: pathgrad's camera does not clip",
            "2:25: property 'rr_depth' of 'path' ignored: pathgrad starts Russian roulette at depth 5",
            "5:122: property 'format' = 'uint8' of 'bitmap' ignored: pathgrad uses 'variant'",
            "1:1: the scene has no emitters: it renders black unless lit by an environment (LoadOptions::environment)",
        ]
    );
}

#[test]
fn missing_and_broken_bitmaps_name_the_file() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("bad.png"), b"not a png").unwrap();
    let body = |f: &str| {
        wrap(&format!(
            r#"<shape type="cube"><bsdf type="diffuse"><texture type="bitmap" name="reflectance"><string name="filename" value="{f}"/></texture></bsdf></shape>"#
        ))
    };
    let file = dir.path().join("b.xml");
    let e = load_text(&body("gone.png"), &file, &[], obj_for_tests).unwrap_err().to_string();
    let col = SENSOR.len() + 106;
    assert_eq!(
        e,
        format!(
            "{}:1:{col}: <string name=\"filename\">: image file 'gone.png' not found (looked for {})",
            file.display(),
            dir.path().join("gone.png").display()
        )
    );
    let e = load_text(&body("bad.png"), &file, &[], obj_for_tests).unwrap_err().to_string();
    assert!(
        e.starts_with(&format!("{}:1:{col}: <string name=\"filename\">: reading 'bad.png': ", file.display())),
        "{e}"
    );
    exr::prelude::write_rgba_file(dir.path().join("hot.exr"), 1, 1, |_, _| (2.0f32, 0.0f32, 0.0f32, 1.0f32)).unwrap();
    let e = load_text(&body("hot.exr"), &file, &[], obj_for_tests).unwrap_err().to_string();
    assert!(e.ends_with("'hot.exr': texel (0, 0) has value 2 outside [0, 1] (reflectances must be at most 1)"), "{e}");
}

#[test]
fn nesting_is_capped_and_cycles_are_found() {
    // 20 blends deep: the 17th level is refused before anything is built.
    let mut body = String::from(r#"<bsdf type="diffuse"/>"#);
    for _ in 0..20 {
        body =
            format!(r#"<bsdf type="blendbsdf"><float name="weight" value="0.5"/>{body}<bsdf type="diffuse"/></bsdf>"#);
    }
    let e = err(&format!(r#"<shape type="cube">{body}</shape>"#));
    assert!(e.ends_with("<bsdf>: BSDFs and textures nest more than 16 deep"), "{e}");
    // A hundred thousand nested elements: no stack overflow, a clean error.
    let deep = "<bsdf type=\"twosided\">".repeat(100_000) + &"</bsdf>".repeat(100_000);
    let e = err(&format!(r#"<shape type="cube">{deep}</shape>"#));
    assert!(e.ends_with("<bsdf>: BSDFs and textures nest more than 16 deep"), "{e}");
    // Mutual references.
    let e =
        err(r#"<bsdf type="twosided" id="a"><ref id="b"/></bsdf><bsdf type="twosided" id="b"><ref id="a"/></bsdf>"#);
    assert!(e.ends_with("<ref id=\"a\">: reference cycle: this BSDF contains itself"), "{e}");
}

/// A mesh reader that returns one triangle, so that thousands of loads stay fast.
fn one_triangle(_: super::loader::MeshFormat, _: &Path) -> crate::error::Result<crate::scene::shapes::Geometry> {
    Ok(crate::scene::shapes::quad(glam::Vec3::ZERO, glam::Vec3::X, glam::Vec3::Y))
}

/// Every prefix of the shipped scenes, and each with single bytes replaced, loads or fails with a
/// located error — never a panic.
#[test]
fn truncated_and_mutated_scenes_fail_cleanly() {
    for rel in ["scenes/cornell-box/cornell-box.xml", "scenes/blend/blend.xml"] {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(rel);
        let text = std::fs::read_to_string(&path).unwrap();
        let mut cuts: Vec<usize> = (0..text.len()).step_by(7).filter(|&i| text.is_char_boundary(i)).collect();
        cuts.push(text.len());
        for cut in cuts {
            if let Err(e) = load_text(&text[..cut], &path, &[], one_triangle) {
                assert!(e.to_string().starts_with(&path.display().to_string()), "{e}");
            }
        }
        let bytes = text.as_bytes();
        for (i, replacement) in
            (0..bytes.len()).step_by(3).zip([b'<', b'"', b'$', b'0', b'-', b'/', b'>', b'x'].iter().cycle())
        {
            let mut m = bytes.to_vec();
            m[i] = *replacement;
            let Ok(m) = String::from_utf8(m) else { continue };
            if let Err(e) = load_text(&m, &path, &[], one_triangle) {
                assert!(e.to_string().starts_with(&path.display().to_string()), "{e}");
            }
        }
    }
}

#[test]
fn sdfgrid_errors_name_the_file_and_the_parameter() {
    use crate::scene::volume::Grid;
    let dir = tempfile::tempdir().unwrap();
    let write = |name: &str, res: glam::UVec3, channels: u32, value: &dyn Fn(u32) -> f32| {
        let n = res.x * res.y * res.z * channels;
        let grid = Grid::new(res, channels, (0..n).map(value).collect()).unwrap();
        std::fs::write(dir.path().join(name), grid.to_bytes()).unwrap();
    };
    // A surface between the grid's first and second x-planes.
    write("good.vol", glam::UVec3::splat(3), 1, &|i| if i % 3 == 0 { -1.0 } else { 1.0 });
    write("rgb.vol", glam::UVec3::splat(2), 3, &|_| -1.0);
    write("empty.vol", glam::UVec3::splat(2), 1, &|_| 2.0);
    write("flat.vol", glam::UVec3::new(2, 2, 1), 1, &|i| i as f32 - 1.5);
    std::fs::write(dir.path().join("short.vol"), b"VOL\x03").unwrap();
    let file = dir.path().join("s.xml");
    let load = |inner: &str| {
        let body = format!(r#"<emitter type="constant"/><shape type="sdfgrid">{inner}</shape>"#);
        load_text(&wrap(&body), &file, &[], obj_for_tests)
    };
    let message = |inner: &str| match load(inner) {
        Ok(_) => panic!("{inner} loaded"),
        Err(e) => e.to_string().split_once(": ").map(|(_, m)| m.to_string()).unwrap(),
    };
    let f = |name: &str| format!(r#"<string name="filename" value="{name}"/>"#);
    let ok = load(&f("good.vol")).unwrap();
    assert_eq!(ok.warnings, Vec::<String>::new());
    assert!(!ok.meshes[0].indices.is_empty());
    assert_eq!(message(""), "<shape>: 'sdfgrid' needs the property 'filename' (a .vol grid)".to_string());
    assert!(message(&f("gone.vol")).starts_with("<string name=\"filename\">: SDF grid file 'gone.vol' not found"));
    assert_eq!(
        message(&f("rgb.vol")),
        "<string name=\"filename\">: SDF grid 'rgb.vol': 3 channels (an SDF grid has 1)"
    );
    assert_eq!(
        message(&f("empty.vol")),
        "<string name=\"filename\">: SDF grid 'empty.vol': no voxel's corners change sign: the surface is empty"
    );
    assert_eq!(
        message(&f("flat.vol")),
        "<string name=\"filename\">: SDF grid 'flat.vol': resolution 2×2×1: an SDF grid needs at least 2 values on \
         each axis"
    );
    let short = message(&f("short.vol"));
    assert!(short.contains("short.vol") && short.contains("too short for a .vol header"), "{short}");
    assert_eq!(
        message(&format!(r#"{}<string name="normals" value="flat"/>"#, f("good.vol"))),
        "<string name=\"normals\">: 'normals' must be 'analytic' or 'smooth', got 'flat'"
    );
    assert_eq!(
        message(&format!(r#"{}<boolean name="flip_normals" value="true"/>"#, f("good.vol"))),
        "<boolean name=\"flip_normals\">: 'flip_normals' is not supported on an sdfgrid (Mitsuba's sdfgrid ignores it)"
    );
    assert_eq!(
        message(&format!(r#"{}<emitter type="area"><rgb name="radiance" value="1"/></emitter>"#, f("good.vol"))),
        "<emitter>: area emitters on an sdfgrid are not supported (Mitsuba's cannot emit)"
    );
    // A rotating to_world loads with Mitsuba's warning about it.
    let turned =
        load(&format!(r#"{}<transform name="to_world"><rotate y="1" angle="30"/></transform>"#, f("good.vol")));
    let warnings = turned.unwrap().warnings;
    assert!(warnings.len() == 1 && warnings[0].contains("whose to_world rotates or mirrors"), "{warnings:?}");
}

//! `normalmap`: what the loader reads (texels outside the parameters, the nested BSDF's names),
//! what it refuses by name, and `--param` on a map's texels.

use super::loader::load_text;
use super::tests::{obj_for_tests, wrap};
use crate::error::Result;
use crate::scene::{Material, Scene, Wrap};

/// Loads `body` (with [`wrap`]'s sensor) from a folder holding `n.png`, a 2×1 raw normal map.
fn load_with_map(body: &str) -> Result<Scene> {
    let dir = tempfile::tempdir().unwrap();
    let png = image::RgbImage::from_raw(2, 1, vec![128, 128, 255, 255, 0, 128]).unwrap();
    png.save(dir.path().join("n.png")).unwrap();
    load_text(&wrap(body), &dir.path().join("s.xml"), &[], obj_for_tests)
}

const BUMP: &str = r#"<texture name="heights" type="bitmap"><boolean name="raw" value="true"/><string name="filename" value="n.png"/></texture>"#;

const MAP: &str = r#"<texture name="normalmap" type="bitmap"><boolean name="raw" value="true"/><string name="filename" value="n.png"/><string name="wrap_mode" value="clamp"/></texture>"#;

#[test]
fn issue_31_a_normal_map_holds_its_texels_and_names_its_bsdf_as_mitsuba() {
    let s = load_with_map(&format!(
        r#"<shape type="cube" id="box"><bsdf type="normalmap">{MAP}<bsdf type="roughconductor"><float name="alpha" value="0.3"/></bsdf></bsdf></shape>
           <shape type="cube" id="back"><bsdf type="twosided"><bsdf type="normalmap">{MAP}<bsdf type="diffuse"/></bsdf></bsdf></shape>"#
    ))
    .unwrap();
    let names: Vec<&str> = s.params.entries().iter().map(|e| e.name.as_str()).collect();
    assert!(names.contains(&"box.bsdf.nested_bsdf.alpha.value"), "{names:?}");
    assert!(names.contains(&"back.bsdf.brdf_0.nested_bsdf.reflectance.value"), "{names:?}");
    assert!(!names.iter().any(|n| n.contains("normalmap")), "a map's texels are not parameters: {names:?}");
    let map = &s.normal_maps[0];
    assert_eq!((map.width, map.height, map.wrap, map.nearest), (2, 1, Wrap::Clamp, false));
    assert_eq!(map.texels, [128.0 / 255.0, 128.0 / 255.0, 1.0, 1.0, 0.0, 128.0 / 255.0]);
    let Material::NormalMap { nested, map } = s.materials[s.meshes[0].material.0 as usize] else {
        panic!("not normal-mapped: {:?}", s.materials[s.meshes[0].material.0 as usize])
    };
    assert!(matches!(s.materials[nested.0 as usize], Material::RoughConductor { .. }) && map == 0);
    let Material::TwoSided(inner) = s.materials[s.meshes[1].material.0 as usize] else { panic!("not two-sided") };
    assert!(matches!(s.materials[inner.0 as usize], Material::NormalMap { .. }));
    // Mitsuba's identity test scene's texture: a `rawconstant` vector, one exact texel.
    let c = load_with_map(
        r#"<shape type="cube"><bsdf type="normalmap"><texture name="normalmap" type="rawconstant"><vector name="value" value="0.5, 0.5, 1"/></texture><bsdf type="diffuse"/></bsdf></shape>"#,
    )
    .unwrap();
    assert_eq!((c.normal_maps[0].texels.as_slice(), c.normal_maps[0].nearest), ([0.5, 0.5, 1.0].as_slice(), true));
    let err = s.params.select(&["box.bsdf.normalmap.data"]).unwrap_err().to_string();
    assert!(err.contains("a normal or bump map's texels are not parameters"), "{err}");
}

#[test]
fn issue_31_a_bump_map_holds_the_luminance_of_its_texels_and_its_scale() {
    let s = load_with_map(&format!(
        r#"<shape type="cube" id="box"><bsdf type="bumpmap"><float name="scale" value="0.25"/>{BUMP}<bsdf type="diffuse"/></bsdf></shape>"#
    ))
    .unwrap();
    let Material::BumpMap { nested, map, scale } = s.materials[s.meshes[0].material.0 as usize] else {
        panic!("not bump-mapped: {:?}", s.materials[s.meshes[0].material.0 as usize])
    };
    assert!(matches!(s.materials[nested.0 as usize], Material::Diffuse { .. }) && scale == 0.25);
    // Each texel's luminance (Mitsuba's weights): (½, ½, 1) and (1, 0, ½).
    let texels = &s.normal_maps[map as usize].texels;
    let half = 128.0 / 255.0;
    assert!((texels[0] - ((0.212_671 + 0.715_160) * half + 0.072_169)).abs() < 1e-6, "{texels:?}");
    assert!((texels[1] - (0.212_671 + 0.072_169 * half)).abs() < 1e-6, "{texels:?}");
    assert_eq!(texels.len(), 2);
    assert!(s.params.find("box.bsdf.nested_bsdf.reflectance.value").is_some());
    let err = s.params.select(&["box.bsdf.nested_texture.data"]).unwrap_err().to_string();
    assert!(err.contains("a normal or bump map's texels are not parameters"), "{err}");
}

#[test]
fn issue_31_normal_maps_refuse_what_they_do_not_read_by_name() {
    let cases = [
        (
            format!(r#"<bsdf type="normalmap">{MAP}<bsdf type="twosided"><bsdf type="diffuse"/></bsdf></bsdf>"#),
            "put 'twosided' outside the map",
        ),
        (
            r#"<bsdf type="normalmap"><bsdf type="diffuse"/></bsdf>"#.into(),
            "needs a nested <texture name=\"normalmap\"",
        ),
        (format!(r#"<bsdf type="normalmap">{MAP}</bsdf>"#), "'normalmap' needs 1 nested BSDF, got 0"),
        (
            format!(
                r#"<bsdf type="normalmap">{MAP}<bsdf type="diffuse"/><boolean name="flip_invalid_normals" value="false"/></bsdf>"#
            ),
            "'flip_invalid_normals' = false of 'normalmap' is not supported",
        ),
        (
            r#"<bsdf type="normalmap"><texture name="normalmap" type="checkerboard"/><bsdf type="diffuse"/></bsdf>"#
                .into(),
            "a normal map must be a 'bitmap' or 'rawconstant' texture, got 'checkerboard'",
        ),
        (
            format!(
                r#"<bsdf type="blendbsdf"><float name="weight" value="0.5"/><bsdf type="normalmap">{MAP}<bsdf type="diffuse"/></bsdf><bsdf type="diffuse"/></bsdf>"#
            ),
            "'blendbsdf' children must both be",
        ),
        (
            format!(r#"<bsdf type="twosided"><bsdf type="normalmap">{MAP}<bsdf type="dielectric"/></bsdf></bsdf>"#),
            "cannot wrap one that transmits light",
        ),
        (
            format!(
                r#"<bsdf type="bumpmap">{BUMP}<bsdf type="roughconductor"><float name="alpha_u" value="0.1"/><float name="alpha_v" value="0.3"/></bsdf></bsdf>"#
            ),
            "an anisotropic BSDF inside a 'bumpmap' is not supported",
        ),
        (r#"<bsdf type="bumpmap"><bsdf type="diffuse"/></bsdf>"#.into(), "'bumpmap' needs 1 nested <texture>, got 0"),
        (
            format!(
                r#"<bsdf type="bumpmap">{BUMP}<bsdf type="diffuse"/><boolean name="use_shadowing_function" value="false"/></bsdf>"#
            ),
            "'use_shadowing_function' = false of 'bumpmap' is not supported",
        ),
        (
            format!(r#"<bsdf type="bumpmap">{BUMP}<bsdf type="normalmap">{MAP}<bsdf type="diffuse"/></bsdf></bsdf>"#),
            "a 'bumpmap' around another normal or bump map is not supported",
        ),
    ];
    for (bsdf, expect) in cases {
        let err = load_with_map(&format!(r#"<shape type="cube">{bsdf}</shape>"#)).unwrap_err().to_string();
        assert!(err.contains(expect), "{bsdf}: {err}");
        assert!(err.contains("s.xml:"), "the message names the file and line: {err}");
    }
}

#[test]
fn issue_31_the_differential_strategy_refuses_a_normal_mapped_roughness() {
    let s = load_with_map(&format!(
        r#"<shape type="cube" id="box"><bsdf type="normalmap">{MAP}<bsdf type="roughconductor"/></bsdf></shape>"#
    ))
    .unwrap();
    let err = crate::integrator::Strategy::from_name(&s, "diff", 0.5, "box.bsdf.nested_bsdf.alpha.value")
        .unwrap_err()
        .to_string();
    assert!(err.contains("a normal-mapped material's roughness or blend weight"), "{err}");
}

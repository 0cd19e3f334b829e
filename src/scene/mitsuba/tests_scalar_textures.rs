//! Textures on scalar properties (issue 31, item 3): roughness and blend weights as one-channel
//! bitmaps or checkerboards of floats, and a conductor's textured reflectance, named as Mitsuba's
//! `traverse`, and what is refused by name.

use super::loader::load_text;
use super::tests::{obj_for_tests, wrap};
use crate::error::Result;
use crate::scene::{Material, Scene};

/// Loads `body` (with [`wrap`]'s sensor) from a folder holding `grey.png` (2×1, grey 0 and 255)
/// and `rgb.png` (1×1, not grey).
fn load_with_images(body: &str) -> Result<Scene> {
    let dir = tempfile::tempdir().unwrap();
    image::RgbImage::from_raw(2, 1, vec![0, 0, 0, 255, 255, 255]).unwrap().save(dir.path().join("grey.png")).unwrap();
    image::RgbImage::from_raw(1, 1, vec![10, 20, 30]).unwrap().save(dir.path().join("rgb.png")).unwrap();
    load_text(&wrap(body), &dir.path().join("s.xml"), &[], obj_for_tests)
}

const GREY: &str = r#"<string name="filename" value="grey.png"/><boolean name="raw" value="true"/>"#;

#[test]
fn issue_31_textured_roughness_and_weights_are_parameters_named_as_mitsuba() {
    let s = load_with_images(&format!(
        r#"<shape type="cube" id="a"><bsdf type="roughconductor">
               <texture type="bitmap" name="alpha_u">{GREY}</texture>
               <texture type="checkerboard" name="alpha_v"><float name="color0" value="0.05"/><transform name="to_uv"><scale x="4" y="2"/></transform></texture>
           </bsdf></shape>
           <shape type="cube" id="b"><bsdf type="roughdielectric"><texture type="checkerboard" name="alpha"/></bsdf></shape>
           <shape type="cube" id="c"><bsdf type="blendbsdf"><texture type="bitmap" name="weight">{GREY}<string name="filter_type" value="nearest"/></texture>
               <bsdf type="diffuse"/><bsdf type="roughconductor"/></bsdf></shape>"#
    ))
    .unwrap();
    let names: Vec<&str> = s.params.entries().iter().map(|e| e.name.as_str()).collect();
    for name in [
        "a.bsdf.alpha_u.data",
        "a.bsdf.alpha_v.color0.value",
        "a.bsdf.alpha_v.color1.value",
        "b.bsdf.alpha.color0.value",
        "b.bsdf.alpha.color1.value",
        "c.bsdf.weight.data",
    ] {
        assert!(names.contains(&name), "{name} missing: {names:?}");
    }
    let u = s.params.find("a.bsdf.alpha_u.data").unwrap();
    assert_eq!(s.params.get(u), [0.0, 1.0], "one channel, raw");
    let t = s.scalar_texture(u).unwrap();
    assert_eq!((t.width, t.height, t.checker, t.nearest), (2, 1, false, false));
    // Mitsuba 3.9.1 reads a float checkerboard's color1 where the halves agree: texel 0.
    let v = s.params.find("a.bsdf.alpha_v.color1.value").unwrap();
    let checker = s.scalar_texture(v).unwrap();
    let color0 = s.params.entry(s.params.find("a.bsdf.alpha_v.color0.value").unwrap()).offset;
    assert_eq!(color0, s.params.entry(v).offset + 1);
    assert_eq!((checker.width, checker.height, checker.checker), (2, 1, true));
    assert_eq!(checker.to_uv[0], glam::Vec3::new(4.0, 0.0, 0.0));
    assert_eq!(s.params.get(s.params.find("a.bsdf.alpha_v.color1.value").unwrap()), [0.2], "Mitsuba's default");
    let Material::RoughConductor { alpha, alpha_v, .. } = s.materials[s.meshes[0].material.0 as usize] else {
        panic!("not a conductor")
    };
    assert_eq!((alpha, alpha_v), (u, v));
    let w = s.params.find("c.bsdf.weight.data").unwrap();
    assert!(s.scalar_texture(w).unwrap().nearest);
    // The differential sampler has no target among texels.
    let err = crate::integrator::Strategy::from_name(&s, "diff", 0.5, "c.bsdf.weight.data").unwrap_err().to_string();
    assert!(err.contains("a texture's texels"), "{err}");
}

#[test]
fn issue_31_a_roughconductors_specular_reflectance_takes_a_colour_texture() {
    let s = load_with_images(
        r#"<shape type="cube" id="a"><bsdf type="roughconductor"><texture type="bitmap" name="specular_reflectance"><string name="filename" value="rgb.png"/></texture></bsdf></shape>
           <shape type="cube" id="b"><bsdf type="roughconductor"><texture type="checkerboard" name="specular_reflectance"/></bsdf></shape>"#,
    )
    .unwrap();
    let specular = |i: usize| match s.materials[s.meshes[i].material.0 as usize] {
        Material::RoughConductor { specular, .. } => specular,
        ref other => panic!("not a conductor: {other:?}"),
    };
    assert!(matches!(specular(0), crate::scene::Albedo::Bitmap(_)));
    assert!(matches!(specular(1), crate::scene::Albedo::Checker { .. }));
    assert!(s.params.find("a.bsdf.specular_reflectance.data").is_some());
    assert!(s.params.find("b.bsdf.specular_reflectance.color0.value").is_some());
}

#[test]
fn issue_31_textures_on_scalar_properties_refuse_what_pathgrad_does_not_read_by_name() {
    let cases = [
        (
            r#"<bsdf type="roughconductor"><texture type="bitmap" name="alpha"><string name="filename" value="rgb.png"/></texture></bsdf>"#,
            "is not grey (",
        ),
        (
            r#"<bsdf type="roughplastic"><texture type="checkerboard" name="alpha"/></bsdf>"#,
            "a textured 'alpha' of 'roughplastic' is not supported",
        ),
        (
            r#"<bsdf type="roughdielectric"><texture type="checkerboard" name="alpha_u"/><texture type="checkerboard" name="alpha_v"/></bsdf>"#,
            "a textured 'alpha_u'/'alpha_v' of 'roughdielectric' is not supported",
        ),
        (
            r#"<bsdf type="roughconductor"><texture type="checkerboard" name="alpha"><rgb name="color0" value="0.1, 0.2, 0.3"/></texture></bsdf>"#,
            "property 'color0' of 'checkerboard' must be a <float>",
        ),
        (
            r#"<bsdf type="roughconductor"><texture type="checkerboard" name="alpha"><float name="color0" value="1.5"/></texture></bsdf>"#,
            "'color0' must lie in [0, 1], got 1.5",
        ),
        (
            r#"<bsdf type="blendbsdf"><texture type="mesh_attribute" name="weight"/><bsdf type="diffuse"/><bsdf type="diffuse"/></bsdf>"#,
            "unsupported plugin 'mesh_attribute' on a float property",
        ),
    ];
    for (bsdf, expect) in cases {
        let err = load_with_images(&format!(r#"<shape type="cube">{bsdf}</shape>"#)).unwrap_err().to_string();
        assert!(err.contains(expect), "{bsdf}: {err}");
        assert!(err.contains("s.xml:"), "the message names the file and line: {err}");
    }
}

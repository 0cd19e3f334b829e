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
fn issue_31_smooth_bsdfs_and_rough_dielectrics_take_textured_specular_colours_named_as_mitsuba() {
    use crate::scene::{Albedo, SmoothColour};
    let s = load_with_images(
        r#"<shape type="cube" id="a"><bsdf type="conductor"><texture type="bitmap" name="specular_reflectance"><string name="filename" value="rgb.png"/></texture></bsdf></shape>
           <shape type="cube" id="b"><bsdf type="dielectric"><texture type="checkerboard" name="specular_transmittance"/><rgb name="specular_reflectance" value="0.5"/></bsdf></shape>
           <shape type="cube" id="c"><bsdf type="thindielectric"><texture type="checkerboard" name="specular_reflectance"/></bsdf></shape>
           <shape type="cube" id="d"><bsdf type="roughdielectric"><texture type="bitmap" name="specular_transmittance"><string name="filename" value="rgb.png"/></texture>
               <texture type="checkerboard" name="specular_reflectance"/></bsdf></shape>"#,
    )
    .unwrap();
    let colours = |i: usize| match s.materials[s.meshes[i].material.0 as usize] {
        Material::Smooth { reflectance, transmittance, .. }
        | Material::RoughDielectric { reflectance, transmittance, .. } => (reflectance, transmittance),
        ref other => panic!("not a smooth BSDF or rough dielectric: {other:?}"),
    };
    assert!(matches!(colours(0).0, SmoothColour::Texture(Albedo::Bitmap(_))));
    assert!(matches!(colours(1), (SmoothColour::Param(_), SmoothColour::Texture(Albedo::Checker { .. }))));
    assert!(matches!(colours(2), (SmoothColour::Texture(Albedo::Checker { .. }), SmoothColour::Constant(_))));
    assert!(matches!(
        colours(3),
        (SmoothColour::Texture(Albedo::Checker { .. }), SmoothColour::Texture(Albedo::Bitmap(_)))
    ));
    for name in [
        "a.bsdf.specular_reflectance.data",
        "b.bsdf.specular_reflectance.value",
        "b.bsdf.specular_transmittance.color0.value",
        "b.bsdf.specular_transmittance.color1.value",
        "c.bsdf.specular_reflectance.color0.value",
        "d.bsdf.specular_transmittance.data",
        "d.bsdf.specular_reflectance.color1.value",
    ] {
        assert!(s.params.find(name).is_some(), "{name} missing");
    }
    // Bad textures on a specular colour are refused by name, with the file and line.
    for (bsdf, expect) in [
        (
            r#"<bsdf type="principled"><texture type="volume" name="base_color"><rgb name="volume" value="0.5"/></texture></bsdf>"#,
            "a 'volume' texture is not supported as 'base_color' of 'principled' (only as a diffuse's 'reflectance' and a conductor's or roughconductor's 'specular_reflectance')",
        ),
        (
            r#"<bsdf type="roughplastic"><texture type="volume" name="specular_reflectance"><rgb name="volume" value="0.5"/></texture></bsdf>"#,
            "a 'volume' texture is not supported as 'specular_reflectance' of 'roughplastic' (only as a diffuse's 'reflectance' and a conductor's or roughconductor's 'specular_reflectance')",
        ),
        (
            r#"<bsdf type="plastic"><texture type="volume" name="diffuse_reflectance"><rgb name="volume" value="0.5"/></texture></bsdf>"#,
            "a 'volume' texture is not supported as 'diffuse_reflectance' of 'plastic' (only as a diffuse's 'reflectance' and a conductor's or roughconductor's 'specular_reflectance')",
        ),
        (
            r#"<bsdf type="conductor"><texture type="checkerboard" name="specular_reflectance"><rgb name="color1" value="1.5"/></texture></bsdf>"#,
            "'color1' must lie in [0, 1]",
        ),
        (
            r#"<bsdf type="roughdielectric"><texture type="bitmap" name="specular_reflectance"><string name="filename" value="missing.png"/></texture></bsdf>"#,
            "missing.png",
        ),
    ] {
        let err = load_with_images(&format!(r#"<shape type="cube">{bsdf}</shape>"#)).unwrap_err().to_string();
        assert!(err.contains(expect), "{bsdf}: {err}");
        assert!(err.contains("s.xml:"), "the message names the file and line: {err}");
    }
    // No `.value` where a texture stands: Mitsuba's traversal names the texture's parameters.
    assert!(s.params.find("a.bsdf.specular_reflectance.value").is_none());
    assert_eq!(s.params.get(s.params.find("a.bsdf.specular_reflectance.data").unwrap()).len(), 3, "1×1 RGB");
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
            r#"<bsdf type="roughconductor"><texture type="checkerboard" name="alpha"><rgb name="color0" value="0.1, 0.2, 0.3"/></texture></bsdf>"#,
            "property 'color0' of 'checkerboard' must be a <float>",
        ),
        (
            r#"<bsdf type="roughconductor"><texture type="checkerboard" name="alpha"><float name="color0" value="1.5"/></texture></bsdf>"#,
            "'color0' must lie in [0, 1], got 1.5",
        ),
        (
            r#"<bsdf type="blendbsdf"><texture type="mesh_attribute" name="weight"><string name="name" value="face_weight"/></texture><bsdf type="diffuse"/><bsdf type="diffuse"/></bsdf>"#,
            "has no mesh attribute 'face_weight' (its attributes: none)",
        ),
    ];
    for (bsdf, expect) in cases {
        let err = load_with_images(&format!(r#"<shape type="cube">{bsdf}</shape>"#)).unwrap_err().to_string();
        assert!(err.contains(expect), "{bsdf}: {err}");
        assert!(err.contains("s.xml:"), "the message names the file and line: {err}");
    }
}

#[test]
fn issue_31_a_mask_reads_its_opacity_as_mitsuba_names_it() {
    let s = load_with_images(&format!(
        r#"<shape type="cube" id="a"><bsdf type="mask"><bsdf type="twosided"><bsdf type="diffuse"/></bsdf></bsdf></shape>
           <shape type="cube" id="b"><bsdf type="mask"><float name="opacity" value="0.25"/><bsdf type="roughconductor"/></bsdf></shape>
           <shape type="cube" id="c"><bsdf type="mask"><texture type="bitmap" name="opacity">{GREY}</texture><bsdf type="diffuse"/></bsdf></shape>
           <shape type="cube" id="d"><bsdf type="mask"><texture type="checkerboard" name="opacity"/><bsdf type="diffuse"/></bsdf></shape>"#
    ))
    .unwrap();
    let value = |name: &str| s.params.get(s.params.find(name).unwrap_or_else(|| panic!("{name} missing"))).to_vec();
    assert_eq!(value("a.bsdf.opacity.value"), [0.5], "Mitsuba's default");
    assert_eq!(value("b.bsdf.opacity.value"), [0.25]);
    assert_eq!(value("c.bsdf.opacity.data"), [0.0, 1.0]);
    assert_eq!(value("d.bsdf.opacity.color1.value"), [0.2]);
    for name in ["a.bsdf.nested_bsdf.brdf_0.reflectance.value", "b.bsdf.nested_bsdf.alpha.value"] {
        assert!(s.params.find(name).is_some(), "{name} missing");
    }
    let Material::Mask { nested, opacity } = s.materials[s.meshes[0].material.0 as usize] else { panic!("not a mask") };
    assert!(matches!(s.materials[nested.0 as usize], Material::TwoSided(_)));
    assert_eq!(opacity, s.params.find("a.bsdf.opacity.value").unwrap());
    // Flattened: the nested material with the opacity's slot (a texture's descriptor for c).
    let flat = crate::scene::flat::FlatScene::new(&s).unwrap();
    let m = &flat.materials[s.meshes[0].material.0 as usize];
    assert_eq!((m.tag, m.two_sided, m.p_opacity), (crate::contract::MAT_DIFFUSE, 1, s.params.entry(opacity).offset));
    let c = &flat.materials[s.meshes[2].material.0 as usize];
    assert_ne!(c.p_opacity & crate::contract::SCALAR_TEXTURE, 0);
    assert!(flat.materials.iter().filter(|m| m.p_opacity == crate::contract::NO_PARAM).count() >= 4);
}

#[test]
fn issue_31_masks_refuse_what_pathgrad_does_not_render_by_name() {
    let cases = [
        (r#"<bsdf type="mask"/>"#, "'mask' needs 1 nested BSDF, got 0"),
        (
            r#"<bsdf type="mask"><bsdf type="diffuse"/><bsdf type="diffuse"/></bsdf>"#,
            "'mask' needs 1 nested BSDF, got 2",
        ),
        (
            r#"<bsdf type="mask"><bsdf type="mask"><bsdf type="diffuse"/></bsdf></bsdf>"#,
            "a 'mask' around another 'mask'",
        ),
        (r#"<bsdf type="mask"><bsdf type="null"/></bsdf>"#, "a 'mask' around a 'null' BSDF"),
        (
            r#"<bsdf type="mask"><float name="opacity" value="1.5"/><bsdf type="diffuse"/></bsdf>"#,
            "'opacity' must lie in [0, 1]",
        ),
        (
            r#"<bsdf type="mask"><texture type="bitmap" name="opacity"><string name="filename" value="rgb.png"/></texture><bsdf type="diffuse"/></bsdf>"#,
            "is not grey (",
        ),
        (
            r#"<bsdf type="blendbsdf"><float name="weight" value="0.5"/><bsdf type="mask"><bsdf type="diffuse"/></bsdf><bsdf type="diffuse"/></bsdf>"#,
            "'blendbsdf' children must both be",
        ),
        (
            r#"<bsdf type="normalmap"><texture type="bitmap" name="normalmap"><string name="filename" value="rgb.png"/></texture><bsdf type="mask"><bsdf type="diffuse"/></bsdf></bsdf>"#,
            "a 'normalmap' around a 'mask' is not supported",
        ),
        (
            r#"<bsdf type="twosided"><bsdf type="mask"><bsdf type="dielectric"/></bsdf></bsdf>"#,
            "cannot wrap one that transmits light",
        ),
    ];
    for (bsdf, expect) in cases {
        let err = load_with_images(&format!(r#"<shape type="cube">{bsdf}</shape>"#)).unwrap_err().to_string();
        assert!(err.contains(expect), "{bsdf}: {err}");
        assert!(err.contains("s.xml:"), "the message names the file and line: {err}");
    }
    // Mitsuba's volpath family does not count a mask's pass-through as a bounce; pathgrad counts
    // as it does (Scene::null_uncounted), so a finite max_depth loads.
    let mask = r#"<shape type="cube"><bsdf type="mask"><bsdf type="diffuse"/></bsdf></shape>"#;
    let volpath = |depth: i32| {
        load_with_images(&format!(
            r#"<integrator type="volpath"><integer name="max_depth" value="{depth}"/></integrator>{mask}"#
        ))
    };
    assert!(volpath(6).unwrap().null_uncounted);
    assert!(volpath(-1).unwrap().null_uncounted);
    let path = load_with_images(&format!(
        r#"<integrator type="path"><integer name="max_depth" value="6"/></integrator>{mask}"#
    ))
    .unwrap();
    assert!(!path.null_uncounted);
}

#[test]
fn issue_31_the_differential_strategy_refuses_a_mask_by_name() {
    let s = load_with_images(
        r#"<shape type="cube" id="box"><bsdf type="mask"><bsdf type="twosided"><bsdf type="roughconductor"/></bsdf></bsdf></shape>"#,
    )
    .unwrap();
    for target in ["box.bsdf.opacity.value", "box.bsdf.nested_bsdf.brdf_0.alpha.value"] {
        let err = crate::integrator::Strategy::from_name(&s, "diff", 0.5, target).unwrap_err().to_string();
        assert!(err.contains("a mask's opacity or a masked material's parameter"), "{target}: {err}");
    }
}

#[test]
fn issue_31_the_differential_strategy_refuses_a_blend_holding_a_mirror_by_name() {
    let s = load_with_images(
        r#"<shape type="cube" id="box"><bsdf type="blendbsdf"><float name="weight" value="0.4"/><bsdf type="roughconductor"/><bsdf type="conductor"/></bsdf></shape>"#,
    )
    .unwrap();
    for target in ["box.bsdf.weight.value", "box.bsdf.bsdf_0.alpha.value"] {
        let err = crate::integrator::Strategy::from_name(&s, "diff", 0.5, target).unwrap_err().to_string();
        assert!(err.contains("a parameter of a blend holding a smooth conductor"), "{target}: {err}");
    }
    let weight = s.params.find("box.bsdf.weight.value").unwrap();
    assert!(!crate::integrator::Strategy::has_differential_sampler(&s, weight));
}

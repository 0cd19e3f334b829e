//! Mitsuba's `volume` texture on a diffuse reflectance and a conductor's specular reflectance:
//! what the loader binds (fields, names as Mitsuba 3.9.1's `traverse` gives them) and every
//! refusal with its location.

use std::path::Path;

use glam::{Mat4, UVec3, Vec3};

use super::loader::load_text;
use super::tests::{SENSOR, obj_for_tests};
use crate::scene::medium::Field;
use crate::scene::volume::Grid;
use crate::scene::{Albedo, Material, Scene, Wrap};

/// A folder with `colour.vol` (2×3×4, three channels, values in [0, 1]) and `density.vol`
/// (2×2×2, one channel, values 0 … 7: not reflectances).
fn grids() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    let colour = Grid::new(UVec3::new(2, 3, 4), 3, (0..72).map(|v| v as f32 / 72.0).collect()).unwrap();
    std::fs::write(dir.path().join("colour.vol"), colour.to_bytes()).unwrap();
    let density = Grid::new(UVec3::splat(2), 1, (0..8).map(|v| v as f32).collect()).unwrap();
    std::fs::write(dir.path().join("density.vol"), density.to_bytes()).unwrap();
    dir
}

fn load_in(dir: &Path, body: &str) -> crate::Result<Scene> {
    let text = format!(r#"<scene version="3.0.0">{SENSOR}<emitter type="constant"/>{body}</scene>"#);
    load_text(&text, &dir.join("test.xml"), &[], obj_for_tests)
}

/// A shape `s` whose BSDF is `bsdf`.
fn shape(bsdf: &str) -> String {
    format!(r#"<shape type="sphere" id="s">{bsdf}</shape>"#)
}

/// A `volume` texture named `reflectance` holding `volume`.
fn volume(inner: &str) -> String {
    format!(r#"<texture type="volume" name="reflectance">{inner}</texture>"#)
}

/// A grid binds its voxels as `SHAPE.bsdf.reflectance.volume.data` (Mitsuba 3.9.1's key for the
/// lego scene's texture is `main-bsdf.reflectance.volume.data`), its `to_world` inverted and its
/// wrap mode kept; an `<rgb>` binds a constant `….volume.value.value`; a texture declared once
/// at scene level and referred to by two shapes is one field.
#[test]
fn volume_texture_binds_a_field() {
    let dir = grids();
    let grid = volume(
        r#"<volume type="gridvolume" name="volume"><string name="filename" value="colour.vol"/>
            <string name="wrap_mode" value="mirror"/>
            <transform name="to_world"><scale value="2"/><translate x="1"/></transform></volume>"#,
    );
    let s = load_in(dir.path(), &shape(&format!(r#"<bsdf type="diffuse">{grid}</bsdf>"#))).unwrap();
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
    let Material::Diffuse { albedo: Albedo::Volume(0) } = s.materials[s.meshes[0].material.0 as usize] else {
        panic!("{:?}", s.materials)
    };
    let Field::Grid { resolution, channels, values, to_local, wrap } = s.volume_textures[0] else {
        panic!("{:?}", s.volume_textures)
    };
    assert_eq!((resolution, channels, wrap), (UVec3::new(2, 3, 4), 3, Wrap::Mirror));
    assert_eq!(s.params.entry(values).name, "s.bsdf.reflectance.volume.data");
    assert_eq!(s.params.get(values).len(), 72);
    let to_world = Mat4::from_translation(Vec3::X) * Mat4::from_scale(Vec3::splat(2.0));
    assert!(to_local.abs_diff_eq(to_world.inverse(), 1e-6), "{to_local}");

    let constant = volume(r#"<rgb name="volume" value="0.2, 0.3, 0.4"/>"#);
    let body = format!(
        r#"<texture type="volume" id="tex"><rgb name="volume" value="0.2, 0.3, 0.4"/></texture>
        {}<shape type="cube" id="t"><bsdf type="diffuse"><ref name="reflectance" id="tex"/></bsdf></shape>
        <shape type="cube" id="u"><bsdf type="diffuse"><ref name="reflectance" id="tex"/></bsdf></shape>"#,
        shape(&format!(r#"<bsdf type="diffuse">{constant}</bsdf>"#))
    );
    let s = load_in(dir.path(), &body).unwrap();
    assert_eq!(s.volume_textures.len(), 2, "{:?}", s.volume_textures);
    let Field::Constant { value, channels: 3 } = s.volume_textures[1] else { panic!("{:?}", s.volume_textures) };
    assert_eq!(s.params.entry(value).name, "s.bsdf.reflectance.volume.value.value");
    assert_eq!(s.params.get(value), [0.2, 0.3, 0.4]);
    let Field::Constant { value, .. } = s.volume_textures[0] else { panic!("{:?}", s.volume_textures) };
    // Mitsuba names a top-level texture reached through <ref> by its address: no stable key.
    assert!(s.params.entry(value).name.ends_with(".volume.value.value"), "{}", s.params.entry(value).name);
    let albedo = |shape: &str| match s.materials[s.meshes.iter().find(|m| m.name == shape).unwrap().material.0 as usize]
    {
        Material::Diffuse { albedo } => albedo,
        ref m => panic!("{m:?}"),
    };
    assert_eq!((albedo("t"), albedo("u")), (Albedo::Volume(0), Albedo::Volume(0)));
}

/// Every refusal names the file, the line and what is wrong: no `volume`, a `volume` texture on
/// a slot where pathgrad does not take it, values outside [0, 1], a nearest filter, a missing
/// file, an unknown volume plugin.
#[test]
fn volume_texture_refusals_are_located() {
    let dir = grids();
    let d = dir.path().display().to_string();
    let colour = r#"<volume type="gridvolume" name="volume"><string name="filename" value="colour.vol"/></volume>"#;
    let as_key = |key: &str| format!(r#"<texture type="volume" name="{key}">{colour}</texture>"#);
    let cases: Vec<(String, String)> = vec![
        (
            shape(&format!(r#"<bsdf type="diffuse">{}</bsdf>"#, volume(""))),
            "a 'volume' texture needs its 'volume'".into(),
        ),
        (
            shape(&format!(r#"<bsdf type="plastic">{}</bsdf>"#, as_key("diffuse_reflectance"))),
            "not supported as 'diffuse_reflectance' of 'plastic'".into(),
        ),
        (
            shape(&format!(r#"<bsdf type="roughplastic">{}</bsdf>"#, as_key("specular_reflectance"))),
            "not supported as 'specular_reflectance' of 'roughplastic'".into(),
        ),
        (
            shape(&format!(r#"<bsdf type="principled">{}</bsdf>"#, as_key("base_color"))),
            "not supported as 'base_color' of 'principled'".into(),
        ),
        // Slots the kernels could read but the conformance matrix does not compare.
        (
            shape(&format!(r#"<bsdf type="dielectric">{}</bsdf>"#, as_key("specular_reflectance"))),
            "not supported as 'specular_reflectance' of 'dielectric'".into(),
        ),
        (
            shape(&format!(r#"<bsdf type="dielectric">{}</bsdf>"#, as_key("specular_transmittance"))),
            "not supported as 'specular_transmittance' of 'dielectric'".into(),
        ),
        (
            shape(&format!(r#"<bsdf type="thindielectric">{}</bsdf>"#, as_key("specular_transmittance"))),
            "not supported as 'specular_transmittance' of 'thindielectric'".into(),
        ),
        (
            shape(&format!(r#"<bsdf type="roughdielectric">{}</bsdf>"#, as_key("specular_transmittance"))),
            "not supported as 'specular_transmittance' of 'roughdielectric'".into(),
        ),
        (
            shape(&format!(
                r#"<bsdf type="diffuse">{}</bsdf>"#,
                volume(
                    r#"<volume type="gridvolume" name="volume"><string name="filename" value="density.vol"/></volume>"#
                )
            )),
            "s.bsdf.reflectance.volume.data".into(),
        ),
        (
            shape(&format!(
                r#"<bsdf type="diffuse">{}</bsdf>"#,
                volume(
                    r#"<volume type="gridvolume" name="volume"><string name="filename" value="colour.vol"/><string name="filter_type" value="nearest"/></volume>"#
                )
            )),
            "filter_type 'nearest' is not supported".into(),
        ),
        (
            shape(&format!(
                r#"<bsdf type="diffuse">{}</bsdf>"#,
                volume(
                    r#"<volume type="gridvolume" name="volume"><string name="filename" value="none.vol"/></volume>"#
                )
            )),
            format!("{d}/none.vol"),
        ),
        (
            shape(&format!(r#"<bsdf type="diffuse">{}</bsdf>"#, volume(r#"<volume type="mesh" name="volume"/>"#))),
            "unsupported plugin 'mesh' (supported volumes: constvolume, gridvolume)".into(),
        ),
    ];
    for (body, expected) in cases {
        let e = load_in(dir.path(), &body).map(|_| ()).unwrap_err().to_string();
        assert!(e.contains(&format!("{d}/test.xml:")) || e.contains(&d), "{body}: {e}");
        assert!(e.contains(&expected), "{body}: {e}");
    }
}

/// A `volume` texture on a rough or smooth conductor's specular reflectance (issue 31): the slot
/// holds the field, its voxels are `SHAPE.bsdf.specular_reflectance.volume.data` (Mitsuba
/// 3.9.1's key), the smooth conductor's flattened slot names the field through a `TEX_VOLUME`
/// descriptor, and the scene asks for the kernels' volume-texture part.
#[test]
fn volume_texture_binds_a_conductor_colour() {
    let dir = grids();
    let colour = r#"<volume type="gridvolume" name="volume"><string name="filename" value="colour.vol"/></volume>"#;
    let as_key = |key: &str| format!(r#"<texture type="volume" name="{key}">{colour}</texture>"#);
    let body = format!(
        r#"<shape type="sphere" id="a"><bsdf type="roughconductor">{}</bsdf></shape>
           <shape type="sphere" id="c"><bsdf type="conductor">{}</bsdf></shape>"#,
        as_key("specular_reflectance"),
        as_key("specular_reflectance")
    );
    let s = load_in(dir.path(), &body).unwrap();
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
    for name in ["a.bsdf.specular_reflectance.volume.data", "c.bsdf.specular_reflectance.volume.data"] {
        assert_eq!(s.params.entry(s.params.find(name).expect(name)).len, 72, "{name}");
    }
    assert_eq!(s.volume_textures.len(), 2);
    let flat = crate::scene::flat::FlatScene::new(&s).unwrap();
    let features = crate::gpu::variant::scene_features(&flat, crate::contract::NO_PARAM);
    assert_ne!(features & crate::gpu::variant::word2(crate::contract::F2_VOLUME_TEXTURE), 0);
    // The smooth conductor's reflectance names field 1 (after the rough conductor's; no media).
    let slots: Vec<Option<u32>> = flat
        .materials
        .iter()
        .flat_map(crate::gpu::variant::specular_colour_slots)
        .map(|slot| crate::gpu::variant::colour_volume(&flat, slot))
        .collect();
    assert_eq!(slots, vec![Some(1)]);
}

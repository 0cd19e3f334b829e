//! Media in Mitsuba XML: names as Mitsuba 3.9.1's `traverse` gives them, fields, phase functions,
//! shared media, and every refusal with its location.

use std::path::Path;

use glam::{UVec3, Vec3};

use super::loader::load_text;
use super::tests::{SENSOR, obj_for_tests};
use crate::scene::Scene;
use crate::scene::medium::{Field, Phase};
use crate::scene::volume::Grid;

/// A folder with `density.vol` (4×4×4, one channel, value x + 4y + 16z at voxel (x, y, z)) and
/// `colour.vol` (2×3×4, three channels, all 0.5).
fn grids() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    let density = Grid::new(UVec3::splat(4), 1, (0..64).map(|v| v as f32).collect()).unwrap();
    std::fs::write(dir.path().join("density.vol"), density.to_bytes()).unwrap();
    let colour = Grid::new(UVec3::new(2, 3, 4), 3, vec![0.5; 72]).unwrap();
    std::fs::write(dir.path().join("colour.vol"), colour.to_bytes()).unwrap();
    dir
}

fn load_in(dir: &Path, body: &str) -> crate::Result<Scene> {
    let text = format!(r#"<scene version="3.0.0">{SENSOR}<emitter type="constant"/>{body}</scene>"#);
    load_text(&text, &dir.join("test.xml"), &[], obj_for_tests)
}

fn names(scene: &Scene) -> Vec<String> {
    scene.params.entries().iter().map(|e| e.name.clone()).collect()
}

const MEDIA: &str = r#"
<medium type="homogeneous" id="fog">
    <rgb name="sigma_t" value="0.1, 0.2, 0.3"/><rgb name="albedo" value="0.5, 0.5, 0.5"/>
    <float name="scale" value="2"/><phase type="hg"><float name="g" value="0.3"/></phase>
</medium>
<shape type="cube" id="box"><bsdf type="null"/><ref name="interior" id="fog"/>
    <transform name="to_world"><translate x="3"/></transform></shape>
<shape type="cube" id="box2"><ref name="interior" id="fog"/>
    <transform name="to_world"><translate x="6"/></transform></shape>
<shape type="cube" id="smoke"><bsdf type="null"/>
    <medium type="heterogeneous" name="interior">
        <volume type="gridvolume" name="sigma_t"><string name="filename" value="density.vol"/>
            <transform name="to_world"><scale value="2"/><translate x="-1" y="-1" z="-1"/></transform></volume>
        <volume type="gridvolume" name="albedo"><string name="filename" value="colour.vol"/><string name="wrap_mode" value="clamp"/></volume>
        <float name="scale" value="3"/>
    </medium>
</shape>
<shape type="sphere" id="c"><bsdf type="null"/><transform name="to_world"><translate x="-3"/></transform>
    <medium type="heterogeneous" name="interior"><float name="sigma_t" value="1"/>
        <volume type="constvolume" name="albedo"><rgb name="value" value="0.2, 0.3, 0.4"/></volume></medium></shape>
"#;

/// The parameter names are those Mitsuba 3.9.1's `mi.traverse` lists for the same file
/// (`fog.sigma_t.value.value`, `smoke.interior_medium.sigma_t.data`, …; `tests_names` compares
/// such scenes with Mitsuba's lists), in its default load's order: the sphere `c` before the
/// meshes; a medium two shapes refer to is one medium; values, channels and the grid's placement
/// are the file's.
#[test]
fn media_load_with_mitsubas_names() {
    let dir = grids();
    let scene = load_in(dir.path(), MEDIA).unwrap();
    let expected = [
        "_unnamed_0.radiance.value",
        "c.interior_medium.sigma_t.value.value",
        "c.interior_medium.albedo.value.value",
        "c.interior_medium.scale",
        "fog.sigma_t.value.value",
        "fog.albedo.value.value",
        "fog.scale",
        "fog.phase_function.g",
        "box2.bsdf.reflectance.value",
        "smoke.interior_medium.sigma_t.data",
        "smoke.interior_medium.albedo.data",
        "smoke.interior_medium.scale",
    ];
    assert_eq!(names(&scene), expected);
    assert_eq!(scene.media.len(), 3);
    let interior: Vec<Option<u32>> = scene.meshes.iter().map(|m| m.interior.map(|i| i.0)).collect();
    assert_eq!(interior, [Some(1), Some(1), Some(2), Some(0)]);
    let fog = &scene.media[1];
    assert!(!fog.heterogeneous);
    assert!(matches!(fog.phase, Phase::HenyeyGreenstein { .. }));
    assert_eq!(fog.sigma_t.channels(), 3);
    assert_eq!(fog.extinction(&scene.params, Vec3::ZERO, 2), 0.6);
    assert_eq!(fog.majorant(&scene.params), 0.6 * (1.0 + crate::contract::MAJORANT_MARGIN));
    let smoke = &scene.media[2];
    assert!(smoke.heterogeneous && smoke.phase == Phase::Isotropic);
    let Field::Grid { resolution, channels, .. } = smoke.sigma_t else { panic!("{:?}", smoke.sigma_t) };
    assert_eq!((resolution, channels), (UVec3::splat(4), 1));
    // to_world maps the unit cube onto [−1, 1]³: the world point (−1 + 2·(x + ½)/4, …) is the
    // centre of voxel (x, y, z), where the lookup gives the voxel's value, times scale 3.
    let centre = |x: f32, y: f32, z: f32| Vec3::new(x, y, z).map(|c| -1.0 + 2.0 * (c + 0.5) / 4.0);
    assert_eq!(smoke.extinction(&scene.params, centre(1.0, 2.0, 3.0), 0), 3.0 * (1.0 + 8.0 + 48.0));
    assert_eq!(smoke.majorant(&scene.params), 3.0 * 63.0 * (1.0 + crate::contract::MAJORANT_MARGIN));
    assert_eq!(smoke.albedo.channels(), 3);
    let c = &scene.media[0];
    assert_eq!(c.sigma_t.channels(), 1);
    assert_eq!(c.albedo.eval(&scene.params, Vec3::ZERO, 1), 0.3);
}

/// Such a scene flattens: its media and fields, and a null boundary alone needs the media code.
#[test]
fn media_flatten() {
    let dir = grids();
    let scene = load_in(dir.path(), MEDIA).unwrap();
    let flat = crate::scene::flat::FlatScene::new(&scene).unwrap();
    assert_eq!((flat.media.len(), flat.fields.len()), (3, 6));
    assert_eq!(flat.media[2].majorant, 3.0 * 63.0 * (1.0 + crate::contract::MAJORANT_MARGIN));
    let null_only = load_in(dir.path(), r#"<shape type="cube" id="glass"><bsdf type="null"/></shape>"#).unwrap();
    let flat = crate::scene::flat::FlatScene::new(&null_only).unwrap();
    assert!(flat.media.is_empty() && crate::cpu::medium::has_media(&flat));
}

/// Every refusal names the file, line and what is wrong.
#[test]
fn bad_media_are_refused_with_their_location() {
    let dir = grids();
    let d = dir.path().display().to_string();
    std::fs::write(
        dir.path().join("short.vol"),
        &Grid::new(UVec3::splat(2), 1, vec![1.0; 8]).unwrap().to_bytes()[..30],
    )
    .unwrap();
    let shape = |medium: &str| format!(r#"<shape type="cube" id="s"><bsdf type="null"/>{medium}</shape>"#);
    let cases: Vec<(String, String)> = vec![
        (
            shape(r#"<medium type="fog" name="interior"/>"#),
            "unsupported plugin 'fog' (supported media: homogeneous, heterogeneous)".into(),
        ),
        (
            shape(r#"<medium type="homogeneous" name="interior"><volume type="mesh" name="sigma_t"/></medium>"#),
            "unsupported plugin 'mesh' (supported volumes: constvolume, gridvolume)".into(),
        ),
        (
            shape(r#"<medium type="homogeneous" name="interior"><phase type="rayleigh"/></medium>"#),
            "unsupported plugin 'rayleigh' (supported phases: isotropic, hg)".into(),
        ),
        (
            shape(
                r#"<medium type="homogeneous" name="interior"><phase type="hg"><float name="g" value="1"/></phase></medium>"#,
            ),
            "'g' must lie in (-1, 1), got 1".into(),
        ),
        (
            shape(r#"<medium type="homogeneous" name="interior"><float name="albedo" value="1.5"/></medium>"#),
            "s.interior_medium.albedo.value.value".into(),
        ),
        (shape(r#"<medium type="homogeneous" name="exterior"/>"#), "exterior media are not supported".into()),
        (
            shape(
                r#"<medium type="heterogeneous" name="interior"><volume type="gridvolume" name="sigma_t"><string name="filename" value="density.vol"/><string name="wrap_mode" value="tile"/></volume></medium>"#,
            ),
            "'wrap_mode' must be 'repeat', 'mirror' or 'clamp', got 'tile'".into(),
        ),
        (
            shape(
                r#"<medium type="heterogeneous" name="interior"><volume type="gridvolume" name="sigma_t"><string name="filename" value="none.vol"/></volume></medium>"#,
            ),
            format!("{d}/none.vol"),
        ),
        (
            shape(
                r#"<medium type="heterogeneous" name="interior"><volume type="gridvolume" name="sigma_t"><string name="filename" value="short.vol"/></volume></medium>"#,
            ),
            format!("{d}/short.vol"),
        ),
        (
            shape(
                r#"<medium type="heterogeneous" name="interior"><volume type="gridvolume" name="albedo"><string name="filename" value="density.vol"/></volume></medium>"#,
            ),
            "s.interior_medium.albedo.data".into(),
        ),
        (
            shape(
                r#"<medium type="heterogeneous" name="interior"><volume type="gridvolume" name="sigma_t"><string name="filename" value="density.vol"/><string name="filter_type" value="nearest"/></volume></medium>"#,
            ),
            "filter_type 'nearest' is not supported".into(),
        ),
        (shape(r#"<ref name="interior" id="nothing"/>"#), "reference to unknown id 'nothing'".into()),
    ];
    for (body, expected) in cases {
        let e = load_in(dir.path(), &body).map(|_| ()).unwrap_err().to_string();
        assert!(e.contains(&format!("{d}/test.xml:")) || e.contains(&d), "{body}: {e}");
        assert!(e.contains(&expected), "{body}: {e}");
    }
    // A sensor inside a shape with a medium (the unit cube around the origin holds SENSOR's
    // camera once scaled up).
    let around = r#"<shape type="cube" id="room"><bsdf type="null"/><medium type="homogeneous" name="interior"/>
        <transform name="to_world"><scale value="100"/></transform></shape>"#;
    let e = load_in(dir.path(), around).map(|_| ()).unwrap_err().to_string();
    assert!(e.contains("inside the medium of shape 'room'") && e.contains("test.xml:"), "{e}");
}

/// Shapes with interior media that nest or cut into each other are refused, naming both and
/// where they are; shapes that only touch (a shared face) or lie apart load.
#[test]
fn overlapping_media_are_refused() {
    let dir = grids();
    let cube = |id: &str, transform: &str| {
        format!(
            r#"<shape type="cube" id="{id}"><bsdf type="null"/><medium type="homogeneous" name="interior"/>
            <transform name="to_world">{transform}</transform></shape>"#
        )
    };
    let refused = |body: String, inner: &str, outer: &str| {
        let e = load_in(dir.path(), &body).map(|_| ()).unwrap_err().to_string();
        assert!(
            e.contains(&format!("shape '{inner}' and shape '{outer}'"))
                && e.contains("nested or intersecting media are not supported")
                && e.matches("test.xml:").count() == 2,
            "{e}"
        );
    };
    // A small box inside a large one (the sensor is outside both).
    refused(cube("outer", r#"<scale value="2"/>"#) + &cube("inner", r#"<scale value="0.5"/>"#), "inner", "outer");
    // Two boxes cutting into each other.
    refused(cube("a", "") + &cube("b", r#"<translate x="1"/>"#), "b", "a");
    // Side by side, sharing the face x = 1, and far apart: both load.
    for shift in ["2", "5"] {
        let body = cube("a", "") + &cube("b", &format!(r#"<translate x="{shift}"/>"#));
        load_in(dir.path(), &body).unwrap();
    }
}

/// A `null` BSDF under `path`, `prb` or no integrator (Mitsuba's default, path) is rendered as
/// volpath renders it, with a warning at the integrator (or the scene) that Mitsuba's path image
/// differs; under a volpath-family integrator, and without a null BSDF, there is no such warning.
#[test]
fn a_null_bsdf_outside_volpath_is_rendered_as_volpath_with_a_warning() {
    let dir = tempfile::tempdir().unwrap();
    let null = r#"<shape type="sphere"><bsdf type="null"/></shape>"#;
    let warned = |integrator: &str, shape: &str| {
        let scene = load_in(dir.path(), &format!("{integrator}{shape}")).unwrap();
        scene.warnings.iter().any(|w| w.to_string().contains("a 'null' BSDF under Mitsuba's path or prb integrator"))
    };
    assert!(warned("", null));
    assert!(warned(r#"<integrator type="path"/>"#, null));
    assert!(warned(r#"<integrator type="prb"/>"#, null));
    assert!(!warned(r#"<integrator type="volpath"/>"#, null));
    assert!(!warned(r#"<integrator type="prbvolpath"/>"#, null));
    assert!(!warned(r#"<integrator type="path"/>"#, r#"<shape type="sphere"><bsdf type="diffuse"/></shape>"#));
}

//! The scene file as Mitsuba 3.9.1 reads it: `<include>`, `<path>`, repeated `<default>`s,
//! references to objects declared at scene level (samplers, area emitters), and the integrators
//! and samplers pathgrad renders in another's place; errors located in the file where they are.

use std::path::Path;

use glam::Vec3;

use super::loader::load_text;
use super::tests::{SENSOR, obj_for_tests};
use crate::scene::{LoadOptions, Scene};

fn write(dir: &Path, name: &str, text: &str) {
    let path = dir.join(name);
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(path, text).unwrap();
}

fn load(dir: &Path, defines: &[(&str, &str)], allow_outside: bool) -> crate::Result<Scene> {
    let options = LoadOptions {
        defines: defines.iter().map(|(n, v)| (n.to_string(), v.to_string())).collect(),
        allow_outside_folder: allow_outside,
        ..LoadOptions::default()
    };
    super::load_with(&dir.join("main.xml"), &options)
}

const QUAD: &str = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n";

/// `main.xml` names `<path value="lib"/>` and includes `parts.xml` (found in `lib/`), which
/// includes `more/ball.xml` (found in `lib/` too) and names `meshes/quad.obj` (in `lib/`).
fn library(dir: &Path, main_defaults: &str) {
    write(
        dir,
        "main.xml",
        &format!(
            r#"<scene version="3.0.0">{main_defaults}
    <path value="lib"/>
    {SENSOR}
    <include filename="parts.xml"/>
    <emitter type="constant"/>
</scene>"#
        ),
    );
    write(
        dir,
        "lib/parts.xml",
        r#"<?xml version="1.0"?>
<scene version="3.0.0">
    <default name="r" value="0.25"/>
    <shape type="obj" id="quad">
        <string name="filename" value="meshes/quad.obj"/>
        <bsdf type="diffuse"><rgb name="reflectance" value="$r"/></bsdf>
    </shape>
    <include filename="more/ball.xml"/>
</scene>"#,
    );
    write(dir, "lib/meshes/quad.obj", QUAD);
    write(dir, "lib/more/ball.xml", r#"<scene version="3.0.0"><shape type="sphere" id="ball"/></scene>"#);
}

fn reflectance(scene: &Scene) -> Vec<f32> {
    scene.params.get(scene.params.find("quad.bsdf.reflectance.value").unwrap()).to_vec()
}

#[test]
fn includes_and_paths_splice_and_resolve_as_mitsuba() {
    let dir = tempfile::tempdir().unwrap();
    library(dir.path(), "");
    let scene = load(dir.path(), &[], false).unwrap();
    let names: Vec<&str> = scene.meshes.iter().map(|m| m.name.as_str()).collect();
    assert_eq!(names, ["quad", "ball"]);
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
    // The included default holds where nothing earlier names `r` ...
    assert_eq!(reflectance(&scene), [0.25; 3]);
    // ... the first default of a name wins, wherever it is (Mitsuba keeps the first) ...
    library(dir.path(), r#"<default name="r" value="0.5"/>"#);
    assert_eq!(reflectance(&load(dir.path(), &[], false).unwrap()), [0.5; 3]);
    // ... and -D over both.
    assert_eq!(reflectance(&load(dir.path(), &[("r", "0.75")], false).unwrap()), [0.75; 3]);
}

#[test]
fn errors_in_an_included_file_name_that_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    library(dir.path(), "");
    write(
        dir.path(),
        "lib/more/ball.xml",
        "<scene version=\"3.0.0\">\n  <shape type=\"sphere\" id=\"ball\">\n    <float name=\"radiuss\" value=\"1\"/>\n  </shape>\n</scene>",
    );
    // The scene file's own lines keep their numbers after the spliced text.
    let main = dir.path().join("main.xml");
    let text = std::fs::read_to_string(&main).unwrap();
    std::fs::write(
        &main,
        text.replace(
            r#"<emitter type="constant"/>"#,
            r#"<emitter type="constant"><float name="scal" value="1"/></emitter>"#,
        ),
    )
    .unwrap();
    let scene = load(dir.path(), &[], false).unwrap();
    let ball = dir.path().join("lib/more/ball.xml");
    assert_eq!(scene.warnings[1], format!("{}:5:30: unknown property 'scal' of 'constant' ignored", main.display()));
    let scene = Scene { warnings: scene.warnings[..1].to_vec(), ..scene };
    assert_eq!(scene.warnings, [format!("{}:3:5: unknown property 'radiuss' of 'sphere' ignored", ball.display())]);

    write(dir.path(), "lib/more/ball.xml", "<scene version=\"3.0.0\">\n  <shape type=\"sphere\">\n</scene>");
    let err = load(dir.path(), &[], false).unwrap_err().to_string();
    let parts = dir.path().join("lib/parts.xml");
    assert!(
        err.starts_with(&format!("{}:3:1: malformed XML (included at {}:8:5)", ball.display(), parts.display())),
        "{err}"
    );
}

#[test]
fn bad_includes_and_paths_are_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    library(dir.path(), "");
    let main = dir.path().join("main.xml");
    let parts = dir.path().join("lib/parts.xml");
    // A cycle.
    write(dir.path(), "lib/more/ball.xml", r#"<scene version="3.0.0"><include filename="parts.xml"/></scene>"#);
    let err = load(dir.path(), &[], false).unwrap_err().to_string();
    assert!(err.ends_with("<include>: 'parts.xml' includes itself"), "{err}");
    // A missing file.
    write(dir.path(), "lib/more/ball.xml", r#"<scene version="3.0.0"><include filename="nowhere.xml"/></scene>"#);
    let err = load(dir.path(), &[], false).unwrap_err().to_string();
    assert!(err.contains("<include>: included file 'nowhere.xml' not found"), "{err}");
    // Not a scene.
    write(dir.path(), "lib/more/ball.xml", r#"<shape type="sphere"/>"#);
    let err = load(dir.path(), &[], false).unwrap_err().to_string();
    assert!(
        err.contains(&format!("an included file's root element must be <scene> (included at {}:8:5)", parts.display())),
        "{err}"
    );
    // A missing folder, and one outside the scene's folder unless allowed.
    library(dir.path(), "");
    let text = std::fs::read_to_string(&main).unwrap();
    std::fs::write(&main, text.replace(r#"<path value="lib"/>"#, r#"<path value="nothing"/>"#)).unwrap();
    let err = load(dir.path(), &[], false).unwrap_err().to_string();
    assert!(err.contains(&format!("{}:2:5: <path>: folder 'nothing' not found", main.display())), "{err}");
    let outside = tempfile::tempdir().unwrap();
    library(outside.path(), "");
    let text = std::fs::read_to_string(outside.path().join("main.xml")).unwrap();
    let lib = dir.path().join("lib");
    std::fs::remove_dir_all(outside.path().join("lib")).unwrap();
    let relative = format!("../{}/lib", dir.path().file_name().unwrap().to_string_lossy());
    std::fs::write(outside.path().join("main.xml"), text.replace(r#"value="lib""#, &format!(r#"value="{relative}""#)))
        .unwrap();
    let err = load(outside.path(), &[], false).unwrap_err().to_string();
    assert!(err.contains("<path>: ") && err.contains("climbs out of the scene's folder"), "{err}");
    assert!(lib.is_dir());
    let scene = load(outside.path(), &[], true).unwrap();
    assert_eq!(scene.meshes.len(), 2);
}

fn text(body: &str) -> crate::Result<Scene> {
    load_text(&format!(r#"<scene version="3.0.0">{body}</scene>"#), Path::new("s.xml"), &[], obj_for_tests)
}

const LIGHT: &str = r#"<shape type="rectangle" id="light"><emitter type="area"/></shape>"#;

#[test]
fn wrapped_and_direct_integrators_render_their_path_tracer() {
    let moment = text(&format!(
        r#"{SENSOR}{LIGHT}<integrator type="moment"><integrator type="path"><integer name="max_depth" value="3"/></integrator></integrator>"#
    ))
    .unwrap();
    assert_eq!(moment.max_depth, 3);
    assert_eq!(
        moment.warnings,
        [format!(
            "s.xml:1:{}: 'moment' integrator: pathgrad renders the integrator nested in it (the same image; no \
             second-moment channels)",
            23 + SENSOR.len() + LIGHT.len() + 1
        )]
    );
    let aov = text(&format!(
        r#"{SENSOR}{LIGHT}<integrator type="aov"><string name="aovs" value="dd.y:depth"/><integrator type="direct"/></integrator>"#
    ))
    .unwrap();
    assert_eq!(aov.max_depth, 2);
    assert_eq!(aov.warnings.len(), 2, "{:?}", aov.warnings);
    assert!(
        aov.warnings[0].ends_with(
            "'aov' integrator: pathgrad renders the integrator nested in it (the same image; no AOV channels)"
        )
    );
    assert!(
        aov.warnings[1]
            .ends_with("'direct' integrator: rendered as a path tracer of max_depth 2 (the same image, other noise)")
    );
    let empty = text(&format!(r#"{SENSOR}{LIGHT}<integrator type="moment"/>"#)).unwrap_err().to_string();
    assert!(empty.ends_with("'moment' needs a nested <integrator>"), "{empty}");
    let unknown = text(&format!(r#"{SENSOR}{LIGHT}<integrator type="depth"/>"#)).unwrap_err().to_string();
    assert!(unknown.contains("unsupported plugin 'depth'"), "{unknown}");
}

#[test]
fn particle_and_projective_integrators_render_as_path_tracers_and_say_where_they_differ() {
    let ptracer = text(&format!(
        r#"{SENSOR}{LIGHT}<integrator type="ptracer"><integer name="max_depth" value="4"/><integer name="samples_per_pass" value="8"/></integrator>"#
    ))
    .unwrap();
    assert_eq!(ptracer.max_depth, 4);
    assert_eq!(ptracer.warnings.len(), 1, "{:?}", ptracer.warnings);
    assert!(ptracer.warnings[0].ends_with(
        "'ptracer' integrator: rendered as a path tracer of the same max_depth (the same image, other noise)"
    ));
    // A mirror: what the camera sees in it is black in Mitsuba's particle tracer.
    let mirror = text(&format!(
        r#"{SENSOR}{LIGHT}<integrator type="ptracer"/><shape type="rectangle"><bsdf type="conductor"/></shape>"#
    ))
    .unwrap();
    assert_eq!(mirror.warnings.len(), 2, "{:?}", mirror.warnings);
    assert!(
        mirror.warnings[1].contains("renders what the camera sees in or through one black"),
        "{:?}",
        mirror.warnings
    );
    let medium = text(&format!(
        r#"{SENSOR}{LIGHT}<integrator type="ptracer"/><shape type="cube"><bsdf type="null"/><medium type="homogeneous" name="interior"/></shape>"#
    ))
    .unwrap_err()
    .to_string();
    assert!(medium.contains("'ptracer' with a participating medium"), "{medium}");

    let prb = text(&format!(
        r#"{SENSOR}{LIGHT}<integrator type="prb_projective"><integer name="max_depth" value="5"/><integer name="sppc" value="16"/><string name="guiding" value="grid"/><boolean name="guiding_proj" value="false"/></integrator>"#
    ))
    .unwrap();
    assert_eq!(prb.max_depth, 5);
    assert_eq!(prb.warnings.len(), 1, "{:?}", prb.warnings);
    assert!(prb.warnings[0].contains("'prb_projective' integrator: rendered as prb"), "{:?}", prb.warnings);
    let direct = text(&format!(
        r#"{SENSOR}{LIGHT}<integrator type="direct_projective"><integer name="sppp" value="4"/></integrator>"#
    ))
    .unwrap();
    assert_eq!(direct.max_depth, 2);
    assert_eq!(direct.warnings.len(), 1, "{:?}", direct.warnings);
    assert!(direct.warnings[0].contains("'direct_projective' integrator: rendered as a path tracer of max_depth 2"));
    let wrong = text(&format!(
        r#"{SENSOR}{LIGHT}<integrator type="direct_projective"><string name="sppc" value="many"/></integrator>"#
    ))
    .unwrap_err()
    .to_string();
    assert!(wrong.contains("sppc"), "{wrong}");
}

#[test]
fn a_sensor_refers_to_a_scene_level_sampler_and_other_samplers_draw_independently() {
    let sensor = SENSOR.replace("</sensor>", r#"<ref id="s"/></sensor>"#);
    let scene = text(&format!(
        r#"<sampler type="stratified" id="s"><integer name="sample_count" value="36"/><boolean name="jitter" value="false"/></sampler>{sensor}{LIGHT}"#
    ))
    .unwrap();
    assert_eq!(scene.default_spp, Some(36));
    assert_eq!(
        scene.warnings,
        ["s.xml:1:24: sampler 'stratified' is drawn as 'independent' (the same expectation, other noise)"]
    );
    let other = text(&format!(r#"<sampler type="sobol" id="s"/>{sensor}{LIGHT}"#)).unwrap_err().to_string();
    assert!(other.contains("unsupported plugin 'sobol'"), "{other}");
    // Without an id there is nothing to refer to it by.
    let loose = text(&format!(r#"<sampler type="independent"/>{SENSOR}{LIGHT}"#)).unwrap_err().to_string();
    assert!(loose.ends_with("a <sampler> must be inside a <sensor>"), "{loose}");
}

#[test]
fn a_shape_refers_to_a_scene_level_area_emitter_named_by_its_id() {
    let emitter = r#"<emitter type="area" id="lamp"><rgb name="radiance" value="2, 3, 4"/></emitter>"#;
    let scene =
        text(&format!(r#"{SENSOR}{emitter}<shape type="rectangle" id="panel"><ref id="lamp"/></shape>"#)).unwrap();
    let names: Vec<&str> = scene.params.entries().iter().map(|e| e.name.as_str()).collect();
    assert_eq!(names, ["panel.bsdf.reflectance.value", "lamp.radiance.value"]);
    assert!(scene.meshes[0].emitter.is_some());
    let twice = text(&format!(
        r#"{SENSOR}{emitter}<shape type="rectangle"><ref id="lamp"/></shape><shape type="sphere"><ref id="lamp"/></shape>"#
    ))
    .unwrap_err()
    .to_string();
    assert!(twice.ends_with("this area emitter is attached to another shape already"), "{twice}");
    let alone = text(&format!(r#"{SENSOR}{emitter}{LIGHT}"#)).unwrap_err().to_string();
    assert!(alone.ends_with("an 'area' emitter must be nested in a <shape> or referred to by one"), "{alone}");
}

#[test]
fn an_environment_option_replaces_the_scenes_own_constant_environment() {
    let options = LoadOptions { environment: Some([3.0, 2.0, 1.0]), ..LoadOptions::default() };
    let text =
        format!(r#"<scene version="3.0.0">{SENSOR}<emitter type="constant" id="sky"/><shape type="cube"/></scene>"#);
    let scene = super::loader::load_text_with(&text, Path::new("e.xml"), &options, obj_for_tests).unwrap();
    let sky = scene.params.find("sky.radiance.value").unwrap();
    assert_eq!(scene.params.get(sky), [3.0, 2.0, 1.0]);
    assert_eq!(scene.environment, Some(sky));
    assert_eq!(
        scene.warnings,
        [
            "the scene's own environment 'sky.radiance.value' takes the radiance [3.0, 2.0, 1.0] of LoadOptions::environment"
        ]
    );
}

#[test]
fn a_pinholes_focus_distance_is_accepted_silently() {
    let sensor =
        SENSOR.replace("<float name=\"fov\"", "<float name=\"focus_distance\" value=\"6\"/><float name=\"fov\"");
    let scene = text(&format!("{sensor}{LIGHT}")).unwrap();
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
}

#[test]
fn a_cylinder_spans_p0_to_p1_with_outward_normals() {
    let shape = r#"<shape type="cylinder" id="c"><point name="p0" value="0, -1, 0"/><point name="p1" value="0, 1, 0"/><float name="radius" value="0.5"/></shape>"#;
    let scene = text(&format!("{SENSOR}{LIGHT}{shape}")).unwrap();
    let mesh = scene.meshes.iter().find(|m| m.name == "c").unwrap();
    let normals = mesh.normals.as_ref().unwrap();
    for (p, n) in mesh.positions.iter().zip(normals) {
        assert!((p.y.abs() - 1.0).abs() < 1e-6 && (Vec3::new(p.x, 0.0, p.z).length() - 0.5).abs() < 1e-6, "{p}");
        assert!((*n - Vec3::new(p.x, 0.0, p.z) * 2.0).length() < 1e-5, "{p} {n}");
    }
    for t in &mesh.indices {
        let [a, b, c] = t.map(|i| mesh.positions[i as usize]);
        let centre = (a + b + c) / 3.0;
        assert!((b - a).cross(c - a).dot(Vec3::new(centre.x, 0.0, centre.z)) > 0.0, "counter-clockwise from outside");
    }
    let same = r#"<shape type="cylinder"><point name="p0" value="1, 1, 1"/><point name="p1" value="1, 1, 1"/></shape>"#;
    let err = text(&format!("{SENSOR}{LIGHT}{same}")).unwrap_err().to_string();
    assert!(err.ends_with("a cylinder's p0 and p1 must differ"), "{err}");
}

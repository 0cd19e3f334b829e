//! `<include>`, `<path>` and repeated `<default>`s as Mitsuba 3.9.1 reads them, and their errors
//! located in the file where they are.

use std::path::Path;

use super::tests::SENSOR;
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
    let scene = load(dir.path(), &[], false).unwrap();
    let ball = dir.path().join("lib/more/ball.xml");
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

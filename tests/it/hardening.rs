//! What an adversarial new user found (issue "Hardening"): each case failed before its fix.

use std::path::Path;
use std::process::{Output, Stdio};

use crate::cli::pathgrad;

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn ok(o: &Output) {
    assert!(o.status.success(), "status {:?}: {}", o.status, stderr(o));
}

/// The files and directories directly in `dir`, sorted.
fn names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> =
        std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().into_string().unwrap()).collect();
    v.sort();
    v
}

/// `scenes/blend/blend.xml` with the blend material's id replaced by `id` (XML-escaped here).
fn blend_scene_with_id(dir: &Path, id: &str) -> std::path::PathBuf {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(root.join("scenes/blend/blend.xml")).unwrap();
    let escaped = id.replace('&', "&amp;").replace('"', "&quot;").replace('\n', "&#10;");
    let text = text.replace(r#"id="object""#, &format!(r#"id="{escaped}""#));
    let path = dir.join("blend.xml");
    std::fs::write(&path, text).unwrap();
    path
}

/// A parameter named from an XML id with a comma, a quote and a line break keeps its CSV column,
/// and `--resume` reads the file back.
#[test]
fn history_csv_quotes_awkward_parameter_names_and_resumes() {
    let dir = tempfile::tempdir().unwrap();
    let id = "obj, \"x\"\ny";
    let scene = blend_scene_with_id(dir.path(), id);
    let out = dir.path().join("run");
    let base = ["--width", "16", "--spp-primal", "1", "--spp-grad", "1", "--spp", "2"];
    let o = pathgrad()
        .arg("optimize")
        .arg(&scene)
        .args(["--target-set", "*.weight.value=0.4", "--param", "*.weight.value=0.8", "--iters", "2", "-o"])
        .arg(&out)
        .args(base)
        .output()
        .unwrap();
    ok(&o);
    let o = pathgrad().args(["optimize", "--resume"]).arg(&out).args(["--iters", "3"]).output().unwrap();
    ok(&o);
    let mut reader = csv::Reader::from_path(out.join("history.csv")).unwrap();
    let header: Vec<String> = reader.headers().unwrap().iter().map(String::from).collect();
    let name = format!("{id}.weight.value");
    assert_eq!(header[3], name, "{header:?}");
    assert_eq!(header[4], format!("error[{name}]"));
    let rows: Vec<csv::StringRecord> = reader.records().map(Result::unwrap).collect();
    assert_eq!(rows.len(), 3);
    for (t, row) in rows.iter().enumerate() {
        assert_eq!(row.len(), header.len());
        assert_eq!(&row[0], t.to_string());
    }
}

/// Two runs started together into one directory: exactly one of them runs there, and its history
/// is whole (before, both exited 0 and one history was lost).
#[test]
fn two_optimize_runs_never_share_a_directory() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let spawn = || {
        pathgrad()
            .args(["optimize", "builtin:blend", "--target-set", "object.weight.value=0.4"])
            .args(["--param", "object.weight.value=0.8", "--width", "16", "--spp-primal", "1", "--spp-grad", "1"])
            .args(["--spp", "2", "--iters", "12", "-o"])
            .arg(&out)
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap()
    };
    let (a, b) = (spawn(), spawn());
    let outputs = [a.wait_with_output().unwrap(), b.wait_with_output().unwrap()];
    let succeeded: Vec<&Output> = outputs.iter().filter(|o| o.status.success()).collect();
    assert_eq!(succeeded.len(), 1, "{:?}", outputs.iter().map(stderr).collect::<Vec<_>>());
    let failed = outputs.iter().find(|o| !o.status.success()).unwrap();
    let message = stderr(failed);
    assert!(
        message.contains("another pathgrad optimize is running") || message.contains("already holds a run"),
        "{message}"
    );
    let text = std::fs::read_to_string(out.join("history.csv")).unwrap();
    assert_eq!(text.lines().count(), 13, "a header and 12 rows, numbered once: {text}");
    assert!(!names(&out).iter().any(|n| n.ends_with(".tmp")), "{:?}", names(&out));
}

/// A failing command leaves nothing new behind: options and output paths are checked before
/// anything renders (`--device 99`, which does not exist, shows that the check came first).
#[test]
fn bad_outputs_and_options_fail_before_rendering_and_leave_nothing() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir(dir.path().join("x.png")).unwrap();
    let render = ["render", "builtin:cornell-box", "--width", "8", "--spp", "1", "--device", "99"];
    let cases: [(&[&str], &str); 5] = [
        (&["-o", "x.exr", "--exposure", "nan"], "invalid --exposure NaN"),
        (&["-o", "x.exr"], "x.png: is a directory"),
        (&["-o", "/nonexistent/x.exr"], "/nonexistent/x.exr: the directory /nonexistent does not exist"),
        (&["-o", "/dev/null"], "must end in .exr or .png"),
        (&["-o", "d.exr", "--exposure", "inf"], "invalid --exposure inf"),
    ];
    for (args, message) in cases {
        let o = pathgrad().current_dir(dir.path()).args(render).args(args).output().unwrap();
        let e = stderr(&o);
        assert!(!o.status.success() && e.contains(message), "{args:?}: expected '{message}' in: {e}");
        assert_eq!(names(dir.path()), ["x.png"], "{args:?} left a file");
    }
    let grad = ["grad", "builtin:cornell-box", "--device", "99", "--target-set", "sphere.bsdf.alpha.value=0.2"];
    let o = pathgrad().args(grad).args(["--param", "typo"]).output().unwrap();
    assert!(stderr(&o).contains("--param: invalid typo: matches no parameter"), "{}", stderr(&o));
    let o =
        pathgrad().args(grad).args(["--param", "sphere.bsdf.alpha.value", "--target-set", "typo=1"]).output().unwrap();
    assert!(stderr(&o).contains("--target-set: invalid typo"), "{}", stderr(&o));
    let o = pathgrad()
        .current_dir(dir.path())
        .args([
            "grad",
            "builtin:cornell-box",
            "--device",
            "99",
            "--image-gradient",
            "sphere.bsdf.alpha.value",
            "-o",
            "x.exr",
        ])
        .output()
        .unwrap();
    assert!(stderr(&o).contains("x.png: is a directory"), "{}", stderr(&o));
    assert_eq!(names(dir.path()), ["x.png"]);
}

/// Negative exposures are values, not flags.
#[test]
fn a_negative_exposure_is_accepted() {
    let dir = tempfile::tempdir().unwrap();
    let o = pathgrad()
        .current_dir(dir.path())
        .args(["render", "builtin:cornell-box", "--width", "8", "--spp", "1", "-o", "a.png", "--exposure", "-2"])
        .output()
        .unwrap();
    ok(&o);
    assert_eq!(names(dir.path()), ["a.png"]);
}

/// A constant environment of 3e38 overflows to infinite pixels: refused, and nothing is written.
#[test]
fn non_finite_results_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("env.xml");
    std::fs::write(
        &scene,
        r#"<scene version="3.0.0">
    <sensor type="perspective">
        <float name="fov" value="40"/>
        <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/></film>
    </sensor>
    <emitter type="constant"><rgb name="radiance" value="3e38"/></emitter>
    <shape type="sphere"><point name="center" x="0" y="0" z="5"/><bsdf type="diffuse"/></shape>
</scene>"#,
    )
    .unwrap();
    for cpu in [false, true] {
        let mut c = pathgrad();
        c.current_dir(dir.path()).args(["render", "env.xml", "--spp", "4", "-o", "env.exr"]);
        if cpu {
            c.arg("--cpu");
        }
        let o = c.output().unwrap();
        let e = stderr(&o);
        assert!(!o.status.success() && e.contains("non-finite values") && e.contains("channel R is inf"), "{e}");
        assert_eq!(names(dir.path()), ["env.xml"], "nothing is written");
    }
}

/// Limits are stated and enforced: `--spp` at most 2²⁰, `--max-depth` at most 1024 (the cap of
/// -1), `--q` only with `--strategy diff`, `--diff-param`/`--placement-mis` only with `diff` or `auto`.
#[test]
fn limits_are_stated_and_ignored_flags_refused() {
    let base = ["render", "builtin:cornell-box", "-o", "never.exr", "--device", "99"];
    let o = pathgrad().args(base).args(["--spp", "4294967295"]).output().unwrap();
    assert!(stderr(&o).contains("invalid --spp: must be between 1 and 1048576"), "{}", stderr(&o));
    let o = pathgrad().args(base).args(["--max-depth", "100000"]).output().unwrap();
    assert!(stderr(&o).contains("invalid --max-depth: 100000 is more than 1024"), "{}", stderr(&o));
    let help = pathgrad().args(["render", "--help"]).output().unwrap();
    let help = String::from_utf8_lossy(&help.stdout).into_owned();
    assert!(help.contains("at most 1048576") && help.contains("at most 1024"), "{help}");
    let grad = ["grad", "builtin:cornell-box", "--device", "99", "--target-set", "sphere.bsdf.alpha.value=0.2"];
    let o = pathgrad().args(grad).args(["--q", "0.3"]).output().unwrap();
    assert!(stderr(&o).contains("--q 0.3 applies only to --strategy diff"), "{}", stderr(&o));
    let o = pathgrad().args(grad).args(["--diff-param", "sphere.bsdf.alpha.value"]).output().unwrap();
    assert!(
        stderr(&o).contains("--diff-param sphere.bsdf.alpha.value applies only to --strategy diff"),
        "{}",
        stderr(&o)
    );
    let o = pathgrad().args(grad).args(["--placement-mis", "power"]).output().unwrap();
    assert!(stderr(&o).contains("--placement-mis power applies only to --strategy diff or auto"), "{}", stderr(&o));
    let diff = ["--strategy", "diff", "--diff-param", "sphere.bsdf.alpha.value"];
    let o = pathgrad().args(grad).args(diff).args(["--placement-mis", "max"]).output().unwrap();
    assert!(stderr(&o).contains("invalid --placement-mis: unknown placement weighting 'max'"), "{}", stderr(&o));
}

/// The built-in Cornell box and its XML twin are one scene: one set of parameter names (Mitsuba's
/// keys, `sphere.bsdf.alpha.value`).
#[test]
fn the_builtin_cornell_box_and_its_xml_twin_share_parameter_names() {
    let sorted = |spec: &str| {
        let scene = pathgrad::scene::load(spec, &[]).unwrap();
        let mut names: Vec<String> = scene.params.entries().iter().map(|e| e.name.clone()).collect();
        names.sort();
        names
    };
    let xml = concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/cornell-box/cornell-box.xml");
    let builtin = sorted("builtin:cornell-box");
    assert_eq!(builtin, sorted(xml));
    assert!(builtin.contains(&"sphere.bsdf.alpha.value".to_string()), "{builtin:?}");
}

/// A scene reads only files inside its folder unless allowed: glTF URIs and XML `filename`s that
/// are absolute or climb out are refused, and `--allow-outside-folder` lets them be read.
#[test]
fn scenes_read_only_inside_their_folder_unless_allowed() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let absolute = root.join("tests/data/gltf/absolute_uri.gltf");
    let o = pathgrad().arg("params").arg(&absolute).output().unwrap();
    assert!(stderr(&o).contains("URI '/etc/passwd' is an absolute path"), "{}", stderr(&o));
    let o = pathgrad().arg("params").arg(&absolute).arg("--allow-outside-folder").output().unwrap();
    // Allowed, the file is read (and its bytes make no valid mesh: the error comes from the mesh).
    assert!(!o.status.success() && stderr(&o).contains("meshes[0].primitives[0]"), "{}", stderr(&o));

    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir(dir.path().join("scene")).unwrap();
    std::fs::write(dir.path().join("tri.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    let xml = dir.path().join("scene/s.xml");
    std::fs::write(
        &xml,
        r#"<scene version="3.0.0">
    <sensor type="perspective"><transform name="to_world"><lookat origin="0, 0, -3" target="0, 0, 0" up="0, 1, 0"/></transform></sensor>
    <shape type="obj"><string name="filename" value="../tri.obj"/><emitter type="area"><rgb name="radiance" value="1"/></emitter></shape>
</scene>"#,
    )
    .unwrap();
    let o = pathgrad().arg("params").arg(&xml).output().unwrap();
    assert!(stderr(&o).contains("'../tri.obj' climbs out of the scene's folder"), "{}", stderr(&o));
    ok(&pathgrad().arg("params").arg(&xml).arg("--allow-outside-folder").output().unwrap());
}

/// Curved shapes are tessellated for the size rendered: a 16-pixel film rendered at 1024 pixels
/// gets the 1024-pixel film's mesh, and a 4096-pixel film rendered at 32 the 32-pixel one's.
#[test]
fn spheres_are_tessellated_for_the_rendered_size() {
    use pathgrad::scene::{LoadOptions, load_with};
    let dir = tempfile::tempdir().unwrap();
    let scene = |film: u32| {
        let path = dir.path().join(format!("s{film}.xml"));
        std::fs::write(
            &path,
            format!(
                r#"<scene version="3.0.0">
    <sensor type="perspective"><film type="hdrfilm"><integer name="width" value="{film}"/><integer name="height" value="{film}"/></film>
        <transform name="to_world"><lookat origin="0, 0, -3" target="0, 0, 0" up="0, 1, 0"/></transform></sensor>
    <shape type="sphere"><emitter type="area"><rgb name="radiance" value="1"/></emitter></shape>
</scene>"#
            ),
        )
        .unwrap();
        path.display().to_string()
    };
    let triangles = |spec: &str, width: Option<u32>| {
        let s = load_with(spec, &LoadOptions { width, ..LoadOptions::default() }).unwrap();
        (s.triangle_count(), s.camera.width, s.camera.height)
    };
    let (small, large) = (scene(16), scene(4096));
    let (fine, _, _) = triangles(&scene(1024), None);
    let (coarse, _, _) = triangles(&scene(32), None);
    assert!(fine > 4 * coarse, "{fine} vs {coarse}");
    assert_eq!(triangles(&small, Some(1024)), (fine, 1024, 1024));
    assert_eq!(triangles(&large, Some(32)), (coarse, 32, 32));
}

/// `--resume` works from another working directory (paths are stored absolute) and refuses a
/// target whose content changed, unless told.
#[test]
fn resume_stores_absolute_paths_and_notices_a_changed_target() {
    let dir = tempfile::tempdir().unwrap();
    let target = dir.path().join("target.exr");
    let mut image = pathgrad::image::Image::new(16, 12);
    image.as_mut_slice().fill(0.3);
    image.write_exr(&target).unwrap();
    let start = |cwd: &Path, extra: &[&str]| {
        pathgrad()
            .current_dir(cwd)
            .args(["optimize", "builtin:blend", "--target", "target.exr", "--param", "object.weight.value=0.8"])
            .args(["--width", "16", "--spp-primal", "1", "--spp-grad", "1", "--spp", "2", "-o", "run"])
            .args(extra)
            .output()
            .unwrap()
    };
    ok(&start(dir.path(), &["--iters", "1"]));
    let elsewhere = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let resume = |iters: &str, extra: &[&str]| {
        pathgrad()
            .current_dir(elsewhere.path())
            .args(["optimize", "--resume"])
            .arg(&run)
            .args(["--iters", iters])
            .args(extra)
            .output()
            .unwrap()
    };
    ok(&resume("2", &[]));
    image.as_mut_slice().fill(0.6);
    image.write_exr(&target).unwrap();
    let o = resume("3", &[]);
    let e = stderr(&o);
    assert!(!o.status.success() && e.contains("target.exr changed since the run started"), "{e}");
    ok(&resume("3", &["--allow-changed-target"]));
    let state: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("state.json")).unwrap()).unwrap();
    assert_eq!(state["iteration"], 3);
    assert!(Path::new(state["config"]["target"].as_str().unwrap()).is_absolute(), "{state}");
}

/// Set-up (loading, the target, the first kernel builds) is reported apart and does not count as
/// iteration time: with an empty shader cache the builds dwarf two tiny iterations.
#[test]
fn optimize_reports_set_up_apart_from_iterations() {
    let dir = tempfile::tempdir().unwrap();
    let o = pathgrad()
        .env("XDG_CACHE_HOME", dir.path().join("cache"))
        .args(["optimize", "builtin:blend", "--target-set", "object.weight.value=0.4"])
        .args(["--param", "object.weight.value=0.8", "--width", "16", "--spp-primal", "1", "--spp-grad", "1"])
        .args(["--spp", "2", "--iters", "2", "--json", "-o"])
        .arg(dir.path().join("run"))
        .output()
        .unwrap();
    ok(&o);
    let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let (setup, time) = (summary["setup_s"].as_f64().unwrap(), summary["time_s"].as_f64().unwrap());
    assert!(setup > 0.0 && time > 0.0, "{summary}");
    let mut reader = csv::Reader::from_path(dir.path().join("run/history.csv")).unwrap();
    let first: f64 = reader.records().next().unwrap().unwrap()[1].parse().unwrap();
    assert!(first < setup, "iteration 0 ({first} s) holds no kernel build (set-up {setup} s)");
}

/// Messages say what is wrong: a directory or a device is not "not found", an OS error is printed
/// once, overflowing geometry is named as such, an empty or foreign `.glb` is not "invalid JSON",
/// and warnings carry neither a doubled file name nor colour codes or timestamps off a terminal.
#[test]
fn messages_name_the_real_problem() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::create_dir(d.join("dir.xml")).unwrap();
    std::fs::write(d.join("empty.glb"), b"").unwrap();
    std::fs::write(d.join("foreign.glb"), b"PK\x03\x04 not a glb").unwrap();
    std::fs::write(
        d.join("huge.xml"),
        r#"<scene version="3.0.0">
    <sensor type="perspective"/>
    <shape type="rectangle"><transform name="to_world"><scale value="3e19"/></transform></shape>
    <shape type="cube"><emitter type="area"><rgb name="radiance" value="1"/></emitter></shape>
    <shape type="rectangle"><transform name="to_world"><scale value="3e19"/></transform><emitter type="area"><rgb name="radiance" value="1"/></emitter></shape>
</scene>"#,
    )
    .unwrap();
    std::fs::write(
        d.join("warn.xml"),
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/xml/unknown_property.xml"))
            .unwrap(),
    )
    .unwrap();
    let run = |args: &[&str]| pathgrad().current_dir(d).args(args).output().unwrap();
    let cases: [(&[&str], &str); 7] = [
        (&["params", "dir.xml"], "error: dir.xml: is a directory, not a scene file\n"),
        (&["params", "/dev/null"], "error: /dev/null: is not a regular file (a device or pipe), not a scene file\n"),
        (&["params", "empty.glb"], "error: empty.glb: the file is empty (0 bytes)\n"),
        (
            &["params", "foreign.glb"],
            "error: foreign.glb: not a GLB file: it does not begin with the magic 'glTF' (it begins with 'PK..')\n",
        ),
        (
            &["grad", "builtin:cornell-box", "--target", "missing.exr", "--device", "cpu"],
            "error: missing.exr: No such file or directory (os error 2)\n",
        ),
        (
            &["grad", "builtin:cornell-box", "--target", ".", "--device", "cpu"],
            "error: .: is a directory, not an OpenEXR file\n",
        ),
        (
            &["params", "huge.xml"],
            "area emitter on shape '_unnamed_2' whose area overflows 32-bit floats (coordinates too large)\n",
        ),
    ];
    for (args, want) in cases {
        let e = stderr(&run(args));
        assert!(e.ends_with(want), "{args:?}: expected it to end with {want:?}: {e:?}");
    }
    let e = stderr(&run(&["params", "huge.xml"]));
    assert!(e.contains("dropped 2 triangle(s) of 2 whose area overflows 32-bit floats"), "{e}");
    let e = stderr(&run(&["params", "warn.xml"]));
    assert!(e.contains(" WARN pathgrad::scene: warn.xml:6:9: unknown property 'radius'"), "{e:?}");
    assert!(!e.contains("warn.xml: warn.xml") && !e.contains('\u{1b}'), "{e:?}");
    assert!(e.lines().all(|l| l.starts_with(" WARN") || l.starts_with("error")), "no timestamps: {e:?}");
}

/// `variance` checks every file it will write before estimating anything.
#[test]
fn variance_checks_its_outputs_first() {
    use std::os::unix::fs::PermissionsExt as _;
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("v");
    std::fs::create_dir(&out).unwrap();
    let summary = out.join("summary.json");
    std::fs::write(&summary, "{}").unwrap();
    std::fs::set_permissions(&summary, std::fs::Permissions::from_mode(0o444)).unwrap();
    let o = pathgrad()
        .args(["variance", "builtin:cornell-box", "--param", "sphere.bsdf.alpha.value", "--runs", "2"])
        .args(["--width", "8", "--spp", "1", "--device", "99", "-o"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(stderr(&o).contains("summary.json: is read-only"), "{}", stderr(&o));
    assert_eq!(names(&out), ["summary.json"]);
}

/// Issue 36, 5: `--view` errors say they come from `--view` (an empty target path, a missing
/// target file), and a negative `--shard` gets the shard's own error, not the parser's.
#[test]
fn issue_36_view_and_shard_messages_name_the_flag() {
    let dir = tempfile::tempdir().unwrap();
    let scene = concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/two-sided/scene.xml");
    let manifest = dir.path().join("m.jsonl");
    std::fs::write(&manifest, "").unwrap();
    let out = dir.path().join("out");
    let out = out.to_str().unwrap();
    let manifest = manifest.to_str().unwrap();
    let cases: [(&[&str], &str); 3] = [
        (
            &["grad", scene, "--view", "front_camera=front.exr", "--view", "back_camera="],
            "error: invalid --view back_camera=: the target path after '=' is empty (give --view back_camera=TARGET.exr)\n",
        ),
        (
            &["grad", scene, "--view", "back_camera=missing.exr"],
            "error: --view back_camera=missing.exr: missing.exr: No such file or directory (os error 2)\n",
        ),
        (
            &["batch", manifest, "-o", out, "--shard", "-1/2"],
            "error: invalid --shard -1/2: '-1' is not a non-negative integer\n",
        ),
    ];
    for (args, want) in cases {
        let o = pathgrad().current_dir(dir.path()).args(args).output().unwrap();
        assert!(!o.status.success());
        let e = stderr(&o);
        assert!(e.ends_with(want), "{args:?}: expected it to end with {want:?}: {e:?}");
    }
}

//! The `pathgrad` binary as a person uses it: outputs, summaries and error messages.

use std::process::Command;

fn pathgrad() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_pathgrad"));
    if std::env::var_os("PATHGRAD_DEVICE").is_none() {
        c.env("PATHGRAD_DEVICE", std::env::var("PATHGRAD_TEST_DEVICE").unwrap_or_else(|_| "cpu".into()));
    }
    c
}

#[test]
fn render_writes_exr_and_png_preview_and_a_json_summary() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("cb.exr");
    let o = pathgrad()
        .args(["render", "builtin:cornell-box", "--spp", "2", "--width", "32", "--seed", "5", "--json", "-o"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(summary["width"], 32);
    assert_eq!(summary["height"], 32, "the height follows the scene's aspect ratio");
    assert!(summary["samples_per_second"].as_f64().unwrap() > 0.0);
    let image = pathgrad::image::Image::read_exr(&out).unwrap();
    assert_eq!((image.width(), image.height()), (32, 32));
    assert!(image.mean().iter().all(|&m| m > 0.0 && m.is_finite()));
    assert!(dir.path().join("cb.png").exists(), "the .png preview is written beside the .exr");
}

#[test]
fn same_seed_gives_the_same_image() {
    let dir = tempfile::tempdir().unwrap();
    let render = |name: &str| {
        let out = dir.path().join(name);
        let o = pathgrad()
            .args(["render", "builtin:blend", "--spp", "2", "--width", "24", "--no-preview", "-o"])
            .arg(&out)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        assert!(!out.with_extension("png").exists(), "--no-preview writes no .png");
        pathgrad::image::Image::read_exr(&out).unwrap()
    };
    assert_eq!(render("a.exr").as_slice(), render("b.exr").as_slice());
}

#[test]
fn bad_input_gets_a_clear_error_and_no_output() {
    let dir = tempfile::tempdir().unwrap();
    let cases: [(&[&str], &str); 6] = [
        (
            &["render", "builtin:cornell-box", "--device", "99", "-o", "x.exr"],
            "no Vulkan device matches '99' (available: [0]",
        ),
        (&["render", "builtin:nope", "-o", "x.exr"], "unknown built-in scene (known: cornell-box, furnace, blend)"),
        (&["render", "scene.xml", "-o", "x.exr"], "scene files are not supported yet"),
        (&["render", "builtin:cornell-box", "-o", "x.jpg"], "must end in .exr or .png"),
        (&["render", "builtin:cornell-box", "--spp", "0", "-o", "x.exr"], "invalid --spp"),
        (&["render", "builtin:cornell-box", "--max-depth", "0", "-o", "x.exr"], "--max-depth"),
    ];
    for (args, message) in cases {
        let o = pathgrad().current_dir(dir.path()).args(args).output().unwrap();
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{args:?} should fail");
        assert!(stderr.contains(message), "{args:?}: expected '{message}' in: {stderr}");
    }
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0, "no output file was left behind");
}

#[test]
fn a_missing_driver_is_reported_with_the_fix() {
    let o = pathgrad()
        .env("VK_DRIVER_FILES", "/nonexistent/icd.json")
        .args(["render", "builtin:cornell-box", "-o", "/tmp/never-written.exr"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(stderr.contains("install mesa-vulkan-drivers"), "{stderr}");
}

#[test]
fn devices_lists_lavapipe() {
    let o = pathgrad().args(["devices", "--json"]).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let list: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(list.as_array().unwrap().iter().any(|d| d["usable"] == true), "{list}");
}

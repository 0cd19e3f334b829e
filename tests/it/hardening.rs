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

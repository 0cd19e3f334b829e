//! `pathgrad batch` and `reduce`: manifests, shards from the flag and the schedulers' variables,
//! reruns, and bad lines.

use std::path::{Path, PathBuf};
use std::process::Output;

use crate::cli::pathgrad;

/// A manifest of `count` items on the blend scene: images, deterministic loss gradients against
/// `target.exr` beside it, and an image gradient; every item with its own seed or values.
fn manifest(dir: &Path, count: usize) -> PathBuf {
    let target = dir.join("target.exr");
    let o = pathgrad()
        .args(["render", "builtin:blend", "--width", "16", "--height", "12", "--spp", "16", "--no-preview", "-o"])
        .arg(&target)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let mut lines = Vec::new();
    for i in 0..count {
        let common = format!(r#""scene": "builtin:blend", "width": 16, "height": 12, "spp": 2, "seed": {i}"#);
        lines.push(match i % 3 {
            0 => format!(r#"{{{common}, "produce": ["image"]}}"#),
            1 => format!(
                r#"{{{common}, "params": {{"object.weight.value": {}}}, "produce": ["image", "loss", "gradients"], "target": "target.exr", "deterministic": true}}"#,
                0.2 + 0.1 * i as f64
            ),
            _ => format!(r#"{{"id": "grad-{i}", {common}, "produce": ["image_gradient"], "image_gradient": "object.weight.value"}}"#),
        });
    }
    let path = dir.join("manifest.jsonl");
    std::fs::write(&path, lines.join("\n") + "\n").unwrap();
    path
}

/// `pathgrad batch MANIFEST -o OUT ARGS` without the schedulers' variables of the test's own
/// environment.
fn batch_command(manifest: &Path, out: &Path, args: &[&str]) -> std::process::Command {
    let mut command = pathgrad();
    command.arg("batch").arg(manifest).arg("-o").arg(out).args(args);
    for var in ["SLURM_ARRAY_TASK_ID", "SLURM_ARRAY_TASK_COUNT", "SLURM_ARRAY_TASK_MIN", "JOB_COMPLETION_INDEX"] {
        command.env_remove(var);
    }
    command
}

fn batch(manifest: &Path, out: &Path, args: &[&str], env: &[(&str, &str)]) -> Output {
    batch_command(manifest, out, args).envs(env.iter().copied()).output().unwrap()
}

fn ok(o: &Output) {
    assert!(o.status.success(), "status {:?}: {}", o.status, String::from_utf8_lossy(&o.stderr));
}

fn reduce(dirs: &[&Path], out: &Path) {
    let o = pathgrad().arg("reduce").args(dirs).arg("-o").arg(out).output().unwrap();
    ok(&o);
}

fn summary(path: &Path) -> Vec<serde_json::Value> {
    std::fs::read_to_string(path).unwrap().lines().map(|l| serde_json::from_str(l).unwrap()).collect()
}

/// The item files of a run (everything but summaries and hidden files: the shards' locks and
/// any temporaries), by name.
fn item_files(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut files: Vec<(String, Vec<u8>)> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| {
            let name = p.file_name().unwrap().to_str().unwrap();
            !name.starts_with('.') && !name.starts_with("summary")
        })
        .filter(|p| p.file_name().unwrap() != "totals.json")
        .map(|p| (p.file_name().unwrap().to_str().unwrap().to_string(), std::fs::read(&p).unwrap()))
        .collect();
    files.sort();
    files
}

/// Three shards from Slurm's array variables into one directory, and three from a Kubernetes
/// Indexed Job's completion index into three, reduce to the unsharded run bit for bit: the same
/// item files and the same gradient totals.
#[test]
fn sharded_runs_reduce_to_the_unsharded_run_bitwise() {
    let dir = tempfile::tempdir().unwrap();
    let manifest = manifest(dir.path(), 7);
    let whole = dir.path().join("whole");
    ok(&batch(&manifest, &whole, &[], &[]));
    reduce(&[&whole], &whole);
    let slurm = dir.path().join("slurm");
    for i in ["10", "11", "12"] {
        let env = [("SLURM_ARRAY_TASK_ID", i), ("SLURM_ARRAY_TASK_COUNT", "3"), ("SLURM_ARRAY_TASK_MIN", "10")];
        ok(&batch(&manifest, &slurm, &[], &env));
    }
    reduce(&[&slurm], &slurm);
    let k8s: Vec<PathBuf> = (0..3).map(|i| dir.path().join(format!("k8s-{i}"))).collect();
    for (i, out) in k8s.iter().enumerate() {
        ok(&batch(&manifest, out, &["--shards", "3"], &[("JOB_COMPLETION_INDEX", &i.to_string())]));
        assert_eq!(summary(&out.join(format!("summary.shard-{i}-of-3.jsonl"))).len(), if i == 0 { 3 } else { 2 });
    }
    let merged = dir.path().join("k8s");
    reduce(&k8s.iter().map(PathBuf::as_path).collect::<Vec<_>>(), &merged);
    let totals = std::fs::read(whole.join("totals.json")).unwrap();
    let parsed: serde_json::Value = serde_json::from_slice(&totals).unwrap();
    assert_eq!(parsed["items"], 7);
    assert_eq!(parsed["with_gradients"], 2);
    assert!(parsed["gradients"]["object.weight.value"][0].as_f64().unwrap() != 0.0, "{parsed}");
    assert_eq!(std::fs::read(slurm.join("totals.json")).unwrap(), totals);
    assert_eq!(std::fs::read(merged.join("totals.json")).unwrap(), totals);
    assert_eq!(item_files(&slurm), item_files(&whole));
    let k8s_files: Vec<(String, Vec<u8>)> = {
        let mut all: Vec<_> = k8s.iter().flat_map(|d| item_files(d)).collect();
        all.sort();
        all
    };
    assert_eq!(k8s_files, item_files(&whole));
    let rows = summary(&merged.join("summary.jsonl"));
    assert_eq!(rows.iter().map(|r| r["index"].as_u64().unwrap()).collect::<Vec<_>>(), (0..7).collect::<Vec<_>>());
}

/// A shard killed mid-way leaves finished items (their record written last) and one item whose
/// images were written but not its record; a rerun does only what is missing, and the files
/// end up as an uninterrupted run writes them.
#[test]
fn a_rerun_completes_only_the_missing_items() {
    let dir = tempfile::tempdir().unwrap();
    let manifest = manifest(dir.path(), 5);
    let out = dir.path().join("out");
    ok(&batch(&manifest, &out, &[], &[]));
    let complete = item_files(&out);
    let rows = summary(&out.join("summary.jsonl"));
    // The state a kill leaves: item 4 never started, item 3 stopped before its record.
    let name = |i: usize| rows[i]["name"].as_str().unwrap().to_string();
    for output in rows[4]["outputs"].as_array().unwrap() {
        std::fs::remove_file(out.join(output.as_str().unwrap())).unwrap();
    }
    std::fs::remove_file(out.join(format!("{}.json", name(3)))).unwrap();
    std::fs::write(out.join(format!(".{}.exr.99999-0.tmp", name(3))), b"torn").unwrap();
    let o = batch(&manifest, &out, &["--json"], &[]);
    ok(&o);
    let report: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!((report["ok"].as_u64(), report["skipped"].as_u64()), (Some(2), Some(3)), "{report}");
    let statuses: Vec<String> =
        summary(&out.join("summary.jsonl")).iter().map(|r| r["status"].as_str().unwrap().to_string()).collect();
    assert_eq!(statuses, ["skipped", "skipped", "skipped", "ok", "ok"]);
    assert!(!out.join(format!(".{}.exr.99999-0.tmp", name(3))).exists(), "the shard removes its temporaries");
    assert_eq!(item_files(&out), complete);
}

/// Bad lines — an unknown key, a missing scene, a bad value, a missing target — are reported with
/// their line numbers in the summary and on stderr; the other items run; the exit status fails.
#[test]
fn bad_manifest_lines_are_reported_and_the_rest_go_on() {
    let dir = tempfile::tempdir().unwrap();
    let good = r#"{"scene": "builtin:blend", "width": 8, "height": 6, "spp": 1, "produce": ["image"]}"#;
    let lines = [
        good,
        r#"{"scene": "builtin:blend", "colour": "red", "produce": ["image"]}"#,
        "",
        r#"{"scene": "nowhere.xml", "produce": ["image"]}"#,
        r#"{"scene": "builtin:blend", "spp": "many", "produce": ["image"]}"#,
        r#"{"scene": "builtin:blend", "width": 8, "height": 6, "produce": ["loss"]}"#,
        r#"{"id": "second", "scene": "builtin:blend", "width": 8, "height": 6, "spp": 1, "seed": 1, "produce": ["image"]}"#,
    ];
    let manifest = dir.path().join("m.jsonl");
    std::fs::write(&manifest, lines.join("\n")).unwrap();
    let out = dir.path().join("out");
    let o = batch(&manifest, &out, &[], &[]);
    assert!(!o.status.success());
    let stderr = String::from_utf8_lossy(&o.stderr);
    let rows = summary(&out.join("summary.jsonl"));
    let status: Vec<(&str, u64)> =
        rows.iter().map(|r| (r["status"].as_str().unwrap(), r["line"].as_u64().unwrap())).collect();
    assert_eq!(status, [("ok", 1), ("failed", 2), ("failed", 4), ("failed", 5), ("failed", 6), ("ok", 7)]);
    for (line, expected) in
        [(2, "unknown field `colour`"), (4, "nowhere.xml"), (5, "invalid type"), (6, "'target' is needed")]
    {
        let row = rows.iter().find(|r| r["line"] == line).unwrap();
        let error = row["error"].as_str().unwrap();
        assert!(error.contains(&format!("m.jsonl:{line}:")) && error.contains(expected), "{error}");
        assert!(stderr.contains(error), "{stderr}");
    }
    assert!(out.join("second.exr").is_file());
}

/// `sampling` reaches the estimator: a glass sphere's index of refraction is in the gradients
/// and has an image gradient with `"attached"`, is left out of the gradients with the default
/// detached sampling (not reported as 0), and its detached image gradient fails the item by name,
/// as does a Jacobian noise without attached sampling.
#[test]
fn batch_items_take_attached_sampling() {
    let dir = tempfile::tempdir().unwrap();
    let scene = format!("{}/tests/data/scenes/attached_sphere.xml", env!("CARGO_MANIFEST_DIR"));
    let common = format!(r#""scene": "{scene}", "width": 8, "height": 6, "spp": 1"#);
    let target = pathgrad::image::Image::from_rgb(8, 6, vec![0.5; 8 * 6 * 3]).unwrap();
    target.write_exr(dir.path().join("target.exr")).unwrap();
    let lines = [
        format!(
            r#"{{"id": "attached", {common}, "produce": ["gradients", "image_gradient"], "target": "target.exr", "image_gradient": "glass.bsdf.eta", "sampling": "attached"}}"#
        ),
        format!(r#"{{"id": "detached", {common}, "produce": ["gradients"], "target": "target.exr"}}"#),
        format!(r#"{{"id": "refused", {common}, "produce": ["image_gradient"], "image_gradient": "glass.bsdf.eta"}}"#),
        format!(r#"{{"id": "noisy", {common}, "produce": ["image"], "jacobian_noise": 0.1}}"#),
    ];
    let manifest = dir.path().join("m.jsonl");
    std::fs::write(&manifest, lines.join("\n")).unwrap();
    let out = dir.path().join("out");
    let o = batch(&manifest, &out, &[], &[]);
    assert!(!o.status.success(), "two items fail");
    let rows = summary(&out.join("summary.jsonl"));
    let status: Vec<&str> = rows.iter().map(|r| r["status"].as_str().unwrap()).collect();
    assert_eq!(status, ["ok", "ok", "failed", "failed"], "{rows:?}");
    assert!(rows[2]["error"].as_str().unwrap().contains("glass.bsdf.eta"), "{rows:?}");
    assert!(rows[3]["error"].as_str().unwrap().contains("'jacobian_noise'"), "{rows:?}");
    let record = |name: &str| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(out.join(format!("{name}.json"))).unwrap()).unwrap()
    };
    let eta = record("attached")["gradients"]["glass.bsdf.eta"][0].as_f64().unwrap();
    assert!(eta != 0.0 && eta.is_finite(), "{eta}");
    assert!(out.join("attached.image_gradient.exr").is_file());
    let detached = record("detached");
    assert!(detached["gradients"].get("glass.bsdf.eta").is_none(), "{detached}");
    assert!(!detached["gradients"].as_object().unwrap().is_empty(), "{detached}");
}

/// A shard really killed (SIGKILL) after its first items: the rerun skips what was finished,
/// runs the rest, and the files are those of an uninterrupted run.
#[test]
fn a_killed_shard_resumes_where_it_stopped() {
    let dir = tempfile::tempdir().unwrap();
    let manifest = manifest(dir.path(), 9);
    let whole = dir.path().join("whole");
    ok(&batch(&manifest, &whole, &[], &[]));
    let out = dir.path().join("killed");
    let mut child = pathgrad().arg("batch").arg(&manifest).arg("-o").arg(&out).spawn().unwrap();
    let summary_path = out.join("summary.jsonl");
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(120);
    while std::fs::read_to_string(&summary_path).map_or(0, |t| t.lines().count()) < 2 {
        assert!(std::time::Instant::now() < deadline, "the shard never finished two items");
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    let done_before = std::fs::read_to_string(&summary_path).unwrap().lines().count();
    let o = batch(&manifest, &out, &["--json"], &[]);
    ok(&o);
    let report: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let (ran, skipped) = (report["ok"].as_u64().unwrap(), report["skipped"].as_u64().unwrap());
    assert_eq!(ran + skipped, 9, "{report}");
    assert!(skipped as usize >= done_before, "{report}: {done_before} were finished before the kill");
    if ran == 0 {
        println!("the shard finished every item before the kill landed: only the skip was exercised");
    }
    let left: Vec<String> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .filter(|n| n.ends_with(".tmp"))
        .collect();
    assert!(left.is_empty(), "the rerun removes what the kill left: {left:?}");
    assert_eq!(item_files(&out), item_files(&whole));
}

/// A manifest of `count` small image items with ids `a0`, `a1`, …, each with seed `seed + i`.
fn id_manifest(dir: &Path, file: &str, count: usize, seed: usize) -> PathBuf {
    let lines: Vec<String> = (0..count)
        .map(|i| {
            format!(
                r#"{{"id": "a{i}", "scene": "builtin:blend", "width": 8, "height": 6, "spp": 1, "seed": {}, "produce": ["image"]}}"#,
                seed + i
            )
        })
        .collect();
    let path = dir.join(file);
    std::fs::write(&path, lines.join("\n") + "\n").unwrap();
    path
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Issue 36, 1: two runs whose items have the same ids at the same indices but other seeds are
/// refused by `reduce`, naming both directories, the index and the id; a second run of the same
/// manifest into another directory still merges.
#[test]
fn issue_36_reduce_refuses_items_of_different_runs() {
    let dir = tempfile::tempdir().unwrap();
    let first = id_manifest(dir.path(), "first.jsonl", 3, 0);
    let other = id_manifest(dir.path(), "other.jsonl", 3, 100);
    let (a, again, b) = (dir.path().join("a"), dir.path().join("again"), dir.path().join("b"));
    ok(&batch(&first, &a, &[], &[]));
    ok(&batch(&first, &again, &[], &[]));
    ok(&batch(&other, &b, &[], &[]));
    reduce(&[&a, &again], &dir.path().join("same"));
    let o = pathgrad().arg("reduce").arg(&a).arg(&b).arg("-o").arg(dir.path().join("mixed")).output().unwrap();
    let e = stderr(&o);
    assert!(!o.status.success(), "{e}");
    for part in [a.display().to_string(), b.display().to_string(), "item 0 ('a0')".into(), "different items".into()] {
        assert!(e.contains(&part), "{part:?} missing: {e}");
    }
    assert!(!dir.path().join("mixed").exists(), "nothing is written");
}

/// Issue 36, 2: two processes of one shard started together into one directory: one runs, the
/// other is refused at once (it holds no lock); two different shards share the directory.
#[test]
fn issue_36_one_process_per_shard_and_directory() {
    let dir = tempfile::tempdir().unwrap();
    let manifest = id_manifest(dir.path(), "m.jsonl", 8, 0);
    let out = dir.path().join("out");
    let spawn = |args: &[&str]| {
        batch_command(&manifest, &out, args)
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap()
    };
    let (p, q) = (spawn(&["--json"]), spawn(&["--json"]));
    let outputs = [p.wait_with_output().unwrap(), q.wait_with_output().unwrap()];
    let refused: Vec<&Output> = outputs.iter().filter(|o| !o.status.success()).collect();
    assert_eq!(refused.len(), 1, "exactly one is refused: {:?}", outputs.iter().map(stderr).collect::<Vec<_>>());
    let e = stderr(refused[0]);
    assert!(e.contains("another pathgrad batch is running shard 0/1 in") && e.contains("out"), "{e}");
    let ran = outputs.iter().find(|o| o.status.success()).unwrap();
    let report: serde_json::Value = serde_json::from_slice(&ran.stdout).unwrap();
    assert_eq!(report["ok"], 8, "{report}");
    let rows = summary(&out.join("summary.jsonl"));
    assert!(rows.iter().all(|r| r["status"] == "ok") && rows.len() == 8, "{rows:?}");
    // Different shards of one manifest share a directory by design.
    let shared = dir.path().join("shared");
    let spawn_shard = |shard: &str| {
        batch_command(&manifest, &shared, &["--shard", shard])
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap()
    };
    let (p, q) = (spawn_shard("0/2"), spawn_shard("1/2"));
    ok(&p.wait_with_output().unwrap());
    ok(&q.wait_with_output().unwrap());
}

/// Issue 36, 3: temporaries a killed run left for the shard's own files — one of a temporary
/// among them, and ones whose process id is alive — are removed when the shard starts again,
/// although every item is finished; temporaries of other names and other files stay.
#[test]
fn issue_36_a_shard_removes_its_stale_temporaries_when_it_starts() {
    let dir = tempfile::tempdir().unwrap();
    let manifest = id_manifest(dir.path(), "m.jsonl", 2, 0);
    let out = dir.path().join("out");
    ok(&batch(&manifest, &out, &[], &[]));
    // A live process id: these temporaries are stale because this shard holds its lock.
    let pid = std::process::id();
    let stale = [
        format!("..a0.exr.{pid}-785.tmp.{pid}-788.tmp"),
        format!(".a1.json.{pid}-3.tmp"),
        format!(".summary.jsonl.{pid}-9.tmp"),
        ".a0.png.2147483632-1.tmp".to_string(),
    ];
    let kept = [".b0.exr.2147483632-1.tmp", ".a0.exr.notes.tmp", ".summary.shard-1-of-2.jsonl.2147483632-1.tmp"];
    for name in stale.iter().map(String::as_str).chain(kept) {
        std::fs::write(out.join(name), b"").unwrap();
    }
    let o = batch(&manifest, &out, &["--json"], &[]);
    ok(&o);
    let report: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(report["skipped"], 2, "{report}");
    for name in &stale {
        assert!(!out.join(name).exists(), "{name} is left");
    }
    for name in kept {
        assert!(out.join(name).exists(), "{name} was removed");
    }
}

/// Issue 36, 4: `reduce` refuses to write into one of several input directories (named directly or
/// through a symbolic link, or by default); into its only input it still writes.
#[test]
fn issue_36_reduce_refuses_an_output_among_several_inputs() {
    let dir = tempfile::tempdir().unwrap();
    let manifest = id_manifest(dir.path(), "m.jsonl", 4, 0);
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    ok(&batch(&manifest, &a, &["--shard", "0/2"], &[]));
    ok(&batch(&manifest, &b, &["--shard", "1/2"], &[]));
    let link = dir.path().join("link");
    std::os::unix::fs::symlink(&a, &link).unwrap();
    let before = item_files(&a);
    for output in [Some(&a), Some(&link), None] {
        let mut command = pathgrad();
        command.arg("reduce").arg(&a).arg(&b);
        if let Some(o) = output {
            command.arg("-o").arg(o);
        }
        let o = command.output().unwrap();
        let e = stderr(&o);
        assert!(!o.status.success() && e.contains("is one of the input directories"), "{output:?}: {e}");
        assert!(!a.join("summary.jsonl").exists() && item_files(&a) == before, "{output:?} wrote into a");
    }
    reduce(&[&a, &b], &dir.path().join("merged"));
    reduce(&[&a], &a);
}

/// Issue 36, 5: manifest errors name the manifest's keys, not the command line's flags; an
/// out-of-range sensor says how many the scene has; a manifest with a byte-order mark is read.
#[test]
fn issue_36_manifest_messages_name_its_keys() {
    let dir = tempfile::tempdir().unwrap();
    let item = |extra: &str| format!(r#"{{"scene": "builtin:blend", {extra}"produce": ["image"]}}"#);
    let lines = [
        item(r#""width": 0, "#),
        item(r#""width": 20000, "height": 6, "#),
        item(r#""width": 8, "height": 6, "spp": 0, "#),
        item(r#""width": 8, "height": 6, "max_depth": 0, "#),
        item(r#""width": 8, "height": 6, "sensor": 5, "#),
    ];
    let manifest = dir.path().join("m.jsonl");
    std::fs::write(&manifest, format!("\u{feff}{}\n", lines.join("\n"))).unwrap();
    let out = dir.path().join("out");
    let o = batch(&manifest, &out, &[], &[]);
    assert!(!o.status.success());
    let rows = summary(&out.join("summary.jsonl"));
    let expected = [
        "m.jsonl:1: invalid 'width'/'height': must be between 1 and 16384",
        "m.jsonl:2: invalid 'width'/'height': must be between 1 and 16384",
        "m.jsonl:3: invalid 'spp': must be between 1 and",
        "m.jsonl:4: invalid 'max_depth': must be at least 1 (or -1 for unbounded)",
        "no sensor '5': the scene has 1 sensor (0: camera)",
    ];
    for (row, want) in rows.iter().zip(expected) {
        let error = row["error"].as_str().unwrap();
        assert!(error.contains(want) && !error.contains("--"), "{want:?}: {error}");
    }
    assert_eq!(rows.len(), 5);
    // The byte-order mark is not part of the first item.
    let good = dir.path().join("good.jsonl");
    std::fs::write(&good, format!("\u{feff}{}\n", item(r#""width": 8, "height": 6, "spp": 1, "#))).unwrap();
    ok(&batch(&good, &dir.path().join("good"), &[], &[]));
}

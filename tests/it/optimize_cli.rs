//! `pathgrad optimize` as a person uses it: outputs, `--resume`, Ctrl-C and bad input.

use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use crate::cli::pathgrad;

/// A small, fast run on the blend scene: 16×12, 2 + 1 spp, weight 0.8 towards 0.4.
const SMALL: &[&str] = &[
    "optimize",
    "builtin:blend",
    "--target-set",
    "object.weight.value=0.4",
    "--param",
    "object.weight.value=0.8",
    "--width",
    "16",
    "--spp-primal",
    "2",
    "--spp-grad",
    "1",
    "--spp",
    "4",
];

fn run(args: &[&str], extra: &[&str]) -> Output {
    pathgrad().args(args).args(extra).output().unwrap()
}

fn ok(o: &Output) {
    assert!(o.status.success(), "status {:?}: {}", o.status, String::from_utf8_lossy(&o.stderr));
}

/// The CSV's data rows, split into fields.
fn rows(dir: &Path) -> (Vec<String>, Vec<Vec<String>>) {
    let text = std::fs::read_to_string(dir.join("history.csv")).unwrap();
    let mut lines = text.lines();
    let header = lines.next().unwrap().split(',').map(String::from).collect();
    (header, lines.map(|l| l.split(',').map(String::from).collect()).collect())
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// A default run writes its history, curves, image, parameters and state; it runs with adaptive
/// pixels and control variates, and `--adaptive=false --control-variates=false` turns both off.
#[test]
fn optimize_writes_the_history_curves_image_and_parameters() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let o = run(SMALL, &["--iters", "3", "--json", "-o", out.to_str().unwrap()]);
    ok(&o);
    let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(summary["iterations"], 3);
    assert_eq!(summary["stopped"], "completed");
    // The default: adaptive pixels and control variates (docs/gradients.md "Which to use").
    assert_eq!(
        (&summary["adaptive"], &summary["control_variates"], &summary["reuse"]),
        (&true.into(), &true.into(), &false.into())
    );
    assert!(out.join("control_variates.bin").is_file());
    let plain_dir = dir.path().join("plain");
    let flags = ["--adaptive=false", "--control-variates=false", "--iters", "1", "--json", "-o"];
    let o = run(SMALL, &[&flags[..], &[plain_dir.to_str().unwrap()]].concat());
    ok(&o);
    let plain: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!((&plain["adaptive"], &plain["control_variates"]), (&false.into(), &false.into()));
    assert!(!plain_dir.join("control_variates.bin").exists());
    let (header, rows) = rows(&out);
    assert_eq!(
        header,
        [
            "iteration",
            "time_s",
            "loss",
            "object.weight.value",
            "error[object.weight.value]",
            "param_error",
            "grad_norm"
        ]
    );
    assert_eq!(rows.len(), 3, "one row per iteration");
    let mut last_time = 0.0;
    for (t, row) in rows.iter().enumerate() {
        assert_eq!(row[0], t.to_string());
        let time: f64 = row[1].parse().unwrap();
        assert!(time > last_time, "wall time grows: {rows:?}");
        last_time = time;
        let weight: f64 = row[3].parse().unwrap();
        // ALGORITHMS.md §7.1: ((θ − θ*)/(θ* + 1e-3))².
        let error: f64 = row[4].parse().unwrap();
        assert!((error - ((weight - 0.4) / 0.401).powi(2)).abs() < 1e-6 * error.max(1.0), "{row:?}");
        assert_eq!(row[4], row[5], "one parameter: its error is the overall error");
        assert!(row[2].parse::<f64>().unwrap() > 0.0 && row[6].parse::<f64>().unwrap().is_finite());
    }
    let params = json(&out.join("params.json"));
    let weight = params["object.weight.value"][0].as_f64().unwrap();
    assert_eq!(rows[2][3].parse::<f64>().unwrap(), weight, "params.json holds the last row's values");
    assert!(weight < 0.8, "three steps towards 0.4 moved the weight down: {weight}");
    assert_eq!(summary["params"], params);
    let image = pathgrad::image::Image::read_exr(out.join("final.exr")).unwrap();
    assert_eq!((image.width(), image.height()), (16, 12));
    assert!(out.join("final.png").exists());
    let svg = std::fs::read_to_string(out.join("curves.svg")).unwrap();
    assert!(svg.starts_with("<svg") && svg.contains("parameter error against wall time"), "{}", &svg[..200]);
    let state = json(&out.join("state.json"));
    assert_eq!(state["iteration"], 3);
    assert_eq!(state["stopped"], "completed");
    let leftovers: Vec<_> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .filter(|n| n.ends_with(".tmp"))
        .collect();
    assert!(leftovers.is_empty(), "no temporary files are left: {leftovers:?}");
}

/// Two iterations, then `--resume` to four, give the same parameters as four in one go (with
/// fixed-point gradients every step is bitwise reproducible) and one CSV numbered 0..3.
#[test]
fn resume_continues_the_numbering_and_the_trajectory() {
    let dir = tempfile::tempdir().unwrap();
    let whole = dir.path().join("whole");
    let split = dir.path().join("split");
    let adaptive = ["--adaptive", "--deterministic", "--seed", "3"];
    ok(&run(SMALL, &[&adaptive[..], &["--iters", "4", "-o", whole.to_str().unwrap()]].concat()));
    ok(&run(SMALL, &[&adaptive[..], &["--iters", "2", "-o", split.to_str().unwrap()]].concat()));
    assert_eq!(rows(&split).1.len(), 2);
    // Changing what the trajectory depends on is refused, naming the flag and both values.
    let o = run(&["optimize", "--resume", split.to_str().unwrap(), "--lr", "0.5", "--spp-grad", "1"], &[]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(stderr.contains("--lr 0.5 (the run has 0.01)") && !stderr.contains("--spp-grad"), "{stderr}");
    ok(&run(&["optimize", "--resume", split.to_str().unwrap(), "--iters", "4"], &[]));
    let (header, resumed) = rows(&split);
    let (_, straight) = rows(&whole);
    assert_eq!(header[3], "object.weight.value");
    assert_eq!(resumed.iter().map(|r| r[0].as_str()).collect::<Vec<_>>(), ["0", "1", "2", "3"]);
    for (a, b) in resumed.iter().zip(&straight) {
        // Everything but the wall time agrees bit for bit.
        assert_eq!((&a[0], &a[2..]), (&b[0], &b[2..]));
    }
    assert!(resumed[2][1].parse::<f64>().unwrap() > resumed[1][1].parse::<f64>().unwrap(), "time accumulates");
    assert_eq!(json(&split.join("params.json")), json(&whole.join("params.json")));
    assert_eq!(json(&split.join("state.json"))["iteration"], 4);
}

/// SIGINT in the middle of a long run: the iteration in flight finishes, everything so far is
/// written, the exit status is 130, and the run resumes where it stopped.
#[test]
fn ctrl_c_writes_everything_so_far() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let mut child = pathgrad()
        .args(SMALL)
        .args(["--iters", "100000", "-o", out.to_str().unwrap()])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let csv = out.join("history.csv");
    let start = Instant::now();
    while std::fs::read_to_string(&csv).map_or(0, |t| t.lines().count()) < 3 {
        assert!(start.elapsed() < Duration::from_secs(300), "no iterations after 300 s");
        assert!(child.try_wait().unwrap().is_none(), "the run ended early");
        std::thread::sleep(Duration::from_millis(50));
    }
    let status = Command::new("kill").args(["-INT", &child.id().to_string()]).status().unwrap();
    assert!(status.success());
    let o = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(130), "{stderr}");
    assert!(stderr.contains("--resume"), "{stderr}");
    let state = json(&out.join("state.json"));
    assert_eq!(state["stopped"], "interrupted");
    let done = state["iteration"].as_u64().unwrap();
    assert!(done >= 2);
    assert_eq!(rows(&out).1.len() as u64, done, "the CSV has a row for every iteration the state holds");
    for file in ["curves.svg", "final.exr", "final.png", "params.json"] {
        assert!(out.join(file).exists(), "{file} was written");
    }
    let more = (done + 1).to_string();
    ok(&run(&["optimize", "--resume", out.to_str().unwrap(), "--iters", &more], &[]));
    let (_, rows) = rows(&out);
    assert_eq!(rows.len() as u64, done + 1);
    assert_eq!(rows.last().unwrap()[0], done.to_string());
}

#[test]
fn optimize_bad_input_names_the_flag_and_leaves_nothing_behind() {
    let dir = tempfile::tempdir().unwrap();
    let small = pathgrad::image::Image::new(8, 8);
    small.write_exr(dir.path().join("small.exr")).unwrap();
    let base = ["optimize", "builtin:cornell-box", "--width", "16", "--spp-primal", "1"];
    let cases: [(&[&str], &str); 11] = [
        (&["--target-set", "sphere.bsdf.alpha.value=0.1"], "give at least one --param"),
        (
            &["--target-set", "sphere.bsdf.alpha.value=0.1", "--param", "nope=0.3"],
            "--param: invalid nope: matches no parameter",
        ),
        (
            &["--target-set", "sphere.bsdf.alpha.value=0.1", "--param", "sphere.bsdf.alpha.value=1.5"],
            "--param: invalid sphere.bsdf.alpha.value: value 1.5 is outside [0.001, 1]",
        ),
        (&["--target-set", "sphere.bsdf.alpha.value=x", "--param", "sphere.bsdf.alpha.value"], "invalid --target-set"),
        (&["--param", "sphere.bsdf.alpha.value"], "give --target REF.exr or --target-set"),
        (
            &["--target", "small.exr", "--param", "sphere.bsdf.alpha.value"],
            "small.exr: it is 8×8 but the render is 16×16",
        ),
        (&["--target", "missing.exr", "--param", "sphere.bsdf.alpha.value"], "missing.exr"),
        (
            &["--target-set", "sphere.bsdf.alpha.value=0.1", "--param", "sphere.bsdf.alpha.value", "--spp-grad", "0"],
            "invalid --spp-grad",
        ),
        (
            &["--target-set", "sphere.bsdf.alpha.value=0.1", "--param", "sphere.bsdf.alpha.value", "--lr", "0"],
            "invalid --lr",
        ),
        (
            &["--target-set", "sphere.bsdf.alpha.value=0.1", "--param", "sphere.bsdf.alpha.value", "--beta1", "1"],
            "invalid --beta1: 1 is not in [0, 1)",
        ),
        (
            &[
                "--target-set",
                "sphere.bsdf.alpha.value=0.1",
                "--param",
                "sphere.bsdf.alpha.value",
                "--adaptive=false",
                "--adaptive-estimator",
                "pixel_mean",
            ],
            "not with --adaptive=false",
        ),
    ];
    for (args, message) in cases {
        let o = pathgrad().current_dir(dir.path()).args(base).args(args).args(["-o", "out"]).output().unwrap();
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{args:?} should fail");
        assert!(stderr.contains(message), "{args:?}: expected '{message}' in: {stderr}");
        assert!(!stderr.contains("panicked"), "{stderr}");
        assert!(!dir.path().join("out").exists(), "{args:?} left an output directory");
    }
    let o = pathgrad().current_dir(dir.path()).args(["optimize", "--resume", "nowhere"]).output().unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && stderr.contains("--resume nowhere: reading nowhere/state.json"), "{stderr}");
    // A directory that holds a run is not overwritten.
    ok(&pathgrad().current_dir(dir.path()).args(SMALL).args(["--iters", "0", "-o", "out"]).output().unwrap());
    let o = pathgrad().current_dir(dir.path()).args(SMALL).args(["--iters", "1", "-o", "out"]).output().unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && stderr.contains("already holds a run"), "{stderr}");
    assert_eq!(rows(&dir.path().join("out")).1.len(), 0);
    let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(names.len(), 2, "only small.exr and out/: {names:?}");
}

/// A target with a NaN or an infinity would make every gradient non-finite: it is refused before
/// anything runs, naming the file, the pixel and the channel, and no output directory is made.
#[test]
fn a_non_finite_target_is_refused_with_the_pixel_named() {
    let dir = tempfile::tempdir().unwrap();
    for (k, bad) in [f32::NAN, f32::INFINITY].into_iter().enumerate() {
        let target = dir.path().join(format!("target{k}.exr"));
        let mut image = pathgrad::image::Image::new(16, 12);
        image.as_mut_slice().fill(0.2);
        image.set_pixel(3, 4, [0.2, bad, 0.2]);
        image.write_exr(&target).unwrap();
        let out = dir.path().join("run");
        let o = pathgrad()
            .args(["optimize", "builtin:blend", "--target"])
            .arg(&target)
            .args(["--param", "object.weight.value=0.8", "--width", "16", "--iters", "2", "-o"])
            .arg(&out)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{stderr}");
        let want = format!("target{k}.exr: pixel (3, 4) channel G is {bad}");
        assert!(stderr.contains(&want), "expected '{want}' in: {stderr}");
        assert!(!out.exists(), "nothing is written for a refused target");
    }
}

/// `optimize --cpu` runs the same protocol on the CPU reference: every iteration's loss, parameter
/// and gradient norm match the GPU run's within the GPU-vs-CPU gradient tolerance (1e-3 relative,
/// tests/it/gradients.rs), and `variance --cpu` gives the GPU's variances within it.
#[test]
fn optimize_and_variance_run_on_the_cpu_reference_like_on_the_gpu() {
    let dir = tempfile::tempdir().unwrap();
    let (gpu, cpu) = (dir.path().join("gpu"), dir.path().join("cpu"));
    ok(&run(SMALL, &["--iters", "4", "-o", gpu.to_str().unwrap()]));
    ok(&run(SMALL, &["--iters", "4", "--cpu", "-o", cpu.to_str().unwrap()]));
    let ((header, on_gpu), (_, on_cpu)) = (rows(&gpu), rows(&cpu));
    assert_eq!(on_gpu.len(), 4);
    for (g, c) in on_gpu.iter().zip(&on_cpu) {
        for column in ["loss", "object.weight.value", "grad_norm"] {
            let i = header.iter().position(|h| h == column).unwrap();
            let (a, b): (f64, f64) = (g[i].parse().unwrap(), c[i].parse().unwrap());
            assert!((a - b).abs() <= 1e-3 * a.abs().max(b.abs()), "iteration {}: {column} GPU {a} vs CPU {b}", g[0]);
        }
    }
    let summary = |extra: &[&str]| {
        let out = dir.path().join(format!("v{}", extra.len()));
        let o = crate::cli::pathgrad()
            .args(["variance", "builtin:blend", "--param", "object.weight.value", "--strategy", "bsdf,diff"])
            .args(["--runs", "3", "--spp", "1", "--width", "16", "--json", "-o"])
            .arg(&out)
            .args(extra)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        serde_json::from_slice::<serde_json::Value>(&o.stdout).unwrap()
    };
    let (g, c) = (summary(&[]), summary(&["--cpu"]));
    assert_eq!(c["device"], "CPU reference");
    for (rg, rc) in g["techniques"].as_array().unwrap().iter().zip(c["techniques"].as_array().unwrap()) {
        let (a, b) = (rg["variance"].as_f64().unwrap(), rc["variance"].as_f64().unwrap());
        assert!((a - b).abs() <= 1e-3 * a.abs().max(b.abs()), "{}: GPU {a} vs CPU {b}", rg["technique"]);
    }
}

/// `--control-variates`: five iterations (the weights start at the fourth), then `--resume` to
/// eight, give the eight-in-one-go run's rows bit for bit (fixed-point gradients): the running
/// estimate, its statistics and the previous parameters travel in `control_variates.bin`.
/// Turning the flag on at `--resume` is refused by name, and so is a state file that does not
/// belong to the run; the first three iterations are the plain run's (the weight is still 0).
#[test]
fn control_variates_resume_bit_for_bit_and_match_plain_while_the_weight_is_zero() {
    let dir = tempfile::tempdir().unwrap();
    let (whole, split, plain) = (dir.path().join("whole"), dir.path().join("split"), dir.path().join("plain"));
    let cv = ["--control-variates", "--deterministic", "--seed", "3", "--lr", "0.05"];
    ok(&run(SMALL, &[&cv[..], &["--iters", "8", "-o", whole.to_str().unwrap()]].concat()));
    ok(&run(SMALL, &[&cv[..], &["--iters", "5", "-o", split.to_str().unwrap()]].concat()));
    let off = ["--control-variates=false"];
    ok(&run(SMALL, &[&off[..], &cv[1..], &["--iters", "5", "-o", plain.to_str().unwrap()]].concat()));
    assert!(split.join("control_variates.bin").is_file());
    let o = run(&["optimize", "--resume", split.to_str().unwrap(), "--iters", "5", "--json"], &[]);
    ok(&o);
    let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(summary["outputs"].to_string().contains("control_variates.bin"), "{summary}");
    assert!(!plain.join("control_variates.bin").exists());
    // Turning them on for a run that had none is refused (left out, a run keeps its own setting).
    let o = run(&["optimize", "--resume", plain.to_str().unwrap(), "--control-variates", "--iters", "6"], &[]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && stderr.contains("--control-variates true (the run has false)"), "{stderr}");
    // A state file of another iteration (the plain run has none; take the whole run's) is refused.
    let saved = std::fs::read(split.join("control_variates.bin")).unwrap();
    std::fs::copy(whole.join("control_variates.bin"), split.join("control_variates.bin")).unwrap();
    let o = run(&["optimize", "--resume", split.to_str().unwrap(), "--iters", "8"], &[]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && stderr.contains("after 8 iterations but state.json is after 5"), "{stderr}");
    std::fs::write(split.join("control_variates.bin"), &saved[..saved.len() - 1]).unwrap();
    let o = run(&["optimize", "--resume", split.to_str().unwrap(), "--iters", "8"], &[]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && stderr.contains("truncated"), "{stderr}");
    std::fs::write(split.join("control_variates.bin"), &saved).unwrap();
    ok(&run(&["optimize", "--resume", split.to_str().unwrap(), "--iters", "8"], &[]));
    let ((_, resumed), (_, straight), (_, plain_rows)) = (rows(&split), rows(&whole), rows(&plain));
    assert_eq!(resumed.len(), 8);
    for (a, b) in resumed.iter().zip(&straight) {
        assert_eq!((&a[0], &a[2..]), (&b[0], &b[2..]), "everything but the wall time agrees bit for bit");
    }
    for (t, (a, b)) in straight.iter().zip(&plain_rows).enumerate() {
        if t < 3 {
            assert_eq!(&a[2..], &b[2..], "iteration {t}: v = 0, the plain run");
        } else {
            assert_ne!(a[2], b[2], "iteration {t}: the control variates change the loss");
        }
    }
}

/// `--reuse`: five iterations, then `--resume` to eight, give the eight-in-one-go run's rows bit
/// for bit (fixed-point gradients): the running gradient estimate, its statistics and the previous
/// parameters travel in `gradient_reuse.bin`. The first three iterations are the plain run's (the
/// weights start at the fourth; G is the plain gradient with the same seed), the fourth is not.
/// A truncated state file is refused, and so is `--reuse` with `--control-variates`.
#[test]
fn gradient_reuse_resumes_bit_for_bit_and_matches_plain_while_the_weight_is_zero() {
    let dir = tempfile::tempdir().unwrap();
    let (whole, split, plain) = (dir.path().join("whole"), dir.path().join("split"), dir.path().join("plain"));
    let reuse = ["--reuse", "--deterministic", "--seed", "3", "--lr", "0.05"];
    ok(&run(SMALL, &[&reuse[..], &["--iters", "8", "-o", whole.to_str().unwrap()]].concat()));
    ok(&run(SMALL, &[&reuse[..], &["--iters", "5", "-o", split.to_str().unwrap()]].concat()));
    let off = ["--control-variates=false"];
    ok(&run(SMALL, &[&off[..], &reuse[1..], &["--iters", "5", "-o", plain.to_str().unwrap()]].concat()));
    assert!(split.join("gradient_reuse.bin").is_file() && !plain.join("gradient_reuse.bin").exists());
    // --reuse replaces the control variates, which are on by default.
    assert!(!split.join("control_variates.bin").exists());
    let saved = std::fs::read(split.join("gradient_reuse.bin")).unwrap();
    std::fs::write(split.join("gradient_reuse.bin"), &saved[..saved.len() - 1]).unwrap();
    let o = run(&["optimize", "--resume", split.to_str().unwrap(), "--iters", "8"], &[]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && stderr.contains("gradient-reuse state") && stderr.contains("truncated"), "{stderr}");
    std::fs::write(split.join("gradient_reuse.bin"), &saved).unwrap();
    let o = run(&["optimize", "--resume", split.to_str().unwrap(), "--iters", "8", "--json"], &[]);
    ok(&o);
    let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(summary["outputs"].to_string().contains("gradient_reuse.bin"), "{summary}");
    let ((_, resumed), (_, straight), (_, plain_rows)) = (rows(&split), rows(&whole), rows(&plain));
    assert_eq!(resumed.len(), 8);
    for (a, b) in resumed.iter().zip(&straight) {
        assert_eq!((&a[0], &a[2..]), (&b[0], &b[2..]), "everything but the wall time agrees bit for bit");
    }
    for (t, (a, b)) in straight.iter().zip(&plain_rows).enumerate() {
        if t < 3 {
            assert_eq!(&a[2..], &b[2..], "iteration {t}: v = 0, the plain run");
        } else if t == 3 {
            assert_ne!(&a[2..], &b[2..], "iteration {t}: the reused gradient moves the parameters otherwise");
        }
    }
    let o = run(SMALL, &["--reuse", "--control-variates", "-o", dir.path().join("both").to_str().unwrap()]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && stderr.contains("--reuse") && stderr.contains("--control-variates"), "{stderr}");
}

/// `optimize --cpu --control-variates` follows the GPU run within the GPU-vs-CPU gradient
/// tolerance (1e-3 relative), through iterations where the weights are in use: the control
/// variates are host-side and the same on both back ends.
#[test]
fn control_variates_run_on_the_cpu_reference_like_on_the_gpu() {
    let dir = tempfile::tempdir().unwrap();
    let (gpu, cpu) = (dir.path().join("gpu"), dir.path().join("cpu"));
    let cv = ["--control-variates", "--iters", "5"];
    ok(&run(SMALL, &[&cv[..], &["-o", gpu.to_str().unwrap()]].concat()));
    ok(&run(SMALL, &[&cv[..], &["--cpu", "-o", cpu.to_str().unwrap()]].concat()));
    let ((header, on_gpu), (_, on_cpu)) = (rows(&gpu), rows(&cpu));
    assert_eq!(on_gpu.len(), 5);
    for (g, c) in on_gpu.iter().zip(&on_cpu) {
        for column in ["loss", "object.weight.value", "grad_norm"] {
            let i = header.iter().position(|h| h == column).unwrap();
            let (a, b): (f64, f64) = (g[i].parse().unwrap(), c[i].parse().unwrap());
            assert!((a - b).abs() <= 1e-3 * a.abs().max(b.abs()), "iteration {}: {column} GPU {a} vs CPU {b}", g[0]);
        }
    }
}

/// `--control-variates` over two `--view`s keeps one running estimate per view (the state file
/// says two views of 16×16) and, as with one view, equals the plain run bit for bit through the
/// warm-up (iterations 0–2) and parts from it once the weights are in use.
#[test]
fn control_variates_keep_an_estimate_per_view() {
    let dir = tempfile::tempdir().unwrap();
    let scene = concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/two-sided/scene.xml");
    let args = |out: &Path, cv: bool| {
        let mut a = vec![
            "optimize",
            scene,
            "--param",
            "front.reflectance.value=0.5",
            "--param",
            "back.reflectance.value=0.5",
            "--target-set",
            "front.reflectance.value=0.7,0.3,0.2",
            "--target-set",
            "back.reflectance.value=0.2,0.4,0.7",
            "--view",
            "front_camera",
            "--view",
            "back_camera",
            "--width",
            "16",
            "--height",
            "16",
            "--spp",
            "4",
            "--iters",
            "5",
            "--deterministic",
            "--lr",
            "0.03",
            "-o",
        ];
        a.push(out.to_str().unwrap());
        a.push(if cv { "--control-variates" } else { "--control-variates=false" });
        run(&a, &[])
    };
    let (with_cv, plain) = (dir.path().join("cv"), dir.path().join("plain"));
    ok(&args(&with_cv, true));
    ok(&args(&plain, false));
    let state = std::fs::read(with_cv.join("control_variates.bin")).unwrap();
    let word = |at: usize| u32::from_le_bytes(state[at..at + 4].try_into().unwrap());
    assert_eq!((word(24), word(28), word(32)), (16, 16, 2), "width, height and views of the state");
    let ((_, a), (_, b)) = (rows(&with_cv), rows(&plain));
    for (t, (a, b)) in a.iter().zip(&b).enumerate() {
        if t < 3 {
            assert_eq!(&a[2..], &b[2..], "iteration {t}");
        } else {
            assert_ne!(a[2], b[2], "iteration {t}");
        }
    }
}

/// `--strategy auto` pilots once, in the preparation: the choice is reported (`--json`, the info
/// line), stored in `state.json`, and `--resume` continues with it without piloting again.
#[test]
fn strategy_auto_pilots_once_and_resume_reuses_its_choice() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("auto");
    let o = run(SMALL, &["--strategy", "auto", "--iters", "2", "--json", "-v", "-o", out.to_str().unwrap()]);
    ok(&o);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(stderr.contains("--strategy auto picked"), "{stderr}");
    let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let pilot = &summary["pilot"];
    assert_eq!(pilot["candidates"].as_array().unwrap().len(), 4, "{summary}");
    assert!(pilot["pilot_s"].as_f64().unwrap() > 0.0, "{summary}");
    assert_eq!(&summary["strategy"], &pilot["picked"], "{summary}");
    let stored = json(&out.join("state.json"))["config"]["pilot"].clone();
    assert_eq!(stored["report"], *pilot);
    let o = run(&["optimize", "--resume", out.to_str().unwrap(), "--iters", "3", "--json", "-v"], &[]);
    ok(&o);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(!stderr.contains("--strategy auto picked"), "resumed runs do not pilot again: {stderr}");
    let resumed: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(resumed["pilot"], *pilot);
    assert_eq!(resumed["strategy"], pilot["picked"]);
    assert_eq!(resumed["iterations"], 3);
}

/// The hero strategy in `optimize` (two roughnesses, weights adapted to each one's gradient
/// variance, ALGORITHMS.md §5.8): three iterations, then `--resume` to six, give the six-in-one-go
/// run's rows bit for bit (fixed-point gradients): the running variances travel in
/// `state.json`, and the adapted weights leave uniform. A state file without them is refused, and so
/// is a hero set with a target that is not optimised (its variance is unknown).
#[test]
fn hero_weights_adapt_and_resume_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    let (whole, split) = (dir.path().join("whole"), dir.path().join("split"));
    let scene = format!("{}/tests/data/scenes/hero_spheres.xml", env!("CARGO_MANIFEST_DIR"));
    let (left, right) = ("left.bsdf.alpha.value", "right.bsdf.alpha.value");
    let args = [
        "optimize",
        &scene,
        "--deterministic",
        "--target-set",
        "left.bsdf.alpha.value=0.1",
        "--target-set",
        "right.bsdf.alpha.value=0.2",
        "--param",
        left,
        "--param",
        right,
        "--strategy",
        "diff",
        "--diff-param",
        "left.bsdf.alpha.value,right.bsdf.alpha.value",
        "--width",
        "16",
        "--height",
        "16",
        "--spp-primal",
        "2",
        "--spp-grad",
        "2",
        "--spp",
        "2",
        "--lr",
        "0.02",
    ];
    ok(&run(&args, &["--iters", "6", "-o", whole.to_str().unwrap()]));
    ok(&run(&args, &["--iters", "3", "-o", split.to_str().unwrap()]));
    let state = json(&split.join("state.json"));
    assert_eq!(state["hero"]["steps"], 3, "{state}");
    ok(&run(&["optimize", "--resume", split.to_str().unwrap(), "--iters", "6"], &[]));
    let ((_, resumed), (_, straight)) = (rows(&split), rows(&whole));
    assert_eq!(resumed.len(), 6);
    for (a, b) in resumed.iter().zip(&straight) {
        assert_eq!((&a[0], &a[2..]), (&b[0], &b[2..]), "everything but the wall time agrees bit for bit");
    }
    let state = json(&whole.join("state.json"));
    let hero = &state["hero"];
    assert_eq!(hero["steps"], 6);
    // The weights these moments give are not uniform (each keeps at least 0.125).
    let variance = |k: usize| {
        let c = 1.0 - 0.9f64.powi(6);
        let (m, s) = (hero["mean"][k].as_f64().unwrap() / c, hero["square"][k].as_f64().unwrap() / c);
        (s - m * m).max(0.0)
    };
    let p0 = 0.125 + 0.75 * variance(0) / (variance(0) + variance(1));
    assert!((p0 - 0.5).abs() > 0.01 && (0.125..=0.875).contains(&p0), "p0 = {p0}");
    // A state.json whose hero state is missing is refused.
    let mut broken = json(&split.join("state.json"));
    broken.as_object_mut().unwrap().remove("hero");
    std::fs::write(split.join("state.json"), broken.to_string()).unwrap();
    let o = run(&["optimize", "--resume", split.to_str().unwrap(), "--iters", "7"], &[]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && stderr.contains("no `hero` state"), "{stderr}");
    // A hero that is not optimised: refused by name.
    let o = run(
        &args[..9],
        &[
            "--strategy",
            "diff",
            "--diff-param",
            "left.bsdf.alpha.value,floor.bsdf.weight.value",
            "--iters",
            "1",
            "-o",
            dir.path().join("x").to_str().unwrap(),
        ],
    );
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && stderr.contains("floor.bsdf.weight.value is not optimised"), "{stderr}");
}

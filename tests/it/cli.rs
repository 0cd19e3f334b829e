//! The `pathgrad` binary as a person uses it: outputs, summaries and error messages.

use std::process::Command;

/// The binary under test, on lavapipe unless `PATHGRAD_DEVICE` or `PATHGRAD_TEST_DEVICE` says otherwise.
pub(crate) fn pathgrad() -> Command {
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
        .args([
            "render",
            "builtin:cornell-box",
            "--spp",
            "2",
            "--width",
            "32",
            "--seed",
            "5",
            "--json",
            "--repeat",
            "2",
        ])
        .arg("-o")
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(summary["width"], 32);
    assert_eq!(summary["height"], 32, "the height follows the scene's aspect ratio");
    assert!(summary["samples_per_second"].as_f64().unwrap() > 0.0);
    let repeats = summary["repeat_s"].as_array().unwrap();
    assert!(repeats.len() == 2 && repeats.iter().all(|t| t.as_f64().unwrap() > 0.0), "--repeat 2: {summary}");
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
    let cases: [(&[&str], &str); 8] = [
        (
            &["render", "builtin:cornell-box", "--device", "99", "-o", "x.exr"],
            "no Vulkan device matches '99' (available: [0]",
        ),
        (&["render", "builtin:nope", "-o", "x.exr"], "unknown built-in scene (known: cornell-box, furnace, blend)"),
        (&["render", "scene.xml", "-o", "x.exr"], "scene.xml: No such file"),
        (
            &["render", "scene.blend", "-o", "x.exr"],
            "scene.blend: unsupported scene format (supported: .xml (Mitsuba 3), .gltf/.glb",
        ),
        (&["render", "builtin:cornell-box", "-o", "x.jpg"], "must end in .exr or .png"),
        (&["render", "builtin:cornell-box", "--spp", "0", "-o", "x.exr"], "invalid --spp"),
        (&["render", "builtin:cornell-box", "--max-depth", "0", "-o", "x.exr"], "--max-depth"),
        (
            &["render", "builtin:blend", "-D", "weight=0.3", "-o", "x.exr"],
            "builtin:blend: -D weight=…: only a Mitsuba XML scene has <default> values",
        ),
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

#[test]
fn grad_prints_loss_and_gradients_as_json() {
    let o = pathgrad()
        .args(["grad", "builtin:cornell-box", "--target-set", "sphere.bsdf.alpha.value=0.4", "--param", "sphere.*"])
        .args(["--spp", "2", "--width", "16", "--json", "--deterministic", "--repeat", "1"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(v["loss"].as_f64().unwrap() > 0.0);
    assert!(v["time_s"].as_f64().unwrap() > 0.0);
    assert_eq!(v["repeat_s"].as_array().unwrap().len(), 1, "--repeat 1: {v}");
    let g = v["gradients"].as_object().unwrap();
    assert_eq!(
        g.keys().collect::<Vec<_>>(),
        [
            "sphere.bsdf.alpha.value",
            "sphere.bsdf.eta.value",
            "sphere.bsdf.k.value",
            "sphere.bsdf.specular_reflectance.value"
        ]
    );
    assert_eq!(g["sphere.bsdf.specular_reflectance.value"].as_array().unwrap().len(), 3);
}

/// `--strategy auto` says what its pilot picked, what each candidate measured and what the pilot
/// cost, and the gradient is taken with the pick.
#[test]
fn grad_strategy_auto_reports_its_pilot() {
    let o = pathgrad()
        .args(["grad", "builtin:blend", "--target-set", "object.weight.value=0.3", "--param", "object.weight.value"])
        .args(["--spp", "2", "--width", "16", "--height", "16", "--json", "--strategy", "auto", "-v"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let pilot = &v["pilot"];
    let candidates = pilot["candidates"].as_array().unwrap();
    let names: Vec<&str> = candidates.iter().map(|c| c["technique"].as_str().unwrap()).collect();
    assert_eq!(names, ["bsdf", "diff q=0.5", "diff q=0.75", "diff q=0.9"], "{v}");
    assert!(pilot["pilot_s"].as_f64().unwrap() > 0.0, "{v}");
    // Warm-up: one pass 1 and the two kernels; then 4 runs of one pass 1 and 4 candidates.
    assert_eq!(pilot["pilot_renders"], 3 + 4 * 5, "{v}");
    assert_eq!(pilot["measure"], "loss gradient", "{v}");
    // The pick is the candidate of least variance × time, and the one the gradient used.
    let best = candidates
        .iter()
        .min_by(|a, b| a["efficiency"].as_f64().unwrap().total_cmp(&b["efficiency"].as_f64().unwrap()))
        .unwrap();
    let picked = &pilot["picked"];
    let label = picked["technique"].as_str().unwrap();
    // Within 5 % the earlier candidate is kept (`PILOT_MARGIN`).
    let efficiency =
        |name: &str| candidates.iter().find(|c| c["technique"] == name).unwrap()["efficiency"].as_f64().unwrap();
    assert!(efficiency(label) <= best["efficiency"].as_f64().unwrap() / 0.95, "{v}");
    assert_eq!(&v["strategy"], picked, "{v}");
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(stderr.contains(&format!("--strategy auto picked {label} for object.weight.value")), "{stderr}");
    assert_eq!(picked["strategy"], if label == "bsdf" { "bsdf" } else { "diff" }, "{v}");
}

#[test]
fn grad_writes_an_image_gradient_with_a_signed_preview() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("d.exr");
    let o = pathgrad()
        .args(["grad", "builtin:blend", "--image-gradient", "object.weight.value", "--spp", "2", "--width", "24", "-o"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let image = pathgrad::image::Image::read_exr(&out).unwrap();
    assert!(image.as_slice().iter().any(|&v| v != 0.0));
    assert!(dir.path().join("d.png").exists());
}

#[test]
fn grad_errors_name_what_is_wrong() {
    let dir = tempfile::tempdir().unwrap();
    let cases: [(&[&str], &str); 4] = [
        (&["grad", "builtin:cornell-box"], "give --target REF.exr or --target-set"),
        (&["grad", "builtin:cornell-box", "--target-set", "nope=1"], "nope: matches no parameter"),
        (&["grad", "builtin:cornell-box", "--target", "missing.exr"], "missing.exr"),
        (
            &["grad", "builtin:cornell-box", "--target-set", "sphere.bsdf.alpha.value=0.3", "--loss", "l3"],
            "'l3' (expected relmse, relmse_max, l2 or l1)",
        ),
    ];
    for (args, message) in cases {
        let o = pathgrad().current_dir(dir.path()).args(args).args(["--spp", "1", "--width", "8"]).output().unwrap();
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{args:?} should fail");
        assert!(stderr.contains(message), "{args:?}: expected '{message}' in: {stderr}");
    }
}

/// A Cornell-box render (24 px wide, 2 spp) to `dir/tag.exr` and a `--deterministic` gradient of
/// the sphere's parameters, each a CLI process that `configure` sets up: the image's bytes, the
/// loss and the gradients.
fn render_and_grad(
    dir: &std::path::Path,
    tag: &str,
    configure: impl Fn(&mut Command),
) -> (Vec<u8>, serde_json::Value, serde_json::Value) {
    let out = dir.join(format!("{tag}.exr"));
    let mut c = pathgrad();
    configure(&mut c);
    let o = c
        .args(["render", "builtin:cornell-box", "--spp", "2", "--width", "24", "--no-preview", "-o"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let mut c = pathgrad();
    configure(&mut c);
    let g = c
        .args(["grad", "builtin:cornell-box", "--target-set", "sphere.bsdf.alpha.value=0.4", "--param", "sphere.*"])
        .args(["--spp", "2", "--width", "16", "--json", "--deterministic"])
        .output()
        .unwrap();
    assert!(g.status.success(), "{}", String::from_utf8_lossy(&g.stderr));
    let v: serde_json::Value = serde_json::from_slice(&g.stdout).unwrap();
    (std::fs::read(&out).unwrap(), v["loss"].clone(), v["gradients"].clone())
}

/// Kernels specialised on the host (src/gpu/specialise.rs), fresh or from its disk cache, render
/// and differentiate bit for bit like kernels the driver specialises (`PATHGRAD_SPECIALISE=0`),
/// and the host's are cached where the cache directory says.
#[test]
fn host_specialised_kernels_match_the_drivers_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    let cache = dir.path().join("cache");
    let run = |tag: &str, host: bool| {
        render_and_grad(dir.path(), tag, |c| {
            c.env("XDG_CACHE_HOME", &cache).env("PATHGRAD_SPECIALISE", if host { "1" } else { "0" });
        })
    };
    let fresh = run("fresh", true);
    let cached_files = std::fs::read_dir(cache.join("pathgrad/kernels")).map(|d| d.count()).unwrap_or(0);
    assert!(cached_files >= 2, "the primal and adjoint kernels are cached: {cached_files} files");
    let cached = run("cached", true);
    let driver = run("driver", false);
    assert!(fresh.0 == cached.0 && fresh.0 == driver.0, "the images differ");
    assert_eq!((&fresh.1, &fresh.2), (&cached.1, &cached.2));
    assert_eq!((&fresh.1, &fresh.2), (&driver.1, &driver.2));
}

/// The CLI has lavapipe build kernels for `pathgrad::gpu::lavapipe_vector_width()` bits (512 on an
/// AVX-512 host, 128 elsewhere) unless `LP_NATIVE_VECTOR_WIDTH` is set (its `main`); a render and
/// a deterministic gradient come out bit for bit the same at the driver's own default, 256 bits
/// (8 lanes; subgroups of 8 in the gradient's reductions), and at 128 bits (4 lanes). Above 128
/// bits Mesa's shader cache is kept in a folder of the width's.
#[test]
fn the_clis_vector_width_changes_no_result() {
    let dir = tempfile::tempdir().unwrap();
    let run = |tag: &str, width: Option<&str>| {
        let cache = dir.path().join(format!("cache-{tag}"));
        render_and_grad(dir.path(), tag, |c| {
            c.env("XDG_CACHE_HOME", &cache).env_remove("MESA_SHADER_CACHE_DIR").env_remove("MESA_SHADER_CACHE_DISABLE");
            match width {
                Some(w) => c.env("LP_NATIVE_VECTOR_WIDTH", w),
                None => c.env_remove("LP_NATIVE_VECTOR_WIDTH"),
            };
        })
    };
    let cli_default = run("default", None);
    let mut widths = vec!["256"];
    let bits = pathgrad::gpu::lavapipe_vector_width();
    // The tests' device (`pathgrad()`): lavapipe unless a variable names another.
    let device = std::env::var("PATHGRAD_DEVICE").or_else(|_| std::env::var("PATHGRAD_TEST_DEVICE")).ok();
    let on_lavapipe = device.is_none_or(|d| d == "cpu");
    if bits != 128 {
        widths.push("128");
        if on_lavapipe {
            // Mesa's cache went to the width's own folder (lavapipe's keys do not tell widths
            // apart), and the driver took the width: its subgroups have bits/32 lanes.
            let mesa = dir.path().join(format!("cache-default/pathgrad/mesa-{bits}-bit"));
            let entries = std::fs::read_dir(&mesa).map(|d| d.count()).unwrap_or(0);
            assert!(entries > 0, "no shader cache in {}", mesa.display());
            let o = pathgrad()
                .args(["devices", "--json"])
                .env("XDG_CACHE_HOME", dir.path().join("cache-devices"))
                .env_remove("LP_NATIVE_VECTOR_WIDTH")
                .env_remove("MESA_SHADER_CACHE_DIR")
                .output()
                .unwrap();
            let listed: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
            let lavapipe =
                listed.as_array().unwrap().iter().find(|d| d["driver"].as_str().unwrap().contains("llvmpipe"));
            assert_eq!(lavapipe.unwrap()["subgroup_size"].as_u64(), Some(u64::from(bits / 32)), "{listed}");
        }
    }
    for width in widths {
        let driver = run(&format!("w{width}"), Some(width));
        assert!(cli_default.0 == driver.0, "the images differ at {width} bits");
        assert_eq!((&cli_default.1, &cli_default.2), (&driver.1, &driver.2), "{width} bits");
    }
}

#[test]
fn env_lights_a_gltf_asset_without_lights() {
    let dir = tempfile::tempdir().unwrap();
    let scene = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/gltf/no_camera.gltf");
    let render = |extra: &[&str], name: &str| {
        let out = dir.path().join(name);
        let o = pathgrad()
            .args(["render", scene, "--spp", "2", "--width", "16"])
            .args(extra)
            .arg("-o")
            .arg(&out)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        (pathgrad::image::Image::read_exr(&out).unwrap().mean(), String::from_utf8_lossy(&o.stderr).into_owned())
    };
    // Without: black, and the warning names the flag that lights it (the library's name for it
    // spelled as the CLI's).
    let (dark, stderr) = render(&[], "dark.exr");
    assert_eq!(dark, [0.0; 3]);
    assert!(stderr.contains("unless lit by an environment (--env)"), "{stderr}");
    let (lit, stderr) = render(&["--env", "0.5,1,2"], "lit.exr");
    assert!(lit[0] > 0.0 && lit[0] < lit[1] && lit[1] < lit[2], "{lit:?}");
    assert!(!stderr.contains("no emitters"), "{stderr}");
    // A map file lights it too: a 4 × 2 sky, brighter in blue, as the map's texels `env.data`.
    let sky = dir.path().join("sky.exr");
    let texels: Vec<f32> = (0..8).flat_map(|_| [0.5, 1.0, 2.0]).collect();
    pathgrad::image::Image::from_rgb(4, 2, texels).unwrap().write_exr(&sky).unwrap();
    let (mapped, stderr) = render(&["--env", sky.to_str().unwrap()], "mapped.exr");
    assert!(mapped[0] > 0.0 && mapped[0] < mapped[1] && mapped[1] < mapped[2], "{mapped:?}");
    // A constant map of the constant's radiance lights it the same way (up to noise).
    assert!(mapped.iter().zip(&lit).all(|(m, l)| (m - l).abs() < 0.05 * l), "{mapped:?} vs {lit:?}");
    assert!(!stderr.contains("no emitters"), "{stderr}");
    for (bad, message) in [
        ("1,2", "2 values: give R,G,B or one number"),
        ("missing.exr", "environment map 'missing.exr' not found"),
        ("0,-1,0", "must be finite and ≥ 0"),
    ] {
        let o =
            pathgrad().args(["render", scene, "--env", bad, "-o", "x.exr"]).current_dir(dir.path()).output().unwrap();
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success() && stderr.contains(message), "--env {bad}: {stderr}");
    }
}

/// Issue 38: `render --json` breaks the run into phases (parse, assemble, flatten, bvh, then device
/// and upload on a GPU — the shading data is made during the upload — or shading on the CPU
/// reference, render, write), each with non-negative seconds and, on Linux, the peak RSS at its end,
/// and reports the device memory the scene's buffers take.
#[test]
fn issue_38_render_json_reports_every_phase() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::copy("tests/data/mesh/quad_binary.ply", dir.path().join("quad.ply")).unwrap();
    let scene = dir.path().join("scene.xml");
    std::fs::write(
        &scene,
        r#"<scene version="3.0.0">
    <sensor type="perspective">
        <transform name="to_world"><lookat origin="0, 0, 4" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/></film>
    </sensor>
    <shape type="ply"><string name="filename" value="quad.ply"/><bsdf type="diffuse"/></shape>
    <shape type="rectangle">
        <transform name="to_world"><translate z="3"/></transform>
        <emitter type="area"><rgb name="radiance" value="1, 1, 1"/></emitter>
    </shape>
</scene>"#,
    )
    .unwrap();
    for (backend, names, on_device) in [
        (None, &["parse", "assemble", "flatten", "bvh", "device", "upload", "render", "write"][..], true),
        (Some("--cpu"), &["parse", "assemble", "flatten", "bvh", "shading", "render", "write"][..], false),
    ] {
        let o = pathgrad()
            .args(["render", "--spp", "1", "--json"])
            .args(backend)
            .arg(&scene)
            .arg("-o")
            .arg(dir.path().join("out.exr"))
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        let phases = summary["phases"].as_array().unwrap();
        let found: Vec<_> = phases.iter().map(|p| p["name"].as_str().unwrap()).collect();
        assert_eq!(found, names, "{summary}");
        for p in phases {
            assert!(p["seconds"].as_f64().unwrap() >= 0.0, "{p}");
            if cfg!(target_os = "linux") {
                let (rss, peak) = (p["rss_bytes"].as_u64().unwrap(), p["peak_rss_bytes"].as_u64().unwrap());
                assert!(rss > 0 && peak >= rss, "{p}");
            }
        }
        if cfg!(target_os = "linux") {
            assert!(summary["peak_rss_bytes"].as_u64().unwrap() > 0, "{summary}");
        }
        let device = &summary["device_bytes"];
        if on_device {
            let (scene_bytes, peak) = (device["scene"].as_u64().unwrap(), device["peak"].as_u64().unwrap());
            assert!(scene_bytes > 0 && peak >= scene_bytes, "{summary}");
        } else {
            assert!(device["scene"].is_null(), "the CPU reference has no device buffers: {summary}");
        }
    }
}

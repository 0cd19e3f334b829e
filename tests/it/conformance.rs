//! The conformance matrix: every scene of `tests/conformance/scenes/` rendered by the kernels and
//! compared with the Mitsuba 3 statistics stored beside it (`tests/conformance/reference/`,
//! written by `tests/conformance/mitsuba_reference.py`), primal and image gradients, block by block.
//!
//! For each scene and each compared quantity (the primal image; the forward-mode image gradient of
//! each parameter the reference lists, tangent 1 on every value), pathgrad renders `SEEDS` seeds
//! and takes, per seed, each B×B block's mean per channel and the image's mean per channel; over
//! the seeds, their means and standard errors. Each block, channel and image mean is compared
//! with Mitsuba's by Welch's t-test (the standard errors come from 32 and 16 seeds, so the
//! statistic has Student's tails; the variance (10⁻⁴ m)² stands for f32 rounding in blocks
//! without variance, a constant sky), and its p-value must stay above the Bonferroni level for a
//! family-wise false-alarm rate of 1 % over all the matrix's tests.
//!
//! The power check: at that level, each image mean must have the power (95 %) to see a relative
//! bias of 1 % (primal) or 5 % (gradients, relative to the mean |block value|), or the larger
//! bias that the scene's reference states (`primal_bias`, `gradient_bias`: the script's `POWER`
//! table, for the noisiest derivatives) — the test fails when it cannot. pathgrad's sample count
//! per scene is sized for it from the reference's own variance, then, where that falls short, from
//! its own measured variance, within a budget (`SPP_RANGE`); a quantity that fails at fewer than
//! the budget's top is rendered again at 4× the samples and judged by its last render
//! (`disagreements`).
//!
//! Every scene must also load without a warning (a warning means pathgrad approximates something,
//! which the matrix must not pass silently) but those its reference lists (`warnings`: a stand-in
//! such as the `direct` integrator, whose image must then still agree), and every parameter pathgrad exposes must carry one
//! of the names Mitsuba's `mi.traverse` prints for the scene.
//!
//! A reference marked `pending` (with its reason) is listed and not compared.
//!
//! A glTF scene (`gltf_*`) is read by pathgrad from the glTF file the reference names
//! (`pathgrad_scene`, at its `pathgrad_width`) and by Mitsuba from the XML that
//! `gltf_to_mitsuba.py` wrote of it; its parameters must be exactly those of the reference's
//! `pathgrad_keys` map, each with a Mitsuba key.
//!
//! `PATHGRAD_CONFORMANCE=name,name` restricts the run to those scenes (by file stem).

use std::path::{Path, PathBuf};

use pathgrad::backend::Backend;
use pathgrad::gpu::Renderer;
use pathgrad::image::Image;
use pathgrad::integrator::{RenderOptions, Sampling};
use serde_json::Value;

use crate::support::TestGpu;

/// Family-wise false-alarm rate of the whole matrix.
const FAMILY_ALPHA: f64 = 0.01;
/// Power demanded of each image-mean test against the bias below.
const POWER: f64 = 0.95;
/// The relative bias of the primal image mean the test must be able to see.
const PRIMAL_BIAS: f64 = 0.01;
/// The relative bias of an image gradient (against its mean |block value|) it must be able to see.
const GRADIENT_BIAS: f64 = 0.05;
/// Seeds per quantity on pathgrad's side: many, so that the standard errors' own uncertainty
/// (Student's t with about as many degrees of freedom) does not eat the power.
const SEEDS: u32 = 32;
/// The sample counts pathgrad may choose from (per seed): at most 8192 samples a pixel in all.
const SPP_RANGE: (u32, u32) = (4, 256);

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/conformance")
}

/// Per-block and image statistics of one quantity over seeds: means and standard errors.
#[derive(Clone, Debug)]
struct Stats {
    mean: Vec<[f64; 3]>,
    se: Vec<[f64; 3]>,
    image_mean: [f64; 3],
    image_se: [f64; 3],
}

fn triples(v: &Value) -> Vec<[f64; 3]> {
    v.as_array()
        .expect("an array of [r, g, b]")
        .iter()
        .map(|t| {
            let t = t.as_array().expect("[r, g, b]");
            [t[0].as_f64().unwrap(), t[1].as_f64().unwrap(), t[2].as_f64().unwrap()]
        })
        .collect()
}

fn triple(v: &Value) -> [f64; 3] {
    triples(&Value::Array(vec![v.clone()]))[0]
}

impl Stats {
    fn from_json(v: &Value) -> Stats {
        Stats {
            mean: triples(&v["mean"]),
            se: triples(&v["se"]),
            image_mean: triple(&v["image_mean"]),
            image_se: triple(&v["image_se"]),
        }
    }

    /// Statistics over the per-seed images `images`, in blocks of `block` pixels.
    fn of_images(images: &[Image], block: u32) -> Stats {
        let (w, h) = (images[0].width(), images[0].height());
        let (bx, by) = (w.div_ceil(block), h.div_ceil(block));
        let per_seed: Vec<(Vec<[f64; 3]>, [f64; 3])> = images
            .iter()
            .map(|img| {
                let mut sums = vec![[0.0f64; 3]; (bx * by) as usize];
                let mut counts = vec![0u32; (bx * by) as usize];
                let mut total = [0.0f64; 3];
                for (i, px) in img.as_slice().chunks_exact(3).enumerate() {
                    let (x, y) = (i as u32 % w, i as u32 / w);
                    let b = ((y / block) * bx + x / block) as usize;
                    counts[b] += 1;
                    for c in 0..3 {
                        sums[b][c] += f64::from(px[c]);
                        total[c] += f64::from(px[c]);
                    }
                }
                let blocks = sums.iter().zip(&counts).map(|(s, &n)| s.map(|v| v / f64::from(n))).collect();
                (blocks, total.map(|v| v / f64::from(w * h)))
            })
            .collect();
        let n = per_seed.len() as f64;
        let mean_se = |values: &dyn Fn(usize) -> f64| {
            let m = (0..per_seed.len()).map(values).sum::<f64>() / n;
            let var = (0..per_seed.len()).map(|s| (values(s) - m).powi(2)).sum::<f64>() / (n - 1.0);
            (m, (var / n).sqrt())
        };
        let mut stats = Stats { mean: Vec::new(), se: Vec::new(), image_mean: [0.0; 3], image_se: [0.0; 3] };
        for b in 0..(bx * by) as usize {
            let (mut m, mut e) = ([0.0; 3], [0.0; 3]);
            for c in 0..3 {
                (m[c], e[c]) = mean_se(&|s| per_seed[s].0[b][c]);
            }
            stats.mean.push(m);
            stats.se.push(e);
        }
        for c in 0..3 {
            (stats.image_mean[c], stats.image_se[c]) = mean_se(&|s| per_seed[s].1[c]);
        }
        stats
    }

    /// The scale a relative bias is measured against, per channel: |image mean| for the primal,
    /// the mean |block value| for a gradient (whose image mean may cancel).
    fn scale(&self, gradient: bool) -> [f64; 3] {
        if !gradient {
            return self.image_mean.map(f64::abs);
        }
        let n = self.mean.len() as f64;
        [0, 1, 2].map(|c| self.mean.iter().map(|b| b[c].abs()).sum::<f64>() / n)
    }
}

/// Welch's t of pathgrad's value `p` (standard error `sp` over `np` seeds) against Mitsuba's `m`
/// (`sm` over `nm`), with the rounding floor (10⁻⁴ m)² as a variance known exactly: (t, degrees
/// of freedom by Welch–Satterthwaite, two-sided p-value). The standard errors come from 32 and 16
/// seeds, so the statistic's tail is Student's, far heavier than the normal's at Bonferroni
/// levels (|t| 4.9 is p = 10⁻⁶ for the normal, 0.0018 for 7 dof, 0.0002 for 15).
fn welch(p: f64, sp: f64, np: f64, m: f64, sm: f64, nm: f64) -> (f64, f64, f64) {
    let floor = (1e-4 * m).powi(2);
    let var = sp * sp + sm * sm + floor;
    if var == 0.0 {
        return if p == m { (0.0, f64::INFINITY, 1.0) } else { (f64::INFINITY, f64::INFINITY, 0.0) };
    }
    let t = (p - m) / var.sqrt();
    let dof = welch_dof(var, sp, np, sm, nm);
    (t, dof, pathgrad::stats::student_t_two_sided(t, dof))
}

/// Welch–Satterthwaite degrees of freedom of a difference with variance `var`, of which `sp²`
/// and `sm²` were estimated from `np` and `nm` seeds (the rest known exactly); at most 10⁷.
fn welch_dof(var: f64, sp: f64, np: f64, sm: f64, nm: f64) -> f64 {
    let spread = sp.powi(4) / (np - 1.0) + sm.powi(4) / (nm - 1.0);
    if spread > 0.0 { (var * var / spread).min(1e7) } else { 1e7 }
}

/// The |t| whose two-sided tail is `p` with `dof` degrees of freedom, by bisection.
fn t_threshold(p: f64, dof: f64) -> f64 {
    let (mut lo, mut hi) = (0.0f64, 1e6f64);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if pathgrad::stats::student_t_two_sided(mid, dof) > p { lo = mid } else { hi = mid }
    }
    0.5 * (lo + hi)
}

/// The bias `(t_{α} + t_{0.05, one-sided})·se` that a test at per-test level `alpha` sees 95 % of
/// the time, for Welch's statistic with these standard errors and seed counts.
fn detectable(sp: f64, np: f64, sm: f64, nm: f64, alpha: f64) -> f64 {
    let var = sp * sp + sm * sm;
    let dof = welch_dof(var, sp, np, sm, nm);
    (t_threshold(alpha, dof) + t_threshold(2.0 * (1.0 - POWER), dof)) * var.sqrt()
}

/// Every block channel and image mean of `mine` that fails Welch's test against `theirs` at
/// per-test level `alpha`, as messages (`block B channel C: …`, `image mean channel C: …`), and
/// the least p-value seen.
///
/// Also what decides whether a quantity is rendered again. At a few samples a pixel, a block that
/// light reaches through unlikely paths (a corner seeing a reflection of a textured panel) has a
/// heavy-tailed per-seed mean: most seeds see little or nothing, a few see much, and the standard
/// error estimated from 32 such seeds is far too small, so Welch's t "fails" on a mean that more
/// samples bring to Mitsuba's. A quantity with any failure below the budget's top is therefore
/// rendered again at 4× the samples, and only the last render is judged. This keeps the test's
/// level (a failure still needs the last, largest render to fail at the Bonferroni level) and only
/// adds power: a real difference stays while the standard errors shrink.
fn disagreements(mine: &Stats, theirs: &Stats, alpha: f64, nm: f64) -> (Vec<String>, f64) {
    let np = f64::from(SEEDS);
    let mut out = Vec::new();
    let mut least = 1.0f64;
    let mut test = |what: String, mp: f64, sp: f64, mm: f64, sm: f64, digits: usize| {
        let (t, dof, pv) = welch(mp, sp, np, mm, sm, nm);
        least = least.min(pv);
        if pv < alpha {
            out.push(format!(
                "{what}: {mp:.digits$} ± {sp:.2e} vs Mitsuba {mm:.digits$} ± {sm:.2e} (t {t:.1}, {dof:.0} dof, p {pv:.1e})"
            ));
        }
    };
    for (b, (mp, mm)) in mine.mean.iter().zip(&theirs.mean).enumerate() {
        for c in 0..3 {
            test(format!("block {b} channel {c}"), mp[c], mine.se[b][c], mm[c], theirs.se[b][c], 5);
        }
    }
    for c in 0..3 {
        let (mp, sp, mm, sm) = (mine.image_mean[c], mine.image_se[c], theirs.image_mean[c], theirs.image_se[c]);
        test(format!("image mean channel {c}"), mp, sp, mm, sm, 6);
    }
    (out, least)
}

/// One reference: the scene, its statistics, what to compare.
struct Reference {
    name: String,
    json: Value,
}

impl Reference {
    fn block(&self) -> u32 {
        self.json["block"].as_u64().unwrap() as u32
    }
    fn blocks(&self) -> usize {
        (self.json["blocks_x"].as_u64().unwrap() * self.json["blocks_y"].as_u64().unwrap()) as usize
    }
    /// The relative bias this scene's primal or gradients must be able to see: the defaults, or
    /// the larger one its MATRIX entry states (with its reason) where the variance of both
    /// renderers puts those out of the suite's budget.
    fn bias(&self, gradient: bool) -> f64 {
        let (key, default) = if gradient { ("gradient_bias", GRADIENT_BIAS) } else { ("primal_bias", PRIMAL_BIAS) };
        self.json[key].as_f64().unwrap_or(default).max(default)
    }

    fn quantities(&self) -> Vec<(Option<String>, Stats)> {
        let mut out = vec![(None, Stats::from_json(&self.json["primal"]))];
        if let Some(grads) = self.json["gradients"].as_object() {
            for (key, g) in grads {
                out.push((Some(key.clone()), Stats::from_json(g)));
            }
        }
        out
    }

    /// Whether the row's gradients are pathgrad's attached ones (issue 34), against Mitsuba's
    /// central differences (its `prb` has none), block by block as every other gradient.
    fn attached(&self) -> bool {
        self.json["sampling"].as_str() == Some("attached")
    }
}

fn references() -> Vec<Reference> {
    let only: Option<Vec<String>> = std::env::var("PATHGRAD_CONFORMANCE")
        .ok()
        .filter(|v| !v.trim().is_empty())
        .map(|v| v.split(',').map(|s| s.trim().to_string()).collect());
    let mut files: Vec<PathBuf> = std::fs::read_dir(root().join("reference"))
        .expect("tests/conformance/reference")
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "json"))
        .collect();
    files.sort();
    files
        .into_iter()
        .map(|p| {
            let name = p.file_stem().unwrap().to_string_lossy().into_owned();
            let json: Value = serde_json::from_str(&std::fs::read_to_string(&p).unwrap())
                .unwrap_or_else(|e| panic!("{}: {e}", p.display()));
            Reference { name, json }
        })
        .filter(|r| only.as_ref().is_none_or(|o| o.contains(&r.name)))
        .collect()
}

/// The smallest power-of-two sample count per seed at which pathgrad's image mean has the power
/// to see `bias` of `scale` in every channel (per-test level `alpha`), assuming its per-sample
/// variance is the reference's (seeds × spp × se² per channel) with a margin of 1.3; at most
/// the range's top.
fn spp_for_power(reference: &Reference, m: &Stats, gradient: bool, alpha: f64) -> u32 {
    let (seeds_m, spp_m) = (reference.json["seeds"].as_f64().unwrap(), reference.json["spp"].as_f64().unwrap());
    let bias = reference.bias(gradient);
    let scale = m.scale(gradient);
    let mut spp = SPP_RANGE.0;
    while spp < SPP_RANGE.1 {
        let enough = scale.into_iter().zip(m.image_se).all(|(scale, se)| {
            let mine = (1.3 * se * se * seeds_m * spp_m / f64::from(SEEDS * spp)).sqrt();
            scale == 0.0 || detectable(mine, f64::from(SEEDS), se, seeds_m, alpha) <= bias * scale
        });
        if enough {
            break;
        }
        spp *= 2;
    }
    spp
}

/// Whether pathgrad's parameter `name` is one of Mitsuba's `keys`, under the two exceptions that
/// `src/scene/mitsuba/mod.rs` documents (and `tests_names` checks): a rough conductor's implicit
/// `specular_reflectance` (1), which Mitsuba does not list, and `_unnamed_N` for an object that
/// Mitsuba names by its address (`object_<address>`), with the same ending.
fn mitsuba_name(name: &str, keys: &[&str]) -> bool {
    if keys.contains(&name) {
        return true;
    }
    if name.ends_with(".specular_reflectance.value") {
        return true;
    }
    match name.split_once('.') {
        Some((head, rest)) if head.starts_with("_unnamed_") => {
            keys.iter().any(|k| k.starts_with("object_") && k.split_once('.').is_some_and(|(_, r)| r == rest))
        }
        _ => false,
    }
}

/// pathgrad's statistics of one quantity (the primal image, or the image gradient of `key`) over
/// `SEEDS` seeds at `spp` samples a pixel, in the reference's blocks.
fn render_stats(
    renderer: &mut Renderer,
    scene: &pathgrad::scene::Scene,
    key: Option<&str>,
    spp: u32,
    r: &Reference,
) -> Stats {
    let images: Vec<Image> = (0..SEEDS)
        .map(|s| {
            let opts = RenderOptions { spp, seed: 1000 + s, ..RenderOptions::for_scene(scene) };
            // Attached rows (issue 34): the forward-mode image gradient with attached sampling.
            let sampling = if r.attached() { Sampling::attached() } else { Sampling::Detached };
            let opts = RenderOptions { sampling, ..opts };
            match key {
                None => renderer.render(&opts),
                Some(k) => renderer.image_gradient(&opts, k),
            }
            .unwrap_or_else(|e| panic!("{}: {e}", r.name))
        })
        .collect();
    Stats::of_images(&images, r.block())
}

#[test]
fn conformance_matrix_agrees_with_mitsuba() {
    let refs = references();
    assert!(!refs.is_empty(), "no references in tests/conformance/reference (or none matches PATHGRAD_CONFORMANCE)");
    // Bonferroni over every block, channel and image mean of every quantity of every scene.
    let tests: usize = refs
        .iter()
        .filter(|r| r.json.get("pending").is_none())
        .map(|r| r.quantities().len() * (r.blocks() + 1) * 3)
        .sum();
    let alpha = FAMILY_ALPHA / tests as f64;
    println!("conformance: {} scenes, {tests} Welch t-tests, each at p < {alpha:.2e}", refs.len());
    let gpu = TestGpu::new();
    let mut failures = Vec::new();
    for r in refs.iter().filter(|r| r.json.get("pending").is_some()) {
        println!("{:<40}  listed, not compared: {}", r.name, r.json["pending"].as_str().unwrap());
    }
    for r in refs.iter().filter(|r| r.json.get("pending").is_none()) {
        let started = std::time::Instant::now();
        // A glTF scene: pathgrad reads the glTF file itself (at the reference's width); Mitsuba
        // read the XML that `gltf_to_mitsuba.py` wrote from it.
        let (file, options) = match r.json["pathgrad_scene"].as_str() {
            Some(gltf) => {
                let width = r.json["pathgrad_width"].as_u64().map(|w| w as u32);
                (root().join(gltf), pathgrad::scene::LoadOptions { width, ..Default::default() })
            }
            None => (root().join("scenes").join(r.json["scene"].as_str().unwrap()), Default::default()),
        };
        let scene = match pathgrad::scene::load_with(file.to_str().unwrap(), &options) {
            Ok(s) => s,
            Err(e) => {
                failures.push(format!("{}: does not load: {e}", r.name));
                continue;
            }
        };
        // glTF scenes all carry the one warning that their materials approximate glTF's BRDF
        // (which the comparison with the mapped materials in Mitsuba does not cover); a scene
        // whose reference lists `warnings` must give each of those, and no other.
        let gltf = r.json.get("pathgrad_scene").is_some();
        let expected: Vec<&str> =
            r.json["warnings"].as_array().map(|w| w.iter().map(|v| v.as_str().unwrap()).collect()).unwrap_or_default();
        let unexpected: Vec<&String> = scene
            .warnings
            .iter()
            .filter(|w| !(gltf && *w == pathgrad::scene::gltf::FRESNEL_WARNING))
            .filter(|w| !expected.iter().any(|e| w.contains(e)))
            .collect();
        if !unexpected.is_empty() {
            failures.push(format!("{}: loads with warnings: {unexpected:?}", r.name));
        }
        for e in expected.iter().filter(|e| !scene.warnings.iter().any(|w| w.contains(*e))) {
            failures.push(format!("{}: the warning '{e}…' is missing", r.name));
        }
        let keys: Vec<&str> = r.json["keys"].as_array().unwrap().iter().map(|k| k.as_str().unwrap()).collect();
        match r.json["pathgrad_keys"].as_object() {
            // glTF: pathgrad's names are its own (src/scene/gltf/mod.rs, "Names"); the converter
            // restated them, so the parameters must be exactly the map's, each with a Mitsuba key.
            Some(map) => {
                let ours: Vec<&str> = scene.params.entries().iter().map(|e| e.name.as_str()).collect();
                for entry in &ours {
                    if !map.contains_key(*entry) {
                        failures.push(format!("{}: parameter '{entry}' is not in gltf_to_mitsuba.py's map", r.name));
                    }
                }
                for (name, key) in map {
                    if !ours.contains(&name.as_str()) {
                        failures.push(format!("{}: pathgrad has no parameter '{name}'", r.name));
                    }
                    if !keys.contains(&key.as_str().unwrap()) {
                        failures.push(format!("{}: '{name}' maps to '{key}', not one of Mitsuba's keys", r.name));
                    }
                }
            }
            None => {
                for entry in scene.params.entries() {
                    if !mitsuba_name(&entry.name, &keys) {
                        failures.push(format!("{}: parameter '{}' is not one of Mitsuba's keys", r.name, entry.name));
                    }
                }
            }
        }
        let mut renderer = Renderer::new(&gpu.ctx, &scene).unwrap();
        let mut line = format!("{:<40}", r.name);
        for (key, theirs) in r.quantities() {
            let gradient = key.is_some();
            let bias = r.bias(gradient);
            let scale = theirs.scale(gradient);
            let (np, nm) = (f64::from(SEEDS), r.json["seeds"].as_f64().unwrap());
            // Sized from Mitsuba's variance; where pathgrad's is larger, sized again from its own
            // (se ∝ 1/√spp, with a margin), up to the budget's top.
            // Attached gradients are sized from pathgrad's own variance (the reference's is that
            // of Mitsuba's finite differences, far larger): from 16 spp up.
            let mut spp = if gradient && r.attached() { 16 } else { spp_for_power(r, &theirs, gradient, alpha) };
            let mut mine = render_stats(&mut renderer, &scene, key.as_deref(), spp, r);
            loop {
                let short = (0..3)
                    .filter(|&c| scale[c] > 0.0)
                    .map(|c| detectable(mine.image_se[c], np, theirs.image_se[c], nm, alpha) / (bias * scale[c]))
                    .fold(0.0f64, f64::max);
                let failing = disagreements(&mine, &theirs, alpha, nm).0.len();
                if (short <= 1.0 && failing == 0) || spp >= SPP_RANGE.1 {
                    break;
                }
                let wanted = (f64::from(spp) * short * short * 1.3).ceil() as u32;
                let wanted = if failing > 0 { wanted.max(4 * spp) } else { wanted };
                spp = wanted.next_power_of_two().clamp(2 * spp, SPP_RANGE.1);
                mine = render_stats(&mut renderer, &scene, key.as_deref(), spp, r);
            }
            let what = key.clone().unwrap_or_else(|| "primal".into());
            assert_eq!(mine.mean.len(), theirs.mean.len(), "{}: block count", r.name);
            let (failed, least) = disagreements(&mine, &theirs, alpha, nm);
            failures.extend(failed.into_iter().map(|f| format!("{} {what}: {f}", r.name)));
            let mut ratio = [0.0; 3];
            let mut sees = 0.0f64;
            for c in 0..3 {
                let (sp, mm, sm) = (mine.image_se[c], theirs.image_mean[c], theirs.image_se[c]);
                ratio[c] = if mm != 0.0 { mine.image_mean[c] / mm } else { f64::NAN };
                // The power check: the bias this test would see 95 % of the time.
                let detectable = detectable(sp, np, sm, nm, alpha);
                if scale[c] > 0.0 {
                    sees = sees.max(detectable / scale[c]);
                }
                if scale[c] > 0.0 && detectable > bias * scale[c] {
                    failures.push(format!(
                        "{} {what}: channel {c} cannot see a {:.0} % bias (it sees {:.2} %) at {spp} spp × {SEEDS} seeds",
                        r.name,
                        100.0 * bias,
                        100.0 * detectable / scale[c]
                    ));
                }
            }
            line += &format!(
                "  {what} [{:.4} {:.4} {:.4}] min p {least:.0e} ({spp} spp, sees {:.2} %)",
                ratio[0],
                ratio[1],
                ratio[2],
                100.0 * sees
            );
        }
        println!("{line}  {:.1} s", started.elapsed().as_secs_f64());
    }
    assert!(failures.is_empty(), "{} disagreement(s) with Mitsuba:\n{}", failures.len(), failures.join("\n"));
}

#[test]
fn the_t_thresholds_are_right() {
    // Two-sided 5 % of t with 7 dof, and 1e-6 of the normal (t with 10⁷ dof).
    assert!((t_threshold(0.05, 7.0) - 2.364_624).abs() < 1e-5);
    assert!((t_threshold(1e-6, 1e7) - 4.891_638).abs() < 1e-3);
    // Welch's dof for equal errors over 8 and 16 seeds: (2s²)² / (s⁴/7 + s⁴/15) = 4/(1/7 + 1/15).
    let (_, dof, _) = welch(1.0, 0.1, 8.0, 1.0, 0.1, 16.0);
    assert!((dof - 4.0 / (1.0 / 7.0 + 1.0 / 15.0)).abs() < 1e-6 * dof);
}

//! `pathgrad batch`: the items of a JSONL manifest (renders, losses, gradients, image gradients)
//! run in shards on existing schedulers, and `pathgrad reduce`: the shards' summaries merged and
//! their gradients summed.
//!
//! An item's outputs are named after the item (its `id`, else a hash of its line's content) and
//! written atomically, its record `NAME.json` last: a rerun skips every item whose record holds
//! the same item, so a killed shard resumes where it stopped and any sharding writes the same
//! files. Seeds come from the items, never from their position in a shard.
//!
//! One process at a time runs a shard into a directory: it holds the shard's lock (an exclusive
//! `flock` on `.SUMMARY.lock`, as `optimize` holds its run directory) and, under it, removes the
//! temporaries that killed runs of the shard left. Different shards share a directory.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context as _, Result, anyhow, bail};
use clap::Args;
use pathgrad::backend::Backend;
use pathgrad::gpu::renderer::GradMode;
use pathgrad::image::Image;
use pathgrad::integrator::{DEFAULT_JACOBIAN_NOISE, RenderOptions, Sampling};
use pathgrad::output::write_bytes_atomically;
use serde::{Deserialize, Serialize};
use serde_json::Value;

use crate::common::{DEFAULT_SPP, context, progress_bar, refuse_non_finite};

#[derive(Args, Debug)]
pub(crate) struct BatchArgs {
    /// The manifest: one JSON object a line (docs/batch.md).
    manifest: PathBuf,
    /// Output directory (shards may share it).
    #[arg(short, long, value_name = "DIR")]
    output: PathBuf,
    /// Run the items with index ≡ I (mod N). Without it: SLURM_ARRAY_TASK_ID of
    /// SLURM_ARRAY_TASK_COUNT, or JOB_COMPLETION_INDEX of --shards N, else every item.
    #[arg(long, value_name = "I/N", allow_hyphen_values = true)]
    shard: Option<String>,
    /// The number of shards of a Kubernetes Indexed Job (its JOB_COMPLETION_INDEX is the shard).
    #[arg(long, value_name = "N", conflicts_with = "shard")]
    shards: Option<u32>,
    /// Vulkan device: an index or UUID from `pathgrad devices`, or `cpu` for a CPU Vulkan device
    /// such as lavapipe (the CPU reference implementation is `--cpu`) (env: PATHGRAD_DEVICE).
    #[arg(long)]
    device: Option<String>,
    /// Run on the CPU reference implementation instead of Vulkan.
    #[arg(long, conflicts_with = "device")]
    cpu: bool,
    /// Print the shard's summary as one JSON line (and no progress bar).
    #[arg(long)]
    json: bool,
}

#[derive(Args, Debug)]
pub(crate) struct ReduceArgs {
    /// Output directories of `pathgrad batch` (one per shard, or one they shared).
    #[arg(required = true)]
    dirs: Vec<PathBuf>,
    /// Where the merged `summary.jsonl` and `totals.json` go: not one of several DIRs
    /// [default: DIR, when there is one].
    #[arg(short, long, value_name = "DIR")]
    output: Option<PathBuf>,
    /// Print the totals as one JSON line.
    #[arg(long)]
    json: bool,
}

/// One manifest line.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
struct Item {
    /// The item's name in the output directory (letters, digits, `.`, `_`, `-`); default
    /// `item-HASH` of the line's content.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    id: Option<String>,
    /// `builtin:NAME` or a scene file, relative to the manifest's folder.
    scene: String,
    /// Scene-file defines (`-D`).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    defines: BTreeMap<String, Value>,
    /// Parameter values: a number for every value, or one number per value.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    params: BTreeMap<String, Value>,
    /// The sensor, by index or name.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    sensor: Option<Value>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    spp: Option<u32>,
    #[serde(default)]
    seed: u32,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    width: Option<u32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    height: Option<u32>,
    /// An environment (`--env`): a constant linear RGB radiance `[r, g, b]`, or a map file
    /// relative to the manifest's folder.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    env: Option<crate::common::EnvArg>,
    /// Surface interactions per path; -1 unbounded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    max_depth: Option<i64>,
    /// What to write: `image`, `loss`, `gradients`, `image_gradient`.
    produce: Vec<Produce>,
    /// The target EXR of `loss` and `gradients`, relative to the manifest's folder.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    target: Option<String>,
    /// The loss of `loss` and `gradients` [default: relmse].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    loss: Option<String>,
    /// The parameter of `image_gradient`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    image_gradient: Option<String>,
    /// Fixed-point gradients (bitwise reproducible).
    #[serde(default)]
    deterministic: bool,
    /// `detached` (the default) or `attached` (`--sampling`): attached sampling differentiates a
    /// dielectric's index of refraction too.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    sampling: Option<String>,
    /// Attached sampling's Jacobian noise amplitude (`--jacobian-noise`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    jacobian_noise: Option<f32>,
}

#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
#[serde(rename_all = "snake_case")]
enum Produce {
    Image,
    Loss,
    Gradients,
    ImageGradient,
}

/// A manifest line: its index among the items, its line number, and the item or why it is bad.
struct Entry {
    index: usize,
    line: usize,
    item: std::result::Result<(Item, String), String>,
}

/// What a summary line says about one item.
#[derive(Serialize, Deserialize, Clone, Debug)]
struct Status {
    index: usize,
    line: usize,
    #[serde(default)]
    name: Option<String>,
    /// `ok`, `skipped` (finished by an earlier run) or `failed`.
    status: String,
    time_s: f64,
    #[serde(default)]
    outputs: Vec<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    error: Option<String>,
}

/// Reads the manifest: every non-blank line that does not start with `#` is an item.
fn read_manifest(path: &Path) -> Result<Vec<Entry>> {
    let text = std::fs::read_to_string(path).with_context(|| format!("reading the manifest {}", path.display()))?;
    // A byte-order mark (Windows editors write one) is not part of the first item.
    let text = text.strip_prefix('\u{feff}').unwrap_or(&text);
    let mut entries = Vec::new();
    let mut names: BTreeMap<String, usize> = BTreeMap::new();
    for (i, raw) in text.lines().enumerate() {
        let line = i + 1;
        if raw.trim().is_empty() || raw.trim_start().starts_with('#') {
            continue;
        }
        let item =
            serde_json::from_str::<Item>(raw).map_err(|e| format!("{}:{line}: {e}", path.display())).and_then(|item| {
                let name = item_name(&item).map_err(|e| format!("{}:{line}: {e}", path.display()))?;
                match names.insert(name.clone(), line) {
                    Some(first) => Err(format!("{}:{line}: item '{name}' is also line {first}", path.display())),
                    None => Ok((item, name)),
                }
            });
        entries.push(Entry { index: entries.len(), line, item });
    }
    Ok(entries)
}

/// The item's output name: its `id`, or `item-` and a 64-bit FNV-1a hash of its canonical JSON.
fn item_name(item: &Item) -> Result<String> {
    if let Some(id) = &item.id {
        if id.is_empty() || !id.chars().all(|c| c.is_ascii_alphanumeric() || "._-".contains(c)) || id.starts_with('.') {
            bail!("invalid id '{id}': use letters, digits, '.', '_' and '-' (not first '.')");
        }
        return Ok(id.clone());
    }
    let canonical = serde_json::to_string(item)?;
    let hash =
        canonical.bytes().fold(0xcbf2_9ce4_8422_2325u64, |h, b| (h ^ u64::from(b)).wrapping_mul(0x100_0000_01b3));
    Ok(format!("item-{hash:016x}"))
}

/// This process's shard (I, N): `--shard`, Slurm's array variables, or a Kubernetes Indexed Job's
/// completion index with `--shards`; (0, 1) without any.
fn shard(args: &BatchArgs, var: impl Fn(&str) -> Option<String>) -> Result<(u64, u64)> {
    let number = |name: &str, text: &str| -> Result<u64> {
        text.trim().parse::<u64>().map_err(|_| anyhow!("invalid {name} '{text}': not a non-negative integer"))
    };
    let (i, n, from) = if let Some(s) = &args.shard {
        let (i, n) = s.split_once('/').ok_or_else(|| anyhow!("invalid --shard {s}: give I/N, e.g. 0/4"))?;
        let part = |text: &str| {
            text.trim()
                .parse::<u64>()
                .map_err(|_| anyhow!("invalid --shard {s}: '{text}' is not a non-negative integer"))
        };
        (part(i)?, part(n)?, format!("--shard {s}"))
    } else if let Some(id) = var("SLURM_ARRAY_TASK_ID") {
        let count = var("SLURM_ARRAY_TASK_COUNT")
            .ok_or_else(|| anyhow!("SLURM_ARRAY_TASK_ID is set but SLURM_ARRAY_TASK_COUNT is not"))?;
        let min = var("SLURM_ARRAY_TASK_MIN").map(|m| number("SLURM_ARRAY_TASK_MIN", &m)).transpose()?.unwrap_or(0);
        let id = number("SLURM_ARRAY_TASK_ID", &id)?;
        let i = id
            .checked_sub(min)
            .ok_or_else(|| anyhow!("SLURM_ARRAY_TASK_ID {id} is below SLURM_ARRAY_TASK_MIN {min}"))?;
        (i, number("SLURM_ARRAY_TASK_COUNT", &count)?, format!("SLURM_ARRAY_TASK_ID {id}"))
    } else if let Some(index) = var("JOB_COMPLETION_INDEX") {
        let n = args
            .shards
            .ok_or_else(|| anyhow!("JOB_COMPLETION_INDEX is set: give the job's --shards N (its completions)"))?;
        (number("JOB_COMPLETION_INDEX", &index)?, u64::from(n), format!("JOB_COMPLETION_INDEX {index}"))
    } else if let Some(n) = args.shards {
        bail!("--shards {n} takes the shard from JOB_COMPLETION_INDEX, which is not set (or give --shard I/N)");
    } else {
        (0, 1, String::new())
    };
    if n == 0 || i >= n {
        bail!("invalid shard from {from}: shard {i} of {n} (it must be below the count)");
    }
    Ok((i, n))
}

/// What a loaded scene depends on: file, defines, sensor, size, environment (radiance bits or the
/// resolved map file).
type SceneKey = (String, Vec<(String, String)>, Option<String>, Option<u32>, Option<u32>, Option<String>);

struct Runner {
    manifest_dir: PathBuf,
    out: PathBuf,
    cpu: bool,
    ctx: Option<std::sync::Arc<pathgrad::gpu::Context>>,
    device: Option<String>,
    scenes: BTreeMap<SceneKey, (pathgrad::scene::Scene, Box<dyn Backend>)>,
}

fn value_text(v: &Value) -> String {
    match v {
        Value::String(s) => s.clone(),
        other => other.to_string(),
    }
}

impl Runner {
    fn resolve(&self, path: &str) -> String {
        if path.starts_with("builtin:") || Path::new(path).is_absolute() {
            path.to_string()
        } else {
            self.manifest_dir.join(path).display().to_string()
        }
    }

    /// The loaded scene and backend of `item`, loading them on first use.
    fn backend(&mut self, item: &Item) -> Result<&mut (pathgrad::scene::Scene, Box<dyn Backend>)> {
        let defines: Vec<(String, String)> = item.defines.iter().map(|(k, v)| (k.clone(), value_text(v))).collect();
        use crate::common::EnvArg;
        let env = match &item.env {
            None => None,
            Some(EnvArg::Rgb(rgb)) => Some(EnvArg::Rgb(*rgb)),
            Some(EnvArg::Map(path)) => Some(EnvArg::Map(PathBuf::from(self.resolve(&path.display().to_string())))),
        };
        let env_key = env.as_ref().map(|e| match e {
            EnvArg::Rgb(rgb) => format!("{:?}", rgb.map(f32::to_bits)),
            EnvArg::Map(path) => path.display().to_string(),
        });
        let key = (
            self.resolve(&item.scene),
            defines,
            item.sensor.as_ref().map(value_text),
            item.width,
            item.height,
            env_key,
        );
        if !self.scenes.contains_key(&key) {
            let options = pathgrad::scene::LoadOptions {
                defines: key.1.clone(),
                width: item.width,
                height: item.height,
                allow_outside_folder: false,
                sensor: key.2.clone(),
                environment: EnvArg::options(env.as_ref()).0,
                environment_map: EnvArg::options(env.as_ref()).1,
            };
            let scene = pathgrad::scene::load_with(&key.0, &options).with_context(|| format!("loading {}", key.0))?;
            let backend: Box<dyn Backend> = if self.cpu {
                Box::new(pathgrad::cpu::Reference::new(&scene)?)
            } else {
                if self.ctx.is_none() {
                    self.ctx = Some(context(&self.device)?);
                }
                let ctx = self.ctx.as_ref().expect("opened above");
                Box::new(pathgrad::gpu::Renderer::new(ctx, &scene)?)
            };
            self.scenes.insert(key.clone(), (scene, backend));
        }
        Ok(self.scenes.get_mut(&key).expect("inserted above"))
    }

    /// Runs one item and writes its outputs, its record last; returns the outputs' names.
    fn run(&mut self, item: &Item, name: &str, record: &Value) -> Result<Vec<String>> {
        let wants = |p: Produce| item.produce.contains(&p);
        if item.produce.is_empty() {
            bail!("'produce' is empty: give any of image, loss, gradients, image_gradient");
        }
        let needs_target = wants(Produce::Loss) || wants(Produce::Gradients);
        if needs_target != item.target.is_some() {
            bail!("'target' is needed exactly when 'produce' has loss or gradients");
        }
        if wants(Produce::ImageGradient) != item.image_gradient.is_some() {
            bail!("'image_gradient' (a parameter name) is needed exactly when 'produce' has image_gradient");
        }
        let loss: pathgrad::loss::Loss = item.loss.as_deref().unwrap_or("relmse").parse().context("'loss'")?;
        let target = match &item.target {
            Some(t) => {
                let path = self.resolve(t);
                let image = Image::read_exr(&path).with_context(|| format!("'target' {path}"))?;
                refuse_non_finite(&image, &format!("the target {path}"))?;
                Some(image)
            }
            None => None,
        };
        // Checked before the scene loads, whose camera would speak of an image size instead.
        for size in [item.width, item.height].into_iter().flatten() {
            if !(1..=pathgrad::integrator::MAX_IMAGE_SIZE).contains(&size) {
                bail!("invalid 'width'/'height': must be between 1 and {}", pathgrad::integrator::MAX_IMAGE_SIZE);
            }
        }
        let out = self.out.clone();
        let (scene, backend) = self.backend(item)?;
        let mut table = scene.params.clone();
        for (param, value) in &item.params {
            let values: Vec<f32> = match value {
                Value::Number(n) => {
                    let id = table.find(param).ok_or_else(|| anyhow!("'params': no parameter {param}"))?;
                    vec![n.as_f64().unwrap_or(f64::NAN) as f32; table.entry(id).len as usize]
                }
                Value::Array(a) => a.iter().map(|v| v.as_f64().map_or(f32::NAN, |x| x as f32)).collect(),
                other => bail!("'params' {param}: {other} is neither a number nor an array of numbers"),
            };
            table.set(param, &values).with_context(|| format!("'params' {param}"))?;
        }
        backend.set_params(&table)?;
        let mut opts = RenderOptions::for_scene(scene);
        opts.spp = item.spp.or(scene.default_spp).unwrap_or(DEFAULT_SPP);
        opts.seed = item.seed;
        opts.max_depth = match item.max_depth {
            None => Some(scene.max_depth),
            Some(-1) => None,
            Some(d) => Some(u32::try_from(d).map_err(|_| anyhow!("'max_depth' {d}: at least 1, or -1"))?),
        };
        opts.sampling = match (item.sampling.as_deref().unwrap_or("detached"), item.jacobian_noise) {
            ("detached", None) => Sampling::Detached,
            ("detached", Some(a)) => bail!("'jacobian_noise' {a} applies only to 'sampling': \"attached\""),
            ("attached", a) => Sampling::Attached { noise: a.unwrap_or(DEFAULT_JACOBIAN_NOISE) },
            (other, _) => bail!("invalid 'sampling' {other:?}: expected \"detached\" or \"attached\""),
        };
        opts.validate()?;
        // Detached sampling leaves the parameters it cannot differentiate (an index of
        // refraction) out of the gradients, as `grad --param '*'` does, rather than report 0;
        // an image gradient of one is refused by the back end, by name.
        let reported = pathgrad::attached::differentiated(scene, scene.params.select(&["*"])?, &[], opts.sampling)?;
        // (file stem, image, whether it is signed: a diverging preview)
        let mut images: Vec<(String, Image, bool)> = Vec::new();
        let mut result = serde_json::Map::new();
        if wants(Produce::Image) {
            let image = backend.render(&opts)?;
            refuse_non_finite(&image, "the image")?;
            images.push((name.to_string(), image, false));
        }
        if let Some(target) = &target {
            let mode = if item.deterministic { GradMode::Deterministic } else { GradMode::Float };
            let (value, gradients) = if wants(Produce::Gradients) {
                backend.loss_and_gradient(&opts, target, loss, mode)?
            } else {
                let (value, _) = backend.loss_image(&opts, opts.spp, target, loss)?;
                (value, pathgrad::params::Gradients::new(&table, vec![0.0; table.values().len()]))
            };
            result.insert("loss".into(), serde_json::json!(value));
            if wants(Produce::Gradients) {
                let map: serde_json::Map<String, Value> = reported
                    .iter()
                    .map(|&id| {
                        let name = &table.entry(id).name;
                        (name.clone(), serde_json::json!(gradients.get(name).expect("one of the scene's")))
                    })
                    .collect();
                result.insert("gradients".into(), Value::Object(map));
            }
        }
        if let Some(param) = &item.image_gradient {
            let image = backend.image_gradient(&opts, param)?;
            refuse_non_finite(&image, &format!("the image gradient ∂I/∂{param}"))?;
            images.push((format!("{name}.image_gradient"), image, true));
        }
        // Keep ITEM_FILES in step with the names written here.
        let mut set = pathgrad::output::OutputSet::new();
        let mut outputs = Vec::new();
        for (stem, image, signed) in &images {
            let exr = set.stage(&out.join(format!("{stem}.exr")))?;
            let png = set.stage(&out.join(format!("{stem}.png")))?;
            image.write_exr(&exr)?;
            if *signed {
                image.write_signed_png(&png, None)?
            } else {
                image.write_png(&png, 0.0)?
            }
            outputs.extend([format!("{stem}.exr"), format!("{stem}.png")]);
        }
        set.commit()?;
        outputs.push(format!("{name}.json"));
        result.insert("item".into(), record.clone());
        result.insert("name".into(), Value::String(name.to_string()));
        result.insert("outputs".into(), serde_json::json!(outputs));
        write_bytes_atomically(out.join(format!("{name}.json")), serde_json::to_string_pretty(&result)?.as_bytes())?;
        Ok(outputs)
    }
}

/// What an item named NAME may write: `NAME` and each of these.
const ITEM_FILES: [&str; 5] = [".exr", ".png", ".image_gradient.exr", ".image_gradient.png", ".json"];

/// Takes the shard's lock: an exclusive `flock` on `.SUMMARY.lock` in the output directory `out`
/// (the empty file stays; the lock goes with the process), so that one process at a time runs
/// a shard into a directory, as `optimize` holds its run directory. Other shards, writing other
/// summaries and items, have other locks.
fn lock_shard(out: &Path, summary: &Path, (i, n): (u64, u64)) -> Result<std::fs::File> {
    let name = summary.file_name().expect("the summary has a file name").to_string_lossy();
    let path = out.join(format!(".{name}.lock"));
    let handle = std::fs::OpenOptions::new()
        .write(true)
        .create(true)
        .truncate(false)
        .open(&path)
        .with_context(|| format!("creating the shard's lock {}", path.display()))?;
    crate::common::try_lock(
        handle,
        || {
            format!(
                "-o {}: another pathgrad batch is running shard {i}/{n} in this directory (it holds {})",
                out.display(),
                path.display()
            )
        },
        || format!("locking {}", path.display()),
    )
}

/// Removes the temporaries that killed runs of this shard left in `out`: those of its items'
/// files and its summary, whichever process made them. Called under the shard's lock, when no
/// live process writes those files (other shards write other names); a process id in a
/// temporary's name would not tell, since shards sharing a directory may run on other machines.
fn remove_shard_temporaries(out: &Path, summary: &Path, mine: &[&Entry]) -> Result<()> {
    let mut files: BTreeSet<String> = BTreeSet::new();
    files.insert(summary.file_name().expect("the summary has a file name").to_string_lossy().into_owned());
    for entry in mine {
        if let Ok((_, name)) = &entry.item {
            files.extend(ITEM_FILES.iter().map(|suffix| format!("{name}{suffix}")));
        }
    }
    let removed = pathgrad::output::remove_temporaries(out, |file| files.contains(file))?;
    for path in removed {
        tracing::debug!(path = %path.display(), "removed a temporary a killed run of this shard left");
    }
    Ok(())
}

/// Whether `name`'s record in `out` holds `record`: the item was finished by an earlier run.
fn finished(out: &Path, name: &str, record: &Value) -> Option<Vec<String>> {
    let text = std::fs::read_to_string(out.join(format!("{name}.json"))).ok()?;
    let stored: Value = serde_json::from_str(&text).ok()?;
    if stored.get("item")? != record {
        return None;
    }
    let outputs: Vec<String> = serde_json::from_value(stored.get("outputs")?.clone()).ok()?;
    outputs.iter().all(|o| out.join(o).is_file()).then_some(outputs)
}

pub(crate) fn batch(args: &BatchArgs) -> Result<()> {
    let (shard_i, shard_n) = shard(args, |name| std::env::var(name).ok())?;
    let entries = read_manifest(&args.manifest)?;
    std::fs::create_dir_all(&args.output).with_context(|| format!("creating -o {}", args.output.display()))?;
    let summary_path = args.output.join(if shard_n == 1 {
        "summary.jsonl".to_string()
    } else {
        format!("summary.shard-{shard_i}-of-{shard_n}.jsonl")
    });
    let mine: Vec<&Entry> = entries.iter().filter(|e| e.index as u64 % shard_n == shard_i).collect();
    let _lock = lock_shard(&args.output, &summary_path, (shard_i, shard_n))?;
    remove_shard_temporaries(&args.output, &summary_path, &mine)?;
    let manifest_dir = args.manifest.parent().map(Path::to_path_buf).unwrap_or_default();
    let mut runner = Runner {
        manifest_dir,
        out: args.output.clone(),
        cpu: args.cpu,
        ctx: None,
        device: args.device.clone(),
        scenes: BTreeMap::new(),
    };
    let bar = progress_bar(mine.len() as u64, "items [{bar:30}] {pos}/{len} ({per_sec})", args.json);
    let started = Instant::now();
    let mut statuses = Vec::new();
    for entry in &mine {
        let begun = Instant::now();
        let status = |name: Option<&str>, status: &str, outputs: Vec<String>, error: Option<String>| Status {
            index: entry.index,
            line: entry.line,
            name: name.map(String::from),
            status: status.into(),
            time_s: begun.elapsed().as_secs_f64(),
            outputs,
            error,
        };
        let s = match &entry.item {
            Err(e) => status(None, "failed", Vec::new(), Some(e.clone())),
            Ok((item, name)) => {
                let record = serde_json::to_value(item)?;
                match finished(&args.output, name, &record) {
                    Some(outputs) => status(Some(name), "skipped", outputs, None),
                    None => match runner.run(item, name, &record) {
                        Ok(outputs) => status(Some(name), "ok", outputs, None),
                        Err(e) => {
                            let e = format!(
                                "{}:{}: {}",
                                args.manifest.display(),
                                entry.line,
                                crate::error_message_with(&e, crate::flags::with_keys)
                            );
                            status(Some(name), "failed", Vec::new(), Some(e))
                        }
                    },
                }
            }
        };
        if let Some(e) = &s.error {
            bar.suspend(|| eprintln!("error: {e}"));
        }
        statuses.push(s);
        let lines: Vec<String> = statuses.iter().map(serde_json::to_string).collect::<serde_json::Result<_>>()?;
        write_bytes_atomically(&summary_path, (lines.join("\n") + "\n").as_bytes())?;
        bar.inc(1);
    }
    bar.finish_and_clear();
    let seconds = started.elapsed().as_secs_f64();
    let count = |what: &str| statuses.iter().filter(|s| s.status == what).count();
    let (ok, skipped, failed) = (count("ok"), count("skipped"), count("failed"));
    if args.json {
        println!(
            "{}",
            serde_json::json!({"shard": [shard_i, shard_n], "items": statuses.len(), "ok": ok, "skipped": skipped,
                "failed": failed, "time_s": seconds, "items_per_s": ok as f64 / seconds.max(1e-9),
                "summary": summary_path})
        );
    } else {
        println!(
            "shard {shard_i}/{shard_n}: {} items ({ok} done, {skipped} finished before, {failed} failed) in {seconds:.2} s ({:.2} items/s) → {}",
            statuses.len(),
            ok as f64 / seconds.max(1e-9),
            summary_path.display()
        );
    }
    if failed > 0 {
        bail!("{failed} of {} items failed (see {})", statuses.len(), summary_path.display());
    }
    Ok(())
}

/// `path` absolute, with its symbolic links resolved, also where its last components do not exist
/// yet (they are taken as written, `..` removing the component before it, as creating them would).
fn resolved(path: &Path) -> PathBuf {
    use std::path::Component;
    let components: Vec<Component> = path.components().collect();
    for k in (0..=components.len()).rev() {
        let prefix: PathBuf = components[..k].iter().collect();
        let prefix = if prefix.as_os_str().is_empty() { PathBuf::from(".") } else { prefix };
        if let Ok(mut resolved) = std::fs::canonicalize(&prefix) {
            for c in &components[k..] {
                match c {
                    Component::ParentDir => {
                        resolved.pop();
                    }
                    Component::Normal(name) => resolved.push(name),
                    _ => {}
                }
            }
            return resolved;
        }
    }
    path.to_path_buf()
}

/// Where `reduce` writes: `-o`, else the only input directory. Not one of several inputs: its
/// merged `summary.jsonl` would name items whose records are in the others, so that a later
/// `reduce` of it fails. (A directory above or below an input is fine: `reduce` reads only the
/// top level of each input, and writes only `summary.jsonl` and `totals.json`.)
fn reduce_output(args: &ReduceArgs) -> Result<PathBuf> {
    let inputs: Vec<PathBuf> = args.dirs.iter().map(|d| resolved(d)).collect();
    let out = args.output.clone().unwrap_or_else(|| args.dirs[0].clone());
    let target = resolved(&out);
    if inputs.iter().any(|d| *d != inputs[0])
        && let Some(k) = inputs.iter().position(|d| *d == target)
    {
        let why = "its merged summary.jsonl would name items whose records are in the other inputs, and a later \
                   reduce of it would fail: give -o a directory of its own";
        match &args.output {
            Some(_) => {
                bail!("-o {} is one of the input directories ({}): {why}", out.display(), args.dirs[k].display())
            }
            None => bail!(
                "without -o, reduce would write into {}, which is one of the input directories: {why}",
                out.display()
            ),
        }
    }
    Ok(out)
}

/// The item a record `DIR/NAME.json` of `pathgrad batch` holds.
fn record_item(dir: &Path, name: &str) -> Result<Value> {
    let path = dir.join(format!("{name}.json"));
    let text = std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    let record: Value = serde_json::from_str(&text).with_context(|| format!("{}", path.display()))?;
    record
        .get("item")
        .cloned()
        .ok_or_else(|| anyhow!("{}: no \"item\" (not a record of pathgrad batch)", path.display()))
}

pub(crate) fn reduce(args: &ReduceArgs) -> Result<()> {
    let out = reduce_output(args)?;
    let mut by_index: BTreeMap<usize, (Status, PathBuf)> = BTreeMap::new();
    for dir in &args.dirs {
        let mut found = false;
        let listing = std::fs::read_dir(dir).with_context(|| format!("reading {}", dir.display()))?;
        let mut files: Vec<PathBuf> = listing
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| {
                let n = p.file_name().and_then(|n| n.to_str()).unwrap_or("");
                n.starts_with("summary") && n.ends_with(".jsonl")
            })
            .collect();
        files.sort();
        for file in files {
            found = true;
            let text = std::fs::read_to_string(&file).with_context(|| format!("reading {}", file.display()))?;
            for (i, line) in text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty()) {
                let s: Status = serde_json::from_str(line).with_context(|| format!("{}:{}", file.display(), i + 1))?;
                match by_index.get(&s.index) {
                    Some((other, _)) if other.name != s.name => bail!(
                        "{}:{}: item {} is '{}' here and '{}' in another summary: the shards ran different manifests",
                        file.display(),
                        i + 1,
                        s.index,
                        s.name.as_deref().unwrap_or("?"),
                        other.name.as_deref().unwrap_or("?")
                    ),
                    // The same name can hold another item (another seed, say): compare the items
                    // the records hold. Summaries in one directory share its records.
                    Some((other, other_dir))
                        if other.status != "failed"
                            && s.status != "failed"
                            && resolved(other_dir) != resolved(dir)
                            && let Some(name) = s.name.as_deref()
                            && record_item(other_dir, name)? != record_item(dir, name)? =>
                    {
                        bail!(
                            "item {} ('{name}'): {} and {} hold different items under that name (another seed, \
                             scene or setting): the directories hold different runs, and reduce merges the shards \
                             of one run",
                            s.index,
                            other_dir.join(format!("{name}.json")).display(),
                            dir.join(format!("{name}.json")).display()
                        )
                    }
                    // A finished entry wins over a failed one of an earlier attempt.
                    Some((other, _)) if other.status != "failed" && s.status == "failed" => {}
                    _ => {
                        by_index.insert(s.index, (s, dir.clone()));
                    }
                }
            }
        }
        if !found {
            bail!("{}: no summary*.jsonl (not a `pathgrad batch` output directory)", dir.display());
        }
    }
    // Gradients summed over the items in index order, in f64: the same sum for any sharding.
    let mut totals: BTreeMap<String, Vec<f64>> = BTreeMap::new();
    let (mut with_gradients, mut failed, mut loss_sum) = (0usize, 0usize, 0.0f64);
    for (status, dir) in by_index.values() {
        if status.status == "failed" {
            failed += 1;
            continue;
        }
        let name = status.name.as_deref().expect("finished items have names");
        let path = dir.join(format!("{name}.json"));
        let record: Value = serde_json::from_str(
            &std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?,
        )
        .with_context(|| format!("{}", path.display()))?;
        if let Some(loss) = record.get("loss").and_then(Value::as_f64) {
            loss_sum += loss;
        }
        let Some(gradients) = record.get("gradients").and_then(Value::as_object) else { continue };
        with_gradients += 1;
        for (param, values) in gradients {
            let values: Vec<f64> =
                serde_json::from_value(values.clone()).with_context(|| format!("{}: {param}", path.display()))?;
            let total = totals.entry(param.clone()).or_insert_with(|| vec![0.0; values.len()]);
            if total.len() != values.len() {
                bail!("{}: {param} has {} values, other items {}", path.display(), values.len(), total.len());
            }
            total.iter_mut().zip(&values).for_each(|(t, v)| *t += v);
        }
    }
    std::fs::create_dir_all(&out).with_context(|| format!("creating -o {}", out.display()))?;
    let lines: Vec<String> =
        by_index.values().map(|(s, _)| serde_json::to_string(s)).collect::<serde_json::Result<_>>()?;
    write_bytes_atomically(out.join("summary.jsonl"), (lines.join("\n") + "\n").as_bytes())?;
    let summary = serde_json::json!({"items": by_index.len(), "failed": failed, "with_gradients": with_gradients,
        "loss_sum": loss_sum, "gradients": totals});
    write_bytes_atomically(out.join("totals.json"), serde_json::to_string_pretty(&summary)?.as_bytes())?;
    if args.json {
        println!(
            "{}",
            serde_json::json!({"items": by_index.len(), "failed": failed, "totals": out.join("totals.json")})
        );
    } else {
        println!(
            "{} items ({failed} failed, {with_gradients} with gradients) → {}, {}",
            by_index.len(),
            out.join("summary.jsonl").display(),
            out.join("totals.json").display()
        );
    }
    if failed > 0 {
        bail!("{failed} of {} items failed", by_index.len());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(shard: Option<&str>, shards: Option<u32>) -> BatchArgs {
        BatchArgs {
            manifest: PathBuf::new(),
            output: PathBuf::new(),
            shard: shard.map(String::from),
            shards,
            device: None,
            cpu: false,
            json: false,
        }
    }

    fn env(pairs: &'static [(&'static str, &'static str)]) -> impl Fn(&str) -> Option<String> {
        move |name| pairs.iter().find(|(n, _)| *n == name).map(|(_, v)| v.to_string())
    }

    #[test]
    fn the_shard_comes_from_the_flag_or_the_scheduler() {
        assert_eq!(shard(&args(Some("2/5"), None), env(&[])).unwrap(), (2, 5));
        assert_eq!(shard(&args(None, None), env(&[])).unwrap(), (0, 1));
        let slurm =
            env(&[("SLURM_ARRAY_TASK_ID", "11"), ("SLURM_ARRAY_TASK_COUNT", "3"), ("SLURM_ARRAY_TASK_MIN", "10")]);
        assert_eq!(shard(&args(None, None), slurm).unwrap(), (1, 3));
        assert_eq!(shard(&args(None, Some(4)), env(&[("JOB_COMPLETION_INDEX", "3")])).unwrap(), (3, 4));
        let bad = [
            (args(Some("5/5"), None), env(&[]), "shard 5 of 5"),
            (args(Some("x"), None), env(&[]), "give I/N"),
            (args(None, None), env(&[("SLURM_ARRAY_TASK_ID", "1")]), "SLURM_ARRAY_TASK_COUNT is not"),
            (args(None, None), env(&[("JOB_COMPLETION_INDEX", "1")]), "--shards N"),
            (args(None, Some(2)), env(&[]), "JOB_COMPLETION_INDEX, which is not set"),
        ];
        for (a, e, expected) in bad {
            let message = shard(&a, e).unwrap_err().to_string();
            assert!(message.contains(expected), "{message}");
        }
    }

    #[test]
    fn names_come_from_the_item_not_its_position() {
        let item: Item =
            serde_json::from_str(r#"{"scene": "builtin:blend", "produce": ["image"], "seed": 3}"#).unwrap();
        let same: Item =
            serde_json::from_str(r#"{"seed": 3, "produce": ["image"], "scene": "builtin:blend"}"#).unwrap();
        assert_eq!(item_name(&item).unwrap(), item_name(&same).unwrap());
        assert!(item_name(&item).unwrap().starts_with("item-"));
        let other = Item { seed: 4, ..item.clone() };
        assert_ne!(item_name(&item).unwrap(), item_name(&other).unwrap());
        assert_eq!(item_name(&Item { id: Some("a-1.b".into()), ..item.clone() }).unwrap(), "a-1.b");
        assert!(item_name(&Item { id: Some("../x".into()), ..item }).is_err());
    }

    #[test]
    fn an_items_env_is_a_radiance_or_a_map_file() {
        use crate::common::EnvArg;
        let parse = |env: &str| -> Item {
            serde_json::from_str(&format!(r#"{{"scene": "builtin:blend", "produce": ["image"], "env": {env}}}"#))
                .unwrap()
        };
        assert_eq!(parse("[0.5, 1, 2]").env, Some(EnvArg::Rgb([0.5, 1.0, 2.0])));
        assert_eq!(parse(r#""sky.exr""#).env, Some(EnvArg::Map(PathBuf::from("sky.exr"))));
        assert!(serde_json::from_str::<Item>(r#"{"scene": "s", "produce": ["image"], "env": [1, 2]}"#).is_err());
    }
}

//! `pathgrad variance`: the variance of gradient estimators per strategy over independent runs —
//! image-gradient maps (the paper's Figures 5–7) or loss gradients (Tables 1–2) — with equal-time
//! efficiency.

use std::path::PathBuf;

use anyhow::{Context as _, Result, bail};
use clap::Args;
use pathgrad::adaptive::AdaptiveEstimator;
use pathgrad::integrator::{DEFAULT_DIFF_Q, PlacementMis, RenderOptions, Sampling, Strategy};
use pathgrad::variance::{self, LossGradientSetup, PilotBudget};

use crate::common::{
    RenderFlags, options, parse_define, pilot_json, progress_bar, strategy_label, target_image, warn_without_sampler,
};

/// Dynamic range of the variance PNGs: this many decades below the largest variance of any
/// technique (one scale for all, so the maps compare by eye).
const PNG_DECADES: f32 = 4.0;

#[derive(Args, Debug)]
pub(crate) struct VarianceArgs {
    /// The scene: builtin:NAME or a scene file.
    scene: String,
    /// Override a scene file's default: NAME=VALUE (repeatable).
    #[arg(short = 'D', long = "define", value_name = "NAME=VALUE", value_parser = parse_define)]
    defines: Vec<(String, String)>,
    /// The differentiated parameter (exact name); it also drives `diff`'s sampler unless
    /// --diff-param says otherwise.
    #[arg(long, value_name = "NAME")]
    param: String,
    /// Strategies to compare, comma-separated: bsdf, diff, auto, attached (default: bsdf and
    /// diff). `auto` is the strategy `--strategy auto` picks from its pilot (run once, its cost
    /// reported apart); `attached` is bsdf with attached sampling (`--sampling attached`, the
    /// default Jacobian noise), the only row that differentiates an index of refraction.
    /// With several --diff-param: `diff` samples by all of them, one hero per path (weights
    /// --hero-weights), `diff:NAME` by NAME alone, `diff@W/W/…` by all with hero weights W.
    #[arg(long, value_delimiter = ',')]
    strategy: Option<Vec<String>>,
    /// Probabilities of `diff`'s differential vertex, comma-separated (one row each: a q sweep).
    #[arg(long, value_delimiter = ',', default_value = "0.5")]
    q: Vec<f32>,
    /// Weightings of `diff`'s placements, comma-separated: balance, power (one row each; `auto`
    /// uses the first).
    #[arg(long, value_delimiter = ',', default_value = "balance")]
    placement_mis: Vec<String>,
    /// Turn next-event estimation off for every strategy.
    #[arg(long)]
    no_nee: bool,
    /// The parameter whose derivative drives `diff`'s sampler (default: --param); several,
    /// comma-separated, for the hero strategy (ALGORITHMS.md §5.8).
    #[arg(long, value_name = "NAME[,NAME…]")]
    diff_param: Option<String>,
    /// With several --diff-param: each one's probability of being a path's hero, comma-separated
    /// (default: uniform).
    #[arg(long, value_name = "W,W…")]
    hero_weights: Option<String>,
    /// Independent estimates per strategy (seeds --seed, --seed + 1, …).
    #[arg(long, default_value_t = 100)]
    runs: u32,
    /// Loss-gradient mode: the loss (relmse, relmse_max, l2 or l1) against --target or --target-set.
    #[arg(long)]
    loss: Option<String>,
    /// Loss-gradient mode: the target image (EXR).
    #[arg(long, conflicts_with = "target_set")]
    target: Option<PathBuf>,
    /// Loss-gradient mode: render the target at these values (NAME=V or NAME=R,G,B; repeatable).
    #[arg(long = "target-set", value_name = "NAME=VALUE", value_parser = parse_define)]
    target_set: Vec<(String, String)>,
    /// Loss-gradient mode: samples per pixel of pass 1, the loss image (default: 3 × --spp, the
    /// 3:1 budget).
    #[arg(long)]
    spp_primal: Option<u32>,
    /// Loss-gradient mode: also run every strategy with adaptive pixel sampling, its pixel weights
    /// fixed from one pass-1 render (the Tables 1–2 protocol).
    #[arg(long)]
    adaptive: bool,
    /// Weights of adaptive samples: importance (unbiased, default) or pixel_mean (the authors').
    #[arg(long, default_value = "importance")]
    adaptive_estimator: String,
    /// Directory for the variance maps and summary.json.
    #[arg(short, long, default_value = "variance-out")]
    output: PathBuf,
    #[command(flatten)]
    flags: RenderFlags,
    /// Print a one-line JSON summary instead of the table.
    #[arg(long)]
    json: bool,
}

/// One row of the comparison: a strategy, with or without adaptive pixel sampling.
struct Technique {
    label: String,
    stem: String,
    strategy: Strategy,
    /// Detached, or attached for the `attached` row.
    sampling: Sampling,
    adaptive: bool,
    /// The row of `auto`: its strategy is the pilot's choice, set once the device is open.
    auto: bool,
}

/// The rows `args` asks for, in order: per strategy (per q for `diff`), uniform then adaptive.
fn techniques(args: &VarianceArgs, scene: &pathgrad::scene::Scene) -> Result<(Vec<Technique>, PlacementMis)> {
    let target = args.diff_param.as_deref().unwrap_or(&args.param);
    let mut rows = Vec::new();
    let mut auto_placement = PlacementMis::Balance;
    let default = vec!["bsdf".to_string(), "diff".to_string()];
    let placements =
        args.placement_mis.iter().map(|p| PlacementMis::from_name(p)).collect::<pathgrad::Result<Vec<_>>>()?;
    let Some(&first_placement) = placements.first() else { bail!("--placement-mis lists no weighting") };
    for name in args.strategy.as_ref().unwrap_or(&default) {
        let parse_weights = |w: &str, sep: char| -> Result<Vec<f32>> {
            w.split(sep)
                .map(|x| x.trim().parse::<f32>().with_context(|| format!("invalid hero weights '{w}'")))
                .collect()
        };
        // The hero strategy's variants: `diff` over several targets, `diff:NAME`, `diff@W/W`.
        let heroes: Vec<&str> = target.split(',').map(str::trim).collect();
        let hero_row = if let Some(one) = name.strip_prefix("diff:") {
            Some((vec![one], None, format!(" [{one}]"), format!("-{one}")))
        } else if let Some(w) = name.strip_prefix("diff@") {
            let w = parse_weights(w, '/')?;
            let tag = w.iter().map(|x| format!("{x}")).collect::<Vec<_>>().join("-");
            Some((heroes.clone(), Some(w), String::new(), format!("-p{tag}")))
        } else if name == "diff" && heroes.len() > 1 {
            let w = args.hero_weights.as_deref().map(|w| parse_weights(w, ',')).transpose()?;
            Some((heroes.clone(), w, String::new(), String::new()))
        } else {
            None
        };
        if let Some((targets, weights, label_tag, stem_tag)) = hero_row {
            if placements != [PlacementMis::Balance] {
                bail!("--placement-mis power is not built for the hero strategy ({name}): use balance");
            }
            for &q in &args.q {
                let strategy = Strategy::hero(scene, &targets, q, weights.as_deref())
                    .with_context(|| format!("invalid --strategy {name}"))?;
                let label = format!("{}{label_tag}", strategy_label(&strategy));
                let stem = format!("diff-q{q}{stem_tag}");
                if rows.iter().any(|r: &Technique| r.stem == stem) {
                    bail!("--strategy/--q list '{label}' twice");
                }
                rows.push(Technique {
                    label: label.clone(),
                    stem: stem.clone(),
                    strategy,
                    sampling: Sampling::Detached,
                    adaptive: false,
                    auto: false,
                });
                if args.adaptive {
                    rows.push(Technique {
                        label: format!("{label} adaptive"),
                        stem: format!("{stem}-adaptive"),
                        strategy,
                        sampling: Sampling::Detached,
                        adaptive: true,
                        auto: false,
                    });
                }
            }
            continue;
        }
        // `attached`: the bsdf strategy, sampled attached.
        let sampling = if name == "attached" { Sampling::attached() } else { Sampling::Detached };
        let name = if sampling.is_attached() { "bsdf" } else { name.as_str() };
        if name != "bsdf" && heroes.len() > 1 {
            bail!("--strategy {name} takes one --diff-param (several: diff, diff:NAME or diff@W/W)");
        }
        let diff = name == "diff";
        let qs: &[f32] = if diff { &args.q } else { &[0.0] };
        let weightings: &[PlacementMis] = if diff { &placements } else { &[PlacementMis::Balance] };
        for (&q, &placement) in qs.iter().flat_map(|q| weightings.iter().map(move |p| (q, p))) {
            let auto = name == "auto";
            let strategy = if auto {
                Strategy::from_name(scene, "diff", DEFAULT_DIFF_Q, target)?;
                Strategy::Bsdf
            } else {
                Strategy::from_name(scene, name, q, target)?.with_placement(placement)
            };
            let (label, stem) = match strategy {
                _ if auto => ("auto".to_string(), "auto".to_string()),
                _ if sampling.is_attached() => ("attached".to_string(), "attached".to_string()),
                Strategy::Bsdf => ("bsdf".to_string(), "bsdf".to_string()),
                Strategy::Diff { q, placement: PlacementMis::Balance, .. } => {
                    (format!("diff q={q}"), format!("diff-q{q}"))
                }
                Strategy::Diff { q, placement: PlacementMis::Power, .. } => {
                    (format!("diff q={q} power"), format!("diff-q{q}-power"))
                }
                // Hero rows are made above; a label all the same.
                Strategy::Hero { .. } => (strategy_label(&strategy), format!("diff-q{q}-hero")),
            };
            for adaptive in [false, true] {
                if adaptive && !args.adaptive {
                    continue;
                }
                let (label, stem) = if adaptive {
                    (format!("{label} adaptive"), format!("{stem}-adaptive"))
                } else {
                    (label.clone(), stem.clone())
                };
                if rows.iter().any(|r: &Technique| r.stem == stem) {
                    bail!("--strategy/--q list '{label}' twice");
                }
                rows.push(Technique { label, stem, strategy, sampling, adaptive, auto });
                if auto {
                    auto_placement = first_placement;
                }
            }
        }
    }
    if rows.is_empty() {
        bail!("--strategy lists no strategy");
    }
    if let Some(row) = rows.iter().find(|r| r.strategy != Strategy::Bsdf) {
        warn_without_sampler(scene, row.strategy);
    }
    Ok((rows, auto_placement))
}

/// What one technique measured, in either mode.
struct Row {
    variance: f64,
    seconds: f64,
    cpu_seconds: Option<f64>,
    extra: serde_json::Value,
}

pub(crate) fn run(args: &VarianceArgs) -> Result<()> {
    let scene = args.flags.load(&args.scene, &args.defines)?;
    let mut opts = options(&scene, &args.flags)?;
    opts.nee = !args.no_nee;
    let param = scene.params.find(&args.param).with_context(|| {
        format!("invalid --param {}: no such parameter (see `pathgrad params {}`)", args.param, args.scene)
    })?;
    let (mut rows, auto_placement) = techniques(args, &scene)?;
    // Detached sampling holds the directions an index of refraction moves: its gradient is 0.
    if pathgrad::attached::attached_only_params(&scene).contains(&param)
        && let Some(row) = rows.iter().find(|r| !r.sampling.is_attached())
    {
        bail!(
            "invalid --strategy {}{}: {} acts only through sampled directions and has no detached derivative; \
             measure it with --strategy attached",
            row.label,
            if args.strategy.is_none() { " (the default is bsdf,diff)" } else { "" },
            args.param
        );
    }
    let loss_mode = args.target.is_some() || !args.target_set.is_empty();
    if !loss_mode && (args.loss.is_some() || args.adaptive || args.spp_primal.is_some()) {
        bail!(
            "--loss, --spp-primal and --adaptive are for loss-gradient mode: give --target REF.exr or --target-set NAME=VALUE"
        );
    }
    let estimator: AdaptiveEstimator = args.adaptive_estimator.parse()?;
    if args.runs < 2 {
        bail!("invalid --runs {}: a variance needs at least 2 runs", args.runs);
    }
    if args.output.exists() && !args.output.is_dir() {
        bail!("invalid -o {}: exists and is not a directory", args.output.display());
    }
    // Every file the run will write is checked before anything is estimated.
    let planned = planned_outputs(&args.output, &rows, loss_mode);
    if args.output.is_dir() {
        for path in &planned {
            pathgrad::output::check_destination(path)?;
        }
    }

    let mut renderer = args.flags.backend(&scene, &args.scene, args.json)?.backend;
    let device = renderer.describe();
    // Only the kind of the parameter measured is compiled into the gradient kernels.
    opts.differentiate = renderer.param_kinds(&[param]);
    // Loss-gradient mode's loss, target and pass-1 spp.
    let loss_setup = match loss_mode {
        false => None,
        true => {
            let loss: pathgrad::loss::Loss = args.loss.as_deref().unwrap_or("relmse").parse()?;
            let target = target_image(renderer.as_mut(), &scene, &opts, args.target.as_deref(), &args.target_set)?;
            Some((loss, target, args.spp_primal.unwrap_or(3 * opts.spp)))
        }
    };
    let params = [param];
    // `auto`: the pilot picks the strategy of its rows, at the run's resolution and seed, on what
    // the run measures (the loss gradient with uniform pixels, or the image gradient).
    let mut pilot = None;
    if rows.iter().any(|r| r.auto) {
        let target = args.diff_param.as_deref().unwrap_or(&args.param);
        let measure = loss_setup.as_ref().map(|(loss, image, spp_primal)| variance::PilotLoss {
            target: image,
            loss: *loss,
            spp_primal: *spp_primal,
            params: &params,
        });
        let choice = variance::choose_strategy(
            renderer.as_mut(),
            &opts,
            target,
            auto_placement,
            PilotBudget::default(),
            measure.as_ref(),
        )
        .context("running the auto row's pilot")?;
        tracing::info!(
            "auto picked {} (pilot: {} renders, {} spp per pixel in all, {:.2} s of which {:.2} s kernel warm-up)",
            strategy_label(&choice.strategy),
            choice.renders,
            choice.samples_per_pixel,
            choice.seconds,
            choice.warm_up_seconds
        );
        for row in rows.iter_mut().filter(|r| r.auto) {
            row.strategy = choice.strategy;
            row.label = row.label.replacen("auto", &format!("auto: {}", strategy_label(&choice.strategy)), 1);
        }
        pilot = Some(pilot_json(&scene, target, &choice, measure.is_some()));
    }
    let runs = u64::from(args.runs) * rows.len() as u64;
    let progress = progress_bar(runs, "{msg:>16} [{bar:40}] {pos}/{len} runs", args.json);

    let mut measured = Vec::with_capacity(rows.len());
    let mut outputs: Option<Outputs> = None;
    let mode;
    // Each sampling the rows use has kernels of its own to warm up.
    let mut samplings: Vec<Sampling> = Vec::new();
    for row in &rows {
        if !samplings.contains(&row.sampling) {
            samplings.push(row.sampling);
        }
    }
    if let Some((loss, target, spp_primal)) = loss_setup {
        mode = "loss";
        // Warm-up, untimed: lavapipe compiles each kernel at its first dispatch.
        let warm_ups = samplings.iter().flat_map(|&s| [(s, false), (s, true)]);
        for (sampling, adaptive) in warm_ups.filter(|&(_, a)| !a || args.adaptive) {
            let setup = LossGradientSetup {
                target: &target,
                loss,
                spp_primal: 1,
                adaptive: adaptive.then_some(estimator),
                params: &params,
            };
            variance::loss_gradient_variance(
                renderer.as_mut(),
                &RenderOptions { spp: 1, sampling, ..opts },
                &setup,
                2,
                &mut |_| {},
            )
            .context("warming up")?;
        }
        for (k, row) in rows.iter().enumerate() {
            progress.set_message(row.label.clone());
            let setup = LossGradientSetup {
                target: &target,
                loss,
                spp_primal,
                adaptive: row.adaptive.then_some(estimator),
                params: &params,
            };
            let base = u64::from(args.runs) * k as u64;
            let r = variance::loss_gradient_variance(
                renderer.as_mut(),
                &RenderOptions { strategy: row.strategy, sampling: row.sampling, ..opts },
                &setup,
                args.runs,
                &mut |done| progress.set_position(base + u64::from(done)),
            )
            .with_context(|| format!("estimating the loss-gradient variance of {}", row.label))?;
            measured.push(Row {
                variance: r.total_variance,
                seconds: r.seconds_per_estimate,
                cpu_seconds: r.cpu_seconds_per_estimate,
                extra: serde_json::json!({"mean_gradient": r.mean, "variance_per_value": r.variance, "mean_loss": r.mean_loss}),
            });
        }
    } else {
        mode = "image";
        let mut maps = Vec::with_capacity(rows.len());
        // Warm-up, untimed: lavapipe compiles each kernel at its first dispatch.
        for &sampling in &samplings {
            renderer.image_gradient(&RenderOptions { spp: 1, sampling, ..opts }, &args.param).context("warming up")?;
        }
        for (k, row) in rows.iter().enumerate() {
            progress.set_message(row.label.clone());
            let base = u64::from(args.runs) * k as u64;
            let r = variance::image_gradient_variance(
                renderer.as_mut(),
                &RenderOptions { strategy: row.strategy, sampling: row.sampling, ..opts },
                &args.param,
                args.runs,
                &mut |done| progress.set_position(base + u64::from(done)),
            )
            .with_context(|| format!("estimating the image-gradient variance of {}", row.label))?;
            measured.push(Row {
                variance: r.mean_variance,
                seconds: r.seconds_per_estimate,
                cpu_seconds: r.cpu_seconds_per_estimate,
                extra: serde_json::json!({}),
            });
            maps.push(r);
        }
        outputs = Some(Outputs::create(&args.output)?);
        let top = maps.iter().map(|m| m.variance.max_channel_mean()).fold(0.0f32, f32::max);
        let scale = maps.iter().map(|m| m.mean.signed_scale()).fold(0.0f32, f32::max);
        for (row, (map, m)) in rows.iter().zip(maps.iter().zip(&mut measured)) {
            let variance_exr = args.output.join(format!("variance-{}.exr", row.stem));
            let mean_exr = args.output.join(format!("mean-{}.exr", row.stem));
            let set = outputs.as_mut().expect("created above");
            map.variance.write_exr(set.stage(&variance_exr)?)?;
            map.variance.write_log_png(set.stage(&variance_exr.with_extension("png"))?, Some(top), PNG_DECADES)?;
            map.mean.write_exr(set.stage(&mean_exr)?)?;
            map.mean.write_signed_png(set.stage(&mean_exr.with_extension("png"))?, Some(scale))?;
            m.extra = serde_json::json!({"outputs": [variance_exr, variance_exr.with_extension("png"), mean_exr, mean_exr.with_extension("png")]});
        }
    }
    progress.finish_and_clear();

    let baseline = rows
        .iter()
        .position(|r| r.strategy == Strategy::Bsdf && r.sampling == Sampling::Detached && !r.adaptive && !r.auto)
        .unwrap_or(0);
    let base = &measured[baseline];
    let ratio = |a: f64, b: f64| if b > 0.0 { a / b } else { f64::NAN };
    // Per row: variance, wall-time and CPU-time efficiency, each relative to the baseline.
    let relative: Vec<(f64, f64, Option<f64>)> = measured
        .iter()
        .map(|m| {
            let cpu = match (m.cpu_seconds, base.cpu_seconds) {
                (Some(c), Some(b)) => {
                    Some(ratio(variance::efficiency(m.variance, c), variance::efficiency(base.variance, b)))
                }
                _ => None,
            };
            let wall =
                ratio(variance::efficiency(m.variance, m.seconds), variance::efficiency(base.variance, base.seconds));
            (ratio(m.variance, base.variance), wall, cpu)
        })
        .collect();
    let items: Vec<serde_json::Value> = rows
        .iter()
        .zip(&measured)
        .zip(&relative)
        .map(|((row, m), &(variance_ratio, efficiency_ratio, cpu_efficiency_ratio))| {
            let mut item = serde_json::json!({
                "technique": row.label,
                "strategy": row.strategy.name(),
                "sampling": row.sampling.name(),
                "q": match row.strategy { Strategy::Diff { q, .. } | Strategy::Hero { q, .. } => Some(q), Strategy::Bsdf => None },
                "placement_mis": match row.strategy { Strategy::Diff { placement, .. } => Some(placement.name()), Strategy::Hero { .. } => Some("balance"), Strategy::Bsdf => None },
                "hero_weights": match row.strategy { Strategy::Hero { heroes, .. } => Some(heroes.weights().to_vec()), _ => None },
                "auto": row.auto,
                "adaptive": row.adaptive,
                "variance": m.variance,
                "variance_ratio": variance_ratio,
                "seconds_per_estimate": m.seconds,
                "efficiency_ratio": efficiency_ratio,
                "cpu_seconds_per_estimate": m.cpu_seconds,
                "cpu_efficiency_ratio": cpu_efficiency_ratio,
            });
            if let (Some(item), Some(extra)) = (item.as_object_mut(), m.extra.as_object()) {
                item.extend(extra.clone());
            }
            item
        })
        .collect();
    let summary = serde_json::json!({
        "scene": args.scene, "param": args.param, "mode": mode, "runs": args.runs, "spp": opts.spp,
        "spp_primal": loss_mode.then(|| args.spp_primal.unwrap_or(3 * opts.spp)),
        "nee": opts.nee, "width": opts.width, "height": opts.height, "seed": opts.seed,
        "baseline": rows[baseline].label, "device": device, "techniques": items, "pilot": pilot,
    });
    let mut outputs = match outputs {
        Some(o) => o,
        None => Outputs::create(&args.output)?,
    };
    let summary_path = args.output.join("summary.json");
    pathgrad::output::write_bytes_atomically(
        outputs.stage(&summary_path)?,
        (serde_json::to_string_pretty(&summary)? + "\n").as_bytes(),
    )?;
    debug_assert_eq!(outputs.set.destinations(), planned, "the planned outputs are the ones written");
    outputs.commit()?;
    if args.json {
        println!("{summary}");
        return Ok(());
    }
    let what = if loss_mode {
        format!("∂loss/∂{}", args.param)
    } else {
        format!("∂I/∂{} (mean over pixels)", args.param)
    };
    println!(
        "variance of {what}: {} runs, {} spp{}, NEE {}, {}×{} on {}",
        args.runs,
        opts.spp,
        if loss_mode { format!(" (pass 1: {} spp)", args.spp_primal.unwrap_or(3 * opts.spp)) } else { String::new() },
        if opts.nee { "on" } else { "off" },
        opts.width,
        opts.height,
        device
    );
    println!(
        "{:<28} {:>12} {:>10} {:>10} {:>10} {:>10} {:>10}",
        "technique", "variance", "ratio", "wall s", "var×wall", "cpu s", "var×cpu"
    );
    let cell = |v: Option<f64>, precision: usize| v.map_or("-".to_string(), |v| format!("{v:.precision$}"));
    for ((row, m), &(variance_ratio, wall, cpu)) in rows.iter().zip(&measured).zip(&relative) {
        println!(
            "{:<28} {:>12.4e} {:>10.4} {:>10.4} {:>10.4} {:>10} {:>10}",
            row.label,
            m.variance,
            variance_ratio,
            m.seconds,
            wall,
            cell(m.cpu_seconds, 4),
            cell(cpu, 4)
        );
    }
    println!(
        "ratio, var×wall and var×cpu are relative to {} (var×time: the variance reached in equal time, lower is better)",
        rows[baseline].label
    );
    println!("→ {}", summary_path.display());
    Ok(())
}

/// The files a run writes into `dir`, in the order it writes them.
fn planned_outputs(dir: &std::path::Path, rows: &[Technique], loss_mode: bool) -> Vec<std::path::PathBuf> {
    let mut files = Vec::new();
    if !loss_mode {
        for row in rows {
            for name in ["variance", "mean"] {
                let exr = dir.join(format!("{name}-{}.exr", row.stem));
                files.push(exr.with_extension("png"));
                files.insert(files.len() - 1, exr);
            }
        }
    }
    files.push(dir.join("summary.json"));
    files
}

/// The output directory (created only once every estimate has succeeded) and the files staged in
/// it: all are put in place together, and if anything fails before, nothing is left — the
/// directory too, if this run created it.
struct Outputs {
    dir: std::path::PathBuf,
    created: bool,
    set: pathgrad::output::OutputSet,
}

impl Outputs {
    fn create(dir: &std::path::Path) -> Result<Outputs> {
        let created = !dir.exists();
        std::fs::create_dir_all(dir).with_context(|| format!("creating -o {}", dir.display()))?;
        Ok(Outputs { dir: dir.to_path_buf(), created, set: pathgrad::output::OutputSet::new() })
    }

    fn stage(&mut self, path: &std::path::Path) -> Result<std::path::PathBuf> {
        Ok(self.set.stage(path)?)
    }

    fn commit(mut self) -> Result<()> {
        let set = std::mem::take(&mut self.set);
        set.commit()?;
        self.created = false;
        Ok(())
    }
}

impl Drop for Outputs {
    fn drop(&mut self) {
        // Uncommitted: the set's own drop removes its files; an emptied new directory goes too.
        self.set = pathgrad::output::OutputSet::new();
        if self.created {
            let _ = std::fs::remove_dir(&self.dir);
        }
    }
}

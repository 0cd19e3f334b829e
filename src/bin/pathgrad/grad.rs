//! `pathgrad grad`: the gradient of a loss against a target, or a forward-mode image gradient.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context as _, Result, bail};
use clap::Args;
use pathgrad::output::OutputSet;

use crate::common::{
    RenderFlags, StrategyArgs, check_output, options, parse_define, parse_views, preview_path, refuse_non_finite,
    target_image, view_targets, with_values,
};
use pathgrad::integrator::View;

#[derive(Args, Debug)]
pub(crate) struct GradArgs {
    /// The scene: builtin:NAME or a scene file.
    pub(crate) scene: String,
    /// Override a scene file's default: NAME=VALUE (repeatable).
    #[arg(short = 'D', long = "define", value_name = "NAME=VALUE", value_parser = parse_define)]
    pub(crate) defines: Vec<(String, String)>,
    /// Parameters to report, by name or glob (`*.alpha.value`); repeatable.
    #[arg(long = "param", value_name = "NAME")]
    pub(crate) params: Vec<String>,
    /// The target image (EXR) the loss compares against.
    #[arg(long, conflicts_with = "target_set")]
    pub(crate) target: Option<PathBuf>,
    /// Differentiate several views in one step: SENSOR=TARGET.exr, or SENSOR with --target-set
    /// (repeatable; by index or name, `pathgrad params` lists them). The loss is the mean of the
    /// views' losses; every view is rendered and differentiated in one pass.
    #[arg(long = "view", value_name = "SENSOR[=TARGET.exr]", conflicts_with_all = ["target", "image_gradient"])]
    pub(crate) views: Vec<String>,
    /// Render the target at these parameter values instead (NAME=V or NAME=R,G,B; repeatable),
    /// with 4× the spp (at least 64) and an independent seed.
    #[arg(long = "target-set", value_name = "NAME=VALUE", value_parser = parse_define)]
    pub(crate) target_set: Vec<(String, String)>,
    /// The loss: relmse, relmse_max, l2 or l1.
    #[arg(long, default_value = "relmse")]
    pub(crate) loss: String,
    /// Accumulate gradients in 64-bit fixed point: bitwise reproducible runs.
    #[arg(long)]
    pub(crate) deterministic: bool,
    /// Instead of a loss gradient, write the forward-mode image gradient ∂I/∂NAME to -o.
    #[arg(long, value_name = "NAME", conflicts_with_all = ["target", "target_set"])]
    pub(crate) image_gradient: Option<String>,
    /// Output of --image-gradient: an .exr (a signed false-colour .png is written beside it).
    #[arg(short, long)]
    pub(crate) output: Option<PathBuf>,
    #[command(flatten)]
    pub(crate) flags: RenderFlags,
    #[command(flatten)]
    pub(crate) sampling: StrategyArgs,
    /// Print JSON: {"loss", "gradients": {name: [..]}, "time_s"}.
    #[arg(long)]
    pub(crate) json: bool,
    /// After the gradient step, take the same step N more times in this process and report each
    /// one's time (`repeat_s` in the JSON): the steady cost, without the one-off costs of opening
    /// the device, the target and building the kernels. Not with --image-gradient.
    #[arg(long, value_name = "N", default_value_t = 0, conflicts_with = "image_gradient")]
    pub(crate) repeat: u32,
}

pub(crate) fn grad(args: &GradArgs) -> Result<()> {
    use pathgrad::gpu::renderer::GradMode;
    // The outputs of --image-gradient are checked before anything is loaded or rendered.
    let image_gradient_outputs = match (&args.image_gradient, &args.output) {
        (None, Some(_)) => bail!("-o is the output of --image-gradient (a loss gradient is printed)"),
        (None, None) => None,
        (Some(_), None) => bail!("--image-gradient needs -o OUT.exr"),
        (Some(_), Some(output)) => {
            if !check_output(output)? {
                bail!("invalid -o {}: an image gradient is written as .exr (plus a .png preview)", output.display());
            }
            let mut outputs = OutputSet::new();
            let exr_file = outputs.stage(output)?;
            let png_file = outputs.stage(&preview_path(output))?;
            Some((output, outputs, exr_file, png_file))
        }
    };
    let scene = args.flags.load(&args.scene, &args.defines)?;
    let mut opts = options(&scene, &args.flags)?;
    let views = match args.views.is_empty() {
        true => Vec::new(),
        false => parse_views(&scene, &args.flags, &args.views, !args.target_set.is_empty(), &mut opts)?,
    };
    let first_param = args.image_gradient.as_deref().or_else(|| args.params.first().map(String::as_str));
    args.sampling.apply(&scene, first_param, &mut opts)?;
    // Names, the loss and the target's values are checked before the device is opened.
    let loss: pathgrad::loss::Loss = args.loss.parse()?;
    let patterns: Vec<&str> =
        if args.params.is_empty() { vec!["*"] } else { args.params.iter().map(String::as_str).collect() };
    let chosen = crate::common::select_differentiated(&scene, &patterns, opts.sampling).context("--param")?;
    if let Some(name) = &args.image_gradient {
        scene.params.select(&[name.as_str()]).context("--image-gradient")?;
    }
    with_values(&scene.params, &args.target_set, "--target-set").context("--target-set")?;
    let mut renderer = args.flags.backend(&scene, &args.scene, args.json)?.backend;
    if let (Some(name), Some((output, outputs, exr_file, png_file))) = (&args.image_gradient, image_gradient_outputs) {
        let pilot = args.sampling.choose(renderer.as_mut(), first_param, &mut opts, None)?;
        let strategy = crate::common::strategy_json(&scene, &opts.strategy);
        let start = Instant::now();
        let image = renderer.image_gradient(&opts, name).with_context(|| format!("differentiating {}", args.scene))?;
        let seconds = start.elapsed().as_secs_f64();
        refuse_non_finite(&image, &format!("the image gradient ∂I/∂{name}"))?;
        image.write_exr(&exr_file)?;
        image.write_signed_png(&png_file, None)?;
        outputs.commit()?;
        let preview = preview_path(output);
        if args.json {
            println!(
                "{}",
                serde_json::json!({"param": name, "time_s": seconds, "outputs": [output, preview], "mean": image.mean(), "strategy": strategy, "pilot": pilot})
            );
        } else {
            println!("∂I/∂{name} in {seconds:.2} s → {}, {}", output.display(), preview.display());
        }
        return Ok(());
    }
    // Only the kinds of the parameters reported are compiled into the gradient kernel.
    opts.differentiate = renderer.param_kinds(&chosen);
    let mode = if args.deterministic { GradMode::Deterministic } else { GradMode::Float };
    // time_s is the gradient step (render, loss, fused adjoint), not the --target-set render nor
    // --strategy auto's pilot (on the loss gradient with one view; on the image gradient with several).
    let pilot;
    let (value, gradients, seconds, repeat_s) = if views.is_empty() {
        let target = target_image(renderer.as_mut(), &scene, &opts, args.target.as_deref(), &args.target_set)?;
        let measure = pathgrad::variance::PilotLoss { target: &target, loss, spp_primal: opts.spp, params: &chosen };
        pilot = args.sampling.choose(renderer.as_mut(), first_param, &mut opts, Some(&measure))?;
        let start = Instant::now();
        let (value, gradients) = renderer
            .loss_and_gradient(&opts, &target, loss, mode)
            .with_context(|| format!("differentiating {}", args.scene))?;
        let seconds = start.elapsed().as_secs_f64();
        let repeat_s = repeated(args.repeat, || renderer.loss_and_gradient(&opts, &target, loss, mode).map(drop))?;
        (value, gradients, seconds, repeat_s)
    } else {
        let targets = view_targets(renderer.as_mut(), &scene, &opts, &views, &args.target_set)?;
        pilot = args.sampling.choose(renderer.as_mut(), first_param, &mut opts, None)?;
        let list: Vec<View> = views.iter().map(|(v, _)| *v).collect();
        let start = Instant::now();
        let (value, gradients) = renderer
            .loss_and_gradient_views(&opts, opts.spp, &list, &targets, loss, mode)
            .with_context(|| format!("differentiating {} over {} views", args.scene, list.len()))?;
        let seconds = start.elapsed().as_secs_f64();
        let repeat_s = repeated(args.repeat, || {
            renderer.loss_and_gradient_views(&opts, opts.spp, &list, &targets, loss, mode).map(drop)
        })?;
        (value, gradients, seconds, repeat_s)
    };
    let strategy = crate::common::strategy_json(&scene, &opts.strategy);
    if args.json {
        let map: serde_json::Map<String, serde_json::Value> = chosen
            .iter()
            .map(|&id| {
                let name = scene.params.entry(id).name.clone();
                let values = gradients.get(&name).expect("the gradient has the table's layout").to_vec();
                (name, serde_json::json!(values))
            })
            .collect();
        println!(
            "{}",
            serde_json::json!({"loss": value, "gradients": map, "time_s": seconds, "repeat_s": repeat_s, "strategy": strategy, "pilot": pilot})
        );
    } else {
        if let Some(pilot) = &pilot {
            println!(
                "--strategy auto: {} (pilot {:.2} s, {} image gradients)",
                pilot["picked"]["technique"].as_str().unwrap_or("?"),
                pilot["pilot_s"].as_f64().unwrap_or(f64::NAN),
                pilot["pilot_renders"]
            );
        }
        println!("loss ({}) = {value:.6e}   ({seconds:.2} s)", args.loss);
        if let Some(best) = repeat_s.iter().copied().reduce(f64::min) {
            println!("  {} repeats: fastest {best:.3} s", repeat_s.len());
        }
        for id in chosen {
            let name = &scene.params.entry(id).name;
            let values = gradients.get(name).expect("the gradient has the table's layout");
            if values.len() <= 4 {
                println!("  ∂loss/∂{name} = {values:?}");
            } else {
                let norm = values.iter().map(|v| f64::from(*v).powi(2)).sum::<f64>().sqrt();
                println!("  ∂loss/∂{name} = [{} values, norm {norm:.4e}]", values.len());
            }
        }
    }
    Ok(())
}

/// `--repeat`: runs `step` `n` times and returns each run's seconds.
fn repeated(n: u32, mut step: impl FnMut() -> pathgrad::Result<()>) -> Result<Vec<f64>> {
    (0..n)
        .map(|_| {
            let start = Instant::now();
            step().context("differentiating again (--repeat)")?;
            Ok(start.elapsed().as_secs_f64())
        })
        .collect()
}

//! What a run writes and tells: CSV rows, progress, memory, the state file, the final outputs and the summary.

use std::fs;
use std::path::PathBuf;

use anyhow::{Context as _, Result};
use pathgrad::integrator::{RenderOptions, Strategy};
use pathgrad::optim::parameter_error;
use pathgrad::output::write_bytes_atomically;
use pathgrad::params::{ParamId, ParamTable};

use crate::curves::Row;

use super::*;

pub(super) fn row(s: &Session, iteration: u64, time_s: f64, loss: f64, grad_norm: f64) -> Row {
    let params = s.run.params();
    let mut values = Vec::new();
    let mut errors = Vec::new();
    for &id in &s.ids {
        let v = params.get(id);
        if v.len() <= 4 {
            values.extend(v.iter().map(|&x| f64::from(x)));
        } else {
            values.push(v.iter().map(|&x| f64::from(x)).sum::<f64>() / v.len() as f64);
        }
        if let Some(truth) = &s.truth {
            errors.push(parameter_error(v, truth.get(id)));
        }
    }
    let error = s.truth.as_ref().map(|truth| overall_error(params, truth, &s.ids));
    Row { iteration, time_s, loss, values, errors, error, grad_norm }
}

/// ALGORITHMS.md §7.1's relative squared error averaged over every optimised value.
pub(super) fn overall_error(params: &ParamTable, truth: &ParamTable, ids: &[ParamId]) -> f64 {
    let (mut sum, mut n) = (0.0, 0usize);
    for &id in ids {
        let len = params.get(id).len();
        sum += parameter_error(params.get(id), truth.get(id)) * len as f64;
        n += len;
    }
    sum / n as f64
}

pub(super) fn progress_message(s: &Session, loss: f64) -> String {
    let mut parts = vec![format!("loss {loss:.4e}")];
    for &id in s.ids.iter().take(3) {
        let v = s.run.params().get(id);
        let name = &s.run.params().entry(id).name;
        parts.push(if v.len() == 1 {
            format!("{name}={:.4}", v[0])
        } else {
            format!("{name}={:.3?}", &v[..v.len().min(3)])
        });
    }
    parts.join("  ")
}

/// Resident set size of this process in KiB (Linux `/proc/self/status`), if known.
pub(super) fn rss_kib() -> Option<u64> {
    let status = fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmRSS:"))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

pub(super) fn log_memory(ctx: Option<&pathgrad::gpu::Context>, iteration: u64) {
    let Some(ctx) = ctx else { return };
    tracing::debug!(
        iteration,
        rss_kib = rss_kib().unwrap_or(0),
        buffer_bytes = ctx.buffer_bytes(),
        peak_buffer_bytes = ctx.peak_buffer_bytes(),
        live_objects = ctx.live_objects(),
        "memory"
    );
}

/// Replaces `state.json` with the run as it is now.
pub(super) fn write_state(s: &Session, stopped: &str) -> Result<()> {
    let adam = s.run.adam().state();
    let state = State {
        version: STATE_VERSION,
        config: s.config.clone(),
        iteration: s.run.iteration(),
        elapsed_s: s.elapsed,
        params: values_of(s.run.params(), &s.ids),
        initial: s.initial.clone(),
        adam_m: adam.m.clone(),
        adam_v: adam.v.clone(),
        adam_steps: adam.steps.clone(),
        stopped: stopped.to_string(),
        hero: s.run.hero_adaptation().map(|h| HeroState {
            steps: h.steps,
            mean: h.mean.clone(),
            square: h.square.clone(),
        }),
    };
    // The control variates' estimate first: state.json then never points past it.
    super::control::write(&s.dir, &s.run, &s.ids)?;
    Ok(write_bytes_atomically(s.dir.join("state.json"), serde_json::to_string_pretty(&state)?.as_bytes())?)
}

/// Writes the end-of-run outputs: state, parameters, the final image and the curves.
pub(super) fn finish(s: &mut Session, stopped: &str) -> Result<()> {
    write_state(s, stopped)?;
    let params = values_of(s.run.params(), &s.ids);
    write_bytes_atomically(s.dir.join("params.json"), serde_json::to_string_pretty(&params)?.as_bytes())?;
    s.history.write_svg(&s.dir.join("curves.svg"), &s.initial_point())?;
    s.renderer.set_params(s.run.params())?;
    let opts = RenderOptions { spp: s.config.spp_final, strategy: Strategy::Bsdf, nee: true, ..s.run.options().render };
    let image = s
        .renderer
        .render_views(&opts, &s.views[..1], pathgrad::rng::PassTag::Primal, &mut |_, _| {})
        .context("rendering the final image")?
        .remove(0);
    image.write_exr(s.dir.join("final.exr"))?;
    image.write_png(s.dir.join("final.png"), 0.0)?;
    Ok(())
}

impl Session {
    /// The parameter error before the first iteration, the curves' first point (if the truth is
    /// known).
    fn initial_point(&self) -> Option<f64> {
        let truth = self.truth.as_ref()?;
        let mut table = self.scene.params.clone();
        for (name, values) in &self.initial {
            let v: Vec<f32> = values.iter().map(|&x| x as f32).collect();
            table.set(name, &v).ok()?;
        }
        Some(overall_error(&table, truth, &self.ids))
    }
}

pub(super) fn summary(s: &Session, stopped: &str, json: bool) {
    let last = s.history.last();
    let params = values_of(s.run.params(), &s.ids);
    let mut outputs: Vec<PathBuf> =
        ["history.csv", "curves.svg", "final.exr", "final.png", "params.json", "state.json"]
            .iter()
            .map(|f| s.dir.join(f))
            .collect();
    for file in [super::control::FILE, super::control::REUSE_FILE] {
        if s.dir.join(file).is_file() {
            outputs.push(s.dir.join(file));
        }
    }
    let ctx = s.ctx.as_deref();
    // The smoothness prior's value at the final parameters (--smooth).
    let prior = s.run.prior().map(|p| p.value(s.run.params()));
    if json {
        let v = serde_json::json!({
            "iterations": s.run.iteration(),
            "strategy": crate::common::strategy_json(&s.scene, &s.run.options().render.strategy),
            "pilot": s.config.pilot.as_ref().map(|p| &p.report),
            "adaptive": s.config.adaptive,
            "control_variates": s.config.control_variates,
            "reuse": s.config.reuse,
            "stopped": stopped,
            "time_s": s.elapsed,
            "setup_s": s.setup_s,
            "loss": last.map(|r| r.loss),
            "prior": prior,
            "param_error": last.and_then(|r| r.error),
            "params": params,
            "dir": s.dir,
            "outputs": outputs,
            "rss_kib": rss_kib(),
            "buffer_bytes": ctx.map(|c| c.buffer_bytes()),
            "peak_buffer_bytes": ctx.map(|c| c.peak_buffer_bytes()),
        });
        println!("{v}");
    } else {
        println!(
            "{stopped} after {} iterations in {:.2} s (set-up {:.2} s: loading, the target, kernel builds){}{}{} → {}",
            s.run.iteration(),
            s.elapsed,
            s.setup_s,
            last.map(|r| format!(", loss {:.4e}", r.loss)).unwrap_or_default(),
            prior.map(|p| format!(", prior {p:.4e}")).unwrap_or_default(),
            last.and_then(|r| r.error).map(|e| format!(", parameter error {e:.4e}")).unwrap_or_default(),
            s.dir.display()
        );
        println!(
            "  gradient pass: {} pixels; loss image: {}",
            if s.config.adaptive { "adaptive" } else { "uniform" },
            match (s.config.control_variates, s.config.reuse) {
                (true, _) => "control variates",
                (false, true) => "plain (gradient reuse across iterations)",
                (false, false) => "plain",
            }
        );
        if let Some(pilot) = &s.config.pilot {
            println!(
                "  --strategy auto picked {} (pilot {:.2} s)",
                pilot.report["picked"]["technique"].as_str().unwrap_or(&pilot.strategy),
                pilot.report["pilot_s"].as_f64().unwrap_or(f64::NAN)
            );
        }
        for (name, values) in &params {
            if values.len() <= 4 {
                println!("  {name} = {values:?}");
            } else {
                let mean = values.iter().sum::<f64>() / values.len() as f64;
                println!("  {name} = [{} values, mean {mean:.4}]", values.len());
            }
        }
    }
}

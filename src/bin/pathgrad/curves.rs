//! The history of an optimisation: `history.csv` (one flushed row per iteration) and `curves.svg` (loss and parameter error against wall time and iterations, log scales).

use std::fs;
use std::io::Write as _;
use std::path::Path;

use anyhow::{Context as _, Result, anyhow, bail};
use pathgrad::params::{ParamId, ParamTable};
use plotters::prelude::*;

/// One iteration in the CSV.
#[derive(Clone, Debug, PartialEq)]
pub(super) struct Row {
    /// The iteration's index t (0-based; its seed is the base seed + t).
    pub iteration: u64,
    /// Wall time of the iterations up to and including this one, in seconds.
    pub time_s: f64,
    /// The loss of pass 1, at the parameters before this iteration's step.
    pub loss: f64,
    /// The optimised values after the step (a parameter of more than 4 values: its mean).
    pub values: Vec<f64>,
    /// Per optimised parameter, its relative squared error after the step (truth known only).
    pub errors: Vec<f64>,
    /// The error averaged over every optimised value (truth known only).
    pub error: Option<f64>,
    /// The gradient's norm over the optimised values.
    pub grad_norm: f64,
}

/// The rows so far and the open CSV.
#[derive(Debug)]
pub(super) struct History {
    columns: Vec<String>,
    value_columns: usize,
    params: Vec<String>,
    truth: bool,
    rows: Vec<Row>,
    file: Option<fs::File>,
}

impl History {
    /// An empty history of the parameters `ids` of `table`, with error columns if the truth is
    /// known.
    pub fn new(table: &ParamTable, ids: &[ParamId], truth: bool) -> History {
        let mut columns: Vec<String> = ["iteration", "time_s", "loss"].map(String::from).to_vec();
        let mut params = Vec::new();
        for &id in ids {
            let e = table.entry(id);
            params.push(e.name.clone());
            match e.len {
                1 => columns.push(e.name.clone()),
                2..=4 => columns.extend((0..e.len).map(|i| format!("{}[{i}]", e.name))),
                _ => columns.push(format!("{}(mean)", e.name)),
            }
        }
        let value_columns = columns.len() - 3;
        if truth {
            columns.extend(params.iter().map(|p| format!("error[{p}]")));
            columns.push("param_error".into());
        }
        columns.push("grad_norm".into());
        History { columns, value_columns, params, truth, rows: Vec::new(), file: None }
    }

    /// The last row.
    pub fn last(&self) -> Option<&Row> {
        self.rows.last()
    }

    /// Creates the CSV at `path` with its header.
    pub fn create(&mut self, path: &Path) -> Result<()> {
        self.rewrite(path)
    }

    /// Reads the rows of an earlier run from `path`, keeping those of iterations before `done`
    /// (a killed run may have written a row its state does not cover). Fields are RFC 4180 CSV:
    /// a parameter name with a comma, quote or line break is a quoted field.
    pub fn read(&mut self, path: &Path, done: u64) -> Result<()> {
        let text = fs::read(path).with_context(|| format!("--resume: reading {}", path.display()))?;
        let mut reader = csv::ReaderBuilder::new().has_headers(false).flexible(true).from_reader(text.as_slice());
        let mut records = reader.records();
        let bad = |e: csv::Error| anyhow!("--resume: {} is not valid CSV ({e})", path.display());
        let header = records.next().transpose().map_err(bad)?.unwrap_or_default();
        if header.iter().ne(self.columns.iter().map(String::as_str)) {
            bail!(
                "--resume: {} has the columns {:?}, not this run's",
                path.display(),
                header.iter().collect::<Vec<_>>()
            );
        }
        let n_err = if self.truth { self.params.len() } else { 0 };
        for record in records {
            let fields = record.map_err(bad)?;
            let line = fields.position().map_or(0, |p| p.line());
            if fields.len() != self.columns.len() {
                bail!(
                    "--resume: {} line {line}: {} fields, expected {}",
                    path.display(),
                    fields.len(),
                    self.columns.len()
                );
            }
            let number = |k: usize| -> Result<f64> {
                fields[k]
                    .parse()
                    .map_err(|_| anyhow!("--resume: {} line {line}: '{}' is not a number", path.display(), &fields[k]))
            };
            let iteration = fields[0]
                .parse::<u64>()
                .map_err(|_| anyhow!("--resume: {} line {line}: bad iteration '{}'", path.display(), &fields[0]))?;
            if iteration >= done {
                continue;
            }
            let v0 = 3;
            let e0 = v0 + self.value_columns;
            let row = Row {
                iteration,
                time_s: number(1)?,
                loss: number(2)?,
                values: (v0..e0).map(number).collect::<Result<_>>()?,
                errors: (e0..e0 + n_err).map(number).collect::<Result<_>>()?,
                error: if self.truth { Some(number(e0 + n_err)?) } else { None },
                grad_norm: number(fields.len() - 1)?,
            };
            self.rows.push(row);
        }
        Ok(())
    }

    /// Replaces the CSV at `path` with the header and the rows held, and opens it for appending.
    pub fn rewrite(&mut self, path: &Path) -> Result<()> {
        let mut text = csv_line(self.columns.iter().map(String::as_str));
        for row in &self.rows {
            text.push_str(&self.line(row));
        }
        pathgrad::output::write_bytes_atomically(path, text.as_bytes())?;
        self.file = Some(
            fs::OpenOptions::new().append(true).open(path).with_context(|| format!("opening {}", path.display()))?,
        );
        Ok(())
    }

    fn line(&self, row: &Row) -> String {
        let mut fields = vec![row.iteration.to_string(), row.time_s.to_string(), row.loss.to_string()];
        fields.extend(row.values.iter().map(f64::to_string));
        fields.extend(row.errors.iter().map(f64::to_string));
        fields.extend(row.error.map(|e| e.to_string()));
        fields.push(row.grad_norm.to_string());
        csv_line(fields.iter().map(String::as_str))
    }

    /// Appends `row` to the CSV at `path` (opened by [`History::create`] or [`History::rewrite`])
    /// and flushes it.
    pub fn append(&mut self, path: &Path, row: Row) -> Result<()> {
        let line = self.line(&row);
        let file = self.file.as_mut().expect("the CSV is opened before the first row");
        file.write_all(line.as_bytes())
            .and_then(|()| file.flush())
            .with_context(|| format!("writing {}", path.display()))?;
        self.rows.push(row);
        Ok(())
    }

    /// Writes `curves.svg`: loss against wall time and iterations, and with the truth known the
    /// parameter error too (overall, and per parameter if there are several), all on log y axes;
    /// `initial_error` is the error before the first step (at time 0, iteration 0).
    pub fn write_svg(&self, path: &Path, initial_error: &Option<f64>) -> Result<()> {
        let mut svg = String::new();
        {
            let panels = if self.truth { (2, 2) } else { (1, 2) };
            let size = (1200, if self.truth { 900 } else { 450 });
            let root = SVGBackend::with_string(&mut svg, size).into_drawing_area();
            root.fill(&WHITE).map_err(plot_error)?;
            let areas = root.split_evenly(panels);
            // The loss of row t was measured at the parameters after t steps.
            let loss: Vec<(f64, f64, f64)> = self.rows.iter().map(|r| (r.time_s, r.iteration as f64, r.loss)).collect();
            let loss_series = vec![("loss".to_string(), loss)];
            plot(&areas[0], "loss against wall time", "wall time (s)", "loss", &loss_series, false)?;
            plot(&areas[1], "loss against iterations", "iterations done", "loss", &loss_series, true)?;
            if self.truth {
                // The error of row t is after t + 1 steps; before the first, it is the initial error.
                let mut series = Vec::new();
                let mut overall: Vec<(f64, f64, f64)> = initial_error.iter().map(|&e| (0.0, 0.0, e)).collect();
                overall.extend(self.rows.iter().filter_map(|r| Some((r.time_s, r.iteration as f64 + 1.0, r.error?))));
                series.push(("parameter error (all values)".to_string(), overall));
                if self.params.len() > 1 {
                    for (k, name) in self.params.iter().enumerate() {
                        let points = self.rows.iter().map(|r| (r.time_s, r.iteration as f64 + 1.0, r.errors[k]));
                        series.push((name.clone(), points.collect()));
                    }
                }
                plot(
                    &areas[2],
                    "parameter error against wall time",
                    "wall time (s)",
                    "relative squared error",
                    &series,
                    false,
                )?;
                plot(
                    &areas[3],
                    "parameter error against iterations",
                    "iterations done",
                    "relative squared error",
                    &series,
                    true,
                )?;
            }
            root.present().map_err(plot_error)?;
        }
        Ok(pathgrad::output::write_bytes_atomically(path, svg.as_bytes())?)
    }
}

/// A named curve: (wall time, iterations, y) per point.
type Series = (String, Vec<(f64, f64, f64)>);

fn plot_error(e: impl std::fmt::Display) -> anyhow::Error {
    anyhow!("drawing curves.svg: {e}")
}

/// One panel: each series' (time, iteration, y) points against time or (`by_iteration`)
/// iterations, on a log y axis. Points with y ≤ 0 or not finite cannot be drawn there and are
/// left out.
fn plot(
    area: &DrawingArea<SVGBackend<'_>, plotters::coord::Shift>,
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series],
    by_iteration: bool,
) -> Result<()> {
    let xy = |p: &(f64, f64, f64)| (if by_iteration { p.1 } else { p.0 }, p.2);
    let drawable = |p: &(f64, f64)| p.1 > 0.0 && p.1.is_finite() && p.0.is_finite();
    let points: Vec<(f64, f64)> = series.iter().flat_map(|(_, s)| s.iter().map(xy)).filter(drawable).collect();
    let x_max = points.iter().map(|p| p.0).fold(0.0f64, f64::max).max(if by_iteration { 1.0 } else { 1e-3 });
    let (y_min, y_max) = points.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), p| (lo.min(p.1), hi.max(p.1)));
    let (y_min, y_max) = if points.is_empty() { (1e-3, 1.0) } else { (y_min / 2.0, y_max * 2.0) };
    let mut chart = ChartBuilder::on(area)
        .caption(title, ("sans-serif", 18))
        .margin(12)
        .x_label_area_size(36)
        .y_label_area_size(70)
        .build_cartesian_2d(0.0..x_max, (y_min..y_max).log_scale())
        .map_err(plot_error)?;
    chart
        .configure_mesh()
        .x_desc(x_label)
        .y_desc(y_label)
        .y_label_formatter(&|y| format!("{y:.0e}"))
        .draw()
        .map_err(plot_error)?;
    for (i, (name, s)) in series.iter().enumerate() {
        let colour = Palette99::pick(i).to_rgba();
        let line: Vec<(f64, f64)> = s.iter().map(xy).filter(drawable).collect();
        chart
            .draw_series(LineSeries::new(line, colour.stroke_width(2)))
            .map_err(plot_error)?
            .label(name.as_str())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], colour.stroke_width(2)));
    }
    chart.configure_series_labels().background_style(WHITE.mix(0.8)).border_style(BLACK).draw().map_err(plot_error)?;
    Ok(())
}

/// One CSV record ending in a newline: fields holding a comma, a quote or a line break are quoted
/// (RFC 4180), so a parameter named after any XML id keeps its column.
fn csv_line<'a>(fields: impl IntoIterator<Item = &'a str>) -> String {
    let mut writer = csv::WriterBuilder::new().terminator(csv::Terminator::Any(b'\n')).from_writer(Vec::new());
    writer.write_record(fields).expect("writing to memory cannot fail");
    String::from_utf8(writer.into_inner().expect("writing to memory cannot fail")).expect("the fields are UTF-8")
}

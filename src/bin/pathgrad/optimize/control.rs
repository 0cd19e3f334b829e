//! The running estimates of `--control-variates` and `--reuse` between sessions: `DIR/control_variates.bin` and `DIR/gradient_reuse.bin`, written before `state.json` after every iteration and read back by `--resume`.
//!
//! Layout of `control_variates.bin`, little-endian: the magic `PGCV`, a u32 version, the u64 step
//! and update counts, the u32 width, height and views, the u32 count of optimised values followed
//! by their previous values (f32, in `--param` order: the parameters H is rendered at), then the
//! eight f64 arrays of
//! [`RunningEstimate::arrays`](pathgrad::optim::RunningEstimate::arrays). `gradient_reuse.bin` is the
//! same with the magic `PGGR` and, in place of width, height and views, the u32 count of values
//! of the estimate (the optimised values again). The values are stored exactly, so a resumed run
//! continues bit for bit.

use std::fs;
use std::path::Path;

use anyhow::{Context as _, Result, bail};
use pathgrad::optim::{ControlVariateState, ControlVariates, GradientReuse, Optimization, RunningEstimate};
use pathgrad::output::write_bytes_atomically;
use pathgrad::params::{ParamId, ParamTable};

/// The control variates' state file's name in the run directory.
pub(super) const FILE: &str = "control_variates.bin";
/// Gradient reuse's state file's name in the run directory.
pub(super) const REUSE_FILE: &str = "gradient_reuse.bin";
const VERSION: u32 = 1;

/// What tells the two state files apart.
struct Kind {
    magic: &'static [u8; 4],
    /// The u32 values after the counts that give the estimate's layout.
    layout_len: usize,
    /// The estimate's length for a layout (`None` if it overflows).
    values: fn(&[u32]) -> Option<usize>,
    /// The option that keeps the file.
    flag: &'static str,
    /// The state's name in messages.
    what: &'static str,
}

/// `control_variates.bin`: width, height and views; three values a pixel.
const CONTROL_VARIATES: Kind = Kind {
    magic: b"PGCV",
    layout_len: 3,
    values: |l| (l[0] as usize).checked_mul(l[1] as usize)?.checked_mul(3)?.checked_mul(l[2] as usize),
    flag: "--control-variates",
    what: "control-variate",
};

/// `gradient_reuse.bin`: the number of values.
const REUSE: Kind =
    Kind { magic: b"PGGR", layout_len: 1, values: |l| Some(l[0] as usize), flag: "--reuse", what: "gradient-reuse" };

/// Writes `run`'s control-variate state and gradient reuse's state to `dir` (each only once an
/// iteration made it).
pub(super) fn write(dir: &Path, run: &Optimization, ids: &[ParamId]) -> Result<()> {
    if let ControlVariates { state: Some(state), previous: Some(previous) } = run.control_variates() {
        let layout = [state.width, state.height, state.views];
        write_file(&dir.join(FILE), CONTROL_VARIATES.magic, &state.running, &layout, previous, ids)?;
    }
    if let GradientReuse { state: Some(state), previous: Some(previous) } = run.gradient_reuse() {
        write_file(&dir.join(REUSE_FILE), REUSE.magic, state, &[state.len() as u32], previous, ids)?;
    }
    Ok(())
}

/// One state file: magic, version, counts, `layout`, the previous values of `ids`, the arrays.
fn write_file(
    path: &Path,
    magic: &[u8; 4],
    running: &RunningEstimate,
    layout: &[u32],
    previous: &ParamTable,
    ids: &[ParamId],
) -> Result<()> {
    let mut bytes = Vec::new();
    bytes.extend_from_slice(magic);
    bytes.extend_from_slice(&VERSION.to_le_bytes());
    bytes.extend_from_slice(&running.steps.to_le_bytes());
    bytes.extend_from_slice(&running.updates.to_le_bytes());
    for v in layout {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    let values: Vec<f32> = ids.iter().flat_map(|&id| previous.get(id).iter().copied()).collect();
    bytes.extend_from_slice(&(values.len() as u32).to_le_bytes());
    for v in values {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    for array in running.arrays() {
        for v in array {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
    }
    Ok(write_bytes_atomically(path, &bytes)?)
}

/// `run` continuing from the control-variate state in `dir`, where the run stopped after
/// `iteration` iterations at parameters `table` (whose layout the previous values take).
pub(super) fn read(dir: &Path, run: Optimization, table: &ParamTable, ids: &[ParamId]) -> Result<Optimization> {
    if run.iteration() == 0 {
        return Ok(run);
    }
    let path = dir.join(FILE);
    let context = || format!("--resume {}: reading {}", dir.display(), path.display());
    let (running, layout, previous) = read_file(&path, &CONTROL_VARIATES, run.iteration(), table, ids, &context)?;
    let [width, height, views] = layout[..] else { unreachable!("read_file reads 3 layout values") };
    let mut state = ControlVariateState::new(width, height, views);
    if running.len() != state.running.len() {
        bail!("{}: {} values for {views} view(s) of {width}×{height}", context(), running.len());
    }
    state.running = running;
    run.with_control_variates(ControlVariates { state: Some(state), previous: Some(previous) }).with_context(context)
}

/// `run` continuing from gradient reuse's state in `dir`, as [`read`].
pub(super) fn read_reuse(dir: &Path, run: Optimization, table: &ParamTable, ids: &[ParamId]) -> Result<Optimization> {
    if run.iteration() == 0 {
        return Ok(run);
    }
    let path = dir.join(REUSE_FILE);
    let context = || format!("--resume {}: reading {}", dir.display(), path.display());
    let (running, _, previous) = read_file(&path, &REUSE, run.iteration(), table, ids, &context)?;
    run.with_gradient_reuse(GradientReuse { state: Some(running), previous: Some(previous) }).with_context(context)
}

/// Reads one state file of `kind`: its running estimate, its layout values and the previous
/// parameters, checked against the run's `iteration`.
fn read_file(
    path: &Path,
    kind: &Kind,
    iteration: u64,
    table: &ParamTable,
    ids: &[ParamId],
    context: &dyn Fn() -> String,
) -> Result<(RunningEstimate, Vec<u32>, ParamTable)> {
    let Kind { magic, layout_len, flag, what, .. } = *kind;
    let bytes =
        fs::read(path).with_context(|| format!("{}: a run with {flag} keeps its running estimate there", context()))?;
    let mut r = Reader { bytes: &bytes, at: 0 };
    let parsed = (|| -> Option<(RunningEstimate, Vec<u32>, Vec<f32>)> {
        if r.take(4)? != magic || r.u32()? != VERSION {
            return None;
        }
        let (steps, updates) = (r.u64()?, r.u64()?);
        let layout = (0..layout_len).map(|_| r.u32()).collect::<Option<Vec<u32>>>()?;
        let count = r.u32()? as usize;
        // Refuse sizes the file cannot hold before allocating them.
        let values = (kind.values)(&layout)?;
        let rest = count.checked_mul(4)?.checked_add(values.checked_mul(8 * 8)?)?;
        if rest != r.bytes.len() - r.at {
            return None;
        }
        let previous = (0..count).map(|_| r.f32()).collect::<Option<Vec<f32>>>()?;
        let mut running = RunningEstimate::new(values);
        running.steps = steps;
        running.updates = updates;
        for array in running.arrays_mut() {
            for v in array.iter_mut() {
                *v = r.f64()?;
            }
        }
        (r.at == r.bytes.len()).then_some((running, layout, previous))
    })();
    let Some((running, layout, values)) = parsed else {
        bail!("{}: not a pathgrad {what} state of version {VERSION}, or truncated", context());
    };
    if running.steps != iteration {
        bail!(
            "{}: it holds the estimate after {} iterations but state.json is after {iteration} (the run was \
             stopped between writing the two); the estimate cannot be recovered, start the run again",
            context(),
            running.steps
        );
    }
    let mut previous = table.clone();
    let mut at = 0;
    for &id in ids {
        let len = previous.get(id).len();
        let Some(v) = values.get(at..at + len) else { bail!("{}: too few previous parameter values", context()) };
        let name = previous.entry(id).name.clone();
        previous.set(&name, v).with_context(|| format!("{}: previous value of {name}", context()))?;
        at += len;
    }
    if at != values.len() {
        bail!("{}: {} previous parameter values for {at} optimised values", context(), values.len());
    }
    Ok((running, layout, previous))
}

struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn take(&mut self, n: usize) -> Option<&[u8]> {
        let s = self.bytes.get(self.at..self.at + n)?;
        self.at += n;
        Some(s)
    }
    fn u32(&mut self) -> Option<u32> {
        Some(u32::from_le_bytes(self.take(4)?.try_into().ok()?))
    }
    fn u64(&mut self) -> Option<u64> {
        Some(u64::from_le_bytes(self.take(8)?.try_into().ok()?))
    }
    fn f32(&mut self) -> Option<f32> {
        Some(f32::from_le_bytes(self.take(4)?.try_into().ok()?))
    }
    fn f64(&mut self) -> Option<f64> {
        Some(f64::from_le_bytes(self.take(8)?.try_into().ok()?))
    }
}

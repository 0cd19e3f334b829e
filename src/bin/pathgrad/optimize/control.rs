//! `--control-variates`' state between sessions: `DIR/control_variates.bin`, written before `state.json` after every iteration and read back by `--resume`.
//!
//! Layout, little-endian: the magic `PGCV`, a u32 version, the u64 step and update counts, the
//! u32 width, height and views, the u32 count of optimised values followed by their previous
//! values (f32, in `--param` order: the parameters H is rendered at), then the eight f64 arrays of
//! [`ControlVariateState::arrays`]. The values are stored exactly, so a resumed run continues bit
//! for bit.

use std::fs;
use std::path::Path;

use anyhow::{Context as _, Result, bail};
use pathgrad::optim::{ControlVariateState, ControlVariates, Optimization};
use pathgrad::output::write_bytes_atomically;
use pathgrad::params::{ParamId, ParamTable};

/// The state file's name in the run directory.
pub(super) const FILE: &str = "control_variates.bin";
const MAGIC: &[u8; 4] = b"PGCV";
const VERSION: u32 = 1;

/// Writes `run`'s control-variate state to `dir` (nothing before the first iteration or without
/// control variates).
pub(super) fn write(dir: &Path, run: &Optimization, ids: &[ParamId]) -> Result<()> {
    let ControlVariates { state: Some(state), previous: Some(previous) } = run.control_variates() else {
        return Ok(());
    };
    let mut bytes = Vec::new();
    bytes.extend_from_slice(MAGIC);
    bytes.extend_from_slice(&VERSION.to_le_bytes());
    bytes.extend_from_slice(&state.steps.to_le_bytes());
    bytes.extend_from_slice(&state.updates.to_le_bytes());
    for v in [state.width, state.height, state.views] {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    let values: Vec<f32> = ids.iter().flat_map(|&id| previous.get(id).iter().copied()).collect();
    bytes.extend_from_slice(&(values.len() as u32).to_le_bytes());
    for v in values {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    for array in state.arrays() {
        for v in array {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
    }
    Ok(write_bytes_atomically(dir.join(FILE), &bytes)?)
}

/// `run` continuing from the control-variate state in `dir`, where the run stopped after
/// `iteration` iterations at parameters `table` (whose layout the previous values take).
pub(super) fn read(dir: &Path, run: Optimization, table: &ParamTable, ids: &[ParamId]) -> Result<Optimization> {
    let iteration = run.iteration();
    let path = dir.join(FILE);
    if iteration == 0 {
        return Ok(run);
    }
    let context = || format!("--resume {}: reading {}", dir.display(), path.display());
    let bytes = fs::read(&path)
        .with_context(|| format!("{}: a run with --control-variates keeps its running estimate there", context()))?;
    let mut r = Reader { bytes: &bytes, at: 0 };
    let parsed = (|| -> Option<(ControlVariateState, Vec<f32>)> {
        if r.take(4)? != MAGIC || r.u32()? != VERSION {
            return None;
        }
        let (steps, updates) = (r.u64()?, r.u64()?);
        let (width, height, views) = (r.u32()?, r.u32()?, r.u32()?);
        let count = r.u32()? as usize;
        // Refuse sizes the file cannot hold before allocating them.
        let values = (width as usize).checked_mul(height as usize)?.checked_mul(3)?.checked_mul(views as usize)?;
        let rest = count.checked_mul(4)?.checked_add(values.checked_mul(8 * 8)?)?;
        if rest != r.bytes.len() - r.at {
            return None;
        }
        let previous = (0..count).map(|_| r.f32()).collect::<Option<Vec<f32>>>()?;
        let mut state = ControlVariateState::new(width, height, views);
        state.steps = steps;
        state.updates = updates;
        for array in state.arrays_mut() {
            for v in array.iter_mut() {
                *v = r.f64()?;
            }
        }
        (r.at == r.bytes.len()).then_some((state, previous))
    })();
    let Some((state, values)) = parsed else {
        bail!("{}: not a pathgrad control-variate state of version {VERSION}, or truncated", context());
    };
    if state.steps != iteration {
        bail!(
            "{}: it holds the estimate after {} iterations but state.json is after {iteration} (the run was \
             stopped between writing the two); the estimate cannot be recovered, start the run again",
            context(),
            state.steps
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
    run.with_control_variates(ControlVariates { state: Some(state), previous: Some(previous) }).with_context(context)
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

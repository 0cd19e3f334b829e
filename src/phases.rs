//! Where the seconds and bytes of preparing a scene go: a [`PhaseReport`] of named phases (parse,
//! assemble, flatten, BVH build, upload, …), each with its wall seconds and the process's memory
//! at its end.
//!
//! The library fills reports ([`crate::scene::load_reporting`], [`crate::gpu::Renderer::report`],
//! [`crate::cpu::Reference::report`]) and logs each phase as a `tracing` event at `info` level (the CLI's `-v`)
//! (target `pathgrad::phases`); it never prints. Memory is read from `/proc/self/status`
//! (`VmRSS`, `VmHWM`), so it is known on Linux only; elsewhere [`Memory::now`] is `None` and a
//! phase reports seconds alone.

use std::time::Instant;

/// The process's resident memory at one moment (Linux: `/proc/self/status`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Memory {
    /// Resident set size now (`VmRSS`), in bytes.
    pub rss_bytes: u64,
    /// The largest resident set size so far in this process (`VmHWM`, the high-water mark), in
    /// bytes.
    pub peak_rss_bytes: u64,
}

impl Memory {
    /// The process's memory now; `None` where `/proc/self/status` cannot be read or lacks the two
    /// fields (any system but Linux).
    pub fn now() -> Option<Memory> {
        let status = std::fs::read_to_string("/proc/self/status").ok()?;
        Memory::parse(&status)
    }

    /// Reads `VmRSS` and `VmHWM` (in kB) from the text of `/proc/self/status`.
    fn parse(status: &str) -> Option<Memory> {
        let field = |name: &str| -> Option<u64> {
            let line = status.lines().find_map(|l| l.strip_prefix(name))?;
            let kb: u64 = line.trim().strip_suffix("kB")?.trim().parse().ok()?;
            Some(kb * 1024)
        };
        Some(Memory { rss_bytes: field("VmRSS:")?, peak_rss_bytes: field("VmHWM:")? })
    }
}

/// One phase: its name, wall seconds, and the memory at its end.
#[derive(Clone, Debug, PartialEq)]
pub struct Phase {
    /// What ran: `parse`, `assemble`, `flatten`, `bvh`, `upload`, … (the function filling the
    /// report documents its names).
    pub name: &'static str,
    /// Wall-clock seconds.
    pub seconds: f64,
    /// The process's memory when the phase ended; `None` where it cannot be read.
    pub memory: Option<Memory>,
}

/// Phases in the order they ran.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PhaseReport {
    phases: Vec<Phase>,
}

impl PhaseReport {
    /// An empty report.
    pub fn new() -> PhaseReport {
        PhaseReport::default()
    }

    /// Records phase `name`, begun at `start` and ending now, with the memory now, and logs it.
    pub fn record(&mut self, name: &'static str, start: Instant) {
        self.push(Phase { name, seconds: start.elapsed().as_secs_f64(), memory: Memory::now() });
    }

    /// Appends `phase` and logs it.
    pub fn push(&mut self, phase: Phase) {
        let (rss, peak) = phase.memory.map_or((None, None), |m| (Some(m.rss_bytes), Some(m.peak_rss_bytes)));
        tracing::info!(
            target: "pathgrad::phases",
            phase = phase.name,
            seconds = phase.seconds,
            rss_bytes = rss,
            peak_rss_bytes = peak,
            "phase done"
        );
        self.phases.push(phase);
    }

    /// Appends the phases of `other`, in order (they were logged when first recorded).
    pub fn extend(&mut self, other: &PhaseReport) {
        self.phases.extend(other.phases.iter().cloned());
    }

    /// The phases in the order they ran.
    pub fn phases(&self) -> &[Phase] {
        &self.phases
    }

    /// The seconds of the phases named `name` (summed if it ran more than once); `None` if none
    /// ran.
    pub fn seconds(&self, name: &str) -> Option<f64> {
        let mut found = self.phases.iter().filter(|p| p.name == name).peekable();
        found.peek()?;
        Some(found.map(|p| p.seconds).sum())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_proc_status() {
        let status = "Name:\tpathgrad\nVmPeak:\t  900 kB\nVmHWM:\t    2048 kB\nVmRSS:\t    1024 kB\n";
        assert_eq!(Memory::parse(status), Some(Memory { rss_bytes: 1024 * 1024, peak_rss_bytes: 2048 * 1024 }));
        assert_eq!(Memory::parse("Name:\tx\nVmRSS:\t1 kB\n"), None);
        assert_eq!(Memory::parse("VmHWM:\tmany kB\nVmRSS:\t1 kB\n"), None);
    }

    #[test]
    fn records_in_order_and_sums_repeats() {
        let mut report = PhaseReport::new();
        let start = Instant::now();
        report.record("parse", start);
        report.push(Phase { name: "bvh", seconds: 0.5, memory: None });
        report.push(Phase { name: "parse", seconds: 0.25, memory: None });
        let names: Vec<_> = report.phases().iter().map(|p| p.name).collect();
        assert_eq!(names, ["parse", "bvh", "parse"]);
        assert!(report.seconds("parse").unwrap() >= 0.25);
        assert_eq!(report.seconds("upload"), None);
        if cfg!(target_os = "linux") {
            let m = report.phases()[0].memory.expect("Linux has /proc/self/status");
            assert!(m.peak_rss_bytes >= m.rss_bytes && m.rss_bytes > 0);
        }
    }
}

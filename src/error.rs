//! The crate's error type: every failure carries the context a user needs to act on it.

use std::path::PathBuf;

use ash::vk;

/// `Result` with [`Error`] as the default error type.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Everything that can go wrong in pathgrad.
///
/// Scene problems name the file (and line where there is one), device problems the Vulkan call,
/// I/O problems the path. The library never panics on bad input; it returns one of these.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The Vulkan loader or an ICD could not be found at all.
    #[error("no Vulkan device found ({reason}) — install mesa-vulkan-drivers (lavapipe) or a GPU driver")]
    NoDevice {
        /// What the loader or the device enumeration said.
        reason: String,
    },
    /// The chosen device lacks a feature pathgrad needs.
    #[error("Vulkan device '{device}' lacks {feature}; pathgrad needs it ({hint})")]
    MissingFeature {
        /// Device name as reported by the driver.
        device: String,
        /// The feature or extension that is missing.
        feature: String,
        /// What to do about it.
        hint: String,
    },
    /// A borrowed device (`Context::from_raw`) was created without extensions or features pathgrad needs.
    #[error(
        "the Vulkan device '{device}' handed to pathgrad was created without {}; enable everything \
         Context::requirements() lists when creating it",
        missing.join(", ")
    )]
    NotEnabled {
        /// Device name as reported by the driver.
        device: String,
        /// The Vulkan name of each missing extension or feature.
        missing: Vec<String>,
    },
    /// A `DeviceChoice` (or `PATHGRAD_DEVICE`) named a device that does not exist.
    #[error("no Vulkan device matches '{selector}' (available: {available})")]
    DeviceNotFound {
        /// The index or UUID the user gave.
        selector: String,
        /// A summary of the devices that exist.
        available: String,
    },
    /// A Vulkan call failed.
    #[error("{call} failed: {result}")]
    Vulkan {
        /// The name of the Vulkan call, e.g. `vkCreateBuffer`.
        call: &'static str,
        /// The result code.
        result: vk::Result,
    },
    /// A device memory allocation failed.
    #[error("allocating '{name}' ({size} bytes) failed: {message}")]
    Allocation {
        /// The allocation's name.
        name: String,
        /// Requested size in bytes.
        size: u64,
        /// gpu-allocator's message.
        message: String,
    },
    /// The GPU did not finish in time (lavapipe has no watchdog, so waits are bounded).
    #[error("GPU work did not finish within {seconds} s ({what})")]
    Timeout {
        /// What was being waited for.
        what: String,
        /// The timeout in seconds.
        seconds: u64,
    },
    /// A kernel exhausted lavapipe's per-invocation loop budget, so its result would be truncated.
    #[error(
        "{kernel}: an invocation ran out of the driver's loop-iteration budget (llvmpipe truncates \
         loops silently at ~65 535 iterations); the result would be wrong, so it was discarded — \
         lower RenderOptions::max_depth or simplify the scene"
    )]
    LoopBudget {
        /// The kernel that hit the limit.
        kernel: &'static str,
    },
    /// A kernel detected a numerical failure (replay drift, fixed-point overflow).
    #[error("{kernel}: {message}")]
    Numeric {
        /// The kernel that detected it.
        kernel: &'static str,
        /// What happened.
        message: String,
    },
    /// An optimisation step met a NaN or infinite gradient value of an optimised parameter; the
    /// step was not taken, so the parameters and the optimiser's state are as before it.
    #[error(
        "iteration {iteration}: the gradient of {parameter}[{index}] is {value}; the step was not taken \
         (parameters and Adam state unchanged)"
    )]
    NonFiniteGradient {
        /// The optimisation iteration (0-based; its seed is the base seed + this).
        iteration: u64,
        /// The parameter's name.
        parameter: String,
        /// The index of the value within the parameter (0 for scalars, the channel for RGB).
        index: u32,
        /// The offending value.
        value: f32,
    },
    /// A scene is invalid.
    #[error("{location}: {message}")]
    Scene {
        /// `file:line:col`, or `builtin:NAME`, or the parameter at fault.
        location: String,
        /// What is wrong.
        message: String,
    },
    /// An option or argument is out of range.
    #[error("invalid {parameter}: {message}")]
    InvalidArgument {
        /// The option or parameter name, e.g. `--spp`.
        parameter: String,
        /// What is wrong with it.
        message: String,
    },
    /// Reading or writing a file failed.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// An output path cannot be written under the rules of [`crate::output`].
    #[error("{}: {message}", path.display())]
    Output {
        /// The destination as given.
        path: PathBuf,
        /// What is wrong with it.
        message: String,
    },
    /// Encoding or decoding an image failed.
    #[error("{}: {message}", path.display())]
    Image {
        /// The image file.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
}

/// Attaches the name of the Vulkan call to a raw `vk::Result`.
pub(crate) trait VkResultExt<T> {
    /// Converts the error into [`Error::Vulkan`] naming `call`.
    fn vk(self, call: &'static str) -> Result<T>;
}

impl<T> VkResultExt<T> for std::result::Result<T, vk::Result> {
    fn vk(self, call: &'static str) -> Result<T> {
        self.map_err(|result| Error::Vulkan { call, result })
    }
}

#[cfg(test)]
mod tests {
    /// Library messages speak of library names (`RenderOptions::spp`), never of the CLI's flags
    /// (`--spp`): no string literal in the library's sources outside `src/bin/` spells a flag.
    /// Test modules and comments are skipped.
    #[test]
    fn library_messages_name_no_cli_flag() {
        let src = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
        let mut stack = vec![src.clone()];
        let mut offences = Vec::new();
        let mut scanned = 0;
        while let Some(dir) = stack.pop() {
            for entry in std::fs::read_dir(&dir).unwrap() {
                let path = entry.unwrap().path();
                let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
                if path.is_dir() {
                    if path != src.join("bin") {
                        stack.push(path);
                    }
                    continue;
                }
                if !name.ends_with(".rs") || name.contains("tests") || name.ends_with("fixtures.rs") {
                    continue;
                }
                scanned += 1;
                let text = std::fs::read_to_string(&path).unwrap();
                let code = text.split("#[cfg(test)]").next().unwrap_or("");
                for (i, line) in code.lines().enumerate() {
                    let line = line.trim_start();
                    if line.starts_with("//") {
                        continue;
                    }
                    // The odd pieces of a line split at quotes are inside string literals.
                    let flag = line.split('"').skip(1).step_by(2).find_map(|s| {
                        s.match_indices("--").find(|(at, _)| s[at + 2..].starts_with(|c: char| c.is_ascii_lowercase()))
                    });
                    if flag.is_some() {
                        offences.push(format!("{}:{}: {line}", path.display(), i + 1));
                    }
                }
            }
        }
        assert!(scanned > 40, "scanned only {scanned} files");
        assert!(offences.is_empty(), "CLI flags in library messages:\n{}", offences.join("\n"));
    }
}

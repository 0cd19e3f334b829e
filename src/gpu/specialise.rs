//! Kernels specialised on the host: a kernel's `FEATURES` value is applied to its SPIR-V and what
//! the value switches off is optimised away (Debian's SPIRV-Tools, `native/specialise.cpp`) before
//! the driver sees the module, and the result is kept in a disk cache.
//!
//! The driver could apply the specialisation constant itself, but lavapipe first parses and
//! optimises the whole module — every feature's code, ~20 000 instructions for the adjoint kernel
//! — which took ~0.6 s per pipeline even with a warm shader cache. A specialised module (~4 300
//! instructions) is created in ~0.1 s (BENCHMARKS.md). Specialising takes ~0.4 s, once per
//! variant and build on a machine; the cache keeps it from the processes after. The optimizer
//! reorders no floating-point arithmetic, so images are bitwise the same either way (a test renders
//! both). `PATHGRAD_SPECIALISE=0` leaves the specialisation to the driver. The cache holds at
//! most 64 MB; past that the entries used longest ago are removed.

use crate::contract::{SPEC_FEATURES, SPEC_FEATURES2};
use std::path::{Path, PathBuf};
use std::time::{Instant, SystemTime};

unsafe extern "C" {
    fn pathgrad_specialise_spirv(
        words: *const u32,
        count: usize,
        spec_ids: *const u32,
        values: *const u32,
        n: usize,
        out: *mut *mut u32,
        out_count: *mut usize,
    ) -> std::ffi::c_int;
    fn pathgrad_free_spirv(words: *mut u32);
    fn pathgrad_spirv_tools_version() -> *const std::ffi::c_char;
}

/// SPIR-V's magic number, the first word of every module.
const SPIRV_MAGIC: u32 = 0x0723_0203;

/// Whether kernels are specialised on the host (`PATHGRAD_SPECIALISE=0` turns it off).
pub fn enabled() -> bool {
    std::env::var("PATHGRAD_SPECIALISE").map_or(true, |v| v != "0")
}

/// `words` with its feature words set to `features` (the low 32 bits are `FEATURES`, the high 32
/// `FEATURES2`: [`crate::gpu::variant`]), frozen, and the module optimised and stripped of debug
/// information; `None` if the optimizer refuses the module.
pub fn specialise(words: &[u32], features: u64) -> Option<Vec<u32>> {
    let ids = [SPEC_FEATURES, SPEC_FEATURES2];
    let values = [features as u32, (features >> 32) as u32];
    let mut out: *mut u32 = std::ptr::null_mut();
    let mut count = 0usize;
    // SAFETY: `words` is valid for `words.len()` reads; on success the shim hands over a malloc'd
    // array of `count` words, copied here and freed by its own `free`.
    unsafe {
        let status = pathgrad_specialise_spirv(
            words.as_ptr(),
            words.len(),
            ids.as_ptr(),
            values.as_ptr(),
            ids.len(),
            &mut out,
            &mut count,
        );
        if status != 0 || out.is_null() {
            return None;
        }
        let result = std::slice::from_raw_parts(out, count).to_vec();
        pathgrad_free_spirv(out);
        (result.first() == Some(&SPIRV_MAGIC)).then_some(result)
    }
}

/// pathgrad's cache folder: `$XDG_CACHE_HOME/pathgrad`, else `$HOME/.cache/pathgrad` (a relative
/// value is ignored, as the XDG specification asks).
pub(crate) fn pathgrad_cache() -> Option<PathBuf> {
    let absolute = |v: &std::ffi::OsString| Path::new(v).is_absolute();
    let base = std::env::var_os("XDG_CACHE_HOME")
        .filter(absolute)
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").filter(absolute).map(|h| PathBuf::from(h).join(".cache")))?;
    Some(base.join("pathgrad"))
}

/// The directory of specialised modules: `kernels` in [`pathgrad_cache`].
fn cache_dir() -> Option<PathBuf> {
    Some(pathgrad_cache()?.join("kernels"))
}

/// The most the kernel cache keeps, in bytes (a specialised module is ~100 KB): entries of older
/// builds are never read again, so past this the entries used longest ago are removed.
const CACHE_LIMIT_BYTES: u64 = 64 << 20;

/// Removes the files of `dir` that were used (read or written) longest ago until the rest fit in
/// `limit` bytes. Best effort: a file that cannot be read or removed is left.
fn prune(dir: &Path, limit: u64) {
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    let mut files: Vec<(SystemTime, u64, PathBuf)> = entries
        .flatten()
        .filter_map(|e| {
            let meta = e.metadata().ok().filter(|m| m.is_file())?;
            Some((meta.modified().ok()?, meta.len(), e.path()))
        })
        .collect();
    let mut total: u64 = files.iter().map(|f| f.1).sum();
    if total <= limit {
        return;
    }
    files.sort();
    for (_, len, path) in files {
        if total <= limit {
            break;
        }
        if std::fs::remove_file(&path).is_ok() {
            total -= len;
            tracing::debug!(file = %path.display(), "old specialised kernel removed from the cache");
        }
    }
}

/// 64-bit FNV-1a.
fn fnv(parts: &[&[u8]]) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    for part in parts {
        for &b in *part {
            h = (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
    h
}

/// What made a cached module besides its input: the specialiser's source (its pass list) and the
/// SPIRV-Tools it was linked with.
fn specialiser_identity() -> Vec<u8> {
    // SAFETY: the shim returns SPIRV-Tools' static, NUL-terminated version string.
    let tools = unsafe { std::ffi::CStr::from_ptr(pathgrad_spirv_tools_version()) };
    [include_bytes!("../../native/specialise.cpp").as_slice(), tools.to_bytes()].concat()
}

/// The cache key: a hash of the module, the features and the specialiser (content-addressed, so a
/// new build's modules or pass list never meet an old build's entries).
fn key(words: &[u32], features: u64) -> u64 {
    fnv(&[bytemuck::cast_slice(words), &features.to_le_bytes(), &specialiser_identity()])
}

/// A cache file's bytes: the module, then the hash of its bytes (a damaged file is not used).
fn cache_bytes(words: &[u32]) -> Vec<u8> {
    let mut bytes = bytemuck::cast_slice::<u32, u8>(words).to_vec();
    let sum = fnv(&[&bytes]);
    bytes.extend_from_slice(&sum.to_le_bytes());
    bytes
}

/// The module in a cache file's bytes, if they are whole.
fn from_cache_bytes(bytes: &[u8]) -> Option<Vec<u32>> {
    let (module, sum) = bytes.split_at_checked(bytes.len().checked_sub(8)?)?;
    if module.len() < 20 || module.len() % 4 != 0 || fnv(&[module]).to_le_bytes() != *sum {
        return None;
    }
    let words: Vec<u32> = module.chunks_exact(4).map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect();
    (words[0] == SPIRV_MAGIC).then_some(words)
}

/// `words` specialised to `features` (see [`specialise`]), from the disk cache when it has them;
/// `None` when host specialisation is off or fails (the driver then specialises).
pub fn specialised_module(name: &str, words: &[u32], features: u64) -> Option<Vec<u32>> {
    if !enabled() {
        return None;
    }
    let file = cache_dir().map(|d| d.join(format!("{name}-{features:016x}-{:016x}.spv", key(words, features))));
    if let Some((file, words)) = file.as_ref().and_then(|f| Some((f, from_cache_bytes(&std::fs::read(f).ok()?)?))) {
        // A use keeps an entry young: pruning removes the entries used longest ago.
        let _ = std::fs::File::options().write(true).open(file).and_then(|f| f.set_modified(SystemTime::now()));
        tracing::debug!(kernel = name, "specialised kernel loaded from the cache");
        return Some(words);
    }
    let start = Instant::now();
    let Some(result) = specialise(words, features) else {
        tracing::warn!(kernel = name, "the SPIR-V optimizer refused the kernel; the driver specialises it");
        return None;
    };
    tracing::debug!(
        kernel = name,
        words = words.len(),
        specialised_words = result.len(),
        seconds = start.elapsed().as_secs_f64(),
        "kernel specialised on the host"
    );
    if let Some(file) = file {
        // Written under a unique name and renamed, so a concurrent reader never sees half a module;
        // a cache that cannot be written only costs the next process this work again.
        let tmp = file.with_extension(format!("tmp{}-{:?}", std::process::id(), std::thread::current().id()));
        let written = file.parent().map(std::fs::create_dir_all).transpose().and_then(|_| {
            std::fs::write(&tmp, cache_bytes(&result))?;
            std::fs::rename(&tmp, &file)
        });
        if let Err(e) = written {
            let _ = std::fs::remove_file(&tmp);
            tracing::debug!(kernel = name, error = %e, "specialised kernel not cached");
        }
        if let Some(dir) = file.parent() {
            prune(dir, CACHE_LIMIT_BYTES);
        }
    }
    Some(result)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn adjoint_words() -> Vec<u32> {
        let bytes = crate::gpu::shaders::spirv("adjoint").expect("the adjoint kernel is embedded");
        ash::util::read_spv(&mut std::io::Cursor::new(bytes)).unwrap()
    }

    /// Specialising drops what a value switches off: the module shrinks, more for fewer features,
    /// and the same value gives the same words.
    #[test]
    fn specialising_shrinks_the_module_and_is_deterministic() {
        use crate::contract::*;
        let words = adjoint_words();
        let few = u64::from(F_NEE | F_EMITTERS | F_DIFFUSE | G_COLOR);
        let a = specialise(&words, few).expect("specialised");
        let b = specialise(&words, few).expect("specialised");
        let all = specialise(&words, u64::MAX).expect("specialised");
        assert_eq!(a, b);
        assert_eq!(a[0], SPIRV_MAGIC);
        assert!(a.len() * 3 < words.len(), "{} of {} words", a.len(), words.len());
        assert!(a.len() < all.len(), "{} vs {} words", a.len(), all.len());
    }

    /// The second feature word reaches the module too: the hero strategy (a bit of `FEATURES2`)
    /// switched off leaves a smaller module than switched on, all else equal.
    #[test]
    fn the_second_feature_word_is_specialised() {
        use crate::contract::*;
        use crate::gpu::variant::word2;
        let words = adjoint_words();
        let diff = u64::from(F_NEE | F_EMITTERS | F_CONDUCTOR | F_GGX | F_DIFF | G_ALPHA);
        let without = specialise(&words, diff).expect("specialised");
        let with = specialise(&words, diff | word2(F2_HERO)).expect("specialised");
        assert!(without.len() < with.len(), "{} vs {} words", without.len(), with.len());
    }

    #[test]
    fn a_broken_module_is_refused() {
        assert_eq!(specialise(&[SPIRV_MAGIC, 0x0001_0500, 0, 7], 1), None);
        assert_eq!(specialise(&[1, 2, 3], 1), None);
    }

    /// A cache file reads back as its module; a cut or altered one is refused.
    #[test]
    fn damaged_cache_files_are_refused() {
        let words: Vec<u32> = vec![SPIRV_MAGIC, 0x0001_0500, 0, 9, 0, 42];
        let bytes = cache_bytes(&words);
        assert_eq!(from_cache_bytes(&bytes), Some(words));
        assert_eq!(from_cache_bytes(&bytes[..bytes.len() - 4]), None);
        let mut altered = bytes.clone();
        altered[10] ^= 1;
        assert_eq!(from_cache_bytes(&altered), None);
        assert_eq!(from_cache_bytes(&[]), None);
    }

    /// Past the limit, the entries used longest ago go first, and only as many as needed.
    #[test]
    fn pruning_removes_the_least_recently_used_entries() {
        let dir = tempfile::tempdir().unwrap();
        let now = SystemTime::now();
        for (i, age) in [30u64, 10, 20, 0].into_iter().enumerate() {
            let path = dir.path().join(format!("k{i}.spv"));
            std::fs::write(&path, vec![0u8; 1000]).unwrap();
            let f = std::fs::File::options().write(true).open(&path).unwrap();
            f.set_modified(now - std::time::Duration::from_secs(age * 60)).unwrap();
        }
        prune(dir.path(), 4000);
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 4, "within the limit nothing goes");
        prune(dir.path(), 2500);
        let mut left: Vec<String> =
            std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name().into_string().unwrap()).collect();
        left.sort();
        assert_eq!(left, ["k1.spv", "k3.spv"], "the two used longest ago (30 and 20 minutes) are removed");
    }

    #[test]
    fn the_key_depends_on_the_module_and_the_value() {
        let words = [SPIRV_MAGIC, 1, 2, 3];
        assert_ne!(key(&words, 1), key(&words, 2));
        assert_ne!(key(&words, 1), key(&words, 1 | crate::gpu::variant::word2(1)), "the second word counts");
        assert_ne!(key(&words, 1), key(&[SPIRV_MAGIC, 1, 2, 4], 1));
        assert_eq!(key(&words, 1), key(&words, 1));
    }
}

//! Output files: what a destination may be, atomic replacement, all-or-nothing sets, stale temporaries.
//!
//! Every file pathgrad writes goes through [`write_atomically`], with these semantics:
//! - The data goes to a hidden temporary file beside the destination, named
//!   `.NAME.PID-N.tmp`, which is synced and then renamed over the destination, so a reader never
//!   sees a half-written file and a failed write leaves the previous file as it was.
//! - A destination that is a **symbolic link is followed**: the file it points to is replaced
//!   (in that file's directory) and the link stays a link.
//! - A destination that exists must be a regular file and writable: a **read-only file is
//!   refused**, not silently replaced; so are directories, devices (`/dev/null`) and pipes.
//! - A process killed mid-write (`kill -9`) leaves its temporary file behind. The next write of
//!   the same destination removes such leftovers of our own naming whose process is gone (on
//!   Linux, where `/proc` tells); nothing else in the directory is touched. A program that knows
//!   no other process writes certain files (it holds a lock) removes all their temporaries with
//!   [`remove_temporaries`].
//!
//! [`check_destination`] applies the same rules without writing, so that a command can refuse a
//! bad output path before it spends minutes rendering. [`OutputSet`] stages several files and
//! puts them in place together: a command that fails half-way leaves nothing new behind. A staged
//! file is itself a temporary: a write to it goes straight to it, with no temporary of its own
//! (which a kill would leave under a name no later write of the destination recognises).

use std::collections::BTreeSet;
use std::ffi::{OsStr, OsString};
use std::fs::{self, File, OpenOptions};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};

use crate::error::{Error, Result};

/// How many symbolic links are followed before a destination is called a loop (Linux's limit).
const MAX_SYMLINK_HOPS: usize = 40;

/// Distinguishes temporary files of concurrent writes from one process.
static TEMP_COUNTER: AtomicU64 = AtomicU64::new(0);

/// The temporary files that [`OutputSet`]s of this process staged and have not yet renamed or
/// removed. [`write_atomically`] writes one of them directly: the set's commit is its rename.
static STAGED: Mutex<BTreeSet<PathBuf>> = Mutex::new(BTreeSet::new());

/// The staged temporaries, whatever a panicking thread left (the set stays valid).
fn staged_temporaries() -> std::sync::MutexGuard<'static, BTreeSet<PathBuf>> {
    STAGED.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

fn output_error(path: &Path, message: impl Into<String>) -> Error {
    Error::Output { path: path.to_path_buf(), message: message.into() }
}

/// The file a write to `path` replaces: `path` itself, or what its chain of symbolic links points
/// to (which need not exist yet).
///
/// # Errors
/// [`Error::Output`] if `path` has no file name or the links loop; [`Error::Io`] if a link cannot
/// be read.
pub fn resolve_destination(path: &Path) -> Result<PathBuf> {
    let mut current = path.to_path_buf();
    for _ in 0..MAX_SYMLINK_HOPS {
        match fs::symlink_metadata(&current) {
            Ok(meta) if meta.file_type().is_symlink() => {
                let target = fs::read_link(&current).map_err(|source| Error::Io { path: current.clone(), source })?;
                current = match current.parent() {
                    Some(parent) if target.is_relative() => parent.join(target),
                    _ => target,
                };
            }
            _ => {
                if current.file_name().is_none() {
                    return Err(output_error(path, "not a file path"));
                }
                return Ok(current);
            }
        }
    }
    Err(output_error(path, format!("more than {MAX_SYMLINK_HOPS} symbolic links (a loop?)")))
}

/// The directory a file at `path` lives in (`.` for a bare file name).
fn directory_of(path: &Path) -> &Path {
    match path.parent() {
        Some(parent) if !parent.as_os_str().is_empty() => parent,
        _ => Path::new("."),
    }
}

/// Checks that a file could be written at `path` under this module's rules, without writing it:
/// its directory exists and takes new files, and an existing destination (after following
/// symbolic links) is a writable regular file. Returns the resolved destination.
///
/// # Errors
/// [`Error::Output`] naming `path` and what is wrong with it.
///
/// # Example
///
/// ```
/// use pathgrad::output::check_destination;
///
/// let dir = std::env::temp_dir();
/// assert!(check_destination(&dir.join("pathgrad-doc-check.exr")).is_ok());
/// let err = check_destination(&dir).unwrap_err();
/// assert!(err.to_string().contains("is a directory"), "{err}");
/// ```
pub fn check_destination(path: &Path) -> Result<PathBuf> {
    let target = check_existing(path)?;
    // Whether the directory takes new files is only known by trying.
    let probe = temp_path(&target)?;
    match OpenOptions::new().write(true).create_new(true).open(&probe) {
        Ok(file) => {
            drop(file);
            let _ = fs::remove_file(&probe);
        }
        Err(e) => {
            return Err(output_error(
                path,
                format!("cannot create files in {} ({e})", directory_of(&target).display()),
            ));
        }
    }
    Ok(target)
}

/// [`check_destination`] without the probe: the resolved destination, once its directory exists
/// and an existing destination is a writable regular file. A writer that creates its temporary
/// file next learns the rest from that.
fn check_existing(path: &Path) -> Result<PathBuf> {
    let target = resolve_destination(path)?;
    let dir = directory_of(&target);
    match fs::metadata(dir) {
        Ok(meta) if meta.is_dir() => {}
        Ok(_) => return Err(output_error(path, format!("{} is not a directory", dir.display()))),
        Err(_) => return Err(output_error(path, format!("the directory {} does not exist", dir.display()))),
    }
    match fs::metadata(&target) {
        Ok(meta) if meta.is_dir() => return Err(output_error(path, "is a directory")),
        Ok(meta) if !meta.is_file() => {
            return Err(output_error(path, "is not a regular file (a device or pipe); give a file path"));
        }
        Ok(meta) if meta.permissions().readonly() => {
            return Err(output_error(
                path,
                "is read-only; pathgrad does not replace read-only files (make it writable or remove it)",
            ));
        }
        _ => {}
    }
    Ok(target)
}

/// A fresh temporary name beside `target`: `.NAME.PID-N.tmp`.
fn temp_path(target: &Path) -> Result<PathBuf> {
    let Some(file_name) = target.file_name() else {
        return Err(output_error(target, "not a file path"));
    };
    let mut name = OsString::from(".");
    name.push(file_name);
    name.push(format!(".{}-{}.tmp", std::process::id(), TEMP_COUNTER.fetch_add(1, Ordering::Relaxed)));
    Ok(directory_of(target).join(name))
}

/// The process id in `entry` if it is one of our temporary names for `file_name`.
fn temp_owner(entry: &OsStr, file_name: &OsStr) -> Option<u32> {
    let entry = entry.to_str()?;
    let rest = entry.strip_prefix('.')?.strip_prefix(file_name.to_str()?)?.strip_prefix('.')?;
    let (pid, counter) = rest.strip_suffix(".tmp")?.split_once('-')?;
    counter.parse::<u64>().ok()?;
    pid.parse().ok()
}

/// `name` without one layer of our temporary naming: `NAME` for `.NAME.PID-N.tmp`.
fn strip_temp_layer(name: &str) -> Option<&str> {
    let (inner, owner) = name.strip_prefix('.')?.strip_suffix(".tmp")?.rsplit_once('.')?;
    let (pid, counter) = owner.split_once('-')?;
    let digits = |s: &str| !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit());
    (digits(pid) && digits(counter) && !inner.is_empty()).then_some(inner)
}

/// The file name a temporary of ours was made for: `a.exr` for `.a.exr.PID-N.tmp`, and for a
/// temporary of a temporary (`..a.exr.PID-N.tmp.PID-M.tmp`, which earlier builds left when a
/// kill interrupted an image written into an [`OutputSet`]) as well; `None` for any other name.
pub fn temporary_destination(name: &str) -> Option<&str> {
    let mut name = strip_temp_layer(name)?;
    while let Some(inner) = strip_temp_layer(name) {
        name = inner;
    }
    Some(name)
}

/// Removes every temporary file of our naming in `dir` (temporaries of temporaries included)
/// whose destination's file name `mine` accepts, whichever process wrote it; returns the removed
/// paths. Only for a caller that knows no live process writes those destinations (it holds
/// their lock): a temporary in use would be pulled from under its writer.
///
/// # Errors
/// [`Error::Io`] naming `dir` if it cannot be listed, or a temporary if it cannot be removed.
pub fn remove_temporaries(dir: &Path, mine: impl Fn(&str) -> bool) -> Result<Vec<PathBuf>> {
    let entries = fs::read_dir(dir).map_err(|source| Error::Io { path: dir.to_path_buf(), source })?;
    let mut removed = Vec::new();
    for entry in entries {
        let entry = entry.map_err(|source| Error::Io { path: dir.to_path_buf(), source })?;
        let name = entry.file_name();
        if !name.to_str().and_then(temporary_destination).is_some_and(&mine) {
            continue;
        }
        match fs::remove_file(entry.path()) {
            Ok(()) => removed.push(entry.path()),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(source) => return Err(Error::Io { path: entry.path(), source }),
        }
    }
    Ok(removed)
}

/// Removes temporary files of our naming for `target` whose process no longer runs. Only where
/// `/proc` says which processes run (Linux); best effort, errors are ignored.
fn remove_stale_temporaries(target: &Path) {
    let (Some(file_name), true) = (target.file_name(), Path::new("/proc/self").exists()) else { return };
    let Ok(entries) = fs::read_dir(directory_of(target)) else { return };
    for entry in entries.flatten() {
        let Some(pid) = temp_owner(&entry.file_name(), file_name) else { continue };
        if pid != std::process::id() && !Path::new("/proc").join(pid.to_string()).exists() {
            tracing::debug!(path = %entry.path().display(), "removing a temporary file a killed write left");
            let _ = fs::remove_file(entry.path());
        }
    }
}

/// Runs `write` on a temporary file beside the destination and renames it over the destination
/// once `write` succeeded and the data is on disk, with the module's rules (symbolic links
/// followed, read-only files refused, stale temporaries removed). On any failure the temporary
/// file is removed and the destination is left as it was.
///
/// # Errors
/// [`Error::Output`] for a destination [`check_destination`] refuses (a directory that takes no new
/// files shows as the next error instead); [`Error::Io`] naming `path` if the file cannot be created,
/// written or renamed; whatever `write` returns.
pub fn write_atomically(path: &Path, write: impl FnOnce(&mut BufWriter<File>) -> Result<()>) -> Result<()> {
    let io_error = |source| Error::Io { path: path.to_path_buf(), source };
    let target = check_existing(path)?;
    if staged_temporaries().contains(&target) {
        // Already a temporary: an OutputSet puts it in place, or removes it if the write fails.
        let file = OpenOptions::new().write(true).create(true).truncate(true).open(&target).map_err(io_error)?;
        let mut out = BufWriter::new(file);
        write(&mut out)?;
        out.flush().map_err(io_error)?;
        let file = out.into_inner().map_err(|e| io_error(e.into_error()))?;
        return file.sync_all().map_err(io_error);
    }
    remove_stale_temporaries(&target);
    let temp = TempFile { path: temp_path(&target)?, kept: false };
    let file = OpenOptions::new().write(true).create_new(true).open(&temp.path).map_err(io_error)?;
    let mut out = BufWriter::new(file);
    write(&mut out)?;
    out.flush().map_err(io_error)?;
    let file = out.into_inner().map_err(|e| io_error(e.into_error()))?;
    file.sync_all().map_err(io_error)?;
    drop(file);
    fs::rename(&temp.path, &target).map_err(io_error)?;
    temp.keep();
    Ok(())
}

/// Writes `bytes` to `path` with [`write_atomically`]: for the text outputs of the command line
/// (CSV, JSON, SVG).
///
/// # Errors
/// As [`write_atomically`].
pub fn write_bytes_atomically(path: impl AsRef<Path>, bytes: &[u8]) -> Result<()> {
    let path = path.as_ref();
    write_atomically(path, |out| out.write_all(bytes).map_err(|source| Error::Io { path: path.to_path_buf(), source }))
}

/// A temporary file that is removed when dropped, unless [`keep`](TempFile::keep) was called.
struct TempFile {
    path: PathBuf,
    kept: bool,
}

impl TempFile {
    /// Leaves the file alone on drop (it has been renamed into place).
    fn keep(mut self) {
        self.kept = true;
    }
}

impl Drop for TempFile {
    fn drop(&mut self) {
        if !self.kept {
            // Best effort: the write has already failed, and that error is the one to report.
            let _ = fs::remove_file(&self.path);
        }
    }
}

/// Several output files put in place together, or none of them.
///
/// [`stage`](OutputSet::stage) checks a destination and returns a temporary path beside it for
/// the caller to write (with any writer of this crate); [`commit`](OutputSet::commit) renames
/// every staged file over its destination. Dropped without a commit, or if a rename fails, the
/// set removes its temporary files and any destination it had already created, so a failed
/// command leaves nothing new behind. (A destination that existed before and was already
/// replaced when a later rename failed keeps its new content: its old content is gone.)
///
/// # Example
///
/// ```
/// use pathgrad::output::OutputSet;
///
/// let dir = std::env::temp_dir().join(format!("pathgrad-doc-outputs-{}", std::process::id()));
/// std::fs::create_dir_all(&dir)?;
/// let mut set = OutputSet::new();
/// let a = set.stage(&dir.join("a.txt"))?;
/// let b = set.stage(&dir.join("b.txt"))?;
/// std::fs::write(&a, "first")?;
/// std::fs::write(&b, "second")?;
/// set.commit()?;
/// assert_eq!(std::fs::read_to_string(dir.join("b.txt"))?, "second");
/// # std::fs::remove_dir_all(&dir)?;
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Debug, Default)]
pub struct OutputSet {
    /// (temporary path, resolved destination, the destination as given, whether it existed).
    staged: Vec<(PathBuf, PathBuf, PathBuf, bool)>,
    /// Destinations created by a commit that then failed part-way.
    created: Vec<PathBuf>,
}

impl OutputSet {
    /// An empty set.
    pub fn new() -> OutputSet {
        OutputSet::default()
    }

    /// Checks `path` ([`check_destination`]) and returns the temporary path to write its content
    /// to. Two stagings of one destination are refused.
    ///
    /// # Errors
    /// Those of [`check_destination`]; [`Error::Output`] if `path` is already staged.
    pub fn stage(&mut self, path: &Path) -> Result<PathBuf> {
        let target = check_destination(path)?;
        if self.staged.iter().any(|(_, t, _, _)| *t == target) {
            return Err(output_error(path, "is written twice by one command"));
        }
        remove_stale_temporaries(&target);
        let temp = temp_path(&target)?;
        let existed = target.exists();
        staged_temporaries().insert(temp.clone());
        self.staged.push((temp.clone(), target, path.to_path_buf(), existed));
        Ok(temp)
    }

    /// The destinations as given to [`stage`](OutputSet::stage), in order.
    pub fn destinations(&self) -> Vec<PathBuf> {
        self.staged.iter().map(|(_, _, given, _)| given.clone()).collect()
    }

    /// Renames every staged file over its destination.
    ///
    /// # Errors
    /// [`Error::Output`] naming a destination whose staged file was never written;
    /// [`Error::Io`] if a rename fails. Either way no new file is left behind.
    pub fn commit(mut self) -> Result<()> {
        for (temp, _, given, _) in &self.staged {
            if !temp.is_file() {
                return Err(output_error(given, "was staged but never written"));
            }
        }
        let staged = std::mem::take(&mut self.staged);
        forget_staged(&staged);
        for (k, (temp, target, given, existed)) in staged.iter().enumerate() {
            if let Err(source) = fs::rename(temp, target) {
                // Put the rest back for the drop to clean up.
                self.staged = staged[k..].to_vec();
                return Err(Error::Io { path: given.clone(), source });
            }
            if !existed {
                self.created.push(target.clone());
            }
        }
        self.created.clear();
        Ok(())
    }
}

/// Takes `staged`'s temporaries out of [`STAGED`]: they are renamed or about to be removed.
fn forget_staged(staged: &[(PathBuf, PathBuf, PathBuf, bool)]) {
    let mut set = staged_temporaries();
    for (temp, _, _, _) in staged {
        set.remove(temp);
    }
}

impl Drop for OutputSet {
    fn drop(&mut self) {
        forget_staged(&self.staged);
        for (temp, _, _, _) in &self.staged {
            let _ = fs::remove_file(temp);
        }
        for created in &self.created {
            let _ = fs::remove_file(created);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> =
            fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().into_string().unwrap()).collect();
        v.sort();
        v
    }

    #[test]
    fn a_symbolic_link_is_followed_and_stays_a_link() {
        let dir = tempfile::tempdir().unwrap();
        let real = dir.path().join("real.txt");
        fs::write(&real, "old").unwrap();
        let link = dir.path().join("link.txt");
        std::os::unix::fs::symlink("real.txt", &link).unwrap();
        write_bytes_atomically(&link, b"new").unwrap();
        assert!(fs::symlink_metadata(&link).unwrap().file_type().is_symlink(), "the link is not replaced");
        assert_eq!(fs::read_to_string(&real).unwrap(), "new");
        // A dangling link creates the file it names.
        let dangling = dir.path().join("dangling.txt");
        std::os::unix::fs::symlink("made.txt", &dangling).unwrap();
        write_bytes_atomically(&dangling, b"made").unwrap();
        assert_eq!(fs::read_to_string(dir.path().join("made.txt")).unwrap(), "made");
        assert_eq!(names(dir.path()), ["dangling.txt", "link.txt", "made.txt", "real.txt"]);
        // A loop is refused with a message.
        let a = dir.path().join("a");
        let b = dir.path().join("b");
        std::os::unix::fs::symlink("b", &a).unwrap();
        std::os::unix::fs::symlink("a", &b).unwrap();
        let err = write_bytes_atomically(&a, b"x").unwrap_err().to_string();
        assert!(err.contains("symbolic links"), "{err}");
    }

    #[test]
    fn read_only_files_directories_and_devices_are_refused() {
        use std::os::unix::fs::PermissionsExt as _;
        let dir = tempfile::tempdir().unwrap();
        let locked = dir.path().join("locked.txt");
        fs::write(&locked, "keep").unwrap();
        fs::set_permissions(&locked, fs::Permissions::from_mode(0o444)).unwrap();
        let err = write_bytes_atomically(&locked, b"new").unwrap_err().to_string();
        assert!(err.contains("locked.txt: is read-only"), "{err}");
        assert_eq!(fs::read_to_string(&locked).unwrap(), "keep");
        let err = write_bytes_atomically(dir.path(), b"x").unwrap_err().to_string();
        assert!(err.contains("is a directory"), "{err}");
        let err = write_bytes_atomically("/dev/null", b"x").unwrap_err().to_string();
        assert!(err.contains("/dev/null: is not a regular file"), "{err}");
        let err = write_bytes_atomically(dir.path().join("nowhere/x.txt"), b"x").unwrap_err().to_string();
        assert!(err.contains("does not exist"), "{err}");
        assert_eq!(names(dir.path()), ["locked.txt"], "no temporary file is left");
    }

    #[test]
    fn temporaries_of_killed_writes_are_removed_and_others_kept() {
        let dir = tempfile::tempdir().unwrap();
        // No process has pid 0x7FFF_FFF0 (above Linux's pid_max); our own pid is alive.
        let stale = dir.path().join(format!(".out.exr.{}-3.tmp", 0x7FFF_FFF0u32));
        let live = dir.path().join(format!(".out.exr.{}-999.tmp", std::process::id()));
        let other = dir.path().join(".other.exr.2147483632-1.tmp");
        let unrelated = dir.path().join(".out.exr.notes.tmp");
        for p in [&stale, &live, &other, &unrelated] {
            fs::write(p, "x").unwrap();
        }
        write_bytes_atomically(dir.path().join("out.exr"), b"data").unwrap();
        let left = names(dir.path());
        assert!(!left.contains(&stale.file_name().unwrap().to_string_lossy().into_owned()), "{left:?}");
        assert_eq!(left.len(), 4, "only the stale temporary of out.exr went: {left:?}");
    }

    /// Issue 36, 3: a writer given a staged path writes that file itself; it makes no temporary
    /// of the temporary (`..a.txt.PID-0.tmp.PID-1.tmp`), which a kill would leave behind under a
    /// name no cleanup of `a.txt` recognises.
    #[test]
    fn issue_36_a_staged_file_gets_no_temporary_of_its_own() {
        let dir = tempfile::tempdir().unwrap();
        let mut set = OutputSet::new();
        let staged = set.stage(&dir.path().join("a.txt")).unwrap();
        let mut during = Vec::new();
        write_atomically(&staged, |out| {
            during = names(dir.path());
            out.write_all(b"a").map_err(|source| Error::Io { path: staged.clone(), source })
        })
        .unwrap();
        assert_eq!(during, [staged.file_name().unwrap().to_str().unwrap()], "while writing");
        set.commit().unwrap();
        assert_eq!(names(dir.path()), ["a.txt"]);
        assert_eq!(fs::read_to_string(dir.path().join("a.txt")).unwrap(), "a");
    }

    #[test]
    fn temporaries_are_recognised_through_their_layers_and_removed_by_destination() {
        assert_eq!(temporary_destination(".a.exr.12-3.tmp"), Some("a.exr"));
        assert_eq!(temporary_destination("..it0098.exr.25308-785.tmp.25308-788.tmp"), Some("it0098.exr"));
        for other in ["a.exr", ".a.exr.notes.tmp", ".a.exr.12-.tmp", "..12-3.tmp", ".a.exr.12-3.tmpx"] {
            assert_eq!(temporary_destination(other), None, "{other}");
        }
        let dir = tempfile::tempdir().unwrap();
        for name in ["..a.exr.1-2.tmp.1-3.tmp", ".a.json.4-5.tmp", ".b.exr.1-2.tmp", "a.exr"] {
            fs::write(dir.path().join(name), "").unwrap();
        }
        let removed = remove_temporaries(dir.path(), |d| d.starts_with("a.")).unwrap();
        assert_eq!(removed.len(), 2);
        assert_eq!(names(dir.path()), [".b.exr.1-2.tmp", "a.exr"]);
    }

    #[test]
    fn an_output_set_commits_all_or_leaves_nothing_new() {
        let dir = tempfile::tempdir().unwrap();
        let mut set = OutputSet::new();
        let a = set.stage(&dir.path().join("a.txt")).unwrap();
        fs::write(&a, "a").unwrap();
        let _b = set.stage(&dir.path().join("b.txt")).unwrap();
        // b is never written: the commit fails and a is not put in place.
        let err = set.commit().unwrap_err().to_string();
        assert!(err.contains("b.txt: was staged but never written"), "{err}");
        assert!(names(dir.path()).is_empty(), "{:?}", names(dir.path()));
        // A failing command drops its set: nothing is left.
        let mut set = OutputSet::new();
        let a = set.stage(&dir.path().join("a.txt")).unwrap();
        fs::write(&a, "a").unwrap();
        drop(set);
        assert!(names(dir.path()).is_empty());
        let mut set = OutputSet::new();
        set.stage(&dir.path().join("a.txt")).unwrap();
        assert!(set.stage(&dir.path().join("a.txt")).unwrap_err().to_string().contains("twice"));
    }
}

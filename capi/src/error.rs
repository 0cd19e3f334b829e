//! Status codes, the thread-local message of the last failure, and the guard every entry point
//! runs its body in (panics become `PgStatus::Panic`, never an unwind into C).

use std::cell::RefCell;
use std::ffi::{CStr, CString, c_char};
use std::panic::{AssertUnwindSafe, catch_unwind};

/// What a call returns: `PG_STATUS_OK` (0), or why it failed. The message of the last failure on
/// the calling thread is `pg_last_error_message`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PgStatus {
    /// Success.
    Ok = 0,
    /// A pointer argument that must not be null was null.
    NullPointer = 1,
    /// An argument was out of range, of the wrong size, not UTF-8, or an unknown name.
    InvalidArgument = 2,
    /// The scene could not be loaded (the message names the file and line).
    Scene = 3,
    /// A file could not be read or written.
    Io = 4,
    /// No Vulkan loader or device, or no device matches the selector.
    NoDevice = 5,
    /// The device lacks something pathgrad needs.
    MissingFeature = 6,
    /// A lent device was created without an extension or feature pathgrad needs (the message
    /// lists every one).
    NotEnabled = 7,
    /// A Vulkan call failed, or device memory could not be allocated.
    Vulkan = 8,
    /// GPU work did not finish in time.
    Timeout = 9,
    /// The kernels reported a numeric failure (a truncated loop, a replay that drifted, a
    /// non-finite gradient, a fixed-point overflow).
    Numeric = 10,
    /// pathgrad panicked: a bug; the message says where. The handles passed to the call may be
    /// in an inconsistent state: destroy them.
    Panic = 11,
}

/// A failed call: its status and message.
pub(crate) struct Failure {
    pub status: PgStatus,
    pub message: String,
}

/// Shorthand for the bodies of entry points.
pub(crate) type Outcome<T = ()> = Result<T, Failure>;

impl Failure {
    pub fn new(status: PgStatus, message: impl Into<String>) -> Failure {
        Failure { status, message: message.into() }
    }

    pub fn argument(message: impl Into<String>) -> Failure {
        Failure::new(PgStatus::InvalidArgument, message)
    }
}

impl From<pathgrad::Error> for Failure {
    fn from(e: pathgrad::Error) -> Failure {
        use pathgrad::Error as E;
        let status = match &e {
            E::NoDevice { .. } | E::DeviceNotFound { .. } => PgStatus::NoDevice,
            E::MissingFeature { .. } => PgStatus::MissingFeature,
            E::NotEnabled { .. } => PgStatus::NotEnabled,
            E::Vulkan { .. } | E::Allocation { .. } => PgStatus::Vulkan,
            E::Timeout { .. } => PgStatus::Timeout,
            E::LoopBudget { .. } | E::Numeric { .. } | E::NonFiniteGradient { .. } => PgStatus::Numeric,
            E::Scene { .. } => PgStatus::Scene,
            E::InvalidArgument { .. } => PgStatus::InvalidArgument,
            E::Io { .. } | E::Output { .. } | E::Image { .. } => PgStatus::Io,
        };
        Failure { status, message: c_names(&e.to_string()) }
    }
}

/// The library's Rust names in `text` (`RenderOptions::spp`, `Context::requirements()`) spelled as
/// this API's, as the command-line program spells them as its flags.
fn c_names(text: &str) -> String {
    const NAMES: &[(&str, &str)] = &[
        (
            "Context::requirements() lists",
            "pg_required_device_extension and capi/README.md (\"Lending a device\") list",
        ),
        ("RenderOptions::width/height", "PgFrameDesc.width/height"),
        ("RenderOptions::spp", "PgFrameDesc.spp"),
        ("RenderOptions::max_depth", "PgFrameDesc.max_depth"),
        ("GradMode::Deterministic", "PgFrameDesc.deterministic"),
        ("Sampling::Attached::noise", "PgFrameDesc.jacobian_noise"),
        ("Sampling::Attached", "PgFrameDesc.attached"),
        ("DeviceChoice", "PgContextDesc.device"),
    ];
    NAMES.iter().fold(text.to_string(), |t, (rust, c)| t.replace(rust, c))
}

thread_local! {
    static LAST_ERROR: RefCell<CString> = RefCell::new(CString::default());
}

fn set_last_error(message: &str) {
    // A message never holds a NUL; if one did, it would end the C string there.
    let text = CString::new(message.replace('\0', " ")).unwrap_or_default();
    LAST_ERROR.with(|last| *last.borrow_mut() = text);
}

/// Runs an entry point's body: its failure (or panic) becomes a status and this thread's last
/// error message, prefixed with the function's name.
pub(crate) fn guard(function: &str, body: impl FnOnce() -> Outcome) -> PgStatus {
    match catch_unwind(AssertUnwindSafe(body)) {
        Ok(Ok(())) => PgStatus::Ok,
        Ok(Err(failure)) => {
            set_last_error(&format!("{function}: {}", failure.message));
            failure.status
        }
        Err(payload) => {
            let what = payload
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| payload.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "a panic without a message".into());
            set_last_error(&format!("{function}: pathgrad panicked (a bug; please report it): {what}"));
            PgStatus::Panic
        }
    }
}

/// The message of the last call on this thread that failed (UTF-8, NUL-terminated), or "" if
/// none has. A successful call leaves it as it was. The pointer stays valid until the next
/// failing call on this thread; copy the text to keep it.
#[unsafe(no_mangle)]
pub extern "C" fn pg_last_error_message() -> *const c_char {
    // Reading a thread-local cannot panic once the thread lives; `try_with` covers teardown.
    LAST_ERROR.try_with(|last| last.borrow().as_ptr()).unwrap_or(c"".as_ptr())
}

/// The reference behind `ptr`, or a `PgStatus::NullPointer` failure naming `what`.
///
/// # Safety
/// A non-null `ptr` must point to a live, properly aligned `T`.
pub(crate) unsafe fn arg<'a, T>(ptr: *const T, what: &str) -> Outcome<&'a T> {
    // SAFETY: the caller guarantees a non-null pointer is valid.
    unsafe { ptr.as_ref() }.ok_or_else(|| Failure::new(PgStatus::NullPointer, format!("`{what}` is null")))
}

/// As `arg`, mutable.
///
/// # Safety
/// A non-null `ptr` must point to a live, properly aligned `T` that nothing else refers to.
pub(crate) unsafe fn arg_mut<'a, T>(ptr: *mut T, what: &str) -> Outcome<&'a mut T> {
    // SAFETY: the caller guarantees a non-null pointer is valid and unaliased.
    unsafe { ptr.as_mut() }.ok_or_else(|| Failure::new(PgStatus::NullPointer, format!("`{what}` is null")))
}

/// The UTF-8 string behind `ptr`.
///
/// # Safety
/// A non-null `ptr` must point to a NUL-terminated string.
pub(crate) unsafe fn string<'a>(ptr: *const c_char, what: &str) -> Outcome<&'a str> {
    if ptr.is_null() {
        return Err(Failure::new(PgStatus::NullPointer, format!("`{what}` is null")));
    }
    // SAFETY: non-null, NUL-terminated (the caller's guarantee).
    unsafe { CStr::from_ptr(ptr) }.to_str().map_err(|_| Failure::argument(format!("`{what}` is not UTF-8")))
}

/// The `count` values behind `ptr`: null is allowed only for `count` 0.
///
/// # Safety
/// A non-null `ptr` must point to `count` initialised values.
pub(crate) unsafe fn slice<'a, T>(ptr: *const T, count: usize, what: &str) -> Outcome<&'a [T]> {
    if count == 0 {
        return Ok(&[]);
    }
    if ptr.is_null() {
        return Err(Failure::new(PgStatus::NullPointer, format!("`{what}` is null (with a count of {count})")));
    }
    // SAFETY: non-null with `count` values (the caller's guarantee).
    Ok(unsafe { std::slice::from_raw_parts(ptr, count) })
}

/// As `slice`, for output: exactly `wanted` values, so a buffer of another size is an error.
///
/// # Safety
/// A non-null `ptr` must point to `count` writable values.
pub(crate) unsafe fn out_slice<'a, T>(ptr: *mut T, count: usize, wanted: usize, what: &str) -> Outcome<&'a mut [T]> {
    if count != wanted {
        return Err(Failure::argument(format!("`{what}` holds {count} values; this call writes {wanted}")));
    }
    if count == 0 {
        return Ok(&mut []);
    }
    if ptr.is_null() {
        return Err(Failure::new(PgStatus::NullPointer, format!("`{what}` is null")));
    }
    // SAFETY: non-null with `count` writable values (the caller's guarantee).
    Ok(unsafe { std::slice::from_raw_parts_mut(ptr, count) })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn message() -> String {
        // SAFETY: the getter returns a NUL-terminated string.
        unsafe { CStr::from_ptr(pg_last_error_message()) }.to_string_lossy().into_owned()
    }

    /// A panic becomes a status and a message, and does not unwind into the caller.
    #[test]
    fn a_panic_is_a_status() {
        let status = guard("pg_test", || panic!("on purpose"));
        assert_eq!(status, PgStatus::Panic);
        assert!(message().contains("pg_test: pathgrad panicked") && message().contains("on purpose"), "{}", message());
        // A success leaves the message; a failure replaces it, on this thread only.
        assert_eq!(guard("pg_test", || Ok(())), PgStatus::Ok);
        assert!(message().contains("on purpose"));
        std::thread::spawn(|| assert_eq!(message(), "")).join().unwrap();
        assert_eq!(guard("pg_other", || Err(Failure::argument("bad\0value"))), PgStatus::InvalidArgument);
        assert_eq!(message(), "pg_other: bad value");
    }
}

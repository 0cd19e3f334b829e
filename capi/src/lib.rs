//! pathgrad's C API: engines in C and C++ lend their Vulkan device to pathgrad, load a scene,
//! record renders and gradient passes into their own command buffers, and read or bind the
//! buffers pathgrad exposes. `include/pathgrad.h` is generated from this crate by cbindgen
//! (`tests/header.rs` checks it); README.md has the lifetime and threading rules.
//!
//! Every fallible function returns a `PgStatus` and leaves a message for
//! `pg_last_error_message`; none unwinds into C (a panic is `PG_STATUS_PANIC`). Null handles and
//! pointers, buffers of the wrong size and unknown names are errors, not undefined behaviour.
//! Getters that cannot fail (counts, names) return a value and treat a null handle as empty.

mod context;
mod error;
mod frame;
mod scene;

pub use context::*;
pub use error::{PgStatus, pg_last_error_message};
pub use frame::*;
pub use scene::*;

/// pathgrad's version ("0.1.0"), static storage.
#[unsafe(no_mangle)]
pub extern "C" fn pg_version() -> *const std::ffi::c_char {
    concat!(env!("CARGO_PKG_VERSION"), "\0").as_ptr().cast()
}

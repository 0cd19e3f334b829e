//! Fuzzes the OBJ loader through a temporary file: any bytes give a mesh or an error, never a panic.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let dir = tempfile::tempdir().expect("a temporary directory");
    let path = dir.path().join("fuzz.obj");
    std::fs::write(&path, data).expect("writing the input");
    let _ = pathgrad::scene::mesh_io::load_obj(&path);
});

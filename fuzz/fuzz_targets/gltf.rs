//! Fuzzes the glTF loader (.glb and .gltf) through a temporary file: any bytes give a scene or an
//! error, never a panic.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let dir = tempfile::tempdir().expect("a temporary directory");
    let ext = if data.starts_with(b"glTF") { "glb" } else { "gltf" };
    let path = dir.path().join(format!("fuzz.{ext}"));
    std::fs::write(&path, data).expect("writing the input");
    let _ = pathgrad::scene::gltf::load(&path);
});

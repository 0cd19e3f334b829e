//! `include/pathgrad.h` is what cbindgen generates from `src/` now: a change to the API that was
//! not followed by regenerating the header fails here.

use std::path::Path;

#[test]
fn committed_header_is_current() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    let config = cbindgen::Config::from_file(dir.join("cbindgen.toml")).expect("cbindgen.toml");
    let mut generated = Vec::new();
    cbindgen::Builder::new()
        .with_crate(dir)
        .with_config(config)
        .generate()
        .expect("cbindgen generates the header")
        .write(&mut generated);
    let generated = String::from_utf8(generated).expect("UTF-8");
    let path = dir.join("include/pathgrad.h");
    if std::env::var("PATHGRAD_BLESS").is_ok_and(|v| v == "1") {
        std::fs::write(&path, &generated).expect("write include/pathgrad.h");
        return;
    }
    let committed = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(
        committed == generated,
        "capi/include/pathgrad.h differs from what cbindgen generates from capi/src; regenerate it with\n  \
         PATHGRAD_BLESS=1 cargo test --manifest-path capi/Cargo.toml --test header\nand commit it"
    );
}

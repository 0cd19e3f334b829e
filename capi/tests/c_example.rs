//! `examples/c/main.c` compiles as C11 against the committed header and this crate's static
//! library, and runs: an engine in C lends its device (validation on) and checks the results.
//! Needs `cc`, the Vulkan headers (`libvulkan-dev`) and the validation layer (scripts/setup).

use std::path::{Path, PathBuf};
use std::process::Command;

/// This crate's static library as `cargo test` left it: in `target/<profile>/deps/`, beside the
/// test binary (a `cargo build` also copies it one folder up, which `cargo test` does not).
fn static_library() -> PathBuf {
    let exe = std::env::current_exe().expect("the test's path");
    let deps = exe.parent().expect("target/<profile>/deps/<test>");
    [deps, deps.parent().unwrap_or(deps)]
        .iter()
        .map(|d| d.join("libpathgrad_c.a"))
        .find(|p| p.exists())
        .unwrap_or_else(|| deps.join("libpathgrad_c.a"))
}

#[test]
fn c_example_compiles_and_runs() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let library = static_library();
    assert!(library.exists(), "{} is missing (cargo builds it with the tests)", library.display());
    let program = Path::new(env!("CARGO_TARGET_TMPDIR")).join("pathgrad-c-example");
    let compiled = Command::new(std::env::var("CC").unwrap_or_else(|_| "cc".into()))
        .args(["-std=c11", "-Wall", "-Wextra", "-Wpedantic", "-Werror", "-O1", "-I"])
        .arg(root.join("include"))
        .arg(root.join("../examples/c/main.c"))
        .arg(&library)
        .args(["-lvulkan", "-lstdc++", "-lgcc_s", "-lm", "-lpthread", "-ldl", "-o"])
        .arg(&program)
        .status()
        .expect("run cc (install a C compiler)");
    assert!(compiled.success(), "compiling examples/c/main.c failed");
    let run = Command::new(&program).output().expect("run the C example");
    let (stdout, stderr) = (String::from_utf8_lossy(&run.stdout), String::from_utf8_lossy(&run.stderr));
    println!("{stdout}");
    eprintln!("{stderr}");
    assert!(run.status.success(), "the C example failed ({})", run.status);
    assert!(stdout.contains("validation messages: 0"), "the example's last line reports no validation messages");
}

/// The header is also valid C++ (the `extern "C"` guards), for engines in C++.
#[test]
fn header_compiles_as_cpp() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let source = Path::new(env!("CARGO_TARGET_TMPDIR")).join("pathgrad-header.cpp");
    std::fs::write(
        &source,
        "#include \"pathgrad.h\"\nint main() { PgContext *c = nullptr; return pg_context_create(nullptr, &c); }\n",
    )
    .expect("write the C++ probe");
    let status = Command::new(std::env::var("CXX").unwrap_or_else(|_| "c++".into()))
        .args(["-std=c++17", "-Wall", "-Wextra", "-Werror", "-fsyntax-only", "-I"])
        .arg(root.join("include"))
        .arg(&source)
        .status()
        .expect("run c++ (install g++)");
    assert!(status.success(), "include/pathgrad.h does not compile as C++");
}

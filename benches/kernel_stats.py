#!/usr/bin/env python3
"""SPIR-V size and gradient-scatter sites of every render kernel, whole and specialised.

A tool for BENCHMARKS.md, not a test. For each kernel that `build.rs` compiled (the newest
`target/*/build/pathgrad-*/out/*.spv`) it prints the module's size and, for a few FEATURES values
(the specialisation constant of shaders/lib/features.glsl), the size after `spirv-opt` applies
the value, folds and strips debug info — what the driver is left to compile — with the number of
atomic instructions and subgroup operations in it.

    python3 benches/kernel_stats.py            # after cargo build --release

Needs Debian's spirv-tools (spirv-opt, spirv-dis), which scripts/setup installs.
"""

import glob
import os
import re
import subprocess
import sys
import tempfile

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def consts():
    """The F_*/G_* bits of src/contract/consts.rs."""
    text = open(os.path.join(REPO, "src/contract/consts.rs")).read()
    bits = {}
    for name, expr in re.findall(r"\b([FG]_[A-Z_]+) = ([^;]+);", text):
        bits[name] = eval(expr.replace("_", ""))  # plain integer arithmetic, e.g. 1 << 4
    return bits


def newest_out_dir():
    dirs = glob.glob(os.path.join(REPO, "target/*/build/pathgrad-*/out"))
    dirs = [d for d in dirs if os.path.exists(os.path.join(d, "adjoint.spv"))]
    if not dirs:
        sys.exit("no compiled kernels: run cargo build --release first")
    return max(dirs, key=lambda d: os.path.getmtime(os.path.join(d, "adjoint.spv")))


def stats(path):
    dis = subprocess.run(["spirv-dis", path], capture_output=True, text=True, check=True).stdout
    ops = re.findall(r"^\s*(?:%\S+ = )?(Op\w+)", dis, re.M)
    atomics = sum(1 for o in ops if o.startswith("OpAtomic"))
    subgroup = sum(1 for o in ops if o.startswith("OpGroupNonUniform"))
    return os.path.getsize(path), len(ops), atomics, subgroup


def main():
    b = consts()
    cornell = b["F_NEE"] | b["F_EMITTERS"] | b["F_DIFFUSE"] | b["F_CONDUCTOR"] | b["F_BECKMANN"]
    variants = [
        ("cornell-box, ∂alpha", cornell | b["G_ALPHA"]),
        ("cornell-box, every kind", cornell | b["G_COLOR"] | b["G_ALPHA"] | b["G_EMISSION"]),
        ("everything (unspecialised)", 0xFFFFFFFF),
    ]
    out = newest_out_dir()
    kernels = ["primal", "adjoint", "adjoint_fixed", "adjoint_adaptive", "adjoint_adaptive_fixed", "image_gradient"]
    print(f"kernels from {os.path.relpath(out, REPO)}")
    print(f"{'kernel':24} {'module':>10}   {'variant':28} {'specialised':>11} {'instrs':>7} {'atomics':>7} {'subgroup':>8}")
    with tempfile.TemporaryDirectory() as tmp:
        for k in kernels:
            spv = os.path.join(out, f"{k}.spv")
            size = os.path.getsize(spv)
            for label, value in variants:
                dst = os.path.join(tmp, f"{k}.spv")
                subprocess.run(
                    ["spirv-opt", f"--set-spec-const-default-value=0:{value}", "--freeze-spec-const", "-O",
                     "--strip-debug", spv, "-o", dst],
                    check=True,
                )
                s, n, a, g = stats(dst)
                print(f"{k:24} {size:>10,}   {label:28} {s:>11,} {n:>7,} {a:>7} {g:>8}")


if __name__ == "__main__":
    main()

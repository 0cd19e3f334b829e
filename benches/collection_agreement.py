#!/usr/bin/env python3
"""Whether the scenes of a Mitsuba scene collection that pathgrad loads render as Mitsuba 3 renders them.

    DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1 \\
        /tmp/mi/bin/python benches/collection_agreement.py [--width 96] [--spp 32] [--seeds 3] DIR...

A tool for people, not a test (nothing is asserted): the conformance matrix (tests/conformance) is
the statistical test, one feature a row. This script asks the broader question of issue 31 — do
the scenes users have, taken whole, agree? For every scene file under DIR that `scripts/coverage`
counts as a scene and that pathgrad loads, it renders

  * pathgrad: `pathgrad render SCENE --allow-outside-folder --width W --spp N --seed s` (the
    height follows the film's aspect), seeds 0..S-1;
  * Mitsuba 3 (`llvm_ad_rgb`, the scene's own integrator and sampler): the same film size (set
    through `mi.traverse`'s `film.size` and `film.crop_size`), `mi.render(scene, spp=N, seed=s)`,
    seeds 1000..1000+S-1;

and reports the image mean per channel of each, their ratio, and the difference in units of its
standard error over the seeds (|z| > 4 is worth a look; the two draw different paths). pathgrad's
load warnings are listed (a stand-in such as `direct` rendered as a path tracer says so there).
Scenes Mitsuba cannot load in `llvm_ad_rgb` (spectral-only plugins) are reported as such.
"""

import argparse
import importlib.machinery
import importlib.util
import math
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def coverage_module():
    loader = importlib.machinery.SourceFileLoader("coverage_script", str(ROOT / "scripts" / "coverage"))
    spec = importlib.util.spec_from_loader("coverage_script", loader)
    module = importlib.util.module_from_spec(spec)
    loader.exec_module(module)
    return module


def mean_se(rows):
    a = np.array(rows, np.float64)
    return a.mean(axis=0), a.std(axis=0, ddof=1) / math.sqrt(len(a)) if len(a) > 1 else np.zeros(3)


def pathgrad_means(binary, scene, width, spp, seeds, tmp):
    import mitsuba as mi
    means, warnings, size = [], [], None
    for seed in seeds:
        out = Path(tmp) / "pg.exr"
        run = subprocess.run([binary, "render", "--allow-outside-folder", str(scene), "--width", str(width),
                              "--spp", str(spp), "--seed", str(seed), "-o", str(out)],
                             capture_output=True, text=True, timeout=1800)
        if run.returncode != 0:
            raise RuntimeError(run.stderr.strip().splitlines()[-1])
        # "WARN target: FILE:LINE:COL: message" -> the message.
        warnings = [re.sub(r"^.*?\.(xml|gltf|glb)(:\d+:\d+)?: ", "", line.split("WARN", 1)[-1].strip())
                    for line in run.stderr.splitlines() if "WARN" in line]
        img = np.array(mi.Bitmap(str(out)), np.float64)
        size = (img.shape[1], img.shape[0])
        means.append(img.reshape(-1, img.shape[-1])[:, :3].mean(axis=0))
    return means, warnings, size


def mitsuba_means(scene_path, size, spp, seeds):
    import mitsuba as mi
    scene = mi.load_file(str(scene_path))
    params = mi.traverse(scene)
    for key in list(params.keys()):
        if key.endswith("film.size") or key.endswith("film.crop_size"):
            params[key] = mi.ScalarVector2u(*size)
        elif key.endswith("film.crop_offset"):
            params[key] = mi.ScalarPoint2u(0, 0)
    params.update()
    means = []
    for seed in seeds:
        img = np.array(mi.render(scene, spp=spp, seed=seed), np.float64)
        means.append(img.reshape(-1, img.shape[-1])[:, :3].mean(axis=0))
    return means


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("dirs", nargs="+", type=Path)
    parser.add_argument("--pathgrad", default=str(ROOT / "target" / "release" / "pathgrad"))
    parser.add_argument("--width", type=int, default=96)
    parser.add_argument("--spp", type=int, default=32)
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--only", nargs="*", help="substrings: scenes whose path contains one of them")
    args = parser.parse_args()
    import mitsuba as mi
    mi.set_variant("llvm_ad_rgb")

    cov = coverage_module()
    files = sorted({f.resolve() for d in args.dirs for f in d.rglob("*.xml")})
    fragments = cov.included(files)
    scenes = [f for f in files if f not in fragments]
    if args.only:
        scenes = [f for f in scenes if any(s in str(f) for s in args.only)]
    print("| scene | pathgrad mean (R, G, B) | Mitsuba mean | ratio | z | pathgrad warnings |")
    print("| --- | --- | --- | --- | --- | --- |")
    worst = []
    with tempfile.TemporaryDirectory() as tmp:
        for f in scenes:
            name = cov.shown(f, args.dirs)
            probe = subprocess.run([args.pathgrad, "params", "--allow-outside-folder", str(f)],
                                   capture_output=True, text=True, timeout=300)
            if probe.returncode != 0:
                continue
            t0 = time.time()
            try:
                pg, warnings, size = pathgrad_means(args.pathgrad, f, args.width, args.spp, range(args.seeds), tmp)
            except Exception as e:  # a render failure is a finding, not a crash of the survey
                print(f"| `{name}` | render failed: {e} | | | | |", flush=True)
                continue
            try:
                mt = mitsuba_means(f, size, args.spp, range(1000, 1000 + args.seeds))
            except Exception as e:
                print(f"| `{name}` | | Mitsuba ({mi.variant()}) cannot render it: {str(e).splitlines()[0][:90]} | | | |",
                      flush=True)
                continue
            (m_pg, se_pg), (m_mt, se_mt) = mean_se(pg), mean_se(mt)
            ratio = m_pg / np.where(m_mt != 0, m_mt, np.nan)
            se = np.sqrt(se_pg ** 2 + se_mt ** 2)
            z = np.where(se > 0, (m_pg - m_mt) / np.where(se > 0, se, 1), 0.0)
            zmax = float(np.max(np.abs(z)))
            worst.append((zmax, name))
            fmt = lambda v: ", ".join(f"{x:.4g}" for x in v)
            shown_warnings = "; ".join(sorted(set(w[:80] for w in warnings)))[:200]
            print(f"| `{name}` | {fmt(m_pg)} | {fmt(m_mt)} | {fmt(ratio)} | {zmax:.1f} | {shown_warnings} |"
                  f"  <!-- {time.time() - t0:.0f} s -->", flush=True)
    worst.sort(reverse=True)
    print()
    print(f"{len(worst)} scenes rendered by both; largest |z|: " + ", ".join(f"{n} {z:.1f}" for z, n in worst[:8]))
    return 0


if __name__ == "__main__":
    sys.exit(main())

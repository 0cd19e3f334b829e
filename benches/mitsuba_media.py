#!/usr/bin/env python3
"""pathgrad against Mitsuba 3 `volpath` on a heterogeneous medium (scenes/smoke/smoke.xml): the
primal's speed side by side, interleaved, and the images' agreement per block over seeds.

    python3 -m venv /tmp/mi && /tmp/mi/bin/pip install mitsuba==3.9.1 numpy
    DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1 /tmp/mi/bin/python benches/mitsuba_media.py

Speed: `pathgrad render --json` (its `time_s`: the render, kernel builds loaded from the cache
after a warm-up) against `mi.render` of the same scene in `llvm_ad_rgb` (after a warm-up render,
so its JIT compile is excluded), `--runs` rounds, medians and their ratio. Agreement: `--seeds`
renders at 32×32 per side, 4×4 blocks of 8×8 pixels, z = (mean_p − mean_m)/√(se_p² + se_m²) per
block with a floor of 1e-4 of the block's value (blocks of constant sky). Prints figures only.
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENE = os.path.join(ROOT, "scenes", "smoke", "smoke.xml")
PATHGRAD = os.path.join(ROOT, "target", "release", "pathgrad")


def pathgrad_render(args, out):
    cmd = [PATHGRAD, "render", SCENE, "--json", "-o", out] + args
    result = subprocess.run(cmd, capture_output=True, text=True, check=True)
    return json.loads(result.stdout)["time_s"]


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--seeds", type=int, default=8)
    p.add_argument("--res", type=int, default=128)
    p.add_argument("--spp", type=int, default=64)
    a = p.parse_args()
    vol = os.path.join(ROOT, "scenes", "smoke", "smoke.vol")
    if not os.path.exists(vol):
        subprocess.run([sys.executable, os.path.join(ROOT, "scenes", "smoke", "make_smoke.py")], check=True)
    import mitsuba as mi
    import drjit as dr

    try:
        mi.set_variant("llvm_ad_rgb")
    except Exception as e:  # no libLLVM: the scalar variant is far slower, so no speed figures
        print(f"llvm_ad_rgb unavailable ({e}); agreement only, in scalar_rgb")
        mi.set_variant("scalar_rgb")
    variant = mi.variant()
    tmp = tempfile.mkdtemp()
    out = os.path.join(tmp, "pg.exr")
    if variant.startswith("llvm"):
        scene = mi.load_file(SCENE, res=a.res, spp=a.spp)
        dr.eval(mi.render(scene, seed=0))
        pathgrad_render(["--spp", str(a.spp), "--seed", "0"], out)
        pg, mt = [], []
        for r in range(a.runs):
            pg.append(pathgrad_render(["--spp", str(a.spp), "--seed", str(r + 1)], out))
            t = time.perf_counter()
            img = mi.render(scene, seed=r + 1)
            dr.eval(img)
            dr.sync_thread()
            mt.append(time.perf_counter() - t)
            print(f"round {r + 1}: pathgrad {pg[-1]:.3f} s, mitsuba volpath {mt[-1]:.3f} s")
        samples = a.res * a.res * a.spp
        p_med, m_med = statistics.median(pg), statistics.median(mt)
        print(f"primal {a.res}x{a.res}, {a.spp} spp: pathgrad {p_med:.3f} s ({samples / p_med / 1e6:.3f} M samples/s), "
              f"mitsuba {m_med:.3f} s ({samples / m_med / 1e6:.3f} M samples/s), ratio {m_med / p_med:.3f}x")
    scene = mi.load_file(SCENE, res=32, spp=128)
    mine, theirs = [], []
    for k in range(1, a.seeds + 1):
        pathgrad_render(["--spp", "128", "--width", "32", "--height", "32", "--seed", str(k)], out)
        mine.append(np.array(mi.Bitmap(out))[..., :3])
        theirs.append(np.array(mi.render(scene, seed=1000 + k))[..., :3])
    def blocks(x):
        x = np.array(x)
        return x.reshape(x.shape[0], 4, 8, 4, 8, 3).mean(axis=(2, 4, 5))
    bp, bm = blocks(mine), blocks(theirs)
    n = bp.shape[0]
    mp, mm = bp.mean(0), bm.mean(0)
    se = np.sqrt(bp.var(0, ddof=1) / n + bm.var(0, ddof=1) / n + (1e-4 * mm) ** 2)
    z = (mp - mm) / se
    np.set_printoptions(precision=2, suppress=True)
    print(f"agreement over {n} seeds per side ({variant}), z per 8x8 block:\n{z}")
    print(f"image mean ratio pathgrad/mitsuba {mp.mean() / mm.mean():.4f}, max |z| {np.abs(z).max():.2f}, "
          f"mean z^2 {np.mean(z ** 2):.2f}")


if __name__ == "__main__":
    main()

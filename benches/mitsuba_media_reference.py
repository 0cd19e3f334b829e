#!/usr/bin/env python3
"""Writes the Mitsuba 3 `volpath` reference of the media agreement test (tests/it/media.rs,
`primal_agrees_with_mitsuba_volpath`): scenes/smoke/smoke.xml at 32×32 with an 8³ grid from
make_smoke.py, rendered over 16 seeds at 256 spp; per seed the mean of each 8×8 pixel block and
channel. Output in tests/data/mitsuba/smoke8/: smoke.vol (the grid) and blocks.json.

    python3 -m venv /tmp/mi && /tmp/mi/bin/pip install mitsuba==3.9.1 numpy
    DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1 /tmp/mi/bin/python benches/mitsuba_media_reference.py
"""
import json
import os
import shutil
import subprocess
import sys
import tempfile

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
OUT = os.path.join(ROOT, "tests", "data", "mitsuba", "smoke8")
RES, SPP, SEEDS, BLOCK = 32, 256, 16, 8


def main():
    import drjit as dr
    import mitsuba as mi

    os.makedirs(OUT, exist_ok=True)
    vol = os.path.join(OUT, "smoke.vol")
    subprocess.run([sys.executable, os.path.join(ROOT, "scenes", "smoke", "make_smoke.py"), vol, "8"], check=True)
    mi.set_variant("llvm_ad_rgb")
    tmp = tempfile.mkdtemp()
    shutil.copy(os.path.join(ROOT, "scenes", "smoke", "smoke.xml"), tmp)
    shutil.copy(vol, tmp)
    scene = mi.load_file(os.path.join(tmp, "smoke.xml"), res=RES, spp=SPP)
    blocks = []
    for seed in range(SEEDS):
        img = np.array(mi.render(scene, seed=seed))[..., :3].astype(np.float64)
        b = img.reshape(RES // BLOCK, BLOCK, RES // BLOCK, BLOCK, 3).mean(axis=(1, 3))
        blocks.append(b.reshape(-1, 3).tolist())
    info = {
        "what": "per seed, the mean of each 8x8 block (row-major) and channel of scenes/smoke/smoke.xml "
        "with this directory's smoke.vol, written by benches/mitsuba_media_reference.py",
        "renderer": f"Mitsuba {mi.__version__} (drjit {dr.__version__}) llvm_ad_rgb volpath",
        "res": RES,
        "spp": SPP,
        "block": BLOCK,
        "blocks": blocks,
    }
    with open(os.path.join(OUT, "blocks.json"), "w") as f:
        json.dump(info, f, indent=1)
    print(f"wrote {OUT}/blocks.json: {SEEDS} seeds, image mean {np.mean(blocks):.5f}")


if __name__ == "__main__":
    main()

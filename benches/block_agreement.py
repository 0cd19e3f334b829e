"""Block-by-block agreement of one scene: pathgrad vs Mitsuba 3.9.1 at WIDTH, SPP, over SEEDS seeds.

usage (text; run from the scene's folder):
    DRJIT_LIBLLVM_PATH=... /tmp/mi/bin/python benches/block_agreement.py PATHGRAD SCENE WIDTH SPP SEEDS BLOCK

Prints the image ratio, the BLOCK x BLOCK block-channels whose Welch z exceeds 3 and 4 (with few
seeds z follows a t law of about 2(SEEDS-1) degrees of freedom, not a normal one: with 4 seeds
about 0.7 % of blocks exceed 4 and 2.4 % exceed 3 by chance), where the |z| > 4 ones lie, and
saves both mean images to /tmp/hc_pg.npy and /tmp/hc_mt.npy.
"""
import sys, subprocess, tempfile, numpy as np, math
from pathlib import Path
import mitsuba as mi
mi.set_variant("llvm_ad_rgb")
binary, scene, width, spp, seeds, block = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5]), int(sys.argv[6])
pg = []
with tempfile.TemporaryDirectory() as tmp:
    for s in range(seeds):
        out = Path(tmp) / "pg.exr"
        subprocess.run([binary, "render", "--allow-outside-folder", scene, "--width", str(width), "--spp", str(spp),
                        "--seed", str(s + 1), "-o", str(out)], check=True, capture_output=True)
        pg.append(np.array(mi.Bitmap(str(out)), np.float64)[..., :3])
h, w = pg[0].shape[:2]
sc = mi.load_file(scene)
p = mi.traverse(sc)
for k in list(p.keys()):
    if k.endswith("film.size") or k.endswith("film.crop_size"):
        p[k] = mi.ScalarVector2u(w, h)
p.update()
mt = [np.array(mi.render(sc, spp=spp, seed=s + 100), np.float64)[..., :3] for s in range(seeds)]
def blocks(imgs):
    a = np.stack(imgs)[:, : h // block * block, : w // block * block]
    a = a.reshape(seeds, h // block, block, w // block, block, 3).mean(axis=(2, 4))
    return a.mean(0), a.std(0, ddof=1) / math.sqrt(seeds)
(m1, s1), (m2, s2) = blocks(pg), blocks(mt)
z = (m1 - m2) / np.sqrt(s1 ** 2 + s2 ** 2 + 1e-30)
print(f"{scene}: {w}x{h}, {spp} spp x {seeds} seeds, {block}x{block} blocks: {z.size} block-channels")
print(f"  image ratio {np.mean(pg, axis=(0,1,2)) / np.mean(mt, axis=(0,1,2))}")
print(f"  max |z| {np.abs(z).max():.2f}; |z| > 4: {(np.abs(z) > 4).sum()}; |z| > 3: {(np.abs(z) > 3).sum()}")
rel = np.abs(m1 - m2) / np.maximum(m2, 1e-3)
print(f"  block |diff|/mean: median {np.median(rel):.4f}, 99th pct {np.percentile(rel, 99):.4f}")
bad = np.argwhere(np.abs(z) > 4)
print("  |z| > 4 at (block row, block col, channel):", [tuple(int(x) for x in b) for b in bad[:40]])
np.save("/tmp/hc_pg.npy", np.mean(pg, 0)); np.save("/tmp/hc_mt.npy", np.mean(mt, 0))

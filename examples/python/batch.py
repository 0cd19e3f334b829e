"""Render a scene at several parameter values and seeds, and the gradient image of each: the
loop a dataset or a sweep runs. Writes EXR (HDR) and PNG previews into the folder given."""
import pathlib
import sys

import numpy as np

import pathgrad as pg

out = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else "sweep")
out.mkdir(parents=True, exist_ok=True)
scene = pg.load("builtin:cornell-box", width=64, height=64)
name = "sphere.bsdf.alpha.value"
for alpha in (0.05, 0.2, 0.5):
    # Four seeds of one parameter value: their mean is a 64-spp image.
    images = [pg.render(scene, {name: alpha}, spp=16, seed=seed) for seed in range(4)]
    mean = np.mean(images, axis=0)
    pg.write_image(out / f"alpha_{alpha}.exr", mean)
    pg.write_image(out / f"alpha_{alpha}.png", mean)
    d_image = pg.image_gradient(scene, name, spp=16)  # ∂image/∂alpha, signed
    pg.write_image(out / f"d_alpha_{alpha}.exr", d_image)
    print(f"alpha {alpha}: image mean {mean.mean():.4f}, ∂mean/∂alpha {d_image.mean():+.4f}")

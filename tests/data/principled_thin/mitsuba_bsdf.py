"""Mitsuba 3.9.1's principledthin BSDF at fixed direction pairs: its value (`eval`), its density
(`pdf`) and the forward-mode derivative of the value by every differentiable parameter, for the
parameter sets below; and its directional albedo at four incidences by its own sampler (2^20
samples: the mean of `sample`'s weights and its standard error). Writes `mitsuba_bsdf.json` next to
this file, which `src/bsdf/principled_thin/tests.rs` compares pathgrad's CPU thin principled BSDF
against.

Run: DRJIT_LIBLLVM_PATH=... python tests/data/principled_thin/mitsuba_bsdf.py (variant llvm_ad_rgb).
"""
import json
import math
import os
import random

import drjit as dr
import mitsuba as mi

mi.set_variant("llvm_ad_rgb")

SCALARS = ["roughness", "anisotropic", "spec_trans", "eta", "spec_tint", "sheen", "sheen_tint", "flatness",
           "diff_trans"]

# name -> the plugin's properties (base_color an RGB triple; the sampling rates).
CASES = {
    "default": {},
    "general": dict(base_color=[0.8, 0.4, 0.2], roughness=0.4, spec_trans=0.4, spec_tint=0.5, sheen=0.6,
                    sheen_tint=0.4, flatness=0.3, diff_trans=0.7, eta=1.4),
    "anisotropic-sheet": dict(base_color=[0.7, 0.1, 0.1], roughness=0.15, spec_tint=0.1, anisotropic=0.5,
                              spec_trans=0.8, diff_trans=0.3, eta=1.33),
    "clear": dict(base_color=[0.9, 0.95, 1.0], roughness=0.25, spec_trans=1.0, eta=1.2),
    "low-eta-rated": dict(base_color=[0.3, 0.6, 0.9], roughness=0.9, spec_trans=0.3, spec_tint=0.7, eta=0.8,
                          sheen=1.0, anisotropic=0.4, diff_trans=1.5,
                          specular_reflectance_sampling_rate=0.5, specular_transmittance_sampling_rate=2.0,
                          diffuse_reflectance_sampling_rate=1.5, diffuse_transmittance_sampling_rate=0.7),
}


def plugin(props):
    # An RGB base colour always (Mitsuba's default 0.5 is a one-value texture, without a derivative
    # per channel).
    d = {"type": "principledthin", "base_color": {"type": "rgb", "value": [0.5, 0.5, 0.5]}}
    for k, v in props.items():
        d[k] = {"type": "rgb", "value": v} if k == "base_color" else v
    return d


def directions(n, rng):
    out = []
    for _ in range(n):
        z = rng.uniform(-1, 1)
        r = (1 - z * z) ** 0.5
        phi = rng.uniform(0, 2 * math.pi)
        out.append([r * math.cos(phi), r * math.sin(phi), z])
    return out


def scalar(x):
    return float(x[0]) if hasattr(x, "__getitem__") else float(x)


def main():
    rng = random.Random(31)
    n = 256
    wis = directions(n, rng)
    wos = directions(n, rng)
    # A quarter of the pairs near the mirror direction and a quarter near its reflection through
    # the sheet, where the specular lobes live.
    for i in range(0, n, 2):
        wi = wis[i]
        side = 1 if i % 4 == 0 else -1
        wo = [-wi[0] + rng.uniform(-0.2, 0.2), -wi[1] + rng.uniform(-0.2, 0.2), side * wi[2]]
        s = sum(c * c for c in wo) ** 0.5
        wos[i] = [c / s for c in wo]
    out = {"pairs": {"wi": wis, "wo": wos}, "cases": []}
    ctx = mi.BSDFContext()
    for name, props in CASES.items():
        bsdf = mi.load_dict(plugin(props))
        si = dr.zeros(mi.SurfaceInteraction3f, n)
        si.wi = mi.Vector3f([w[0] for w in wis], [w[1] for w in wis], [w[2] for w in wis])
        si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
        wo = mi.Vector3f([w[0] for w in wos], [w[1] for w in wos], [w[2] for w in wos])
        value = bsdf.eval(ctx, si, wo)
        pdf = bsdf.pdf(ctx, si, wo)
        case = {"name": name, "props": props, "value": [list(map(float, value[c])) for c in range(3)],
                "pdf": list(map(float, pdf)), "grad": {}}
        params = mi.traverse(bsdf)
        for key in SCALARS + ["base_color0", "base_color1", "base_color2"]:
            pkey = ("base_color" if key.startswith("base_color") else key) + ".value"
            p = params[pkey]
            dr.enable_grad(p)
            params.update()
            v = bsdf.eval(ctx, si, wo)
            if key.startswith("base_color"):
                t = [0.0, 0.0, 0.0]
                t[int(key[-1])] = 1.0
                dr.set_grad(p, type(p)(t[0], t[1], t[2]))
            else:
                dr.set_grad(p, 1.0)
            # A parameter whose lobe is off (Mitsuba's flag) has no derivative: zeros.
            g = dr.forward_to(v, flags=dr.ADFlag.Default | dr.ADFlag.AllowNoGrad)
            case["grad"][key] = [list(map(float, g[c])) for c in range(3)]
            dr.disable_grad(p)
            params = mi.traverse(bsdf)
        # The directional albedo by Mitsuba's own sampler: the mean of its sample weights.
        m = 1 << 20
        albedo = []
        for cos_i in [0.9, 0.5, 0.1, -0.5]:
            sin_i = (1 - cos_i * cos_i) ** 0.5
            si2 = dr.zeros(mi.SurfaceInteraction3f, m)
            si2.wi = mi.Vector3f(sin_i * 0.8, sin_i * 0.6, cos_i)
            si2.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
            sampler = mi.load_dict({"type": "independent"})
            sampler.seed(7, m)
            _, weight = bsdf.sample(ctx, si2, sampler.next_1d(), sampler.next_2d())
            mean = [scalar(dr.mean(weight[c])) for c in range(3)]
            var = [scalar(dr.mean(dr.square(weight[c] - mean[c]))) for c in range(3)]
            albedo.append({"cos_i": cos_i, "mean": mean, "sigma": [(x / m) ** 0.5 for x in var]})
        case["albedo"] = albedo
        out["cases"].append(case)
    here = os.path.dirname(os.path.abspath(__file__))
    with open(os.path.join(here, "mitsuba_bsdf.json"), "w") as f:
        json.dump(out, f)


if __name__ == "__main__":
    main()

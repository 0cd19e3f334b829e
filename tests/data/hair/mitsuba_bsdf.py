"""Mitsuba 3.9.1's hair BSDF at fixed direction pairs: its value (`eval`), its density (`pdf`) and
the forward-mode derivative of the value by eumelanin, pheomelanin, both roughnesses and each
channel of `sigma_a`, for the parameter sets below; and, per set, the mean weight of Mitsuba's own
sampler at three incidences (2^20 samples) next to the albedo ∫ f dω by uniform sphere sampling
of its `eval` (2^22 samples), which shows the bias of its sampler's residual (p = 3) lobe.
Writes `mitsuba_bsdf.json` next to this file, which `src/bsdf/hair.rs`'s tests compare
pathgrad's CPU hair BSDF against.

Run: DRJIT_LIBLLVM_PATH=... python tests/data/hair/mitsuba_bsdf.py (variant llvm_ad_rgb).
Local frame as Mitsuba's hair takes it: y along the fibre, z the normal.
"""
import json
import math
import os
import random

import drjit as dr
import mitsuba as mi

mi.set_variant("llvm_ad_rgb")

CASES = {
    "default": {},
    "blonde": dict(eumelanin=0.2, pheomelanin=0.4, longitudinal_roughness=0.25, azimuthal_roughness=0.4),
    "smooth": dict(eumelanin=0.8, pheomelanin=0.1, longitudinal_roughness=0.08, azimuthal_roughness=0.15,
                   scale_tilt=3.0, int_ior=1.6),
    "sigma": dict(sigma_a=[0.2, 0.25, 0.7], scale=2.0, longitudinal_roughness=0.5, azimuthal_roughness=0.7,
                  scale_tilt=-2.0),
    "white": dict(sigma_a=[0.0, 0.0, 0.0], longitudinal_roughness=0.3, azimuthal_roughness=0.5),
}
GRADS = ["eumelanin", "pheomelanin", "longitudinal_roughness", "azimuthal_roughness", "scale_tilt"]


def plugin(props):
    d = {"type": "hair"}
    for k, v in props.items():
        d[k] = {"type": "rgb", "value": v} if k == "sigma_a" else v
    return d


def directions(n, rng):
    out = []
    for _ in range(n):
        z = rng.uniform(-1, 1)
        r = (1 - z * z) ** 0.5
        phi = rng.uniform(0, 2 * math.pi)
        out.append([r * math.cos(phi), r * math.sin(phi), z])
    return out


def vec(ws):
    return mi.Vector3f([w[0] for w in ws], [w[1] for w in ws], [w[2] for w in ws])


def scalar(x):
    return float(x[0]) if hasattr(x, "__getitem__") else float(x)


def main():
    rng = random.Random(31)
    n = 256
    wis = directions(n, rng)
    wos = directions(n, rng)
    # A quarter of the pairs near the specular cone (sin θo ≈ −sin θi), where the lobes live.
    for i in range(0, n, 4):
        wi = wis[i]
        phi = rng.uniform(0, 2 * math.pi)
        s = -wi[1] + rng.uniform(-0.1, 0.1)
        c = max(0.0, 1 - s * s) ** 0.5
        wos[i] = [c * math.cos(phi), s, c * math.sin(phi)]
    out = {"pairs": {"wi": wis, "wo": wos}, "cases": []}
    ctx = mi.BSDFContext()
    for name, props in CASES.items():
        bsdf = mi.load_dict(plugin(props))
        si = dr.zeros(mi.SurfaceInteraction3f, n)
        si.wi = vec(wis)
        si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
        wo = vec(wos)
        value = bsdf.eval(ctx, si, wo)
        pdf = bsdf.pdf(ctx, si, wo)
        case = {"name": name, "props": props, "value": [list(map(float, value[c])) for c in range(3)],
                "pdf": list(map(float, pdf)), "grad": {}}
        params = mi.traverse(bsdf)
        keys = [k for k in GRADS if "sigma_a" not in props or k not in ("eumelanin", "pheomelanin")]
        if "sigma_a" in props:
            keys += ["sigma_a0", "sigma_a1", "sigma_a2"]
        for key in keys:
            pkey = "sigma_a.value" if key.startswith("sigma_a") else key
            p = params[pkey]
            dr.enable_grad(p)
            params.update()
            v = bsdf.eval(ctx, si, wo)
            if key.startswith("sigma_a"):
                t = [0.0, 0.0, 0.0]
                t[int(key[-1])] = 1.0
                dr.set_grad(p, type(p)(t[0], t[1], t[2]))
            else:
                dr.set_grad(p, 1.0)
            g = dr.forward_to(v)
            case["grad"][key] = [list(map(float, g[c])) for c in range(3)]
            dr.disable_grad(p)
            params = mi.traverse(bsdf)
        albedo = []
        m = 1 << 20
        for sin_i in [0.0, 0.5, -0.8]:
            cos_i = (1 - sin_i * sin_i) ** 0.5
            wi = mi.Vector3f(cos_i * 0.6, sin_i, cos_i * 0.8)
            si2 = dr.zeros(mi.SurfaceInteraction3f, m)
            si2.wi = wi
            si2.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
            sampler = mi.load_dict({"type": "independent"})
            sampler.seed(7, m)
            _, weight = bsdf.sample(ctx, si2, sampler.next_1d(), sampler.next_2d())
            mean = [scalar(dr.mean(weight[c])) for c in range(3)]
            # ∫ f dω by uniform directions.
            k = 1 << 22
            si3 = dr.zeros(mi.SurfaceInteraction3f, k)
            si3.wi = wi
            si3.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
            sampler.seed(8, k)
            d = mi.warp.square_to_uniform_sphere(sampler.next_2d())
            f = bsdf.eval(ctx, si3, d) * (4 * math.pi)
            integral = [scalar(dr.mean(f[c])) for c in range(3)]
            sigma = [(scalar(dr.mean(dr.square(f[c] - integral[c]))) / k) ** 0.5 for c in range(3)]
            albedo.append({"wi": [cos_i * 0.6, sin_i, cos_i * 0.8], "sampler_mean": mean, "integral": integral,
                           "integral_sigma": sigma})
        case["albedo"] = albedo
        out["cases"].append(case)
    here = os.path.dirname(os.path.abspath(__file__))
    with open(os.path.join(here, "mitsuba_bsdf.json"), "w") as f:
        json.dump(out, f)


if __name__ == "__main__":
    main()

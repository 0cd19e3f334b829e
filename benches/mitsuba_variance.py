#!/usr/bin/env python3
"""Mitsuba 3's image-gradient variance (``prb``, ``prb_basic``) next to ``pathgrad variance``.

This is a measurement tool for people, not part of CI and not a test: nothing here is asserted on.
It follows the image-gradient protocol of ALGORITHMS.md §7.4 on the Mitsuba side: for seeds
0 .. R-1 it renders the forward-mode image gradient dI/dθ (tangent 1 on the parameter,
``integrator.render_forward``) with the given integrators, then per pixel and channel takes the
sample variance over the R images (divisor R - 1, as ``pathgrad variance``), and reports its mean
over pixels and channels. The variance and mean-gradient maps are written as EXRs.

With ``--pathgrad DIR`` (the ``-o`` directory of a ``pathgrad variance`` run on the same scene,
parameter, size and spp) it also reads pathgrad's ``variance-*.exr`` and ``mean-*.exr`` and prints,
for every pair, the variance ratio and a check that the two mean gradients agree within noise: per
channel the image sum of the mean gradient with its standard error sqrt(sum_p var_p / R) (pixels
are independent in both renderers), the z-score of the difference, and the mean over pixels of the
squared per-pixel z-score (about 1 when the means agree; heavy-tailed estimators push it a little
either way). A film-size, field-of-view or parameter mistake shows up as large z.

Install (Debian 12; Mitsuba from PyPI into a venv outside the repository):

    python3 -m venv /tmp/mi && /tmp/mi/bin/pip install mitsuba numpy
    apt-get install libllvm19
    export DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1

Older releases install the same way (``pip install mitsuba==3.6.4`` into another venv). The release
matters for a ``blendbsdf`` parameter: up to 3.7.1 ``blendbsdf``'s sample() returns the selected
child's density and weight (3.8.0 on: the mixture's), and up to 3.6.4 ``prb``/``prb_basic`` divide
the re-evaluated BSDF derivative by the detached product weight x density of that sample (3.7.0 on:
by the detached re-evaluated BSDF value itself). With both old behaviours (3.6.x, and the Mitsuba
fork of Su & Gkioulekas 2024) a diffuse-child sample in the specular lobe divides the specular
derivative by the diffuse child's value alone; up to 3.7.1 the BSDF-sampling MIS weight also uses
the child's density while NEE uses the mixture's, which biases the NEE estimate.

Example, from the repository root:

    pathgrad variance scenes/blend/blend.xml --param object.weight.value --runs 64 --spp 2 \\
        --width 64 -o /tmp/pv-blend
    /tmp/mi/bin/python benches/mitsuba_variance.py scenes/blend/blend.xml \\
        --param ball.bsdf.weight.value --runs 64 --spp 2 --width 64 --pathgrad /tmp/pv-blend

Mitsuba names a BSDF nested in a shape after the shape (``ball.bsdf.weight.value``); pathgrad uses
the BSDF's id (``object.weight.value``): ``--list-params`` prints Mitsuba's keys, ``pathgrad
params SCENE`` pathgrad's.
"""

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

from mitsuba_film import resize_film  # benches/, beside this script

RR_DEPTH = 5  # Mitsuba's default, which pathgrad also uses


def parse_args():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("scene", help="Mitsuba 3 XML scene")
    p.add_argument("--param", help="Mitsuba parameter key (mi.traverse)")
    p.add_argument("-D", "--define", action="append", default=[], help="scene default NAME=VALUE (repeatable)")
    p.add_argument("--integrator", default="prb,prb_basic", help="comma-separated Mitsuba AD integrators")
    p.add_argument("--runs", type=int, default=32)
    p.add_argument("--seed", type=int, default=0, help="first seed; runs use seed .. seed + runs - 1")
    p.add_argument("--spp", type=int, default=2)
    p.add_argument("--width", type=int, default=64)
    p.add_argument("--height", type=int, help="default: keeps the film's aspect (as pathgrad --width)")
    p.add_argument("--max-depth", type=int, default=6)
    p.add_argument("--rr-depth", type=int, default=RR_DEPTH)
    p.add_argument("--variant", default="llvm_ad_rgb")
    p.add_argument("--pathgrad", help="a `pathgrad variance -o` directory to compare against")
    p.add_argument("--fd-check", type=float, metavar="H",
                   help="also compare the image-sum gradient with a central difference of step H "
                        "(same seeds both sides, 16 x spp)")  # fmt: skip
    p.add_argument("-o", "--output", help="directory for Mitsuba's variance/mean EXRs and summary.json")
    p.add_argument("--json", action="store_true", help="print one JSON line instead of the table")
    p.add_argument("--list-params", action="store_true", help="print Mitsuba's parameter keys and exit")
    return p.parse_args()


class Setup:
    def __init__(self, args):
        import drjit as dr
        import mitsuba as mi

        self.dr, self.mi, self.args = dr, mi, args
        mi.set_variant(args.variant)
        defines = dict(d.split("=", 1) for d in args.define)
        self.scene = mi.load_file(args.scene, **defines)
        self.params = mi.traverse(self.scene)
        if args.list_params:
            for key in self.params.keys():
                print(key)
            sys.exit(0)
        if args.param not in self.params:
            sys.exit(f"no Mitsuba parameter {args.param!r}; --list-params prints them")
        self.width, self.height = resize_film(self.mi, self.params, args.width, args.height)
        self.key = args.param
        self.value0 = type(self.params[self.key])(self.params[self.key])

    def integrator(self, name):
        return self.mi.load_dict({"type": name, "max_depth": self.args.max_depth, "rr_depth": self.args.rr_depth})

    def gradient(self, integrator, seed, spp):
        """Forward-mode dI/dθ, tangent 1 on every component of the parameter, as an (H, W, C) array."""
        dr = self.dr
        theta = type(self.value0)(self.value0)
        dr.enable_grad(theta)
        self.params[self.key] = theta
        self.params.update()
        dr.forward(theta, dr.ADFlag.ClearEdges)
        grad = integrator.render_forward(self.scene, params=self.params, seed=seed, spp=spp)
        out = np.array(grad, dtype=np.float64)
        self.params[self.key] = type(self.value0)(self.value0)  # detached again
        self.params.update()
        return out

    def primal_sum(self, integrator, value, seed, spp):
        self.params[self.key] = type(self.value0)(value)
        self.params.update()
        img = np.array(self.mi.render(self.scene, integrator=integrator, seed=seed, spp=spp), dtype=np.float64)
        self.params[self.key] = type(self.value0)(self.value0)
        self.params.update()
        return img.reshape(-1, img.shape[-1]).sum(axis=0)

    def write_exr(self, path, arr):
        self.mi.Bitmap(arr.astype(np.float32)).write(str(path))

    def read_exr(self, path):
        return np.array(self.mi.Bitmap(str(path)), dtype=np.float64)


def stats(images):
    stack = np.stack(images)  # (R, H, W, C)
    mean = stack.mean(axis=0)
    var = stack.var(axis=0, ddof=1)
    per_pixel = var.mean(axis=-1)
    flat = np.sort(per_pixel.ravel())[::-1]
    top = max(1, len(flat) // 100)
    return {
        "mean": mean,
        "variance": var,
        "mean_variance": float(var.mean()),
        "median_pixel_variance": float(np.median(per_pixel)),
        "top1pct_variance_share": float(flat[:top].sum() / max(flat.sum(), 1e-300)),
        "max_abs_gradient": float(np.abs(stack).max()),
    }


def agreement(mean_a, var_a, runs_a, mean_b, var_b, runs_b):
    """Mean gradients of two unbiased estimators: image-sum z per channel, mean per-pixel z^2."""
    s_a, s_b = mean_a.sum(axis=(0, 1)), mean_b.sum(axis=(0, 1))
    se = np.sqrt(var_a.sum(axis=(0, 1)) / runs_a + var_b.sum(axis=(0, 1)) / runs_b)
    z_sum = (s_a - s_b) / np.where(se > 0, se, np.nan)
    den = var_a / runs_a + var_b / runs_b
    ok = den > 0
    z2 = float(np.mean(np.square(mean_a - mean_b)[ok] / den[ok])) if ok.any() else float("nan")
    return {"sum_a": s_a.tolist(), "sum_b": s_b.tolist(), "sum_se": se.tolist(), "z_sum": z_sum.tolist(),
            "mean_z2": z2, "pixels": int(ok.sum())}  # fmt: skip


def main():
    args = parse_args()
    setup = Setup(args)
    dr, mi = setup.dr, setup.mi
    out_dir = Path(args.output) if args.output else None
    if out_dir:
        out_dir.mkdir(parents=True, exist_ok=True)
    llvm = ""
    if args.variant.startswith("llvm"):
        v = dr.detail.llvm_version()
        llvm = ", LLVM " + (v if isinstance(v, str) else ".".join(map(str, v)))
    header = {
        "scene": str(Path(args.scene).resolve()), "param": args.param, "defines": args.define,
        "mitsuba": mi.__version__, "drjit": dr.__version__, "variant": args.variant + llvm,
        "width": setup.width, "height": setup.height, "spp": args.spp, "runs": args.runs,
        "seeds": [args.seed, args.seed + args.runs - 1], "max_depth": args.max_depth, "rr_depth": args.rr_depth,
    }  # fmt: skip
    if not args.json:
        print(json.dumps(header))

    results = {}
    for name in [s.strip() for s in args.integrator.split(",") if s.strip()]:
        integrator = setup.integrator(name)
        t0 = time.perf_counter()
        setup.gradient(integrator, 10_000, args.spp)  # warm-up: kernel compilation / cache load
        t_warm = time.perf_counter() - t0
        images, t0 = [], time.perf_counter()
        for i in range(args.runs):
            images.append(setup.gradient(integrator, args.seed + i, args.spp))
        r = stats(images)
        r["seconds_per_estimate"] = (time.perf_counter() - t0) / args.runs
        r["warmup_s"] = t_warm
        if args.fd_check:
            h, spp_fd = args.fd_check, 16 * args.spp
            v = float(np.ravel(np.array(setup.value0))[0])
            fd = [(setup.primal_sum(integrator, v + h, s, spp_fd) - setup.primal_sum(integrator, v - h, s, spp_fd)) / (2 * h)
                  for s in range(args.seed, args.seed + 8)]  # fmt: skip
            fd = np.array(fd)
            r["fd_image_sum"] = fd.mean(axis=0).tolist()
            r["fd_image_sum_se"] = (fd.std(axis=0, ddof=1) / math.sqrt(len(fd))).tolist()
        if out_dir:
            setup.write_exr(out_dir / f"variance-{name}.exr", r["variance"])
            setup.write_exr(out_dir / f"mean-{name}.exr", r["mean"])
        results[name] = r

    pathgrad = {}
    if args.pathgrad:
        pg_dir = Path(args.pathgrad)
        summary = json.loads((pg_dir / "summary.json").read_text())
        runs_pg = summary["runs"]
        if (summary["width"], summary["height"], summary["spp"]) != (setup.width, setup.height, args.spp):
            print(f"warning: pathgrad ran {summary['width']}x{summary['height']} at {summary['spp']} spp", file=sys.stderr)
        for t in summary["techniques"]:
            var_path = next(Path(o) for o in t["outputs"] if Path(o).name.startswith("variance-") and o.endswith(".exr"))
            mean_path = next(Path(o) for o in t["outputs"] if Path(o).name.startswith("mean-") and o.endswith(".exr"))
            var = setup.read_exr(pg_dir / var_path.name)
            mean = setup.read_exr(pg_dir / mean_path.name)
            entry = {"technique": t["technique"], "nee": summary["nee"], "runs": runs_pg,
                     "mean_variance": float(var.mean()), "reported_variance": t["variance"],
                     "median_pixel_variance": float(np.median(var.mean(axis=-1))),
                     "image_sum": mean.sum(axis=(0, 1)).tolist(), "vs": {}}  # fmt: skip
            for name, r in results.items():
                entry["vs"][name] = {"variance_ratio_mitsuba_over_pathgrad": r["mean_variance"] / entry["mean_variance"],
                                     **agreement(r["mean"], r["variance"], args.runs, mean, var, runs_pg)}  # fmt: skip
            pathgrad[t["technique"]] = entry

    report = dict(header)
    report["mitsuba_results"] = {n: {k: v for k, v in r.items() if k not in ("mean", "variance")} | {
        "image_sum": r["mean"].sum(axis=(0, 1)).tolist(),
        "image_sum_se": np.sqrt(r["variance"].sum(axis=(0, 1)) / args.runs).tolist()} for n, r in results.items()}  # fmt: skip
    report["pathgrad"] = pathgrad
    if out_dir:
        (out_dir / "summary.json").write_text(json.dumps(report, indent=1))
    if args.json:
        print(json.dumps(report))
        return

    print(f"\n{'estimator':<22} {'mean var':>11} {'median px var':>13} {'top1% share':>11} {'max |g|':>10} {'s/est':>7}  image-sum gradient (± SE)")  # fmt: skip
    for n, r in report["mitsuba_results"].items():
        sums = ", ".join(f"{s:.4g}±{e:.2g}" for s, e in zip(r["image_sum"], r["image_sum_se"]))
        print(f"{'mitsuba ' + n:<22} {r['mean_variance']:>11.4g} {r['median_pixel_variance']:>13.4g} "
              f"{r['top1pct_variance_share']:>11.3f} {r['max_abs_gradient']:>10.3g} {r['seconds_per_estimate']:>7.3f}  {sums}")  # fmt: skip
        if "fd_image_sum" in r:
            print(f"{'':<22} central difference of the image sum: "
                  + ", ".join(f"{s:.4g}±{e:.2g}" for s, e in zip(r["fd_image_sum"], r["fd_image_sum_se"])))  # fmt: skip
    for tech, e in pathgrad.items():
        sums = ", ".join(f"{s:.4g}" for s in e["image_sum"])
        print(f"{'pathgrad ' + tech + (' nee' if e['nee'] else ' no-nee'):<22} {e['mean_variance']:>11.4g} "
              f"{e['median_pixel_variance']:>13.4g} {'':>11} {'':>10} {'':>7}  {sums}")  # fmt: skip
    for tech, e in pathgrad.items():
        for n, v in e["vs"].items():
            z = ", ".join(f"{x:+.2f}" for x in v["z_sum"])
            print(f"mitsuba {n} / pathgrad {tech}: variance ratio {v['variance_ratio_mitsuba_over_pathgrad']:.3g}; "
                  f"image-sum z [{z}], mean per-pixel z^2 {v['mean_z2']:.2f}")  # fmt: skip


if __name__ == "__main__":
    main()

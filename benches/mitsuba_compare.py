#!/usr/bin/env python3
"""Mitsuba 3 `prb` (`prbvolpath` with media) next to pathgrad on the same XML scene: timings, losses, gradients, mean radiance.

This is a benchmarking tool for people, not part of CI and not a test: nothing here is asserted on.
For each seed it

  * renders the primal image in both renderers and reports its time and mean radiance per channel;
  * renders a target with one parameter changed (``--target-value``) at pathgrad's target spp rule,
    max(4 x spp, 64), with an independent seed, each renderer with its own target;
  * takes the loss (``l2`` or ``relmse``, pathgrad's definitions: mean over all W x H x 3 values of
    (I - T)^2 or ((I - T) / (T + 1e-3))^2) and its gradient by the parameter: Mitsuba with the
    ``prb`` integrator (``dr.enable_grad`` + ``mi.render`` + ``dr.backward``), pathgrad with
    ``pathgrad grad SCENE --target-set NAME=VALUE --param NAME --json``.

The two renderers use different random numbers, so their figures agree only within noise: the
summary gives mean +- standard error over the seeds, and the difference in units of its standard
error.

Timing notes. Mitsuba's LLVM backend runs kernels asynchronously; every timed span ends with
``dr.sync_thread()``. One warm-up primal + gradient step runs first so the Mitsuba figures exclude
kernel compilation (its kernel cache in ~/.drjit also persists between runs). pathgrad is timed by
its own ``time_s`` in fresh processes, so its figures include the shader compilation of that process
(on lavapipe a fraction of a second per kernel). ``pathgrad grad --target-set`` renders its target
inside its timed span, so the gradient step (primal + fused adjoint) is timed by a second
``pathgrad grad --target PRIMAL.exr --seed SEED+1`` against the seed's primal render (whose loss
and gradient are not reported); the ``--target-set`` run's full time is printed too.

Install (Debian 12; Mitsuba from PyPI into a venv outside the repository):

    python3 -m venv /tmp/mi && /tmp/mi/bin/pip install mitsuba drjit numpy
    apt-get install libllvm19          # LLVM for Dr.Jit's LLVM backend (Mesa's libLLVM-15 also works)
    export DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1
    cargo build --release              # the pathgrad binary, target/release/pathgrad

Run from the repository root:

    /tmp/mi/bin/python benches/mitsuba_compare.py --width 128 --height 128 --spp 16 --max-depth 6

Parameter names are Mitsuba's ``mi.traverse`` keys; pathgrad's XML loader uses the same names
(``sphere.bsdf.alpha.value``), see ``pathgrad params SCENE``; ``--pathgrad-param`` overrides.
"""

import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from mitsuba_film import resize_film  # benches/, beside this script

REPO = Path(__file__).resolve().parent.parent
# pathgrad's `grad --target-set` target: TARGET_SPP_FACTOR x spp, at least TARGET_MIN_SPP, seed + offset.
TARGET_SPP_FACTOR = 4
TARGET_MIN_SPP = 64
TARGET_SEED_OFFSET = 0x5EED
# Mitsuba's default `rr_depth`, which pathgrad also uses.
RR_DEPTH = 5
REL_MSE_EPSILON = 1e-3


def parse_args():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("scene", nargs="?", default="scenes/cornell-box/cornell-box.xml", help="Mitsuba 3 XML scene")
    p.add_argument("--param", default="sphere.bsdf.alpha.value", help="Mitsuba parameter key (mi.traverse)")
    p.add_argument("--pathgrad-param", help="pathgrad's name for it (default: the same as --param)")
    p.add_argument("--target-value", default="0.4", help="the parameter's value in the target: V or R,G,B")
    p.add_argument("--width", type=int, default=128)
    p.add_argument("--height", type=int, default=128)
    p.add_argument("--spp", type=int, default=16)
    p.add_argument("--max-depth", type=int, default=6)
    p.add_argument("--loss", choices=["l2", "relmse"], default="l2")
    p.add_argument("--seeds", type=int, default=4, help="number of seeds (0, 1, ...) to average over")
    p.add_argument("--variant", default="llvm_ad_rgb", help="Mitsuba variant; scalar_rgb: no gradients")
    p.add_argument("--pathgrad", default=str(REPO / "target" / "release" / "pathgrad"), help="pathgrad binary")
    p.add_argument("--device", help="pathgrad --device (default: its own choice)")
    p.add_argument("--integrator", help="Mitsuba integrator (default: prb, or prbvolpath in a scene with media)")
    p.add_argument("--list-params", action="store_true", help="print Mitsuba's parameter keys and exit")
    return p.parse_args()


def mean_se(xs):
    if any(math.isnan(x) for x in xs):
        return math.nan, math.nan
    m = statistics.fmean(xs)
    se = statistics.stdev(xs) / math.sqrt(len(xs)) if len(xs) > 1 else float("nan")
    return m, se


def fmt(m, se, digits=4):
    return f"{m:.{digits}g} ± {se:.2g}"


# ----------------------------------------------------------------------------------------------
# Mitsuba


class MitsubaSide:
    def __init__(self, args):
        import drjit as dr
        import mitsuba as mi

        self.dr, self.mi = dr, mi
        mi.set_variant(args.variant)
        self.args = args
        self.ad = "_ad_" in args.variant
        self.scene = mi.load_file(args.scene)
        self.params = mi.traverse(self.scene)
        if args.list_params:
            for key in self.params.keys():
                print(key)
            sys.exit(0)
        resize_film(self.mi, self.params, args.width, args.height)
        # prb exists in the AD variants only; `path` is the same primal estimator. A scene with a
        # participating medium takes their volumetric twins, prbvolpath and volpath.
        media = any(".interior_medium." in key for key in self.params.keys())
        default = {(False, True): "prb", (False, False): "path", (True, True): "prbvolpath", (True, False): "volpath"}
        self.integrator_type = args.integrator or default[(media, self.ad)]
        self.integrator = mi.load_dict(
            {"type": self.integrator_type, "max_depth": args.max_depth, "rr_depth": RR_DEPTH}
        )
        self.key = args.param
        if self.key not in self.params:
            sys.exit(f"no Mitsuba parameter {self.key!r}; --list-params prints them")
        self.original = type(self.params[self.key])(self.params[self.key])
        values = [float(v) for v in args.target_value.split(",")]
        self.target_value = type(self.original)(*values)

    def _render(self, spp, seed, params=None):
        img = self.mi.render(self.scene, params, integrator=self.integrator, spp=spp, seed=seed)
        self.dr.eval(img)
        self.dr.sync_thread()
        return img

    def _set(self, value):
        self.params[self.key] = type(self.original)(value)
        self.params.update()

    def loss(self, img, target):
        dr = self.dr
        diff = img - target
        if self.args.loss == "relmse":
            diff = diff / (target + REL_MSE_EPSILON)
        return dr.mean(dr.square(diff), axis=None)

    def run(self, seed):
        dr, args = self.dr, self.args
        target_spp = max(TARGET_SPP_FACTOR * args.spp, TARGET_MIN_SPP)
        self._set(self.target_value)
        target = self._render(target_spp, seed + TARGET_SEED_OFFSET)
        self._set(self.original)

        t0 = time.perf_counter()
        primal = self._render(args.spp, seed)
        t_primal = time.perf_counter() - t0
        mean = [float(v) for v in primal.numpy().reshape(-1, 3).astype("float64").mean(axis=0)]

        if not self.ad:  # scalar_* variants: primal only
            nan = float("nan")
            loss = self.loss(primal, target)
            return {"primal_s": t_primal, "step_s": nan, "adjoint_s": nan, "loss": float(loss.array[0]),
                    "grad": [], "mean": mean}  # fmt: skip

        value = self.params[self.key]
        dr.enable_grad(value)
        self.params.update()
        t0 = time.perf_counter()
        img = self._render(args.spp, seed, self.params)
        t_render = time.perf_counter() - t0
        loss = self.loss(img, target)
        dr.backward(loss)
        grad = dr.grad(value)
        dr.eval(grad)
        dr.sync_thread()
        t_step = time.perf_counter() - t0
        dr.disable_grad(value)
        self._set(self.original)
        return {
            "primal_s": t_primal,
            "step_s": t_step,
            "adjoint_s": t_step - t_render,
            "loss": float(loss.array[0]),
            "grad": [float(v) for v in dr.ravel(grad)],
            "mean": mean,
        }


# ----------------------------------------------------------------------------------------------
# pathgrad


class PathgradSide:
    def __init__(self, args, tmp):
        self.args, self.tmp = args, Path(tmp)
        self.name = args.pathgrad_param or args.param
        if not Path(args.pathgrad).is_file():
            sys.exit(f"no pathgrad binary at {args.pathgrad}: cargo build --release")
        self.flags = [
            "--width", str(args.width), "--height", str(args.height), "--max-depth", str(args.max_depth),
        ]  # fmt: skip
        if args.device:
            self.flags += ["--device", args.device]

    def _json(self, cmd):
        out = subprocess.run(cmd, check=False, cwd=REPO, capture_output=True, text=True)
        if out.returncode != 0:
            sys.exit(f"{' '.join(cmd)} failed:\n{out.stderr}")
        return json.loads(out.stdout.strip().splitlines()[-1])

    def render(self, spp, seed):
        out = self.tmp / "pathgrad.exr"
        cmd = [self.args.pathgrad, "render", self.args.scene, "-o", str(out), "--no-preview", "--json",
               "--spp", str(spp), "--seed", str(seed), *self.flags]  # fmt: skip
        return self._json(cmd)

    def grad(self, seed, target):
        args = self.args
        cmd = [args.pathgrad, "grad", args.scene, *target, "--param", self.name, "--loss", args.loss,
               "--spp", str(args.spp), "--seed", str(seed), "--json", *self.flags]  # fmt: skip
        return self._json(cmd)

    def run(self, seed):
        args = self.args
        primal = self.render(args.spp, seed)
        grad = self.grad(seed, ["--target-set", f"{self.name}={args.target_value}"])
        # The same step against a ready target (this seed's primal image; another seed, so the
        # adjoint image is not zero): its time_s is the primal + fused adjoint alone.
        step = self.grad(seed + 1, ["--target", primal["outputs"][0]])
        return {
            "primal_s": primal["time_s"],
            "step_s": step["time_s"],
            "grad_cli_s": grad["time_s"],
            "loss": grad["loss"],
            "grad": grad["gradients"][self.name],
            "mean": primal["mean"],
            "device": primal["device"],
        }


# ----------------------------------------------------------------------------------------------


def main():
    args = parse_args()
    if not Path(args.scene).exists():  # relative to the repository, as the default
        args.scene = str(REPO / args.scene)
    args.scene = str(Path(args.scene).resolve())
    mit = MitsubaSide(args)
    import drjit as dr
    import mitsuba as mi

    llvm = ""
    if args.variant.startswith("llvm"):
        llvm = ", LLVM " + ".".join(map(str, dr.detail.llvm_version()))
    print(f"scene {os.path.relpath(args.scene, REPO)}, {args.width}×{args.height}, {args.spp} spp, "
          f"max depth {args.max_depth}, rr depth {RR_DEPTH}, loss {args.loss}, "
          f"d/d {args.param} at target value {args.target_value}, "
          f"target spp {max(TARGET_SPP_FACTOR * args.spp, TARGET_MIN_SPP)}, {args.seeds} seeds")  # fmt: skip
    print(f"Mitsuba {mi.__version__} (drjit {dr.__version__}), variant {args.variant}{llvm}, "
          f"integrator {mit.integrator_type}")  # fmt: skip

    t0 = time.perf_counter()
    mit.run(10_000)  # warm-up: compiles (or loads from the cache) the primal and adjoint kernels
    print(f"Mitsuba warm-up step (kernel compilation or cache load): {time.perf_counter() - t0:.2f} s")

    with tempfile.TemporaryDirectory(prefix="mitsuba_compare") as tmp:
        pg = PathgradSide(args, tmp)
        rows = {"mitsuba": [], "pathgrad": []}
        print(f"\n{'seed':>4} {'renderer':>9} {'primal s':>9} {'step s':>8} {'loss':>12} {'gradient':>28}  mean RGB")
        for seed in range(args.seeds):
            for name, side in (("mitsuba", mit), ("pathgrad", pg)):
                r = side.run(seed)
                rows[name].append(r)
                g = ", ".join(f"{v:.5g}" for v in r["grad"])
                m = ", ".join(f"{v:.5f}" for v in r["mean"])
                print(f"{seed:>4} {name:>9} {r['primal_s']:>9.3f} {r['step_s']:>8.3f} {r['loss']:>12.5e} "
                      f"{'[' + g + ']':>28}  [{m}]", flush=True)  # fmt: skip
        print(f"pathgrad device: {rows['pathgrad'][0]['device']}")

    print(f"\nsummary, mean ± standard error over {args.seeds} seeds; "
          "z = (pathgrad − Mitsuba) / SE of the difference")  # fmt: skip
    print(f"{'':<26} {'Mitsuba ' + mit.integrator_type:>22} {'pathgrad':>22} {'z':>7}")

    def line(label, a, b, digits=4, z=True):
        (ma, sa), (mb, sb) = mean_se(a), mean_se(b)
        zs = f"{(mb - ma) / math.hypot(sa, sb):>7.2f}" if z and math.hypot(sa, sb) > 0 else ""
        print(f"{label:<26} {fmt(ma, sa, digits):>22} {fmt(mb, sb, digits):>22} {zs}")

    M, P = rows["mitsuba"], rows["pathgrad"]
    line("primal time (s)", [r["primal_s"] for r in M], [r["primal_s"] for r in P], 3, z=False)
    line("gradient step time (s)", [r["step_s"] for r in M], [r["step_s"] for r in P], 3, z=False)
    line("loss", [r["loss"] for r in M], [r["loss"] for r in P])
    for i in range(len(P[0]["grad"])):
        line(f"gradient[{i}]", [r["grad"][i] if r["grad"] else math.nan for r in M], [r["grad"][i] for r in P])
    for c, ch in enumerate("RGB"):
        line(f"mean radiance {ch}", [r["mean"][c] for r in M], [r["mean"][c] for r in P], 5)
    print(f"Mitsuba step: mi.render + dr.backward (dr.backward alone {mean_se([r['adjoint_s'] for r in M])[0]:.3f} s). "
          f"pathgrad step: time_s of `grad --target PRIMAL.exr`; the `grad --target-set` runs took "
          f"{mean_se([r['grad_cli_s'] for r in P])[0]:.3f} s with their target render.")
    print("The loss includes each renderer's own image and target variance, so only the gradients and the "
          "means are expected to agree.")  # fmt: skip

if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""Speed of pathgrad next to Mitsuba 3 (LLVM backend) on one XML scene: primal, gradient step, cold start.

This is a benchmarking tool for people (issue 11, "Fast kernels"), not part of CI and not a test:
nothing here is asserted on. In one run, with the repetitions INTERLEAVED (pathgrad, Mitsuba,
pathgrad, Mitsuba, ...) so that drift of the machine hits both alike, it times

  * primal: ``pathgrad render SCENE --width W --height H --spp S --max-depth D --json`` as a whole
    process (wall clock: Vulkan start-up, scene load, BVH build, pipeline creation, render, EXR
    write) and by its own ``time_s`` (the render, including the creation of the pipelines it uses,
    which pathgrad builds on first use: a lavapipe compile, or a load from Mesa's shader cache in
    $XDG_CACHE_HOME), against Mitsuba's ``mi.render`` with the
    ``path`` integrator (``--mitsuba-primal`` changes it) ending in ``dr.sync_thread()``, in this
    process after a warm-up (kernel compilation excluded for Mitsuba: its kernel cache in ~/.drjit
    persists between runs anyway). Samples per second W*H*S of each and the throughput ratio.
  * gradient step (render + relative-MSE loss + backward): ``pathgrad grad SCENE --target T.exr
    --param P --loss relmse --json`` (whole process, and its ``time_s``: render, loss and fused
    adjoint and their pipelines' creation, without the target's load) against Mitsuba's ``prb`` (``dr.enable_grad`` on the
    parameter, ``mi.render``, loss mean(((I - T) / (T + 1e-3))^2) over all W*H*3 values,
    ``dr.backward``, ``dr.sync_thread()``). Each renderer has its own target, rendered once before
    the timings with the parameter at ``--target-value``, max(4 x spp, 64) spp and seed 0x5EED
    (pathgrad's ``--target-set`` rule): pathgrad's with ``pathgrad render -D NAME=VALUE``, where
    ``--target-define NAME`` is the scene's ``<default>`` that sets the parameter (``alpha`` in the
    sphere scene), Mitsuba's through ``mi.traverse``. With ``--target-define ''`` pathgrad uses
    Mitsuba's target, written as EXR.
  * cold first gradient: the same gradient at ``--cold-width`` x ``--cold-height`` (64 x 64),
    ``--cold-spp`` (1) spp, as a whole fresh process with empty caches: ``pathgrad grad`` with a new
    empty ``HOME`` and ``XDG_CACHE_HOME`` (lavapipe's shader cache lives there), and a fresh Python
    process that imports Mitsuba, loads the scene and takes the gradient with a new empty ``HOME``
    (so ~/.drjit has no kernels). Then "warm": a second such process with the same, now filled,
    cache directory. Its own ``time_s`` (pathgrad) or in-process step time (Mitsuba) is shown too.

Each timed pathgrad process also renders (steps) ``--repeat`` more times with ``--repeat``; the
median of those is the "steady" figure: throughput in a process whose kernels are built, which is
what Mitsuba's warm in-process timings measure (and what an engine or a batch job sees after its
first frame). The whole-process and ``time_s`` figures are kept beside it.

Whole-process CPU time (user + system, all threads) is recorded beside every wall time: on a
machine with few cores it shows how much of the wall time is parallel work. Every figure is the
median over ``--runs`` repetitions (``--cold-runs`` for the cold part); ``--json`` prints every
sample as well.

Install (Debian 12; Mitsuba from PyPI into a venv outside the repository):

    python3 -m venv /tmp/mi && /tmp/mi/bin/pip install mitsuba==3.9.1 numpy
    apt-get install libllvm19          # LLVM for Dr.Jit's LLVM backend
    export DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1   # (set by this script if unset)
    cargo build --release              # the pathgrad binary, target/release/pathgrad

Run from the repository root (defaults: the paper's sphere scene, 256 x 256, 16 spp, max depth 6,
d/d diff_bsdf.alpha.value against a target at alpha 0.3, 3 runs):

    /tmp/mi/bin/python benches/mitsuba_speed.py
    /tmp/mi/bin/python benches/mitsuba_speed.py --runs 5 --json > speed.json

The default scene is benches/scenes/sphere/sphere.xml (Su & Gkioulekas 2024's sphere scene; see
its header for the source, licence and changes). Any other scene needs ``--param`` (Mitsuba's
``mi.traverse`` key; ``--pathgrad-param`` if pathgrad's name differs, see ``pathgrad params
SCENE``) and ``--target-define`` (or ``''``).
"""

import argparse
import json
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from mitsuba_film import resize_film  # benches/, beside this script

REPO = Path(__file__).resolve().parent.parent
DEFAULT_SCENE = "benches/scenes/sphere/sphere.xml"
# pathgrad's `grad --target-set` target: TARGET_SPP_FACTOR x spp, at least TARGET_MIN_SPP, this seed.
TARGET_SPP_FACTOR = 4
TARGET_MIN_SPP = 64
TARGET_SEED = 0x5EED
RR_DEPTH = 5  # Mitsuba's default, which pathgrad also uses
REL_MSE_EPSILON = 1e-3  # pathgrad's relmse: ((I - T) / (T + eps))^2
LLVM_CANDIDATES = [
    "/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1",
    "/usr/lib/x86_64-linux-gnu/libLLVM-19.so",
    "/usr/lib/x86_64-linux-gnu/libLLVM-15.so.1",
]


def default_llvm():
    """Dr.Jit reads DRJIT_LIBLLVM_PATH when its LLVM backend starts: set it before importing."""
    if "DRJIT_LIBLLVM_PATH" not in os.environ:
        for path in LLVM_CANDIDATES:
            if Path(path).exists():
                os.environ["DRJIT_LIBLLVM_PATH"] = path
                break


def parse_args():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("scene", nargs="?", default=DEFAULT_SCENE, help="Mitsuba 3 XML scene")
    p.add_argument("--width", type=int, default=256)
    p.add_argument("--height", type=int, default=256)
    p.add_argument("--spp", type=int, default=16)
    p.add_argument("--max-depth", type=int, default=6, help="surface interactions per path; -1: unbounded")
    p.add_argument("--runs", type=int, default=3, help="repetitions of each timing (interleaved)")
    p.add_argument("--repeat", type=int, default=2,
                   help="pathgrad's --repeat: renders (steps) after the first in each timed process; their "
                        "median is the steady figure, without the process's kernel builds (0: none)")  # fmt: skip
    p.add_argument("--cold-runs", type=int, help="repetitions of the cold/warm processes (default: --runs)")
    p.add_argument("--cold-width", type=int, default=64)
    p.add_argument("--cold-height", type=int, default=64)
    p.add_argument("--cold-spp", type=int, default=1)
    p.add_argument("--param", default="diff_bsdf.alpha.value", help="Mitsuba parameter key (mi.traverse)")
    p.add_argument("--pathgrad-param", help="pathgrad's name for it (default: the same as --param)")
    p.add_argument("--target-value", default="0.3", help="the parameter's value in the targets: V or R,G,B")
    p.add_argument("--target-define", default="alpha",
                   help="the scene <default> that sets the parameter, for pathgrad render -D NAME=VALUE; "
                        "'' = give pathgrad Mitsuba's target")  # fmt: skip
    p.add_argument("--parts", default="primal,grad,cold", help="comma-separated subset of primal,grad,cold")
    p.add_argument("--variant", default="llvm_ad_rgb", help="Mitsuba variant (an _ad_ one: gradients)")
    p.add_argument("--mitsuba-primal", default="path", help="Mitsuba integrator for the primal timing")
    p.add_argument("--pathgrad", default=str(REPO / "target" / "release" / "pathgrad"), help="pathgrad binary")
    p.add_argument("--device", help="pathgrad --device (default: its own choice, or PATHGRAD_DEVICE)")
    p.add_argument("--json", action="store_true", help="print one JSON object (every sample) instead of the table")
    p.add_argument("--_worker", help=argparse.SUPPRESS)  # a fresh Mitsuba process of the cold part
    args = p.parse_args()
    args.parts = set(filter(None, args.parts.split(",")))
    if args.parts - {"primal", "grad", "cold"}:
        p.error(f"unknown --parts {sorted(args.parts - {'primal', 'grad', 'cold'})}")
    if args.cold_runs is None:
        args.cold_runs = args.runs
    return args


def log(*a):
    print(*a, file=sys.stderr, flush=True)


def median(xs):
    xs = [x for x in xs if x is not None]
    return statistics.median(xs) if xs else float("nan")


def children_cpu():
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def run_process(cmd, env=None):
    """Runs cmd to completion; returns (wall s, CPU s of the process and its threads, last stdout line as JSON)."""
    cpu0, t0 = children_cpu(), time.perf_counter()
    out = subprocess.run(cmd, cwd=REPO, env=env, capture_output=True, text=True, check=False)
    wall, cpu = time.perf_counter() - t0, children_cpu() - cpu0
    if out.returncode != 0:
        sys.exit(f"{' '.join(map(str, cmd))} failed (status {out.returncode}):\n{out.stderr}")
    lines = out.stdout.strip().splitlines()
    if not lines:
        sys.exit(f"{' '.join(map(str, cmd))} printed nothing:\n{out.stderr}")
    return wall, cpu, json.loads(lines[-1])


def fresh_env(home):
    """The environment with HOME (and XDG_CACHE_HOME) in a new, empty directory."""
    env = dict(os.environ)
    env["HOME"] = str(home)
    env["XDG_CACHE_HOME"] = str(Path(home) / ".cache")
    return env


def tree_bytes(path):
    return sum(f.stat().st_size for f in Path(path).rglob("*") if f.is_file())


# ----------------------------------------------------------------------------------------------
# Mitsuba


class Mitsuba:
    """A loaded scene at one film size, with a `path` (or --mitsuba-primal) and a `prb` integrator."""

    def __init__(self, scene, variant, width, height, max_depth, key, primal="path"):
        import drjit as dr
        import mitsuba as mi

        self.dr, self.mi = dr, mi
        mi.set_variant(variant)
        if "_ad_" not in variant:
            sys.exit(f"variant {variant} has no automatic differentiation: use an _ad_ variant")
        self.scene = mi.load_file(str(scene))
        self.params = mi.traverse(self.scene)
        resize_film(mi, self.params, width, height)
        self.key = key
        if key not in self.params:
            sys.exit(f"no Mitsuba parameter {key!r}; keys: {', '.join(self.params.keys())}")
        self.original = type(self.params[key])(self.params[key])
        self.primal_integrator = mi.load_dict({"type": primal, "max_depth": max_depth, "rr_depth": RR_DEPTH})
        self.prb = mi.load_dict({"type": "prb", "max_depth": max_depth, "rr_depth": RR_DEPTH})

    def set(self, value):
        """value: a list of floats, or None for the scene's own."""
        v = self.original if value is None else type(self.original)(*value)
        self.params[self.key] = type(self.original)(v)
        self.params.update()

    def render(self, spp, seed, integrator=None):
        dr, mi = self.dr, self.mi
        t0 = time.perf_counter()
        img = mi.render(self.scene, integrator=integrator or self.primal_integrator, spp=spp, seed=seed)
        dr.eval(img)
        dr.sync_thread()
        return time.perf_counter() - t0, img

    def target(self, value, spp, seed=TARGET_SEED):
        self.set(value)
        _, img = self.render(spp, seed)
        self.set(None)
        return img

    def grad_step(self, target, spp, seed):
        """render + relMSE + backward; returns (seconds, loss, gradient values)."""
        dr, mi = self.dr, self.mi
        self.set(None)
        value = self.params[self.key]
        dr.enable_grad(value)
        self.params.update()
        t0 = time.perf_counter()
        img = mi.render(self.scene, self.params, integrator=self.prb, spp=spp, seed=seed)
        loss = dr.mean(dr.square((img - target) / (target + REL_MSE_EPSILON)), axis=None)
        dr.backward(loss)
        grad = dr.grad(value)
        dr.eval(grad, loss)
        dr.sync_thread()
        seconds = time.perf_counter() - t0
        result = seconds, float(loss.array[0]), [float(v) for v in dr.ravel(grad)]
        dr.disable_grad(value)
        self.set(None)
        return result

    def versions(self):
        dr, mi = self.dr, self.mi
        llvm = ".".join(map(str, dr.detail.llvm_version())) if hasattr(dr.detail, "llvm_version") else "?"
        return {"mitsuba": mi.__version__, "drjit": dr.__version__, "llvm": llvm,
                "threads": dr.thread_count(), "libllvm": os.environ.get("DRJIT_LIBLLVM_PATH")}  # fmt: skip


def worker(config):
    """A fresh process's first gradient (the cold part): prints one JSON line with in-process times."""
    t_start = time.perf_counter()
    import numpy as np

    import drjit as dr  # noqa: F401  (import time counts)
    import mitsuba as mi  # noqa: F401

    t_import = time.perf_counter()
    c = json.loads(config)
    m = Mitsuba(c["scene"], c["variant"], c["width"], c["height"], c["max_depth"], c["key"])
    target = m.mi.TensorXf(np.load(c["target"]))
    t_load = time.perf_counter()
    step_s, loss, grad = m.grad_step(target, c["spp"], c["seed"])
    print(json.dumps({"import_s": t_import - t_start, "load_s": t_load - t_import, "step_s": step_s,
                      "total_s": time.perf_counter() - t_start, "loss": loss, "grad": grad,
                      "drjit_cache": str(Path.home() / ".drjit")}))  # fmt: skip


# ----------------------------------------------------------------------------------------------
# pathgrad


class Pathgrad:
    def __init__(self, args, tmp):
        self.args, self.tmp = args, Path(tmp)
        self.name = args.pathgrad_param or args.param
        if not Path(args.pathgrad).is_file():
            sys.exit(f"no pathgrad binary at {args.pathgrad}: cargo build --release")
        self.common = ["--max-depth", str(args.max_depth)] + (["--device", args.device] if args.device else [])

    def size(self, width, height, spp):
        return ["--width", str(width), "--height", str(height), "--spp", str(spp)]

    def render(self, width, height, spp, seed, out, defines=(), env=None, repeat=0):
        cmd = [self.args.pathgrad, "render", self.args.scene, "-o", str(out), "--no-preview", "--json",
               *self.size(width, height, spp), "--seed", str(seed), "--repeat", str(repeat), *self.common]  # fmt: skip
        for d in defines:
            cmd += ["-D", d]
        return run_process(cmd, env)

    def grad(self, width, height, spp, seed, target, env=None, repeat=0):
        cmd = [self.args.pathgrad, "grad", self.args.scene, "--target", str(target), "--param", self.name,
               "--loss", "relmse", "--json", *self.size(width, height, spp), "--seed", str(seed),
               "--repeat", str(repeat), *self.common]  # fmt: skip
        return run_process(cmd, env)


# ----------------------------------------------------------------------------------------------


def write_exr(mi, img, path):
    mi.Bitmap(img).write(str(path))


def main():
    args = parse_args()
    default_llvm()
    if args._worker:
        worker(args._worker)
        return
    if not Path(args.scene).exists():  # relative to the repository, as the default
        args.scene = str(REPO / args.scene)
    args.scene = str(Path(args.scene).resolve())
    target_value = [float(v) for v in args.target_value.split(",")]
    target_spp = max(TARGET_SPP_FACTOR * args.spp, TARGET_MIN_SPP)
    cold_target_spp = max(TARGET_SPP_FACTOR * args.cold_spp, TARGET_MIN_SPP)
    samples = args.width * args.height * args.spp
    result = {
        "scene": os.path.relpath(args.scene, REPO), "width": args.width, "height": args.height, "spp": args.spp,
        "max_depth": args.max_depth, "rr_depth": RR_DEPTH, "runs": args.runs, "param": args.param,
        "target_value": target_value, "target_spp": target_spp, "loss": "relmse",
        "cold": {"width": args.cold_width, "height": args.cold_height, "spp": args.cold_spp,
                 "runs": args.cold_runs, "target_spp": cold_target_spp},
    }  # fmt: skip

    mit = Mitsuba(args.scene, args.variant, args.width, args.height, args.max_depth, args.param, args.mitsuba_primal)
    result["mitsuba"] = mit.versions() | {"variant": args.variant, "primal_integrator": args.mitsuba_primal}
    log(f"scene {result['scene']}, {args.width}×{args.height}, {args.spp} spp, max depth {args.max_depth}; "
        f"Mitsuba {result['mitsuba']['mitsuba']} {args.variant} (LLVM {result['mitsuba']['llvm']}, "
        f"{result['mitsuba']['threads']} threads)")  # fmt: skip

    with tempfile.TemporaryDirectory(prefix="mitsuba_speed") as tmp:
        tmp = Path(tmp)
        pg = Pathgrad(args, tmp)
        # Targets (untimed), each renderer its own unless --target-define ''.
        need_grad = "grad" in args.parts
        need_cold = "cold" in args.parts
        mi_target = mit.target(target_value, target_spp) if need_grad else None
        pg_target = tmp / "pathgrad-target.exr"
        pg_cold_target = tmp / "pathgrad-target-cold.exr"
        mi_cold_target = tmp / "mitsuba-target-cold.npy"
        defines = [f"{args.target_define}={args.target_value}"] if args.target_define else None
        if need_cold:
            mit_cold = Mitsuba(args.scene, args.variant, args.cold_width, args.cold_height, args.max_depth,
                               args.param, args.mitsuba_primal)  # fmt: skip
            cold_img = mit_cold.target(target_value, cold_target_spp)
            import numpy as np

            np.save(mi_cold_target, np.array(cold_img))
            if defines is None:
                write_exr(mit.mi, cold_img, pg_cold_target)
            else:
                pg.render(args.cold_width, args.cold_height, cold_target_spp, TARGET_SEED, pg_cold_target, defines)
            del mit_cold
        if need_grad:
            if defines is None:
                write_exr(mit.mi, mi_target, pg_target)
            else:
                pg.render(args.width, args.height, target_spp, TARGET_SEED, pg_target, defines)

        # Warm-ups: Mitsuba compiles (or loads from ~/.drjit) its kernels; pathgrad fills lavapipe's cache.
        t0 = time.perf_counter()
        if "primal" in args.parts:
            mit.render(args.spp, 10_000)
        if need_grad:
            mit.grad_step(mi_target, args.spp, 10_000)
        result["mitsuba_warmup_s"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        if "primal" in args.parts:
            pg.render(args.width, args.height, args.spp, 10_000, tmp / "primal.exr")
        if need_grad:
            pg.grad(args.width, args.height, args.spp, 10_000, pg_target)
        result["pathgrad_warmup_s"] = time.perf_counter() - t0
        log(f"warm-up: Mitsuba {result['mitsuba_warmup_s']:.2f} s, pathgrad {result['pathgrad_warmup_s']:.2f} s")

        if "primal" in args.parts:
            rows = {"pathgrad_wall_s": [], "pathgrad_cpu_s": [], "pathgrad_time_s": [], "pathgrad_steady_s": [],
                    "mitsuba_s": [], "mitsuba_cpu_s": [], "pathgrad_mean": [], "mitsuba_mean": []}  # fmt: skip
            for i in range(args.runs):
                wall, cpu, j = pg.render(args.width, args.height, args.spp, i, tmp / "primal.exr", repeat=args.repeat)
                if j.get("repeat_s"):
                    rows["pathgrad_steady_s"].append(median(j["repeat_s"]))
                rows["pathgrad_wall_s"].append(wall)
                rows["pathgrad_cpu_s"].append(cpu)
                rows["pathgrad_time_s"].append(j.get("time_s"))
                rows["pathgrad_mean"].append(j.get("mean"))
                result["pathgrad_device"] = j.get("device")
                c0 = time.process_time()
                s, img = mit.render(args.spp, i)
                rows["mitsuba_s"].append(s)
                rows["mitsuba_cpu_s"].append(time.process_time() - c0)
                rows["mitsuba_mean"].append([float(v) for v in img.numpy().reshape(-1, 3).mean(axis=0)])
                log(f"primal {i}: pathgrad {wall:.3f} s whole ({j.get('time_s', float('nan')):.3f} s own), "
                    f"Mitsuba {s:.3f} s")  # fmt: skip
            result["primal"] = rows

        if need_grad:
            rows = {"pathgrad_wall_s": [], "pathgrad_cpu_s": [], "pathgrad_time_s": [], "pathgrad_loss": [],
                    "pathgrad_grad": [], "mitsuba_s": [], "mitsuba_cpu_s": [], "mitsuba_loss": [],
                    "mitsuba_grad": [], "pathgrad_steady_s": []}  # fmt: skip
            for i in range(args.runs):
                wall, cpu, j = pg.grad(args.width, args.height, args.spp, i, pg_target, repeat=args.repeat)
                if j.get("repeat_s"):
                    rows["pathgrad_steady_s"].append(median(j["repeat_s"]))
                rows["pathgrad_wall_s"].append(wall)
                rows["pathgrad_cpu_s"].append(cpu)
                rows["pathgrad_time_s"].append(j.get("time_s"))
                rows["pathgrad_loss"].append(j.get("loss"))
                rows["pathgrad_grad"].append(j.get("gradients", {}).get(pg.name))
                c0 = time.process_time()
                s, loss, grad = mit.grad_step(mi_target, args.spp, i)
                rows["mitsuba_s"].append(s)
                rows["mitsuba_cpu_s"].append(time.process_time() - c0)
                rows["mitsuba_loss"].append(loss)
                rows["mitsuba_grad"].append(grad)
                log(f"grad {i}: pathgrad {wall:.3f} s whole ({j.get('time_s', float('nan')):.3f} s own), "
                    f"Mitsuba {s:.3f} s")  # fmt: skip
            result["grad"] = rows

        if need_cold:
            rows = {k: [] for k in ("pathgrad_cold_wall_s", "pathgrad_cold_cpu_s", "pathgrad_cold_time_s",
                                    "pathgrad_warm_wall_s", "pathgrad_warm_cpu_s", "pathgrad_warm_time_s",
                                    "pathgrad_cache_bytes", "mitsuba_cold_wall_s", "mitsuba_cold_cpu_s",
                                    "mitsuba_cold_step_s", "mitsuba_cold_import_s", "mitsuba_warm_wall_s",
                                    "mitsuba_warm_cpu_s", "mitsuba_warm_step_s", "mitsuba_cache_bytes")}  # fmt: skip
            config = {"scene": args.scene, "variant": args.variant, "width": args.cold_width,
                      "height": args.cold_height, "spp": args.cold_spp, "max_depth": args.max_depth,
                      "key": args.param, "target": str(mi_cold_target), "seed": 0}  # fmt: skip
            worker_cmd = [sys.executable, str(Path(__file__).resolve()), "--_worker", json.dumps(config)]
            for i in range(args.cold_runs):
                pg_home = Path(tempfile.mkdtemp(prefix="pg-home", dir=tmp))
                mi_home = Path(tempfile.mkdtemp(prefix="mi-home", dir=tmp))
                grad = lambda env: pg.grad(args.cold_width, args.cold_height, args.cold_spp, 0, pg_cold_target, env)  # noqa: E731
                for state, (who, run) in [
                    ("cold", ("pathgrad", lambda: grad(fresh_env(pg_home)))),
                    ("cold", ("mitsuba", lambda: run_process(worker_cmd, fresh_env(mi_home)))),
                    ("warm", ("pathgrad", lambda: grad(fresh_env(pg_home)))),
                    ("warm", ("mitsuba", lambda: run_process(worker_cmd, fresh_env(mi_home)))),
                ]:
                    wall, cpu, j = run()
                    rows[f"{who}_{state}_wall_s"].append(wall)
                    rows[f"{who}_{state}_cpu_s"].append(cpu)
                    if who == "pathgrad":
                        rows[f"pathgrad_{state}_time_s"].append(j.get("time_s"))
                    else:
                        rows[f"mitsuba_{state}_step_s"].append(j["step_s"])
                        if state == "cold":
                            rows["mitsuba_cold_import_s"].append(j["import_s"])
                            if not Path(j["drjit_cache"]).is_relative_to(mi_home):
                                log(f"warning: Mitsuba's kernel cache is {j['drjit_cache']}, not under the fresh HOME")
                    log(f"cold {i}: {who} {state} process {wall:.2f} s")
                rows["pathgrad_cache_bytes"].append(tree_bytes(pg_home))
                rows["mitsuba_cache_bytes"].append(tree_bytes(mi_home))
                shutil.rmtree(pg_home, ignore_errors=True)
                shutil.rmtree(mi_home, ignore_errors=True)
            result["cold"] |= rows

    summarize(result, samples, args)


def summarize(result, samples, args):
    """Adds medians and ratios to result; prints the table (or, with --json, the JSON)."""
    med = {}
    for part in ("primal", "grad"):
        if part in result:
            med[part] = {k: median(v) for k, v in result[part].items() if k.endswith("_s") and v}
    if "cold" in args.parts:
        med["cold"] = {k: median(v) for k, v in result["cold"].items() if k.endswith("_s") or k.endswith("_bytes")}
    result["median"] = med
    # Ratios: Mitsuba time / pathgrad time = pathgrad / Mitsuba throughput (> 1: pathgrad is faster).
    ratios = {}
    for part in ("primal", "grad"):
        if part in med:
            m = med[part]
            ratios[part] = {"whole_process": m["mitsuba_s"] / m["pathgrad_wall_s"],
                            "own_time": m["mitsuba_s"] / m["pathgrad_time_s"]}  # fmt: skip
            if "pathgrad_steady_s" in m:
                ratios[part]["steady"] = m["mitsuba_s"] / m["pathgrad_steady_s"]
    if "cold" in med:
        m = med["cold"]
        ratios["cold"] = {"cold_process": m["mitsuba_cold_wall_s"] / m["pathgrad_cold_wall_s"],
                          "warm_process": m["mitsuba_warm_wall_s"] / m["pathgrad_warm_wall_s"]}  # fmt: skip
    result["ratio_mitsuba_time_over_pathgrad_time"] = ratios
    if args.json:
        print(json.dumps(result))
        return

    mit = result["mitsuba"]
    print(f"scene {result['scene']}, {args.width}×{args.height}, {args.spp} spp, max depth {args.max_depth}, "
          f"rr depth {RR_DEPTH}; medians of {args.runs} interleaved runs")  # fmt: skip
    print(f"pathgrad on {result.get('pathgrad_device', '?')}; Mitsuba {mit['mitsuba']} (drjit {mit['drjit']}) "
          f"{args.variant}, LLVM {mit['llvm']}, {mit['threads']} threads")  # fmt: skip
    print(f"warm-up (untimed): Mitsuba {result['mitsuba_warmup_s']:.2f} s, pathgrad {result['pathgrad_warmup_s']:.2f} s")
    ms = lambda s: f"{samples / s / 1e6:10.4g}"  # noqa: E731
    head = f"{'':<52} {'time s':>9} {'CPU s':>8} {'Msamples/s':>10}"

    def row(label, s, cpu=None, rate=True):
        c = f"{cpu:8.3f}" if cpu is not None else f"{'':>8}"
        print(f"  {label:<50} {s:9.3f} {c} {ms(s) if rate else '':>10}")

    if "primal" in med:
        m, r = med["primal"], ratios["primal"]
        print(f"\nprimal render\n{head}")
        row("pathgrad render, whole process", m["pathgrad_wall_s"], m["pathgrad_cpu_s"])
        row("pathgrad render, its time_s", m["pathgrad_time_s"])
        if "steady" in r:
            row("pathgrad render, steady (--repeat, in process)", m["pathgrad_steady_s"])
        row(f"Mitsuba mi.render ({args.mitsuba_primal}) + sync, warm", m["mitsuba_s"], m["mitsuba_cpu_s"])
        steady = f"{r['steady']:.3f}× (steady), " if "steady" in r else ""
        print(f"  throughput pathgrad / Mitsuba: {steady}{r['own_time']:.3f}× (time_s), "
              f"{r['whole_process']:.3f}× (whole process)")  # fmt: skip
    if "grad" in med:
        m, r = med["grad"], ratios["grad"]
        print(f"\ngradient step (render + relMSE + backward) of {args.param}, target at {args.target_value}\n{head}")
        row("pathgrad grad --target, whole process", m["pathgrad_wall_s"], m["pathgrad_cpu_s"])
        row("pathgrad grad --target, its time_s", m["pathgrad_time_s"])
        if "steady" in r:
            row("pathgrad grad --target, steady (--repeat, in process)", m["pathgrad_steady_s"])
        row("Mitsuba prb: render + loss + dr.backward + sync", m["mitsuba_s"], m["mitsuba_cpu_s"])
        steady = f"{r['steady']:.3f}× (steady), " if "steady" in r else ""
        print(f"  time Mitsuba / pathgrad: {steady}{r['own_time']:.3f}× (time_s), "
              f"{r['whole_process']:.3f}× (whole process)")  # fmt: skip
        g = result["grad"]
        print(f"  loss: pathgrad {median(g['pathgrad_loss']):.5g}, Mitsuba {median(g['mitsuba_loss']):.5g}; "
              f"gradient: pathgrad {median([v[0] for v in g['pathgrad_grad'] if v]):.5g}, "
              f"Mitsuba {median([v[0] for v in g['mitsuba_grad'] if v]):.5g} (medians, one seed each run)")  # fmt: skip
    if "cold" in med:
        c, m, r = result["cold"], med["cold"], ratios["cold"]
        print(f"\nfirst gradient in a fresh process, {c['width']}×{c['height']}, {c['spp']} spp; "
              f"medians of {c['runs']}; cold: empty HOME/XDG_CACHE_HOME, warm: the same cache again")  # fmt: skip
        print(f"{'':<52} {'process s':>9} {'CPU s':>8} {'step s':>10}")
        print(f"  {'pathgrad grad, cold':<50} {m['pathgrad_cold_wall_s']:9.3f} {m['pathgrad_cold_cpu_s']:8.3f} "
              f"{m['pathgrad_cold_time_s']:10.3f}")  # fmt: skip
        print(f"  {'pathgrad grad, warm':<50} {m['pathgrad_warm_wall_s']:9.3f} {m['pathgrad_warm_cpu_s']:8.3f} "
              f"{m['pathgrad_warm_time_s']:10.3f}")  # fmt: skip
        print(f"  {'Mitsuba python process, cold (empty ~/.drjit)':<50} {m['mitsuba_cold_wall_s']:9.3f} "
              f"{m['mitsuba_cold_cpu_s']:8.3f} {m['mitsuba_cold_step_s']:10.3f}")  # fmt: skip
        print(f"  {'Mitsuba python process, warm':<50} {m['mitsuba_warm_wall_s']:9.3f} "
              f"{m['mitsuba_warm_cpu_s']:8.3f} {m['mitsuba_warm_step_s']:10.3f}")  # fmt: skip
        print(f"  process time Mitsuba / pathgrad: {r['cold_process']:.3f}× cold, {r['warm_process']:.3f}× warm; "
              f"Mitsuba's import alone {m['mitsuba_cold_import_s']:.2f} s; cache written: pathgrad "
              f"{m['pathgrad_cache_bytes'] / 1e6:.2f} MB, Mitsuba {m['mitsuba_cache_bytes'] / 1e6:.2f} MB")  # fmt: skip
    print("\nRatios > 1: pathgrad is faster. pathgrad's time_s excludes its start-up (Vulkan, scene load, BVH) but "
          "includes creating its pipelines, which it does on first use (a lavapipe compile, or a load from Mesa's "
          "shader cache, where lavapipe still runs its NIR passes); 'steady' is the median of the --repeat renders "
          "(steps) after the first in the same process, as Mitsuba's warm timings, which exclude kernel "
          "compilation and Python start-up.")  # fmt: skip


if __name__ == "__main__":
    main()

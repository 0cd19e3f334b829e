#!/usr/bin/env python3
"""Recovery of a density grid by `pathgrad optimize` from rendered views (issue 13): voxel RMSE.

A benchmark for people, not a test (nothing is asserted). It writes, in a scratch directory,

  * the truth: ``scenes/smoke/make_smoke.py truth.vol RES`` (four soft blobs in the unit cube);
  * a scene: that grid as the σ_t of a cube of scattering medium (albedo ``--albedo``, ``--scale``,
    isotropic phase) under a white constant sky, seen by ``--views`` cameras of ``--size``² pixels
    on a ring around it (alternately 25° above and 10° below the horizon) and one from above;
  * one target per view: ``pathgrad render --cpu --sensor K --spp TARGET_SPP``;

then runs ``pathgrad optimize --cpu`` over every view from a constant grid ``--init`` for each
weight of ``--smooth`` (0: no prior), and prints the voxel RMSE against the truth at the start and
the end, the truth's own RMS (the error of an empty grid), the final image loss and the time.

    python3 benches/media_recovery.py                       # 16³, 8 + 1 views of 32², λ 0 and 0.05
    python3 benches/media_recovery.py --smooth 0 0.01 0.05 0.2 --iters 800

The CPU reference (``--cpu``) is used throughout: it is deterministic, and at these sizes it is
faster than lavapipe (BENCHMARKS.md, "Media gradient step"). ``--device`` runs the optimisation on
a Vulkan device instead.
"""

import argparse
import json
import math
import os
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
PARAM = "smoke.interior_medium.sigma_t.data"


def read_vol(path):
    data = Path(path).read_bytes()
    assert data[:4] == b"VOL\x03", path
    _, nx, ny, nz, ch = struct.unpack("<iiiii", data[4:24])
    return list(struct.unpack("<%df" % (nx * ny * nz * ch), data[48:]))


def cameras(n):
    """`n` ring cameras around the cube's centre (0, 0.5, 0) at distance 3.5, then one above."""
    out = []
    for k in range(n):
        phi = 2 * math.pi * k / n
        elev = math.radians(25 if k % 2 == 0 else -10)
        x, y, z = 3.5 * math.cos(elev) * math.sin(phi), 0.5 + 3.5 * math.sin(elev), 3.5 * math.cos(elev) * math.cos(phi)
        out.append((f"ring{k}", f"{x:.5f}, {y:.5f}, {z:.5f}", "0, 1, 0"))
    out.append(("top", "0.2, 4, 0.3", "0, 0, -1"))
    return out


def scene_xml(views, size, scale, albedo):
    sensors = "".join(
        f'<sensor type="perspective" id="{name}"><float name="fov" value="30"/>'
        f'<transform name="to_world"><lookat origin="{origin}" target="0, 0.5, 0" up="{up}"/></transform>'
        f'<film type="hdrfilm"><integer name="width" value="{size}"/><integer name="height" value="{size}"/></film></sensor>'
        for name, origin, up in views
    )
    return f"""<scene version="3.0.0">{sensors}
<integrator type="volpath"><integer name="max_depth" value="8"/></integrator>
<emitter type="constant"><rgb name="radiance" value="1, 1, 1"/></emitter>
<shape type="cube" id="smoke"><bsdf type="null"/><medium type="heterogeneous" name="interior">
  <volume type="gridvolume" name="sigma_t"><string name="filename" value="truth.vol"/>
    <transform name="to_world"><translate x="-0.5" z="-0.5"/></transform></volume>
  <float name="albedo" value="{albedo}"/><float name="scale" value="{scale}"/></medium>
  <transform name="to_world"><scale value="0.5"/><translate y="0.5"/></transform></shape>
</scene>
"""


def run(cmd):
    p = subprocess.run(cmd, capture_output=True, text=True)
    if p.returncode != 0:
        sys.exit(f"{' '.join(map(str, cmd))} failed:\n{p.stderr}")
    return p.stdout


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--pathgrad", default=str(REPO / "target/release/pathgrad"))
    ap.add_argument("--res", type=int, default=16, help="grid resolution (cubed)")
    ap.add_argument("--views", type=int, default=8, help="ring cameras (one from above is added)")
    ap.add_argument("--size", type=int, default=32, help="pixels along each side of a view")
    ap.add_argument("--scale", type=float, default=4.0)
    ap.add_argument("--albedo", type=float, default=0.5)
    ap.add_argument("--target-spp", type=int, default=512)
    ap.add_argument("--init", type=float, default=0.2)
    ap.add_argument("--iters", type=int, default=600)
    ap.add_argument("--lr", type=float, default=0.02)
    ap.add_argument("--spp-primal", type=int, default=8)
    ap.add_argument("--spp-grad", type=int, default=8)
    ap.add_argument("--smooth", type=float, nargs="+", default=[0.0, 0.05])
    ap.add_argument("--device", help="optimise on this Vulkan device instead of the CPU reference")
    ap.add_argument("--keep", help="work in this directory and keep it")
    args = ap.parse_args()

    work = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="recovery-"))
    work.mkdir(parents=True, exist_ok=True)
    run([sys.executable, str(REPO / "scenes/smoke/make_smoke.py"), str(work / "truth.vol"), str(args.res)])
    truth = read_vol(work / "truth.vol")
    views = cameras(args.views)
    scene = work / "scene.xml"
    scene.write_text(scene_xml(views, args.size, args.scale, args.albedo))
    t0 = time.time()
    view_args = []
    for name, _, _ in views:
        target = work / f"{name}.exr"
        if not target.exists():
            run([args.pathgrad, "render", str(scene), "--cpu", "--sensor", name, "--spp", str(args.target_spp),
                 "--seed", "77", "--no-preview", "-o", str(target)])
        view_args += ["--view", f"{name}={target}"]
    print(f"{args.res}³ grid (truth RMS {math.sqrt(sum(v * v for v in truth) / len(truth)):.4f}), "
          f"{len(views)} views of {args.size}², targets at {args.target_spp} spp ({time.time() - t0:.1f} s)")

    def rmse(values):
        return math.sqrt(sum((a - b) ** 2 for a, b in zip(values, truth)) / len(truth))

    print(f"start: constant {args.init}, RMSE {rmse([args.init] * len(truth)):.4f}")
    for weight in args.smooth:
        out = work / f"run-smooth-{weight}"
        cmd = [args.pathgrad, "optimize", str(scene), "--param", f"{PARAM}={args.init}", "--iters", str(args.iters),
               "--lr", str(args.lr), "--spp", "4", "--spp-primal", str(args.spp_primal), "--spp-grad",
               str(args.spp_grad), "--json", "-o", str(out)] + view_args
        # Plain steps, as BENCHMARKS.md recorded them (`optimize` now adds adaptive pixels and
        # control variates by default).
        cmd += ["--adaptive=false", "--control-variates=false"]
        cmd += ["--device", args.device] if args.device else ["--cpu"]
        if weight > 0:
            cmd += ["--smooth", str(weight)]
        if out.exists():
            subprocess.run(["rm", "-rf", str(out)], check=True)
        t = time.time()
        summary = json.loads(run(cmd))
        values = summary["params"][PARAM]
        print(f"--smooth {weight:<6}: RMSE {rmse(values):.4f}, image loss {summary['loss']:.3e}, "
              f"prior {summary.get('prior') or 0:.3e}, {summary['iterations']} iterations in "
              f"{summary['time_s']:.1f} s (process {time.time() - t:.1f} s)")
    if not args.keep:
        subprocess.run(["rm", "-rf", str(work)], check=True)


if __name__ == "__main__":
    main()

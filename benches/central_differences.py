#!/usr/bin/env python3
"""Central differences of a scene's image mean by one XML value, with common random numbers.

Writes two copies of SCENE beside it with the attribute `name="NAME" value="V"` set to V ± H,
renders each with `pathgrad render --json` at the same seed (seeds 1..SEEDS), and prints the mean
and standard error over seeds of (mean(I(V + H)) − mean(I(V − H)))/(2H) per channel. The check of
issue 34's rough glass (BENCHMARKS.md, "A rough glass's η against central differences"):

    python3 benches/central_differences.py tests/conformance/scenes/attached_rough_sphere.xml \\
        int_ior 1.5 0.0075 --spp 4096 --seeds 8
"""

import argparse
import json
import math
import os
import re
import subprocess
import sys
import tempfile


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene")
    ap.add_argument("name", help="the XML attribute's name, e.g. int_ior or alpha")
    ap.add_argument("value", type=float, help="its value in SCENE")
    ap.add_argument("h", type=float, help="the half step")
    ap.add_argument("--spp", type=int, default=1024)
    ap.add_argument("--seeds", type=int, default=8)
    ap.add_argument("--pathgrad", default="target/release/pathgrad")
    args = ap.parse_args()
    text = open(args.scene, encoding="utf-8").read()
    pattern = re.compile(r'(name="%s"\s+value=")([^"]*)(")' % re.escape(args.name))
    if len(pattern.findall(text)) != 1:
        sys.exit(f"{args.scene}: needs exactly one name=\"{args.name}\" value=\"...\"")
    folder = os.path.dirname(os.path.abspath(args.scene))
    copies = {}
    for sign in (+1, -1):
        v = args.value + sign * args.h
        path = os.path.join(folder, f".cd_{os.getpid()}_{'p' if sign > 0 else 'm'}.xml")
        with open(path, "w", encoding="utf-8") as f:
            f.write(pattern.sub(lambda m: f"{m.group(1)}{v!r}{m.group(3)}", text))
        copies[sign] = path
    image = os.path.join(tempfile.gettempdir(), f".cd_{os.getpid()}.exr")
    diffs = []
    try:
        for seed in range(1, args.seeds + 1):
            means = {}
            for sign, path in copies.items():
                out = subprocess.run(
                    [args.pathgrad, "render", path, "-o", image,
                     "--no-preview", "--spp", str(args.spp), "--seed", str(seed), "--json"],
                    check=True, capture_output=True, text=True).stdout
                means[sign] = json.loads(out)["mean"]
            d = [(p - m) / (2 * args.h) for p, m in zip(means[+1], means[-1])]
            diffs.append(d)
            print(f"seed {seed}: " + " ".join(f"{x:.6f}" for x in d), flush=True)
    finally:
        for path in list(copies.values()) + [image]:
            if os.path.exists(path):
                os.remove(path)
    n = len(diffs)
    for c, name in enumerate("RGB"):
        xs = [d[c] for d in diffs]
        mean = sum(xs) / n
        se = math.sqrt(sum((x - mean) ** 2 for x in xs) / (n - 1) / n) if n > 1 else float("nan")
        print(f"{name}: {mean:.6f} ± {se:.6f}")


if __name__ == "__main__":
    main()

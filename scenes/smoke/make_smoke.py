#!/usr/bin/env python3
"""Writes smoke.vol beside this script: a 32³ procedural density grid (a few soft blobs, empty
towards the faces) in Mitsuba's .vol format, version 3, float32, one channel. Standard library only.

    python3 scenes/smoke/make_smoke.py [OUT.vol] [RESOLUTION]
"""
import math
import os
import struct
import sys

BLOBS = [  # (centre in the unit cube, radius, density)
    ((0.50, 0.35, 0.50), 0.22, 1.0),
    ((0.38, 0.58, 0.45), 0.16, 0.8),
    ((0.62, 0.62, 0.58), 0.14, 0.9),
    ((0.50, 0.80, 0.50), 0.10, 0.6),
]
HAZE = 0.0


def density(x, y, z):
    d = HAZE
    for (cx, cy, cz), r, rho in BLOBS:
        q = ((x - cx) ** 2 + (y - cy) ** 2 + (z - cz) ** 2) / (r * r)
        d += rho * math.exp(-2.0 * q)
    return min(d, 1.0)


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    out = sys.argv[1] if len(sys.argv) > 1 else os.path.join(here, "smoke.vol")
    n = int(sys.argv[2]) if len(sys.argv) > 2 else 32
    values = []
    for k in range(n):  # z slowest, x fastest, as .vol stores them
        for j in range(n):
            for i in range(n):
                values.append(density((i + 0.5) / n, (j + 0.5) / n, (k + 0.5) / n))
    header = b"VOL" + bytes([3]) + struct.pack("<iiiii", 1, n, n, n, 1) + struct.pack("<6f", 0, 0, 0, 1, 1, 1)
    with open(out, "wb") as f:
        f.write(header + struct.pack("<%df" % len(values), *values))
    print(f"wrote {out}: {n}x{n}x{n}, max {max(values):.3f}")


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""Writes sparse.vol beside this script: a 64³ density grid of thin haze (0.01) with one small
dense knot (1.0, radius 0.05 of the cube, near a corner), Mitsuba's .vol format, version 3,
float32, one channel. With one majorant for the grid every ray steps at the knot's density; with
pathgrad's majorant grid only the rays near the knot do. Standard library only.

    python3 benches/scenes/sparse/make_sparse.py [OUT.vol] [RESOLUTION]
"""
import math
import os
import struct
import sys

KNOT = ((0.8, 0.75, 0.8), 0.05)
HAZE = 0.01


def density(x, y, z):
    (cx, cy, cz), r = KNOT
    q = ((x - cx) ** 2 + (y - cy) ** 2 + (z - cz) ** 2) / (r * r)
    return max(HAZE, math.exp(-2.0 * q))


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    out = sys.argv[1] if len(sys.argv) > 1 else os.path.join(here, "sparse.vol")
    n = int(sys.argv[2]) if len(sys.argv) > 2 else 64
    values = [density((i + 0.5) / n, (j + 0.5) / n, (k + 0.5) / n) for k in range(n) for j in range(n) for i in range(n)]
    with open(out, "wb") as f:
        f.write(b"VOL" + bytes([3]) + struct.pack("<iiiii", 1, n, n, n, 1))
        f.write(struct.pack("<6f", 0, 0, 0, 1, 1, 1))
        f.write(struct.pack(f"<{len(values)}f", *values))
    print(f"{out}: {n}^3, haze {HAZE}, knot {KNOT}")


if __name__ == "__main__":
    main()

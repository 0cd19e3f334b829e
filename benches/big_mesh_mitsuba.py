#!/usr/bin/env python3
"""Mitsuba 3's side of issue 38's comparison: load a scene (benches/big_mesh.py), render it once
with ``llvm_ad_rgb``, write the EXR, and print the seconds of load and render.

Run the whole process under ``/usr/bin/time -v`` for its wall time and peak RSS:

    /usr/bin/time -v python benches/big_mesh_mitsuba.py /tmp/big/bumpy_2000000.xml /tmp/big/mi.exr
"""

import sys
import time

import drjit as dr
import mitsuba as mi


def main():
    if len(sys.argv) != 3:
        sys.exit("usage: big_mesh_mitsuba.py SCENE.xml OUT.exr")
    mi.set_variant("llvm_ad_rgb")
    start = time.perf_counter()
    scene = mi.load_file(sys.argv[1])
    loaded = time.perf_counter()
    image = mi.render(scene)
    dr.eval(image)
    dr.sync_thread()
    rendered = time.perf_counter()
    mi.util.write_bitmap(sys.argv[2], image)
    print(f"load {loaded - start:.3f} s, render {rendered - loaded:.3f} s")


if __name__ == "__main__":
    main()

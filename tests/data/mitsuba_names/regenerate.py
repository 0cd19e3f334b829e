#!/usr/bin/env python3
"""Rewrites NAME.keys.txt beside each NAME.xml here with the keys Mitsuba's `mi.traverse` lists for
the scene, as `src/scene/mitsuba/tests_names.rs` reads them:

    DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM-19.so \\
        /tmp/mi/bin/python tests/data/mitsuba_names/regenerate.py [NAME.xml ...]

Each file is loaded as an optimisation script loads it, `mi.load_file(path)` with Mitsuba's
defaults (`optimize=True`), in the `llvm_ad_rgb` variant (`--variant` to change it), and its keys
are written one a line after a first line `# mitsuba VERSION mi.traverse keys`. Two things in
Mitsuba's output change from run to run and are made stable, so that the files only change when
the names do: the order in which meshes are traversed (the keys are grouped by the scene-level
object they start with, groups sorted by name, each in traversal order) and the addresses by which
Mitsuba names scene-level objects without an id, and every scene-level texture (`object_94...`,
written `object_ADDR1`, `object_ADDR2`, ... in the order of their sorted key lists). The script
prints which files changed.
"""

import argparse
import glob
import os
import re
import sys

HERE = os.path.dirname(os.path.abspath(__file__))


def keys(mi, path):
    """The traverse keys of the scene at `path`, grouped by scene-level object in a stable order,
    addresses renumbered."""
    groups = {}
    for k in mi.traverse(mi.load_file(path)).keys():
        head, dot, rest = k.partition(".")
        groups.setdefault(head, []).append(dot + rest)
    named = sorted(h for h in groups if not re.fullmatch(r"object_\d+", h))
    unnamed = sorted((h for h in groups if h not in named), key=lambda h: groups[h])
    out = [h + r for h in named for r in groups[h]]
    for i, h in enumerate(unnamed):
        out += ["object_ADDR%d%s" % (i + 1, r) for r in groups[h]]
    return out


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("scenes", nargs="*", help="scene files (default: every *.xml beside this script)")
    p.add_argument("--variant", default="llvm_ad_rgb")
    args = p.parse_args()
    import mitsuba as mi

    mi.set_variant(args.variant)
    scenes = args.scenes or sorted(glob.glob(os.path.join(HERE, "*.xml")))
    for scene in scenes:
        out = os.path.splitext(scene)[0] + ".keys.txt"
        text = "# mitsuba %s mi.traverse keys\n" % mi.__version__
        text += "".join(k + "\n" for k in keys(mi, scene))
        old = open(out).read() if os.path.exists(out) else None
        if old != text:
            with open(out + ".tmp", "w") as f:
                f.write(text)
            os.replace(out + ".tmp", out)
        print("%s: %s" % (os.path.relpath(out), "unchanged" if old == text else "written"))
    return 0


if __name__ == "__main__":
    sys.exit(main())

#!/usr/bin/env python3
"""Times `pathgrad params` on glTF scenes of many emissive one-triangle nodes (a tool for
BENCHMARKS.md; nothing is asserted): distinct node names, and every node named "m" (name
uniquing's worst case). Prints one line per binary and scene.

    python3 benches/gltf_nodes.py [--nodes 100000] BINARY...
"""
import argparse
import base64
import json
import os
import struct
import subprocess
import tempfile
import time


def scene(n, same_name):
    data = base64.b64encode(struct.pack("<9f", 0, 0, 0, 1, 0, 0, 0, 1, 0)).decode()
    primitive = {"attributes": {"POSITION": 0}, "material": 0}
    return {
        "asset": {"version": "2.0"},
        "scenes": [{"nodes": list(range(n))}],
        "nodes": [{"name": "m" if same_name else f"n{i}", "mesh": 0} for i in range(n)],
        "meshes": [{"primitives": [primitive]}],
        "materials": [{"name": "m", "emissiveFactor": [1, 1, 1]}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                       "min": [0, 0, 0], "max": [1, 1, 0]}],
        "bufferViews": [{"buffer": 0, "byteLength": 36}],
        "buffers": [{"byteLength": 36, "uri": "data:application/octet-stream;base64," + data}],
    }


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--nodes", type=int, default=100_000)
    parser.add_argument("binaries", nargs="+")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        for same in (False, True):
            path = os.path.join(tmp, f"nodes-{'same' if same else 'distinct'}.gltf")
            with open(path, "w") as f:
                json.dump(scene(args.nodes, same), f)
            for binary in args.binaries:
                start = time.perf_counter()
                done = subprocess.run([binary, "params", path], capture_output=True)
                seconds = time.perf_counter() - start
                status = "ok" if done.returncode == 0 else "failed: " + done.stderr.decode().strip()[-200:]
                print(f"{binary}  {args.nodes} nodes, {'one name' if same else 'distinct names'}: {seconds:.2f} s ({status})")


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""Writes the "millions of triangles" scene of issue 38: a bumpy sphere of about N triangles.

A tool for people (run by hand, nothing asserts on it). It writes, into OUT_DIR,

  * ``bumpy_N.ply``: a UV sphere of radius about 1 whose radius is modulated by a bump pattern,
    as binary little-endian PLY with vertex positions and unit vertex normals (float x, y, z,
    nx, ny, nz; faces as ``list uchar int vertex_indices``, the layout Mitsuba's ``write_ply``
    gives such a mesh);
  * ``bumpy_N.xml``: a Mitsuba 3 scene that both pathgrad and Mitsuba 3 load: the sphere with a
    rough conductor (GGX, alpha 0.2) on a diffuse floor under a square area light, a 256 x 256
    ``hdrfilm``, 16 spp and a ``path`` integrator of max depth 6;
  * with ``--obj``, also ``bumpy_N.obj`` (the same vertices, normals and triangles as Wavefront OBJ
    text: ``v``, ``vn`` and ``f v//vn`` lines, floats printed so that they read back bit for bit)
    and ``bumpy_N_obj.xml``, the scene with the OBJ in place of the PLY.

The sphere has ``2 * C * (R - 1)`` triangles for ``R`` rings of ``C = 2 R`` vertices plus the two
poles (fans at the poles, two triangles per quad between rings), so the count is N rounded to
that form; the script prints the exact count. Standard library and numpy only.

    python3 benches/big_mesh.py 2000000 /tmp/big
    pathgrad render /tmp/big/bumpy_2000000.xml -o /tmp/big/a.exr --json
    python3 benches/big_mesh.py 2000000 /tmp/big --obj   # also bumpy_2000000{.obj,_obj.xml}
"""

import argparse
import math
import os
import sys

import numpy as np


def bumpy_sphere(triangles):
    """Positions (V, 3) float32, normals (V, 3) float32 and faces (F, 3) int32."""
    rings = max(2, round(0.5 + math.sqrt(0.25 + triangles / 4.0)))
    cols = 2 * rings
    # Ring k of `rings - 1` interior rings at polar angle pi * (k + 1) / rings.
    theta = np.pi * (np.arange(1, rings, dtype=np.float64)) / rings
    phi = 2.0 * np.pi * np.arange(cols, dtype=np.float64) / cols
    th, ph = np.meshgrid(theta, phi, indexing="ij")
    bump = 1.0 + 0.03 * np.sin(24.0 * th) * np.sin(24.0 * ph) + 0.01 * np.sin(97.0 * th + 3.0 * ph)
    ring_pos = np.stack(
        [bump * np.sin(th) * np.cos(ph), bump * np.cos(th), bump * np.sin(th) * np.sin(ph)], axis=-1
    ).reshape(-1, 3)
    positions = np.concatenate([[[0.0, 1.0, 0.0]], ring_pos, [[0.0, -1.0, 0.0]]]).astype(np.float64)
    top, bottom = 0, len(positions) - 1

    def ring(k):
        return 1 + k * cols + np.arange(cols)

    faces = []
    first = ring(0)
    faces.append(np.stack([np.full(cols, top), np.roll(first, -1), first], axis=-1))
    for k in range(rings - 2):
        a, b = ring(k), ring(k + 1)
        a1, b1 = np.roll(a, -1), np.roll(b, -1)
        faces.append(np.stack([a, a1, b1], axis=-1))
        faces.append(np.stack([a, b1, b], axis=-1))
    last = ring(rings - 2)
    faces.append(np.stack([np.full(cols, bottom), last, np.roll(last, -1)], axis=-1))
    faces = np.concatenate(faces).astype(np.int32)

    # Area-weighted vertex normals of the faces (outward: the winding is counter-clockwise seen
    # from outside).
    p = positions[faces]
    face_n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    normals = np.zeros_like(positions)
    for corner in range(3):
        np.add.at(normals, faces[:, corner], face_n)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    return positions.astype(np.float32), normals.astype(np.float32), faces


def write_ply(path, positions, normals, faces):
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        f"element vertex {len(positions)}\n"
        "property float x\nproperty float y\nproperty float z\n"
        "property float nx\nproperty float ny\nproperty float nz\n"
        f"element face {len(faces)}\n"
        "property list uchar int vertex_indices\nend_header\n"
    )
    vertex = np.concatenate([positions, normals], axis=1).astype("<f4")
    face = np.zeros(len(faces), dtype=[("n", "u1"), ("i", "<i4", (3,))])
    face["n"] = 3
    face["i"] = faces
    tmp = path + ".tmp"
    with open(tmp, "wb") as f:
        f.write(header.encode("ascii"))
        f.write(vertex.tobytes())
        f.write(face.tobytes())
    os.replace(tmp, path)


def write_obj(path, positions, normals, faces):
    """Writes the mesh as OBJ: '%.9g' prints a float32 so that it parses back to the same float."""
    tmp = path + ".tmp"
    with open(tmp, "w") as f:
        f.write(f"# bumpy sphere: {len(positions)} vertices, {len(faces)} triangles (benches/big_mesh.py)\no bumpy\n")
        np.savetxt(f, positions.astype(np.float64), fmt="v %.9g %.9g %.9g")
        np.savetxt(f, normals.astype(np.float64), fmt="vn %.9g %.9g %.9g")
        # Vertex k has normal k: each index is written twice, as v//vn.
        np.savetxt(f, np.repeat(faces.astype(np.int64) + 1, 2, axis=1), fmt="f %d//%d %d//%d %d//%d")
    os.replace(tmp, path)


SCENE = """<?xml version="1.0" encoding="utf-8"?>
<!-- Issue 38's scene, written by benches/big_mesh.py: a bumpy sphere of {count} triangles. -->
<scene version="3.0.0">
    <integrator type="path">
        <integer name="max_depth" value="6"/>
    </integrator>
    <sensor type="perspective">
        <float name="fov" value="40"/>
        <transform name="to_world">
            <lookat origin="0, 1.6, 4.2" target="0, 0.1, 0" up="0, 1, 0"/>
        </transform>
        <sampler type="independent">
            <integer name="sample_count" value="16"/>
        </sampler>
        <film type="hdrfilm">
            <integer name="width" value="256"/>
            <integer name="height" value="256"/>
            <rfilter type="box"/>
        </film>
    </sensor>
    <bsdf type="roughconductor" id="metal">
        <string name="distribution" value="ggx"/>
        <float name="alpha" value="0.2"/>
    </bsdf>
    <bsdf type="diffuse" id="floor">
        <rgb name="reflectance" value="0.6, 0.6, 0.6"/>
    </bsdf>
    <shape type="{kind}">
        <string name="filename" value="{mesh}"/>
        <transform name="to_world">
            <translate y="0.05"/>
        </transform>
        <ref id="metal"/>
    </shape>
    <shape type="rectangle">
        <transform name="to_world">
            <rotate x="1" angle="-90"/>
            <scale value="5"/>
            <translate y="-1"/>
        </transform>
        <ref id="floor"/>
    </shape>
    <shape type="rectangle">
        <transform name="to_world">
            <rotate x="1" angle="90"/>
            <translate y="3"/>
        </transform>
        <bsdf type="diffuse">
            <rgb name="reflectance" value="0, 0, 0"/>
        </bsdf>
        <emitter type="area">
            <rgb name="radiance" value="12, 12, 12"/>
        </emitter>
    </shape>
</scene>
"""


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("triangles", type=int, help="about how many triangles the sphere has")
    parser.add_argument("out_dir", help="folder for bumpy_N.ply and bumpy_N.xml")
    parser.add_argument("--obj", action="store_true", help="also write bumpy_N.obj and bumpy_N_obj.xml")
    args = parser.parse_args()
    if args.triangles < 8:
        sys.exit("big_mesh.py: at least 8 triangles")
    os.makedirs(args.out_dir, exist_ok=True)
    positions, normals, faces = bumpy_sphere(args.triangles)
    name = f"bumpy_{args.triangles}"
    write_ply(os.path.join(args.out_dir, name + ".ply"), positions, normals, faces)
    with open(os.path.join(args.out_dir, name + ".xml"), "w") as f:
        f.write(SCENE.format(count=len(faces), kind="ply", mesh=name + ".ply"))
    print(f"{args.out_dir}/{name}.xml: {len(faces)} triangles, {len(positions)} vertices")
    if args.obj:
        write_obj(os.path.join(args.out_dir, name + ".obj"), positions, normals, faces)
        with open(os.path.join(args.out_dir, name + "_obj.xml"), "w") as f:
            f.write(SCENE.format(count=len(faces), kind="obj", mesh=name + ".obj"))
        print(f"{args.out_dir}/{name}_obj.xml: the same mesh as {name}.obj")


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""Writes the conformance scenes' data files into scenes/data/: tiny meshes, bitmaps and grids.

Deterministic (no randomness), numpy and the standard library only, so the files can be
regenerated bit for bit:  python3 tests/conformance/make_data.py

Every file stays a few KB: an icosphere of 42 vertices, 8x8 bitmaps, 8^3 grids (one 16^3 grid,
Mitsuba's own `sigmat.vol`, recomputed with the function of mitsuba-data's
`tests/scenes/participating_media/create_volume_data.py`).
"""

import math
import struct
import zlib
from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parent / "scenes" / "data"


# ---- meshes ----

def icosphere(subdivisions):
    """Unit icosphere: positions (outward normals = positions) and counter-clockwise triangles."""
    t = (1.0 + 5.0 ** 0.5) / 2.0
    verts = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t), (0, 1, -t),
             (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    verts = [np.array(v, float) / np.linalg.norm(v) for v in verts]
    faces = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2),
             (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5), (2, 4, 11),
             (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    for _ in range(subdivisions):
        cache = {}

        def mid(a, b):
            key = (min(a, b), max(a, b))
            if key not in cache:
                m = verts[a] + verts[b]
                verts.append(m / np.linalg.norm(m))
                cache[key] = len(verts) - 1
            return cache[key]

        new = []
        for a, b, c in faces:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            new += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = new
    return np.array(verts), faces


def f6(x):
    return f"{x:.6f}"


def write_obj_icosphere(path):
    """Icosphere (1 subdivision) with vertex normals: smooth, or faceted with face_normals."""
    v, faces = icosphere(1)
    lines = ["# icosphere, 1 subdivision: 42 vertices, 80 triangles, unit radius, vertex normals"]
    lines += [f"v {f6(a)} {f6(b)} {f6(c)}" for a, b, c in v]
    lines += [f"vn {f6(a)} {f6(b)} {f6(c)}" for a, b, c in v]
    lines += [f"f {a + 1}//{a + 1} {b + 1}//{b + 1} {c + 1}//{c + 1}" for a, b, c in faces]
    path.write_text("\n".join(lines) + "\n")


def write_obj_quad_uv(path):
    """A unit quad [-1, 1]^2 in z = 0 facing +z, one polygon with texture coordinates (Mitsuba and
    pathgrad flip v on load: vt (0, 1) is the image's top-left)."""
    path.write_text(
        "# quad [-1,1]^2 at z = 0 facing +z, one 4-vertex face with texture coordinates\n"
        "v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\n"
        "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
        "f 1/1 2/2 3/3 4/4\n")


def write_obj_quad_uv_wide(path):
    """The quad of write_obj_quad_uv with texture coordinates from -0.75 to 1.75 (2.5 repeats of an
    8-texel image: every wrap mode shows), as two triangles."""
    path.write_text(
        "# quad [-1,1]^2 at z = 0 facing +z, texture coordinates -0.75 .. 1.75\n"
        "v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\n"
        "vt -0.75 -0.75\nvt 1.75 -0.75\nvt 1.75 1.75\nvt -0.75 1.75\n"
        "f 1/1 2/2 3/3\nf 1/1 3/3 4/4\n")


def write_ply_icosahedron_ascii(path):
    """Icosahedron (no subdivision) as ASCII PLY with vertex normals."""
    v, faces = icosphere(0)
    head = ["ply", "format ascii 1.0", "comment icosahedron, unit radius, vertex normals",
            f"element vertex {len(v)}", "property float x", "property float y", "property float z",
            "property float nx", "property float ny", "property float nz",
            f"element face {len(faces)}", "property list uchar int vertex_indices", "end_header"]
    body = [" ".join(f6(c) for c in (*p, *p)) for p in v] + [f"3 {a} {b} {c}" for a, b, c in faces]
    path.write_text("\n".join(head + body) + "\n")


def write_ply_quad_uv_binary(path):
    """A 2 x 2 grid of quads over [-1, 1]^2 (z = 0, facing +z) as binary little-endian PLY with
    u, v per vertex (taken as they are, v = 0 at y = -1), as triangles (Mitsuba's ply plugin reads
    triangle meshes only)."""
    n = 3
    verts, faces = [], []
    for j in range(n):
        for i in range(n):
            x, y = -1 + 2 * i / (n - 1), -1 + 2 * j / (n - 1)
            verts.append((x, y, 0.0, i / (n - 1), j / (n - 1)))
    for j in range(n - 1):
        for i in range(n - 1):
            a = j * n + i
            faces += [(a, a + 1, a + n + 1), (a, a + n + 1, a + n)]
    head = "\n".join(["ply", "format binary_little_endian 1.0", "comment 2x2 quads as triangles, texture coordinates",
                      f"element vertex {len(verts)}", "property float x", "property float y", "property float z",
                      "property float u", "property float v", f"element face {len(faces)}",
                      "property list uchar int vertex_indices", "end_header"]) + "\n"
    body = b"".join(struct.pack("<5f", *p) for p in verts)
    body += b"".join(struct.pack("<B3i", 3, *f) for f in faces)
    path.write_bytes(head.encode() + body)


def write_ply_attributes(path):
    """Icosphere (1 subdivision) as binary little-endian PLY with vertex normals and Mitsuba mesh
    attributes: `color_0 color_1 color_2` per vertex (`vertex_color`, a smooth function of the
    position), `red green blue` and `weight_0` per face (`face_color`, `face_weight`, patterns of
    the face index); every value in [0.1, 0.9]."""
    v, faces = icosphere(1)
    head = "\n".join(["ply", "format binary_little_endian 1.0",
                      "comment icosphere, 1 subdivision, vertex normals, mesh attributes",
                      f"element vertex {len(v)}", "property float x", "property float y", "property float z",
                      "property float nx", "property float ny", "property float nz",
                      "property float color_0", "property float color_1", "property float color_2",
                      f"element face {len(faces)}", "property list uchar int vertex_indices",
                      "property float red", "property float green", "property float blue",
                      "property float weight_0", "end_header"]) + "\n"
    body = b""
    for p in v:
        color = 0.5 + 0.4 * np.array([p[0], p[1] * p[2], -p[2]])
        body += struct.pack("<9f", *p, *p, *color)
    for i, f in enumerate(faces):
        color = [0.1 + 0.8 * ((i * 37) % 10) / 9, 0.1 + 0.8 * ((i * 11) % 7) / 6, 0.1 + 0.8 * ((i * 5) % 4) / 3]
        weight = 0.1 + 0.8 * ((i * 7) % 5) / 4
        body += struct.pack("<B3i4f", 3, *f, *color, weight)
    path.write_bytes(head.encode() + body)


def pedestal():
    """A low-poly stand-in for mitsuba-data's 575 KB `sphere_base.obj` (a pedestal, not a sphere):
    a closed solid of revolution about y through the original's profile, 24 segments; vertices and
    outward faces (triangles and quads)."""
    profile = [(0.0, -0.524), (0.767, -0.524), (0.735, -0.851), (0.898, -0.969), (0.905, -1.015), (0.0, -1.015)]
    seg = 24
    verts, faces = [], []
    ring_start = []
    for r, y in profile:
        if r == 0.0:
            ring_start.append(len(verts))
            verts.append((0.0, y, 0.0))
        else:
            ring_start.append(len(verts))
            for k in range(seg):
                phi = 2 * math.pi * k / seg
                verts.append((r * math.cos(phi), y, -r * math.sin(phi)))
    for i in range(len(profile) - 1):
        (ra, _), (rb, _) = profile[i], profile[i + 1]
        a0, b0 = ring_start[i], ring_start[i + 1]
        for k in range(seg):
            k1 = (k + 1) % seg
            if ra == 0.0:
                faces.append((a0, b0 + k, b0 + k1))
            elif rb == 0.0:
                faces.append((a0 + k, b0, a0 + k1))
            else:
                faces.append((a0 + k, b0 + k, b0 + k1, a0 + k1))
    return verts, faces


def write_obj_pedestal(path):
    verts, faces = pedestal()
    lines = ["# pedestal: solid of revolution about y, 24 segments, outward faces (face normals)"]
    lines += [f"v {f6(x)} {f6(y)} {f6(z)}" for x, y, z in verts]
    lines += ["f " + " ".join(str(i + 1) for i in f) for f in faces]
    path.write_text("\n".join(lines) + "\n")


def write_obj_cube_centered(path):
    """mitsuba-data's `unit_cube_centered.obj` ([-0.5, 0.5]^3, outward faces), without its uvs."""
    v = [(x, y, z) for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)]
    # Index = 4·[x > 0] + 2·[y > 0] + [z > 0]; each quad counter-clockwise from outside.
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    lines = ["# [-0.5, 0.5]^3, outward faces"] + [f"v {x} {y} {z}" for x, y, z in v]
    lines += ["f " + " ".join(str(i + 1) for i in q) for q in quads]
    path.write_text("\n".join(lines) + "\n")


def write_obj_background(path):
    """mitsuba-data's `background.obj`: a floor and a back wall in one L-shaped mesh, with uvs."""
    path.write_text(
        "# mitsuba-data tests/scenes/participating_media/meshes/background.obj (floor + back wall)\n"
        "v -4.684556 -1.044930 3.122140\nv 4.684556 -1.044930 3.122140\nv -4.684556 -1.044930 -3.122140\n"
        "v 4.684556 -1.044930 -3.122140\nv -4.684556 4.445930 -3.122140\nv 4.684556 4.445930 -3.122140\n"
        "vt 0.000073 0.999927\nvt 0.532096 0.467904\nvt 0.532096 0.999927\nvt 0.000073 0.467904\n"
        "vt 0.532096 0.000073\nvt 0.000073 0.000073\n"
        "vn 0.0000 1.0000 0.0000\nvn 0.0000 0.0000 1.0000\n"
        "f 2/1/1 3/2/1 1/3/1\nf 4/4/2 5/5/2 3/2/2\nf 2/1/1 4/4/1 3/2/1\nf 4/4/2 6/6/2 5/5/2\n")


def write_serialized(path):
    """Mitsuba's serialized format (version 4, zlib streams, a table of offsets at the end), three
    meshes: 0 the icosphere with vertex normals (single precision); 1 the pedestal without
    normals, in double precision (Mitsuba computes smooth normals); 2 a unit quad in z = 0 with
    normals, texture coordinates and the face-normals flag (its normals unused)."""
    out, offsets = b"", []

    def mesh(flags, name, positions, normals, uvs, triangles):
        f = "<d" if flags & 0x2000 else "<f"
        body = struct.pack("<I", flags) + name.encode() + b"\0" + struct.pack("<QQ", len(positions), len(triangles))
        for arr in (positions, normals or [], uvs or []):
            body += b"".join(struct.pack(f, c) for v in arr for c in v)
        body += b"".join(struct.pack("<3I", *t) for t in triangles)
        return struct.pack("<HH", 0x041C, 4) + zlib.compress(body, 9)

    verts, faces = icosphere(2)
    ball = [tuple(float(c) for c in v) for v in verts]
    ped_v, ped_f = pedestal()
    ped_t = [t for f in ped_f for t in ([f] if len(f) == 3 else [(f[0], f[1], f[2]), (f[0], f[2], f[3])])]
    quad = [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (1.0, 1.0, 0.0), (0.0, 1.0, 0.0)]
    for data in (mesh(0x1000 | 0x0001, "ball", ball, ball, None, faces),
                 mesh(0x2000, "pedestal", ped_v, None, None, ped_t),
                 mesh(0x1000 | 0x0001 | 0x0002 | 0x0010, "card", quad, [(0.0, 0.0, 1.0)] * 4,
                      [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)], [(0, 1, 2), (0, 2, 3)])):
        offsets.append(len(out))
        out += data
    out += b"".join(struct.pack("<Q", o) for o in offsets) + struct.pack("<I", len(offsets))
    path.write_bytes(out)


# ---- bitmaps ----

def png_bytes(rgb):
    """8-bit RGB PNG from an (h, w, 3) uint8 array, no ancillary chunks."""
    h, w, _ = rgb.shape
    raw = b"".join(b"\x00" + rgb[y].tobytes() for y in range(h))

    def chunk(kind, data):
        c = kind + data
        return struct.pack(">I", len(data)) + c + struct.pack(">I", zlib.crc32(c) & 0xFFFFFFFF)

    png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
    return png + chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b"")


def write_png(path, rgb):
    path.write_bytes(png_bytes(rgb))


def checker_texture(a=(200, 60, 40), b=(40, 160, 220), c=(230, 210, 50)):
    """8 x 8: a 2-texel checker of a (orange) and b (blue), its top-left quadrant c (yellow), so a
    flip in u or v, or a transposition, changes the image."""
    img = np.zeros((8, 8, 3), np.uint8)
    for y in range(8):
        for x in range(8):
            img[y, x] = c if (x < 4 and y < 4) else (a if ((x // 2) + (y // 2)) % 2 == 0 else b)
    return img


def ramp_texture():
    """8 x 8 grey ramp along x (texel x has value 30·x + 20), read with raw=true."""
    img = np.zeros((8, 8, 3), np.uint8)
    for x in range(8):
        img[:, x] = 30 * x + 20
    return img


def background_checker():
    """16 x 16 checker of 0.2 and 0.4 (linear; read with raw=true), 2 texels a square: a bitmap
    stand-in for the mitsuba-data scenes' `checkerboard` texture, which pathgrad does not read."""
    img = np.zeros((16, 16, 3), np.uint8)
    for y in range(16):
        for x in range(16):
            img[y, x] = 51 if ((x // 2) + (y // 2)) % 2 == 0 else 102
    return img


def normal_bumps():
    """8 x 8 tangent-space normal map (read with raw=true): n = normalize(0.9 sin a, 0.7 cos b, 1)
    with a, b = 2π(x + ½)/8, 2π(y + ½)/8, stored as round(255 (n + 1)/2); x and y tilt differently,
    so a swapped or mirrored tangent frame changes the image. Its top-left texel tilts past 70°
    (n = (0.95, 0.1, 0.3) normalised), where the shadow terminator's α² is clamped to 1."""
    img = np.zeros((8, 8, 3), np.uint8)
    for y in range(8):
        for x in range(8):
            a, b = 2 * math.pi * (x + 0.5) / 8, 2 * math.pi * (y + 0.5) / 8
            n = np.array([0.9 * math.sin(a), 0.7 * math.cos(b), 1.0])
            if x == 0 and y == 0:
                n = np.array([0.95, 0.1, 0.3])
            n /= np.linalg.norm(n)
            img[y, x] = np.round(255 * (n + 1) / 2).astype(np.uint8)
    return img


def bump_heights():
    """8 x 8 bump map (read with raw=true): height h = 0.5 + 0.3 sin(a) cos(b) with a, b as in
    `normal_bumps`, stored as RGB (h + 0.1, h, h − 0.1), so its luminance (what Mitsuba's bump
    map differentiates) is not any one channel."""
    img = np.zeros((8, 8, 3), np.uint8)
    for y in range(8):
        for x in range(8):
            a, b = 2 * math.pi * (x + 0.5) / 8, 2 * math.pi * (y + 0.5) / 8
            h = 0.5 + 0.3 * math.sin(a) * math.cos(b)
            img[y, x] = np.round(255 * np.clip([h + 0.1, h, h - 0.1], 0, 1)).astype(np.uint8)
    return img


# ---- grids ----

def write_exr(path, rgb):
    """An uncompressed scanline OpenEXR file of float32 R, G, B channels (rows top to bottom)."""
    rgb = np.asarray(rgb, np.float32)
    height, width = rgb.shape[:2]

    def attribute(name, kind, value):
        return name.encode() + b"\0" + kind.encode() + b"\0" + struct.pack("<i", len(value)) + value

    channels = b"".join(c.encode() + b"\0" + struct.pack("<iB3xii", 2, 0, 1, 1) for c in "BGR") + b"\0"
    window = struct.pack("<iiii", 0, 0, width - 1, height - 1)
    header = (struct.pack("<ii", 20000630, 2)
              + attribute("channels", "chlist", channels)
              + attribute("compression", "compression", b"\0")
              + attribute("dataWindow", "box2i", window)
              + attribute("displayWindow", "box2i", window)
              + attribute("lineOrder", "lineOrder", b"\0")
              + attribute("pixelAspectRatio", "float", struct.pack("<f", 1.0))
              + attribute("screenWindowCenter", "v2f", struct.pack("<ff", 0.0, 0.0))
              + attribute("screenWindowWidth", "float", struct.pack("<f", 1.0))
              + b"\0")
    lines = []
    for y in range(height):
        data = b"".join(rgb[y, :, c].astype("<f4").tobytes() for c in (2, 1, 0))
        lines.append(struct.pack("<ii", y, len(data)) + data)
    offset = len(header) + 8 * height
    table = b""
    for line in lines:
        table += struct.pack("<Q", offset)
        offset += len(line)
    path.write_bytes(header + table + b"".join(lines))


def sky_texels():
    """A 32 x 16 latitude-longitude sky: a blue gradient, a warm sun and a green band low on one side."""
    h, w = 16, 32
    v = (np.arange(h) + 0.5)[:, None] / h * np.ones((1, w))
    u = np.ones((h, 1)) * (np.arange(w) + 0.5)[None, :] / w
    rgb = np.stack([0.3 + 0.4 * v, 0.45 + 0.3 * v, 0.9 - 0.2 * v], axis=-1)
    sun = np.exp(-(((u - 0.3) / 0.05) ** 2 + ((v - 0.25) / 0.08) ** 2))
    rgb += 12.0 * sun[..., None] * np.array([1.0, 0.85, 0.6])
    band = (np.abs(v - 0.6) < 0.08) & (u > 0.55) & (u < 0.8)
    rgb[band] = [0.2, 1.5, 0.3]
    return rgb


def write_vol(path, values):
    """Mitsuba .vol v3, float32; `values` indexed [z, y, x] or [z, y, x, c] (x fastest on disk)."""
    values = np.asarray(values, np.float32)
    channels = 1 if values.ndim == 3 else values.shape[3]
    zr, yr, xr = values.shape[:3]
    head = b"VOL" + bytes([3]) + struct.pack("<iiiii", 1, xr, yr, zr, channels)
    head += struct.pack("<6f", 0, 0, 0, 1, 1, 1)
    path.write_bytes(head + values.ravel().tobytes())


def cell_centres(res):
    c = (np.arange(res) + 0.5) / res
    z, y, x = np.meshgrid(c, c, c, indexing="ij")
    return x, y, z


def blob_grid():
    """8^3 density in [0, 1]: a smooth off-centre blob times a slab pattern along y."""
    x, y, z = cell_centres(8)
    r2 = (x - 0.45) ** 2 + (y - 0.55) ** 2 + (z - 0.5) ** 2
    return np.exp(-r2 / 0.08) * (0.6 + 0.4 * np.cos(6.0 * y))


def albedo_grid():
    """8^3 RGB albedo: red rises along x, green along y, blue along z, each in [0.3, 0.95]."""
    x, y, z = cell_centres(8)
    return np.stack([0.3 + 0.65 * x, 0.3 + 0.65 * y, 0.95 - 0.65 * z], axis=-1)


def grey_albedo_grid():
    """8^3 grey reflectance in [0.2, 0.8]: the blob rescaled (a `volume` texture's grid, away from
    0 and 1 so finite differences of every voxel stay reflectances)."""
    b = blob_grid()
    return 0.2 + 0.6 * (b - b.min()) / (b.max() - b.min())


def sigma_rgb_grid():
    """8^3 RGB extinction: the blob, scaled differently per channel."""
    b = blob_grid()
    return np.stack([b, 0.6 * b, 0.25 + 0.3 * b], axis=-1)


def sdf_grid():
    """10^3 signed distances on the grid's nodes (i/9): a torus (radii 0.27, 0.11, axis y) and a
    sphere (radius 0.16) through its hole, united; coarse, so the voxels' trilinear patches and
    the two normal modes show."""
    c = np.arange(10) / 9.0
    z, y, x = np.meshgrid(c, c, c, indexing="ij")
    q = np.sqrt((x - 0.5) ** 2 + (z - 0.5) ** 2) - 0.27
    torus = np.sqrt(q ** 2 + (y - 0.5) ** 2) - 0.11
    sphere = np.sqrt((x - 0.5) ** 2 + (y - 0.62) ** 2 + (z - 0.5) ** 2) - 0.16
    return np.minimum(torus, sphere)


def mitsuba_sigmat(x, y, z):
    if x > 0.2 and y > 0.7 and z < 0.5:
        return 5.0
    return max(0.0, (math.sin(16 * (x + 4 * ((y - 0.5) ** 2 - 0.25))) + 1) * 0.5)


def mitsuba_albedo_f(x, y, z):
    return math.cos(45 * (x + ((y - 0.7) ** 2 - 0.25)) + 1) * 0.5


def mitsuba_grids():
    """mitsuba-data's sigmat.vol (16^3, as its create_volume_data.py) and albedo.vol (its
    function, sampled at 8^3 instead of 16^3 to stay small)."""
    res = 16
    sig = np.zeros((res, res, res))
    for z in range(res):
        for y in range(res):
            for x in range(res):
                sig[z, y, x] = mitsuba_sigmat(x / res, y / res, z / res)
    res = 8
    alb = np.zeros((res, res, res, 3))
    for z in range(res):
        for y in range(res):
            for x in range(res):
                alb[z, y, x, 0] = mitsuba_albedo_f(x / res, y / res, z / res) + 0.5 * math.cos(y / res) + 0.5
                alb[z, y, x, 1] = mitsuba_sigmat(((x / res) + 0.3) % 1, ((y / res) + 0.7) % 1, z / res)
                alb[z, y, x, 2] = mitsuba_albedo_f(x / res, y / res, z / res)
    return np.maximum(sig, 0), np.clip(alb, 0, 1)


def main():
    DATA.mkdir(parents=True, exist_ok=True)
    write_obj_icosphere(DATA / "icosphere.obj")
    write_obj_quad_uv(DATA / "quad_uv.obj")
    write_obj_quad_uv_wide(DATA / "quad_uv_wide.obj")
    write_ply_icosahedron_ascii(DATA / "icosahedron_ascii.ply")
    write_ply_quad_uv_binary(DATA / "quad_uv_binary.ply")
    write_ply_attributes(DATA / "icosphere_attributes.ply")
    write_obj_pedestal(DATA / "pedestal.obj")
    write_obj_cube_centered(DATA / "unit_cube_centered.obj")
    write_obj_background(DATA / "background.obj")
    write_serialized(DATA / "meshes.serialized")
    write_png(DATA / "checker.png", checker_texture())
    write_png(DATA / "ramp_raw.png", ramp_texture())
    write_png(DATA / "background_checker.png", background_checker())
    write_png(DATA / "normal_bumps.png", normal_bumps())
    write_png(DATA / "bump_heights.png", bump_heights())
    write_exr(DATA / "sky.exr", sky_texels())
    write_vol(DATA / "blob.vol", blob_grid())
    write_vol(DATA / "albedo_rgb.vol", albedo_grid())
    write_vol(DATA / "sigma_t_rgb.vol", sigma_rgb_grid())
    write_vol(DATA / "sdf_torus.vol", sdf_grid())
    write_vol(DATA / "grey_albedo.vol", grey_albedo_grid())
    sig, alb = mitsuba_grids()
    write_vol(DATA / "mitsuba_sigmat.vol", sig)
    write_vol(DATA / "mitsuba_albedo.vol", alb)
    for p in sorted(DATA.iterdir()):
        print(f"{p.name:28s} {p.stat().st_size:7d} bytes")


if __name__ == "__main__":
    main()

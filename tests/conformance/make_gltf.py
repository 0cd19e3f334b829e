#!/usr/bin/env python3
"""Writes scenes/gltf_src/features.gltf, lights.gltf, normalmap.gltf and textures.gltf: small glTF 2.0 scenes exercising the parts
of the glTF loader that the showcase (scenes/gltf/showcase.gltf) does not, for the conformance
matrix.

lights.gltf: a floor lit only by KHR_lights_punctual lights — a point light, a spot light (inner
and outer cone angles) and a directional light, each on a rotated node — with a frosted-glass ball
(KHR_materials_transmission 1, KHR_materials_ior 1.45, tinted) and a plastic box whose ior (1.7)
sets its specular share.

textures.gltf: metallic-roughness and emissive textures — a tiled floor whose metallic-roughness
texture has the base colour's size (metal and dielectric tiles, roughness ramping along u), a
panel whose 4 x 4 metallic-roughness texture is smaller than its 8 x 8 base colour (resampled,
warned), a frosted ball (KHR_materials_transmission) with a roughness texture, a matte box
(metallic 0) with one, and a lamp whose emissive texture is scaled by emissiveStrength.

Deterministic, numpy and the standard library only:  python3 tests/conformance/make_gltf.py

What it holds (each line a loader rule of src/scene/gltf/mod.rs):
- two scenes, `scene: 1`: the first scene's node is not rendered;
- the camera on a child of a rotated parent, without `aspectRatio` (square image);
- `floor`: UNSIGNED_BYTE indices, a base-colour texture embedded as a data URI, read through
  TEXCOORD_1 (normalized UNSIGNED_SHORT) while TEXCOORD_0 holds other coordinates;
- `box`: no NORMAL (flat shading), no indices, a `matrix` with rotation and non-uniform scale,
  no material (glTF's default material: white, metallic 1, roughness 1);
- `ball`: an icosphere with normals and UNSIGNED_INT indices under a TRS with non-uniform scale
  (normals by the inverse transpose);
- `lamp`: one mesh of two primitives (meshes `lamp_0`, `lamp_1`), emissive without
  KHR_materials_emissive_strength, under a mirroring scale (determinant < 0: winding reversed,
  so the emitting side stays the front);
- two nodes named `post` (`post_5`, `post_6`) sharing the `plastic` material with `ball`.
"""

import base64
import json
import struct
from pathlib import Path

import numpy as np

from make_data import checker_texture, icosphere, png_bytes

OUT = Path(__file__).resolve().parent / "scenes" / "gltf_src"


class Builder:
    def __init__(self):
        self.data = bytearray()
        self.views, self.accessors = [], []

    def add(self, array, component, kind, target=None, normalized=False, minmax=False):
        while len(self.data) % 4:
            self.data.append(0)
        raw = array.tobytes()
        view = {"buffer": 0, "byteOffset": len(self.data), "byteLength": len(raw)}
        if target:
            view["target"] = target
        self.data += raw
        self.views.append(view)
        acc = {"bufferView": len(self.views) - 1, "componentType": component, "count": len(array), "type": kind}
        if normalized:
            acc["normalized"] = True
        if minmax:
            acc["min"] = [float(v) for v in array.min(axis=0)]
            acc["max"] = [float(v) for v in array.max(axis=0)]
        self.accessors.append(acc)
        return len(self.accessors) - 1

    def positions(self, p):
        return self.add(np.asarray(p, "<f4"), 5126, "VEC3", 34962, minmax=True)

    def vec3(self, v):
        return self.add(np.asarray(v, "<f4"), 5126, "VEC3", 34962)

    def vec2(self, v):
        return self.add(np.asarray(v, "<f4"), 5126, "VEC2", 34962)


def quad():
    """A unit quad in the xz plane facing +y (counter-clockwise seen from above)."""
    p = np.array([[-0.5, 0, -0.5], [-0.5, 0, 0.5], [0.5, 0, 0.5], [0.5, 0, -0.5]])
    return p, np.tile([0.0, 1.0, 0.0], (4, 1)), np.array([[0, 1, 2], [0, 2, 3]])


def cube_soup():
    """A unit cube centred at the origin as 12 separate triangles (36 vertices), outward winding."""
    tris = []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            n = np.zeros(3)
            n[axis] = sign
            u = np.zeros(3)
            u[(axis + 1) % 3] = 1.0
            v = np.cross(n, u)
            c = 0.5 * n
            corners = [c + 0.5 * (a * u + b * v) for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
            tris += [corners[0], corners[1], corners[2], corners[0], corners[2], corners[3]]
    return np.array(tris)


def main():
    b = Builder()
    # floor: a 4 x 4 quad; TEXCOORD_0 a decoy, TEXCOORD_1 the texture's (two repeats, normalized u16).
    p, n, t = quad()
    floor = {
        "POSITION": b.positions(p * [4, 1, 4]),
        "NORMAL": b.vec3(n),
        "TEXCOORD_0": b.vec2(np.zeros((4, 2))),
        "TEXCOORD_1": b.add(np.array([[0, 0], [0, 65535], [65535, 65535], [65535, 0]], "<u2"), 5123, "VEC2", 34962,
                            normalized=True),
    }
    floor_indices = b.add(np.asarray(t.reshape(-1), "<u1"), 5121, "SCALAR", 34963)
    box = {"POSITION": b.positions(cube_soup())}
    verts, faces = icosphere(1)
    verts = np.array(verts)
    ball = {"POSITION": b.positions(verts), "NORMAL": b.vec3(verts)}
    ball_indices = b.add(np.asarray(np.array(faces).reshape(-1), "<u4"), 5125, "SCALAR", 34963)
    # lamp: primitive 0 a quad facing -y after the mirroring node (its winding faces +x before),
    # primitive 1 a larger backing plate behind it.
    lp = np.array([[0, -0.6, -0.6], [0, 0.6, -0.6], [0, 0.6, 0.6], [0, -0.6, 0.6]])
    lamp_light = {"POSITION": b.positions(lp), "NORMAL": b.vec3(np.tile([1.0, 0, 0], (4, 1)))}
    lamp_light_indices = b.add(np.array([0, 1, 2, 0, 2, 3], "<u2"), 5123, "SCALAR", 34963)
    fp = lp * [1, 1.3, 1.3] + [-0.05, 0, 0]
    lamp_frame = {"POSITION": b.positions(fp), "NORMAL": b.vec3(np.tile([1.0, 0, 0], (4, 1)))}
    lamp_frame_indices = b.add(np.array([0, 1, 2, 0, 2, 3], "<u2"), 5123, "SCALAR", 34963)
    post = {"POSITION": b.positions(cube_soup() * [0.15, 0.8, 0.15])}

    # A cream and teal checker, its top-left quadrant red.
    png = png_bytes(checker_texture((235, 225, 200), (30, 130, 140), (210, 40, 30)))
    doc = {
        "asset": {"version": "2.0", "generator": "pathgrad tests/conformance/make_gltf.py"},
        "scene": 1,
        "scenes": [{"nodes": [0]}, {"nodes": [1, 3, 4, 5, 6, 7, 8]}],
        "nodes": [
            {"name": "not_rendered", "mesh": 1, "translation": [0, 1, 0]},
            {"name": "rig", "rotation": [-0.1736482, 0.0, 0.0, 0.9848078], "translation": [0.3, 2.2, 5.5],
             "children": [2]},
            {"name": "camera", "camera": 0, "rotation": [0.0, 0.0436194, 0.0, 0.9990482]},
            {"name": "floor", "mesh": 0},
            {"name": "box", "mesh": 1,
             # rotate 30 degrees about y, scale (0.8, 0.6, 0.5), translate (-1.1, 0.3, 0.2), column-major
             "matrix": [0.6928203, 0.0, -0.4, 0.0, 0.0, 0.6, 0.0, 0.0, 0.25, 0.0, 0.4330127, 0.0,
                        -1.1, 0.3, 0.2, 1.0]},
            {"name": "ball", "mesh": 2, "translation": [0.7, 0.45, 0.3], "scale": [0.55, 0.45, 0.4],
             "rotation": [0.0, 0.0, 0.258819, 0.9659258]},
            {"name": "lamp", "mesh": 3, "translation": [0.2, 2.6, 0.8],
             # rotate 90 degrees about z (+x -> +y), then mirror in y: the quad's +x side faces -y
             "rotation": [0.0, 0.0, 0.7071068, 0.7071068], "scale": [-1.0, 1.0, 1.0]},
            {"name": "post", "mesh": 4, "translation": [1.6, 0.4, -1.0]},
            {"name": "post", "mesh": 4, "translation": [-1.7, 0.4, -1.2]},
        ],
        "cameras": [{"type": "perspective", "perspective": {"yfov": 0.75, "znear": 0.05}}],
        "meshes": [
            {"name": "floor", "primitives": [{"attributes": floor, "indices": floor_indices, "material": 0}]},
            {"name": "box", "primitives": [{"attributes": box}]},
            {"name": "ball", "primitives": [{"attributes": ball, "indices": ball_indices, "material": 1}]},
            {"name": "lamp", "primitives": [
                {"attributes": lamp_light, "indices": lamp_light_indices, "material": 2},
                {"attributes": lamp_frame, "indices": lamp_frame_indices, "material": 1}]},
            {"name": "post", "primitives": [{"attributes": post, "material": 1}]},
        ],
        "materials": [
            {"name": "tiles", "pbrMetallicRoughness": {
                "baseColorFactor": [0.9, 0.85, 0.8, 1.0], "baseColorTexture": {"index": 0, "texCoord": 1},
                "metallicFactor": 0.0, "roughnessFactor": 0.6}},
            {"name": "plastic", "pbrMetallicRoughness": {
                "baseColorFactor": [0.8, 0.25, 0.1, 1.0], "metallicFactor": 0.25, "roughnessFactor": 0.45}},
            {"name": "lamp", "emissiveFactor": [1.0, 0.85, 0.7], "pbrMetallicRoughness": {
                "baseColorFactor": [0.1, 0.1, 0.1, 1.0], "metallicFactor": 0.0, "roughnessFactor": 1.0}},
        ],
        "textures": [{"source": 0, "sampler": 0}],
        "samplers": [{"magFilter": 9729, "minFilter": 9729, "wrapS": 10497, "wrapT": 10497}],
        "images": [{"uri": "data:image/png;base64," + base64.b64encode(png).decode()}],
        "accessors": b.accessors,
        "bufferViews": b.views,
        "buffers": [{"byteLength": len(b.data),
                     "uri": "data:application/octet-stream;base64," + base64.b64encode(bytes(b.data)).decode()}],
    }
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "features.gltf").write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {OUT / 'features.gltf'}")
    lights()
    normal_maps()
    textures()


def lights():
    b = Builder()
    p, n, t = quad()
    floor = {"POSITION": b.positions(p * [5, 1, 5]), "NORMAL": b.vec3(n)}
    floor_indices = b.add(np.asarray(t.reshape(-1), "<u2"), 5123, "SCALAR", 34963)
    verts, faces = icosphere(2)
    verts = np.array(verts)
    ball = {"POSITION": b.positions(verts), "NORMAL": b.vec3(verts)}
    ball_indices = b.add(np.asarray(np.array(faces).reshape(-1), "<u4"), 5125, "SCALAR", 34963)
    box = {"POSITION": b.positions(cube_soup())}
    # Rotations as quaternions (x, y, z, w): the spot and the sun look down (their -z) at an angle.
    down_45 = [-0.3826834, 0.0, 0.0, 0.9238795]
    down_60_turned = [-0.4829629, 0.2241439, 0.1294095, 0.8365163]
    doc = {
        "asset": {"version": "2.0", "generator": "pathgrad tests/conformance/make_gltf.py"},
        "extensionsUsed": ["KHR_lights_punctual", "KHR_materials_transmission", "KHR_materials_ior"],
        "extensions": {"KHR_lights_punctual": {"lights": [
            {"type": "point", "color": [1.0, 0.9, 0.8], "intensity": 6.0},
            {"type": "spot", "color": [0.6, 0.8, 1.0], "intensity": 25.0,
             "spot": {"innerConeAngle": 0.25, "outerConeAngle": 0.5}},
            {"type": "directional", "color": [1.0, 0.95, 0.85], "intensity": 0.8},
        ]}},
        "scene": 0,
        "scenes": [{"nodes": [0, 1, 2, 3, 4, 5, 6]}],
        "nodes": [
            {"name": "camera", "camera": 0, "translation": [0.0, 1.6, 4.5],
             "rotation": [-0.1736482, 0.0, 0.0, 0.9848078]},
            {"name": "floor", "mesh": 0},
            {"name": "ball", "mesh": 1, "translation": [-0.6, 0.5, 0.0], "scale": [0.5, 0.5, 0.5]},
            {"name": "box", "mesh": 2, "translation": [0.8, 0.35, -0.3], "scale": [0.7, 0.7, 0.7],
             "rotation": [0.0, 0.2588190, 0.0, 0.9659258]},
            {"name": "bulb", "translation": [1.2, 2.0, 1.5], "extensions": {"KHR_lights_punctual": {"light": 0}}},
            {"name": "spot", "translation": [-1.0, 2.5, 2.0], "rotation": down_45,
             "extensions": {"KHR_lights_punctual": {"light": 1}}},
            {"name": "sun", "rotation": down_60_turned, "extensions": {"KHR_lights_punctual": {"light": 2}}},
        ],
        "cameras": [{"type": "perspective", "perspective": {"yfov": 0.7, "aspectRatio": 1.25, "znear": 0.05}}],
        "meshes": [
            {"name": "floor", "primitives": [{"attributes": floor, "indices": floor_indices, "material": 0}]},
            {"name": "ball", "primitives": [{"attributes": ball, "indices": ball_indices, "material": 1}]},
            {"name": "box", "primitives": [{"attributes": box, "material": 2}]},
        ],
        "materials": [
            {"name": "floor", "pbrMetallicRoughness": {
                "baseColorFactor": [0.7, 0.7, 0.65, 1.0], "metallicFactor": 0.0, "roughnessFactor": 0.9}},
            {"name": "glass", "pbrMetallicRoughness": {
                "baseColorFactor": [0.9, 0.95, 0.8, 1.0], "metallicFactor": 0.0, "roughnessFactor": 0.35},
             "extensions": {"KHR_materials_transmission": {"transmissionFactor": 1.0},
                            "KHR_materials_ior": {"ior": 1.45}}},
            {"name": "plastic", "pbrMetallicRoughness": {
                "baseColorFactor": [0.2, 0.4, 0.8, 1.0], "metallicFactor": 0.0, "roughnessFactor": 0.4},
             "extensions": {"KHR_materials_ior": {"ior": 1.7}}},
        ],
        "accessors": b.accessors,
        "bufferViews": b.views,
        "buffers": [{"byteLength": len(b.data),
                     "uri": "data:application/octet-stream;base64," + base64.b64encode(bytes(b.data)).decode()}],
    }
    (OUT / "lights.gltf").write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {OUT / 'lights.gltf'}")


def normal_texture():
    """8 x 8 tangent-space normals, stored as (n + 1)/2: tilted towards +x in the left half and
    towards -x in the right, towards +y in the top two rows and -y in the bottom two, so a flip in
    u or v, a swapped channel or a mirrored bitangent changes the image."""
    img = np.zeros((8, 8, 3), np.uint8)
    for y in range(8):
        for x in range(8):
            sx = 0.6 if x < 4 else -0.3
            sy = 0.5 if y < 2 else (-0.4 if y >= 6 else 0.0)
            n = np.array([sx, sy, 1.0]) / np.linalg.norm([sx, sy, 1.0])
            img[y, x] = np.round((n + 1.0) * 0.5 * 255.0)
    return img


def normal_maps():
    """normalmap.gltf: glTF normal textures — a double-sided plastic floor (a blend, no base-colour texture)
    with a normal texture of scale 0.7 repeated three times, a metallic panel facing the camera
    with the same texture at scale 1, under an emissive quad."""
    b = Builder()
    p, n, t = quad()
    uv = np.stack([p[:, 0] + 0.5, p[:, 2] + 0.5], axis=1)
    floor = {"POSITION": b.positions(p * [5, 1, 5]), "NORMAL": b.vec3(n), "TEXCOORD_0": b.vec2(uv * 3.0)}
    panel = {"POSITION": b.positions(p), "NORMAL": b.vec3(n), "TEXCOORD_0": b.vec2(uv)}
    lamp = {"POSITION": b.positions(p), "NORMAL": b.vec3(n)}
    indices = b.add(np.asarray(t.reshape(-1), "<u2"), 5123, "SCALAR", 34963)
    png = png_bytes(normal_texture())
    doc = {
        "asset": {"version": "2.0", "generator": "pathgrad tests/conformance/make_gltf.py"},
        "extensionsUsed": ["KHR_materials_emissive_strength"],
        "scene": 0,
        "scenes": [{"nodes": [0, 1, 2, 3]}],
        "nodes": [
            {"name": "camera", "camera": 0, "translation": [0.0, 2.0, 4.2],
             "rotation": [-0.1736482, 0.0, 0.0, 0.9848078]},
            {"name": "floor", "mesh": 0},
            # a 1.4 x 1.4 panel tilted 60 degrees about x: its +y normal turns towards +z
            {"name": "panel", "mesh": 1, "translation": [0.5, 0.75, 0.3], "scale": [1.4, 1.4, 1.4],
             "rotation": [0.5, 0.0, 0.0, 0.8660254]},
            # the lamp quad turned over (180 degrees about x): it faces -y
            {"name": "lamp", "mesh": 2, "translation": [-0.6, 2.4, 0.8], "scale": [1.2, 1.0, 1.2],
             "rotation": [1.0, 0.0, 0.0, 0.0]},
        ],
        "cameras": [{"type": "perspective", "perspective": {"yfov": 0.8, "aspectRatio": 1.25, "znear": 0.05}}],
        "meshes": [
            {"name": "floor", "primitives": [{"attributes": floor, "indices": indices, "material": 0}]},
            {"name": "panel", "primitives": [{"attributes": panel, "indices": indices, "material": 1}]},
            {"name": "lamp", "primitives": [{"attributes": lamp, "indices": indices, "material": 2}]},
        ],
        "materials": [
            {"name": "bumpy", "doubleSided": True, "normalTexture": {"index": 0, "scale": 0.7},
             "pbrMetallicRoughness": {"baseColorFactor": [0.7, 0.6, 0.5, 1.0], "metallicFactor": 0.0,
                                      "roughnessFactor": 0.5}},
            {"name": "brushed", "normalTexture": {"index": 0},
             "pbrMetallicRoughness": {"baseColorFactor": [0.9, 0.8, 0.6, 1.0], "metallicFactor": 1.0,
                                      "roughnessFactor": 0.3}},
            {"name": "lamp", "emissiveFactor": [1.0, 0.9, 0.8],
             "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 6.0}},
             "pbrMetallicRoughness": {"baseColorFactor": [0.0, 0.0, 0.0, 1.0], "metallicFactor": 0.0,
                                      "roughnessFactor": 1.0}},
        ],
        "textures": [{"source": 0}],
        "images": [{"uri": "data:image/png;base64," + base64.b64encode(png).decode()}],
        "accessors": b.accessors,
        "bufferViews": b.views,
        "buffers": [{"byteLength": len(b.data),
                     "uri": "data:application/octet-stream;base64," + base64.b64encode(bytes(b.data)).decode()}],
    }
    (OUT / "normalmap.gltf").write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {OUT / 'normalmap.gltf'}")


def metal_rough_texture(size, roughness, metallic):
    """size x size metallic-roughness texels (R unused, G roughness, B metallic) from two
    functions of the texel (x, y)."""
    img = np.zeros((size, size, 3), np.uint8)
    for y in range(size):
        for x in range(size):
            img[y, x] = (17, round(255 * roughness(x, y)), round(255 * metallic(x, y)))
    return img


def textures():
    """textures.gltf: metallic-roughness and emissive textures (see the module's docstring)."""
    b = Builder()
    p, n, t = quad()
    uv = np.stack([p[:, 0] + 0.5, p[:, 2] + 0.5], axis=1)
    floor = {"POSITION": b.positions(p * [5, 1, 5]), "NORMAL": b.vec3(n), "TEXCOORD_0": b.vec2(uv * 2.0)}
    panel = {"POSITION": b.positions(p), "NORMAL": b.vec3(n), "TEXCOORD_0": b.vec2(uv)}
    indices = b.add(np.asarray(t.reshape(-1), "<u2"), 5123, "SCALAR", 34963)
    verts, faces = icosphere(2)
    verts = np.array(verts)
    # the ball's texture coordinates: longitude and latitude
    ball_uv = np.stack([np.arctan2(verts[:, 2], verts[:, 0]) / (2 * np.pi) + 0.5,
                        np.arccos(np.clip(verts[:, 1], -1, 1)) / np.pi], axis=1)
    ball = {"POSITION": b.positions(verts), "NORMAL": b.vec3(verts), "TEXCOORD_0": b.vec2(ball_uv * [3, 2])}
    ball_indices = b.add(np.asarray(np.array(faces).reshape(-1), "<u2"), 5123, "SCALAR", 34963)
    box = {"POSITION": b.positions(cube_soup() * [0.7, 0.7, 0.7]),
           "TEXCOORD_0": b.vec2(np.tile([[0, 0], [1, 0], [1, 1]], (12, 1)))}
    lamp = {"POSITION": b.positions(p), "NORMAL": b.vec3(n), "TEXCOORD_0": b.vec2(uv)}
    base = png_bytes(checker_texture((235, 225, 200), (30, 130, 140), (210, 40, 30)))
    tiles_mr = png_bytes(metal_rough_texture(8, lambda x, y: 0.15 + 0.1 * x, lambda x, y: 0.9 * ((x // 2 + y // 2) % 2)))
    worn_mr = png_bytes(metal_rough_texture(4, lambda x, y: 0.3 + 0.15 * y, lambda x, y: 0.25 * x + 0.1))
    frost_mr = png_bytes(metal_rough_texture(4, lambda x, y: 0.2 + 0.2 * ((x + y) % 3), lambda x, y: 0.0))
    glow = np.zeros((4, 4, 3), np.uint8)
    for y in range(4):
        for x in range(4):
            glow[y, x] = (255, 200, 120) if (x + y) % 2 == 0 else (120, 180, 255)
    glow = png_bytes(glow)
    image = lambda png: {"uri": "data:image/png;base64," + base64.b64encode(png).decode()}
    doc = {
        "asset": {"version": "2.0", "generator": "pathgrad tests/conformance/make_gltf.py"},
        "extensionsUsed": ["KHR_materials_emissive_strength", "KHR_materials_transmission"],
        "scene": 0,
        "scenes": [{"nodes": [0, 1, 2, 3, 4, 5]}],
        "nodes": [
            {"name": "camera", "camera": 0, "translation": [0.0, 2.2, 4.4],
             "rotation": [-0.2164396, 0.0, 0.0, 0.9762960]},
            {"name": "floor", "mesh": 0},
            # a 1.6 x 1.6 panel tilted 70 degrees about x, towards the camera
            {"name": "panel", "mesh": 1, "translation": [0.9, 0.8, -0.4], "scale": [1.6, 1.6, 1.6],
             "rotation": [0.5735764, 0.0, 0.0, 0.8191520]},
            {"name": "ball", "mesh": 2, "translation": [-1.0, 0.6, 0.3], "scale": [0.6, 0.6, 0.6]},
            {"name": "box", "mesh": 3, "translation": [0.2, 0.35, 1.1], "rotation": [0.0, 0.3826834, 0.0, 0.9238795]},
            # the lamp quad turned over (180 degrees about x): it faces -y
            {"name": "lamp", "mesh": 4, "translation": [0.0, 3.0, 0.5], "scale": [2.0, 1.0, 1.5],
             "rotation": [1.0, 0.0, 0.0, 0.0]},
        ],
        "cameras": [{"type": "perspective", "perspective": {"yfov": 0.9, "aspectRatio": 1.25, "znear": 0.05}}],
        "meshes": [
            {"name": "floor", "primitives": [{"attributes": floor, "indices": indices, "material": 0}]},
            {"name": "panel", "primitives": [{"attributes": panel, "indices": indices, "material": 1}]},
            {"name": "ball", "primitives": [{"attributes": ball, "indices": ball_indices, "material": 2}]},
            {"name": "box", "primitives": [{"attributes": box, "material": 3}]},
            {"name": "lamp", "primitives": [{"attributes": lamp, "indices": indices, "material": 4}]},
        ],
        "materials": [
            {"name": "tiles", "pbrMetallicRoughness": {
                "baseColorTexture": {"index": 0}, "metallicRoughnessTexture": {"index": 1},
                "metallicFactor": 1.0, "roughnessFactor": 1.0}},
            {"name": "worn", "pbrMetallicRoughness": {
                "baseColorTexture": {"index": 0}, "metallicRoughnessTexture": {"index": 2},
                "baseColorFactor": [0.9, 0.8, 0.7, 1.0], "metallicFactor": 0.8, "roughnessFactor": 0.6}},
            {"name": "frosted", "extensions": {"KHR_materials_transmission": {"transmissionFactor": 1.0}},
             "pbrMetallicRoughness": {"baseColorFactor": [0.9, 0.95, 1.0, 1.0], "metallicFactor": 0.0,
                                      "metallicRoughnessTexture": {"index": 3}, "roughnessFactor": 0.8}},
            {"name": "matte", "pbrMetallicRoughness": {"baseColorFactor": [0.3, 0.5, 0.3, 1.0], "metallicFactor": 0.0,
                                                       "metallicRoughnessTexture": {"index": 1}}},
            {"name": "lamp", "emissiveFactor": [1.0, 1.0, 1.0], "emissiveTexture": {"index": 4},
             "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 8.0}},
             "pbrMetallicRoughness": {"baseColorFactor": [0.0, 0.0, 0.0, 1.0], "metallicFactor": 0.0}},
        ],
        "textures": [{"source": i} for i in range(5)],
        "images": [image(base), image(tiles_mr), image(worn_mr), image(frost_mr), image(glow)],
        "accessors": b.accessors,
        "bufferViews": b.views,
        "buffers": [{"byteLength": len(b.data),
                     "uri": "data:application/octet-stream;base64," + base64.b64encode(bytes(b.data)).decode()}],
    }
    (OUT / "textures.gltf").write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {OUT / 'textures.gltf'}")


if __name__ == "__main__":
    main()

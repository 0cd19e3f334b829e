#!/usr/bin/env python3
"""Writes a Mitsuba 3 XML scene that is a glTF 2.0 file as pathgrad reads it: the conformance
matrix's Mitsuba side of a glTF scene.

pathgrad maps glTF's metallic-roughness materials to its own BSDFs by a documented table
(src/scene/gltf/mod.rs, "Materials"). This script restates that table and glTF's node, mesh and
camera rules in Python, independently of pathgrad's Rust loader, and writes:

    OUT/NAME.xml              the scene: a perspective sensor, one `ply` shape per primitive in
                              world space, one BSDF per material (id = pathgrad's material name),
                              area emitters for emissive materials, integrator `prb`
    OUT/NAME/*.ply            the meshes (binary, world space, with normals/uv as present)
    OUT/NAME/*.exr            base-colour textures, linear and multiplied by baseColorFactor; normal
                              textures as stored, their scale folded in (inside a normalmap); the
                              textures a metallic-roughness texture becomes (α, blend weight,
                              specular colour per texel) and emissive textures times their
                              factor and strength

and returns the map from each parameter pathgrad exposes to the key Mitsuba's `mi.traverse`
gives the same quantity, which the reference JSON stores (`pathgrad_keys`). Mitsuba renders the
XML; pathgrad renders the glTF file itself. So the comparison checks pathgrad's glTF loader
(accessors, node transforms, normals, texture coordinates, camera, names) and its renderer
together against Mitsuba rendering the mapped materials; it does not check the mapping against
glTF's own BRDF (appendix B), which pathgrad approximates and says so in a warning.

Shapes are named `<mesh>__shape` in the XML (a glTF material and a node may share a name, and
XML ids may not); everything else keeps pathgrad's names.

    /tmp/mi/bin/python tests/conformance/gltf_to_mitsuba.py IN.gltf OUT_DIR NAME [--width W]
"""

import argparse
import base64
import json
import math
import struct
from pathlib import Path

import numpy as np

DIELECTRIC_F0 = 0.04
ALPHA_MIN = 1e-3
DEFAULT_WIDTH = 512
COMPONENTS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}
TYPES = {5120: ("<i1", 127.0), 5121: ("<u1", 255.0), 5122: ("<i2", 32767.0), 5123: ("<u2", 65535.0),
         5125: ("<u4", None), 5126: ("<f4", None)}


def sanitize(name):
    return "".join(c if (c.isascii() and c.isalnum()) or c in "_-" else "_" for c in name)


def unique_names(names, kind):
    """pathgrad's names: sanitized, `KIND_i` when empty, `_i` appended to names used twice."""
    out = [sanitize(n) if n and sanitize(n) else f"{kind}_{i}" for i, n in enumerate(names)]
    counts = {}
    for n in out:
        counts[n] = counts.get(n, 0) + 1
    taken = {n for n in out if counts[n] == 1}
    result = []
    for i, n in enumerate(out):
        if counts[n] == 1:
            result.append(n)
            continue
        candidate = fresh(taken, f"{n}_{i}")
        taken.add(candidate)
        result.append(candidate)
    return result


def fresh(taken, candidate):
    name, k = candidate, 2
    while name in taken:
        name, k = f"{candidate}_{k}", k + 1
    return name


def srgb_to_linear(c):
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


class Gltf:
    def __init__(self, path):
        self.path = Path(path)
        raw = self.path.read_bytes()
        self.blob = None
        if raw[:4] == b"glTF":
            offset, chunks = 12, {}
            while offset + 8 <= len(raw):
                length, kind = struct.unpack_from("<II", raw, offset)
                chunks[kind] = raw[offset + 8:offset + 8 + length]
                offset += 8 + length
            self.doc = json.loads(chunks[0x4E4F534A])
            self.blob = chunks.get(0x004E4942)
        else:
            self.doc = json.loads(raw)
        self.buffers = [self._buffer(i, b) for i, b in enumerate(self.doc.get("buffers", []))]

    def _uri(self, uri):
        if uri.startswith("data:"):
            return base64.b64decode(uri.split(",", 1)[1])
        return (self.path.parent / uri).read_bytes()

    def _buffer(self, index, b):
        return self._uri(b["uri"]) if "uri" in b else self.blob

    def view(self, index):
        v = self.doc["bufferViews"][index]
        start = v.get("byteOffset", 0)
        return self.buffers[v["buffer"]][start:start + v["byteLength"]], v.get("byteStride")

    def accessor(self, index):
        """An accessor as float64 (normalized integers scaled) or int64 array, shape (count, n)."""
        a = self.doc["accessors"][index]
        dtype, norm = TYPES[a["componentType"]]
        n = COMPONENTS[a["type"]]
        data, stride = self.view(a["bufferView"])
        item = np.dtype(dtype).itemsize
        stride = stride or item * n
        offset = a.get("byteOffset", 0)
        rows = [np.frombuffer(data, dtype, n, offset + i * stride) for i in range(a["count"])]
        out = np.array(rows).reshape(a["count"], n)
        if a.get("normalized") and norm:
            return np.maximum(out.astype(np.float64) / norm, -1.0)
        return out.astype(np.int64) if norm or dtype == "<u4" else out.astype(np.float64)

    def image_rgb(self, index):
        """Image `index` as its 8-bit sRGB values / 255 (RGB, row 0 at the top), decoded by Mitsuba."""
        import tempfile
        import mitsuba as mi
        img = self.doc["images"][index]
        raw = self.view(img["bufferView"])[0] if "bufferView" in img else self._uri(img["uri"])
        with tempfile.NamedTemporaryFile(suffix=".img") as f:
            f.write(bytes(raw))
            f.flush()
            bitmap = mi.Bitmap(f.name)
        assert bitmap.component_format() == mi.Struct.Type.UInt8, "8-bit images only"
        bitmap = bitmap.convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.UInt8, srgb_gamma=bitmap.srgb_gamma())
        return np.array(bitmap, dtype=np.float64) / 255.0


def local_matrix(node):
    if "matrix" in node:
        return np.array(node["matrix"], np.float64).reshape(4, 4).T
    t = np.array(node.get("translation", [0, 0, 0]), np.float64)
    s = np.array(node.get("scale", [1, 1, 1]), np.float64)
    x, y, z, w = np.array(node.get("rotation", [0, 0, 0, 1]), np.float64) / np.linalg.norm(node.get("rotation", [0, 0, 0, 1]))
    r = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                  [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                  [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    m = np.eye(4)
    m[:3, :3] = r * s
    m[:3, 3] = t
    return m


def write_ply(path, positions, normals, uvs, faces):
    props = ["x", "y", "z"] + (["nx", "ny", "nz"] if normals is not None else []) + (["u", "v"] if uvs is not None else [])
    header = ["ply", "format binary_little_endian 1.0", f"element vertex {len(positions)}"]
    header += [f"property float {p}" for p in props]
    header += [f"element face {len(faces)}", "property list uchar int vertex_indices", "end_header"]
    cols = [positions] + ([normals] if normals is not None else []) + ([uvs] if uvs is not None else [])
    verts = np.hstack(cols).astype("<f4")
    with open(path, "wb") as f:
        f.write(("\n".join(header) + "\n").encode())
        for v in verts:
            f.write(v.tobytes())
        for t in faces:
            f.write(struct.pack("<B3i", 3, *(int(i) for i in t)))


def rgb(v):
    return ", ".join(f"{float(x):.9g}" for x in v)


def bitmap(name, file):
    """A raw (linear) bitmap texture on property `name`."""
    return (f'<texture type="bitmap" name="{name}"><string name="filename" value="{file}"/>'
            f'<boolean name="raw" value="true"/></texture>')


def resample(texels, width, height):
    """RGB `texels` (rows, columns, 3) looked up bilinearly, repeating, at the centres of a
    `width` × `height` grid: pathgrad's texture filter (src/cpu/surface.rs `texture_footprint`)."""
    h, w, _ = texels.shape
    x = (np.arange(width) + 0.5) / width * w - 0.5
    y = (np.arange(height) + 0.5) / height * h - 0.5
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = (x - x0)[None, :, None], (y - y0)[:, None, None]
    x1, y1 = (x0 + 1) % w, (y0 + 1) % h
    x0, y0 = x0 % w, y0 % h
    top = texels[y0][:, x0] * (1 - fx) + texels[y0][:, x1] * fx
    bottom = texels[y1][:, x0] * (1 - fx) + texels[y1][:, x1] * fx
    return top * (1 - fy) + bottom * fy


class Converter:
    def __init__(self, gltf, out_dir, name, width):
        self.g, self.doc = gltf, gltf.doc
        self.out_dir, self.name, self.width = Path(out_dir), name, width
        self.assets = self.out_dir / name
        self.material_names = unique_names([m.get("name") for m in self.doc.get("materials", [])], "material")
        self.node_names = unique_names([n.get("name") for n in self.doc.get("nodes", [])], "node")
        self.taken = set(self.node_names)
        self.materials = {}  # index (None: default) -> (name, xml, radiance, tex_coord)
        self.keys = {}  # pathgrad name -> Mitsuba key
        self.shapes, self.emitters, self.sensor = [], [], None

    # ---- materials (src/scene/gltf/mod.rs, "Materials") ----
    def material(self, index):
        if index in self.materials:
            return self.materials[index]
        m = self.doc["materials"][index] if index is not None else {}
        name = self.material_names[index] if index is not None else "default_material"
        pbr = m.get("pbrMetallicRoughness", {})
        base = np.array(pbr.get("baseColorFactor", [1, 1, 1, 1])[:3], np.float64)
        metallic, roughness = pbr.get("metallicFactor", 1.0), pbr.get("roughnessFactor", 1.0)
        alpha = max(roughness * roughness, ALPHA_MIN)
        ext = m.get("extensions", {})
        ior = ext.get("KHR_materials_ior", {}).get("ior", 1.5)
        f0 = ((ior - 1.0) / (ior + 1.0)) ** 2
        transmits = ext.get("KHR_materials_transmission", {}).get("transmissionFactor", 0.0) > 0 and metallic < 1.0
        double_sided = m.get("doubleSided") and not transmits
        prefix = f"{name}.brdf_0" if double_sided else name
        # A normal texture wraps the material in a normalmap (inside the twosided), its scale
        # folded into the stored texels: (2·rgb − 1)·(s, s, 1) kept as (n + 1)/2.
        normal_map = None
        if "normalTexture" in m:
            info = m["normalTexture"]
            source = self.doc["textures"][info["index"]]["source"]
            texels = self.g.image_rgb(source)
            texels[..., :2] = ((2.0 * texels[..., :2] - 1.0) * info.get("scale", 1.0) + 1.0) * 0.5
            normal_map = self.write_texture(name, texels, "normal")
            prefix += ".nested_bsdf"
        texture, base_texels, mean, tex_coord = None, None, base, None

        def same_set(info):
            nonlocal tex_coord
            set_ = info.get("texCoord", 0)
            assert tex_coord in (None, set_), "pathgrad refuses two texture coordinate sets"
            tex_coord = set_

        if "baseColorTexture" in pbr:
            info = pbr["baseColorTexture"]
            source = self.doc["textures"][info["index"]]["source"]
            base_texels = np.clip(srgb_to_linear(self.g.image_rgb(source)) * base, 0.0, 1.0)
            mean = base_texels.reshape(-1, 3).mean(axis=0)
            same_set(info)
        # The metallic-roughness texture: roughness in G, metallic in B, stored values times the factors.
        rough_texels = metal_texels = None
        if "metallicRoughnessTexture" in pbr:
            info = pbr["metallicRoughnessTexture"]
            stored = self.g.image_rgb(self.doc["textures"][info["index"]]["source"])
            rough_texels = np.clip(stored[..., 1] * roughness, 0.0, 1.0)
            metal_texels = np.clip(stored[..., 2] * metallic, 0.0, 1.0)
            same_set(info)
        strength = m.get("extensions", {}).get("KHR_materials_emissive_strength", {}).get("emissiveStrength", 1.0)
        radiance = np.array(m.get("emissiveFactor", [0, 0, 0]), np.float64) * strength
        if radiance.max() > 0 and "emissiveTexture" in m:
            info = m["emissiveTexture"]
            stored = self.g.image_rgb(self.doc["textures"][info["index"]]["source"])
            radiance = self.write_texture(name, srgb_to_linear(stored) * radiance, "emission")
            same_set(info)
        elif "emissiveTexture" in m:
            same_set(m["emissiveTexture"])
        if "normalTexture" in m:
            same_set(m["normalTexture"])
        textured_metal = metal_texels is not None and metallic > 0.0 and not transmits

        def alpha_xml(key, pathgrad):
            """The roughness: α = max(r², 10⁻³), a texture of the metallic-roughness texels or one value."""
            if rough_texels is None:
                self.keys[f"{pathgrad}.alpha.value"] = f"{key}.alpha.value"
                return f'<float name="alpha" value="{alpha:.9g}"/>'
            file = self.write_texture(pathgrad, np.maximum(rough_texels ** 2, ALPHA_MIN), "alpha")
            self.keys[f"{pathgrad}.alpha.data"] = f"{key}.alpha.data"
            return bitmap("alpha", file)

        def conductor(specular, key, pathgrad):
            colour = (bitmap("specular_reflectance", specular) if isinstance(specular, str)
                      else f'<rgb name="specular_reflectance" value="{rgb(specular)}"/>')
            return (f'<bsdf type="roughconductor"><string name="distribution" value="ggx"/>'
                    f'{alpha_xml(key, pathgrad)}{colour}</bsdf>')

        def diffuse_xml():
            if base_texels is None:
                self.keys[f"{name}.bsdf_0.reflectance.value"] = f"{prefix}.bsdf_0.reflectance.value"
                return f'<bsdf type="diffuse"><rgb name="reflectance" value="{rgb(base)}"/></bsdf>'
            self.keys[f"{name}.base_color.data"] = f"{prefix}.bsdf_0.reflectance.data"
            return f'<bsdf type="diffuse">{bitmap("reflectance", self.write_texture(name, base_texels))}</bsdf>'

        if textured_metal:
            # Per metallic-roughness texel: w = F0 + (1 − F0)·m, s = (m·b + F0·(1 − m))/w, b the base
            # colour there (resampled bilinearly at the texel centres when the sizes differ).
            h, w_ = metal_texels.shape
            colour = base if base_texels is None else resample(base_texels, w_, h)
            m_ = metal_texels[..., None]
            weight = f0 + (1.0 - f0) * m_
            specular = np.minimum((m_ * colour + f0 * (1.0 - m_)) / weight, 1.0)
            weight_file = self.write_texture(name, weight[..., 0], "weight")
            specular_file = self.write_texture(name, specular, "specular")
            self.keys[f"{name}.weight.data"] = f"{prefix}.weight.data"
            self.keys[f"{name}.bsdf_1.specular_reflectance.data"] = f"{prefix}.bsdf_1.specular_reflectance.data"
            xml = (f'<bsdf type="blendbsdf">{bitmap("weight", weight_file)}\n            {diffuse_xml()}\n'
                   f'            {conductor(specular_file, prefix + ".bsdf_1", name + ".bsdf_1")}\n        </bsdf>')
        elif metallic >= 1.0:
            assert base_texels is None, "a textured metallic material is approximated by pathgrad (warned); not converted"
            xml = conductor(mean, prefix, name)
            self.keys[f"{name}.specular_reflectance.value"] = f"{prefix}.specular_reflectance.value"
        elif transmits:
            assert base_texels is None, "a textured transmitting material is approximated by pathgrad (warned)"
            # A rough dielectric (transmission taken as 1, metallic as 0), tinted by the mean colour.
            xml = (f'<bsdf type="roughdielectric"><string name="distribution" value="ggx"/>'
                   f'{alpha_xml(prefix, name)}<float name="int_ior" value="{ior:.9g}"/>'
                   f'<float name="ext_ior" value="1"/><rgb name="specular_transmittance" value="{rgb(mean)}"/></bsdf>')
            self.keys[f"{name}.specular_transmittance.value"] = f"{prefix}.specular_transmittance.value"
        else:
            assert base_texels is None or metallic == 0.0, "a textured metallic material is approximated (warned)"
            w = f0 + (1.0 - f0) * metallic
            specular = np.minimum((metallic * mean + f0 * (1.0 - metallic)) / w, 1.0)
            xml = (f'<bsdf type="blendbsdf"><float name="weight" value="{w:.9g}"/>\n            {diffuse_xml()}\n'
                   f'            {conductor(specular, prefix + ".bsdf_1", name + ".bsdf_1")}\n        </bsdf>')
            self.keys[f"{name}.weight.value"] = f"{prefix}.weight.value"
            self.keys[f"{name}.bsdf_1.specular_reflectance.value"] = f"{prefix}.bsdf_1.specular_reflectance.value"
        if normal_map:
            xml = (f'<bsdf type="normalmap">\n        <texture type="bitmap" name="normalmap">'
                   f'<string name="filename" value="{normal_map}"/><boolean name="raw" value="true"/></texture>\n'
                   f'        {xml}\n    </bsdf>')
        if double_sided:
            xml = f'<bsdf type="twosided">\n        {xml}\n    </bsdf>'
        xml = xml.replace("<bsdf type=", f'<bsdf id="{name}" type=', 1)
        entry = (name, xml, radiance if isinstance(radiance, str) or radiance.max() > 0 else None, tex_coord)
        self.materials[index] = entry
        return entry

    def write_texture(self, name, texels, kind="base_color"):
        """An EXR of linear texels (RGB, or one channel for a 2-D array) beside the scene."""
        import mitsuba as mi
        self.assets.mkdir(parents=True, exist_ok=True)
        file = self.assets / f"{name}_{kind}.exr"
        fmt = mi.Bitmap.PixelFormat.Y if texels.ndim == 2 else mi.Bitmap.PixelFormat.RGB
        mi.Bitmap(np.ascontiguousarray(texels, dtype=np.float32), fmt).write(str(file))
        return f"{self.name}/{file.name}"

    # ---- nodes ----
    def run(self):
        doc = self.doc
        if "scene" in doc:
            roots = doc["scenes"][doc["scene"]]["nodes"]
        elif doc.get("scenes"):
            roots = doc["scenes"][0]["nodes"]
        else:
            children = {c for n in doc.get("nodes", []) for c in n.get("children", [])}
            roots = [i for i in range(len(doc.get("nodes", []))) if i not in children]
        stack = [(r, np.eye(4)) for r in reversed(roots)]
        while stack:
            index, parent = stack.pop()
            node = doc["nodes"][index]
            world = parent @ local_matrix(node)
            if "camera" in node and self.sensor is None:
                self.camera(node["camera"], world, index)
            if "KHR_lights_punctual" in node.get("extensions", {}):
                self.light(node["extensions"]["KHR_lights_punctual"]["light"], world, index)
            if "mesh" in node:
                self.mesh(index, node["mesh"], world)
            for child in reversed(node.get("children", [])):
                stack.append((child, world))
        assert self.sensor is not None, "the conformance scenes carry a perspective camera"

    # ---- lights (src/scene/gltf/mod.rs, "Lights") ----
    def light(self, index, world, node):
        light = self.doc["extensions"]["KHR_lights_punctual"]["lights"][index]
        name = self.node_names[node]
        value = np.array(light.get("color", [1, 1, 1]), np.float64) * light.get("intensity", 1.0)
        position = world[:3, 3]
        axis = world[:3, :3] @ np.array([0, 0, -1.0])
        axis /= np.linalg.norm(axis)
        kind = light["type"]
        if kind == "point":
            body = f'<point name="position" value="{rgb(position)}"/><rgb name="intensity" value="{rgb(value)}"/>'
            key = "intensity"
        elif kind == "spot":
            spot = light.get("spot", {})
            inner, outer = spot.get("innerConeAngle", 0.0), spot.get("outerConeAngle", math.pi / 4)
            up = np.array([0, 1.0, 0]) if abs(axis[1]) < 0.9 else np.array([1.0, 0, 0])
            body = (f'<transform name="to_world"><lookat origin="{rgb(position)}" target="{rgb(position + axis)}" '
                    f'up="{rgb(up)}"/></transform><float name="cutoff_angle" value="{math.degrees(outer):.9g}"/>'
                    f'<float name="beam_width" value="{max(math.degrees(inner), 1e-3):.9g}"/>'
                    f'<rgb name="intensity" value="{rgb(value)}"/>')
            key = "intensity"
        else:
            body = f'<vector name="direction" value="{rgb(axis)}"/><rgb name="irradiance" value="{rgb(value)}"/>'
            key = "irradiance"
        self.emitters.append(f'    <emitter type="{kind}" id="{name}">{body}</emitter>')
        self.keys[f"{name}.{key}.value"] = f"{name}.{key}.value"

    def camera(self, index, world, node):
        p = self.doc["cameras"][index]["perspective"]
        aspect = p.get("aspectRatio")
        width = self.width or DEFAULT_WIDTH
        height = max(1, round(width / aspect)) if aspect else width
        origin = world[:3, 3]
        forward = world[:3, :3] @ np.array([0, 0, -1.0])
        forward /= np.linalg.norm(forward)
        up = world[:3, :3] @ np.array([0, 1.0, 0])
        up /= np.linalg.norm(up)
        self.sensor = f"""    <sensor type="perspective" id="{self.node_names[node]}">
        <float name="fov" value="{math.degrees(p['yfov']):.9g}"/>
        <string name="fov_axis" value="y"/>
        <float name="near_clip" value="0.001"/>
        <transform name="to_world"><lookat origin="{rgb(origin)}" target="{rgb(origin + forward)}" up="{rgb(up)}"/></transform>
        <film type="hdrfilm">
            <integer name="width" value="{width}"/>
            <integer name="height" value="{height}"/>
            <rfilter type="box"/>
        </film>
    </sensor>"""

    def mesh(self, node, index, world):
        primitives = self.doc["meshes"][index]["primitives"]
        for j, prim in enumerate(primitives):
            assert prim.get("mode", 4) == 4
            material, xml, radiance, tex_coord = self.material(prim.get("material"))
            if len(primitives) > 1:
                name = fresh(self.taken, f"{self.node_names[node]}_{j}")
                self.taken.add(name)
            else:
                name = self.node_names[node]
            attrs = prim["attributes"]
            positions = self.g.accessor(attrs["POSITION"])
            n = len(positions)
            normals = self.g.accessor(attrs["NORMAL"]) if "NORMAL" in attrs else None
            uv_key = f"TEXCOORD_{tex_coord or 0}"
            uvs = self.g.accessor(attrs[uv_key]) if uv_key in attrs else None
            faces = (self.g.accessor(prim["indices"]).reshape(-1, 3) if "indices" in prim
                     else np.arange(n).reshape(-1, 3))
            positions = positions @ world[:3, :3].T + world[:3, 3]
            if normals is not None:
                normals = normals / np.linalg.norm(normals, axis=1, keepdims=True)
                normals = normals @ np.linalg.inv(world[:3, :3])
                normals /= np.linalg.norm(normals, axis=1, keepdims=True)
            if np.linalg.det(world[:3, :3]) < 0:
                faces = faces[:, [0, 2, 1]]
            self.assets.mkdir(parents=True, exist_ok=True)
            write_ply(self.assets / f"{name}.ply", positions, normals, uvs, faces)
            shape = f'    <shape type="ply" id="{name}__shape">\n        <string name="filename" value="{self.name}/{name}.ply"/>\n'
            if normals is None:
                shape += '        <boolean name="face_normals" value="true"/>\n'
            shape += f'        <ref id="{material}"/>\n'
            if isinstance(radiance, str):
                shape += f'        <emitter type="area">{bitmap("radiance", radiance)}</emitter>\n'
                self.keys[f"{name}.emitter.radiance.data"] = f"{name}__shape.emitter.radiance.data"
            elif radiance is not None:
                shape += f'        <emitter type="area"><rgb name="radiance" value="{rgb(radiance)}"/></emitter>\n'
                self.keys[f"{name}.emitter.radiance.value"] = f"{name}__shape.emitter.radiance.value"
            self.shapes.append(shape + "    </shape>")

    def xml(self, source, max_depth):
        bsdfs = [xml for (_, xml, _, _) in self.materials.values()]
        return "\n".join([
            '<?xml version="1.0" encoding="utf-8"?>',
            f"<!-- {source} as pathgrad reads it (written by gltf_to_mitsuba.py; do not edit). -->",
            '<scene version="3.0.0">',
            f'    <integrator type="prb"><integer name="max_depth" value="{max_depth}"/></integrator>',
            self.sensor,
            *self.emitters,
            *[f"    {b}" for b in bsdfs],
            *self.shapes,
            "</scene>",
            "",
        ])


def convert(source, out_dir, name, width=None, max_depth=6):
    """Writes OUT_DIR/NAME.xml and its assets; returns {pathgrad parameter: Mitsuba key}."""
    c = Converter(Gltf(source), out_dir, name, width)
    c.run()
    try:
        shown = Path(source).resolve().relative_to(Path(__file__).resolve().parents[2])
    except ValueError:
        shown = Path(source).name
    (Path(out_dir) / f"{name}.xml").write_text(c.xml(shown, max_depth))
    return dict(sorted(c.keys.items()))


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("source")
    parser.add_argument("out_dir")
    parser.add_argument("name")
    parser.add_argument("--width", type=int)
    args = parser.parse_args()
    import mitsuba as mi
    mi.set_variant("scalar_rgb")
    print(json.dumps(convert(args.source, args.out_dir, args.name, args.width), indent=1))


if __name__ == "__main__":
    main()

"""Which surface Mitsuba 3.9.1 (Embree) intersects for a `bsplinecurve` whose radius varies fast.

usage (text):
    DRJIT_LIBLLVM_PATH=... /tmp/mi/bin/python benches/bspline_surface.py

Writes a two-segment curve (radius 0.05 -> 0.6 -> 0.05 -> 0.6 -> 0.05 over 4 units), shoots 2000
rays at it and, at each hit p with Mitsuba's v (which gives the segment and its t), prints how far
p is from (a) the circle of radius r(t) normal to the tangent c'(t), i.e. |R.T| and ||R| - r| with
R = p - c(t), and (b) the swept sphere's envelope, where R.T = -r r'/|c'|; and the largest angle
between Mitsuba's normal and R/|R| (the sphere's normal).
"""
import os, tempfile
import numpy as np
import drjit as dr
import mitsuba as mi

mi.set_variant("llvm_ad_rgb")
pts = np.array([(-1.5, 0, 0, 0.05), (-0.5, 0, 0, 0.6), (0.5, 0, 0, 0.05), (1.5, 0, 0, 0.6), (2.5, 0, 0, 0.05)])
path = os.path.join(tempfile.mkdtemp(), "c.txt")
with open(path, "w") as f:
    f.write("\n".join(" ".join(map(str, p)) for p in pts) + "\n")
scene = mi.load_dict({"type": "scene", "c": {"type": "bsplinecurve", "filename": path}})
n = 2000
x = np.linspace(-0.6, 1.6, n).astype(np.float32)
o = mi.Point3f(x, np.full(n, 3, np.float32), np.zeros(n, np.float32))
si = scene.ray_intersect(mi.Ray3f(o, mi.Vector3f(0, -1, 0)))
hit = np.array(si.is_valid())
p = np.array(si.p).T
v = np.array(si.uv.y) * 2  # two segments
seg = np.floor(np.clip(v, 0, 1.999)).astype(int)
t = v - seg
b = [(-t**3 + 3 * t**2 - 3 * t + 1) / 6, (3 * t**3 - 6 * t**2 + 4) / 6, (-3 * t**3 + 3 * t**2 + 3 * t + 1) / 6, t**3 / 6]
db = [(-3 * t**2 + 6 * t - 3) / 6, (9 * t**2 - 12 * t) / 6, (-9 * t**2 + 6 * t + 3) / 6, 3 * t**2 / 6]
c = sum(b[k][:, None] * pts[seg + k] for k in range(4))
d = sum(db[k][:, None] * pts[seg + k] for k in range(4))
R = p - c[:, :3]
T = d[:, :3] / np.linalg.norm(d[:, :3], axis=1)[:, None]
along = (R * T).sum(1)
envelope = -c[:, 3] * d[:, 3] / np.linalg.norm(d[:, :3], axis=1)
m = hit
print(f"{m.sum()} hits")
print(f"circle normal to the tangent: max |R.T| {np.abs(along[m]).max():.3g}, max ||R| - r| {np.abs(np.linalg.norm(R[m], axis=1) - c[m, 3]).max():.3g}")
print(f"swept sphere's envelope: max |R.T - (-r r'/|c'|)| {np.abs(along[m] - envelope[m]).max():.3g}")
nrm = np.array(si.n).T
cos = (nrm[m] * R[m]).sum(1) / np.linalg.norm(R[m], axis=1)
print(f"largest angle between Mitsuba's normal and R/|R|: {np.degrees(np.arccos(np.clip(cos, -1, 1))).max():.2f} deg")

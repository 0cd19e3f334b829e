"""Shared by the Mitsuba 3 comparison tools in benches/: resizing a loaded scene's film the way
pathgrad's --width/--height do (the vertical field of view is kept)."""

import math
import sys


def resize_film(mi, params, width, height=None):
    """Sets the film of the one sensor in `params` (from mi.traverse) to width x height, keeping
    the vertical field of view; height None keeps the aspect ratio. Returns (width, height)."""
    size_keys = [k for k in params.keys() if k.endswith("film.size")]
    fov_keys = [k for k in params.keys() if k.endswith("x_fov")]
    if len(size_keys) != 1 or len(fov_keys) != 1:
        sys.exit("expected one sensor with a film and an x_fov")
    w0, h0 = params[size_keys[0]]
    if height is None:
        height = max(1, round(width * h0 / w0))
    x_fov0 = params[fov_keys[0]]
    x_fov0 = float(x_fov0[0] if hasattr(x_fov0, "__len__") else x_fov0)  # Float, or float in scalar_*
    tan_y = math.tan(math.radians(x_fov0) / 2) * h0 / w0
    params[size_keys[0]] = mi.ScalarVector2u(width, height)
    params[fov_keys[0]] = math.degrees(2 * math.atan(tan_y * width / height))
    params.update()
    return width, height

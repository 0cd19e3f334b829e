"""pathgrad: a differentiable path tracer on Vulkan compute — images and their gradients.

Load a scene (a Mitsuba XML or glTF file, or ``builtin:NAME``), render it to a NumPy array, and
differentiate it with respect to its parameters (Mitsuba's ``traverse`` names)::

    import numpy as np
    import pathgrad as pg

    scene = pg.load("builtin:cornell-box", width=64, height=64)
    image = pg.render(scene, spp=16, seed=0)            # (64, 64, 3) float32
    grads = pg.grad(scene, np.ones_like(image), wrt=["sphere.bsdf.alpha.value"])

Renders run on the default Vulkan device (a GPU, or lavapipe on a plain CPU); ``device="cpu"``
runs the CPU reference implementation of the same estimators with the same random numbers. The
PyTorch bridge is :mod:`pathgrad.torch` (imported on first use; torch is optional).

Parameter values set through :attr:`Scene.params` or a call's ``params`` stay set. Every render
and gradient releases the GIL. Errors are :class:`pathgrad.errors.Error` subclasses with the
library's messages.
"""

from __future__ import annotations

import collections.abc
import numbers
import os
from typing import Any, Dict, Iterator, List, Mapping, NamedTuple, Optional, Sequence, Tuple, Union

import numpy as np

from . import _pathgrad as _native

# lavapipe builds its kernels for the vector width `LP_NATIVE_VECTOR_WIDTH` names, read when the
# driver starts: the command-line program's choice unless the environment sets one (512 bits on
# an AVX-512 host, 128 elsewhere), with Mesa's shader cache in a folder of that width's unless the
# environment names one (lavapipe's cache does not tell widths apart):
# `pathgrad::gpu::lavapipe_environment`. Other drivers ignore the width. Importing the native
# module opens no Vulkan instance, so this comes in time.
for _name, _value in _native.lavapipe_environment():
    os.environ[_name] = _value

from .errors import (  # noqa: E402
    ArgumentError,
    DeviceError,
    Error,
    FileError,
    NumericError,
    SceneError,
    UnknownParameterError,
)

__all__ = [
    "Scene",
    "Params",
    "ParamInfo",
    "load",
    "render",
    "grad",
    "loss_and_grad",
    "image_gradient",
    "read_image",
    "write_image",
    "devices",
    "Error",
    "SceneError",
    "ArgumentError",
    "UnknownParameterError",
    "FileError",
    "DeviceError",
    "NumericError",
]

__version__ = "0.1.0"

Sensor = Union[int, str]


class ParamInfo(NamedTuple):
    """What a parameter is: its name, array shape and inclusive bounds."""

    name: str
    shape: Tuple[int, ...]
    bounds: Tuple[float, float]


def _float_array(value: Any, what: str) -> np.ndarray:
    """``value`` (array-like, a torch tensor or a number) as a floating-point NumPy array."""
    if type(value).__module__.startswith("torch"):
        value = value.detach().cpu().numpy()
    if isinstance(value, bool) or isinstance(value, np.bool_):
        raise ArgumentError(f"invalid {what}: a bool, expected floating-point values")
    if isinstance(value, numbers.Real):
        return np.asarray(float(value), dtype=np.float64)
    try:
        array = np.asarray(value)
    except Exception as e:  # ragged lists and other objects NumPy cannot take
        raise ArgumentError(f"invalid {what}: not an array of numbers ({e})") from None
    if array.dtype.kind != "f":
        raise ArgumentError(f"invalid {what}: dtype {array.dtype}, expected a floating-point array (float32 or float64)")
    return array


def _check_finite(array: np.ndarray, what: str) -> None:
    bad = np.flatnonzero(~np.isfinite(array))
    if bad.size:
        index = np.unravel_index(int(bad[0]), array.shape) if array.ndim else ()
        raise ArgumentError(
            f"invalid {what}: {bad.size} value(s) not finite, the first {array.reshape(-1)[bad[0]]} at index {tuple(int(i) for i in index)}"
        )


class Params(collections.abc.MutableMapping):
    """The scene's parameters by name: reading one gives a copy of its values in its shape,
    assigning one sets it (same shape, finite, inside its bounds). Parameters cannot be added or
    removed. ``info(name)`` gives the shape and bounds.

    >>> scene.params["sphere.bsdf.alpha.value"] = 0.3          # doctest: +SKIP
    >>> scene.params.info("sphere.bsdf.alpha.value").bounds     # doctest: +SKIP
    (0.001, 1.0)
    """

    def __init__(self, scene: "Scene") -> None:
        self._scene = scene

    def __getitem__(self, name: str) -> np.ndarray:
        return self._scene._native.get_param(self._name(name))

    def __setitem__(self, name: str, value: Any) -> None:
        info = self.info(name)
        array = _float_array(value, f"value of parameter {name}")
        size = int(np.prod(info.shape))
        if array.shape != info.shape and not (size == 1 and array.size == 1 and array.ndim <= 1):
            raise ArgumentError(f"invalid value of parameter {name}: shape {array.shape}, expected {info.shape}")
        _check_finite(array, f"value of parameter {name}")
        flat = np.ascontiguousarray(array, dtype=np.float32).reshape(-1)
        lo, hi = info.bounds
        outside = np.flatnonzero((flat < lo) | (flat > hi))
        if outside.size:
            raise ArgumentError(
                f"invalid value of parameter {name}: {flat[outside[0]]} at flat index {int(outside[0])} is outside its bounds [{lo}, {hi}]"
            )
        self._scene._native.set_param(name, flat)

    def __delitem__(self, name: str) -> None:
        raise TypeError("a scene's parameters cannot be removed")

    def __iter__(self) -> Iterator[str]:
        return iter(self._scene._native.param_names())

    def __len__(self) -> int:
        return len(self._scene._native.param_names())

    def __contains__(self, name: object) -> bool:
        return isinstance(name, str) and name in self._scene._native.param_names()

    def info(self, name: str) -> ParamInfo:
        """The shape and bounds of parameter ``name``."""
        shape, bounds = self._scene._native.param_info(self._name(name))
        return ParamInfo(name, tuple(shape), (float(str(np.float32(bounds[0]))), float(str(np.float32(bounds[1])))))

    def _name(self, name: Any) -> str:
        if not isinstance(name, str):
            raise ArgumentError(f"invalid parameter name: {name!r} is a {type(name).__name__}, expected a str")
        return name

    def __repr__(self) -> str:
        lines = [f"{i.name}: shape {i.shape}, bounds {i.bounds}" for i in map(self.info, self)]
        return "Params(\n  " + "\n  ".join(lines) + "\n)"


class Scene:
    """A loaded scene: its parameters (:attr:`params`), sensors and the renderers opened on it
    (one per device, opened on first use and kept). Made by :func:`load`."""

    def __init__(self, native: Any) -> None:
        self._native = native
        self.params = Params(self)

    @property
    def source(self) -> str:
        """The scene file, or ``builtin:NAME``."""
        return self._native.source

    @property
    def size(self) -> Tuple[int, int]:
        """``(width, height)`` of every render."""
        return tuple(self._native.size)

    @property
    def sensors(self) -> List[Dict[str, Any]]:
        """Every sensor: index, name, position, target, up, fov_y_degrees, width, height, lens."""
        return self._native.sensors()

    @property
    def warnings(self) -> List[str]:
        """What the loader rendered differently than the file asks, and why."""
        return self._native.warnings

    def __repr__(self) -> str:
        w, h = self.size
        return f"Scene({self.source!r}, {w}×{h}, {len(self.params)} parameters, {len(self.sensors)} sensor(s))"


def load(
    path: Union[str, "os.PathLike[str]"],
    *,
    width: Optional[int] = None,
    height: Optional[int] = None,
    sensor: Optional[Sensor] = None,
    env: Union[None, float, Sequence[float], str, "os.PathLike[str]"] = None,
    allow_outside_folder: bool = False,
    **defines: Any,
) -> Scene:
    """Loads a scene: a Mitsuba XML file, a glTF file (``.gltf``/``.glb``) or ``builtin:NAME``.

    Parameters
    ----------
    path:
        The scene file or ``builtin:cornell-box`` (also ``furnace``, ``blend``).
    width, height:
        The size to render, if not the scene's film (with one, the other follows the aspect ratio).
    sensor:
        The sensor whose film sets the size (index or name; the first by default).
    env:
        Light the scene with a constant environment (a number or ``(r, g, b)``) or an
        environment map file, for scenes without lights of their own (most glTF assets).
    allow_outside_folder:
        Let the scene read files outside its own folder.
    **defines:
        Overrides of a Mitsuba scene's ``<default>`` values, e.g. ``spp=64, res=128``.
    """
    pairs = []
    for name, value in defines.items():
        text = ("true" if value else "false") if isinstance(value, bool) else str(value)
        pairs.append((name, text))
    env_rgb, env_map = None, None
    if env is not None:
        if isinstance(env, (str, os.PathLike)):
            env_map = os.fspath(env)
        else:
            rgb = np.broadcast_to(_float_array(env, "env"), (3,)) if np.ndim(env) == 0 else _float_array(env, "env")
            if rgb.shape != (3,):
                raise ArgumentError(f"invalid env: shape {rgb.shape}, expected one number or (r, g, b)")
            _check_finite(rgb, "env")
            env_rgb = [float(v) for v in rgb]
    selector = None if sensor is None else str(sensor)
    native = _native.load(os.fspath(path), pairs, width, height, selector, env_rgb, env_map, allow_outside_folder)
    return Scene(native)


def _check_scene(scene: Any) -> Scene:
    if not isinstance(scene, Scene):
        raise ArgumentError(f"invalid scene: a {type(scene).__name__}, expected a pathgrad.Scene from pathgrad.load")
    return scene


def _sensor_list(scene: Scene, sensor: Optional[Sensor], sensors: Optional[Sequence[Sensor]]) -> Tuple[List[int], bool]:
    """The sensor indices a call names, and whether it named a list (a stacked result)."""
    if sensor is not None and sensors is not None:
        raise ArgumentError("invalid sensors: give sensor= or sensors=, not both")
    many = sensors is not None
    chosen: Sequence[Sensor] = list(sensors) if many else [0 if sensor is None else sensor]  # type: ignore[arg-type]
    indices = []
    for s in chosen:
        if isinstance(s, bool) or not isinstance(s, (int, str, np.integer)):
            raise ArgumentError(f"invalid sensor: {s!r}, expected an index or a sensor's name")
        if isinstance(s, (int, np.integer)) and s < 0:
            raise ArgumentError(f"invalid sensor: {s}, expected an index ≥ 0")
        indices.append(scene._native.sensor_index(str(s)))
    return indices, many


def _count(value: Any, what: str, minimum: int, maximum: int = 2**32 - 1) -> Optional[int]:
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not minimum <= value <= maximum:
        raise ArgumentError(f"invalid {what}: {value!r}, expected an integer in [{minimum}, {maximum}]")
    return int(value)


def _depth(value: Any) -> Optional[int]:
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not (value == -1 or 1 <= value <= 1024):
        raise ArgumentError(f"invalid max_depth: {value!r}, expected an integer in [1, 1024], or -1 for unbounded")
    return int(value)


def _settings(spp: Any, seed: Any, device: Any, max_depth: Any) -> Tuple[Optional[int], int, Optional[str], Optional[int]]:
    """The arguments every render and gradient takes, checked, in the native functions' order."""
    return _count(spp, "spp", 1, 1 << 20), _count(seed, "seed", 0), None if device is None else str(device), _depth(max_depth)


def _sampling(sampling: Any, jacobian_noise: Any) -> Tuple[str, Optional[float]]:
    """``sampling`` and ``jacobian_noise``, checked for type (the native side checks the values)."""
    if not isinstance(sampling, str):
        raise ArgumentError(f"invalid sampling: {sampling!r}, expected 'detached' or 'attached'")
    if jacobian_noise is None:
        return sampling, None
    if isinstance(jacobian_noise, bool) or not isinstance(jacobian_noise, (int, float)):
        raise ArgumentError(f"invalid jacobian_noise: {jacobian_noise!r}, expected a number in [0, 1)")
    return sampling, float(jacobian_noise)


def _set_params(scene: Scene, params: Optional[Mapping[str, Any]]) -> None:
    if params is None:
        return
    if not isinstance(params, collections.abc.Mapping):
        raise ArgumentError(f"invalid params: a {type(params).__name__}, expected a mapping of names to values")
    for name, value in params.items():
        scene.params[name] = value


def render(
    scene: Scene,
    params: Optional[Mapping[str, Any]] = None,
    *,
    sensor: Optional[Sensor] = None,
    sensors: Optional[Sequence[Sensor]] = None,
    spp: Optional[int] = None,
    seed: int = 0,
    device: Union[None, int, str] = None,
    max_depth: Optional[int] = None,
) -> np.ndarray:
    """Renders the scene: a ``(height, width, 3)`` ``float32`` array of linear RGB radiance.

    Parameters
    ----------
    params:
        Parameter values to set first (they stay set), ``{name: value}``.
    sensor, sensors:
        The sensor (index or name; the first by default), or a list of them: then the result is
        ``(len(sensors), height, width, 3)``, every sensor rendered in one pass at the scene's size.
    spp:
        Samples per pixel (default: the scene's, else 16).
    seed:
        The random seed: the same seed gives the same image on the same device.
    device:
        ``None`` (the default Vulkan device), an index or UUID from :func:`devices`,
        ``"lavapipe"``, or ``"cpu"`` for the CPU reference implementation.
    max_depth:
        Maximum surface interactions per path (default: the scene's; -1 unbounded).
    """
    scene = _check_scene(scene)
    _set_params(scene, params)
    indices, many = _sensor_list(scene, sensor, sensors)
    images = _native.render(
        scene._native,
        indices,
        *_settings(spp, seed, device, max_depth),
    )
    return images if many else images[0]


def _image_values(scene: Scene, value: Any, count: int, many: bool, what: str) -> np.ndarray:
    width, height = scene.size
    expected = (count, height, width, 3) if many else (height, width, 3)
    array = _float_array(value, what)
    if array.shape != expected:
        raise ArgumentError(f"invalid {what}: shape {array.shape}, expected {expected}")
    _check_finite(array, what)
    return np.ascontiguousarray(array, dtype=np.float32).reshape(-1)


def _wrt(scene: Scene, wrt: Union[None, str, Sequence[str]]) -> Optional[List[str]]:
    if wrt is None:
        return None
    names = [wrt] if isinstance(wrt, str) else list(wrt)
    for n in names:
        scene.params.info(n)  # an unknown name raises, listing the parameters
    return names


def grad(
    scene: Scene,
    adjoint: Any,
    params: Optional[Mapping[str, Any]] = None,
    *,
    wrt: Union[None, str, Sequence[str]] = None,
    sensor: Optional[Sensor] = None,
    sensors: Optional[Sequence[Sensor]] = None,
    spp: Optional[int] = None,
    seed: int = 0,
    device: Union[None, int, str] = None,
    max_depth: Optional[int] = None,
    deterministic: bool = False,
    sampling: str = "detached",
    jacobian_noise: Optional[float] = None,
) -> Dict[str, np.ndarray]:
    """Reverse-mode gradient by Path Replay Backpropagation: the derivative of
    ``sum(adjoint * render(scene))`` by every parameter in ``wrt`` (all by default).

    ``adjoint`` is ∂loss/∂pixel, shaped as :func:`render`'s result for the same ``sensor`` or
    ``sensors``. The gradient pass draws its own random numbers (independent of a render's with
    the same seed). Returns ``{name: array of the parameter's shape}``. ``deterministic``
    accumulates in 64-bit fixed point: bitwise identical results run to run.

    ``sampling`` is ``"detached"`` (the sampled directions held fixed) or ``"attached"`` (they
    move with the parameters, as ``pathgrad grad --sampling attached``): only attached sampling
    differentiates a smooth dielectric's index of refraction, so detached sampling leaves it out
    of "all" and refuses it in ``wrt``. ``jacobian_noise`` is attached sampling's regularisation
    amplitude (``--jacobian-noise``; default none). See the guide's "Attached derivatives" for
    the scenes attached sampling supports.
    """
    scene = _check_scene(scene)
    _set_params(scene, params)
    indices, many = _sensor_list(scene, sensor, sensors)
    values = _image_values(scene, adjoint, len(indices), many, "adjoint")
    return _native.backward(
        scene._native,
        values,
        indices,
        _wrt(scene, wrt),
        *_settings(spp, seed, device, max_depth),
        bool(deterministic),
        *_sampling(sampling, jacobian_noise),
    )


def loss_and_grad(
    scene: Scene,
    target: Any,
    params: Optional[Mapping[str, Any]] = None,
    *,
    loss: str = "relmse",
    wrt: Union[None, str, Sequence[str]] = None,
    sensor: Optional[Sensor] = None,
    sensors: Optional[Sequence[Sensor]] = None,
    spp: Optional[int] = None,
    seed: int = 0,
    device: Union[None, int, str] = None,
    max_depth: Optional[int] = None,
    deterministic: bool = False,
    sampling: str = "detached",
    jacobian_noise: Optional[float] = None,
) -> Tuple[float, Dict[str, np.ndarray]]:
    """A gradient step as ``pathgrad grad`` takes it: render, the loss against ``target``
    (``l1``, ``l2``, ``relmse`` or ``relmse_max``, averaged over pixels and sensors), and its
    gradient in one fused pass. Returns ``(loss, {name: gradient})``. ``sampling`` and
    ``jacobian_noise`` as :func:`grad`'s."""
    scene = _check_scene(scene)
    _set_params(scene, params)
    indices, many = _sensor_list(scene, sensor, sensors)
    values = _image_values(scene, target, len(indices), many, "target")
    if not isinstance(loss, str):
        raise ArgumentError(f"invalid loss: {loss!r}, expected l1, l2, relmse or relmse_max")
    return _native.loss_and_gradient(
        scene._native,
        values,
        indices,
        loss,
        _wrt(scene, wrt),
        *_settings(spp, seed, device, max_depth),
        bool(deterministic),
        *_sampling(sampling, jacobian_noise),
    )


def image_gradient(
    scene: Scene,
    name: str,
    params: Optional[Mapping[str, Any]] = None,
    *,
    spp: Optional[int] = None,
    seed: int = 0,
    device: Union[None, int, str] = None,
    max_depth: Optional[int] = None,
    sampling: str = "detached",
    jacobian_noise: Optional[float] = None,
) -> np.ndarray:
    """Forward-mode image gradient ∂image/∂``name`` of the scene's sensor, summed over the
    parameter's elements: a ``(height, width, 3)`` array (signed). ``sampling`` and
    ``jacobian_noise`` as :func:`grad`'s: a dielectric's index of refraction needs
    ``sampling="attached"`` (three times the work: one pass per colour channel)."""
    scene = _check_scene(scene)
    _set_params(scene, params)
    scene.params.info(name)
    return _native.image_gradient(
        scene._native,
        name,
        *_settings(spp, seed, device, max_depth),
        *_sampling(sampling, jacobian_noise),
    )[0]


def read_image(path: Union[str, "os.PathLike[str]"]) -> np.ndarray:
    """Reads an EXR image as a ``(height, width, 3)`` ``float32`` array."""
    return _native.read_image(os.fspath(path))


def write_image(path: Union[str, "os.PathLike[str]"], image: Any) -> None:
    """Writes a ``(height, width, 3)`` image as EXR (HDR, by the extension ``.exr``) or PNG
    (sRGB, clamped)."""
    array = _float_array(image, "image")
    if array.ndim != 3 or array.shape[2] != 3:
        raise ArgumentError(f"invalid image: shape {array.shape}, expected (height, width, 3)")
    height, width = array.shape[:2]
    _native.write_image(os.fspath(path), width, height, np.ascontiguousarray(array, dtype=np.float32).reshape(-1))


def devices() -> List[Dict[str, Any]]:
    """The Vulkan devices: index, name, driver, and what pathgrad needs that each lacks."""
    return [dict(index=i, name=n, driver=d, missing=list(m)) for i, n, d, m in _native.devices()]


def __getattr__(name: str) -> Any:
    # `pathgrad.torch` is imported on first use, so that torch stays optional.
    if name == "torch":
        import importlib

        return importlib.import_module(".torch", __name__)
    raise AttributeError(f"module 'pathgrad' has no attribute {name!r}")

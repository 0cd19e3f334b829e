"""The PyTorch bridge: a render whose inputs are parameter tensors, differentiable by autograd.

::

    import torch
    import pathgrad as pg
    import pathgrad.torch as pgt

    scene = pg.load("builtin:cornell-box", width=64, height=64)
    alpha = torch.tensor([0.5], requires_grad=True)
    image = pgt.render(scene, {"sphere.bsdf.alpha.value": alpha}, spp=16, seed=0)
    loss = ((image - target) ** 2).mean()
    loss.backward()          # alpha.grad: by Path Replay Backpropagation

The forward pass sets the tensors' values on the scene and renders; it keeps the scene, the
parameter names, the seed and the sample counts, and references to the input tensors (no image).
The backward pass runs the adjoint pass with the incoming image gradient as the adjoint image, at
``spp_grad`` samples per pixel and with random numbers independent of the forward render's (the
gradient pass has its own key: PRB's decorrelation of the primal and the adjoint), and returns a
gradient only for the inputs that need one. Under ``torch.no_grad()`` no graph is kept.
"""

from __future__ import annotations

from typing import Any, Mapping, Optional, Sequence, Union

import torch

import pathgrad as _pg
from pathgrad.errors import ArgumentError

__all__ = ["render"]


class _Render(torch.autograd.Function):
    """``render`` as an autograd function: inputs ``(scene, names, settings, *tensors)``."""

    @staticmethod
    def forward(ctx: Any, scene: _pg.Scene, names: tuple, settings: dict, *tensors: torch.Tensor) -> torch.Tensor:
        values = {n: t.detach() for n, t in zip(names, tensors)}
        image = _pg.render(
            scene,
            values,
            sensors=settings["sensors"],
            spp=settings["spp"],
            seed=settings["seed"],
            device=settings["device"],
            max_depth=settings["max_depth"],
        )
        if not settings["many"]:
            image = image[0]
        ctx.scene, ctx.names, ctx.settings = scene, names, settings
        ctx.save_for_backward(*tensors)
        out = torch.from_numpy(image)
        return out.to(tensors[0].device) if tensors else out

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx: Any, grad_image: torch.Tensor) -> tuple:
        tensors = ctx.saved_tensors
        needed = ctx.needs_input_grad[3:]
        wanted = [n for n, need in zip(ctx.names, needed) if need]
        if not wanted:
            return (None, None, None) + (None,) * len(tensors)
        s = ctx.settings
        adjoint = grad_image.detach().to("cpu", torch.float32).numpy()
        if not s["many"]:
            adjoint = adjoint[None]
        # The values of the forward pass: another render may have set others since.
        values = {n: t.detach() for n, t in zip(ctx.names, tensors)}
        grads = _pg.grad(
            ctx.scene,
            adjoint,
            values,
            wrt=wanted,
            sensors=s["sensors"],
            spp=s["spp_grad"],
            seed=s["seed"],
            device=s["device"],
            max_depth=s["max_depth"],
            deterministic=s["deterministic"],
            sampling=s["sampling"],
            jacobian_noise=s["jacobian_noise"],
        )
        out = []
        for name, t, need in zip(ctx.names, tensors, needed):
            out.append(torch.from_numpy(grads[name]).reshape(t.shape).to(t.device, t.dtype) if need else None)
        return (None, None, None) + tuple(out)


def render(
    scene: _pg.Scene,
    params: Mapping[str, torch.Tensor],
    *,
    spp: Optional[int] = None,
    spp_grad: Optional[int] = None,
    seed: int = 0,
    sensor: Optional[Union[int, str]] = None,
    sensors: Optional[Sequence[Union[int, str]]] = None,
    device: Union[None, int, str] = None,
    max_depth: Optional[int] = None,
    deterministic: bool = False,
    sampling: str = "detached",
    jacobian_noise: Optional[float] = None,
) -> torch.Tensor:
    """Renders ``scene`` with the parameters ``params`` (``{name: tensor}``, each of the
    parameter's shape; a scalar parameter also takes shape ``()``) as a differentiable tensor:
    ``(height, width, 3)`` ``float32``, or ``(len(sensors), height, width, 3)`` for a list of
    sensors (every sensor in one render and one adjoint pass).

    ``spp`` is the forward render's samples per pixel (default: the scene's, else 16),
    ``spp_grad`` the adjoint pass's (default: ``spp``); ``seed`` keys both (they draw
    independent random numbers). The result lives on the first tensor's device. ``device`` is
    pathgrad's device (see :func:`pathgrad.render`), not torch's. ``sampling`` and
    ``jacobian_noise`` choose the adjoint pass's sampling as in :func:`pathgrad.grad`
    (``"attached"`` to differentiate a glass object's index of refraction).
    """
    if not isinstance(params, Mapping) or not params:
        raise ArgumentError("invalid params: expected a non-empty mapping {name: tensor}")
    scene = _pg._check_scene(scene)
    names = tuple(params)
    tensors = []
    for name in names:
        t = params[name]
        if not isinstance(t, torch.Tensor):
            raise ArgumentError(f"invalid value of parameter {name}: a {type(t).__name__}, expected a torch.Tensor")
        if not t.is_floating_point():
            raise ArgumentError(f"invalid value of parameter {name}: dtype {t.dtype}, expected a floating-point tensor")
        tensors.append(t)
    indices, many = _pg._sensor_list(scene, sensor, sensors)
    settings = dict(
        sensors=indices,
        many=many,
        spp=_pg._count(spp, "spp", 1, 1 << 20),
        spp_grad=_pg._count(spp if spp_grad is None else spp_grad, "spp_grad", 1, 1 << 20),
        seed=_pg._count(seed, "seed", 0),
        device=None if device is None else str(device),
        max_depth=_pg._depth(max_depth),
        deterministic=bool(deterministic),
    )
    settings["sampling"], settings["jacobian_noise"] = _pg._sampling(sampling, jacobian_noise)
    return _Render.apply(scene, names, settings, *tensors)


"""The PyTorch bridge: the same numbers as the NumPy interface, gradients that agree with finite
differences, an optimisation that converges, flat memory, and clear errors."""

import os

import numpy as np
import pytest

import pathgrad as pg
# scripts/test sets PATHGRAD_TEST_TORCH=1, so that a missing torch fails there instead of
# skipping this module.
if os.environ.get("PATHGRAD_TEST_TORCH") == "1":
    import torch
else:
    torch = pytest.importorskip("torch")
import pathgrad.torch as pgt  # noqa: E402

ALPHA = "sphere.bsdf.alpha.value"
RED = "red.reflectance.value"


def rss_bytes() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


@pytest.fixture
def cornell():
    return pg.load("builtin:cornell-box", width=16, height=16)


def test_forward_and_backward_equal_the_numpy_interface(cornell):
    alpha = torch.tensor([0.3], requires_grad=True)
    red = torch.tensor([0.6, 0.1, 0.1], dtype=torch.float64, requires_grad=True)
    image = pgt.render(cornell, {ALPHA: alpha, RED: red}, spp=4, spp_grad=8, seed=11, deterministic=True)
    assert image.shape == (16, 16, 3) and image.dtype == torch.float32 and image.requires_grad
    weights = torch.linspace(-1, 1, 16 * 16 * 3).reshape(16, 16, 3)
    (image * weights).sum().backward()
    assert np.array_equal(image.detach().numpy(), pg.render(cornell, {ALPHA: 0.3, RED: [0.6, 0.1, 0.1]}, spp=4, seed=11))
    expected = pg.grad(cornell, weights.numpy(), wrt=[ALPHA, RED], spp=8, seed=11, deterministic=True)
    assert alpha.grad.dtype == torch.float32 and red.grad.dtype == torch.float64
    assert np.array_equal(alpha.grad.numpy(), expected[ALPHA])
    assert np.array_equal(red.grad.numpy().astype(np.float32), expected[RED])


def test_attached_sampling_reaches_the_adjoint_pass(repo):
    # A glass sphere's index of refraction as a tensor: its gradient by attached sampling is
    # the NumPy interface's, and detached sampling refuses it by name.
    glass = pg.load(repo / "tests/data/scenes/attached_sphere.xml", width=12, height=12)
    name = "glass.bsdf.eta"
    eta = torch.tensor([1.4], requires_grad=True)
    pgt.render(glass, {name: eta}, spp=2, seed=5, device="cpu", sampling="attached").sum().backward()
    expected = pg.grad(glass, np.ones((12, 12, 3), np.float32), {name: 1.4}, wrt=name, spp=2, seed=5, device="cpu",
                       sampling="attached")
    assert eta.grad.numpy()[0] != 0 and np.array_equal(eta.grad.numpy(), expected[name])
    detached = torch.tensor([1.4], requires_grad=True)
    with pytest.raises(pg.ArgumentError, match="glass.bsdf.eta"):
        pgt.render(glass, {name: detached}, spp=2, device="cpu").sum().backward()


def test_gradients_only_where_needed_and_no_graph_under_no_grad(cornell):
    alpha = torch.tensor(0.3, requires_grad=True)  # shape () for a scalar parameter
    red = torch.tensor([0.6, 0.1, 0.1])  # no gradient wanted
    image = pgt.render(cornell, {ALPHA: alpha, RED: red}, spp=2)
    image.mean().backward()
    assert alpha.grad is not None and alpha.grad.shape == () and red.grad is None
    with torch.no_grad():
        assert pgt.render(cornell, {ALPHA: alpha}, spp=2).grad_fn is None
    # The backward pass uses the forward's values, even when another render set others since.
    a = torch.tensor([0.3], requires_grad=True)
    first = pgt.render(cornell, {ALPHA: a}, spp=2, seed=1, deterministic=True)
    pgt.render(cornell, {ALPHA: torch.tensor([0.9])}, spp=2)
    first.sum().backward()
    expected = pg.grad(cornell, np.ones((16, 16, 3), np.float32), {ALPHA: 0.3}, wrt=ALPHA, spp=2, seed=1,
                       deterministic=True)
    assert np.array_equal(a.grad.numpy(), expected[ALPHA])


def test_several_sensors_in_one_call(repo):
    scene = pg.load(repo / "scenes/two-sided/scene.xml", res=12)
    front = torch.tensor([0.7, 0.3, 0.2], requires_grad=True)
    images = pgt.render(scene, {"front.reflectance.value": front}, sensors=[0, 1], spp=4, seed=3)
    assert images.shape == (2, 12, 12, 3)
    images[0].sum().backward()
    seen = front.grad.clone()
    front.grad = None
    images = pgt.render(scene, {"front.reflectance.value": front}, sensors=[0, 1], spp=4, seed=3)
    images[1].sum().backward()  # the back camera does not see the front panel
    assert seen.abs().min() > 0 and front.grad.abs().max() < 1e-3 * seen.abs().min()


@pytest.mark.parametrize("name, x0, h", [(ALPHA, 0.2, 0.02), (RED, 0.5, 0.02)])
def test_gradients_agree_with_finite_differences(cornell, name, x0, h):
    """The bridge's gradient of ⟨w, I(θ)⟩ against central differences of the same functional
    with common random numbers, over 16 seeds: Welch's t below 4, and a standard error under a
    tenth of the derivative, so that an error of 40 % (or a wrong sign) would be caught."""
    shape = cornell.params.info(name).shape
    # Weights of the sign of ∂I/∂θ: the functional moves with θ wherever the image does.
    w = torch.from_numpy(np.sign(pg.image_gradient(cornell, name, {name: np.full(shape, x0)}, spp=64, seed=999)))
    bridge, fd = [], []
    for seed in range(16):
        x = torch.full(shape, x0, dtype=torch.float64, requires_grad=True)
        (pgt.render(cornell, {name: x}, spp=128, seed=seed) * w).sum().backward()
        bridge.append(x.grad.sum().item())
        with torch.no_grad():
            up = (pgt.render(cornell, {name: torch.full(shape, x0 + h)}, spp=128, seed=seed) * w).sum().item()
            down = (pgt.render(cornell, {name: torch.full(shape, x0 - h)}, spp=128, seed=seed) * w).sum().item()
        fd.append((up - down) / (2 * h))
    bridge, fd = np.array(bridge), np.array(fd)
    se = np.sqrt(bridge.var(ddof=1) / len(bridge) + fd.var(ddof=1) / len(fd))
    t = (bridge.mean() - fd.mean()) / se
    assert se < 0.1 * abs(fd.mean()), f"too noisy to test: se {se}, FD {fd.mean()}"
    assert abs(t) < 4, f"bridge {bridge.mean()} ± {bridge.std()}, FD {fd.mean()} ± {fd.std()}, t = {t}"


def test_an_adam_loop_recovers_a_roughness():
    scene = pg.load("builtin:cornell-box", width=32, height=32)
    target = torch.from_numpy(pg.render(scene, {ALPHA: 0.2}, spp=256, seed=10**6))
    alpha = torch.tensor([0.6], requires_grad=True)
    optimizer = torch.optim.Adam([alpha], lr=0.03)
    history = []
    for it in range(60):
        optimizer.zero_grad()
        image = pgt.render(scene, {ALPHA: alpha}, spp=16, seed=it)
        ((image - target) ** 2).mean().backward()
        optimizer.step()
        with torch.no_grad():
            alpha.clamp_(0.01, 1.0)
        history.append(alpha.item())
    assert abs(np.mean(history[-10:]) - 0.2) < 0.05, history


def test_memory_stays_flat_over_1000_iterations():
    """A forward and backward pass a thousand times: the process's resident memory after the
    1000th is within 8 MiB of that after the 100th (a leaked 64×64 image a pass would add 43)."""
    scene = pg.load("builtin:cornell-box", width=64, height=64)
    alpha = torch.tensor([0.4], requires_grad=True)
    for it in range(1000):
        image = pgt.render(scene, {ALPHA: alpha}, spp=1, seed=it)
        image.sum().backward()
        if it == 99:
            after_100 = rss_bytes()
    growth = rss_bytes() - after_100
    assert growth < 8 << 20, f"resident memory grew by {growth / 2**20:.1f} MiB over 900 iterations"


@pytest.mark.parametrize(
    "params, message",
    [
        ({}, "non-empty mapping"),
        ({ALPHA: 0.3}, "expected a torch.Tensor"),
        ({ALPHA: torch.tensor([1], dtype=torch.int32)}, "dtype torch.int32"),
        ({ALPHA: torch.tensor([0.1, 0.2])}, r"shape \(2,\), expected \(1,\)"),
        ({RED: torch.tensor([0.1, float("nan"), 0.2])}, "not finite"),
        ({"nope": torch.tensor([0.1])}, "'nope' is not a parameter"),
    ],
)
def test_bad_arguments_raise_clear_errors(cornell, params, message):
    with pytest.raises(pg.ArgumentError, match=message):
        pgt.render(cornell, params, spp=1)

"""pathgrad's NumPy interface: the same numbers as the Rust library and its program, shapes
and bounds of parameters, sensors, and clear errors for bad arguments."""

import json
import threading
import time

import numpy as np
import pytest

import pathgrad as pg

ALPHA = "sphere.bsdf.alpha.value"


@pytest.fixture
def cornell():
    return pg.load("builtin:cornell-box", width=24, height=20)


def test_render_equals_the_program_bit_for_bit(cornell, run_cli, tmp_path):
    for device, flags in [(None, []), ("cpu", ["--cpu"])]:
        out = tmp_path / f"cli-{device}.exr"
        run_cli("render", "builtin:cornell-box", "--width", "24", "--height", "20", "--spp", "4", "--seed", "7",
                "-o", str(out), *flags)
        ours = pg.render(cornell, spp=4, seed=7, device=device)
        assert ours.shape == (20, 24, 3) and ours.dtype == np.float32
        theirs = pg.read_image(out)
        assert np.array_equal(ours, theirs), f"device {device}: max |Δ| {np.abs(ours - theirs).max()}"
    # The GPU and the CPU reference agree up to float rounding, and seeds differ.
    gpu, cpu = pg.render(cornell, spp=4, seed=7), pg.render(cornell, spp=4, seed=7, device="cpu")
    assert np.abs(gpu - cpu).max() < 1e-3
    assert not np.array_equal(gpu, pg.render(cornell, spp=4, seed=8))


def test_loss_gradient_equals_the_program_bit_for_bit(cornell, run_cli, tmp_path):
    target = pg.render(cornell, {ALPHA: 0.15}, spp=32, seed=100)
    pg.write_image(tmp_path / "target.exr", target)
    assert cornell.params[ALPHA][0] == np.float32(0.15)  # values set in a call stay set
    cornell.params[ALPHA] = 0.2  # the scene's own value, which the program loads
    stdout = run_cli("grad", "builtin:cornell-box", "--width", "24", "--height", "20", "--spp", "8", "--seed", "3",
                     "--target", str(tmp_path / "target.exr"), "--loss", "l2", "--deterministic", "--json",
                     "--param", ALPHA, "--param", "red.reflectance.value")
    report = json.loads(stdout)
    loss, grads = pg.loss_and_grad(cornell, pg.read_image(tmp_path / "target.exr"), loss="l2", spp=8, seed=3,
                                   deterministic=True, wrt=[ALPHA, "red.reflectance.value"])
    assert loss == report["loss"]
    for name in (ALPHA, "red.reflectance.value"):
        assert np.array_equal(grads[name], np.asarray(report["gradients"][name], dtype=np.float32)), name


def test_image_gradient_equals_the_program_bit_for_bit(cornell, run_cli, tmp_path):
    out = tmp_path / "d_alpha.exr"
    run_cli("grad", "builtin:cornell-box", "--width", "24", "--height", "20", "--spp", "4", "--seed", "5",
            "--image-gradient", ALPHA, "-o", str(out))
    ours = pg.image_gradient(cornell, ALPHA, spp=4, seed=5)
    assert np.array_equal(ours, pg.read_image(out))
    assert np.abs(ours).max() > 0


def test_backward_is_the_derivative_of_the_adjoint_weighted_image(cornell):
    # grad(adjoint) equals loss_and_grad's gradient for the l2 loss's adjoint image, and a
    # deterministic pass repeats bit for bit.
    ones = np.ones((20, 24, 3), np.float32)
    a = pg.grad(cornell, ones, wrt=ALPHA, spp=8, seed=1, deterministic=True)
    b = pg.grad(cornell, ones, wrt=[ALPHA], spp=8, seed=1, deterministic=True)
    assert list(a) == [ALPHA] and a[ALPHA].shape == (1,)
    assert np.array_equal(a[ALPHA], b[ALPHA])
    twice = pg.grad(cornell, 2 * ones, wrt=ALPHA, spp=8, seed=1, deterministic=True)
    assert np.allclose(twice[ALPHA], 2 * a[ALPHA], rtol=1e-5)
    everything = pg.grad(cornell, ones, spp=8, seed=1, deterministic=True)
    assert set(everything) == set(cornell.params)
    assert np.allclose(everything[ALPHA], a[ALPHA], rtol=1e-5)


GLASS_ETA = "glass.bsdf.eta"


@pytest.fixture
def glass(repo):
    return pg.load(repo / "tests/data/scenes/attached_sphere.xml", width=16, height=12)


def test_attached_sampling_equals_the_program(glass, run_cli, tmp_path):
    # A glass sphere's index of refraction, differentiable only by attached sampling: the same
    # loss and gradient as `pathgrad grad --sampling attached`, bit for bit on the CPU reference,
    # and on the device up to the order of its float additions.
    own = glass.params[GLASS_ETA].copy()  # the scene's own value (Mitsuba's bk7), which the program loads
    pg.write_image(tmp_path / "target.exr", pg.render(glass, {GLASS_ETA: 1.3}, spp=8, seed=100))
    target = pg.read_image(tmp_path / "target.exr")
    glass.params[GLASS_ETA] = own
    for device, flags in [("cpu", ["--cpu"]), (None, [])]:
        stdout = run_cli("grad", str(glass.source), "--width", "16", "--height", "12", "--spp", "4", "--seed", "3",
                         "--target", str(tmp_path / "target.exr"), "--loss", "l2", "--json", "--sampling",
                         "attached", "--param", GLASS_ETA, *flags)
        report = json.loads(stdout)
        loss, grads = pg.loss_and_grad(glass, target, loss="l2", spp=4, seed=3, wrt=GLASS_ETA, sampling="attached",
                                       device=device)
        theirs = np.asarray(report["gradients"][GLASS_ETA], dtype=np.float32)
        assert grads[GLASS_ETA].shape == (1,) and grads[GLASS_ETA][0] != 0
        if device == "cpu":
            assert loss == report["loss"] and np.array_equal(grads[GLASS_ETA], theirs), (grads, theirs)
        else:
            assert np.allclose(grads[GLASS_ETA], theirs, rtol=1e-4), (grads, theirs)
    # The noise amplitude reaches the estimator: another amplitude, another estimate.
    noisy = pg.grad(glass, np.ones((12, 16, 3), np.float32), wrt=GLASS_ETA, spp=2, sampling="attached",
                    jacobian_noise=0.2, device="cpu")
    plain = pg.grad(glass, np.ones((12, 16, 3), np.float32), wrt=GLASS_ETA, spp=2, sampling="attached", device="cpu")
    assert noisy[GLASS_ETA][0] != plain[GLASS_ETA][0]


def test_detached_sampling_leaves_out_or_refuses_the_index_of_refraction(glass):
    ones = np.ones((12, 16, 3), np.float32)
    everything = pg.grad(glass, ones, spp=1, device="cpu")
    assert GLASS_ETA not in everything and set(everything) == set(glass.params) - {GLASS_ETA}
    assert GLASS_ETA in pg.grad(glass, ones, spp=1, device="cpu", sampling="attached")
    with pytest.raises(pg.ArgumentError, match=r"glass\.bsdf\.eta.*sampling=\"attached\""):
        pg.grad(glass, ones, wrt=GLASS_ETA, spp=1)
    with pytest.raises(pg.ArgumentError, match="jacobian_noise.*applies only to"):
        pg.grad(glass, ones, spp=1, jacobian_noise=0.1)
    with pytest.raises(pg.ArgumentError, match=r"sampling: 'sideways': expected detached or attached"):
        pg.loss_and_grad(glass, ones, spp=1, sampling="sideways")
    with pytest.raises(pg.ArgumentError, match=r"noise.*\[0, 1\)"):
        pg.grad(glass, ones, spp=1, sampling="attached", jacobian_noise=1.5)


def test_params_view(cornell):
    params = cornell.params
    # The seven of before, and since issue 34 the rough sphere's conductor eta and k.
    assert len(params) == 9 and ALPHA in params and "nope" not in params
    assert "sphere.bsdf.eta.value" in params and params.info("sphere.bsdf.k.value").shape == (3,)
    info = params.info(ALPHA)
    assert info.shape == (1,) and info.bounds == (0.001, 1.0)
    assert params.info("red.reflectance.value").shape == (3,)
    before = params["red.reflectance.value"]
    params["red.reflectance.value"] = np.array([0.1, 0.2, 0.3])  # float64 is taken, as float32
    assert np.array_equal(params["red.reflectance.value"], np.float32([0.1, 0.2, 0.3]))
    before[0] = 0.9  # a copy: the scene does not change
    assert params["red.reflectance.value"][0] == np.float32(0.1)
    assert params.get("nope") is None and params.get(ALPHA) is not None  # dict behaviour
    with pytest.raises(KeyError):
        params["nope"]
    params[ALPHA] = 0.25  # a scalar parameter takes a number
    assert params[ALPHA].shape == (1,)
    params.update({ALPHA: np.float32([0.35])})
    assert params[ALPHA][0] == np.float32(0.35)
    # Values set on the scene are what renders see: set one way or the other, the same image.
    a = pg.render(cornell, spp=2, seed=0)
    b = pg.render(cornell, {ALPHA: 0.35}, spp=2, seed=0)
    c = pg.render(cornell, {ALPHA: 0.6}, spp=2, seed=0)
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    assert cornell._native.open_backends() == 1


def test_shapes_of_texture_and_grid_parameters(repo):
    bitmap = pg.load(repo / "tests/conformance/scenes/bsdf_diffuse_bitmap.xml")
    textures = [n for n in bitmap.params if n.endswith(".data")]
    assert textures
    for name in textures:
        assert bitmap.params.info(name).shape == (8, 8, 3)
        assert bitmap.params[name].shape == (8, 8, 3)
    grid = pg.load(repo / "tests/conformance/scenes/medium_grid_sigma_t.xml")
    (name,) = [n for n in grid.params if n.endswith("sigma_t.data")]
    shape = grid.params.info(name).shape
    assert len(shape) == 4 and grid.params[name].size == np.prod(shape)
    with pytest.raises(pg.ArgumentError, match=r"shape \(3,\), expected"):
        grid.params[name] = np.ones(3)


def test_several_sensors_render_as_each_alone(repo):
    scene = pg.load(repo / "scenes/two-sided/scene.xml", res=16)
    assert [s["name"] for s in scene.sensors] == ["front_camera", "back_camera"]
    both = pg.render(scene, sensors=[0, "back_camera"], spp=4, seed=2)
    assert both.shape == (2, 16, 16, 3)
    assert np.array_equal(both[0], pg.render(scene, spp=4, seed=2))
    assert np.array_equal(both[1], pg.render(scene, sensor=1, spp=4, seed=2))
    assert not np.array_equal(both[0], both[1])
    adjoint = np.ones((2, 16, 16, 3), np.float32)
    grads = pg.grad(scene, adjoint, sensors=[0, 1], spp=4, seed=2, deterministic=True)
    one = pg.grad(scene, adjoint[0], sensor=0, spp=4, seed=2, deterministic=True)
    other = pg.grad(scene, adjoint[1], sensor=1, spp=4, seed=2, deterministic=True)
    for name in grads:
        assert np.allclose(grads[name], one[name] + other[name], rtol=1e-5, atol=1e-6), name


def test_the_gil_is_released_while_rendering(cornell):
    pg.render(cornell, spp=1)  # kernels built, renderer open
    ticks = []
    done = threading.Event()

    def count():
        while not done.is_set():
            ticks.append(1)
            time.sleep(0.001)

    counter = threading.Thread(target=count)
    counter.start()
    start = time.perf_counter()
    try:
        while time.perf_counter() - start < 0.5:
            before = len(ticks)
            pg.render(cornell, spp=64, seed=1, device="cpu")
    finally:
        done.set()
        counter.join()
    # The counter ran during the renders: at least some ticks in the last render alone.
    assert len(ticks) - before > 5


@pytest.mark.parametrize(
    "call, error, message",
    [
        (lambda s: s.params.__setitem__(ALPHA, np.ones((2,))), pg.ArgumentError, r"shape \(2,\), expected \(1,\)"),
        (lambda s: s.params.__setitem__("red.reflectance.value", np.ones(3, np.int64)), pg.ArgumentError, "dtype int64"),
        (lambda s: s.params.__setitem__("red.reflectance.value", [0.1, float("nan"), 0.2]), pg.ArgumentError,
         r"not finite, the first nan at index \(1,\)"),
        (lambda s: s.params.__setitem__(ALPHA, 2.0), pg.ArgumentError, r"outside its bounds \[0.001, 1.0\]"),
        (lambda s: s.params.__setitem__(ALPHA, True), pg.ArgumentError, "a bool"),
        (lambda s: s.params["nope"], pg.ArgumentError, "'nope' is not a parameter of builtin:cornell-box"),
        (lambda s: pg.render(s, {"nope": 1.0}), pg.ArgumentError, "'nope' is not a parameter"),
        (lambda s: pg.render(s, spp=0), pg.ArgumentError, "invalid spp"),
        (lambda s: pg.render(s, seed=-1), pg.ArgumentError, "invalid seed"),
        (lambda s: pg.render(s, sensor=3), pg.SceneError, "sensor"),
        (lambda s: pg.render(s, max_depth=0), pg.ArgumentError, "max_depth"),
        (lambda s: pg.render(s, max_depth=2.5), pg.ArgumentError, "max_depth"),
        (lambda s: pg.render(s, device="7"), pg.DeviceError, "7"),
        (lambda s: pg.render("builtin:cornell-box"), pg.ArgumentError, "expected a pathgrad.Scene"),
        (lambda s: pg.grad(s, np.ones((20, 24))), pg.ArgumentError, r"adjoint: shape \(20, 24\), expected \(20, 24, 3\)"),
        (lambda s: pg.grad(s, np.ones((20, 24, 3), np.float32), wrt="nope"), pg.ArgumentError, "'nope'"),
        (lambda s: pg.grad(s, np.full((20, 24, 3), np.inf)), pg.ArgumentError, "adjoint: 1440 value"),
        (lambda s: pg.loss_and_grad(s, np.ones((20, 24, 3)), loss="l3"), pg.ArgumentError, "expected l1, l2"),
        (lambda s: pg.image_gradient(s, "nope"), pg.ArgumentError, "'nope'"),
    ],
)
def test_bad_arguments_raise_clear_errors(cornell, call, error, message):
    with pytest.raises(error, match=message):
        call(cornell)


def test_bad_scenes_and_files(tmp_path):
    with pytest.raises(pg.SceneError, match="unknown built-in scene"):
        pg.load("builtin:nope")
    bad = tmp_path / "bad.xml"
    bad.write_text('<scene version="3.0.0">\n  <sensor type="perspective"/>\n  <bsdf type="nope"/>\n</scene>\n')
    with pytest.raises(pg.SceneError, match="bad.xml:3:3: .*nope"):
        pg.load(bad)
    with pytest.raises(pg.FileError):
        pg.read_image(tmp_path / "missing.exr")
    with pytest.raises(pg.SceneError, match="only a Mitsuba XML scene"):
        pg.load("builtin:cornell-box", spp=4)
    # Library messages name this package's keywords, not the Rust library's option names.
    with pytest.raises(pg.ArgumentError) as refused:
        pg.load("builtin:furnace", env=tmp_path / "sky.exr")
    assert "invalid env" in str(refused.value) and "LoadOptions" not in str(refused.value)
    # Every error is a pathgrad.Error, and the argument errors are ValueErrors too.
    assert issubclass(pg.ArgumentError, ValueError) and issubclass(pg.SceneError, pg.Error)


def test_defines_and_env(repo):
    scene = pg.load(repo / "scenes/two-sided/scene.xml", res=12)
    assert scene.size == (12, 12)
    assert pg.render(scene, spp=2).shape == (12, 12, 3)
    lit = pg.load("builtin:cornell-box", width=8, env=0.25)
    assert lit.size == (8, 8)
    assert np.array_equal(lit.params["env.radiance.value"], np.float32([0.25, 0.25, 0.25]))
    with pytest.raises(pg.ArgumentError, match="env"):
        pg.load("builtin:cornell-box", env=(1.0, 2.0))


def test_attached_image_gradient_sums_to_the_gradient(glass):
    # Forward mode with attached sampling: the image gradient weighted by an adjoint image and
    # summed is the reverse-mode gradient with that adjoint (the same paths on the CPU reference);
    # detached sampling refuses the index of refraction's image gradient by name.
    weights = np.linspace(0.5, 1.5, 12 * 16 * 3, dtype=np.float32).reshape(12, 16, 3)
    image = pg.image_gradient(glass, GLASS_ETA, spp=2, seed=4, device="cpu", sampling="attached")
    assert image.shape == (12, 16, 3) and np.abs(image).sum() > 0
    grads = pg.grad(glass, weights, wrt=GLASS_ETA, spp=2, seed=4, sampling="attached", device="cpu")
    forward = float((image.astype(np.float64) * weights).sum())
    assert np.isclose(forward, float(grads[GLASS_ETA][0]), rtol=1e-5), (forward, grads)
    with pytest.raises(pg.ArgumentError, match=r"glass\.bsdf\.eta.*sampling=\"attached\""):
        pg.image_gradient(glass, GLASS_ETA, spp=1, device="cpu")

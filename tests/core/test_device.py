"""One core on any array library (issue 47): core.render through a CPU double of CuPy arrays
(tests/device_double.py: it refuses every implicit host <-> device transfer, as CuPy does)
gives the numpy path's images exactly, on every model of the registry and on the scene
features a trace meets (a disk, a volume, a moving camera, ray differentials, a texture
sky, a user metric). A stray ``np.asarray`` or host array in the trace fails here, not on a
user's GPU. CI has no GPU: benchmarks/gpu.py runs the same scenes on CuPy where one is."""

from __future__ import annotations

import importlib.util
import sys

import numpy as np
import pytest

import core
from core import backend
from core import hamiltonians as hm
from core.integrators import METHODS
from core.integrators.splitting import Splitting
from core.models.registry import MODELS
from core.tolerances import TRACE_SHARE
from tests.device_double import DEVICE, XP, DeviceArray, HostTransferError, host_reads

WIDTH, HEIGHT = 16, 12
OLD_NUMPY = int(np.__version__.split(".")[0]) < 2
"""numpy 1.26 (Blender 4.2) only: a pass's floats may differ in their last bits (compared
to 1e-12 relative, 1e-14 absolute: radians far below any tolerance). Where host code
meets a device's rays (the volumes, the disk's light) it works on contiguous copies, and
numpy 1.26 evaluates some functions on contiguous arrays (SIMD loops) and on strided views
(scalar loops) to different last bits (seen: one error estimate of 108 off by 1.7e-17,
20 ulp of a difference of nearly equal directions). The absolute floor is 1e-14 rad: a
difference of nearly equal unit directions keeps their rounding whatever its size (40
spheres around a hole: one pixel's error estimate 4e-15 on one path, 1e-15 on the other;
1e-14 is 45 ulp of a unit vector, 1e-12 of a pixel there); 1e-15 was the floor before
that scene.
numpy 2 agrees to the last bit, and there every pass is compared exactly; the images
(rgba) are compared exactly on both."""


def _camera(position=(0, -30, 2), width: int = WIDTH, height: int = HEIGHT) -> core.Camera:
    return core.Camera.perspective(position=position, look_at=(0, 0, 0), up=(0, 0, 1),
                                   fov_deg=40, width=width, height=height)  # fmt: skip


def _objects() -> list:
    """A textured board behind the centre and a ball beside it."""
    board = core.Plane(point=(0, 12, 0), normal=(0, -1, 0), u_axis=(1, 0, 0), extent=(16, 16),
                       color=core.checker(8, 8))  # fmt: skip
    return [board, core.Sphere((3.0, 0.0, 1.0), 1.0, (0.3, 0.5, 1.0, 1.0))]


TEXT_MODELS = {  # kinds read from text: a model of each that bends light
    "index": lambda: hm.medium("1 + 0.5*exp(-(x*x + y*y + z*z))"),
    "metric": lambda: hm.metric(
        [["-exp(-2*phi)", "0", "0", "0"], ["0", "exp(2*phi)", "0", "0"],
         ["0", "0", "exp(2*phi)", "0"], ["0", "0", "0", "exp(2*phi)"]],
        parameters={"m": 0.5, "b": 1.0},
        definitions=[("phi", "-m/sqrt(x**2 + y**2 + z**2 + b**2)")],
    ),
    "hamiltonian": lambda: hm.from_expression(
        "0.5*(p_x**2 + p_y**2 + p_z**2)/(1 + 0.5*exp(-(x*x + y*y + z*z)))**2",
        q=["x", "y", "z"], p=["p_x", "p_y", "p_z"],
    ),
}  # fmt: skip


def _model(name: str):
    """The registry kind ``name`` at its defaults (spin a/M 0.6, charge Q/M 0.3)."""
    kind = MODELS[name]
    if kind.inputs:
        return TEXT_MODELS[kind.inputs]()
    if kind.build is None:
        return None
    values = {p.name: p.default for p in kind.parameters} | {"spin": 0.6, "charge": 0.3}
    return kind.build(**{n: values[n] for n in kind.parameter_names()})


def _same(cpu: core.RenderResult, device: core.RenderResult) -> None:
    """Every pass and the image equal to the last bit, and all of them numpy arrays."""
    assert isinstance(device.rgba, np.ndarray)
    np.testing.assert_array_equal(device.rgba, cpu.rgba)
    assert device.passes.keys() == cpu.passes.keys()
    for name, data in cpu.passes.items():
        assert isinstance(device.passes[name], np.ndarray), name
        if OLD_NUMPY and data.dtype.kind == "f":
            np.testing.assert_allclose(device.passes[name], data, rtol=1e-12, atol=1e-14)
        else:
            np.testing.assert_array_equal(device.passes[name], data, err_msg=name)
    for key in ("rays", "failed", "max_steps", "captured", "escaped", "hit"):
        assert device.summary.get(key) == cpu.summary.get(key), key


def _both(scene: core.Scene, camera: core.Camera, **options):
    """(the numpy render, the double's render) of one scene, one worker (at 1e-5 rad, not
    1e-8, unless asked: fewer steps, the same code)."""
    options.setdefault("tolerance", 1e-5)
    cpu = core.render(scene, camera, workers=1, **options)
    return cpu, core.render(scene, camera, workers=1, device=DEVICE, **options)


# --- the double refuses what CuPy refuses ----------------------------------------------------


def test_the_double_refuses_implicit_transfers_and_dispatches_the_rest():
    """np.asarray of a device array, a numpy array mixed into a device operation, as an
    index or as a value set: TypeError. Scalars mix; numpy's functions return device
    arrays; size-1 arrays read as Python numbers; to_host brings the data back."""
    a = XP.arange(6.0)
    with pytest.raises(HostTransferError):
        np.asarray(a)
    with pytest.raises(HostTransferError):
        a + np.ones(6)
    with pytest.raises(HostTransferError):
        a[np.array([0, 1])]
    with pytest.raises(HostTransferError):
        a[:2] = np.zeros(2)
    b = np.sqrt(2.0 * a + 1)
    assert isinstance(b, DeviceArray) and isinstance(np.flatnonzero(a > 2), DeviceArray)
    assert float(a.max()) == 5.0 and int(np.count_nonzero(a)) == 5 and bool(a.any())
    assert backend.array_module(a) is XP and backend.array_module(np.ones(2), 1.0) is np
    np.testing.assert_array_equal(backend.to_host(b), np.sqrt(2.0 * np.arange(6.0) + 1))


def test_placed_constants_are_copied_once_per_device():
    """A host constant beside numpy arrays is itself; beside a device's, its copy, made once."""
    rotation = np.eye(3)
    assert backend.placed(rotation, np.zeros(3)) is rotation
    first = backend.placed(rotation, XP.zeros(3))
    assert isinstance(first, DeviceArray) and backend.placed(rotation, XP.ones(2)) is first


# --- every model, every feature: the same image ----------------------------------------------


@pytest.mark.parametrize("name", list(MODELS))
def test_every_model_renders_on_the_device_as_on_the_cpu(name):
    """Each kind of the registry (flat, the holes, a medium, a user metric, a Hamiltonian
    as text), its default method: image and passes equal to the numpy path's."""
    model = _model(name)
    scene = core.Scene(model=model, objects=_objects(), background="procedural")
    _same(*_both(scene, _camera()))


@pytest.mark.parametrize(
    "name, differentials",
    [("SCHWARZSCHILD", False), ("KERR", False), ("MEDIUM", False), ("SCHWARZSCHILD", True),
     ("KERR", True)],
)  # fmt: skip
def test_a_splittings_step_reads_nothing_back_from_the_device(name, differentials, monkeypatch):
    """A step of an explicit splitting on the device (each model whose default method is
    one: its split's kicks and drifts; with ray differentials, their tangent maps too)
    reads no device value back to the host: a GPU runs it without waiting between its
    flows, and a CUDA graph can capture it. Counted over every step of a render
    (host_reads); before, Kerr's split compared each flow's theta with the one its sines
    were kept for on the host (20 syncs a step), and its tangent maps asked in every flow
    whether E varies along a tangent (read once per batch now, by gauge_tangents)."""
    model = _model(name)
    scene = core.Scene(model=model, objects=_objects(), background="procedural")
    steps, reads, step = [0], [0], Splitting.step

    def counted(self, *args, **kwargs):
        with host_reads() as inside:
            out = step(self, *args, **kwargs)
        steps[0] += 1
        reads[0] += inside.count
        return out

    monkeypatch.setattr(Splitting, "step", counted)
    passes = (*core.render.__kwdefaults__["passes"], "magnification")
    options = dict(passes=passes) if differentials else {}
    camera = _camera(width=8, height=6)
    core.render(scene, camera, workers=1, device=DEVICE, tolerance=1e-5, **options)
    assert steps[0] > 10
    assert reads[0] == 0


def test_the_double_answers_on_the_device_where_cupy_does_and_counts_host_reads():
    """array_equal is a 0-d device array (as CuPy's), and reading it, or any size-1 value,
    as a Python value is counted as a read back to the host."""
    a = XP.asarray([1.0, 2.0])
    with host_reads() as reads:
        same = np.array_equal(a, a + 0.0)
        assert isinstance(same, DeviceArray) and same.shape == ()
        assert reads.count == 0
        assert bool(same) and float(a[1]) == 2.0 and a.sum().item() == 3.0
    assert reads.count == 3


@pytest.mark.parametrize("method", ["blanes_moan_s6", "gauss4", "rk4"])
def test_other_methods_render_on_the_device_as_on_the_cpu(method):
    """An explicit splitting, the implicit Gauss method and a Runge-Kutta method."""
    scene = core.Scene(model=hm.schwarzschild(rg=1.0), objects=_objects())
    _same(*_both(scene, _camera(), method=method))


@pytest.mark.parametrize("method", list(METHODS))
def test_every_method_renders_on_the_device_or_is_refused_alike(method):
    """Every method of core.METHODS on a Schwarzschild hole (8 x 6 px, at most 120 steps a
    ray: the first-order methods' rays end as max_steps alike): the device's image equals
    the CPU's, or both refuse with the same message (Tao's for a black hole)."""
    scene = core.Scene(model=hm.schwarzschild(rg=1.0), objects=_objects())
    camera, options = _camera(width=8, height=6), dict(method=method, tolerance=1e-4)
    options |= dict(max_steps=120, workers=1)
    try:
        cpu = core.render(scene, camera, **options)
    except ValueError as refused:
        with pytest.raises(ValueError) as also:
            core.render(scene, camera, device=DEVICE, **options)
        assert str(also.value) == str(refused)
        return
    _same(cpu, core.render(scene, camera, device=DEVICE, **options))


def test_a_disk_a_volume_and_a_texture_sky_render_on_the_device_as_on_the_cpu():
    """Kerr with an accretion disk (its redshift and colour), an emitting volume beside it,
    an image sky filtered over each pixel's footprint."""
    rng = np.random.default_rng(47)
    sky = core.Background(0.2 + 0.6 * rng.random((32, 64, 3)))
    volume = core.Volume((4, -2, -2), (8, 2, 2), density=lambda p: np.ones(len(p)),
                         emission=lambda p: np.tile([0.3, 0.1, 0.0], (len(p), 1)),
                         absorption=0.2)  # fmt: skip
    model = hm.kerr(rg=1.0, a=0.45, chart="kerr_schild")
    scene = core.Scene(model=model, disk=core.AccretionDisk(r_out=8.0), volumes=[volume],
                       background=sky)  # fmt: skip
    _same(*_both(scene, _camera((0, -25, 4), 12, 9)))


def test_a_lens_in_a_box_with_a_kink_renders_on_the_device_as_on_the_cpu():
    """A graded-index lens in a box (the box region: entry, leaving, exit times) whose
    index has a kink inside it (Luneburg's lens inside r = 1, n = 1 beyond: the kink
    tests' cubic through each step): before, the box's corners and the cubic's sample
    points were host arrays mixed into device operations."""
    r2 = "(x*x + y*y + z*z)"
    index = f"sqrt(2 - ({r2} + 1 - abs({r2} - 1))/2)"  # r^2 clipped at 1: n = 1 beyond
    model = hm.medium(index, bounds=((-1.5,) * 3, (1.5,) * 3))
    ball = core.Sphere((0.45, 0.3, -0.3), 0.2, core.checker(8, 4, (1.0, 0.5, 0.2)))
    scene = core.Scene(model=model, objects=[ball], background="procedural")
    camera = core.Camera.perspective(position=(0, -6, 0.45), look_at=(0, 0, 0), up=(0, 0, 1),
                                     fov_deg=40, width=12, height=9)  # fmt: skip
    _same(*_both(scene, camera))


@pytest.mark.parametrize("observer", ["orbit", "infall"])
def test_a_moving_camera_renders_on_the_device_as_on_the_cpu(observer):
    """Aberration and Doppler shift of a camera orbiting or falling near a Kerr hole."""
    scene = core.Scene(model=hm.kerr(rg=1.0, a=0.45), objects=_objects())
    _same(*_both(scene, _camera((0, -16, 0), 12, 9), observer=observer))


@pytest.mark.parametrize("name", ["SCHWARZSCHILD", "KERR"])
def test_ray_differentials_render_on_the_device_as_on_the_cpu(name):
    """The magnification pass: tangents carried through the steps (DualRows) on the device
    (Kerr's: its split's own tangent maps, E's terms as gauge_tangents found them)."""
    scene = core.Scene(model=_model(name), objects=_objects())
    passes = (*core.render.__kwdefaults__["passes"], "magnification")
    _same(*_both(scene, _camera(), passes=passes))


def test_tolerance_px_on_the_device_traces_every_pixel_at_the_samplers_step():
    """With tolerance_px a device traces every pixel centre at the integration's share of
    it: the CPU's dense render at that tolerance, bit for bit."""
    scene = core.Scene(model=hm.schwarzschild(rg=1.0), objects=_objects())
    camera = _camera()
    device = core.render(scene, camera, workers=1, device=DEVICE, tolerance_px=1.0)
    pixel_angle = device.summary["pixel_angle"]
    cpu = core.render(scene, camera, workers=1, tolerance=TRACE_SHARE * pixel_angle)
    np.testing.assert_array_equal(device.rgba, cpu.rgba)
    assert device.summary["rays"] == WIDTH * HEIGHT
    assert (device.summary["device"], cpu.summary["device"]) == ("double", "cpu")


# --- refusals ----------------------------------------------------------------------------------


def test_a_device_render_refuses_anti_aliasing_and_clusters_by_name():
    """samples > 1 and a cluster client name themselves and the device."""
    scene = core.Scene(model=hm.schwarzschild(rg=1.0))
    with pytest.raises(ValueError, match="samples > 1.*device 'double'"):
        core.render(scene, _camera(), device=DEVICE, samples=4, tolerance_px=1.0)
    with pytest.raises(ValueError, match="device must be 'cpu' or 'cuda'"):
        core.render(scene, _camera(), device="gpu")


def test_cuda_without_cupy_names_the_package_to_install(monkeypatch):
    """No CuPy: "cuda" is refused with the package's name (CuPy is never required); CuPy
    without a GPU: with CUDA's reason."""
    if importlib.util.find_spec("cupy") is None:
        with pytest.raises(RuntimeError, match="needs CuPy.*pip install cupy"):
            core.render(core.Scene(), _camera(), device="cuda")
        assert "CuPy" in (backend.cuda_problem() or "")
    monkeypatch.setitem(sys.modules, "cupy", None)  # as if not installed: import fails
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None)
    with pytest.raises(RuntimeError, match="needs CuPy.*pip install cupy"):
        backend.device_of("cuda")


def test_many_objects_render_on_the_device_as_on_the_cpu():
    """40 spheres around a hole (more than NEAR_BOXES: steps near geometry by the objects'
    own boxes at once, core.geometry.boxcells.ManyBoxes; a Group's broad phase): image and
    passes equal to the numpy path's."""
    rng = np.random.default_rng(40)
    direction = rng.normal(size=(40, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    centres = rng.uniform(4.0, 12.0, (40, 1)) * direction
    spheres = [core.Sphere(c, 0.8, (0.3, 0.5, 1.0, 1.0)) for c in centres]
    scene = core.Scene(model=hm.schwarzschild(rg=1.0), objects=spheres, background="procedural")
    _same(*_both(scene, _camera()))

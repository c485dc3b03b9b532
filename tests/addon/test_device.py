"""Render Properties › Device (issue 47): CPU or GPU, as Cycles has it. Without CuPy in
Blender's Python the GPU is refused by name before anything is traced; with a device (here
the CPU double of CuPy arrays, tests/device_double.py, standing in for CuPy) F12 traces
every pixel there and gives the CPU's dense image at the same step, bit for bit."""

from __future__ import annotations

from types import SimpleNamespace

import bpy
import numpy as np
import pytest

from tests.device_double import XP

from .conftest import operator_error
from .test_first_contact import f12
from .test_panel import FakeLayout

WIDTH, HEIGHT = 48, 36


def _hole_scene(scene) -> None:
    """The factory scene (its cube, camera and light) with a Kerr hole beside the cube, small."""
    scene.cursor.location = (2.5, 0.0, 0.0)
    assert bpy.ops.symray.add_black_hole(size=0.6, spin=0.6, disk=False) == {"FINISHED"}
    scene.render.resolution_x, scene.render.resolution_y = WIDTH, HEIGHT
    scene.render.resolution_percentage = 100
    scene.symray.workers = 1  # one chunk: the device's batch, ray for ray
    bpy.context.view_layer.update()


@pytest.fixture
def double_gpu(addon, monkeypatch):
    """CuPy replaced by the double in the extension's core (a GPU that is the CPU)."""
    backend, asked = addon.core.backend, []
    monkeypatch.setattr(backend, "_cupy", lambda: asked.append(1) or XP)
    monkeypatch.setattr(backend, "cuda_problem", lambda: None)
    return asked


def test_the_device_defaults_to_the_cpu(addon, factory_scene):
    """A new scene renders on the CPU; the job asks core.render for "cpu"."""
    assert factory_scene.symray.device == "CPU"
    render_job = addon.module("symray_addon.render_job")
    job = render_job.prepare(factory_scene, bpy.context.evaluated_depsgraph_get())
    assert job.options["device"] == "cpu"


def test_gpu_without_cupy_is_refused_by_name_before_tracing(addon, factory_scene, tmp_path):
    """Device GPU where CuPy does not import or finds no GPU: the panel's problems and F12
    name CuPy, why, and the way back (Device CPU)."""
    problem = addon.core.backend.cuda_problem()
    if problem is None:
        pytest.skip("a GPU renders here")
    scene = factory_scene
    scene.symray.device = "GPU"
    panel = addon.module("symray_addon.panel")
    problems = panel.render_problems(scene)
    assert any("Device GPU" in p and problem in p and "Device to CPU" in p for p in problems)
    message = operator_error(lambda: bpy.ops.render.render(scene=scene.name))
    assert "CuPy" in message and problem in message


def test_f12_on_the_gpu_is_the_cpus_dense_image_at_the_same_step(addon, factory_scene, tmp_path,
                                                                  double_gpu):  # fmt: skip
    """Preview (1 px) on the device: every pixel traced at the integration's share of the
    tolerance (core.tolerances.TRACE_SHARE); the CPU's render at that tolerance in radians
    (dense, one worker) is the same image. Final's 16 samples become 1, with a warning."""
    scene = factory_scene
    _hole_scene(scene)
    scene.symray.device = "GPU"
    gpu = f12(scene, tmp_path, "gpu")
    assert double_gpu  # traced through the double
    summary = addon.module("symray_addon.render_job").last_summary
    assert summary["rays"] == WIDTH * HEIGHT and summary["parallel"] == "inline"
    share = addon.core.tolerances.TRACE_SHARE
    scene.symray.device = "CPU"
    scene.symray.quality, scene.symray.tolerance = "RADIANS", share * summary["pixel_angle"]
    cpu = f12(scene, tmp_path, "cpu")
    np.testing.assert_array_equal(gpu, cpu)
    shadow = gpu[..., :3].max(axis=-1) < 1e-3
    assert 20 < shadow.sum() < WIDTH * HEIGHT / 4  # the hole is in the frame, not all of it
    scene.symray.device, scene.symray.quality = "GPU", "FINAL"
    render_job = addon.module("symray_addon.render_job")
    job = render_job.prepare(scene, bpy.context.evaluated_depsgraph_get())
    assert job.options["samples"] == 1 and job.options["device"] == "cuda"
    assert render_job.GPU_SAMPLES_WARNING in job.warnings


class _Recording(FakeLayout):
    """A fake layout that also records each property's text and its row's enabled state."""

    enabled = True

    def _child(self, *_args, **_kwargs) -> _Recording:
        return _Recording(self.log)

    row = column = split = box = _child

    def prop(self, data, name: str, text: str | None = None, **kwargs) -> None:
        super().prop(data, name, **kwargs)
        self.log.append(("shown", name, text, self.enabled))


def _device_row(scene) -> tuple:
    """(text, enabled) of the Device row the SymRay render panel draws."""
    log: list = []
    bpy.types.RENDER_PT_symray.draw(SimpleNamespace(layout=_Recording(log)),
                                    SimpleNamespace(scene=scene))  # fmt: skip
    (row,) = [entry[2:] for entry in log if entry[:2] == ("shown", "device")]
    return row


def test_the_device_row_is_greyed_with_its_reason_where_no_gpu_renders(addon, factory_scene,
                                                                        monkeypatch):  # fmt: skip
    """No CuPy: the row is greyed out and says why; chosen anyway (a .blend from a GPU
    machine): it stays editable, so the way back to CPU is open; a GPU: a plain row."""
    validation = addon.module("symray_addon.validation")
    missing = "device 'cuda' needs CuPy, which is not installed here (pip install cupy)"
    monkeypatch.setattr(validation, "gpu_problem", lambda: missing)
    assert _device_row(factory_scene) == ("Device (GPU needs CuPy)", False)
    monkeypatch.setattr(validation, "gpu_problem", lambda: "cudaErrorNoDevice")
    assert _device_row(factory_scene) == ("Device (no usable GPU)", False)
    factory_scene.symray.device = "GPU"
    assert _device_row(factory_scene) == ("Device (no usable GPU)", True)
    monkeypatch.setattr(validation, "gpu_problem", lambda: None)
    assert _device_row(factory_scene) == (None, True)

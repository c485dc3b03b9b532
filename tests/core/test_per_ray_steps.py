"""Tracer.trace with a step per ray: runs at several steps share one batch (the error
pass's companion rides with the main run) and give exactly what separate runs give."""

from __future__ import annotations

import numpy as np
import pytest

import core
from core import hamiltonians as hm
from core.trace import TraceOptions, Tracer

FIELDS = ("ending", "direction", "position", "surface", "steps", "energy_error", "tangent")


def _board_scene(model) -> core.Scene:
    board = core.Plane(point=(0, 12, 0), normal=(0, -1, 0), u_axis=(1, 0, 0), extent=(16, 16),
                       color=(0.9, 0.7, 0.2, 1))  # fmt: skip
    return core.Scene(model=model, objects=[board])


def _cases():
    kerr = _board_scene(hm.kerr(rg=1.0, a=0.45, chart="kerr_schild"))
    schwarzschild = _board_scene(hm.schwarzschild(1.0))
    mirage, _ = core.presets.mirage_view("fig10", 12, 9)
    return [
        ("kerr", kerr, "blanes_moan_s10"), ("kerr", kerr, "gauss4"), ("kerr", kerr, "dopri5"),
        ("schwarzschild", schwarzschild, "blanes_moan6"), ("mirage", mirage, "blanes_moan4"),
    ]  # fmt: skip


@pytest.mark.parametrize(("label", "scene", "method"), _cases(), ids=lambda x: str(x)[:16])
def test_one_batch_at_two_steps_equals_two_runs(label, scene, method):
    """The same 16x12 camera rays at h and 2h, once in one batch with per-ray steps and
    once as two batches: every result field identical (bitwise)."""
    if label == "mirage":
        _, cam = core.presets.mirage_view("fig10", 16, 12)
    else:
        cam = core.Camera.perspective(position=(0, -30, 2), look_at=(0, 0, 0), up=(0, 0, 1),
                                      fov_deg=40, width=16, height=12)  # fmt: skip
    origins, directions = cam.rays()
    tracer = Tracer(scene, TraceOptions(method=method, tolerance=1e-6), extent=30)
    h = tracer.step
    n = origins.shape[0]
    apart = [tracer.trace(origins, directions, step=s) for s in (h, 2 * h)]
    twice = [np.concatenate([a, a]) for a in (origins, directions)]
    both = tracer.trace(*twice, step=np.repeat([h, 2 * h], n))
    assert len(np.unique(apart[0].ending)) > 1  # more than one kind of ending in view
    for name in FIELDS:
        joined = np.concatenate([getattr(r, name) for r in apart])
        np.testing.assert_array_equal(getattr(both, name), joined, err_msg=name)
    assert not np.array_equal(apart[0].direction, apart[1].direction)  # the steps differ


def test_a_step_per_ray_of_the_wrong_length_is_refused():
    tracer = Tracer(_board_scene(hm.schwarzschild(1.0)), TraceOptions(tolerance=1e-6), extent=30)
    origins = np.zeros((3, 3)) + [0, -30, 0]
    with pytest.raises(ValueError, match="one per ray"):
        tracer.trace(origins, np.tile([0.0, 1.0, 0.0], (3, 1)), step=np.ones(2))

"""Rays landing on an opaque accretion disk within a step.

Interface: ``land_on_disk(tracer, idx, cols, u, out, step_ends)``: the rays whose chords hit
an opaque disk (at the fraction ``u`` of the step on its cubic) placed where the method's
own path crosses the disk's plane (``StepEnds.plane_crossing``), their hit undone where
that crossing is off the disk, and lit there (``DiskLight.shade``) -> the undone ones.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..backend import placed
from .scene import DISK_ID
from .segments import RayResults
from .step_ends import StepEnds

if TYPE_CHECKING:
    from .tracer_state import TracerState


def land_on_disk(
    tracer: TracerState, idx: np.ndarray, cols: np.ndarray, u: np.ndarray, out: RayResults,
    step_ends: StepEnds,
) -> np.ndarray:  # fmt: skip
    """The rays of the batch rows ``cols`` ended on an opaque disk at the fraction ``u``
    of this step (the cubic's): their hit points where the method crosses the disk
    (StepEnds.plane_crossing; the cubic's stands where it does not converge), and the
    disk's light there. Where the method crosses the disk's plane off the disk (the
    cubic's hit lay within its slack of an edge), the ray did not hit it: its hit is
    undone and it goes on from the step's end. -> (M,) bool: those undone."""
    assert tracer.disk is not None
    X, ok = step_ends.plane_crossing(cols, u)
    rows = idx[cols]
    world = tracer._to_world(X.T)
    off = np.zeros_like(cols, dtype=bool)
    if ok.any():
        # across the plane (found to share |X|), along its normal
        near = 1e-3 * np.linalg.norm(X[:, ok], axis=0)[:, None] * placed(tracer.rotation, X)[:, 2]
        across = tracer.geometry.cast(world[ok] - near, world[ok] + near)
        off[ok] = ~(across.hit & (across.object_id == DISK_ID))
    out.position[rows[ok]] = world[ok]
    undone = rows[off]
    out.ending[undone], out.object_id[undone], out.surface[undone] = -1, -1, 0.0
    on = ~off
    tracer.disk.shade(rows[on], out.position[rows[on]], step_ends.state(cols[on]), out)
    return off

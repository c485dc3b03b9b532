"""Recording rays' clearance as a trace goes: each step's chords near the objects' box.

Interface: ``watch_step(tracer, idx, X_prev, X, camera, paths, share, out)`` (a batch's step
recorded in its rays' clearance, core/tracing/clearance.py ``ClearanceBoxes.record``, its
chords bent into their cubic paths where they pass near geometry) and ``bends(paths, X)``
(those bends, and the slack of the hit test's chords).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..backend import array_module, placed
from ..geometry import segment_overlaps
from .near_geometry import NearPaths
from .segments import RayResults

if TYPE_CHECKING:
    from .tracer_state import TracerState


def bends(paths: NearPaths | None, X: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(P, R) (3, n) that bend each of a batch's n step chords X0 -> X1 (X1: ``X``) into
    the cubic path the hit test follows (core/tracing/dense.py), P = X0 - X1 + h V0 and R = X0 - X1
    + h V1, and (n,) the slack of its hit test: how far the chords it casts stray from the
    cubic (dense.pieces), where the step passes near geometry (``paths``); elsewhere 0
    (the chord). A path curving towards an object between its ends comes closer to it
    than its chord (a mirage's ray dips below it over hot ground), and an object within
    the slack of the cubic may be hit or missed whatever the chords cast say."""
    n, xp = X.shape[1], array_module(X)
    P, R, slack = xp.zeros((3, n)), xp.zeros((3, n)), xp.zeros(n)
    if paths is not None:
        P[:, paths.rows] = paths.X0 - paths.X1 + paths.h * paths.V0
        R[:, paths.rows] = paths.X0 - paths.X1 + paths.h * paths.V1
        slack[paths.rows] = paths.deviation / (paths.pieces * paths.pieces)
    return P, R, slack


def watch_step(
    tracer: TracerState, idx: np.ndarray, X_prev: np.ndarray, X: np.ndarray, camera: np.ndarray,
    paths: NearPaths | None, share: np.ndarray, out: RayResults, until: np.ndarray,
) -> None:  # fmt: skip
    """Lower the clearance of a batch's rays (``idx``) by their step X_prev -> X (local,
    (3, M), seen from ``camera``), where it lies within the margin of the objects' box
    (``TracerState._watch_near``) and the ray's ``share`` of the margin is above 0: each step's
    chord bent into its cubic path where it passes near geometry (``paths``: ``bends``),
    up to ``until`` (M,) of it (a ray that hit a surface in this step: to its hit; the
    rest of the step is not its path: an object behind the hit is no obstacle)."""
    near = segment_overlaps(X_prev.T, X.T, *tracer._watch_near)
    r = np.flatnonzero(near & (share > 0))
    if r.size:
        world = [tracer._to_world(x[:, r].T) for x in (X_prev, X, camera)]
        *bent, slack = bends(paths, X)
        R = placed(tracer.rotation, X)
        bend = (*(b[:, r].T @ R.T for b in bent), slack[r])
        tracer._watch_segments(idx[r], world[0], world[1], out, world[2], bend, share[r], until[r])

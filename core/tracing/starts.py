"""Where a batch's rays start, and what they carry from there.

Interface (each takes the ``Tracer`` whose rays they are): ``start_results`` (the results
of rays not traced yet, along the static observer's directions: a moving camera's
aberrated, with their Doppler factor), ``start_state`` (the chart's coordinates and the
observer frame's momenta at the rays' start), ``start_tangents`` (the start state's
derivatives along the rays' differentials), ``axial`` (whether one differential goes by the
model's symmetry) and ``supports_tangents`` / ``check_tangents`` (whether the trace can
carry ray differentials at all).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from ..observer import medium_momenta, spacetime_momenta
from .differentials import directional, unit_directional
from .regions import SphereRegion
from .segments import RayResults

if TYPE_CHECKING:
    from .tracer_state import TracerState


def start_results(
    tracer: TracerState, origins: np.ndarray, directions: np.ndarray, tangents: np.ndarray | None
) -> tuple[RayResults, Any]:
    """The results of rays not traced yet, along the static observer's directions (a
    moving camera's aberrated, with their Doppler factor), and those directions'
    tangents (None without ``tangents``)."""
    shift = None
    motion = tracer.motion
    if motion is not None:

        def aberrated(d: np.ndarray) -> np.ndarray:
            return motion.aberrate(d)[0]

        shift = motion.colour_shift(directions)
        if tangents is not None:
            tangents = unit_directional(aberrated, directions, tangents)
        directions, _ = motion.aberrate(directions)
    out = RayResults.empty(origins.shape[0], origins, directions)
    if shift is not None:
        out.doppler = shift
    if tangents is not None:
        out.sky_jacobian = np.full_like(tangents, np.nan)
    return out, tangents


def start_state(tracer: TracerState, X: np.ndarray, D: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(Q, P) of rays starting at local positions X (3, M) along local directions D
    (3, M): the chart's coordinates and the observer frame's momenta."""
    S = tracer.chart.to_coords(X)
    if tracer.spacetime:
        return spacetime_momenta(tracer.model, tracer.chart, S, D)
    return medium_momenta(tracer.model, S, D)


def axial(tracer: TracerState) -> bool:
    """Whether rays' differentials go by the model's spherical symmetry: one traced,
    the other a turn about the camera's axis (core/tracing/differentials.py
    axial_tangents): a spherical model in a ball about its centre."""
    return tracer.model.spherical and isinstance(tracer.region, SphereRegion)


def start_tangents(
    tracer: TracerState, camera: np.ndarray, D: np.ndarray, tangents: np.ndarray, n: int
) -> tuple[np.ndarray, np.ndarray]:
    """(dQ, dP) (k, n, M): the start state's derivatives along the directions' tangents
    (M, k, 3), through the region's entry point, the chart and the observer's frame
    (central differences, core/tracing/differentials.py)."""
    region = tracer.region
    assert region is not None

    def state(d: np.ndarray) -> np.ndarray:
        X, _ = region.entry(camera.T, d)
        Q, P = start_state(tracer, X.T.copy(), d.T.copy())
        return np.concatenate([Q, P]).T

    periodic = [i + tracer.chart.offset for i in tracer.chart.periodic]
    dZ = directional(state, D.T, tangents, periodic)  # unit directions: |d| = 1 each side
    dZ = np.moveaxis(dZ, 0, -1)  # (k, 2n, M)
    return dZ[:, :n].copy(), dZ[:, n:].copy()


def supports_tangents(tracer: TracerState) -> bool:
    """Whether ``trace`` can carry ray differentials here: flat space, or a splitting on
    a split whose flows take derivatives (``SplitSystem.tangents``)."""
    if not tracer.curved:
        return True
    if not tracer.method.needs_split:
        return False
    split = tracer.model.split_parts(0.0)
    return split is not None and split.tangents


def check_tangents(tracer: TracerState) -> None:
    """ValueError naming why this trace cannot carry ray differentials, if it cannot."""
    if not supports_tangents(tracer):
        raise ValueError(
            "ray differentials (the magnification pass, point stars) need the rays "
            "carried by an explicit splitting on a split whose flows take derivatives: "
            "Schwarzschild, Kerr with |a| < M (their default methods) and flat space; "
            f"this scene's rays are integrated by {tracer.method!r} on "
            f"{type(tracer.model).__name__}"
        )

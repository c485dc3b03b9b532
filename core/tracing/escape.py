"""Rays outside the model's region: cast straight, and leaving it.

Interface (each takes the ``Tracer`` whose rays they are): ``straight`` (rays straight on
from a point: one cast each, hit or escaped), ``straight_to_region`` (rays from outside the
region to its boundary, or past it with their far-field direction), ``leave`` (rays that
left the region in a step: along their escape direction, or where a model without a mass
crosses its boundary: ``leave_at_boundary``), ``escape`` / ``escape_direction`` (the
direction a ray leaves along, with its derivatives) and ``far_field`` (the rest of a mass's
first-order deflection beyond the region).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from ..backend import placed
from ..integrators.batch import Batch
from .differentials import axial_final, directional, unit_directional
from .regions import BoxRegion
from .scene import ENDING
from .segments import RayResults
from .step_ends import StepEnds

if TYPE_CHECKING:
    from .tracer_state import TracerState

_FAR = 1e12  # length of the straight segment cast after a ray leaves the model's region


def straight(
    tracer: TracerState, rows: np.ndarray, a: np.ndarray, d: np.ndarray, out: RayResults,
    eye: np.ndarray | None = None,
) -> None:  # fmt: skip
    """Rays that stay straight from a along d: one cast each, ending hit or escaped
    (``eye``: where they are seen from, default a)."""
    h = tracer.geometry.record(rows, a, a + _FAR * d, out)
    _watch_to_hits(tracer, rows, a, a + _FAR * d, h, out, eye)
    out.ending[rows[~h]] = ENDING["escaped"]
    out.direction[rows] = d


def _watch_to_hits(
    tracer: TracerState, rows: np.ndarray, a: np.ndarray, b: np.ndarray, hit: np.ndarray,
    out: RayResults, eye: np.ndarray | None = None,
) -> None:  # fmt: skip
    """Record the straight segments a -> b of ``rows`` in their clearance, those that
    ``hit`` a surface only up to it (what lies behind a hit is not on the ray's path)."""
    if tracer._watch is None:
        return
    end = np.where(hit[:, None], out.position[rows], b)
    tracer._watch_segments(rows, a, end, out, eye)


def straight_to_region(
    tracer: TracerState, rows: np.ndarray, origins: np.ndarray, directions: np.ndarray,
    start: np.ndarray, out: RayResults, tangents: np.ndarray | None = None,
) -> None:  # fmt: skip
    """Rays starting outside the region: straight to its boundary (or forever); those
    that miss it get their far-field direction (and its derivatives along the
    ``tangents`` of ``directions``, if given)."""
    X_entry = start[rows]
    enters = np.isfinite(X_entry[:, 0])
    a = origins[rows]
    b = np.where(enters[:, None], tracer._to_world(X_entry), a + _FAR * directions[rows])
    h = tracer.geometry.record(rows, a, b, out)
    _watch_to_hits(tracer, rows, a, b, h, out)
    miss = ~h & ~enters
    if miss.any():
        X0 = tracer._to_local(a[miss])

        def far(d_world: np.ndarray) -> np.ndarray:
            R = placed(tracer.rotation, X0)
            return far_field(tracer.mass, X0, d_world @ R) @ R.T

        out.direction[rows[miss]] = far(directions[rows[miss]])
        out.ending[rows[miss]] = ENDING["escaped"]
        if tangents is not None:
            seen = tangents[rows[miss]]
            out.sky_jacobian[rows[miss]] = unit_directional(far, directions[rows[miss]], seen)


def leave(
    tracer: TracerState, batch: Batch, leaving: np.ndarray, X_prev: np.ndarray, X: np.ndarray,
    ends: StepEnds, out: RayResults,
) -> None:  # fmt: skip
    """The rays ``leaving`` ((M,) bool) left the region in this step (from X_prev to X,
    ``ends``): out along their escape direction (``escape``), or where a model without a
    mass crosses the sphere (``leave_at_boundary``)."""
    idx, camera = batch.arrays["idx"], ends.camera
    rest = leaving.copy()
    if cuts_at_boundary(tracer):
        rest &= ~leave_at_boundary(tracer, idx, np.flatnonzero(leaving), X_prev, X, ends, out)
    if rest.any():
        Q, P = ends.end
        shares = batch.arrays.get("axial")
        escape(
            tracer, idx[rest], Q[:, rest], P[:, rest], tracer._to_world(X[:, rest].T), out,
            tracer._to_world(camera[:, rest].T),
            [d[..., rest] for d in tracer.method.tangents_of(batch.state)],
            None if shares is None else shares[..., rest],
        )  # fmt: skip


def cuts_at_boundary(tracer: TracerState) -> bool:
    """Whether rays leave the region where they cross its boundary
    (``leave_at_boundary``): models without a mass (user metrics' spheres, media's
    boxes), whose field beyond the region no far field stands for."""
    return tracer.mass == 0.0


def leave_at_boundary(
    tracer: TracerState, idx: np.ndarray, cols: np.ndarray, X_prev: np.ndarray, X: np.ndarray,
    ends: StepEnds, out: RayResults,
) -> np.ndarray:  # fmt: skip
    """The rays of the batch rows ``cols``, past the region's boundary at this step's
    end, leave it where the method itself crosses it (``StepEnds.crossing``), along
    their velocity there, straight on. A model without a mass has no far field for the
    rest of its field: a ray leaving at its step's end took in the field up to there,
    which the step's size decided (benchmarks/honesty.py user_metric at 1 px: errors
    of 1e-3 px, erratic in the step, 3x above the estimate on 1.4 % of the pixels; a
    Maxwell fish-eye's box, where n is 0.62: first order in the step, and the run at
    twice the step, leaving at the same step end, estimated 1e-7 of it, issue 50); at
    the boundary every run leaves at the same place. A medium's ray leaving its box where
    its index jumps (``Medium.face_jump``) is failed (an unbounded medium's sphere is
    not its box: its rays go on straight there, as before). -> (M,) bool: the rows done (where
    the crossing did not converge the step's end stands: ``escape``)."""
    region = tracer.region
    assert region is not None
    done = np.zeros_like(X[0], dtype=bool)
    u = region.exit_time(X_prev[:, cols], X[:, cols] - X_prev[:, cols])
    crossing, ok, V = ends.crossing(
        cols, np.clip(np.nan_to_num(u, nan=1.0), 0.0, 1.0),
        lambda todo, Xt, Vt: region.exit_time(Xt, Vt) * Vt, with_velocity=True,
        strict=True,
    )  # fmt: skip
    ok &= np.isfinite(V).all(axis=0) & (np.linalg.norm(V, axis=0) > 0)
    if not ok.any():
        return done
    rows = cols[ok]
    bad = np.zeros_like(rows, dtype=bool)
    if isinstance(region, BoxRegion):  # a medium's box
        bad = tracer.model.face_jump(crossing[:, ok])
    if bad.any():  # an interface the medium's box cuts: no plausible colour
        out.ending[idx[rows[bad]]] = ENDING["failed"]
        out.position[idx[rows[bad]]] = tracer._to_world(crossing[:, ok][:, bad].T)
    go = ~bad
    D = (V[:, ok][:, go] / np.linalg.norm(V[:, ok][:, go], axis=0)).T @ placed(tracer.rotation, V).T
    world = tracer._to_world(crossing[:, ok][:, go].T)
    eye = tracer._to_world(ends.camera[:, rows[go]].T)
    straight(tracer, idx[rows[go]], world, D, out, eye)
    done[rows] = True
    return done


def escape(
    tracer: TracerState, rows: np.ndarray, Q: np.ndarray, P: np.ndarray, world: np.ndarray,
    out: RayResults, eye: np.ndarray, tangents: Sequence[np.ndarray] = (),
    shares: np.ndarray | None = None,
) -> None:  # fmt: skip
    """Rays leaving the region: direction from dq/ds, far-field correction, straight on
    (with ``tangents`` (dQ, dP) (k, n, M): the escape direction's derivatives too; with
    ``shares``, the traced tangent's expanded into the camera's k: axial_final)."""
    d_world = escape_direction(tracer, Q, P)
    straight(tracer, rows, world, d_world, out, eye)
    failed = ~np.isfinite(d_world).all(axis=1)
    out.ending[rows[failed]] = ENDING["failed"]
    if len(tangents) == 2:
        n = Q.shape[0]

        def direction(z: np.ndarray) -> np.ndarray:
            return escape_direction(tracer, z[:, :n].T.copy(), z[:, n:].T.copy())

        Z = np.concatenate([Q, P]).T
        dZ = np.moveaxis(np.concatenate(tangents, axis=1), -1, 0)  # (M, k, 2n)
        jacobian = directional(direction, Z, dZ)
        if shares is not None:  # the cameras' axes: eye - centre, in world axes
            axis = eye - placed(tracer.scene.center, eye)
            axis /= np.linalg.norm(axis, axis=1, keepdims=True)
            jacobian = axial_final(shares, jacobian, d_world, axis)
        sky = out.ending[rows] == ENDING["escaped"]
        out.sky_jacobian[rows[sky]] = jacobian[sky]


def escape_direction(tracer: TracerState, Q: np.ndarray, P: np.ndarray) -> np.ndarray:
    """Unit world directions (M, 3) rays leave the region along from (Q, P) (n, M): the
    velocity dX/dσ, bent by the rest of the far field (``far_field``)."""
    S = Q[tracer.chart.offset :]
    _, dHdp = tracer.model.gradient_soa(Q, P, wrt="p")
    V = tracer.chart.cartesian_velocity(S, dHdp[tracer.chart.offset :])
    D = (V / np.linalg.norm(V, axis=0)).T
    return far_field(tracer.mass, tracer.chart.to_cartesian(S).T, D) @ placed(tracer.rotation, D).T


def far_field(mass: float, X: np.ndarray, D: np.ndarray) -> np.ndarray:
    """Bend directions D (M, 3) at X by the rest of the first-order deflection of a mass
    ``mass`` (none where it is 0).

    A straight ray from X along D passes the mass M at impact b; it still turns by
    (2M/b)(1 - cos psi) towards the mass (cos psi = X.D/|X|, impulse approximation),
    i.e. by 2M b / (r (r + X.D)) (1 - cos psi = b^2 / (r (r + X.D))): written so, the
    turn (its angle times the unit vector towards the mass) is -2M perp / (r (r + X.D))
    with perp = X - (X.D) D, free of the cancellations of 1 - cos psi and of perp / b
    on rays leaving nearly radially.
    """
    if mass == 0.0:
        return D
    r = np.linalg.norm(X, axis=1)
    along = np.einsum("ij,ij->i", X, D)
    perp = X - along[:, None] * D  # from the ray's line to X, ⟂ D
    with np.errstate(all="ignore"):
        turn = (-2.0 * mass / (r * (r + along)))[:, None] * perp
    angle = np.linalg.norm(turn, axis=1)
    return np.cos(angle)[:, None] * D + np.sinc(angle / np.pi)[:, None] * turn

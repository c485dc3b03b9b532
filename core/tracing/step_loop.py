"""The step loop: rays integrated through the model's region, step by step.

Interface (each takes the ``Tracer`` whose rays they are): ``trace_curved`` (rays straight
to the region, then integrated through it), ``integrate`` (the batch loop over the rays
inside: core.integrators.batch.run_batch), ``step_events`` (after each step: failed, hit,
captured or left the region) and ``finish_energy`` (the ended rays' energy error).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from .. import integrators
from ..backend import array_module, placed
from ..integrators.batch import Batch, run_batch
from .crossings import along_paths
from .differentials import axial_tangents
from .escape import leave, straight_to_region
from .near_geometry import bent_steps, chord_turns, near_paths
from .scene import ENDING
from .segments import RayResults
from .starts import axial, start_state, start_tangents
from .step_ends import StepEnds
from .stepping import OFF_CONE, OFF_CONE_STEPS
from .watching import watch_step

if TYPE_CHECKING:
    from .tracer_state import TracerState


def trace_curved(
    tracer: TracerState, origins: np.ndarray, directions: np.ndarray,
    step: float | np.ndarray | None, cancel: Callable[[], bool] | None,
    tangents: np.ndarray | None, out: RayResults,
    clearance: np.ndarray | None = None,
) -> None:  # fmt: skip
    """Rays straight to the model's region, then integrated through it (``Tracer.trace``)."""
    assert tracer.region is not None
    xp = array_module(origins)
    X = tracer._to_local(origins)
    D = directions @ placed(tracer.rotation, directions)  # (N, 3) local components
    start, inside = tracer.region.entry(X, D)
    outside = np.flatnonzero(~inside)
    if outside.size:
        straight_to_region(tracer, outside, origins, directions, start, out, tangents)
    todo = np.flatnonzero(np.isfinite(start[:, 0]) & (out.ending < 0))
    h = tracer.step if step is None else step
    assert h is not None  # a curved scene's tracer has a step
    if todo.size:
        camera = tracer._to_local(origins[todo]).T  # (3, M): where each ray is seen from
        if np.ndim(h):
            h = xp.asarray(h, dtype=np.float64)[todo]
        local_tangents = None if tangents is None else tangents[todo] @ placed(tracer.rotation, D)
        watch = None if clearance is None else xp.asarray(clearance, np.float64)[todo]
        integrate(
            tracer, todo, start[todo].T.copy(), D[todo].T.copy(), out, h, cancel, camera,
            local_tangents, watch,
        )  # fmt: skip


def integrate(
    tracer: TracerState, rows: np.ndarray, X: np.ndarray, D: np.ndarray, out: RayResults,
    h: float | np.ndarray, cancel: Callable[[], bool] | None, camera: np.ndarray,
    tangents: np.ndarray | None = None, watch: np.ndarray | None = None,
) -> None:  # fmt: skip
    """Follow rays from local positions X (3, M) along local directions D (3, M) (with
    ``tangents`` (M, k, 3): the directions' derivatives, carried along; ``watch`` (M,)
    each ray's share of the margin its clearance is recorded within, default all).

    Per step, everything is done in the model's local frame on (3, M) arrays; world
    coordinates are computed only for the rays that need them: segments near geometry
    (a local box around the objects and volumes), and rays that end.
    """
    model, xp = tracer.model, array_module(X)
    Q, P = start_state(tracer, X, D)
    H0 = model.value_soa(Q, P)
    K = model.split_parts(H0) or integrators.PoincareTransformed(model, H0)
    state = tracer.method.init(K, Q, P)
    shares = None
    if tangents is not None:
        if axial(tracer):  # one tangent traced, the other by symmetry
            shares, tangents = axial_tangents(camera.T, D.T, tangents)
        dQ, dP = start_tangents(tracer, camera, D, tangents, Q.shape[0])
        state = tracer.method.with_tangents(K, state, dQ, dP)
    batch = Batch(
        tracer.method,
        state,
        {"K": K},
        {"idx": rows.copy(), "X": X, "camera": camera, "H0": H0,
         "h": xp.broadcast_to(xp.asarray(h, dtype=np.float64), rows.shape).copy(),
         "h0": xp.broadcast_to(xp.asarray(h, dtype=np.float64), rows.shape).copy(),
         "heading": D / np.linalg.norm(D, axis=0),  # the last chord's direction
         "streak": xp.zeros(rows.size, dtype=np.int64),  # steps in a row off the cone
         "watch": xp.ones(rows.size) if watch is None else watch,
         "kinks": xp.zeros(rows.size, dtype=np.int64)},  # the model's kinks crossed
    )  # fmt: skip
    if shares is not None:
        batch.arrays["axial"] = shares

    def step(batch: Batch):
        assert tracer.stepper is not None  # a curved scene's tracer has one
        K, h = batch.systems["K"], batch.arrays["h"]
        state, ok, shell, crossings = tracer.stepper.advance(K, batch.state, h)
        batch.arrays["kinks"] |= crossings
        return state, ok, shell

    def events(batch: Batch, taken: int, start, ok, shell) -> np.ndarray:
        return step_events(tracer, batch, taken, start, ok, shell, out)

    taken = run_batch(batch, step, events, tracer.options.max_steps, cancel)
    if batch.size == 0:
        return
    idx, X_last = batch.arrays["idx"], batch.arrays["X"]
    out.ending[idx] = ENDING["max_steps"]
    out.steps[idx] = taken
    out.kinks[idx] = batch.arrays["kinks"]
    Q, P = tracer.method.qp(batch.state)
    out.position[idx] = tracer._to_world(X_last.T)
    finish_energy(tracer, out, idx, Q, P, batch.arrays["H0"])


def step_events(
    tracer: TracerState, batch: Batch, taken: int, start: Any, ok: np.ndarray, shell: np.ndarray,
    out: RayResults,
) -> np.ndarray:  # fmt: skip
    """After a step: which rays failed, hit something, were captured or left the
    region ((M,) bool), each recorded in ``out``; the batch's X becomes the step's end."""
    chart, arrays = tracer.chart, batch.arrays
    idx, X_prev, camera = arrays["idx"], arrays["X"], arrays["camera"]
    raw_start, start = start, tracer.method.qp(start)
    Q, P = tracer.method.qp(batch.state)
    if tracer.spacetime:
        with np.errstate(invalid="ignore"):
            streak = np.where(shell > OFF_CONE * P[0] * P[0], arrays["streak"] + 1, 0)
        arrays["streak"] = streak
        ok &= streak < OFF_CONE_STEPS
    S = Q[chart.offset :]
    X = chart.to_cartesian(S)
    ok &= np.isfinite(X).all(axis=0)
    ended = ~ok
    if not ok.all():
        out.ending[idx[ended]] = ENDING["failed"]
        out.position[idx[ended]] = tracer._to_world(X_prev[:, ended].T)
    paths, going = None, ok
    h_taken = arrays["h"].copy()  # the step taken (a copy: bent_steps sets the next one)
    if tracer._near is not None:  # surfaces and volumes along this step's segment
        step_ends = StepEnds(tracer, batch.systems["K"], start, (Q, P), h_taken, camera)
        chord, turn = chord_turns(X_prev, X, arrays["heading"])
        paths = near_paths(tracer, X_prev, X, ok, step_ends, camera, turn, arrays["h0"])
        redo = bent_steps(tracer, paths, chord, turn, ok, arrays)
        if redo.any():  # back to the step's start, at half the step
            batch.state = tuple(
                np.where(redo, a, b) for a, b in zip(raw_start, batch.state, strict=True)
            )
            Q, P = tracer.method.qp(batch.state)
            S, X = Q[chart.offset :], np.where(redo, X_prev, X)
            paths, going = paths.without(redo), ok & ~redo
    until = array_module(X).ones(X.shape[1])  # the share of the step each ray travels (to its hit)
    if paths is not None:
        ended |= along_paths(tracer, idx, paths, out, step_ends, until)
    if tracer._watch is not None:  # the steps within the margin of the objects' box
        watch_step(tracer, idx, X_prev, X, camera, paths, arrays["watch"], out, until)
    if tracer.captured is not None:
        captured = ~ended & going & tracer.captured(Q, P)
        if captured.any():
            out.ending[idx[captured]] = ENDING["captured"]
            out.position[idx[captured]] = tracer._to_world(X[:, captured].T)
            ended |= captured
    assert tracer.region is not None
    leaving = ~ended & going & tracer.region.left_soa(X, X_prev)
    if leaving.any():
        ends = StepEnds(tracer, batch.systems["K"], start, (Q, P), h_taken, camera)
        leave(tracer, batch, leaving, X_prev, X, ends, out)
        ended |= leaving
    if ended.any():
        out.steps[idx[ended]] = taken
        out.kinks[idx[ended]] = arrays["kinks"][ended]
        finish_energy(tracer, out, idx[ended], Q[:, ended], P[:, ended], arrays["H0"][ended])
    arrays["X"] = X
    return ended


def finish_energy(
    tracer: TracerState, out: RayResults, rows: np.ndarray, Q: np.ndarray, P: np.ndarray,
    H0: np.ndarray,
) -> None:  # fmt: skip
    """Each ended ray's energy error |H(Q, P) - H0| (``RayResults.energy_error``)."""
    with np.errstate(all="ignore"):
        out.energy_error[rows] = np.abs(tracer.model.value_soa(Q, P) - H0)

"""Steps near the scene's geometry: which steps' paths may pass it, and which are halved.

Interface: ``near_paths(tracer, ...)`` (the steps whose path may pass the geometry's box,
or an object's own, with their cubic paths' deviations and allowances: ``NearPaths``),
``bent_steps(tracer, ...)`` (those to take again at half the step: turning, bending or
changing pace past BEND_LIMIT, PACE_LIMIT, TURN_LIMIT; MAX_HALVINGS deep),
``allowance_scale`` (the chords' allowance on a run below the rule's step) and
``chord_turns`` (a step's chords and their turn from the ray's heading). CHORD_SHARE bounds
how closely their chords follow them (which boxes a step is near: tracer_state.NEAR_BOXES).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING, Any

import numpy as np

from ..backend import array_module, to_host
from ..geometry import segment_overlaps
from . import dense
from .step_ends import StepEnds

if TYPE_CHECKING:
    from .tracer_state import TracerState

BEND_LIMIT = 64.0
"""A step near geometry whose cubic path deviates from its chord by more than BEND_LIMIT
chord allowances is taken again at half the step (bent_steps): hits are found on
the cubic, and a long step whose bend is not a cubic's (far from a small hole, where the
steps grow with r and the bending happened near one end) misplaced them by pixels while
the step-doubling estimate, one step either way, saw nothing."""
PACE_LIMIT = 2.0
"""With geometry, a step whose end speeds (in the fictitious time: a ray's pace there
changes as r does) differ by more than this factor is taken again at half the step
(bent_steps): it spans a stretch of the path as long as its distance from the
hole, whose bending (~1/r^2) the cubic through its ends does not follow. (The bend limit
once counted the change of pace as a bend: 17 % of a Kerr board frame's steps were taken
again for it; without any limit on the pace, hits on spheres 400 rg behind a hole were
0.3-0.5 px off at 0.05 px with both runs agreeing, benchmarks/honesty.py far_small.)"""
TURN_LIMIT = 0.1
"""With geometry, a step whose chord turns from the ray's heading by more than this
(radians) is taken again at half the step (bent_steps)."""
MAX_HALVINGS = 10
"""At most this many halvings of a ray's step (1/1024 of the rule's)."""
CHORD_SHARE = 0.5
"""Chords near geometry stay within CHORD_SHARE x tolerance x (distance from the camera) of
the ray's cubic path: half the tolerance, as the integration gets (core/tracing/steps.py)."""


@dataclass
class NearPaths:
    """Steps near geometry (near_paths): their rows in the batch, local ends and
    velocities (3, K), step sizes, cubic deviations from the chords and allowances (K,)."""

    rows: np.ndarray
    X0: np.ndarray
    X1: np.ndarray
    V0: np.ndarray
    V1: np.ndarray
    h: Any
    deviation: np.ndarray
    allowed: np.ndarray

    def without(self, rows: np.ndarray) -> NearPaths:
        """These paths less those of the batch rows ``rows`` ((M,) bool)."""
        keep = ~rows[self.rows]
        h = self.h if np.ndim(self.h) == 0 else self.h[keep]
        return NearPaths(
            self.rows[keep], self.X0[:, keep], self.X1[:, keep], self.V0[:, keep],
            self.V1[:, keep], h, self.deviation[keep], self.allowed[keep],
        )  # fmt: skip

    @cached_property
    def pieces(self) -> np.ndarray:
        """(K,) chords the hit test casts per step (dense.pieces), shared by the hit test
        (crossings.along_paths) and the clearance's slack (clearance.bends)."""
        return dense.pieces(self.deviation, self.allowed)


def near_paths(
    tracer: TracerState, X_prev: np.ndarray, X: np.ndarray, ok: np.ndarray, step_ends: StepEnds,
    camera: np.ndarray, turn: np.ndarray, h0: np.ndarray,
) -> NearPaths:  # fmt: skip
    """The steps whose path X_prev -> X may pass the geometry's box, and one object's
    own box where there are not too many (``TracerState._near_boxes``, ``_near_many``)
    (their chord's bounds widened by how
    far a path turning by ``turn`` from its heading can stray from it) and may leave
    the ball around the hole that holds no geometry (with an
    accretion disk: ``TracerState._clear``; a path from X_prev to X stays within the larger |X|
    plus its stray; a camera inside that ball keeps its rays' steps checked: halved
    where they turn, which near the camera keeps the error pass's estimate honest:
    where a ball reached past the camera, benchmarks/honesty.py near_tangent, it
    under-reported 3x on 2.2 % of the pixels instead of 0.4 %), with their ends'
    velocities, their cubics' deviation from the chord and the deviation the chords may
    keep at their distance from the camera (core/tracing/dense.py)."""
    assert tracer._near is not None
    stray = np.linalg.norm(X - X_prev, axis=0) * np.sin(np.minimum(turn, 0.5 * np.pi))
    near = ok.copy()
    if tracer._clear > 0.0:
        out = np.maximum(np.linalg.norm(X_prev, axis=0), np.linalg.norm(X, axis=0)) + stray
        near &= (out >= tracer._clear) | (np.linalg.norm(camera, axis=0) <= tracer._clear)
    low = np.minimum(X_prev, X) - stray
    high = np.maximum(X_prev, X) + stray
    near &= segment_overlaps(low.T, high.T, *tracer._near)  # their bounds, as boxes
    if tracer._near_boxes is not None and near.any():  # each object's own box
        rows = np.flatnonzero(near)
        any_box = np.zeros_like(rows, dtype=bool)
        for lo, hi in tracer._near_boxes:
            any_box |= segment_overlaps(low[:, rows].T, high[:, rows].T, lo, hi)
        near[rows[~any_box]] = False
    if tracer._near_many is not None and near.any():  # many objects' own boxes, at once
        rows = np.flatnonzero(near)  # (on the host, as the objects' hit tests: Segments.cast)
        meets = tracer._near_many.meets(to_host(low[:, rows]), to_host(high[:, rows]))
        near[rows[~array_module(near).asarray(meets)]] = False
    c = np.flatnonzero(near)
    X0, X1 = X_prev[:, c], X[:, c]
    if c.size == 0:  # none: no velocities to evaluate (a model's gradient, ~100 calls)
        h = step_ends.h if np.ndim(step_ends.h) == 0 else step_ends.h[c]
        return NearPaths(c, X0, X1, X0.copy(), X1.copy(), h, X0[0].copy(), X0[0].copy())
    V0, V1, h = step_ends.velocities(c)
    allowed = CHORD_SHARE * tracer.options.tolerance * np.linalg.norm(X0 - camera[:, c], axis=0)
    allowed = allowed * allowance_scale(tracer, h0[c])
    return NearPaths(c, X0, X1, V0, V1, h, dense.chord_deviation(X0, X1, V0, V1, h), allowed)


def allowance_scale(tracer: TracerState, h0: np.ndarray) -> np.ndarray | float:
    """(K,) what the chords' allowance is scaled by on a run at a step below the rule's
    (a retrace, core.sampling): (h0 / step)^order, as its integration error is; 1 at
    the rule's step and above (the error pass's companion). A near miss traced again
    at half the step then has its hit test's slack fall with its error: at the rule's
    allowance a ray passing within it of an edge stayed near, and wrong, whatever the
    step (benchmarks/honesty.py thin_front: strips 0.07 rg wide missed after three
    retraces by rays the reference sees hit)."""
    if tracer.options.step is not None or tracer.method.adaptive or not tracer.order:
        return 1.0
    return np.minimum(h0 / tracer.step, 1.0) ** tracer.order


def bent_steps(
    tracer: TracerState, paths: NearPaths, chord: np.ndarray, turn: np.ndarray, ok: np.ndarray,
    arrays: dict[str, Any],
) -> np.ndarray:  # fmt: skip
    """(M,) the steps near geometry to take again at half the step (down to
    2^-MAX_HALVINGS of the rule's): those whose chord turns from the ray's heading (its
    last chord's direction, ``turn``) by more than TURN_LIMIT, or whose cubic path
    deviates from its chord by more than BEND_LIMIT chord allowances, or whose pace
    changes by more than PACE_LIMIT over it. Hits are found on the cubic through a
    step's ends; a step in the Poincaré time covers a distance ~ r / M, so far from a
    small hole one step can jump past it (or back out of the region), and the cubic is
    then no path at all. A ray's step grows back (doubling) after a step at which twice
    the step would stay within all three (the bend grows 4x with it, the pace's log 2x;
    the turn is given 4x); its heading follows its accepted chords. A run at another
    step than the rule's (the error pass's companion, a retrace) has its limits scaled
    with it (the turn and the pace's log as the step, the bend as its square), so near
    geometry its steps stay in the ratio of its start's: two runs halved to the same
    steps there would agree on an error they share, and Richardson would see none.
    None with an explicit ``TraceOptions.step`` (step studies) or an adaptive method
    (its own control)."""
    h, h0, heading = arrays["h"], arrays["h0"], arrays["heading"]
    if tracer.options.step is not None or tracer.method.adaptive:
        return np.zeros_like(h, dtype=bool)  # a step given is taken as given; dopri5
    near = np.zeros_like(h, dtype=bool)
    near[paths.rows] = True
    scale = h0 / tracer.step  # a run at r x the rule's step keeps r x its steps here
    turn_limit, bend_limit = TURN_LIMIT * scale, BEND_LIMIT * scale[paths.rows] ** 2
    bent = near & (turn > turn_limit)
    allowed = paths.allowed / allowance_scale(tracer, h0[paths.rows])  # the rule's
    bent[paths.rows] |= paths.deviation > bend_limit * allowed
    with np.errstate(divide="ignore", invalid="ignore"):  # ln of the end speeds' ratio
        pace = np.abs(np.log(np.linalg.norm(paths.V1, axis=0) / np.linalg.norm(paths.V0, axis=0)))
    pace_limit = math.log(PACE_LIMIT) * scale[paths.rows]
    bent[paths.rows] |= pace > pace_limit
    close = near & (turn > 0.25 * turn_limit)
    close[paths.rows] |= (paths.deviation > 0.25 * bend_limit * allowed) | (pace > 0.5 * pace_limit)
    redo = ok & bent & (h > h0 * 0.5**MAX_HALVINGS)
    h[redo] *= 0.5
    grow = ok & ~redo & ~close & (h < h0)
    h[grow] = np.minimum(2.0 * h[grow], h0[grow])
    taken = ok & ~redo & np.isfinite(chord).all(axis=0)
    heading[:, taken] = chord[:, taken]
    return redo


def chord_turns(
    X_prev: np.ndarray, X: np.ndarray, heading: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(unit chords X_prev -> X (3, M), their angles from ``heading`` (M,); 0 where not
    finite)."""
    with np.errstate(all="ignore"):
        chord = (X - X_prev) / np.linalg.norm(X - X_prev, axis=0)
        turn = np.arccos(np.clip(np.einsum("im,im->m", chord, heading), -1.0, 1.0))
    return chord, np.where(np.isfinite(turn), turn, 0.0)

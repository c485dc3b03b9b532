"""A step's two ends, and where within the step the method's own path meets a surface.

Interface: ``StepEnds(tracer, K, start, end, h, camera)``: ``state(rows)`` (Q, P, camera
at the step's end: the disk's light), ``velocities(rows)`` (the local Cartesian velocities
dX/dσ at both ends and the step: the cubic path), ``crossing(rows, u, offset)`` (Newton's
method on the fraction of the step, by the method's own partial steps, to where ``offset``
says a surface lies) and ``plane_crossing(rows, u)`` (the same to the plane z = 0: the
disk). CROSSING_SHARE, CROSSING_ITERATIONS and CROSSING_REACH bound its Newton steps.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from ..backend import array_module

if TYPE_CHECKING:
    from .tracer_state import TracerState

CROSSING_SHARE, CROSSING_ITERATIONS = 1e-3, 4
"""The disk's crossing is found to |z| <= CROSSING_SHARE x tolerance x |X| (a share of the
integration's own error there) in at most CROSSING_ITERATIONS Newton steps."""
CROSSING_REACH = 1.0
"""A crossing's last Newton step is taken along the velocity instead of by the method
(one partial step fewer: each costs a whole step's per-call overhead, ~45 % of a disk
scene's time before) where it moves the point by at most CROSSING_REACH x sqrt(allowed
share) x |X|: a light ray's path outside a horizon bends with a radius of at least ~|X|/2
(Schwarzschild: curvature <= 3M/r^2, r > 2M), so the straight step is then off by at
most CROSSING_REACH^2 x the allowance (|X| x the share, what a point found by the
method may miss the plane by). At 0.1 (before) 88 % of crossings took a second partial
step; at 1, ~40 % (the first step's move, over sqrt(share) |X|: median 0.56, p90 3.4,
the Kerr-with-disk preset)."""


class StepEnds:
    """A step's two ends (Q, P) and size, with the local Cartesian velocities dX/dσ there
    for the rays that need them (surfaces near their path)."""

    def __init__(
        self, tracer: TracerState, K: Any, start: tuple, end: tuple, h: Any, camera: np.ndarray
    ) -> None:
        self.tracer, self.K, self.start, self.end, self.h = tracer, K, start, end, h
        self.camera = camera

    def state(self, rows: np.ndarray) -> list[np.ndarray]:
        """(Q, P, camera) at the step's end of the rays ``rows`` (the disk's light)."""
        Q, P = self.end
        return [Q[:, rows], P[:, rows], self.camera[:, rows]]

    def velocities(self, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, Any]:
        """(V at the start, V at the end, h) of the rays ``rows``, each V (3, M)."""
        both = np.concatenate([rows, rows])  # one call for both ends: one call's overhead
        Q, P = (np.concatenate([a[:, rows], b[:, rows]], axis=1)
                for a, b in zip(self.start, self.end, strict=True))  # fmt: skip
        V = self._velocity(self.K.subset(both), Q, P)
        h = self.h if np.ndim(self.h) == 0 else self.h[rows]
        return V[:, : rows.size], V[:, rows.size :], h

    def plane_crossing(self, rows: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Where the rays ``rows`` cross the local plane z = 0 within this step (``crossing``
        from the cubic's estimate u): -> (X (3, M), ok (M,)); not ok where it did not
        converge inside the step (the cubic's point stands). The disk's g depends on where
        the ray crosses it, which the cubic only finds to O(h^4) (long split steps)."""

        def to_plane(todo, X, V):
            with np.errstate(all="ignore"):
                return -(X[2] / V[2]) * V

        return self.crossing(rows, u, to_plane)

    def crossing(
        self, rows: np.ndarray, u: np.ndarray, offset, with_velocity: bool = False,
        strict: bool = False,
    ):  # fmt: skip
        """Newton's method on the fraction u of this step where the rays ``rows`` meet a
        surface: X(u) by the method's own partial step from the step's start, then
        ``offset(todo, X, V)`` -> the straight move (3, M) along the velocity V from X to the
        surface (NaN: none), u moved by its length. -> (X + move (3, M), ok (M,)): ok once
        the move is at most CROSSING_REACH sqrt(share) |X| (or |X| share) with u inside the
        step, within CROSSING_ITERATIONS; a straight move that short is off the path by
        at most CROSSING_REACH^2 share |X| (share = CROSSING_SHARE x tolerance). With
        ``with_velocity``, also V (3, M) there; ``strict``: ok only once the move is at most
        share |X| (V turns over a longer move by more than the tolerance allows)."""
        K = self.K.subset(rows)
        Q0, P0 = (x[:, rows] for x in self.start)
        h = self.h if np.ndim(self.h) == 0 else self.h[rows]
        xp = array_module(rows)
        u = xp.asarray(u, dtype=np.float64).copy()
        X = xp.full((3, rows.size), np.nan)
        velocity = xp.full((3, rows.size), np.nan)
        ok = xp.zeros(rows.size, dtype=bool)
        share = CROSSING_SHARE * self.tracer.options.tolerance
        reach = 0.0 if strict else CROSSING_REACH * math.sqrt(share)
        todo = xp.arange(rows.size)  # the rays not yet there
        with np.errstate(all="ignore"):
            for _ in range(CROSSING_ITERATIONS):
                Kt = K.subset(todo) if todo.size < rows.size else K
                ht = h if np.ndim(h) == 0 else h[todo]
                Xt, V, good = self._partial(Kt, Q0[:, todo], P0[:, todo], u[todo] * ht)
                move = offset(todo, Xt, V)
                finite = good & np.isfinite(move).all(axis=0)
                du = np.einsum("im,im->m", move, V) / (ht * np.einsum("im,im->m", V, V))
                size, length = np.linalg.norm(Xt, axis=0), np.linalg.norm(move, axis=0)
                inside = (u[todo] + du >= 0.0) & (u[todo] + du <= 1.0)
                there = finite & ((length <= share * size) | (inside & (length <= reach * size)))
                X[:, todo], ok[todo], velocity[:, todo] = Xt + move, there, V
                left = ~there
                u[todo[left]] = np.clip(u[todo[left]] + np.where(finite, du, 0.0)[left], 0, 1)
                todo = todo[left]
                if todo.size == 0:
                    break
        return (X, ok, velocity) if with_velocity else (X, ok)

    def _partial(self, K: Any, Q0: np.ndarray, P0: np.ndarray, step) -> tuple:
        method, chart = self.tracer.method, self.tracer.chart
        state, good = method.step(K, method.init(K, Q0.copy(), P0.copy()), step)
        Q, P = method.qp(state)
        return chart.to_cartesian(Q[chart.offset :]), self._velocity(K, Q, P), good

    def _velocity(self, K: Any, Q: np.ndarray, P: np.ndarray) -> np.ndarray:
        chart = self.tracer.chart
        _, dp = K.gradient_soa(Q, P, wrt="p")
        with np.errstate(all="ignore"):
            return chart.cartesian_velocity(Q[chart.offset :], dp[chart.offset :])

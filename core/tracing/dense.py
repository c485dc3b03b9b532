"""Between two steps: the ray's path as a cubic, and how many chords follow it closely.

A step gives the ray's positions X0, X1 and velocities V0, V1 (dX/dσ, local Cartesian) at
its two ends. The cubic Hermite interpolant through them,

    X(t) = (2t³ − 3t² + 1) X0 + (t³ − 2t² + t) h V0 + (3t² − 2t³) X1 + (t³ − t²) h V1,

follows the ray to O(h⁴) (the order of the 4th-order methods), where the straight chord
X0 → X1 is off by second order: by the velocities' parts across it (chord_deviation;
along it the cubic only runs at another pace, as the ray's speed in the fictitious time
changes with r, and a chord's hit is placed where the cubic reaches it: on_cubic).
Surfaces are found on k chords
through points of the cubic, k chosen per ray so that each chord's own deviation, about
that over k², stays below what the tolerance allows at the ray's distance from the camera.
The hit found there is then moved to where the method's own partial step meets the surface
(core/tracing/crossings.py, surface_crossing): the cubic's error constant (1/384) is far
above a symplectic method's, and varies with where in the step the surface falls.
"""

from __future__ import annotations

import math

import numpy as np

from ..backend import array_module

MAX_PIECES = 16
"""At most this many chords per step to look for surfaces (the deviation shrinks 256-fold)."""
REFINE_PIECES, REFINE_LEVELS = 16, 1
"""A chord that hits a surface is cut again into REFINE_PIECES chords on the cubic, up to
REFINE_LEVELS times while they still deviate more than HIT_SHARE x allowed: the hit is then
found on the cubic to within 1/256 of the chord's deviation, for the rays that end there
only, and moved from there to where the method's own path meets the surface
(crossings.surface_crossing, whose first Newton step it is well within). A second level
(1/65536) changed no figure of benchmarks/honesty.py, no colour of the Kerr board's frames
and their error estimates by under 1e-4 of themselves, for 5 % of a Final frame's time
there; none (the chord's own hit as the crossing's start) put 24 pixels of mirage_grazing's
grazing ground over 3x the tolerance at 0.25 px."""
HIT_SHARE = 1e-3
"""A hit point is refined while its chord deviates from the cubic by more than HIT_SHARE x
the chords' allowance: the chord's part of a hit point's error is then small next to the
cubic's, and the refined point is a close start for the method's own crossing (step
doubling cannot see a chord error bounded by the tolerance: both runs share it; measured on
the Kerr board scene at 0.25 px: hit errors under-reported ~10x before)."""


def hermite(X0: np.ndarray, V0: np.ndarray, X1: np.ndarray, V1: np.ndarray, h, t) -> np.ndarray:
    """The cubic Hermite interpolant at t in [0, 1] (each array (3, M); h and t a float or
    per ray (M,))."""
    t2, t3 = t * t, t * t * t
    return (
        (2 * t3 - 3 * t2 + 1) * X0
        + (t3 - 2 * t2 + t) * h * V0
        + (3 * t2 - 2 * t3) * X1
        + (t3 - t2) * h * V1
    )


class CubicPath:
    """The cubic Hermite path of M rays' steps (see the module); points by (t, rays)."""

    def __init__(self, X0: np.ndarray, V0: np.ndarray, X1: np.ndarray, V1: np.ndarray, h):
        self.X0, self.V0, self.X1, self.V1 = X0, V0, X1, V1
        xp = array_module(X0)
        self.h = xp.broadcast_to(xp.asarray(h, dtype=np.float64), X0.shape[1:])

    @property
    def size(self) -> int:
        """Number of rays."""
        return self.X0.shape[1]

    def at(self, t, rays: np.ndarray) -> np.ndarray:
        """Points (3, len(rays)) at t (a float or per ray) of the rays ``rays``."""
        return hermite(self.X0[:, rays], self.V0[:, rays], self.X1[:, rays],
                       self.V1[:, rays], self.h[rays], t)  # fmt: skip

    def points(self, ts: np.ndarray, rays: np.ndarray) -> np.ndarray:
        """Points (3, T, len(rays)) of the rays ``rays`` at T parameters each: ``ts`` (T,)
        shared, or (T, len(rays)) per ray (each ray's ends gathered once)."""
        ts = array_module(self.X0).asarray(ts, dtype=np.float64)
        return hermite(self.X0[:, None, rays], self.V0[:, None, rays], self.X1[:, None, rays],
                       self.V1[:, None, rays], self.h[rays],
                       ts[:, None] if ts.ndim == 1 else ts)  # fmt: skip


NEWTON_STEPS = 8
"""on_cubic's Newton steps on its cubic polynomial (from the chord's own fraction)."""


def on_cubic(path: CubicPath, rays: np.ndarray, t0, width: float, fraction) -> np.ndarray:
    """(K,) the cubic's parameters in [t0, t0 + width] (t0 per ray or shared) at which the
    rays' paths reach ``fraction`` of the chord X(t0) -> X(t0 + width), measured along it:
    where a chord's hit lies on the cubic, which runs along its chord at another pace (a
    ray's speed in the fictitious time changes as r does). Newton's method (NEWTON_STEPS)
    on that measure, a cubic polynomial in t, from the chord's own fraction, kept inside
    the chord's stretch; where the cubic turns back along its chord, the chord's fraction."""
    X0, X1 = path.X0[:, rays], path.X1[:, rays]
    hV0, hV1 = path.h[rays] * path.V0[:, rays], path.h[rays] * path.V1[:, rays]
    # X(t) = X0 + B t + C t^2 + D t^3 (the Hermite basis of the module's docstring)
    B, C, D = hV0, 3.0 * (X1 - X0) - 2.0 * hV0 - hV1, 2.0 * (X0 - X1) + hV0 + hV1
    xp = array_module(X0)
    lo = xp.broadcast_to(xp.asarray(t0, dtype=np.float64), rays.shape)
    hi = lo + width
    a = hermite(X0, hV0, X1, hV1, 1.0, lo)
    chord = hermite(X0, hV0, X1, hV1, 1.0, hi) - a
    with np.errstate(divide="ignore", invalid="ignore"):
        d = chord / np.einsum("im,im->m", chord, chord)  # along(t) = (X(t) - a) . d
        b, c, e = (np.einsum("im,im->m", v, d) for v in (B, C, D))
        start = lo + xp.asarray(fraction) * width
        t = start.copy()
        target = xp.asarray(fraction) + np.einsum("im,im->m", a - X0, d)
        for _ in range(NEWTON_STEPS):
            slope = b + t * (2.0 * c + 3.0 * e * t)
            t = np.clip(t - (t * (b + t * (c + e * t)) - target) / slope, lo, hi)
        forward = (b + lo * (2.0 * c + 3.0 * e * lo) > 0) & (b + hi * (2.0 * c + 3.0 * e * hi) > 0)
    return np.where(forward & np.isfinite(t), t, start)


def chord_deviation(
    X0: np.ndarray, X1: np.ndarray, V0: np.ndarray, V1: np.ndarray, h
) -> np.ndarray:
    """(M,) a bound on the distance between the cubic and the line of its chord X0 -> X1.
    With p0, p1 the parts of h V0, h V1 across the chord, the cubic is off that line by
    t (1 - t) ((1 - t) p0 - t p1): at most |p0 - p1| / 8 (|h (V0 - V1)| / 8 where the
    velocities turn symmetrically, a circle's arc) + |p0 + p1| / (12 sqrt 3). Along the
    chord the cubic only moves at another pace, which no chord cut from it misses (a ray's
    speed in the fictitious time changes over a step as r does: |h (V0 - V1)| / 8, which
    counted that too, was a median 70x this bound on the Kerr board's steps near its board,
    and chose chords, halved steps and widened slacks by it). A chord of length 0 (or not
    finite) keeps |h (V0 - V1)| / 8."""
    chord = X1 - X0
    with np.errstate(divide="ignore", invalid="ignore"):
        unit = chord / np.linalg.norm(chord, axis=0)
        hv0, hv1 = h * V0, h * V1
        p0 = hv0 - np.einsum("im,im->m", hv0, unit) * unit
        p1 = hv1 - np.einsum("im,im->m", hv1, unit) * unit
        d = np.linalg.norm(p0 - p1, axis=0) / 8.0
        d += np.linalg.norm(p0 + p1, axis=0) / (12.0 * math.sqrt(3.0))
        whole = np.linalg.norm(V0 - V1, axis=0) * (np.abs(h) / 8.0)
    d = np.where(np.isfinite(d), d, whole)
    return np.where(np.isfinite(d), d, 0.0)


def pieces(deviation: np.ndarray, allowed: np.ndarray) -> np.ndarray:
    """(M,) chords per step: the power of two k <= MAX_PIECES with deviation / k² <= allowed."""
    with np.errstate(divide="ignore", invalid="ignore"):
        need = np.sqrt(deviation / allowed)
    k = np.ones_like(deviation, dtype=np.int64)
    while True:
        more = (k < need) & (k < MAX_PIECES)
        if not more.any():
            return k
        k[more] *= 2

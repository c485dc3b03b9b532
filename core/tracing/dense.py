"""Between two steps: the ray's path as a cubic, and how many chords follow it closely.

A step gives the ray's positions X0, X1 and velocities V0, V1 (dX/dσ, local Cartesian) at
its two ends. The cubic Hermite interpolant through them,

    X(t) = (2t³ − 3t² + 1) X0 + (t³ − 2t² + t) h V0 + (3t² − 2t³) X1 + (t³ − t²) h V1,

follows the ray to O(h⁴) (the order of the 4th-order methods), where the straight chord
X0 → X1 is off by up to |h (V0 − V1)| / 8 (second order). Surfaces are found on k chords
through points of the cubic, k chosen per ray so that each chord's own deviation, about
that over k², stays below what the tolerance allows at the ray's distance from the camera.
"""

from __future__ import annotations

import numpy as np

MAX_PIECES = 16
"""At most this many chords per step (the deviation then shrinks 256-fold)."""


def hermite(
    X0: np.ndarray, V0: np.ndarray, X1: np.ndarray, V1: np.ndarray, h, t: float
) -> np.ndarray:
    """The cubic Hermite interpolant at t in [0, 1] (each array (3, M); h float or (M,))."""
    t2, t3 = t * t, t * t * t
    return (
        (2 * t3 - 3 * t2 + 1) * X0
        + (t3 - 2 * t2 + t) * h * V0
        + (3 * t2 - 2 * t3) * X1
        + (t3 - t2) * h * V1
    )


def chord_deviation(V0: np.ndarray, V1: np.ndarray, h) -> np.ndarray:
    """(M,) largest distance between the cubic and the chord X0 -> X1: |h (V0 − V1)| / 8."""
    d = np.linalg.norm(V0 - V1, axis=0) * (np.abs(h) / 8.0)
    return np.where(np.isfinite(d), d, 0.0)


def pieces(deviation: np.ndarray, allowed: np.ndarray) -> np.ndarray:
    """(M,) chords per step: the power of two k <= MAX_PIECES with deviation / k² <= allowed."""
    with np.errstate(divide="ignore", invalid="ignore"):
        need = np.sqrt(deviation / allowed)
    k = np.ones(deviation.shape, dtype=np.int64)
    while True:
        more = (k < need) & (k < MAX_PIECES)
        if not more.any():
            return k
        k[more] *= 2

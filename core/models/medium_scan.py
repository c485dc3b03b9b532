"""Poles of a medium's refractive index inside its box, found before any ray is traced.

A pole of n (n -> infinity; the Add › Medium default once had one at z = -0.87 in its
±10 box) makes rays near it fail or crawl, silently. ``index_pole`` samples 1/n on a grid
of lines along each axis, brackets every local minimum of |1/n| along a line (the sample
nearest a pole is one; a line's ends count), and narrows each bracket by golden-section
search, all brackets at once. A pole is where |1/n| falls below ``POLE_RATIO`` of its
median over the grid (n more than 1e9 times its typical value).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

POLE_RATIO = 1e-9
"""|1/n| below this fraction of its median over the box is a pole of n."""
GOLDEN_ITERATIONS = 48
"""Golden-section steps per bracket: a bracket of two grid cells narrows ~1e-10-fold."""
_INVPHI = (math.sqrt(5.0) - 1.0) / 2.0


def _inverse_index(model: Any, points: np.ndarray) -> np.ndarray:
    """|1/n| at points (N, 3); NaN where n is not finite or 1/n is not."""
    with np.errstate(all="ignore"):
        n = np.asarray(model.index_soa(points.T), dtype=np.float64)
        return np.abs(1.0 / n)


def _brackets(r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lines, start index) of the 3-sample brackets around each local minimum of ``r``
    (lines, G) along its last axis; a minimum at a line's end brackets that end's cell."""
    left = np.concatenate([np.full(r.shape[:-1] + (1,), np.inf), r[..., :-1]], axis=-1)
    right = np.concatenate([r[..., 1:], np.full(r.shape[:-1] + (1,), np.inf)], axis=-1)
    with np.errstate(invalid="ignore"):
        minimum = (r <= left) & (r <= right) & (r < np.inf)
    lines, index = np.nonzero(minimum)
    return lines, np.clip(index - 1, 0, r.shape[-1] - 1)


def _golden(f, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Minimise ``f`` (vectorised over rows) on the segments a -> b (M, 3): (points, f);
    one evaluation of every row per step."""
    lo, hi = np.zeros(len(a)), np.ones(len(a))
    c, d = hi - _INVPHI * (hi - lo), lo + _INVPHI * (hi - lo)
    fc, fd = f(a + c[:, None] * (b - a)), f(a + d[:, None] * (b - a))
    for _ in range(GOLDEN_ITERATIONS):
        left = np.isnan(fd) | (fc <= fd)  # NaN counts as larger: the search leaves it
        hi, lo = np.where(left, d, hi), np.where(left, lo, c)
        new = np.where(left, hi - _INVPHI * (hi - lo), lo + _INVPHI * (hi - lo))
        f_new = f(a + new[:, None] * (b - a))
        c, d, fc, fd = (
            np.where(left, new, d),
            np.where(left, c, new),
            np.where(left, f_new, fd),
            np.where(left, fc, f_new),
        )
    best = np.isnan(fd) | (fc <= fd)
    t = np.where(best, c, d)
    return a + t[:, None] * (b - a), np.where(best, fc, fd)


def index_pole(model: Any, lo: Any, hi: Any, samples: int = 17) -> tuple[np.ndarray, float] | None:
    """(where (3,), n there) of a pole of ``model.index_soa`` in the box lo..hi (local
    coordinates), or None. ``samples`` grid points per axis."""
    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    axes = [np.linspace(lo[i], hi[i], samples) for i in range(3)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)  # (G, G, G, 3)
    r = _inverse_index(model, grid.reshape(-1, 3)).reshape(grid.shape[:3])
    typical = np.nanmedian(r) if np.isfinite(r).any() else math.nan
    if not typical > 0:
        return None  # n is nowhere finite and positive: check_index names that
    starts, ends = [], []
    for axis in range(3):
        lines_r = np.moveaxis(r, axis, -1).reshape(-1, samples)
        lines_p = np.moveaxis(grid, axis, -2).reshape(-1, samples, 3)
        line, first = _brackets(lines_r)
        last = np.minimum(first + 2, samples - 1)
        starts.append(lines_p[line, first])
        ends.append(lines_p[line, last])
    a, b = np.concatenate(starts), np.concatenate(ends)
    if len(a) == 0:
        return None
    where, smallest = _golden(lambda p: _inverse_index(model, p), a, b)
    with np.errstate(invalid="ignore"):
        pole = smallest < POLE_RATIO * typical
    if not pole.any():
        return None
    centre = 0.5 * (lo + hi)  # name the pole nearest the box's centre
    k = int(np.nanargmin(np.where(pole, np.linalg.norm(where - centre, axis=1), np.nan)))
    return where[k], float(1.0 / smallest[k]) if smallest[k] > 0 else math.inf

"""Pixel filters and sub-pixel sample points.

Offers ``FILTERS`` (the reconstruction filters' names), ``sample_offsets`` and
``filter_samples`` (offsets and weights of points under a filter), ``pixel_samples`` (a
pixel's jittered, stratified samples), ``stratified_points`` and ``cells_per_side`` (the
k x k grid they come from). Needs numpy alone.
"""

from __future__ import annotations

import math

import numpy as np

FILTERS = ("box", "blackman_harris")
"""Reconstruction filters: the pixel's square, or Cycles' default (width ``filter_size``)."""


def sample_offsets(unit: np.ndarray, pixel_filter: str, filter_size: float) -> tuple:
    """Sub-pixel offsets (..., 2) from the pixel centre of points ``unit`` (..., 2) in the
    unit square, and their filter weights (...): the pixel's square (box) or the filter's
    footprint (Blackman-Harris of width ``filter_size``)."""
    if pixel_filter == "box":
        return unit - 0.5, np.ones(unit.shape[:-1])
    offsets = (unit - 0.5) * filter_size
    a0, a1, a2, a3 = BLACKMAN_HARRIS
    window = a0 - a1 * np.cos(2 * np.pi * unit) + a2 * np.cos(4 * np.pi * unit)
    window -= a3 * np.cos(6 * np.pi * unit)
    return offsets, np.prod(window, axis=-1)


BLACKMAN_HARRIS = (0.35875, 0.48829, 0.14128, 0.01168)
"""The Blackman-Harris window's cosine coefficients (sample_offsets)."""


def _window_inverse(count: int = 4097) -> tuple[np.ndarray, np.ndarray]:
    """(cdf, t): the Blackman-Harris window's cumulative share on [0, 1] at ``count`` points
    (closed form), for its inverse by interpolation (filter_samples)."""
    a0, a1, a2, a3 = BLACKMAN_HARRIS
    t = np.linspace(0.0, 1.0, count)
    cdf = (
        a0 * t
        - a1 * np.sin(2 * np.pi * t) / (2 * np.pi)
        + a2 * np.sin(4 * np.pi * t) / (4 * np.pi)
        - a3 * np.sin(6 * np.pi * t) / (6 * np.pi)
    )
    return cdf / cdf[-1], t


_WINDOW_CDF, _WINDOW_T = _window_inverse()


def filter_samples(unit: np.ndarray, pixel_filter: str, filter_size: float) -> tuple:
    """Sub-pixel offsets (..., 2) from the pixel centre of anti-aliasing samples ``unit``
    (..., 2) (stratified in the unit square), and their weights (...): the filter importance-
    sampled, each axis through the inverse of the window's cumulative share, every sample of
    weight 1 (the box: the pixel's square). Stratified over the filter's weight, not its
    square: Blackman-Harris's corner cells weighed ~1e-3 each, and a sub-pixel image near
    the centre that the samples missed lost its light (issue 50)."""
    if pixel_filter == "box":
        return unit - 0.5, np.ones(unit.shape[:-1])
    t = np.interp(unit, _WINDOW_CDF, _WINDOW_T)
    return (t - 0.5) * filter_size, np.ones(unit.shape[:-1])


R2 = np.array([0.7548776662466927, 0.5698402909980532])
"""The R2 sequence's steps (frac(n R2), n = 0, 1, ...: low-discrepancy points in 2-D)."""
PIXEL_STRIDE = 65537
"""Pixel (row, column) numbers its samples' jitter from (row PIXEL_STRIDE + column) K."""


def pixel_samples(
    unit: np.ndarray, ks: slice, k: int, rows: np.ndarray, columns: np.ndarray
) -> np.ndarray:
    """(P, K, 2) points in the unit square: the samples ``ks`` of the cell centres ``unit``
    (of a k x k grid) of the pixels (rows, columns) (image indices, (P,)), each jittered
    within its cell, differently in every pixel (the R2 sequence over the pixel's and the
    sample's numbers): stratified, unbiased for any feature, whereas one fixed pattern
    for all pixels covers a strip 0.3 px wide along a column with the same one or two grid
    columns in every pixel (0.25 or 0.5 of its light)."""
    count = unit.shape[0]
    number = (rows.astype(np.float64) * PIXEL_STRIDE + columns)[:, None] * count
    number = number + np.arange(count)[ks][None, :]
    jitter = np.mod(0.5 + number[..., None] * R2, 1.0)  # (P, K, 2)
    return unit[ks][None, :, :] + (jitter - 0.5) / k


def stratified_points(n: int) -> np.ndarray:
    """n points (n, 2) in the unit square: centres of a k x k grid's cells, k = ceil(sqrt n),
    in farthest-point order from the one nearest the middle (every prefix is spread out)."""
    k = cells_per_side(n)
    cells = (np.stack(np.meshgrid(np.arange(k), np.arange(k)), axis=-1).reshape(-1, 2) + 0.5) / k
    order = [int(np.argmin(np.hypot(*(cells - 0.5).T)))]
    gap = np.hypot(*(cells - cells[order[0]]).T)
    while len(order) < n:
        order.append(int(np.argmax(gap)))
        gap = np.minimum(gap, np.hypot(*(cells - cells[order[-1]]).T))
    return cells[order]


def cells_per_side(n: int) -> int:
    """k = ceil(sqrt(n)): the side of the k x k grid whose cells n points take."""
    return math.isqrt(n - 1) + 1 if n > 1 else 1

"""Colour of surfaces: a constant (r, g, b[, a]) or a texture callable.

A texture is ``texture(uv (N, 2), position (N, 3), normal (N, 3)) -> (N, 3|4)``; it is
evaluated only at hit points. A texture that can average itself over each pixel's
footprint has a method ``filtered(uv, position, normal, footprint)``, ``footprint``
(N, 2, 2) the uv's derivatives along image x and y (column k = ∂(u, v)/∂(image coordinate
k); NaN: a point): renders call it with the footprints they find (core.mipmap's
surface_footprint, mapped into uv by each surface); a plain callable is sampled at the
pixel's centre (*Final*'s samples are then its only filter). ``checker`` filters exactly.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

Texture = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]


def _rgba(color: Any) -> np.ndarray | Texture:
    """Validate a colour spec: constant rgba (4,) or a texture callable."""
    if callable(color):
        return color
    c = np.asarray(color, dtype=np.float64).reshape(-1)
    if c.shape[0] == 3:
        c = np.append(c, 1.0)
    if c.shape[0] != 4:
        raise ValueError(f"color must be (r, g, b[, a]) or a texture callable, got {color}")
    return c


def _constant(color: Any) -> np.ndarray:
    """A constant colour spec as rgba (4,) (not a texture)."""
    c = _rgba(color)
    if callable(c):
        raise ValueError("a checker's colours must be constants (r, g, b[, a])")
    return c


def texture_filters(color: np.ndarray | Texture) -> bool:
    """Whether a colour spec averages itself over footprints (a ``filtered`` method)."""
    return callable(getattr(color, "filtered", None))


def _shade(
    color: np.ndarray | Texture,
    uv: np.ndarray,
    p: np.ndarray,
    n: np.ndarray,
    footprint: np.ndarray | None = None,
):
    """Evaluate a colour spec at hit points -> (M, 4), over each hit's uv ``footprint``
    (M, 2, 2) where given and the texture filters."""
    if uv.shape[0] == 0:  # no hit: a texture is not asked about an empty batch
        return np.zeros((0, 4))
    if not callable(color):
        return np.broadcast_to(color, (uv.shape[0], 4)).copy()
    if footprint is not None and texture_filters(color):
        c = np.asarray(color.filtered(uv, p, n, footprint), dtype=np.float64)  # type: ignore[attr-defined]
    else:
        c = np.asarray(color(uv, p, n), dtype=np.float64)
    c = c.reshape(uv.shape[0], -1)
    if c.shape[1] == 3:
        c = np.concatenate([c, np.ones((c.shape[0], 1))], axis=1)
    return c


PIECES = (4, 2)
"""A footprint's longer and shorter sides are cut into this many pieces (Checker.filtered)."""
SMALL_PIECES = (2, 2)
"""... a footprint less than a cell wide each way (it crosses at most one edge each way)."""
BOXY = 0.7
"""A footprint filling this share of its bounding box is taken as the box (Checker.filtered)."""


class Checker:
    """Texture: an n_u x n_v checkerboard over uv in [0, 1]^2 (cell (0, 0) is color_a),
    box-filtered exactly over footprints (``filtered``)."""

    def __init__(self, n_u: int, n_v: int, color_a: Any, color_b: Any) -> None:
        self.cells = np.array([n_u, n_v], dtype=np.float64)
        self.color_a, self.color_b = _constant(color_a), _constant(color_b)

    def __call__(self, uv: np.ndarray, position: np.ndarray, normal: np.ndarray) -> np.ndarray:
        """The colour at ``uv`` (N, 2)."""
        parity = _square_wave(np.asarray(uv) * self.cells)
        return np.where((parity[:, 0] == parity[:, 1])[:, None], self.color_a, self.color_b)

    def filtered(self, uv, position, normal, footprint: np.ndarray) -> np.ndarray:
        """The colour averaged over each footprint's parallelogram (N, 2, 2; module): the
        checker is (a + b)/2 + (a − b)/2 s(u n_u) s(v n_v), s the ±1 square wave, whose mean
        over an axis-aligned box is the product of s's means along each side (its integral
        a triangle wave). A footprint whose bounding box lies inside one cell keeps the
        point value; one that fills at least BOXY of its bounding box is taken as that box;
        another is cut into like pieces (PIECES along its longer side and across;
        SMALL_PIECES under a cell each way), each taken as its bounding box."""
        cells = np.where(np.isfinite(footprint), footprint, 0.0) * self.cells[None, :, None]
        centre = np.asarray(uv) * self.cells
        box = np.abs(cells).sum(axis=2)  # the footprint's bounding box, in cells
        parity = _square_wave(centre)
        s = parity[:, 0] * parity[:, 1]
        edge = np.any(np.floor(centre - 0.5 * box) != np.floor(centre + 0.5 * box), axis=1)
        area = np.abs(cells[:, 0, 0] * cells[:, 1, 1] - cells[:, 0, 1] * cells[:, 1, 0])
        boxy = area >= BOXY * box[:, 0] * box[:, 1]  # fills most of its bounding box
        whole = np.flatnonzero(edge & boxy)
        mean = _square_wave_mean(centre[whole], box[whole])
        s[whole] = mean[:, 0] * mean[:, 1]
        small = np.all(box < 1.0, axis=1)  # crosses at most one edge each way
        for pieces, rows in ((SMALL_PIECES, edge & ~boxy & small), (PIECES, edge & ~boxy & ~small)):
            cut = np.flatnonzero(rows)
            s[cut] = _cut_mean(centre[cut], cells[cut], pieces)
        return self._mix(s)

    def _mix(self, s: np.ndarray) -> np.ndarray:
        """(a + b)/2 + (a − b)/2 s, s (N,) in [−1, 1]: a or b exactly at s = ±1."""
        half_sum, half_difference = (
            0.5 * (self.color_a + self.color_b),
            0.5 * (self.color_a - self.color_b),
        )
        mix = half_sum + s[:, None] * half_difference
        return np.where(
            (s == 1.0)[:, None], self.color_a, np.where((s == -1.0)[:, None], self.color_b, mix)
        )


def _cut_mean(centre: np.ndarray, cells: np.ndarray, pieces: tuple[int, int]) -> np.ndarray:
    """The mean of s(u) s(v) (Checker.filtered) over parallelograms about ``centre`` (E, 2)
    with sides ``cells`` (E, 2, 2), cut into pieces[0] along the longer side and pieces[1]
    across, each taken as its bounding box."""
    a, b = cells[:, None, :, 0], cells[:, None, :, 1]  # (E, 1, 2) the two sides
    longer = (np.abs(a).sum(axis=2) >= np.abs(b).sum(axis=2))[..., None]
    a, b = np.where(longer, a, b), np.where(longer, b, a)
    along = (np.arange(pieces[0]) + 0.5) / pieces[0] - 0.5
    across = (np.arange(pieces[1]) + 0.5) / pieces[1] - 0.5
    i, j = (g.ravel()[None, :, None] for g in np.meshgrid(along, across, indexing="ij"))
    mean = _square_wave_mean(centre[:, None] + i * a + j * b,
                             np.abs(a) / pieces[0] + np.abs(b) / pieces[1])  # fmt: skip
    return np.mean(mean[..., 0] * mean[..., 1], axis=1)


def _odd(floor: np.ndarray) -> np.ndarray:
    """1 where the integers ``floor`` are odd, 0 where even (as floats)."""
    return floor - 2.0 * np.floor(0.5 * floor)


def _square_wave(x: np.ndarray) -> np.ndarray:
    """+1 where floor(x) is even, −1 where odd."""
    return 1.0 - 2.0 * _odd(np.floor(x))


def _triangle_wave(x: np.ndarray, floor: np.ndarray) -> np.ndarray:
    """The integral of _square_wave from 0 at x (``floor`` = floor(x)): period 2, 0 at even
    x, 1 at odd."""
    fraction = x - floor
    return fraction + _odd(floor) * (1.0 - 2.0 * fraction)


def _square_wave_mean(x: np.ndarray, width: np.ndarray) -> np.ndarray:
    """The mean of _square_wave over [x − width/2, x + width/2] (elementwise): its point
    value where the interval lies within one cell."""
    lo, hi = x - 0.5 * width, x + 0.5 * width
    floor_lo, floor_hi = np.floor(lo), np.floor(hi)
    with np.errstate(divide="ignore", invalid="ignore"):
        mean = (_triangle_wave(hi, floor_hi) - _triangle_wave(lo, floor_lo)) / width
    inside = floor_lo == floor_hi
    return np.where(inside, 1.0 - 2.0 * _odd(floor_lo), np.clip(mean, -1.0, 1.0))


def checker(n_u: int, n_v: int, color_a: Any = (0.9, 0.9, 0.9), color_b: Any = (0.1, 0.1, 0.1)):
    """Texture: an n_u x n_v checkerboard over uv in [0, 1]^2 (cell (0, 0) is color_a),
    filtered exactly over footprints (Checker)."""
    return Checker(n_u, n_v, color_a, color_b)


def colormap(stops: Sequence[tuple[float, Sequence[float]]]) -> Callable[[np.ndarray], np.ndarray]:
    """Piecewise-linear colormap: [(value, (r, g, b)), ...] -> f(values (N,)) -> (N, 3)."""
    xs = np.array([s[0] for s in stops], dtype=np.float64)
    cs = np.array([s[1] for s in stops], dtype=np.float64).reshape(len(stops), 3)
    if np.any(np.diff(xs) <= 0):
        raise ValueError("colormap stop values must increase")

    def cmap(values: np.ndarray) -> np.ndarray:
        v = np.asarray(values, dtype=np.float64)
        return np.stack([np.interp(v, xs, cs[:, c]) for c in range(3)], axis=-1)

    return cmap

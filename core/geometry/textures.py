"""Colour of surfaces: a constant (r, g, b[, a]) or a texture callable.

A texture is ``texture(uv (N, 2), position (N, 3), normal (N, 3)) -> (N, 3|4)``; it is
evaluated only at hit points.
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


def _shade(color: np.ndarray | Texture, uv: np.ndarray, p: np.ndarray, n: np.ndarray):
    """Evaluate a colour spec at hit points -> (M, 4)."""
    if uv.shape[0] == 0:  # no hit: a texture is not asked about an empty batch
        return np.zeros((0, 4))
    if not callable(color):
        return np.broadcast_to(color, (uv.shape[0], 4)).copy()
    c = np.asarray(color(uv, p, n), dtype=np.float64).reshape(uv.shape[0], -1)
    if c.shape[1] == 3:
        c = np.concatenate([c, np.ones((c.shape[0], 1))], axis=1)
    return c


def checker(n_u: int, n_v: int, color_a: Any = (0.9, 0.9, 0.9), color_b: Any = (0.1, 0.1, 0.1)):
    """Texture: an n_u x n_v checkerboard over uv in [0, 1]^2 (cell (0, 0) is color_a)."""
    ca, cb = _rgba(color_a), _rgba(color_b)

    def texture(uv: np.ndarray, position: np.ndarray, normal: np.ndarray) -> np.ndarray:
        iu = np.floor(np.asarray(uv)[:, 0] * n_u).astype(np.int64)
        iv = np.floor(np.asarray(uv)[:, 1] * n_v).astype(np.int64)
        return np.where(((iu + iv) % 2 == 0)[:, None], ca, cb)

    return texture


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

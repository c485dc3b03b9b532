"""Volumes: emitting, absorbing media in a box, composited along segments front to back.

Volumes are not intersectors: ``Volume.segment`` gives the light a segment collects and
its transmittance, ``Volume.accumulate`` composites it behind what was gathered before.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from .hits import _INF, _segments
from .primitives import _vec


def _gauss_tables(order: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Gauss-Legendre nodes, weights on [0, 1] and the matrix S with S @ f = int_0^{x_i} f."""
    x, w = np.polynomial.legendre.leggauss(order)
    vander = np.polynomial.legendre.legvander(x, order - 1)  # f = V c
    coef_to_int = np.zeros((order, order))
    for j in range(order):
        e = np.zeros(order)
        e[j] = 1.0
        integ = np.polynomial.legendre.legint(e, lbnd=-1.0)
        coef_to_int[:, j] = np.polynomial.legendre.legval(x, integ)
    s = coef_to_int @ np.linalg.inv(vander)  # int_{-1}^{x_i} of the interpolant
    return 0.5 * (x + 1.0), 0.5 * w, 0.5 * s


class Volume:
    """Emitting, absorbing medium in the box [lo, hi] (no scattering).

    sigma(x) = absorption * density(x); emission j(x) (rgb per unit length) is
    ``emission(points) -> (N, 3)`` or, when only ``colormap`` is given,
    ``colormap(density(points))``. Along a segment, front to back:
    dL = T j ds, dT = -T sigma ds. Each segment's part inside the box is split into
    sub-intervals of at most ``max_step`` (at least ``min_intervals``), each integrated with
    ``order``-point Gauss-Legendre; the optical depth at the nodes is integrated spectrally.
    """

    def __init__(
        self,
        lo: Any,
        hi: Any,
        density: Callable[[np.ndarray], np.ndarray],
        emission: Callable[[np.ndarray], np.ndarray] | None = None,
        *,
        colormap: Callable[[np.ndarray], np.ndarray] | None = None,
        absorption: float = 1.0,
        order: int = 8,
        min_intervals: int = 4,
        max_step: float | None = None,
        max_points: int = 1 << 20,
    ) -> None:
        """Box [lo, hi] with a density field and emission (callable or colormap of density)."""
        self.lo, self.hi = _vec(lo, "lo"), _vec(hi, "hi")
        if np.any(self.hi <= self.lo):
            raise ValueError("Volume needs lo < hi on every axis")
        if emission is None and colormap is None:
            raise ValueError("Volume needs emission or colormap")
        self.density, self.emission, self.colormap = density, emission, colormap
        self.absorption = float(absorption)
        self.order, self.min_intervals = int(order), int(min_intervals)
        diag = float(np.linalg.norm(self.hi - self.lo))
        self.max_step = diag / 16 if max_step is None else float(max_step)
        self.max_points = int(max_points)
        self._x, self._w, self._s = _gauss_tables(self.order)
        self.bounds = (self.lo, self.hi)

    def _clip(self, a: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Slab test: the parameter range [t0, t1] of a + t d, t in [0, 1], inside the box."""
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / d
            ta, tb = (self.lo - a) * inv, (self.hi - a) * inv
        inside = (a >= self.lo) & (a <= self.hi)
        tmin = np.where(d == 0, np.where(inside, -_INF, _INF), np.fmin(ta, tb))
        tmax = np.where(d == 0, np.where(inside, _INF, -_INF), np.fmax(ta, tb))
        return np.clip(tmin.max(axis=1), 0, 1), np.clip(tmax.min(axis=1), 0, 1)

    def _sources(self, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Absorption coefficient (M,) and emission (M, 3) at points (M, 3)."""
        rho = np.asarray(self.density(pts), dtype=np.float64).reshape(-1)
        if self.emission is not None:
            j = np.asarray(self.emission(pts), dtype=np.float64).reshape(-1, 3)
        else:
            assert self.colormap is not None  # __init__ requires emission or colormap
            j = np.asarray(self.colormap(rho), dtype=np.float64).reshape(-1, 3)
        return self.absorption * rho, j

    def segment(self, a: Any, b: Any) -> tuple[np.ndarray, np.ndarray]:
        """Radiance (N, 3) emitted towards a along a -> b and transmittance (N,) of the path."""
        a, b = _segments(a, b)
        n = a.shape[0]
        radiance, trans = np.zeros((n, 3)), np.ones(n)
        d = b - a
        t0, t1 = self._clip(a, d)
        rows = np.flatnonzero(t1 > t0)
        if rows.size == 0:
            return radiance, trans
        length = (t1 - t0)[rows] * np.linalg.norm(d[rows], axis=1)
        k = max(self.min_intervals, math.ceil(float(length.max()) / self.max_step))
        per = max(1, self.max_points // (k * self.order))
        for c in range(0, rows.size, per):
            r = rows[c : c + per]
            radiance[r], trans[r] = self._integrate(a[r], d[r], t0[r], t1[r], k)
        return radiance, trans

    def _integrate(self, a, d, t0, t1, k: int):
        """Composite Gauss-Legendre over k sub-intervals of [t0, t1] for rays a + t d."""
        m = self.order
        edges = t0[:, None] + (t1 - t0)[:, None] * (np.arange(k) / k)[None, :]  # (R, k)
        tn = edges[:, :, None] + ((t1 - t0) / k)[:, None, None] * self._x[None, None, :]
        pts = a[:, None, None, :] + tn[..., None] * d[:, None, None, :]  # (R, k, m, 3)
        sigma, j = self._sources(pts.reshape(-1, 3))
        sigma, j = sigma.reshape(-1, k, m), j.reshape(-1, k, m, 3)
        h = ((t1 - t0) / k * np.linalg.norm(d, axis=1))[:, None]  # sub-interval length (R, 1)
        tau_end = np.cumsum(h * (sigma @ self._w), axis=1)  # (R, k) optical depth at ends
        tau_start = np.concatenate([np.zeros((tau_end.shape[0], 1)), tau_end[:, :-1]], axis=1)
        tau = tau_start[..., None] + h[..., None] * (sigma @ self._s.T)  # (R, k, m)
        weight = np.exp(-tau) * self._w * h[..., None]
        radiance = np.einsum("rkm,rkmc->rc", weight, j)
        return radiance, np.exp(-tau_end[:, -1])

    def accumulate(
        self, a: Any, b: Any, radiance: np.ndarray, transmittance: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Composite segment a -> b behind what was gathered so far: L += T L_seg, T *= T_seg."""
        seg_l, seg_t = self.segment(a, b)
        radiance = np.asarray(radiance, dtype=np.float64)
        transmittance = np.asarray(transmittance, dtype=np.float64)
        return radiance + transmittance[:, None] * seg_l, transmittance * seg_t

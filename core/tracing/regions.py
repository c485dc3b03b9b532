"""Where a model bends light: a sphere around a mass (or a user model), or a medium's box.

Inside its region a ray follows Hamilton's equations; outside it moves straight. Positions
are in the model's local Cartesian frame, as (N, 3) for entry points and (3, M) per step.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..backend import placed
from .steps import FAR_FIELD_CONSTANT, FAR_FIELD_SHARE


class Region:
    """The region interface: entry points, leaving test and the step's length unit."""

    radius: float | None = None
    """The sphere's radius (None for a box); reported in the render summary."""

    def scaled(self, model: Any) -> bool:
        """Whether the model's Poincaré g(q) grows with the distance from a mass."""
        return False

    def length_scale(self, model: Any) -> float:
        """Step unit: 1 where the model's g(q) already scales with distance, else the size."""
        raise NotImplementedError

    def entry(self, X: np.ndarray, D: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Start points (N, 3) inside the region and whether the ray starts inside.

        Rays starting inside start where they are; others at their first entry point;
        rays that never enter get NaN start points.
        """
        raise NotImplementedError

    def left_soa(self, X: np.ndarray, X_prev: np.ndarray) -> np.ndarray:
        """Rays (M,) at X (3, M), coming from X_prev, that have left the region."""
        raise NotImplementedError

    def exit_time(self, X: np.ndarray, V: np.ndarray) -> np.ndarray:
        """(M,) t where the line X + t V (3, M) leaves the region outwards (NaN: never)."""
        raise NotImplementedError


class SphereRegion(Region):
    """A ball of radius R about the model's centre."""

    radius: float

    def __init__(self, radius: float, scale_time: bool) -> None:
        self.radius = radius
        self.scale_time = scale_time

    def scaled(self, model: Any) -> bool:
        return bool(self.scale_time and model.scales_time)

    def length_scale(self, model: Any) -> float:
        if self.scaled(model):
            return 1.0
        return self.radius / 20.0

    def entry(self, X: np.ndarray, D: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        r2 = np.einsum("ij,ij->i", X, X)
        inside = r2 < self.radius**2
        along = np.einsum("ij,ij->i", X, D)
        disc = along**2 - (r2 - self.radius**2)
        t = -along - np.sqrt(np.maximum(disc, 0.0))
        enters = ~inside & (disc > 0) & (t > 0)
        return _start_points(X, D, inside, enters, t), inside

    def left_soa(self, X: np.ndarray, X_prev: np.ndarray) -> np.ndarray:
        """Outside the sphere and moving away from the centre."""
        r2 = X[0] * X[0] + X[1] * X[1] + X[2] * X[2]
        away = X[0] * (X[0] - X_prev[0]) + X[1] * (X[1] - X_prev[1]) + X[2] * (X[2] - X_prev[2])
        return (r2 > self.radius**2) & (away > 0)

    def exit_time(self, X: np.ndarray, V: np.ndarray) -> np.ndarray:
        """The outward crossing of the sphere: the quadratic's larger root."""
        a = np.einsum("im,im->m", V, V)
        b = np.einsum("im,im->m", X, V)
        c = np.einsum("im,im->m", X, X) - self.radius * self.radius
        with np.errstate(all="ignore"):
            return (-b + np.sqrt(b * b - a * c)) / a


class BoxRegion(Region):
    """An axis-aligned box [lo, hi] (a medium's bounds); its g(q) is never distance-scaled."""

    def __init__(self, lo: np.ndarray, hi: np.ndarray) -> None:
        self.lo, self.hi = lo, hi

    def length_scale(self, model: Any) -> float:
        return float(np.linalg.norm(self.hi - self.lo)) / 20.0

    def entry(self, X: np.ndarray, D: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        lo, hi = placed(self.lo, X), placed(self.hi, X)
        inside = np.all((X >= lo) & (X <= hi), axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            ta, tb = (lo - X) / D, (hi - X) / D
        t0 = np.nanmax(np.fmin(ta, tb), axis=1)
        t1 = np.nanmin(np.fmax(ta, tb), axis=1)
        enters = ~inside & (t1 >= t0) & (t0 > 0)
        return _start_points(X, D, inside, enters, t0), inside

    def left_soa(self, X: np.ndarray, X_prev: np.ndarray) -> np.ndarray:
        """Outside the box."""
        lo, hi = placed(self.lo, X), placed(self.hi, X)
        return ~np.all((X >= lo[:, None]) & (X <= hi[:, None]), axis=0)

    def exit_time(self, X: np.ndarray, V: np.ndarray) -> np.ndarray:
        """Where the line leaves the slabs' intersection: the nearest far face (from a point
        past a face, a negative t back to it)."""
        lo, hi = placed(self.lo, X), placed(self.hi, X)
        with np.errstate(divide="ignore", invalid="ignore"):
            ta, tb = (lo[:, None] - X) / V, (hi[:, None] - X) / V
        far = np.where(V == 0.0, np.inf, np.fmax(ta, tb))
        t = np.min(far, axis=0)
        return np.where(np.isfinite(t), t, np.nan)

    def faces(self, count: int) -> np.ndarray:
        """(3, 6 count^2) points on the box's faces: a count x count grid of cell centres
        on each."""
        u = (np.arange(count) + 0.5) / count
        a, b = (g.ravel() for g in np.meshgrid(u, u))
        points = []
        for axis in range(3):
            i, j = (k for k in range(3) if k != axis)
            for end in (self.lo, self.hi):
                P = np.empty((3, a.size))
                P[axis] = end[axis]
                P[i] = self.lo[i] + a * (self.hi[i] - self.lo[i])
                P[j] = self.lo[j] + b * (self.hi[j] - self.lo[j])
                points.append(P)
        return np.concatenate(points, axis=1)


def _start_points(
    X: np.ndarray, D: np.ndarray, inside: np.ndarray, enters: np.ndarray, t: np.ndarray
) -> np.ndarray:
    """X where inside, the entry point X + t D (nudged in) where the ray enters, else NaN."""
    start = np.where(inside[:, None], X, np.nan)
    start[enters] = X[enters] + (t[enters, None] * (1 + 1e-12)) * D[enters]
    return start


def region_for(model: Any, tolerance: float, extent: float, radius: float | None = None) -> Region:
    """The region of a model: its box if it has bounds (and no radius is asked for), else a
    sphere; around a mass of radius sqrt(2 C / tol) M (first-order far field).

    Beyond R the far field leaves an error ~ C (M / R)^2 (FAR_FIELD_CONSTANT): R keeps it
    below FAR_FIELD_SHARE x tolerance, and at least 1.5x beyond the camera and the objects.
    """
    if model.bounds is not None and radius is None:
        return BoxRegion(np.asarray(model.bounds[0], float), np.asarray(model.bounds[1], float))
    if radius is None:
        rg = float(model.rg)
        if rg > 0:
            tol = min(max(float(tolerance), 1e-14), 1e-1)
            share = FAR_FIELD_SHARE * tol
            radius = min(0.5 * rg * math.sqrt(FAR_FIELD_CONSTANT / share), 1e6 * rg)
            radius = max(radius, 1.5 * extent)
        else:
            radius = 2.0 * extent
    return SphereRegion(float(radius), scale_time=model.rg > 0)

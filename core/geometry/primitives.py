"""Analytic primitives: Sphere, Plane (infinite or a rectangle) and Disk (an annulus).

Each has ``bounds`` and ``intersect(a, b) -> Hits`` (see core.geometry.hits) and a colour
(core.geometry.textures); ``_Primitive`` holds the shared plumbing.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .hits import _INF, Hits, _fill, _segments
from .textures import Texture, _rgba, _shade, texture_filters


def _vec(v: Any, name: str) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64).reshape(3)
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{name} must be a finite 3-vector, got {v.tolist()}")
    return v


def _unit(v: Any, name: str) -> np.ndarray:
    v = _vec(v, name)
    n = float(np.linalg.norm(v))
    if n == 0.0:
        raise ValueError(f"{name} must be non-zero")
    return v / n


def _tangent(normal: np.ndarray, u_axis: Any = None) -> np.ndarray:
    """Unit vector perpendicular to normal: u_axis projected, or a stable default."""
    if u_axis is None:
        helper = np.eye(3)[int(np.argmin(np.abs(normal)))]
    else:
        helper = _vec(u_axis, "u_axis")
    u = helper - (helper @ normal) * normal
    if np.linalg.norm(u) < 1e-12:
        raise ValueError("u_axis must not be parallel to the normal")
    return u / np.linalg.norm(u)


class _Primitive:
    """Shared plumbing: colour and object id; subclasses implement ``_hit``."""

    color: np.ndarray | Texture
    object_id: int
    bounds: tuple[np.ndarray, np.ndarray]

    @property
    def filters(self) -> bool:
        """Whether its colour averages over footprints (core.geometry.textures)."""
        return texture_filters(self.color)

    def intersect(self, a: np.ndarray, b: np.ndarray, footprint: np.ndarray | None = None) -> Hits:
        """Nearest hit of each segment a -> b (N, 3) with this object; coloured over each
        segment's ``footprint`` (N, 2, 3: ∂(hit point)/∂(image x, y)) where given."""
        a, b = _segments(a, b)
        rows, t, p, n, uv, part = self._hit(a, b)
        uv_footprint = None
        if footprint is not None and self.filters:
            seen = footprint[rows]
            along = np.einsum("mkj,mj->mk", seen, n)
            uv_footprint = self._uv_derivatives(p, n, seen - along[..., None] * n[:, None], part)
        c = _shade(self.color, uv, p, n, uv_footprint)
        return _fill(a.shape[0], rows, t, p, n, uv, c, self.object_id)

    def _hit(self, a: np.ndarray, b: np.ndarray) -> tuple:
        """(rows, t, position, normal, uv, part) of the segments that hit; ``part`` what
        ``_uv_derivatives`` needs besides (a mesh's faces), else None."""
        raise NotImplementedError

    def _uv_derivatives(self, p: np.ndarray, n: np.ndarray, dp: np.ndarray, part) -> np.ndarray:
        """(M, 2, 2) ∂(u, v)/∂(image x, y) at hit points p from their derivatives ``dp``
        (M, 2, 3), in the surface's tangent plane."""
        raise NotImplementedError


def sphere_hits(a: np.ndarray, b: np.ndarray, center: Any, radius: Any, radius2: Any) -> tuple:
    """(rows, t, position, normal, uv) of the segments a -> b (N, 3) that hit the sphere of
    ``center`` (3,) or (N, 3), ``radius`` and its square ``radius2`` (numbers or (N,): the
    square as Python's ``radius**2``, which numpy's differs from in the last bit at times):
    one sphere, or one per segment (core.geometry.group's batches), by the same
    arithmetic per segment."""
    d = b - a
    m = a - center
    qa = np.einsum("ij,ij->i", d, d)
    qb = np.einsum("ij,ij->i", d, m)  # half of the linear coefficient
    qc = np.einsum("ij,ij->i", m, m) - radius2
    disc = qb * qb - qa * qc
    ok = (disc >= 0) & (qa > 0)
    sq = np.sqrt(np.where(ok, disc, 0.0))
    q = -(qb + np.copysign(sq, qb))  # stable roots: q / qa and qc / q
    with np.errstate(divide="ignore", invalid="ignore"):
        r1, r2 = q / qa, qc / q
    t0, t1 = np.fmin(r1, r2), np.fmax(r1, r2)
    t = np.where((t0 >= 0) & (t0 <= 1), t0, np.where((t1 >= 0) & (t1 <= 1), t1, np.nan))
    rows = np.flatnonzero(ok & np.isfinite(t))
    t = t[rows]
    p = a[rows] + t[:, None] * d[rows]
    if np.ndim(center) == 2:
        center, radius = center[rows], radius[rows, None]
    n = (p - center) / radius
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    uv = np.stack([
        0.5 + np.arctan2(n[:, 1], n[:, 0]) / (2 * np.pi),
        0.5 + np.arcsin(np.clip(n[:, 2], -1, 1)) / np.pi,
    ], axis=1)  # fmt: skip
    return rows, t, p, n, uv


SPHERE_ROW = 10
"""The length of a Sphere's record (Sphere)."""


# -- analytic primitives ---------------------------------------------------------------------


class Sphere(_Primitive):
    """Sphere; uv = (longitude around +Z from +X, latitude), each in [0, 1].

    ``center``, ``radius`` and ``color`` are kept in one float64 record (``_row``,
    SPHERE_ROW: centre, radius, Python's radius**2, rgba, 1 if the colour is constant)
    that a Group reads for thousands of spheres at once (core.geometry.group._read);
    ``center`` and a constant ``color`` are views of it, set through their properties;
    ``_view``, a memoryview of it (Python joins those faster than numpy's buffers).
    """

    def __init__(
        self, center: Any, radius: float, color: Any = (1, 1, 1, 1), object_id: int = 0
    ) -> None:
        """Sphere of the given centre and radius (> 0)."""
        self._row = np.zeros(SPHERE_ROW)
        self._view = memoryview(self._row)
        self.center = center
        self.radius = radius
        self.color = color
        self.object_id = int(object_id)

    def __getstate__(self) -> dict:
        """Pickled without ``_view`` (a memoryview does not pickle)."""
        return {k: v for k, v in self.__dict__.items() if k != "_view"}

    def __setstate__(self, state: dict) -> None:
        if "_row" not in state:  # pickled before the record: made again
            state = dict(state)
            centre, radius, colour = (state.pop(k) for k in ("center", "radius", "color"))
            Sphere.__init__(self, centre, radius, colour, state.pop("object_id", 0))
            state.pop("bounds", None)
        self.__dict__.update(state)
        self._view = memoryview(self._row)

    @property
    def center(self) -> np.ndarray:
        """(3,) the centre (a view of the record: written in place, the record follows)."""
        return self._row[:3]

    @center.setter
    def center(self, value: Any) -> None:
        self._row[:3] = _vec(value, "center")
        self._bound()

    @property
    def radius(self) -> float:
        """The radius (> 0)."""
        return self._radius

    @radius.setter
    def radius(self, value: float) -> None:
        if not value > 0:
            raise ValueError(f"radius must be positive, got {value}")
        self._radius = r = float(value)
        self._row[3:5] = r, r**2
        self._bound()

    @property
    def color(self) -> np.ndarray | Texture:
        """rgba (4,) (a view of the record) or a texture callable."""
        return self._row[5:9] if self._texture is None else self._texture

    @color.setter
    def color(self, value: Any) -> None:
        c = _rgba(value)
        self._texture = c if callable(c) else None
        self._row[5:9] = np.nan if callable(c) else c
        self._row[9] = self._texture is None

    def _bound(self) -> None:
        """``bounds`` from the centre and radius (once both are set)."""
        if hasattr(self, "_radius"):
            self.bounds = (self.center - self._radius, self.center + self._radius)

    def _hit(self, a, b):
        return (*sphere_hits(a, b, self.center, self.radius, self.radius**2), None)

    def _uv_derivatives(self, p, n, dp, part):
        dn = dp / self.radius  # the unit normal's derivatives
        x, y, z = (n[:, None, i] for i in range(3))
        rho2 = x * x + y * y
        with np.errstate(divide="ignore", invalid="ignore"):
            du = (x * dn[..., 1] - y * dn[..., 0]) / rho2 / (2 * np.pi)
            dv = dn[..., 2] / np.sqrt(rho2) / np.pi
        return np.stack([du, dv], axis=1)


class Plane(_Primitive):
    """Infinite plane, or a finite rectangle of size ``extent`` = (size_u, size_v) centred at point.

    uv: in [0, 1] across a finite rectangle (u along ``u_axis``, v along normal x u_axis);
    on an infinite plane, the fractional part of (local coordinates / ``tile`` + 0.5).
    """

    def __init__(
        self,
        point: Any,
        normal: Any,
        color: Any = (1, 1, 1, 1),
        *,
        u_axis: Any = None,
        extent: tuple[float, float] | None = None,
        tile: float = 1.0,
        object_id: int = 0,
    ) -> None:
        """Plane through point with the given normal; finite if extent is given."""
        self.point = _vec(point, "point")
        self.normal = _unit(normal, "normal")
        self.u_axis = _tangent(self.normal, u_axis)
        self.v_axis = np.cross(self.normal, self.u_axis)
        self.extent = None if extent is None else (float(extent[0]), float(extent[1]))
        if self.extent is not None and min(self.extent) <= 0:
            raise ValueError(f"extent must be positive, got {extent}")
        self.tile = float(tile)
        self.color = _rgba(color)
        self.object_id = int(object_id)
        self.bounds = self._bounds()

    def _bounds(self):
        if self.extent is None:
            lo, hi = np.full(3, -_INF), np.full(3, _INF)
            axis = np.flatnonzero(np.abs(self.normal) == 1.0)
            lo[axis] = hi[axis] = self.point[axis]
            return lo, hi
        hu, hv = 0.5 * self.extent[0] * self.u_axis, 0.5 * self.extent[1] * self.v_axis
        corners = self.point + np.array([hu + hv, hu - hv, -hu + hv, -hu - hv])
        return corners.min(axis=0), corners.max(axis=0)

    def _hit(self, a, b):
        d = b - a
        den = d @ self.normal
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ((self.point - a) @ self.normal) / den
        ok = (den != 0) & (t >= 0) & (t <= 1)
        rows = np.flatnonzero(ok)
        t = t[rows]
        p = a[rows] + t[:, None] * d[rows]
        local = p - self.point
        lu, lv = local @ self.u_axis, local @ self.v_axis
        if self.extent is None:
            uv = np.stack([lu, lv], axis=1) / self.tile + 0.5
            uv -= np.floor(uv)
        else:
            uv = np.stack([lu / self.extent[0], lv / self.extent[1]], axis=1) + 0.5
            inside = np.all((uv >= 0) & (uv <= 1), axis=1)
            rows, t, p, uv = rows[inside], t[inside], p[inside], uv[inside]
        n = np.broadcast_to(self.normal, p.shape).copy()
        return rows, t, p, n, uv, None

    def _uv_derivatives(self, p, n, dp, part):
        size = (self.tile, self.tile) if self.extent is None else self.extent
        return np.stack([dp @ self.u_axis / size[0], dp @ self.v_axis / size[1]], axis=1)


class Disk(_Primitive):
    """Flat annulus r_in <= r <= r_out; uv = ((r - r_in)/(r_out - r_in), angle / 2 pi).

    The angle is measured from ``u_axis`` towards normal x u_axis, in [0, 1).
    """

    def __init__(
        self,
        center: Any,
        normal: Any,
        r_in: float,
        r_out: float,
        color: Any = (1, 1, 1, 1),
        *,
        u_axis: Any = None,
        object_id: int = 0,
    ) -> None:
        """Annulus (a full disk when r_in = 0) around center in the plane of normal."""
        if not 0 <= r_in < r_out:
            raise ValueError(f"need 0 <= r_in < r_out, got r_in={r_in}, r_out={r_out}")
        self.center = _vec(center, "center")
        self.normal = _unit(normal, "normal")
        self.u_axis = _tangent(self.normal, u_axis)
        self.v_axis = np.cross(self.normal, self.u_axis)
        self.r_in, self.r_out = float(r_in), float(r_out)
        self.color = _rgba(color)
        self.object_id = int(object_id)
        half = self.r_out * np.sqrt(np.clip(1 - self.normal**2, 0, 1))
        self.bounds = (self.center - half, self.center + half)

    def _hit(self, a, b):
        """Crossings at t in (0, 1]: a segment starting on the plane (a camera in the
        accretion disk's plane, a chord starting where the previous one ended on it) does
        not cross it there."""
        d = b - a
        den = d @ self.normal
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ((self.center - a) @ self.normal) / den
        rows = np.flatnonzero((den != 0) & (t > 0) & (t <= 1))
        t = t[rows]
        p = a[rows] + t[:, None] * d[rows]
        local = p - self.center
        x, y = local @ self.u_axis, local @ self.v_axis
        r = np.hypot(x, y)
        inside = (r >= self.r_in) & (r <= self.r_out)
        rows, t, p, r, x, y = rows[inside], t[inside], p[inside], r[inside], x[inside], y[inside]
        ang = np.arctan2(y, x) / (2 * np.pi)
        uv = np.stack([(r - self.r_in) / (self.r_out - self.r_in), ang - np.floor(ang)], axis=1)
        n = np.broadcast_to(self.normal, p.shape).copy()
        return rows, t, p, n, uv, None

    def _uv_derivatives(self, p, n, dp, part):
        local = p - self.center
        x, y = (local @ self.u_axis)[:, None], (local @ self.v_axis)[:, None]
        dx, dy = dp @ self.u_axis, dp @ self.v_axis
        r2 = x * x + y * y
        with np.errstate(divide="ignore", invalid="ignore"):
            du = (x * dx + y * dy) / np.sqrt(r2) / (self.r_out - self.r_in)
            dv = (x * dy - y * dx) / r2 / (2 * np.pi)
        return np.stack([du, dv], axis=1)

"""Intersectors: which straight segment a -> b hits which object first (the core/Blender seam).

Every intersector has ``bounds`` (lo (3,), hi (3,), world AABB; infinite where unbounded) and
``intersect(a, b) -> Hits`` for segment ends a, b of shape (N, 3). Hits report the nearest
hit along each segment; where ``hit`` is False, ``t`` is +inf, ``object_id`` is -1 and the
other fields are 0. Normals are the geometric, outward (sphere) or user-given (plane, disk,
mesh winding) unit normals, not flipped towards the ray.

Colour: a constant (r, g, b[, a]) or a texture callable ``texture(uv (N, 2), position (N, 3),
normal (N, 3)) -> (N, 3|4)``; it is evaluated only at hit points.

Volumes (emission/absorption media) are not intersectors: ``Volume.accumulate`` composites
their light along each segment, front to back.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

__all__ = [
    "Disk",
    "Group",
    "Hits",
    "Intersector",
    "Plane",
    "Sphere",
    "TriangleMesh",
    "Volume",
    "checker",
    "colormap",
    "segment_overlaps",
]

Texture = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]
_INF = np.inf


@dataclass
class Hits:
    """Nearest hits of N segments (see the module docstring for the miss convention)."""

    hit: np.ndarray  # (N,) bool
    t: np.ndarray  # (N,) in [0, 1] along a -> b; +inf where no hit
    object_id: np.ndarray  # (N,) int32; -1 where no hit
    position: np.ndarray  # (N, 3)
    normal: np.ndarray  # (N, 3)
    uv: np.ndarray  # (N, 2)
    color: np.ndarray  # (N, 4) float64

    @classmethod
    def miss(cls, n: int) -> Hits:
        """N segments that hit nothing."""
        return cls(
            np.zeros(n, dtype=bool), np.full(n, _INF), np.full(n, -1, dtype=np.int32),
            np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 2)), np.zeros((n, 4)),
        )  # fmt: skip

    def __len__(self) -> int:
        return self.hit.shape[0]

    def merge(self, rows: np.ndarray, other: Hits, object_id: int | None = None) -> None:
        """Take other's hits where nearer, in place; ``rows``: integer indices of other's rows.

        ``object_id``, if given, replaces the ids reported by ``other``.
        """
        nearer = other.hit & (other.t < self.t[rows])
        r = rows[nearer]
        self.hit[r] = True
        self.t[r] = other.t[nearer]
        self.object_id[r] = other.object_id[nearer] if object_id is None else object_id
        self.position[r] = other.position[nearer]
        self.normal[r] = other.normal[nearer]
        self.uv[r] = other.uv[nearer]
        self.color[r] = other.color[nearer]


class Intersector(Protocol):
    """What the tracer needs from a scene: world bounds and segment intersection."""

    bounds: tuple[np.ndarray, np.ndarray]

    def intersect(self, a: np.ndarray, b: np.ndarray) -> Hits: ...


# -- helpers ------------------------------------------------------------------------------------


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


def _segments(a: Any, b: Any) -> tuple[np.ndarray, np.ndarray]:
    a = np.asarray(a, dtype=np.float64).reshape(-1, 3)
    b = np.asarray(b, dtype=np.float64).reshape(-1, 3)
    if a.shape != b.shape:
        raise ValueError(f"segment ends must have equal shapes, got {a.shape} and {b.shape}")
    return a, b


def segment_overlaps(a: np.ndarray, b: np.ndarray, lo: np.ndarray, hi: np.ndarray):
    """(N,) bool: the AABB of each segment a -> b overlaps the box [lo, hi]."""
    return np.all((np.minimum(a, b) <= hi) & (np.maximum(a, b) >= lo), axis=1)


def _fill(n: int, rows: np.ndarray, t, p, nrm, uv, color, object_id: int) -> Hits:
    """Hits for n segments of which ``rows`` hit with the given per-hit data."""
    h = Hits.miss(n)
    h.hit[rows] = True
    h.t[rows] = t
    h.object_id[rows] = object_id
    h.position[rows] = p
    h.normal[rows] = nrm
    h.uv[rows] = uv
    h.color[rows] = color
    return h


class _Primitive:
    """Shared plumbing: colour and object id; subclasses implement ``_hit``."""

    color: np.ndarray | Texture
    object_id: int
    bounds: tuple[np.ndarray, np.ndarray]

    def intersect(self, a: np.ndarray, b: np.ndarray) -> Hits:
        """Nearest hit of each segment a -> b (N, 3) with this object."""
        a, b = _segments(a, b)
        rows, t, p, n, uv = self._hit(a, b)
        c = _shade(self.color, uv, p, n)
        return _fill(a.shape[0], rows, t, p, n, uv, c, self.object_id)

    def _hit(self, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, ...]:
        raise NotImplementedError


# -- analytic primitives ---------------------------------------------------------------------


class Sphere(_Primitive):
    """Sphere; uv = (longitude around +Z from +X, latitude), each in [0, 1]."""

    def __init__(
        self, center: Any, radius: float, color: Any = (1, 1, 1, 1), object_id: int = 0
    ) -> None:
        """Sphere of the given centre and radius (> 0)."""
        self.center = _vec(center, "center")
        if not radius > 0:
            raise ValueError(f"radius must be positive, got {radius}")
        self.radius = float(radius)
        self.color = _rgba(color)
        self.object_id = int(object_id)
        self.bounds = (self.center - radius, self.center + radius)

    def _hit(self, a, b):
        d = b - a
        m = a - self.center
        qa = np.einsum("ij,ij->i", d, d)
        qb = np.einsum("ij,ij->i", d, m)  # half of the linear coefficient
        qc = np.einsum("ij,ij->i", m, m) - self.radius**2
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
        n = (p - self.center) / self.radius
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        uv = np.stack([
            0.5 + np.arctan2(n[:, 1], n[:, 0]) / (2 * np.pi),
            0.5 + np.arcsin(np.clip(n[:, 2], -1, 1)) / np.pi,
        ], axis=1)  # fmt: skip
        return rows, t, p, n, uv


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
        return rows, t, p, n, uv


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
        d = b - a
        den = d @ self.normal
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ((self.center - a) @ self.normal) / den
        rows = np.flatnonzero((den != 0) & (t >= 0) & (t <= 1))
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
        return rows, t, p, n, uv


# -- triangle meshes ---------------------------------------------------------------------------


def _morton(points: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """30-bit Morton codes of points (N, 3) quantised to a 1024^3 grid over [lo, hi]."""
    span = np.where(hi > lo, hi - lo, 1.0)
    q = np.clip(((points - lo) / span * 1023.0).astype(np.int64), 0, 1023)
    code = np.zeros(points.shape[0], dtype=np.int64)
    for bit in range(10):
        for axis in range(3):
            code |= ((q[:, axis] >> bit) & 1) << (3 * bit + axis)
    return code


def _slab(a: np.ndarray, inv_d: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Entry parameter t of segments a + t d, t in [0, 1], into the box; +inf where missed."""
    with np.errstate(invalid="ignore", over="ignore"):
        t1, t2 = (lo - a) * inv_d, (hi - a) * inv_d
    # fmin/fmax skip the NaN of 0 * inf (a segment parallel to a slab, starting on its face)
    enter = np.maximum(np.fmax.reduce(np.fmin(t1, t2), axis=1), 0.0)
    leave = np.minimum(np.fmin.reduce(np.fmax(t1, t2), axis=1), 1.0)
    return np.where(enter <= leave, enter, _INF)


class TriangleMesh(_Primitive):
    """Triangle soup: a BVH over blocks of triangles, vectorised Moller-Trumbore at the leaves.

    Triangles are sorted by the Morton code of their centroids and grouped in blocks of
    ``block``; a binary tree of block ranges is traversed by packets of segments (slab tests,
    near child first, skipping boxes behind the nearest hit so far). At a leaf, segments x
    triangles are tested in chunks of at most ``max_pairs`` pairs. uv: the per-corner ``uvs``
    (F, 3, 2) interpolated, else the barycentric (u, v) of the hit. Normals follow the
    winding (right-hand rule over v0, v1, v2).
    """

    def __init__(
        self,
        vertices: Any,
        faces: Any,
        color: Any = (1, 1, 1, 1),
        *,
        uvs: Any = None,
        object_id: int = 0,
        block: int = 16,
        max_pairs: int = 1 << 18,
    ) -> None:
        """Mesh from vertices (V, 3) and triangle indices (F, 3); degenerate faces never hit."""
        v = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
        f = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
        if f.size == 0 or f.min() < 0 or f.max() >= v.shape[0]:
            raise ValueError("faces must index vertices and be non-empty")
        if not np.all(np.isfinite(v)):
            raise ValueError("vertices must be finite")
        tri = v[f]  # (F, 3, 3)
        order = np.argsort(_morton(tri.mean(axis=1), v.min(axis=0), v.max(axis=0)), kind="stable")
        self.face_index = order  # sorted position -> original face index
        tri = tri[order]
        self.v0, self.e1, self.e2 = tri[:, 0], tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
        soa = [np.ascontiguousarray(x.T) for x in (self.v0, self.e1, self.e2)]
        self._v0t, self._e1t, self._e2t = soa  # (3, F) each, for the leaf tests
        n = np.cross(self.e1, self.e2)
        ln = np.linalg.norm(n, axis=1, keepdims=True)
        self.face_normal = np.where(ln > 0, n / np.where(ln > 0, ln, 1), 0.0)
        self.uvs = None if uvs is None else np.asarray(uvs, np.float64).reshape(-1, 3, 2)[order]
        self.color = _rgba(color)
        self.object_id = int(object_id)
        self.block, self.max_pairs = int(block), int(max_pairs)
        starts = np.arange(0, len(order), self.block)
        block_lo = np.minimum.reduceat(tri.min(axis=1), starts, axis=0)
        block_hi = np.maximum.reduceat(tri.max(axis=1), starts, axis=0)
        self._build_tree(block_lo, block_hi)
        self.bounds = (block_lo.min(axis=0), block_hi.max(axis=0))

    def _build_tree(self, block_lo: np.ndarray, block_hi: np.ndarray) -> None:
        """Binary tree over contiguous block ranges (Morton order keeps ranges compact)."""
        lo, hi, kids, leaf = [], [], [], []

        def build(i: int, j: int) -> int:
            node = len(lo)
            lo.append(block_lo[i:j].min(axis=0))
            hi.append(block_hi[i:j].max(axis=0))
            kids.append((-1, -1))
            leaf.append(i if j - i == 1 else -1)
            if j - i > 1:
                mid = (i + j) // 2
                kids[node] = (build(i, mid), build(mid, j))
            return node

        build(0, block_lo.shape[0])
        pad = 1e-9 * (1.0 + float(np.abs(np.concatenate([block_lo, block_hi])).max()))
        self._node_lo, self._node_hi = np.array(lo) - pad, np.array(hi) + pad  # rounding
        self._node_kids, self._node_leaf = kids, leaf

    @property
    def n_faces(self) -> int:
        """Number of triangles."""
        return self.v0.shape[0]

    def _hit(self, a, b):
        n = a.shape[0]
        d = b - a
        with np.errstate(divide="ignore"):
            inv_d = 1.0 / d
        best = (np.full(n, _INF), np.full(n, -1, np.int64), np.zeros(n), np.zeros(n))
        stack = [(0, np.arange(n))]
        while stack:
            node, rows = stack.pop()
            enter = _slab(a[rows], inv_d[rows], self._node_lo[node], self._node_hi[node])
            rows = rows[enter < best[0][rows]]
            if rows.size == 0:
                continue
            if self._node_leaf[node] >= 0:
                self._leaf(a, d, rows, self._node_leaf[node], best)
                continue
            left, right = self._node_kids[node]
            mean_d = d[rows].sum(axis=0)
            centre = 0.5 * (self._node_lo + self._node_hi)
            if (centre[left] - centre[right]) @ mean_d > 0:
                left, right = right, left  # visit the nearer child first (pushed last)
            stack += [(right, rows), (left, rows)]
        t, fi, bu, bv = best
        rows = np.flatnonzero(np.isfinite(t))
        t, fi, bu, bv = t[rows], fi[rows], bu[rows], bv[rows]
        p = a[rows] + t[:, None] * d[rows]
        if self.uvs is None:
            uv = np.stack([bu, bv], axis=1)
        else:
            c = self.uvs[fi]
            uv = (1 - bu - bv)[:, None] * c[:, 0] + bu[:, None] * c[:, 1] + bv[:, None] * c[:, 2]
        return rows, t, p, self.face_normal[fi], uv

    def _leaf(self, a, d, rows, blk: int, best) -> None:
        """Test segments ``rows`` against one block of triangles; update ``best`` in place."""
        faces = np.arange(blk * self.block, min((blk + 1) * self.block, self.n_faces))
        step = max(1, self.max_pairs // faces.size)
        for r0 in range(0, rows.size, step):
            r = rows[r0 : r0 + step]
            t, fi, bu, bv = self._nearest(a[r], d[r], faces)
            better = t < best[0][r]
            rb = r[better]
            best[0][rb], best[1][rb] = t[better], fi[better]
            best[2][rb], best[3][rb] = bu[better], bv[better]

    def _nearest(self, a, d, faces):
        """Moller-Trumbore for segments a + t d (S,) x faces (F,): nearest t, face, (u, v)."""
        dx, dy, dz = (d[:, k : k + 1] for k in range(3))  # (S, 1) each
        e1x, e1y, e1z = self._e1t[:, faces]  # (F,) each
        e2x, e2y, e2z = self._e2t[:, faces]
        px, py, pz = dy * e2z - dz * e2y, dz * e2x - dx * e2z, dx * e2y - dy * e2x
        det = e1x * px + e1y * py + e1z * pz
        ok = np.abs(det) > 1e-300
        inv = 1.0 / np.where(ok, det, 1.0)
        v0 = self._v0t[:, faces]
        tx, ty, tz = (a[:, k : k + 1] - v0[k] for k in range(3))
        bu = (tx * px + ty * py + tz * pz) * inv
        qx, qy, qz = ty * e1z - tz * e1y, tz * e1x - tx * e1z, tx * e1y - ty * e1x
        bv = (dx * qx + dy * qy + dz * qz) * inv
        t = (e2x * qx + e2y * qy + e2z * qz) * inv
        ok &= (bu >= 0) & (bv >= 0) & (bu + bv <= 1) & (t >= 0) & (t <= 1)
        t = np.where(ok, t, _INF)
        j = np.argmin(t, axis=1)
        s = np.arange(a.shape[0])
        return t[s, j], faces[j], bu[s, j], bv[s, j]


# -- groups --------------------------------------------------------------------------------------


class Group:
    """The nearest hit over member intersectors, each sent only the segments near its bounds.

    Object ids: member k reports ``ids[k]`` (default: k, its position in the list).
    """

    def __init__(self, objects: Sequence[Any], ids: Sequence[int] | None = None) -> None:
        """Group of intersectors (anything with ``bounds`` and ``intersect``)."""
        self.objects = list(objects)
        self.ids = list(range(len(self.objects))) if ids is None else [int(i) for i in ids]
        if len(self.ids) != len(self.objects):
            raise ValueError("ids must have one entry per object")
        if self.objects:
            lo = np.min([np.asarray(o.bounds[0], np.float64) for o in self.objects], axis=0)
            hi = np.max([np.asarray(o.bounds[1], np.float64) for o in self.objects], axis=0)
        else:
            lo, hi = np.full(3, _INF), np.full(3, -_INF)
        self.bounds = (lo, hi)

    def intersect(self, a: np.ndarray, b: np.ndarray) -> Hits:
        """Nearest hit of each segment a -> b (N, 3) over all members."""
        a, b = _segments(a, b)
        out = Hits.miss(a.shape[0])
        for obj, oid in zip(self.objects, self.ids, strict=True):
            rows = np.flatnonzero(segment_overlaps(a, b, *obj.bounds))
            if rows.size:
                out.merge(rows, obj.intersect(a[rows], b[rows]), oid)
        return out


# -- textures ------------------------------------------------------------------------------------


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


# -- volumes ---------------------------------------------------------------------------------


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

"""Triangle meshes: a BVH over Morton-ordered blocks of triangles, Möller–Trumbore leaves."""

from __future__ import annotations

from typing import Any

import numpy as np

from .boxtree import morton
from .hits import _INF, slab_entry
from .primitives import _Primitive
from .textures import _rgba


def barycentric_gradients(e1: np.ndarray, e2: np.ndarray) -> np.ndarray:
    """(F, 2, 3) per triangle of edges e1 = v1 − v0, e2 = v2 − v0 (F, 3): the rows that take
    p − v0 to the barycentric weights (w1, w2) of its projection on the triangle's plane
    (zero rows for a degenerate triangle)."""
    d11, d12, d22 = (np.einsum("ij,ij->i", u, v) for u, v in ((e1, e1), (e1, e2), (e2, e2)))
    den = d11 * d22 - d12 * d12
    den = np.where(den == 0.0, 1.0, den)[:, None]
    return np.stack(
        [
            (d22[:, None] * e1 - d12[:, None] * e2) / den,
            (d11[:, None] * e2 - d12[:, None] * e1) / den,
        ],
        axis=1,
    )


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
        order = np.argsort(morton(tri.mean(axis=1), v.min(axis=0), v.max(axis=0)), kind="stable")
        self.face_index = order  # sorted position -> original face index
        tri = tri[order]
        self.v0, self.e1, self.e2 = tri[:, 0], tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
        soa = [np.ascontiguousarray(x.T) for x in (self.v0, self.e1, self.e2)]
        self._v0t, self._e1t, self._e2t = soa  # (3, F) each, for the leaf tests
        n = np.cross(self.e1, self.e2)
        ln = np.linalg.norm(n, axis=1, keepdims=True)
        self.face_normal = np.where(ln > 0, n / np.where(ln > 0, ln, 1), 0.0)
        self._gradients = barycentric_gradients(self.e1, self.e2)
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
        lo: list[np.ndarray] = []
        hi: list[np.ndarray] = []
        kids: list[tuple[int, int]] = []
        leaf: list[int] = []

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

    def nearest_faces(self, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, ...]:
        """(rows, t, faces): the segments a -> b (N, 3) that hit, where along them (0..1)
        and which face (index into the faces given), nearest first: the bare hit, without
        colour or uv (the add-on's mesh intersector colours its own)."""
        rows, t, *_, fi = self._hit(np.asarray(a, np.float64), np.asarray(b, np.float64))
        return rows, t, self.face_index[fi]

    def _hit(self, a, b):
        n = a.shape[0]
        d = b - a
        with np.errstate(divide="ignore"):
            inv_d = 1.0 / d
        best = (np.full(n, _INF), np.full(n, -1, np.int64), np.zeros(n), np.zeros(n))
        stack = [(0, np.arange(n))]
        while stack:
            node, rows = stack.pop()
            enter = slab_entry(a[rows], inv_d[rows], self._node_lo[node], self._node_hi[node])
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
        return rows, t, p, self.face_normal[fi], uv, fi

    def _uv_derivatives(self, p, n, dp, part):
        weights = np.einsum("mij,mkj->mik", self._gradients[part], dp)  # (M, 2 weights, 2)
        if self.uvs is None:
            return weights
        c = self.uvs[part]
        edges = np.stack([c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]], axis=2)  # (M, 2 uv, 2 weights)
        return edges @ weights

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

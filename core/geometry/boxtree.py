"""A bounding-volume hierarchy over boxes, queried by whole batches of segments at once.

Boxes are sorted by the Morton code of their centres and cut into leaves of ``LEAF`` boxes;
an implicit complete binary tree (level l has 2**l nodes, node k's children are 2k and
2k + 1) holds each node's box. A query walks the tree level by level with array
operations over (segment, node) pairs, no Python loop over segments or nodes, so its cost
grows with the depth, log2(boxes / LEAF), and with the nodes each segment passes through.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .hits import segment_overlaps, slab_span

LEAF = 4
"""Boxes per leaf."""
PAD = 1e-9
"""Boxes are widened by PAD (1 + |segment start| + |box|) (max-norms) in the slab tests:
more than their rounding (a few ulp of those sizes), so a segment that reaches a box is
never lost to it."""
WINDOW = 8
"""Leaves a window of a segment crosses, about (BoxTree.window)."""
PAIRS = 1 << 20
"""(segment, node) pairs tested at once at most: segments are queried in chunks."""


def morton(points: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """30-bit Morton codes of points (N, 3) quantised to a 1024^3 grid over [lo, hi]."""
    span = np.where(hi > lo, hi - lo, 1.0)
    q = np.clip(((points - lo) / span * 1023.0).astype(np.int64), 0, 1023)
    code = np.zeros(points.shape[0], dtype=np.int64)
    for bit in range(10):
        for axis in range(3):
            code |= ((q[:, axis] >> bit) & 1) << (3 * bit + axis)
    return code


class BoxTree:
    """BVH over finite boxes (lo, hi) (M >= 1, 3) each; ``pairs`` finds, for a batch of
    segments, every (segment, box) whose segment passes through the box and whose own
    bounds overlap it (core.geometry.hits.segment_overlaps: the brute-force test)."""

    def __init__(self, lo: np.ndarray, hi: np.ndarray) -> None:
        """Tree over boxes [lo[i], hi[i]] (finite, lo <= hi)."""
        lo, hi = (
            np.asarray(lo, np.float64).reshape(-1, 3),
            np.asarray(hi, np.float64).reshape(-1, 3),
        )
        centre = 0.5 * (lo + hi)
        order = np.argsort(morton(centre, centre.min(axis=0), centre.max(axis=0)), kind="stable")
        leaves = 1 << max(0, int(np.ceil(np.log2(max(1, -(-len(order) // LEAF))))))
        slots = leaves * LEAF
        self.member = np.full(slots, -1, np.int64)  # slot -> box index (-1: empty)
        self.member[: len(order)] = order
        fill = np.concatenate([order, np.full(slots - len(order), order[-1])])
        self.lo, self.hi = lo[fill], hi[fill]  # empty slots repeat the last box
        self.size = _size(self.lo, self.hi)
        self.levels = _levels(self.lo.reshape(leaves, LEAF, 3).min(axis=1),
                              self.hi.reshape(leaves, LEAF, 3).max(axis=1))  # fmt: skip
        leaf = np.linalg.norm(self.levels[-1][1] - self.levels[-1][0], axis=1)
        root = float(np.linalg.norm(self.levels[0][1] - self.levels[0][0]))
        self.window = max(WINDOW * float(np.median(leaf)), root / 64, 1e-300)
        """A length (world units) of segment queried at once: about WINDOW leaves, at most
        64 windows across the whole tree (core.geometry.group walks long segments window
        by window, nearest first, and stops each where it has hit)."""

    def segments(self, a: np.ndarray, b: np.ndarray) -> Segments:
        """Segments a -> b (N, 3) made ready for queries (``pairs``)."""
        with np.errstate(divide="ignore"):
            inv_d = 1.0 / (b - a)
        reach = PAD * (1.0 + np.abs(a).max(axis=1, initial=0.0))
        return Segments(a, b, inv_d, reach)

    def span(self, seg: Segments) -> tuple[np.ndarray, np.ndarray]:
        """(enter, leave) (N,) of each segment in the root's box (enter > leave: misses it)."""
        lo, hi, size = self.levels[0]
        rows = np.arange(seg.a.shape[0])
        return _span(seg, rows, lo[np.zeros_like(rows)], hi[np.zeros_like(rows)], size[0])

    def pairs(
        self, seg: Segments, rows: np.ndarray, t_from: np.ndarray, t_to: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """(rows, boxes): each segment ``rows`` (M,) with each box its part [t_from, t_to]
        (M,) passes through and whose bounds overlap the box, sorted by box, then row."""
        chunk = max(1, PAIRS // (2 * LEAF * len(self.levels)))
        found = [self._pairs(seg, rows[s : s + chunk], t_from[s : s + chunk], t_to[s : s + chunk])
                 for s in range(0, rows.size, chunk)]  # fmt: skip
        rows = np.concatenate([f[0] for f in found]) if found else np.zeros(0, np.int64)
        boxes = np.concatenate([f[1] for f in found]) if found else np.zeros(0, np.int64)
        order = np.lexsort((rows, boxes))
        return rows[order], boxes[order]

    def _pairs(self, seg: Segments, rows, t_from, t_to) -> tuple[np.ndarray, np.ndarray]:
        """The pairs of the segments ``rows``, walking the tree level by level."""
        nodes, part = np.zeros(rows.size, np.int64), np.arange(rows.size)
        for depth, (lo, hi, size) in enumerate(self.levels):
            if depth:
                part, nodes = np.repeat(part, 2), (2 * nodes[:, None] + (0, 1)).ravel()
            enter, leave = _span(seg, rows[part], lo[nodes], hi[nodes], size[nodes])
            keep = np.maximum(enter, t_from[part]) <= np.minimum(leave, t_to[part])
            part, nodes = part[keep], nodes[keep]
        part = np.repeat(part, LEAF)
        slots = (LEAF * nodes[:, None] + np.arange(LEAF)).ravel()
        lo, hi, r = self.lo[slots], self.hi[slots], rows[part]
        enter, leave = _span(seg, r, lo, hi, self.size[slots])
        keep = (np.maximum(enter, t_from[part]) <= np.minimum(leave, t_to[part])) & (
            self.member[slots] >= 0
        )
        keep[keep] = segment_overlaps(seg.a[r[keep]], seg.b[r[keep]], lo[keep], hi[keep])
        return r[keep], self.member[slots[keep]]


class Segments(NamedTuple):
    """A batch of segments a -> b (N, 3) for BoxTree queries: 1 / (b - a) and each one's
    rounding margin (PAD (1 + |a|))."""

    a: np.ndarray
    b: np.ndarray
    inv_d: np.ndarray
    reach: np.ndarray


def _size(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(M,) PAD times (1 + the largest finite |coordinate| of each box): its widening."""
    ends = np.where(np.isfinite(lo), np.abs(lo), 0.0), np.where(np.isfinite(hi), np.abs(hi), 0.0)
    return PAD * (1.0 + np.maximum(*ends).max(axis=1))


def _levels(lo: np.ndarray, hi: np.ndarray) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """(lo, hi, widening) of every level's nodes, the root's first, from the leaves'."""
    levels = [(lo, hi)]
    while levels[0][0].shape[0] > 1:
        lo, hi = levels[0]
        levels.insert(0, (np.minimum(lo[0::2], lo[1::2]), np.maximum(hi[0::2], hi[1::2])))
    return [(lo, hi, _size(lo, hi)) for lo, hi in levels]


def _span(seg: Segments, rows, lo, hi, size) -> tuple[np.ndarray, np.ndarray]:
    """(enter, leave) (P,) of segment ``rows[i]`` in box i widened by its and the segment's
    rounding margins (PAD), within [0, 1] (enter > leave: it misses the box)."""
    pad = (seg.reach[rows] + size)[:, None]
    return slab_span(seg.a[rows], seg.inv_d[rows], lo - pad, hi + pad)

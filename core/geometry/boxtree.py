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

from .hits import segment_overlaps

LEAF = 4
"""Boxes per leaf."""
PAD = 1e-9
"""Boxes are widened by PAD (1 + |segment start| + |box|) (max-norms) in the slab tests:
more than their rounding (a few ulp of those sizes), so a segment that reaches a box is
never lost to it."""
WINDOW = 4
"""Leaves a window of a segment crosses, about (BoxTree.window, BoxTree.windows)."""
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
        self.padded = _padded(self.lo, self.hi)
        leaf_lo = self.lo.reshape(leaves, LEAF, 3).min(axis=1)
        leaf_hi = self.hi.reshape(leaves, LEAF, 3).max(axis=1)
        self.levels = _levels(leaf_lo, leaf_hi)
        leaf = float(np.median(np.linalg.norm(leaf_hi - leaf_lo, axis=1)))
        root = float(np.linalg.norm(leaf_hi.max(axis=0) - leaf_lo.min(axis=0)))
        self.window = max(WINDOW * leaf, root / 64, 1e-300)
        """A length (world units) of segment queried at once: about WINDOW leaves, at most
        64 windows across the whole tree (``windows`` walks long segments window by
        window, nearest first, and stops each where it has hit)."""

    def span(self, seg: Segments) -> tuple[np.ndarray, np.ndarray]:
        """(enter, leave) (N,) of each segment in the root's box (enter > leave: misses it)."""
        n = seg.a.shape[0]
        root = np.zeros(n, np.int64)
        return _span(seg, np.arange(n), self.levels[0], root, np.zeros(n), np.ones(n))

    def windows(self, seg: Segments, hit_t: np.ndarray, rows: np.ndarray | None = None):
        """Yield (rows, boxes) (``pairs``) window by window along the segments (``rows``,
        default all), nearest first, about ``window`` long each; a segment goes on while
        ``hit_t`` (N,), its nearest hit so far, which the caller lowers in place between
        windows, lies beyond the window's end."""
        enter, leave = self.span(seg)
        rows = np.arange(enter.size) if rows is None else rows
        todo = rows[enter[rows] <= leave[rows]]
        length = np.linalg.norm(seg.b - seg.a, axis=1)
        step = self.window / np.maximum(length, 1e-300)
        start = enter.copy()
        while todo.size:
            ahead = np.maximum(start[todo] + step[todo], np.nextafter(start[todo], 2.0))
            stop = np.minimum(ahead, leave[todo])
            yield self.pairs(seg, todo, start[todo], np.minimum(stop, hit_t[todo]))
            going = (hit_t[todo] > stop) & (stop < leave[todo])  # nothing hit up to its end
            start[todo[going]] = stop[going]
            todo = todo[going]

    def pairs(
        self, seg: Segments, rows: np.ndarray, t_from: np.ndarray, t_to: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """(rows, boxes): each segment ``rows`` (M,) with each box its part [t_from, t_to]
        (M,) passes through and whose bounds overlap the box, each pair once, unsorted."""
        chunk = max(1, PAIRS // (2 * LEAF * len(self.levels)))
        found = [self._pairs(seg, rows[s : s + chunk], t_from[s : s + chunk], t_to[s : s + chunk])
                 for s in range(0, rows.size, chunk)]  # fmt: skip
        rows = np.concatenate([f[0] for f in found]) if found else np.zeros(0, np.int64)
        boxes = np.concatenate([f[1] for f in found]) if found else np.zeros(0, np.int64)
        return rows, boxes

    def _pairs(self, seg: Segments, rows, t_from, t_to) -> tuple[np.ndarray, np.ndarray]:
        """The pairs of the segments ``rows``, walking the tree level by level."""
        nodes, part = np.zeros(rows.size, np.int64), np.arange(rows.size)
        for depth, level in enumerate(self.levels):
            if depth:
                part, nodes = np.repeat(part, 2), (2 * nodes[:, None] + (0, 1)).ravel()
            keep = _meets(seg, rows[part], level, nodes, t_from[part], t_to[part])
            part, nodes = part[keep], nodes[keep]
        part = np.repeat(part, LEAF)
        slots = (LEAF * nodes[:, None] + np.arange(LEAF)).ravel()
        r = rows[part]
        keep = _meets(seg, r, self.padded, slots, t_from[part], t_to[part])
        keep &= self.member[slots] >= 0
        lo, hi = self.lo[slots[keep]], self.hi[slots[keep]]
        keep[keep] = segment_overlaps(seg.a[r[keep]], seg.b[r[keep]], lo, hi)
        return r[keep], self.member[slots[keep]]


def _by_axis(reduce, x: np.ndarray) -> np.ndarray:
    """(3,) ``reduce`` (np.min, np.max) of each column of x (M, 3), column by column
    (numpy's reductions of a 2-D array along either axis run ~10x slower)."""
    return np.array([reduce(column) for column in x.T])


def segments(a: np.ndarray, b: np.ndarray) -> Segments:
    """Segments a -> b (N, 3) made ready for queries (BoxTree.pairs, BoxGrid.pairs)."""
    d = b - a
    with np.errstate(divide="ignore"):
        inv_d = 1.0 / d
    reach = PAD * (1.0 + np.abs(a).max(axis=1, initial=0.0))
    axes = np.ascontiguousarray
    return Segments(a, b, axes(a.T), axes(inv_d.T), reach, axes(d.T))


class Segments(NamedTuple):
    """A batch of segments a -> b (N, 3) for BoxTree queries: a and 1 / (b - a) by axis
    (3, N), each one's rounding margin (PAD (1 + |a|)) and b - a by axis (3, N)."""

    a: np.ndarray
    b: np.ndarray
    a_axes: np.ndarray
    inv_axes: np.ndarray
    reach: np.ndarray
    d_axes: np.ndarray


def _padded(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Boxes (M, 3) widened by PAD (1 + their largest |coordinate|), by axis (3, M) each."""
    size = PAD * (1.0 + np.maximum(np.abs(lo), np.abs(hi)).max(axis=1))
    return np.ascontiguousarray((lo - size[:, None]).T), np.ascontiguousarray(
        (hi + size[:, None]).T
    )


def _levels(lo: np.ndarray, hi: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """Every level's nodes' boxes (``_padded``), the root's first, from the leaves'."""
    levels = [(lo, hi)]
    while levels[0][0].shape[0] > 1:
        lo, hi = levels[0]
        levels.insert(0, (np.minimum(lo[0::2], lo[1::2]), np.maximum(hi[0::2], hi[1::2])))
    return [_padded(lo, hi) for lo, hi in levels]


def _span(seg: Segments, rows, boxes, nodes, t_from, t_to) -> tuple[np.ndarray, np.ndarray]:
    """(enter, leave) (P,) of the part [t_from, t_to] of segment ``rows[i]`` in box
    ``nodes[i]`` of ``boxes`` (``_padded``) widened by the segment's margin (enter > leave:
    it misses the box; a slab test as core.geometry.hits.slab_span, axis by axis)."""
    pad = seg.reach.take(rows)
    enter, leave = t_from, t_to
    with np.errstate(invalid="ignore", over="ignore"):
        for k in range(3):  # 1-D gathers by take: the cheapest at every batch size measured
            a, inv = seg.a_axes[k].take(rows), seg.inv_axes[k].take(rows)
            t1 = (boxes[0][k].take(nodes) - pad - a) * inv
            t2 = (boxes[1][k].take(nodes) + pad - a) * inv
            enter = np.fmax(enter, np.fmin(t1, t2))  # fmin/fmax skip 0 * inf's NaN
            leave = np.fmin(leave, np.fmax(t1, t2))
    return enter, leave


def _meets(seg: Segments, rows, boxes, nodes, t_from, t_to) -> np.ndarray:
    """(P,) bool: the part [t_from, t_to] of segment ``rows[i]`` meets box ``nodes[i]``."""
    enter, leave = _span(seg, rows, boxes, nodes, t_from, t_to)
    return enter <= leave

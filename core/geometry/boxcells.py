"""Which of a batch of boxes overlap any of many boxes, exactly, at once.

``ManyBoxes(lo, hi)`` answers ``meets(low, high)``: for each query box [low, high], whether
it overlaps one of the boxes, as testing every box in turn would (hits.segment_overlaps:
touching counts). Two steps, both whole-batch array operations:

- ``BoxCells``: the boxes' union cut into CELLS cells an axis, each cell marked where a box
  overlaps it; a query meeting no marked cell (a 3-D prefix sum: eight lookups) meets no
  box. Conservative (cells widened by EPS of a cell against rounding).
- a sweep: the boxes sorted by their low side along each axis; a query's candidates along
  an axis are those whose low side lies within [its low - the widest width, its high] (two
  searchsorted); it is swept along the axis where it has the fewest, each tested exactly.
  Boxes wider than WIDE x the median width are tested apart (else the sweep's candidates
  would be every box): one by one, or swept among themselves where there are many.

Used where a step is near geometry by many objects' own boxes (core.tracing.near_geometry).
"""

from __future__ import annotations

import numpy as np

CELLS = 64
"""Cells along each axis of the boxes' union (64^3: 2 MB of prefix sums)."""
EPS = 1e-6
"""Cell indices are taken this share of a cell wider on both sides (rounding)."""
WIDE = 4.0
"""Boxes wider than this many median widths (on the sweep's axis) are tested one by one."""
FEW = 16
"""Up to this many wide boxes are tested one by one; more are swept apart (their own
ManyBoxes: fewer than half the boxes each time)."""
PAIRS = 1 << 18
"""Candidate pairs tested at once at most (memory bounded)."""
QUERY_CELLS = 64
"""A query over at most this many cells meets the boxes listed in them (_CellLists); a
larger one is swept."""
REFS = 8
"""Cell lists hold each box in every cell it overlaps, up to REFS entries a box on average
(more: no lists, every query swept)."""


class BoxCells:
    """Cells over finite boxes [lo[k], hi[k]] (K >= 1, 3) marked where a box overlaps them."""

    def __init__(self, lo: np.ndarray, hi: np.ndarray, cells: int = CELLS) -> None:
        """Mark the cells (``cells`` an axis over the union; one on an axis of no extent)."""
        lo, hi = (np.asarray(x, np.float64).reshape(-1, 3) for x in (lo, hi))
        self.origin, self.top = lo.min(axis=0), hi.max(axis=0)
        extent = self.top - self.origin
        self.shape = np.where(extent > 0, cells, 1).astype(np.int64)
        self.size = np.where(extent > 0, extent / self.shape, 1.0)
        i0, i1 = self._index(lo.T, -EPS), self._index(hi.T, EPS)
        marks = np.zeros(tuple(self.shape + 1), np.int64)  # a difference array of the boxes
        for corner in range(8):
            pick = [(corner >> axis) & 1 for axis in range(3)]
            at = tuple(i1[k] + 1 if pick[k] else i0[k] for k in range(3))
            np.add.at(marks, at, -1 if sum(pick) % 2 else 1)
        covered = marks.cumsum(axis=0).cumsum(axis=1).cumsum(axis=2)[:-1, :-1, :-1] > 0
        self.prefix = np.zeros(tuple(self.shape + 1), np.int64)
        """Marked cells below each corner: prefix[i, j, k] counts cells [0, i) x [0, j) x
        [0, k)."""
        self.prefix[1:, 1:, 1:] = covered.cumsum(axis=0).cumsum(axis=1).cumsum(axis=2)

    def _index(self, x: np.ndarray, shift: float) -> np.ndarray:
        """(3, M) the cells of points x (3, M), shifted by ``shift`` cells, within the grid."""
        at = (x - self.origin[:, None]) / self.size[:, None] + shift
        return np.clip(np.floor(at), 0, self.shape[:, None] - 1).astype(np.int64)

    def meets(self, low: np.ndarray, high: np.ndarray) -> np.ndarray:
        """(M,) whether each box [low[:, m], high[:, m]] (3, M each) overlaps a marked cell."""
        inside = np.all((high >= self.origin[:, None]) & (low <= self.top[:, None]), axis=0)
        j0, j1 = self._index(low, -EPS), self._index(high, EPS) + 1
        count = np.zeros(low.shape[1], np.int64)
        flat = self.prefix.reshape(-1)
        stride = (self.prefix.shape[1] * self.prefix.shape[2], self.prefix.shape[2], 1)
        for corner in range(8):
            pick = [(corner >> axis) & 1 for axis in range(3)]
            at = sum((j1[k] if pick[k] else j0[k]) * stride[k] for k in range(3))
            term = flat.take(at)
            count += term if (3 - sum(pick)) % 2 == 0 else -term
        return inside & (count > 0)


class ManyBoxes:
    """Finite boxes [lo[k], hi[k]] (K >= 1, 3): ``meets`` as testing each in turn, at once."""

    def __init__(self, lo: np.ndarray, hi: np.ndarray) -> None:
        """Index the boxes: their cells, a sweep along each axis, the wide ones apart."""
        lo, hi = (np.asarray(x, np.float64).reshape(-1, 3) for x in (lo, hi))
        self.cells = BoxCells(lo, hi)
        width = hi - lo
        wide = np.any(width > WIDE * np.median(width, axis=0), axis=1)
        if 2 * np.count_nonzero(wide) > wide.size:  # no fewer apart: sweep them all
            wide[:] = False
        self.wide: list[tuple[np.ndarray, np.ndarray]] | ManyBoxes = (
            list(zip(lo[wide], hi[wide], strict=True))
            if np.count_nonzero(wide) <= FEW
            else ManyBoxes(lo[wide], hi[wide])
        )
        """The wide boxes: up to FEW, (lo, hi) each, tested one by one; more, swept apart."""
        narrow = np.flatnonzero(~wide)
        scale = float(np.abs(np.concatenate([lo, hi])).max())
        self.sweeps = [_Sweep(lo[narrow], hi[narrow], k, scale) for k in range(3)]
        """The other boxes, sorted along each axis: a query over many cells is swept along
        the axis where it has the fewest candidates ..."""
        self.lists = _CellLists(self.cells, lo[narrow], hi[narrow])
        """... one over few, tested against the boxes listed in its cells."""

    def meets(self, low: np.ndarray, high: np.ndarray) -> np.ndarray:
        """(M,) whether each box [low[:, m], high[:, m]] (3, M each) overlaps one of the
        boxes (touching counts)."""
        out = np.zeros(low.shape[1], bool)
        rows = np.flatnonzero(self.cells.meets(low, high))
        if rows.size == 0:
            return out
        low, high = low[:, rows], high[:, rows]
        found = np.zeros(rows.size, bool)
        if isinstance(self.wide, ManyBoxes):
            found |= self.wide.meets(low, high)
        else:
            for lo, hi in self.wide:
                found |= np.all((low <= hi[:, None]) & (high >= lo[:, None]), axis=0)
        if self.sweeps[0].lo.shape[1] == 0:
            out[rows] = found
            return out
        few = self.lists.few_cells(low, high)
        if few.any():
            found[few] |= self.lists.meets(low[:, few], high[:, few])
            rest = np.flatnonzero(~few)
            found[rest] |= self._swept(low[:, rest], high[:, rest])
        else:
            found |= self._swept(low, high)
        out[rows] = found
        return out

    def _swept(self, low: np.ndarray, high: np.ndarray) -> np.ndarray:
        """(M,) whether each query meets one of the swept boxes, each query swept along
        the axis where it has the fewest candidates."""
        found = np.zeros(low.shape[1], bool)
        if low.shape[1]:
            spans = [sweep.candidates(low, high) for sweep in self.sweeps]
            best = np.argmin(np.stack([count for _, count in spans]), axis=0)
            for sweep, (first, count), k in zip(self.sweeps, spans, range(3), strict=True):
                pick = np.flatnonzero(best == k)
                if pick.size:
                    found[pick] |= sweep.meets(low[:, pick], high[:, pick], first[pick],
                                               count[pick])  # fmt: skip
        return found


class _Sweep:
    """Boxes (lo, hi) (K, 3) sorted by their low side along ``axis``."""

    def __init__(self, lo: np.ndarray, hi: np.ndarray, axis: int, scale: float) -> None:
        """Sort them (``scale``: the largest coordinate's size, for rounding)."""
        order = np.argsort(lo[:, axis], kind="stable")
        self.axis = axis
        self.lo, self.hi = lo[order].T.copy(), hi[order].T.copy()  # (3, K) sorted
        most = float((hi[:, axis] - lo[:, axis]).max()) if lo.size else 0.0
        self.reach = most * (1 + 1e-9) + 1e-12 * scale
        """The widest box's width on the axis (and a hair for rounding): a query's
        candidates start there."""

    def candidates(self, low: np.ndarray, high: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(first, count) (M,): each query's candidates, the boxes from ``first`` on whose
        low side lies within [its low - reach, its high] on the axis."""
        key = self.lo[self.axis]
        first = np.searchsorted(key, low[self.axis] - self.reach, side="left")
        last = np.searchsorted(key, high[self.axis], side="right")
        return first, np.maximum(last - first, 0)

    def meets(self, low, high, first: np.ndarray, count: np.ndarray) -> np.ndarray:
        """(M,) whether each query (low, high (3, M)) overlaps one of its ``count``
        candidates from ``first`` on, each tested exactly, PAIRS at a time at most."""
        found = np.zeros(first.size, bool)
        ends, start = np.cumsum(count), 0
        while start < first.size:  # chunks of at most PAIRS candidates (or one query)
            top = ends[start] - count[start] + PAIRS
            stop = max(start + 1, int(np.searchsorted(ends, top, side="right")))
            part = slice(start, stop)
            found[part] = self._pairs(low[:, part], high[:, part], first[part], count[part])
            start = stop
        return found

    def _pairs(self, low, high, first: np.ndarray, count: np.ndarray) -> np.ndarray:
        """``meets`` for one chunk of queries."""
        query = np.arange(first.size).repeat(count)
        box = np.arange(query.size) - (np.cumsum(count) - count).repeat(count)
        box += first.repeat(count)
        overlap = np.ones(query.size, bool)
        for k in range(3):
            overlap &= (low[k].take(query) <= self.hi[k].take(box)) & (
                high[k].take(query) >= self.lo[k].take(box)
            )
        found = np.zeros(first.size, bool)
        found[query[overlap]] = True
        return found


class _CellLists:
    """Boxes (lo, hi) (K, 3) listed in every cell of ``grid`` (a BoxCells) they overlap
    (``ok``: at most REFS entries a box on average, else no lists)."""

    def __init__(self, grid: BoxCells, lo: np.ndarray, hi: np.ndarray) -> None:
        """List the boxes cell by cell (``start``, ``box``: compressed rows)."""
        self.grid = grid
        self.lo, self.hi = lo.T.copy(), hi.T.copy()  # (3, K)
        self.stride = (int(grid.shape[1] * grid.shape[2]), int(grid.shape[2]), 1)
        i0, i1 = grid._index(self.lo, -EPS), grid._index(self.hi, EPS)
        count = np.prod(i1 - i0 + 1, axis=0)
        self.ok = bool(count.sum() <= REFS * max(1, count.size))
        if not self.ok:
            return
        owner, cell = self._cells(i0, i1)
        order = np.argsort(cell, kind="stable")
        self.box = owner[order]
        """The boxes in each cell, cell by cell."""
        self.start = np.zeros(int(np.prod(grid.shape)) + 1, np.int64)
        np.cumsum(np.bincount(cell, minlength=self.start.size - 1), out=self.start[1:])
        """Where each cell's boxes begin in ``box``."""

    def _cells(self, i0: np.ndarray, i1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(owner, cell): each cell (flat index) of each range [i0, i1] (3, M), with the
        range's position."""
        n = i1 - i0 + 1
        each = n[0] * n[1] * n[2]
        owner = np.arange(each.size).repeat(each)
        j = np.arange(owner.size) - (np.cumsum(each) - each).repeat(each)
        nz, ny = n[2].take(owner), n[1].take(owner)
        dz, j = j % nz, j // nz
        dy, dx = j % ny, j // ny
        cell = (i0[0].take(owner) + dx) * self.stride[0] + (i0[1].take(owner) + dy) * self.stride[1]
        return owner, cell + i0[2].take(owner) + dz

    def few_cells(self, low: np.ndarray, high: np.ndarray) -> np.ndarray:
        """(M,) whether each query box spans at most QUERY_CELLS cells (none without lists)."""
        if not self.ok:
            return np.zeros(low.shape[1], bool)
        j0, j1 = self.grid._index(low, -EPS), self.grid._index(high, EPS)
        return np.prod(j1 - j0 + 1, axis=0) <= QUERY_CELLS

    def meets(self, low: np.ndarray, high: np.ndarray) -> np.ndarray:
        """(M,) whether each query box (over few cells) overlaps a box listed in its cells,
        each tested exactly, PAIRS // QUERY_CELLS queries at a time."""
        found = np.zeros(low.shape[1], bool)
        step = max(1, PAIRS // QUERY_CELLS)
        for start in range(0, low.shape[1], step):
            part = slice(start, start + step)
            found[part] = self._part(low[:, part], high[:, part])
        return found

    def _part(self, low: np.ndarray, high: np.ndarray) -> np.ndarray:
        """``meets`` for one chunk of queries."""
        j0, j1 = self.grid._index(low, -EPS), self.grid._index(high, EPS)
        query, cell = self._cells(j0, j1)
        first = self.start.take(cell)
        count = self.start.take(cell + 1) - first
        query = query.repeat(count)
        ref = np.arange(query.size) - (np.cumsum(count) - count).repeat(count)
        box = self.box.take(ref + first.repeat(count))
        overlap = np.ones(query.size, bool)
        for k in range(3):
            overlap &= (low[k].take(query) <= self.hi[k].take(box)) & (
                high[k].take(query) >= self.lo[k].take(box)
            )
        found = np.zeros(low.shape[1], bool)
        found[query[overlap]] = True
        return found

"""Which of a batch of boxes overlap any of many boxes, exactly, at once.

``ManyBoxes(lo, hi)`` answers ``meets(low, high)``: for each query box [low, high], whether
it overlaps one of the boxes, as testing every box in turn would (hits.segment_overlaps:
touching counts). Two steps, both whole-batch array operations:

- ``BoxCells``: the boxes' union cut into CELLS cells an axis, each cell marked where a box
  overlaps it; a query meeting no marked cell (a 3-D prefix sum: eight lookups) meets no
  box. Conservative (cells widened by EPS of a cell against rounding).
- each query is then tested exactly against the candidates of the cheaper of two lists:
  the boxes listed in each cell it spans (a prefix sum of the lists' lengths counts them
  with the cells), or a sweep: the boxes sorted by their low side along each axis, a
  query's candidates along an axis those whose low side lies within [its low - the widest
  width, its high] (two searchsorted), along the axis where it has the fewest (a query
  over at most FEW_CELLS cells takes its cells' lists unweighed).
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
FEW_CELLS = 64
"""A query over at most this many cells is tested against the boxes listed in them without
weighing a sweep (a small step's common case: no searchsorted)."""
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
        count = _range_sums(self.prefix, j0, j1)
        return inside & (count > 0)


def _range_sums(prefix: np.ndarray, j0: np.ndarray, j1: np.ndarray) -> np.ndarray:
    """(M,) the sums over cell ranges [j0, j1) (3, M each) of a 3-D prefix sum (``prefix``
    [i, j, k]: the sum over cells [0, i) x [0, j) x [0, k)): eight lookups."""
    count = np.zeros(j0.shape[1], np.int64)
    flat = prefix.reshape(-1)
    stride = (prefix.shape[1] * prefix.shape[2], prefix.shape[2], 1)
    for corner in range(8):
        pick = [(corner >> axis) & 1 for axis in range(3)]
        at = sum((j1[k] if pick[k] else j0[k]) * stride[k] for k in range(3))
        term = flat.take(at)
        count += term if (3 - sum(pick)) % 2 == 0 else -term
    return count


class ManyBoxes:
    """Finite boxes [lo[k], hi[k]] (K >= 1, 3): ``meets`` as testing each in turn, at once."""

    def __init__(self, lo: np.ndarray, hi: np.ndarray) -> None:
        """Index the boxes: their cells, a sweep along each axis, the wide ones apart."""
        lo, hi = (np.asarray(x, np.float64).reshape(-1, 3) for x in (lo, hi))
        self.cells = BoxCells(lo, hi)
        self.count = lo.shape[0]
        """How many boxes there are."""
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
        self.wide_index = np.flatnonzero(wide)
        """Their indices among all the boxes."""
        narrow = np.flatnonzero(~wide)
        self.narrow_index = narrow
        """The other boxes' indices (the sweeps' and the cell lists' boxes are these)."""
        scale = float(np.abs(np.concatenate([lo, hi])).max())
        self.sweeps = [_Sweep(lo[narrow], hi[narrow], k, scale) for k in range(3)]
        """The other boxes, sorted along each axis: a query is swept along the axis where
        it has the fewest candidates ..."""
        self.lists = _CellLists(self.cells, lo[narrow], hi[narrow])
        """... or tested against the boxes listed in its cells, where they are fewer."""

    def meets(self, low: np.ndarray, high: np.ndarray) -> np.ndarray:
        """(M,) whether each box [low[:, m], high[:, m]] (3, M each) overlaps one of the
        boxes (touching counts)."""
        out = np.zeros(low.shape[1], bool)
        big = np.flatnonzero(np.all(high - low >= 4.0 * self.cells.size[:, None], axis=0))
        if big.size:  # a box listed in a cell well inside the query (none in a small one)
            out[big] = self.lists.surely_meets(low[:, big], high[:, big])
        rest = np.flatnonzero(~out)
        for query, _ in self._overlaps(low[:, rest], high[:, rest]):
            out[rest[query]] = True
        return out

    def pairs(
        self, low: np.ndarray, high: np.ndarray, owner: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """(query, box): every query box [low[:, m], high[:, m]] (3, M each) and box
        [lo[k], hi[k]] that overlap (touching counts), each pair once, by query; with
        ``owner`` (M,) (ints, queries that are parts of one), (owner, box) pairs instead."""
        found = list(self._overlaps(low, high))
        if not found:
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        query, box = (np.concatenate(x) for x in zip(*found, strict=True))
        if owner is not None:
            query = owner[query]
        key = np.unique(query * np.int64(self.count) + box)  # lists repeat a box per cell
        return key // self.count, key % self.count

    def _overlaps(self, low: np.ndarray, high: np.ndarray):
        """Yield (query, box) arrays of overlapping pairs (boxes by their index; a pair may
        come more than once)."""
        rows = np.flatnonzero(self.cells.meets(low, high))
        if rows.size == 0:
            return
        low, high = low[:, rows], high[:, rows]
        if isinstance(self.wide, ManyBoxes):
            for query, box in self.wide._overlaps(low, high):
                yield rows[query], self.wide_index[box]
        else:
            for box, (lo, hi) in zip(self.wide_index, self.wide, strict=True):
                query = np.flatnonzero(np.all((low <= hi[:, None]) & (high >= lo[:, None]), axis=0))
                yield rows[query], np.full(query.size, box)
        if self.narrow_index.size == 0:
            return
        cost, cells = self.lists.cost(low, high)
        few = np.flatnonzero(cells <= FEW_CELLS)  # listed whatever the sweep holds
        if few.size:
            for query, box in self.lists.overlaps(low[:, few], high[:, few], cost[few]):
                yield rows[few[query]], self.narrow_index[box]
        rest = np.flatnonzero(cells > FEW_CELLS)
        if rest.size:
            for query, box in self._listed_or_swept(low[:, rest], high[:, rest], cost[rest]):
                yield rows[rest[query]], self.narrow_index[box]

    def _listed_or_swept(self, low: np.ndarray, high: np.ndarray, cost: np.ndarray):
        """Yield (query, box) of the narrow boxes: each query tested against the boxes
        listed in its cells (``cost`` (M,): cells and boxes listed) or swept along the axis
        where it has the fewest candidates, whichever are fewer."""
        spans = [sweep.candidates(low, high) for sweep in self.sweeps]
        counts = np.stack([count for _, count in spans])
        listed = cost <= counts.min(axis=0)
        best = np.where(listed, 3, np.argmin(counts, axis=0))
        pick = np.flatnonzero(listed)
        if pick.size:
            for query, box in self.lists.overlaps(low[:, pick], high[:, pick], cost[pick]):
                yield pick[query], box
        for sweep, (first, count), k in zip(self.sweeps, spans, range(3), strict=True):
            pick = np.flatnonzero(best == k)
            if pick.size:
                for query, box in sweep.overlaps(low[:, pick], high[:, pick], first[pick],
                                                 count[pick]):  # fmt: skip
                    yield pick[query], box


class _Sweep:
    """Boxes (lo, hi) (K, 3) sorted by their low side along ``axis``."""

    def __init__(self, lo: np.ndarray, hi: np.ndarray, axis: int, scale: float) -> None:
        """Sort them (``scale``: the largest coordinate's size, for rounding)."""
        order = np.argsort(lo[:, axis], kind="stable")
        self.order = order
        """The boxes' indices, sorted."""
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

    def overlaps(self, low, high, first: np.ndarray, count: np.ndarray):
        """Yield (query, box) of each query (low, high (3, M)) and those of its ``count``
        candidates from ``first`` on it overlaps, each tested exactly, PAIRS at a time at
        most (boxes by their index before sorting)."""
        for part in _parts(count):
            query, box = self._pairs(low[:, part], high[:, part], first[part], count[part])
            yield query + part.start, self.order[box]

    def _pairs(self, low, high, first: np.ndarray, count: np.ndarray):
        """``overlaps`` for one chunk of queries (boxes by their sorted position)."""
        query = np.arange(first.size).repeat(count)
        box = np.arange(query.size) - (np.cumsum(count) - count).repeat(count)
        box += first.repeat(count)
        overlap = _overlap(low, high, query, self.lo, self.hi, box)
        return query[overlap], box[overlap]


def _parts(cost: np.ndarray):
    """Slices of queries whose ``cost`` (M,) (candidates each) sums to PAIRS at most (or
    one query)."""
    ends, start = np.cumsum(cost), 0
    while start < cost.size:
        top = ends[start] - cost[start] + PAIRS
        stop = max(start + 1, int(np.searchsorted(ends, top, side="right")))
        yield slice(start, stop)
        start = stop


def _overlap(low, high, query: np.ndarray, lo, hi, box: np.ndarray) -> np.ndarray:
    """(P,) whether query boxes [low, high] (3, M) ``query`` and boxes [lo, hi] (3, K)
    ``box`` overlap, pair by pair (touching counts)."""
    overlap = np.ones(query.size, bool)
    for k in range(3):
        overlap &= low[k].take(query) <= hi[k].take(box)
        overlap &= high[k].take(query) >= lo[k].take(box)
    return overlap


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
        per_cell = np.bincount(cell, minlength=int(np.prod(grid.shape)))
        self.start = np.zeros(per_cell.size + 1, np.int64)
        np.cumsum(per_cell, out=self.start[1:])
        """Where each cell's boxes begin in ``box``."""
        self.prefix = np.zeros(tuple(grid.shape + 1), np.int64)
        """Boxes listed in the cells below each corner (as BoxCells.prefix)."""
        listed = per_cell.reshape(tuple(grid.shape))
        self.prefix[1:, 1:, 1:] = listed.cumsum(axis=0).cumsum(axis=1).cumsum(axis=2)

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

    def cost(self, low: np.ndarray, high: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(M,) (cost, cells): the cells each query box spans and the boxes listed in them,
        and the cells alone (the largest int64 each without lists)."""
        if not self.ok:
            most = np.full(low.shape[1], np.iinfo(np.int64).max)
            return most, most
        j0, j1 = self.grid._index(low, -EPS), self.grid._index(high, EPS) + 1
        cells = np.prod(j1 - j0, axis=0)
        return _range_sums(self.prefix, j0, j1) + cells, cells

    def surely_meets(self, low: np.ndarray, high: np.ndarray) -> np.ndarray:
        """(M,) whether a box is listed in a cell that lies inside the query box by a cell
        or more (then that box, which meets its cell widened by EPS, meets the query: a
        long step through a crowd is answered by eight lookups, not hundreds of tests);
        False where unsure, and without lists."""
        if not self.ok:
            return np.zeros(low.shape[1], bool)
        j0 = np.minimum(self.grid._index(low, -EPS) + 2, self.grid.shape[:, None])
        j1 = np.maximum(self.grid._index(high, EPS) - 1, j0)  # exclusive; empty: no cells
        return _range_sums(self.prefix, j0, j1) > 0

    def listed(self, low: np.ndarray, high: np.ndarray) -> np.ndarray:
        """(M,) the boxes listed in the cells each query box spans (a box once a cell; the
        largest int64 without lists)."""
        if not self.ok:
            return np.full(low.shape[1], np.iinfo(np.int64).max)
        j0, j1 = self.grid._index(low, -EPS), self.grid._index(high, EPS) + 1
        return _range_sums(self.prefix, j0, j1)

    def overlaps(self, low: np.ndarray, high: np.ndarray, cost: np.ndarray):
        """Yield (query, box) of each query box and the boxes listed in its cells it
        overlaps, each tested exactly, queries of ``cost`` (M,) PAIRS at a time at most (a
        box listed in several of a query's cells comes once each)."""
        for part in _parts(cost):
            query, box = self._part(low[:, part], high[:, part])
            yield query + part.start, box

    def _part(self, low: np.ndarray, high: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``overlaps`` for one chunk of queries."""
        j0, j1 = self.grid._index(low, -EPS), self.grid._index(high, EPS)
        query, cell = self._cells(j0, j1)
        first = self.start.take(cell)
        count = self.start.take(cell + 1) - first
        query = query.repeat(count)
        ref = np.arange(query.size) - (np.cumsum(count) - count).repeat(count)
        box = self.box.take(ref + first.repeat(count))
        overlap = _overlap(low, high, query, self.lo, self.hi, box)
        return query[overlap], box[overlap]

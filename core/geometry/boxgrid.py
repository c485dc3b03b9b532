"""A uniform grid over boxes, walked by whole batches of segments at once.

For many boxes spread through space (a cloud of small spheres) a grid finds the boxes near
a segment for a few operations per cell it passes, where a tree walks its depth for every
window. Cells hold the boxes within ``margin`` of them (compressed rows: ``start``,
``box``; a border of empty cells around). Segments walk the cells they pass cell by cell
(a 3-D DDA, Amanatides and Woo: one array step moves every segment of the batch), window
by window, nearest first (WINDOW cells, then twice as many each time, up to LONGEST); the
boxes of each cell walked that the segment's part in that cell passes through (a slab
test, the axis it moves least along first) are its pairs. Boxes over more than SPREAD
cells on an axis go to a BoxTree beside the grid, walked first. ``index`` picks the grid
where its cells stay thinly filled (CROWD), else a BoxTree.

Rounding: a walk may miss a cell the segment clips within its rounding of an edge or a
corner, never by more, and boxes enter every cell within ``margin`` (a box's own margin,
boxtree._padded, and MARGIN cell widths) of them: every box whose padded bounds a segment
passes within its own margin (boxtree.PAD (1 + |start|)) of, as the tree finds them, is
found, while that margin is below ``near`` (a quarter of MARGIN cell widths). Segments
starting farther away (over ~10^4 cell widths) walk a BoxTree over the same boxes. The
parts the walk puts in cells (between the planes it crossed) tile the segment: a point of
a box on the segment lies in some cell's part, a cell the box entered (within ``margin``
of it), whose part is tested against the box widened by ``near`` and its own margin.
"""

from __future__ import annotations

import functools
from collections.abc import Iterator

import numpy as np

from .boxtree import PAD, BoxTree, Segments, _by_axis, _span

TEST_COST = 2.0
"""What testing a box costs a walk, in cell steps: the cell width minimises a walk's
expected cost per unit length, (1 + TEST_COST density (width + box size)^3) / width, the
boxes spread evenly over their bounds (a box test costs about two steps, as measured;
1 and 4 measured no better, 10^2 to 10^5 spheres in a shell)."""
MOST_CELLS = 32
"""Cells per box at most."""
CROWD = 6.0
"""The grid is used where a box shares its cells with at most this many boxes on average
(sum of count^2 / sum of count over cells); more crowded (clustered) boxes take the tree."""
SPREAD = 3
"""Boxes over more than SPREAD cells on an axis go to a BoxTree beside the grid."""
MARGIN = 1e-4
"""Boxes enter the cells within MARGIN cell widths of them (module docstring)."""
WINDOW = 6
"""Cells a segment's first window walks (core.geometry.group); each next one twice as many,
up to LONGEST."""
LONGEST = 48
"""Cells a window walks at most."""
_BIG = float(np.finfo(np.float64).max)


def index(lo: np.ndarray, hi: np.ndarray) -> BoxGrid | BoxTree:
    """A BoxGrid over boxes [lo[i], hi[i]] (M >= 1, 3) where it suits them, else a BoxTree."""
    grid = BoxGrid(lo, hi)
    return grid if grid.suits else BoxTree(lo, hi)


class BoxGrid:
    """Uniform grid over finite boxes (lo, hi) (M >= 1, 3): ``windows`` as BoxTree's (each
    pair at least once, unsorted); ``suits``: whether its cells are thinly filled."""

    def __init__(self, lo: np.ndarray, hi: np.ndarray) -> None:
        """Grid over boxes [lo[i], hi[i]] (finite, lo <= hi)."""
        self.lo = np.asarray(lo, np.float64).reshape(-1, 3)
        self.hi = np.asarray(hi, np.float64).reshape(-1, 3)
        lo3, hi3 = np.ascontiguousarray(self.lo.T), np.ascontiguousarray(self.hi.T)  # (3, M)
        pad = self._frame(lo3, hi3)
        i0, i1 = self._cell(lo3 - self.margin), self._cell(hi3 + self.margin)
        span = i1 - i0
        small = (span[0] < SPREAD) & (span[1] < SPREAD) & (span[2] < SPREAD)
        self.small, self.rest = np.flatnonzero(small), np.flatnonzero(~small)
        cell, box = self._refs(i0[:, small], i1[:, small], self.small)
        count = np.bincount(cell, minlength=int(self.shape.prod()))
        crowd = count @ count <= CROWD * max(1, cell.size)
        self.suits = bool(crowd) and 2 * self.rest.size <= self.small.size
        if self.suits:
            self._fill(count, cell, box, (lo3, hi3), pad + 2 * self.near)

    def _frame(self, lo3: np.ndarray, hi3: np.ndarray) -> float:
        """Place the cells around boxes (lo3, hi3) (3, M) each: ``origin``, ``size``,
        ``shape``, ``root``, ``margin``, ``near``. Returns a margin over every box's own
        (boxtree._padded)."""
        root_lo, root_hi = _by_axis(np.min, lo3.T), _by_axis(np.max, hi3.T)
        extent = root_hi - root_lo
        shape, size = _cells(extent, _cell_count(extent, hi3 - lo3))
        pad = PAD * (1.0 + float(np.max(np.abs(np.concatenate([root_lo, root_hi])))))
        self.near = 0.25 * MARGIN * float(size.min())
        """Segments whose margin (Segments.reach) is at most this walk the grid."""
        self.margin = pad + MARGIN * float(size.min())
        """Boxes enter the cells within this of them (world units)."""
        self.origin = root_lo - self.margin
        self.size = (extent + 2 * self.margin) / shape
        self.shape = shape + 2  # a border of empty cells: a walk may step one cell out
        self.root = (self.origin[:, None], (self.origin + shape * self.size)[:, None])
        return pad

    def _fill(self, count: np.ndarray, cell: np.ndarray, box: np.ndarray, boxes, wide: float):
        """Hold the boxes ``box`` in cells ``cell`` (``count`` a cell), widened by ``wide``
        from ``boxes`` ((lo, hi) (3, M) each), and a BoxTree of the rest."""
        self.start = np.zeros(count.size + 1, np.int64)
        np.cumsum(count, out=self.start[1:])
        """Where each cell's boxes begin in ``box`` (cells + 1,)."""
        self.occupied = count > 0
        self.box = box[_order(cell, count.size)]  # within a cell, any order
        """The boxes in each cell, cell by cell."""
        lo3, hi3 = boxes
        self.ref = (np.take(lo3, self.box, axis=1) - wide, np.take(hi3, self.box, axis=1) + wide)
        """Each cell's boxes widened by their margin and twice ``near`` (3, refs) each,
        cell by cell (as ``box``): a walking segment's part passing within its margin
        and the box's of a box (boxtree._meets) passes through its widened box."""
        self.tree = BoxTree(self.lo[self.rest], self.hi[self.rest]) if self.rest.size else None
        """The boxes over more than SPREAD cells on an axis (``rest``)."""
        self._far: BoxTree | None = None

    def _cell(self, x: np.ndarray) -> np.ndarray:
        """(3, M) the cell indices of points x (3, M), within the grid but its border."""
        i = np.floor((x - self.origin[:, None]) / self.size[:, None]) + 1
        return np.clip(i, 1, self.shape[:, None] - 2).astype(np.int64)

    def _refs(self, i0: np.ndarray, i1: np.ndarray, boxes: np.ndarray):
        """(cell, box): each cell (flat index) a box of ``boxes`` overlaps, from its first
        and last cells i0, i1 (3, K) (at most SPREAD apart), with the box: each box's cells
        its first one's plus the offsets of its block's shape (_blocks), taken at once."""
        stride = (int(self.shape[1] * self.shape[2]), int(self.shape[2]), 1)
        offsets, counts = _blocks(stride)
        span = i1 - i0
        shape = (span[0] * SPREAD + span[1]) * SPREAD + span[2]  # the block's row in offsets
        each = counts.take(shape)
        src = np.arange(boxes.size).repeat(each)
        slot = np.arange(src.size) - (np.cumsum(each) - each).take(src)  # within the block
        cell = (np.array(stride) @ i0).take(src) + offsets.take(shape.take(src) * SPREAD**3 + slot)
        return cell, boxes.take(src)

    def windows(self, seg: Segments, hit_t: np.ndarray) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        """Yield (rows, boxes): every (segment, box) whose segment passes through the box
        and whose bounds overlap it (BoxTree.pairs), window by window along the segments,
        nearest first; a segment goes on while ``hit_t`` (N,), its nearest hit so far,
        which the caller lowers in place between windows, lies beyond the window's end."""
        if self.tree is not None:
            for rows, boxes in self.tree.windows(seg, hit_t):
                yield rows, self.rest[boxes]
        far = np.flatnonzero(seg.reach > self.near)
        if far.size:
            if self._far is None:
                self._far = BoxTree(self.lo[self.small], self.hi[self.small])
            for rows, boxes in self._far.windows(seg, hit_t, far):
                yield rows, self.small[boxes]
        yield from self._walk(seg, np.flatnonzero(seg.reach <= self.near), hit_t)

    def _walk(self, seg: Segments, rows: np.ndarray, hit_t: np.ndarray):
        """``windows`` of the segments ``rows`` through the grid's cells."""
        n = rows.size
        enter, leave = _span(seg, rows, self.root, np.zeros(n, np.int64), np.zeros(n), np.ones(n))
        going = enter <= leave
        walk = _Walk(self, seg, rows[going], enter[going], leave[going])
        cells = WINDOW
        while walk.row.size:
            row, until = walk.row, np.minimum(walk.leave, hit_t[walk.row])
            k, cell, t_in, t_out = walk.steps(cells, until)
            pick, slot = self._slots(cell)
            r = row.take(k.take(pick))
            parts = t_in.take(pick), t_out.take(pick)
            keep = _crosses(seg, r, self.ref, slot, *parts, _axes(seg, row))
            yield r[keep], self.box[slot[keep]]
            walk.go_on(hit_t)
            cells = min(2 * cells, LONGEST)

    def _slots(self, cell: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(pick, slots): the boxes in cells ``cell`` (their places in ``box``), each with
        its cell's position in ``cell`` (one repeat: numpy's take is ~6x faster)."""
        first = self.start.take(cell)
        count = self.start.take(cell + 1) - first
        pick = np.arange(cell.size).repeat(count)
        shift = first - (np.cumsum(count) - count)  # a cell's slots less their positions
        return pick, np.arange(pick.size) + shift.take(pick)


class _Walk:
    """Segments walking a grid cell by cell, all at once: each one's ``row``, ``cell`` (a
    flat index), the parameters where it next crosses a plane between cells on each axis
    (``next``) and between two on it (``delta``), how its cell index moves then (``move``),
    the end of its part in the grid (``leave``), where its window began (``start``), how
    far the cells walked cover it (``covered``), where this window stops it (``limit``),
    its position in the walk as the window began (``at``) and whether it walks on in this
    window (``on``)."""

    def __init__(self, grid: BoxGrid, seg: Segments, rows, enter, leave) -> None:
        """The segments ``rows`` entering the grid at ``enter``, leaving at ``leave``."""
        self.occupied = grid.occupied
        self.row, self.leave, self.start = rows, leave, enter
        self.cell = np.zeros(rows.size, np.int64)
        self.next, self.delta, self.move = [], [], []
        stride = (grid.shape[1] * grid.shape[2], grid.shape[2], 1)
        for k in range(3):
            a, d, inv = (x[k].take(rows) for x in (seg.a_axes, seg.d_axes, seg.inv_axes))
            i = np.floor((a + enter * d - grid.origin[k]) / grid.size[k]) + 1
            i = np.clip(i, 1, grid.shape[k] - 2).astype(np.int64)
            plane = grid.origin[k] + (i - 1 + (d > 0)) * grid.size[k]
            with np.errstate(invalid="ignore"):
                self.next.append(np.where(d != 0, (plane - a) * inv, np.inf))
            delta = np.where(d != 0, grid.size[k] * np.abs(inv), np.inf)
            self.delta.append(np.minimum(delta, _BIG))  # finite: delta * False is 0
            self.cell += i * stride[k]
            self.move.append(np.sign(d).astype(np.int64) * stride[k])
        self.on = np.ones(rows.size, bool)
        self.covered, self.limit, self.at = enter, leave, np.arange(rows.size)

    def steps(self, count: int, limit: np.ndarray) -> tuple[np.ndarray, ...]:
        """Walk ``count`` cells, fewer where a segment leaves the grid or passes its
        ``limit`` (its hit so far, or its end): (k, cell, t_in, t_out) of the cells that
        hold boxes, ``k`` the segment's position in the walk as it was (those that stop
        are let go), [t_in, t_out] the part of it the walk put in the cell (the parts
        tile the segment: each next one begins where the last one ended)."""
        self.limit, self.at = limit, np.arange(self.row.size)
        ats, cells, ins, outs = [], [], [], []
        for step in range(count):
            cell, on = self.cell, self.on
            occ = np.flatnonzero(self.occupied.take(cell * on))  # stopped: 0, border
            ats.append(self.at.take(occ))
            cells.append(cell.take(occ))
            ins.append(self.covered.take(occ))
            t = np.minimum(np.minimum(self.next[0], self.next[1]), self.next[2])
            outs.append(t.take(occ))
            on &= t <= self.limit  # those stopped step on unseen (their cells: 0 above)
            self.covered = t  # the cells walked cover the segment up to here (where on)
            with np.errstate(over="ignore"):  # those stopped may run far
                for nxt, delta, move in zip(self.next, self.delta, self.move, strict=True):
                    cross = nxt == t  # products, not np.add(where=cross): ~5x faster
                    nxt += delta * cross
                    cell += move * cross
            if step % 2 and np.count_nonzero(on) < 0.75 * on.size:
                self._keep(on)  # fewer to step
        return tuple(np.concatenate(v) for v in (ats, cells, ins, outs))

    def go_on(self, hit_t: np.ndarray) -> None:
        """Keep walking the segments still in the grid whose hit so far (``hit_t``) lies
        beyond the cells walked, their next windows starting there."""
        self._keep(self.on & (hit_t[self.row] > self.covered))
        self.start = self.covered

    def _keep(self, going: np.ndarray) -> None:
        """Walk on only the segments ``going`` (in the order held)."""
        keep = np.flatnonzero(going)  # once, then takes: a mask per array costs more
        for name in ("row", "leave", "cell", "limit", "covered", "at"):
            setattr(self, name, getattr(self, name).take(keep))
        for name in ("next", "delta", "move"):
            setattr(self, name, [v.take(keep) for v in getattr(self, name)])
        self.on = np.ones(self.row.size, bool)


def _axes(seg: Segments, rows: np.ndarray) -> list[int]:
    """The axes, those the segments ``rows`` move least along first (a box's slab on them
    turns away the most pairs: _crosses)."""
    move = [float(np.abs(seg.d_axes[k].take(rows)).sum()) for k in range(3)]
    return sorted(range(3), key=move.__getitem__)


def _crosses(seg: Segments, rows, boxes, slots, t_from, t_to, axes=(0, 1, 2)) -> np.ndarray:
    """(P',) the pairs i whose part [t_from, t_to] of segment ``rows[i]`` (its part in a
    cell) meets box ``slots[i]`` of ``boxes`` ((lo, hi) (3, K) each; a slab test as
    boxtree._span, without its margin), axis by axis in the order ``axes``, the pairs
    the first turns away dropped (enter only grows, leave only falls: the same pairs)."""
    keep, enter, leave = np.arange(0), t_from, t_to
    with np.errstate(invalid="ignore", over="ignore"):
        for i, k in enumerate(axes):
            a, inv = seg.a_axes[k].take(rows), seg.inv_axes[k].take(rows)
            t1 = (boxes[0][k].take(slots) - a) * inv
            t2 = (boxes[1][k].take(slots) - a) * inv
            enter = np.fmax(enter, np.fmin(t1, t2))  # fmin/fmax skip 0 * inf's NaN
            leave = np.fmin(leave, np.fmax(t1, t2))
            if i == 0:
                keep = np.flatnonzero(enter <= leave)
                rows, slots, enter, leave = (v.take(keep) for v in (rows, slots, enter, leave))
    return keep[enter <= leave]


def _order(keys: np.ndarray, top: int) -> np.ndarray:
    """The positions that sort int ``keys`` (K,) in [0, top), stably: one np.sort of
    key * 2^b + position where that fits in 63 bits (numpy's sort runs ~2x faster
    than its argsort)."""
    bits = int(keys.size).bit_length()
    if top <= 1 << (62 - bits):
        return np.sort((keys << bits) | np.arange(keys.size)) & ((1 << bits) - 1)
    return np.argsort(keys, kind="stable")


@functools.lru_cache(maxsize=8)
def _blocks(stride: tuple[int, int, int]) -> tuple[np.ndarray, np.ndarray]:
    """(offsets (SPREAD^6,), counts (SPREAD^3,)): for each block of n0 x n1 x n2 cells (n
    in 1..SPREAD; row ((n0 - 1) SPREAD + n1 - 1) SPREAD + n2 - 1), the flat offsets of its
    cells from its first one (grid ``stride``), padded to SPREAD^3 a row, and how many."""
    corner = np.indices((SPREAD,) * 3).reshape(3, -1)  # every cell of the largest block
    offsets, counts = np.zeros((SPREAD**3, SPREAD**3), np.int64), np.zeros(SPREAD**3, np.int64)
    for row, n in enumerate(corner.T + 1):
        inside = np.array(stride) @ corner[:, np.all(corner < n[:, None], axis=0)]
        offsets[row, : inside.size], counts[row] = inside, inside.size
    offsets.flags.writeable = counts.flags.writeable = False  # cached: shared by grids
    return offsets.reshape(-1), counts


def _cell_count(extent: np.ndarray, sizes: np.ndarray) -> float:
    """How many cells to cut ``extent`` (3,) into for boxes of ``sizes`` (3, M) (TEST_COST)."""
    m = sizes.shape[1]
    dims = extent[extent > 0]
    if dims.size == 0:
        return 1.0
    volume = float(np.prod(dims))
    mean = (sizes[0] + sizes[1] + sizes[2]) / 3.0
    size = float(np.partition(mean, m // 2)[m // 2])  # the median
    width = (volume / m) ** (1.0 / dims.size) * np.geomspace(0.05, 2.0, 48)
    cost = (1 + TEST_COST * m / volume * (width + size) ** dims.size) / width
    best = width[int(np.argmin(cost))]
    return float(min(volume / best**dims.size, MOST_CELLS * m))


def _cells(extent: np.ndarray, target: float) -> tuple[np.ndarray, np.ndarray]:
    """(shape (3,) ints, size (3,)): about ``target`` cells of one width over ``extent``
    (axes of no extent: one cell)."""
    ext = np.maximum(extent, 0.0)
    width = np.inf
    for dims in (3, 2, 1):  # the widest axes with room for cells of this width
        top = np.sort(ext)[::-1][:dims]
        if top[-1] <= 0:
            continue
        width = float(np.prod(top) / max(target, 1.0)) ** (1.0 / dims)
        if width <= top[-1]:
            break
    shape = np.where(ext > 0, np.clip(np.round(ext / width), 1, None), 1).astype(np.int64)
    size = np.where(ext > 0, ext / shape, 1.0)
    return shape, size

"""Groups of intersectors: the nearest hit over the members, found through a broad phase."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np

from . import boxgrid
from .boxgrid import BoxGrid
from .boxtree import BoxTree, _by_axis, segments
from .hits import _INF, Hits, _segments, filters, segment_overlaps
from .primitives import SPHERE_ROW, Sphere, sphere_hits

FEW = 8
"""Up to this many members with finite bounds, each is asked in turn (no broad phase)."""
_OWN_ROWS = (Sphere,)
"""Members whose answer for a segment depends on that segment alone, to the last bit (of
exactly these types): asked only about the segments that reach their box. Others are
asked, once the broad phase finds a segment reaching them, about every segment whose
bounds overlap theirs, as one by one
(planes and annuli take dot products by BLAS, whose last bit follows the batch; meshes
break ties between faces in an order that follows it; nested groups, the add-on's
intersectors: unknown)."""


class Group:
    """The nearest hit over member intersectors, each sent only the segments near its bounds.

    Object ids: member k reports ``ids[k]`` (default: k, its position in the list; an id
    None keeps the ids the member reports itself). Hits equal those of asking every member
    in turn (``intersect_each``): the nearest, the earlier member on a tie. Beyond FEW
    members with finite bounds, a grid or a bounding-volume hierarchy over their boxes
    (core.geometry.boxgrid.index) finds the segments that reach each; spheres of one
    colour are then hit all at once.
    """

    def __init__(self, objects: Sequence[Any], ids: Sequence[int | None] | None = None) -> None:
        """Group of intersectors (anything with ``bounds`` and ``intersect``)."""
        self.objects = list(objects)
        self.ids: Sequence[int | None] = (
            range(len(self.objects))  # a range: 10^5 ints in a list cost ~3 ms
            if ids is None
            else [None if i is None else int(i) for i in ids]
        )
        if len(self.ids) != len(self.objects):
            raise ValueError("ids must have one entry per object")
        self._by_position = ids is None
        """Whether each member's id is its position (the default ``ids``)."""
        read = _read(self.objects)
        self.member_bounds = lo, hi = read.lo, read.hi
        """(lo, hi) (M, 3): each member's bounds."""
        if np.isnan(lo).any() or np.isnan(hi).any():
            k = int(np.flatnonzero(np.isnan(lo).any(axis=1) | np.isnan(hi).any(axis=1))[0])
            raise ValueError(f"object {k} has NaN bounds (non-finite vertices?)")
        if self.objects:
            self.bounds = (_by_axis(np.min, lo), _by_axis(np.max, hi))
        else:
            self.bounds = (np.full(3, _INF), np.full(3, -_INF))
        plain = np.zeros(len(self.objects), bool)
        plain[read.spheres[read.plain]] = True
        self.filters = any(filters(self.objects[k]) for k in np.flatnonzero(~plain).tolist())
        """Whether a member colours over footprints (core.geometry.hits.filters; a plain
        sphere's colour does not)."""
        finite = np.isfinite(lo) & np.isfinite(hi)
        bounded = finite[:, 0] & finite[:, 1] & finite[:, 2]
        self._broad = _BroadPhase(self, read, bounded) if bounded.sum() > FEW else None

    def intersect(self, a: np.ndarray, b: np.ndarray, footprint: np.ndarray | None = None) -> Hits:
        """Nearest hit of each segment a -> b (N, 3) over all members, those that filter
        coloured over ``footprint`` (N, 2, 3) where given."""
        a, b = _segments(a, b)
        if self._broad is None:
            return self.intersect_each(a, b, footprint)
        return self._broad.intersect(self, a, b, footprint)

    def intersect_each(
        self, a: np.ndarray, b: np.ndarray, footprint: np.ndarray | None = None
    ) -> Hits:
        """``intersect`` by asking every member in turn about the segments whose bounds
        overlap its box (the brute force the broad phase equals)."""
        a, b = _segments(a, b)
        out = Hits.miss(a.shape[0])
        for obj, oid in zip(self.objects, self.ids, strict=True):
            rows = np.flatnonzero(segment_overlaps(a, b, *obj.bounds))
            if rows.size == 0:
                continue
            whole = len(self.objects) == 1 and rows.size == a.shape[0]
            near: Any = slice(None) if whole else rows  # one member near all: its hits
            hits = _ask(obj, a[near], b[near], footprint, near)
            if whole:
                if oid is not None:
                    hits.object_id[hits.hit] = oid
                return hits
            out.merge(rows, hits, oid)
        return out


def member_bounds(objects: Sequence[Any]) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) (M, 3) of every intersector's bounds, at once."""
    read = _read(list(objects))
    return read.lo, read.hi


class _Read(NamedTuple):
    """What one pass over a group's members reads: every member's bounds (lo, hi) (M, 3);
    the positions of its Spheres (``spheres`` (S,), exactly core's Sphere), their centres
    (S, 3), radii and Python's radius**2 (S,), constant colours (S, 4) and which of them
    are plain (``plain`` (S,): one constant colour)."""

    lo: np.ndarray
    hi: np.ndarray
    spheres: np.ndarray
    centre: np.ndarray
    radius: np.ndarray
    radius2: np.ndarray
    colour: np.ndarray
    plain: np.ndarray


def _read(objects: list[Any]) -> _Read:
    """The members' bounds, and their Spheres' records (Sphere._row, joined as bytes in one
    pass over the members): a Sphere's bounds are its centre -/+ its radius (as Sphere
    makes them)."""
    m = len(objects)
    views: list[Any] = [o._view if type(o) is Sphere else None for o in objects]  # one pass
    try:
        joined, sphere = b"".join(views), np.ones(m, bool)  # every member a Sphere
    except TypeError:  # some are not (None)
        sphere = np.array([v is not None for v in views], bool).reshape(m)
        joined = b"".join([v for v in views if v is not None])
    at = np.flatnonzero(sphere)
    rec = np.frombuffer(joined, np.float64).reshape(-1, SPHERE_ROW)
    axes, r = rec[:, :3].T, rec[:, 3]  # by axis: numpy's loops run long
    read = (at, rec[:, :3], r, rec[:, 4], rec[:, 5:9], rec[:, 9] == 1.0)
    if at.size == m:  # (3, M) arrays: each axis's bounds contiguous
        return _Read(np.subtract(axes, r, order="C").T, np.add(axes, r, order="C").T, *read)
    lo, hi = np.empty((m, 3)), np.empty((m, 3))
    lo[at], hi[at] = (axes - r).T, (axes + r).T
    rest = np.flatnonzero(~sphere)
    if rest.size:
        boxes = np.array([objects[k].bounds for k in rest.tolist()], dtype=np.float64)
        lo[rest], hi[rest] = boxes.reshape(-1, 2, 3)[:, 0], boxes.reshape(-1, 2, 3)[:, 1]
    return _Read(lo, hi, *read)


def _ask(obj: Any, a: np.ndarray, b: np.ndarray, footprint: np.ndarray | None, rows) -> Hits:
    """One member's hits of segments a -> b, over ``footprint[rows]`` where it filters."""
    if footprint is None or not filters(obj):
        return obj.intersect(a, b)
    return obj.intersect(a, b, footprint[rows])


class _BroadPhase:
    """A Group's members split for the broad phase (more than FEW bounded ones): unbounded
    ones (infinite planes) asked in turn, bounded ones in a grid or tree (``index``),
    plain spheres (one constant colour each) in arrays hit all at once."""

    def __init__(self, group: Group, read: _Read, bounded: np.ndarray) -> None:
        """Split the ``group``'s members (``read`` from them; ``bounded`` (M,): finite)."""
        objects = group.objects
        self.unbounded = np.flatnonzero(~bounded)
        self.boxed = np.flatnonzero(bounded)
        every = self.boxed.size == bounded.size
        lo, hi = (read.lo, read.hi) if every else (read.lo[self.boxed], read.hi[self.boxed])
        self.index: BoxGrid | BoxTree = boxgrid.index(lo, hi)
        """A grid or tree over the bounded members' boxes (core.geometry.boxgrid.index)."""
        where = np.full(len(objects), -1)  # member -> its row among the spheres read
        where[read.spheres] = np.arange(read.spheres.size)
        row = where[self.boxed]
        self.ball = row >= 0
        self.ball[self.ball] = read.plain[row[self.ball]]
        self.own_rows = row >= 0  # the Spheres read: _OWN_ROWS
        s = row[self.ball]
        arrays = [read.centre, read.radius, read.radius2, read.colour]  # radius2: Python's
        if s.size != read.radius.size:  # not every Sphere read (else no copies)
            arrays = [v[s] for v in arrays]
        self.centre, self.radius, self.radius2, self.colour = arrays
        members = self.boxed[self.ball]
        if group._by_position:
            self.ball_id = members.astype(np.int32)
        else:
            whole = members.size == len(objects)
            ids = group.ids if whole else [group.ids[k] for k in members.tolist()]
            self.ball_id = _ids(objects if whole else [objects[k] for k in members.tolist()], ids)
        self.ball_index = np.cumsum(self.ball) - 1  # boxed position -> row in the arrays

    def intersect(self, group: Group, a: np.ndarray, b: np.ndarray, footprint) -> Hits:
        """The group's hits (Group.intersect) through the grid or tree, window by window
        along the segments (``index.windows``: each reads the hits found so far)."""
        index = self.index
        assert index is not None
        out, won = Hits.miss(a.shape[0]), np.full(a.shape[0], len(group.objects))
        for k in self.unbounded.tolist():
            rows = np.flatnonzero(segment_overlaps(a, b, *group.objects[k].bounds))
            self._member(group, k, rows, a, b, footprint, out, won)
        asked: set[int] = set()  # members asked about all their rows (not _OWN_ROWS)
        for rows, boxed in index.windows(segments(a, b), out.t):  # nearest first
            self._window(group, rows, boxed, a, b, footprint, out, won, asked)
        return out

    def _window(self, group: Group, rows, boxed, a, b, footprint, out: Hits, won, asked) -> None:
        """The hits of the (segment ``rows``, member ``boxed``) pairs a window found, in
        any order, maybe repeated (members in ``asked`` have answered for all their rows
        already)."""
        balls = self.ball[boxed]
        self._balls(rows[balls], boxed[balls], a, b, out, won)
        if balls.all():
            return
        pair = np.unique(boxed[~balls] * a.shape[0] + rows[~balls])  # by member, then row
        rows, boxed = pair % a.shape[0], pair // a.shape[0]
        ends = np.r_[np.flatnonzero(np.diff(boxed, prepend=-1)), boxed.size]  # each member's pairs
        for start, stop in zip(ends[:-1], ends[1:], strict=True):
            k = int(self.boxed[boxed[start]])
            if self.own_rows[boxed[start]]:
                near = rows[start:stop]
            elif k in asked:
                continue
            else:  # the rows the brute force sends (_OWN_ROWS)
                near = np.flatnonzero(segment_overlaps(a, b, *group.objects[k].bounds))
                asked.add(k)
            self._member(group, k, near, a, b, footprint, out, won)

    @staticmethod
    def _member(group: Group, k: int, rows, a, b, footprint, out: Hits, won) -> None:
        """Member k's hits of the segments ``rows``, kept where nearer (``_keep``)."""
        if rows.size:
            hits = _ask(group.objects[k], a[rows], b[rows], footprint, rows)
            _keep(out, won, rows, hits, k, group.ids[k])

    def _balls(self, rows, boxed, a, b, out: Hits, won) -> None:
        """The plain spheres' hits of the (segment ``rows``, sphere ``boxed``) pairs, all at
        once; each segment's nearest kept where nearer (``_keep``)."""
        s = self.ball_index[boxed]
        hit, t, p, n, uv = sphere_hits(
            a.take(rows, axis=0), b.take(rows, axis=0), self.centre[s], self.radius[s],
            self.radius2[s],
        )  # fmt: skip
        rows, boxed, s = rows[hit], boxed[hit], s[hit]
        member = self.boxed[boxed]
        first = _firsts(a.shape[0], rows, t, member)
        r = rows[first]
        hits = Hits(np.ones(r.size, bool), t[first], self.ball_id[s[first]], p[first], n[first],
                    uv[first], self.colour[s[first]].copy())  # fmt: skip
        _keep(out, won, r, hits, member[first], None)


def _firsts(n: int, rows: np.ndarray, *keys: np.ndarray) -> np.ndarray:
    """The position i of each segment's first pair (``rows`` (P,) in range(n)) by
    ``keys`` in turn (the least first), then by i: a stable sort's firsts, unsorted."""
    pick = np.arange(rows.size)
    for key in (*keys, None):
        key = pick if key is None else key[pick]
        r = rows[pick]
        top = np.inf if key.dtype.kind == "f" else np.iinfo(key.dtype).max
        least = np.full(n, top, key.dtype)
        np.minimum.at(least, r, key)
        pick = pick[key == least[r]]
    return pick


def _ids(balls: list[Any], ids: Sequence[int | None]) -> np.ndarray:
    """(B,) int32: the ids the members ``balls`` report: the group's ``ids`` for them,
    their own where None."""
    if None not in ids:
        return np.array(ids, np.int64).reshape(-1).astype(np.int32)
    out = np.array([0 if oid is None else oid for oid in ids], np.int64).reshape(-1)
    own = [k for k, oid in enumerate(ids) if oid is None]
    out[own] = [int(balls[k].object_id) for k in own]
    return out.astype(np.int32)


def _keep(out: Hits, won: np.ndarray, rows: np.ndarray, hits: Hits, member, oid) -> None:
    """Take ``hits`` (of segments ``rows``) from ``member`` (an index, or one per row) where
    nearer than ``out``'s, or as near from an earlier member (``won``: whose hit ``out``
    holds); ``oid``, if not None, replaces the ids ``hits`` report (as Hits.merge)."""
    held = out.t[rows]
    better = hits.hit & ((hits.t < held) | ((hits.t == held) & (member < won[rows])))
    r = rows[better]
    won[r] = member[better] if np.ndim(member) else member
    out.assign(r, hits, np.flatnonzero(better))
    if oid is not None:
        out.object_id[r] = oid

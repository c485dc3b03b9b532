"""Groups of intersectors: the nearest hit over the members, found through a broad phase."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from .boxtree import BoxTree
from .hits import _INF, Hits, _segments, filters, segment_overlaps
from .primitives import Sphere, sphere_hits

FEW = 8
"""Up to this many members with finite bounds, each is asked in turn (no tree)."""
_OWN_ROWS = (Sphere,)
"""Members whose answer for a segment depends on that segment alone, to the last bit:
asked only about the segments that reach their box. Others are asked, once the tree finds
a segment reaching them, about every segment whose bounds overlap theirs, as one by one
(planes and annuli take dot products by BLAS, whose last bit follows the batch; meshes
break ties between faces in an order that follows it; nested groups, the add-on's
intersectors: unknown)."""


class Group:
    """The nearest hit over member intersectors, each sent only the segments near its bounds.

    Object ids: member k reports ``ids[k]`` (default: k, its position in the list; an id
    None keeps the ids the member reports itself). Hits equal those of asking every member
    in turn (``intersect_each``): the nearest, the earlier member on a tie. Beyond FEW
    members with finite bounds, a bounding-volume hierarchy over their boxes (BoxTree)
    finds the segments that reach each; spheres of one colour are then hit all at once.
    """

    def __init__(self, objects: Sequence[Any], ids: Sequence[int | None] | None = None) -> None:
        """Group of intersectors (anything with ``bounds`` and ``intersect``)."""
        self.objects = list(objects)
        self.ids: list[int | None] = (
            list(range(len(self.objects)))
            if ids is None
            else [None if i is None else int(i) for i in ids]
        )
        if len(self.ids) != len(self.objects):
            raise ValueError("ids must have one entry per object")
        self.member_bounds = lo, hi = member_bounds(self.objects)
        """(lo, hi) (M, 3): each member's bounds."""
        if np.isnan(lo).any() or np.isnan(hi).any():
            k = int(np.flatnonzero(np.isnan(lo).any(axis=1) | np.isnan(hi).any(axis=1))[0])
            raise ValueError(f"object {k} has NaN bounds (non-finite vertices?)")
        if self.objects:
            self.bounds = (lo.min(axis=0), hi.max(axis=0))
        else:
            self.bounds = (np.full(3, _INF), np.full(3, -_INF))
        self.filters = any(filters(obj) for obj in self.objects)
        """Whether a member colours over footprints (core.geometry.hits.filters)."""
        self._broad = _BroadPhase(self.objects, self.ids, lo, hi) if self.objects else None
        if self._broad is not None and self._broad.tree is None:
            self._broad = None

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
    if not objects:
        return np.zeros((0, 3)), np.zeros((0, 3))
    boxes = np.array([o.bounds for o in objects], dtype=np.float64).reshape(-1, 2, 3)
    return boxes[:, 0], boxes[:, 1]


def _ask(obj: Any, a: np.ndarray, b: np.ndarray, footprint: np.ndarray | None, rows) -> Hits:
    """One member's hits of segments a -> b, over ``footprint[rows]`` where it filters."""
    if footprint is None or not filters(obj):
        return obj.intersect(a, b)
    return obj.intersect(a, b, footprint[rows])


class _BroadPhase:
    """A Group's members split for the broad phase: unbounded ones (infinite planes) asked
    in turn, bounded ones in a BoxTree (None: FEW or fewer), plain spheres (one constant
    colour each) in arrays hit all at once."""

    def __init__(self, objects: list[Any], ids: list[int | None], lo, hi) -> None:
        """Split ``objects`` (with ``ids``, bounds ``lo``, ``hi``)."""
        bounded = np.all(np.isfinite(lo) & np.isfinite(hi), axis=1)
        self.unbounded = np.flatnonzero(~bounded)
        self.boxed = np.flatnonzero(bounded)
        self.tree = BoxTree(lo[self.boxed], hi[self.boxed]) if self.boxed.size > FEW else None
        kind = [type(objects[k]) for k in self.boxed]
        self.ball = np.array([t is Sphere and not callable(objects[k].color)
                              for t, k in zip(kind, self.boxed, strict=True)], bool)  # fmt: skip
        self.own_rows = np.array([t in _OWN_ROWS for t in kind], bool)
        balls = [objects[k] for k in self.boxed[self.ball]]
        self.centre = np.array([s.center for s in balls]).reshape(-1, 3)
        self.radius = np.array([s.radius for s in balls], np.float64)
        self.radius2 = np.array([s.radius**2 for s in balls], np.float64)  # as Sphere's
        self.colour = np.array([s.color for s in balls]).reshape(-1, 4)
        self.ball_id = np.array([_id(s, oid) for s, oid in
                                 zip(balls, np.array(ids, object)[self.boxed[self.ball]],
                                     strict=True)], np.int32)  # fmt: skip
        self.ball_index = np.cumsum(self.ball) - 1  # boxed position -> row in the arrays

    def intersect(self, group: Group, a: np.ndarray, b: np.ndarray, footprint) -> Hits:
        """The group's hits (Group.intersect) through the tree."""
        assert self.tree is not None
        out, won = Hits.miss(a.shape[0]), np.full(a.shape[0], len(group.objects))
        for k in self.unbounded.tolist():
            rows = np.flatnonzero(segment_overlaps(a, b, *group.objects[k].bounds))
            self._member(group, k, rows, a, b, footprint, out, won)
        seg = self.tree.segments(a, b)
        enter, leave = self.tree.span(seg)
        todo = np.flatnonzero(enter <= leave)
        step = self.tree.window / np.maximum(np.linalg.norm(b - a, axis=1), 1e-300)
        start = enter.copy()
        asked: set[int] = set()  # members asked about all their rows (not _OWN_ROWS)
        while todo.size:  # window by window along the segments, nearest first
            ahead = np.maximum(start[todo] + step[todo], np.nextafter(start[todo], 2.0))
            stop = np.minimum(ahead, leave[todo])
            rows, boxed = self.tree.pairs(seg, todo, start[todo], np.minimum(stop, out.t[todo]))
            self._window(group, rows, boxed, a, b, footprint, out, won, asked)
            going = (out.t[todo] > stop) & (stop < leave[todo])  # nothing hit up to its end
            start[todo[going]] = stop[going]
            todo = todo[going]
        return out

    def _window(self, group: Group, rows, boxed, a, b, footprint, out: Hits, won, asked) -> None:
        """The hits of the (segment ``rows``, member ``boxed``) pairs a window found
        (members in ``asked`` have answered for all their rows already)."""
        balls = self.ball[boxed]
        self._balls(rows[balls], boxed[balls], a, b, out, won)
        rows, boxed = rows[~balls], boxed[~balls]
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
            a[rows], b[rows], self.centre[s], self.radius[s], self.radius2[s]
        )
        rows, boxed, s = rows[hit], boxed[hit], s[hit]
        member = self.boxed[boxed]
        order = np.lexsort((member, t, rows))  # per segment: nearest, then earliest member
        first = order[np.r_[True, rows[order][1:] != rows[order][:-1]]] if rows.size else order
        r = rows[first]
        hits = Hits(np.ones(r.size, bool), t[first], self.ball_id[s[first]], p[first], n[first],
                    uv[first], self.colour[s[first]].copy())  # fmt: skip
        _keep(out, won, r, hits, member[first], None)


def _id(obj: Any, oid: int | None) -> int:
    """The id a member's hits report: the group's for it, else its own."""
    return int(obj.object_id) if oid is None else int(oid)


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

"""Groups of intersectors: the nearest hit over the members."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from .hits import _INF, Hits, _segments, filters, segment_overlaps


class Group:
    """The nearest hit over member intersectors, each sent only the segments near its bounds.

    Object ids: member k reports ``ids[k]`` (default: k, its position in the list; an id
    None keeps the ids the member reports itself).
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
        for k, obj in enumerate(self.objects):
            if np.isnan(np.asarray(obj.bounds, dtype=np.float64)).any():
                raise ValueError(f"object {k} has NaN bounds (non-finite vertices?)")
        if self.objects:
            lo = np.min([np.asarray(o.bounds[0], np.float64) for o in self.objects], axis=0)
            hi = np.max([np.asarray(o.bounds[1], np.float64) for o in self.objects], axis=0)
        else:
            lo, hi = np.full(3, _INF), np.full(3, -_INF)
        self.bounds = (lo, hi)

    @property
    def filters(self) -> bool:
        """Whether a member colours over footprints (core.geometry.hits.filters)."""
        return any(filters(obj) for obj in self.objects)

    def intersect(self, a: np.ndarray, b: np.ndarray, footprint: np.ndarray | None = None) -> Hits:
        """Nearest hit of each segment a -> b (N, 3) over all members, those that filter
        coloured over ``footprint`` (N, 2, 3) where given."""
        a, b = _segments(a, b)
        out = Hits.miss(a.shape[0])
        for obj, oid in zip(self.objects, self.ids, strict=True):
            rows = np.flatnonzero(segment_overlaps(a, b, *obj.bounds))
            if rows.size == 0:
                continue
            seen = None if footprint is None or not filters(obj) else footprint[rows]
            whole = len(self.objects) == 1 and rows.size == a.shape[0]
            near: Any = slice(None) if whole else rows  # one member near all: its hits
            hits = obj.intersect(a[near], b[near]) if seen is None else (
                obj.intersect(a[near], b[near], seen))  # fmt: skip
            if whole:
                if oid is not None:
                    hits.object_id[hits.hit] = oid
                return hits
            out.merge(rows, hits, oid)
        return out

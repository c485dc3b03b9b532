"""A ray's clearance from the scene's objects: the smallest angle, seen from the camera,
between any chord of its path and any one object's bounds (``RayResults.clearance``).

Adaptive sampling (core.sampling) interpolates a block of pixels only where its rays kept
clear of everything by more than the block's spread: then nothing can hide between them;
a traced ray that missed an object by less than its own error reports a possible flip,
and a hit ray's clearance counts only the objects it did not hit (``besides_hit``).
Each object and volume keeps its own box (objects spread over the frame do not merge into
one box that covers it all), and every chord of a path counts, not its ends: long steps
far from a hole pass small objects between their ends. Beyond FEW_BOXES objects a chord
meets only those a broad phase finds near its path, nearest first (LEVELS): a crowd of
10^5 spheres costs a chord its few nearest, not the hundreds within its margin.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from ..geometry import Disk, Plane, Sphere
from ..geometry.boxcells import ManyBoxes
from ..geometry.hits import slab_span

SUBPOINTS = 8
"""A chord is measured at SUBPOINTS + 1 evenly spaced points, then refined near the
nearest of them (_zoom)."""


class Gap:
    """The exact distance from one kind of shape (0 inside), its parameters as fields:
    those of one object, or stacked (``stack``: shaped (K, 1, ...) against points (K, S,
    3)) and taken per (chord, object) pair (``take``). Exact
    where the shape's box is loose (a sphere's corners reach 0.7 of its radius beyond it; an
    annulus's box holds its hole, where rays pass the accretion disk's shadow; a tilted
    strip's box holds much sky)."""

    def __call__(self, points: np.ndarray) -> np.ndarray:
        """(...) the distance from points (..., 3) (one object; taken: (P, K, 3))."""
        raise NotImplementedError

    def take(self, rows: np.ndarray) -> Gap:
        """The stacked parameters ``rows`` (one a pair)."""
        return type(self)(**{f.name: getattr(self, f.name)[rows] for f in fields(self)})  # type: ignore[arg-type]

    @classmethod
    def stack(cls, gaps: Sequence[Gap]) -> Gap:
        """Objects' parameters stacked on a leading axis, each shaped (K, 1, ...) against
        points (K, ..., 3)."""
        names = [f.name for f in fields(cls)]  # type: ignore[arg-type]
        return cls(**{n: np.stack([np.asarray(getattr(g, n), float) for g in gaps])[:, None]
                      for n in names})  # fmt: skip


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The dot products of a and b along their last axis (broadcast; einsum: 5x a sum of
    their product over an axis of 3)."""
    return np.einsum("...i,...i->...", a, b)


def _length(a: np.ndarray) -> np.ndarray:
    """The lengths of vectors a (..., 3)."""
    return np.sqrt(_dot(a, a))


@dataclass(frozen=True)
class BoxGap(Gap):
    """The distance from a box [lo, hi] (infinite sides: none along them)."""

    lo: np.ndarray
    hi: np.ndarray

    def __call__(self, points: np.ndarray) -> np.ndarray:
        with np.errstate(invalid="ignore"):
            outside = np.maximum(np.maximum(self.lo - points, points - self.hi), 0.0)
            outside = np.nan_to_num(outside)
        return _length(outside)


@dataclass(frozen=True)
class SphereGap(Gap):
    """The distance from a ball (a core.Sphere)."""

    centre: np.ndarray
    radius: np.ndarray

    def __call__(self, points: np.ndarray) -> np.ndarray:
        return np.maximum(_length(points - self.centre) - self.radius, 0.0)


@dataclass(frozen=True)
class AnnulusGap(Gap):
    """The distance from an annulus (a core.Disk)."""

    centre: np.ndarray
    normal: np.ndarray
    r_in: np.ndarray
    r_out: np.ndarray

    def __call__(self, points: np.ndarray) -> np.ndarray:
        offset = points - self.centre
        height = _dot(offset, self.normal)
        radial = _length(offset - height[..., None] * self.normal)
        beyond = np.maximum(np.maximum(self.r_in - radial, radial - self.r_out), 0.0)
        return np.hypot(height, beyond)


@dataclass(frozen=True)
class RectangleGap(Gap):
    """The distance from a finite plane (a rectangle centred at its point)."""

    point: np.ndarray
    normal: np.ndarray
    u_axis: np.ndarray
    v_axis: np.ndarray
    half_u: np.ndarray  # half its extent along u
    half_v: np.ndarray

    def __call__(self, points: np.ndarray) -> np.ndarray:
        offset = points - self.point
        height = _dot(offset, self.normal)
        u = np.maximum(np.abs(_dot(offset, self.u_axis)) - self.half_u, 0.0)
        v = np.maximum(np.abs(_dot(offset, self.v_axis)) - self.half_v, 0.0)
        return np.sqrt(height * height + u * u + v * v)


Bound = tuple[np.ndarray, np.ndarray, "Gap | None", int]
"""(lo, hi, gap, object id): an object's world box, where known its exact distance, and
the id its hits report (Hits.object_id; VOLUME_ID for a volume)."""

VOLUME_ID = -3
"""The id of a volume's bound: no hit reports it (-1 is no hit, -2 the accretion disk's
DISK_ID), so a volume is never taken for the object a ray hit."""

FEW_BOXES = 16
"""Up to this many bounds, every chord is tested against each; more, only against those a
broad phase (core.geometry.boxcells.ManyBoxes) finds overlapping the chord's box widened
by its margin."""
PAIRS = 1 << 16
"""(chord, bound) pairs measured at once at most (memory bounded)."""
FEW_NEAR = 32
"""A chord with at most this many bounds listed in the cells around it (a bound once a
cell) looks for its bounds at its whole margin at once (LEVELS)."""
PIECES = 16
"""The broad phase takes a chord in up to PIECES pieces, each about a cell of its grid or
twice the chord's reach long (a long slanting chord's own box holds many bounds far from
it)."""
LEVELS = (1 / 32, 1 / 16, 1 / 8, 1 / 4, 1 / 2, 1.0)
"""With the broad phase, chords look for the bounds within these shares of their margin in
turn: a chord with two bounds nearer (as seen) than any beyond the share can be is done
(its nearest and the nearest of the others are among them); the others look farther. In
a crowd (10^5 spheres) a chord is near hundreds of bounds within its margin, and only its
nearest two count."""


def shape_distance(obj: Any) -> Gap | None:
    """The exact distance from a Sphere, a Disk (annulus) or a finite Plane (a rectangle:
    a tilted strip's box holds much sky, and a ray through it kept a clearance of 0, traced
    again at every retrace: benchmarks/honesty.py thin_front, 0.3 retraces a ray); None
    for other shapes (their box stands for them)."""
    if isinstance(obj, Sphere):
        return SphereGap(np.asarray(obj.center, float), np.asarray(obj.radius, float))
    if isinstance(obj, Disk):
        return AnnulusGap(*(np.asarray(x, float) for x in (obj.center, obj.normal, obj.r_in,
                                                          obj.r_out)))  # fmt: skip
    if isinstance(obj, Plane) and obj.extent is not None:
        axes = (obj.point, obj.normal, obj.u_axis, obj.v_axis, *(0.5 * np.asarray(obj.extent)))
        return RectangleGap(*(np.asarray(x, float) for x in axes))
    return None


class ClearanceBoxes:
    """World bounds of the scene's objects and volumes, one each, and the margin beyond
    which a chord counts as clear (the coarsest block's spread at the farthest box)."""

    def __init__(self, boxes: Sequence[Bound], margin: float) -> None:
        """Bounds (lo, hi, gap, id) in world coordinates (infinite sides allowed:
        planes); their gaps stacked by kind (a box's own where none is known)."""
        self.lo = np.array([lo for lo, *_ in boxes], float).reshape(-1, 3)
        self.hi = np.array([hi for _, hi, *_ in boxes], float).reshape(-1, 3)
        self.ids = np.array([oid for *_, oid in boxes], dtype=np.int64)
        self.margin = float(margin)
        gaps = [BoxGap(lo, hi) if g is None else g for lo, hi, g, _ in boxes]
        kinds = list(dict.fromkeys(type(g) for g in gaps))
        self.kind = np.array([kinds.index(type(g)) for g in gaps], np.int64)
        """Each bound's kind of gap: an index into ``gaps``."""
        self.slot = np.zeros(len(gaps), np.int64)
        """Each bound's row in its kind's stacked gaps."""
        self.gaps = []
        for index, kind in enumerate(kinds):
            members = np.flatnonzero(self.kind == index)
            self.slot[members] = np.arange(members.size)
            self.gaps.append(kind.stack([gaps[m] for m in members]))
        finite = np.isfinite(self.lo).all(axis=1) & np.isfinite(self.hi).all(axis=1)
        self.apart = np.flatnonzero(~finite)
        """The bounds every chord is tested against (unbounded; all, up to FEW_BOXES)."""
        self.broad = None
        if len(gaps) > FEW_BOXES and finite.any():
            self.boxed = np.flatnonzero(finite)
            self.broad = ManyBoxes(self.lo[finite], self.hi[finite])
        else:
            self.apart = np.arange(len(gaps))

    def record(
        self,
        rows: np.ndarray,
        a: np.ndarray,
        b: np.ndarray,
        eye,
        out: Any,
        bend=None,
        share: np.ndarray | None = None,
        until: np.ndarray | None = None,
    ) -> None:
        """Lower the clearances of the rays ``rows`` (distinct; ``out``: RayResults) by the
        world chords a -> b (M, 3) seen from ``eye`` (M, 3), each chord measured on its part
        within the margin of a box; with ``bend`` (P, R, slack) ((M, 3), (M, 3), (M,)),
        on the cubic path a + U (b - a) + U (1 - U) ((1 - U) P - U R) instead (the Hermite
        cubic of a step a -> b with end velocities v0, v1: P = a - b + h v0, R = a - b
        + h v1), its gaps less ``slack``:
        ``clearance`` the smallest angle to any box, the box it was to (``clearance_box``)
        and the smallest to any other (``clearance_other``; a bound from below: _lower's
        rule). With ``share`` (M,), chord k is
        measured within share[k] x the margin. With ``until`` (M,), chord k only up to that
        fraction of it (where its ray hit a surface: what lies beyond is not on its path)."""
        share = np.ones(len(rows)) if share is None else share
        until = np.ones(len(rows)) if until is None else until
        margin = self.margin * share
        levels = LEVELS if self.broad is not None else (1.0,)
        beyond = _Beyond(a, b, eye, bend) if len(levels) > 1 else None
        first = self._first_level(a, b, margin, len(levels) - 1)
        pending = np.zeros(0, np.int64)
        for level, scale in enumerate(levels):
            last = level == len(levels) - 1
            starting = np.flatnonzero(first == level)  # none of them pending
            pending = np.sort(np.concatenate([pending, starting])) if pending.size else starting
            chord, box = self._candidates(a, b, bend, scale * margin, pending)
            resolved = np.zeros(len(rows), bool)
            for part in _chunks(chord, PAIRS):
                q, k = chord[part], box[part]
                with np.errstate(divide="ignore"):
                    inv_d = 1.0 / (b[q] - a[q])
                wide = margin[q, None]
                enter, leave = slab_span(a[q], inv_d, self.lo[k] - wide, self.hi[k] + wide)
                leave = np.minimum(leave, until[q])
                r = rows[q]
                done = (out.clearance[r] <= 0.0) & (out.clearance_box[r] == k)
                near = np.flatnonzero((enter <= leave) & ~done)  # touching box k: lowers nothing
                q, k, span = q[near], k[near], (enter[near], leave[near])
                angle = self._angles(q, k, span, a, b, eye, bend)
                if beyond is not None and not last:  # chords whose nearest two lie within reach
                    ok = _two_below(q, angle, beyond.least(scale * margin))
                    resolved[q[ok]] = True
                    q, k, angle = q[ok], k[ok], angle[ok]
                if q.size:
                    _lower(out, rows, q, k, angle)
            pending = pending[~resolved[pending]]

    def _first_level(self, a: np.ndarray, b: np.ndarray, margin: np.ndarray, last: int):
        """(M,) the level of LEVELS each chord starts at: the last where few bounds are
        listed in the cells around its box widened by its margin (FEW_NEAR: looking
        nearer first would cost more than it saves), else the first."""
        if self.broad is None:
            return np.full(len(a), last)
        wide = margin[:, None]
        low, high = (np.minimum(a, b) - wide).T, (np.maximum(a, b) + wide).T
        return np.where(self.broad.lists.listed(low, high) <= FEW_NEAR, last, 0)

    def _candidates(self, a, b, bend, reach: np.ndarray, pending: np.ndarray):
        """(chord, bound) pairs, by chord, of the chords ``pending`` whose paths (bent by
        ``bend``: ClearanceBoxes.record) may come within ``reach`` (M,) of a bound: each
        with every bound ``apart``, and with those the broad phase finds overlapping the
        boxes of its path's pieces widened by its reach (and by how far a piece of the cubic
        can stray from its chord: its second derivative is at most 4 (|P| + |R|), so a
        piece of 1/n of it strays at most (|P| + |R|) / (2 n^2))."""
        chord = pending.repeat(self.apart.size)
        box = np.tile(self.apart, pending.size)
        if self.broad is not None and pending.size:
            a, b, wide = a[pending], b[pending], reach[pending]
            n = np.zeros(pending.size) if bend is None else _bow(bend[0], bend[1])[pending]
            length = np.linalg.norm(b - a, axis=1) + 2.0 * n
            size = np.maximum(2.0 * wide, float(self.broad.cells.size.min()))
            pieces = np.clip(np.ceil(length / size), 1, PIECES).astype(np.int64)
            owner = np.arange(pending.size).repeat(pieces)
            t = np.arange(owner.size) - (np.cumsum(pieces) - pieces).repeat(pieces)
            t0, t1 = (x / pieces[owner] for x in (t, t + 1))
            path = _Path(a[owner], b[owner], None if bend is None else (
                np.zeros(owner.size), np.ones(owner.size),
                *(x[pending][owner] for x in bend)))  # fmt: skip
            ends = [path.at(u[:, None])[:, 0] for u in (t0, t1)]
            stray = 27.0 / 8.0 * n / pieces * (1.0 / pieces)  # (|P| + |R|) / (2 n^2)
            wide = (wide + stray)[owner, None]
            low, high = np.minimum(*ends) - wide, np.maximum(*ends) + wide
            near, boxed = self.broad.pairs(low.T, high.T, owner)
            chord = np.concatenate([chord, pending[near]])
            box = np.concatenate([box, self.boxed[boxed]])
            order = np.argsort(chord, kind="stable")
            chord, box = chord[order], box[order]
        return chord, box

    def _angles(self, q, k, span, a, b, eye, bend) -> np.ndarray:
        """(P,) the angle of each pair's chord part [enter, leave] (``span``) to its bound,
        each kind of bound's pairs measured at once."""
        angle = np.empty(q.size)
        for index, gaps in enumerate(self.gaps):
            pick = np.flatnonzero(self.kind[k] == index)
            if pick.size == 0:
                continue
            c, enter, leave = q[pick], span[0][pick], span[1][pick]
            d = b[c] - a[c]
            start, end = a[c] + enter[:, None] * d, a[c] + leave[:, None] * d
            bent = None if bend is None else (enter, leave, *(x[c] for x in bend))
            angle[pick] = _chord_angle(start, end, eye[c], gaps.take(self.slot[k[pick]]), bent)
        return angle

    def besides_hit(self, out: Any) -> np.ndarray:
        """(N,) each ray's clearance from everything but the object it hit (all of it for
        the rays that hit nothing)."""
        box = out.clearance_box
        own = (box >= 0) & (out.object_id != -1)  # -1: no hit (the disk's id is -2)
        own[own] = self.ids[box[own]] == out.object_id[own]
        return np.where(own, out.clearance_other, out.clearance)


def _chunks(chord: np.ndarray, most: int):
    """Slices of pairs sorted by chord, at most ``most`` each (or one chord's), none
    splitting a chord's pairs."""
    start = 0
    while start < chord.size:
        stop = min(start + most, chord.size)
        if stop < chord.size:
            cut = int(np.searchsorted(chord, chord[stop], side="left"))
            stop = cut if cut > start else int(np.searchsorted(chord, chord[stop], side="right"))
        yield slice(start, stop)
        start = stop


def _bow(P: np.ndarray, R: np.ndarray) -> np.ndarray:
    """(M,) how far a cubic a + U (b - a) + U (1 - U) ((1 - U) P - U R) strays from its
    chord at most: 4/27 (|P| + |R|)."""
    return 4.0 / 27.0 * (np.linalg.norm(P, axis=1) + np.linalg.norm(R, axis=1))


class _Beyond:
    """How near, as seen from the eye, the paths of chords a -> b (M, 3) (bent: ``bend``,
    ClearanceBoxes.record) can come to a bound that lies beyond a reach of the path."""

    def __init__(self, a: np.ndarray, b: np.ndarray, eye: np.ndarray, bend) -> None:
        """The paths' farthest point from the eye (a cubic strays from its chord by its
        bow at most) and their slack."""
        self.slack, bow = np.zeros(len(a)), np.zeros(len(a))
        if bend is not None:
            bow, self.slack = _bow(bend[0], bend[1]), bend[2]
        far = np.maximum(np.linalg.norm(a - eye, axis=1), np.linalg.norm(b - eye, axis=1))
        self.far = far + bow

    def least(self, reach: np.ndarray) -> np.ndarray:
        """(M,) the least angle a bound beyond ``reach`` (M,) of each path can be seen at
        from it, its gaps less its slack (0 where the slack is that large)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            angle = np.maximum(reach - self.slack, 0.0) / self.far
        return np.nan_to_num(angle, nan=0.0, posinf=0.0)


def _two_below(q: np.ndarray, angle: np.ndarray, bound: np.ndarray) -> np.ndarray:
    """(P,) whether pair p's chord q[p] (pairs by chord, a bound once each) has two pairs
    with angles below its ``bound`` (M,): no bound beyond can then be its nearest or the
    nearest of the others (_lower)."""
    count = np.bincount(q[angle < bound[q]], minlength=bound.size)
    return count[q] >= 2


def _lower(out: Any, rows: np.ndarray, q: np.ndarray, k: np.ndarray, angle: np.ndarray) -> None:
    """Lower the clearances of rays rows[q] by the angles of their chords q (sorted) to
    bounds k (each bound once a chord), all of a chord's pairs at once: ``clearance`` the
    least of all; ``clearance_box`` the first bound at the least where that is below what
    the ray had, else the one it had; ``clearance_other`` the least of the other bounds'
    angles and, where the nearest bound changed, what the ray had."""
    starts = np.flatnonzero(np.r_[True, q[1:] != q[:-1]])  # each chord's first pair
    chord = np.cumsum(np.r_[False, q[1:] != q[:-1]])  # each pair's chord among them
    r = rows[q[starts]]
    best, box, other = out.clearance[r], out.clearance_box[r], out.clearance_other[r]
    least = np.minimum.reduceat(angle, starts)
    top = np.iinfo(np.int64).max
    first = np.minimum.reduceat(np.where(angle == least[chord], k, top), starts)
    lower = least < best
    moved = lower & (first != box)
    box = np.where(lower, first, box)
    nearest = np.minimum.reduceat(np.where(k != box[chord], angle, np.inf), starts)
    other = np.minimum(other, nearest)
    out.clearance_other[r] = np.where(moved, np.minimum(other, best), other)
    out.clearance[r] = np.minimum(best, least)
    out.clearance_box[r] = box


def _chord_angle(a, b, eye, gap_of: Gap, bent=None) -> np.ndarray:
    """(M,) the angle, seen from ``eye``, between chords a -> b and their objects (their
    ``gap_of``, stacked: one a chord): the least over SUBPOINTS + 1 points of each chord
    and the point nearest the object, found by a zooming grid search (_zoom) between the
    two points beside the nearest of them. With ``bent`` (enter, leave, P,
    R, slack), a -> b is the part [enter, leave] of a step's chord, the points are moved
    onto the step's cubic and the gaps are less slack (ClearanceBoxes.record)."""
    path = _Path(a, b, bent)
    t = np.linspace(0.0, 1.0, SUBPOINTS + 1)
    points = path.at(t[None, :])  # (M, K, 3)
    gap = path.less_slack(gap_of(points))
    with np.errstate(divide="ignore", invalid="ignore"):
        angle = gap / _length(points - eye[:, None, :])
    least = np.nan_to_num(np.min(angle, axis=1), nan=0.0)
    spacing = 0.5 * _length(b - a) / SUBPOINTS  # a point's farthest from a sample
    closest = np.min(gap, axis=1)
    rough = np.flatnonzero((closest < 2.0 * spacing) & (closest > 0.0))  # samples may miss it
    if rough.size:
        k = np.argmin(gap[rough], axis=1)
        lo_t, hi_t = t[np.maximum(k - 1, 0)], t[np.minimum(k + 1, SUBPOINTS)]
        near, near_gap = path.take(rough), gap_of.take(rough)
        best = _zoom(lambda u: near.less_slack(near_gap(near.at(u))), lo_t, hi_t)
        at = near.at(best[:, None])  # (R, 1, 3)
        with np.errstate(divide="ignore", invalid="ignore"):
            nearest = near.less_slack(near_gap(at)[:, 0]) / _length(at[:, 0] - eye[rough])
        least[rough] = np.minimum(least[rough], np.nan_to_num(nearest, nan=0.0))
    return least


class _Path:
    """Chords a -> b (M, 3), or with ``bent`` (enter, leave, P, R, slack) the cubic paths
    over them with their slack (_chord_angle): points by parameter."""

    def __init__(self, a: np.ndarray, b: np.ndarray, bent=None) -> None:
        self.a, self.d, self.bent = a, b - a, bent

    def take(self, rows: np.ndarray) -> _Path:
        """The paths ``rows``."""
        bent = None if self.bent is None else tuple(x[rows] for x in self.bent)
        return _Path(self.a[rows], self.a[rows] + self.d[rows], bent)

    def at(self, t: np.ndarray) -> np.ndarray:
        """Points (M, K, 3) at the parameters t ((M, K) or (1, K)) of the chords, moved
        onto the cubics: U (1 - U) ((1 - U) P - U R) at U = enter + t (leave - enter)."""
        points = self.a[:, None, :] + t[..., None] * self.d[:, None, :]
        if self.bent is not None:
            enter, leave, P, R, _ = self.bent
            U = enter[:, None] + t * (leave - enter)[:, None]
            bow = U * (1 - U)
            points += (bow * (1 - U))[..., None] * P[:, None, :]
            points -= (bow * U)[..., None] * R[:, None, :]
        return points

    def less_slack(self, gap: np.ndarray) -> np.ndarray:
        """Gaps (M,) or (M, K) less the paths' slack, not below 0."""
        if self.bent is None:
            return gap
        slack = self.bent[4]
        return np.maximum(gap - (slack if gap.ndim == 1 else slack[:, None]), 0.0)


ZOOM_POINTS, ZOOMS = 9, 5
"""A chord's point nearest an object, where the samples may have missed it (their nearest
within two half-spacings of it), is found on ZOOM_POINTS evenly spaced points of its
bracket (a quarter of the chord), ZOOMS times, each time around the best of them (the
bracket shrinks 4x a time: to 1e-3 of itself; all rays at once, a few array operations
each time, where a golden-section search took 34 small ones)."""


def _zoom(f, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(M,) where each f (of (M, K) parameters -> (M, K) values) is least in [lo, hi]:
    grid search with zoom (exact for a convex f: the distance from a box or a ball along
    a line; a local minimum near the sampled one otherwise)."""
    grid = np.linspace(0.0, 1.0, ZOOM_POINTS)
    rows = np.arange(lo.size)
    for _ in range(ZOOMS):
        u = lo[:, None] + grid[None, :] * (hi - lo)[:, None]
        best = np.argmin(f(u), axis=1)
        lo = u[rows, np.maximum(best - 1, 0)]
        hi = u[rows, np.minimum(best + 1, ZOOM_POINTS - 1)]
    return 0.5 * (lo + hi)


def clear_radius(bounds: Sequence[Bound], point: np.ndarray) -> float:
    """How far ``point`` (3,) is from the nearest of ``bounds`` (each object's exact shape
    where known, else its box); inf: no bounds."""
    gaps = [(BoxGap(lo, hi) if g is None else g)(point) for lo, hi, g, _ in bounds]
    return float(min(gaps, default=np.inf))

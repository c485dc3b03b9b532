"""A ray's clearance from the scene's objects: the smallest angle, seen from the camera,
between any chord of its path and any one object's bounds (``RayResults.clearance``).

Adaptive sampling (core.sampling) interpolates a block of pixels only where its rays kept
clear of everything by more than the block's spread: then nothing can hide between them;
a traced ray that missed an object by less than its own error reports a possible flip,
and a hit ray's clearance counts only the objects it did not hit (``besides_hit``).
Each object and volume keeps its own box (objects spread over the frame do not merge into
one box that covers it all), and every chord of a path counts, not its ends: long steps
far from a hole pass small objects between their ends.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from ..geometry import Disk, Plane, Sphere
from ..geometry.hits import slab_span

SUBPOINTS = 8
"""A chord is measured at SUBPOINTS + 1 evenly spaced points, then refined near the
nearest of them (_zoom)."""


Distance = Callable[[np.ndarray], np.ndarray]
"""World points (..., 3) -> their distance (...) from an object (0 inside): exact for the
shapes whose box is loose (a sphere's corners reach 0.7 of its radius beyond it; an
annulus's box holds its hole, where rays pass the accretion disk's shadow)."""
Bound = tuple[np.ndarray, np.ndarray, "Distance | None", int]
"""(lo, hi, distance, object id): an object's world box, where known its exact distance,
and the id its hits report (Hits.object_id; VOLUME_ID for a volume)."""

VOLUME_ID = -3
"""The id of a volume's bound: no hit reports it (-1 is no hit, -2 the accretion disk's
DISK_ID), so a volume is never taken for the object a ray hit."""


def shape_distance(obj: Any) -> Distance | None:
    """The exact distance from a Sphere, a Disk (annulus) or a finite Plane (a rectangle:
    a tilted strip's box holds much sky, and a ray through it kept a clearance of 0, traced
    again at every retrace: benchmarks/honesty.py thin_front, 0.3 retraces a ray); None
    for other shapes (their box stands for them)."""
    if isinstance(obj, Sphere):
        centre, radius = obj.center, obj.radius
        return lambda p: np.maximum(np.linalg.norm(p - centre, axis=-1) - radius, 0.0)
    if isinstance(obj, Disk):
        return lambda p: _annulus_distance(p, obj)
    if isinstance(obj, Plane) and obj.extent is not None:
        return lambda p: _rectangle_distance(p, obj)
    return None


def _rectangle_distance(points: np.ndarray, plane: Any) -> np.ndarray:
    """Distance from the points (..., 3) to the finite plane ``plane`` (a core.Plane with
    an extent: a rectangle centred at its point)."""
    offset = points - plane.point
    height = offset @ plane.normal
    u = np.maximum(np.abs(offset @ plane.u_axis) - 0.5 * plane.extent[0], 0.0)
    v = np.maximum(np.abs(offset @ plane.v_axis) - 0.5 * plane.extent[1], 0.0)
    return np.sqrt(height * height + u * u + v * v)


def _annulus_distance(points: np.ndarray, disk: Any) -> np.ndarray:
    """Distance from the points (..., 3) to the annulus ``disk`` (a core.Disk)."""
    offset = points - disk.center
    height = offset @ disk.normal
    radial = np.linalg.norm(offset - height[..., None] * disk.normal, axis=-1)
    beyond = np.maximum(np.maximum(disk.r_in - radial, radial - disk.r_out), 0.0)
    return np.hypot(height, beyond)


class ClearanceBoxes:
    """World bounds of the scene's objects and volumes, one each, and the margin beyond
    which a chord counts as clear (the coarsest block's spread at the farthest box)."""

    def __init__(self, boxes: Sequence[Bound], margin: float) -> None:
        """Bounds (lo, hi, distance, id) in world coordinates (infinite sides allowed:
        planes)."""
        self.boxes = [(np.asarray(lo, float), np.asarray(hi, float), d) for lo, hi, d, _ in boxes]
        self.ids = np.array([oid for *_, oid in boxes], dtype=np.int64)
        self.margin = float(margin)

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
        """Lower the clearances of the rays ``rows`` (``out``: RayResults) by the world
        chords a -> b (M, 3) seen from ``eye`` (M, 3), each chord measured on its part
        within the margin of a box; with ``bend`` (P, R, slack) ((M, 3), (M, 3), (M,)),
        on the cubic path a + U (b - a) + U (1 - U) ((1 - U) P - U R) instead (the Hermite
        cubic of a step a -> b with end velocities v0, v1: P = a - b + h v0, R = a - b
        + h v1), its gaps less ``slack``:
        ``clearance`` the smallest angle to any box, the box it was to (``clearance_box``)
        and the smallest to any other (``clearance_other``; a bound from below: a box
        overtaken keeps what it had). With ``share`` (M,), chord k is measured within
        share[k] x the margin. With ``until`` (M,), chord k only up to that fraction of it
        (where its ray hit a surface: what lies beyond is not on its path)."""
        with np.errstate(divide="ignore"):
            inv_d = 1.0 / (b - a)
        margin = self.margin if share is None else self.margin * share[:, None]
        for k, (lo, hi, distance) in enumerate(self.boxes):
            enter, leave = slab_span(a, inv_d, lo - margin, hi + margin)
            if until is not None:
                leave = np.minimum(leave, until)
            near = np.flatnonzero(enter <= leave)
            done = (out.clearance[rows[near]] <= 0.0) & (out.clearance_box[rows[near]] == k)
            near = near[~done]  # touching box k already: its chords can lower nothing
            if near.size == 0:
                continue
            d = b[near] - a[near]
            start, end = (a[near] + t[near, None] * d for t in (enter, leave))
            bent = None if bend is None else (enter[near], leave[near], *(x[near] for x in bend))
            angle = _chord_angle(start, end, eye[near], lo, hi, distance, bent)
            r = rows[near]
            best, box = out.clearance[r], out.clearance_box[r]
            same = box == k
            overtakes = ~same & (angle < best)
            out.clearance_other[r] = np.where(
                overtakes, np.minimum(best, out.clearance_other[r]),
                np.where(same, out.clearance_other[r], np.minimum(out.clearance_other[r], angle)),
            )  # fmt: skip
            out.clearance[r] = np.minimum(best, angle)
            out.clearance_box[r] = np.where(overtakes, k, box)

    def besides_hit(self, out: Any) -> np.ndarray:
        """(N,) each ray's clearance from everything but the object it hit (all of it for
        the rays that hit nothing)."""
        box = out.clearance_box
        own = (box >= 0) & (out.object_id != -1)  # -1: no hit (the disk's id is -2)
        own[own] = self.ids[box[own]] == out.object_id[own]
        return np.where(own, out.clearance_other, out.clearance)


def _chord_angle(a, b, eye, lo, hi, distance=None, bent=None) -> np.ndarray:
    """(M,) the angle, seen from ``eye``, between chords a -> b and the box [lo, hi] (or
    the object, by its ``distance``): the least over SUBPOINTS + 1 points of each chord
    and the point nearest the object, found by a zooming grid search (_zoom) between the
    two points beside the nearest of them. With ``bent`` (enter, leave, P,
    R, slack), a -> b is the part [enter, leave] of a step's chord, the points are moved
    onto the step's cubic and the gaps are less slack (ClearanceBoxes.record)."""
    gap_of = distance if distance is not None else _box_distance(lo, hi)
    path = _Path(a, b, bent)
    t = np.linspace(0.0, 1.0, SUBPOINTS + 1)
    points = path.at(t[None, :])  # (M, K, 3)
    gap = path.less_slack(gap_of(points))
    with np.errstate(divide="ignore", invalid="ignore"):
        angle = gap / np.linalg.norm(points - eye[:, None, :], axis=2)
    least = np.nan_to_num(np.min(angle, axis=1), nan=0.0)
    spacing = 0.5 * np.linalg.norm(b - a, axis=1) / SUBPOINTS  # a point's farthest from a sample
    closest = np.min(gap, axis=1)
    rough = np.flatnonzero((closest < 2.0 * spacing) & (closest > 0.0))  # samples may miss it
    if rough.size:
        k = np.argmin(gap[rough], axis=1)
        lo_t, hi_t = t[np.maximum(k - 1, 0)], t[np.minimum(k + 1, SUBPOINTS)]
        near = path.take(rough)
        best = _zoom(lambda u: near.less_slack(gap_of(near.at(u))), lo_t, hi_t)
        at = near.at(best[:, None])[:, 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            nearest = near.less_slack(gap_of(at)) / np.linalg.norm(at - eye[rough], axis=1)
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
    gaps = [(d if d is not None else _box_distance(lo, hi))(point[None, :])[0]
            for lo, hi, d, _ in bounds]  # fmt: skip
    return float(min(gaps, default=np.inf))


def _box_distance(lo: np.ndarray, hi: np.ndarray) -> Distance:
    """The distance from the box [lo, hi] (infinite sides: none along them)."""

    def gap(points: np.ndarray) -> np.ndarray:
        with np.errstate(invalid="ignore"):
            outside = np.nan_to_num(np.maximum(np.maximum(lo - points, points - hi), 0.0))
        return np.sqrt(np.sum(outside * outside, axis=-1))

    return gap

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

from ..geometry import Disk, Sphere
from ..geometry.hits import slab_span

SUBPOINTS = 8
"""A chord is measured at SUBPOINTS + 1 evenly spaced points, then refined near the
nearest of them (_golden)."""


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
    """The exact distance from a Sphere or a Disk (annulus); None for other shapes (their
    box stands for them)."""
    if isinstance(obj, Sphere):
        centre, radius = obj.center, obj.radius
        return lambda p: np.maximum(np.linalg.norm(p - centre, axis=-1) - radius, 0.0)
    if isinstance(obj, Disk):
        return lambda p: _annulus_distance(p, obj)
    return None


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

    def record(self, rows: np.ndarray, a: np.ndarray, b: np.ndarray, eye, out: Any) -> None:
        """Lower the clearances of the rays ``rows`` (``out``: RayResults) by the world
        chords a -> b (M, 3) seen from ``eye`` (M, 3), each chord measured on its part
        within the margin of a box: ``clearance`` the smallest angle to any box, the box
        it was to (``clearance_box``) and the smallest to any other (``clearance_other``;
        a bound from below: a box overtaken keeps what it had)."""
        with np.errstate(divide="ignore"):
            inv_d = 1.0 / (b - a)
        for k, (lo, hi, distance) in enumerate(self.boxes):
            enter, leave = slab_span(a, inv_d, lo - self.margin, hi + self.margin)
            near = np.flatnonzero(enter <= leave)
            if near.size == 0:
                continue
            d = b[near] - a[near]
            start, end = (a[near] + t[near, None] * d for t in (enter, leave))
            angle = _chord_angle(start, end, eye[near], lo, hi, distance)
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


def _chord_angle(a, b, eye, lo, hi, distance=None) -> np.ndarray:
    """(M,) the angle, seen from ``eye``, between chords a -> b and the box [lo, hi] (or
    the object, by its ``distance``): the least over SUBPOINTS + 1 points of each chord
    and the point nearest the object, found by golden-section search (REFINE steps)
    between the two points beside the nearest of them."""
    gap_of = distance if distance is not None else _box_distance(lo, hi)
    t = np.linspace(0.0, 1.0, SUBPOINTS + 1)
    d = b - a
    points = a[:, None, :] + t[None, :, None] * d[:, None, :]  # (M, K, 3)
    gap = gap_of(points)
    with np.errstate(divide="ignore", invalid="ignore"):
        angle = gap / np.linalg.norm(points - eye[:, None, :], axis=2)
    least = np.nan_to_num(np.min(angle, axis=1), nan=0.0)
    slack = 0.5 * np.linalg.norm(d, axis=1) / SUBPOINTS  # a point's farthest from a sample
    rough = np.flatnonzero(np.min(gap, axis=1) < 2.0 * slack)  # the samples may miss it
    if rough.size:
        k = np.argmin(gap[rough], axis=1)
        lo_t, hi_t = t[np.maximum(k - 1, 0)], t[np.minimum(k + 1, SUBPOINTS)]
        a, d, eye = a[rough], d[rough], eye[rough]
        best = _golden(lambda u: gap_of(a + u[:, None] * d), lo_t, hi_t)
        at = a + best[:, None] * d
        with np.errstate(divide="ignore", invalid="ignore"):
            nearest = gap_of(at) / np.linalg.norm(at - eye, axis=1)
        least[rough] = np.minimum(least[rough], np.nan_to_num(nearest, nan=0.0))
    return least


REFINE = 16
"""Golden-section steps for a chord's point nearest an object (its bracket, a quarter of
the chord, shrinks to 0.618^16 ~ 5e-4 of itself), where the samples may have missed it
(their nearest within two half-spacings of it)."""


def _golden(f, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(M,) where each f (of (M,) parameters -> (M,) values) is least in [lo, hi]:
    golden-section search (exact for a convex f: the distance from a box or a ball along
    a line; a local minimum near the sampled one otherwise)."""
    ratio = (np.sqrt(5.0) - 1.0) / 2.0
    x1, x2 = hi - ratio * (hi - lo), lo + ratio * (hi - lo)
    f1, f2 = f(x1), f(x2)
    for _ in range(REFINE):
        left = f1 <= f2
        hi = np.where(left, x2, hi)
        lo = np.where(left, lo, x1)
        x1, x2 = hi - ratio * (hi - lo), lo + ratio * (hi - lo)
        f1, f2 = f(x1), f(x2)
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

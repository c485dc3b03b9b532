"""A ray's clearance from the scene's objects: the smallest angle, seen from the camera,
between any chord of its path and any one object's bounds (``RayResults.clearance``).

Adaptive sampling (core.sampling) interpolates a block of pixels only where its rays kept
clear of everything by more than the block's spread: then nothing can hide between them.
Each object and volume keeps its own box (objects spread over the frame do not merge into
one box that covers it all), and every chord of a path counts, not its ends: long steps
far from a hole pass small objects between their ends.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..geometry.hits import slab_span

SUBPOINTS = 8
"""A chord is measured at SUBPOINTS + 1 evenly spaced points; the distance from a point
on it to a box is 1-Lipschitz along it, so the smallest of those less half their spacing
bounds the chord's distance from below."""


class ClearanceBoxes:
    """World boxes of the scene's objects and volumes, one each, and the margin beyond
    which a chord counts as clear (the coarsest block's spread at the farthest box)."""

    def __init__(self, boxes: Sequence[tuple[np.ndarray, np.ndarray]], margin: float) -> None:
        """Boxes (lo, hi) in world coordinates (infinite sides allowed: planes)."""
        self.boxes = [(np.asarray(lo, float), np.asarray(hi, float)) for lo, hi in boxes]
        self.margin = float(margin)

    def angles(self, a: np.ndarray, b: np.ndarray, eye: np.ndarray) -> np.ndarray:
        """(M,) radians: the smallest angle, seen from ``eye`` (M, 3), between the world
        chords a -> b (M, 3) and any box (+inf where every box is beyond the margin): each
        chord is measured on its part within the margin of a box."""
        out = np.full(a.shape[0], np.inf)
        with np.errstate(divide="ignore"):
            inv_d = 1.0 / (b - a)
        for lo, hi in self.boxes:
            enter, leave = slab_span(a, inv_d, lo - self.margin, hi + self.margin)
            rows = np.flatnonzero(enter <= leave)
            if rows.size:
                d = b[rows] - a[rows]
                near_a = a[rows] + enter[rows, None] * d
                near_b = a[rows] + leave[rows, None] * d
                angle = _chord_angle(near_a, near_b, eye[rows], lo, hi)
                out[rows] = np.minimum(out[rows], angle)
        return out


def _chord_angle(a, b, eye, lo, hi) -> np.ndarray:
    """(M,) lower bound of the angle, seen from ``eye``, between chords a -> b and the box
    [lo, hi]: 0 where a chord may touch it."""
    t = np.linspace(0.0, 1.0, SUBPOINTS + 1)
    points = a[:, None, :] + t[None, :, None] * (b - a)[:, None, :]  # (M, K, 3)
    with np.errstate(invalid="ignore"):
        outside = np.maximum(np.maximum(lo - points, points - hi), 0.0)
    gap = np.sqrt(np.einsum("mkj,mkj->mk", outside, outside))
    slack = 0.5 * np.linalg.norm(b - a, axis=1) / SUBPOINTS
    seen = np.linalg.norm(points - eye[:, None, :], axis=2) + slack[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        angle = np.maximum(gap - slack[:, None], 0.0) / seen
    return np.min(np.nan_to_num(angle, nan=0.0), axis=1)

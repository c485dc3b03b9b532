"""Hits of straight segments and the intersector interface (the core/Blender seam).

Every intersector has ``bounds`` (lo (3,), hi (3,), world AABB; infinite where unbounded)
and ``intersect(a, b) -> Hits`` for segment ends a, b of shape (N, 3). Hits report the
nearest hit along each segment; where ``hit`` is False, ``t`` is +inf, ``object_id`` is -1
and the other fields are 0. Normals are the geometric, outward (sphere) or user-given
(plane, disk, mesh winding) unit normals, not flipped towards the ray.

An intersector whose colours can be averaged over each pixel's footprint says so by a
true ``filters`` attribute and then takes ``intersect(a, b, footprint)``, ``footprint``
(N, 2, 3) the hit point's derivatives along image x and y (world units; NaN: a point):
renders find them (core.mipmap.surface_footprint) and cast again through each hit point
with them (core.tracing.segments.SceneGeometry.colour_over).
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any, Protocol, runtime_checkable

import numpy as np

from ..backend import array_module, placed

_INF = np.inf


@dataclass
class Hits:
    """Nearest hits of N segments (see the module docstring for the miss convention)."""

    hit: np.ndarray  # (N,) bool
    t: np.ndarray  # (N,) in [0, 1] along a -> b; +inf where no hit
    object_id: np.ndarray  # (N,) int32; -1 where no hit
    position: np.ndarray  # (N, 3)
    normal: np.ndarray  # (N, 3)
    uv: np.ndarray  # (N, 2)
    color: np.ndarray  # (N, 4) float64

    @classmethod
    def miss(cls, n: int, like: Any = None) -> Hits:
        """N segments that hit nothing (arrays of ``like``'s library: core.backend)."""
        xp = array_module(like)
        return cls(
            xp.zeros(n, dtype=bool), xp.full(n, _INF), xp.full(n, -1, dtype=np.int32),
            xp.zeros((n, 3)), xp.zeros((n, 3)), xp.zeros((n, 2)), xp.zeros((n, 4)),
        )  # fmt: skip

    @classmethod
    def concatenate(cls, parts: list[Hits]) -> Hits:
        """The hits of several sets of segments, one set after another."""
        return cls(*(np.concatenate([getattr(p, f.name) for p in parts]) for f in fields(cls)))

    def __len__(self) -> int:
        return self.hit.shape[0]

    def moved(self, xp: Any) -> Hits:
        """These hits as arrays of the library ``xp`` (host hits onto a device)."""
        return (
            self if xp is np else Hits(*(xp.asarray(getattr(self, f.name)) for f in fields(self)))
        )

    def take(self, rows: np.ndarray | slice) -> Hits:
        """The hits of the segments ``rows`` only (a slice or indices)."""
        return Hits(*(getattr(self, f.name)[rows] for f in fields(self)))

    def assign(self, rows: np.ndarray, other: Hits, other_rows: np.ndarray) -> None:
        """Replace the hits ``rows`` by ``other``'s ``other_rows``, in place (every field)."""
        for name in ("hit", "t", "object_id", "position", "normal", "uv", "color"):
            getattr(self, name)[rows] = getattr(other, name)[other_rows]

    def merge(self, rows: np.ndarray, other: Hits, object_id: int | None = None) -> None:
        """Take other's hits where nearer, in place; ``rows``: integer indices of other's rows.

        ``object_id``, if given, replaces the ids reported by ``other``.
        """
        nearer = other.hit & (other.t < self.t[rows])
        r = rows[nearer]
        self.hit[r] = True
        self.t[r] = other.t[nearer]
        self.object_id[r] = other.object_id[nearer] if object_id is None else object_id
        self.position[r] = other.position[nearer]
        self.normal[r] = other.normal[nearer]
        self.uv[r] = other.uv[nearer]
        self.color[r] = other.color[nearer]


@runtime_checkable
class Intersector(Protocol):
    """What the tracer needs from a scene: world bounds and segment intersection."""

    bounds: tuple[np.ndarray, np.ndarray]

    def intersect(self, a: np.ndarray, b: np.ndarray) -> Hits: ...


# The Intersector protocol's optional members, looked up here only (a user's intersector
# may have none of them):


def filters(intersector: Any) -> bool:
    """Whether an intersector colours over footprints (``filters``; the module)."""
    return bool(getattr(intersector, "filters", False))


def part_bounds(intersector: Any) -> Any:
    """((lo, hi, id) of each object) of an intersector holding many objects that reports
    their ids itself (``part_bounds``: the add-on's meshes); None for one object."""
    return getattr(intersector, "part_bounds", None)


def reported_id(intersector: Any) -> int:
    """The object id an intersector's hits report (``object_id``: core's primitives),
    -3 where it does not say."""
    return int(getattr(intersector, "object_id", -3))


def _segments(a: Any, b: Any) -> tuple[np.ndarray, np.ndarray]:
    a = np.asarray(a, dtype=np.float64).reshape(-1, 3)
    b = np.asarray(b, dtype=np.float64).reshape(-1, 3)
    if a.shape != b.shape:
        raise ValueError(f"segment ends must have equal shapes, got {a.shape} and {b.shape}")
    return a, b


def segment_overlaps(a: np.ndarray, b: np.ndarray, lo: np.ndarray, hi: np.ndarray):
    """(N,) bool: the AABB of each segment a -> b overlaps the box [lo, hi]."""
    lo, hi = placed(lo, a), placed(hi, a)
    return np.all((np.minimum(a, b) <= hi) & (np.maximum(a, b) >= lo), axis=1)


def _fill(n: int, rows: np.ndarray, t, p, nrm, uv, color, object_id: int) -> Hits:
    """Hits for n segments of which ``rows`` hit with the given per-hit data."""
    h = Hits.miss(n)
    h.hit[rows] = True
    h.t[rows] = t
    h.object_id[rows] = object_id
    h.position[rows] = p
    h.normal[rows] = nrm
    h.uv[rows] = uv
    h.color[rows] = color
    return h


def slab_entry(a: np.ndarray, inv_d: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Entry parameter t of segments a + t d, t in [0, 1], into the box; +inf where missed."""
    enter, leave = slab_span(a, inv_d, lo, hi)
    return np.where(enter <= leave, enter, _INF)


def slab_span(a: np.ndarray, inv_d: np.ndarray, lo: np.ndarray, hi: np.ndarray):
    """(enter, leave) parameters t of segments a + t d inside the box [lo, hi], clipped to
    [0, 1] (enter > leave where missed)."""
    with np.errstate(invalid="ignore", over="ignore"):
        t1, t2 = (lo - a) * inv_d, (hi - a) * inv_d
    # fmin/fmax skip the NaN of 0 * inf (a segment parallel to a slab, starting on its face)
    # (numpy's stubs do not type ufunc.reduce of an array expression)
    enter = np.maximum(np.fmax.reduce(np.fmin(t1, t2), axis=1), 0.0)  # type: ignore[call-overload]
    leave = np.minimum(np.fmin.reduce(np.fmax(t1, t2), axis=1), 1.0)  # type: ignore[call-overload]
    return enter, leave


def box_corners(lo: Any, hi: Any) -> np.ndarray:
    """(8, 3) the corners of the box [lo, hi]."""
    return np.array(np.meshgrid(*zip(lo, hi, strict=True))).reshape(3, -1).T


def segment_meets_box(a: np.ndarray, b: np.ndarray, lo: np.ndarray, hi: np.ndarray):
    """(N,) bool: the segment a -> b passes through the box [lo, hi] (a slab test)."""
    with np.errstate(divide="ignore"):
        inv_d = 1.0 / (b - a)
    return np.isfinite(slab_entry(a, inv_d, lo, hi))

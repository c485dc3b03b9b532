"""The scene's geometry along straight segments: surface hits and volume light.

Segments are cast in world space; only segments whose bounds meet the geometry's are
sent to the intersector, and only the volumes a segment's bounds meet are integrated.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from ..backend import array_module, to_host
from ..geometry import Group, Hits, Intersector, filters, segment_overlaps
from ..geometry.hits import box_corners, part_bounds, reported_id
from ..mipmap import surface_footprint
from .clearance import VOLUME_ID, Bound, shape_distance
from .scene import ENDING


@dataclass
class RayResults:
    """Per-ray outcome of a batch (rays on the first axis, world space)."""

    ending: np.ndarray  # (N,) int8
    direction: np.ndarray  # (N, 3) final direction (escape direction for escaped rays)
    position: np.ndarray  # (N, 3) final position (hit point for hit rays)
    surface: np.ndarray  # (N, 4) surface colour where hit
    radiance: np.ndarray  # (N, 3) volume emission collected in front of the ending
    transmittance: np.ndarray  # (N,) volume transmittance
    steps: np.ndarray  # (N,) int32 integration steps
    energy_error: np.ndarray  # (N,) |H - H0| at the end
    redshift: np.ndarray  # (N,) g = nu_obs / nu_emit where the ray ended on a disk, else NaN
    clearance: np.ndarray  # (N,) radians from objects' bounds (Tracer.watch_geometry)
    clearance_box: np.ndarray  # (N,) int: the bound it was to (-1: none)
    clearance_other: np.ndarray  # (N,) radians from the other bounds
    object_id: np.ndarray  # (N,) int32: the object hit (Hits.object_id); -1 where none
    tangent: np.ndarray  # (N, 3) where hit: the unit direction of the chord that hit
    doppler: np.ndarray  # (N,) g of the camera's motion its colours take (core.motion; 1: none)
    sky_jacobian: np.ndarray
    """(N, k, 3) where escaped, traced with tangents: the final direction's derivatives with
    respect to the k image coordinates (core/tracing/differentials.py); NaN elsewhere; k = 0
    without tangents."""
    magnification: np.ndarray
    """(N,) where escaped, traced with tangents: |μ| of its image, the camera's solid angle
    over the sky's (core/tracing/differentials.py); NaN elsewhere."""
    kinks: np.ndarray
    """(N,) int64: bit k set where the ray crossed the model's kink k (a jump in the slope
    of a medium's n: core.tracing.stepping.Stepper.advance); 0 for a smooth model."""

    @classmethod
    def empty(cls, n: int, origins: np.ndarray, directions: np.ndarray) -> RayResults:
        """N rays not ended yet (ending -1) at their origins, with nothing collected."""
        xp = array_module(origins)
        return cls(
            ending=xp.full(n, -1, dtype=np.int8),
            direction=directions.copy(),
            position=origins.copy(),
            surface=xp.zeros((n, 4)),
            radiance=xp.zeros((n, 3)),
            transmittance=xp.ones(n),
            steps=xp.zeros(n, dtype=np.int32),
            energy_error=xp.zeros(n),
            redshift=xp.full(n, np.nan),
            clearance=xp.full(n, np.inf),
            clearance_box=xp.full(n, -1, dtype=np.int64),
            clearance_other=xp.full(n, np.inf),
            object_id=xp.full(n, -1, dtype=np.int32),
            tangent=xp.zeros((n, 3)),
            doppler=xp.ones(n),
            sky_jacobian=xp.zeros((n, 0, 3)),
            magnification=xp.full(n, np.nan),
            kinks=xp.zeros(n, dtype=np.int64),
        )

    def take(self, rows: slice | np.ndarray) -> RayResults:
        """The results of the rays ``rows`` (a slice or indices)."""
        return RayResults(**{f.name: getattr(self, f.name)[rows] for f in fields(self)})

    def to_host(self) -> RayResults:
        """These results with every field a numpy array (from a device: core.backend)."""
        return RayResults(**{f.name: to_host(getattr(self, f.name)) for f in fields(self)})

    def accumulate(
        self, rows: np.ndarray, radiance: np.ndarray | None, trans: np.ndarray | None
    ) -> None:
        """Composite a segment's volume emission behind what the rays have collected."""
        if radiance is None:  # no volumes in the scene
            return
        self.radiance[rows] += self.transmittance[rows, None] * radiance
        self.transmittance[rows] *= trans


class SceneGeometry:
    """The objects (one intersector) and volumes of a scene, cast against world segments."""

    def __init__(self, objects: Intersector, volumes: list[Any]) -> None:
        self.objects = objects
        self.volumes = volumes
        self._bounds: list[Bound] | None = None  # boxes(), read once (10^5 spheres: 1 s)

    def record(self, rows: np.ndarray, a: np.ndarray, b: np.ndarray, out: RayResults) -> np.ndarray:
        """Cast world segments a -> b of rays ``rows``: composite the volumes crossed and
        record surface hits in ``out``. Returns which segments hit a surface (M,)."""
        return self.record_hits(rows, a, b, self.cast(a, b), out)

    def record_hits(
        self, rows: np.ndarray, a: np.ndarray, b: np.ndarray, hits: Hits, out: RayResults
    ) -> np.ndarray:
        """Record ``hits`` (of segments a -> b, possibly refined) and the volumes' light up
        to them in ``out``. Returns which segments hit a surface (M,)."""
        rad, trans = self._volume_light_on(array_module(a), a, b, hits)
        out.accumulate(rows, rad, trans)
        h = hits.hit
        out.ending[rows[h]] = ENDING["hit"]
        out.position[rows[h]] = hits.position[h]
        out.surface[rows[h]] = hits.color[h]
        out.object_id[rows[h]] = hits.object_id[h]
        chord = b[h] - a[h]
        out.tangent[rows[h]] = chord / np.linalg.norm(chord, axis=1, keepdims=True)
        return h

    @property
    def filters(self) -> bool:
        """Whether some surface's colour averages over footprints (core.geometry.hits)."""
        return filters(self.objects)

    def cast(self, a: np.ndarray, b: np.ndarray, footprint: np.ndarray | None = None) -> Hits:
        """Nearest surface hits of segments a -> b, querying only segments near geometry;
        coloured over ``footprint`` (N, 2, 3) where given and the objects filter.

        When most segments are near, all of them go (an intersector answers misses for the
        others; cheaper than gathering the near ones and scattering their hits back).
        Intersectors work on the host (the Intersector protocol): a device's segments go
        there and their hits come back (core.backend).
        """
        xp = array_module(a)
        if xp is not np:
            return self.cast(to_host(a), to_host(b), to_host(footprint)).moved(xp)
        lo, hi = self.objects.bounds
        if np.any(lo > hi):  # an empty group; infinite planes have infinite bounds
            return Hits.miss(a.shape[0])
        near = segment_overlaps(a, b, lo, hi)
        rows = np.flatnonzero(near)
        if footprint is not None and not self.filters:
            footprint = None
        if rows.size > 0.5 * a.shape[0]:
            return self._intersect(a, b, footprint)
        hits = Hits.miss(a.shape[0])
        if rows.size:
            seen = None if footprint is None else footprint[rows]
            hits.merge(rows, self._intersect(a[rows], b[rows], seen))
        return hits

    def _intersect(self, a: np.ndarray, b: np.ndarray, footprint: np.ndarray | None) -> Hits:
        """The objects' hits of segments a -> b, over ``footprint`` where not None."""
        if footprint is None:
            return self.objects.intersect(a, b)
        return self.objects.intersect(a, b, footprint)  # type: ignore[call-arg]

    def colour_over(
        self, position: np.ndarray, tangent: np.ndarray, object_id: np.ndarray, footprint
    ) -> tuple[np.ndarray, np.ndarray]:
        """(colours (M, 4), found (M,)) of surfaces at hit points ``position`` (M, 3)
        averaged over their ``footprint`` (M, 2, 3): a segment through each along its
        hitting chord's unit ``tangent``, as far either side as the footprint reaches, cast
        with it; not ``found`` where it meets something other than ``object_id`` first."""
        reach = np.max(np.linalg.norm(footprint, axis=2), axis=1)
        reach = (reach + 1e-9 * (1.0 + np.linalg.norm(position, axis=1)))[:, None]
        hits = self.cast(position - reach * tangent, position + reach * tangent, footprint)
        return hits.color, hits.hit & (hits.object_id == object_id)

    def _volume_light_on(self, xp: Any, a: np.ndarray, b: np.ndarray, hits: Hits) -> tuple:
        """``volume_light`` of a device's segments, worked out on the host (volumes, like
        intersectors, are host code), as arrays of ``xp``."""
        if xp is np or not self.volumes:
            return self.volume_light(a, b, hits)
        host = Hits(*(to_host(getattr(hits, f.name)) for f in fields(hits)))
        return tuple(xp.asarray(x) for x in self.volume_light(to_host(a), to_host(b), host))

    def volume_light(
        self, a: np.ndarray, b: np.ndarray, hits: Hits
    ) -> tuple[np.ndarray | None, np.ndarray | None]:
        """Emission and transmittance of every volume along a -> (b or the hit point)."""
        if not self.volumes:
            return None, None
        n = a.shape[0]
        radiance, trans = np.zeros((n, 3)), np.ones(n)
        end = np.where(hits.hit[:, None], hits.position, b)
        for vol in self.volumes:
            rows = np.flatnonzero(segment_overlaps(a, end, vol.lo, vol.hi))
            if rows.size:
                r, t = vol.segment(a[rows], end[rows])
                radiance[rows] += trans[rows, None] * r
                trans[rows] *= t
        return radiance, trans

    def boxes(self) -> list[Bound]:
        """World (lo, hi, gap, object id) of each object (each member of a Group) and
        volume (core.tracing.clearance: the exact distance from a sphere, an annulus or a
        rectangle, else None; the id its hits report, clearance.VOLUME_ID for a volume;
        read once). An intersector
        that holds many objects (the add-on's meshes) and reports their ids itself gives
        their boxes as ``part_bounds`` ((lo, hi, id) each; id -3 for a box of several):
        a hit's clearance is then from every object but its own, not 0 from the box of
        all of them (which made every hit a near miss, traced again, error pi)."""
        if self._bounds is None:
            self._bounds = self._read_bounds()
        return self._bounds

    def _read_bounds(self) -> list[Bound]:
        """``boxes``, read from the objects and volumes."""
        group = self.objects if isinstance(self.objects, Group) else None
        members = [self.objects] if group is None else group.objects
        ids: Sequence[int | None] = [None] if group is None else group.ids
        boxes: list[Bound] = [(np.asarray(v.lo, float), np.asarray(v.hi, float), None, VOLUME_ID)
                              for v in self.volumes]  # fmt: skip
        for obj, oid in zip(members, ids, strict=True):
            parts = part_bounds(obj)
            if parts is not None and oid is None:  # one intersector for many objects
                boxes += [(np.asarray(lo, float), np.asarray(hi, float), None, int(part))
                          for lo, hi, part in parts]  # fmt: skip
                continue
            lo, hi = (np.asarray(x, float) for x in obj.bounds)
            if not np.any(lo > hi):
                oid = reported_id(obj) if oid is None else oid
                boxes.append((lo, hi, shape_distance(obj), oid))
        return boxes

    def box_count(self) -> int:
        """How many boxes ``boxes`` lists, from a Group's member bounds where it has them."""
        if not isinstance(self.objects, Group):
            return len(self.boxes())
        bounds = self.objects.member_bounds
        return len(self.volumes) + int(np.count_nonzero(~np.any(bounds[0] > bounds[1], axis=1)))

    def local_boxes(self, to_local: Any) -> list[tuple[np.ndarray, np.ndarray]]:
        """(lo, hi) in local coordinates of each object's and volume's box (boxes), one
        pair a box (``local_box_arrays``)."""
        return list(zip(*self.local_box_arrays(to_local), strict=True))

    def local_box_arrays(self, to_local: Any) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi) (K, 3) in local coordinates of each box ``boxes`` lists, all at once (the
        box of its eight corners' images; -inf, inf where not finite)."""
        lo, hi = self._box_arrays()
        finite = np.isfinite(lo).all(axis=1) & np.isfinite(hi).all(axis=1)
        upper = ((np.arange(8)[:, None] >> np.arange(3)) & 1).astype(bool)  # (8, 3)
        corners = np.where(upper, hi[finite, None], lo[finite, None])  # (F, 8, 3)
        local = to_local(corners.reshape(-1, 3)).reshape(-1, 8, 3)
        out_lo, out_hi = np.full_like(lo, -np.inf), np.full_like(hi, np.inf)
        out_lo[finite], out_hi[finite] = local.min(axis=1), local.max(axis=1)
        return out_lo, out_hi

    def _box_arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi) (K, 3) world: the boxes ``boxes`` lists, in any order; a Group's members
        from its member bounds at once (10^5 spheres: ~2 s in boxes' loop)."""
        group = self.objects if isinstance(self.objects, Group) else None
        if group is None:
            listed = [(lo, hi) for lo, hi, _, _ in self.boxes()]
            plain_lo, plain_hi = np.empty((0, 3)), np.empty((0, 3))
        else:
            parts = [part_bounds(obj) if oid is None else None
                     for obj, oid in zip(group.objects, group.ids, strict=True)]  # fmt: skip
            plain = np.array([p is None for p in parts], bool).reshape(-1)
            plain_lo, plain_hi = (x[plain] for x in group.member_bounds)
            empty = np.any(plain_lo > plain_hi, axis=1)
            plain_lo, plain_hi = plain_lo[~empty], plain_hi[~empty]
            listed = [(v.lo, v.hi) for v in self.volumes]
            listed += [(a, b) for p in parts if p is not None for a, b, _ in p]
        lo = np.array([b[0] for b in listed], np.float64).reshape(-1, 3)
        hi = np.array([b[1] for b in listed], np.float64).reshape(-1, 3)
        return np.concatenate([lo, plain_lo]), np.concatenate([hi, plain_hi])

    def local_box(self, to_local: Any) -> tuple[np.ndarray, np.ndarray] | None:
        """(lo, hi) in local coordinates (``to_local``: world (N, 3) -> local) around every
        object and volume; None: nothing."""
        boxes = [(np.asarray(v.lo, float), np.asarray(v.hi, float)) for v in self.volumes]
        lo, hi = self.objects.bounds
        if not np.any(np.asarray(lo) > np.asarray(hi)):
            boxes.append((np.asarray(lo, float), np.asarray(hi, float)))
        if not boxes:
            return None
        lo = np.min([b[0] for b in boxes], axis=0)
        hi = np.max([b[1] for b in boxes], axis=0)
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
            return np.full(3, -np.inf), np.full(3, np.inf)
        corners = box_corners(lo, hi)
        local = to_local(corners)
        return local.min(axis=0), local.max(axis=0)


SURFACE_CHUNK = 1 << 16
"""Hit points cast again at once by surface_colours (memory stays bounded)."""


def surface_colours(
    geometry: SceneGeometry, position: np.ndarray, tangent: np.ndarray, label: np.ndarray,
    start: int, width: int,
) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """(rows, colours (M, 4)): surface colours averaged over each pixel's footprint, for
    the pixels [start, start + N) of an image ``width`` wide (row by row) with hit points
    ``position`` (N, 3) along hitting chords ``tangent`` (N, 3) on the objects ``label``
    (N,; below 0: none, not a neighbour). The footprint from neighbouring pixels' hit points
    on the same object (core.mipmap.surface_footprint), the colour cast again through each
    hit point with it (SceneGeometry.colour_over); pixels without a neighbour, or whose
    segment meets another object first, are not among ``rows``."""
    footprint = surface_footprint(position, label, start, width)
    rows = np.flatnonzero((label >= 0) & np.all(np.isfinite(footprint), axis=(1, 2)))
    found_rows, colours = [], []
    for first in range(0, rows.size, SURFACE_CHUNK):
        part = rows[first : first + SURFACE_CHUNK]
        colour, found = geometry.colour_over(
            position[part], tangent[part], label[part], footprint[part]
        )
        found_rows.append(part[found])
        colours.append(colour[found])
    if not found_rows:
        return rows, np.zeros((0, 4))
    return np.concatenate(found_rows), np.concatenate(colours)


def filter_surfaces(geometry: SceneGeometry, rays: RayResults, start: int, width: int) -> None:
    """The surface colours of ``rays`` (the pixels [start, start + N) of an image ``width``
    wide, row by row) averaged over each pixel's footprint there, in place
    (surface_colours). The accretion disk's pixels (no texture) keep theirs."""
    if not geometry.filters:
        return
    hit = (rays.ending == ENDING["hit"]) & (rays.object_id >= 0)
    label = np.where(hit, rays.object_id, -1)
    rows, colour = surface_colours(geometry, rays.position, rays.tangent, label, start, width)
    rays.surface[rows] = colour

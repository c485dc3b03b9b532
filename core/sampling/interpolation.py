"""Interpolation: what a point of the lattice shows, from its node or its accepted block.

Offers ``evaluate`` (colour, ending, error and passes at lattice points: a traced node's
own, else interpolated in its accepted block, else left to be traced), ``interpolate`` (the
bilinear interpolation inside accepted blocks: the sky in the blended direction, surfaces
cast again, the disk at its blended r and g), ``recast`` (interpolated hit points cast
again along their chords), ``Points`` (what ``evaluate`` returns), and
``INTERPOLATE_POINTS`` and ``REACH``. Needs a TileContext, the lattice,
core.sampling.acceptance (the error's shape) and core.sampling.disk.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..geometry import Hits
from ..motion import shift as doppler_shift
from ..passes import STORED
from ..tracing import ENDING
from ..tracing.differentials import magnification
from ..tracing.scene import DISK_ID
from .acceptance import error_shape
from .context import TileContext
from .disk import interpolate_disk
from .lattice import Blocks, Nodes

INTERPOLATE_POINTS = 1 << 15
"""Points are interpolated this many at a time: their temporaries stay in the cache and
the allocator's reused memory (a 1080p tile's ~480 000 centres at once: the Kerr board's
Preview frame 9.45-9.67 s against 8.51-8.53 s, 2 workers)."""
REACH = 4.0
"""An interpolated hit point is cast again along its interpolated chord direction, REACH
block widths (at its distance from the camera) either side: the surface is found even where
the bilinear point lies off a curved surface."""


@dataclass(frozen=True)
class PointValue:
    """One array ``evaluate`` gives at each lattice point."""

    name: str
    """Its name: the Nodes array it is taken from (where a point is a traced node)."""
    dtype: Any
    channels: int
    fill: float
    """Its value before anything is known (ending -1: to be traced)."""
    hits_only: bool = False
    """Taken from a traced node only where its ray hit a surface."""

    def empty(self, m: int) -> np.ndarray:
        """M points' values, all ``fill``."""
        shape = (m,) if self.channels == 1 else (m, self.channels)
        return np.full(shape, self.fill, dtype=self.dtype)


POINT_VALUES: tuple[PointValue, ...] = (
    PointValue("rgba", np.float64, 4, 0.0),
    *(PointValue(p.name, p.working_dtype, p.channels, p.fill, p.hits_only)
      for p in STORED if p.interpolated),
    PointValue("object_id", np.int32, 1, -1, hits_only=True),
    PointValue("tangent", np.float64, 3, 0.0, hits_only=True),
    PointValue("surface", np.float64, 4, 0.0, hits_only=True),
)  # fmt: skip
"""What a lattice point holds: its colour, every interpolated pass of core.passes (ending,
error, direction, position, redshift, magnification, transmittance: a new pass is its row
there), and what a hit is cast again with (object, chord direction, surface colour)."""


class Points:
    """What ``evaluate`` finds at M lattice points: one array per POINT_VALUES entry, by its
    name (``points.rgba``, ``points.ending`` (-1: to be traced), ...; ``values``: all)."""

    def __init__(self, m: int) -> None:
        self.values = {v.name: v.empty(m) for v in POINT_VALUES}

    def __getattr__(self, name: str) -> np.ndarray:
        try:
            return self.__dict__["values"][name]
        except KeyError:
            raise AttributeError(name) from None


def evaluate(
    ctx: TileContext, nodes: Nodes, blocks: Blocks, y: np.ndarray, x: np.ndarray
) -> Points:
    """Colour, ending and error at lattice points (y, x) (node units, (M,)): a traced
    node's own where a point is one, else interpolated in its accepted block; points in
    no accepted block and on no traced node get ending -1 (to be traced)."""
    m = y.shape[0]
    out = Points(m)
    cell_j = np.clip(np.floor(y).astype(np.int64), 0, blocks.block.shape[0] - 1)
    cell_i = np.clip(np.floor(x).astype(np.int64), 0, blocks.block.shape[1] - 1)
    b = blocks.block[cell_j, cell_i]
    on_node = (y == np.round(y)) & (x == np.round(x))
    nj, ni = np.round(y).astype(np.int64), np.round(x).astype(np.int64)
    traced = on_node & nodes.traced[np.clip(nj, 0, None), np.clip(ni, 0, None)]
    inside = np.flatnonzero((b >= 0) & ~traced)  # a traced node's own stands
    for start in range(0, inside.size, INTERPOLATE_POINTS):
        part = inside[start : start + INTERPOLATE_POINTS]
        interpolate(ctx, nodes, blocks, b[part], y[part], x[part], out, part)
    t = np.flatnonzero(traced)
    for value in POINT_VALUES:  # a traced node's own
        if not value.hits_only:
            out.values[value.name][t] = getattr(nodes, value.name)[nj[t], ni[t]]
    hit = t[out.ending[t] == ENDING["hit"]]
    for value in POINT_VALUES:
        if value.hits_only:
            out.values[value.name][hit] = getattr(nodes, value.name)[nj[hit], ni[hit]]
    return out


def interpolate(
    ctx: TileContext,
    nodes: Nodes,
    blocks: Blocks,
    b: np.ndarray,
    y: np.ndarray,
    x: np.ndarray,
    out: Points,
    rows: np.ndarray,
) -> None:
    """Shade points (y, x) inside accepted blocks b by bilinear interpolation: the sky in
    the interpolated direction; an object where the interpolated hit point and chord,
    cast again, meet it (elsewhere, as at its edge, the point is left to be traced)."""
    bj, bi, s = blocks.j[b], blocks.i[b], blocks.size[b]
    u, v = (x - bi) / s, (y - bj) / s
    weights = [(1 - u) * (1 - v), u * (1 - v), (1 - u) * v, u * v]
    corners = [(bj, bi), (bj, bi + s), (bj + s, bi), (bj + s, bi + s)]
    width = nodes.traced.shape[1]
    first = bj * width + bi  # a node's index in a flattened field
    flat = [first, first + s, first + s * width, first + s * (width + 1)]

    def blend(field, at=slice(None)):
        spread = (-1,) + (1,) * (field.ndim - 2)  # a weight per point, over its values
        rows = field.reshape(-1, *field.shape[2:])
        total = None
        for wk, k in zip(weights, flat, strict=True):
            term = (wk[at] if field.ndim == 2 else wk[at].reshape(spread)) * rows[k[at]]
            if total is None:
                total = term
            else:
                total += term
        return total

    d = blend(nodes.direction)
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    ending = nodes.ending[bj, bi].copy()
    colour = np.zeros((b.size, 4))
    colour[:, 3] = 1.0
    sky = ending == ENDING["escaped"]
    jacobian = blend(nodes.jacobian, sky) if ctx.with_tangents and sky.any() else None
    if sky.any():  # over the footprint of the nodes' ray differentials, blended
        colour[sky] = ctx.background(d[sky], jacobian)
    out.direction[rows] = np.where(sky[:, None], d, np.nan)
    if jacobian is not None:
        seen = ctx.camera.direction_tangents(ctx.image_xy(y[sky], x[sky]))
        out.magnification[rows[sky]] = magnification(seen, jacobian)
    disk = np.flatnonzero((ending == ENDING["hit"]) & (nodes.object_id[bj, bi] == DISK_ID))
    if disk.size:  # the disk's light at the interpolated radius and g
        sub = [(j[disk], i[disk]) for j, i in corners]
        rgb, on, g, position, seen = interpolate_disk(
            ctx, nodes, sub, [wk[disk] for wk in weights], y[disk], x[disk]
        )
        colour[disk[on], :3] = rgb[on]
        ending[disk[~on]] = -1  # off the disk between the nodes: traced
        at = rows[disk[on]]
        out.redshift[at], out.position[at], out.direction[at] = g[on], position[on], seen[on]
    hit = np.flatnonzero((ending == ENDING["hit"]) & (nodes.object_id[bj, bi] != DISK_ID))
    if hit.size:
        origins, _ = ctx.camera.rays_at(ctx.image_xy(y[hit], x[hit]))
        position, tangent = blend(nodes.position, hit), blend(nodes.tangent, hit)
        reach = REACH * s[hit] * ctx.pixel_angle * np.linalg.norm(position - origins, axis=1)
        found = recast(ctx, position, tangent, reach, nodes.object_id[bj[hit], bi[hit]])
        ok = found.hit
        colour[hit[ok]] = found.color[ok]
        ending[hit[~ok]] = -1  # missed its object (an edge): trace this point
        at = rows[hit[ok]]
        out.position[at] = found.position[ok]
        out.object_id[at], out.surface[at] = found.object_id[ok], found.color[ok]
        out.tangent[at] = tangent[ok]
        seen = found.position[ok] - origins[ok]
        out.direction[rows[hit[ok]]] = seen / np.linalg.norm(seen, axis=1, keepdims=True)
    moving = ctx.tracer.motion
    if moving is not None:  # static emitters seen by a moving camera (render.shade)
        surface = (ending == ENDING["hit"]) & (nodes.object_id[bj, bi] != DISK_ID)
        shifted = np.flatnonzero(sky | surface)
        _, seen = ctx.camera.rays_at(ctx.image_xy(y[shifted], x[shifted]))
        colour[shifted, :3] = doppler_shift(colour[shifted, :3], moving.colour_shift(seen))
    out.rgba[rows] = colour
    out.ending[rows] = ending
    shape = error_shape(u, v)
    interpolation = np.einsum("mk,mk->m", blocks.deviation[b], shape)
    summed = np.matmul(shape[:, None, :], blocks.vectors[b])[:, 0]  # (M, 3)
    with np.errstate(invalid="ignore"):
        as_vector = np.sqrt(np.einsum("mc,mc->m", summed, summed))
    interpolation = np.where(np.isfinite(as_vector), as_vector, interpolation)
    out.error[rows] = blend(nodes.error[..., None])[:, 0] + interpolation


def recast(
    ctx: TileContext,
    position: np.ndarray,
    tangent: np.ndarray,
    reach: np.ndarray,
    object_id: np.ndarray,
    footprint: np.ndarray | None = None,
) -> Hits:
    """Hits of segments through interpolated hit points along their interpolated chord
    directions, ``reach`` (M,) world units either side; ``hit`` only where the first
    thing met is the block's object ``object_id`` (M,); coloured over ``footprint``
    (M, 2, 3) where given."""
    tangent = tangent / np.linalg.norm(tangent, axis=1, keepdims=True)
    reach = reach[:, None]
    a, b = position - reach * tangent, position + reach * tangent
    hits = ctx.tracer.geometry.cast(a, b, footprint)
    hits.hit &= hits.object_id == object_id
    return hits

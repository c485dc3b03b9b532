"""The colour test: interpolated pixel centres whose colour could change over their error.

Offers ``shaky`` (the interpolated centres to trace: their colour could change by more than
``COLOUR_STEP`` over their error), ``shaky_sky`` and ``shaky_surface`` (what the sky and
surfaces show when looked up moved by the error), ``neighbour_change`` (a pixel's largest
difference from its neighbours), ``moves``, and ``COLOUR_STEP``. Needs a TileContext, the
lattice's Nodes, core.mipmap's footprints and core.sampling.interpolation (``recast``).
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from ..mipmap import map_footprint, screen_differences
from ..tracing import ENDING
from .context import TileContext
from .interpolation import REACH, Points, recast
from .lattice import Nodes

COLOUR_STEP = 0.05
"""An interpolated pixel centre is traced where its colour could change by more than
COLOUR_STEP in a channel over its own error estimate (shaky): where the
largest difference from its four neighbours' colours (a pixel apart), times its error in
pixels, exceeds it, and what it shows (the sky; a surface, cast again) changes by more when
looked up moved by its error across x and y, either way. A checker's edge moved by ~0.2
px, under the 1 px tolerance, changed the colour of the centres it passed by more than 0.1
(benchmarks/honesty.py: 1.5 % of near_tangent's pixels at 1 px, 0.3 % of
schwarzschild's). The neighbour test alone traced every centre beside a checker's edge
(+21 % rays on the Kerr board at 960 x 540; +4 % with both). Half the 0.1 the benchmark
counts: an estimate within 3x of the truth, on a filtered edge (change in proportion to
the move), rarely under-reads a change of 0.1 by more. Where the sky's detail is smaller
than a pixel (Background.detail), which neighbours need not show (a star between centres),
every interpolated sky centre is looked up moved (3 sub-pixel star images of 561 were lost
at 1 px on the benchmark's stars scene, none now). A detail wider than a pixel spans a
neighbour: the Kerr board at 960 x 540 (stars 2.4 px across) spent 9 % of its time on
these lookups for 114 more rays of 120 000 when they were taken below 3 px."""


def shaky(
    ctx: TileContext,
    nodes: Nodes,
    centre: Points,
    shape: tuple[int, int],
    jj: np.ndarray,
    ii: np.ndarray,
) -> np.ndarray:
    """Rows of the interpolated pixel centres (a grid ``shape`` of lattice points jj, ii)
    whose colour could change by more than COLOUR_STEP over their error: those whose
    largest difference in a channel from a neighbour a pixel away, times their error in
    pixels, exceeds it, where what they show, looked up moved by the error across x and
    y, changes by more (the sky, surfaces; the rest, as the disk, kept); and sky centres
    whose background has detail smaller than a pixel (Background.detail) that changes."""
    change = neighbour_change(centre.rgba[:, :3].reshape(shape + (3,))).ravel()
    interpolated = ~nodes.traced[jj, ii]
    move = centre.error / ctx.pixel_angle
    shaky = interpolated & (change * move > COLOUR_STEP)
    escaped = centre.ending == ENDING["escaped"]
    hit = (centre.ending == ENDING["hit"]) & (centre.object_id >= 0)
    sky = interpolated & escaped
    if ctx.background.detail >= ctx.pixel_angle:
        sky &= shaky
    if sky.any():
        rows = np.flatnonzero(sky)
        slope = map_footprint(centre.direction.reshape(shape + (3,)), escaped.reshape(shape), rows)
        shaky[rows] = shaky_sky(ctx, centre.direction[rows], slope, move[rows])
    surface = shaky & hit
    if surface.any():
        label = np.where(hit, centre.object_id, -1).reshape(shape)
        rows = np.flatnonzero(surface)
        slope = screen_differences(
            centre.position.reshape(shape + (3,)), label, jumps=True, rows=rows
        )
        shaky[rows] = shaky_surface(ctx, centre, rows, slope, move[rows], jj, ii)
    return np.flatnonzero(shaky)


def shaky_sky(ctx: TileContext, d: np.ndarray, slope: np.ndarray, move: np.ndarray) -> np.ndarray:
    """(M,) sky points (directions d (M, 3), their derivatives along image x and y
    ``slope`` (M, 2, 3); NaN: none, taken as shaky) whose colour changes by more than
    COLOUR_STEP in a channel when their direction moves ``move`` (M,) pixels across x or
    y, either way."""
    centre = ctx.background(d)[:, :3]
    change = np.zeros(d.shape[0])
    for offset in moves(slope, move):
        probe = d + offset
        with np.errstate(invalid="ignore"):
            probe /= np.linalg.norm(probe, axis=1, keepdims=True)
        seen = ctx.background(np.nan_to_num(probe), None)[:, :3]
        change = np.maximum(change, np.max(np.abs(seen - centre), axis=1))
        change[~np.all(np.isfinite(probe), axis=1)] = np.inf
    return change > COLOUR_STEP


def shaky_surface(
    ctx: TileContext,
    centre: Points,
    rows: np.ndarray,
    slope: np.ndarray,
    move: np.ndarray,
    jj: np.ndarray,
    ii: np.ndarray,
) -> np.ndarray:
    """(M,) the hits ``rows`` of ``centre`` (at lattice points jj, ii) whose colour
    changes by more than COLOUR_STEP, or whose object is not met, when their hit point
    moves ``move`` (M,) pixels across image x or y along its derivatives ``slope`` (M, 2,
    3; NaN: none, taken as shaky), either way: cast again along their chords (over the
    footprint ``slope`` where the surfaces filter)."""
    position, tangent = centre.position[rows], centre.tangent[rows]
    origins, _ = ctx.camera.rays_at(ctx.image_xy(jj[rows] * 1.0, ii[rows] * 1.0))
    far = np.linalg.norm(position - origins, axis=1)
    reach = REACH * np.maximum(move, 1.0) * ctx.pixel_angle * far
    footprint = slope if ctx.tracer.geometry.filters else None
    object_id = centre.object_id[rows]
    first = recast(ctx, position, tangent, reach, object_id, footprint)
    shaky = ~first.hit | ~np.all(np.isfinite(slope), axis=(1, 2))
    for offset in moves(np.nan_to_num(slope), move):
        probe = recast(ctx, position + offset, tangent, reach, object_id, footprint)
        change = np.max(np.abs(probe.color[:, :3] - first.color[:, :3]), axis=1)
        shaky |= ~probe.hit | (change > COLOUR_STEP)
    return shaky


def moves(slope: np.ndarray, move: np.ndarray) -> Iterator[np.ndarray]:
    """The four offsets (M, 3) of points moved ``move`` (M,) pixels along +x, -x, +y and -y
    of the image, by their derivatives ``slope`` (M, 2, 3) along x and y (shaky)."""
    for k in (0, 1):
        for sign in (1.0, -1.0):
            yield (sign * move)[:, None] * slope[:, k]


def neighbour_change(rgb: np.ndarray) -> np.ndarray:
    """(H, W) the largest difference in a channel between each pixel of ``rgb`` (H, W, 3)
    and its four neighbours (those inside the grid)."""
    change = np.zeros(rgb.shape[:2])
    for axis in (0, 1):
        step = np.max(np.abs(np.diff(rgb, axis=axis)), axis=-1)
        first = [slice(None), slice(None)]
        second = [slice(None), slice(None)]
        first[axis], second[axis] = slice(None, -1), slice(1, None)
        np.maximum(change[tuple(first)], step, out=change[tuple(first)])
        np.maximum(change[tuple(second)], step, out=change[tuple(second)])
    return change

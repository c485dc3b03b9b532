"""Footprint filtering: the sky and surfaces at pixel centres averaged over each pixel.

Offers ``filter_sky`` and ``filter_surfaces`` (the sky's and the surfaces' share of the
centres' colours replaced by their colour filtered over each pixel's footprint) and
``replace_share``. Needs a TileContext (its background, tracer's geometry and motion),
core.mipmap and core.tracing.segments.
"""

from __future__ import annotations

import numpy as np

from ..mipmap import map_footprint
from ..motion import shift as doppler_shift
from ..tracing import ENDING
from ..tracing.segments import surface_colours
from .context import TileContext
from .interpolation import Points


def filter_sky(
    ctx: TileContext, centre: Points, shape: tuple[int, int], jj: np.ndarray, ii: np.ndarray
) -> None:
    """The sky seen at the pixel centres (a grid ``shape``, rows jj, columns ii) averaged
    over each pixel's footprint, taken from the centres' own directions
    (core.mipmap.map_footprint): the sky's share of each colour (its transmittance
    times the sky, Doppler shifted for a moving camera) replaced by the filtered one."""
    sky = centre.ending == ENDING["escaped"]
    footprint = map_footprint(centre.direction.reshape(shape + (3,)), sky.reshape(shape))
    rows = np.flatnonzero(sky)
    if rows.size == 0:
        return
    d = centre.direction[rows]
    filtered = ctx.background(d, footprint.reshape(-1, 2, 3)[rows])
    replace_share(ctx, centre, rows, jj, ii, ctx.background(d), filtered)


def filter_surfaces(
    ctx: TileContext, centre: Points, shape: tuple[int, int], jj: np.ndarray, ii: np.ndarray
) -> None:
    """The surfaces seen at the pixel centres (a grid ``shape``, rows jj, columns ii)
    averaged over each pixel's footprint there, from neighbouring centres' hit points
    on the same object (core.mipmap.surface_footprint; SceneGeometry.colour_over): the
    surface's share of each colour (its transmittance times the surface, Doppler
    shifted for a moving camera) replaced by the filtered one. Centres past the image's
    edges are not neighbours (as on a whole image: core.viewport.reshade_surfaces)."""
    row, column = ctx.origin[0] + jj, ctx.origin[1] + ii
    inside = (row >= 0) & (row < ctx.camera.height) & (column >= 0) & (column < ctx.camera.width)
    hit = (centre.ending == ENDING["hit"]) & (centre.object_id >= 0) & inside
    label = np.where(hit, centre.object_id, -1)
    rows, colour = surface_colours(
        ctx.tracer.geometry, centre.position, centre.tangent, label, 0, shape[1]
    )
    if rows.size:
        replace_share(ctx, centre, rows, jj, ii, centre.surface[rows].copy(), colour)


def replace_share(
    ctx: TileContext,
    centre: Points,
    rows: np.ndarray,
    jj: np.ndarray,
    ii: np.ndarray,
    plain: np.ndarray,
    filtered: np.ndarray,
) -> None:
    """In place: the centres ``rows``' colours with the share of ``plain`` (what they
    show of the sky or a surface, unshifted) in them, its transmittance times it, Doppler
    shifted for a moving camera, replaced by ``filtered``'s."""
    moving = ctx.tracer.motion
    if moving is not None:
        _, seen = ctx.camera.rays_at(ctx.image_xy(jj[rows] * 1.0, ii[rows] * 1.0))
        g = moving.colour_shift(seen)
        plain[:, :3] = doppler_shift(plain[:, :3], g)
        filtered[:, :3] = doppler_shift(filtered[:, :3], g)
    centre.rgba[rows] += centre.transmittance[rows, None] * (filtered - plain)

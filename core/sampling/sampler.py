"""The tile sampler: renders one tile of an image by the steps of core.sampling's modules.

Offers ``TileSampler`` (a TileContext whose ``render_tile`` renders a tile: its lattice
refined (core.sampling.quadtree) or traced, its retraces, then its pixels: centres
evaluated, traced where interpolation missed or the colour test asks, footprint-filtered,
supersampled where the contrast asks). Needs every other module of core.sampling.
"""

from __future__ import annotations

import copy
import math

import numpy as np

from ..passes import BY_NAME, STORED
from . import lattice, quadtree
from .anchors import trace_nodes
from .context import Cancel, TileContext
from .footprints import filter_sky, filter_surfaces
from .interpolation import Points, evaluate
from .lattice import Blocks, Nodes
from .quadtree import refine
from .retrace import companions, retrace
from .shaky import shaky
from .supersample import contrast, supersample
from .tiling import Tile, TileResult


class TileSampler(TileContext):
    """Renders tiles of one image (see core.sampling's docstring): the steps are functions
    of the sampler, as a TileContext, in core.sampling's modules."""

    def render_tile(self, tile: Tile, cancel: Cancel = None) -> TileResult | None:
        """Colour and passes of one tile (None if cancelled): refined, or where that cannot
        pay (quadtree.refining_pays) every pixel traced. Threads share the sampler: each
        tile works on its own shallow copy (its origin and ray counts)."""
        return copy.copy(self)._render_tile(tile, cancel)

    def _render_tile(self, tile: Tile, cancel: Cancel) -> TileResult | None:
        self.rays = self.error_rays = self.companion_rays = 0
        h, w = tile.shape
        refined = self.interpolation > 0 and quadtree.refining_pays(h * w)  # the cost guard
        s = lattice.STRIDE if refined else 1
        ny, nx = 1 + s * math.ceil((h + 1) / s), 1 + s * math.ceil((w + 1) / s)
        origin = (tile.y0 - 1, tile.x0 - 1)  # image (row, column) of node (0, 0)
        self.origin = origin
        nodes = Nodes(ny, nx, self.with_tangents)
        blocks = Blocks(ny - 1, nx - 1)
        if s == 1:
            jj, ii = np.mgrid[0:ny, 0:nx]
            trace_nodes(self, nodes, jj.ravel(), ii.ravel(), origin, cancel, dense=True,
                        defer=True)  # fmt: skip
        else:
            refine(self, nodes, blocks, s, (h + 1, w + 1), origin, cancel)
        retrace(self, nodes, cancel)
        if cancel is not None and cancel():
            return None
        return self._pixels(tile, nodes, blocks, origin, cancel)

    def _pixels(
        self, tile: Tile, nodes: Nodes, blocks: Blocks, origin: tuple[int, int], cancel: Cancel
    ) -> TileResult:
        """Pixel colours and passes: traced nodes as they are, the rest interpolated; then
        anti-aliasing where the contrast asks for it."""
        h, w = tile.shape
        jj, ii = (a.ravel() for a in np.mgrid[0 : h + 2, 0 : w + 2])
        centre = evaluate(self, nodes, blocks, jj.astype(float), ii.astype(float))
        missed = np.flatnonzero(centre.ending < 0)  # interpolated hits that missed: trace
        self._trace_centres(nodes, blocks, centre, missed, jj, ii, cancel)
        shaky_rows = shaky(self, nodes, centre, (h + 2, w + 2), jj, ii)
        self._trace_centres(nodes, blocks, centre, shaky_rows, jj, ii, cancel)
        if self.background.filters and not self.with_tangents:
            filter_sky(self, centre, (h + 2, w + 2), jj, ii)
        if self.tracer.geometry.filters:
            filter_surfaces(self, centre, (h + 2, w + 2), jj, ii)
        rgba = centre.rgba.reshape(h + 2, w + 2, 4)
        ending = centre.ending.reshape(h + 2, w + 2)
        inner = (slice(1, h + 1), slice(1, w + 1))
        energy = nodes.energy[inner]
        colour = rgba[inner].copy()
        if self.samples > 1:
            differs = contrast(rgba, ending)
            near = nodes.traced[inner] & (
                nodes.clearance[inner] < self.footprint * self.pixel_angle
            )
            busy = np.any(np.stack(differs), axis=0) | near
            colour[busy] = supersample(self, nodes, blocks, busy, differs, near, colour[busy],
                                       cancel)  # fmt: skip
        passes = {  # every stored pass: the points' where interpolated, else the nodes'
            kind.name: (
                centre.values[kind.name].reshape((h + 2, w + 2) + kind.empty(0).shape[1:])
                if kind.interpolated
                else getattr(nodes, kind.name)
            )[inner]
            for kind in STORED
        }
        return TileResult(
            colour.astype(np.float32),
            {name: data.astype(BY_NAME[name].dtype, copy=False) for name, data in passes.items()},
            energy, self.rays, self.error_rays, self.companion_rays,
        )  # fmt: skip

    def _trace_centres(
        self,
        nodes: Nodes,
        blocks: Blocks,
        centre: Points,
        rows: np.ndarray,
        jj: np.ndarray,
        ii: np.ndarray,
        cancel: Cancel,
    ) -> None:
        """In place: the pixel centres ``rows`` (of the lattice points jj, ii) traced, and
        ``centre``'s values there replaced by their rays'. Their companions run where
        their cell's corners cannot judge them (anchors.settle), in a batch of their own."""
        if rows.size == 0:
            return
        trace_nodes(self, nodes, jj[rows], ii[rows], self.origin, cancel, defer=True)
        companions(self, nodes, cancel)
        again = evaluate(self, nodes, blocks, jj[rows] * 1.0, ii[rows] * 1.0)
        for name, values in centre.values.items():
            values[rows] = again.values[name]

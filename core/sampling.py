"""Adaptive image sampling: rays where the image needs them, anti-aliasing by sub-pixel samples.

An image is rendered in tiles (``TILE`` pixels square, each a unit of work). A tile is
covered by a lattice of *nodes* at pixel centres, one pixel beyond the tile on every side
(filter footprints reach up to a pixel past a pixel's centre). Blocks of ``STRIDE`` nodes
are refined as a quadtree: a block's four corners and its centre are traced; the block is
*accepted* when

- all five rays escaped, none came near geometry (``Tracer.watch_geometry``, with a margin
  of one block) and none crossed a volume, and the centre's final direction differs from
  the corners' bilinear interpolation by at most the interpolation tolerance: the block's
  directions are then interpolated (bilinear, normalised) and each point is shaded from the
  background in its interpolated direction, so the sky's own detail is kept; or
- all five were captured and none came near geometry (the shadow's inside, black).

Otherwise it splits into four, down to ``FINEST``, where every pixel of a refused block is
traced. For a
quadratic direction map the bilinear interpolation error over a block peaks at its centre,
so the centre's deviation d bounds it, and at block coordinates (u, v) in [0, 1]^2 it is
about 2 d (u (1 - u) + v (1 - v)) (what the error pass reports for interpolated points).
Interpolation never crosses an ending change: a block is accepted only when all its rays
end the same way, away from every object.

Anti-aliasing (``samples`` > 1): a pixel whose colour differs from a neighbour's by more
than ``AA_CONTRAST`` (or whose ending does) gets ``samples`` points spread over its filter
footprint (an R2 low-discrepancy pattern, the same in every pixel), each shaded by
interpolation inside an accepted block or by a traced ray elsewhere; its colour is their
filter-weighted mean (box over the pixel, or Blackman-Harris of width ``filter_size`` as in
Cycles). Other pixels keep their centre's colour.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .sky import Background
from .tracing import ENDING, RayResults, Tracer

TILE = 256
"""Pixels per tile side: a tile's first round traces ~(TILE/STRIDE)^2 x 2 rays at once."""
STRIDE = 8
"""Pixels per side of the coarsest interpolation block."""
FINEST = 4
"""Pixels per side of the finest block tried: every pixel of a block refused at this size
is traced (one round instead of two more: each round costs a batch's per-step overhead)."""
AA_CONTRAST = 0.03
"""A pixel is supersampled where its colour differs from a neighbour's by more than this
(largest channel difference, linear RGB) or its ending does."""
FILTERS = ("box", "blackman_harris")
"""Reconstruction filters: the pixel's square, or Cycles' default (width ``filter_size``)."""
COMPANION_RATIO = 2.0
"""The error pass traces each camera ray again at COMPANION_RATIO x the step: for a method
of order p the ray's error is |d_h - d_rh| / (r^p - 1) (Richardson); 1 / r of the cost."""


@dataclass(frozen=True)
class Tile:
    """A rectangle of pixels [x0, x1) x [y0, y1) (row 0 at the top)."""

    x0: int
    y0: int
    x1: int
    y1: int

    @property
    def shape(self) -> tuple[int, int]:
        """(height, width) of the tile in pixels."""
        return self.y1 - self.y0, self.x1 - self.x0


def tiles(width: int, height: int, size: int = TILE) -> list[Tile]:
    """The tiles covering a width x height image, row by row from the top."""
    return [
        Tile(x, y, min(x + size, width), min(y + size, height))
        for y in range(0, height, size)
        for x in range(0, width, size)
    ]


def sample_offsets(samples: int, pixel_filter: str, filter_size: float) -> tuple:
    """Sub-pixel offsets (S, 2) from the pixel centre and their filter weights (S,)."""
    if samples == 1:
        return np.zeros((1, 2)), np.ones(1)
    g = 1.32471795724474602596  # the plastic number: the R2 sequence (Roberts 2018)
    k = np.arange(1, samples + 1)[:, None]
    unit = np.mod(0.5 + k * np.array([1.0 / g, 1.0 / (g * g)]), 1.0)
    if pixel_filter == "box":
        return unit - 0.5, np.ones(samples)
    offsets = (unit - 0.5) * filter_size
    window = 0.35875 - 0.48829 * np.cos(2 * np.pi * unit) + 0.14128 * np.cos(4 * np.pi * unit)
    window -= 0.01168 * np.cos(6 * np.pi * unit)
    return offsets, np.prod(window, axis=1)


@dataclass
class TileResult:
    """What a tile adds to the image: per-pixel colour and passes, and its ray counts."""

    rgba: np.ndarray  # (h, w, 4) float32
    error: np.ndarray  # (h, w) radians, +inf where failed
    steps: np.ndarray  # (h, w) int32
    ending: np.ndarray  # (h, w) int8
    energy: np.ndarray  # (h, w) |H - H0|
    rays: int
    error_rays: int


class _Nodes:
    """The lattice of a tile: what is known at each node (traced or not)."""

    def __init__(self, ny: int, nx: int) -> None:
        shape = (ny, nx)
        self.traced = np.zeros(shape, dtype=bool)
        self.direction = np.zeros(shape + (3,))
        self.ending = np.full(shape, -1, dtype=np.int8)
        self.rgba = np.zeros(shape + (4,))
        self.error = np.zeros(shape)
        self.steps = np.zeros(shape, dtype=np.int32)
        self.energy = np.zeros(shape)
        self.plain = np.zeros(shape, dtype=bool)  # escaped or captured, nothing met on the way


class TileSampler:
    """Renders tiles of one image (see the module docstring)."""

    def __init__(
        self,
        tracer: Tracer,
        camera,
        background: Background,
        shade: Callable[[RayResults, Background], np.ndarray],
        *,
        interpolation: float,
        samples: int = 1,
        pixel_filter: str = "box",
        filter_size: float = 1.0,
        with_error: bool = False,
        far_field: float = 0.0,
    ) -> None:
        self.tracer, self.camera, self.background, self.shade = tracer, camera, background, shade
        self.interpolation = float(interpolation)  # radians; 0: trace every pixel
        self.samples = int(samples)
        self.offsets, self.weights = sample_offsets(self.samples, pixel_filter, filter_size)
        self.with_error = with_error and tracer.curved
        self.far_field = far_field  # error of escaped rays beyond the region, radians
        self.rays = 0
        self.error_rays = 0

    # --- tracing nodes -----------------------------------------------------------------
    def _trace_points(
        self, xy: np.ndarray, cancel, companion: bool = True
    ) -> tuple[RayResults, np.ndarray | None]:
        """Trace camera rays through image points xy (M, 2); with the error pass (and
        ``companion``), their Richardson error (radians) from a companion run at
        COMPANION_RATIO x the step (sub-pixel samples need none: the pass reports centres)."""
        origins, directions = self.camera.rays_at(xy)
        self.rays += xy.shape[0]
        rays = self.tracer.trace(origins, directions, cancel=cancel)
        if not (self.with_error and companion):
            return rays, None
        assert self.tracer.step is not None
        coarse = self.tracer.trace(
            origins, directions, step=COMPANION_RATIO * self.tracer.step, cancel=cancel
        )
        self.error_rays += xy.shape[0]
        return rays, richardson_error(rays, coarse, origins, self.tracer.method.order)

    def _trace_nodes(self, nodes: _Nodes, jj: np.ndarray, ii: np.ndarray, origin, cancel):
        """Trace the untraced nodes among (jj, ii) (flat index arrays) and store them."""
        flat = np.unique(jj * nodes.traced.shape[1] + ii)
        jj, ii = np.divmod(flat, nodes.traced.shape[1])
        todo = ~nodes.traced[jj, ii]
        jj, ii = jj[todo], ii[todo]
        if jj.size == 0:
            return
        xy = np.stack([origin[1] + ii + 0.5, origin[0] + jj + 0.5], axis=1)
        rays, error = self._trace_points(xy, cancel)
        nodes.traced[jj, ii] = True
        nodes.direction[jj, ii] = rays.direction
        nodes.ending[jj, ii] = rays.ending
        nodes.rgba[jj, ii] = self.shade(rays, self.background)
        nodes.steps[jj, ii] = rays.steps
        nodes.energy[jj, ii] = rays.energy_error
        escaped = rays.ending == ENDING["escaped"]
        no_light = (rays.transmittance == 1.0) & ~np.any(rays.radiance, axis=1)
        nodes.plain[jj, ii] = (
            (escaped | (rays.ending == ENDING["captured"])) & ~rays.near & no_light
        )
        err = np.zeros(jj.size) if error is None else error
        far = np.where(escaped, self.far_field, 0.0)
        nodes.error[jj, ii] = np.where(rays.ending == ENDING["failed"], np.inf, err + far)

    # --- the quadtree ------------------------------------------------------------------
    def render_tile(self, tile: Tile, cancel=None) -> TileResult | None:
        """Colour and passes of one tile (None if cancelled)."""
        self.rays = self.error_rays = 0
        h, w = tile.shape
        s = STRIDE if self.interpolation > 0 else 1
        ny, nx = 1 + s * math.ceil((h + 1) / s), 1 + s * math.ceil((w + 1) / s)
        origin = (tile.y0 - 1, tile.x0 - 1)  # image (row, column) of node (0, 0)
        nodes = _Nodes(ny, nx)
        blocks = _Blocks(ny - 1, nx - 1)
        if s == 1:
            jj, ii = np.mgrid[0:ny, 0:nx]
            self._trace_nodes(nodes, jj.ravel(), ii.ravel(), origin, cancel)
        else:
            self._refine(nodes, blocks, s, origin, cancel)
        if cancel is not None and cancel():
            return None
        return self._pixels(tile, nodes, blocks, origin, cancel)

    def _refine(self, nodes: _Nodes, blocks: _Blocks, s: int, origin, cancel) -> None:
        """Trace and accept blocks level by level, from size s down to FINEST; the nodes of
        blocks still refused there are all traced."""
        ny, nx = nodes.traced.shape
        bj, bi = (a.ravel() for a in np.mgrid[0 : ny - 1 : s, 0 : nx - 1 : s])
        while bj.size:
            half = s // 2
            corners_j = np.concatenate([bj, bj, bj + s, bj + s, bj + half])
            corners_i = np.concatenate([bi, bi + s, bi, bi + s, bi + half])
            self._trace_nodes(nodes, corners_j, corners_i, origin, cancel)
            if cancel is not None and cancel():
                return
            accepted, deviation = self._accept(nodes, bj, bi, s)
            blocks.add(bj[accepted], bi[accepted], s, deviation[accepted])
            sj, si = bj[~accepted], bi[~accepted]
            if s <= FINEST:
                dj, di = (a.ravel() for a in np.mgrid[0 : s + 1, 0 : s + 1])
                jj, ii = (sj[:, None] + dj).ravel(), (si[:, None] + di).ravel()
                self._trace_nodes(nodes, jj, ii, origin, cancel)
                return
            bj = np.concatenate([sj, sj, sj + half, sj + half])
            bi = np.concatenate([si, si + half, si, si + half])
            s = half

    def _accept(self, nodes: _Nodes, bj, bi, s: int) -> tuple[np.ndarray, np.ndarray]:
        """Which blocks (size s) are interpolated, and their centres' deviation (radians)."""
        cj, ci = bj + s // 2, bi + s // 2
        corners = [(bj, bi), (bj, bi + s), (bj + s, bi), (bj + s, bi + s)]
        plain = nodes.plain[cj, ci].copy()
        ending = nodes.ending[cj, ci]
        for j, i in corners:
            plain &= nodes.plain[j, i] & (nodes.ending[j, i] == ending)
        mean = sum(nodes.direction[j, i] for j, i in corners)
        deviation = _angle(mean, nodes.direction[cj, ci])
        sky = ending == ENDING["escaped"]
        deviation = np.where(sky, deviation, 0.0)
        accepted = plain & (deviation <= self.interpolation)
        return accepted, deviation

    # --- pixels ------------------------------------------------------------------------
    def _pixels(self, tile: Tile, nodes: _Nodes, blocks: _Blocks, origin, cancel) -> TileResult:
        """Pixel colours and passes: traced nodes as they are, the rest interpolated; then
        anti-aliasing where the contrast asks for it."""
        h, w = tile.shape
        jj, ii = (a.astype(float) for a in np.mgrid[0 : h + 2, 0 : w + 2])
        centre = self._evaluate(nodes, blocks, jj.ravel(), ii.ravel())
        rgba = centre.rgba.reshape(h + 2, w + 2, 4)
        error = centre.error.reshape(h + 2, w + 2)
        ending = centre.ending.reshape(h + 2, w + 2)
        inner = (slice(1, h + 1), slice(1, w + 1))
        steps = nodes.steps[inner]
        energy = nodes.energy[inner]
        colour = rgba[inner].copy()
        if self.samples > 1:
            busy = _contrast(rgba, ending)
            colour[busy] = self._supersample(nodes, blocks, busy, origin, cancel)
        return TileResult(
            colour.astype(np.float32), error[inner].astype(np.float32), steps,
            ending[inner], energy, self.rays, self.error_rays,
        )  # fmt: skip

    def _evaluate(self, nodes: _Nodes, blocks: _Blocks, y, x) -> _Points:
        """Colour, ending and error at lattice points (y, x) (node units, (M,)): a traced
        node's own where a point is one, else interpolated in its accepted block; points in
        no accepted block and on no traced node get ending -1 (to be traced)."""
        m = y.shape[0]
        out = _Points(np.zeros((m, 4)), np.full(m, -1, dtype=np.int8), np.zeros(m))
        cell_j = np.clip(np.floor(y).astype(np.int64), 0, blocks.block.shape[0] - 1)
        cell_i = np.clip(np.floor(x).astype(np.int64), 0, blocks.block.shape[1] - 1)
        b = blocks.block[cell_j, cell_i]
        inside = np.flatnonzero(b >= 0)
        if inside.size:
            self._interpolate(nodes, blocks, b[inside], y[inside], x[inside], out, inside)
        on_node = (y == np.round(y)) & (x == np.round(x))
        nj, ni = np.round(y).astype(np.int64), np.round(x).astype(np.int64)
        traced = on_node & nodes.traced[np.clip(nj, 0, None), np.clip(ni, 0, None)]
        t = np.flatnonzero(traced)
        out.rgba[t] = nodes.rgba[nj[t], ni[t]]
        out.ending[t] = nodes.ending[nj[t], ni[t]]
        out.error[t] = nodes.error[nj[t], ni[t]]
        return out

    def _interpolate(self, nodes: _Nodes, blocks: _Blocks, b, y, x, out: _Points, rows):
        """Shade points (y, x) inside accepted blocks b by bilinear interpolation."""
        bj, bi, s = blocks.j[b], blocks.i[b], blocks.size[b]
        u, v = (x - bi) / s, (y - bj) / s
        weights = [(1 - u) * (1 - v), u * (1 - v), (1 - u) * v, u * v]
        corners = [(bj, bi), (bj, bi + s), (bj + s, bi), (bj + s, bi + s)]
        d = sum(
            wk[:, None] * nodes.direction[j, i] for wk, (j, i) in zip(weights, corners, strict=True)
        )
        err = sum(wk * nodes.error[j, i] for wk, (j, i) in zip(weights, corners, strict=True))
        ending = nodes.ending[bj, bi]
        sky = ending == ENDING["escaped"]
        colour = np.zeros((b.size, 4))
        colour[:, 3] = 1.0
        if sky.any():
            dirs = d[sky] / np.linalg.norm(d[sky], axis=1, keepdims=True)
            colour[sky] = self.background(dirs)
        shape = 2.0 * (u * (1 - u) + v * (1 - v))
        out.rgba[rows] = colour
        out.ending[rows] = ending
        out.error[rows] = err + blocks.deviation[b] * shape

    def _supersample(self, nodes: _Nodes, blocks: _Blocks, busy, origin, cancel) -> np.ndarray:
        """Filter-weighted colour (K, 4) of the ``busy`` pixels (h, w mask) from
        ``samples`` points each: interpolated where a block allows, traced elsewhere."""
        pj, pi = np.nonzero(busy)
        k = self.offsets.shape[0]
        y = (pj[:, None] + 1 + self.offsets[None, :, 1]).ravel()
        x = (pi[:, None] + 1 + self.offsets[None, :, 0]).ravel()
        points = self._evaluate(nodes, blocks, y, x)
        todo = np.flatnonzero(points.ending < 0)
        if todo.size:
            xy = np.stack([origin[1] + x[todo] + 0.5, origin[0] + y[todo] + 0.5], axis=1)
            rays, _ = self._trace_points(xy, cancel, companion=False)
            points.rgba[todo] = self.shade(rays, self.background)
        colour = points.rgba.reshape(pj.size, k, 4)
        return np.einsum("pkc,k->pc", colour, self.weights) / self.weights.sum()


@dataclass
class _Points:
    rgba: np.ndarray
    ending: np.ndarray
    error: np.ndarray


class _Blocks:
    """Accepted blocks and, per lattice cell, the accepted block covering it (-1: none)."""

    def __init__(self, ny: int, nx: int) -> None:
        self.block = np.full((ny, nx), -1, dtype=np.int64)
        self.j = np.zeros(0, dtype=np.int64)
        self.i = np.zeros(0, dtype=np.int64)
        self.size = np.zeros(0, dtype=np.int64)
        self.deviation = np.zeros(0)

    def add(self, bj: np.ndarray, bi: np.ndarray, s: int, deviation: np.ndarray) -> None:
        """Record accepted blocks of size s at (bj, bi) and mark their cells."""
        first = self.j.size
        self.j = np.concatenate([self.j, bj])
        self.i = np.concatenate([self.i, bi])
        self.size = np.concatenate([self.size, np.full(bj.size, s)])
        self.deviation = np.concatenate([self.deviation, deviation])
        dj, di = (a.ravel() for a in np.mgrid[0:s, 0:s])
        ids = np.arange(first, first + bj.size)
        self.block[(bj[:, None] + dj).ravel(), (bi[:, None] + di).ravel()] = np.repeat(ids, s * s)


def _contrast(rgba: np.ndarray, ending: np.ndarray) -> np.ndarray:
    """(h, w) pixels (inner part of the (h+2, w+2) lattice) whose colour or ending differs
    from one of their eight neighbours' (AA_CONTRAST)."""
    h, w = rgba.shape[0] - 2, rgba.shape[1] - 2
    centre_c, centre_e = rgba[1 : h + 1, 1 : w + 1], ending[1 : h + 1, 1 : w + 1]
    busy = np.zeros((h, w), dtype=bool)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            if dy == dx == 0:
                continue
            other = (slice(1 + dy, h + 1 + dy), slice(1 + dx, w + 1 + dx))
            diff = np.max(np.abs(rgba[other] - centre_c), axis=-1)
            busy |= (diff > AA_CONTRAST) | (ending[other] != centre_e)
    return busy


def richardson_error(fine: RayResults, coarse: RayResults, origins, order: int) -> np.ndarray:
    """Richardson estimate of the fine run's final-direction error (radians, (N,)) from a
    run at COMPANION_RATIO x its step: the escape direction's, or for a hit the direction
    from the camera to the hit point; pi where the endings differ, +inf where failed."""
    escaped = fine.ending == ENDING["escaped"]
    vec_c = np.where(escaped[:, None], coarse.direction, coarse.position - origins)
    vec_f = np.where(escaped[:, None], fine.direction, fine.position - origins)
    with np.errstate(all="ignore"):
        err = _angle(vec_c, vec_f) / (COMPANION_RATIO**order - 1.0)
    err = np.where(coarse.ending == fine.ending, err, np.pi)
    err = np.where(fine.ending == ENDING["captured"], 0.0, err)
    bad = (fine.ending == ENDING["failed"]) | (fine.ending == ENDING["max_steps"])
    return np.where(bad | ~np.isfinite(err), np.inf, err)


def _angle(u, v) -> np.ndarray:
    """Angle between vectors (..., 3), accurate for tiny angles (atan2 of |u x v| and u.v)."""
    cross = np.linalg.norm(np.cross(u, v), axis=-1)
    return np.arctan2(cross, np.einsum("...i,...i->...", u, v))

"""Supersampling: anti-aliased colour of pixels whose neighbours differ.

Offers ``supersample`` (the filter-weighted colour of busy pixels from their sub-pixel
samples, more where the first disagree), ``sample`` (one group of samples, interpolated or
traced), ``contrast`` (which pixels differ from a neighbour), ``pixel_groups``,
``edge_unseen``, and ``AA_CONTRAST``, ``FIRST_SAMPLES`` and ``SAMPLE_POINTS``.
``SAMPLE_POINTS`` is read here at each call (patch it here). Needs a TileContext,
core.sampling.filters and core.sampling.interpolation (``evaluate``).
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from .context import Cancel, TileContext
from .filters import cells_per_side, filter_samples, pixel_samples
from .interpolation import evaluate
from .lattice import Blocks, Nodes

AA_CONTRAST = 0.03
"""A pixel is supersampled where its colour differs from a neighbour's by more than this
(largest channel difference, linear RGB) or its ending does."""
FIRST_SAMPLES = 5
"""A supersampled pixel gets 5 points first (with 16 samples: the corner cells of its 4 x 4
grid and one near the middle); the rest of ``samples`` only where these differ by more than
AA_CONTRAST (a pixel flagged by a neighbour's edge but itself uniform stops there)."""
SAMPLE_POINTS = 1 << 16
"""Anti-aliasing shades at most this many sub-pixel points (pixels x their samples) at once:
its memory does not grow with ``samples`` (128x96 at 1024 samples: 1.3 GiB before, in one
batch; ~0.5 kB a traced point)."""


def supersample(
    ctx: TileContext,
    nodes: Nodes,
    blocks: Blocks,
    busy: np.ndarray,
    differs: list[np.ndarray],
    near: np.ndarray,
    centre: np.ndarray,
    cancel: Cancel,
) -> np.ndarray:
    """Filter-weighted colour (K, 4) of the ``busy`` pixels (h, w mask) from up to
    ``samples`` points each (interpolated where a block allows, traced elsewhere): the
    first FIRST_SAMPLES; the rest where those disagree with each other or with the
    centre's colour ``centre`` (K, 4) by > AA_CONTRAST, where a pixel and a neighbour it
    differs from both looked uniform (edge_unseen), or where the centre's ray passed
    an object's bounds within the filter's footprint (``near``: a thin object or a star
    between the samples). Where no sample shows what the centre shows (within
    AA_CONTRAST), the centre's colour counts as one more sample: a sub-pixel image the
    centre's ray hit keeps a share (Preview shows it whole; 16 samples missed tiny
    images near a Kerr hole's photon ring that the centre hit, which kept 2-14 % of
    their light, issue 50); elsewhere the samples alone, unbiased. The pixels go in
    groups of at most SAMPLE_POINTS points (pixel_groups)."""
    pj, pi = np.nonzero(busy)
    count = ctx.samples
    first = min(FIRST_SAMPLES, count)
    total, spread = np.zeros((pj.size, 4)), np.zeros(pj.size)
    norm, seen = np.zeros(pj.size), np.zeros(pj.size, dtype=bool)
    for rows in pixel_groups(pj.size, first):
        colour, weight = sample(ctx, nodes, blocks, pj[rows], pi[rows], slice(0, first), cancel)
        total[rows] = np.einsum("pkc,pk->pc", colour, weight)
        norm[rows] = weight.sum(axis=1)
        apart = np.max(np.abs(colour - centre[rows, None, :]), axis=2)
        spread[rows] = np.max(apart, axis=1)
        seen[rows] = np.any(apart <= AA_CONTRAST, axis=1)
    uniform = np.ones(busy.shape, dtype=bool)
    uniform[pj, pi] = spread <= AA_CONTRAST
    more = ~uniform[pj, pi] | edge_unseen(differs, uniform)[pj, pi] | near[pj, pi]
    more = np.flatnonzero(more)
    if more.size and first < count:
        for k in range(first, count, SAMPLE_POINTS):  # one round unless samples > that
            ks = slice(k, min(k + SAMPLE_POINTS, count))
            for rows in pixel_groups(more.size, ks.stop - ks.start):
                at = more[rows]
                rest, weight = sample(ctx, nodes, blocks, pj[at], pi[at], ks, cancel)
                total[at] += np.einsum("pkc,pk->pc", rest, weight)
                norm[at] += weight.sum(axis=1)
                near_centre = np.max(np.abs(rest - centre[at, None, :]), axis=2)
                seen[at] |= np.any(near_centre <= AA_CONTRAST, axis=1)
    total[~seen] += centre[~seen]  # the centre's own, one sample's weight (filter_samples)
    norm[~seen] += 1.0
    return total / norm[:, None]


def sample(
    ctx: TileContext,
    nodes: Nodes,
    blocks: Blocks,
    pj: np.ndarray,
    pi: np.ndarray,
    ks: slice,
    cancel: Cancel,
) -> tuple[np.ndarray, np.ndarray]:
    """Colours (P, K, 4) and filter weights (P, K) at the pixels (pj, pi) (tile pixels)
    of their samples ``ks`` (of ``stratified_points``, jittered per pixel)."""
    rows, columns = ctx.origin[0] + pj + 1, ctx.origin[1] + pi + 1
    k = cells_per_side(ctx.samples)
    unit = pixel_samples(ctx.unit, ks, k, rows, columns)
    offsets, weight = filter_samples(unit, ctx.pixel_filter, ctx.filter_size)
    y = (pj[:, None] + 1 + offsets[:, :, 1]).ravel()
    x = (pi[:, None] + 1 + offsets[:, :, 0]).ravel()
    points = evaluate(ctx, nodes, blocks, y, x)
    todo = np.flatnonzero(points.ending < 0)
    if todo.size:
        xy = ctx.image_xy(y[todo], x[todo])
        rays, _, _ = ctx.trace_points(xy, cancel, False, node=False)
        points.rgba[todo] = ctx.shade(rays, ctx.background)
    return points.rgba.reshape(pj.size, -1, 4), weight


def pixel_groups(pixels: int, samples: int) -> Iterator[slice]:
    """Slices of ``pixels`` pixels with ``samples`` points each: at most SAMPLE_POINTS
    points a slice (one pixel at least)."""
    per = max(1, SAMPLE_POINTS // samples)
    return (slice(p, p + per) for p in range(0, pixels, per))


_NEIGHBOURS = [(dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1) if (dy, dx) != (0, 0)]


def contrast(rgba: np.ndarray, ending: np.ndarray) -> list[np.ndarray]:
    """Per neighbour (_NEIGHBOURS order) the (h, w) mask of pixels (the inner part of the
    (h+2, w+2) lattice) whose colour (by AA_CONTRAST) or ending differs from it."""
    h, w = rgba.shape[0] - 2, rgba.shape[1] - 2
    centre_c, centre_e = rgba[1 : h + 1, 1 : w + 1], ending[1 : h + 1, 1 : w + 1]
    masks = []
    for dy, dx in _NEIGHBOURS:
        other = (slice(1 + dy, h + 1 + dy), slice(1 + dx, w + 1 + dx))
        diff = np.max(np.abs(rgba[other] - centre_c), axis=-1)
        masks.append((diff > AA_CONTRAST) | (ending[other] != centre_e))
    return masks


def edge_unseen(differs: list[np.ndarray], uniform: np.ndarray) -> np.ndarray:
    """(h, w) pixels that differ from a neighbour although both looked uniform inside (the
    edge between them runs through a sliver of one): they get the rest of their samples.
    Neighbours outside the tile count as uniform."""
    h, w = uniform.shape
    padded = np.ones((h + 2, w + 2), dtype=bool)
    padded[1:-1, 1:-1] = uniform
    unseen = np.zeros((h, w), dtype=bool)
    for (dy, dx), differ in zip(_NEIGHBOURS, differs, strict=True):
        unseen |= differ & padded[1 + dy : h + 1 + dy, 1 + dx : w + 1 + dx]
    return unseen & uniform

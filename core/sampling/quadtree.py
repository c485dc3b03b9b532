"""The quadtree: refining a tile's blocks level by level, and what a round of tracing costs.

Offers ``refine`` (trace and accept blocks from the coarsest down to ``FINEST``, the nodes
of blocks refused there all traced), ``refining_pays`` (the cost guard: whether a tile is
refined at all, or its every pixel traced from the start), ``dense_pays`` (whether tracing
a level's refused blocks densely costs less than refining them), ``first_lattice`` (how
far down the first round traces at once), ``block_nodes``, and ``FINEST`` and
``ROUND_RAYS``. ``ROUND_RAYS`` is read here at each call (patch it here: core.render reads
it from this module too). Needs a TileContext, the lattice, core.sampling.anchors (tracing
nodes) and core.sampling.acceptance.
"""

from __future__ import annotations

import math

import numpy as np

from .acceptance import accept
from .anchors import trace_nodes
from .context import Cancel, TileContext
from .lattice import Blocks, Nodes, block_points

FINEST = 4
"""Pixels per side of the finest block tried: every pixel of a block refused at this size
is traced (one round instead of two more: each round costs a batch's per-step overhead)."""
ROUND_RAYS = 1500
"""What one round of tracing (a batch) costs beyond its rays, in rays: each step of a
batch pays numpy's per-call overhead whatever its size (measured at 160 x 120, one
worker: a round of 65 rays took as long as 1500-3700 more rays of a large one, thin_front
and stars). refine weighs rounds against rays with it: how far down the quadtree the
first round traces at once (first_lattice), and where tracing every remaining node of a
tile's refused blocks in one round costs less than refining them (refine). A constant,
not a timing: the same scene gives the same image on any machine."""

REFINE_ROUNDS = 6
"""Rounds of tracing a refined tile takes (its first lattice, its levels, retraces, the
pixel centres interpolation missed and those the colour test asks for) ...."""
DENSE_ROUNDS = 2
"""... and one whose every pixel is traced (its nodes, retraces) ..."""
REFINED_SHARE = 0.5
"""... and the share of a tile's pixels refining traces at best (benchmarks/honesty.py's
family at 160 x 90 traced 0.44-1.11 rays a pixel, median 0.87; at 640 x 360 ~0.3-0.5):
refining_pays weighs them."""


def refining_pays(pixels: int) -> bool:
    """Whether refining a tile of ``pixels`` can cost less than tracing its every pixel
    from the start (the cost guard): the rounds it adds (REFINE_ROUNDS - DENSE_ROUNDS,
    ROUND_RAYS each) against the rays it saves at best ((1 - REFINED_SHARE) of them).
    A tile where it cannot is traced at every pixel, as core.render(interpolate=False)
    traces one: the same image."""
    added = (REFINE_ROUNDS - DENSE_ROUNDS) * ROUND_RAYS
    return added < (1.0 - REFINED_SHARE) * pixels


def refine(
    ctx: TileContext,
    nodes: Nodes,
    blocks: Blocks,
    s: int,
    last: tuple[int, int],
    origin: tuple[int, int],
    cancel: Cancel,
) -> None:
    """Trace and accept blocks level by level, from size s down to FINEST; the nodes of
    blocks still refused there are all traced. Only blocks reaching the tile's nodes
    (rows and columns up to ``last``: the lattice may run past them) are refined."""
    ny, nx = nodes.traced.shape
    bj, bi = (a.ravel() for a in np.mgrid[0 : ny - 1 : s, 0 : nx - 1 : s])
    first = first_lattice((last[0] + 1) * (last[1] + 1), s)
    if first < s // 2:  # one round for the levels whose points lie on its lattice
        jj, ii = (a.ravel() for a in np.mgrid[0:ny:first, 0:nx:first])
        trace_nodes(ctx, nodes, jj, ii, origin, cancel, defer=True)
    while bj.size:
        half = s // 2
        nine = block_points(bj, bi, s)
        jj, ii = (np.concatenate([p[k] for p in nine]) for k in (0, 1))
        trace_nodes(ctx, nodes, jj, ii, origin, cancel, defer=True)
        if cancel is not None and cancel():
            return
        accepted, deviation, vectors = accept(ctx, nodes, bj, bi, s)
        blocks.add(bj[accepted], bi[accepted], s, deviation[accepted], vectors[accepted])
        sj, si = bj[~accepted], bi[~accepted]
        jj, ii = block_nodes(sj, si, s, last)
        if s <= FINEST or dense_pays(nodes, jj, ii, sj, si, s, last, first):
            trace_nodes(ctx, nodes, jj, ii, origin, cancel, dense=True, defer=True)
            return
        bj = np.concatenate([sj, sj, sj + half, sj + half])
        bi = np.concatenate([si, si + half, si, si + half])
        reach = (bj <= last[0]) & (bi <= last[1])
        bj, bi, s = bj[reach], bi[reach], half


def dense_pays(
    nodes: Nodes,
    jj: np.ndarray,
    ii: np.ndarray,
    sj: np.ndarray,
    si: np.ndarray,
    s: int,
    last: tuple[int, int],
    first: int,
) -> bool:
    """Whether tracing every untraced node (jj, ii) of the blocks (sj, si) refused at
    size s in one round costs less (ROUND_RAYS a round) than refining them: a round
    per level below s whose points are off the ``first`` round's lattice, down to
    FINEST, and the dense one after it; the next level's points; half of what is
    left (a guess: about half of the blocks refused at one level were refused at the
    next in benchmarks/honesty.py's family)."""
    dense = int(np.count_nonzero(~nodes.traced[jj, ii]))
    half = s // 2
    bj = np.concatenate([sj, sj, sj + half, sj + half])
    bi = np.concatenate([si, si + half, si, si + half])
    pj, pi = (np.concatenate([p[k] for p in block_points(bj, bi, half)]) for k in (0, 1))
    inside = (pj <= last[0]) & (pi <= last[1])
    flat = np.unique(pj[inside] * nodes.traced.shape[1] + pi[inside])
    level = int(np.count_nonzero(~nodes.traced.ravel()[flat]))
    levels = [size for size in (half >> k for k in range(8)) if size >= FINEST]
    rounds = 1 + sum((size // 2) % first != 0 for size in levels)
    refined = rounds * ROUND_RAYS + level + 0.5 * max(dense - level, 0)
    return ROUND_RAYS + dense <= refined


def first_lattice(pixels: int, stride: int) -> int:
    """The spacing of the nodes refine traces in its first round: stride / 2 (the points
    of the coarsest blocks alone), or less, down to FINEST (the points of every level
    down to blocks of 2 FINEST at once), where the rounds saved (ROUND_RAYS each) cost
    more than the nodes traced ahead (pixels / spacing^2 at most, all blocks accepted)."""
    best, cost, spacing = stride // 2, 0.0, stride // 4
    while spacing >= FINEST:
        saved = int(math.log2(stride // 2 // spacing)) * ROUND_RAYS
        extra = pixels / spacing**2 - pixels / (stride // 2) ** 2 - saved
        if extra < cost:
            best, cost = spacing, extra
        spacing //= 2
    return best


def block_nodes(
    sj: np.ndarray, si: np.ndarray, s: int, last: tuple[int, int]
) -> tuple[np.ndarray, np.ndarray]:
    """(jj, ii) every node of the blocks (sj, si) of size s up to row and column ``last``."""
    dj, di = (a.ravel() for a in np.mgrid[0 : s + 1, 0 : s + 1])
    jj, ii = (sj[:, None] + dj).ravel(), (si[:, None] + di).ravel()
    inside = (jj <= last[0]) & (ii <= last[1])
    return jj[inside], ii[inside]

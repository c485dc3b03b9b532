"""Tracing lattice nodes, their companions at the anchors.

Offers ``trace_nodes`` (trace and judge a tile's untraced nodes; with ``defer`` only the
anchors run a companion at once), ``settle`` (judge the deferred nodes by their anchors'
errors, or name those that need a companion of their own), ``from_anchors``, ``spare`` and
``clear_of`` (what the anchors say of a node), ``anchors`` and ``ANCHOR``. Needs a
TileContext (tracing points), the lattice and core.sampling.judging.
"""

from __future__ import annotations

import numpy as np

from ..tracing import ENDING
from .context import Cancel, TileContext
from .error import COMPANION_RATIO, FLIP
from .judging import NEAR_MISS, judge, record
from .lattice import DENSE_MARGIN, Nodes, node_margin

ANCHOR = 4
"""With the error pass, only the nodes at multiples of ANCHOR (the anchors) get their
companion as they are traced; the others take the largest error of the anchors at their
cell's corners where those end as they do (settle), or a companion of their
own then. The nodes of blocks of 8 and up are all anchors: what is spared is the
companions of the finest rounds, most of a tile's rays."""


def anchors(jj: np.ndarray, ii: np.ndarray) -> np.ndarray:
    """(M,) bool: which nodes (jj, ii) are anchors (ANCHOR)."""
    return (jj % ANCHOR == 0) & (ii % ANCHOR == 0)


def trace_nodes(
    ctx: TileContext,
    nodes: Nodes,
    jj: np.ndarray,
    ii: np.ndarray,
    origin: tuple[int, int],
    cancel: Cancel,
    dense: bool = False,
    defer: bool = False,
) -> None:
    """Trace the untraced nodes among (jj, ii) (flat index arrays) and store them
    (``dense``: no block will interpolate them; TileContext.trace_points). ``defer``: only the
    anchors (``anchors``) get a companion now, the others' error waits for settle."""
    flat = np.unique(jj * nodes.traced.shape[1] + ii)
    jj, ii = np.divmod(flat, nodes.traced.shape[1])
    todo = ~nodes.traced[jj, ii]
    jj, ii = jj[todo], ii[todo]
    if jj.size == 0:
        return
    margin = node_margin(jj, ii, dense)
    companion = ~spare(ctx, nodes, jj, ii) if defer and ctx.with_error else True
    xy = ctx.image_xy(jj, ii)
    rays, seen, error = ctx.trace_points(xy, cancel, companion, margin=margin)
    record(ctx, nodes, jj, ii, rays, seen)
    nodes.loose[jj, ii] = error is not None and ctx.bound_applies(ctx.step)
    if error is not None and not isinstance(companion, bool):
        nodes.pending[jj, ii] = ~companion
        jj, ii, error = jj[companion], ii[companion], error[companion]
    judge(ctx, nodes, jj, ii, error)


def from_anchors(
    ctx: TileContext, nodes: Nodes, jj: np.ndarray, ii: np.ndarray
) -> tuple[np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray], np.ndarray]:
    """What the anchors at the corners of the nodes (jj, ii)'s ANCHOR cells say of
    their errors -> (agree, estimate, like, judged): ``agree`` where all four are traced,
    judged, finite, no flip or near miss, end alike (escaped, captured, on one object,
    across the same kinks: the error is smooth across the cell) and keep clear of the
    geometry by more than a companion's error could move a ray (clear_of) unless
    captured; ``estimate`` their largest error (0 if captured); ``like``: the corner
    whose ending the node must share (its (j, i)); ``judged``: all four are."""
    ny, nx = nodes.traced.shape
    cj, ci = jj - jj % ANCHOR, ii - ii % ANCHOR
    judged, estimate = np.ones(jj.size, dtype=bool), np.zeros(jj.size)
    agree, least = np.ones(jj.size, dtype=bool), np.full(jj.size, np.inf)
    for dj in (0, ANCHOR):
        for di in (0, ANCHOR):
            aj, ai = np.minimum(cj + dj, ny - 1), np.minimum(ci + di, nx - 1)
            judged &= (aj == cj + dj) & (ai == ci + di) & nodes.traced[aj, ai]
            judged &= ~nodes.pending[aj, ai]
            agree &= ~nodes.flipped[aj, ai] & ~nodes.near[aj, ai]
            agree &= np.isfinite(nodes.integration[aj, ai]) & (nodes.integration[aj, ai] < FLIP)
            agree &= nodes.ending[aj, ai] == nodes.ending[cj, ci]
            agree &= nodes.object_id[aj, ai] == nodes.object_id[cj, ci]
            agree &= nodes.kinks[aj, ai] == nodes.kinks[cj, ci]
            estimate = np.maximum(estimate, nodes.integration[aj, ai])
            least = np.minimum(least, nodes.clearance[aj, ai])
    captured = nodes.ending[cj, ci] == ENDING["captured"]
    estimate = np.where(captured, 0.0, estimate)
    agree &= judged & ((least >= clear_of(ctx, estimate)) | captured)
    return agree, estimate, (cj, ci), judged


def clear_of(ctx: TileContext, estimate: np.ndarray) -> np.ndarray:
    """The clearance (radians) a node of error ``estimate`` needs for its companion to
    be spared: more than the companion's error could move it (NEAR_MISS x
    COMPANION_RATIO^order x the estimate: a thin object between anchors) and
    DENSE_MARGIN pixels (benchmarks/honesty.py thin_front at 1 px: 5 flips estimated
    under a pixel with the first alone)."""
    assert ctx.tracer.order is not None  # an error pass: the scene is curved
    reach = NEAR_MISS * COMPANION_RATIO**ctx.tracer.order
    return np.maximum(reach * estimate, DENSE_MARGIN * ctx.pixel_angle)


def spare(ctx: TileContext, nodes: Nodes, jj: np.ndarray, ii: np.ndarray) -> np.ndarray:
    """(M,) bool: the nodes (jj, ii), not traced yet, whose companion is spared for now
    (trace_nodes' ``defer``): not anchors, and their anchors agree (from_anchors) or
    are not all judged yet (traced in this round: settle will know)."""
    agree, _, _, judged = from_anchors(ctx, nodes, jj, ii)
    return ~anchors(jj, ii) & (agree | ~judged)


def settle(ctx: TileContext, nodes: Nodes) -> tuple[np.ndarray, np.ndarray]:
    """Judge the pending nodes (traced without their companion: spare) by their
    anchors' largest error where they end as their anchors do and keep as clear of
    the geometry (from_anchors; captured as they are: the shadow's inside has no
    error, and a camera at 3 rg in a disk's plane sees it through rays of clearance
    0) -> (jj, ii) the others: their companions run with the first retraces."""
    jj, ii = np.nonzero(nodes.pending)
    if jj.size == 0:
        return jj, ii
    agree, estimate, (cj, ci), _ = from_anchors(ctx, nodes, jj, ii)
    nodes.pending[:] = False
    like = (nodes.ending[jj, ii] == nodes.ending[cj, ci]) & agree
    like &= nodes.object_id[jj, ii] == nodes.object_id[cj, ci]
    like &= nodes.kinks[jj, ii] == nodes.kinks[cj, ci]
    captured = nodes.ending[jj, ii] == ENDING["captured"]
    like &= (nodes.clearance[jj, ii] >= clear_of(ctx, estimate)) | captured
    rest = np.flatnonzero(~like)  # those their whole cell cannot judge
    side, estimate[rest] = by_side(ctx, nodes, jj[rest], ii[rest])
    like[rest[side]] = True
    judge(ctx, nodes, jj[like], ii[like], estimate[like])
    return jj[~like], ii[~like]


def by_side(
    ctx: TileContext, nodes: Nodes, jj: np.ndarray, ii: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(M,) which pending nodes (jj, ii) whose cell an object's silhouette crosses are
    judged by the anchors on their side of it, and (M,) their estimate: all four anchors
    judged and sound (no flip, no near miss, a finite error), at least two ending as the
    node does (the same object, the same kinks), the others differing only by an object
    hit (never captured against escaped: the shadow's edge, where errors grow without
    bound), and the node and those two keeping clear of the geometry by clear_of their
    largest error (a node on an object is then tested against its own edge by judge's
    near_edge)."""
    ny, nx = nodes.traced.shape
    cj, ci = jj - jj % ANCHOR, ii - ii % ANCHOR
    ending, kinks, hit = nodes.ending[jj, ii], nodes.kinks[jj, ii], ENDING["hit"]
    sound, count = np.ones(jj.size, dtype=bool), np.zeros(jj.size, dtype=np.int64)
    estimate, least = np.zeros(jj.size), np.full(jj.size, np.inf)
    for dj in (0, ANCHOR):
        for di in (0, ANCHOR):
            aj, ai = np.minimum(cj + dj, ny - 1), np.minimum(ci + di, nx - 1)
            error = nodes.integration[aj, ai]
            sound &= (aj == cj + dj) & (ai == ci + di) & nodes.traced[aj, ai]
            sound &= ~nodes.pending[aj, ai] & ~nodes.flipped[aj, ai] & ~nodes.near[aj, ai]
            sound &= np.isfinite(error) & (error < FLIP) & (nodes.kinks[aj, ai] == kinks)
            same = (nodes.ending[aj, ai] == ending) & (
                nodes.object_id[aj, ai] == nodes.object_id[jj, ii]
            )
            sound &= same | (nodes.ending[aj, ai] == hit) | (ending == hit)
            count += same
            estimate = np.where(same, np.maximum(estimate, error), estimate)
            least = np.where(same, np.minimum(least, nodes.clearance[aj, ai]), least)
    need = clear_of(ctx, estimate)
    side = sound & (count >= 2) & (ending != ENDING["captured"])
    side &= (nodes.clearance[jj, ii] >= need) & (least >= need)
    return side, estimate

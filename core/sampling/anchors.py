"""Tracing lattice nodes, their companions at the anchors.

Offers ``trace_nodes`` (trace and judge a tile's untraced nodes; with ``defer`` only the
roots run a companion at once), ``settle`` (judge the deferred nodes by the errors at
their cell's corners, or name those that need a companion of their own), ``from_anchors``,
``spare``, ``cell_sides`` and ``clear_of`` (what a cell's corners say of a node),
``anchors``, ``roots``, ``ANCHOR`` and ``ROOT``. Needs a TileContext (tracing points), the
lattice and core.sampling.judging.
"""

from __future__ import annotations

import numpy as np

from ..tracing import ENDING
from .context import Cancel, TileContext
from .error import COMPANION_RATIO, FLIP
from .judging import NEAR_MISS, budgets, judge, record
from .lattice import DENSE_MARGIN, Nodes, node_margin

ANCHOR = 4
"""With the error pass, a node not at multiples of ANCHOR takes the largest error of the
anchors (the nodes at multiples of ANCHOR) at its ANCHOR cell's corners where those end as
it does and agree (settle), or a companion of its own then ..."""
ROOT = 16
"""... and an anchor the largest error of the roots (the nodes at multiples of ROOT, which
alone get their companion as they are traced) at its ROOT cell's corners, in the same way,
unless it hits a surface (a hit point's error varies from ray to ray more than a cell of
ROOT shows: _by_cell). The nodes of blocks of 8 and up are all anchors: where a tile's
image is smooth they are most of its rays (benchmarks/honesty.py near_tangent at 640 x
360, 1 px: 7179 of 22 930 rays, each with its companion when the anchors were the
roots)."""


def anchors(shape: tuple[int, int], jj: np.ndarray, ii: np.ndarray) -> np.ndarray:
    """(M,) bool: which nodes (jj, ii) of a lattice of ``shape`` are anchors: at multiples
    of ANCHOR or on its last row or column (the corners of its cells cut short there)."""
    return _on(shape, jj, ii, ANCHOR)


def roots(shape: tuple[int, int], jj: np.ndarray, ii: np.ndarray) -> np.ndarray:
    """(M,) bool: which nodes (jj, ii) of a lattice of ``shape`` are roots (at multiples
    of ROOT or on its last row or column): their companion runs as they are traced."""
    return _on(shape, jj, ii, ROOT)


def _on(shape: tuple[int, int], jj: np.ndarray, ii: np.ndarray, side: int) -> np.ndarray:
    """(M,) bool: nodes (jj, ii) at multiples of ``side`` or on the lattice's last row or
    column, in both directions."""
    return ((jj % side == 0) | (jj == shape[0] - 1)) & ((ii % side == 0) | (ii == shape[1] - 1))


def corners(
    shape: tuple[int, int], jj: np.ndarray, ii: np.ndarray, side: np.ndarray | int
) -> list[tuple[np.ndarray, np.ndarray]]:
    """The four corners (aj, ai) of the nodes (jj, ii)'s cells of ``side`` (one or (M,)),
    the first its top left; a cell past the lattice's last row or column is cut short
    there."""
    cj, ci = jj - jj % side, ii - ii % side
    far_j, far_i = np.minimum(cj + side, shape[0] - 1), np.minimum(ci + side, shape[1] - 1)
    return [(cj, ci), (cj, far_i), (far_j, ci), (far_j, far_i)]


def cell_sides(traced: np.ndarray, jj: np.ndarray, ii: np.ndarray) -> np.ndarray:
    """(M,) the side of the cell whose corners judge the nodes (jj, ii) of a lattice whose
    nodes ``traced`` (or about to be): ROOT for anchors, ANCHOR for the others where all
    four of their ANCHOR cell's corners are, ROOT where not (a pixel centre traced late
    inside a block of 8 or more, whose anchors inside were never traced)."""
    shape = traced.shape
    inside = np.ones(jj.size, dtype=bool)
    for aj, ai in corners(shape, jj, ii, ANCHOR):
        inside &= traced[aj, ai]
    return np.where(anchors(shape, jj, ii) | ~inside, ROOT, ANCHOR)


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
    roots (``roots``) get a companion now, the others' error waits for settle."""
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
    ctx: TileContext, nodes: Nodes, jj: np.ndarray, ii: np.ndarray, side: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray], np.ndarray]:
    """What the nodes at the corners of the nodes (jj, ii)'s cells (of ``side``, (M,):
    cell_sides; ``corners``) say of their errors -> (agree, estimate, lowest, like,
    judged):
    ``agree`` where all four are traced, judged, finite, no flip or near miss, end alike
    (escaped, captured, on one object, across the same kinks: the error is smooth across
    the cell) and keep clear of the geometry by more than a companion's error could move
    a ray (clear_of) unless captured; ``estimate`` the largest error of their first runs
    (Nodes.first: a node is judged at its own run's step, a retraced corner's later
    runs are finer; 0 if captured), ``lowest`` the least of them (a cell of ROOT whose
    root read no error at all, its two runs alike to the last bit, speaks for no node);
    ``like``: the corner whose ending the node must share (its (j, i)); ``judged``: all
    four are."""
    four = corners(nodes.traced.shape, jj, ii, side)
    cj, ci = four[0]
    judged, estimate = np.ones(jj.size, dtype=bool), np.zeros(jj.size)
    agree, least = np.ones(jj.size, dtype=bool), np.full(jj.size, np.inf)
    lowest = np.full(jj.size, np.inf)
    for aj, ai in four:
        lowest = np.minimum(lowest, nodes.first[aj, ai])
        judged &= nodes.traced[aj, ai] & ~nodes.pending[aj, ai]
        agree &= ~nodes.flipped[aj, ai] & ~nodes.near[aj, ai]
        agree &= np.isfinite(nodes.first[aj, ai]) & (nodes.first[aj, ai] < FLIP)
        agree &= nodes.ending[aj, ai] == nodes.ending[cj, ci]
        agree &= nodes.object_id[aj, ai] == nodes.object_id[cj, ci]
        agree &= nodes.kinks[aj, ai] == nodes.kinks[cj, ci]
        estimate = np.maximum(estimate, nodes.first[aj, ai])
        least = np.minimum(least, nodes.clearance[aj, ai])
    captured = nodes.ending[cj, ci] == ENDING["captured"]
    estimate = np.where(captured, 0.0, estimate)
    agree &= judged & ((least >= clear_of(ctx, estimate)) | captured)
    agree &= (side < ROOT) | captured | (lowest > 0)
    return agree, estimate, lowest, (cj, ci), judged


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
    (trace_nodes' ``defer``): not roots, and their cell's corners (an anchor's ROOT cell,
    another node's ANCHOR cell) agree (from_anchors) or are not all judged yet (traced in
    this round, or judged by settle: settle will know), unless what settle asks of them
    already fails there: a cell of ROOT whose corners hit, a cell's error that would
    send them to a retrace where some of its corners' would not (_by_cell)."""
    traced = nodes.traced.copy()
    traced[jj, ii] = True  # this round's
    side = cell_sides(traced, jj, ii)
    agree, estimate, lowest, (cj, ci), judged = from_anchors(ctx, nodes, jj, ii, side)
    loose = np.full(jj.size, ctx.bound_applies(ctx.step))  # as trace_nodes records it
    agree &= ~_rough(side, nodes.ending[cj, ci]) & ~_straddles(ctx, estimate, lowest, loose)
    return ~roots(traced.shape, jj, ii) & (agree | ~judged)


def _rough(side: np.ndarray, ending: np.ndarray) -> np.ndarray:
    """(M,) bool: nodes a cell of ``side`` cannot judge however its corners agree: a hit
    (``ending``) under a cell of ROOT (a hit point's error follows where its crossing
    falls in its step: benchmarks/honesty.py schwarzschild's board at the rule's largest
    step, roots 0.001 px, the anchors between them 0.005)."""
    return (side >= ROOT) & (ending == ENDING["hit"])


def _straddles(
    ctx: TileContext, estimate: np.ndarray, lowest: np.ndarray, loose: np.ndarray
) -> np.ndarray:
    """(M,) bool: nodes whose cell's ``estimate`` is over the error that sends a node to
    a retrace (judging.budgets; ``loose``: Nodes.loose of them) where its ``lowest``
    corner's is not: its own companion (half a ray) may spare it a retrace (a ray at half
    the step)."""
    limit = budgets(ctx, loose)
    return (estimate > limit) & (lowest <= limit)


def settle(ctx: TileContext, nodes: Nodes) -> tuple[np.ndarray, np.ndarray]:
    """Judge the pending nodes (traced without their companion: spare) by the largest
    error at their cell's corners (cell_sides) where they end as those do and keep as
    clear of the geometry (from_anchors; captured as they are: the shadow's inside has
    no error, and a camera at 3 rg in a disk's plane sees it through rays of clearance
    0): the anchors first, by the roots, then the other nodes by the anchors -> (jj, ii)
    those that need a companion of their own (retrace.retrace_batch). The nodes whose
    cell has an anchor still pending stay pending: settle judges them once it is
    (retrace.retrace, retrace.companions)."""
    jj, ii = np.nonzero(nodes.pending)
    if jj.size == 0:
        return jj, ii
    side = cell_sides(nodes.traced, jj, ii)
    left = []
    for first in (True, False):  # the cells of ROOT first: their corners are judged
        rows = np.flatnonzero((side == ROOT) == first)
        like, judged = _by_cell(ctx, nodes, jj[rows], ii[rows], side[rows])
        left.append(rows[~like & (judged | first)])
    rest = np.concatenate(left)
    return jj[rest], ii[rest]


def _by_cell(
    ctx: TileContext, nodes: Nodes, jj: np.ndarray, ii: np.ndarray, side: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(M,) bool: which pending nodes (jj, ii) settle judged by their cell of ``side``
    (no longer pending): those ending as its corners do (from_anchors), else by the
    corners on their side of a silhouette (by_side), but never a hit by a cell of ROOT,
    nor a node whose cell's error would send it to a retrace where some of its corners'
    would not (budgets: its own companion, half a ray, may spare it one, a ray at half
    the step); and (M,) whose corners were all judged."""
    agree, estimate, lowest, (cj, ci), judged = from_anchors(ctx, nodes, jj, ii, side)
    like = (nodes.ending[jj, ii] == nodes.ending[cj, ci]) & agree
    like &= nodes.object_id[jj, ii] == nodes.object_id[cj, ci]
    like &= nodes.kinks[jj, ii] == nodes.kinks[cj, ci]
    captured = nodes.ending[jj, ii] == ENDING["captured"]
    like &= (nodes.clearance[jj, ii] >= clear_of(ctx, estimate)) | captured
    rough = _rough(side, nodes.ending[jj, ii])
    like &= ~rough
    rest = np.flatnonzero(~like & ~rough)  # those their whole cell cannot judge
    beside, estimate[rest] = by_side(ctx, nodes, jj[rest], ii[rest], side[rest])
    like[rest[beside]] = True
    like &= ~_straddles(ctx, estimate, lowest, nodes.loose[jj, ii])
    judge(ctx, nodes, jj[like], ii[like], estimate[like])
    nodes.pending[jj[like], ii[like]] = False
    return like, judged


def by_side(
    ctx: TileContext, nodes: Nodes, jj: np.ndarray, ii: np.ndarray, side: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(M,) which pending nodes (jj, ii) whose cell (of ``side``, (M,)) an object's
    silhouette crosses are judged by the corners on their side of it, and (M,) their
    estimate: all four corners judged and sound (no flip, no near miss, a finite error),
    at least two ending as the node does (the same object, the same kinks), the others
    differing only by an object hit (never captured against escaped: the shadow's edge,
    where errors grow without bound), and the node and those two keeping clear of the
    geometry by clear_of their largest error (a node on an object is then tested against
    its own edge by judge's near_edge)."""
    ending, kinks, hit = nodes.ending[jj, ii], nodes.kinks[jj, ii], ENDING["hit"]
    sound, count = np.ones(jj.size, dtype=bool), np.zeros(jj.size, dtype=np.int64)
    estimate, least = np.zeros(jj.size), np.full(jj.size, np.inf)
    for aj, ai in corners(nodes.traced.shape, jj, ii, side):
        error = nodes.first[aj, ai]
        sound &= nodes.traced[aj, ai]
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
    beside = sound & (count >= 2) & (ending != ENDING["captured"])
    beside &= (nodes.clearance[jj, ii] >= need) & (least >= need)
    return beside, estimate

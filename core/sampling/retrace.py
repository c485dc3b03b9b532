"""Retraces: rays whose error exceeds the budget, or that nearly missed, traced again.

Offers ``retrace`` (a tile's nodes over their error budget, and its near misses, traced
again at half the step, up to ``RETRACE`` times, with the companions ``settle`` left over),
``retrace_batch`` (one such round's rays) and ``companions`` (those left over alone), and
``RETRACE``. Needs a TileContext (tracing points, companions), the lattice,
core.sampling.anchors (settle) and core.sampling.judging (its budgets).
"""

from __future__ import annotations

import numpy as np

from ..tracing import RayResults
from .anchors import settle
from .context import Cancel, TileContext
from .error import COMPANION_RATIO, richardson, seen_apart, seen_direction
from .judging import budgets, judge, store
from .lattice import Nodes, dense_margin, node_rays

RETRACE = 3
"""With ``tolerance_px``, a traced ray whose estimated error exceeds its budget is traced
again at half the step, up to RETRACE times: rays magnified near the photon ring (whose
forward error the step rule, made for the initial direction's, does not bound) still meet
the tolerance, at the cost of those rays only."""


def retrace(ctx: TileContext, nodes: Nodes, cancel: Cancel) -> None:
    """Trace the nodes whose integration error exceeds ``budget`` again at half the
    step, their previous run the companion, up to RETRACE times (all of a tile's at
    once: each run costs a batch's per-step overhead), and the near misses
    (``Nodes.near``: their path, less its hit test's slack, within NEAR_MISS x their
    error of an object) as long as they stay near: at half the step the error is 16x
    smaller and the slack 4x (the ray of a mirage grazing hot ground that missed it on
    its cubic while the true path dips below hits it then; benchmarks/honesty.py
    mirage_grazing@1: 18 pixels off by a flip before, and after one retrace; +7 % time
    on a 1080p Kerr disk frame). A near edge (judging.near_edge) is not
    traced again: its retrace, agreeing, would report it clear of the edge whatever the
    truth (thin_front: quiet flips). A flip whose retrace ended as its last run did is
    not traced again: it keeps its flip's error whatever later runs find, and further
    halvings, agreeing too, only cost (the Kerr board's ~1800 flips per 1080p tile, at
    the shadow's edge, took all RETRACE rounds: 10 % of its time). The pending nodes
    that settle cannot judge have their companions in the first round's batch: they are
    judged by them and join the later rounds; where other nodes wait on some of them (an
    anchor's), those run first, in a batch of companions alone (a round at twice the
    step), and the nodes that waited are settled then (a node settled after the first
    round is retraced at a later round's step: 3 rounds of up to 198 steps on
    benchmarks/honesty.py point_stars at 640 x 360, against 2 with this batch)."""
    settled = np.zeros_like(nodes.traced)  # flips whose retrace ended as before
    unsure = settle(ctx, nodes)
    if np.count_nonzero(nodes.pending) > unsure[0].size:  # some wait on these: theirs first
        retrace_batch(ctx, nodes, np.zeros((0, 2)), np.zeros(0), unsure, cancel)
        unsure = settle(ctx, nodes)
    for k in range(1, RETRACE + 1 if ctx.with_error else 1):
        err = nodes.integration
        again = ((np.isfinite(err) & (err > budgets(ctx, nodes.loose))) | nodes.near) & ~settled
        jj, ii = np.nonzero(nodes.traced & again & ~nodes.pending)
        if cancel is not None and cancel():
            return
        if jj.size == 0 and unsure[0].size == 0:
            break
        step = np.full(jj.size, ctx.first_step / COMPANION_RATIO**k)
        xy = ctx.image_xy(jj, ii)
        rays = retrace_batch(ctx, nodes, xy, step, unsure, cancel)
        if rays is not None:
            _store_retraces(ctx, nodes, (jj, ii), xy, rays, settled, k)
        unsure = (np.zeros(0, int), np.zeros(0, int))
    companions(ctx, nodes, cancel)


def _store_retraces(
    ctx: TileContext,
    nodes: Nodes,
    where: tuple[np.ndarray, np.ndarray],
    xy: np.ndarray,
    rays: RayResults,
    settled: np.ndarray,
    halvings: int,
) -> None:
    """Store the retraces ``rays`` of the nodes ``where`` (jj, ii; image points xy) at
    the first run's step halved ``halvings`` times, their error against the nodes' last
    run (Richardson at the two runs' ratio: a node settled late, whose first run is its
    last, is retraced at the round's step too); a flip that ended as before is marked
    ``settled``."""
    jj, ii = where
    origins, _ = ctx.camera.rays_at(xy)
    seen = seen_direction(rays, origins)
    assert ctx.tracer.order is not None  # a companion run: the scene is curved
    apart = seen_apart(
        seen, rays.position, nodes.direction[jj, ii], nodes.position[jj, ii],
        rays.ending, origins,
    )  # fmt: skip
    alike = (rays.ending == nodes.ending[jj, ii]) & (rays.object_id == nodes.object_id[jj, ii])
    ratio = COMPANION_RATIO ** (halvings - nodes.halvings[jj, ii])
    error = richardson(apart, rays.ending, alike, ctx.tracer.order, ratio)
    settled[jj, ii] = alike & nodes.flipped[jj, ii]
    store(ctx, nodes, jj, ii, rays, seen, error)
    nodes.halvings[jj, ii] = halvings
    nodes.loose[jj, ii] = False  # its last run's step is not half the first run's


def companions(ctx: TileContext, nodes: Nodes, cancel: Cancel) -> None:
    """Judge every pending node (anchors.settle) by its cell, or by a companion of its
    own run in a batch of companions alone, again while some wait on those (a node
    whose cell's anchor had none)."""
    while nodes.pending.any() and not (cancel is not None and cancel()):
        unsure = settle(ctx, nodes)
        if unsure[0].size == 0:  # nothing they wait on will be judged: their own
            unsure = np.nonzero(nodes.pending)
        retrace_batch(ctx, nodes, np.zeros((0, 2)), np.zeros(0), unsure, cancel)


def retrace_batch(
    ctx: TileContext,
    nodes: Nodes,
    xy: np.ndarray,
    step: np.ndarray,
    unsure: tuple[np.ndarray, np.ndarray],
    cancel: Cancel,
) -> RayResults | None:
    """The retraces of the points xy at ``step`` (each its own; returned, None if none), in one
    batch with the companions of the ``unsure`` nodes (jj, ii) where there are no
    differentials (a retrace carries them), which are judged by them."""
    uj, ui = unsure
    n, margin = xy.shape[0], dense_margin()
    ctx.error_rays += n + uj.size
    ctx.companion_rays += uj.size
    rays: RayResults | None = None
    if ctx.with_tangents:
        if n:
            rays = ctx.trace_points(xy, cancel, False, step=step, margin=margin)[0]
        if uj.size == 0:
            return rays
        points = ctx.image_xy(uj, ui)
    else:
        points = np.concatenate([xy, ctx.image_xy(uj, ui)])
    origins, directions = ctx.camera.rays_at(points)
    counts = [points.shape[0] - uj.size, uj.size]
    coarse = np.full(uj.size, COMPANION_RATIO * ctx.first_step)
    traced = ctx.tracer.trace(
        origins, directions, cancel=cancel,
        step=coarse if ctx.with_tangents else np.concatenate([step, coarse]),
        clearance=np.repeat([margin, 0.0], counts),
    )  # fmt: skip
    if not ctx.with_tangents:
        rays, traced = traced.take(slice(0, n)) if n else None, traced.take(slice(n, None))
    if uj.size:
        rest = origins[origins.shape[0] - uj.size :]
        error = ctx.companion_error(node_rays(nodes, uj, ui, rest), traced, rest, ctx.first_step)
        judge(ctx, nodes, uj, ui, error)
        nodes.pending[uj, ui] = False
        nodes.loose[uj, ui] = ctx.bound_applies(ctx.step)
    return rays


# --- the quadtree ------------------------------------------------------------------

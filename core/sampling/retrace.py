"""Retraces: rays whose error exceeds the budget, or that nearly missed, traced again.

Offers ``retrace`` (a tile's nodes over their error budget, and its near misses, traced
again at half the step, up to ``RETRACE`` times, with the companions ``settle`` left over)
and ``retrace_batch`` (one such round's rays), and ``RETRACE`` and ``LOOSE_SHARE``. Needs a
TileContext (tracing points, companions), the lattice and core.sampling.judging.
"""

from __future__ import annotations

import numpy as np

from ..tracing import RayResults
from .context import Cancel, TileContext
from .error import COMPANION_RATIO, richardson, seen_apart, seen_direction
from .judging import judge, store
from .lattice import Nodes, dense_margin, node_rays

RETRACE = 3
"""With ``tolerance_px``, a traced ray whose estimated error exceeds its budget is traced
again at half the step, up to RETRACE times: rays magnified near the photon ring (whose
forward error the step rule, made for the initial direction's, does not bound) still meet
the tolerance, at the cost of those rays only."""
LOOSE_SHARE = 0.3
"""A traced ray whose companion ran past the rule's largest step (Richardson outside its
asymptotic range; TileContext._bound) and whose estimate exceeds LOOSE_SHARE x the retrace
budget is traced again at half the step, its first run the companion (RETRACE's first
round): escaped rays of Schwarzschild and Kerr at the cap had errors at 2 h 40-50x those
at h, read as ~3x the truth, so an estimate above 0.3 of the tolerance may stand for a
truth above a tenth of it, where the error pass promises 3x (benchmarks/honesty.py
point_stars and disk_high_spin at 0.05 px: 88 % and 87 % within 3x -> 100 %). At 0.1 the
Kerr board took 1.4x as long (1080p Preview), at 0.3 1.02x."""


def retrace(
    ctx: TileContext,
    nodes: Nodes,
    cancel: Cancel,
    unsure: tuple[np.ndarray, np.ndarray] | None = None,
) -> None:
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
    the shadow's edge, took all RETRACE rounds: 10 % of its time). The ``unsure``
    nodes (jj, ii) (anchors.settle) have their companions in the first round's batch: they
    are judged by them and join the later rounds."""
    step = ctx.step
    settled = np.zeros_like(nodes.traced)  # flips whose retrace ended as before
    unsure = (np.zeros(0, int), np.zeros(0, int)) if unsure is None else unsure
    for _ in range(RETRACE if ctx.with_error else 0):
        err = nodes.integration
        budget = np.where(nodes.loose, LOOSE_SHARE * ctx.budget, ctx.budget)
        again = ((np.isfinite(err) & (err > budget)) | nodes.near) & ~settled
        nodes.loose[:] = False  # a later round's step is not half the first run's
        jj, ii = np.nonzero(nodes.traced & again)
        if (jj.size == 0 and unsure[0].size == 0) or (cancel is not None and cancel()):
            return
        assert step is not None  # an error pass: the scene is curved
        step /= COMPANION_RATIO
        xy = ctx.image_xy(jj, ii)
        rays = retrace_batch(ctx, nodes, xy, step, unsure, cancel)
        unsure = (np.zeros(0, int), np.zeros(0, int))
        if rays is None:
            continue
        seen = seen_direction(rays, ctx.camera.rays_at(xy)[0])
        assert ctx.tracer.order is not None  # a companion run: the scene is curved
        origins, _ = ctx.camera.rays_at(xy)
        apart = seen_apart(
            seen, rays.position, nodes.direction[jj, ii], nodes.position[jj, ii],
            rays.ending, origins,
        )  # fmt: skip
        alike = (rays.ending == nodes.ending[jj, ii]) & (rays.object_id == nodes.object_id[jj, ii])
        error = richardson(apart, rays.ending, alike, ctx.tracer.order)
        settled[jj, ii] = alike & nodes.flipped[jj, ii]
        store(ctx, nodes, jj, ii, rays, seen, error)


def retrace_batch(
    ctx: TileContext,
    nodes: Nodes,
    xy: np.ndarray,
    step: float,
    unsure: tuple[np.ndarray, np.ndarray],
    cancel: Cancel,
) -> RayResults | None:
    """The retraces of the points xy at ``step`` (returned; None if none), in one
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
    traced = ctx.tracer.trace(
        origins, directions, cancel=cancel,
        step=np.repeat([step, COMPANION_RATIO * ctx.first_step], counts),
        clearance=np.repeat([margin, 0.0], counts),
    )  # fmt: skip
    if not ctx.with_tangents:
        rays, traced = traced.take(slice(0, n)) if n else None, traced.take(slice(n, None))
    if uj.size:
        rest = origins[origins.shape[0] - uj.size :]
        error = ctx.companion_error(node_rays(nodes, uj, ui, rest), traced, rest, ctx.first_step)
        judge(ctx, nodes, uj, ui, error)
        nodes.loose[uj, ui] = ctx.bound_applies(ctx.step)
    return rays


# --- the quadtree ------------------------------------------------------------------

"""Recording traced nodes and judging their errors: flips, near misses, near edges.

Offers ``record`` (a traced ray's values at its node), ``judge`` (a node's error from its
integration's: flips, near misses to be traced again, near edges, the far field), ``store``
(both), ``near_edge`` (hits that may have missed their object's edge), ``budgets`` (the
errors above which nodes are traced again), and ``NEAR_MISS``, ``LOOSE_SHARE``,
``EDGE_REACH`` and ``EDGE_STRETCH``. Needs a TileContext (its tracer, camera, shading) and
the lattice's Nodes.
"""

from __future__ import annotations

import numpy as np

from ..tracing import ENDING, RayResults
from ..tracing.scene import DISK_ID
from .context import TileContext
from .error import FLIP
from .lattice import RAY_PASSES, Nodes

NEAR_MISS = 2.0
"""A traced ray that missed every object by less than NEAR_MISS x its integration error
(its clearance, in radians like the error: from its cubic path less its hit test's slack,
core/tracing/clearance.py) may have hit one: it reports a flip (FLIP) and is traced again
(RETRACE)."""
EDGE_REACH = 4.0
"""A hit moved on its surface to test for the surface's edge (near_edge) is
looked for EDGE_REACH x the move along its chord either side (a curved surface curves away
from its tangent plane)."""
EDGE_STRETCH = 100.0
"""... and moved along the ray's trace on the surface at most EDGE_STRETCH x as far as
across it (a surface seen within 0.6° of grazing counts as seen at 0.6°)."""


LOOSE_SHARE = 0.3
"""A traced ray whose companion ran past the rule's largest step (Richardson outside its
asymptotic range; TileContext._bound) and whose estimate exceeds LOOSE_SHARE x the retrace
budget is traced again at half the step, its first run the companion (RETRACE's first
round): escaped rays of Schwarzschild and Kerr at the cap had errors at 2 h 40-50x those
at h, read as ~3x the truth, so an estimate above 0.3 of the tolerance may stand for a
truth above a tenth of it, where the error pass promises 3x (benchmarks/honesty.py
point_stars and disk_high_spin at 0.05 px: 88 % and 87 % within 3x -> 100 %). At 0.1 the
Kerr board took 1.4x as long (1080p Preview), at 0.3 1.02x."""


def budgets(ctx: TileContext, loose: np.ndarray) -> np.ndarray:
    """The errors above which nodes are traced again (retrace.retrace): the retrace
    budget, LOOSE_SHARE of it where their companion ran past the rule's range (``loose``:
    their Nodes.loose)."""
    return np.where(loose, LOOSE_SHARE * ctx.budget, ctx.budget)


def store(
    ctx: TileContext,
    nodes: Nodes,
    jj: np.ndarray,
    ii: np.ndarray,
    rays: RayResults,
    seen: np.ndarray,
    error: np.ndarray | None,
) -> None:
    """Record traced rays at the nodes (jj, ii) and judge them; ``error`` is the
    integration's."""
    record(ctx, nodes, jj, ii, rays, seen)
    judge(ctx, nodes, jj, ii, error, first=False)


def record(
    ctx: TileContext,
    nodes: Nodes,
    jj: np.ndarray,
    ii: np.ndarray,
    rays: RayResults,
    seen: np.ndarray,
) -> None:
    """Record traced rays at the nodes (jj, ii)."""
    nodes.traced[jj, ii] = True
    nodes.direction[jj, ii] = seen
    for kind in RAY_PASSES:  # ending, steps, position, redshift, magnification, ...
        getattr(nodes, kind.name)[jj, ii] = getattr(rays, kind.name)
    nodes.rgba[jj, ii] = ctx.shade(rays, ctx.background)
    nodes.energy[jj, ii] = rays.energy_error
    escaped = rays.ending == ENDING["escaped"]
    no_light = (rays.transmittance == 1.0) & ~np.any(rays.radiance, axis=1)
    hit = rays.ending == ENDING["hit"]
    nodes.plain[jj, ii] = (escaped | (rays.ending == ENDING["captured"]) | hit) & no_light
    nodes.clearance[jj, ii] = rays.clearance  # a hit's: from all but its object
    nodes.object_id[jj, ii] = rays.object_id
    nodes.kinks[jj, ii] = rays.kinks
    nodes.tangent[jj, ii] = rays.tangent
    nodes.surface[jj, ii] = rays.surface
    on_disk = np.flatnonzero(hit & (rays.object_id == DISK_ID))
    nodes.radius[jj, ii] = np.nan
    if nodes.jacobian.shape[2] == rays.sky_jacobian.shape[1]:
        nodes.jacobian[jj, ii] = rays.sky_jacobian
    if on_disk.size:
        radius = ctx.tracer.scene.disk_radius(rays.position[on_disk])
        nodes.radius[jj[on_disk], ii[on_disk]] = radius


def judge(
    ctx: TileContext,
    nodes: Nodes,
    jj: np.ndarray,
    ii: np.ndarray,
    error: np.ndarray | None,
    first: bool = True,
) -> None:
    """The recorded nodes (jj, ii)'s errors from their integration's (``error``, None:
    0): flips, near misses (traced again), near edges, the far field. ``first``: their
    first run's (at the tile's step), which nodes settled by them take (anchors.settle),
    not a retrace's."""
    err = np.zeros(jj.size) if error is None else error
    nodes.flipped[jj, ii] |= err >= FLIP  # once two runs ended apart, it stays a flip
    err = np.where(nodes.flipped[jj, ii], np.maximum(err, FLIP), err)
    nodes.integration[jj, ii] = err  # a flip is traced again (RETRACE), as a near miss
    if first:
        nodes.first[jj, ii] = err
    near_miss = nodes.clearance[jj, ii] < NEAR_MISS * err  # it may have hit something
    nodes.near[jj, ii] = near_miss  # traced again (retrace.retrace); a near edge is not: its
    # retrace, agreeing, would report it clear of the edge whatever the truth
    near_miss |= near_edge(ctx, nodes, jj, ii, err)  # it may have missed its object
    ending = nodes.ending[jj, ii]
    far = np.where(ending == ENDING["escaped"], ctx.far_field, 0.0)
    err = np.where(near_miss, np.maximum(err, FLIP), err + far)
    nodes.error[jj, ii] = np.where(ending == ENDING["failed"], np.inf, err)


def near_edge(
    ctx: TileContext, nodes: Nodes, jj: np.ndarray, ii: np.ndarray, err: np.ndarray
) -> np.ndarray:
    """(M,) which rays that hit an object pass within NEAR_MISS x their error of its
    edge (they may have missed it). The error, as seen from the camera at the hit's
    distance, is a move across the ray; on the surface (its tangent plane, from a cast
    through the hit point) that reaches as far across the ray and 1/|cos| as far along
    its trace (at most EDGE_STRETCH times: grazing). Segments along the hitting chord
    through the four points so moved, EDGE_REACH x their move long either side, must
    each meet the same object first."""
    ending = nodes.ending[jj, ii]
    rows = np.flatnonzero((ending == ENDING["hit"]) & (err > 0) & np.isfinite(err))
    out = np.zeros(ending.shape, dtype=bool)
    if rows.size == 0:
        return out
    origins, _ = ctx.camera.rays_at(ctx.image_xy(jj[rows] * 1.0, ii[rows] * 1.0))
    j, i = jj[rows], ii[rows]
    p, t, own = nodes.position[j, i], nodes.tangent[j, i], nodes.object_id[j, i]
    move = NEAR_MISS * err[rows] * np.linalg.norm(p - origins, axis=1)
    reach = (EDGE_REACH * move)[:, None] * t
    found = ctx.tracer.geometry.cast(p - reach, p + reach)
    n = found.normal
    cos = np.abs(np.einsum("ij,ij->i", n, t))
    side = np.cross(n, t)
    trace = t - np.einsum("ij,ij->i", t, n)[:, None] * n  # the ray on the surface
    lengths = [move, move * np.minimum(1.0 / np.maximum(cos, 1e-12), EDGE_STRETCH)]
    ways = []
    for direction, length in zip((side, trace), lengths, strict=True):
        norm = np.linalg.norm(direction, axis=1, keepdims=True)
        unit = np.where(norm > 0, direction / np.where(norm > 0, norm, 1.0), 0.0)
        ways += [length[:, None] * unit, -length[:, None] * unit]
    moved = np.concatenate([p + w for w in ways])
    along = np.concatenate([(EDGE_REACH * np.maximum(length, move))[:, None] * t
                            for length in lengths for _ in (0, 1)])  # fmt: skip
    hits = ctx.tracer.geometry.cast(moved - along, moved + along)
    same = (hits.hit & (hits.object_id == np.tile(own, 4))).reshape(4, -1).all(axis=0)
    out[rows] = ~(found.hit & (found.object_id == own) & same)
    return out

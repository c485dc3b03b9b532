"""Block acceptance: whether a block's nine traced rays let it be interpolated.

Offers ``accept`` (which blocks of a size are interpolated, with their deviations),
``deviations``, ``deviation_vectors`` and ``radius_deviations`` (how far a block's edge
midpoints and centre lie from its corners' interpolation: directions, hit points, the
disk's r, g and azimuth), ``error_shape`` (their weights in the interpolation's error at a
point), and ``CLEARANCE``, ``INTERPOLATION_SAFETY``, ``MAGNIFICATION_SHARE`` and ``EDGES``.
Needs a TileContext, the lattice, core.sampling.disk and core.sampling.error.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from ..tracing import ENDING
from ..tracing.scene import DISK_ID
from .context import TileContext
from .disk import disk_azimuth, opaque_disk, wrapped
from .error import angle_between, seen_apart
from .lattice import Nodes, block_points

CLEARANCE = 1.0
"""Blocks are interpolated only where each of their traced rays kept clear of every
object's bounds (a hit's: of every object but its own) by more than CLEARANCE x the
block's spread (its width as seen from the camera, times how much its rays spread apart
on the way: _magnification): every point of a block lies within half a block width of one
of its nine traced rays, so an object cannot reach an untraced ray there without passing
within that of a traced one."""
INTERPOLATION_SAFETY = 1.0
"""A block is interpolated only where its estimated interpolation error (_worst) is at most
the tolerance over this. The estimate is measured along both directions; summed as
lengths it bounds the error (on the interpolated pixels of the honesty benchmark's scenes
at 1, 0.25 and 0.05 px, benchmarks/honesty.py, estimate / truth was 0.95-1.1 at the 1st
percentile, 0.37 on the high-spin disk, whose r and g stand in for the hit point, and
1.1-4.1 at the 99th, the two directions' parts added up where they partly cancel: the
error pass reports their vector sum instead, deviation_vectors). 2.0 (the centre-only
rule's margin) kept the 3 sub-pixel star images of 561 that 1.0 lost at 1 px, for 8-20 %
more rays (Kerr board, 1080p Preview); the colour test (COLOUR_STEP) keeps them now, at
1.0, tracing only the centres near them."""
MAGNIFICATION_SHARE = 0.01
"""With the magnification pass, a sky block is interpolated only where ln |μ| is within
this of bilinear over it (_smooth_magnification): |μ| to ~1 %."""


def accept(
    ctx: TileContext, nodes: Nodes, bj: np.ndarray, bi: np.ndarray, s: int
) -> tuple[np.ndarray, ...]:
    """Which blocks (size s) are interpolated, their deviations (B, 5) (radians: its
    edges' midpoints' and the centre's excess; _edge_deviations) and those as vectors
    (B, 5, 3) (deviation_vectors): every one of a block's
    nine traced rays ends alike (escaped, captured, or on one object), having crossed
    the same kinks of the model (RayResults.kinks: the image's map has a kink between
    rays that crossed different ones, which the midpoints' deviations, made for a smooth
    map, under-read: a fish-eye's edge at n's kink, 1-2 px off estimated 1/15 of it)."""
    nine = block_points(bj, bi, s)
    corners, (cj, ci) = nine[:4], nine[8]
    alike = nodes.plain[cj, ci].copy()
    ending, object_id = nodes.ending[cj, ci], nodes.object_id[cj, ci]
    alike &= (object_id != DISK_ID) | opaque_disk(ctx)
    width = s * ctx.pixel_angle  # the block's width, radians
    clear = CLEARANCE * width * _magnification(nodes, corners, width)
    for j, i in nine:  # no (other) object in between
        alike &= nodes.plain[j, i] & (nodes.ending[j, i] == ending)
        alike &= (nodes.object_id[j, i] == object_id) & (nodes.clearance[j, i] > clear)
        alike &= nodes.kinks[j, i] == nodes.kinks[cj, ci]  # no kink of the map between
    deviation = deviations(ctx, nodes, nine, ending)
    vectors = deviation_vectors(ctx, nodes, nine, ending)
    disk = np.flatnonzero(alike & (object_id == DISK_ID))
    if disk.size:  # what the disk interpolates is its radius (and g): no texture
        on_disk = [(j[disk], i[disk]) for j, i in nine]
        deviation[disk] = radius_deviations(ctx, nodes, on_disk, width)
        vectors[disk] = np.nan  # r and g: their magnitudes stand
    worst = _worst(deviation)
    accepted = alike & (INTERPOLATION_SAFETY * worst <= ctx.interpolation)
    if ctx.with_magnification:
        accepted &= _smooth_magnification(nodes, nine, ending)
    return accepted, deviation, vectors


def deviation_vectors(
    ctx: TileContext, nodes: Nodes, nine: list[tuple[np.ndarray, np.ndarray]], ending: np.ndarray
) -> np.ndarray:
    """(B, 5, 3) the deviations of deviations as vectors (radians: a direction's
    difference, or a hit point's over its distance from the camera), the centre's excess
    being the centre's deviation less half the edges' sum (0 for a quadratic map): the
    bilinear interpolation's error at (u, v) is their sum weighted by error_shape, whose
    length the error pass reports (the sum of their lengths, what acceptance bounds,
    adds up parts that cancel: a lens map's x and y curvatures, opposite where its
    deflection is harmonic, made it 3-3.5x the truth)."""
    hit = (ending == ENDING["hit"])[:, None]
    j8, i8 = nine[8]
    origins, _ = ctx.camera.rays_at(ctx.image_xy(j8, i8))
    scale = np.linalg.norm(nodes.position[j8, i8] - origins, axis=1, keepdims=True)
    with np.errstate(all="ignore"):
        seen = [np.where(hit, nodes.position[j, i] / scale, nodes.direction[j, i])
                for j, i in nine]  # fmt: skip

    def apart(k, ends):
        return seen[k] - sum(seen[e] for e in ends) / len(ends)

    edges = [apart(k, ends) for k, ends in EDGES]
    beyond = apart(8, (0, 1, 2, 3)) - 0.5 * sum(edges)
    vectors = np.stack([*edges, beyond], axis=1)
    return np.where((ending == ENDING["captured"])[:, None, None], 0.0, vectors)


def deviations(
    ctx: TileContext, nodes: Nodes, nine: list[tuple[np.ndarray, np.ndarray]], ending: np.ndarray
) -> np.ndarray:
    """(B, 5) radians: how far the edges' midpoints lie from their ends' mean and the
    centre from its corners' beyond what those make (_edge_deviations), in what a block
    interpolates: directions for the sky, hit points (over the pixel footprint there)
    for hits."""

    def apart(k, ends):
        (j, i), others = nine[k], [nine[e] for e in ends]
        mean = sum(nodes.direction[a, b] for a, b in others)
        at = sum(nodes.position[a, b] for a, b in others) / len(others)
        origins, _ = ctx.camera.rays_at(ctx.image_xy(j, i))
        return seen_apart(nodes.direction[j, i], nodes.position[j, i], mean, at, ending,
                          origins)  # fmt: skip

    deviation = _edge_deviations(apart)
    return np.where((ending == ENDING["captured"])[:, None], 0.0, deviation)


def radius_deviations(
    ctx: TileContext, nodes: Nodes, nine: list[tuple[np.ndarray, np.ndarray]], width: float
) -> np.ndarray:
    """deviations for blocks on the disk: of its radius r, redshift g and azimuth
    (the hit point pass's place on it), each as the angle the block's own gradient of
    it (its corners' spread over ``width``) takes to make that much (the disk pixel
    shows what a ray that far off shows; NaN: refused), and r's and the azimuth's as
    the move on the disk they make over its distance from the camera, where that is
    more (a hit's error, docs/design.md: on a disk seen near edge-on a move in r is
    foreshortened on screen; the Kerr board's disk, seen from 2 rg above its plane,
    had interpolated pixels 0.44 px off at a median estimate half that)."""
    worst = np.zeros(nine[0][0].shape + (5,))
    light = ctx.tracer.disk
    assert light is not None  # only blocks on the disk come here
    azimuth = [disk_azimuth(ctx, nodes.position[j, i]) for j, i in nine]
    azimuth = [azimuth[8] + wrapped(a - azimuth[8]) for a in azimuth]
    radius = [nodes.radius[j, i] for j, i in nine]
    distance = [np.linalg.norm(nodes.position[j, i] - ctx.camera.rays_at(
        ctx.image_xy(j, i))[0], axis=1) for j, i in nine]  # fmt: skip
    moves = (
        [1.0 / d for d in distance],  # per unit of r (in the plane: at most 1)
        [np.zeros(d.shape) for d in distance],  # g moves nothing
        [np.hypot(r, light.disk.spin) / d for r, d in zip(radius, distance, strict=True)],
    )
    for values, move in zip(
        (radius, [nodes.redshift[j, i] for j, i in nine], azimuth), moves, strict=True
    ):
        corners = np.stack(values[:4])
        spread = corners.max(axis=0) - corners.min(axis=0)

        def apart(k, ends, values=values, spread=spread, move=move):
            off = np.abs(values[k] - sum(values[e] for e in ends) / len(ends))
            with np.errstate(invalid="ignore", divide="ignore"):
                angle = np.where(off == 0, 0.0, np.maximum(off * width / spread,
                                                           off * move[k]))  # fmt: skip
            return np.where(np.isfinite(angle), angle, np.inf)

        worst = np.maximum(worst, _edge_deviations(apart))
    return worst


EDGES = ((4, (0, 1)), (5, (2, 3)), (6, (0, 2)), (7, (1, 3)))
"""block_points' edge midpoints with their edges' ends: top, bottom (along x), left, right."""


def _edge_deviations(apart: Callable) -> np.ndarray:
    """(B, 5) from ``apart(k, ends)`` (block_points' point k's deviation from the mean of
    points ``ends``, (B,)): the top, bottom, left and right edges' midpoints', and the
    centre's beyond what those make there (a quadratic map's is at most the mean of the two
    edges along x plus that of the two along y: more is a higher order)."""
    top, bottom, left, right = (apart(k, ends) for k, ends in EDGES)
    expected = 0.5 * (top + bottom + left + right)
    beyond = np.maximum(apart(8, (0, 1, 2, 3)) - expected, 0.0)
    return np.stack([top, bottom, left, right, beyond], axis=-1)


def error_shape(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(M, 5) weights of a block's deviations (_edge_deviations) in its bilinear
    interpolation's error at block coordinates (u, v): along x, 4 u (1 - u) times the top
    and bottom edges' blended by v; along y, 4 v (1 - v) times the left and right edges'
    blended by u; the centre's excess, 16 u (1 - u) v (1 - v)."""
    across, down = 4 * u * (1 - u), 4 * v * (1 - v)
    return np.stack([across * (1 - v), across * v, down * (1 - u), down * u, across * down], axis=1)


def _worst(deviation: np.ndarray) -> np.ndarray:
    """(B,) a bound on a block's interpolation error from its deviations (B, 5): the larger
    edge along x, plus the larger along y, plus the centre's excess."""
    top, bottom, left, right, beyond = np.moveaxis(deviation, -1, 0)
    return np.maximum(top, bottom) + np.maximum(left, right) + beyond


def _smooth_magnification(
    nodes: Nodes, nine: list[tuple[np.ndarray, np.ndarray]], ending: np.ndarray
) -> np.ndarray:
    """(B,) blocks whose magnification pass may be interpolated (the nodes' ray differentials
    blended): not on the sky, or ln |μ| within MAGNIFICATION_SHARE of bilinear (the
    deviations of _edge_deviations, bounded as by _worst)."""
    with np.errstate(all="ignore"):
        values = [np.log(nodes.magnification[j, i]) for j, i in nine]

    def apart(k, ends):
        return np.abs(values[k] - sum(values[e] for e in ends) / len(ends))

    worst = _worst(_edge_deviations(apart))
    return (ending != ENDING["escaped"]) | (worst <= MAGNIFICATION_SHARE)


def _magnification(
    nodes: Nodes, corners: list[tuple[np.ndarray, np.ndarray]], width: float
) -> np.ndarray:
    """(B,) how much wider than at the camera a block's rays spread at their ends (at
    least 1): the largest angle between its corners' final directions over their angle
    at the camera (``width`` radians along an edge, width sqrt 2 across); the bundle's
    spread on the way stays within the larger of the two (NaN: 1)."""
    (a, b, c, d) = (nodes.direction[j, i] for j, i in corners)
    edges = [angle_between(a, b), angle_between(c, d), angle_between(a, c), angle_between(b, d)]
    diagonals = [angle_between(a, d), angle_between(b, c)]
    ratio = np.maximum(np.max(edges, axis=0), np.max(diagonals, axis=0) / math.sqrt(2))
    return np.maximum(np.nan_to_num(ratio / width, nan=0.0), 1.0)

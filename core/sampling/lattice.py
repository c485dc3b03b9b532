"""A tile's lattice: its nodes, its accepted blocks, and the clearance margins nodes record.

Offers ``Nodes`` (what is known at each node of a tile's lattice), ``Blocks`` (the accepted
blocks and the block covering each cell), ``block_points`` (a block's nine traced nodes),
``node_margin`` and ``dense_margin`` (the share of the tracer's clearance margin a node
records its clearance within), ``node_rays`` (a node's recorded ray, for a companion's
comparison), and ``STRIDE``, ``MARGIN_BLOCKS`` and ``DENSE_MARGIN``. ``STRIDE`` is read
here at each call (patch it here: core.render and the sampler read it from this module).
Needs core.tracing's RayResults.
"""

from __future__ import annotations

import numpy as np

from ..passes import STORED
from ..tracing import RayResults

STRIDE = 32
"""Pixels per side of the coarsest interpolation block."""
MARGIN_BLOCKS = 2.0
"""A node records its clearance within MARGIN_BLOCKS x the largest block it may be
interpolated in (node_margin; a block is accepted where its rays keep clear by its width
times the sky's magnification over it: twice leaves room for a magnification of 2, the
coarsest block's margin (core.render._watch_margin) bounds it anyway)."""
DENSE_MARGIN = 2.0
"""Nodes traced densely record their clearance within DENSE_MARGIN pixels of the objects
(at the farthest box, as the blocks' margin: core.render._watch_margin), not a coarsest
block's: what they need it for is a near miss (NEAR_MISS x their error) and a traced
pixel's footprint (supersample.supersample). Dense: every node of a block refused at FINEST, every
node where nothing is interpolated, and every retrace (blocks are chosen by then); a
clearance watched 32 pixels wide was 45 % of thin_front's time at 96 x 54."""


RAY_PASSES = tuple(kind for kind in STORED if kind.per_ray)
"""The passes a node holds as its ray's own field (core.passes' ``per_ray``: ending, steps,
position, redshift, magnification, transmittance): Nodes makes an array for each, and
judging.record copies the ray's."""


class Nodes:
    """The lattice of a tile: what is known at each node (traced or not). Besides the
    arrays below, one per RAY_PASSES entry, by its name (``nodes.ending``, ``nodes.steps``,
    ``nodes.position``, ...)."""

    def __init__(self, ny: int, nx: int, tangents: bool = False) -> None:
        shape = (ny, nx)
        self.passes = {  # RAY_PASSES' arrays, their fill where not traced (position NaN)
            kind.name: np.full(shape + kind.empty(0).shape[1:], kind.fill, kind.working_dtype)
            for kind in RAY_PASSES
        }
        self.traced = np.zeros(shape, dtype=bool)
        self.direction = np.zeros(shape + (3,))
        self.rgba = np.zeros(shape + (4,))
        self.error = np.zeros(shape)
        self.energy = np.zeros(shape)
        self.plain = np.zeros(shape, dtype=bool)  # ended without volume light
        self.clearance = np.zeros(shape)  # radians from geometry (RayResults.clearance)
        self.integration = np.zeros(shape)  # the integration's error estimate (radians)
        self.first = np.zeros(shape)  # ... of its first run, at the tile's step (settle's)
        self.halvings = np.zeros(shape, dtype=np.int64)  # its run's step: the first's / 2^this
        self.object_id = np.full(shape, -1, dtype=np.int32)
        self.kinks = np.zeros(shape, dtype=np.int64)  # the model's kinks its ray crossed
        self.tangent = np.zeros(shape + (3,))  # the hitting chords' directions
        self.surface = np.zeros(shape + (4,))  # the surface's colour where hit
        self.radius = np.full(shape, np.nan)  # Boyer–Lindquist r of a hit on the disk
        self.flipped = np.zeros(shape, dtype=bool)  # two of its runs ended on different things
        self.near = np.zeros(shape, dtype=bool)  # missed an object by under NEAR_MISS x its error
        self.loose = np.zeros(shape, dtype=bool)  # its companion ran past the rule's range
        self.pending = np.zeros(
            shape, dtype=bool
        )  # traced, its error not judged yet (anchors.settle)
        # d(direction) / d(image x, y) where it sees the sky (RayResults.sky_jacobian)
        self.jacobian = np.full(shape + ((2, 3) if tangents else (0, 3)), np.nan)

    def __getattr__(self, name: str) -> np.ndarray:
        try:
            return self.__dict__["passes"][name]
        except KeyError:
            raise AttributeError(name) from None


class Blocks:
    """Accepted blocks and, per lattice cell, the accepted block covering it (-1: none)."""

    def __init__(self, ny: int, nx: int) -> None:
        self.block = np.full((ny, nx), -1, dtype=np.int64)
        self.j = np.zeros(0, dtype=np.int64)
        self.i = np.zeros(0, dtype=np.int64)
        self.size = np.zeros(0, dtype=np.int64)
        self.deviation = np.zeros((0, 5))
        self.vectors = np.zeros((0, 5, 3))

    def add(
        self, bj: np.ndarray, bi: np.ndarray, s: int, deviation: np.ndarray, vectors: np.ndarray
    ) -> None:
        """Record accepted blocks of size s at (bj, bi) with their deviations (B, 5), as
        vectors (B, 5, 3) (NaN: none), and mark their cells."""
        first = self.j.size
        self.j = np.concatenate([self.j, bj])
        self.i = np.concatenate([self.i, bi])
        self.size = np.concatenate([self.size, np.full(bj.size, s)])
        self.deviation = np.concatenate([self.deviation, deviation])
        self.vectors = np.concatenate([self.vectors, vectors])
        dj, di = (a.ravel() for a in np.mgrid[0:s, 0:s])
        ids = np.arange(first, first + bj.size)
        self.block[(bj[:, None] + dj).ravel(), (bi[:, None] + di).ravel()] = np.repeat(ids, s * s)


def block_points(bj: np.ndarray, bi: np.ndarray, s: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """The nine traced nodes of blocks of size s at (bj, bi): corners (top left, top right,
    bottom left, bottom right), the edges' midpoints (top, bottom, left, right), the centre."""
    h = s // 2
    return [(bj, bi), (bj, bi + s), (bj + s, bi), (bj + s, bi + s),
            (bj, bi + h), (bj + s, bi + h), (bj + h, bi), (bj + h, bi + s),
            (bj + h, bi + h)]  # fmt: skip


def node_margin(jj: np.ndarray, ii: np.ndarray, dense: bool) -> np.ndarray | float:
    """The share of the tracer's clearance margin (a coarsest block's) nodes (jj, ii)
    record theirs within: MARGIN_BLOCKS x the largest block they are one of the nine
    points of (blocks of s start at multiples of s: a node at multiples of p is a point of
    blocks of 2 p), DENSE_MARGIN pixels where no block will interpolate them (``dense``)."""
    if dense:
        return dense_margin()
    lattice = jj | ii | (STRIDE // 2)
    block = 2 * (lattice & -lattice)  # the lowest bit both share, at most STRIDE / 2
    return np.minimum(1.0, MARGIN_BLOCKS * np.maximum(block, DENSE_MARGIN) / STRIDE)


def dense_margin() -> float:
    """The share of the tracer's clearance margin nodes traced densely record theirs within
    (DENSE_MARGIN pixels: node_margin's ``dense``)."""
    return DENSE_MARGIN / STRIDE


def node_rays(nodes: Nodes, jj: np.ndarray, ii: np.ndarray, origins: np.ndarray) -> RayResults:
    """The rays recorded at nodes (jj, ii) from ``origins``, as far as
    TileContext.companion_error reads them (what they see, ending, object, steps)."""
    rays = RayResults.empty(jj.size, origins, nodes.direction[jj, ii])
    rays.ending, rays.object_id = nodes.ending[jj, ii], nodes.object_id[jj, ii]
    rays.position, rays.steps = nodes.position[jj, ii], nodes.steps[jj, ii]
    return rays

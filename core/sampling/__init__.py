"""Adaptive image sampling: rays where the image needs them, anti-aliasing by sub-pixel samples.

An image is rendered in tiles (core.render's bands of whole rows; ``tiles``), each a unit
of work. A tile is covered by a lattice of *nodes* at pixel centres, one pixel beyond the
tile on every side (filter footprints reach up to a pixel past a pixel's centre), and
rounded up to whole blocks of ``STRIDE`` nodes; blocks reaching the tile are refined as a
quadtree: a block's four corners, its edges' midpoints and its centre are traced; the
block is *accepted* when

- all nine rays escaped, each kept clear of every object's own bounds, along every chord
  of its path, by more than ``CLEARANCE`` x the block's spread (``Tracer.watch_geometry``,
  core/tracing/clearance.py), none crossed a volume, and their final directions differ
  from the block's bilinear interpolation by at most the interpolation tolerance (as
  below): the block's directions are then
  interpolated (bilinear, normalised) and each point is shaded from the background in its
  interpolated direction, so the sky's own detail is kept; or
- all nine hit the same object and their hit points are within the tolerance of the
  corners' interpolation (the distance over the pixel footprint there: what the renderer
  interpolates is the hit point): each point's hit point and chord direction are
  interpolated and cast again against the scene (its texture is kept); a point whose
  segment misses the object (an edge) is traced. On an opaque accretion disk (no texture)
  what is interpolated is its radius r and redshift g, each tested like a direction: a
  point's deviation from the interpolation, as the angle the block's own gradient of r
  (of g, of the azimuth) needs to make it, within the tolerance; each point shows the
  disk's light at its interpolated r and g (off the disk's radii: traced), its hit point
  at the interpolated r and azimuth; or
- all nine were captured, kept clear of geometry as above (the shadow's inside, black).

Otherwise it splits into four, down to ``FINEST``, where every pixel of a refused block is
traced. Besides its corners and centre, a block's four edge midpoints are traced (the
corners of its quarters, were it split): a midpoint's deviation from its edge's ends
measures the map's second derivative along that edge, the centre's alone only their sum
(which cancels for a lens map, whose deflection is a potential's gradient: a harmonic
field). For a quadratic map, at block coordinates (u, v) in [0, 1]^2 the bilinear error is
4 u (1 - u) d_x + 4 v (1 - v) d_y, d_x a midpoint's deviation along x (the top and bottom
edges' blended by v), d_y along y (left and right, blended by u); what the centre deviates
beyond that is a higher order, added as 16 u (1 - u) v (1 - v) d_c (acceptance.error_shape). A
block is accepted when that estimate's largest value, times INTERPOLATION_SAFETY, is within
the tolerance; the error pass reports the same sum taken over the deviations as vectors
(its length, acceptance.deviation_vectors: a lens map's curvatures along x and y partly cancel).
Interpolation never crosses an ending change: a block is accepted only when all nine rays
end the same way (the same object, for hits).

Anti-aliasing (``samples`` > 1): a pixel whose colour differs from a neighbour's by more
than ``AA_CONTRAST`` (or whose ending does) gets up to ``samples`` points spread over its
filter footprint (one in each cell of a k x k grid, k = ceil(sqrt(samples)), jittered
within it differently in every pixel, farthest-first; ``FIRST_SAMPLES`` first, the rest
where those disagree), and so does, with all its samples, a traced pixel whose ray passed
an object within the footprint (a thin strip or a small sphere between the samples); each
point is shaded by interpolation inside an accepted block or by a traced ray elsewhere;
its colour is their mean (box over the pixel, or Blackman-Harris of width ``filter_size`` as
in Cycles, importance-sampled: filter_samples), with the centre's colour as one more sample
where none shows it. Other pixels keep their centre's colour.

Cost (issue 48): a round of tracing is counted as ROUND_RAYS rays (its per-step overhead);
the coarse levels are traced in one first round where that pays (quadtree.first_lattice), a
tile's refused blocks at once where refining them would not (quadtree.dense_pays), and the
error pass's companions run at the roots (ROOT) and where a node's cell's corners (the
roots for an anchor, ANCHOR, the anchors for the others) cannot speak for it
(anchors.settle).

The package's modules, one subject each (each one's docstring states what it offers and
needs); the steps of a tile are functions of a ``TileContext`` (the sampler's settings and
the tile's state), which ``TileSampler`` is:

- ``tiling``: Tile, tiles, TileResult: an image's units of work.
- ``filters``: pixel filters, sub-pixel sample offsets, stratified points.
- ``error``: Richardson error from a companion run; what a ray sees, how far apart.
- ``lattice``: a tile's nodes, its accepted blocks, the clearance margins nodes record.
- ``context``: TileContext: settings, the tile's origin and ray counts, tracing points.
- ``judging``: recording traced nodes; their errors: flips, near misses, near edges.
- ``anchors``: tracing nodes, their companions at the roots (and ``settle``).
- ``retrace``: rays over their error budget, and near misses, traced again.
- ``disk``: the opaque accretion disk's interpolation (radius, g, azimuth).
- ``acceptance``: which blocks are interpolated: their deviations, clearance, kinks.
- ``quadtree``: refining blocks level by level; what a round of tracing costs.
- ``interpolation``: lattice points evaluated: a node's own or its block's blend.
- ``shaky``: the colour test: interpolated centres whose colour could change.
- ``footprints``: the sky and surfaces at pixel centres filtered over each pixel.
- ``supersample``: anti-aliasing: samples of pixels whose neighbours differ.
- ``sampler``: TileSampler: a tile rendered by the steps above.

Constants live in the module that reads them; they are re-exported here to be read, but a
test that changes one patches its module: ``lattice.STRIDE``, ``quadtree.ROUND_RAYS`` (both
read by core.render from there too), ``supersample.SAMPLE_POINTS``, ``shaky.COLOUR_STEP``,
``anchors.ANCHOR``, ``anchors.ROOT``.
"""

from __future__ import annotations

from .acceptance import (
    CLEARANCE,
    EDGES,
    INTERPOLATION_SAFETY,
    MAGNIFICATION_SHARE,
    error_shape,
)
from .acceptance import _edge_deviations as _edge_deviations
from .acceptance import _worst as _worst
from .anchors import ANCHOR, ROOT
from .context import TileContext
from .error import (
    COMPANION_RATIO,
    DOUBT_BELOW,
    DOUBTED,
    FLIP,
    HIT_ORDER,
    SHARED_STEPS,
    angle_between,
    richardson_error,
    seen_apart,
    seen_direction,
    shared_steps,
)
from .filters import (
    BLACKMAN_HARRIS,
    FILTERS,
    PIXEL_STRIDE,
    R2,
    filter_samples,
    pixel_samples,
    sample_offsets,
    stratified_points,
)
from .interpolation import INTERPOLATE_POINTS, REACH
from .judging import EDGE_REACH, EDGE_STRETCH, LOOSE_SHARE, NEAR_MISS
from .lattice import DENSE_MARGIN, MARGIN_BLOCKS, STRIDE
from .quadtree import FINEST, ROUND_RAYS
from .retrace import RETRACE
from .sampler import TileSampler
from .shaky import COLOUR_STEP, neighbour_change
from .supersample import AA_CONTRAST, FIRST_SAMPLES, SAMPLE_POINTS
from .tiling import MAX_TILE_PIXELS, TILE, Tile, TileResult, tiles

_error_shape = error_shape  # the names tests read
_neighbour_change = neighbour_change

__all__ = [
    "AA_CONTRAST",
    "ANCHOR",
    "ROOT",
    "BLACKMAN_HARRIS",
    "CLEARANCE",
    "COLOUR_STEP",
    "COMPANION_RATIO",
    "DENSE_MARGIN",
    "DOUBTED",
    "DOUBT_BELOW",
    "EDGES",
    "EDGE_REACH",
    "EDGE_STRETCH",
    "FILTERS",
    "FINEST",
    "FIRST_SAMPLES",
    "FLIP",
    "HIT_ORDER",
    "INTERPOLATE_POINTS",
    "INTERPOLATION_SAFETY",
    "LOOSE_SHARE",
    "MAGNIFICATION_SHARE",
    "MARGIN_BLOCKS",
    "MAX_TILE_PIXELS",
    "NEAR_MISS",
    "PIXEL_STRIDE",
    "R2",
    "REACH",
    "RETRACE",
    "ROUND_RAYS",
    "SAMPLE_POINTS",
    "SHARED_STEPS",
    "STRIDE",
    "TILE",
    "Tile",
    "TileContext",
    "TileResult",
    "TileSampler",
    "angle_between",
    "filter_samples",
    "pixel_samples",
    "richardson_error",
    "sample_offsets",
    "seen_apart",
    "seen_direction",
    "shared_steps",
    "stratified_points",
    "tiles",
]

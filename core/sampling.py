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
beyond that is a higher order, added as 16 u (1 - u) v (1 - v) d_c (_error_shape). A
block is accepted when that estimate's largest value, times INTERPOLATION_SAFETY, is within
the tolerance; the error pass reports the same sum taken over the deviations as vectors
(its length, _deviation_vectors: a lens map's curvatures along x and y partly cancel).
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
the coarse levels are traced in one first round where that pays (_first_lattice), a tile's
refused blocks at once where refining them would not (_dense_pays), and the error pass's
companions run at the anchors (ANCHOR) and where the anchors cannot speak for a node
(TileSampler._settle).
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .geometry import Hits
from .mipmap import map_footprint, screen_differences
from .motion import shift as doppler_shift
from .passes import BY_NAME
from .sky import Background
from .tracing import ENDING, RayResults, Tracer
from .tracing.differentials import magnification
from .tracing.scene import DISK_ID
from .tracing.segments import surface_colours

TILE = 512
"""``tiles``' default: squares of TILE - 1 pixels (core.render makes bands instead)."""
STRIDE = 32
"""Pixels per side of the coarsest interpolation block."""
MAX_TILE_PIXELS = 1 << 19
"""core.render's tiles are bands of rows of at most this many pixels (memory: ~0.8 kB a
tile pixel at the peak, lattice and temporaries; ~400 MiB a worker, measured)."""
MAGNIFICATION_SHARE = 0.01
"""With the magnification pass, a sky block is interpolated only where ln |μ| is within
this of bilinear over it (_smooth_magnification): |μ| to ~1 %."""
FINEST = 4
"""Pixels per side of the finest block tried: every pixel of a block refused at this size
is traced (one round instead of two more: each round costs a batch's per-step overhead)."""
ROUND_RAYS = 1500
"""What one round of tracing (a batch) costs beyond its rays, in rays: each step of a
batch pays numpy's per-call overhead whatever its size (measured at 160 x 120, one
worker: a round of 65 rays took as long as 1500-3700 more rays of a large one, thin_front
and stars). _refine weighs rounds against rays with it: how far down the quadtree the
first round traces at once (_first_lattice), and where tracing every remaining node of a
tile's refused blocks in one round costs less than refining them (_refine). A constant,
not a timing: the same scene gives the same image on any machine."""
MARGIN_BLOCKS = 2.0
"""A node records its clearance within MARGIN_BLOCKS x the largest block it may be
interpolated in (_node_margin; a block is accepted where its rays keep clear by its width
times the sky's magnification over it: twice leaves room for a magnification of 2, the
coarsest block's margin (core.render._watch_margin) bounds it anyway)."""
DENSE_MARGIN = 2.0
"""Nodes traced densely record their clearance within DENSE_MARGIN pixels of the objects
(at the farthest box, as the blocks' margin: core.render._watch_margin), not a coarsest
block's: what they need it for is a near miss (NEAR_MISS x their error) and a traced
pixel's footprint (_supersample). Dense: every node of a block refused at FINEST, every
node where nothing is interpolated, and every retrace (blocks are chosen by then); a
clearance watched 32 pixels wide was 45 % of thin_front's time at 96 x 54."""
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
INTERPOLATE_POINTS = 1 << 15
"""Points are interpolated this many at a time: their temporaries stay in the cache and
the allocator's reused memory (a 1080p tile's ~480 000 centres at once: the Kerr board's
Preview frame 9.45-9.67 s against 8.51-8.53 s, 2 workers)."""
FILTERS = ("box", "blackman_harris")
"""Reconstruction filters: the pixel's square, or Cycles' default (width ``filter_size``)."""
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
error pass reports their vector sum instead, _deviation_vectors). 2.0 (the centre-only
rule's margin) kept the 3 sub-pixel star images of 561 that 1.0 lost at 1 px, for 8-20 %
more rays (Kerr board, 1080p Preview); the colour test (COLOUR_STEP) keeps them now, at
1.0, tracing only the centres near them."""
LOOSE_SHARE = 0.3
"""A traced ray whose companion ran past the rule's largest step (Richardson outside its
asymptotic range; TileSampler._bound) and whose estimate exceeds LOOSE_SHARE x the retrace
budget is traced again at half the step, its first run the companion (RETRACE's first
round): escaped rays of Schwarzschild and Kerr at the cap had errors at 2 h 40-50x those
at h, read as ~3x the truth, so an estimate above 0.3 of the tolerance may stand for a
truth above a tenth of it, where the error pass promises 3x (benchmarks/honesty.py
point_stars and disk_high_spin at 0.05 px: 88 % and 87 % within 3x -> 100 %). At 0.1 the
Kerr board took 1.4x as long (1080p Preview), at 0.3 1.02x."""
COLOUR_STEP = 0.05
"""An interpolated pixel centre is traced where its colour could change by more than
COLOUR_STEP in a channel over its own error estimate (TileSampler._shaky): where the
largest difference from its four neighbours' colours (a pixel apart), times its error in
pixels, exceeds it, and what it shows (the sky; a surface, cast again) changes by more when
looked up moved by its error across x and y, either way. A checker's edge moved by ~0.2
px, under the 1 px tolerance, changed the colour of the centres it passed by more than 0.1
(benchmarks/honesty.py: 1.5 % of near_tangent's pixels at 1 px, 0.3 % of
schwarzschild's). The neighbour test alone traced every centre beside a checker's edge
(+21 % rays on the Kerr board at 960 x 540; +4 % with both). Half the 0.1 the benchmark
counts: an estimate within 3x of the truth, on a filtered edge (change in proportion to
the move), rarely under-reads a change of 0.1 by more. Where the sky's detail is smaller
than a pixel (Background.detail), which neighbours need not show (a star between centres),
every interpolated sky centre is looked up moved (3 sub-pixel star images of 561 were lost
at 1 px on the benchmark's stars scene, none now). A detail wider than a pixel spans a
neighbour: the Kerr board at 960 x 540 (stars 2.4 px across) spent 9 % of its time on
these lookups for 114 more rays of 120 000 when they were taken below 3 px."""
REACH = 4.0
"""An interpolated hit point is cast again along its interpolated chord direction, REACH
block widths (at its distance from the camera) either side: the surface is found even where
the bilinear point lies off a curved surface."""
RETRACE = 3
"""With ``tolerance_px``, a traced ray whose estimated error exceeds its budget is traced
again at half the step, up to RETRACE times: rays magnified near the photon ring (whose
forward error the step rule, made for the initial direction's, does not bound) still meet
the tolerance, at the cost of those rays only."""
FLIP = math.pi
"""The error (radians) of a pixel whose runs at two steps ended on different things (sky,
shadow, another object): what it shows may be wrong whatever its last runs agree on (its
ray passes within the integration's error of an edge); it keeps this error."""
NEAR_MISS = 2.0
"""A traced ray that missed every object by less than NEAR_MISS x its integration error
(its clearance, in radians like the error: from its cubic path less its hit test's slack,
core/tracing/clearance.py) may have hit one: it reports a flip (FLIP) and is traced again
(RETRACE)."""
SHARED_STEPS = 0.75
"""A companion run taking at least this share of the checked run's steps (not about
1 / COMPANION_RATIO of them) took the same steps for part of its way (shared_steps)."""
DOUBTED, DOUBT_BELOW = 2.0, 1e-5
"""... and whose estimate is below DOUBT_BELOW x the retrace budget (runs that shared their
steps agree to rounding: 1e-8 of the budget measured; at 1e-2 more rays go, +34 % steps on
a Kerr disk frame against +13 % here, for Schwarzschild's ring's rays too) has it raised to
DOUBTED x the budget:
the ray is traced again at half the step (RETRACE), where the runs part, and that run's
estimate, against this one, is taken as it is."""
EDGE_REACH = 4.0
"""A hit moved on its surface to test for the surface's edge (TileSampler._near_edge) is
looked for EDGE_REACH x the move along its chord either side (a curved surface curves away
from its tangent plane)."""
EDGE_STRETCH = 100.0
"""... and moved along the ray's trace on the surface at most EDGE_STRETCH x as far as
across it (a surface seen within 0.6° of grazing counts as seen at 0.6°)."""
COMPANION_RATIO = 2.0
"""The error pass traces each camera ray again at COMPANION_RATIO x the step: for a method
of order p the ray's error is |d_h - d_rh| / (r^p - 1) (Richardson); 1 / r of the cost."""


@dataclass(frozen=True)
class Tile:
    """A rectangle of pixels [x0, x1) x [y0, y1) (row 0 at the top)."""

    x0: int
    y0: int
    x1: int
    y1: int

    @property
    def shape(self) -> tuple[int, int]:
        """(height, width) of the tile in pixels."""
        return self.y1 - self.y0, self.x1 - self.x0


def tiles(width: int, height: int, size: int | None = None, rows: int | None = None) -> list[Tile]:
    """The tiles covering a width x height image, ``size`` pixels wide (default TILE - 1)
    and ``rows`` high (default: as wide), row by row from the top."""
    size = size or TILE - 1
    rows = rows or size
    return [
        Tile(x, y, min(x + size, width), min(y + rows, height))
        for y in range(0, height, rows)
        for x in range(0, width, size)
    ]


def sample_offsets(unit: np.ndarray, pixel_filter: str, filter_size: float) -> tuple:
    """Sub-pixel offsets (..., 2) from the pixel centre of points ``unit`` (..., 2) in the
    unit square, and their filter weights (...): the pixel's square (box) or the filter's
    footprint (Blackman-Harris of width ``filter_size``)."""
    if pixel_filter == "box":
        return unit - 0.5, np.ones(unit.shape[:-1])
    offsets = (unit - 0.5) * filter_size
    a0, a1, a2, a3 = BLACKMAN_HARRIS
    window = a0 - a1 * np.cos(2 * np.pi * unit) + a2 * np.cos(4 * np.pi * unit)
    window -= a3 * np.cos(6 * np.pi * unit)
    return offsets, np.prod(window, axis=-1)


BLACKMAN_HARRIS = (0.35875, 0.48829, 0.14128, 0.01168)
"""The Blackman-Harris window's cosine coefficients (sample_offsets)."""


def _window_inverse(count: int = 4097) -> tuple[np.ndarray, np.ndarray]:
    """(cdf, t): the Blackman-Harris window's cumulative share on [0, 1] at ``count`` points
    (closed form), for its inverse by interpolation (filter_samples)."""
    a0, a1, a2, a3 = BLACKMAN_HARRIS
    t = np.linspace(0.0, 1.0, count)
    cdf = (
        a0 * t
        - a1 * np.sin(2 * np.pi * t) / (2 * np.pi)
        + a2 * np.sin(4 * np.pi * t) / (4 * np.pi)
        - a3 * np.sin(6 * np.pi * t) / (6 * np.pi)
    )
    return cdf / cdf[-1], t


_WINDOW_CDF, _WINDOW_T = _window_inverse()


def filter_samples(unit: np.ndarray, pixel_filter: str, filter_size: float) -> tuple:
    """Sub-pixel offsets (..., 2) from the pixel centre of anti-aliasing samples ``unit``
    (..., 2) (stratified in the unit square), and their weights (...): the filter importance-
    sampled, each axis through the inverse of the window's cumulative share, every sample of
    weight 1 (the box: the pixel's square). Stratified over the filter's weight, not its
    square: Blackman-Harris's corner cells weighed ~1e-3 each, and a sub-pixel image near
    the centre that the samples missed lost its light (issue 50)."""
    if pixel_filter == "box":
        return unit - 0.5, np.ones(unit.shape[:-1])
    t = np.interp(unit, _WINDOW_CDF, _WINDOW_T)
    return (t - 0.5) * filter_size, np.ones(unit.shape[:-1])


R2 = np.array([0.7548776662466927, 0.5698402909980532])
"""The R2 sequence's steps (frac(n R2), n = 0, 1, ...: low-discrepancy points in 2-D)."""
PIXEL_STRIDE = 65537
"""Pixel (row, column) numbers its samples' jitter from (row PIXEL_STRIDE + column) K."""


def pixel_samples(
    unit: np.ndarray, ks: slice, k: int, rows: np.ndarray, columns: np.ndarray
) -> np.ndarray:
    """(P, K, 2) points in the unit square: the samples ``ks`` of the cell centres ``unit``
    (of a k x k grid) of the pixels (rows, columns) (image indices, (P,)), each jittered
    within its cell, differently in every pixel (the R2 sequence over the pixel's and the
    sample's numbers): stratified, unbiased for any feature, whereas one fixed pattern
    for all pixels covers a strip 0.3 px wide along a column with the same one or two grid
    columns in every pixel (0.25 or 0.5 of its light)."""
    count = unit.shape[0]
    number = (rows.astype(np.float64) * PIXEL_STRIDE + columns)[:, None] * count
    number = number + np.arange(count)[ks][None, :]
    jitter = np.mod(0.5 + number[..., None] * R2, 1.0)  # (P, K, 2)
    return unit[ks][None, :, :] + (jitter - 0.5) / k


def stratified_points(n: int) -> np.ndarray:
    """n points (n, 2) in the unit square: centres of a k x k grid's cells, k = ceil(sqrt n),
    in farthest-point order from the one nearest the middle (every prefix is spread out)."""
    k = _cells_per_side(n)
    cells = (np.stack(np.meshgrid(np.arange(k), np.arange(k)), axis=-1).reshape(-1, 2) + 0.5) / k
    order = [int(np.argmin(np.hypot(*(cells - 0.5).T)))]
    gap = np.hypot(*(cells - cells[order[0]]).T)
    while len(order) < n:
        order.append(int(np.argmax(gap)))
        gap = np.minimum(gap, np.hypot(*(cells - cells[order[-1]]).T))
    return cells[order]


def _cells_per_side(n: int) -> int:
    """k = ceil(sqrt(n)): the side of the k x k grid whose cells n points take."""
    return math.isqrt(n - 1) + 1 if n > 1 else 1


@dataclass
class TileResult:
    """What a tile adds to the image: per-pixel colour and passes, and its ray counts."""

    rgba: np.ndarray  # (h, w, 4) float32
    passes: dict[str, np.ndarray]
    """The stored passes (core.passes.STORED) by name, (h, w) or (h, w, channels), each of
    its pass's type: the pixel centre's (error: +inf where failed)."""
    energy: np.ndarray  # (h, w) |H - H0|
    rays: int
    error_rays: int  # companions and retraces
    companion_rays: int = 0  # the error pass's companion runs alone


class _Nodes:
    """The lattice of a tile: what is known at each node (traced or not)."""

    def __init__(self, ny: int, nx: int, tangents: bool = False) -> None:
        shape = (ny, nx)
        self.traced = np.zeros(shape, dtype=bool)
        self.direction = np.zeros(shape + (3,))
        self.ending = np.full(shape, -1, dtype=np.int8)
        self.rgba = np.zeros(shape + (4,))
        self.error = np.zeros(shape)
        self.steps = np.zeros(shape, dtype=np.int32)
        self.energy = np.zeros(shape)
        self.plain = np.zeros(shape, dtype=bool)  # ended without volume light
        self.clearance = np.zeros(shape)  # radians from geometry (RayResults.clearance)
        self.integration = np.zeros(shape)  # the integration's error estimate (radians)
        self.object_id = np.full(shape, -1, dtype=np.int32)
        self.kinks = np.zeros(shape, dtype=np.int64)  # the model's kinks its ray crossed
        self.position = np.zeros(shape + (3,))  # hit points (world)
        self.tangent = np.zeros(shape + (3,))  # the hitting chords' directions
        self.surface = np.zeros(shape + (4,))  # the surface's colour where hit
        self.redshift = np.full(shape, np.nan)  # g on the accretion disk
        self.radius = np.full(shape, np.nan)  # Boyer–Lindquist r of a hit on the disk
        self.flipped = np.zeros(shape, dtype=bool)  # two of its runs ended on different things
        self.near = np.zeros(shape, dtype=bool)  # missed an object by under NEAR_MISS x its error
        self.loose = np.zeros(shape, dtype=bool)  # its companion ran past the rule's range
        self.pending = np.zeros(shape, dtype=bool)  # traced, its error not judged yet (_settle)
        self.magnification = np.full(shape, np.nan)  # |μ| where it sees the sky (with tangents)
        self.transmittance = np.ones(shape)  # through volumes and a translucent disk
        # d(direction) / d(image x, y) where it sees the sky (RayResults.sky_jacobian)
        self.jacobian = np.full(shape + ((2, 3) if tangents else (0, 3)), np.nan)


class TileSampler:
    """Renders tiles of one image (see the module docstring)."""

    def __init__(
        self,
        tracer: Tracer,
        camera,
        background: Background,
        shade: Callable[[RayResults, Background], np.ndarray],
        *,
        interpolation: float,
        samples: int = 1,
        pixel_filter: str = "box",
        filter_size: float = 1.0,
        with_error: bool = False,
        far_field: float = 0.0,
        pixel_angle: float = 1.0,
        budget: float = np.inf,
        tangents: bool = False,
        magnification: bool = False,
    ) -> None:
        self.tracer, self.camera, self.background, self.shade = tracer, camera, background, shade
        self._colour_tracer = tracer.without_clearance()  # for sub-pixel samples (_sample)
        self.interpolation = float(interpolation)  # radians; 0: trace every pixel
        self.samples = int(samples)
        self.unit = stratified_points(self.samples)  # (S, 2), jittered per pixel
        self.pixel_filter, self.filter_size = pixel_filter, filter_size
        extent = 1.0 if pixel_filter == "box" else filter_size
        self.footprint = extent / math.sqrt(2)  # pixels from the centre to its corners
        self.with_error = with_error and tracer.curved
        self.step = tracer.step  # a node's first run's (retraces halve it)
        self.far_field = far_field  # error of escaped rays beyond the region, radians
        self.pixel_angle = pixel_angle  # radians (core.Camera.pixel_angle)
        self.budget = budget  # radians: a traced ray's integration error above it is redone
        self.with_tangents = tangents  # ray differentials: sky footprints, magnification
        self.with_magnification = magnification  # the pass: blocks where ln |μ| is bilinear
        self._origin = (0, 0)  # image (row, column) of the current tile's node (0, 0)
        self.rays = 0
        self.error_rays = 0  # companions and retraces
        self.companion_rays = 0

    # --- tracing nodes -----------------------------------------------------------------
    def _trace_points(
        self,
        xy: np.ndarray,
        cancel,
        companion: bool | np.ndarray = True,
        step: float | None = None,
        node: bool = True,
        margin: np.ndarray | float = 1.0,
    ) -> tuple[RayResults, np.ndarray, np.ndarray | None]:
        """Trace camera rays through image points xy (M, 2) at ``step`` (default: the
        tracer's) -> (rays, seen directions, and with the error pass (and ``companion``)
        their Richardson error in radians from a companion run at COMPANION_RATIO x the
        step; sub-pixel samples need none: the pass reports pixel centres). Nodes (``node``)
        carry ray differentials where the sampler takes them; other points (samples) no
        clearance (Tracer.without_clearance: their colour is all the sampler takes); nodes
        record it within ``margin`` of the tracer's (a share, one or per point:
        _node_margin). ``companion`` may name the points (M,) bool that get one: the
        others' error is NaN."""
        origins, directions = self.camera.rays_at(xy)
        n = xy.shape[0]
        share = np.broadcast_to(np.asarray(margin, np.float64), (n,))
        self.rays += n if step is None else 0
        step = step or self.step
        seen = self.camera.direction_tangents(xy) if self.with_tangents and node else None
        if not self.with_error or companion is False:
            tracer = self.tracer if node else self._colour_tracer  # a sample's colour alone
            rays = tracer.trace(origins, directions, step=step, cancel=cancel, tangents=seen,
                                clearance=share if node else None)  # fmt: skip
            return rays, seen_direction(rays, origins), None
        assert step is not None
        some = np.flatnonzero(np.broadcast_to(companion, (n,)))
        if seen is None:  # one batch: the companion shares the main run's per-step overhead
            both = self.tracer.trace(
                np.concatenate([origins, origins[some]]),
                np.concatenate([directions, directions[some]]),
                step=np.repeat([step, COMPANION_RATIO * step], [n, some.size]),
                cancel=cancel,
                clearance=np.concatenate([share, np.zeros(some.size)]),  # the companion's: unread
            )
            rays, coarse = both.take(slice(0, n)), both.take(slice(n, None))
        else:  # the companion needs no differentials: a batch of its own costs less than
            # carrying them through its half of a shared batch (benchmarks/frame.py)
            rays = self.tracer.trace(origins, directions, step=step, cancel=cancel,
                                     tangents=seen, clearance=share)  # fmt: skip
            coarse = self.tracer.trace(origins[some], directions[some],
                                       step=COMPANION_RATIO * step, cancel=cancel,
                                       clearance=np.zeros(some.size))  # fmt: skip
        self.error_rays += some.size
        self.companion_rays += some.size
        error = np.full(n, np.nan)
        error[some] = self._companion_error(rays.take(some), coarse, origins[some], step)
        return rays, seen_direction(rays, origins), error

    def _companion_error(self, rays: RayResults, coarse: RayResults, origins, step: float):
        """(M,) the error of ``rays`` run at ``step`` from their companion ``coarse``
        (Richardson; doubted where both took the same steps; at least the rule's bound
        where the companion ran past its range); captured rays neither."""
        assert self.tracer.order is not None  # a companion run: the scene is curved
        error = richardson_error(rays, coarse, origins, self.tracer.order)
        seen = rays.ending != ENDING["captured"]  # the shadow's inside has no direction
        error = np.where(seen, self._doubted(error, rays.steps, coarse.steps), error)
        return np.where(seen, np.maximum(error, self._bound(step)), error)

    @property
    def _first_step(self) -> float:
        """A node's first run's step (the tracer's), where there is one: a curved scene's."""
        assert self.step is not None
        return self.step

    def _bound(self, step: float) -> float:
        """The least error a run at ``step`` reports from its companion: where the companion
        runs past the steps the rule's constant was measured at (the step at the rule's
        cap), Richardson compares with a run outside its asymptotic range (Schwarzschild
        at the cap, 1.0: errors at 2 h were 0.3-4x those at h, at h / 2 1/16 of them; the
        estimate read 0.03-0.3 of the truth on 2.6-2.8 % of benchmarks/honesty.py
        schwarzschild's pixels at every tolerance), and the rule's bound C h^order at h
        stands in; within the rule's range, none (Richardson's own)."""
        return self.tracer.error_bound(step) if self._bound_applies(step) else 0.0

    def _bound_applies(self, step: float | None) -> bool:
        """Whether a run at ``step``'s companion runs past the rule's largest step."""
        return step is not None and COMPANION_RATIO * step > self.tracer.plan.largest_step

    def _doubted(self, error: np.ndarray, steps: np.ndarray, other_steps: np.ndarray):
        """``error`` raised above the retrace budget where the two runs it compares took
        about as many steps (shared_steps) and agree within DOUBT_BELOW x the budget:
        Richardson then compared a run with itself. Not asked of captured rays (by
        _trace_points): the shadow's inside has no direction to be wrong, its runs agree
        exactly whatever their steps, and a ray near its edge circles the photon orbit in
        steps of its own (a flip shows as one); doubted, every captured ray of a camera at
        3 rg was traced again (benchmarks/honesty.py orbit_disk: 2 error runs an image ray)."""
        shared = shared_steps(steps, other_steps) & (error < DOUBT_BELOW * self.budget)
        if not math.isfinite(self.budget):
            return error
        return np.where(shared, np.maximum(error, DOUBTED * self.budget), error)

    def _trace_nodes(self, nodes: _Nodes, jj: np.ndarray, ii: np.ndarray, origin, cancel,
                     dense: bool = False, defer: bool = False):  # fmt: skip
        """Trace the untraced nodes among (jj, ii) (flat index arrays) and store them
        (``dense``: no block will interpolate them; _trace_points). ``defer``: only the
        anchors (_anchors) get a companion now, the others' error waits for _settle."""
        flat = np.unique(jj * nodes.traced.shape[1] + ii)
        jj, ii = np.divmod(flat, nodes.traced.shape[1])
        todo = ~nodes.traced[jj, ii]
        jj, ii = jj[todo], ii[todo]
        if jj.size == 0:
            return
        margin = _node_margin(jj, ii, dense)
        companion = ~self._spare(nodes, jj, ii) if defer and self.with_error else True
        xy = self._image_xy(jj, ii)
        rays, seen, error = self._trace_points(xy, cancel, companion, margin=margin)
        self._record(nodes, jj, ii, rays, seen)
        nodes.loose[jj, ii] = error is not None and self._bound_applies(self.step)
        if error is not None and not isinstance(companion, bool):
            nodes.pending[jj, ii] = ~companion
            jj, ii, error = jj[companion], ii[companion], error[companion]
        self._judge(nodes, jj, ii, error)

    def _from_anchors(self, nodes: _Nodes, jj, ii):
        """What the anchors at the corners of the nodes (jj, ii)'s ANCHOR cells say of
        their errors -> (agree, estimate, like, judged): ``agree`` where all four are traced,
        judged, finite, no flip or near miss, end alike (escaped, captured, on one object,
        across the same kinks: the error is smooth across the cell) and keep clear of the
        geometry by more than a companion's error could move a ray (_clear_of) unless
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
        agree &= judged & ((least >= self._clear_of(estimate)) | captured)
        return agree, estimate, (cj, ci), judged

    def _clear_of(self, estimate: np.ndarray) -> np.ndarray:
        """The clearance (radians) a node of error ``estimate`` needs for its companion to
        be spared: more than the companion's error could move it (NEAR_MISS x
        COMPANION_RATIO^order x the estimate: a thin object between anchors) and
        DENSE_MARGIN pixels (benchmarks/honesty.py thin_front at 1 px: 5 flips estimated
        under a pixel with the first alone)."""
        assert self.tracer.order is not None  # an error pass: the scene is curved
        reach = NEAR_MISS * COMPANION_RATIO**self.tracer.order
        return np.maximum(reach * estimate, DENSE_MARGIN * self.pixel_angle)

    def _spare(self, nodes: _Nodes, jj, ii) -> np.ndarray:
        """(M,) bool: the nodes (jj, ii), not traced yet, whose companion is spared for now
        (_trace_nodes' ``defer``): not anchors, and their anchors agree (_from_anchors) or
        are not all judged yet (traced in this round: _settle will know)."""
        agree, _, _, judged = self._from_anchors(nodes, jj, ii)
        return ~_anchors(jj, ii) & (agree | ~judged)

    def _settle(self, nodes: _Nodes) -> tuple[np.ndarray, np.ndarray]:
        """Judge the pending nodes (traced without their companion: _spare) by their
        anchors' largest error where they end as their anchors do and keep as clear of
        the geometry (_from_anchors; captured as they are: the shadow's inside has no
        error, and a camera at 3 rg in a disk's plane sees it through rays of clearance
        0) -> (jj, ii) the others: their companions run with the first retraces."""
        jj, ii = np.nonzero(nodes.pending)
        if jj.size == 0:
            return jj, ii
        agree, estimate, (cj, ci), _ = self._from_anchors(nodes, jj, ii)
        nodes.pending[:] = False
        like = (nodes.ending[jj, ii] == nodes.ending[cj, ci]) & agree
        like &= nodes.object_id[jj, ii] == nodes.object_id[cj, ci]
        like &= nodes.kinks[jj, ii] == nodes.kinks[cj, ci]
        captured = nodes.ending[jj, ii] == ENDING["captured"]
        like &= (nodes.clearance[jj, ii] >= self._clear_of(estimate)) | captured
        self._judge(nodes, jj[like], ii[like], estimate[like])
        return jj[~like], ii[~like]

    def _store(self, nodes: _Nodes, jj, ii, rays: RayResults, seen, error) -> None:
        """Record traced rays at the nodes (jj, ii) and judge them; ``error`` is the
        integration's."""
        self._record(nodes, jj, ii, rays, seen)
        self._judge(nodes, jj, ii, error)

    def _record(self, nodes: _Nodes, jj, ii, rays: RayResults, seen) -> None:
        """Record traced rays at the nodes (jj, ii)."""
        nodes.traced[jj, ii] = True
        nodes.direction[jj, ii] = seen
        nodes.ending[jj, ii] = rays.ending
        nodes.rgba[jj, ii] = self.shade(rays, self.background)
        nodes.steps[jj, ii] = rays.steps
        nodes.energy[jj, ii] = rays.energy_error
        escaped = rays.ending == ENDING["escaped"]
        no_light = (rays.transmittance == 1.0) & ~np.any(rays.radiance, axis=1)
        hit = rays.ending == ENDING["hit"]
        nodes.plain[jj, ii] = (escaped | (rays.ending == ENDING["captured"]) | hit) & no_light
        nodes.clearance[jj, ii] = rays.clearance  # a hit's: from all but its object
        nodes.object_id[jj, ii] = rays.object_id
        nodes.kinks[jj, ii] = rays.kinks
        nodes.position[jj, ii] = rays.position
        nodes.tangent[jj, ii] = rays.tangent
        nodes.surface[jj, ii] = rays.surface
        nodes.redshift[jj, ii] = rays.redshift
        on_disk = np.flatnonzero(hit & (rays.object_id == DISK_ID))
        nodes.radius[jj, ii] = np.nan
        nodes.magnification[jj, ii] = rays.magnification
        nodes.transmittance[jj, ii] = rays.transmittance
        if nodes.jacobian.shape[2] == rays.sky_jacobian.shape[1]:
            nodes.jacobian[jj, ii] = rays.sky_jacobian
        if on_disk.size:
            radius = self.tracer.scene.disk_radius(rays.position[on_disk])
            nodes.radius[jj[on_disk], ii[on_disk]] = radius

    def _judge(self, nodes: _Nodes, jj, ii, error) -> None:
        """The recorded nodes (jj, ii)'s errors from their integration's (``error``, None:
        0): flips, near misses (traced again), near edges, the far field."""
        err = np.zeros(jj.size) if error is None else error
        nodes.flipped[jj, ii] |= err >= FLIP  # once two runs ended apart, it stays a flip
        err = np.where(nodes.flipped[jj, ii], np.maximum(err, FLIP), err)
        nodes.integration[jj, ii] = err  # a flip is traced again (RETRACE), as a near miss
        near_miss = nodes.clearance[jj, ii] < NEAR_MISS * err  # it may have hit something
        nodes.near[jj, ii] = near_miss  # traced again (_retrace); a near edge is not: its
        # retrace, agreeing, would report it clear of the edge whatever the truth
        near_miss |= self._near_edge(nodes, jj, ii, err)  # it may have missed its object
        ending = nodes.ending[jj, ii]
        far = np.where(ending == ENDING["escaped"], self.far_field, 0.0)
        err = np.where(near_miss, np.maximum(err, FLIP), err + far)
        nodes.error[jj, ii] = np.where(ending == ENDING["failed"], np.inf, err)

    def _near_edge(self, nodes: _Nodes, jj, ii, err: np.ndarray) -> np.ndarray:
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
        origins, _ = self.camera.rays_at(self._image_xy(jj[rows] * 1.0, ii[rows] * 1.0))
        j, i = jj[rows], ii[rows]
        p, t, own = nodes.position[j, i], nodes.tangent[j, i], nodes.object_id[j, i]
        move = NEAR_MISS * err[rows] * np.linalg.norm(p - origins, axis=1)
        reach = (EDGE_REACH * move)[:, None] * t
        found = self.tracer.geometry.cast(p - reach, p + reach)
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
        hits = self.tracer.geometry.cast(moved - along, moved + along)
        same = (hits.hit & (hits.object_id == np.tile(own, 4))).reshape(4, -1).all(axis=0)
        out[rows] = ~(found.hit & (found.object_id == own) & same)
        return out

    def _retrace(self, nodes: _Nodes, cancel, unsure=None) -> None:
        """Trace the nodes whose integration error exceeds ``budget`` again at half the
        step, their previous run the companion, up to RETRACE times (all of a tile's at
        once: each run costs a batch's per-step overhead), and the near misses
        (``_Nodes.near``: their path, less its hit test's slack, within NEAR_MISS x their
        error of an object) as long as they stay near: at half the step the error is 16x
        smaller and the slack 4x (the ray of a mirage grazing hot ground that missed it on
        its cubic while the true path dips below hits it then; benchmarks/honesty.py
        mirage_grazing@1: 18 pixels off by a flip before, and after one retrace; +7 % time
        on a 1080p Kerr disk frame). A near edge (_near_edge) is not
        traced again: its retrace, agreeing, would report it clear of the edge whatever the
        truth (thin_front: quiet flips). A flip whose retrace ended as its last run did is
        not traced again: it keeps its flip's error whatever later runs find, and further
        halvings, agreeing too, only cost (the Kerr board's ~1800 flips per 1080p tile, at
        the shadow's edge, took all RETRACE rounds: 10 % of its time). The ``unsure``
        nodes (jj, ii) (_settle) have their companions in the first round's batch: they
        are judged by them and join the later rounds."""
        step = self.step
        settled = np.zeros_like(nodes.traced)  # flips whose retrace ended as before
        unsure = (np.zeros(0, int), np.zeros(0, int)) if unsure is None else unsure
        for _ in range(RETRACE if self.with_error else 0):
            err = nodes.integration
            budget = np.where(nodes.loose, LOOSE_SHARE * self.budget, self.budget)
            again = ((np.isfinite(err) & (err > budget)) | nodes.near) & ~settled
            nodes.loose[:] = False  # a later round's step is not half the first run's
            jj, ii = np.nonzero(nodes.traced & again)
            if (jj.size == 0 and unsure[0].size == 0) or (cancel is not None and cancel()):
                return
            assert step is not None  # an error pass: the scene is curved
            step /= COMPANION_RATIO
            xy = self._image_xy(jj, ii)
            rays = self._retrace_batch(nodes, xy, step, unsure, cancel)
            unsure = (np.zeros(0, int), np.zeros(0, int))
            if rays is None:
                continue
            seen = seen_direction(rays, self.camera.rays_at(xy)[0])
            assert self.tracer.order is not None  # a companion run: the scene is curved
            origins, _ = self.camera.rays_at(xy)
            apart = seen_apart(
                seen, rays.position, nodes.direction[jj, ii], nodes.position[jj, ii],
                rays.ending, origins,
            )  # fmt: skip
            alike = (rays.ending == nodes.ending[jj, ii]) & (
                rays.object_id == nodes.object_id[jj, ii]
            )
            error = _richardson(apart, rays.ending, alike, self.tracer.order)
            settled[jj, ii] = alike & nodes.flipped[jj, ii]
            self._store(nodes, jj, ii, rays, seen, error)

    def _retrace_batch(self, nodes: _Nodes, xy, step: float, unsure, cancel):
        """The retraces of the points xy at ``step`` (returned; None if none), in one
        batch with the companions of the ``unsure`` nodes (jj, ii) where there are no
        differentials (a retrace carries them), which are judged by them."""
        uj, ui = unsure
        n, margin = xy.shape[0], DENSE_MARGIN / STRIDE
        self.error_rays += n + uj.size
        self.companion_rays += uj.size
        rays: RayResults | None = None
        if self.with_tangents:
            if n:
                rays = self._trace_points(xy, cancel, False, step=step, margin=margin)[0]
            if uj.size == 0:
                return rays
            points = self._image_xy(uj, ui)
        else:
            points = np.concatenate([xy, self._image_xy(uj, ui)])
        origins, directions = self.camera.rays_at(points)
        counts = [points.shape[0] - uj.size, uj.size]
        traced = self.tracer.trace(
            origins, directions, cancel=cancel,
            step=np.repeat([step, COMPANION_RATIO * self._first_step], counts),
            clearance=np.repeat([margin, 0.0], counts),
        )  # fmt: skip
        if not self.with_tangents:
            rays, traced = traced.take(slice(0, n)) if n else None, traced.take(slice(n, None))
        if uj.size:
            rest = origins[origins.shape[0] - uj.size :]
            error = self._companion_error(
                _node_rays(nodes, uj, ui, rest), traced, rest, self._first_step
            )
            self._judge(nodes, uj, ui, error)
            nodes.loose[uj, ui] = self._bound_applies(self.step)
        return rays

    # --- the quadtree ------------------------------------------------------------------
    def render_tile(self, tile: Tile, cancel=None) -> TileResult | None:
        """Colour and passes of one tile (None if cancelled). Threads share the sampler:
        each tile works on its own shallow copy (its origin and ray counts)."""
        return copy.copy(self)._render_tile(tile, cancel)

    def _render_tile(self, tile: Tile, cancel) -> TileResult | None:
        self.rays = self.error_rays = self.companion_rays = 0
        h, w = tile.shape
        s = STRIDE if self.interpolation > 0 else 1
        ny, nx = 1 + s * math.ceil((h + 1) / s), 1 + s * math.ceil((w + 1) / s)
        origin = (tile.y0 - 1, tile.x0 - 1)  # image (row, column) of node (0, 0)
        self._origin = origin
        nodes = _Nodes(ny, nx, self.with_tangents)
        blocks = _Blocks(ny - 1, nx - 1)
        if s == 1:
            jj, ii = np.mgrid[0:ny, 0:nx]
            self._trace_nodes(nodes, jj.ravel(), ii.ravel(), origin, cancel, dense=True,
                              defer=True)  # fmt: skip
        else:
            self._refine(nodes, blocks, s, (h + 1, w + 1), origin, cancel)
        self._retrace(nodes, cancel, self._settle(nodes))
        if cancel is not None and cancel():
            return None
        return self._pixels(tile, nodes, blocks, origin, cancel)

    def _refine(self, nodes: _Nodes, blocks: _Blocks, s: int, last, origin, cancel) -> None:
        """Trace and accept blocks level by level, from size s down to FINEST; the nodes of
        blocks still refused there are all traced. Only blocks reaching the tile's nodes
        (rows and columns up to ``last``: the lattice may run past them) are refined."""
        ny, nx = nodes.traced.shape
        bj, bi = (a.ravel() for a in np.mgrid[0 : ny - 1 : s, 0 : nx - 1 : s])
        first = _first_lattice((last[0] + 1) * (last[1] + 1), s)
        if first < s // 2:  # one round for the levels whose points lie on its lattice
            jj, ii = (a.ravel() for a in np.mgrid[0:ny:first, 0:nx:first])
            self._trace_nodes(nodes, jj, ii, origin, cancel, defer=True)
        while bj.size:
            half = s // 2
            nine = _block_points(bj, bi, s)
            jj, ii = (np.concatenate([p[k] for p in nine]) for k in (0, 1))
            self._trace_nodes(nodes, jj, ii, origin, cancel, defer=True)
            if cancel is not None and cancel():
                return
            accepted, deviation, vectors = self._accept(nodes, bj, bi, s)
            blocks.add(bj[accepted], bi[accepted], s, deviation[accepted], vectors[accepted])
            sj, si = bj[~accepted], bi[~accepted]
            jj, ii = _block_nodes(sj, si, s, last)
            if s <= FINEST or self._dense_pays(nodes, jj, ii, sj, si, s, last, first):
                self._trace_nodes(nodes, jj, ii, origin, cancel, dense=True, defer=True)
                return
            bj = np.concatenate([sj, sj, sj + half, sj + half])
            bi = np.concatenate([si, si + half, si, si + half])
            reach = (bj <= last[0]) & (bi <= last[1])
            bj, bi, s = bj[reach], bi[reach], half

    @staticmethod
    def _dense_pays(nodes: _Nodes, jj, ii, sj, si, s: int, last, first: int) -> bool:
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
        pj, pi = (np.concatenate([p[k] for p in _block_points(bj, bi, half)]) for k in (0, 1))
        inside = (pj <= last[0]) & (pi <= last[1])
        flat = np.unique(pj[inside] * nodes.traced.shape[1] + pi[inside])
        level = int(np.count_nonzero(~nodes.traced.ravel()[flat]))
        levels = [size for size in (half >> k for k in range(8)) if size >= FINEST]
        rounds = 1 + sum((size // 2) % first != 0 for size in levels)
        refined = rounds * ROUND_RAYS + level + 0.5 * max(dense - level, 0)
        return ROUND_RAYS + dense <= refined

    def _accept(self, nodes: _Nodes, bj, bi, s: int) -> tuple[np.ndarray, ...]:
        """Which blocks (size s) are interpolated, their deviations (B, 5) (radians: its
        edges' midpoints' and the centre's excess; _edge_deviations) and those as vectors
        (B, 5, 3) (_deviation_vectors): every one of a block's
        nine traced rays ends alike (escaped, captured, or on one object), having crossed
        the same kinks of the model (RayResults.kinks: the image's map has a kink between
        rays that crossed different ones, which the midpoints' deviations, made for a smooth
        map, under-read: a fish-eye's edge at n's kink, 1-2 px off estimated 1/15 of it)."""
        nine = _block_points(bj, bi, s)
        corners, (cj, ci) = nine[:4], nine[8]
        alike = nodes.plain[cj, ci].copy()
        ending, object_id = nodes.ending[cj, ci], nodes.object_id[cj, ci]
        alike &= (object_id != DISK_ID) | self._opaque_disk()
        width = s * self.pixel_angle  # the block's width, radians
        clear = CLEARANCE * width * _magnification(nodes, corners, width)
        for j, i in nine:  # no (other) object in between
            alike &= nodes.plain[j, i] & (nodes.ending[j, i] == ending)
            alike &= (nodes.object_id[j, i] == object_id) & (nodes.clearance[j, i] > clear)
            alike &= nodes.kinks[j, i] == nodes.kinks[cj, ci]  # no kink of the map between
        deviation = self._deviations(nodes, nine, ending)
        vectors = self._deviation_vectors(nodes, nine, ending)
        disk = np.flatnonzero(alike & (object_id == DISK_ID))
        if disk.size:  # what the disk interpolates is its radius (and g): no texture
            on_disk = [(j[disk], i[disk]) for j, i in nine]
            deviation[disk] = self._radius_deviations(nodes, on_disk, width)
            vectors[disk] = np.nan  # r and g: their magnitudes stand
        worst = _worst(deviation)
        accepted = alike & (INTERPOLATION_SAFETY * worst <= self.interpolation)
        if self.with_magnification:
            accepted &= _smooth_magnification(nodes, nine, ending)
        return accepted, deviation, vectors

    def _deviation_vectors(self, nodes: _Nodes, nine, ending) -> np.ndarray:
        """(B, 5, 3) the deviations of _deviations as vectors (radians: a direction's
        difference, or a hit point's over its distance from the camera), the centre's excess
        being the centre's deviation less half the edges' sum (0 for a quadratic map): the
        bilinear interpolation's error at (u, v) is their sum weighted by _error_shape, whose
        length the error pass reports (the sum of their lengths, what acceptance bounds,
        adds up parts that cancel: a lens map's x and y curvatures, opposite where its
        deflection is harmonic, made it 3-3.5x the truth)."""
        hit = (ending == ENDING["hit"])[:, None]
        j8, i8 = nine[8]
        origins, _ = self.camera.rays_at(self._image_xy(j8, i8))
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

    def _deviations(self, nodes: _Nodes, nine, ending) -> np.ndarray:
        """(B, 5) radians: how far the edges' midpoints lie from their ends' mean and the
        centre from its corners' beyond what those make (_edge_deviations), in what a block
        interpolates: directions for the sky, hit points (over the pixel footprint there)
        for hits."""

        def apart(k, ends):
            (j, i), others = nine[k], [nine[e] for e in ends]
            mean = sum(nodes.direction[a, b] for a, b in others)
            at = sum(nodes.position[a, b] for a, b in others) / len(others)
            origins, _ = self.camera.rays_at(self._image_xy(j, i))
            return seen_apart(nodes.direction[j, i], nodes.position[j, i], mean, at, ending,
                              origins)  # fmt: skip

        deviation = _edge_deviations(apart)
        return np.where((ending == ENDING["captured"])[:, None], 0.0, deviation)

    def _radius_deviations(self, nodes: _Nodes, nine, width: float) -> np.ndarray:
        """_deviations for blocks on the disk: of its radius r, redshift g and azimuth
        (the hit point pass's place on it), each as the angle the block's own gradient of
        it (its corners' spread over ``width``) takes to make that much (the disk pixel
        shows what a ray that far off shows; NaN: refused), and r's and the azimuth's as
        the move on the disk they make over its distance from the camera, where that is
        more (a hit's error, docs/design.md: on a disk seen near edge-on a move in r is
        foreshortened on screen; the Kerr board's disk, seen from 2 rg above its plane,
        had interpolated pixels 0.44 px off at a median estimate half that)."""
        worst = np.zeros(nine[0][0].shape + (5,))
        light = self.tracer.disk
        assert light is not None  # only blocks on the disk come here
        azimuth = [self._disk_azimuth(nodes.position[j, i]) for j, i in nine]
        azimuth = [azimuth[8] + _wrapped(a - azimuth[8]) for a in azimuth]
        radius = [nodes.radius[j, i] for j, i in nine]
        distance = [np.linalg.norm(nodes.position[j, i] - self.camera.rays_at(
            self._image_xy(j, i))[0], axis=1) for j, i in nine]  # fmt: skip
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

    def _opaque_disk(self) -> bool:
        """Whether the scene's disk can be interpolated: opaque (a translucent one shows
        what lies behind it, ray by ray)."""
        light = self.tracer.disk
        return light is not None and light.disk.opacity >= 1.0

    def _interpolate_disk(self, nodes: _Nodes, corners, weights, y, x):
        """Points (y, x) inside blocks on the opaque accretion disk (``corners``: the blocks'
        corner nodes, ``weights``: the points' bilinear weights): -> (RGB (M, 3), on (M,),
        g, hit point, seen direction); the light at the interpolated radius and g. A point
        whose radius falls off the disk (an edge between the nodes) is not ``on``: traced."""
        light = self.tracer.disk
        assert light is not None  # only blocks on the disk come here
        pairs = list(zip(weights, corners, strict=True))
        radius = sum(wk * nodes.radius[j, i] for wk, (j, i) in pairs)
        g = sum(wk * nodes.redshift[j, i] for wk, (j, i) in pairs)
        first = self._disk_azimuth(nodes.position[corners[0]])
        azimuth = first + sum(
            wk * _wrapped(self._disk_azimuth(nodes.position[j, i]) - first) for wk, (j, i) in pairs
        )
        position = self._on_disk_at(radius, azimuth)
        on = (radius >= light.disk.r_in) & (radius <= light.disk.r_out)
        rgb = light.disk.colour(np.where(on, g, 0.0), radius)
        origins, _ = self.camera.rays_at(self._image_xy(y, x))
        seen = position - origins
        seen /= np.linalg.norm(seen, axis=1, keepdims=True)
        return rgb, on, g, position, seen

    def _disk_azimuth(self, position: np.ndarray) -> np.ndarray:
        """(M,) the azimuth on the disk's plane (its local frame) of world points (M, 3)."""
        light = self.tracer.disk
        assert light is not None
        local = light.to_local(position)
        return np.arctan2(local[:, 1], local[:, 0])

    def _on_disk_at(self, radius: np.ndarray, azimuth: np.ndarray) -> np.ndarray:
        """World points (M, 3) on the disk's plane at BL ``radius`` (Cartesian √(r² + a²))
        and ``azimuth``: the hit point pass holds the interpolated place the pixel is shaded
        at (before, the blended hit points' direction stood for the azimuth: a lensed
        block's points moved 2-7 px, on the Kerr disk frame at 1 px, under an estimate of
        less than one)."""
        light = self.tracer.disk
        assert light is not None
        across = np.hypot(radius, light.disk.spin)
        local = np.stack([across * np.cos(azimuth), across * np.sin(azimuth),
                          np.zeros_like(across)], axis=1)  # fmt: skip
        return self.tracer._to_world(local)

    # --- pixels ------------------------------------------------------------------------
    def _pixels(self, tile: Tile, nodes: _Nodes, blocks: _Blocks, origin, cancel) -> TileResult:
        """Pixel colours and passes: traced nodes as they are, the rest interpolated; then
        anti-aliasing where the contrast asks for it."""
        h, w = tile.shape
        jj, ii = (a.ravel() for a in np.mgrid[0 : h + 2, 0 : w + 2])
        centre = self._evaluate(nodes, blocks, jj.astype(float), ii.astype(float))
        missed = np.flatnonzero(centre.ending < 0)  # interpolated hits that missed: trace
        self._trace_centres(nodes, blocks, centre, missed, jj, ii, cancel)
        shaky = self._shaky(nodes, centre, (h + 2, w + 2), jj, ii)
        self._trace_centres(nodes, blocks, centre, shaky, jj, ii, cancel)
        if self.background.filters and not self.with_tangents:
            self._filter_sky(centre, (h + 2, w + 2), jj, ii)
        if self.tracer.geometry.filters:
            self._filter_surfaces(centre, (h + 2, w + 2), jj, ii)
        rgba = centre.rgba.reshape(h + 2, w + 2, 4)
        error = centre.error.reshape(h + 2, w + 2)
        ending = centre.ending.reshape(h + 2, w + 2)
        direction = centre.direction.reshape(h + 2, w + 2, 3)
        redshift = centre.redshift.reshape(h + 2, w + 2)
        position = centre.position.reshape(h + 2, w + 2, 3)
        inner = (slice(1, h + 1), slice(1, w + 1))
        steps = nodes.steps[inner]
        energy = nodes.energy[inner]
        colour = rgba[inner].copy()
        if self.samples > 1:
            differs = _contrast(rgba, ending)
            near = nodes.traced[inner] & (
                nodes.clearance[inner] < self.footprint * self.pixel_angle
            )
            busy = np.any(np.stack(differs), axis=0) | near
            colour[busy] = self._supersample(nodes, blocks, busy, differs, near, colour[busy],
                                             cancel)  # fmt: skip
        passes = {"error": error[inner], "steps": steps, "ending": ending[inner],
                  "direction": direction[inner], "redshift": redshift[inner],
                  "position": position[inner],
                  "magnification": centre.magnification.reshape(h + 2, w + 2)[inner],
                  "transmittance": centre.transmittance.reshape(h + 2, w + 2)[inner]}  # fmt: skip
        return TileResult(
            colour.astype(np.float32),
            {name: data.astype(BY_NAME[name].dtype, copy=False) for name, data in passes.items()},
            energy, self.rays, self.error_rays, self.companion_rays,
        )  # fmt: skip

    def _trace_centres(self, nodes: _Nodes, blocks: _Blocks, centre: _Points, rows, jj, ii, cancel):
        """In place: the pixel centres ``rows`` (of the lattice points jj, ii) traced, and
        ``centre``'s values there replaced by their rays'."""
        if rows.size == 0:
            return
        self._trace_nodes(nodes, jj[rows], ii[rows], self._origin, cancel)
        again = self._evaluate(nodes, blocks, jj[rows] * 1.0, ii[rows] * 1.0)
        for name in (
            "rgba", "ending", "error", "direction", "redshift", "position", "magnification",
            "transmittance", "object_id", "tangent", "surface",
        ):  # fmt: skip
            getattr(centre, name)[rows] = getattr(again, name)

    def _shaky(self, nodes: _Nodes, centre: _Points, shape: tuple[int, int], jj, ii):
        """Rows of the interpolated pixel centres (a grid ``shape`` of lattice points jj, ii)
        whose colour could change by more than COLOUR_STEP over their error: those whose
        largest difference in a channel from a neighbour a pixel away, times their error in
        pixels, exceeds it, where what they show, looked up moved by the error across x and
        y, changes by more (the sky, surfaces; the rest, as the disk, kept); and sky centres
        whose background has detail smaller than a pixel (Background.detail) that changes."""
        change = _neighbour_change(centre.rgba[:, :3].reshape(shape + (3,))).ravel()
        interpolated = ~nodes.traced[jj, ii]
        move = centre.error / self.pixel_angle
        shaky = interpolated & (change * move > COLOUR_STEP)
        escaped = centre.ending == ENDING["escaped"]
        hit = (centre.ending == ENDING["hit"]) & (centre.object_id >= 0)
        sky = interpolated & escaped
        if self.background.detail >= self.pixel_angle:
            sky &= shaky
        if sky.any():
            rows = np.flatnonzero(sky)
            slope = map_footprint(
                centre.direction.reshape(shape + (3,)), escaped.reshape(shape), rows
            )
            shaky[rows] = self._shaky_sky(centre.direction[rows], slope, move[rows])
        surface = shaky & hit
        if surface.any():
            label = np.where(hit, centre.object_id, -1).reshape(shape)
            rows = np.flatnonzero(surface)
            slope = screen_differences(
                centre.position.reshape(shape + (3,)), label, jumps=True, rows=rows
            )
            shaky[rows] = self._shaky_surface(centre, rows, slope, move[rows], jj, ii)
        return np.flatnonzero(shaky)

    def _shaky_sky(self, d: np.ndarray, slope: np.ndarray, move: np.ndarray) -> np.ndarray:
        """(M,) sky points (directions d (M, 3), their derivatives along image x and y
        ``slope`` (M, 2, 3); NaN: none, taken as shaky) whose colour changes by more than
        COLOUR_STEP in a channel when their direction moves ``move`` (M,) pixels across x or
        y, either way."""
        centre = self.background(d)[:, :3]
        change = np.zeros(d.shape[0])
        for offset in _moves(slope, move):
            probe = d + offset
            with np.errstate(invalid="ignore"):
                probe /= np.linalg.norm(probe, axis=1, keepdims=True)
            seen = self.background(np.nan_to_num(probe), None)[:, :3]
            change = np.maximum(change, np.max(np.abs(seen - centre), axis=1))
            change[~np.all(np.isfinite(probe), axis=1)] = np.inf
        return change > COLOUR_STEP

    def _shaky_surface(self, centre: _Points, rows, slope, move, jj, ii) -> np.ndarray:
        """(M,) the hits ``rows`` of ``centre`` (at lattice points jj, ii) whose colour
        changes by more than COLOUR_STEP, or whose object is not met, when their hit point
        moves ``move`` (M,) pixels across image x or y along its derivatives ``slope`` (M, 2,
        3; NaN: none, taken as shaky), either way: cast again along their chords (over the
        footprint ``slope`` where the surfaces filter)."""
        position, tangent = centre.position[rows], centre.tangent[rows]
        origins, _ = self.camera.rays_at(self._image_xy(jj[rows] * 1.0, ii[rows] * 1.0))
        far = np.linalg.norm(position - origins, axis=1)
        reach = REACH * np.maximum(move, 1.0) * self.pixel_angle * far
        footprint = slope if self.tracer.geometry.filters else None
        object_id = centre.object_id[rows]
        first = self._recast(position, tangent, reach, object_id, footprint)
        shaky = ~first.hit | ~np.all(np.isfinite(slope), axis=(1, 2))
        for offset in _moves(np.nan_to_num(slope), move):
            probe = self._recast(position + offset, tangent, reach, object_id, footprint)
            change = np.max(np.abs(probe.color[:, :3] - first.color[:, :3]), axis=1)
            shaky |= ~probe.hit | (change > COLOUR_STEP)
        return shaky

    def _filter_sky(self, centre: _Points, shape: tuple[int, int], jj, ii) -> None:
        """The sky seen at the pixel centres (a grid ``shape``, rows jj, columns ii) averaged
        over each pixel's footprint, taken from the centres' own directions
        (core.mipmap.map_footprint): the sky's share of each colour (its transmittance
        times the sky, Doppler shifted for a moving camera) replaced by the filtered one."""
        sky = centre.ending == ENDING["escaped"]
        footprint = map_footprint(centre.direction.reshape(shape + (3,)), sky.reshape(shape))
        rows = np.flatnonzero(sky)
        if rows.size == 0:
            return
        d = centre.direction[rows]
        filtered = self.background(d, footprint.reshape(-1, 2, 3)[rows])
        self._replace_share(centre, rows, jj, ii, self.background(d), filtered)

    def _filter_surfaces(self, centre: _Points, shape: tuple[int, int], jj, ii) -> None:
        """The surfaces seen at the pixel centres (a grid ``shape``, rows jj, columns ii)
        averaged over each pixel's footprint there, from neighbouring centres' hit points
        on the same object (core.mipmap.surface_footprint; SceneGeometry.colour_over): the
        surface's share of each colour (its transmittance times the surface, Doppler
        shifted for a moving camera) replaced by the filtered one. Centres past the image's
        edges are not neighbours (as on a whole image: core.viewport.reshade_surfaces)."""
        row, column = self._origin[0] + jj, self._origin[1] + ii
        inside = (
            (row >= 0) & (row < self.camera.height) & (column >= 0) & (column < self.camera.width)
        )
        hit = (centre.ending == ENDING["hit"]) & (centre.object_id >= 0) & inside
        label = np.where(hit, centre.object_id, -1)
        rows, colour = surface_colours(
            self.tracer.geometry, centre.position, centre.tangent, label, 0, shape[1]
        )
        if rows.size:
            self._replace_share(centre, rows, jj, ii, centre.surface[rows].copy(), colour)

    def _replace_share(self, centre: _Points, rows, jj, ii, plain, filtered) -> None:
        """In place: the centres ``rows``' colours with the share of ``plain`` (what they
        show of the sky or a surface, unshifted) in them, its transmittance times it, Doppler
        shifted for a moving camera, replaced by ``filtered``'s."""
        moving = self.tracer.motion
        if moving is not None:
            _, seen = self.camera.rays_at(self._image_xy(jj[rows] * 1.0, ii[rows] * 1.0))
            g = moving.colour_shift(seen)
            plain[:, :3] = doppler_shift(plain[:, :3], g)
            filtered[:, :3] = doppler_shift(filtered[:, :3], g)
        centre.rgba[rows] += centre.transmittance[rows, None] * (filtered - plain)

    def _evaluate(self, nodes: _Nodes, blocks: _Blocks, y, x) -> _Points:
        """Colour, ending and error at lattice points (y, x) (node units, (M,)): a traced
        node's own where a point is one, else interpolated in its accepted block; points in
        no accepted block and on no traced node get ending -1 (to be traced)."""
        m = y.shape[0]
        out = _Points(
            np.zeros((m, 4)), np.full(m, -1, dtype=np.int8), np.zeros(m), np.full((m, 3), np.nan),
            np.full(m, np.nan), np.full((m, 3), np.nan), np.full(m, np.nan), np.ones(m),
            np.full(m, -1, dtype=np.int32), np.zeros((m, 3)), np.zeros((m, 4)),
        )  # fmt: skip
        cell_j = np.clip(np.floor(y).astype(np.int64), 0, blocks.block.shape[0] - 1)
        cell_i = np.clip(np.floor(x).astype(np.int64), 0, blocks.block.shape[1] - 1)
        b = blocks.block[cell_j, cell_i]
        on_node = (y == np.round(y)) & (x == np.round(x))
        nj, ni = np.round(y).astype(np.int64), np.round(x).astype(np.int64)
        traced = on_node & nodes.traced[np.clip(nj, 0, None), np.clip(ni, 0, None)]
        inside = np.flatnonzero((b >= 0) & ~traced)  # a traced node's own stands
        for start in range(0, inside.size, INTERPOLATE_POINTS):
            part = inside[start : start + INTERPOLATE_POINTS]
            self._interpolate(nodes, blocks, b[part], y[part], x[part], out, part)
        t = np.flatnonzero(traced)
        out.rgba[t] = nodes.rgba[nj[t], ni[t]]
        out.ending[t] = nodes.ending[nj[t], ni[t]]
        out.error[t] = nodes.error[nj[t], ni[t]]
        out.direction[t] = nodes.direction[nj[t], ni[t]]
        out.redshift[t] = nodes.redshift[nj[t], ni[t]]
        out.magnification[t] = nodes.magnification[nj[t], ni[t]]
        out.transmittance[t] = nodes.transmittance[nj[t], ni[t]]
        hit = t[out.ending[t] == ENDING["hit"]]
        out.position[hit] = nodes.position[nj[hit], ni[hit]]
        out.object_id[hit] = nodes.object_id[nj[hit], ni[hit]]
        out.tangent[hit] = nodes.tangent[nj[hit], ni[hit]]
        out.surface[hit] = nodes.surface[nj[hit], ni[hit]]
        return out

    def _interpolate(self, nodes: _Nodes, blocks: _Blocks, b, y, x, out: _Points, rows):
        """Shade points (y, x) inside accepted blocks b by bilinear interpolation: the sky in
        the interpolated direction; an object where the interpolated hit point and chord,
        cast again, meet it (elsewhere, as at its edge, the point is left to be traced)."""
        bj, bi, s = blocks.j[b], blocks.i[b], blocks.size[b]
        u, v = (x - bi) / s, (y - bj) / s
        weights = [(1 - u) * (1 - v), u * (1 - v), (1 - u) * v, u * v]
        corners = [(bj, bi), (bj, bi + s), (bj + s, bi), (bj + s, bi + s)]
        width = nodes.traced.shape[1]
        first = bj * width + bi  # a node's index in a flattened field
        flat = [first, first + s, first + s * width, first + s * (width + 1)]

        def blend(field, at=slice(None)):
            spread = (-1,) + (1,) * (field.ndim - 2)  # a weight per point, over its values
            rows = field.reshape(-1, *field.shape[2:])
            total = None
            for wk, k in zip(weights, flat, strict=True):
                term = (wk[at] if field.ndim == 2 else wk[at].reshape(spread)) * rows[k[at]]
                if total is None:
                    total = term
                else:
                    total += term
            return total

        d = blend(nodes.direction)
        d = d / np.linalg.norm(d, axis=1, keepdims=True)
        ending = nodes.ending[bj, bi].copy()
        colour = np.zeros((b.size, 4))
        colour[:, 3] = 1.0
        sky = ending == ENDING["escaped"]
        jacobian = blend(nodes.jacobian, sky) if self.with_tangents and sky.any() else None
        if sky.any():  # over the footprint of the nodes' ray differentials, blended
            colour[sky] = self.background(d[sky], jacobian)
        out.direction[rows] = np.where(sky[:, None], d, np.nan)
        if jacobian is not None:
            seen = self.camera.direction_tangents(self._image_xy(y[sky], x[sky]))
            out.magnification[rows[sky]] = magnification(seen, jacobian)
        disk = np.flatnonzero((ending == ENDING["hit"]) & (nodes.object_id[bj, bi] == DISK_ID))
        if disk.size:  # the disk's light at the interpolated radius and g
            sub = [(j[disk], i[disk]) for j, i in corners]
            rgb, on, g, position, seen = self._interpolate_disk(
                nodes, sub, [wk[disk] for wk in weights], y[disk], x[disk]
            )
            colour[disk[on], :3] = rgb[on]
            ending[disk[~on]] = -1  # off the disk between the nodes: traced
            at = rows[disk[on]]
            out.redshift[at], out.position[at], out.direction[at] = g[on], position[on], seen[on]
        hit = np.flatnonzero((ending == ENDING["hit"]) & (nodes.object_id[bj, bi] != DISK_ID))
        if hit.size:
            origins, _ = self.camera.rays_at(self._image_xy(y[hit], x[hit]))
            position, tangent = blend(nodes.position, hit), blend(nodes.tangent, hit)
            reach = REACH * s[hit] * self.pixel_angle * np.linalg.norm(position - origins, axis=1)
            found = self._recast(position, tangent, reach, nodes.object_id[bj[hit], bi[hit]])
            ok = found.hit
            colour[hit[ok]] = found.color[ok]
            ending[hit[~ok]] = -1  # missed its object (an edge): trace this point
            at = rows[hit[ok]]
            out.position[at] = found.position[ok]
            out.object_id[at], out.surface[at] = found.object_id[ok], found.color[ok]
            out.tangent[at] = tangent[ok]
            seen = found.position[ok] - origins[ok]
            out.direction[rows[hit[ok]]] = seen / np.linalg.norm(seen, axis=1, keepdims=True)
        moving = self.tracer.motion
        if moving is not None:  # static emitters seen by a moving camera (render.shade)
            surface = (ending == ENDING["hit"]) & (nodes.object_id[bj, bi] != DISK_ID)
            shifted = np.flatnonzero(sky | surface)
            _, seen = self.camera.rays_at(self._image_xy(y[shifted], x[shifted]))
            colour[shifted, :3] = doppler_shift(colour[shifted, :3], moving.colour_shift(seen))
        out.rgba[rows] = colour
        out.ending[rows] = ending
        shape = _error_shape(u, v)
        interpolation = np.einsum("mk,mk->m", blocks.deviation[b], shape)
        summed = np.matmul(shape[:, None, :], blocks.vectors[b])[:, 0]  # (M, 3)
        with np.errstate(invalid="ignore"):
            as_vector = np.sqrt(np.einsum("mc,mc->m", summed, summed))
        interpolation = np.where(np.isfinite(as_vector), as_vector, interpolation)
        out.error[rows] = blend(nodes.error[..., None])[:, 0] + interpolation

    def _recast(self, position, tangent, reach, object_id, footprint=None) -> Hits:
        """Hits of segments through interpolated hit points along their interpolated chord
        directions, ``reach`` (M,) world units either side; ``hit`` only where the first
        thing met is the block's object ``object_id`` (M,); coloured over ``footprint``
        (M, 2, 3) where given."""
        tangent = tangent / np.linalg.norm(tangent, axis=1, keepdims=True)
        reach = reach[:, None]
        a, b = position - reach * tangent, position + reach * tangent
        hits = self.tracer.geometry.cast(a, b, footprint)
        hits.hit &= hits.object_id == object_id
        return hits

    def _image_xy(self, y: np.ndarray, x: np.ndarray) -> np.ndarray:
        """Image points (M, 2) (column, row) of lattice points (y, x) of the current tile."""
        return np.stack([self._origin[1] + x + 0.5, self._origin[0] + y + 0.5], axis=1)

    def _supersample(self, nodes: _Nodes, blocks: _Blocks, busy, differs, near, centre,
                     cancel):  # fmt: skip
        """Filter-weighted colour (K, 4) of the ``busy`` pixels (h, w mask) from up to
        ``samples`` points each (interpolated where a block allows, traced elsewhere): the
        first FIRST_SAMPLES; the rest where those disagree with each other or with the
        centre's colour ``centre`` (K, 4) by > AA_CONTRAST, where a pixel and a neighbour it
        differs from both looked uniform (_edge_unseen), or where the centre's ray passed
        an object's bounds within the filter's footprint (``near``: a thin object or a star
        between the samples). Where no sample shows what the centre shows (within
        AA_CONTRAST), the centre's colour counts as one more sample: a sub-pixel image the
        centre's ray hit keeps a share (Preview shows it whole; 16 samples missed tiny
        images near a Kerr hole's photon ring that the centre hit, which kept 2-14 % of
        their light, issue 50); elsewhere the samples alone, unbiased. The pixels go in
        groups of at most SAMPLE_POINTS points (_pixel_groups)."""
        pj, pi = np.nonzero(busy)
        count = self.samples
        first = min(FIRST_SAMPLES, count)
        total, spread = np.zeros((pj.size, 4)), np.zeros(pj.size)
        norm, seen = np.zeros(pj.size), np.zeros(pj.size, dtype=bool)
        for rows in _pixel_groups(pj.size, first):
            colour, weight = self._sample(
                nodes, blocks, pj[rows], pi[rows], slice(0, first), cancel
            )
            total[rows] = np.einsum("pkc,pk->pc", colour, weight)
            norm[rows] = weight.sum(axis=1)
            apart = np.max(np.abs(colour - centre[rows, None, :]), axis=2)
            spread[rows] = np.max(apart, axis=1)
            seen[rows] = np.any(apart <= AA_CONTRAST, axis=1)
        uniform = np.ones(busy.shape, dtype=bool)
        uniform[pj, pi] = spread <= AA_CONTRAST
        more = ~uniform[pj, pi] | _edge_unseen(differs, uniform)[pj, pi] | near[pj, pi]
        more = np.flatnonzero(more)
        if more.size and first < count:
            for k in range(first, count, SAMPLE_POINTS):  # one round unless samples > that
                ks = slice(k, min(k + SAMPLE_POINTS, count))
                for rows in _pixel_groups(more.size, ks.stop - ks.start):
                    at = more[rows]
                    rest, weight = self._sample(nodes, blocks, pj[at], pi[at], ks, cancel)
                    total[at] += np.einsum("pkc,pk->pc", rest, weight)
                    norm[at] += weight.sum(axis=1)
                    near_centre = np.max(np.abs(rest - centre[at, None, :]), axis=2)
                    seen[at] |= np.any(near_centre <= AA_CONTRAST, axis=1)
        total[~seen] += centre[~seen]  # the centre's own, one sample's weight (filter_samples)
        norm[~seen] += 1.0
        return total / norm[:, None]

    def _sample(self, nodes: _Nodes, blocks: _Blocks, pj, pi, ks: slice, cancel):
        """Colours (P, K, 4) and filter weights (P, K) at the pixels (pj, pi) (tile pixels)
        of their samples ``ks`` (of ``stratified_points``, jittered per pixel)."""
        rows, columns = self._origin[0] + pj + 1, self._origin[1] + pi + 1
        k = _cells_per_side(self.samples)
        unit = pixel_samples(self.unit, ks, k, rows, columns)
        offsets, weight = filter_samples(unit, self.pixel_filter, self.filter_size)
        y = (pj[:, None] + 1 + offsets[:, :, 1]).ravel()
        x = (pi[:, None] + 1 + offsets[:, :, 0]).ravel()
        points = self._evaluate(nodes, blocks, y, x)
        todo = np.flatnonzero(points.ending < 0)
        if todo.size:
            xy = self._image_xy(y[todo], x[todo])
            rays, _, _ = self._trace_points(xy, cancel, False, node=False)
            points.rgba[todo] = self.shade(rays, self.background)
        return points.rgba.reshape(pj.size, -1, 4), weight


def _wrapped(angle: np.ndarray) -> np.ndarray:
    """Angles (radians) brought into [-pi, pi)."""
    return (angle + np.pi) % (2 * np.pi) - np.pi


def _node_margin(jj: np.ndarray, ii: np.ndarray, dense: bool) -> np.ndarray | float:
    """The share of the tracer's clearance margin (a coarsest block's) nodes (jj, ii)
    record theirs within: MARGIN_BLOCKS x the largest block they are one of the nine
    points of (blocks of s start at multiples of s: a node at multiples of p is a point of
    blocks of 2 p), DENSE_MARGIN pixels where no block will interpolate them (``dense``)."""
    if dense:
        return DENSE_MARGIN / STRIDE
    lattice = jj | ii | (STRIDE // 2)
    block = 2 * (lattice & -lattice)  # the lowest bit both share, at most STRIDE / 2
    return np.minimum(1.0, MARGIN_BLOCKS * np.maximum(block, DENSE_MARGIN) / STRIDE)


ANCHOR = 4
"""With the error pass, only the nodes at multiples of ANCHOR (the anchors) get their
companion as they are traced; the others take the largest error of the anchors at their
cell's corners where those end as they do (TileSampler._settle), or a companion of their
own then. The nodes of blocks of 8 and up are all anchors: what is spared is the
companions of the finest rounds, most of a tile's rays."""


def _anchors(jj: np.ndarray, ii: np.ndarray) -> np.ndarray:
    """(M,) bool: which nodes (jj, ii) are anchors (ANCHOR)."""
    return (jj % ANCHOR == 0) & (ii % ANCHOR == 0)


def _node_rays(nodes: _Nodes, jj, ii, origins: np.ndarray) -> RayResults:
    """The rays recorded at nodes (jj, ii) from ``origins``, as far as
    TileSampler._companion_error reads them (what they see, ending, object, steps)."""
    rays = RayResults.empty(jj.size, origins, nodes.direction[jj, ii])
    rays.ending, rays.object_id = nodes.ending[jj, ii], nodes.object_id[jj, ii]
    rays.position, rays.steps = nodes.position[jj, ii], nodes.steps[jj, ii]
    return rays


def _first_lattice(pixels: int, stride: int) -> int:
    """The spacing of the nodes _refine traces in its first round: stride / 2 (the points
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


def _block_nodes(sj: np.ndarray, si: np.ndarray, s: int, last) -> tuple[np.ndarray, np.ndarray]:
    """(jj, ii) every node of the blocks (sj, si) of size s up to row and column ``last``."""
    dj, di = (a.ravel() for a in np.mgrid[0 : s + 1, 0 : s + 1])
    jj, ii = (sj[:, None] + dj).ravel(), (si[:, None] + di).ravel()
    inside = (jj <= last[0]) & (ii <= last[1])
    return jj[inside], ii[inside]


def _block_points(bj: np.ndarray, bi: np.ndarray, s: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """The nine traced nodes of blocks of size s at (bj, bi): corners (top left, top right,
    bottom left, bottom right), the edges' midpoints (top, bottom, left, right), the centre."""
    h = s // 2
    return [(bj, bi), (bj, bi + s), (bj + s, bi), (bj + s, bi + s),
            (bj, bi + h), (bj + s, bi + h), (bj + h, bi), (bj + h, bi + s),
            (bj + h, bi + h)]  # fmt: skip


EDGES = ((4, (0, 1)), (5, (2, 3)), (6, (0, 2)), (7, (1, 3)))
"""_block_points' edge midpoints with their edges' ends: top, bottom (along x), left, right."""


def _edge_deviations(apart: Callable) -> np.ndarray:
    """(B, 5) from ``apart(k, ends)`` (_block_points' point k's deviation from the mean of
    points ``ends``, (B,)): the top, bottom, left and right edges' midpoints', and the
    centre's beyond what those make there (a quadratic map's is at most the mean of the two
    edges along x plus that of the two along y: more is a higher order)."""
    top, bottom, left, right = (apart(k, ends) for k, ends in EDGES)
    expected = 0.5 * (top + bottom + left + right)
    beyond = np.maximum(apart(8, (0, 1, 2, 3)) - expected, 0.0)
    return np.stack([top, bottom, left, right, beyond], axis=-1)


def _error_shape(u: np.ndarray, v: np.ndarray) -> np.ndarray:
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


def _smooth_magnification(nodes: _Nodes, nine, ending) -> np.ndarray:
    """(B,) blocks whose magnification pass may be interpolated (the nodes' ray differentials
    blended): not on the sky, or ln |μ| within MAGNIFICATION_SHARE of bilinear (the
    deviations of _edge_deviations, bounded as by _worst)."""
    with np.errstate(all="ignore"):
        values = [np.log(nodes.magnification[j, i]) for j, i in nine]

    def apart(k, ends):
        return np.abs(values[k] - sum(values[e] for e in ends) / len(ends))

    worst = _worst(_edge_deviations(apart))
    return (ending != ENDING["escaped"]) | (worst <= MAGNIFICATION_SHARE)


def _magnification(nodes: _Nodes, corners, width: float) -> np.ndarray:
    """(B,) how much wider than at the camera a block's rays spread at their ends (at
    least 1): the largest angle between its corners' final directions over their angle
    at the camera (``width`` radians along an edge, width sqrt 2 across); the bundle's
    spread on the way stays within the larger of the two (NaN: 1)."""
    (a, b, c, d) = (nodes.direction[j, i] for j, i in corners)
    edges = [angle_between(a, b), angle_between(c, d), angle_between(a, c), angle_between(b, d)]
    diagonals = [angle_between(a, d), angle_between(b, c)]
    ratio = np.maximum(np.max(edges, axis=0), np.max(diagonals, axis=0) / math.sqrt(2))
    return np.maximum(np.nan_to_num(ratio / width, nan=0.0), 1.0)


def _pixel_groups(pixels: int, samples: int):
    """Slices of ``pixels`` pixels with ``samples`` points each: at most SAMPLE_POINTS
    points a slice (one pixel at least)."""
    per = max(1, SAMPLE_POINTS // samples)
    return (slice(p, p + per) for p in range(0, pixels, per))


@dataclass
class _Points:
    rgba: np.ndarray
    ending: np.ndarray
    error: np.ndarray
    direction: np.ndarray
    redshift: np.ndarray
    position: np.ndarray
    magnification: np.ndarray
    transmittance: np.ndarray
    """1 where interpolated: blocks are only where nothing lies in front (_Nodes.plain)."""
    object_id: np.ndarray
    tangent: np.ndarray
    surface: np.ndarray


class _Blocks:
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


_NEIGHBOURS = [(dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1) if (dy, dx) != (0, 0)]


def _moves(slope: np.ndarray, move: np.ndarray):
    """The four offsets (M, 3) of points moved ``move`` (M,) pixels along +x, -x, +y and -y
    of the image, by their derivatives ``slope`` (M, 2, 3) along x and y (TileSampler._shaky)."""
    for k in (0, 1):
        for sign in (1.0, -1.0):
            yield (sign * move)[:, None] * slope[:, k]


def _neighbour_change(rgb: np.ndarray) -> np.ndarray:
    """(H, W) the largest difference in a channel between each pixel of ``rgb`` (H, W, 3)
    and its four neighbours (those inside the grid)."""
    change = np.zeros(rgb.shape[:2])
    for axis in (0, 1):
        step = np.max(np.abs(np.diff(rgb, axis=axis)), axis=-1)
        first = [slice(None), slice(None)]
        second = [slice(None), slice(None)]
        first[axis], second[axis] = slice(None, -1), slice(1, None)
        np.maximum(change[tuple(first)], step, out=change[tuple(first)])
        np.maximum(change[tuple(second)], step, out=change[tuple(second)])
    return change


def _contrast(rgba: np.ndarray, ending: np.ndarray) -> list[np.ndarray]:
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


def _edge_unseen(differs: list[np.ndarray], uniform: np.ndarray) -> np.ndarray:
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


def seen_direction(rays: RayResults, origins: np.ndarray) -> np.ndarray:
    """(N, 3) what a pixel's ray points at: the escape direction of an escaped ray, else
    the unit vector from the ray's origin to where it ended (a hit point)."""
    escaped = rays.ending == ENDING["escaped"]
    to_end = rays.position - origins
    with np.errstate(all="ignore"):
        to_end /= np.linalg.norm(to_end, axis=1, keepdims=True)
    return np.where(escaped[:, None], rays.direction, to_end)


HIT_ORDER = 4
"""Highest order assumed of a hit point's error in the step: a hit is where the method's
own partial step meets the surface (Tracer._surface_crossing), at the method's order, but
one whose crossing did not converge keeps the cubic Hermite path's point (tracing/dense.py,
fourth order). Conservative for a sixth-order method's hits (over-reported <= 63/15)."""


def shared_steps(fine: np.ndarray, coarse: np.ndarray) -> np.ndarray:
    """(N,) whether a run at COMPANION_RATIO x a ray's step took at least SHARED_STEPS x
    the steps of the run it checks (``fine``, ``coarse``: steps taken): near geometry both
    runs halve their steps, and where they halved to the same steps they share their error,
    which Richardson then does not see (measured: a disk hit 1.2e-4 rg off in both runs,
    estimated 1e-11 rad, benchmarks/honesty.py disk_high_spin)."""
    return coarse >= SHARED_STEPS * fine


def richardson_error(fine: RayResults, coarse: RayResults, origins, order: int) -> np.ndarray:
    """Richardson estimate of the fine run's error (radians, (N,)) from a run at
    COMPANION_RATIO x its step: the escape direction's, or for a hit its hit point's over
    its distance from the camera (``seen_apart``); pi where the endings or the objects hit
    differ, +inf where failed."""
    apart = seen_apart(
        seen_direction(fine, origins), fine.position, seen_direction(coarse, origins),
        coarse.position, fine.ending, origins,
    )  # fmt: skip
    alike = (fine.ending == coarse.ending) & (fine.object_id == coarse.object_id)
    return _richardson(apart, fine.ending, alike, order)


def seen_apart(seen_a, position_a, seen_b, position_b, ending, origins) -> np.ndarray:
    """(N,) radians between what two rays from ``origins`` see: for a hit (``ending``), the
    distance between the hit points over the first's distance from the camera (the pixel
    footprint there, at any angle of incidence: a grazing surface's hit point moves far
    while its direction barely turns); else the angle between the directions."""
    hit = ending == ENDING["hit"]
    with np.errstate(all="ignore"):
        gap = np.linalg.norm(position_a - position_b, axis=-1)
        moved = gap / np.linalg.norm(position_a - origins, axis=-1)
    return np.where(hit, moved, angle_between(seen_a, seen_b))


def _richardson(apart, ending_fine, alike, order: int) -> np.ndarray:
    """richardson_error from how far apart the two runs' ends are (radians, ``seen_apart``)
    and whether they end ``alike``. A hit point's error is taken to fall at most at
    HIT_ORDER, whatever the method's order."""
    orders = np.where(ending_fine == ENDING["hit"], min(order, HIT_ORDER), order)
    with np.errstate(all="ignore"):
        err = apart / (COMPANION_RATIO**orders - 1.0)
    err = np.where(ending_fine == ENDING["captured"], 0.0, err)
    err = np.where(alike, err, FLIP)  # an ending flip, captured or not
    bad = (ending_fine == ENDING["failed"]) | (ending_fine == ENDING["max_steps"])
    return np.where(bad | ~np.isfinite(err), np.inf, err)


def angle_between(u, v) -> np.ndarray:
    """Angle between vectors (..., 3), accurate for tiny angles (atan2 of |u x v| and u.v)."""
    cross = np.linalg.norm(np.cross(u, v), axis=-1)
    return np.arctan2(cross, np.einsum("...i,...i->...", u, v))

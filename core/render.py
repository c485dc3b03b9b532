"""core.render: a whole image in chunks (bounded memory), with passes and a summary.

Passes: ``error`` (estimated final-direction error in radians: the integration's, from a
companion run of every camera ray at twice the step, |d_h - d_2h| / (2^p - 1); the far
field's beyond the region; the image interpolation's (core.sampling); +inf where a ray
failed), ``error_px`` (the same in pixels of this camera), ``steps``, ``ending``
(``core.ENDING`` codes) and ``redshift`` (g = ν_obs / ν_emit of rays that end on the scene's
accretion disk, or first cross a translucent one; NaN elsewhere; core/tracing/disklight.py;
the pixel centre's, like the error). A disk of automatic exposure (``AccretionDisk.exposure``
None) gets one from a small probe render first (``disk_exposure``); the summary's
``disk_exposure`` is the exposure used. Failed rays are drawn in ``FAILED_COLOR`` and rays
that ran out of steps in ``MAX_STEPS_COLOR``, never as a plausible colour.
"""

from __future__ import annotations

import copy
import math
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field, replace
from functools import partial
from typing import Any

import numpy as np

from . import checks, cluster
from . import sampling as sampling_module
from . import workers as workers_module
from .backend import CPU, Device, device_of
from .blackbody import XYZ_FROM_RGB
from .geometry import Group, Intersector
from .geometry.group import member_bounds
from .imageio import FAILED_COLOR
from .mipmap import span_footprint
from .motion import check_observer, observer_motion
from .motion import shift as doppler_shift
from .observer import ObserverError, check_camera
from .passes import (
    ALL_PASSES,
    BY_NAME,
    DEFAULT_PASSES,
    ON_REQUEST,  # noqa: F401 (core.render.ON_REQUEST: the passes asked for by name)
    OPTIONAL,
    STORED,
    traced_passes,
)
from .sampling import (
    CLEARANCE,
    COMPANION_RATIO,
    FILTERS,
    STRIDE,
    Tile,
    TileResult,
    TileSampler,
    richardson_error,
    seen_direction,
    tiles,
)
from .sky import Background
from .star_images import draw_stars
from .stars import StarField
from .tolerances import TRACE_SHARE, Tolerances
from .tracing import ENDING, RayResults, Scene, TraceOptions, Tracer
from .tracing.plan import PlacedPlan
from .tracing.scene import DISK_ID
from .tracing.segments import filter_surfaces
from .tracing.shared_rounds import SharedRounds
from .tracing.steps import DEFAULT_METHOD

MAX_STEPS_COLOR = (0.0, 1.0, 1.0, 1.0)
"""Debug colour of rays that reached max_steps without ending (cyan)."""
_MIN_CHUNK = 2048
DEVICE_CHUNK = 1 << 21
"""Rays a device traces at once (a 1080p frame in one batch; about 2 GB of GPU memory
with the error pass's companion)."""
_CAMERA_CHUNK = 1 << 16
"""Pixels per chunk of a pass computed from camera rays alone (doppler): memory bounded."""
TILES_PER_WORKER = 2
"""Tiles per worker, one worker's (its tiles share their rounds: tile_groups) or from
BALANCE_FROM workers: the work of a frame is rarely even over its rows (the hole, the
photon ring), and a worker with a second tile to take evens it out; each tile costs a few
batches' per-step overhead ..."""
BALANCE_FROM = 8
"""... which outweighs the imbalance below this many workers: two to seven take one tile
each. Measured (docs/performance.md, stop 62): two workers, every scene of
benchmarks/honesty.py at 640 x 360, 3-35 % faster with one band each, none slower (nor a
hole at the top or in a corner of the frame); the Kerr board's tiles simulated
(benchmarks/scaling.py): 640 x 360 at 2, 3, 4 workers 66, 48, 50 % -> 82, 66, 58 % of
linear, 1080p at 3 and 4 workers 80 -> 95 % and 84 -> 83 %, at 8 67 -> 51 % (so two tiles
from 8 on)."""
TILE_ROUNDS = 6
"""... and a worker gets a second tile only where each keeps at least the pixels of
TILE_ROUNDS rounds (core.sampling.quadtree.ROUND_RAYS each: its refine's, retraces and
centres) at the ~0.5 rays a pixel most scenes trace (benchmarks/honesty.py at 160 x
120)."""
SQUARES_FROM = 8
"""Near-square tiles replace bands only from this many tiles (4 workers on): with fewer,
a band's extra lattice rows cost little and the squares gained nothing measurable (1080p
Kerr board Preview, 2 workers, 3 alternated runs: bands 9.93-11.17 s, 4 squares of 960 x
544 9.86-11.42 s)."""
PROBE_SCALE = 1 / 8
"""Automatic disk exposure: the probe render's size per side, relative to the frame's
(rounded up: the Rendered viewport's first level, core.viewport, is this probe) ..."""
PROBE_MIN_SIDE = 64
"""... but at least this many pixels on its longer side (at most the frame's)."""
PROBE_DISK_PIXELS = 1500
"""The disk pixels the probe looks for (fewer: the disk's rectangle is probed finer)."""


@dataclass
class RenderResult:
    """An image (row 0 at the top), its passes and a summary of the run."""

    rgba: np.ndarray
    passes: dict = field(default_factory=dict)
    summary: dict = field(default_factory=dict)
    cancelled: bool = False


def render(
    scene: Scene,
    camera,
    *,
    method: Any = None,
    tolerance: float = 1e-8,
    tolerance_px: float | None = None,
    samples: int = 1,
    pixel_filter: str = "blackman_harris",
    filter_size: float = 1.5,
    step: float | None = None,
    max_steps: int = 20_000,
    passes: Sequence[str] = DEFAULT_PASSES,
    chunk_size: int = 16_384,
    workers: int | None = None,
    parallel: str = "auto",
    cores: int | None = None,
    progress: Callable[[int, int], None] | None = None,
    should_cancel: Callable[[], bool] | None = None,
    on_tile: Callable[[tuple[int, int, int, int], RenderResult], None] | None = None,
    observer: Any = "static",
    shift_colours: bool = True,
    client: Any = None,
    device: str | Device = "cpu",
    interpolate: bool = True,
) -> RenderResult:
    """Render ``scene`` seen by ``camera`` (docs/design.md, "Rendering in the core").

    ``tolerance_px`` (pixels of this camera; replaces ``tolerance``, radians) turns on
    adaptive sampling (core.sampling): rays where the image needs them, interpolation
    where it stays within tolerance. ``samples`` > 1: up to that many camera rays per
    pixel where the contrast asks for them (anti-aliasing with ``pixel_filter`` "box" or
    "blackman_harris" of width ``filter_size`` pixels, as Cycles). The image is traced in
    chunks (tiles when sampling) by ``workers`` forked processes or threads
    (``parallel``: "auto", "processes", "threads"; see core.workers); without
    ``workers``, one process per core (at most ``cores``) or two threads.
    ``progress(done, total)`` (pixels), ``should_cancel()`` and ``on_tile((x0, y0, x1,
    y1), part)`` (a finished tile's pixels, row 0 at the top) are called from the
    caller's thread, or from the worker threads when there are threads.
    ``observer``: who looks through the camera (core.motion): "static" (Kerr: the
    zero-angular-momentum observer), "orbit" (the prograde circular geodesic through the
    camera), "infall" (falling from rest at infinity) or a 3-velocity (vx, vy, vz) (units of
    c, world axes) relative to the static one; ``shift_colours`` False keeps the colours
    (and the disk's g) of the static observer, with the moving one's aberration.
    ``client`` (a dask.distributed Client, optional) runs the chunks as tasks on its
    cluster (core.cluster); ``workers`` then defaults to the cluster's threads and sets
    the tiling, so the image equals a local render's with the same ``workers``, bit for
    bit. The disk's exposure probe stays local.
    ``device``: "cpu" (numpy) or "cuda" (CuPy: core.backend; a core.backend.Device for
    tests). On a device the frame is traced in as few batches as ``DEVICE_CHUNK`` allows,
    one pixel-centre ray each (with ``tolerance_px``: every pixel at the step the sampler
    would take, no interpolation), the intersectors and the shading on the host; images
    equal the CPU's dense render at the same step. ``samples`` > 1 and ``client`` are
    refused there.
    ``interpolate`` False (with ``tolerance_px``): every pixel centre traced, nothing
    interpolated, with the same promise (the same step, the error pass, rays over their
    budget or near a miss traced again): what the adaptive image is weighed against.
    """
    passes = _check_render_call(passes, chunk_size, workers, cores, interpolate)
    dev = _device_for_render(device, samples, client)
    cluster_threads = cluster.check_client(client) if client is not None else None
    _check_sampling(tolerance_px, samples, pixel_filter, filter_size)
    check_observer(observer)
    pixel_angle = camera.pixel_angle(_camera_distance(scene, camera))
    tol = Tolerances.of(tolerance, tolerance_px, pixel_angle)  # made once, used throughout
    options = TraceOptions(method=method, tolerance=tol.trace, step=step, max_steps=max_steps)
    start_time = time.perf_counter()
    values = (method, step, max_steps, workers, parallel, cores, should_cancel, observer,
              shift_colours)  # fmt: skip
    probe = dict(zip(PROBE_OPTIONS, values, strict=True))
    scene = disk_exposure(scene, camera, **probe)
    objects = scene.intersector()  # built once: its members' bounds give the extent too
    extent = _scene_extent(scene, camera, objects)
    options = camera_options(scene, options, extent, camera.frame.position)
    placed = PlacedPlan(scene, options, extent)  # no geometry yet: checks and motion
    if placed.curved:
        checks.check_render_method(placed.method, time_scaled(placed.model))
    check_camera(placed, camera.frame.position)
    moving = observer_motion(observer, placed, camera.frame.position, shift_colours)
    if moving is not None:  # the tolerances hold in the static frame (core.motion)
        tol = tol.narrowed(min(1.0, moving.smallest_doppler(camera)), tolerance)
        options = replace(options, tolerance=tol.trace)
    tracer = Tracer(scene, options, extent, objects)  # built once
    tracer.set_motion(moving)
    tol = tol.for_plan(tracer, interpolate)
    background = Background.of(scene.background)
    n = camera.n_pixels
    # with tolerance_px the companion run always goes: its estimate picks the rays to redo
    with_error = "error" in passes or "error_px" in passes or tolerance_px is not None
    with_error = with_error and tracer.curved
    with_tangents = "magnification" in passes
    if with_tangents:  # refused by name before anything is traced
        tracer.check_tangents()
        camera.direction_tangents(np.zeros((1, 2)))
    image = _Buffers(n, with_error, camera.width, passes, tol.pixel_angle)
    image.hold_stars(background, camera)
    image.camera, image.motion = camera, moving
    kind, count = _where_chunks_run(parallel, workers, n, cores, cluster_threads)
    sampled = samples > 1 or (tolerance_px is not None and tracer.curved)
    if not dev.on_host:  # every pixel centre, in batches as large as the device holds
        sampled, kind, count, chunk_size = False, "inline", 1, DEVICE_CHUNK
    if sampled:
        if tol.interpolation > 0 or samples > 1 or not interpolate:  # near misses too
            tracer.watch_geometry(_watch_margin(tracer, camera, tol.pixel_angle))
        sampler = TileSampler(
            tracer, camera, background, shade, tol, samples=samples,
            pixel_filter=pixel_filter, filter_size=filter_size, with_error=with_error,
            tangents=with_tangents, magnification=with_tangents,
        )  # fmt: skip
        tile_list = _tiles_for(camera, count)
        middles = [((t.x0 + t.x1) / 2, (t.y0 + t.y1) / 2) for t in tile_list]
        groups = tile_groups(tile_list, expected_cost_rank(camera, scene.center, middles), count)
        chunks = [(k, k + 1) for k in range(len(groups))]  # costliest first
        work = _tile_work(sampler, tile_list, groups)
    else:
        chunks = _span_chunks(n, chunk_size, count)
        work = _span_work(tracer, camera, with_error, tol.far_field, with_tangents, dev)
        middles = [(camera.width / 2, (a + b) / 2 / camera.width) for a, b in chunks]
        chunks = costliest_first(chunks, expected_cost_rank(camera, scene.center, middles))
    cancelled = workers_module.CancelLatch(should_cancel)
    finished = _run(work, chunks, kind, count, cancelled, client)
    done = _store_chunks(finished, image, background, passes, on_tile, progress)
    was_cancelled = done < n or cancelled()
    image.draw_stars(pixel_filter, filter_size, tracer, was_cancelled)
    result = image.result(camera, passes, time.perf_counter() - start_time, was_cancelled, tracer)
    result.summary["parallel"] = f"{count} {kind}" if kind != "inline" else "inline"
    result.summary["device"] = dev.name
    result.summary["pixel_angle"] = tol.pixel_angle
    if scene.disk is not None:
        result.summary["disk_exposure"] = scene.disk.exposure
    _summarise_px(result.summary, tol.pixel_angle)
    return result


PROBE_OPTIONS = ("method", "step", "max_steps", "workers", "parallel", "cores", "should_cancel",
                 "observer", "shift_colours")  # fmt: skip
"""core.render's options that its exposure probe takes too (disk_exposure's keywords)."""


def auto_exposure(scene: Scene, camera, **options: Any) -> float | None:
    """The automatic exposure core.render(scene, camera, **options) gives the scene's disk
    (its summary's ``disk_exposure``), without the render; None without a disk of automatic
    exposure. ``options``: any of core.render's (those outside PROBE_OPTIONS are ignored)."""
    if scene.disk is None or scene.disk.exposure is not None:
        return None
    probe = {name: value for name, value in options.items() if name in PROBE_OPTIONS}
    disk = disk_exposure(scene, camera, **probe).disk
    return None if disk is None or disk.exposure is None else float(disk.exposure)


def disk_exposure(scene: Scene, camera, **probe: Any) -> Scene:
    """``scene`` with its disk's automatic exposure (``exposure`` None) chosen: a copy whose
    disk has ``disk.exposure_for`` the median luminance of the disk's pixels in a probe
    render (``scene`` itself when there is nothing to choose): ``exposure_probe``'s
    ``exposed``. ``probe``: the render's method, step, max_steps, workers, parallel, cores
    and should_cancel."""
    found = exposure_probe(scene, camera, **probe)
    return scene if found is None else found.exposed(scene)


@dataclass(frozen=True)
class ExposureProbe:
    """The disk's pixels in disk_exposure's probe render: their redshift g, Boyer–Lindquist
    radius and luminance (at brightness 1 and exposure 1)."""

    g: np.ndarray
    radius: np.ndarray
    luminance: np.ndarray

    def exposed(self, scene: Scene) -> Scene:
        """``scene`` (its disk's automatic exposure, in its look) with the exposure chosen
        from these pixels: an opaque disk's luminance is the colour of its g and r in
        ``scene``'s look (a change of look needs no new probe), a translucent one's as
        rendered."""
        disk = scene.disk
        if disk is None or disk.exposure is not None:
            return scene
        luminance = self.luminance
        if disk.opacity >= 1.0 and self.g.size:
            seen = replace(disk, brightness=1.0, exposure=1.0)
            luminance = seen.colour(self.g, self.radius) @ XYZ_FROM_RGB[1]
        median = float(np.median(luminance)) if luminance.size else math.nan
        exposed = copy.copy(scene)
        exposed.disk = replace(disk, exposure=disk.exposure_for(median))
        return exposed


def exposure_probe(
    scene: Scene, camera, first: tuple | None = None, **probe: Any
) -> ExposureProbe | None:
    """The probe render of an automatic disk exposure (None: the scene has no disk, or its
    exposure is set).

    The probe sees the whole frame (whatever the camera's border region: every part of a
    frame gets the same exposure) at PROBE_SCALE of its size per side (at least
    PROBE_MIN_SIDE pixels on the longer side; ``probe_camera``), one ray through each pixel
    centre at the Preview tolerance (half a probe pixel), with the disk at brightness 1 and
    exposure 1 and a black sky; the disk's pixels are those with a finite redshift. Where
    fewer than PROBE_DISK_PIXELS show the disk, the rectangle around them is probed again,
    finer, so that about that many do (the median's sampling error, ~1/√n of the
    luminances' spread). Deterministic: the same scene and camera give the same pixels.
    ``first``: the first probe's (disk pixels, g, hit points, luminance) when the caller
    has rendered probe_camera's view already (each (h, w) or (h, w, 3); an opaque disk's
    luminance is not used)."""
    disk = scene.disk
    if disk is None or disk.exposure is not None:
        return None
    seen = copy.copy(scene)
    seen.disk = replace(disk, brightness=1.0, exposure=1.0)
    seen.background = (0.0, 0.0, 0.0)
    width, height = camera.full_size
    stage = probe_camera(camera)
    size = stage.full_size
    found = first if first is not None else _probe(seen, stage, probe)
    on = found[0]
    count = int(np.count_nonzero(on))
    finer = math.ceil(math.sqrt(PROBE_DISK_PIXELS / max(count, 1)))
    finer = min(finer, max(width // size[0], 1), max(height // size[1], 1))
    if 0 < count < PROBE_DISK_PIXELS and finer > 1:
        rows, cols = np.nonzero(on)  # row 0 at the top; the region counts from the bottom
        h = size[1]
        box = (
            max(cols.min() - 1, 0) * finer, min(cols.max() + 2, size[0]) * finer,
            max(h - rows.max() - 2, 0) * finer, min(h - rows.min() + 1, h) * finer,
        )  # fmt: skip
        found = _probe(seen, camera.resized(size[0] * finer, size[1] * finer, box), probe)
    on, g, position, luminance = found
    return ExposureProbe(g[on], scene.disk_radius(position[on]), luminance[on])


def probe_camera(camera):
    """The camera of exposure_probe's first render: the whole frame at PROBE_SCALE of its
    size per side, rounded up (at least PROBE_MIN_SIDE on the longer side)."""
    width, height = camera.full_size
    scale = min(1.0, max(PROBE_SCALE, PROBE_MIN_SIDE / max(width, height)))
    return camera.resized(max(1, math.ceil(width * scale)), max(1, math.ceil(height * scale)))


def _probe(scene: Scene, camera, probe: dict) -> tuple[np.ndarray, ...]:
    """(disk pixels (h, w) bool, g (h, w), hit points (h, w, 3), luminance (h, w)) of
    ``camera`` at half a pixel's tolerance (core.render with ``probe``'s arguments)."""
    angle = camera.pixel_angle(_camera_distance(scene, camera))
    out = render(scene, camera, tolerance=TRACE_SHARE * angle, passes=("redshift", "position"),
                 **probe)  # fmt: skip
    luminance = out.rgba[..., :3].astype(np.float64) @ XYZ_FROM_RGB[1]
    g = np.asarray(out.passes["redshift"], dtype=np.float64)
    position = np.asarray(out.passes["position"], dtype=np.float64).reshape(g.shape + (3,))
    return np.isfinite(g), g, position, luminance


def _span_work(
    tracer: Tracer, camera, with_error: bool, far_field: float, tangents: bool,
    device: Device = CPU,
):  # fmt: skip
    """A chunk of flat pixel indices: one ray through each pixel centre (with its ray
    differentials where ``tangents``), traced on ``device``."""

    def work(span, cancel):
        if cancel():
            return None
        origins, directions = camera.rays(*span)
        seen = camera.direction_tangents(camera.pixel_centres(*span)) if tangents else None
        chunk = _trace_chunk(
            tracer, origins, directions, with_error, cancel, far_field, seen, device
        )
        if cancel():
            return None
        filter_surfaces(tracer.geometry, chunk[0], span[0], camera.width)
        return chunk

    return work


def _tile_work(sampler: TileSampler, tile_list: list[Tile], groups: list[list[int]]):
    """A chunk (k, k + 1): group k's tiles, adaptively sampled together -> [(tile, its
    part), ...]. The tiles a process renders at once (a group's, and those of a pool of
    threads) trace their rounds as shared batches (core.tracing.shared_rounds)."""

    shared = SharedRounds()  # a process's threads (a group's, or a thread pool's) share it

    def work(span, cancel):
        if cancel():
            return None
        members = [tile_list[k] for k in groups[span[0]]]
        if len(members) == 1:
            with shared.member():
                parts = [sampler.render_tile(members[0], cancel)]
        else:
            parts = shared.run([partial(sampler.render_tile, tile, cancel) for tile in members])
        return None if cancel() else list(zip(members, parts, strict=True))

    return work


def tile_groups(tile_list: list[Tile], ranks: Sequence[int], workers: int) -> list[list[int]]:
    """The tiles (indices into ``tile_list``) each chunk renders together, the costliest
    first (``ranks``, expected_cost_rank). One worker renders its tiles together, as many
    at a time as MAX_TILE_PIXELS holds (a group's tiles are in memory at once), their
    rounds traced in shared batches (core.tracing.shared_rounds): it pays one tile's
    per-step overhead a round, not each tile's. Several workers take their tiles one by
    one: a worker with a group of its own could not even out what the others take
    (fixed pairs of a costly and a cheap tile, two workers at 640 x 360: 5-24 % faster on
    seven scenes of make bench-honesty, 13 % slower where the expected cost misjudged
    the tiles, orbit_disk; docs/performance.md)."""
    order = costliest_first(list(range(len(tile_list))), ranks)
    if workers > 1:
        return [[k] for k in order]
    most = sampling_module.tiling.MAX_TILE_PIXELS
    groups: list[list[int]] = [[]]
    pixels = 0
    for k in order:
        size = tile_list[k].shape[0] * tile_list[k].shape[1]
        if groups[-1] and pixels + size > most:
            groups.append([])
            pixels = 0
        groups[-1].append(k)
        pixels += size
    return groups


def _store_chunks(finished: Iterator, image: _Buffers, background: Background, passes,
                  on_tile, progress) -> int:  # fmt: skip
    """Store each finished chunk (a group's tiles one by one), telling ``on_tile`` and
    ``progress`` of each; -> the pixels filled."""
    done = 0
    for span, chunk in finished:
        for piece in [] if chunk is None else chunk if isinstance(chunk, list) else [chunk]:
            done += image.store(span, piece, background)
            if on_tile is not None:
                on_tile(*image.part(span, piece, passes))
            if progress is not None:
                progress(done, image.n)
    return done


def _run(work, chunks: list, kind: str, count: int, cancelled, client) -> Iterator:
    """(span, chunk) as each chunk finishes: on the cluster (kind "dask", chunks in
    ``chunks``' order of priority) or workers_module.run_chunks."""
    if kind == "dask":
        priorities = list(range(len(chunks), 0, -1))
        return cluster.run_on_client(client, work, chunks, priorities, cancelled)
    return workers_module.run_chunks(work, chunks, kind, count, cancelled)


def _where_chunks_run(parallel, workers, n, cores, cluster_threads) -> tuple[str, int]:
    """-> (kind, worker count): workers_module.choose's, or ("dask", ``workers`` or the
    cluster's threads) where there is a cluster (``cluster_threads`` not None)."""
    if cluster_threads is not None:
        workers_module.choose(parallel, workers, n, cores)  # the same arguments refused
        return "dask", workers or cluster_threads
    return workers_module.choose(parallel, workers, n, cores)


def _span_chunks(n: int, chunk_size: int, count: int) -> list[tuple[int, int]]:
    """The flat pixel spans of an image traced without sampling: at least two chunks per
    worker (a small image still keeps every core busy), but not below _MIN_CHUNK rays
    (per-step work is Python overhead on small batches)."""
    size = max(_MIN_CHUNK, min(chunk_size, -(-n // (2 * count))))
    return [(s, min(s + size, n)) for s in range(0, n, size)]


def expected_cost_rank(camera, centre, middles: Sequence[tuple[float, float]]) -> list[int]:
    """Each chunk's rank by its expected cost, the costliest highest: rays passing nearer
    the scene's centre (its hole, lens or medium) bend more and take more steps. ``middles``:
    each chunk's middle as an image point (x, y) in pixels."""
    origins, directions = camera.rays_at(np.asarray(middles, dtype=np.float64))
    towards = np.asarray(centre, dtype=np.float64) - origins
    along = np.einsum("ij,ij->i", towards, directions)
    miss = np.linalg.norm(towards - along[:, None] * directions, axis=1)
    miss = np.where(along > 0, miss, np.linalg.norm(towards, axis=1))  # looking away
    order = np.argsort(-miss, kind="stable")  # farthest first: rank 0
    rank = np.empty(len(middles), dtype=np.int64)
    rank[order] = np.arange(len(middles))
    return rank.tolist()


def costliest_first(chunks: list, ranks: Sequence[int]) -> list:
    """``chunks`` in the order workers take them: the highest ``ranks`` (expected cost,
    ``expected_cost_rank``) first, so that the last to finish are cheap ones (a frame's
    hole band taken last kept every other worker waiting)."""
    order = sorted(range(len(chunks)), key=lambda k: -ranks[k])
    return [chunks[k] for k in order]


def _tiles_for(camera, workers: int) -> list[Tile]:
    """The image's tiles: TILES_PER_WORKER per worker with one worker or from BALANCE_FROM
    workers, else one (and one where a tile would be under TILE_ROUNDS' pixels), at most
    MAX_TILE_PIXELS each: bands of whole rows (the width split only past
    MAX_TILE_PIXELS), of equal height, or as many near-square tiles of
    whole coarsest blocks where their lattices hold fewer nodes (many workers: a thin band
    traces two or three lattice rows for its one block row; 1080p at 16 workers: 34-row
    bands, 32 tiles' work 42.8 s, squares of 256 x 288 28.9 s). A band's lattice may run
    past its last row: only blocks reaching the band are refined. Every
    round of a tile's quadtree is one batch, whose per-step overhead is paid per round
    whatever its size: fewer, larger tiles cost less, more balance the workers better
    (the Kerr board at 1080p Preview, traced in one process: 4 tiles 15 s, 16 tiles 22 s,
    32 tiles 30 s, 70 tiles 43 s; benchmarks/scaling.py)."""
    w, h, stride = camera.width, camera.height, sampling_module.lattice.STRIDE
    most = sampling_module.tiling.MAX_TILE_PIXELS
    cols = w if w * (2 * stride - 1) <= most else stride * max(2, most // (2 * stride**2)) - 1
    least = max(1, 2 * TILE_ROUNDS * sampling_module.quadtree.ROUND_RAYS)  # pixels a tile
    wanted = TILES_PER_WORKER if workers == 1 or workers >= BALANCE_FROM else 1
    per_worker = min(wanted, max(1, w * h // (workers * least)))
    bands = max(per_worker * workers, math.ceil(h * cols / most))
    bands = min(bands, math.ceil(h / (stride - 1)))  # bands of at least STRIDE - 1 rows
    band = (cols, math.ceil(h / bands))
    square = _square_tile(w, h, bands, stride)
    if (
        bands >= SQUARES_FROM
        and square[0] * square[1] <= most
        and _lattice_nodes(w, h, square) < _lattice_nodes(w, h, band)
    ):
        return tiles(w, h, *square)
    return tiles(w, h, *band)


def _square_tile(w: int, h: int, count: int, stride: int) -> tuple[int, int]:
    """(width, height) of a grid of ``count`` to 10 % more tiles of whole coarsest blocks
    (``stride`` pixels) a side whose lattices hold the fewest nodes (the squarest)."""
    shapes = []
    for across in range(1, count + 1):
        down = math.ceil(count / across)
        shape = (stride * math.ceil(w / across / stride), stride * math.ceil(h / down / stride))
        if count <= math.ceil(w / shape[0]) * math.ceil(h / shape[1]) <= math.ceil(1.1 * count):
            shapes.append((_lattice_nodes(w, h, shape), shape))
    return min(shapes)[1] if shapes else (w, h)


def _lattice_nodes(w: int, h: int, shape: tuple[int, int]) -> int:
    """Coarsest lattice nodes the tiles of ``shape`` (width, height) trace over a w x h
    image: each tile its own, its borders included (shared borders traced twice)."""
    stride = sampling_module.lattice.STRIDE
    tw, th = min(shape[0], w), min(shape[1], h)
    per_tile = (math.ceil(tw / stride) + 1) * (math.ceil(th / stride) + 1)
    return math.ceil(w / tw) * math.ceil(h / th) * per_tile


def _check_sampling(tolerance_px, samples, pixel_filter, filter_size) -> None:
    """ValueError for sampling options out of range."""
    if tolerance_px is not None:
        checks.check_positive("tolerance_px", tolerance_px)
        if not 1e-9 <= tolerance_px <= 100:
            raise ValueError(f"tolerance_px must lie in [1e-9, 100] pixels, got {tolerance_px}")
    checks.check_int("samples", samples)
    if samples > 1024:
        raise ValueError(f"samples must lie in [1, 1024], got {samples}")
    if pixel_filter not in FILTERS:
        raise ValueError(f"pixel_filter must be one of {FILTERS}, got {pixel_filter!r}")
    checks.check_positive("filter_size", filter_size)
    if not 0.01 <= filter_size <= 2.0:
        raise ValueError(f"filter_size must lie in [0.01, 2] pixels, got {filter_size}")


def _camera_distance(scene: Scene, camera) -> float:
    """Distance from the camera to the scene's centre (an orthographic pixel's angle)."""
    return float(max(np.linalg.norm(camera.frame.position - scene.center), 1e-9))


def _watch_margin(tracer: Tracer, camera, pixel_angle: float) -> float:
    """World margin around each object beyond which a ray counts as clear of it: a
    coarsest block (core.sampling.STRIDE pixels) seen at the farthest finite corner of the
    objects' boxes (an infinite side, a plane's, counts at the camera's coordinate)."""
    boxes = tracer.geometry.boxes()
    if not boxes:
        return 0.0
    eye = camera.frame.position
    sides = (np.array([box[i] for box in boxes], float) for i in (0, 1))  # lo, hi (K, 3)
    reach = [np.abs(np.where(np.isfinite(x), x, eye) - eye) for x in sides]
    far = float(np.max(np.linalg.norm(np.maximum(*reach), axis=1)))  # each box's farthest corner
    return CLEARANCE * STRIDE * pixel_angle * far


def _summarise_px(summary: dict, pixel_angle: float) -> None:
    """Add the error summary in pixels (error_px_median, error_px_max)."""
    for key in ("median", "max"):
        value = summary.get(f"error_{key}")
        summary[f"error_px_{key}"] = None if value is None else value / pixel_angle


def _check_render_call(passes, chunk_size, workers, cores, interpolate) -> tuple[str, ...]:
    """ValueError (TypeError for ``interpolate``) for what core.render refuses beyond
    TraceOptions; -> the passes."""
    if not isinstance(interpolate, bool):
        raise TypeError(f"interpolate must be True or False, got {interpolate!r}")
    passes = tuple(passes)
    unknown = set(passes) - set(ALL_PASSES)
    if unknown:
        raise ValueError(f"unknown passes {sorted(unknown)}; choose from {ALL_PASSES}")
    checks.check_int("chunk_size", chunk_size)
    checks.check_optional(checks.check_int, "workers", workers)
    checks.check_optional(checks.check_int, "cores", cores)
    return passes


def time_scaled(model) -> bool:
    """Whether a model's rays are integrated with a Poincaré time scale g(q) (not 1)."""
    return bool(model.scales_time)


def check_scene_camera(scene: Scene, position, tolerance: float = 1e-8) -> None:
    """Raise the core.ObserverError that rendering ``scene`` from ``position`` would meet
    (camera inside a horizon or on a coordinate axis, metric singular or of the wrong
    signature there); nothing for a camera where rays can start. Plans the trace only (no
    tracer, no geometry): the add-on asks at every panel redraw."""
    far = max(float(np.linalg.norm(np.asarray(position, dtype=np.float64) - scene.center)), 1e-9)
    options = camera_options(scene, TraceOptions(tolerance=tolerance), far, position)
    check_camera(PlacedPlan(scene, options, far), position)


def camera_options(scene: Scene, options: TraceOptions, extent: float, position) -> TraceOptions:
    """``options``; with the default method (options.method None) and a model whose
    explicit split cannot start rays at the camera (Kerr's Boyer–Lindquist split: a camera
    on the polar axis, where Kerr–Schild still can), the implicit default (DEFAULT_METHOD)
    in the model's own chart instead."""
    if options.method is not None or not scene.curved:
        return options
    placed = PlacedPlan(scene, options, extent)
    if not placed.method.needs_split:
        return options
    try:
        with np.errstate(all="ignore"):
            check_camera(placed, position)
    except ObserverError:
        return replace(options, method=DEFAULT_METHOD)
    return options


def tracer_for_camera(scene: Scene, options: TraceOptions, extent: float, position) -> Tracer:
    """The scene's tracer, with the method ``camera_options`` picks for a camera at
    ``position``."""
    return Tracer(scene, camera_options(scene, options, extent, position), extent)


def _trace_chunk(
    tracer: Tracer, origins, directions, with_error: bool, cancel, far_field=0.0, tangents=None,
    device: Device = CPU,
):  # fmt: skip
    """Trace one chunk on ``device`` (with ``tangents``: the directions' derivatives along
    the image, for the magnification pass); with the error pass, a companion run at
    COMPANION_RATIO x the step."""
    rays = _traced_on(device, tracer, origins, directions, cancel=cancel, tangents=tangents)
    seen = seen_direction(rays, origins)
    if not with_error:
        return rays, seen, None
    assert tracer.step is not None and tracer.order is not None  # with_error: curved
    companion = COMPANION_RATIO * tracer.step
    coarse = _traced_on(device, tracer, origins, directions, step=companion, cancel=cancel)
    error = richardson_error(rays, coarse, origins, tracer.order)
    return rays, seen, error + np.where(rays.ending == ENDING["escaped"], far_field, 0.0)


def _traced_on(device: Device, tracer: Tracer, origins, directions, **options) -> RayResults:
    """``tracer.trace`` of host rays on ``device``: the rays (and tangents) go there, their
    results come back (core.backend)."""
    if device.on_host:
        return tracer.trace(origins, directions, **options)
    tangents = options.pop("tangents", None)
    if tangents is not None:
        options["tangents"] = device.to_device(tangents)
    return tracer.trace(
        device.to_device(origins), device.to_device(directions), **options
    ).to_host()


def _device_for_render(device: str | Device, samples: int, client: Any) -> Device:
    """The Device ``core.render``'s ``device`` names; ValueError for what a device
    render does not take (``samples`` > 1, a cluster ``client``)."""
    dev = device_of(device)
    if not dev.on_host and samples > 1:
        raise ValueError(
            f"samples > 1 (anti-aliasing) runs on the CPU only; device {dev.name!r} traces "
            "one ray per pixel centre"
        )
    if not dev.on_host and client is not None:
        raise ValueError(f"a cluster client renders on the CPU; got device {dev.name!r}")
    return dev


class _Buffers:
    """Flat per-pixel buffers filled chunk by chunk (spans of flat indices, or tiles).

    Only the output's: the energy error is kept as its running maximum, the seen
    directions only for the ``direction`` pass. They are allocated at the first chunk
    stored, after the worker processes have forked: a worker forked with them would keep
    the original of every page the caller then writes (copy-on-write), a full-frame copy
    of what was filled before the fork (measured: 17 bytes a pixel in the workers, 20 in
    the caller, that grew with the image).
    """

    def __init__(self, n: int, with_error: bool, width: int, passes, pixel_angle: float):
        self.n = n
        self.pixel_angle = pixel_angle
        self.camera: Any = None
        self.motion: Any = None  # the camera's (core.motion), for the doppler pass
        self.stars: StarField | None = None  # point stars, drawn on the finished frame
        self.star_images: int | None = None  # how many of their images were drawn
        self.with_error = with_error
        self.optional = {name for name in OPTIONAL if name in passes}
        """The passes of core.passes.OPTIONAL asked for: only those are held."""
        self.width = width
        self.rays = 0
        self.error_rays = 0  # companions and retraces
        self.companion_rays = 0  # the error pass's companion runs
        self.energy_max: float | None = None  # over pixels with a finite error, not captured
        self.passes: dict[str, np.ndarray] = {}
        """The stored passes (core.passes.STORED) by name, (n,) or (n, channels)."""

    def allocate(self) -> None:
        """The full-frame buffers (once; the first store or the result does it)."""
        if self.passes:
            return
        self.rgba = np.zeros((self.n, 4), dtype=np.float32)
        for kind in STORED:
            wanted = kind.name not in OPTIONAL or kind.name in self.optional
            self.passes[kind.name] = kind.empty(self.n if wanted else 0)

    @property
    def error(self) -> np.ndarray:
        return self.passes["error"]

    @property
    def ending(self) -> np.ndarray:
        return self.passes["ending"]

    def _energy(self, idx, energy) -> None:
        """Fold the energy errors of stored pixels ``idx`` into ``energy_max``."""
        ending = self.ending[idx]
        kept = (ending >= 0) & np.isfinite(self.error[idx]) & (ending != ENDING["captured"])
        if np.any(kept):
            top = float(np.max(np.asarray(energy)[kept]))
            if self.energy_max is not None:  # np.maximum: a NaN stays, as in one np.max
                top = float(np.maximum(self.energy_max, top))
            self.energy_max = top

    def _put(self, idx, values: dict) -> None:
        """Store the passes ``values`` (by name) of the pixels ``idx``."""
        for name, data in values.items():
            if name not in OPTIONAL or name in self.optional:
                self.passes[name][idx] = data

    def store(self, span, chunk, background: Background) -> int:
        """Store a finished chunk; -> the number of pixels it filled."""
        self.allocate()
        if isinstance(chunk[0], Tile):
            return self._store_tile(*chunk)
        a, b = span
        rays, seen, error = chunk
        footprint = None  # a texture sky's: the pixels' own directions (core.mipmap)
        if background.filters and rays.sky_jacobian.shape[1] != 2:
            sky = rays.ending == ENDING["escaped"]
            footprint = span_footprint(rays.direction, sky, a, self.width)
        self.rgba[a:b] = shade(rays, background, footprint)
        self._put(slice(a, b), traced_passes(rays, seen, error))
        self.rays += b - a
        if error is not None:
            self.error_rays += b - a
            self.companion_rays += b - a
        failed = rays.ending == ENDING["failed"]
        self.error[a:b][failed] = np.inf
        self._energy(slice(a, b), rays.energy_error)
        return b - a

    def _rows(self, tile: Tile) -> np.ndarray:
        """Flat indices (h, w) of a tile's pixels."""
        rows = np.arange(tile.y0, tile.y1)[:, None] * self.width
        return rows + np.arange(tile.x0, tile.x1)[None, :]

    def _store_tile(self, tile: Tile, part: TileResult) -> int:
        idx = self._rows(tile)
        self.rgba[idx] = part.rgba
        self._put(idx, part.passes)
        self._energy(idx, part.energy)
        self.rays += part.rays
        self.error_rays += part.error_rays
        self.companion_rays += part.companion_rays
        return idx.size

    def part(self, span, chunk, passes) -> tuple[tuple[int, int, int, int], RenderResult]:
        """A finished chunk as (x0, y0, x1, y1) and its pixels (for progressive display):
        a tile, or the rows a span of flat indices covers (whole rows, as stored so far),
        with every pass asked for."""
        if isinstance(chunk[0], Tile):
            tile = chunk[0]
        else:
            first, last = span[0] // self.width, -(-span[1] // self.width)
            tile = Tile(0, first, self.width, last)
        idx = self._rows(tile)
        return (tile.x0, tile.y0, tile.x1, tile.y1), self._image(idx, idx.shape, passes)

    def _image(self, idx, shape: tuple, passes, cancelled: bool = False) -> RenderResult:
        """The pixels ``idx`` as an image of ``shape`` (h, w) with ``passes``: the stored
        ones as views where idx is a slice, the derived ones (error_px: the error over the
        pixel angle) as arrays of their own."""
        out = RenderResult(self.rgba[idx].reshape(*shape, 4), cancelled=cancelled)
        for name in passes:
            kind = BY_NAME[name]
            if kind.from_camera:
                out.passes[name] = self._doppler(idx).reshape(shape)
                continue
            data = self.passes[kind.derived_from or name][idx]
            if kind.derived_from and isinstance(idx, slice):  # a view: its own copy
                data = data.copy()
            if name == "error_px":  # in place: no second full-frame temporary
                data /= np.float32(self.pixel_angle)
            if name == "direction":  # nothing is seen where a ray was captured or failed
                ending = self.ending[idx]
                data[(ending == ENDING["captured"]) | (ending == ENDING["failed"])] = np.nan
            out.passes[name] = data.reshape(
                shape if kind.channels == 1 else (*shape, kind.channels)
            )
        return out

    def hold_stars(self, background: Background, camera) -> None:
        """With point stars (a StarField background), hold what their images are found and
        dimmed from (the direction and transmittance passes); a camera whose pixels span no
        solid angle is refused by name."""
        if isinstance(background, StarField):
            camera.direction_tangents(np.zeros((1, 2)))
            self.stars = background
            self.optional |= {"direction", "transmittance"}

    def draw_stars(self, pixel_filter: str, filter_size: float, tracer, cancelled: bool) -> None:
        """Add the point stars' lensed images to the finished frame (core.star_images),
        counted in ``star_images``; nothing on a cancelled one."""
        if self.stars is None or cancelled:
            return
        h, w = self.n // self.width, self.width
        self.star_images = draw_stars(
            self.rgba.reshape(h, w, 4),
            self.passes["direction"].reshape(h, w, 3),
            (self.ending == ENDING["escaped"]).reshape(h, w),
            self.passes["transmittance"].reshape(h, w),
            self.camera, self.stars, tracer, self.motion, pixel_filter, filter_size,
        )  # fmt: skip

    def _doppler(self, idx) -> np.ndarray:
        """The doppler pass (float32, flat) of the pixels ``idx`` (a slice or indices): the
        camera's motion's g along each pixel centre's ray, in chunks (1 without a motion)."""
        size = len(range(self.n)[idx]) if isinstance(idx, slice) else np.size(idx)
        g = np.ones(size, dtype=np.float32)
        if self.motion is None:
            return g
        for start in range(0, size, _CAMERA_CHUNK):
            stop = min(start + _CAMERA_CHUNK, size)
            if isinstance(idx, slice):
                first = range(self.n)[idx][start]  # whole-frame slices have step 1
                _, seen = self.camera.rays(first, first + stop - start)
            else:
                row, col = np.divmod(np.asarray(idx).reshape(-1)[start:stop], self.width)
                _, seen = self.camera.rays_at(np.stack([col + 0.5, row + 0.5], axis=1))
            g[start:stop] = self.motion.doppler(seen)
        return g

    def result(self, camera, passes, seconds, cancelled, tracer) -> RenderResult:
        self.allocate()
        h, w = camera.height, camera.width
        out = self._image(slice(None), (h, w), passes, cancelled)
        out.summary = self.summary(seconds, tracer)
        return out

    def summary(self, seconds, tracer) -> dict:
        traced = self.ending >= 0
        finite = traced & np.isfinite(self.error) & (self.ending != ENDING["captured"])
        errs = self.error[finite] if self.with_error else self.error[:0]
        del finite
        error_max = float(np.max(errs)) if errs.size else None
        counts = {name: int(np.count_nonzero(self.ending == code)) for name, code in ENDING.items()}
        # no estimate (no error pass, nothing integrated, every ray failed): None, never 0
        energy_max = self.energy_max if tracer.curved else None
        return {
            "time_s": seconds,
            "rays": self.rays,
            "pixels": int(np.count_nonzero(traced)),
            "error_rays": self.error_rays,
            "companion_rays": self.companion_rays,
            "steps": int(self.passes["steps"].sum()),
            "failed": counts["failed"],
            # errs is a copy: the median may sort it in place (no second full-frame one)
            "error_median": float(np.median(errs, overwrite_input=True)) if errs.size else None,
            "error_max": error_max,
            # |H - H0| at the end of the rays that colour a pixel (a captured ray's last
            # step inside the horizon says nothing about the image)
            "energy_error_max": energy_max,
            "endings": counts,
            "step": tracer.step,
            "region_radius": None if tracer.region is None else tracer.region.radius,
            "method": tracer.method.name if tracer.curved else "straight",
        } | ({} if self.star_images is None else {"star_images": self.star_images})


_SUMMARY_FIELDS = (
    ("time_s", "{:.2f} s"),
    ("rays", "{} rays"),
    ("steps", "{} steps"),
    ("failed", "{} failed"),
    ("error_px_median", "median error {:.3g} px"),
    ("error_px_max", "max error {:.3g} px"),
    ("error_median", "median error {:.3g} rad"),
    ("error_max", "max error {:.3g} rad"),
    ("disk_exposure", "disk exposure {:.3g}"),
)
"""What summary_text prints, in order; the error in pixels of the camera (the Error pass's
unit) where the summary has it, else in radians."""


def summary_text(summary: dict) -> str:
    """One line describing a render summary, with units; an error without an estimate
    (None) is 'n/a'."""
    parts = []
    for key, fmt in _SUMMARY_FIELDS:
        in_pixels = key.replace("error_", "error_px_", 1) in summary
        if key not in summary or key.startswith("error_") and in_pixels:
            continue
        value = summary[key]
        try:
            parts.append(fmt.format(value) if value is not None else _no_value(fmt))
        except (TypeError, ValueError):
            parts.append(f"{key} {value}")
    return ", ".join(parts)


def _no_value(fmt: str) -> str:
    """A summary field without a value: its words, then 'n/a' (no unit)."""
    words = fmt.split("{")[0].strip()
    return f"{words} n/a" if words else "n/a"


def shade(rays: RayResults, background: Background, footprint=None) -> np.ndarray:
    """RGBA (N, 4) of traced rays: surfaces, sky, black horizon, volumes; debug colours.
    The sky over each pixel's ``footprint`` (N, 2, 3), else over the ray differentials the
    rays carry, if any (core.mipmap).
    Sky and surfaces take the Doppler shift of a moving camera (core.motion.shift; volumes'
    light does not: a documented approximation).

    What lies in front of a ray's ending (volumes, a translucent disk: radiance, and
    transmittance T) covers 1 - T of it: alpha = 1 - T (1 - the ending's alpha). A
    background of alpha 0 (Film › Transparent: (0, 0, 0, 0)) leaves the premultiplied
    foreground, which composited over a background b gives radiance + T b again."""
    n = rays.ending.shape[0]
    color = np.zeros((n, 4))
    color[:, 3] = 1.0
    hit = rays.ending == ENDING["hit"]
    color[hit] = rays.surface[hit]
    escaped = rays.ending == ENDING["escaped"]
    if escaped.any():
        if footprint is None and rays.sky_jacobian.shape[1] == 2:  # ray differentials
            footprint = rays.sky_jacobian
        seen = None if footprint is None else footprint[escaped]
        color[escaped] = background(rays.direction[escaped], seen)
    moving = np.flatnonzero((escaped | hit & (rays.object_id != DISK_ID)) & (rays.doppler != 1.0))
    if moving.size:  # static emitters seen by a moving camera (the disk's g has it already)
        color[moving, :3] = doppler_shift(color[moving, :3], rays.doppler[moving])
    color[:, :3] = rays.radiance + rays.transmittance[:, None] * color[:, :3]
    color[:, 3] = 1.0 - rays.transmittance * (1.0 - color[:, 3])
    color[rays.ending == ENDING["failed"]] = FAILED_COLOR
    color[rays.ending == ENDING["max_steps"]] = MAX_STEPS_COLOR
    return color.astype(np.float32)


def _scene_extent(scene: Scene, camera, objects: Any = None) -> float:
    """Largest distance from the model's centre to the camera or to any object's bounds
    (``objects``: the scene's intersector where already made, whose members' bounds are
    read where it is the Group of a list of objects and the disk's annulus)."""
    far = np.linalg.norm(camera.frame.position - scene.center)
    extra = [(v.lo, v.hi) for v in scene.volumes]
    if isinstance(objects, Group) and not isinstance(scene.objects, Intersector):
        lo, hi = objects.member_bounds  # the list's and the annulus's
    else:
        one = scene.objects
        lo, hi = member_bounds([one] if isinstance(one, Intersector) else list(one))
        annulus = scene.disk_annulus()
        if annulus is not None:
            extra.append(annulus.bounds)
    if extra:
        more = np.array([np.asarray(box, np.float64).reshape(2, 3) for box in extra])
        lo, hi = np.concatenate([lo, more[:, 0]]), np.concatenate([hi, more[:, 1]])
    if not (np.isfinite(lo).all() and np.isfinite(hi).all()):
        finite = np.isfinite(lo).all(axis=1) & np.isfinite(hi).all(axis=1)
        lo, hi = lo[finite], hi[finite]
    if lo.size:  # a box's farthest corner takes the farther end on every axis
        c = np.asarray(scene.center)[:, None]  # by axis: numpy's loops run long
        reach = np.maximum(np.abs(lo.T - c), np.abs(hi.T - c))  # (3, M)
        far = max(far, float(np.max(np.linalg.norm(reach, axis=0))))
    return float(max(far, 1e-9))

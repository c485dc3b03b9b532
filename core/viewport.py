"""An interactive view of a scene: rendered coarse to fine off the caller's thread, and
what a change can reuse instead of tracing again (the add-on's Rendered viewport).

A view is rendered in LEVELS: first at 1/8 of its size per side at *Preview* accuracy (one
pixel of that coarse image), then 1/4 (Preview), then the full size at the scene's
own quality (``Quality``). Each level is a ``core.render`` of ``Camera.resized``, run by
``ProgressiveView`` in a daemon thread; ``cancel()`` stops it within a tile (core.render's
``should_cancel``). A change starts a new view; what it may reuse from the last image:

- ``reshade``: a change of the disk's look only (look, beaming, exposure, brightness,
  temperature, profile): every pixel whose centre sees the opaque disk is recoloured from
  its redshift g and radius r (``AccretionDisk.colour``), nothing is traced. Exact for
  one ray per pixel (samples 1: *Preview*); with anti-aliasing, a pixel on the disk's
  edge keeps its old share of the disk's colour until the view is rendered again.
- ``resample``: the view turned or zoomed at the same position (a camera's orientation
  and lens): the light arriving at the observer depends only on its direction there, so
  the last image is a *direction map*. Each new pixel's direction is projected into the
  old image; inside a cell whose four pixel centres end alike (all escaped, or all on the
  same kind of thing) it is interpolated: escaped rays by their final directions (the sky
  looked up again at the interpolated direction: as sharp as a fresh render), the disk by
  its g and r. Surfaces are not resampled: the image keeps only their colour, and a blend
  of colours across a texture's edge is no colour a fresh render shows (a checker board's
  lensed images near a hole: 23 % of the blended pixels off by > 0.1; 0.6 % still where
  the four colours agreed within 0.05). Pixels outside the old image, on a surface, or in
  a cell across an edge are marked uncovered: a fresh render of the view replaces them.

- ``reshade_surfaces``: a change of the surfaces' colours only (materials, textures; the
  geometry the same): each pixel whose centre ended on a surface is coloured again where
  that surface is met by a short segment through its hit point, nothing traced. Exact for
  one ray per pixel; with anti-aliasing (or where a surface seen edge-on is not met
  again) the add-on renders the last level again behind the re-shaded image.

Anything else (the observer moved, an object, the model) renders again from the coarsest
level.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from . import workers
from .camera import Camera
from .geometry import filters
from .mipmap import span_footprint
from .render import (
    TRACE_SHARE,
    ExposureProbe,
    RenderResult,
    exposure_probe,
    probe_camera,
    render,
)
from .sky import Background
from .tracing import ENDING, Scene
from .tracing.segments import SceneGeometry, surface_colours

LEVELS = (8, 4, 1)
"""Downscale factors per side of a view's successive images (the last: full size). No 1/2
level: it cost a quarter of the way to the full image (Kerr with disk, 960x540: 1.7 of
8.8 s) and the full level reuses nothing of it."""
VIEW_PASSES = ("ending", "direction", "position", "redshift")
"""What a view keeps per pixel: enough to resample and reshade it."""
DISK_LOOK = ("look", "beaming", "exposure", "brightness", "temperature", "profile")
"""AccretionDisk fields a reshade follows (the rest change where the disk is: retrace)."""
SKY_SPREAD = 4.0
"""A resampled cell of sky is interpolated only where its corners' final directions lie
within this many of the old image's pixel angles of the first's: next to the shadow rays
one pixel apart leave radians apart, and a blend of them is no direction (sky pixels 0.23
rad off at the 99.5th percentile past a Schwarzschild hole without it)."""
RESAMPLE_CHUNK = 1 << 16
"""Pixels a resample works on at once (its memory does not grow with the view's size)."""
RECAST_REACH = 1e-4
"""reshade_surfaces' segments reach this share of a hit point's distance from the camera
either side of it (the position pass is float32: ~1e-7 of that distance off the surface)."""
SAME_POSITION = 1e-9
"""Relative distance below which two observers stand at the same place (resample)."""


@dataclass(frozen=True)
class Quality:
    """How finely a view's last level is rendered (core.render's tolerance_px, samples)."""

    tolerance_px: float = 1.0
    samples: int = 1


PREVIEW = Quality()
"""The coarse levels' accuracy: one pixel of the level's own image, one sample."""


@dataclass
class ViewImage:
    """One level of a view: its image (row 0 at the top), passes and camera."""

    level: int
    camera: Camera
    rgba: np.ndarray
    passes: dict
    seconds: float
    final: bool = False
    summary: dict = field(default_factory=dict)
    derived: dict = field(default_factory=dict)
    """What a resample computes once from the image (the disk's radius map)."""


def level_camera(camera: Camera, level: int) -> Camera:
    """``camera`` at 1 / ``level`` of its size per side (at least one pixel)."""
    width, height = camera.full_size
    return camera.resized(max(1, math.ceil(width / level)), max(1, math.ceil(height / level)))


def render_level(
    scene: Scene,
    camera: Camera,
    level: int,
    quality: Quality,
    should_cancel: Callable[[], bool] | None = None,
    **options: Any,
) -> ViewImage | None:
    """One level of a view (None when cancelled). Below full size, *Preview* accuracy the
    quickest way: every pixel centre traced at half a (coarse) pixel's tolerance, no error
    pass, no sampler (which pays its per-step overhead per block round: 3-4x slower on
    an image of ~10^4 pixels); at full size, core.render with ``quality`` (as F12).
    ``options``: core.render's (workers, parallel, cores, method, max_steps, ...)."""
    seen = level_camera(camera, level)
    final = level == 1
    start = time.perf_counter()
    if final:
        accuracy: dict[str, Any] = {
            "tolerance_px": quality.tolerance_px,
            "samples": quality.samples,
        }
    else:
        distance = float(np.linalg.norm(seen.frame.position - np.asarray(scene.center)))
        accuracy = {"tolerance": TRACE_SHARE * seen.pixel_angle(max(distance, 1e-9))}
    out = render(scene, seen, passes=VIEW_PASSES, should_cancel=should_cancel, **accuracy,
                 **options)  # fmt: skip
    if out.cancelled:
        return None
    return _image(out, level, seen, time.perf_counter() - start, final)


def _image(out: RenderResult, level: int, camera: Camera, seconds: float, final: bool):
    """A level's ViewImage from core.render's result (passes as (h, w) or (h, w, 3))."""
    h, w = camera.height, camera.width
    passes = {}
    for name in VIEW_PASSES:
        data = np.asarray(out.passes[name])
        passes[name] = data.reshape(h, w) if data.size == h * w else data.reshape(h, w, -1)
    return ViewImage(level, camera, out.rgba.reshape(h, w, 4), passes, seconds, final, out.summary)


class ProgressiveView(workers.BackgroundTask):
    """Renders one view level by level (LEVELS) in a daemon thread. ``latest`` is the
    finest image so far; ``on_image(image)`` is called from the thread with each one;
    ``probe`` is the automatic disk exposure's probe once it has run (``reshade`` reuses
    it). A change of anything: ``cancel()`` this view and start another."""

    def __init__(
        self,
        scene: Scene,
        camera: Camera,
        quality: Quality = PREVIEW,
        on_image: Callable[[ViewImage], None] | None = None,
        levels: tuple[int, ...] = LEVELS,
        **options: Any,
    ) -> None:
        super().__init__("symray-view")
        self.scene, self.camera, self.quality = scene, camera, quality
        self.levels, self.options, self.on_image = levels, options, on_image
        self.latest: ViewImage | None = None
        self.probe: ExposureProbe | None = None

    def _work(self) -> None:
        # one level per pass, each pass cancellable. An automatic disk exposure is chosen
        # once, as F12 chooses it for this view: its probe runs beside the first level
        # (which an opaque disk lets re-shade once the exposure is known)
        scene, first = self._first_level()
        for level in self.levels:
            if self.cancelled:
                return
            image = first if level == self.levels[0] else None
            if image is None:
                image = render_level(scene, self.camera, level, self.quality,
                                     self._cancel.is_set, **self.options)  # fmt: skip
            if image is None or self.cancelled:
                return
            if scene.disk is not None:
                _radius_map(image, scene)  # here, not in the first resample's redraw
            self.latest = image
            if self.on_image is not None:
                self.on_image(image)

    def _first_level(self) -> tuple[Scene, ViewImage | None]:
        """(the scene with its disk's exposure chosen, the first level when it was
        rendered for the exposure's probe, else None). An opaque disk's first level at
        exposure 1 is the probe's first render (probe_camera) where their sizes agree:
        re-shaded once the exposure is known."""
        probe = _probe_options({**self.options, "should_cancel": self._cancel.is_set})
        disk = self.scene.disk
        if disk is None or disk.exposure is not None:
            return self.scene, None
        shared = (
            probe_camera(self.camera).full_size
            == level_camera(self.camera, self.levels[0]).full_size
        )
        if disk.opacity < 1.0 or not shared:
            self.probe = exposure_probe(self.scene, self.camera, **probe)
            return self._exposed(), None
        unexposed = copy.copy(self.scene)
        unexposed.disk = dataclasses.replace(disk, brightness=1.0, exposure=1.0)
        first = render_level(unexposed, self.camera, self.levels[0], self.quality,
                             self._cancel.is_set, **self.options)  # fmt: skip
        if first is None:
            return self.scene, None
        g = np.asarray(first.passes["redshift"], dtype=np.float64)
        stage = (np.isfinite(g), g, first.passes["position"], np.zeros(g.shape))
        self.probe = exposure_probe(self.scene, self.camera, stage, **probe)
        scene = self._exposed()
        assert scene.disk is not None
        first.rgba = _recolour(first, scene)
        first.summary["disk_exposure"] = scene.disk.exposure
        return scene, first

    def _exposed(self) -> Scene:
        return self.scene if self.probe is None else self.probe.exposed(self.scene)


# -- reuse ---------------------------------------------------------------------------------


def look_only_change(old: Scene, new: Scene) -> bool:
    """Whether ``new`` differs from ``old`` only in its disk's look (DISK_LOOK): everything
    else the same objects, model, centre, background."""
    if old.disk is None or new.disk is None:
        return False
    keep = {name: getattr(old.disk, name) for name in DISK_LOOK}
    if dataclasses.replace(new.disk, **keep) != old.disk:
        return False
    return _same_fields(old, new, ("model", "center", "objects", "background", "volumes"))


def surfaces_only_change(old: Scene, new: Scene) -> bool:
    """Whether ``new`` may differ from ``old`` only in its surfaces' colours: the same
    model, centre, disk, background and volumes (that the objects' geometry is the same,
    only the caller knows: the add-on from Blender's depsgraph and the meshes' arrays)."""
    return _same_fields(old, new, ("model", "center", "disk", "background", "volumes"))


def _same_fields(old: Scene, new: Scene, fields: tuple[str, ...]) -> bool:
    return all(getattr(old, name) is getattr(new, name) or _same(getattr(old, name),
               getattr(new, name)) for name in fields)  # fmt: skip


def _same(a: Any, b: Any) -> bool:
    try:
        return bool(np.all(a == b))
    except Exception:  # noqa: BLE001 - incomparable: not the same
        return False


def reshade(
    image: ViewImage,
    scene: Scene,
    camera: Camera | None = None,
    probe: ExposureProbe | None = None,
    **options: Any,
) -> np.ndarray:
    """``image``'s RGBA with its disk's pixels recoloured by ``scene``'s disk (its look:
    ``look_only_change``), nothing traced. An automatic exposure is chosen again as a
    render of the view ``camera`` (default: the image's) would: from ``probe`` (the
    view's: ProgressiveView.probe), else from a new probe (``options``: core.render's)."""
    disk = scene.disk
    if disk is None or disk.opacity < 1.0:
        return image.rgba.copy()
    if probe is None:
        probe = exposure_probe(scene, camera or image.camera, **_probe_options(options))
    return _recolour(image, scene if probe is None else probe.exposed(scene))


def _recolour(image: ViewImage, scene: Scene) -> np.ndarray:
    """``image``'s RGBA with the pixels whose centre sees the disk coloured by ``scene``'s
    disk (opaque, its exposure chosen) from their g and r."""
    disk = scene.disk
    assert disk is not None
    rgba = image.rgba.copy()
    g = np.asarray(image.passes["redshift"], dtype=np.float64)
    on = np.isfinite(g) & (image.passes["ending"] == ENDING["hit"])
    if on.any():
        rgba[on, :3] = disk.colour(g[on], _radius_map(image, scene)[on])
    return rgba


def reshade_surfaces(image: ViewImage, scene: Scene) -> tuple[np.ndarray, np.ndarray] | None:
    """(RGBA (h, w, 4), found (h, w)) of ``image`` with every pixel whose centre ended on a
    surface coloured by ``scene``'s objects, nothing traced: ``scene`` is the image's with
    only its surfaces' colours changed (the caller knows: the add-on from Blender's
    depsgraph). A segment through each hit point along the pixel's direction from the
    camera (RECAST_REACH either side) meets its surface there again; not ``found`` where
    it does not (seen exactly edge-on: the old colour stays). Exact for one ray per pixel.
    None where the pixels hold light besides their surface's (volumes, a translucent disk:
    not kept per pixel)."""
    if scene.volumes or (scene.disk is not None and scene.disk.opacity < 1.0):
        return None
    h, w = image.rgba.shape[:2]
    rgba, found = image.rgba.reshape(h * w, 4).copy(), np.ones(h * w, dtype=bool)
    surface = (image.passes["ending"] == ENDING["hit"]) & ~np.isfinite(image.passes["redshift"])
    pixels = np.flatnonzero(surface)
    objects = scene.intersector(disk=False)
    eye = image.camera.frame.position
    label = np.full(h * w, -1, dtype=np.int64)
    for start in range(0, pixels.size, RESAMPLE_CHUNK):
        chunk = pixels[start : start + RESAMPLE_CHUNK]
        point = image.passes["position"].reshape(-1, 3)[chunk].astype(np.float64)
        direction = image.passes["direction"].reshape(-1, 3)[chunk].astype(np.float64)
        reach = RECAST_REACH * np.linalg.norm(point - eye, axis=1, keepdims=True)
        hits = objects.intersect(point - reach * direction, point + reach * direction)
        rgba[chunk[hits.hit]] = hits.color[hits.hit]
        found[chunk] = hits.hit
        label[chunk[hits.hit]] = hits.object_id[hits.hit]
    if filters(objects):
        _filter_surfaces(image, objects, label, rgba)
    return rgba.reshape(h, w, 4), found.reshape(h, w)


def _filter_surfaces(image: ViewImage, objects, label: np.ndarray, rgba: np.ndarray) -> None:
    """Surface colours ``rgba`` (h w, 4) of ``image``'s pixels on the ``objects`` (an
    intersector) ``label`` says (h w,: object ids; -1: none) averaged over each pixel's
    footprint, in place, as a fresh render has them (core.tracing.segments.surface_colours,
    the whole image's neighbours)."""
    position = image.passes["position"].reshape(-1, 3).astype(np.float64)
    direction = image.passes["direction"].reshape(-1, 3).astype(np.float64)
    geometry = SceneGeometry(objects, [])
    width = image.rgba.shape[1]
    rows, colour = surface_colours(geometry, position, direction, label, 0, width)
    rgba[rows] = colour


def _probe_options(options: dict) -> dict:
    names = ("method", "step", "max_steps", "workers", "parallel", "cores", "should_cancel")
    probe = {name: options.get(name) for name in names}
    probe["max_steps"] = probe["max_steps"] or 20_000
    probe["parallel"] = probe["parallel"] or "auto"
    return probe


def same_position(a: Camera, b: Camera) -> bool:
    """Whether two cameras stand at the same place (a resample can serve)."""
    pa, pb = a.frame.position, b.frame.position
    scale = max(float(np.linalg.norm(pa)), float(np.linalg.norm(pb)), 1.0)
    return bool(np.linalg.norm(pa - pb) <= SAME_POSITION * scale)


def resample(image: ViewImage, camera: Camera, scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """(RGBA (h, w, 4), covered (h, w)) of ``camera``'s view read from ``image``'s
    direction map (both cameras at the same place: ``same_position``); uncovered pixels
    are black (see the module docstring). In chunks of RESAMPLE_CHUNK pixels."""
    h, w = camera.height, camera.width
    rgba = np.zeros((h * w, 4), dtype=np.float32)
    covered = np.zeros(h * w, dtype=bool)
    for start in range(0, h * w, RESAMPLE_CHUNK):
        pixels = np.arange(start, min(start + RESAMPLE_CHUNK, h * w))
        row, col = np.divmod(pixels, w)
        _, directions = camera.rays_at(np.stack([col + 0.5, row + 0.5], axis=1))
        at = image.camera.image_points(directions)  # (M, 2) in the old image, NaN off it
        x, y = at[:, 0] - 0.5, at[:, 1] - 0.5  # in pixel-centre units
        old_h, old_w = image.rgba.shape[:2]
        inside = np.isfinite(x) & (x >= 0) & (y >= 0) & (x <= old_w - 1) & (y <= old_h - 1)
        idx = np.flatnonzero(inside)
        if idx.size:
            colour, ok, sky = _interpolate(image, x[idx], y[idx], scene)
            _look_up_sky(colour, sky, idx, pixels, w, scene)
            rgba[pixels[idx[ok]]] = colour[ok]
            covered[pixels[idx[ok]]] = True
    return rgba.reshape(h, w, 4), covered.reshape(h, w)


def _look_up_sky(colour, sky: np.ndarray, idx: np.ndarray, pixels: np.ndarray, width: int,
                 scene: Scene) -> None:  # fmt: skip
    """The sky seen at a resampled chunk's points ``idx`` (``sky``: (M, 3) directions, NaN
    where none), in place in ``colour``: a texture sky over each pixel's footprint, from
    the chunk's own directions (core.mipmap.span_footprint), as a fresh render has it."""
    rows = np.flatnonzero(np.isfinite(sky[:, 0]))
    if rows.size == 0:
        return
    background = Background.of(scene.background)
    footprint = None
    if background.filters:
        directions = np.full((pixels.size, 3), np.nan)
        directions[idx] = sky
        seen = np.isfinite(directions[:, 0])
        footprint = span_footprint(directions, seen, int(pixels[0]), width)[idx[rows]]
    colour[rows] = background(sky[rows], footprint)


def _interpolate(image: ViewImage, x, y, scene: Scene) -> tuple[np.ndarray, ...]:
    """Colour (M, 4) at old-image points (x, y) (pixel-centre units), whether their cell's
    four centres end alike (else not ok), and the sky's directions there (M, 3; NaN where
    no sky is looked up)."""
    old_h, old_w = image.rgba.shape[:2]
    i0 = np.clip(np.floor(x).astype(np.int64), 0, max(old_w - 2, 0))
    j0 = np.clip(np.floor(y).astype(np.int64), 0, max(old_h - 2, 0))
    u, v = x - i0, y - j0
    first = j0 * old_w + i0  # flat indices of the cells' four centres
    right, down = np.minimum(i0 + 1, old_w - 1) - i0, (np.minimum(j0 + 1, old_h - 1) - j0) * old_w
    corners = [first, first + right, first + down, first + down + right]
    weights = [(1 - u) * (1 - v), u * (1 - v), (1 - u) * v, u * v]

    def blend(field: np.ndarray, rows: np.ndarray) -> np.ndarray:
        flat = field.reshape(old_h * old_w, -1)
        parts = [w[rows, None] * flat[k[rows]] for w, k in zip(weights, corners, strict=True)]
        blended = np.asarray(sum(parts), dtype=np.float64)
        return blended if field.ndim == 3 else blended[:, 0]

    ending = image.passes["ending"].reshape(-1)
    on_disk = np.isfinite(np.asarray(image.passes["redshift"]).reshape(-1))
    end, disk_cell = ending[first], on_disk[first]
    alike = np.ones(x.shape, dtype=bool)
    for k in corners[1:]:
        alike &= (ending[k] == end) & (on_disk[k] == disk_cell)
    alike &= (end != ENDING["hit"]) | disk_cell  # a surface: only its colour is kept
    sky = end == ENDING["escaped"]
    directions = image.passes["direction"].reshape(-1, 3)
    d0 = directions[first[sky]]
    least = np.cos(SKY_SPREAD * image.camera.pixel_angle())
    for k in corners[1:]:  # a cell whose rays part by far more than a pixel: too bent
        alike[sky] &= np.einsum("ij,ij->i", directions[k[sky]], d0) >= least
    colour = np.zeros((x.size, 4))
    captured = np.flatnonzero(alike & (end == ENDING["captured"]))
    colour[captured] = blend(image.rgba, captured)
    escaped = np.flatnonzero(alike & sky)
    seen = np.full((x.size, 3), np.nan)
    if escaped.size:  # the sky itself is looked up by the caller (_look_up_sky)
        d = blend(image.passes["direction"], escaped)
        seen[escaped] = d / np.linalg.norm(d, axis=1, keepdims=True)
    disk = np.flatnonzero(alike & disk_cell & (end == ENDING["hit"]))
    if disk.size and scene.disk is not None and scene.disk.opacity >= 1.0:
        exposure = image.summary.get("disk_exposure", scene.disk.exposure)
        bound = dataclasses.replace(scene.disk, exposure=exposure)
        g = np.asarray(image.passes["redshift"], dtype=np.float64)
        colour[disk, :3] = bound.colour(blend(g, disk), blend(_radius_map(image, scene), disk))
        colour[disk, 3] = blend(image.rgba[..., 3], disk)
    return colour.astype(np.float32), alike, seen


def _radius_map(image: ViewImage, scene: Scene) -> np.ndarray:
    """The disk's radius at each pixel of ``image`` (NaN off it; kept with the image: the
    radius is blended as the sampler blends it, not the points)."""
    if "radius" not in image.derived:
        on = np.isfinite(image.passes["redshift"])
        radius = np.full(on.shape, np.nan)
        radius[on] = scene.disk_radius(image.passes["position"][on])
        image.derived["radius"] = radius
    return image.derived["radius"]

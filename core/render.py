"""core.render: a whole image in chunks (bounded memory), with passes and a summary.

Passes: ``error`` (estimated final-direction error in radians, from step doubling:
every traced ray is traced again at half the step; the image shows the finer run and
the error is |d_h - d_h/2| / (2^p - 1), +inf where a ray failed), ``steps`` and
``ending`` (``core.ENDING`` codes) and ``redshift`` (g = ν_obs / ν_emit of rays that end on
the scene's accretion disk, NaN elsewhere; core/tracing/disklight.py). Failed rays are
drawn in ``FAILED_COLOR`` and rays that ran out of steps in ``MAX_STEPS_COLOR``, never as a
plausible colour.
"""

from __future__ import annotations

import re
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from . import checks
from . import workers as workers_module
from .geometry import Intersector
from .imageio import FAILED_COLOR
from .observer import check_camera
from .sky import Background
from .tracing import ENDING, RayResults, Scene, TraceOptions, Tracer

MAX_STEPS_COLOR = (0.0, 1.0, 1.0, 1.0)
"""Debug colour of rays that reached max_steps without ending (cyan)."""
ALL_PASSES = ("error", "steps", "ending", "redshift")
"""The passes, in their one order (the add-on's render passes and EXR channels follow it)."""
_MIN_CHUNK = 2048


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
    step: float | None = None,
    max_steps: int = 20_000,
    passes: Sequence[str] = ALL_PASSES,
    chunk_size: int = 16_384,
    workers: int | None = None,
    parallel: str = "auto",
    cores: int | None = None,
    progress: Callable[[int, int], None] | None = None,
    should_cancel: Callable[[], bool] | None = None,
) -> RenderResult:
    """Render ``scene`` seen by ``camera`` (docs/design.md, "Rendering in the core").

    The image is traced in chunks of at most ``chunk_size`` rays by ``workers`` forked
    processes or threads (``parallel``: "auto", "processes", "threads"; see
    core.workers); without ``workers``, one process per core (at most ``cores``) or two
    threads. ``progress(done, total)`` and ``should_cancel()`` are called from the
    caller's thread, or from the worker threads when there are threads.
    """
    options = TraceOptions(method=method, tolerance=tolerance, step=step, max_steps=max_steps)
    passes = _check_render_call(passes, chunk_size, workers, cores)
    start_time = time.perf_counter()
    extent = _scene_extent(scene, camera)
    tracer = Tracer(scene, options, extent)
    if tracer.curved:
        checks.check_render_method(tracer.method, time_scaled(tracer.model))
    check_camera(tracer, camera.frame.position)
    background = (
        scene.background
        if isinstance(scene.background, Background)
        else Background(scene.background)
    )
    n = camera.n_pixels
    kind, count = workers_module.choose(parallel, workers, n, cores)
    with_error = "error" in passes and tracer.curved
    image = _Buffers(n, with_error)
    # at least two chunks per worker (a small image still keeps every core busy), but not
    # below _MIN_CHUNK rays: per-step work is Python overhead on small batches
    size = max(_MIN_CHUNK, min(chunk_size, -(-n // (2 * count))))
    chunks = [(s, min(s + size, n)) for s in range(0, n, size)]
    cancelled = workers_module.CancelLatch(should_cancel)

    def work(span, cancel):
        if cancel():
            return None
        origins, directions = camera.rays(*span)
        chunk = _trace_chunk(tracer, origins, directions, with_error, cancel)
        return None if cancel() else chunk

    done = 0
    for span, chunk in workers_module.run_chunks(work, chunks, kind, count, cancelled):
        if chunk is None:
            continue
        image.store(span, chunk, background)
        done += span[1] - span[0]
        if progress is not None:
            progress(done, n)
    was_cancelled = done < n or cancelled()
    result = image.result(camera, passes, time.perf_counter() - start_time, was_cancelled, tracer)
    result.summary["parallel"] = f"{count} {kind}" if kind != "inline" else "inline"
    return result


def _check_render_call(passes, chunk_size, workers, cores) -> tuple[str, ...]:
    """ValueError for what core.render refuses beyond TraceOptions; -> the passes."""
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
    signature there); nothing for a camera where rays can start."""
    far = float(np.linalg.norm(np.asarray(position, dtype=np.float64) - scene.center))
    check_camera(Tracer(scene, TraceOptions(tolerance=tolerance), max(far, 1e-9)), position)


def _trace_chunk(tracer: Tracer, origins, directions, with_error: bool, cancel):
    """Trace one chunk; with the error pass, again at half the step (step doubling)."""
    coarse = tracer.trace(origins, directions, cancel=cancel)
    if not with_error:
        return coarse, None
    assert tracer.step is not None  # with_error: the scene is curved
    fine = tracer.trace(origins, directions, step=0.5 * tracer.step, cancel=cancel)
    return fine, _doubling_error(coarse, fine, origins, tracer.method.order)


def _doubling_error(coarse: RayResults, fine: RayResults, origins, order: int) -> np.ndarray:
    """Richardson estimate of the fine run's final-direction error, radians (N,)."""
    escaped = fine.ending == ENDING["escaped"]
    vec_c = np.where(escaped[:, None], coarse.direction, coarse.position - origins)
    vec_f = np.where(escaped[:, None], fine.direction, fine.position - origins)
    with np.errstate(all="ignore"):
        err = _angle(vec_c, vec_f) / (2.0**order - 1.0)
    err = np.where(coarse.ending == fine.ending, err, np.pi)
    err = np.where(fine.ending == ENDING["captured"], 0.0, err)
    bad = (fine.ending == ENDING["failed"]) | (fine.ending == ENDING["max_steps"])
    return np.where(bad | ~np.isfinite(err), np.inf, err)


def _angle(u, v) -> np.ndarray:
    """Angle between vectors, accurate for tiny angles (atan2 of |u x v| and u.v)."""
    cross = np.linalg.norm(np.cross(u, v), axis=1)
    return np.arctan2(cross, np.einsum("ij,ij->i", u, v))


class _Buffers:
    """Flat per-pixel buffers filled chunk by chunk."""

    def __init__(self, n: int, with_error: bool):
        self.rgba = np.zeros((n, 4), dtype=np.float32)
        self.error = np.zeros(n, dtype=np.float32)
        self.steps = np.zeros(n, dtype=np.int32)
        self.ending = np.full(n, -1, dtype=np.int8)
        self.energy = np.zeros(n)
        self.redshift = np.full(n, np.nan, dtype=np.float32)
        self.with_error = with_error

    def store(self, span, chunk, background: Background):
        a, b = span
        rays, error = chunk
        self.rgba[a:b] = shade(rays, background)
        self.steps[a:b] = rays.steps
        self.ending[a:b] = rays.ending
        self.energy[a:b] = rays.energy_error
        self.redshift[a:b] = rays.redshift
        if error is not None:
            self.error[a:b] = error
        failed = rays.ending == ENDING["failed"]
        self.error[a:b][failed] = np.inf

    def result(self, camera, passes, seconds, cancelled, tracer) -> RenderResult:
        h, w = camera.height, camera.width
        out = RenderResult(self.rgba.reshape(h, w, 4), cancelled=cancelled)
        if "error" in passes:
            out.passes["error"] = self.error.reshape(h, w)
        if "steps" in passes:
            out.passes["steps"] = self.steps.reshape(h, w)
        if "ending" in passes:
            out.passes["ending"] = self.ending.reshape(h, w)
        if "redshift" in passes:
            out.passes["redshift"] = self.redshift.reshape(h, w)
        out.summary = self.summary(seconds, tracer)
        return out

    def summary(self, seconds, tracer) -> dict:
        traced = self.ending >= 0
        finite = traced & np.isfinite(self.error) & (self.ending != ENDING["captured"])
        errs = self.error[finite] if self.with_error else self.error[:0]
        counts = {name: int(np.count_nonzero(self.ending == code)) for name, code in ENDING.items()}
        # no estimate (no error pass, nothing integrated, every ray failed): None, never 0
        integrated = self.energy[finite] if tracer.curved else self.energy[:0]
        return {
            "time_s": seconds,
            "rays": int(np.count_nonzero(traced)),
            "steps": int(self.steps.sum()),
            "failed": counts["failed"],
            "error_median": float(np.median(errs)) if errs.size else None,
            "error_max": float(np.max(errs)) if errs.size else None,
            # |H - H0| at the end of the rays that colour a pixel (a captured ray's last
            # step inside the horizon says nothing about the image)
            "energy_error_max": float(np.max(integrated)) if integrated.size else None,
            "endings": counts,
            "step": tracer.step,
            "region_radius": None if tracer.region is None else tracer.region.radius,
            "method": tracer.method.name if tracer.curved else "straight",
        }


_SUMMARY_FIELDS = (
    ("time_s", "{:.2f} s"),
    ("rays", "{} rays"),
    ("steps", "{} steps"),
    ("failed", "{} failed"),
    ("error_median", "median error {:.3g}"),
    ("error_max", "max error {:.3g}"),
)


def summary_text(summary: dict) -> str:
    """One line describing a render summary; an error without an estimate (None) is 'n/a'."""
    parts = []
    for key, fmt in _SUMMARY_FIELDS:
        if key not in summary:
            continue
        value = summary[key]
        try:
            parts.append(
                fmt.format(value) if value is not None else re.sub(r"\{[^}]*\}", "n/a", fmt)
            )
        except (TypeError, ValueError):
            parts.append(f"{key} {value}")
    return ", ".join(parts)


def shade(rays: RayResults, background: Background) -> np.ndarray:
    """RGBA (N, 4) of traced rays: surfaces, sky, black horizon, volumes; debug colours."""
    n = rays.ending.shape[0]
    color = np.zeros((n, 4))
    color[:, 3] = 1.0
    hit = rays.ending == ENDING["hit"]
    color[hit] = rays.surface[hit]
    escaped = rays.ending == ENDING["escaped"]
    if escaped.any():
        color[escaped] = background(rays.direction[escaped])
    color[:, :3] = rays.radiance + rays.transmittance[:, None] * color[:, :3]
    color[rays.ending == ENDING["failed"]] = FAILED_COLOR
    color[rays.ending == ENDING["max_steps"]] = MAX_STEPS_COLOR
    return color.astype(np.float32)


def _scene_extent(scene: Scene, camera) -> float:
    """Largest distance from the model's centre to the camera or to any object's bounds."""
    far = np.linalg.norm(camera.frame.position - scene.center)
    objects = scene.objects
    bounds = [objects.bounds] if isinstance(objects, Intersector) else [o.bounds for o in objects]
    bounds += [(v.lo, v.hi) for v in scene.volumes]
    annulus = scene.disk_annulus()
    if annulus is not None:
        bounds.append(annulus.bounds)
    for lo, hi in bounds:
        corners = np.array(np.meshgrid(*zip(lo, hi, strict=True))).reshape(3, -1).T
        if np.all(np.isfinite(corners)):
            far = max(far, float(np.max(np.linalg.norm(corners - scene.center, axis=1))))
    return float(max(far, 1e-9))

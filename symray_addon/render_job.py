"""One render: read a Blender scene into core objects (main thread), then trace (any thread).

``prepare`` does all bpy work and all input checks, so that every problem surfaces as a
ValueError (or OSError) with a clear message before anything is traced, and ``run`` needs
no bpy at all: the operator calls it from a worker thread, the engine from its render
thread, background mode directly.
"""

from __future__ import annotations

import copy
import dataclasses
import traceback
from collections.abc import Callable
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from typing import Any

import bpy
import numpy as np

from .. import core
from ..core.render import auto_exposure as core_auto_exposure
from ..core.render import summary_text as render_summary_text
from . import (
    bake,
    export_camera,
    export_meshes,
    models,
    objects,
    observer,
    properties,
    validation,
    world,
)

Progress = Callable[[int, int], None]
Cancel = Callable[[], bool]

TRANSPARENT = (0.0, 0.0, 0.0, 0.0)
"""The background of a render with Film › Transparent (premultiplied RGBA, as Blender's)."""
last_summary: dict[str, Any] = {}
"""Summary of the last frame the engine or the operator finished (for scripts and tests)."""


@dataclass
class RenderJob:
    """Everything core.render needs, plus what the caller needs to write the result."""

    scene: Any
    camera: Any
    options: dict[str, Any] = field(default_factory=dict)
    width: int = 0
    height: int = 0
    transparent: bool = False
    warnings: list[str] = field(default_factory=list)
    """What the render cannot do as asked (unevaluated nodes, ...): reported once each."""


def _evaluated(obj: bpy.types.Object, depsgraph: bpy.types.Depsgraph) -> bpy.types.Object:
    """The evaluated version of ``obj`` in ``depsgraph`` (obj itself if already evaluated)."""
    return obj if obj.is_evaluated else obj.evaluated_get(depsgraph)


def prepare(
    scene: bpy.types.Scene,
    depsgraph: bpy.types.Depsgraph,
    use_border: bool = False,
    camera_object: bpy.types.Object | None = None,
    view_camera: Any = None,
) -> RenderJob:
    """Check the inputs and build core.Scene, core.Camera and the render options.

    ``camera_object`` overrides the scene camera; ``view_camera`` (a core.Camera: the
    viewport's own view) replaces any camera, and the surfaces' lighting is then only
    what is cached (a viewport never bakes: UNBAKED_WARNING without a bake). Raises
    ValueError (bad settings, no camera, camera inside a horizon, nothing to render).
    """
    settings = objects.effective(scene.symray, depsgraph)  # the frame's evaluated objects
    problems = validation.settings_problems(settings)
    if problems:
        raise ValueError(problems[0])
    if view_camera is not None:
        camera, camera_object, position = view_camera, None, view_camera.frame.position
    else:
        camera_object = camera_object or scene.camera
        if camera_object is None:
            raise ValueError("The scene has no active camera: add one or set Scene > Camera")
        camera_object = _evaluated(camera_object, depsgraph)
        kwargs = export_camera.camera_kwargs(scene, camera_object, use_border=use_border)
        camera = core.Camera.blender(**kwargs)
        position = np.array(kwargs["matrix_world"])[:3, 3]

    center_matrix = None
    if settings.center is not None:
        center_matrix = _evaluated(settings.center, depsgraph).matrix_world
    where = models.placement(center_matrix)
    model = models.build_model(settings, properties.metric_source(settings))
    models.check_camera(settings, model, where, position)

    warnings = validation.ignored_settings(scene, depsgraph.view_layer, camera_object)
    hole = objects.hole_of(scene, depsgraph) if settings.follows_objects else None
    inside = objects.inside_warning(scene, hole) if hole is not None else ""
    if inside:
        warnings.append(inside)
    baked = _baked_surfaces(scene, depsgraph, warnings, cached_only=view_camera is not None)
    intersector = export_meshes.build_intersector(depsgraph, baked, warnings)
    if intersector is None and model is None:
        raise ValueError(
            "Nothing to render: the scene has no visible mesh objects and no black hole "
            "(Add › SymRay › Black Hole)"
        )
    transparent = bool(scene.render.film_transparent)
    # Film › Transparent: a clear sky, so that what lies in front of it (a translucent disk,
    # volumes) keeps its light and its coverage (core.render.shade)
    background = (
        TRANSPARENT if transparent else world.world_background(scene, settings.background, warnings)
    )
    core_scene = core.Scene(
        model=model,
        center=tuple(where.center),
        axis=tuple(where.axis),
        rotation=where.rotation,
        # the intersector itself, not a list: its hits keep their objects' own ids
        objects=[] if intersector is None else intersector,
        background=background,
        disk=models.build_disk(settings),
    )
    passes = settings.passes()
    options = {
        "method": None if settings.method == "AUTO" else settings.method,
        **settings.accuracy(),
        # Blender's pixel filter (Film > Filter Size), Cycles' Blackman-Harris
        "filter_size": validation.filter_size(scene.render.filter_size, warnings),
        "max_steps": int(settings.max_steps),
        "passes": passes,
        "parallel": settings.parallel.lower(),
        **device_options(settings, warnings),
        "workers": int(settings.workers) or None,
        # Blender's own thread count (-t N on the command line, or Performance › Threads)
        # bounds the automatic one worker per core
        "cores": int(scene.render.threads),
        # the camera's Observer (a viewport's own view: the static observer)
        **observer.observer_options(scene, camera_object),
    }
    job = RenderJob(core_scene, camera, options, camera.width, camera.height, transparent)
    job.warnings = warnings
    return job


GPU_SAMPLES_WARNING = (
    "Device GPU traces one ray per pixel: the quality's anti-aliasing samples run on the CPU "
    "only (set Device to CPU for them)"
)


def device_options(settings: Any, warnings: list[str]) -> dict[str, Any]:
    """core.render's ``device`` for Render Properties › Device; on the GPU one sample a
    pixel (a warning where the quality asked for more)."""
    if settings.device != "GPU":
        return {"device": "cpu"}
    if settings.accuracy().get("samples", 1) > 1:
        warnings.append(GPU_SAMPLES_WARNING)
    return {"device": "cuda", "samples": 1}


UNBAKED_WARNING = (
    "Surfaces are unlit: Cycles bakes their lighting on Blender's main thread, which F12 "
    "does not run on. Press Bake Lighting in the SymRay panel (or use Render SymRay Image) "
    "for lit surfaces"
)


def _baked_surfaces(
    scene: bpy.types.Scene, depsgraph: bpy.types.Depsgraph, warnings: list,
    cached_only: bool = False,
):  # fmt: skip
    """Baked surfaces when the settings ask for them (bake.py), else None. Automatic
    lighting that cannot bake here (F12's render thread, nothing cached) renders unlit
    with UNBAKED_WARNING; Baked lighting then refuses (ValueError). ``cached_only`` (the
    viewport): the cached bakes if every object has one, else unlit with the warning."""
    settings = scene.symray
    if not bake.wants_baking(settings, depsgraph):
        return None
    if cached_only and not bake.all_cached(scene, depsgraph):
        warnings.append(UNBAKED_WARNING)
        return None
    if settings.lighting == "AUTO" and not bake.can_bake_now(scene, depsgraph):
        warnings.append(UNBAKED_WARNING)
        return None
    return bake.bake_surfaces(scene, depsgraph, warnings, bake=not cached_only)


def pin_exposure(job: RenderJob, exposure: float | None) -> bool:
    """Give the job's disk of automatic exposure the fixed ``exposure`` (an animation's
    first frame's: engine.job_exposure); True when it had one to fix."""
    disk = job.scene.disk
    if exposure is None or disk is None or disk.exposure is not None:
        return False
    job.scene = copy.copy(job.scene)
    job.scene.disk = dataclasses.replace(disk, exposure=exposure)
    return True


def auto_exposure(job: RenderJob) -> float | None:
    """The disk's automatic exposure for the job's frame, as its render would choose it
    (core.render.auto_exposure with the job's options); None without a disk of automatic
    exposure."""
    return core_auto_exposure(job.scene, job.camera, **job.options)


def run(
    job: RenderJob,
    progress: Progress | None = None,
    should_cancel: Cancel | None = None,
    on_tile: Callable[[tuple[int, int, int, int], Any], None] | None = None,
) -> Any:
    """Trace ``job`` with core.render; no bpy is touched (safe in a worker thread).
    ``on_tile(rect, part)`` sees each finished tile (core.render's, in the caller's thread)."""
    result = core.render(
        job.scene,
        job.camera,
        progress=progress,
        should_cancel=should_cancel,
        on_tile=on_tile,
        **job.options,
    )
    return result


def summary_text(summary: dict[str, Any]) -> str:
    """One line describing a render summary (core.render's summary_text: 'n/a' where an
    error has no estimate)."""
    return render_summary_text(summary)


def finished(summary: dict[str, Any]) -> str:
    """Remember ``summary`` as the last one (``last_summary``) and return its one-line text."""
    last_summary.clear()
    last_summary.update(summary)
    return summary_text(summary)


def failure_message(err: BaseException) -> str:
    """What to tell the user when a render failed with ``err`` (any exception).

    Problems the user can fix (ValueError, OSError) are their own message; anything else
    is named plainly, and its traceback goes to the console for a bug report.
    """
    if isinstance(err, (ValueError, OSError)):
        return str(err)
    if isinstance(err, MemoryError):
        return (
            "SymRay ran out of memory: lower the resolution, the number of workers "
            "or Max Steps; nothing was written"
        )
    if isinstance(err, BrokenProcessPool):
        return (
            "A SymRay worker process stopped unexpectedly (killed, or out of memory); "
            "nothing was written"
        )
    traceback.print_exception(err)
    if isinstance(err, RecursionError):
        return "SymRay failed: Python's recursion limit was reached; nothing was written"
    return f"SymRay failed ({type(err).__name__}: {err}); nothing was written"

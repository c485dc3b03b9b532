"""The Rendered viewport: SymRay's image of the 3D view, coarse to fine (core.viewport).

``view_update`` (a change of the scene) reads the scene on the main thread
(``render_job.prepare`` with the view's camera; cached bakes only) and starts a
``core.viewport.ProgressiveView`` in a thread; ``view_draw`` (every redraw, and a change of
the view itself) draws the latest image, and when the view moved: at the same position
(turned, zoomed) it first shows the last image resampled (``core.viewport.resample``),
then renders the new view; anywhere else it renders it from the coarsest level. A change
of the disk's look only is re-shaded (``core.viewport.reshade``), nothing traced.
Drawing never waits for the work: a timer asks for a redraw when an image is ready.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import bpy
import gpu
import numpy as np
from gpu_extras.presets import draw_texture_2d

from .. import core
from ..core import viewport as core_viewport
from . import render_job

POLL_SECONDS = 0.1
"""How often the timer looks for a finished image while a view renders."""


def view_camera(context: Any) -> core.Camera:
    """The core camera of the context's 3D view region (its own matrices and size)."""
    region, view = context.region, context.region_data
    return core.Camera.from_view(
        np.array(view.view_matrix), np.array(view.window_matrix), region.width, region.height
    )


def texture_of(rgba: np.ndarray) -> gpu.types.GPUTexture:
    """A float texture of an image (h, w, 4), row 0 at the top (flipped: GPU rows go up)."""
    h, w = rgba.shape[:2]
    data = np.ascontiguousarray(rgba[::-1], dtype=np.float32).ravel()
    buffer = gpu.types.Buffer("FLOAT", data.size, data)
    return gpu.types.GPUTexture((w, h), format="RGBA16F", data=buffer)


def draw_image(texture: gpu.types.GPUTexture, width: int, height: int) -> None:
    """Draw ``texture`` over the region's width x height pixels (premultiplied alpha)."""
    gpu.state.blend_set("ALPHA_PREMULT")
    draw_texture_2d(texture, (0, 0), width, height)
    gpu.state.blend_set("NONE")


@dataclasses.dataclass
class ViewSession:
    """What one viewport engine keeps between calls: the scene read, the view rendering,
    the image shown and its texture."""

    job: Any = None
    camera: core.Camera | None = None
    view: core_viewport.ProgressiveView | None = None
    shown: np.ndarray | None = None
    shown_from: Any = None
    texture: Any = None
    error: str = ""

    def stop(self) -> None:
        """Cancel the work in flight."""
        if self.view is not None:
            self.view.cancel()

    def restart(self, camera: core.Camera, levels: tuple[int, ...] = core_viewport.LEVELS) -> None:
        """Render ``camera``'s view from the coarsest of ``levels`` (the work in flight
        cancelled)."""
        self.stop()
        self.camera = camera
        if self.job is None:
            return
        options = {k: v for k, v in self.job.options.items() if k in _VIEW_OPTIONS}
        self.view = core_viewport.ProgressiveView(
            self.job.scene, camera, self.quality(), levels=levels, **options
        )
        self.view.start()

    def quality(self) -> core_viewport.Quality:
        """The scene's accuracy for the view's last level."""
        options = self.job.options
        return core_viewport.Quality(
            options.get("tolerance_px") or 1.0, int(options.get("samples", 1))
        )

    def latest(self) -> np.ndarray | None:
        """The image to show now: the view's latest level, else what is shown."""
        if self.view is not None and self.view.error is not None:
            self.error = render_job.failure_message(self.view.error)
        image = self.view.latest if self.view is not None else None
        if image is not None and image is not self.shown_from:
            self.shown, self.shown_from, self.texture = image.rgba, image, None
        return self.shown


_VIEW_OPTIONS = ("method", "max_steps", "parallel", "workers", "cores", "pixel_filter",
                 "filter_size", "device")  # fmt: skip
"""Render options the viewport takes from the scene's (accuracy comes from Quality)."""


def update(engine: Any, context: Any, depsgraph: Any) -> None:
    """view_update: read the scene again; re-shade a disk-look change, else render anew."""
    session = _session(engine)
    camera = view_camera(context)
    try:
        job = render_job.prepare(depsgraph.scene, depsgraph, view_camera=camera)
    except Exception as err:  # shown in the viewport's header, never raised into Blender
        session.stop()
        session.error, session.job = render_job.failure_message(err), None
        engine.update_stats("", f"SymRay: {session.error}")
        return
    old, session.job, session.error = session.job, job, ""
    for warning in job.warnings:
        engine.update_stats("", f"SymRay: {warning}")
    image = session.view.latest if session.view is not None else None
    look_only = old is not None and _look_only(old, job, depsgraph)
    if image is not None and look_only:
        session.stop()
        session.shown = core_viewport.reshade(image, job.scene, camera, session.view.probe)
        session.shown_from, session.texture = image, None
        image.rgba = session.shown
        engine.tag_redraw()
        return
    surfaces = None
    if image is not None and old is not None and _surfaces_only(old, job, depsgraph):
        surfaces = core_viewport.reshade_surfaces(image, job.scene)
    if surfaces is not None:  # re-shaded; rendered again only where that is not exact
        session.stop()
        rgba, found = surfaces
        session.shown, session.shown_from, session.texture = rgba, image, None
        image.rgba = rgba
        engine.tag_redraw()
        if session.quality().samples == 1 and found.all():
            return
        session.restart(camera, levels=(1,))
    else:
        session.restart(camera)
    _poll(engine)


def _surfaces_only(old: Any, new: Any, depsgraph: Any) -> bool:
    """Whether the change from job ``old`` to ``new`` is the surfaces' colours alone:
    updates only of materials, shader trees, images or textures and of objects and meshes
    with neither their geometry nor their transform updated, the same options and model,
    core.viewport.surfaces_only_change, and the same triangles (a visibility setting
    reads as a shading update but may hide an object)."""
    for update in getattr(depsgraph, "updates", ()):
        shaded = isinstance(update.id, (bpy.types.Object, bpy.types.Mesh))
        shaded = shaded and not (update.is_updated_geometry or update.is_updated_transform)
        colours = (bpy.types.Material, bpy.types.NodeTree, bpy.types.Image, bpy.types.Texture)
        if not (shaded or isinstance(update.id, colours)):
            return False
    if old.options != new.options or repr(old.scene.model) != repr(new.scene.model):
        return False
    candidate = dataclasses.replace(new.scene, model=old.scene.model)
    if not core_viewport.surfaces_only_change(old.scene, candidate):
        return False
    if not _same_triangles(old.scene.objects, new.scene.objects):
        return False
    new.scene = candidate
    return True


def _same_triangles(old: Any, new: Any) -> bool:
    """Whether two scenes' objects (an intersector or a list of them) are the same
    triangles (export_meshes.BVHIntersector: vertices, triangles, their objects)."""
    old, new = (list(x) if isinstance(x, (list, tuple)) else [x] for x in (old, new))
    names = ("vertices", "triangles", "tri_object")
    if len(old) != len(new):
        return False
    for a, b in zip(old, new, strict=True):
        if not all(isinstance(getattr(x, n, None), np.ndarray) for x in (a, b) for n in names):
            return False
        if not all(np.array_equal(getattr(a, n), getattr(b, n)) for n in names):
            return False
    return True


def _look_only(old: Any, new: Any, depsgraph: Any) -> bool:
    """Whether the change from job ``old`` to ``new`` is the disk's look alone: only the
    Scene ID updated (no object, mesh, material or world), the same options and model
    (its parameters), and core.viewport.look_only_change on the scenes with the old
    objects (the meshes are rebuilt at every read). ``new.scene`` keeps ``old``'s."""
    for update in getattr(depsgraph, "updates", ()):
        if not isinstance(update.id, bpy.types.Scene) or update.is_updated_geometry:
            return False
    if old.options != new.options or repr(old.scene.model) != repr(new.scene.model):
        return False
    candidate = dataclasses.replace(new.scene, objects=old.scene.objects, model=old.scene.model)
    if not core_viewport.look_only_change(old.scene, candidate):
        return False
    new.scene = candidate
    return True


def draw(engine: Any, context: Any, depsgraph: Any) -> None:
    """view_draw: follow a change of the view, then draw the latest image."""
    session = _session(engine)
    camera = view_camera(context)
    if session.camera is None or not _same_view(session.camera, camera):
        image = session.view.latest if session.view is not None else None
        reuse = image is not None and session.job is not None
        if reuse and core_viewport.same_position(image.camera, camera):
            rgba, _covered = core_viewport.resample(image, camera, session.job.scene)
            session.shown, session.shown_from, session.texture = rgba, image, None
        session.restart(camera)
        _poll(engine)
    rgba = session.latest()
    if rgba is None:
        return
    if session.texture is None:
        session.texture = texture_of(rgba)
    engine.bind_display_space_shader(depsgraph.scene)
    draw_image(session.texture, context.region.width, context.region.height)
    engine.unbind_display_space_shader()


def _same_view(a: core.Camera, b: core.Camera) -> bool:
    """Whether two view cameras see exactly the same (no new render needed)."""
    fa, fb = a.frame, b.frame
    turned = any(not np.allclose(getattr(fa, k), getattr(fb, k)) for k in ("forward", "up"))
    return (a.kind == b.kind and a.full_size == b.full_size and np.allclose(a.window, b.window)
            and not turned and core_viewport.same_position(a, b))  # fmt: skip


_sessions: dict[int, ViewSession] = {}


def _session(engine: Any) -> ViewSession:
    return _sessions.setdefault(id(engine), ViewSession())


def free(engine: Any) -> None:
    """The engine goes: stop its view."""
    session = _sessions.pop(id(engine), None)
    if session is not None:
        session.stop()


def _poll(engine: Any) -> None:
    """Redraw the viewport while its view renders (bpy.app.timers; the work's thread never
    touches Blender)."""
    session = _session(engine)
    seen = [None]

    def tick() -> float | None:
        view = session.view
        if view is None:
            return None
        try:
            if view.latest is not seen[0]:
                seen[0] = view.latest
                engine.tag_redraw()
        except ReferenceError:  # the engine was freed
            return None
        return None if view.finished or view.cancelled else POLL_SECONDS

    bpy.app.timers.register(tick, first_interval=POLL_SECONDS)

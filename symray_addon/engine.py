"""The SYMRAY render engine: F12, ``bpy.ops.render.render`` and ``blender -b -E SYMRAY``.

Each frame traces the evaluated depsgraph's scene (``render_job``; lit surfaces are baked
by Cycles first, or reused from the cache: bake.py), honouring the render
region (border), resolution percentage, Esc (``test_break``) and film transparency, and
writes the Combined pass plus "SymRay Error", "SymRay Steps", "SymRay Ending" and "SymRay
Redshift" (one channel 'X' each, when enabled in the SymRay panel). Saving is Blender's
business: choose a multi-layer OpenEXR in Output Properties to keep every pass.
"""

from __future__ import annotations

import time
from typing import Any

import bpy
import numpy as np

from ..core import passes as core_passes
from . import bake, output, render_job, viewport

PASSES = tuple((p.name, p.layer, p.toggle) for p in core_passes.PASSES if p.label)
"""(core pass, Blender pass name, scene.symray toggle) of the add-on's passes, in the core
table's order (core.passes)."""


def enabled_passes(settings: Any) -> list[tuple[str, str]]:
    """(core pass, Blender pass name) of the passes switched on in ``settings``."""
    return [(core_name, name) for core_name, name, toggle in PASSES if getattr(settings, toggle)]


class SymRayRenderEngine(bpy.types.RenderEngine):
    """Symplectic ray tracing of bent light"""

    bl_idname = "SYMRAY"
    bl_label = "SymRay"
    bl_use_postprocess = True
    bl_use_preview = False  # material previews stay off (README: the Rendered viewport)
    bl_use_shading_nodes_custom = False
    bl_use_eevee_viewport = True  # Material Preview shading is EEVEE's; Rendered is SymRay's

    def __del__(self) -> None:
        viewport.free(self)

    def view_update(self, context: bpy.types.Context, depsgraph: bpy.types.Depsgraph) -> None:
        """The scene changed: the Rendered viewport reads it again (symray_addon/viewport)."""
        viewport.update(self, context, depsgraph)

    def view_draw(self, context: bpy.types.Context, depsgraph: bpy.types.Depsgraph) -> None:
        """Draw the Rendered viewport's latest image (following a change of the view)."""
        viewport.draw(self, context, depsgraph)

    def update_render_passes(
        self, scene: bpy.types.Scene | None = None, renderlayer: bpy.types.ViewLayer | None = None
    ) -> None:
        """Declare the passes so view layers and the compositor know them."""
        self.register_pass(scene, renderlayer, "Combined", 4, "RGBA", "COLOR")
        for _core_name, name in enabled_passes(scene.symray):
            self.register_pass(scene, renderlayer, name, 1, "X", "VALUE")

    def _fail(self, message: str) -> None:
        """Report a failed frame. An ERROR report is what makes Blender's render operator
        raise and keep the output file as it was (error_set alone or raising does not); in
        the background the report is the console's one line (error_set would print the
        message a second time), else error_set also shows it in the render window."""
        self.report({"ERROR"}, message)
        if not bpy.app.background:
            self.error_set(message)

    def render(self, depsgraph: bpy.types.Depsgraph) -> None:
        """Trace one frame of the evaluated scene into the render result.

        Any failure (bad settings, a killed worker process, no memory, a bug) is reported
        as an error, so that no blank or partial image is written as the frame.
        """
        try:
            self._render(depsgraph)
        except Exception as err:  # every failure of a frame is the user's to see
            self._fail(render_job.failure_message(err))

    def _render(self, depsgraph: bpy.types.Depsgraph) -> None:
        """render() itself; raises on any failure."""
        scene = depsgraph.scene
        baking = "" if scene.symray.lighting == "UNLIT" else " (Cycles bakes the lighting)"
        self.update_stats("", f"SymRay: reading the scene{baking}")
        with bake.reporting(self._bake_progress):
            job = render_job.prepare(
                scene, depsgraph, use_border=True, camera_object=self.camera_override
            )
        if self.is_animation:
            self._pin_exposure(job)
        for warning in job.warnings:
            if warning not in _warned:  # once per render job: an animation's frames repeat them
                _warned.add(warning)
                self.report({"WARNING"}, warning)
        passes = enabled_passes(scene.symray)
        for _core_name, name in passes:
            self.add_pass(name, 1, "X")
        self.update_stats("", "SymRay: tracing")
        view_layer = depsgraph.view_layer.name if depsgraph.view_layer else ""
        # Coordinates are relative to the render region (border), which is what we traced.
        res = self.begin_result(0, 0, job.camera.width, job.camera.height, layer=view_layer)
        try:
            shown = _Progressive(self, res, job.camera.width, job.camera.height)
            progress = self._progress_callback(scene.frame_current)
            result = render_job.run(job, progress, self.test_break, shown.tile)
            if result.cancelled or self.test_break():
                self.end_result(res, cancel=True)
                return
            output.check_finite(result.rgba)
            if bpy.app.background or self.is_animation:  # the frame will be saved
                output.check_room_to_save(scene, job.width, job.height, len(passes))
            self._write_result(res, result, passes)
        except BaseException:
            self.end_result(res, cancel=True)  # nothing of a failed frame is committed
            raise
        self.end_result(res)
        if self.is_animation and job_exposure.frame is None:
            job_exposure.found(result.summary.get("disk_exposure"), scene.frame_current)
        text = render_job.finished(result.summary)
        self.update_stats("", f"SymRay: {text}")
        if bpy.app.background:
            print(f"SymRay: frame {scene.frame_current}: {text}")

    def _pin_exposure(self, job: render_job.RenderJob) -> None:
        """An animation's frames after the first take the first frame's automatic disk
        exposure (job_exposure), so that they do not flicker; said once per job."""
        if job_exposure.frame is None or not render_job.pin_exposure(job, job_exposure.value):
            return
        if not job_exposure.said:
            job_exposure.said = True
            self.report({"INFO"}, job_exposure.text())

    def _bake_progress(self, done: int, total: int, name: str) -> None:
        """The progress bar and status line while Cycles bakes the lighting (bake.py)."""
        if total > 0:
            self.update_progress(min(done / total, 1.0))
        if name:
            self.update_stats(
                "", f"SymRay: baking the lighting of '{name}' ({done + 1} of {total})"
            )
        else:
            self.update_stats("", f"SymRay: lighting of {total} objects baked")

    def _progress_callback(self, frame: int):
        """progress(done, total) for core.render: the progress bar and a status line; in
        the background (``blender -b``, a farm) a console line every PRINT_INTERVAL_S."""
        last_report = [0.0]
        started = time.monotonic()
        last_print = [started]

        def progress(done: int, total: int) -> None:
            if total > 0:
                self.update_progress(min(done / total, 1.0))
            now = time.monotonic()
            if now - last_report[0] > 0.25:
                last_report[0] = now
                self.update_stats("", f"SymRay: {done} of {total} pixels")
            if bpy.app.background and total > 0 and now - last_print[0] >= PRINT_INTERVAL_S:
                last_print[0] = now
                print(
                    f"SymRay: frame {frame}: {100 * done / total:.0f} % "
                    f"({done} of {total} pixels, {now - started:.0f} s)",
                    flush=True,
                )

        return progress

    def _write_result(self, res: Any, result: Any, passes: list[tuple[str, str]]) -> None:
        """Copy the image and passes into Blender's render result ``res`` (not committed),
        each with one ``foreach_set`` of a flat float32 buffer (``rect = array`` converts
        element by element: seconds at 1080p)."""
        layer = res.layers[0]
        write_pass(layer.passes["Combined"], result.rgba, 4)
        for core_name, name in passes:
            data = result.passes.get(core_name)
            render_pass = layer.passes.get(name)
            if data is not None and render_pass is not None:
                write_pass(render_pass, data, 1)


def write_pass(render_pass: Any, image: np.ndarray, channels: int) -> None:
    """Write a (h, w[, c]) top-first image into ``render_pass`` of the same size."""
    render_pass.rect.foreach_set(output.bottom_up(image, channels).reshape(-1))


PRINT_INTERVAL_S = 10.0
"""A background render prints its progress this often."""
SHOW_INTERVAL_S = 1.0
"""Finished tiles are shown at most this often (and never so often that showing them takes
more than SHOW_SHARE of the time): a redraw copies and redraws the whole frame."""
SHOW_SHARE = 0.05


class _Progressive:
    """Shows the finished tiles in the open render result (``update_result``), as Cycles
    shows its tiles; the result is committed (or discarded) by the engine at the end.

    Each tile is copied into a frame buffer (its own region only); the frame is pushed
    to Blender (``show``) when SHOW_INTERVAL_S has passed since the last push and the
    pushes have cost at most SHOW_SHARE of the time since the first tile."""

    clock = staticmethod(time.monotonic)

    def __init__(self, engine: SymRayRenderEngine, res: Any, width: int, height: int) -> None:
        self.engine, self.res = engine, res
        self.rgba = np.zeros((height, width, 4), dtype=np.float32)  # row 0 at the top
        self.start = self.last = self.clock()
        self.spent = 0.0
        self.shown = 0
        """Frames pushed to Blender so far."""

    def tile(self, rect: tuple[int, int, int, int], part: Any) -> None:
        """Copy a finished tile (x0, y0, x1, y1; row 0 at the top); redraw when due."""
        x0, y0, x1, y1 = rect
        self.rgba[y0:y1, x0:x1] = part.rgba.reshape(y1 - y0, x1 - x0, 4)
        now = self.clock()
        due = now - self.last >= SHOW_INTERVAL_S
        if due and self.spent <= SHOW_SHARE * (now - self.start):
            self.show()

    def show(self) -> None:
        """Push the frame so far to Blender's render window."""
        began = self.clock()
        write_pass(self.res.layers[0].passes["Combined"], self.rgba, 4)
        self.engine.update_result(self.res)
        self.last = self.clock()
        self.spent += self.last - began
        self.shown += 1


# Built-in panels shown for SYMRAY: every generic panel (those listing BLENDER_RENDER in
# COMPAT_ENGINES: camera, output, format, colour management, mesh data, ...) except
# Freestyle, which SymRay does not draw; plus the EEVEE material and world surface panels,
# which edit the Principled BSDF / Background nodes SymRay reads; and View Layer › Passes,
# where SymRay lists its own passes. Film (Filter Size, Transparent) is SymRay's own panel:
# the built-in ones carry engine settings SymRay does not have (EEVEE's overscan).
EXTRA_PANELS = (
    "EEVEE_MATERIAL_PT_context_material",
    "EEVEE_MATERIAL_PT_surface",
    "EEVEE_WORLD_PT_surface",
    "DATA_PT_lens",
    "VIEWLAYER_PT_layer_passes",
)
EXCLUDED_PREFIXES = ("RENDER_PT_freestyle", "VIEWLAYER_PT_freestyle", "MATERIAL_PT_freestyle")
_warned: set[str] = set()
"""Warnings reported in this render job (a still, or every frame of an animation)."""


class _JobExposure:
    """The automatic disk exposure of an animation render job's first frame."""

    def __init__(self) -> None:
        self.value: float | None = None
        self.frame: int | None = None
        self.said = False

    def found(self, value: float | None, frame: int) -> None:
        """Remember the first frame's exposure (nothing when it has no disk)."""
        if value is not None:
            self.value, self.frame = float(value), frame

    def text(self) -> str:
        """What the user is told once per job."""
        return (
            f"Auto Exposure: every frame of this animation uses frame {self.frame}'s disk "
            f"exposure {self.value:.3g}, so that the frames do not flicker (rendering frames "
            "in separate jobs, as a farm does? Press Pin beside Auto Exposure, or set "
            "Exposure to that value with Auto Exposure off, so that every job uses it)"
        )

    def clear(self) -> None:
        """A new render job."""
        self.value = self.frame = None
        self.said = False


job_exposure = _JobExposure()


@bpy.app.handlers.persistent
def _new_render_job(*_args: Any) -> None:
    """A render job starts (F12, or an animation before its first frame): warn afresh, and
    choose the automatic disk exposure afresh."""
    _warned.clear()
    job_exposure.clear()


_added_to: list[type] = []


def _compat_panels() -> list[type]:
    """Built-in panel classes that should list SYMRAY in their COMPAT_ENGINES."""
    panels = []
    for name in dir(bpy.types):
        cls = getattr(bpy.types, name, None)
        engines = getattr(cls, "COMPAT_ENGINES", None)
        if not isinstance(engines, set) or name.startswith(EXCLUDED_PREFIXES):
            continue
        if "BLENDER_RENDER" in engines or name in EXTRA_PANELS:
            panels.append(cls)
    return panels


def _add_compat_engine() -> None:
    """Add SYMRAY to the COMPAT_ENGINES of the built-in panels that apply."""
    for panel in _compat_panels():
        if "SYMRAY" not in panel.COMPAT_ENGINES:
            panel.COMPAT_ENGINES.add("SYMRAY")
            _added_to.append(panel)


def _remove_compat_engine() -> None:
    """Undo _add_compat_engine."""
    for panel in _added_to:
        panel.COMPAT_ENGINES.discard("SYMRAY")
    _added_to.clear()


def register() -> None:
    """Register the SYMRAY render engine."""
    bpy.utils.register_class(SymRayRenderEngine)
    _add_compat_engine()
    if _new_render_job not in bpy.app.handlers.render_init:
        bpy.app.handlers.render_init.append(_new_render_job)


def unregister() -> None:
    """Unregister the SYMRAY render engine."""
    if _new_render_job in bpy.app.handlers.render_init:
        bpy.app.handlers.render_init.remove(_new_render_job)
    _remove_compat_engine()
    bpy.utils.unregister_class(SymRayRenderEngine)

"""The SYMRAY render engine: F12, ``bpy.ops.render.render`` and ``blender -b -E SYMRAY``.

Each frame traces the evaluated depsgraph's scene (``render_job``; lit surfaces are baked
by Cycles first, or reused from the cache: bake.py), honouring the render
region (border), resolution percentage, Esc (``test_break``) and film transparency, and
writes the Combined pass plus "SymRay Error", "SymRay Steps", "SymRay Ending" and "SymRay
Redshift" (one channel 'X' each, when enabled in the SymRay panel). Saving is Blender's
business: choose OpenEXR MultiLayer in Output Properties to keep every pass.
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
        raise and keep the output file as it was (error_set alone or raising does not)."""
        self.report({"ERROR"}, message)
        self.error_set(message)
        if bpy.app.background:
            print(f"SymRay: error: {message}")

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
            result = render_job.run(job, self._progress_callback(), self.test_break, shown.tile)
            if result.cancelled or self.test_break():
                self.end_result(res, cancel=True)
                return
            output.check_finite(result.rgba)
            self._write_result(res, result, passes)
        except BaseException:
            self.end_result(res, cancel=True)  # nothing of a failed frame is committed
            raise
        self.end_result(res)
        text = render_job.finished(result.summary)
        self.update_stats("", f"SymRay: {text}")
        if bpy.app.background:
            print(f"SymRay: frame {scene.frame_current}: {text}")

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

    def _progress_callback(self):
        """progress(done, total) for core.render: the progress bar and a status line."""
        last_report = [0.0]

        def progress(done: int, total: int) -> None:
            if total > 0:
                self.update_progress(min(done / total, 1.0))
            now = time.monotonic()
            if now - last_report[0] > 0.25:
                last_report[0] = now
                self.update_stats("", f"SymRay: {done} of {total} pixels")

        return progress

    def _write_result(self, res: Any, result: Any, passes: list[tuple[str, str]]) -> None:
        """Copy the image and passes into Blender's render result ``res`` (not committed)."""
        layer = res.layers[0]
        layer.passes["Combined"].rect = output.bottom_up(result.rgba, 4)
        for core_name, name in passes:
            data = result.passes.get(core_name)
            render_pass = layer.passes.get(name)
            if data is not None and render_pass is not None:
                render_pass.rect = output.bottom_up(data, 1)


class _Progressive:
    """Shows each finished tile in the open render result (``update_result``), as Cycles
    shows its tiles; the result is committed (or discarded) by the engine at the end."""

    def __init__(self, engine: SymRayRenderEngine, res: Any, width: int, height: int) -> None:
        self.engine, self.res = engine, res
        self.rgba = np.zeros((height, width, 4), dtype=np.float32)  # row 0 at the top

    def tile(self, rect: tuple[int, int, int, int], part: Any) -> None:
        """Copy a finished tile (x0, y0, x1, y1; row 0 at the top) and redraw."""
        x0, y0, x1, y1 = rect
        self.rgba[y0:y1, x0:x1] = part.rgba.reshape(y1 - y0, x1 - x0, 4)
        self.res.layers[0].passes["Combined"].rect = output.bottom_up(self.rgba, 4)
        self.engine.update_result(self.res)


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


@bpy.app.handlers.persistent
def _new_render_job(*_args: Any) -> None:
    """A render job starts (F12, or an animation before its first frame): warn afresh."""
    _warned.clear()


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

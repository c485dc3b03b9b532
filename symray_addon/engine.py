"""The SYMRAY render engine: F12, ``bpy.ops.render.render`` and ``blender -b -E SYMRAY``.

Each frame traces the evaluated depsgraph's scene (``render_job``), honouring the render
region (border), resolution percentage, Esc (``test_break``) and film transparency, and
writes the Combined pass plus "SymRay Error", "SymRay Steps" and "SymRay Ending" (one
channel 'X' each, when enabled in the SymRay panel). Saving is Blender's business: choose
OpenEXR MultiLayer in Output Properties to keep every pass.
"""

from __future__ import annotations

import time
from typing import Any

import bpy
import numpy as np

from ..core.render import ALL_PASSES
from . import render_job

PASSES = tuple((name, f"SymRay {name.capitalize()}", f"pass_{name}") for name in ALL_PASSES)
"""(core pass, Blender pass name, scene.symray toggle), in core.render.ALL_PASSES order."""

last_summary: dict[str, Any] = {}
"""Summary of the last frame the engine rendered (for scripts and tests)."""


def enabled_passes(settings: Any) -> list[tuple[str, str]]:
    """(core pass, Blender pass name) of the passes switched on in ``settings``."""
    return [(core_name, name) for core_name, name, toggle in PASSES if getattr(settings, toggle)]


def _bottom_up(image: np.ndarray, channels: int) -> np.ndarray:
    """A (h, w[, c]) top-first image as a (h*w, channels) float32 bottom-up pass buffer."""
    flipped = np.asarray(image, dtype=np.float32)[::-1]
    return np.ascontiguousarray(flipped.reshape(-1, channels))


class SymRayRenderEngine(bpy.types.RenderEngine):
    """Symplectic ray tracing of bent light"""

    bl_idname = "SYMRAY"
    bl_label = "SymRay"
    bl_use_postprocess = True
    bl_use_preview = False
    bl_use_shading_nodes_custom = False
    bl_use_eevee_viewport = True

    def update_render_passes(self, scene: bpy.types.Scene | None = None,
                             renderlayer: bpy.types.ViewLayer | None = None) -> None:
        """Declare the passes so view layers and the compositor know them."""
        self.register_pass(scene, renderlayer, "Combined", 4, "RGBA", "COLOR")
        for _core_name, name in enabled_passes(scene.symray):
            self.register_pass(scene, renderlayer, name, 1, "X", "VALUE")

    def _fail(self, message: str) -> None:
        """Report a problem the user can fix; the frame stays empty."""
        self.report({"ERROR"}, message)
        self.error_set(message)
        if bpy.app.background:
            print(f"SymRay: error: {message}")

    def render(self, depsgraph: bpy.types.Depsgraph) -> None:
        """Trace one frame of the evaluated scene into the render result."""
        scene = depsgraph.scene
        settings = scene.symray
        self.update_stats("", "SymRay: reading the scene")
        try:
            job = render_job.prepare(scene, depsgraph, use_border=True,
                                     camera_object=self.camera_override)
        except (ValueError, OSError) as err:
            self._fail(str(err))
            return
        width, height = job.camera.width, job.camera.height
        passes = enabled_passes(settings)
        for _core_name, name in passes:
            self.add_pass(name, 1, "X")

        last_report = [0.0]

        def progress(done: int, total: int) -> None:
            if total > 0:
                self.update_progress(min(done / total, 1.0))
            now = time.monotonic()
            if now - last_report[0] > 0.25:
                last_report[0] = now
                self.update_stats("", f"SymRay: traced {done} of {total}")

        self.update_stats("", "SymRay: tracing")
        try:
            result = render_job.run(job, progress, self.test_break)
        except (ValueError, OSError) as err:
            self._fail(str(err))
            return
        if result.cancelled or self.test_break():
            return
        view_layer = depsgraph.view_layer.name if depsgraph.view_layer else ""
        # Coordinates are relative to the render region (border), which is what we traced.
        res = self.begin_result(0, 0, width, height, layer=view_layer)
        try:
            layer = res.layers[0]
            layer.passes["Combined"].rect = _bottom_up(result.rgba, 4)
            for core_name, name in passes:
                data = result.passes.get(core_name)
                render_pass = layer.passes.get(name)
                if data is not None and render_pass is not None:
                    render_pass.rect = _bottom_up(data, 1)
        finally:
            self.end_result(res)
        last_summary.clear()
        last_summary.update(result.summary)
        text = render_job.summary_text(result.summary)
        self.update_stats("", f"SymRay: {text}")
        if bpy.app.background:
            print(f"SymRay: frame {scene.frame_current}: {text}")


# Built-in panels shown for SYMRAY: every generic panel (those listing BLENDER_RENDER in
# COMPAT_ENGINES: camera, output, format, colour management, mesh data, ...) except
# Freestyle, which SymRay does not draw; plus the EEVEE material and world surface panels,
# which edit the Principled BSDF / Background nodes SymRay reads.
EXTRA_PANELS = ("EEVEE_MATERIAL_PT_context_material", "EEVEE_MATERIAL_PT_surface",
                "EEVEE_WORLD_PT_surface", "DATA_PT_lens")
EXCLUDED_PREFIXES = ("RENDER_PT_freestyle", "VIEWLAYER_PT_freestyle", "MATERIAL_PT_freestyle")
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


def unregister() -> None:
    """Unregister the SYMRAY render engine."""
    _remove_compat_engine()
    bpy.utils.unregister_class(SymRayRenderEngine)

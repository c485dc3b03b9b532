"""``symray.render``: trace the scene into an image (and optionally an EXR).

From the UI (invoke) the core render runs in a worker thread while a modal operator shows
progress in the status bar and the window's progress indicator; Esc cancels and leaves
the previous image as it was. Called from a script (execute) or in background mode it runs
synchronously. Only the main thread touches bpy data: the scene is read before the worker
starts (``render_job.prepare``) and the image/EXR written after it ends.
"""

from __future__ import annotations

from typing import Any, ClassVar

import bpy

from ..core import workers
from . import bake, output, render_job


class RenderTask(workers.BackgroundTask):
    """A core render in a worker thread, with progress and cancellation for the UI."""

    def __init__(self, job: render_job.RenderJob) -> None:
        """Wrap ``job``; call start() to begin."""
        super().__init__("SymRay render")
        self.job = job
        self.done = 0
        self.total = 0
        self.result: Any = None

    def _progress(self, done: int, total: int) -> None:
        self.done, self.total = int(done), int(total)

    def _work(self) -> None:
        self.result = render_job.run(self.job, self._progress, self._cancel.is_set)

    @property
    def fraction(self) -> float:
        """Progress in [0, 1]."""
        return min(self.done / self.total, 1.0) if self.total > 0 else 0.0

    def collect(self) -> Any:
        """After the worker ended: its result, None if cancelled; re-raises its error."""
        if self.error is not None:
            raise self.error
        if self.cancelled or self.result is None or getattr(self.result, "cancelled", False):
            return None
        return self.result


def finish(
    operator: bpy.types.Operator,
    result: Any,
    image_name: str,
    exr_path: str,
    passes: tuple[str, ...] = (),
) -> set[str]:
    """Write a finished render (the EXR pair with the ``passes`` switched on first, then
    the image); report and return the status."""
    if result is None or getattr(result, "cancelled", False):
        operator.report({"WARNING"}, "SymRay render cancelled; the previous image is unchanged")
        return {"CANCELLED"}
    output.check_finite(result.rgba)
    written = output.write_exr(exr_path, result.rgba, result.passes, passes) if exr_path else []
    try:
        output.write_image(image_name, result.rgba)
    except Exception as err:  # the message must say what was written before it
        files = " and ".join(f"'{path}'" for path in written)
        done = f"; {files} were written" if written else "; nothing was written"
        raise OSError(
            f"SymRay could not write image '{image_name}' ({type(err).__name__}: {err}){done}"
        ) from err
    text = render_job.finished(result.summary)
    if bpy.app.background:
        print(f"SymRay: {text}")
    operator.report({"INFO"}, f"SymRay: {text}")
    return {"FINISHED"}


class SYMRAY_OT_render(bpy.types.Operator):
    """Trace the scene with SymRay into the image named in the SymRay panel"""

    bl_idname = "symray.render"
    bl_label = "Render SymRay Image"
    bl_options = {"REGISTER"}

    _running: ClassVar[bool] = False

    @classmethod
    def poll(cls, context: bpy.types.Context) -> bool:
        """Needs a scene and no other SymRay render running."""
        return context.scene is not None and not cls._running

    def _prepare(self, context: bpy.types.Context) -> tuple[render_job.RenderJob, str, str]:
        """Check the settings and read the scene: the job, image name and EXR path (the
        passes switched on go to ``self._passes``)."""
        scene = context.scene
        image_name = output.check_image_name(scene.symray.image_name)
        exr_path = scene.symray.exr_path.strip()
        if exr_path:
            output.check_writable(exr_path)
        job = render_job.prepare(scene, context.evaluated_depsgraph_get())
        for warning in job.warnings:
            self.report({"WARNING"}, warning)
        self._passes = scene.symray.passes()
        return job, image_name, exr_path

    def _failed(self, err: Exception) -> set[str]:
        """Report any failure as an error (never a traceback); the image stays as it was."""
        self.report({"ERROR"}, render_job.failure_message(err))
        return {"CANCELLED"}

    def execute(self, context: bpy.types.Context) -> set[str]:
        """Render synchronously (scripts, background mode)."""
        try:
            job, image_name, exr_path = self._prepare(context)
            result = render_job.run(job)
            return finish(self, result, image_name, exr_path, self._passes)
        except Exception as err:  # every failure is reported, whatever it is
            return self._failed(err)

    def invoke(self, context: bpy.types.Context, event: bpy.types.Event) -> set[str]:
        """Render in a worker thread with progress; Esc cancels."""
        if bpy.app.background or context.window is None:
            return self.execute(context)
        try:
            job, self._image_name, self._exr_path = self._prepare(context)
        except Exception as err:  # every failure is reported, whatever it is
            return self._failed(err)
        self._task = RenderTask(job)
        self._task.start()
        wm = context.window_manager
        self._timer = wm.event_timer_add(0.1, window=context.window)
        wm.progress_begin(0, 1000)
        wm.modal_handler_add(self)
        SYMRAY_OT_render._running = True
        self._status(context, "SymRay: starting… (Esc to cancel)")
        return {"RUNNING_MODAL"}

    @staticmethod
    def _status(context: bpy.types.Context, text: str | None) -> None:
        workspace = getattr(context, "workspace", None)
        if workspace is not None:
            workspace.status_text_set(text)

    def _cleanup(self, context: bpy.types.Context) -> None:
        wm = context.window_manager
        if getattr(self, "_timer", None) is not None:
            wm.event_timer_remove(self._timer)
            self._timer = None
        wm.progress_end()
        self._status(context, None)
        SYMRAY_OT_render._running = False

    def modal(self, context: bpy.types.Context, event: bpy.types.Event) -> set[str]:
        """Poll the worker on timer events; Esc cancels."""
        task = self._task
        if event.type == "ESC" and event.value == "PRESS" and not task.cancelled:
            task.cancel()
            self._status(context, "SymRay: cancelling…")
            return {"RUNNING_MODAL"}
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        if not task.finished:
            context.window_manager.progress_update(int(1000 * task.fraction))
            if not task.cancelled:
                self._status(context, f"SymRay: {100 * task.fraction:.0f}% (Esc to cancel)")
            return {"PASS_THROUGH"}
        self._cleanup(context)
        try:
            return finish(self, task.collect(), self._image_name, self._exr_path, self._passes)
        except Exception as err:  # every failure is reported, whatever it is
            return self._failed(err)

    def cancel(self, context: bpy.types.Context) -> None:
        """Blender ended the modal operator (e.g. a file was loaded): stop the worker."""
        task = getattr(self, "_task", None)
        if task is not None:
            task.cancel()
            task.join(5.0)
        self._cleanup(context)


class SYMRAY_OT_bake_lighting(bpy.types.Operator):
    """Bake the light on every visible object with Cycles now, so that renders (F12
    included) reuse it until the scene changes"""

    bl_idname = "symray.bake_lighting"
    bl_label = "Bake Lighting"
    bl_options = {"REGISTER"}

    @classmethod
    def poll(cls, context: bpy.types.Context) -> bool:
        """Needs a scene with SymRay settings."""
        return context.scene is not None and hasattr(context.scene, "symray")

    def execute(self, context: bpy.types.Context) -> set[str]:
        """Bake (or find in the cache) every object's lighting for the current frame."""
        warnings: list[str] = []
        try:
            depsgraph = context.evaluated_depsgraph_get()
            surfaces = bake.bake_surfaces(context.scene, depsgraph, warnings)
        except Exception as err:  # every failure is reported, whatever it is
            self.report({"ERROR"}, render_job.failure_message(err))
            return {"CANCELLED"}
        for warning in warnings:
            self.report({"WARNING"}, warning)
        self.report({"INFO"}, f"SymRay: lighting of {len(surfaces)} objects baked")
        return {"FINISHED"}


class SYMRAY_OT_pin_exposure(bpy.types.Operator):
    """Measure the disk's automatic exposure at this frame and keep it (Auto Exposure off):
    every frame of an animation, and every job of a render farm, then uses the same"""

    bl_idname = "symray.pin_exposure"
    bl_label = "Pin Exposure"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context: bpy.types.Context) -> bool:
        """Needs a scene whose disk has Auto Exposure on."""
        settings = getattr(context.scene, "symray", None)
        return settings is not None and settings.disk.auto_exposure

    def execute(self, context: bpy.types.Context) -> set[str]:
        """Probe the current frame as F12 would, and set Exposure to what it finds."""
        scene = context.scene
        try:
            job = render_job.prepare(scene, context.evaluated_depsgraph_get())
            value = render_job.auto_exposure(job)
        except Exception as err:  # every failure is reported, whatever it is
            self.report({"ERROR"}, render_job.failure_message(err))
            return {"CANCELLED"}
        if value is None:
            self.report({"WARNING"}, "SymRay: this scene renders no accretion disk to expose")
            return {"CANCELLED"}
        disk = scene.symray.disk
        disk.exposure, disk.auto_exposure = value, False
        self.report({"INFO"}, f"SymRay: disk exposure pinned at {value:.4g} "
                              f"(frame {scene.frame_current})")  # fmt: skip
        return {"FINISHED"}


CLASSES = (SYMRAY_OT_render, SYMRAY_OT_bake_lighting, SYMRAY_OT_pin_exposure)


register, unregister = bpy.utils.register_classes_factory(CLASSES)
"""Register / unregister the render operator (in order, and in reverse)."""

"""The SymRay panels: Render Properties and View Layer › Passes when SymRay is the render
engine; for any other engine only a small panel with the Render SymRay Image button."""

from __future__ import annotations

import math
import textwrap

import bpy

from ..core.models.registry import MODELS, hole_kind, hole_parameters
from . import models, objects, observer, presets, properties, validation
from .capabilities import capabilities
from .operator import SYMRAY_OT_bake_lighting, SYMRAY_OT_render

WRAP = 60
"""Characters per line of error messages in the panel."""


def _error_lines(layout: bpy.types.UILayout, message: str) -> None:
    """Show an error message, wrapped, with an error icon on the first line."""
    col = layout.column(align=True)
    col.alert = True
    for i, line in enumerate(textwrap.wrap(message, WRAP) or [message]):
        col.label(text=line, icon="ERROR" if i == 0 else "BLANK1")


def _expression(
    layout: bpy.types.UILayout, settings: bpy.types.PropertyGroup, prop: str, error: str
) -> None:
    """An expression field, red with its message below while it is invalid."""
    row = layout.row()
    row.alert = bool(error)
    row.prop(settings, prop)
    if error:
        _error_lines(layout, error)


def render_problems(scene: bpy.types.Scene) -> list[str]:
    """What a render would stop with that is known before it: settings out of range (a
    .blend or a script can set anything), a method that cannot trace the model, a camera
    where no rays can start (inside a horizon, metric singular or of the wrong signature)."""
    settings = objects.effective(scene.symray)
    problems = validation.settings_problems(settings)
    if problems or scene.camera is None:
        return problems
    center = settings.center.matrix_world if settings.center is not None else None
    problem = models.camera_problem(
        settings, properties.metric_source(settings), center, scene.camera.matrix_world.translation
    )
    return [problem] if problem else []


ENGINE = "SYMRAY"
LIGHTING_LIMITS = (
    "Baked light is view-independent (no glossy, no refraction)",
    "and reaches surfaces on straight paths (Cycles' flat space)",
)
"""What baking cannot show, in two panel lines (README: Surfaces lit by Blender)."""


def _has_settings(context: bpy.types.Context) -> bool:
    """Whether the context has a scene with SymRay settings."""
    return context.scene is not None and hasattr(context.scene, "symray")


class SymRayPanelMixin:
    """Common placement: Render Properties, shown when SymRay is the render engine."""

    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "render"
    COMPAT_ENGINES = {ENGINE}

    @classmethod
    def poll(cls, context: bpy.types.Context) -> bool:
        """Shown when the scene renders with SymRay."""
        return _has_settings(context) and context.scene.render.engine in cls.COMPAT_ENGINES


class RENDER_PT_symray_launch(bpy.types.Panel):
    """The Render SymRay Image button for scenes that render with another engine"""

    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "render"
    bl_label = "SymRay"

    @classmethod
    def poll(cls, context: bpy.types.Context) -> bool:
        """Shown when another engine is chosen (SymRay's own panel has the button)."""
        return _has_settings(context) and context.scene.render.engine != ENGINE

    def draw(self, context: bpy.types.Context) -> None:
        """The render button and where SymRay's settings are."""
        layout = self.layout
        layout.label(text="Settings: choose the SymRay render engine", icon="INFO")
        layout.operator(SYMRAY_OT_render.bl_idname, icon="RENDER_STILL")


class RENDER_PT_symray(SymRayPanelMixin, bpy.types.Panel):
    """Model, its parameters and the render button"""

    bl_label = "SymRay"
    bl_order = 0

    def draw_header_preset(self, _context: bpy.types.Context) -> None:
        """The presets menu in the panel header."""
        self.layout.menu(presets.SYMRAY_MT_presets.bl_idname, text="Presets", icon="PRESET")

    def draw(self, context: bpy.types.Context) -> None:
        """Draw the model settings, the quality and the render button."""
        settings = context.scene.symray
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = True
        layout.prop(settings, "model")
        if settings.model == "OBJECTS":
            _scene_objects(layout, context.scene)
        else:
            layout.prop(settings, "center")
            _model_settings(layout, settings)
        _device_row(layout, context.scene.symray)
        layout.prop(settings, "quality")
        if settings.quality == "CUSTOM":
            layout.prop(settings, "tolerance_px")
            layout.prop(settings, "samples")
        elif settings.quality == "RADIANS":
            layout.prop(settings, "tolerance")
        layout.separator()
        for message in render_problems(context.scene):
            _error_lines(layout, message)
        row = layout.row()
        row.scale_y = 1.3
        row.operator(SYMRAY_OT_render.bl_idname, icon="RENDER_STILL")


def _device_row(layout: bpy.types.UILayout, settings) -> None:
    """Device: CPU / GPU, as Cycles has it; greyed out, the reason in its name, where no
    GPU can render (CuPy missing from Blender's Python, or no CUDA GPU; the whole message
    is a render problem once GPU is chosen)."""
    problem = validation.gpu_problem()
    row = layout.row()
    row.enabled = problem is None or settings.device == "GPU"
    if problem is None:
        row.prop(settings, "device")
    else:
        reason = "GPU needs CuPy" if "not installed" in problem else "no usable GPU"
        row.prop(settings, "device", text=f"Device ({reason})")


def _scene_objects(layout: bpy.types.UILayout, scene: bpy.types.Scene) -> None:
    """What the scene's SymRay objects make of the model: the hole's or medium's settings,
    or how to add one."""
    hole = objects.hole_of(scene)
    media = objects.of_kind(scene, "MEDIUM")
    if hole is not None:
        hole_settings(layout, hole)
    elif len(media) == 1:
        layout.label(text=f"Medium: {media[0].name}", icon="MOD_FLUID")
        medium_settings(layout, scene.symray)
    elif not objects.objects_problem(scene):
        col = layout.column(align=True)
        col.label(text="Flat space: the scene has no black hole", icon="INFO")
        col.label(text="Add one: Add › SymRay › Black Hole", icon="BLANK1")
        col.operator(objects.SYMRAY_OT_add_black_hole.bl_idname, text="Add Black Hole")


def hole_settings(layout: bpy.types.UILayout, hole: bpy.types.Object) -> None:
    """A hole object's Size and Spin, with its horizon and shadow in scene units."""
    layout.label(text=f"Black Hole: {hole.name}", icon="SHADING_SOLID")
    values = objects.hole_values(hole)
    problem = hole_kind(values).problem(values)
    layout.prop(hole.symray, "size")
    for parameter in hole_parameters():
        row = layout.row()
        row.alert = bool(problem)
        row.prop(hole.symray, parameter.name)
    if problem:
        _error_lines(layout, problem)
    shadow = 1.5 * math.sqrt(3.0) * values["rg"]  # from afar at spin 0 (Kerr: within ~7 %)
    layout.label(text=f"Its shadow's radius: about {_length(hole, shadow)}", icon="INFO")


def medium_settings(layout: bpy.types.UILayout, settings: bpy.types.PropertyGroup) -> None:
    """The refractive index and the optical form of the medium."""
    _expression(layout, settings, "refractive_index", settings.refractive_index_error)
    layout.prop(settings, "index_form")


def _length(datablock: bpy.types.ID, value: float) -> str:
    """A length in scene units as Blender writes it (unit system and scale of the scene
    of ``datablock``, or metres)."""
    scene = datablock if isinstance(datablock, bpy.types.Scene) else bpy.context.scene
    units = scene.unit_settings
    if units.system == "NONE":
        return f"{value:.3g}"
    return bpy.utils.units.to_string(
        units.system, "LENGTH", value * units.scale_length, precision=3
    )


def _model_settings(layout: bpy.types.UILayout, settings: bpy.types.PropertyGroup) -> None:
    """The explicit model's parameters (all models but Scene Objects): its registry kind's
    numbers (the row alert when they build no model), or its text inputs."""
    kind = MODELS.get(settings.model)
    if kind is None:
        return
    problem = bool(validation.parameter_problem(settings))
    for name in kind.parameter_names():
        row = layout.row()
        row.alert = problem and name != "rg"
        row.prop(settings, name)
    if kind.inputs:
        _TEXT_INPUTS[kind.inputs](layout, settings)


def _index_inputs(layout: bpy.types.UILayout, settings: bpy.types.PropertyGroup) -> None:
    """A medium's n(x, y, z), optical form and box."""
    medium_settings(layout, settings)
    layout.prop(settings, "use_medium_bounds")
    col = layout.column()
    col.active = settings.use_medium_bounds
    col.prop(settings, "medium_min")
    col.prop(settings, "medium_max")


def _metric_inputs(layout: bpy.types.UILayout, settings: bpy.types.PropertyGroup) -> None:
    """The inverse metric: one line, or a Text data-block."""
    if settings.metric_text is None:
        _expression(layout, settings, "metric", settings.metric_error)
    layout.prop(settings, "metric_text")
    if settings.metric_text is not None:
        error = validation.check_metric(properties.metric_source(settings))
        if error:
            _error_lines(layout, error)


def _hamiltonian_inputs(layout: bpy.types.UILayout, settings: bpy.types.PropertyGroup) -> None:
    """H(x, y, z, p_x, p_y, p_z) as text."""
    _expression(layout, settings, "hamiltonian", settings.hamiltonian_error)


_TEXT_INPUTS = {
    "index": _index_inputs,
    "metric": _metric_inputs,
    "hamiltonian": _hamiltonian_inputs,
}
"""A registry kind's ``inputs`` -> the rows that draw them."""


class RENDER_PT_symray_integration(SymRayPanelMixin, bpy.types.Panel):
    """How Hamilton's equations are integrated, and how the cores share the work"""

    bl_label = "Advanced"
    bl_parent_id = "RENDER_PT_symray"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context: bpy.types.Context) -> None:
        """Draw method, step limit and how the cores are shared."""
        settings = context.scene.symray
        layout = self.layout
        layout.use_property_split = True
        layout.prop(settings, "method")
        layout.prop(settings, "max_steps")
        layout.prop(settings, "parallel")
        layout.prop(settings, "workers")


class RENDER_PT_symray_disk(SymRayPanelMixin, bpy.types.Panel):
    """The accretion disk around a Schwarzschild or Kerr hole"""

    bl_label = "Accretion Disk"
    bl_parent_id = "RENDER_PT_symray"
    bl_options = {"DEFAULT_CLOSED"}

    @classmethod
    def poll(cls, context: bpy.types.Context) -> bool:
        """Shown for the black-hole models."""
        return super().poll(context) and capabilities(_model(context.scene)).disk

    def draw_header(self, context: bpy.types.Context) -> None:
        """The on/off switch in the header."""
        self.layout.prop(context.scene.symray.disk, "enabled", text="")

    def draw(self, context: bpy.types.Context) -> None:
        """Draw the disk's settings."""
        self.layout.active = context.scene.symray.disk.enabled
        disk_settings(self.layout, context.scene)


def _model(scene: bpy.types.Scene) -> str:
    """The model the scene renders with (Scene Objects resolved)."""
    return objects.effective(scene.symray).model


def disk_settings(layout: bpy.types.UILayout, scene: bpy.types.Scene) -> None:
    """The disk's radii (the innermost stable orbit in scene units), temperature and light."""
    settings = objects.effective(scene.symray)
    disk = settings.disk
    layout.use_property_split = True
    layout.prop(disk, "use_isco")
    row = layout.row()
    row.active = not disk.use_isco
    row.prop(disk, "inner_radius")
    if capabilities(settings.model).disk and settings.rg > 0:
        isco = _length(scene, validation.inner_edge(settings))
        layout.label(text=f"Innermost stable orbit: {isco}", icon="INFO")
    layout.prop(disk, "outer_radius")
    layout.prop(disk, "look")
    row = layout.row()
    row.active = disk.look == "CINEMATIC"
    row.prop(disk, "beaming")
    row = layout.row()
    row.prop(disk, "auto_exposure")
    if disk.auto_exposure:  # keep this frame's for an animation or a farm
        row.operator("symray.pin_exposure", text="Pin", icon="PINNED")
    row = layout.row()
    row.active = not disk.auto_exposure
    row.prop(disk, "exposure")
    layout.prop(disk, "brightness")
    layout.prop(disk, "profile")
    row = layout.row()
    row.active = disk.look == "PHYSICAL"  # the other looks keep only its profile's shape
    row.prop(disk, "temperature")
    layout.prop(disk, "doppler")
    layout.prop(disk, "opacity")


class RENDER_PT_symray_lighting(SymRayPanelMixin, bpy.types.Panel):
    """How surfaces are lit: baked by Cycles, or unlit"""

    bl_label = "Surface Lighting"
    bl_parent_id = "RENDER_PT_symray"

    def draw(self, context: bpy.types.Context) -> None:
        """Draw the lighting mode, the bake settings, their limits and the bake button."""
        settings = context.scene.symray
        layout = self.layout
        layout.use_property_split = True
        layout.prop(settings, "lighting")
        col = layout.column()
        col.active = settings.lighting != "UNLIT"
        col.prop(settings, "bake_texel_size")
        if settings.bake_texel_size == 0.0:
            col.label(text="Texel Size 0: automatic, ~1.5 px of the render", icon="INFO")
        col.prop(settings, "bake_max_resolution")
        col.prop(settings, "bake_samples")
        notes = col.column(align=True)
        for i, line in enumerate(LIGHTING_LIMITS):
            notes.label(text=line, icon="INFO" if i == 0 else "BLANK1")
        col.operator(SYMRAY_OT_bake_lighting.bl_idname, icon="LIGHT")


class RENDER_PT_symray_output(SymRayPanelMixin, bpy.types.Panel):
    """Background and where the SymRay Render operator writes"""

    bl_label = "Output"
    bl_parent_id = "RENDER_PT_symray"

    def draw(self, context: bpy.types.Context) -> None:
        """Draw background, image and EXR settings (passes: View Layer › Passes)."""
        settings = context.scene.symray
        layout = self.layout
        layout.use_property_split = True
        layout.prop(settings, "background")
        if settings.background == "STARS":
            layout.prop(settings, "star_catalog")
            column = layout.column()
            column.enabled = not settings.star_catalog.strip()
            column.prop(settings, "star_count")
            column.prop(settings, "star_seed")
            layout.prop(settings, "star_brightness")
        layout.prop(settings, "image_name")
        layout.prop(settings, "exr_path")


class VIEWLAYER_PT_symray_passes(SymRayPanelMixin, bpy.types.Panel):
    """SymRay's render passes, under View Layer › Passes"""

    bl_context = "view_layer"
    bl_label = "SymRay"
    bl_parent_id = "VIEWLAYER_PT_layer_passes"

    def draw(self, context: bpy.types.Context) -> None:
        """The pass toggles (each adds a 'SymRay ...' pass the compositor sees)."""
        settings = context.scene.symray
        layout = self.layout
        layout.use_property_split = True
        col = layout.column(heading="Include", align=True)
        for _core_name, _label, toggle in properties.PASSES:
            col.prop(settings, toggle)


class OBJECT_PT_symray(bpy.types.Panel):
    """A SymRay object's settings (a black hole or a medium), in Object Properties"""

    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "object"
    bl_label = "SymRay"

    @classmethod
    def poll(cls, context: bpy.types.Context) -> bool:
        """Shown for black hole and medium objects, whatever the render engine."""
        obj = context.object
        return (
            obj is not None
            and getattr(obj, "symray", None) is not None
            and (obj.symray.kind != "NONE")
        )

    def draw(self, context: bpy.types.Context) -> None:
        """The hole's size, spin and disk, or the medium's index."""
        obj, scene = context.object, context.scene
        layout = self.layout
        layout.use_property_split = True
        layout.prop(obj.symray, "kind")
        if obj.symray.kind == "BLACK_HOLE":
            hole_settings(layout, obj)
            layout.prop(scene.symray.disk, "enabled")
            col = layout.column()
            col.active = scene.symray.disk.enabled
            disk_settings(col, scene)
        else:
            medium_settings(layout, scene.symray)
            layout.label(text="The Empty's cube is the medium's box", icon="INFO")
        if scene.symray.model != "OBJECTS":
            _error_lines(layout, "The scene's SymRay model is not Scene Objects: this object "
                         "is not rendered as what it is")  # fmt: skip
        elif objects.objects_problem(scene):
            _error_lines(layout, objects.objects_problem(scene))


class RENDER_PT_symray_film(SymRayPanelMixin, bpy.types.Panel):
    """Blender's film settings that SymRay honours"""

    bl_label = "Film"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context: bpy.types.Context) -> None:
        """Filter Size (the anti-aliasing filter's width) and Transparent."""
        layout = self.layout
        layout.use_property_split = True
        col = layout.column()
        col.prop(context.scene.render, "filter_size")
        col.label(text="SymRay uses 0.01 to 2 px of it", icon="INFO")
        col.prop(context.scene.render, "film_transparent", text="Transparent")


class DATA_PT_symray_observer(SymRayPanelMixin, bpy.types.Panel):
    """Who looks through the camera (SymRay), in the camera's Object Data Properties"""

    bl_context = "data"
    bl_label = "SymRay Observer"

    @classmethod
    def poll(cls, context: bpy.types.Context) -> bool:
        """Shown for a camera when the scene renders with SymRay."""
        return super().poll(context) and getattr(context, "camera", None) is not None

    def draw(self, context: bpy.types.Context) -> None:
        """Static, Orbit, Infall, a velocity or From Animation; Shift Colours."""
        observer.observer_settings(self.layout, context.camera)


CLASSES = (
    RENDER_PT_symray,
    RENDER_PT_symray_integration,
    RENDER_PT_symray_disk,
    RENDER_PT_symray_lighting,
    RENDER_PT_symray_output,
    RENDER_PT_symray_launch,
    RENDER_PT_symray_film,
    VIEWLAYER_PT_symray_passes,
    OBJECT_PT_symray,
    DATA_PT_symray_observer,
)


register, unregister = bpy.utils.register_classes_factory(CLASSES)
"""Register / unregister the panels (in order, and in reverse)."""

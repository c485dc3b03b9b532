"""The SymRay panels: Render Properties and View Layer › Passes when SymRay is the render
engine; for any other engine only a small panel with the Render SymRay Image button."""

from __future__ import annotations

import textwrap

import bpy

from . import models, presets, properties, validation
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
    settings = scene.symray
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
        """Draw the model settings."""
        settings = context.scene.symray
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = True
        layout.prop(settings, "model")
        layout.prop(settings, "center")
        model = settings.model
        if capabilities(model).mass:
            layout.prop(settings, "rg")
        if model == "KERR":
            row = layout.row()
            row.alert = bool(validation.spin_problem(settings.spin))
            row.prop(settings, "spin")
        elif model == "MEDIUM":
            _expression(layout, settings, "refractive_index", settings.refractive_index_error)
            layout.prop(settings, "index_form")
            layout.prop(settings, "use_medium_bounds")
            col = layout.column()
            col.active = settings.use_medium_bounds
            col.prop(settings, "medium_min")
            col.prop(settings, "medium_max")
        elif model == "METRIC":
            if settings.metric_text is None:
                _expression(layout, settings, "metric", settings.metric_error)
            layout.prop(settings, "metric_text")
            if settings.metric_text is not None:
                error = validation.check_metric(properties.metric_source(settings))
                if error:
                    _error_lines(layout, error)
        elif model == "CUSTOM":
            _expression(layout, settings, "hamiltonian", settings.hamiltonian_error)
        layout.separator()
        for message in render_problems(context.scene):
            _error_lines(layout, message)
        row = layout.row()
        row.scale_y = 1.3
        row.operator(SYMRAY_OT_render.bl_idname, icon="RENDER_STILL")


class RENDER_PT_symray_integration(SymRayPanelMixin, bpy.types.Panel):
    """How Hamilton's equations are integrated"""

    bl_label = "Integration"
    bl_parent_id = "RENDER_PT_symray"

    def draw(self, context: bpy.types.Context) -> None:
        """Draw method, quality (accuracy), step limit and how the cores are shared."""
        settings = context.scene.symray
        layout = self.layout
        layout.use_property_split = True
        layout.prop(settings, "method")
        layout.prop(settings, "quality")
        if settings.quality == "CUSTOM":
            layout.prop(settings, "tolerance_px")
            layout.prop(settings, "samples")
        elif settings.quality == "RADIANS":
            layout.prop(settings, "tolerance")
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
        return super().poll(context) and capabilities(context.scene.symray.model).disk

    def draw_header(self, context: bpy.types.Context) -> None:
        """The on/off switch in the header."""
        self.layout.prop(context.scene.symray.disk, "enabled", text="")

    def draw(self, context: bpy.types.Context) -> None:
        """Draw the disk's radii, temperature and light."""
        settings = context.scene.symray
        disk = settings.disk
        layout = self.layout
        layout.use_property_split = True
        layout.active = disk.enabled
        layout.prop(disk, "use_isco")
        row = layout.row()
        row.active = not disk.use_isco
        row.prop(disk, "inner_radius")
        if settings.rg > 0:
            layout.label(text=f"ISCO: r = {validation.inner_edge(settings):.4g}", icon="INFO")
        layout.prop(disk, "outer_radius")
        layout.prop(disk, "profile")
        layout.prop(disk, "temperature")
        layout.prop(disk, "doppler")
        layout.prop(disk, "brightness")
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


CLASSES = (
    RENDER_PT_symray,
    RENDER_PT_symray_integration,
    RENDER_PT_symray_disk,
    RENDER_PT_symray_lighting,
    RENDER_PT_symray_output,
    RENDER_PT_symray_launch,
    RENDER_PT_symray_film,
    VIEWLAYER_PT_symray_passes,
)


register, unregister = bpy.utils.register_classes_factory(CLASSES)
"""Register / unregister the panels (in order, and in reverse)."""

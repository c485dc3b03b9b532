"""Presets for the seed paper's scenes, and the operator that applies them.

The refractive-index expressions of the seed's mirage figures (Satoh, "Symplectic Ray
Tracing", Eq. 17 and 18) live in ``core/presets.py`` and nowhere else. They are written for
the seed's literal optical Hamiltonian H = n |p|^2 / 2 (``index_form = 'SEED'``), so the
figures can be reproduced as printed; see docs/design.md, "Models and conventions".
"""

from __future__ import annotations

import math

import bpy
import numpy as np
from mathutils import Matrix, Vector

from ..core.presets import MIRAGE_EQ17_INDEX, MIRAGE_EQ18_INDEX
from . import models, objects, world

MINKOWSKI_METRIC = "-1, 0, 0, 0; 0, 1, 0, 0; 0, 0, 1, 0; 0, 0, 0, 1"
"""Flat spacetime in Cartesian coordinates (seed Eq. 13): the default user metric."""

PRESETS: dict[str, tuple[str, str, dict[str, object]]] = {
    "SCHWARZSCHILD_LENS": (
        "Schwarzschild Lens",
        "A black hole that does not spin (seed Eq. 15), Size 1, lensing the sky and the "
        "objects behind it; the camera frames it",
        {"hole.size": 1.0, "hole.spin": 0.0, "method": "AUTO", "tolerance": 1e-6},
    ),
    "KERR": (
        "Kerr Black Hole",
        "A black hole spinning at 0.9 of the fastest possible (seed Eq. 12), Size 1, about "
        "its local Z; the camera frames it",
        {"hole.size": 1.0, "hole.spin": 0.9, "method": "AUTO", "tolerance": 1e-6},
    ),
    "KERR_DISK": (
        "Kerr with Accretion Disk",
        "A black hole spinning at 0.9, Size 1, with a hot thin disk from its innermost "
        "stable orbit to 12× its size (Novikov–Thorne, 6000 K, Doppler, the Cinematic look), "
        "seen from 10° above the disk, and the SymRay Redshift pass",
        {
            "hole.size": 1.0,
            "hole.spin": 0.9,
            "method": "AUTO",
            "tolerance": 1e-6,
            "pass_redshift": True,
            "disk.enabled": True,
            "disk.use_isco": True,
            "disk.outer_radius": 12.0,
            "disk.profile": "NOVIKOV_THORNE",
            "disk.temperature": 6000.0,
            "disk.doppler": True,
            "disk.look": "CINEMATIC",
            "disk.auto_exposure": True,
            "disk.brightness": 1.0,
            "disk.opacity": 1.0,
        },
    ),
    "MIRAGE_EQ17": (
        "Mirage (Eq. 17)",
        "Refractive index of the seed's Eq. 17 with its literal Hamiltonian H = n|p|^2/2",
        {
            "model": "MEDIUM",
            "refractive_index": MIRAGE_EQ17_INDEX,
            "index_form": "SEED",
            "use_medium_bounds": False,
            "method": "AUTO",
            "tolerance": 1e-6,
        },
    ),
    "MIRAGE_EQ18": (
        "Mirage (Eq. 18)",
        "Refractive index of the seed's Eq. 18 with its literal Hamiltonian H = n|p|^2/2",
        {
            "model": "MEDIUM",
            "refractive_index": MIRAGE_EQ18_INDEX,
            "index_form": "SEED",
            "use_medium_bounds": False,
            "method": "AUTO",
            "tolerance": 1e-6,
        },
    ),
}
"""identifier -> (label, description, settings to assign to scene.symray; "disk.x" is
scene.symray.disk.x, "hole.x" the scene's black hole object's object.symray.x)."""

FILL = 0.7
"""A black hole preset's camera sees the hole (and disk) across this part of the frame."""
INCLINATION = {True: 80.0, False: 90.0}
"""Degrees between the hole's spin axis and the camera, with and without a disk."""


def apply_preset(settings: bpy.types.PropertyGroup, identifier: str) -> None:
    """Assign the values of preset ``identifier`` to ``settings`` (a scene.symray); a
    preset without a disk switches the disk off. A black hole preset sets the scene's
    hole object (made at the 3D cursor if it has none) and the model Scene Objects."""
    values = PRESETS[identifier][2]
    if "disk.enabled" not in values:
        settings.disk.enabled = False
    hole = None
    if any(key.startswith("hole.") for key in values):
        hole = objects.ensure_hole(settings.id_data)
        settings.model, settings.center = "OBJECTS", None
    for key, value in values.items():
        *group, name = key.split(".")
        target = (
            {"disk": settings.disk, "hole": hole and hole.symray}.get(group[0])
            if group
            else settings
        )
        setattr(target, name, value)


def frame_hole(scene: bpy.types.Scene, camera: bpy.types.Object) -> None:
    """Place ``camera`` to see the scene's hole (and its disk) across FILL of the frame:
    looking at its centre from INCLINATION off its spin axis."""
    hole = objects.hole_of(scene)
    if hole is None:
        return
    if bpy.context.scene == scene:  # a hole made just now: its matrix_world is not set yet
        bpy.context.view_layer.update()
    where = models.placement(hole.matrix_world)
    rg = objects.hole_values(hole)["rg"]
    disk = scene.symray.disk.enabled
    # what must fit: the disk's outer edge, or twice the shadow's radius (its lensed ring)
    extent = scene.symray.disk.outer_radius if disk else 2.0 * 1.5 * math.sqrt(3.0) * rg
    render = scene.render
    aspect = (
        render.resolution_x * render.pixel_aspect_x / (render.resolution_y * render.pixel_aspect_y)
    )
    data = camera.data
    data.sensor_fit = "AUTO"
    wide = 2.0 * math.atan(0.5 * data.sensor_width / data.lens)  # across the longer side
    narrow = 2.0 * math.atan(math.tan(0.5 * wide) / max(aspect, 1.0 / aspect))
    # a disk spans the frame's width; a hole alone its height
    half_angle = 0.5 * FILL * (wide if disk else narrow)
    distance = extent / math.tan(half_angle)
    inclination = math.radians(INCLINATION[disk])
    local = np.array([0.0, -math.sin(inclination), math.cos(inclination)])
    location = Vector(where.center + where.rotation @ local * distance)
    forward = Vector(-(where.rotation @ local))
    turn = forward.to_track_quat("-Z", "Y").to_matrix().to_4x4()
    # in the world, whatever the camera's parents (a rig) do to its own location/rotation
    camera.matrix_world = Matrix.Translation(location) @ turn
    data.clip_end = max(data.clip_end, 4.0 * distance)
    if bpy.context.scene == scene:
        bpy.context.view_layer.update()


class SYMRAY_OT_apply_preset(bpy.types.Operator):
    """Set the SymRay model and its parameters to one of the seed paper's scenes"""

    bl_idname = "symray.apply_preset"
    bl_label = "Apply SymRay Preset"
    bl_options = {"REGISTER", "UNDO"}

    preset: bpy.props.EnumProperty(  # type: ignore[valid-type]
        name="Preset",
        items=[(key, label, desc) for key, (label, desc, _) in PRESETS.items()],
    )
    add_center: bpy.props.BoolProperty(  # type: ignore[valid-type]
        name="Add Centre",
        description="Create an Empty at the world origin as the model's centre if none is set "
        "(the mirages; the black holes are objects of their own)",
        default=True,
    )
    frame_camera: bpy.props.BoolProperty(  # type: ignore[valid-type]
        name="Frame Camera",
        description="Move the scene camera (or add one) to see the black hole and its disk "
        f"across {FILL:.0%} of the frame",
        default=True,
    )

    def execute(self, context: bpy.types.Context) -> set[str]:
        """Apply the preset to the active scene."""
        scene = context.scene
        settings = scene.symray
        apply_preset(settings, self.preset)
        if settings.model == "OBJECTS":
            if self.frame_camera:
                frame_hole(scene, _scene_camera(scene))
            self._show_lensing(scene)
            return {"FINISHED"}
        if self.add_center and settings.center is None:
            empty = bpy.data.objects.new("SymRay Centre", None)
            empty.empty_display_type = "SPHERE"
            context.scene.collection.objects.link(empty)
            settings.center = empty
        return {"FINISHED"}

    def _show_lensing(self, scene: bpy.types.Scene) -> None:
        """A black hole preset's picture shows lensing: a plain-colour world (the factory
        grey) gives way to the procedural sky, and a hole inside an object is reported."""
        settings = scene.symray
        if settings.background == "AUTO" and world.plain_colour(scene):
            settings.background = "PROCEDURAL"
            self.report({"INFO"}, SKY_NOTE)
        hole = objects.hole_of(scene)
        warning = objects.inside_warning(scene, hole) if hole is not None else ""
        if warning:
            self.report({"WARNING"}, warning)


SKY_NOTE = (
    "Background set to Procedural Sky: the world is one plain colour, which shows nothing "
    "of the lensing (Render Properties › SymRay › Background › Auto shows the world again)"
)
"""What a black hole preset says when it gives a plain-colour world the procedural sky."""


def _scene_camera(scene: bpy.types.Scene) -> bpy.types.Object:
    """The scene's camera; a new one (made the scene camera) if it has none."""
    if scene.camera is None:
        camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
        scene.collection.objects.link(camera)
        scene.camera = camera
    return scene.camera


class SYMRAY_MT_presets(bpy.types.Menu):
    """Menu of the seed paper's scenes"""

    bl_idname = "SYMRAY_MT_presets"
    bl_label = "Presets"

    def draw(self, context: bpy.types.Context) -> None:
        """One entry per preset."""
        for key, (label, _desc, _values) in PRESETS.items():
            self.layout.operator(SYMRAY_OT_apply_preset.bl_idname, text=label).preset = key


CLASSES = (SYMRAY_OT_apply_preset, SYMRAY_MT_presets)


register, unregister = bpy.utils.register_classes_factory(CLASSES)
"""Register / unregister the preset operator and menu (in order, and in reverse)."""

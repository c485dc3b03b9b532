"""Who looks through a camera: its Observer setting (core.render's ``observer``).

Each camera holds ``camera.data.symray`` (SymRayObserverSettings): Static, Orbit, Infall,
a Velocity (units of c, world axes) or From Animation: the camera's own motion, the time
derivative of its animated location (central difference over one frame each side, at the
scene's frame rate), over the speed of light in Blender units per second that the user
sets. Only the location's animation counts (not drivers, constraints or a moving parent).
"""

from __future__ import annotations

from typing import Any

import bpy
import numpy as np

from ..core import motion

_KINDS = [
    ("STATIC", "Static", "At rest where it stands (around a spinning hole: the zero-angular-"
     "momentum observer, which turns with the hole's frame dragging)"),
    ("ORBIT", "Orbit", "On the prograde circular orbit through the camera (it must be in the "
     "hole's equatorial plane, outside the photon orbit)"),
    ("INFALL", "Infall", "Falling into the hole from rest far away"),
    ("VELOCITY", "Velocity", "Moving with the velocity set here (units of c, world axes), "
     "relative to the static observer"),
    ("ANIMATION", "From Animation", "Moving as the camera's animated location moves, with the "
     "speed of light set here"),
]  # fmt: skip


def _changed(settings: Any, _context: Any) -> None:
    """Tag the camera's data so that its evaluated copy (what a render reads) follows."""
    settings.id_data.update_tag()


class SymRayObserverSettings(bpy.types.PropertyGroup):
    """A camera's observer for SymRay (``camera.data.symray``)."""

    kind: bpy.props.EnumProperty(  # type: ignore[valid-type]
        name="Observer",
        items=_KINDS,
        default="STATIC",
        update=_changed,
        description="Who looks through this camera: its motion bends (aberration) and shifts "
        "(Doppler, beaming) the light it sees",
    )
    velocity: bpy.props.FloatVectorProperty(  # type: ignore[valid-type]
        name="Velocity",
        size=3,
        default=(0.0, 0.0, 0.0),
        update=_changed,
        soft_min=-0.99,
        soft_max=0.99,
        precision=4,
        description="The camera's velocity in units of the speed of light, world axes, "
        "relative to an observer at rest where it stands (its length must be below 1)",
    )
    speed_of_light: bpy.props.FloatProperty(  # type: ignore[valid-type]
        name="Speed of Light",
        default=100.0,
        update=_changed,
        min=1e-6,
        soft_max=1e4,
        unit="VELOCITY",
        description="The speed of light in Blender units per second of the animation (at "
        "the scene's frame rate): the camera's animated speed over this is its speed in c",
    )
    shift_colours: bpy.props.BoolProperty(  # type: ignore[valid-type]
        name="Shift Colours",
        default=True,
        update=_changed,
        description="Doppler-shift and beam what the moving camera sees (each colour as a "
        "black body of its colour temperature); off: only the aberration",
    )


def observer_options(scene: bpy.types.Scene, camera_object: Any) -> dict[str, Any]:
    """core.render's ``observer`` and ``shift_colours`` for ``camera_object`` (an evaluated
    camera, or None: the static observer); ValueError naming the problem (a speed at or
    above c)."""
    settings = getattr(getattr(camera_object, "data", None), "symray", None)
    if settings is None or settings.kind == "STATIC":
        return {}
    if settings.kind in ("ORBIT", "INFALL"):
        observer: Any = settings.kind.lower()
    elif settings.kind == "VELOCITY":
        observer = tuple(float(v) for v in settings.velocity)
    else:
        observer = tuple(float(v) for v in animated_velocity(scene, camera_object))
        observer = tuple(v / float(settings.speed_of_light) for v in observer)
    try:
        motion.check_observer(observer)
    except ValueError as err:
        raise ValueError(_refusal(camera_object.name, settings, observer, err)) from None
    return {"observer": observer, "shift_colours": bool(settings.shift_colours)}


def _refusal(camera: str, settings: Any, observer: Any, err: ValueError) -> str:
    """Why ``camera``'s observer is refused, naming its settings (and plain numbers)."""
    where = f"Camera '{camera}' › SymRay Observer"
    if isinstance(observer, str):
        return f"{where}: {err}"
    speed = float(np.linalg.norm(observer))
    limit = "it must be below the speed of light (1 c)"
    if settings.kind == "VELOCITY":
        return f"{where} › Velocity {motion.plain(observer)} has speed {speed:.6g} c: {limit}"
    return (
        f"{where} (From Animation): the camera moves at {speed:.6g} c, its animated velocity "
        f"over Speed of Light ({float(settings.speed_of_light):g} units/s): {limit}; raise "
        "Speed of Light or slow the camera"
    )


def animated_velocity(scene: bpy.types.Scene, camera_object: Any) -> np.ndarray:
    """The camera's world velocity (3,) in Blender units per second at the scene's frame:
    its location's F-curves differenced over one frame each side, through its parent's
    transform; zeros without an animated location."""
    curves = location_curves(camera_object)
    if not curves:
        return np.zeros(3)
    frame = scene.frame_current + scene.frame_subframe
    delta = np.array([
        curves[i].evaluate(frame + 1.0) - curves[i].evaluate(frame - 1.0) if i in curves else 0.0
        for i in range(3)
    ])  # fmt: skip
    world = np.array(camera_object.matrix_world, dtype=np.float64)
    basis = np.array(camera_object.matrix_basis, dtype=np.float64)
    parent = (world @ np.linalg.inv(basis))[:3, :3]  # what carries its location to the world
    fps = scene.render.fps / scene.render.fps_base
    return parent @ delta * (fps / 2.0)


def location_curves(obj: Any) -> dict[int, Any]:
    """The F-curves of ``obj``'s animated location by axis index (Blender 4.2's action
    F-curves, or 4.4+'s channel bag of the object's action slot)."""
    animation = getattr(obj, "animation_data", None)
    action = getattr(animation, "action", None)
    if action is None:
        return {}
    fcurves = getattr(action, "fcurves", None)
    if not fcurves and hasattr(action, "layers"):
        from bpy_extras import anim_utils

        channels = anim_utils.action_get_channelbag_for_slot(action, animation.action_slot)
        fcurves = channels.fcurves if channels is not None else []
    return {fc.array_index: fc for fc in fcurves or [] if fc.data_path == "location"}


def observer_settings(layout: Any, camera: Any) -> None:
    """The Observer panel's fields for a camera's data."""
    settings = camera.symray
    layout.use_property_split = True
    layout.prop(settings, "kind")
    if settings.kind == "VELOCITY":
        layout.prop(settings, "velocity")
    elif settings.kind == "ANIMATION":
        layout.prop(settings, "speed_of_light")
    if settings.kind != "STATIC":
        layout.prop(settings, "shift_colours")


def register() -> None:
    """Register the settings as ``bpy.types.Camera.symray``."""
    bpy.utils.register_class(SymRayObserverSettings)
    bpy.types.Camera.symray = bpy.props.PointerProperty(type=SymRayObserverSettings)


def unregister() -> None:
    """Remove ``bpy.types.Camera.symray`` and its class."""
    del bpy.types.Camera.symray
    bpy.utils.unregister_class(SymRayObserverSettings)

"""Blender camera + render settings -> keyword arguments of ``core.Camera.blender``."""

from __future__ import annotations

from typing import Any

import bpy
import numpy as np

_PANORAMA_KEYS = ("latitude_min", "latitude_max", "longitude_min", "longitude_max")


def border_of(render: bpy.types.RenderSettings) -> tuple[float, float, float, float] | None:
    """The render region (min_x, max_x, min_y, max_y) if border rendering is on, else None."""
    if not render.use_border:
        return None
    border = (render.border_min_x, render.border_max_x, render.border_min_y, render.border_max_y)
    if border == (0.0, 1.0, 0.0, 1.0):
        return None
    return border


def camera_kwargs(
    scene: bpy.types.Scene, camera_object: bpy.types.Object, use_border: bool = True
) -> dict[str, Any]:
    """Keyword arguments of ``core.Camera.blender`` for ``camera_object`` seen by ``scene``.

    Pass an evaluated camera object (``obj.evaluated_get(depsgraph)``) to see animation and
    drivers. ``use_border`` False ignores the scene's render region.
    """
    if camera_object is None or camera_object.type != "CAMERA":
        raise ValueError("The scene has no active camera: set Scene > Camera")
    cam = camera_object.data
    render = scene.render
    kwargs: dict[str, Any] = {
        "type": cam.type,
        "lens": float(cam.lens),
        "sensor_width": float(cam.sensor_width),
        "sensor_height": float(cam.sensor_height),
        "sensor_fit": cam.sensor_fit,
        "shift_x": float(cam.shift_x),
        "shift_y": float(cam.shift_y),
        "ortho_scale": float(cam.ortho_scale),
        "resolution_x": int(render.resolution_x),
        "resolution_y": int(render.resolution_y),
        "resolution_percentage": int(render.resolution_percentage),
        "pixel_aspect_x": float(render.pixel_aspect_x),
        "pixel_aspect_y": float(render.pixel_aspect_y),
        "matrix_world": np.array(camera_object.matrix_world, dtype=np.float64),
        "border": border_of(render) if use_border else None,
    }
    if cam.type == "PANO":
        # Blender 4.x/5.x keep the panorama settings on the camera itself.
        kwargs["panorama_type"] = getattr(cam, "panorama_type", "EQUIRECTANGULAR")
        for key in _PANORAMA_KEYS:
            if hasattr(cam, key):
                kwargs[key] = float(getattr(cam, key))
    return kwargs


def full_size(scene: bpy.types.Scene) -> tuple[int, int]:
    """Rendered frame size in pixels (resolution x percentage), as Blender computes it."""
    render = scene.render
    pct = int(render.resolution_percentage)
    return int(render.resolution_x) * pct // 100, int(render.resolution_y) * pct // 100

"""Render output as linear RGBA 32-bit float OpenEXR (tests and animation_job.py)."""

from __future__ import annotations

from pathlib import Path
from typing import Any


def exr_output(scene: Any, path: Path | str | None = None) -> None:
    """Make ``scene``'s renders write linear RGBA float EXR (to ``path`` exactly, when given:
    no frame number or extension added)."""
    settings = scene.render.image_settings
    if "media_type" in settings.bl_rna.properties:  # Blender 5
        settings.media_type = "IMAGE"
    settings.file_format = "OPEN_EXR"
    settings.color_depth = "32"
    settings.color_mode = "RGBA"
    if path is not None:
        scene.render.filepath = str(path)
        scene.render.use_file_extension = False


def read_exr(path: Path | str):
    """Pixels of an EXR file as (h, w, 4) float32, row 0 at the top (read by Blender)."""
    import bpy
    import numpy as np

    image = bpy.data.images.load(str(path))
    w, h = image.size
    flat = np.empty(w * h * 4, dtype=np.float32)
    image.pixels.foreach_get(flat)
    bpy.data.images.remove(image)
    return flat.reshape(h, w, 4)[::-1]

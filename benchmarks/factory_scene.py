"""The benchmarks' Blender scene: the factory startup scene with a SymRay preset (bpy wheel,
the extension installed in $BLENDER_USER_RESOURCES)."""

from __future__ import annotations

import importlib

import bpy

MODULE = "bl_ext.user_default.symray"
"""The installed extension's package."""


def preset_scene(preset: str, width: int, height: int) -> bpy.types.Scene:
    """The factory scene without its cube, SymRay the engine, at width x height (100 %),
    with a black hole preset applied (``ADD_BLACK_HOLE``: *Add › Black Hole* at the cursor
    with its defaults, the camera framed by it)."""
    bpy.ops.wm.read_homefile(use_factory_startup=True)
    bpy.ops.preferences.addon_enable(module=MODULE)
    bpy.data.objects.remove(bpy.data.objects["Cube"])
    scene = bpy.context.scene
    scene.render.engine = "SYMRAY"
    scene.render.resolution_x, scene.render.resolution_y = width, height
    scene.render.resolution_percentage = 100
    if preset == "ADD_BLACK_HOLE":
        bpy.ops.symray.add_black_hole()
        presets = importlib.import_module(f"{MODULE}.symray_addon.presets")
        presets.frame_hole(scene, scene.camera)
    else:
        bpy.ops.symray.apply_preset(preset=preset)
    bpy.context.view_layer.update()
    return scene

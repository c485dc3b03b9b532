"""Write old_centre.blend and old_centre_render.npz: a file saved by SymRay 470bb2e (before
the black hole became an object, issue 24) and what that version rendered of it.

Run once with that version's extension installed, in the oldest supported Blender (the
bpy 4.2 wheel, .venv311: 5.x reads 4.2 files, not the other way round):
    BLENDER_USER_RESOURCES=<folder with symray 470bb2e installed> python make_old_file.py
Two scenes: "Kerr" (model KERR set explicitly, a centre Empty off the origin, tilted, a
disk in scene units) and "Scene" (the model left at that version's default, Schwarzschild,
rg 0.7, with a centre Empty). Both leave Quality (then Final) and Background (then the
procedural sky over a plain grey world) at their defaults.
"""

from pathlib import Path

import bpy
import numpy as np

HERE = Path(__file__).resolve().parent


def _setup(scene: bpy.types.Scene) -> None:
    scene.render.engine = "SYMRAY"
    scene.render.resolution_x, scene.render.resolution_y = 64, 36
    scene.render.resolution_percentage = 100
    centre = bpy.data.objects.new(f"Centre {scene.name}", None)
    centre.location = (0.4, 0.3, 0.2)
    centre.rotation_euler = (0.2, -0.1, 0.3)
    scene.collection.objects.link(centre)
    scene.symray.center = centre


def main() -> None:
    bpy.ops.wm.read_homefile(use_factory_startup=True)
    bpy.ops.preferences.addon_enable(module="bl_ext.user_default.symray")
    bpy.data.objects.remove(bpy.data.objects["Light"])
    cube = bpy.data.objects["Cube"]
    cube.location, cube.scale = (-1.5, 4.0, 0.5), (0.5, 0.5, 0.5)
    default = bpy.context.scene
    kerr = default.copy()  # LINK_COPY: the same objects, its own settings
    kerr.name = "Kerr"
    kerr.use_fake_user = True  # no window shows it: saved only with a fake user
    for scene in (default, kerr):
        _setup(scene)
    default.symray.rg = 0.7
    kerr.symray.model = "KERR"
    kerr.symray.rg, kerr.symray.spin = 0.8, 0.7
    kerr.symray.disk.enabled = True
    kerr.symray.disk.outer_radius = 4.0
    renders = {}
    for scene in (default, kerr):
        scene.render.image_settings.file_format = "OPEN_EXR"
        scene.render.image_settings.color_depth = "32"
        bpy.ops.render.render(scene=scene.name)
        image = bpy.data.images["Render Result"]
        path = HERE / "old_render.exr"
        image.save_render(str(path), scene=scene)
        loaded = bpy.data.images.load(str(path))
        w, h = loaded.size
        renders[scene.name] = np.array(loaded.pixels[:], dtype=np.float32).reshape(h, w, 4)
        bpy.data.images.remove(loaded)
        path.unlink()
    bpy.ops.wm.save_as_mainfile(filepath=str(HERE / "old_centre.blend"), compress=True)
    np.savez_compressed(HERE / "old_centre_render.npz", **renders)


main()

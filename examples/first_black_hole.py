"""The first black hole a new user makes, as the README shows it.

    .venv/bin/python examples/first_black_hole.py --out docs/img/first_black_hole.png
    (bpy wheel, the extension installed: `make render` installs it)

Blender's factory scene (its cube, light, camera and grey world), SymRay chosen as the
render engine, *Add › SymRay › Black Hole* with its defaults, moved (as with G) to
``--location``, and F12 at the default quality (Preview), saved through Blender's own
view transform (AgX).
"""

from __future__ import annotations

import argparse
import os
import sys

import bpy

MODULE = "bl_ext.user_default.symray"


def main() -> None:
    """Build the scene, render it, save the PNG."""
    argv = sys.argv[sys.argv.index("--") + 1 :] if "--" in sys.argv else sys.argv[1:]
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="out/first_black_hole.png")
    parser.add_argument("--size", default="960x540", help="resolution, WxH")
    parser.add_argument("--location", default="-7.2,6.8,-2.0", help="the hole's x,y,z")
    args = parser.parse_args(argv)
    bpy.ops.wm.read_homefile(use_factory_startup=True)
    bpy.ops.preferences.addon_enable(module=MODULE)
    scene = bpy.context.scene
    scene.render.engine = "SYMRAY"
    scene.render.resolution_x, scene.render.resolution_y = (int(v) for v in args.size.split("x"))
    scene.render.resolution_percentage = 100
    bpy.ops.symray.add_black_hole()
    bpy.context.active_object.location = tuple(float(v) for v in args.location.split(","))
    bpy.context.view_layer.update()
    bpy.ops.render.render()
    settings = scene.render.image_settings
    settings.file_format, settings.color_mode = "PNG", "RGB"
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    bpy.data.images["Render Result"].save_render(os.path.abspath(args.out), scene=scene)
    print(f"first_black_hole: wrote {args.out}")


main()

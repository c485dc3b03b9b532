"""One farm worker's chunk: ``blender -b BLEND -E SYMRAY -s START -e END -a`` with the bpy wheel.

    python farm_chunk.py ZIP BLEND OUT --start S --end E

As a farm manager's job does (README, "Beyond one machine"): installs the extension ZIP
into this worker's own user folder (BLENDER_USER_RESOURCES, set by the caller), opens
BLEND, renders frames S..E of its animation with Blender's own writer into
OUT/frame_####.exr, and nothing else: every frame depends on the file and its number only.
"""

from __future__ import annotations

import argparse
import os


def main() -> None:
    """Install, open, render the chunk (see the module docstring)."""
    parser = argparse.ArgumentParser()
    parser.add_argument("zip")
    parser.add_argument("blend")
    parser.add_argument("out")
    parser.add_argument("--start", type=int, required=True)
    parser.add_argument("--end", type=int, required=True)
    args = parser.parse_args()
    assert os.environ.get("BLENDER_USER_RESOURCES"), "set BLENDER_USER_RESOURCES first"

    import bpy

    assert bpy.ops.extensions.package_install_files(
        filepath=args.zip, repo="user_default", enable_on_install=True
    ) == {"FINISHED"}
    bpy.ops.wm.open_mainfile(filepath=args.blend)
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = args.start, args.end  # -s, -e
    scene.render.filepath = os.path.join(args.out, "frame_")  # -o
    assert bpy.ops.render.render(animation=True) == {"FINISHED"}  # -a


if __name__ == "__main__":
    main()

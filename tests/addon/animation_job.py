"""An animation render with lit surfaces baked inside it, in a process of its own.

Run by test_bake_crashes.py and benchmarks/bench_bake_soak.py (a crash of Blender ends
only this process):

    python animation_job.py ZIP OUT --frames N [--stills 1,3] [--unlit 1] [--texel 0.25]

Installs the extension ZIP into the user folder named by BLENDER_USER_RESOURCES, loads
Blender's factory scene (the cube, the light, the camera in "Collection"), makes the light
a Sun and moves the cube over the frames, and renders ``render(animation=True)`` with
Surface Lighting *Auto* (each frame bakes again: the cube moves) into OUT/frame_####.exr.
Then, for each frame in --stills, a fresh bake (cache cleared) and an F12 still into
OUT/still_####.exr, and for each frame in --unlit an unlit still into OUT/unlit_####.exr.
OUT/report.json holds the resident memory after each frame (bytes; as it is, and once the
C heap gave its free pages back) and the bake counts.
"""

from __future__ import annotations

import argparse
import ctypes
import importlib
import json
import os
import resource
from pathlib import Path

from exr_output import exr_output  # this folder: the script's own


def _rss() -> int:
    """Resident memory of this process now, in bytes (Linux)."""
    with open("/proc/self/statm", encoding="ascii") as statm:
        return int(statm.read().split()[1]) * resource.getpagesize()


def _trimmed_rss() -> int:
    """Resident memory once the C heap has given its free pages back (glibc's malloc_trim):
    what the process holds, not what its allocator keeps for later."""
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):
        pass
    return _rss()


def _scene(frames: int, texel: float):
    """The factory scene, lit by a Sun, the cube moving from x = -1 to x = 1."""
    import bpy

    bpy.ops.wm.read_homefile(use_factory_startup=True)
    scene = bpy.context.scene
    scene.render.engine = "SYMRAY"
    scene.render.resolution_x, scene.render.resolution_y = 32, 24
    scene.render.resolution_percentage = 100
    scene.symray.model = "FLAT"
    scene.symray.quality = "RADIANS"
    scene.symray.lighting = "AUTO"
    scene.symray.bake_texel_size = texel
    scene.symray.bake_samples = 4
    light = bpy.data.objects["Light"]
    light.data.type = "SUN"
    light.data.energy = 3.0
    cube = bpy.data.objects["Cube"]
    scene.frame_start, scene.frame_end = 1, frames
    for frame, x in ((1, -1.0), (max(frames, 2), 1.0)):
        cube.location.x = x
        cube.keyframe_insert("location", index=0, frame=frame)
    exr_output(scene)
    scene.render.use_file_extension = True
    scene.frame_set(1)
    return scene


def _still(scene, frame: int, path: Path, lighting: str) -> None:
    """An F12 still of ``frame`` with a fresh bake (or unlit) into ``path``."""
    import bpy

    scene.frame_set(frame)
    scene.symray.lighting = lighting
    scene.render.filepath = str(path)
    scene.render.use_file_extension = False
    assert bpy.ops.render.render(write_still=True) == {"FINISHED"}
    scene.symray.lighting = "AUTO"


def main() -> None:
    """Render the animation, the stills and the report (see the module docstring)."""
    parser = argparse.ArgumentParser()
    parser.add_argument("zip")
    parser.add_argument("out", type=Path)
    parser.add_argument("--frames", type=int, default=3)
    parser.add_argument("--stills", default="")
    parser.add_argument("--unlit", default="")
    parser.add_argument("--texel", type=float, default=0.25, help="Bake Texel Size")
    args = parser.parse_args()
    assert os.environ.get("BLENDER_USER_RESOURCES"), "set BLENDER_USER_RESOURCES first"

    import bpy
    from bpy.app.handlers import persistent

    assert bpy.ops.extensions.package_install_files(
        filepath=args.zip, repo="user_default", enable_on_install=True
    ) == {"FINISHED"}
    bake = importlib.import_module("bl_ext.user_default.symray.symray_addon.bake")
    scene = _scene(args.frames, args.texel)
    rss: dict[int, int] = {}
    trimmed: dict[int, int] = {}

    @persistent
    def after_frame(scene, _depsgraph=None) -> None:
        rss[scene.frame_current] = _rss()
        trimmed[scene.frame_current] = _trimmed_rss()

    bpy.app.handlers.render_post.append(after_frame)
    scene.render.filepath = str(args.out / "frame_")
    assert bpy.ops.render.render(animation=True) == {"FINISHED"}
    bpy.app.handlers.render_post.remove(after_frame)
    baked = bake.stats["baked"]
    for frame in (int(f) for f in args.stills.split(",") if f):
        bake.clear_cache()
        _still(scene, frame, args.out / f"still_{frame:04d}.exr", "AUTO")
    for frame in (int(f) for f in args.unlit.split(",") if f):
        _still(scene, frame, args.out / f"unlit_{frame:04d}.exr", "UNLIT")
    report = {
        "rss": rss,
        "trimmed_rss": trimmed,
        "baked_in_animation": baked,
        "cached_bytes": sum(s.pixels.nbytes for s in bake._cache.values()),
        "scenes": len(bpy.data.scenes),
    }
    (args.out / "report.json").write_text(json.dumps(report), encoding="utf-8")


if __name__ == "__main__":
    main()

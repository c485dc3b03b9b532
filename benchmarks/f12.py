"""F12 against the core: what Blender's render operator adds to SymRay's own render.

    make bench-f12                            (installs the extension, then runs this)
    python benchmarks/f12.py [--size 1920x1080] [--scenes FACTORY,KERR_DISK]
        (bpy wheel, the extension installed in $BLENDER_USER_RESOURCES)

Per scene, the same frame twice: through the engine as F12 renders it
(``bpy.ops.render.render``), and through the add-on's own job (``render_job.prepare`` +
``render_job.run``: reading the scene, baking the lighting, tracing), each from a fresh
bake cache. Printed: both times and their ratio (issue 51's target: F12 within 1.1x of
the core, at 1080p on 2 cores), and how often the engine pushed the frame to Blender's
render window while tracing. Scenes: FACTORY is Blender's factory startup scene (cube,
light, camera) with SymRay as the engine; HOLE adds Add › Black Hole (with its disk, unlit)
and FLOOR a 30 m plane under them (issue 51's target: FLOOR <= 2x HOLE at 960x540
Preview, printed when both run); a preset name (KERR_DISK, ...) is the factory
scene without its cube and with that preset applied (benchmarks/factory_scene.py).
"""

from __future__ import annotations

import argparse
import importlib
import sys
import time

import bpy
from factory_scene import MODULE, preset_scene


def _scene(name: str, width: int, height: int) -> bpy.types.Scene:
    """The scene ``name`` at width x height, Preview, with its bake cache emptied."""
    if name in ("FACTORY", "HOLE", "FLOOR"):
        bpy.ops.wm.read_homefile(use_factory_startup=True)
        bpy.ops.preferences.addon_enable(module=MODULE)
        scene = bpy.context.scene
        scene.render.engine = "SYMRAY"
        scene.render.resolution_x, scene.render.resolution_y = width, height
        scene.render.resolution_percentage = 100
        if name != "FACTORY":  # Add › Black Hole (with its disk) at the cursor, unlit
            bpy.ops.symray.add_black_hole()
            scene.symray.lighting = "UNLIT"
        if name == "FLOOR":  # issue 51's floor: a 30 m plane under the hole and disk
            bpy.ops.mesh.primitive_plane_add(size=30, location=(0.0, 0.0, -1.0))
    else:
        scene = preset_scene(name, width, height)
    importlib.import_module(f"{MODULE}.symray_addon.bake").clear_cache()
    bpy.context.view_layer.update()
    return scene


def _core_seconds(name: str, width: int, height: int) -> float:
    """prepare + run of the scene's frame, as render_job does it."""
    job = importlib.import_module(f"{MODULE}.symray_addon.render_job")
    scene = _scene(name, width, height)
    began = time.perf_counter()
    job.run(job.prepare(scene, bpy.context.evaluated_depsgraph_get(), use_border=True))
    return time.perf_counter() - began


def _f12_seconds(name: str, width: int, height: int) -> tuple[float, int]:
    """bpy.ops.render.render of the scene's frame, and the frame pushes it made."""
    engine = importlib.import_module(f"{MODULE}.symray_addon.engine")
    _scene(name, width, height)
    pushes = [0]
    show = getattr(engine._Progressive, "show", None)
    if show is None:  # a baseline without counted pushes
        began = time.perf_counter()
        bpy.ops.render.render()
        return time.perf_counter() - began, -1

    def counted(self) -> None:
        pushes[0] += 1
        show(self)

    engine._Progressive.show = counted
    try:
        began = time.perf_counter()
        bpy.ops.render.render()
        return time.perf_counter() - began, pushes[0]
    finally:
        engine._Progressive.show = show


def main() -> None:
    """Time every scene both ways and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", default="1920x1080")
    parser.add_argument("--scenes", default="FACTORY,KERR_DISK")
    args = parser.parse_args(sys.argv[sys.argv.index("--") + 1 :] if "--" in sys.argv else None)
    width, height = (int(v) for v in args.size.split("x"))
    print(
        f"{'scene':12s} {'core s':>8s} {'F12 s':>8s} {'F12/core':>9s} {'target':>7s} {'pushes':>7s}"
    )
    seconds: dict[str, float] = {}
    for name in args.scenes.split(","):
        core_s = _core_seconds(name, width, height)
        f12_s, pushes = _f12_seconds(name, width, height)
        print(f"{name:12s} {core_s:8.1f} {f12_s:8.1f} {f12_s / core_s:9.2f} {1.1:7.1f} {pushes:7d}")
        seconds[name] = core_s
    if "HOLE" in seconds and "FLOOR" in seconds:
        print(f"FLOOR / HOLE (core): {seconds['FLOOR'] / seconds['HOLE']:.2f}x (target <= 2x)")


main()

"""How the black hole presets frame themselves, and what they cost at 1080p Preview.

    make bench-presets                      (installs the extension, then runs this)
    python benchmarks/presets.py [--size 1920x1080] [--quality PREVIEW]   (bpy wheel,
        the extension installed in $BLENDER_USER_RESOURCES)

Each black hole preset (and *Add › Black Hole* with its defaults) is applied to Blender's
factory scene without its cube (the hole goes to the cursor at the origin, where the cube
is), its camera framed by the preset; the frame is rendered as F12 renders it. Printed per
preset: the render's seconds and rays (its summary), and how much of the frame the hole
fills: with a disk, the share of the frame's width between the leftmost and rightmost
disk pixel (target ~0.7); without, the shadow's height over the frame's height (the
framing puts twice the shadow's diameter across 0.7 of it: target ~0.35). Targets of
issue 24: <= 20 s at 1920x1080 Preview on 2 cores.
"""

from __future__ import annotations

import argparse
import csv
import importlib
import os
import sys

import bpy
import numpy as np
from factory_scene import MODULE, preset_scene

PRESETS = ("SCHWARZSCHILD_LENS", "KERR", "KERR_DISK", "ADD_BLACK_HOLE")
SECONDS_TARGET = 20.0


def _scene(preset: str, width: int, height: int, quality: str) -> bpy.types.Scene:
    """The factory scene with the preset (factory_scene), at the given quality, with the
    Redshift and Ending passes."""
    scene = preset_scene(preset, width, height)
    scene.symray.quality = quality
    scene.symray.pass_redshift = scene.symray.pass_ending = True
    bpy.context.view_layer.update()
    return scene


def fill(scene: bpy.types.Scene, passes: dict) -> float:
    """The disk's width over the frame's, or (no disk) the shadow's height over the
    frame's."""
    if scene.symray.disk.enabled:
        columns = np.nonzero(np.isfinite(passes["redshift"]).any(axis=0))[0]
        return (columns.max() - columns.min() + 1) / passes["redshift"].shape[1]
    rows = np.nonzero((passes["ending"] == 1).any(axis=1))[0]
    return (rows.max() - rows.min() + 1) / passes["ending"].shape[0]


def main() -> None:
    """Render every preset and print the table (and out/bench/presets.csv)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", default="1920x1080")
    parser.add_argument("--quality", default="PREVIEW")
    parser.add_argument("--presets", default=",".join(PRESETS))
    args = parser.parse_args(sys.argv[sys.argv.index("--") + 1 :] if "--" in sys.argv else None)
    width, height = (int(v) for v in args.size.split("x"))
    job = importlib.import_module(f"{MODULE}.symray_addon.render_job")
    rows = []
    print(f"{'preset':20s} {'seconds':>8s} {'target':>7s} {'rays':>9s} {'fill':>6s} {'target':>7s}")
    for preset in args.presets.split(","):
        scene = _scene(preset, width, height, args.quality)
        out = job.run(job.prepare(scene, bpy.context.evaluated_depsgraph_get()))
        seconds, rays = out.summary["time_s"], out.summary["rays"]
        share = fill(scene, out.passes)
        aim = "~0.70" if scene.symray.disk.enabled else "~0.35"
        print(f"{preset:20s} {seconds:8.1f} {SECONDS_TARGET:7.0f} {rays:9d} {share:6.2f} {aim:>7s}")
        rows.append({"preset": preset, "seconds": seconds, "rays": rays, "fill": share})
    os.makedirs("out/bench", exist_ok=True)
    with open("out/bench/presets.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


main()

"""What the Rendered viewport costs: first image, full Preview, a re-shade, an orbit's redraws.

    make bench-viewport                      (installs the extension, then runs this)
    python benchmarks/viewport.py [--size 960x540] [--turns 1,2,5,10]   (bpy wheel, the
        extension installed in $BLENDER_USER_RESOURCES)

The *Kerr with Accretion Disk* preset on Blender's factory scene (its cube removed), seen
through its camera at --size, as the viewport's session renders it (symray_addon.viewport:
the scene read by render_job.prepare with the view's camera, core.viewport.ProgressiveView
with the scene's quality). Printed beside issue 25's targets (2 cores):

- first image: seconds from the start of a view to its first (1/8) level (<= 1 s);
- full Preview: seconds to its last level (<= 10 s);
- re-shade: seconds for core.viewport.reshade after a change of the disk's look (<= 0.5 s);
- orbit: per redraw, seconds for core.viewport.resample of the view turned by each of
  --turns degrees about the vertical at the same position (<= 0.3 s), and the share of its
  pixels covered (the rest waits for the new render).

Also written to out/bench/viewport.csv.
"""

from __future__ import annotations

import argparse
import csv
import importlib
import os
import sys
import time

import bpy
import numpy as np
from factory_scene import MODULE, preset_scene

TARGETS = {"first image": 1.0, "full preview": 10.0, "reshade": 0.5, "orbit redraw": 0.3}


def _turned(core, camera, degrees: float):
    """``camera`` turned by ``degrees`` about the world's vertical, at the same place."""
    angle = np.radians(degrees)
    turn = np.array(
        [[np.cos(angle), -np.sin(angle), 0.0], [np.sin(angle), np.cos(angle), 0.0], [0, 0, 1]]
    )
    frame = camera.frame
    basis = turn @ np.stack([frame.right, frame.up, -frame.forward], axis=1)
    return core.Camera(camera.kind, frame.position, basis, camera.window, camera.full_size)


def main() -> None:
    """Render the view, time each step, print the table (and out/bench/viewport.csv)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", default="960x540")
    parser.add_argument("--turns", default="1,2,5,10")
    args = parser.parse_args(sys.argv[sys.argv.index("--") + 1 :] if "--" in sys.argv else None)
    width, height = (int(v) for v in args.size.split("x"))
    core = importlib.import_module(f"{MODULE}.core")
    core_viewport = importlib.import_module(f"{MODULE}.core.viewport")
    render_job = importlib.import_module(f"{MODULE}.symray_addon.render_job")
    viewport = importlib.import_module(f"{MODULE}.symray_addon.viewport")

    scene = preset_scene("KERR_DISK", width, height)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    camera = render_job.prepare(scene, depsgraph).camera
    session = viewport.ViewSession(job=render_job.prepare(scene, depsgraph, view_camera=camera))
    start = time.perf_counter()
    session.restart(camera)
    levels = []
    while not session.view.join(0.01):
        image = session.view.latest
        if image is not None and (not levels or levels[-1][0] != image.level):
            levels.append((image.level, time.perf_counter() - start))
    if session.view.error is not None:
        raise session.view.error
    image = session.view.latest
    levels.append((image.level, time.perf_counter() - start))
    times = dict(levels)
    rows = [("first image", times[core_viewport.LEVELS[0]], "1/8 level")]
    for level in core_viewport.LEVELS[1:-1]:
        rows.append((f"level 1/{level}", times[level], ""))
    rays = image.summary.get("rays", 0)
    rows.append(("full preview", times[1], f"last level {image.seconds:.2f} s, {rays} rays"))

    scene.symray.disk.look = "EHT"
    bpy.context.view_layer.update()
    new = render_job.prepare(scene, bpy.context.evaluated_depsgraph_get(), view_camera=camera)
    tick = time.perf_counter()
    core_viewport.reshade(image, new.scene, camera, session.view.probe)
    rows.append(("reshade", time.perf_counter() - tick, "Cinematic -> EHT"))

    for degrees in (float(v) for v in args.turns.split(",")):
        turned = _turned(core, camera, degrees)
        tick = time.perf_counter()
        _, covered = core_viewport.resample(image, turned, session.job.scene)
        seconds = time.perf_counter() - tick
        rows.append(
            ("orbit redraw", seconds, f"turned {degrees:g} deg, {covered.mean():.1%} covered")
        )

    print(f"Kerr with Accretion Disk preset, {width}x{height} viewport, {os.cpu_count()} cores")
    print(f"{'step':14s} {'seconds':>8s} {'target':>7s}  notes")
    for name, seconds, notes in rows:
        target = TARGETS.get(name)
        aim = f"{target:7.1f}" if target else f"{'':7s}"
        missed = "*" if target and seconds > target else " "
        print(f"{name:14s} {seconds:8.2f}{missed}{aim}  {notes}")
    print("* : target missed")
    os.makedirs("out/bench", exist_ok=True)
    with open("out/bench/viewport.csv", "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["step", "seconds", "target", "notes"])
        writer.writerows([(n, f"{s:.3f}", TARGETS.get(n, ""), t) for n, s, t in rows])


main()

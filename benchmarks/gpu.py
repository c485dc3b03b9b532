"""The same frames on the CPU (all cores) and on a GPU (issue 47): times and per-pixel agreement.

    PYTHONPATH=. python3 benchmarks/gpu.py [--size 1920x1080]
        [--scenes board,board_final,disk,lens]
        [--device cuda] [--workers N] [--warmup 64x36] [--csv PATH]

Scenes (benchmarks/frame.py's Kerr board and camera): ``board`` (Preview: tolerance_px 1),
``board_final`` (Final: tolerance_px 0.25; the CPU with 16 samples, the GPU one ray per
pixel), ``disk`` (the board with an accretion disk, Preview), ``lens`` (a graded-index lens in
a box, benchmarks/honesty.py's luneburg_matched: a medium, its box region and the kink at
the lens's edge; no target). Each is rendered once by
core.render on the CPU (``--workers``, default every core; the adaptive sampler) and on
``--device`` after a warm-up render at ``--warmup`` size (CuPy compiles its kernels at the
first call). Printed per scene: both times, the GPU's speed-up, rays, and the agreement of
what each pixel centre sees (the ``direction`` pass): the share of pixels whose ending is the
same, and of those, the share whose directions agree within the tolerance (the larger of the
two renders' ``error`` estimates, at least tolerance_px), and the largest difference in px.
Issue 47's targets on an H100/H200: board Preview <= 0.5 s, Final <= 1.5 s, disk Preview
<= 0.5 s. ``--device double`` runs the CPU double of CuPy arrays (tests/device_double.py):
the script checked on a machine without a GPU (slow; small sizes).
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import os
import sys
import time

import numpy as np

import core
from benchmarks import frame, honesty

PASSES = ("error", "error_px", "steps", "ending", "direction")
SCENES = {  # name -> (tolerance_px, CPU samples)
    "board": (1.0, 1),
    "board_final": (0.25, 16),
    "disk": (1.0, 1),
    "lens": (1.0, 1),
}
TARGETS = {"board": 0.5, "board_final": 1.5, "disk": 0.5}
"""Issue 47's GPU times (seconds, H100/H200, after a warm-up)."""


def scene_of(name: str, width: int, height: int) -> tuple[core.Scene, core.Camera]:
    """(scene, camera): the Kerr board and frame.py's camera, with a disk for ``disk``;
    honesty.py's luneburg_matched for ``lens``."""
    if name == "lens":
        return honesty.luneburg_matched(width, height)
    scene = frame.kerr_board_scene()
    if name == "disk":
        scene = dataclasses.replace(scene, disk=core.AccretionDisk(r_out=10.0))
    return scene, frame.camera(width, height)


def device_of(name: str):
    """core.backend's device, or the CPU double for ``double``."""
    if name == "double":
        sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
        from tests.device_double import DEVICE

        return DEVICE
    return name


def timed(scene, camera, **options) -> tuple[float, core.RenderResult]:
    """(seconds, result) of one core.render."""
    start = time.perf_counter()
    result = core.render(scene, camera, passes=PASSES, **options)
    return time.perf_counter() - start, result


def agreement(cpu: core.RenderResult, gpu: core.RenderResult, px: float) -> tuple:
    """(share of pixels ending alike, share of those within tolerance, largest px apart)."""
    angle = cpu.summary["pixel_angle"]
    same = cpu.passes["ending"] == gpu.passes["ending"]
    a, b = cpu.passes["direction"][same], gpu.passes["direction"][same]
    seen = np.isfinite(a).all(axis=1) & np.isfinite(b).all(axis=1)
    cosine = np.clip(np.einsum("ij,ij->i", a[seen], b[seen]), -1.0, 1.0)
    apart = np.arccos(cosine) / angle
    allowed = np.maximum(
        px, np.maximum(cpu.passes["error_px"][same][seen], gpu.passes["error_px"][same][seen])
    )
    within = float(np.mean(apart <= allowed)) if apart.size else 1.0
    return float(np.mean(same)), within, float(apart.max(initial=0.0))


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", default="1920x1080")
    parser.add_argument("--scenes", default=",".join(SCENES))
    parser.add_argument("--device", default="cuda")
    parser.add_argument("--workers", type=int, default=None)
    parser.add_argument("--warmup", default="64x36")
    parser.add_argument("--csv", default=None)
    args = parser.parse_args(argv)
    width, height = (int(x) for x in args.size.split("x"))
    device = device_of(args.device)
    rows = []
    print(f"{args.size}, CPU: {args.workers or os.cpu_count()} workers, GPU: {args.device}")
    print("| scene | CPU s | GPU s | speed-up | target | CPU rays | GPU rays | ending same "
          "| within tol | max px |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name in args.scenes.split(","):
        px, samples = SCENES[name]
        scene, camera = scene_of(name, width, height)
        cpu_s, cpu = timed(scene, camera, tolerance_px=px, samples=samples, workers=args.workers)
        _, warm = scene_of(name, *(int(x) for x in args.warmup.split("x")))
        timed(scene, warm, tolerance_px=px, device=device)
        gpu_s, gpu = timed(scene, camera, tolerance_px=px, device=device)
        same, within, most = agreement(cpu, gpu, px)
        row = [name, cpu_s, gpu_s, cpu_s / gpu_s, TARGETS.get(name), cpu.summary["rays"],
               gpu.summary["rays"], same, within, most]  # fmt: skip
        rows.append(row)
        target = f"<= {TARGETS[name]}" if name in TARGETS else "–"
        print(f"| {name} | {cpu_s:.2f} | {gpu_s:.3f} | {cpu_s / gpu_s:.1f}x | {target} "
              f"| {row[5]} | {row[6]} | {100 * same:.2f} % | {100 * within:.2f} % "
              f"| {most:.2f} |")  # fmt: skip
    if args.csv:
        with open(args.csv, "w", newline="") as handle:
            writer = csv.writer(handle)
            writer.writerow(["scene", "cpu_s", "gpu_s", "speedup", "target_s", "cpu_rays",
                             "gpu_rays", "ending_same", "within_tol", "max_px"])  # fmt: skip
            writer.writerows(rows)


if __name__ == "__main__":
    main()

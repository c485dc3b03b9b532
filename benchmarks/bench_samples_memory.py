"""Peak memory of one worker against samples per pixel (issue 22; a benchmark, not a test).

    PYTHONPATH=. python benchmarks/bench_samples_memory.py [--size 128x96]
        [--samples 16,256,1024] [--scene kerr|edge]

Each sample count renders in a fresh subprocess, inline (one worker: the peak is that
worker's), with tolerance_px 0.25 (the add-on's Custom quality at its default accuracy).
Reported: the process's peak resident set (ru_maxrss) after imports and a warm-up render
(baseline) and after the frame, their difference (working), the rays traced and the time.
Target: working memory independent of the sample count (core.sampling.SAMPLE_POINTS bounds
the sub-pixel samples shaded at once).
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time

MIB = 1024.0  # ru_maxrss is in KiB on Linux


def _scene(name: str, width: int, height: int):
    import numpy as np  # noqa: F401

    import core

    if name == "edge":
        across = np.array([1.0, -0.3, 0.0]) / np.hypot(1.0, 0.3)
        disk = [
            core.Sphere(center=(x, y, 0), radius=0.7, color=(1, 1, 1, 1), object_id=k + 1)
            for k, (x, y) in enumerate([(-2, -1), (0, 1), (2, -1)])
        ]
        white = core.Plane(point=50.0 * across, normal=(0, 0, 1), u_axis=across,
                           extent=(100, 100), color=core.checker(40, 40))  # fmt: skip
        scene = core.Scene(objects=[white, *disk], background=(0, 0, 0))
        cam = core.Camera.orthographic((0, 0, 5), (0, 0, 0), (0, 1, 0), 8.0, width, height)
        return scene, cam
    sys.path.insert(0, "benchmarks")
    from image_precision import _black_hole_camera
    from image_quality import kerr_board_scene

    return kerr_board_scene(), _black_hole_camera(width, height)


def child(size: str, samples: int, scene_name: str) -> dict:
    """In a fresh process: baseline and peak ru_maxrss of one inline render."""
    import core

    width, height = (int(v) for v in size.split("x"))
    scene, cam = _scene(scene_name, width, height)
    small, small_cam = _scene(scene_name, 16, 12)
    core.render(small, small_cam, tolerance_px=0.25, samples=4, workers=1)  # warm-up
    base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    start = time.perf_counter()
    result = core.render(scene, cam, tolerance_px=0.25, samples=samples, workers=1)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return {
        "samples": samples,
        "baseline_mib": base / MIB,
        "peak_mib": peak / MIB,
        "working_mib": (peak - base) / MIB,
        "rays": result.summary["rays"],
        "seconds": time.perf_counter() - start,
    }


def main() -> None:
    """Run each sample count in its own subprocess and print a table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", default="128x96")
    parser.add_argument("--samples", default="16,256,1024")
    parser.add_argument("--scene", default="kerr", choices=("kerr", "edge"))
    parser.add_argument("--child", type=int, default=0, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(child(args.size, args.child, args.scene)))
        return
    print(f"{args.scene} {args.size}, tolerance_px 0.25, one worker (inline)")
    print("samples  baseline MiB  peak MiB  working MiB      rays  seconds")
    for samples in (int(s) for s in args.samples.split(",")):
        out = subprocess.run(
            [sys.executable, __file__, "--size", args.size, "--scene", args.scene,
             "--child", str(samples)],
            capture_output=True, text=True, check=True,
        )  # fmt: skip
        row = json.loads(out.stdout.strip().splitlines()[-1])
        print(
            f"{samples:7d}  {row['baseline_mib']:12.0f}  {row['peak_mib']:8.0f}  "
            f"{row['working_mib']:11.0f}  {row['rays']:8d}  {row['seconds']:7.1f}"
        )


if __name__ == "__main__":
    main()

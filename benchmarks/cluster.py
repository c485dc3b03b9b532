"""A frame on the built-in process pool beside the same frame on a Dask LocalCluster.

    PYTHONPATH=. python benchmarks/cluster.py [--width 1920 --height 1080] [--cores N]
        [--quality final|preview] [--sweep OUT]

The Kerr board (benchmarks/frame.py's scene and camera) rendered twice on the same cores,
one run after the other: core.render with N worker processes, then core.render(client=)
on a LocalCluster of N single-thread worker processes (TCP on localhost). Prints both
times, their ratio (the issue's target: the cluster within 1.15x of the pool) and whether
the images are equal bit for bit. ``--sweep OUT``: also a 3x3 sweep (spin x inclination,
``kerr_view``) on the cluster into OUT, with its table. Needs Dask (``core.cluster.INSTALL``).
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

import core
from benchmarks import frame
from core import hamiltonians as hm

QUALITY = {"final": {"tolerance_px": 0.25, "samples": 16}, "preview": {"tolerance_px": 1.0}}
"""The add-on's quality presets as core.render options."""


def kerr_view(spin: float = 0.6, inclination: float = 80.0, size: int = 32):
    """A sweep's scene and camera: a Kerr hole (rg 1, a/M ``spin``) before the procedural
    sky with a thin checker ring around it, seen from 30 rg at ``inclination`` degrees
    from the spin axis; a ``size`` x ``size`` * 3/4 image."""
    ring = core.Disk(center=(0, 0, 0), normal=(0, 0, 1), r_in=5.0, r_out=9.0,
                     color=core.checker(16, 2))  # fmt: skip
    scene = core.Scene(model=hm.kerr(rg=1.0, a=0.5 * spin, chart="kerr_schild"),
                       objects=[ring], background="procedural")  # fmt: skip
    tilt = math.radians(inclination)
    eye = (0.0, -30.0 * math.sin(tilt), 30.0 * math.cos(tilt))
    height = max(1, size * 3 // 4)
    camera = core.Camera.perspective(position=eye, look_at=(0, 0, 0), up=(0, 0, 1),
                                     fov_deg=40, width=size, height=height)  # fmt: skip
    return scene, camera


def _timed(label: str, **options) -> tuple[float, core.RenderResult]:
    """One render of the Kerr board with ``options``; prints and returns its time."""
    start = time.perf_counter()
    result = core.render(SCENE, CAMERA, **options)
    seconds = time.perf_counter() - start
    print(f"{label:>28}: {seconds:7.2f} s  ({result.summary['parallel']}, "
          f"{result.summary['rays']} rays)", flush=True)  # fmt: skip
    return seconds, result


SCENE = CAMERA = None


def main(argv: list[str] | None = None) -> None:
    """Parse the arguments, render on the pool and on the cluster, print the table."""
    global SCENE, CAMERA
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--width", type=int, default=1920)
    parser.add_argument("--height", type=int, default=1080)
    parser.add_argument("--cores", type=int, default=core.workers.available_cores())
    parser.add_argument("--quality", choices=sorted(QUALITY), default="final")
    parser.add_argument("--sweep", default=None, help="also run a 3x3 sweep into this folder")
    args = parser.parse_args(argv)
    from distributed import Client, LocalCluster

    SCENE, CAMERA = frame.kerr_board_scene(), frame.camera(args.width, args.height)
    options = QUALITY[args.quality]
    print(f"Kerr board {args.width}x{args.height} {args.quality}, {args.cores} cores")
    pool_s, pool = _timed("process pool", workers=args.cores, **options)
    with (
        LocalCluster(n_workers=args.cores, threads_per_worker=1, processes=True,
                     dashboard_address=":0") as cluster,
        Client(cluster) as client,
    ):  # fmt: skip
        dask_s, on_dask = _timed("Dask LocalCluster", client=client, **options)
        same = np.array_equal(pool.rgba, on_dask.rgba)
        print(f"{'cluster / pool':>28}: {dask_s / pool_s:7.2f}x   (target <= 1.15x)")
        print(f"{'images equal bit for bit':>28}: {same}")
        if args.sweep:
            start = time.perf_counter()
            rows = core.sweep(kerr_view, {"spin": [0.0, 0.5, 0.9], "inclination": [30, 60, 85],
                                          "size": [96]}, args.sweep, client=client,
                              tolerance_px=1.0)  # fmt: skip
            print(f"sweep of {len(rows)} images: {time.perf_counter() - start:.1f} s "
                  f"-> {args.sweep}/sweep.csv")  # fmt: skip


if __name__ == "__main__":
    main()

"""How many cores a frame can use: per-tile times from one run, the pool simulated.

    PYTHONPATH=. python benchmarks/scaling.py [--size 1920x1080] [--quality preview,final]
        [--workers 1,2,4,8,16,32] [--measure] [--csv PATH]

For each worker count N, the Kerr board (benchmarks/frame.py's scene and camera) is tiled
as core.render tiles it for N workers, and every tile is traced once in this process, one
after another (core.render inline with that tiling), its time taken; the rest of the
render's time is its serial part. The pool is then simulated: N workers each take the next
tile as they come free, in the order core.render hands them out (this code: costliest
first, ``render.costliest_first``) and in the former order (top to bottom). Printed per N:
the tiles, the longest tile's share, the work (the sum of the tiles: each tile pays its
quadtree rounds' per-step overhead, so more tiles cost more), and the speedup and
efficiency against the one-worker render (its own tiling: the fastest on one core).
Issue 47's target: >= 80 % of linear at 16 workers at 1080p. ``--measure`` also times
core.render at every N up to the machine's cores.
"""

from __future__ import annotations

import argparse
import csv
import sys
import time

import core
from benchmarks import frame
from benchmarks.cluster import QUALITY

RENDER = sys.modules["core.render"]
SCENE = None


def tile_times(camera, workers: int, options: dict) -> tuple[list, list, float]:
    """(tiles in row order, each one's seconds, the serial seconds): core.render inline
    with the tiling of ``workers`` workers."""
    spans: dict[int, float] = {}
    saved = RENDER.workers_module.choose, RENDER._tile_work

    def timed_work(sampler, tile_list):
        work = saved[1](sampler, tile_list)

        def timed(span, cancel):
            begin = time.perf_counter()
            out = work(span, cancel)
            spans[span[0]] = time.perf_counter() - begin
            return out

        return timed

    RENDER._tile_work = timed_work
    RENDER.workers_module.choose = lambda *a, **k: ("inline", workers)
    try:
        start = time.perf_counter()
        core.render(SCENE, camera, **options)
        total = time.perf_counter() - start
    finally:
        RENDER.workers_module.choose, RENDER._tile_work = saved
    tiles = RENDER._tiles_for(camera, workers)
    times = [spans[k] for k in range(len(tiles))]
    return tiles, times, total - sum(times)


def simulate(times: list[float], order: list[int], workers: int, serial: float) -> float:
    """Wall time of ``workers`` taking the tiles in ``order`` as they come free."""
    free = [0.0] * workers
    for k in order:
        i = min(range(workers), key=free.__getitem__)
        free[i] += times[k]
    return serial + max(free)


def hand_out_order(camera, tiles) -> list[int]:
    """The order this code hands the tiles out: costliest first."""
    middles = [((t.x0 + t.x1) / 2, (t.y0 + t.y1) / 2) for t in tiles]
    ranks = RENDER.expected_cost_rank(camera, SCENE.center, middles)
    return RENDER.costliest_first(list(range(len(tiles))), ranks)


def main(argv: list[str] | None = None) -> None:
    """Measure the tiles, simulate the pools, print the table."""
    global SCENE
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", default="1920x1080")
    parser.add_argument("--quality", default="preview,final")
    parser.add_argument("--workers", default="1,2,4,8,16,32")
    parser.add_argument("--measure", action="store_true")
    parser.add_argument("--csv", default=None)
    args = parser.parse_args(argv)
    width, height = (int(v) for v in args.size.split("x"))
    SCENE = frame.kerr_board_scene()
    camera = frame.camera(width, height)
    counts = [int(v) for v in args.workers.split(",")]
    rows = []
    print(f"Kerr board {width}x{height}; speedup and efficiency against one worker's render")
    print(f"{'quality':8s} {'N':>3s} {'tiles':>6s} {'longest':>8s} {'serial s':>9s} "
          f"{'work s':>8s} {'former':>16s} {'costliest first':>16s}")  # fmt: skip
    for quality in args.quality.split(","):
        options = QUALITY[quality]
        one = None
        for n in counts:
            tiles, times, serial = tile_times(camera, n, options)
            one = one or serial + sum(times)
            row = {"quality": quality, "workers": n, "tiles": len(tiles), "serial_s": serial,
                   "work_s": sum(times), "longest_share": max(times) / sum(times)}  # fmt: skip
            for name, order in (("former", list(range(len(tiles)))),
                                ("costliest_first", hand_out_order(camera, tiles))):  # fmt: skip
                speedup = one / simulate(times, order, n, serial)
                row[f"{name}_speedup"], row[f"{name}_efficiency"] = speedup, speedup / n
            rows.append(row)
            cells = [f"{row[f'{k}_speedup']:5.2f}x {row[f'{k}_efficiency']:6.1%}"
                     for k in ("former", "costliest_first")]  # fmt: skip
            print(f"{quality:8s} {n:3d} {len(tiles):6d} {row['longest_share']:8.1%} "
                  f"{serial:9.2f} {sum(times):8.1f} {cells[0]:>16s} {cells[1]:>16s}",
                  flush=True)  # fmt: skip
        if args.measure:
            for n in counts:
                if n > core.workers.available_cores():
                    break
                start = time.perf_counter()
                core.render(SCENE, camera, workers=n, **options)
                print(f"{quality:8s} {n:3d} measured: {time.perf_counter() - start:.2f} s")
    if args.csv:
        with open(args.csv, "w", newline="") as f:
            table = csv.DictWriter(f, fieldnames=list(rows[0]))
            table.writeheader()
            table.writerows(rows)


if __name__ == "__main__":
    main()

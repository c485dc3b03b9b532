"""How many cores a frame can use: per-tile times from one run, the pool simulated.

    PYTHONPATH=. python benchmarks/scaling.py [--size 1920x1080] [--quality preview,final]
        [--workers 1,2,4,8,16,32] [--reference-runs 2] [--measure] [--csv PATH]

For each worker count N, the Kerr board (benchmarks/frame.py's scene and camera) is tiled
as core.render tiles it for N workers, and every chunk (a tile, or with one worker a group
of tiles rendered together in shared rounds: ``render.tile_groups``) is traced once in
this process, one after another (core.render inline with that tiling), its time taken;
the rest of the render's time is its serial part. The reference is the best of
``--reference-runs`` one-worker renders. The pool is then simulated: N workers each take
the next chunk as they come free, in the order core.render hands them out (costliest
first) and top to bottom. Printed per N: the tiles and chunks, the longest chunk's
share, the work (the sum of the chunks: each pays its quadtree rounds' per-step
overhead, so more tiles cost more), and the speedup and efficiency against the one-worker
render (its own tiling).
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


def chunk_times(camera, workers: int, options: dict) -> tuple[list, list, float]:
    """(each chunk's tiles, in the order they are handed out; each chunk's seconds; the
    serial seconds): core.render inline with the tiling and grouping of ``workers``
    workers."""
    spans: dict[int, float] = {}
    members: dict[int, list] = {}
    saved = RENDER.workers_module.choose, RENDER._tile_work

    def timed_work(sampler, tile_list, groups):
        work = saved[1](sampler, tile_list, groups)

        def timed(span, cancel):
            begin = time.perf_counter()
            out = work(span, cancel)
            spans[span[0]] = time.perf_counter() - begin
            members[span[0]] = [tile_list[k] for k in groups[span[0]]]
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
    times = [spans[k] for k in range(len(spans))]
    return [members[k] for k in range(len(spans))], times, total - sum(times)


def reference_seconds(camera, options: dict, runs: int) -> float:
    """The one-worker render's seconds (its chunks and serial part): the best of ``runs``
    (a busy moment on a shared machine would flatter every other row)."""
    best = float("inf")
    for _ in range(max(1, runs)):
        _, times, serial = chunk_times(camera, 1, options)
        best = min(best, serial + sum(times))
    return best


def simulate(times: list[float], order: list[int], workers: int, serial: float) -> float:
    """Wall time of ``workers`` taking the chunks in ``order`` as they come free."""
    free = [0.0] * workers
    for k in order:
        i = min(range(workers), key=free.__getitem__)
        free[i] += times[k]
    return serial + max(free)


def top_to_bottom(chunks: list) -> list[int]:
    """The chunks in the order of their first tile from the top (the order before
    issue 47 handed them out)."""
    return sorted(range(len(chunks)), key=lambda k: min((t.y0, t.x0) for t in chunks[k]))


def main(argv: list[str] | None = None) -> None:
    """Measure the tiles, simulate the pools, print the table."""
    global SCENE
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", default="1920x1080")
    parser.add_argument("--quality", default="preview,final")
    parser.add_argument("--workers", default="1,2,4,8,16,32")
    parser.add_argument(
        "--reference-runs",
        type=int,
        default=2,
        help="one-worker renders whose best is the reference (noise)",
    )
    parser.add_argument("--measure", action="store_true")
    parser.add_argument("--csv", default=None)
    args = parser.parse_args(argv)
    width, height = (int(v) for v in args.size.split("x"))
    SCENE = frame.kerr_board_scene()
    camera = frame.camera(width, height)
    counts = [int(v) for v in args.workers.split(",")]
    rows = []
    print(f"Kerr board {width}x{height}; speedup and efficiency against one worker's render")
    print(f"{'quality':8s} {'N':>3s} {'tiles':>6s} {'chunks':>6s} {'longest':>8s} "
          f"{'serial s':>9s} {'work s':>8s} {'top down':>16s} "
          f"{'costliest first':>16s}")  # fmt: skip
    for quality in args.quality.split(","):
        options = QUALITY[quality]
        one = reference_seconds(camera, options, args.reference_runs)
        for n in counts:
            chunks, times, serial = chunk_times(camera, n, options)
            row = {"quality": quality, "workers": n, "tiles": sum(len(c) for c in chunks),
                   "chunks": len(chunks), "serial_s": serial, "work_s": sum(times),
                   "longest_share": max(times) / sum(times)}  # fmt: skip
            for name, order in (("top_down", top_to_bottom(chunks)),
                                ("costliest_first", list(range(len(chunks))))):  # fmt: skip
                speedup = one / simulate(times, order, n, serial)
                row[f"{name}_speedup"], row[f"{name}_efficiency"] = speedup, speedup / n
            rows.append(row)
            cells = [f"{row[f'{k}_speedup']:5.2f}x {row[f'{k}_efficiency']:6.1%}"
                     for k in ("top_down", "costliest_first")]  # fmt: skip
            print(f"{quality:8s} {n:3d} {row['tiles']:6d} {len(chunks):6d} "
                  f"{row['longest_share']:8.1%} {serial:9.2f} {sum(times):8.1f} "
                  f"{cells[0]:>16s} {cells[1]:>16s}", flush=True)  # fmt: skip
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

"""Peak memory of tiled Kerr renders against resolution (issue 13; a benchmark, not a test).

    PYTHONPATH=. python benchmarks/bench_memory.py [--sizes 1920x1080,3840x2160,7680x4320]
        [--presets preview,final] [--cancel-after-tiles N]

Target (issue 13): memory stays bounded by chunks at any resolution, 8K included. The
output image (RGBA float32 and the passes) is full-frame and cannot be avoided; what must
not grow with resolution is the *working* memory beyond it: the tiles in flight in the
workers and the finished tiles waiting for the caller.

Each size and preset renders the Kerr board scene of benchmarks/image_quality.py (a/M =
0.9, camera at 30 rg, default passes: error pass on) at the add-on's presets (Preview:
tolerance_px 1, 1 sample; Final: 0.25 px, 16 samples) in a fresh subprocess, so that
peaks never mix. There a thread sums the proportional set size (Pss, /proc/<pid>/
smaps_rollup: pages shared by the forked workers counted once) of the process and its
descendants every 20 ms. Reported: the peak total, the output buffers (rgba and every
pass array of the result, nbytes), the baseline (after imports and a 64x36 warm-up
render, before the frame), and working = peak - output - baseline. Verdict: working
memory flat in resolution, i.e. every size's working <= 1.5x the smallest size's (from
1920x1080 up, the tiles are bands of 484k-490k pixels, near MAX_TILE_PIXELS = 2^19, at
every size, so the working set should be the same; smaller frames have smaller tiles;
1.5x leaves room for the 20 ms sampling and malloc's slack, and anything that grows with
the frame, even 5 bytes a pixel, fails it at 8K: 160 MiB).
The ``error_px`` pass is a copy made after the workers have left: its 4 bytes a pixel count
in the output but never coincide with the workers' peak (working reads that much low).
A CSV goes to out/bench/memory.csv.
"""

from __future__ import annotations

import argparse
import csv
import glob
import json
import os
import resource
import subprocess
import sys
import threading
import time

from image_precision import _black_hole_camera
from image_quality import QUALITIES, kerr_board_scene

import core

OUT = os.path.join("out", "bench")
MIB = float(1 << 20)
FLAT = 1.5
"""Target: every size's working memory is at most FLAT x the smallest size's."""
INTERVAL_S = 0.02


def tree(pid: int) -> list[int]:
    """``pid`` and all its descendants (Linux: /proc/<pid>/task/*/children)."""
    found, todo = [], [pid]
    while todo:
        p = todo.pop()
        found.append(p)
        for path in glob.glob(f"/proc/{p}/task/*/children"):
            try:
                with open(path) as f:
                    todo += [int(c) for c in f.read().split()]
            except OSError:
                pass  # the process or thread has just gone
    return found


def pss_bytes(pid: int) -> int:
    """Proportional set size of one process, bytes (0 if it has gone)."""
    try:
        with open(f"/proc/{pid}/smaps_rollup") as f:
            for line in f:
                if line.startswith("Pss:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 0


class PeakSampler(threading.Thread):
    """Samples the summed Pss of this process tree every INTERVAL_S; keeps the peak."""

    def __init__(self) -> None:
        super().__init__(daemon=True)
        self.stopped = threading.Event()
        self.peak, self.peak_parent, self.peak_at, self.samples = 0, 0, 0.0, 0
        self.start_time = time.perf_counter()

    def sample(self) -> None:
        """One sample of the tree; the peak (and the parent's share of it) kept."""
        pids = tree(os.getpid())
        sizes = [pss_bytes(p) for p in pids]
        self.samples += 1
        if sum(sizes) > self.peak:
            self.peak, self.peak_parent = sum(sizes), sizes[0]
            self.peak_at = time.perf_counter() - self.start_time

    def run(self) -> None:
        """Sample until stopped."""
        while not self.stopped.wait(INTERVAL_S):
            self.sample()

    def stop(self) -> None:
        """Stop sampling after one last sample."""
        self.stopped.set()
        self.join()
        self.sample()


def output_bytes(result) -> int:
    """Bytes of the result's arrays: rgba and every pass."""
    return result.rgba.nbytes + sum(a.nbytes for a in result.passes.values())


def measure(width: int, height: int, preset: str, cancel_after: int | None) -> dict:
    """Render one frame here and return its figures (the child's side)."""
    scene = kerr_board_scene()
    px, samples = QUALITIES[preset]
    core.render(scene, _black_hole_camera(64, 36), tolerance_px=px, samples=samples)
    baseline = pss_bytes(os.getpid())
    camera = _black_hole_camera(width, height)
    tiles = [0]

    def on_tile(box, part) -> None:
        tiles[0] += 1

    sampler = PeakSampler()
    sampler.start()
    result = core.render(
        scene, camera, tolerance_px=px, samples=samples, on_tile=on_tile,
        should_cancel=None if cancel_after is None else lambda: tiles[0] >= cancel_after,
    )  # fmt: skip
    sampler.stop()
    s, output = result.summary, output_bytes(result)
    return {
        "size": f"{width}x{height}",
        "preset": preset,
        "seconds": s["time_s"],
        "complete": not result.cancelled,
        "tiles": tiles[0],
        "rays_per_pixel": s["rays"] / max(s["pixels"], 1),
        "parallel": s["parallel"],
        "peak_mib": sampler.peak / MIB,
        "peak_parent_mib": sampler.peak_parent / MIB,
        "peak_at_s": sampler.peak_at,
        "output_mib": output / MIB,
        "baseline_mib": baseline / MIB,
        "working_mib": (sampler.peak - output - baseline) / MIB,
        "maxrss_self_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "maxrss_children_mib": resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024,
        "pss_samples": sampler.samples,
    }


def run_child(size: str, preset: str, cancel_after: int | None) -> dict:
    """Measure one size and preset in a fresh interpreter; -> its figures."""
    cmd = [sys.executable, __file__, "--child", size, "--presets", preset]
    if cancel_after is not None:
        cmd += ["--cancel-after-tiles", str(cancel_after)]
    out = subprocess.run(cmd, check=True, stdout=subprocess.PIPE, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def report(row: dict) -> None:
    """Print one run's figures."""
    print(
        f"{row['size']:>9} {row['preset']:<7} {row['seconds']:7.1f} s "
        f"{row['rays_per_pixel']:5.2f} rays/px  peak {row['peak_mib']:7.0f} MiB "
        f"(parent {row['peak_parent_mib']:.0f}, at {row['peak_at_s']:.1f} s)  "
        f"output {row['output_mib']:6.0f}  baseline {row['baseline_mib']:4.0f}  "
        f"working {row['working_mib']:5.0f} MiB"
        + ("" if row["complete"] else f"  (cancelled after {row['tiles']} tiles)"),
        flush=True,
    )


def _pixels(size: str) -> int:
    """Pixels of a "WxH" size."""
    width, height = (int(v) for v in size.split("x"))
    return width * height


def verdict(rows: list[dict]) -> None:
    """Per preset: each size's working memory against the smallest size's (target FLAT x)."""
    for preset in dict.fromkeys(r["preset"] for r in rows):
        runs = [r for r in rows if r["preset"] == preset]
        first = min(runs, key=lambda r: _pixels(r["size"]))
        for r in runs:
            ratio = r["working_mib"] / first["working_mib"]
            print(
                f"{preset} {r['size']}: working {ratio:.2f}x the {first['size']} frame's "
                f"(target <= {FLAT}x): {'ok' if ratio <= FLAT else 'MISSED'}"
            )


def main() -> None:
    """Render each size and preset in a subprocess; print figures, verdict and a CSV."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="1920x1080,3840x2160")
    parser.add_argument("--presets", default="preview", help="preview and/or final")
    parser.add_argument("--cancel-after-tiles", type=int, default=None)
    parser.add_argument("--child", default=None, help=argparse.SUPPRESS)
    args = parser.parse_args()
    presets = [p.strip().capitalize() for p in args.presets.split(",")]
    if args.child:
        width, height = (int(v) for v in args.child.split("x"))
        print(json.dumps(measure(width, height, presets[0], args.cancel_after_tiles)))
        return
    rows = []
    for preset in presets:
        for size in args.sizes.split(","):
            rows.append(run_child(size, preset, args.cancel_after_tiles))
            report(rows[-1])
    verdict(rows)
    os.makedirs(OUT, exist_ok=True)
    with open(os.path.join(OUT, "memory.csv"), "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


if __name__ == "__main__":
    main()

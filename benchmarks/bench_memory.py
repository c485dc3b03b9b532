"""Peak memory of a 1920x1080 Kerr render (a benchmark script, not a test).

    PYTHONPATH=. python benchmarks/bench_memory.py [--chunks 6] [--full]

The renderer works in independent chunks of pixels, so memory is the full-frame output
buffers plus a bounded working set per chunk in flight. By default this renders the
first few chunks of the 1080p frame (then cancels) and prints the peak resident memory;
--full renders the whole frame.
"""

from __future__ import annotations

import argparse
import resource
import time

import core
from core import hamiltonians as hm


def peak_rss_mib() -> float:
    """Peak resident set size of this process, MiB (Linux reports KiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def main() -> None:
    """Render (part of) the 1080p Kerr frame and print time and peak memory."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--chunks", type=int, default=6)
    parser.add_argument("--chunk-size", type=int, default=16_384)
    parser.add_argument("--method", default="rk4")
    parser.add_argument("--full", action="store_true")
    args = parser.parse_args()
    cam = core.Camera.perspective(
        position=(0, -30, 3), look_at=(0, 0, 0), up=(0, 0, 1), fov_deg=40, width=1920, height=1080
    )
    scene = core.Scene(
        model=hm.kerr(rg=1.0, a=0.45, chart="kerr_schild"),
        objects=[core.Sphere(center=(0, 8, 0), radius=1, color=(1, 0, 0, 1))],
    )
    before = peak_rss_mib()
    limit = cam.n_pixels if args.full else args.chunks * args.chunk_size
    state = {"done": 0}

    def progress(done, total):
        state["done"] = done
        print(f"\r{done}/{total} pixels, peak RSS {peak_rss_mib():.0f} MiB", end="", flush=True)

    start = time.perf_counter()
    out = core.render(
        scene,
        cam,
        method=args.method,
        tolerance=1e-6,
        chunk_size=args.chunk_size,
        progress=progress,
        should_cancel=lambda: state["done"] >= limit,
    )
    seconds = time.perf_counter() - start
    print()
    print(
        f"rendered {state['done']} of {cam.n_pixels} pixels in {seconds:.1f} s "
        f"({'complete' if not out.cancelled else 'cancelled as asked'}); "
        f"peak RSS {peak_rss_mib():.0f} MiB (imports {before:.0f} MiB); target < 2048 MiB"
    )


if __name__ == "__main__":
    main()

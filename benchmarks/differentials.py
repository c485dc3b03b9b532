"""What ray differentials cost (issue 26): the same render with and without the
magnification pass, per traced ray.

    python benchmarks/differentials.py [--size 320x180] [--repeat 3] [--workers 2]
        [--scenes board,stars,...] [--modes bare,default,preview,final] [--csv PATH]

Each scene is rendered by core.render in each mode, alternately without and with the pass
(the best of ``--repeat`` runs of each), and the seconds per traced ray compared:

- ``bare``: every pixel centre traced at the default tolerance (1e-8 rad), the ``ending``
  pass alone: the trace itself, nothing else;
- ``default``: the same with core.render's default passes (the error pass's companion run
  among them, which carries no differentials);
- ``preview`` / ``final``: the add-on's Preview (1 px, one ray per pixel at most) and Final
  (0.25 px, up to 16 rays per pixel) adaptive renders, default passes: what a frame costs.

Scenes: ``board`` (Kerr a/M 0.9, a checker board behind the hole, camera at 30 rg:
benchmarks/frame.py) and benchmarks/honesty.py's scenes that carry differentials
(``stars``, ``schwarzschild``: Schwarzschild; ``point_stars``, ``near_tangent``,
``disk_high_spin``, ``far_small``, ``thin_front``: Kerr). Target: <= 1.6x per traced ray.
"""

from __future__ import annotations

import argparse
import csv
import importlib
import time

import frame
import honesty
from image_quality import QUALITIES

import core

render_module = importlib.import_module("core.render")  # core.render is also the function
DEFAULT_PASSES = render_module.DEFAULT_PASSES
TARGET = 1.6
MODES = {
    "bare": {"passes": ("ending",)},
    "default": {},
    "preview": dict(zip(("tolerance_px", "samples"), QUALITIES["Preview"], strict=True)),
    "final": dict(zip(("tolerance_px", "samples"), QUALITIES["Final"], strict=True)),
}
"""core.render's settings of each mode (see the module)."""
SCENES = ["board", "stars", "schwarzschild", "point_stars", "near_tangent", "disk_high_spin"]


def scene_and_camera(name: str, width: int, height: int):
    """(scene, camera) of a scene by name (see the module)."""
    if name == "board":
        return frame.kerr_board_scene(), frame.camera(width, height)
    return honesty.SCENES[name](width, height)


def timed(scene, camera, settings: dict, magnification: bool, workers: int):
    """(seconds, traced rays) of one core.render."""
    passes = tuple(settings.get("passes", DEFAULT_PASSES))
    if magnification:
        passes += ("magnification",)
    options = {key: value for key, value in settings.items() if key != "passes"}
    start = time.perf_counter()
    result = core.render(scene, camera, passes=passes, workers=workers, **options)
    return time.perf_counter() - start, int(result.summary["rays"])


def measure(name: str, mode: str, size: tuple[int, int], repeat: int, workers: int) -> dict:
    """One row: the best of ``repeat`` alternated runs without and with the pass."""
    scene, camera = scene_and_camera(name, *size)
    best: dict[bool, tuple[float, int]] = {}
    for _ in range(repeat):
        for magnification in (False, True):
            seconds, rays = timed(scene, camera, MODES[mode], magnification, workers)
            if magnification not in best or seconds < best[magnification][0]:
                best[magnification] = (seconds, rays)
    (plain, plain_rays), (with_pass, pass_rays) = best[False], best[True]
    ratio = (with_pass / pass_rays) / (plain / plain_rays)
    return {"scene": name, "mode": mode, "plain_s": round(plain, 3), "plain_rays": plain_rays,
            "with_pass_s": round(with_pass, 3), "with_pass_rays": pass_rays,
            "per_ray": round(ratio, 3), "met": ratio <= TARGET}  # fmt: skip


def main(argv: list[str] | None = None) -> list[dict]:
    """Print the table (and write ``--csv``)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", default="320x180")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--scenes", default=",".join(SCENES))
    parser.add_argument("--modes", default=",".join(MODES))
    parser.add_argument("--csv", default=None)
    args = parser.parse_args(argv)
    size = tuple(int(v) for v in args.size.split("x"))
    print(f"{'scene':15} {'mode':8} {'plain s':>8} {'rays':>8} {'+pass s':>8} {'rays':>8} "
          f"{'per ray':>8}  target <= {TARGET}x", flush=True)  # fmt: skip
    rows = []
    for name in args.scenes.split(","):
        for mode in args.modes.split(","):
            row = measure(name, mode, size, args.repeat, args.workers)
            rows.append(row)
            verdict = "met" if row["met"] else "MISSED"
            print(f"{name:15} {mode:8} {row['plain_s']:8.2f} {row['plain_rays']:8d} "
                  f"{row['with_pass_s']:8.2f} {row['with_pass_rays']:8d} "
                  f"{row['per_ray']:7.2f}x  {verdict}", flush=True)  # fmt: skip
    if args.csv:
        with open(args.csv, "w", newline="") as handle:
            writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
            writer.writeheader()
            writer.writerows(rows)
    return rows


if __name__ == "__main__":
    main()

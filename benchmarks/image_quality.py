"""Image quality per unit of time (issue 13): error-pass honesty, anti-aliasing, targets.

    python benchmarks/image_quality.py [--quick] [--only honesty,aa,speed]

- ``honesty``: the Kerr scene with a checker board (a/M = 0.9, camera at 30 rg) rendered at
  ``tolerance_px`` with the error pass, against a dopri5 render at 1e-11 rad (region
  1e6 rg: its far field is exact to ~3e-11): per pixel the true error (pixels) next to the
  estimate. Target: of the pixels whose true error exceeds tolerance_px / 10, >= 90 % have
  an estimate within 3x of the truth; <= 1 % of all pixels are under-reported > 3x.
- ``aa``: Schwarzschild + checker board at samples=16 (box filter) against 8x8
  supersampling box-filtered: mean and 99th-percentile absolute colour difference, and the
  cost relative to samples=1. Target: <= 0.02 mean, <= 0.1 p99, <= 3x the cost.
- ``versus`` (with ``--baseline DIR``, a checkout of BASELINE): that commit's gauss4 at the
  radian tolerance of 0.25 px against this code's default at 0.25 px (and Final), error
  pass on in all, alternated in one run, each with the share of escaped pixels within
  0.25 px of a dopri5 1e-11 render. Target: >= 4x faster at equal measured accuracy.
- ``speed``: Preview and Final frames of the Kerr board scene at a resolution (default
  512x288; --full: 1920x1080), seconds, rays per pixel and steps. Targets (2 cores, 1080p):
  Final with anti-aliasing and the error pass <= 5 min, Preview <= 20 s.

Figures print next to their targets; a CSV goes to out/bench/image_quality.csv.
"""

from __future__ import annotations

import argparse
import csv
import os
import subprocess
import sys
import time

import numpy as np
from image_precision import _black_hole_camera, schwarzschild_scene

import core
from core import hamiltonians as hm
from core.sampling import angle_between, seen_apart

BASELINE = "af19e2b"
"""The commit the adaptive image's speed-up is measured against (one ray a pixel, gauss4;
docs/performance.md keeps what it was)."""
OUT = os.path.join("out", "bench")


def kerr_board_scene() -> core.Scene:
    """Kerr a/M = 0.9 (rg = 1, Kerr-Schild) with a 16 rg checker board 12 rg behind it."""
    board = schwarzschild_scene().objects[0]
    return core.Scene(
        model=hm.kerr(rg=1.0, a=0.45, chart="kerr_schild"), objects=[board], background="procedural"
    )


def _seen(result, name: str = "direction") -> np.ndarray:
    return result.passes[name].reshape(-1, 3).astype(np.float64)


def true_error_px(ref, run, pixel: float, eye=None) -> np.ndarray:
    """Per pixel, how far (pixels) what the run shows is from what the reference shows
    (tolerance_px's measure, core.sampling.seen_apart): the angle between the escape
    directions; for a hit, with a position pass and the camera's ``eye``, the distance
    between the hit points over the pixel's footprint there (else the angle between the
    directions to them); inf where the endings differ; NaN where both are captured."""
    e_ref, e_run = ref.passes["ending"].ravel(), run.passes["ending"].ravel()
    with np.errstate(all="ignore"):
        if eye is not None and "position" in ref.passes and "position" in run.passes:
            apart = seen_apart(_seen(ref), _seen(ref, "position"), _seen(run),
                               _seen(run, "position"), e_ref, np.asarray(eye, float))  # fmt: skip
        else:
            apart = angle_between(_seen(ref), _seen(run))
        angle = apart / pixel
    angle = np.where(e_ref == e_run, angle, np.inf)
    return np.where((e_ref == e_run) & (e_ref == core.ENDING["captured"]), np.nan, angle)


def honesty(width: int, height: int, tolerance_px: float) -> dict:
    """Error-pass honesty on the Kerr board scene (see the module docstring)."""
    cam = _black_hole_camera(width, height)
    scene = kerr_board_scene()
    passes = ("error_px", "ending", "direction")
    t = time.perf_counter()
    ref = core.render(scene, cam, method="dopri5", tolerance=1e-11, passes=passes, max_steps=10**6)
    t_ref = time.perf_counter() - t
    run = core.render(scene, cam, tolerance_px=tolerance_px, passes=passes)
    pixel = run.summary["pixel_angle"]
    truth = true_error_px(ref, run, pixel)
    est = run.passes["error_px"].ravel().astype(np.float64)
    seen = np.isfinite(truth)
    big = seen & (truth > tolerance_px / 10)
    within = big & (est <= 3 * truth) & (est >= truth / 3)
    under = seen & (est < truth / 3) & (truth > 0)
    apart = np.count_nonzero(np.isinf(truth))
    row = {
        "test": "honesty",
        "size": f"{width}x{height}",
        "tolerance_px": tolerance_px,
        "pixels_true_above_tol10": int(big.sum()),
        "within_3x_share": float(within.sum() / max(big.sum(), 1)),
        "under_3x_share_all": float(under.sum() / truth.size),
        "ending_apart": int(apart),
        "true_p99_px": float(np.nanpercentile(truth[seen], 99)),
        "est_p99_px": float(np.nanpercentile(est[seen], 99)),
        "reference_s": t_ref,
        "seconds": run.summary["time_s"],
    }
    print(
        f"honesty {width}x{height} tol {tolerance_px} px: of {row['pixels_true_above_tol10']} "
        f"pixels with true error > tol/10, {100 * row['within_3x_share']:.1f} % estimated within "
        f"3x (target >= 90 %); under-reported > 3x: {100 * row['under_3x_share_all']:.2f} % of "
        f"all pixels (target <= 1 %); endings apart {apart}; p99 true {row['true_p99_px']:.3g} "
        f"px, estimate {row['est_p99_px']:.3g} px"
    )
    return row


def anti_aliasing(size: int) -> dict:
    """samples=16 against 8x8 supersampling (box) on the Schwarzschild board scene."""
    scene = schwarzschild_scene()
    cam = _black_hole_camera(size, size)
    common = dict(tolerance_px=0.25, pixel_filter="box", passes=())
    one = core.render(scene, cam, samples=1, **common)
    aa = core.render(scene, cam, samples=16, **common)
    big = _black_hole_camera(8 * size, 8 * size)
    ss = core.render(scene, big, tolerance_px=2.0, passes=())  # 0.25 px of the small image
    truth = ss.rgba[..., :3].reshape(size, 8, size, 8, 3).mean(axis=(1, 3))
    diff = np.abs(aa.rgba[..., :3] - truth).mean(axis=-1)  # per pixel, mean over R, G, B
    diff1 = np.abs(one.rgba[..., :3] - truth).mean(axis=-1)
    row = {
        "test": "aa",
        "size": f"{size}x{size}",
        "mean_abs": float(diff.mean()),
        "p99_abs": float(np.percentile(diff, 99)),
        "mean_abs_samples1": float(diff1.mean()),
        "cost_ratio": aa.summary["time_s"] / one.summary["time_s"],
        "rays_per_pixel": aa.summary["rays"] / aa.summary["pixels"],
    }
    print(
        f"anti-aliasing {size}x{size}: samples=16 vs 8x8 supersampled: mean {row['mean_abs']:.4f} "
        f"(target <= 0.02; samples=1: {row['mean_abs_samples1']:.4f}), p99 {row['p99_abs']:.3f} "
        f"(target <= 0.1), cost {row['cost_ratio']:.2f}x samples=1 (target <= 3x), "
        f"{row['rays_per_pixel']:.2f} rays/pixel"
    )
    return row


QUALITIES = {"Preview": (1.0, 1), "Final": (0.25, 16)}
"""The add-on's presets: (tolerance_px, samples)."""


def speed(width: int, height: int) -> list[dict]:
    """Preview and Final frames of the Kerr board scene, error pass on."""
    scene = kerr_board_scene()
    cam = _black_hole_camera(width, height)
    rows = []
    targets = {"Preview": 20.0, "Final": 300.0}
    for name, (px, samples) in QUALITIES.items():
        r = core.render(scene, cam, tolerance_px=px, samples=samples)
        s = r.summary
        rows.append(
            {
                "test": "speed",
                "size": f"{width}x{height}",
                "quality": name,
                "seconds": s["time_s"],
                "rays_per_pixel": s["rays"] / s["pixels"],
                "steps": s["steps"],
                "error_px_median": s["error_px_median"],
            }  # fmt: skip
        )
        target = f" (target at 1920x1080: <= {targets[name]:.0f} s)"
        print(
            f"{name} {width}x{height}: {s['time_s']:.1f} s{target}, "
            f"{rows[-1]['rays_per_pixel']:.2f} rays/pixel, {s['steps']} steps, "
            f"median error {s['error_px_median']:.3g} px, {s['parallel']}"
        )
    return rows


def before_after(out_dir: str, width: int = 320, height: int = 180) -> None:
    """docs/img/quality_before_after.png: the Kerr board scene with one ray through every
    pixel centre (before) and at Final quality (0.25 px, 16 samples), each with a 6x zoom
    of the shadow's edge (nearest-neighbour, so the pixels show)."""
    from core.imageio import write_png

    scene, cam = kerr_board_scene(), _black_hole_camera(width, height)
    before = core.render(scene, cam, tolerance=0.25 * cam.pixel_angle(), passes=()).rgba
    after = core.render(scene, cam, tolerance_px=0.25, samples=16, passes=()).rgba
    y0, x0, size = height // 2 - 34, width // 2 - 34, 30  # the shadow's upper-left edge
    rows = []
    for image in (before, after):
        zoom = np.kron(image[y0 : y0 + size, x0 : x0 + size], np.ones((6, 6, 1)))
        pad = np.zeros((height, zoom.shape[1] + 8, 4), dtype=np.float32)
        pad[:, :, 3] = 1.0
        pad[: zoom.shape[0], 8:] = zoom
        rows.append(np.concatenate([image, pad], axis=1))
    gap = np.ones((6, rows[0].shape[1], 4), dtype=np.float32)
    os.makedirs(out_dir, exist_ok=True)
    path = os.path.join(out_dir, "quality_before_after.png")
    write_png(path, np.concatenate([rows[0], gap, rows[1]], axis=0))
    print(f"wrote {path} (top: one ray a pixel; bottom: Final)")


def _frame(checkout: str, out: str, size, *flags: str) -> dict:
    """benchmarks/frame.py under ``checkout`` (its own core) -> its saved figures."""
    here = os.path.dirname(os.path.abspath(__file__))
    env = dict(os.environ, PYTHONPATH=os.path.abspath(checkout))
    out = os.path.abspath(out)
    command = [sys.executable, os.path.join(here, "frame.py"), out, "--width", str(size[0]),
               "--height", str(size[1]), *flags]  # fmt: skip
    subprocess.run(command, check=True, env=env, cwd=os.path.abspath(checkout))
    return dict(np.load(out))


def _within(ref: dict, run: dict, pixel: float, px: float = 0.25) -> float:
    """Share of the reference's escaped pixels that the run sees within ``px`` pixels."""
    escaped = (ref["ending"] == core.ENDING["escaped"]).ravel()
    u, v = ref["seen"].reshape(-1, 3)[escaped], run["seen"].reshape(-1, 3)[escaped]
    with np.errstate(all="ignore"):
        angle = angle_between(u, v)
    same = (run["ending"].ravel() == ref["ending"].ravel())[escaped]
    return float(np.mean(same & (angle / pixel <= px)))


def versus(
    baseline: str, width: int, height: int, repeats: int = 2, reference: bool = True
) -> list[dict]:
    """Today's main (a checkout at ``baseline``, gauss4 at 0.25 px in radians, error pass)
    against this code's default (0.25 px, error pass; and Final with 16 samples), alternated
    in one run; accuracy: the share of escaped pixels within 0.25 px of dopri5 1e-11."""
    os.makedirs(OUT, exist_ok=True)
    here = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    size = (width, height)
    pixel = _black_hole_camera(width, height).pixel_angle()
    ref_path = os.path.join(OUT, f"quality_ref_{width}x{height}.npz")
    if reference and not os.path.exists(ref_path):
        _frame(here, ref_path, size, "--method", "dopri5", "--tolerance", "1e-11")
    ref = dict(np.load(ref_path)) if reference else None  # without: no accuracy column
    runs = {
        f"{BASELINE} gauss4 0.25 px (radians)": (baseline, ("--method", "gauss4", "--tolerance",
                                                        f"{0.25 * pixel!r}")),
        "new default, 0.25 px, 1 sample": (here, ("--tolerance-px", "0.25")),
        "new default, Final (0.25 px, 16 samples)": (here, ("--tolerance-px", "0.25",
                                                            "--samples", "16")),
    }  # fmt: skip
    times: dict[str, list[float]] = {name: [] for name in runs}
    figures: dict[str, dict] = {}
    for _ in range(repeats):
        for name, (checkout, flags) in runs.items():
            figures[name] = _frame(checkout, os.path.join(OUT, "quality_run.npz"), size, *flags)
            times[name].append(float(figures[name]["seconds"]))
    rows = []
    base = min(times[next(iter(runs))])
    for name in runs:
        best = min(times[name])
        row = {"test": "versus", "size": f"{width}x{height}", "run": name, "seconds": best,
               "within_0.25px": _within(ref, figures[name], pixel) if ref else np.nan,
               "rays": int(figures[name]["rays"]), "speedup": base / best}  # fmt: skip
        rows.append(row)
        print(f"{width}x{height} {name}: {best:.1f} s (best of {repeats}), "
              f"{100 * row['within_0.25px']:.2f} % of escaped pixels within 0.25 px, "
              f"{row['rays']} rays, {row['speedup']:.2f}x {BASELINE} (target >= 4x)")  # fmt: skip
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small images")
    parser.add_argument("--full", action="store_true", help="speed at 1920x1080")
    parser.add_argument("--only", default="honesty,aa,speed")
    parser.add_argument("--aa-size", type=int, default=128)
    parser.add_argument("--images", default=None, help="write the before/after figure here")
    parser.add_argument("--baseline", default=None, help=f"a checkout of {BASELINE} (versus)")
    args = parser.parse_args()
    only = set(args.only.split(","))
    if args.images:
        before_after(args.images)
    rows: list[dict] = []
    if "honesty" in only:
        rows.append(honesty(*((64, 36) if args.quick else (160, 90)), tolerance_px=0.25))
    if "aa" in only:
        rows.append(anti_aliasing(32 if args.quick else args.aa_size))
    if "versus" in only and args.baseline:
        rows += versus(args.baseline, *((192, 108) if args.quick else (512, 288)))
    if "speed" in only:
        size = (1920, 1080) if args.full else ((256, 144) if args.quick else (512, 288))
        rows += speed(*size)
    os.makedirs(OUT, exist_ok=True)
    keys = sorted({k for r in rows for k in r})
    with open(os.path.join(OUT, "image_quality.csv"), "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=keys)
        writer.writeheader()
        writer.writerows(rows)


if __name__ == "__main__":
    main()

"""Image-level error against run time, scene by scene (part of `make bench`).

    PYTHONPATH=. python benchmarks/image_precision.py [--quick] [--scenes schwarzschild,mirage]

Every pixel of a scene is traced with each method at several tolerances (the tracer's own
step rule) and compared with a tight reference render (dopri5, tolerance 1e-11):

- escaped rays: the angle between the final directions, in pixels of the camera;
- rays that hit a surface: the distance between the hit points over the pixel's footprint
  there (distance from the camera x pixel angle), in pixels;
- pixels whose ending differs (escaped / captured / hit) are counted apart.

The verdict is the cheapest run with 99 % of the pixels within 0.1, 0.01 and 0.001 px (and
at most 1e-4 of them ending differently). The scenes:

- ``kerr``: the README's scene, a/M = 0.9 (Kerr–Schild), a red sphere behind the hole;
- ``kerr998``: the same at a/M = 0.998;
- ``schwarzschild``: the same camera, a = 0, a checker board behind the hole;
- ``mirage``: the seed's Fig. 10 view (hot ground, Eq. 17, literal form).

Black holes are traced with a region of 2000 rg (the far field beyond it is then common to
every run and the reference). Writes out/bench/image_<scene>.csv and .png.
"""

from __future__ import annotations

import argparse
import csv
import math
import os
import time
from dataclasses import dataclass

import numpy as np

import core
from core import hamiltonians as hm
from core.presets import MIRAGE_VIEWS, mirage_view
from core.sampling import angle_between
from core.trace import TraceOptions, Tracer

OUT = os.path.join("out", "bench")
REFERENCE = ("dopri5", 1e-11)
REGION = 2000.0
CHUNK = 8192


def _black_hole_camera(width: int, height: int) -> core.Camera:
    return core.Camera.perspective(
        position=(0, -30, 2),
        look_at=(0, 0, 0),
        up=(0, 0, 1),
        fov_deg=40,
        width=width,
        height=height,
    )


def kerr_scene(a: float = 0.45) -> core.Scene:
    """The README's Kerr scene: a/M = 0.9 (Kerr–Schild, rg = 1), a red sphere behind the
    hole; another spin ``a`` (a/M = 2 a)."""
    return core.Scene(
        model=hm.kerr(rg=1.0, a=a, chart="kerr_schild"),
        objects=[core.Sphere(center=(0, 8, 0), radius=1, color=(1, 0, 0, 1))],
        background="procedural",
    )


def schwarzschild_scene() -> core.Scene:
    """Schwarzschild (rg = 1) with a 16 rg checker board 12 rg behind the hole."""
    board = core.Plane(
        point=(0, 12, 0),
        normal=(0, -1, 0),
        u_axis=(1, 0, 0),
        extent=(16, 16),
        color=core.checker(8, 8),
    )
    return core.Scene(model=hm.schwarzschild(rg=1.0), objects=[board], background="procedural")


@dataclass
class SceneCase:
    """A scene, its camera and pixel angle, the region radius and the runs to compare."""

    scene: core.Scene
    camera: core.Camera
    pixel: float
    region: float | None
    runs: list[tuple[str, tuple[float, ...]]]


def scene_case(name: str, quick: bool) -> SceneCase:
    """The scene ``name`` at the size for ``quick`` or full runs."""
    if name == "mirage":
        w, h = (64, 48) if quick else (192, 144)
        scene, cam = mirage_view("fig10", w, h)
        fov = MIRAGE_VIEWS["fig10"][4]
        return SceneCase(scene, cam, math.radians(fov) / w, None, _runs(quick, media=True))
    size = 48 if quick else 192
    if name in KERR_SPINS:
        scene, runs = kerr_scene(KERR_SPINS[name]), _kerr_runs(quick)
    else:
        scene, runs = schwarzschild_scene(), _runs(quick, media=False)
    return SceneCase(scene, _black_hole_camera(size, size), math.radians(40.0) / size, REGION, runs)


KERR_SPINS = {"kerr": 0.45, "kerr998": 0.499}
"""Kerr scenes by name: spin a (rg = 1; a/M = 0.9 and 0.998)."""


def _kerr_runs(quick: bool):
    """Kerr's runs: the Kerr–Schild methods and the splittings of the Boyer–Lindquist
    square-root split (core/models/kerr_split.py), on one grid of tolerances from 1e-2."""
    if quick:
        grid = (1e-3, 1e-5)
        return [(m, grid) for m in ("rk4", "dopri5", "gauss4", "blanes_moan_s6", "blanes_moan_s10")]
    grid = (1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-8)
    return [
        ("rk4", grid),
        ("dopri5", grid),
        ("gauss4", (1e-2, 1e-3, 1e-4, 1e-6, 1e-8)),
        ("blanes_moan_s6", grid),
        ("blanes_moan_s10", grid),
        ("blanes_moan6", (1e-4, 1e-6)),
    ]


def _runs(quick: bool, media: bool, splits: bool = True):
    """(method, tolerances) per scene kind. Media's step rule goes by order alone (no
    calibrated constant), so their tolerances are a finer grid, the same for every method."""
    if media:
        grid = (1e-4, 1e-5, 1e-6) if quick else (1e-3, 1e-4, 3e-5, 1e-5, 3e-6, 1e-6, 1e-7)
        low = (1e-3, 1e-4) if quick else (1e-3, 3e-4, 1e-4, 3e-5, 1e-5)
        return [
            ("rk4", grid),
            ("dopri5", grid),
            ("gauss4", grid),
            ("yoshida4", grid),
            ("leapfrog", low),
            ("blanes_moan4", grid),
            ("blanes_moan6", grid),
        ]
    wide = (1e-4, 1e-6) if quick else (1e-4, 1e-5, 1e-6, 1e-7, 1e-8)
    tight = (1e-4, 1e-7) if quick else (1e-4, 1e-6, 1e-8, 1e-10)
    runs = [
        ("rk4", wide),
        ("dopri5", wide),
        ("gauss4", (1e-4, 1e-6) if quick else (1e-4, 1e-6, 1e-8)),
        ("yoshida4", (1e-4,) if quick else (1e-4, 1e-6)),
    ]
    if splits:
        runs += [
            ("leapfrog", (1e-4,) if quick else (1e-4, 1e-6)),
            ("blanes_moan4", tight),
            ("blanes_moan6", tight),
        ]
    return runs


def trace(case: SceneCase, method: str, tolerance: float):
    """(ending, direction, position, steps, seconds) of every pixel."""
    extent = float(np.linalg.norm(case.camera.frame.position - case.scene.center))
    options = TraceOptions(
        method=method, tolerance=tolerance, region_radius=case.region, max_steps=10**6
    )
    tracer = Tracer(case.scene, options, extent)
    n = case.camera.n_pixels
    ending, steps = np.empty(n, np.int8), np.empty(n, np.int64)
    direction, position = np.empty((n, 3)), np.empty((n, 3))
    start = time.perf_counter()
    for a in range(0, n, CHUNK):
        b = min(a + CHUNK, n)
        origins, dirs = case.camera.rays(a, b)
        with np.errstate(all="ignore"):
            r = tracer.trace(origins, dirs)
        ending[a:b], steps[a:b] = r.ending, r.steps
        direction[a:b], position[a:b] = r.direction, r.position
    return ending, direction, position, steps, time.perf_counter() - start


def pixel_errors(case: SceneCase, ref, run) -> tuple[np.ndarray, int]:
    """(errors in pixels of the pixels ending alike (escaped or hit), pixels ending apart)."""
    origins, _ = case.camera.rays()
    same = ref[0] == run[0]
    esc = same & (ref[0] == core.ENDING["escaped"])
    hit = same & (ref[0] == core.ENDING["hit"])
    u, v = ref[1][esc], run[1][esc]
    angle = angle_between(u, v)
    dist = np.linalg.norm(ref[2][hit] - origins[hit], axis=1)
    moved = np.linalg.norm(run[2][hit] - ref[2][hit], axis=1) / (dist * case.pixel)
    return np.concatenate([angle / case.pixel, moved]), int(np.count_nonzero(~same))


def reference(name: str, case: SceneCase, out: str):
    """The tight reference render of a scene (cached in out/bench/image_ref_<scene>.npz)."""
    n = case.camera.n_pixels
    path = os.path.join(out, f"image_ref_{name}.npz")
    key = f"{REFERENCE[0]} {REFERENCE[1]:g} {case.region} {n}"
    if os.path.exists(path):
        data = np.load(path)
        if str(data["key"]) == key:
            print(f"  reference {key} from {path} ({float(data['seconds']):.1f} s)")
            return (data["ending"], data["direction"], data["position"]), float(data["seconds"])
    print(f"  reference render ({key}) ...", flush=True)
    e, d, p, s, sec = trace(case, *REFERENCE)
    np.savez(path, ending=e, direction=d, position=p, seconds=sec, key=key)
    print(f"  reference: {sec:.1f} s, {s.sum()} steps")
    return (e, d, p), sec


def run_scene(name: str, quick: bool, out: str) -> list[dict]:
    """Every run of one scene against its reference: CSV rows (also printed)."""
    case = scene_case(name, quick)
    ref, _ = reference(name, case, out)
    rows = []
    for method, tolerances in case.runs:
        for tol in tolerances:
            e, d, p, s, sec = trace(case, method, tol)
            err, apart = pixel_errors(case, ref, (e, d, p))
            row = dict(
                scene=name,
                method=method,
                tolerance=tol,
                pixels=case.camera.n_pixels,
                seconds=round(sec, 3),
                steps=int(s.sum()),
                ns_per_ray_step=round(1e9 * sec / max(int(s.sum()), 1)),
                err_median_px=float(np.median(err)),
                err_p99_px=float(np.percentile(err, 99)),
                err_max_px=float(err.max()),
                ending_apart=apart,
                failed=int(np.count_nonzero(e == core.ENDING["failed"])),
            )
            rows.append(row)
            print(
                f"  {name:13s} {method:13s} tol {tol:7.0e}: {sec:7.2f} s, error p99 "
                f"{row['err_p99_px']:.2e} max {row['err_max_px']:.2e} px, {apart} pixels "
                f"end apart, {row['failed']} failed",
                flush=True,
            )
    return rows


def verdict(rows: list[dict]) -> list[str]:
    """Cheapest run with 99 % of the pixels within 0.1, 0.01, 0.001 px (and at most 1e-4
    of them ending apart), per scene."""
    lines = []
    for name in dict.fromkeys(r["scene"] for r in rows):
        mine = [r for r in rows if r["scene"] == name]
        for level in (0.1, 0.01, 0.001):
            ok = [
                r
                for r in mine
                if r["err_p99_px"] <= level and r["ending_apart"] <= 1e-4 * r["pixels"]
            ]
            if not ok:
                lines.append(f"  {name}: 99% within {level:g} px: no run got there")
                continue
            best = min(ok, key=lambda r: r["seconds"])
            others = sorted(
                {r["method"]: r for r in sorted(ok, key=lambda r: -r["seconds"])}.values(),
                key=lambda r: r["seconds"],
            )
            tail = ", ".join(f"{r['method']} {r['seconds']:.2f} s" for r in others[1:4])
            lines.append(
                f"  {name}: 99% within {level:g} px: cheapest {best['method']} at "
                f"tolerance {best['tolerance']:g}, {best['seconds']:.2f} s "
                f"(next: {tail})"
            )
    return lines


def plot(rows: list[dict], path: str) -> None:
    """Error (99th percentile, max) against time for one scene's rows."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 5.5))
    for k, method in enumerate(dict.fromkeys(r["method"] for r in rows)):
        mine = [r for r in rows if r["method"] == method]
        t = [r["seconds"] for r in mine]
        ax.loglog(
            t, [max(r["err_p99_px"], 1e-9) for r in mine], "-o", ms=3, color=f"C{k}", label=method
        )
        ax.loglog(t, [max(r["err_max_px"], 1e-9) for r in mine], ":", color=f"C{k}", lw=0.8)
    name, n = rows[0]["scene"], rows[0]["pixels"]
    ax.axhline(0.1, color="0.5", lw=0.6)
    ax.set(
        xlabel="trace time (s, one core)",
        ylabel="error against the reference (px)",
        title=f"{name}, {n} pixels: solid = 99th percentile, dotted = max",
    )
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)


def write_csv(path: str, rows: list[dict]) -> None:
    """Rows (dicts with the same keys) as a CSV file with a header; nothing if no rows."""
    if not rows:
        return
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)


def main(argv: list[str] | None = None) -> list[str]:
    """Run the chosen scenes; write CSVs and plots; print and return the verdicts."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small images, fewer runs")
    parser.add_argument("--scenes", default="schwarzschild,mirage,kerr,kerr998")
    parser.add_argument("--out", default=OUT)
    args = parser.parse_args(argv)
    found = run_scenes([s for s in args.scenes.split(",") if s], args.quick, args.out)
    print("image verdicts:")
    print("\n".join(found))
    return found


def run_scenes(names: list[str], quick: bool, out: str) -> list[str]:
    """Run, write (image_<scene>.csv and .png under ``out``) and judge the scenes."""
    os.makedirs(out, exist_ok=True)
    found = []
    for name in names:
        rows = run_scene(name, quick, out)
        write_csv(os.path.join(out, f"image_{name}.csv"), rows)
        plot(rows, os.path.join(out, f"image_{name}.png"))
        found += verdict(rows)
    return found


if __name__ == "__main__":
    main()

"""Renders of a fixed family of core scenes, to show that a change leaves images alone.

    PYTHONPATH=. python benchmarks/render_fingerprints.py save DIR     # every scene -> DIR/*.npz
    PYTHONPATH=. python benchmarks/render_fingerprints.py compare A B  # largest differences

Each scene renders small (48 x 36) with every pass (core.render.ALL_PASSES), one worker,
so the images depend on the code only. ``compare`` prints, per scene and array, the largest
absolute difference (NaN where a NaN moved) and whether they are identical; a refactoring
that claims "behaviour unchanged" shows 0 everywhere.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np

import core
from core import hamiltonians as hm
from core.render import ALL_PASSES

WIDTH, HEIGHT = 48, 36


def _camera(position=(0, -30, 2), look_at=(0, 0, 0), fov=40.0) -> core.Camera:
    return core.Camera.perspective(position, look_at, (0, 0, 1), fov, WIDTH, HEIGHT)


def _board(y: float = 12.0) -> core.Plane:
    return core.Plane(point=(0, y, 0), normal=(0, -1, 0), u_axis=(1, 0, 0), extent=(16, 16),
                      color=core.checker(8, 8))  # fmt: skip


def _spheres() -> list[core.Sphere]:
    return [core.Sphere(center=(x, 6, 0), radius=1.0, color=(1, 0.2 * k, 0.1, 1), object_id=k)
            for k, x in enumerate((-4.0, 0.0, 4.0), start=1)]  # fmt: skip


def _mesh() -> core.TriangleMesh:
    vertices = [(-3, 4, -3), (3, 4, -3), (3, 4, 3), (-3, 4, 3)]
    uvs = [[(0, 0), (1, 0), (1, 1)], [(0, 0), (1, 1), (0, 1)]]  # per triangle corner
    return core.TriangleMesh(vertices, [(0, 1, 2), (0, 2, 3)], core.checker(4, 4), uvs=uvs,
                             object_id=7)  # fmt: skip


def _volume() -> core.Volume:
    def density(p):
        return np.exp(-np.sum(p**2, axis=1))

    def emission(p):
        return np.outer(density(p), [1.0, 0.5, 0.25])

    return core.Volume((-2, -2, -2), (2, 2, 2), density, emission=emission, absorption=0.7)


def _kerr(a=0.45, **kw) -> core.Scene:
    return core.Scene(model=hm.kerr(rg=1.0, a=a, chart="kerr_schild"), **kw)


SCENES: dict[str, Callable[[], tuple[core.Scene, core.Camera, dict]]] = {
    "flat": lambda: (core.Scene(objects=[_board(), *_spheres()], background="procedural"),
                     _camera(), {}),
    "flat_mesh_px": lambda: (core.Scene(objects=[_mesh(), *_spheres()]), _camera(),
                             {"tolerance_px": 0.5}),
    "schwarzschild": lambda: (core.Scene(model=hm.schwarzschild(1.0), objects=[_board()],
                                         background="procedural"), _camera(), {}),
    "schwarzschild_px": lambda: (core.Scene(model=hm.schwarzschild(1.0), objects=[_board()],
                                            background="procedural"), _camera(),
                                 {"tolerance_px": 0.25}),
    "schwarzschild_yoshida4": lambda: (core.Scene(model=hm.schwarzschild(1.0),
                                                  objects=[_board()]), _camera(),
                                       {"method": "yoshida4", "tolerance": 1e-6}),
    "kerr": lambda: (_kerr(objects=[_board()], background="procedural"), _camera(), {}),
    "kerr_px_samples": lambda: (_kerr(objects=[_board(), *_spheres()], background="procedural"),
                                _camera(), {"tolerance_px": 0.5, "samples": 4}),
    "kerr_box_filter": lambda: (_kerr(objects=[_board()]), _camera(),
                                {"tolerance_px": 1.0, "samples": 4, "pixel_filter": "box",
                                 "filter_size": 1.0}),
    "kerr_gauss4": lambda: (_kerr(objects=[_board()]), _camera(),
                            {"method": "gauss4", "tolerance": 1e-6}),
    "kerr_dopri5": lambda: (_kerr(objects=[*_spheres()]), _camera(),
                            {"method": "dopri5", "tolerance": 1e-7}),
    "kerr_blanes_moan6": lambda: (_kerr(objects=[_board()]), _camera(),
                                  {"method": "blanes_moan6", "tolerance": 1e-6}),
    "kerr_disk": lambda: (_kerr(a=0.49, disk=core.AccretionDisk(r_out=10.0),
                                background="procedural"),
                          _camera((0, -30, 6)), {"tolerance_px": 0.5}),
    "kerr_disk_translucent": lambda: (_kerr(disk=core.AccretionDisk(r_out=8.0, opacity=0.5),
                                            background=(0.0, 0.0, 0.0, 0.0)),
                                      _camera((0, -25, 3)), {}),
    "near_hole": lambda: (_kerr(objects=[_board(6.0)], background="procedural"),
                          _camera((0, -4, 0.5), (1, 0, 0.5), fov=70), {"tolerance": 1e-6}),
    "mirage": lambda: (core.Scene(model=hm.medium("1 + 0.02*z"), objects=[_board(30.0)],
                                  background="procedural"), _camera((0, -10, 0.5), (0, 0, 0.4)),
                       {"tolerance": 1e-6}),
    "volume": lambda: (core.Scene(model=None, volumes=[_volume()], background=(0, 0, 0)),
                       _camera((0, -8, 0)), {}),
    "metric_text": lambda: (core.Scene(model=hm.metric(
        [["-1/(1-2*M/r)", "0", "0", "0"], ["0", "1-2*M/r*x*x/(r*r)", "-2*M/r*x*y/(r*r)",
          "-2*M/r*x*z/(r*r)"], ["0", "-2*M/r*x*y/(r*r)", "1-2*M/r*y*y/(r*r)",
          "-2*M/r*y*z/(r*r)"], ["0", "-2*M/r*x*z/(r*r)", "-2*M/r*y*z/(r*r)",
          "1-2*M/r*z*z/(r*r)"]], parameters={"M": 0.5},
        definitions=[("r", "sqrt(x*x + y*y + z*z)")]), objects=[_board()]),
        _camera(), {"tolerance": 1e-5}),
}  # fmt: skip
"""Scene name -> (scene, camera, render options)."""


def save(directory: Path) -> None:
    """Render every scene into ``directory``/<name>.npz (rgba and each pass)."""
    directory.mkdir(parents=True, exist_ok=True)
    for name, build in SCENES.items():
        scene, camera, options = build()
        out, left_out = _render(scene, camera, options)
        np.savez(directory / f"{name}.npz", rgba=out.rgba, **out.passes)
        print(f"{name:24s} {out.summary['rays']:7d} rays  failed {out.summary['failed']}"
              + (f"  (no {left_out} pass: its method carries no ray differentials)"
                 if left_out else ""))  # fmt: skip


def _render(scene: core.Scene, camera: core.Camera, options: dict) -> tuple:
    """Every pass; a scene whose method refuses ray differentials renders without the
    magnification pass (the core refuses it by name rather than guess it)."""
    try:
        return core.render(scene, camera, passes=ALL_PASSES, workers=1, **options), ""
    except ValueError as err:
        if "ray differentials" not in str(err):
            raise
    passes = tuple(p for p in ALL_PASSES if p != "magnification")
    return core.render(scene, camera, passes=passes, workers=1, **options), "magnification"


def _difference(a: np.ndarray, b: np.ndarray) -> float:
    """Largest absolute difference (equal values, infinities and NaNs included, count 0);
    NaN where the shapes differ or a NaN is not in the same place."""
    if a.shape != b.shape:
        return float("nan")
    a, b = a.astype(np.float64), b.astype(np.float64)
    if not np.array_equal(np.isnan(a), np.isnan(b)):
        return float("nan")
    with np.errstate(invalid="ignore"):
        gap = np.where((a == b) | np.isnan(a), 0.0, np.abs(a - b))
    return float(np.max(gap, initial=0.0))


def compare(before: Path, after: Path) -> int:
    """Print the largest difference of every array of every scene; 1 if any differs."""
    differs = 0
    for name in SCENES:
        a, b = np.load(before / f"{name}.npz"), np.load(after / f"{name}.npz")
        keys = sorted(set(a.files) | set(b.files))
        row = []
        for key in keys:
            d = _difference(a[key], b[key]) if key in a.files and key in b.files else np.nan
            differs += not d == 0.0
            row.append(f"{key} {d:.1e}" if d else f"{key} 0")
        print(f"{name:24s} " + ", ".join(row))
    print("identical" if not differs else f"{differs} arrays differ")
    return int(differs > 0)


def main() -> None:
    """Command line: save DIR, or compare A B."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("action", choices=("save", "compare"))
    parser.add_argument("paths", nargs="+", type=Path)
    args = parser.parse_args()
    if args.action == "save":
        save(args.paths[0])
    else:
        sys.exit(compare(*args.paths[:2]))


if __name__ == "__main__":
    main()

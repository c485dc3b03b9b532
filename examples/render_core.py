"""Render a Schwarzschild and a mirage scene with the core alone (no Blender) to out/.

    PYTHONPATH=. python examples/render_core.py [--width 160] [--height 120] [--method rk4]

(`make render-core` runs it in the project's environment.)

Writes out/core_schwarzschild.png/.exr and out/core_mirage.png/.exr (EXR channels R, G,
B, A, error, steps) and prints each render's summary.
"""

from __future__ import annotations

import argparse
import os

import numpy as np

import core
from core import hamiltonians as hm
from core.presets import mirage_view
from core.render import summary_text


def schwarzschild_scene() -> core.Scene:
    """A black hole (rg = 1) with a checkered board behind it and two spheres, seed Fig. 8."""
    board = core.Plane(
        point=(0, 12, 0),
        normal=(0, -1, 0),
        u_axis=(1, 0, 0),
        extent=(16, 16),
        color=core.checker(8, 8, (0.9, 0.8, 0.2, 1), (0.1, 0.2, 0.6, 1)),
    )
    spheres = [
        core.Sphere(center=(-3.5, 4, 1), radius=1.0, color=(0.9, 0.2, 0.2, 1)),
        core.Sphere(center=(3.5, -2, -1), radius=0.8, color=(0.2, 0.9, 0.3, 1)),
    ]
    return core.Scene(
        model=hm.schwarzschild(rg=1.0), objects=[board, *spheres], background="procedural"
    )


def render_to(
    name: str, scene: core.Scene, camera: core.Camera, method: str | None, out_dir: str, **options
) -> None:
    """Render, write PNG and EXR, print the summary."""
    result = core.render(
        scene,
        camera,
        method=method,
        progress=lambda done, total: print(f"\r{name}: {done}/{total} pixels", end="", flush=True),
        **options,
    )
    print()
    png = core.write_png(os.path.join(out_dir, f"core_{name}.png"), result.rgba)
    channels = {c: result.rgba[..., i] for i, c in enumerate("RGBA")}
    channels["error"] = result.passes["error"].astype(np.float32)
    channels["steps"] = result.passes["steps"].astype(np.float32)
    exr = core.write_exr(os.path.join(out_dir, f"core_{name}.exr"), channels)
    s = result.summary
    print(f"{name}: {summary_text(s)} (errors in rad); endings {s['endings']}\n  -> {png}, {exr}")


def main(argv: list[str] | None = None) -> None:
    """Parse arguments and render both scenes."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--width", type=int, default=160)
    parser.add_argument("--height", type=int, default=120)
    parser.add_argument(
        "--method", default=None, help="integrator (default: the measured cheapest for each model)"
    )
    parser.add_argument("--out", default="out")
    args = parser.parse_args(argv)
    os.makedirs(args.out, exist_ok=True)
    cam = core.Camera.perspective(
        position=(0, -20, 2),
        look_at=(0, 0, 0),
        up=(0, 0, 1),
        fov_deg=45,
        width=args.width,
        height=args.height,
    )
    render_to("schwarzschild", schwarzschild_scene(), cam, args.method, args.out, tolerance=1e-6)
    scene, cam = mirage_view("fig10", args.width, args.height)  # the seed's Fig. 10 view
    render_to("mirage", scene, cam, args.method, args.out, tolerance=1e-6)


if __name__ == "__main__":
    main()

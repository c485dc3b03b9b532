"""The accretion disk's three looks side by side: docs/img/disk_looks.png.

    PYTHONPATH=. .venv/bin/python examples/disk_looks.py [--width 960] [--height 540] [--out PATH]

The scene of the "Kerr with Accretion Disk" preset (a hole of Size 1 spinning at a/M = 0.9,
a Novikov–Thorne disk at 6000 K from the innermost stable orbit to 12 units, Doppler on),
framed as the preset frames it (80° from the spin axis, the disk across 70 % of the frame's
width, a 50 mm lens), in the looks Physical, Cinematic and EHT-like (left to right), each
with automatic exposure, rendered by the core (what the add-on's engine calls) and written
through Blender's colour management (the bpy module: AgX, Blender's default view
transform), as F12 would save them. Prints each look's exposure and the median brightness
(Rec.709 luma of the display values) of its disk pixels.
"""

from __future__ import annotations

import argparse
import math
import os
import tempfile

import bpy
import numpy as np

import core
from core import hamiltonians as hm
from core.sky import procedural_sky

SIZE, SPIN, OUTER = 1.0, 0.9, 12.0
"""The preset's hole (horizon radius, a/M) and its disk's outer radius (scene units)."""
INCLINATION, FILL, LENS, SENSOR = 80.0, 0.7, 50.0, 36.0
"""The preset's framing: degrees from the spin axis, share of the frame's width, camera."""
LOOKS = ("physical", "cinematic", "eht")
LUMA = np.array([0.2126, 0.7152, 0.0722])


def stars(directions: np.ndarray) -> np.ndarray:
    """The procedural sky's stars alone, on black (no galaxy band, no gradient)."""
    return procedural_sky(directions, galaxy=False) - procedural_sky(
        directions, galaxy=False, stars=False
    )


def scene_for(look: str) -> core.Scene:
    """The preset's hole and disk in ``look``, automatic exposure, stars behind."""
    rg = 2.0 * SIZE / (1.0 + math.sqrt(1.0 - SPIN * SPIN))  # horizon r+ = M (1 + √(1 − χ²))
    disk = core.AccretionDisk(r_out=OUTER, temperature=6000.0, look=look, exposure=None)
    model = hm.kerr(rg=rg, a=SPIN * rg / 2.0, chart="kerr_schild")
    return core.Scene(model=model, disk=disk, background=stars)


def camera(width: int, height: int) -> core.Camera:
    """The preset's framing: the disk's outer edge across FILL of the frame's width."""
    half = 0.5 * FILL * 2.0 * math.atan(0.5 * SENSOR / LENS)
    distance = OUTER / math.tan(half)
    inc = math.radians(INCLINATION)
    position = distance * np.array([0.0, -math.sin(inc), math.cos(inc)])
    matrix = np.eye(4)
    matrix[:3, :3] = [[1, 0, 0], [0, math.cos(inc), -math.sin(inc)],
                      [0, math.sin(inc), math.cos(inc)]]  # fmt: skip
    matrix[:3, 3] = position
    return core.Camera.blender(lens=LENS, sensor_width=SENSOR, resolution_x=width,
                               resolution_y=height, matrix_world=matrix)  # fmt: skip


def through_view_transform(rgba: np.ndarray, path: str, view: str = "AgX") -> np.ndarray:
    """Write scene-linear ``rgba`` (h, w, 4; row 0 at the top) as a PNG through Blender's
    ``view`` transform; -> the PNG's display values (h, w, 3)."""
    scene = bpy.context.scene
    scene.view_settings.view_transform, scene.view_settings.look = view, "None"
    scene.view_settings.exposure, scene.view_settings.gamma = 0.0, 1.0
    settings = scene.render.image_settings
    settings.file_format, settings.color_mode, settings.color_depth = "PNG", "RGB", "8"
    h, w = rgba.shape[:2]
    image = bpy.data.images.new("disk looks", w, h, alpha=True, float_buffer=True)
    pixels = np.ascontiguousarray(rgba[::-1], dtype=np.float32)
    pixels[..., 3] = 1.0
    image.pixels.foreach_set(pixels.ravel())
    image.save_render(path, scene=scene)
    bpy.data.images.remove(image)
    saved = bpy.data.images.load(path)
    saved.colorspace_settings.name = "Non-Color"
    flat = np.empty(w * h * 4, dtype=np.float32)
    saved.pixels.foreach_get(flat)
    bpy.data.images.remove(saved)
    return flat.reshape(h, w, 4)[::-1, :, :3]


def main() -> None:
    """Render the three looks, write them side by side, print their exposures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--width", type=int, default=960)
    parser.add_argument("--height", type=int, default=540)
    parser.add_argument("--tolerance-px", type=float, default=0.5)
    parser.add_argument("--samples", type=int, default=4)
    parser.add_argument("--workers", type=int, default=None)
    parser.add_argument("--out", default=os.path.join("docs", "img", "disk_looks.png"))
    args = parser.parse_args()
    cam = camera(args.width, args.height)
    panels = []
    for look in LOOKS:
        out = core.render(scene_for(look), cam, tolerance_px=args.tolerance_px,
                          samples=args.samples, workers=args.workers)  # fmt: skip
        with tempfile.TemporaryDirectory() as folder:
            shown = through_view_transform(out.rgba, os.path.join(folder, "look.png"))
        on = np.isfinite(out.passes["redshift"])
        median = float(np.median(shown[on] @ LUMA))
        print(f"{look}: exposure {out.summary['disk_exposure']:.3g}, disk median {median:.3f}"
              f" on screen (AgX), {out.summary['time_s']:.0f} s")  # fmt: skip
        panels.append(out.rgba)
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    through_view_transform(np.concatenate(panels, axis=1), os.path.abspath(args.out))
    print(f"disk_looks: wrote {args.out}")


if __name__ == "__main__":
    main()

"""Does the adaptive sampler keep its promise on scenes unlike the Kerr board?

    PYTHONPATH=. python benchmarks/honesty.py [--quick] [--size WxH] [--scenes a,b]
        [--tolerances 1,0.25,0.05] [--fresh] [--save-images DIR] [--no-strip]

``core.render(scene, camera, tolerance_px=T)`` promises pixels within T pixels of the
truth, and an ``error_px`` pass that honestly estimates each pixel's error. Each scene of
SCENES is rendered at every T (samples=1, passes ending, direction, error_px) and compared
pixel by pixel with a dense reference: every pixel centre traced with dopri5 at 1e-10 rad
(no interpolation, max_steps 1e6), cached in out/bench/honesty_ref/<scene>_<WxH>.npz.

The true error of a pixel (pixels) is the angle between the reference's and the run's
``direction`` pass (what the pixel centre sees: the escape direction, or the unit vector
to the hit point) over the run's pixel angle, where the endings agree; +inf where they
differ (an ending flip: escaped / captured / hit); NaN where both were captured (left
out). core has no object-id pass yet, so two hits on different objects count as the same
ending (the colour column sees such a swap); an ``object_id`` pass (OBJECT_PASS) is used
as soon as core.passes has one. The columns, with their targets:

- ``over_tol%``: share of the pixels whose true error exceeds T (<= 0.5 %);
- ``over_3tol``: pixels whose true error exceeds 3 T (0);
- ``under3%``: share of all pixels whose estimate is below a third of the truth (a flip
  counts as under-reported unless its estimate is >= 1 px) (<= 1 %); next to it, without
  a target, the share of all pixels that are so and have a true error above T / 10 (the
  rest are errors far below the tolerance, often under 1e-3 px, under-estimated);
- ``within3%``: of the pixels whose true error exceeds T / 10 (flips included), the share
  estimated within [truth / 3, 3 truth] (a flip: estimate >= 1 px) (>= 90 %);
- ``flips``: ending flips, and how many of them have an estimate below 1 px (no target
  of their own: they count in the columns above);
- ``colour%``: share of the pixels whose RGBA differs from the reference's by more than
  0.1 in a channel (<= 0.2 %);
- ``images``: connected components (8-neighbours) of the reference's hit pixels (and, in
  the star scenes, of pixels brighter than BRIGHT) / those lost: no pixel of the same kind
  in the run (a hit; brighter than BRIGHT / 2) within the component grown by 1 px (0 lost);
- ``rays/px`` and ``seconds`` of the run (its summary);
- ``every s`` and ``x every``: the same scene with every pixel centre traced and the same
  promise kept (``core.render(..., interpolate=False)``: the run's step, the error pass,
  near misses and rays over their budget traced again), and the run's time over it
  (<= 1.1: the adaptive image never costs more than tracing every pixel);
- ``dense s``, ``x dense`` and ``dense >3T``: every pixel centre traced plainly at the
  run's integration tolerance with the companion's error pass and nothing traced again
  (issue 48's first bar), the run's time over it, and its pixels over 3 T (no target: it
  shows what the plain render does not keep; mirage_grazing at 1 px: 18 flips).

``final_strip`` (printed apart): a white strip 0.3 px wide on black beside a Schwarzschild
hole at tolerance_px=0.25, samples=16, box filter, against the same columns supersampled
8x8 (the dense reference settings, box-averaged): the strip's total light, run over
reference (>= 0.9).

The scenes are SCENES (each builder's docstring says what it shows): far_small,
thin_front, stars, point_stars, mirage_grazing, near_tangent, disk_high_spin, schwarzschild
and user_metric, the graded-index lenses (issue 50) fisheye_matched, fisheye_jump,
luneburg_matched and luneburg_jump, orbit_disk, medium_text and sphere_cloud (a scene
core.render refuses is printed as refused, with its message, and has no row). 2 cores:
--quick ~2.5 min with its references rendered (~1.6 min of it); the full 160x90 run ~6 min
(references ~3 min, cached after the first run; each row also renders the scene twice with
every pixel traced: ``x every`` and ``x dense``).

A table row per (scene, T), a line counting the rows that miss each target, and the CSV
out/bench/honesty.csv; ``--save-images DIR``: per scene at the loosest T, reference | run
| mask (white: colour differs by > 0.1, red: ending flip) as <scene>.png.
"""

from __future__ import annotations

import argparse
import copy
import csv
import hashlib
import inspect
import math
import os
import time
from collections.abc import Callable, Sequence
from types import SimpleNamespace
from typing import Any

import numpy as np
from image_precision import _black_hole_camera
from image_quality import true_error_px
from scipy import ndimage

import core
from core import hamiltonians as hm
from core.passes import BY_NAME
from core.presets import mirage_view
from core.render import TRACE_SHARE
from core.sky import procedural_sky

OUT = os.path.join("out", "bench")
REF_DIR = os.path.join(OUT, "honesty_ref")
REFERENCE = dict(method="dopri5", tolerance=1e-10, max_steps=10**6)
"""The dense reference: every pixel centre traced, no interpolation."""
KINKED_REFERENCE = dict(method="gauss4", tolerance=1e-10, max_steps=10**6)
"""The reference of the lenses with a kink in n (KINKED): a Runge-Kutta method's stages near
a kink's crossing lie off its path, across the kink, and dopri5 at 1e-10 was 0.02-0.06 px
off there (first order in its step); gauss4 and the splittings place it where scipy's DOP853
stopped at the kink by its event location does (to 1e-5 px; tests/core/test_medium_box.py
checks the tracer's kinks so)."""
OBJECT_PASS = "object_id"
"""An object-id pass, used where core.passes has one (it has none yet: hits on different
objects then compare as the same ending)."""
IDS = (OBJECT_PASS,) if OBJECT_PASS in BY_NAME else ()
POSITIONS = ("position",) if "position" in BY_NAME else ()
"""Hit points, where core has the pass (a hit's error: their distance over the footprint)."""
REF_PASSES = ("ending", "direction", *POSITIONS, *IDS)
RUN_PASSES = (*REF_PASSES, "error_px")
TOLERANCES = (1.0, 0.25, 0.05)
QUICK_TOLERANCES = (1.0, 0.25)
SIZE, QUICK_SIZE = (160, 90), (96, 54)
MEASURABLE = 1e-3
"""Pixels: true errors below this are not counted as under-reported (the passes are
float32: a direction to ~6e-8 rad, 1e-5 px of these cameras; a hit point to ~1e-7 of its
distance)."""
COLOUR_STEP = 0.1
"""A pixel's colour differs when a channel differs from the reference's by more than this."""
BRIGHT = {"stars": 0.05, "point_stars": 0.05}
"""Scenes whose bright pixels (luminance above this) also count as lensed images."""
TARGETS = {
    "over_tol_pct": ("<=", 0.5),
    "over_3tol": ("<=", 0),
    "under3_pct": ("<=", 1.0),
    "within3_pct": (">=", 90.0),
    "colour_pct": ("<=", 0.2),
    "images_lost": ("<=", 0),
    "x_every": ("<=", 1.1),
    "companions": ("<=", 0.3),
}
STRIP_TARGET = 0.9
HIT = core.ENDING["hit"]
LUMA = np.array([0.2126, 0.7152, 0.0722])
"""Rec.709 luminance of linear RGB."""


# -- scenes ------------------------------------------------------------------------------------


def _camera(
    position: Any, look_at: Any, width: int, height: int, fov_deg: float = 40.0
) -> core.Camera:
    """A pinhole camera with +z up; fov_deg spans the image's width."""
    return core.Camera.perspective(position, look_at, (0, 0, 1), fov_deg, width, height)


def far_small(width: int, height: int) -> tuple[core.Scene, core.Camera]:
    """Schwarzschild seen from 30 rg; three spheres of 2-5 rg ~400 rg behind the hole,
    off axis: each makes a lensed arc near the Einstein ring (14 deg) and a small
    counter-image on the other side."""
    cam = _black_hole_camera(width, height)  # (0, -30, 2) looking at the hole
    behind = 400.0
    axis_z = -2.0 * behind / 30.0  # the line of sight through the hole, at y = 400
    spheres = [
        core.Sphere((-25, behind, axis_z + 6), 3.0, (1.0, 0.3, 0.2, 1)),
        core.Sphere((15, behind, axis_z - 4), 2.0, (0.3, 1.0, 0.3, 1)),
        core.Sphere((40, behind, axis_z + 10), 5.0, (0.4, 0.5, 1.0, 1)),
    ]
    scene = core.Scene(model=hm.schwarzschild(rg=1.0), objects=spheres, background=(0, 0, 0))
    return scene, cam


def thin_front(width: int, height: int) -> tuple[core.Scene, core.Camera]:
    """Schwarzschild from 30 rg with thin strips, a crossed-strip rod, an edge-on disk and
    small spheres in front of and beside the hole, spread over the frame."""
    cam = _black_hole_camera(width, height)
    strip = dict(normal=(0, -1, 0), color=(0.9, 0.9, 0.2, 1))
    objects = [
        core.Plane((-5.0, -8, 0.5), u_axis=(0, 0, 1), extent=(9.0, 0.08), **strip),
        core.Plane((0.5, -12, -2.6), u_axis=(1, 0, 0), extent=(11.0, 0.06), **strip),
        core.Plane((6.0, -6, 1.5), u_axis=(1, 0, 1), extent=(7.0, 0.07), **strip),
        # a thin rod along z: two crossed strips 0.1 rg wide
        core.Plane((3.5, 2, 0), normal=(0, -1, 0), u_axis=(0, 0, 1), extent=(10, 0.1)),
        core.Plane((3.5, 2, 0), normal=(1, 0, 0), u_axis=(0, 0, 1), extent=(10, 0.1)),
        core.Disk((-3.0, -4, -1.5), (1, 0.1, 0.15), 0.0, 1.5, (0.2, 0.9, 1.0, 1)),  # edge-on
        core.Sphere((7.5, -3, -3.0), 0.25, (1, 0.2, 0.2, 1)),
        core.Sphere((-8.0, 3, 3.5), 0.35, (0.2, 1, 0.2, 1)),
        core.Sphere((-2.0, -15, 2.8), 0.12, (1, 1, 1, 1)),
        core.Sphere((2.6, 0, 0.8), 0.2, (1, 0.5, 0, 1)),
        core.Sphere((-6.5, -10, -3.0), 0.15, (0.8, 0.3, 1, 1)),
    ]
    return core.Scene(model=hm.schwarzschild(rg=1.0), objects=objects), cam


def _star_sky(directions: np.ndarray) -> np.ndarray:
    """The procedural sky's stars alone, 2.5x their default size (about a pixel)."""
    return procedural_sky(directions, galaxy=False, star_size=2.5)


def stars(width: int, height: int) -> tuple[core.Scene, core.Camera]:
    """Point stars (the procedural star layers, no galaxy band) behind a Schwarzschild
    hole seen from 20 rg: lensed, doubled and crowded near the photon ring."""
    cam = _camera((0, -20, 1), (0, 0, 0), width, height, fov_deg=50.0)
    return core.Scene(model=hm.schwarzschild(rg=1.0), background=_star_sky), cam


def point_stars(width: int, height: int) -> tuple[core.Scene, core.Camera]:
    """2000 point stars (core.StarField, no diffuse sky; a 5th-magnitude star fills a
    pixel) behind a Kerr hole (a/M = 0.9) seen from 15 rg: each star's lensed images,
    magnified and drawn at their true places, crowded and demagnified near the photon
    ring."""
    cam = _camera((0, -15, 1), (0, 0, 0), width, height, fov_deg=50.0)
    pixel = (math.radians(50.0) / width) ** 2
    field = core.StarField.random(2000, seed=23, diffuse=(0.0, 0.0, 0.0),
                                  flux_zero=pixel / 10 ** (-0.4 * 5.0))  # fmt: skip
    return core.Scene(model=hm.kerr(rg=1.0, a=0.45, chart="kerr_schild"), background=field), cam


def mirage_grazing(width: int, height: int) -> tuple[core.Scene, core.Camera]:
    """The seed's Fig. 10 mirage scene (hot ground, Eq. 17) with the ground's checker at
    0.1 m squares, seen from 0.4 m looking 3.4 deg down, 16 deg wide: the squares span ~3 px
    at the bottom and fall far below a pixel towards the horizon, where rays graze the
    ground and turn up."""
    scene, _ = mirage_view("fig10", width, height)
    cam = _camera((0, 0, 0.4), (1, 0, 0.34), width, height, fov_deg=16.0)
    ground = scene.objects[-1]
    cells = int(ground.extent[0] / 0.1)
    fine = core.checker(cells, cells, (0.35, 0.3, 0.25, 1), (0.15, 0.12, 0.1, 1))
    objects = list(scene.objects[:-1])
    objects.append(core.Plane(ground.point, ground.normal, fine, u_axis=ground.u_axis,
                              extent=ground.extent))  # fmt: skip
    return core.Scene(model=scene.model, objects=objects, background=scene.background), cam


def near_tangent(width: int, height: int) -> tuple[core.Scene, core.Camera]:
    """Kerr a/M = 0.9 (Kerr-Schild) from 5 rg, looking along the orbit (perpendicular to
    the hole's direction), 70 deg wide, at a checker board and a sphere."""
    cam = _camera((0, -5, 0.5), (10, -5, 0.5), width, height, fov_deg=70.0)
    board = core.Plane((12, -3, 0), (-1, 0, 0), core.checker(15, 15), u_axis=(0, 1, 0),
                       extent=(30, 30))  # fmt: skip
    ball = core.Sphere((6, -8, 1), 1.0, (1, 0.4, 0.1, 1))
    scene = core.Scene(model=hm.kerr(rg=1.0, a=0.45, chart="kerr_schild"), objects=[board, ball])
    return scene, cam


def disk_high_spin(width: int, height: int) -> tuple[core.Scene, core.Camera]:
    """Kerr a/M = 0.99 (Kerr-Schild) with a Novikov-Thorne disk (ISCO to 8 rg, 8000 K)
    seen at 70 deg inclination from 25 rg, on the procedural sky."""
    inc = math.radians(70.0)
    cam = _camera((0, -25 * math.sin(inc), 25 * math.cos(inc)), (0, 0, 0), width, height, 40.0)
    disk = core.AccretionDisk(r_out=8.0, temperature=8000.0, brightness=0.7)
    scene = core.Scene(model=hm.kerr(rg=1.0, a=0.495, chart="kerr_schild"), disk=disk)
    return scene, cam


def schwarzschild(width: int, height: int) -> tuple[core.Scene, core.Camera]:
    """Schwarzschild from 17 rg, off axis and above, 60 deg wide, a 60 x 40 rg checker
    board 20 rg behind the hole."""
    cam = _camera((8, -14, 5), (0, 0, 0), width, height, fov_deg=60.0)
    board = core.Plane((0, 20, 0), (0, -1, 0), core.checker(24, 16), u_axis=(1, 0, 0),
                       extent=(60, 40))  # fmt: skip
    return core.Scene(model=hm.schwarzschild(rg=1.0), objects=[board]), cam


def plummer_lens(mass: float = 0.5, core_radius: float = 1.0) -> core.hamiltonians.Hamiltonian:
    """A user metric: the exponential metric of a Plummer potential, g_tt = -exp(2 phi),
    g_ii = exp(-2 phi), phi = -m / sqrt(r^2 + b^2): no horizon, a strong lens with a
    transparent core (caustics, multiple images)."""
    space = "exp(2*phi)"
    inverse = [
        ["-exp(-2*phi)", "0", "0", "0"],
        ["0", space, "0", "0"],
        ["0", "0", space, "0"],
        ["0", "0", "0", space],
    ]
    return hm.metric(
        inverse=inverse,
        parameters={"m": mass, "b": core_radius},
        definitions=[("phi", "-m/sqrt(x**2 + y**2 + z**2 + b**2)")],
    )


def user_metric(width: int, height: int) -> tuple[core.Scene, core.Camera]:
    """A user metric (plummer_lens, m = 0.5, b = 1) from 25 rg: a checker board 15 rg
    behind it and a sphere 6 rg behind, just off the axis."""
    cam = _camera((0, -25, 1), (0, 0, 0), width, height)
    board = core.Plane((0, 15, 0), (0, -1, 0), core.checker(12, 12, (0.9, 0.8, 0.3)),
                       u_axis=(1, 0, 0), extent=(24, 24))  # fmt: skip
    ball = core.Sphere((1.5, 6, 0.8), 0.8, (0.3, 0.5, 1.0, 1))
    return core.Scene(model=plummer_lens(), objects=[board, ball]), cam


FISH_EYE = "2/(1 + (x*x + y*y + z*z)/4)"
"""Maxwell's fish-eye, n = 2 / (1 + r^2/4): 1 at r = 2, 0.62 at r = 3, 0.26 at (3, 3, 3)."""
LUNEBURG = "sqrt(2 - (x*x + y*y + z*z))"
"""Luneburg's lens, n = sqrt(2 - r^2): 1 at r = 1, where it focuses parallel light."""


def _within(index: str, radius2: float) -> str:
    """``index`` inside r^2 < radius2 and its value at r^2 = radius2 outside: r^2 replaced by
    min(r^2, radius2), written with abs (the expression language has no min)."""
    r2 = "(x*x + y*y + z*z)"
    clipped = f"(({r2} + {radius2:g} - abs({r2} - {radius2:g}))/2)"
    return index.replace(r2, clipped)


def _lens_scene(index: str, half: float, distance: float, width: int, height: int):
    """A graded-index lens ``index`` in a box of +-half, a small checker sphere inside it, a
    checker board behind it, seen from ``distance`` (fov 40, a little above the axis)."""
    cam = _camera((0.0, -distance, 0.3 * half), (0, 0, 0), width, height)
    ball = core.Sphere((0.3 * half, 0.2 * half, -0.2 * half), 0.15 * half,
                       core.checker(8, 4, (1.0, 0.5, 0.2)))  # fmt: skip
    board = core.Plane((0, 2.5 * half, 0), (0, -1, 0), core.checker(16, 16, (0.9, 0.9, 0.9)),
                       u_axis=(1, 0, 0), extent=(8 * half, 8 * half))  # fmt: skip
    model = hm.medium(index, bounds=((-half,) * 3, (half,) * 3))
    return core.Scene(model=model, objects=[ball, board], background=(0.2, 0.3, 0.5)), cam


def fisheye_matched(width: int, height: int) -> tuple[core.Scene, core.Camera]:
    """Maxwell's fish-eye inside r = 2 (n = 1 beyond: a kink in n there) in a box of +-3,
    whose faces are at n = 1, seen from 12 units."""
    return _lens_scene(_within(FISH_EYE, 4.0), 3.0, 12.0, width, height)


def fisheye_jump(width: int, height: int) -> tuple[core.Scene, core.Camera]:
    """Maxwell's fish-eye n = 2 / (1 + r^2/4) everywhere in a box of +-3 (issue 50's
    scene): n is 0.26-0.62 on the box's faces, 1 outside it."""
    return _lens_scene(FISH_EYE, 3.0, 12.0, width, height)


def luneburg_matched(width: int, height: int) -> tuple[core.Scene, core.Camera]:
    """Luneburg's lens inside r = 1 (n = 1 beyond: a kink in n there) in a box of +-1.5,
    whose faces are at n = 1, seen from 6 units."""
    return _lens_scene(_within(LUNEBURG, 1.0), 1.5, 6.0, width, height)


def luneburg_jump(width: int, height: int) -> tuple[core.Scene, core.Camera]:
    """Luneburg's n = sqrt(2 - r^2) in a box of +-0.5 inside its ball: n is 1.22-1.32 on
    the box's faces, 1 outside it; seen from 2 units."""
    return _lens_scene(LUNEBURG, 0.5, 2.0, width, height)


def orbit_disk(width: int, height: int) -> tuple[core.Scene, core.Camera]:
    """Issue 48's audit scene: Kerr a/M = 0.9 (Kerr-Schild) with a Novikov-Thorne disk to
    8 rg and 2000 point stars, seen from 3 rg off the axis, 60 deg wide (the render's
    observer stays static here: the honesty references are static)."""
    cam = core.Camera.perspective((0, -3.0, 0.0), (0.3, 0, 0.2), (0, 0, 1), 60.0, width, height)
    pixel = (math.radians(60.0) / width) ** 2
    field = core.StarField.random(2000, seed=23, diffuse=(0.0, 0.0, 0.0),
                                  flux_zero=pixel / 10 ** (-0.4 * 5.0))  # fmt: skip
    disk = core.AccretionDisk(r_out=8.0, temperature=8000.0, brightness=0.7)
    model = hm.kerr(rg=1.0, a=0.45, chart="kerr_schild")
    return core.Scene(model=model, disk=disk, background=field), cam


def _glyphs(uv: np.ndarray, position: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """A page of text-like glyphs: 24 x 12 glyphs of 5 x 7 dots (a fixed random bitmap),
    black on paper, looked up at the nearest dot (a plain texture: no filter)."""
    dots = np.random.default_rng(5).random((12 * 9, 24 * 6)) < 0.45
    dots[8::9, :] = dots[7::9, :] = False  # line spacing
    dots[:, 5::6] = False  # letter spacing
    v = np.clip(((1.0 - uv[:, 1]) * dots.shape[0]).astype(int), 0, dots.shape[0] - 1)
    u = np.clip((uv[:, 0] * dots.shape[1]).astype(int), 0, dots.shape[1] - 1)
    ink = dots[v, u][:, None]
    return np.where(ink, [[0.05, 0.05, 0.08, 1.0]], [[0.95, 0.92, 0.85, 1.0]])


def medium_text(width: int, height: int) -> tuple[core.Scene, core.Camera]:
    """Issue 48's second audit scene: a graded-index lens n = 1 + 0.5 exp(-r^2) (unbounded)
    between the camera and a page of text (_glyphs) 4 units behind it, seen from 8."""
    cam = _camera((0.0, -8.0, 0.5), (0, 0, 0), width, height, fov_deg=40.0)
    page = core.Plane((0, 4, 0), (0, -1, 0), _glyphs, u_axis=(1, 0, 0), extent=(8, 4))
    model = hm.medium("1 + 0.5*exp(-(x*x + y*y + z*z))")
    return core.Scene(model=model, objects=[page], background=(0.2, 0.3, 0.5)), cam


def sphere_cloud(width: int, height: int) -> tuple[core.Scene, core.Camera]:
    """60 spheres (radius 0.4-1.2 rg) in a shell 4 < r < 12 rg around a Schwarzschild hole,
    seen from 30 rg: more objects than core.tracing's NEAR_BOXES, so a step is near
    geometry by the cells their boxes overlap (core.geometry.boxcells); lensed sky between."""
    cam = _camera((0, -30, 2), (0, 0, 0), width, height, fov_deg=40.0)
    rng = np.random.default_rng(60)
    direction = rng.normal(size=(60, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    centre = (rng.uniform(4.0**3, 12.0**3, 60) ** (1 / 3))[:, None] * direction
    radius, colour = rng.uniform(0.4, 1.2, 60), rng.uniform(0.2, 1.0, (60, 3))
    spheres = [core.Sphere(c, r, color=(*k, 1.0))
               for c, r, k in zip(centre, radius, colour, strict=True)]  # fmt: skip
    return core.Scene(model=hm.schwarzschild(rg=1.0), objects=spheres), cam


SCENES: dict[str, Callable[[int, int], tuple[core.Scene, core.Camera]]] = {
    "far_small": far_small,
    "thin_front": thin_front,
    "stars": stars,
    "point_stars": point_stars,
    "mirage_grazing": mirage_grazing,
    "near_tangent": near_tangent,
    "disk_high_spin": disk_high_spin,
    "schwarzschild": schwarzschild,
    "user_metric": user_metric,
    "fisheye_matched": fisheye_matched,
    "fisheye_jump": fisheye_jump,
    "luneburg_matched": luneburg_matched,
    "luneburg_jump": luneburg_jump,
    "orbit_disk": orbit_disk,
    "medium_text": medium_text,
    "sphere_cloud": sphere_cloud,
}
"""Scene builders by name: (width, height) -> (scene, camera)."""
KINKED = ("fisheye_matched", "luneburg_matched")
"""Scenes whose index has a kink (n = 1 outside the lens, written with abs)."""


# -- reference and comparison -----------------------------------------------------------------


def reference_options(name: str) -> dict:
    """The dense reference's settings for a scene (REFERENCE; KINKED_REFERENCE for KINKED)."""
    return KINKED_REFERENCE if name in KINKED else REFERENCE


def _scene_key(name: str, width: int, height: int) -> str:
    """What a cached reference must match: the settings, the size and the source of the
    builder and of this module's functions it calls."""
    source = inspect.getsource(SCENES[name])
    helpers = [f for key, f in globals().items() if inspect.isfunction(f) and f"{key}(" in source]
    source += "".join(inspect.getsource(f) for f in helpers)
    digest = hashlib.sha1(source.encode()).hexdigest()[:12]
    return f"{name} {width}x{height} {reference_options(name)} {REF_PASSES} {digest}"


def reference(name: str, width: int, height: int, fresh: bool = False) -> SimpleNamespace:
    """The dense reference of a scene (rgba, passes, seconds), from the cache if it matches."""
    path = os.path.join(REF_DIR, f"{name}_{width}x{height}.npz")
    key = _scene_key(name, width, height)
    if not fresh and os.path.exists(path):
        data = np.load(path)
        if str(data["key"]) == key:
            passes = {key: data[key] for key in REF_PASSES}
            return SimpleNamespace(rgba=data["rgba"], passes=passes,
                                   seconds=float(data["seconds"]), cached=True)  # fmt: skip
    scene, cam = SCENES[name](width, height)
    ref = core.render(scene, cam, passes=REF_PASSES, **reference_options(name))
    seconds = ref.summary["time_s"]
    os.makedirs(REF_DIR, exist_ok=True)
    stored = {key: ref.passes[key] for key in REF_PASSES}
    np.savez_compressed(path, key=key, rgba=ref.rgba, seconds=seconds, **stored)
    return SimpleNamespace(rgba=ref.rgba, passes=ref.passes, seconds=seconds, cached=False)


def _luminance(rgba: np.ndarray) -> np.ndarray:
    """Rec.709 luminance (h, w) of a linear RGBA image."""
    return rgba[..., :3] @ LUMA


def lost_images(ref_mask: np.ndarray, run_mask: np.ndarray) -> tuple[int, int]:
    """(components of ref_mask (8-neighbours), those with no run_mask pixel within 1 px)."""
    eight = np.ones((3, 3), dtype=bool)
    labels, count = ndimage.label(ref_mask, structure=eight)
    if count == 0:
        return 0, 0
    near = ndimage.binary_dilation(run_mask, structure=eight)  # = each component grown 1 px
    found = np.bincount(labels[near], minlength=count + 1)[1:]
    return count, int(np.count_nonzero(found == 0))


def image_counts(name: str, ref: Any, run: Any) -> tuple[int, int]:
    """(lensed images in the reference, images the run lost): hit components, and bright
    ones in BRIGHT's scenes."""
    h, w = ref.rgba.shape[:2]
    hit_ref = ref.passes["ending"].reshape(h, w) == HIT
    hit_run = run.passes["ending"].reshape(h, w) == HIT
    count, lost = 0, 0
    if IDS:  # per object
        id_ref = ref.passes[OBJECT_PASS].reshape(h, w)
        id_run = run.passes[OBJECT_PASS].reshape(h, w)
        for k in np.unique(id_ref[hit_ref]):
            more = lost_images(hit_ref & (id_ref == k), hit_run & (id_run == k))
            count, lost = count + more[0], lost + more[1]
    else:
        count, lost = lost_images(hit_ref, hit_run)
    if name in BRIGHT:
        level = BRIGHT[name]
        more = lost_images(_luminance(ref.rgba) > level, _luminance(run.rgba) > level / 2)
        count, lost = count + more[0], lost + more[1]
    return count, lost


def compare(name: str, ref: Any, run: Any, tolerance_px: float, eye) -> dict:
    """The metrics of one run against its reference (see the module docstring)."""
    truth = true_error_px(ref, run, run.summary["pixel_angle"], eye)
    if IDS:  # a hit on another object is a flip too
        both = (ref.passes["ending"].ravel() == HIT) & (run.passes["ending"].ravel() == HIT)
        other = ref.passes[OBJECT_PASS].ravel() != run.passes[OBJECT_PASS].ravel()
        truth[both & other] = np.inf
    est = np.nan_to_num(run.passes["error_px"].ravel().astype(np.float64), nan=0.0)
    seen = ~np.isnan(truth)
    flip = np.isinf(truth)
    n = max(int(seen.sum()), 1)
    with np.errstate(invalid="ignore"):
        under = np.where(flip, est < 1.0, (est < truth / 3) & (truth > MEASURABLE)) & seen
        within = np.where(flip, est >= 1.0, (est >= truth / 3) & (est <= 3 * truth))
    big = seen & (truth > tolerance_px / 10)
    colour = np.any(np.abs(run.rgba - ref.rgba) > COLOUR_STEP, axis=-1)
    images, lost = image_counts(name, ref, run)
    finite = seen & ~flip
    summary = run.summary
    return {
        "scene": name,
        "size": f"{run.rgba.shape[1]}x{run.rgba.shape[0]}",
        "tolerance_px": tolerance_px,
        "pixels": int(truth.size),
        "over_tol_pct": 100 * np.count_nonzero(seen & (truth > tolerance_px)) / n,
        "over_3tol": int(np.count_nonzero(seen & (truth > 3 * tolerance_px))),
        "under3_pct": 100 * np.count_nonzero(under) / n,
        "under3_big_pct": 100 * np.count_nonzero(under & big) / n,
        "within3_pct": 100 * np.count_nonzero(big & within) / max(int(big.sum()), 1),
        "within3_n": int(big.sum()),
        "flips": int(flip.sum()),
        "flips_quiet": int(np.count_nonzero(flip & (est < 1.0))),
        "colour_pct": 100 * float(colour.mean()),
        "images_ref": images,
        "images_lost": lost,
        "true_max_px": float(truth[finite].max()) if finite.any() else 0.0,
        "est_median_px": float(np.median(est[seen])) if seen.any() else 0.0,
        "failed": int(summary["failed"]),
        "rays_per_px": summary["rays"] / summary["pixels"],
        "companions": summary.get("companion_rays", 0) / max(summary["rays"], 1),
        "retraces": (summary.get("error_rays", 0) - summary.get("companion_rays", 0))
        / max(summary["rays"], 1),
        "seconds": summary["time_s"],
        "reference_s": ref.seconds,
    }


# -- the table ---------------------------------------------------------------------------------

COLUMNS = (
    # (key, header, format)
    ("scene", "scene", "{:<14}"),
    ("tolerance_px", "tol px", "{:>6g}"),
    ("over_tol_pct", "over_tol% <=0.5", "{:>15.2f}"),
    ("over_3tol", "over_3tol =0", "{:>12d}"),
    ("under3_pct", "under3% <=1", "{:>11.2f}"),
    ("under3_big_pct", ">tol/10", "{:>7.2f}"),
    ("within3_pct", "within3% >=90", "{:>13.1f}"),
    ("within3_n", "of n", "{:>5d}"),
    ("flips", "flips", "{:>5d}"),
    ("flips_quiet", "<1px", "{:>4d}"),
    ("colour_pct", "colour% <=0.2", "{:>13.2f}"),
    ("images_ref", "images", "{:>6d}"),
    ("images_lost", "lost =0", "{:>7d}"),
    ("rays_per_px", "rays/px", "{:>7.2f}"),
    ("seconds", "seconds", "{:>7.1f}"),
    ("every_s", "every s", "{:>7.1f}"),
    ("x_every", "x every <=1.1", "{:>13.2f}"),
    ("dense_s", "dense s", "{:>7.1f}"),
    ("x_dense", "x dense", "{:>7.2f}"),
    ("dense_over_3tol", "dense >3T", "{:>9d}"),
    ("companions", "comp/ray <=0.3", "{:>14.2f}"),
    ("retraces", "retrace/ray", "{:>11.2f}"),
)


def _width(fmt: str) -> int:
    """The field width of a format like '{:>7.1f}'."""
    spec = fmt[3:-1].lstrip("<>")
    return int(spec.split(".")[0].rstrip("dfg") or 0)


def header() -> str:
    """The table's header line: each metric with its target."""
    return "  ".join(
        (f"{title:<{_width(fmt)}}" if key == "scene" else f"{title:>{_width(fmt)}}")
        for key, title, fmt in COLUMNS
    )


def format_row(row: dict) -> str:
    """One table line; a metric that misses its target is marked with '*'."""
    cells = []
    for key, _, fmt in COLUMNS:
        text = fmt.format(row[key])
        if key in TARGETS and missed(row, key):
            text = text[1:] + "*" if text.startswith(" ") else text + "*"
        cells.append(text)
    return "  ".join(cells)


def missed(row: dict, key: str) -> bool:
    """Whether the row's metric ``key`` misses its TARGETS entry (within3 needs pixels)."""
    op, bound = TARGETS[key]
    if key == "within3_pct" and row["within3_n"] == 0:
        return False
    return row[key] > bound if op == "<=" else row[key] < bound


def verdict(rows: list[dict]) -> str:
    """How many rows miss which target, one line."""
    parts = []
    for key, (op, bound) in TARGETS.items():
        bad = [r for r in rows if missed(r, key)]
        if bad:
            which = ", ".join(f"{r['scene']}@{r['tolerance_px']:g}" for r in bad)
            parts.append(f"{key} {op} {bound:g}: {len(bad)} ({which})")
    if not parts:
        return f"all {len(rows)} rows meet every target"
    return f"of {len(rows)} rows, missed: " + "; ".join(parts)


def cost_line(rows: list[dict]) -> str:
    """The run's time over every-pixel tracing and over the plain dense render: median,
    largest and rows within 1.1 (issue 48's targets: every row <= 1.1, median <= 0.5)."""
    if not rows:
        return "no rows"
    parts = []
    for key, name in (("x_every", "every pixel with the promise"), ("x_dense", "plain dense")):
        x = np.array([r[key] for r in rows])
        parts.append(f"x {name}: median {np.median(x):.2f}, max {x.max():.2f}, "
                     f"rows <= 1.1 {int((x <= 1.1).sum())} of {x.size}")  # fmt: skip
    broken = sum(r["dense_over_3tol"] > 0 for r in rows)
    return "; ".join(parts) + f"; plain dense over 3T on {broken} rows"


# -- images for a human ------------------------------------------------------------------------


def save_images(directory: str, name: str, ref: Any, run: Any) -> str:
    """reference | run | mask (white: |diff| > 0.1, red: ending flip) as <name>.png."""
    h, w = ref.rgba.shape[:2]
    differs = np.any(np.abs(run.rgba - ref.rgba) > COLOUR_STEP, axis=-1)
    flip = (ref.passes["ending"] != run.passes["ending"]).reshape(h, w)
    mask = np.zeros((h, w, 4), dtype=np.float32)
    mask[..., 3] = 1.0
    mask[differs, :3] = 1.0
    mask[flip, :3] = (1.0, 0.0, 0.0)
    gap = np.ones((h, 4, 4), dtype=np.float32)
    panels = [ref.rgba, gap, run.rgba, gap, mask]
    image = np.concatenate([np.asarray(p, dtype=np.float32) for p in panels], axis=1)
    os.makedirs(directory, exist_ok=True)
    path = os.path.join(directory, f"{name}.png")
    core.write_png(path, np.kron(image, np.ones((2, 2, 1), dtype=np.float32)))
    return path


# -- the thin strip ----------------------------------------------------------------------------


def strip_scene(width: int, height: int) -> tuple[core.Scene, core.Camera, float]:
    """A white strip 0.3 px wide and 10 rg tall, tilted 3 deg, on black, 7 rg beside a
    Schwarzschild hole seen from 30 rg: (scene, camera, its width in rg)."""
    cam = _black_hole_camera(width, height)
    centre = np.array([7.0, 0.0, 0.0])
    distance = float(np.linalg.norm(centre - cam.frame.position))
    wide = 0.3 * cam.pixel_angle() * distance
    tilt = math.radians(3.0)
    strip = core.Plane(centre, (0, -1, 0), (1, 1, 1, 1), u_axis=(math.sin(tilt), 0, math.cos(tilt)),
                       extent=(10.0, wide))  # fmt: skip
    scene = core.Scene(model=hm.schwarzschild(rg=1.0), objects=[strip], background=(0, 0, 0))
    return scene, cam, wide


def final_strip(width: int = 64, height: int = 48, factor: int = 8) -> dict:
    """The strip's total light at tolerance_px 0.25, 16 samples, box filter, over that of
    the dense reference supersampled factor x factor (box) on the strip's columns."""
    scene, cam, wide = strip_scene(width, height)
    run = core.render(scene, cam, tolerance_px=0.25, samples=16, pixel_filter="box", passes=())
    light = _luminance(run.rgba)
    big = _black_hole_camera(factor * width, factor * height)
    # the strip's columns (lit in a quick dense look or the run, the run of them holding the
    # brightest; not its secondary image past the hole), 2 px either side: the reference's crop
    quick = core.render(scene, cam, samples=16, pixel_filter="box", passes=(), tolerance=1e-6)
    seen = _luminance(quick.rgba).sum(axis=0)
    runs, _ = ndimage.label(seen + light.sum(axis=0) > 0)
    cols = np.flatnonzero(runs == runs[np.argmax(seen)])
    c0, c1 = max(int(cols.min()) - 2, 0), min(int(cols.max()) + 3, width)
    crop = copy.copy(big)
    crop.region = (factor * c0, factor * c1, 0, factor * height)
    t = time.perf_counter()
    ref = core.render(scene, crop, passes=(), **REFERENCE)
    dense = ref.rgba.reshape(height, factor, c1 - c0, factor, 4).mean(axis=(1, 3))
    ratio = float(light[:, c0:c1].sum() / max(_luminance(dense).sum(), 1e-12))
    row = {
        "strip_width_rg": wide,
        "columns": f"{c0}-{c1 - 1}",
        "light_run": float(light[:, c0:c1].sum()),
        "light_ref": float(_luminance(dense).sum()),
        "ratio": ratio,
        "rays_per_px": run.summary["rays"] / run.summary["pixels"],
        "seconds": run.summary["time_s"],
        "reference_s": time.perf_counter() - t,
    }
    mark = "" if ratio >= STRIP_TARGET else "  MISSED"
    print(
        f"final_strip {width}x{height} (0.3 px wide, tolerance_px 0.25, 16 samples, box) "
        f"against {factor}x{factor} supersampled columns {row['columns']}: light run / reference "
        f"{ratio:.3f} (target >= {STRIP_TARGET}){mark}; {row['rays_per_px']:.2f} rays/px, "
        f"{row['seconds']:.1f} s (reference {row['reference_s']:.1f} s)"
    )
    return row


# -- main --------------------------------------------------------------------------------------


def run_scene(
    name: str, size: tuple[int, int], tolerances: Sequence[float], fresh: bool, images: str | None
) -> list[dict]:
    """Every tolerance of one scene against its reference: rows (printed as they come)."""
    width, height = size
    t = time.perf_counter()
    try:
        ref = reference(name, width, height, fresh)
    except ValueError as refused:  # a scene core.render refuses, by name: no row
        print(f"{name:<14}  refused: {refused}", flush=True)
        return []
    if not ref.cached:
        print(f"  ({name}: reference rendered in {time.perf_counter() - t:.1f} s)", flush=True)
    scene, cam = SCENES[name](width, height)
    rows = []
    for tol in tolerances:
        run = core.render(scene, cam, tolerance_px=tol, samples=1, passes=RUN_PASSES)
        rows.append(compare(name, ref, run, tol, cam.frame.position))
        rows[-1].update(dense_row(scene, cam, tol, run, ref))
        print(format_row(rows[-1]), flush=True)
        if images and tol == max(tolerances):
            save_images(images, name, ref, run)
    return rows


def dense_row(scene: core.Scene, cam: core.Camera, tolerance_px: float, run: Any, ref: Any) -> dict:
    """The same scene with every pixel centre traced, twice, with the run's passes: with
    the promise (``interpolate=False``: the run's step, its error pass, near misses and
    rays over budget traced again; the bar the adaptive image is weighed against) and
    plainly (the integration tolerance the adaptive run gave its tracer, TRACE_SHARE x
    tolerance_px pixels, and the companion's error pass, nothing traced again): each one's
    seconds, the run's over them, and how many pixels the plain one has over 3 T."""
    every = core.render(scene, cam, tolerance_px=tolerance_px, samples=1, passes=RUN_PASSES,
                        interpolate=False)  # fmt: skip
    tolerance = TRACE_SHARE * tolerance_px * run.summary["pixel_angle"]
    dense = core.render(scene, cam, tolerance=tolerance, samples=1, passes=RUN_PASSES)
    truth = true_error_px(ref, dense, dense.summary["pixel_angle"], cam.frame.position)
    seconds, every_s = dense.summary["time_s"], every.summary["time_s"]
    return {
        "every_s": every_s,
        "x_every": run.summary["time_s"] / every_s,
        "dense_s": seconds,
        "x_dense": run.summary["time_s"] / seconds,
        "dense_over_3tol": int(np.count_nonzero(truth > 3 * tolerance_px)),
    }


def write_csv(path: str, rows: list[dict]) -> None:
    """Rows as CSV (the first row's keys)."""
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def _size(text: str) -> tuple[int, int]:
    """'160x90' -> (160, 90)."""
    w, h = text.lower().split("x")
    return int(w), int(h)


def main(argv: list[str] | None = None) -> list[dict]:
    """Parse the command line, run the scenes and the strip, print and write the results."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="96x54, tolerances 1 and 0.25")
    parser.add_argument("--size", type=_size, default=None, help="WxH (default 160x90)")
    parser.add_argument("--scenes", default=",".join(SCENES), help="comma-separated names")
    parser.add_argument("--tolerances", default=None, help="tolerance_px values, e.g. 1,0.25")
    parser.add_argument("--fresh", action="store_true", help="ignore the cached references")
    parser.add_argument("--save-images", default=None, metavar="DIR")
    parser.add_argument("--no-strip", action="store_true", help="skip final_strip")
    parser.add_argument("--out", default=os.path.join(OUT, "honesty.csv"))
    args = parser.parse_args(argv)
    size = args.size or (QUICK_SIZE if args.quick else SIZE)
    tolerances = (
        tuple(float(t) for t in args.tolerances.split(","))
        if args.tolerances
        else (QUICK_TOLERANCES if args.quick else TOLERANCES)
    )
    names = [s for s in args.scenes.split(",") if s]
    unknown = set(names) - set(SCENES)
    if unknown:
        parser.error(f"unknown scenes {sorted(unknown)}; choose from {list(SCENES)}")
    start = time.perf_counter()
    print(f"honesty {size[0]}x{size[1]}, tolerances {tolerances} px ('*': misses its target)")
    print(header(), flush=True)
    rows: list[dict] = []
    for name in names:
        rows += run_scene(name, size, tolerances, args.fresh, args.save_images)
    print(verdict(rows))
    print(cost_line(rows))
    write_csv(args.out, rows)
    if not args.no_strip:
        final_strip()
    print(f"total {time.perf_counter() - start:.0f} s; rows in {args.out}")
    return rows


if __name__ == "__main__":
    main()

"""How fine a bake is: an object's texel size from its size on the rendered image.

With *Texel Size* 0 (automatic) a baked texel is about ``TEXEL_PIXELS`` pixels of the
render where the object is seen through the scene camera in flat space: the texel size
is the root-mean-square pixel footprint over the object's surface inside the camera's
view, estimated from ``SAMPLES`` points spread over the surface by area (a fixed seed: the
same object and camera give the same size). A pixel covers the world area
``z³ / |n·v|`` times its window area (a pinhole at distance 1: ``v`` from the camera to
the point, ``z`` its depth, ``n`` the surface normal), so faces seen edge-on or far away
ask for fewer texels, and an object filling the frame for more. An object wholly outside
the view (seen only through bent light, or only lighting others) is sized as if the
camera turned to face it. The side is then rounded to the nearest step of a ladder
(factors of √2) and clamped to *Max Resolution*, so that a camera moving a little keeps
its bakes (``bake.py`` reuses a bake at least as fine as the one asked for).

Bent light can magnify a surface (near a black hole's shadow, an Einstein ring): there the
texels show; a fixed *Texel Size* (scene units) is the remedy.
"""

from __future__ import annotations

import math

import bpy
import numpy as np

from .. import core
from .export_camera import camera_kwargs

TEXEL_PIXELS = 1.5
"""Width of an automatic texel in pixels of the render (where the object is seen)."""
SAMPLES = 4096
"""Surface points the on-screen size is estimated from."""
NO_CAMERA_SIDE = 256
"""Side of an automatic bake when the scene has no usable camera."""
MIN_RESOLUTION = 8


def scene_camera(scene: bpy.types.Scene, depsgraph: bpy.types.Depsgraph) -> core.Camera | None:
    """The scene camera at the render resolution (whole frame), or None without one."""
    camera = scene.camera
    if camera is None or camera.type != "CAMERA":
        return None
    try:
        return core.Camera.blender(
            **camera_kwargs(scene, camera.evaluated_get(depsgraph), use_border=False)
        )
    except (ValueError, RuntimeError, ReferenceError):  # the render says what is wrong
        return None


def _surface_points(
    world: np.ndarray, rng: np.random.Generator, count: int
) -> tuple[np.ndarray, np.ndarray]:
    """``count`` points spread over triangles ``world`` (T, 3, 3) by area, and their unit
    normals; empty where the triangles have no area."""
    cross = np.cross(world[:, 1] - world[:, 0], world[:, 2] - world[:, 0])
    double_area = np.linalg.norm(cross, axis=1)
    keep = double_area > 0.0
    if not np.any(keep) or not np.isfinite(double_area[keep].sum()):
        return np.empty((0, 3)), np.empty((0, 3))
    world, cross, double_area = world[keep], cross[keep], double_area[keep]
    chosen = rng.choice(len(world), size=count, p=double_area / double_area.sum())
    r1, r2 = np.sqrt(rng.random(count)), rng.random(count)
    weights = np.stack([1.0 - r1, r1 * (1.0 - r2), r1 * r2], axis=1)
    points = np.einsum("nk,nkj->nj", weights, world[chosen])
    return points, cross[chosen] / double_area[chosen, None]


def pixel_footprint(camera: core.Camera, world: np.ndarray) -> float | None:
    """World size of one pixel of ``camera`` over the surface of triangles ``world``
    (T, 3, 3): its visible part, or all of it as if faced where none is in view (see
    the module docstring). None where the surface has no area or faces nowhere."""
    rng = np.random.default_rng(0)
    points, normals = _surface_points(np.asarray(world, dtype=np.float64), rng, SAMPLES)
    if len(points) == 0:
        return None
    frame = camera.frame
    xmin, xmax, ymin, ymax = camera.window
    winx, winy = camera.full_size
    pixel = (xmax - xmin) / winx * (ymax - ymin) / winy  # window area of one pixel
    v = points - frame.position
    z, x, y = v @ frame.forward, v @ frame.right, v @ frame.up
    r = np.linalg.norm(v, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        if camera.kind == "ortho":
            sx, sy, front = x, y, z > 0.0
            density = np.abs(normals @ frame.forward) / pixel
            faced = density
        elif camera.kind == "pano":
            sx, sy, front = np.arctan2(x, z), np.arcsin(np.clip(y / r, -1.0, 1.0)), r > 0.0
            faced = np.abs(np.einsum("nj,nj->n", normals, v)) / (r**3 * pixel)
            density = faced / np.maximum(np.cos(sy), 1e-6)
        else:
            sx, sy, front = x / z, y / z, z > 1e-9 * (1.0 + r)
            cos_n = np.abs(np.einsum("nj,nj->n", normals, v))
            density, faced = cos_n / (z**3 * pixel), cos_n / (r**3 * pixel)
    seen = front & (sx >= xmin) & (sx <= xmax) & (sy >= ymin) & (sy <= ymax)
    chosen = density[seen] if np.any(seen) else faced
    mean = float(np.mean(chosen[np.isfinite(chosen)])) if np.any(np.isfinite(chosen)) else 0.0
    if not mean > 0.0 or not math.isfinite(mean):
        return None
    return 1.0 / math.sqrt(mean)


def ladder(side: float) -> int:
    """``side`` rounded to the nearest of 8, 11, 16, 23, 32, 45, 64, ... (8·√2^k)."""
    k = round(2.0 * math.log2(max(side, MIN_RESOLUTION) / MIN_RESOLUTION))
    return int(round(MIN_RESOLUTION * 2.0 ** (k / 2.0)))


def side(extent: float, texel: float | None, max_resolution: int, automatic: bool) -> int:
    """Side of a square bake whose UV square spans ``extent`` world units (the root of the
    surface's area over the UV area it covers) at ``texel`` world units a texel: on the
    ladder when ``automatic`` (NO_CAMERA_SIDE where ``texel`` is None), within
    [MIN_RESOLUTION, ``max_resolution``]."""
    if texel is None or not texel > 0.0:
        wanted = float(NO_CAMERA_SIDE if texel is None else MIN_RESOLUTION)
    else:
        wanted = math.ceil(extent / texel) if math.isfinite(extent / texel) else max_resolution
    if automatic:
        wanted = ladder(wanted)
    return int(min(max(wanted, MIN_RESOLUTION), max_resolution))

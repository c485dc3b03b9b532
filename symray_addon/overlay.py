"""The black hole drawn in the 3D viewport at its true size, as Blender draws a light.

Around each hole object: its horizon (the Kerr–Schild image of r = r₊, an oblate spheroid,
as three ellipses), its photon orbits (the prograde and retrograde circular ones in the
equator), the disk's inner and outer edge when the disk is on, and the spin axis. The
geometry (``hole_lines``) is plain numpy; ``_draw`` hands it to the GPU in the UI only.
"""

from __future__ import annotations

import math
from typing import Any

import bpy
import numpy as np

from ..core.geometry.disk import isco
from . import objects
from .models import placement

SEGMENTS = 64
"""Line segments per circle."""
COLOURS = {
    "horizon": (0.05, 0.05, 0.05, 1.0),
    "photon": (1.0, 0.75, 0.2, 1.0),
    "disk": (1.0, 0.45, 0.1, 1.0),
    "axis": (0.3, 0.6, 1.0, 1.0),
}


def photon_orbit_radii(rg: float, spin: float, charge: float = 0.0) -> tuple[float, float]:
    """Boyer–Lindquist radii of the prograde and retrograde circular photon orbits: at
    charge 0 Bardeen, Press & Teukolsky's 2M (1 + cos(⅔ arccos(∓χ))); a charged hole's are
    the outermost roots of r² − 3Mr + 2Q² ± 2a √(Mr − Q²) = 0 (Kerr–Newman's equator, with
    a = χM, Q = qM), found on a fine grid (a drawing's accuracy)."""
    mass, chi = 0.5 * rg, min(abs(spin), 1.0)
    if charge == 0.0:
        return tuple(2 * mass * (1 + math.cos(2 / 3 * math.acos(s * chi))) for s in (-1.0, 1.0))
    a, q2 = chi * mass, (float(charge) * mass) ** 2
    r = np.linspace(4.0 * mass, q2 / mass, 40_001)  # from outside every photon orbit inwards
    radii = []
    for sign in (1.0, -1.0):  # prograde, retrograde
        f = r * r - 3.0 * mass * r + 2.0 * q2 + sign * 2.0 * a * np.sqrt(mass * r - q2)
        crossing = np.flatnonzero(np.sign(f[1:]) != np.sign(f[:-1]))
        radii.append(float(r[crossing[0]]) if crossing.size else float("nan"))
    return tuple(radii)


def _ellipse(a: float, b: float, plane: str) -> np.ndarray:
    """Segments (SEGMENTS, 2, 3) of an ellipse of semi-axes a, b in the local XY, XZ or YZ
    plane."""
    t = np.linspace(0.0, 2 * np.pi, SEGMENTS + 1)
    points = np.zeros((SEGMENTS + 1, 3))
    first, second = {"XY": (0, 1), "XZ": (0, 2), "YZ": (1, 2)}[plane]
    points[:, first], points[:, second] = a * np.cos(t), b * np.sin(t)
    return np.stack([points[:-1], points[1:]], axis=1)


def _circles(a: float, radii: Any) -> np.ndarray:
    """Segments of equatorial circles at Boyer–Lindquist radii ``radii`` (Kerr–Schild
    Cartesian radius √(r² + a²))."""
    return np.concatenate([_ellipse(math.hypot(r, a), math.hypot(r, a), "XY") for r in radii])


def hole_lines(
    size: float,
    spin: float,
    disk_radii: tuple[float, float] | None = None,
    charge: float = 0.0,
) -> dict[str, np.ndarray]:
    """Line segments (N, 2, 3) in the hole's local frame, by what they show: 'horizon',
    'photon', 'disk' (Boyer–Lindquist radii ``disk_radii``, or none) and 'axis'.
    Equatorial radii are Kerr–Schild's √(r² + a²), as the renderer places them."""
    rg = objects.rg_of(size, spin, charge)
    a = 0.5 * rg * spin
    equator = math.hypot(size, a)
    lines = {
        "horizon": np.concatenate(
            [_ellipse(equator, equator, "XY")]
            + [_ellipse(equator, size, plane) for plane in ("XZ", "YZ")]
        ),
        "photon": _circles(a, photon_orbit_radii(rg, spin, charge)),
        "axis": np.array([[[0.0, 0.0, -2.0 * size], [0.0, 0.0, 2.0 * size]]]),
    }
    if disk_radii is not None:
        lines["disk"] = _circles(a, disk_radii)
    return lines


def _disk_radii(scene: bpy.types.Scene, size: float, spin: float) -> tuple[float, float] | None:
    """The BL radii of the scene's disk around its hole, None when it is off."""
    disk = scene.symray.disk
    if not disk.enabled or abs(spin) >= 1.0:
        return None
    mass = 0.5 * objects.rg_of(size, spin)
    inner = isco(mass, spin * mass) if disk.use_isco else float(disk.inner_radius)
    return inner, float(disk.outer_radius)


def world_lines(scene: bpy.types.Scene) -> dict[str, np.ndarray]:
    """The scene's hole's lines in world coordinates ({} without a hole)."""
    hole = objects.hole_of(scene)
    if hole is None:
        return {}
    size, spin = float(hole.symray.size), float(hole.symray.spin)
    where = placement(hole.matrix_world)
    charge = float(hole.symray.charge)
    lines = hole_lines(size, spin, _disk_radii(scene, size, spin), charge)
    return {k: v @ where.rotation.T + where.center for k, v in lines.items()}


def _draw() -> None:
    """Draw handler: the lines of the context scene's hole (viewport, UI only)."""
    import gpu
    from gpu_extras.batch import batch_for_shader

    context: Any = bpy.context
    if context.scene is None or not hasattr(context.scene, "symray"):
        return
    shader = gpu.shader.from_builtin("UNIFORM_COLOR")
    gpu.state.depth_test_set("LESS_EQUAL")
    for name, segments in world_lines(context.scene).items():
        batch = batch_for_shader(shader, "LINES", {"pos": segments.reshape(-1, 3).tolist()})
        shader.uniform_float("color", COLOURS[name])
        batch.draw(shader)
    gpu.state.depth_test_set("NONE")


_handle: list[Any] = []


def register() -> None:
    """Add the viewport draw handler (not in background mode: no viewport to draw in)."""
    if not bpy.app.background:
        _handle.append(bpy.types.SpaceView3D.draw_handler_add(_draw, (), "WINDOW", "POST_VIEW"))


def unregister() -> None:
    """Remove the draw handler."""
    while _handle:
        bpy.types.SpaceView3D.draw_handler_remove(_handle.pop(), "WINDOW")

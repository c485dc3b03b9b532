"""The seed's mirage scenes: index profiles and the scene builder, shared by tests, examples,
benchmarks and the add-on.

The seed's Figs. 10 and 11 show an inferior mirage (an inverted image below the object)
and Vince's phenomenon (an inverted ghost, and an upright one, above the object). Its
Eq. 17 and 18 are used with the literal Hamiltonian H = n |p|^2 / 2 (Eq. 8/16), whose n
is the physical index to the power -2. The seed's printed coefficients are not
available to us, so these are our reconstructions with the same phenomena, written in
that literal form (lengths in metres, the ground at z = 0):

- Eq. 17 (inferior mirage): hot ground; the physical index rises by 3e-3 within ~15 cm
  above it, n(z) = 1 + 0.003 (1 - exp(-z/0.15)).
- Eq. 18 (Vince's phenomenon): a warm inversion layer at 1.1 m; the physical index
  falls by 4e-3 across it, n(z) = 1 - 0.002 tanh((z - 1.1)/0.1).
"""

from __future__ import annotations

import numpy as np

from .camera import Camera
from .geometry import Plane, checker
from .models import medium
from .tracing import Scene

MIRAGE_EQ17_INDEX = "1/(1 + 0.003*(1 - exp(-z/0.15)))**2"
"""Literal-form n for the inferior mirage (seed Fig. 10)."""
MIRAGE_EQ18_INDEX = "1/(1 - 0.002*tanh((z - 1.1)/0.1))**2"
"""Literal-form n for Vince's phenomenon, a ghost above the object (seed Fig. 11)."""

MIRAGE_BOX = ((-1.0, -100.0, -1.0), (250.0, 100.0, 3.0))
"""Where the mirage media bend light (outside, n is constant to 1e-9: rays are straight)."""

MIRAGE_VIEWS = {
    # name: (literal index, camera height, tilt, board z range, horizontal fov in degrees)
    "fig10": (MIRAGE_EQ17_INDEX, 0.4, -0.04, (0.1, 0.7), 10.0),
    "fig11": (MIRAGE_EQ18_INDEX, 0.9, 0.0, (0.2, 0.9), 10.0),
}
"""The seed's two mirage views (Figs. 10 and 11), shared by examples, benchmarks and tests."""


def band_texture(z0: float, z1: float):
    """A texture (uv, position, normal) -> RGBA of three horizontal bands between heights z0
    and z1: red (top third), green, white (bottom third)."""

    def paint(uv, p, n):
        c = np.zeros((len(p), 4))
        c[:, 3] = 1.0
        f = (p[:, 2] - z0) / (z1 - z0)
        c[f > 2 / 3, 0] = 1.0
        c[(f <= 2 / 3) & (f > 1 / 3), 1] = 1.0
        c[f <= 1 / 3, :3] = 1.0
        return c

    return paint


def mirage_scene(index: str | None, board_z: tuple[float, float]) -> Scene:
    """A banded board (red top, green, white bottom) 20 m away on a checkered ground, seen
    through the literal-form medium ``index`` within MIRAGE_BOX (None: no medium)."""
    z0, z1 = board_z
    paint = band_texture(z0, z1)
    board = Plane(
        point=(20, 0, 0.5 * (z0 + z1)),
        normal=(-1, 0, 0),
        u_axis=(0, 1, 0),
        extent=(1.0, z1 - z0),
        color=paint,
    )
    ground = Plane(
        point=(0, 0, 0),
        normal=(0, 0, 1),
        u_axis=(1, 0, 0),
        extent=(400, 400),
        color=checker(200, 200, (0.35, 0.3, 0.25, 1), (0.3, 0.25, 0.2, 1)),
    )
    poles = [
        Plane(
            point=(x, y, 0.6),
            normal=(-1, 0, 0),
            u_axis=(0, 1, 0),
            extent=(0.08, 1.2),
            color=(0.25, 0.12, 0.05, 1),
        )
        for x, y in ((12.0, -1.0), (32.0, 1.6))
    ]
    model = None if index is None else medium(index, literal=True, bounds=MIRAGE_BOX)
    return Scene(model=model, objects=[board, *poles, ground], background=(0.3, 0.45, 0.95))


def mirage_view(
    name: str, width: int, height: int, with_medium: bool = True
) -> tuple[Scene, Camera]:
    """The scene and camera of a MIRAGE_VIEWS view (``fov`` spans the larger dimension)."""
    index, cz, tilt, board, fov = MIRAGE_VIEWS[name]
    cam = Camera.perspective(
        position=(0, 0, cz),
        look_at=(1, 0, cz + tilt),
        up=(0, 0, 1),
        fov_deg=fov,
        width=width,
        height=height,
    )
    return mirage_scene(index if with_medium else None, board), cam

"""Ray differentials: the derivative of each camera ray's final direction with respect to
the image coordinates (its *sky Jacobian*), and the magnification of the image it belongs
to.

Inside the model's region the derivative is carried through every step by forward-mode dual
numbers: the splits' exact flows run on ``core.dual.DualRows`` (``Splitting.step`` on a state
with tangents), so it is the derivative of the discrete flow the image shows (the tangent map
of a symplectic step is itself symplectic). The closed-form maps before and after it, from the
camera's direction to the ray's start (aberration, the region's entry point, the chart, the
observer's frame) and from the ray's last state to its escape direction (the far-field
correction), are differentiated by central differences along the tangent: they are smooth,
and a relative step of ``FD_STEP`` leaves an error ~FD_STEP^2 + 1e-16 / FD_STEP ~ 1e-10.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

FD_STEP = 1e-6
"""Relative step of the central differences of the closed-form maps (see the module)."""


def directional(
    f: Callable[[np.ndarray], np.ndarray],
    x: np.ndarray,
    tangents: np.ndarray,
    periodic: Sequence[int] = (),
) -> np.ndarray:
    """Derivatives (M, k, m') of ``f`` (x (M, m) -> (M, m'), row by row) at x along each of
    the k tangents (M, k, m), by central differences with a step of FD_STEP (1 + |x|) per
    ray and tangent; output columns ``periodic`` are angles (their differences are taken
    modulo 2 pi)."""
    size = 1.0 + np.linalg.norm(x, axis=1)
    out = []
    for k in range(tangents.shape[1]):
        t = tangents[:, k]
        length = np.linalg.norm(t, axis=1)
        with np.errstate(all="ignore"):
            eps = np.where(length > 0, FD_STEP * size / length, 0.0)
        delta = f(x + eps[:, None] * t) - f(x - eps[:, None] * t)
        for column in periodic:
            delta[:, column] = np.angle(np.exp(1j * delta[:, column]))
        with np.errstate(all="ignore"):
            out.append(np.where(eps[:, None] > 0, delta / (2.0 * eps[:, None]), 0.0))
    return np.stack(out, axis=1)


def unit_directional(f: Callable[[np.ndarray], np.ndarray], d: np.ndarray, tangents) -> np.ndarray:
    """``directional`` for a map of unit directions d (M, 3): the points either side are
    normalised again (tangents ⟂ d keep their length to first order)."""

    def on_sphere(x: np.ndarray) -> np.ndarray:
        return f(x / np.linalg.norm(x, axis=1, keepdims=True))

    return directional(on_sphere, d, tangents)


def solid_angle_rate(tangents: np.ndarray) -> np.ndarray:
    """|t_x × t_y| (M,): the solid angle per unit image area that unit directions with
    derivatives (M, 2, 3) sweep."""
    return np.linalg.norm(np.cross(tangents[:, 0], tangents[:, 1]), axis=1)


def magnification(camera_tangents: np.ndarray, sky_jacobian: np.ndarray) -> np.ndarray:
    """|μ| (M,): the camera's solid angle per unit image area over the sky's (each (M, 2, 3)
    derivatives of unit directions with respect to the image coordinates): how much brighter
    a point source looks in this image than without the lens (inf on a caustic; NaN where
    there is no sky Jacobian)."""
    with np.errstate(all="ignore"):
        return solid_angle_rate(camera_tangents) / solid_angle_rate(sky_jacobian)

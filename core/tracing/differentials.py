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

from ..backend import array_module

FD_STEP = 1e-6
"""Relative step of the central differences of the closed-form maps (see the module)."""
RADIAL = 1e-7
"""|â × d| below which a ray leaves the camera along the axis â (``axial_tangents``): off it,
the turn's share is known to ~1e-16 / |â × d|; on it, the second tangent is the first turned,
to O(|â × d|)."""


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


def axial_final(shares: np.ndarray, traced: np.ndarray, d: np.ndarray, axis: np.ndarray):
    """The k tangents' final-direction derivatives (M, k, 3) from ``axial_tangents``'
    ``shares`` (3, k, M), the traced tangent's (M, 1, 3), the final directions d (M, 3) and
    the cameras' axes â (M, 3), all in the same axes: a turn about â by ε turns the whole
    path, so d by ε â × d; the traced one turned by 90° about â is â × u + (â · u) â."""
    u = traced[:, 0]
    spin = np.cross(axis, d)
    quarter = np.cross(axis, u) + np.einsum("ij,ij->i", axis, u)[:, None] * axis
    along, turn, turned = (share.T[..., None] for share in shares)
    return along * u[:, None] + turn * spin[:, None] + turned * quarter[:, None]


def axial_tangents(
    camera: np.ndarray, d: np.ndarray, tangents: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Split the direction tangents (M, k, 3) of unit directions d (M, 3) seen from cameras
    at ``camera`` (M, 3) (local, about a spherically symmetric model's centre) into one to
    trace and the rest by symmetry. A ray and the axis â = camera / |camera| span a plane
    that holds its path: e_out = â × d / |â × d| turns the ray about â (the whole path turns:
    its state's derivative is the rotation's generator over |â × d|), e_in = e_out × d stays
    in the plane and is traced. Rays along â (|â × d| < RADIAL) have no plane: e_in is the
    tangents' own direction across d, and e_out = e_in turned by 90° about â, whose path is
    the traced one's turned. -> (shares (3, k, M), e_in (M, 1, 3)): each tangent's share of
    e_in, of the turn about â per radian (rays off the axis) and of e_in turned by 90° about
    â (rays on it), rays on the last axis (``axial_final``)."""
    axis = camera / np.linalg.norm(camera, axis=1, keepdims=True)
    cross = np.cross(axis, d)
    size = np.linalg.norm(cross, axis=1)
    radial = size < RADIAL
    with np.errstate(divide="ignore", invalid="ignore"):
        e_out = cross / size[:, None]
    e_in = np.cross(e_out, d)
    if radial.any():
        e_in[radial], e_out[radial] = _radial_frame(axis[radial], d[radial], tangents[radial])
    along = np.einsum("mkj,mj->km", tangents, e_in)
    side = np.einsum("mkj,mj->km", tangents, e_out)
    with np.errstate(divide="ignore", invalid="ignore"):
        turn = np.where(radial, 0.0, side / size)
    turned = np.where(radial, side, 0.0)
    return np.stack([along, turn, turned]), e_in[:, None, :]


def _radial_frame(axis, d, tangents) -> tuple[np.ndarray, np.ndarray]:
    """(e_in, e_out) (M, 3) of rays along the axis (``axial_tangents``): e_in the unit part
    across d of the tangent with the largest one, e_out = e_in turned by 90° about â."""
    across = tangents - np.einsum("mkj,mj->mk", tangents, d)[..., None] * d[:, None]
    sizes = np.linalg.norm(across, axis=2)
    pick = np.argmax(sizes, axis=1)
    rows = array_module(d).arange(d.shape[0])
    e_in = across[rows, pick] / sizes[rows, pick][:, None]
    e_out = np.cross(axis, e_in) + np.einsum("ij,ij->i", axis, e_in)[:, None] * axis
    return e_in, e_out

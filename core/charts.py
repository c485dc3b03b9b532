"""Coordinate charts: a model's coordinates <-> Cartesian positions and directions.

The renderer works in the model's *local Cartesian* frame (origin at the model's centre,
z along its axis). A chart maps those positions to the model's coordinates q and maps
coordinate velocities dq/ds back to Cartesian ones. Arrays are structure-of-arrays:
positions (3, N), directions (3, N).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from .models import Hamiltonian


class CartesianChart:
    """q = (x, y, z) [or (t, x, y, z) with a leading time]: the identity map."""

    name = "cartesian"

    def __init__(self, time_index: int | None):
        self.time_index = time_index
        self.offset = 0 if time_index is None else 1

    def to_coords(self, X: np.ndarray) -> np.ndarray:
        """Spatial coordinates (3, N) of local Cartesian positions (3, N)."""
        return X.copy()

    def to_cartesian(self, S: np.ndarray) -> np.ndarray:
        """Local Cartesian positions of spatial coordinates (3, N)."""
        return S

    def coord_directions(self, S: np.ndarray, D: np.ndarray) -> np.ndarray:
        """Coordinate components dq of Cartesian direction vectors D at S."""
        return D.copy()

    def cartesian_velocity(self, S: np.ndarray, dS: np.ndarray) -> np.ndarray:
        """Cartesian velocity (3, N) from coordinate velocity dq/ds at S."""
        return dS

    def axial_killing(self, S: np.ndarray) -> np.ndarray:
        """Spatial components of the rotation generator about z: (-y, x, 0)."""
        return np.stack([-S[1], S[0], np.zeros_like(S[0])])


class SpheroidalChart:
    """Boyer–Lindquist (r, theta, phi) with spin a: x = sqrt(r^2+a^2) sin(theta) cos(phi), ...

    a = 0 gives ordinary spherical coordinates. q = (t, r, theta, phi).
    """

    name = "spherical"
    offset = 1
    time_index = 0

    def __init__(self, a: float = 0.0):
        self.a = float(a)

    def to_coords(self, X):
        """(r, theta, phi) of local Cartesian positions (3, N)."""
        x, y, z = X
        a2 = self.a**2
        rho2 = x * x + y * y + z * z - a2
        r = np.sqrt(0.5 * (rho2 + np.sqrt(rho2 * rho2 + 4 * a2 * z * z)))
        with np.errstate(invalid="ignore", divide="ignore"):
            cos_t = np.where(r > 0, z / r, 0.0)
        theta = np.arccos(np.clip(cos_t, -1.0, 1.0))
        phi = np.arctan2(y, x)
        return np.stack([r, theta, phi])

    def to_cartesian(self, S):
        """Local Cartesian positions of (r, theta, phi) (3, N)."""
        r, theta, phi = S
        rho = np.sqrt(r * r + self.a**2) * np.sin(theta)
        return np.stack([rho * np.cos(phi), rho * np.sin(phi), r * np.cos(theta)])

    def jacobian(self, S):
        """d(x, y, z)/d(r, theta, phi) as (N, 3, 3)."""
        r, theta, phi = S
        R = np.sqrt(r * r + self.a**2)
        st, ct, sp, cp = np.sin(theta), np.cos(theta), np.sin(phi), np.cos(phi)
        J = np.empty((r.shape[0], 3, 3))
        J[:, 0, 0] = r / R * st * cp
        J[:, 0, 1] = R * ct * cp
        J[:, 0, 2] = -R * st * sp
        J[:, 1, 0] = r / R * st * sp
        J[:, 1, 1] = R * ct * sp
        J[:, 1, 2] = R * st * cp
        J[:, 2, 0] = ct
        J[:, 2, 1] = -r * st
        J[:, 2, 2] = 0.0
        return J

    def coord_directions(self, S, D):
        """Coordinate components (dr, dtheta, dphi) of Cartesian vectors D (3, N) at S."""
        J = self.jacobian(S)
        return np.linalg.solve(J, D.T[..., None])[..., 0].T

    def cartesian_velocity(self, S, dS):
        """Cartesian velocity (3, N) from (dr, dtheta, dphi)/ds."""
        J = self.jacobian(S)
        return np.einsum("nij,jn->in", J, dS)

    def axial_killing(self, S):
        """Components of d/dphi: (0, 0, 1)."""
        z = np.zeros_like(S[0])
        return np.stack([z, z, np.ones_like(z)])


class IsotropicChart:
    """World (Schwarzschild-Cartesian, r = |X|) <-> isotropic Cartesian (ρ = |x|) positions.

    Both charts share directions (the map is radial), and a static observer's orthonormal
    frame has the same components in both (its spatial metric is diagonal in radial and
    tangential directions in both), so camera directions carry over unchanged.
    """

    name = "isotropic"
    offset = 0
    time_index = None

    def __init__(self, mass: float):
        self.mass = float(mass)

    def to_coords(self, X: np.ndarray) -> np.ndarray:
        """Isotropic positions (3, N) of world positions (3, N) (NaN inside r = 2M)."""
        r = np.sqrt(np.einsum("ij,ij->j", X, X))
        M = self.mass
        with np.errstate(invalid="ignore", divide="ignore"):
            rho = 0.5 * (r - M + np.sqrt(r * r - 2.0 * M * r))
            return X * np.where(r > 0, rho / r, np.nan)

    def to_cartesian(self, S: np.ndarray) -> np.ndarray:
        """World positions of isotropic ones: X = x (1 + M/2ρ)²."""
        rho = np.sqrt(np.einsum("ij,ij->j", S, S))
        return S * (1.0 + 0.5 * self.mass / rho) ** 2

    def coord_directions(self, S: np.ndarray, D: np.ndarray) -> np.ndarray:
        """Isotropic components of world directions: the same (see the class)."""
        return D.copy()

    def cartesian_velocity(self, S: np.ndarray, dS: np.ndarray) -> np.ndarray:
        """World velocity J dS of an isotropic one: J = λ I + λ'(ρ) x xᵀ / ρ, λ = (1 + M/2ρ)²."""
        rho = np.sqrt(np.einsum("ij,ij->j", S, S))
        u = 0.5 * self.mass / rho
        lam = (1.0 + u) ** 2
        dlam = -2.0 * (1.0 + u) * u / rho
        radial = np.einsum("ij,ij->j", S, dS) / rho
        return lam * dS + dlam * radial * S

    def axial_killing(self, S: np.ndarray) -> np.ndarray:
        """Spatial components of the rotation generator about z: (-y, x, 0)."""
        return np.stack([-S[1], S[0], np.zeros_like(S[0])])


def chart_for(model: Hamiltonian) -> CartesianChart | SpheroidalChart | IsotropicChart:
    """The chart a model's coordinates are written in."""
    if model.chart == "isotropic":
        return IsotropicChart(model.mass)
    if model.chart == "spherical":
        return SpheroidalChart(model.a)
    if model.kind == "spacetime":
        if model.dim != 4:
            raise ValueError(f"a spacetime model needs 4 coordinates (t, x, y, z), got {model.dim}")
        return CartesianChart(time_index=0)
    if model.dim != 3:
        raise ValueError(
            f"to render, a model needs coordinates (x, y, z) or (t, x, y, z); got {model.coords}"
        )
    return CartesianChart(time_index=None)

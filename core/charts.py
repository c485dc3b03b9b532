"""Coordinate charts: a model's coordinates <-> Cartesian positions and directions.

The renderer works in the model's *local Cartesian* frame (origin at the model's centre,
z along its axis). A chart maps those positions to the model's coordinates q and maps
coordinate velocities dq/ds back to Cartesian ones. Arrays are structure-of-arrays:
positions (3, N), directions (3, N).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .backend import array_module


class CartesianChart:
    """q = (x, y, z) [or (t, x, y, z) with a leading time]: the identity map."""

    name = "cartesian"
    polar_axis = False
    """Whether theta = Q[2] is a polar angle, singular on the axis (sin theta = 0)."""
    axis_hint = ""
    periodic: tuple[int, ...] = ()
    """Spatial coordinates (indices from the first spatial one) that wrap by 2π, whose
    finite differences are taken modulo 2π (core.tracing.starts): none here."""

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

    def coord_time(self, S: np.ndarray, D: np.ndarray) -> np.ndarray:
        """Coordinate-time component of Cartesian vectors D (the same time slices): 0."""
        return np.zeros_like(S[0])

    def axial_killing(self, S: np.ndarray) -> np.ndarray:
        """Spatial components of the rotation generator about z: (-y, x, 0)."""
        return np.stack([-S[1], S[0], np.zeros_like(S[0])])


class SpheroidalChart:
    """Boyer–Lindquist (r, theta, phi) with spin a: x = sqrt(r^2+a^2) sin(theta) cos(phi), ...

    a = 0 gives ordinary spherical coordinates. q = (t, r, theta, phi).
    """

    name = "spherical"
    polar_axis = True
    axis_hint = ""
    periodic: tuple[int, ...] = ()
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
        J = np.empty_like(r, shape=(r.shape[0], 3, 3))
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

    def coord_time(self, S: np.ndarray, D: np.ndarray) -> np.ndarray:
        """Coordinate-time component of Cartesian vectors D (the same time slices): 0."""
        return np.zeros_like(S[0])

    def axial_killing(self, S):
        """Components of d/dphi: (0, 0, 1)."""
        z = np.zeros_like(S[0])
        return np.stack([z, z, np.ones_like(z)])


class KerrBLChart:
    """The tracer's Kerr–Schild Cartesian frame <-> Boyer–Lindquist (s, theta, phi) of Kerr.

    s is the BL radius r in the tortoise-like form r = M + b cosh s, b = sqrt(M^2 - a^2)
    (ds = dr / sqrt(Delta): Delta = b^2 sinh^2 s; the horizon r+ is s = 0). The outgoing
    Kerr–Schild frame the renderer traces Kerr in (core.models.kerr_schild, outgoing) is
    x + i y = (r - i a) sin(theta) e^(i phî), z = r cos(theta), with phî = phi - Phi(r) and
    t̂ = t - T(r), where Phi = int a/Delta dr = (a/b) ln tanh(s/2) (0 at infinity) and
    T' = 2 M r / Delta (checked against the metrics in tests/core/test_kerr_split.py).
    q = (t, s, theta, phi); a = 0 gives Schwarzschild (b = M).
    """

    name = "kerr_bl"
    polar_axis = True
    axis_hint = (
        " with an implicit method such as gauss4 (Kerr's explicit split is traced in"
        " Boyer–Lindquist)"
    )
    """What to add to the polar-axis refusal's advice to use the Kerr–Schild chart."""
    offset = 1
    time_index = 0
    periodic = (2,)
    """The angles among the spatial coordinates (phi): their differences wrap modulo 2 pi."""

    def __init__(self, mass: float, a: float):
        self.mass, self.a = float(mass), float(a)
        self.b = float(np.sqrt(self.mass**2 - self.a**2))

    def radius(self, s: np.ndarray) -> np.ndarray:
        """BL (= Kerr–Schild) r of s."""
        return self.mass + self.b * np.cosh(s)

    def phi_shift(self, s: np.ndarray) -> np.ndarray:
        """Phi(s) = phi - phî, (a / b) ln tanh(s / 2); mirrored (|s|) for s < 0, the same r,
        where a step past the horizon lands (the capture test ends those rays)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return (self.a / self.b) * np.log(np.tanh(0.5 * np.abs(s)))

    def to_coords(self, X: np.ndarray) -> np.ndarray:
        """(s, theta, phi) of local Cartesian positions (3, N) (NaN inside the horizon)."""
        r, theta, psi = SpheroidalChart(self.a).to_coords(X)
        with np.errstate(invalid="ignore"):
            s = np.arccosh((r - self.mass) / self.b)
        # x = sqrt(r^2 + a^2) sin(theta) cos(psi) with psi = phî - atan(a / r)
        phi = psi + np.arctan2(self.a, r) + self.phi_shift(s)
        return np.stack([s, theta, phi])

    def _parts(self, S: np.ndarray):
        s, theta, phi = S
        r = self.radius(s)
        ph = phi - self.phi_shift(s)
        st, ct, sp, cp = np.sin(theta), np.cos(theta), np.sin(ph), np.cos(ph)
        return s, r, st, ct, sp, cp

    def to_cartesian(self, S: np.ndarray) -> np.ndarray:
        """Local Cartesian positions of (s, theta, phi) (3, N)."""
        _, r, st, ct, sp, cp = self._parts(S)
        a = self.a
        return np.stack([st * (r * cp + a * sp), st * (r * sp - a * cp), r * ct])

    def jacobian(self, S: np.ndarray) -> np.ndarray:
        """d(x, y, z)/d(s, theta, phi) as (N, 3, 3)."""
        s, r, st, ct, sp, cp = self._parts(S)
        a, b = self.a, self.b
        sh = np.sinh(s)
        J = np.empty_like(s, shape=(s.shape[0], 3, 3))
        d_phi = np.stack([-st * (r * sp - a * cp), st * (r * cp + a * sp), np.zeros_like(s)])
        d_r = np.stack([st * cp, st * sp, ct])
        with np.errstate(divide="ignore", invalid="ignore"):
            J[:, :, 0] = (d_r * (b * sh) - d_phi * (a / (b * sh))).T
        J[:, :, 1] = np.stack([ct * (r * cp + a * sp), ct * (r * sp - a * cp), -r * st]).T
        J[:, :, 2] = d_phi.T
        return J

    def coord_directions(self, S: np.ndarray, D: np.ndarray) -> np.ndarray:
        """(ds, dtheta, dphi) of Cartesian vectors D (3, N) at S (NaN where the chart is
        singular: on the axis, at the horizon)."""
        J = self.jacobian(S)
        ok = np.isfinite(J).all(axis=(1, 2)) & (np.abs(np.linalg.det(np.nan_to_num(J))) > 1e-300)
        J[~ok] = array_module(J).eye(3)
        out = np.linalg.solve(J, D.T[..., None])[..., 0].T
        out[:, ~ok] = np.nan
        return out

    def coord_time(self, S: np.ndarray, D: np.ndarray) -> np.ndarray:
        """dt of Cartesian vectors D at fixed Kerr–Schild time: dt = T'(r) dr, that is
        2 M r ds / (b sinh s)."""
        dS = self.coord_directions(S, D)
        r = self.radius(S[0])
        return 2.0 * self.mass * r * dS[0] / (self.b * np.sinh(S[0]))

    def cartesian_velocity(self, S: np.ndarray, dS: np.ndarray) -> np.ndarray:
        """Cartesian velocity (3, N) from (ds, dtheta, dphi)/dσ."""
        return np.einsum("nij,jn->in", self.jacobian(S), dS)

    def axial_killing(self, S: np.ndarray) -> np.ndarray:
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
    polar_axis = False
    axis_hint = ""
    periodic: tuple[int, ...] = ()
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

    def coord_time(self, S: np.ndarray, D: np.ndarray) -> np.ndarray:
        """Coordinate-time component of Cartesian vectors D (the same time slices): 0."""
        return np.zeros_like(S[0])

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


Chart = CartesianChart | SpheroidalChart | IsotropicChart | KerrBLChart


def chart_for(model: Any) -> Chart:
    """The chart a model (a core.models.Hamiltonian) has its coordinates written in: its
    own ``chart``."""
    return model.chart

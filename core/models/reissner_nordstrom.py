"""Reissner–Nordström: a charged, non-rotating black hole, in outgoing Kerr–Schild form.

With M = rg/2 and the charge Q as a length (G = c = 4πε0 = 1), |Q| < M, the metric is
Schwarzschild's with f(r) = 1 - rg/r + Q²/r². In Cartesian Kerr–Schild coordinates
(t, x, y, z), g^uv = η^uv - F l^u l^v with F = 1 - f = rg/r - Q²/r² and l = (-1, x/r, y/r,
z/r) (outgoing: regular on the past horizon, which rays traced backwards from a camera
cross; the same form as core.models.kerr_schild with a = 0 and rg/r replaced by F):

    H = 1/2 (-p_t² + |p|² - F (p_t + (x p_x + y p_y + z p_z)/r)²).

Horizons r± = M ± √(M² - Q²); photon sphere r_ph = (3M + √(9M² - 8Q²))/2; shadow (critical
impact parameter) b_c = r_ph / √f(r_ph). Q = 0 is Schwarzschild. It has no explicit split
and no disk (its circular orbits are not Kerr's): it is traced as written, by the default
implicit method, with the Poincaré time scale g = r.
"""

from __future__ import annotations

import math

import numpy as np

from .. import checks
from .expression import ExpressionHamiltonian


class ReissnerNordstrom(ExpressionHamiltonian):
    """A charged black hole of Schwarzschild radius rg and charge Q (|Q| < rg/2)."""

    kind = "spacetime"

    def __init__(self, rg: float, charge: float):
        rg = checks.check_positive("rg (Schwarzschild radius)", rg)
        charge = checks.check_range("charge Q", charge)
        if not abs(charge) < rg / 2:
            raise ValueError(
                f"Reissner–Nordström charge Q = {charge:g} must lie within |Q| < M = rg/2 = "
                f"{rg / 2:g} (at |Q| = M the hole is extremal, beyond it a naked singularity)"
            )
        super().__init__(
            "0.5*(-p_t**2 + p_x**2 + p_y**2 + p_z**2 - F*lp**2)",
            ("t", "x", "y", "z"),
            ("p_t", "p_x", "p_y", "p_z"),
            parameters={"rg": rg, "Q": charge},
            definitions=[
                ("r", "sqrt(x**2 + y**2 + z**2)"),
                ("F", "rg/r - Q**2/r**2"),
                ("lp", "p_t + (x*p_x + y*p_y + z*p_z)/r"),
            ],
            time_scale="sqrt(x**2 + y**2 + z**2)",
        )
        self.rg, self.a, self.charge = rg, 0.0, charge
        self.horizon = self.mass + math.sqrt(self.mass**2 - charge**2)

    def f(self, r: float) -> float:
        """f(r) = 1 - rg/r + Q²/r² (g_tt = -f in Schwarzschild-like coordinates)."""
        return 1.0 - self.rg / r + self.charge**2 / r**2

    @property
    def photon_sphere(self) -> float:
        """r_ph = (3M + √(9M² - 8Q²))/2: circular light orbits."""
        m = self.mass
        return 0.5 * (3.0 * m + math.sqrt(9.0 * m * m - 8.0 * self.charge**2))

    @property
    def shadow_radius(self) -> float:
        """b_c = r_ph / √f(r_ph): the impact parameter below which light falls in."""
        return self.photon_sphere / math.sqrt(self.f(self.photon_sphere))

    def radius_at(self, X: np.ndarray) -> np.ndarray:
        """r = |x| at local Cartesian positions X (3, N)."""
        return np.sqrt(np.einsum("ij,ij->j", X, X))

    def capture_test(self):
        """Rays inside the outer horizon (see captured_soa)."""
        return self.captured_soa

    def captured_soa(self, Q: np.ndarray) -> np.ndarray:
        """Rays inside the outer horizon, r < r+ (N,): traced backwards, they came out of it."""
        return np.sqrt(Q[1] ** 2 + Q[2] ** 2 + Q[3] ** 2) < self.horizon


def reissner_nordstrom(rg: float = 1.0, charge: float = 0.0) -> ReissnerNordstrom:
    """Reissner–Nordström black hole of Schwarzschild radius rg and charge Q (|Q| < rg/2)."""
    return ReissnerNordstrom(rg, charge)

"""Kerr–Newman: a charged, rotating black hole, in outgoing Kerr–Schild form.

With M = rg/2, spin length a = J/M and the charge Q as a length (G = c = 4πε0 = 1),
a² + Q² < M². In Cartesian Kerr–Schild coordinates (t, x, y, z) the metric is
g_uv = η_uv + F l_u l_v with

    F = r² (rg r - Q²) / (r⁴ + a² z²),
    l = (-1, (r x - a y)/(r² + a²), (r y + a x)/(r² + a²), z/r)   (outgoing),

where r is the spheroidal radius, x² + y² + z² = r² + a² (1 - z²/r²). The inverse is
g^uv = η^uv - F l^u l^v, so

    H = 1/2 (-p_t² + |p|² - F (l·p)²)

(Kerr's form, core.models.kerr_schild, with rg r replaced by rg r - Q²). Horizons
r± = M ± √(M² - a² - Q²). a = 0 is Reissner–Nordström, Q = 0 is Kerr. It has no explicit
split and no disk (its circular orbits are not Kerr's): it is traced as written, by the
default implicit method, with the Poincaré time scale g = r.
"""

from __future__ import annotations

import math

import numpy as np

from .. import checks
from .expression import ExpressionHamiltonian

_SPHEROIDAL = [
    ("rho2", "x**2 + y**2 + z**2 - a**2"),
    ("r2", "0.5*(rho2 + sqrt(rho2**2 + 4*a**2*z**2))"),
    ("r", "sqrt(r2)"),
]


class KerrNewman(ExpressionHamiltonian):
    """A charged rotating black hole: Schwarzschild radius rg, spin length a, charge Q."""

    kind = "spacetime"

    def __init__(self, rg: float, a: float, charge: float):
        rg = checks.check_positive("rg (Schwarzschild radius)", rg)
        a = checks.check_range("spin length a", a)
        charge = checks.check_range("charge Q", charge)
        mass = rg / 2
        if not a * a + charge * charge < mass * mass:
            raise ValueError(
                f"Kerr–Newman spin a = {a:g} and charge Q = {charge:g} must satisfy "
                f"a² + Q² < M² = (rg/2)² = {mass * mass:g} (beyond it: no horizon, a naked "
                "singularity)"
            )
        super().__init__(
            "0.5*(-p_t**2 + p_x**2 + p_y**2 + p_z**2 - F*lp**2)",
            ("t", "x", "y", "z"),
            ("p_t", "p_x", "p_y", "p_z"),
            parameters={"rg": rg, "a": a, "Q": charge},
            definitions=[
                *_SPHEROIDAL,
                ("ra2", "r2 + a**2"),
                ("F", "r2*(rg*r - Q**2)/(r2**2 + a**2*z**2)"),
                ("lp", "p_t + ((r*x - a*y)/ra2)*p_x + ((r*y + a*x)/ra2)*p_y + (z/r)*p_z"),
            ],
            time_scale="sqrt(0.5*(x**2 + y**2 + z**2 - a**2 + "
            "sqrt((x**2 + y**2 + z**2 - a**2)**2 + 4*a**2*z**2)))",
        )
        self.rg, self.a, self.charge = rg, a, charge
        self.horizon = mass + math.sqrt(mass * mass - a * a - charge * charge)

    def radius_at(self, X: np.ndarray) -> np.ndarray:
        """The spheroidal (Boyer–Lindquist) radius r at local Cartesian positions X (3, N)."""
        rho2 = np.einsum("ij,ij->j", X, X) - self.a**2
        return np.sqrt(0.5 * (rho2 + np.sqrt(rho2**2 + 4.0 * self.a**2 * X[2] ** 2)))

    def capture_test(self):
        """Rays inside the outer horizon (see captured_soa)."""
        return self.captured_soa

    def captured_soa(self, Q: np.ndarray) -> np.ndarray:
        """Rays inside the outer horizon, r < r+ (N,): traced backwards, they came out of it."""
        return self.radius_at(Q[1:4]) < self.horizon

    def critical_curve(self, inclination: float, count: int = 400) -> np.ndarray:
        """The shadow's edge seen from far away at ``inclination`` (radians from the spin
        axis): (2, K) celestial coordinates (α, β) in units of length, from the spherical
        photon orbits (Bardeen 1973 with Δ = r² - rg r + a² + Q²)."""
        m, a, q2 = self.mass, self.a, self.charge**2
        if a == 0.0:
            b = _charged_shadow_radius(m, q2)
            t = np.linspace(0.0, 2.0 * np.pi, count)
            return np.stack([b * np.cos(t), b * np.sin(t)])
        r = np.linspace(self.horizon * (1 + 1e-9), 4.0 * m, 200_000)
        delta = r * r - 2.0 * m * r + a * a + q2
        xi = (r * r + a * a - 2.0 * r * delta / (r - m)) / a
        eta = 4.0 * r * r * delta / (r - m) ** 2 - (xi - a) ** 2
        sin_i, cos_i = math.sin(inclination), math.cos(inclination)
        beta2 = eta + a * a * cos_i**2 - xi**2 * cos_i**2 / sin_i**2
        seen = beta2 >= 0.0
        alpha, beta = -xi[seen] / sin_i, np.sqrt(beta2[seen])
        return np.stack([np.concatenate([alpha, alpha[::-1]]), np.concatenate([beta, -beta[::-1]])])


def _charged_shadow_radius(m: float, q2: float) -> float:
    """b_c = r_ph / √f(r_ph) of Reissner–Nordström (the a = 0 limit)."""
    r_ph = 0.5 * (3.0 * m + math.sqrt(9.0 * m * m - 8.0 * q2))
    return r_ph / math.sqrt(1.0 - 2.0 * m / r_ph + q2 / r_ph**2)


def kerr_newman(rg: float = 1.0, a: float = 0.0, charge: float = 0.0) -> KerrNewman:
    """Kerr–Newman black hole of Schwarzschild radius rg, spin length a and charge Q
    (a² + Q² < (rg/2)²)."""
    return KerrNewman(rg, a, charge)

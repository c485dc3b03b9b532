"""Named spacetimes: Minkowski, Schwarzschild and Kerr (Boyer–Lindquist or Kerr–Schild)."""

from __future__ import annotations

import math

import numpy as np

from .. import checks
from ..charts import SpheroidalChart
from .base import Hamiltonian
from .kerr_schild import KerrSchild
from .metric import MetricHamiltonian
from .schwarzschild_optical import SchwarzschildOptical

_FLAT_CARTESIAN = [
    ["-1", "0", "0", "0"],
    ["0", "1", "0", "0"],
    ["0", "0", "1", "0"],
    ["0", "0", "0", "1"],
]


def _check_rg(rg: float) -> float:
    return checks.check_positive("rg (Schwarzschild radius)", rg)


def _check_spin(rg: float, a: float) -> float:
    a = checks.check_range("a (Kerr spin)", a)
    if abs(a) > rg / 2:
        raise ValueError(
            f"Kerr spin a = {a} is beyond extremal: need |a| <= rg/2 = M = {rg / 2}"
            f" (a/M = {2 * a / rg:.4g})"
        )
    return a


def kerr_horizon(rg: float, a: float) -> float:
    """Outer horizon radius r+ = M + sqrt(M^2 - a^2) of a Kerr hole (M = rg/2)."""
    m = rg / 2
    return m + math.sqrt(max(m * m - a * a, 0.0))


class Minkowski(MetricHamiltonian):
    """Flat spacetime in Cartesian (t, x, y, z) (seed Eq. 13): light is not bent."""

    flat = True

    def __init__(self) -> None:
        super().__init__(_FLAT_CARTESIAN, ("t", "x", "y", "z"), ("p_t", "p_x", "p_y", "p_z"))


class SphericalSpacetime(MetricHamiltonian):
    """A metric in (t, r, theta, phi) Boyer–Lindquist-like coordinates around a mass."""

    @property
    def chart(self) -> SpheroidalChart:
        """Boyer–Lindquist-like (t, r, theta, phi) of spin length a (spherical at a = 0)."""
        return SpheroidalChart(self.a)

    def __init__(self, inverse, rg, a, time_scale, definitions=(), horizon=0.0, kerr=False):
        coords = ("t", "r", "theta", "phi")
        super().__init__(
            inverse,
            coords,
            ("p_t", "p_r", "p_theta", "p_phi"),
            parameters={"rg": rg, "a": a},
            definitions=definitions,
            time_scale=time_scale,
        )
        self.rg, self.a = rg, a
        self.horizon = horizon
        self.kerr = kerr
        """Whether the metric is Kerr's of (rg, a) (Schwarzschild's at a = 0): only then
        may the tracer follow it in Kerr's other forms, and a disk orbit it."""

    def kerr_orbits(self) -> tuple[float, float] | None:
        """(M, a) for Kerr's metric around a mass (see Hamiltonian.kerr_orbits)."""
        return (self.mass, self.a) if self.kerr and self.rg > 0 else None

    def for_backward_tracing(self, explicit_split: bool = False) -> Hamiltonian:
        """Schwarzschild (a = 0, rg > 0): Kerr–Schild with a = 0, outgoing, which has the
        same r, theta, phi but no coordinate pole and no horizon singularity (the picture is
        the same); for an explicit splitting, the isotropic optical medium, which has a
        split (the same picture again). Otherwise (another metric written in these
        coordinates, Kerr in them) the model itself."""
        if self.kerr and self.a == 0.0 and self.rg > 0:
            if explicit_split:
                return SchwarzschildOptical(self.rg)
            return KerrSchild(self.rg, 0.0, kerr_horizon(self.rg, 0.0), outgoing=True)
        return self

    def radius_at(self, X: np.ndarray) -> np.ndarray:
        """Boyer–Lindquist r at local Cartesian positions X (3, N)."""
        return SpheroidalChart(self.a).to_coords(X)[0]

    def capture_test(self):
        """Rays at r < 1.01 r+ (see captured_soa)."""
        return self.captured_soa

    def captured_soa(self, Q) -> np.ndarray:
        """Rays at r < 1.01 r+ (N,): the Poincaré step only reaches r+ asymptotically here,
        and an ingoing photon that close to the horizon cannot come back out."""
        return Q[1] < 1.01 * self.horizon if self.horizon > 0 else np.zeros_like(Q[0], bool)

    def invariants_soa(self, Q, P):
        """E = -p_t, L = p_phi and the Carter constant (photons, mu = 0)."""
        if self.rg == 0.0:
            return {"p_t": P[0].copy(), "p_phi": P[3].copy()}
        cos2 = np.cos(Q[2]) ** 2
        sin2 = 1.0 - cos2
        carter = P[2] ** 2 + cos2 * (-(self.a**2) * P[0] ** 2 + P[3] ** 2 / sin2)
        return {"p_t": P[0].copy(), "p_phi": P[3].copy(), "carter": carter}


def minkowski(chart: str = "cartesian") -> MetricHamiltonian:
    """Flat spacetime: Cartesian (seed Eq. 13) or spherical (seed Eq. 14) coordinates."""
    if chart == "cartesian":
        return Minkowski()
    if chart == "spherical":
        inv = [
            ["-1", "0", "0", "0"],
            ["0", "1", "0", "0"],
            ["0", "0", "1/r**2", "0"],
            ["0", "0", "0", "1/(r**2*sin(theta)**2)"],
        ]
        return SphericalSpacetime(inv, 0.0, 0.0, time_scale=None)
    raise ValueError(f"unknown chart '{chart}' for minkowski (use 'cartesian' or 'spherical')")


def schwarzschild(rg: float = 1.0) -> SphericalSpacetime:
    """Schwarzschild black hole in (t, r, theta, phi) (seed Eq. 9/15, with the p_phi term)."""
    rg = _check_rg(rg)
    inv = [
        ["-1/(1 - rg/r)", "0", "0", "0"],
        ["0", "1 - rg/r", "0", "0"],
        ["0", "0", "1/r**2", "0"],
        ["0", "0", "0", "1/(r**2*sin(theta)**2)"],
    ]
    return SphericalSpacetime(inv, rg, 0.0, time_scale="r - rg", horizon=rg, kerr=True)


def kerr(
    rg: float = 1.0, a: float = 0.0, chart: str = "boyer_lindquist", outgoing: bool = False
) -> Hamiltonian:
    """Kerr black hole, spin length a = J/M with |a| <= M = rg/2 (seed Eq. 12).

    ``chart="boyer_lindquist"``: (t, r, theta, phi). ``chart="kerr_schild"``: Cartesian
    (t, x, y, z), horizon-penetrating, no coordinate pole (docs/design.md formula); ingoing
    (regular on the future horizon) unless ``outgoing=True`` (regular on the past one).
    """
    rg = _check_rg(rg)
    a = _check_spin(rg, a)
    horizon = kerr_horizon(rg, a)
    if chart == "boyer_lindquist":
        defs = [
            ("s2", "sin(theta)**2"),
            ("sigma", "r**2 + a**2*(1 - s2)"),
            ("delta", "r**2 - rg*r + a**2"),
            ("sd", "sigma*delta"),
        ]
        inv = [
            ["-((r**2 + a**2)**2 - a**2*delta*s2)/sd", "0", "0", "-rg*a*r/sd"],
            ["0", "delta/sigma", "0", "0"],
            ["0", "0", "1/sigma", "0"],
            ["-rg*a*r/sd", "0", "0", "(delta - a**2*s2)/(sd*s2)"],
        ]
        return SphericalSpacetime(
            inv,
            rg,
            a,
            time_scale="(r**2 - rg*r + a**2)/r",
            definitions=defs,
            horizon=horizon,
            kerr=True,
        )
    if chart == "kerr_schild":
        return KerrSchild(rg, a, horizon, outgoing)
    raise ValueError(f"unknown chart '{chart}' for kerr (use 'boyer_lindquist' or 'kerr_schild')")

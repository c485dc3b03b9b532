"""Schwarzschild as an optical medium, split explicitly.

In isotropic coordinates (ρ = |x|, r = ρ (1 + M/2ρ)²) the Schwarzschild metric is
conformally flat in space, and its light rays are those of the optical metric n² δ_ij with

    n(ρ) = (1 + M/2ρ)³ / (1 − M/2ρ)

in Cartesian coordinates: pole-free, no frame rotation per ray. With H = |p|²/(2n²) and
the Poincaré g = n², K = A(p) − B(q), A = |p|²/2 − H0, B = H0 (n² − 1) (K = 0 on the rays).
Fixed steps of K are uniform in ρ-length, where a step ∝ distance is wanted (the fine steps
belong near the hole). The logarithmic Hamiltonian (Mikkola & Tanikawa 1999; Preto &
Tremaine 1999)

    Λ = ln A(p) − ln B(q)

has the same rays on K = 0 (its flow is K's divided by A = B) and is still separable, each
part solved exactly: the drift q += t p / A(p) (p fixed), the kick p += t ∇ln(n² − 1)
(q fixed). On the rays dq/dσ = p / (H0 (n² − 1)): far away (n² − 1 ≈ 4M/ρ) a step covers
a length ∝ ρ, like the Kerr–Schild tracing's g = r; near the horizon (n → ∞) it shrinks
to zero, so rays close in on the horizon without crossing it and are captured at 1.01 r+.
"""

from __future__ import annotations

import math

import numpy as np

from .. import dual
from ..backend import asarray, is_array
from ..charts import IsotropicChart
from ..dual import DualRows
from ..integrators.splitting import SplitSystem
from .medium import Medium


def index_and_slope(u):
    """n = (1 + u)³ / (1 − u) and dn/du at u = M/2ρ (arrays, or core.dual Duals)."""
    return (1.0 + u) ** 3 / (1.0 - u), (1.0 + u) ** 2 * (4.0 - 2.0 * u) / (1.0 - u) ** 2


class SchwarzschildOptical(Medium):
    """Schwarzschild light rays as the isotropic optical medium n(ρ) (see the module)."""

    @property
    def chart(self) -> IsotropicChart:
        """Isotropic Cartesian (x, y, z) of Schwarzschild's mass (core.charts)."""
        return IsotropicChart(self.mass)

    def __init__(self, rg: float):
        rg = float(rg)
        if not (math.isfinite(rg) and rg > 0):
            raise ValueError(f"rg (Schwarzschild radius) must be a positive number, got {rg}")
        m = 0.5 * rg
        rho = "sqrt(x**2 + y**2 + z**2)"
        super().__init__(
            f"(1 + M/(2*{rho}))**3/(1 - M/(2*{rho}))", literal=False, parameters={"M": m}
        )
        self.rg, self.a, self.horizon = rg, 0.0, rg
        # the capture radius 1.01 r+ in isotropic ρ
        r_c = 1.01 * rg
        self._rho_capture = 0.5 * (r_c - m + math.sqrt(r_c * r_c - 2.0 * m * r_c))

    def index_gradient_soa(self, Q: np.ndarray):
        """n (N,) and ∇n (3, N), written out: u = M/2ρ, n = (1+u)³/(1−u)."""
        rho = np.sqrt(np.einsum("ij,ij->j", Q, Q))
        with np.errstate(all="ignore"):
            u = 0.5 * self.mass / rho
            n, dn_du = index_and_slope(u)
            grad = (dn_du * (-u / (rho * rho))) * Q
            n = np.where(~(u < 1.0), np.nan, n)
        return n, grad

    def killing_block_soa(self, S: np.ndarray):
        """(g_tt, g_tφ, g_φφ) (N,) of the isotropic Schwarzschild metric
        −A² dt² + B² |dx|² (A = (1 − u)/(1 + u), B = (1 + u)², u = M/2ρ) at isotropic
        positions S (3, N), on ξ_t and the rotation about z: (−A², 0, B² (x² + y²)). The
        rays' optical momentum p is the spatial part of −k/E (k the photon's covariant
        4-momentum), so p_t = 1 and p_φ = x p_y − y p_x (core/tracing/disklight.py)."""
        rho = np.sqrt(np.einsum("ij,ij->j", S, S))
        with np.errstate(all="ignore"):
            u = 0.5 * self.mass / rho
            A, B = (1.0 - u) / (1.0 + u), (1.0 + u) ** 2
        return -A * A, np.zeros_like(rho), B * B * (S[0] * S[0] + S[1] * S[1])

    @property
    def scales_time(self) -> bool:
        """The logarithmic split's steps scale with the distance from the mass."""
        return True

    @property
    def spherical(self) -> bool:
        """n depends on ρ alone, in Cartesian isotropic coordinates: rotations about the
        mass map rays to rays (see Hamiltonian.spherical)."""
        return True

    def kerr_orbits(self) -> tuple[float, float]:
        """(M, 0): Schwarzschild's metric (see Hamiltonian.kerr_orbits)."""
        return self.mass, 0.0

    def radius_at(self, X: np.ndarray) -> np.ndarray:
        """Schwarzschild r (the world's radius) at local Cartesian positions X (3, N)."""
        return np.sqrt(np.einsum("ij,ij->j", X, X))

    def captured_soa(self, Q: np.ndarray) -> np.ndarray:
        """Rays inside 1.01 r+ (isotropic ρ below its image), (N,)."""
        return np.einsum("ij,ij->j", Q, Q) < self._rho_capture**2

    def capture_test(self):
        """Q -> rays inside 1.01 r+."""
        return self.captured_soa

    def split_parts(self, H0=0.0, clocked: bool = False):
        """The logarithmic split Λ = ln A(p) − ln B(q) (the module); no clocked form (its
        parameter s would not be a function of q alone), so core.integrate with
        adaptive=True refuses the splittings for this model."""
        if clocked:
            return None
        return LogarithmicSplit(self, H0)


class LogarithmicSplit(SplitSystem):
    """Λ = ln(|p|²/2 − H0) − ln(H0 (n² − 1)) with its exact drift and kick flows."""

    separable = True
    tangents = True

    def __init__(self, model: SchwarzschildOptical, H0) -> None:
        self.model = model
        self.H0 = asarray(H0, dtype=np.float64)
        self.dim = 3

    def subset(self, keep) -> LogarithmicSplit:
        """The split for the rays keep (per-ray H0)."""
        return LogarithmicSplit(self.model, self.H0 if self.H0.ndim == 0 else self.H0[keep])

    def _force_factor(self, Q):
        """f with ∇ln(n² − 1) = f q (n radial: 2 n n'(ρ) / ((n² − 1) ρ)), (N,); NaN inside
        ρ = M/2. Written row by row with core.dual's functions: on rows carrying
        derivatives (core.dual.DualRows) it gives f's as well, f being a function of ρ²
        alone (its derivative is taken with one scalar seed, then chained)."""
        if is_array(Q):
            return self._radial_factor(np.einsum("ij,ij->j", Q, Q))
        rho2 = Q[0] * Q[0] + Q[1] * Q[1] + Q[2] * Q[2]
        if isinstance(rho2, dual.Dual):
            f = self._radial_factor(dual.Dual.variable(rho2.v, 0))
            return dual.Dual(f.v, {0: f.d[0] * rho2.d[0]})
        return self._radial_factor(rho2)

    def _radial_factor(self, rho2, with_slope: bool = False):
        """f of ``_force_factor`` at ρ² (an array, or a Dual); ``with_slope`` (arrays):
        (f, 2 df/dρ²). With u = M/2ρ, a = 1 + u, b = 1 − u (n = a³/b, n' = dn/du =
        2a²(2 − u)/b²: index_and_slope) and 1/ρ² = 4u²/M², f = −2 n n' u / ((n² − 1) ρ²)
        is rational in u; n² − 1 = (a³ − b)(a³ + b)/b² with a³ − b = u (4 + 3u + u²), so
        f = −(16/M²) u² a⁵ (2 − u) / (b w (a³ + b)), w = 4 + 3u + u², free of the
        cancellation in n² − 1 far away (u → 0), and df/dρ² = f (d ln f/du) du/dρ² with
        d ln f/du = 2/u + 5/a + 1/(b (2 − u)) − (3 + 2u)/w − (3a² − 1)/(a³ + b) and
        du/dρ² = −2u³/M²; NaN inside ρ = M/2."""
        m = self.model.mass
        with np.errstate(all="ignore"):
            u = (0.5 * m) / dual.sqrt(rho2)
            a, b, c = 1.0 + u, 1.0 - u, 2.0 - u
            a2 = a * a
            a3 = a2 * a
            w = 4.0 + u * (3.0 + u)
            rest = a3 + b
            u2 = u * u
            factor = (-16.0 / (m * m)) * u2 * (a3 * a2) * c / (b * w * rest)
            if with_slope:
                log_slope = 2.0 / u + 5.0 / a + 1.0 / (b * c)  # 1/b - 1/c = 1/(b c)
                log_slope -= (3.0 + 2.0 * u) / w + (3.0 * a2 - 1.0) / rest
                slope = factor * log_slope * ((-4.0 / (m * m)) * u2 * u)  # twice df/dρ²
        inside = dual.value_of(u) < 1.0
        if with_slope:
            return np.where(inside, factor, np.nan), slope
        return dual.where(inside, factor, np.nan)

    def _force(self, Q: np.ndarray) -> np.ndarray:
        """∇ln(n² − 1) = 2 n ∇n / (n² − 1), (3, N)."""
        return self._force_factor(Q) * Q

    def kick(self, Q, P, t) -> None:
        """Exact flow of −ln B over t (q fixed): p += t ∇ln(n² − 1). In place, row by row
        (arrays), or on core.dual.DualRows with its tangent map written out: c = t f(ρ²),
        dc = t 2 f'(ρ²) q·dq (2f' written out: ``_radial_factor``), dp += dc q + c dq."""
        if isinstance(Q, DualRows):
            q, dq = Q.value, Q.tangent
            f, slope2 = self._radial_factor(np.einsum("ij,ij->j", q, q), with_slope=True)
            c = t * f
            dc = (t * slope2) * np.einsum("ij,kij->kj", q, dq)
            P.tangent += c * dq
            P.tangent += dc[:, None, :] * q
            P.value += c * q
            return
        c = t * self._force_factor(Q)
        for i in range(3):
            P[i] += c * Q[i]

    def drift(self, Q, P, t) -> None:
        """Exact flow of ln A over t (p fixed): q += t p / A(p). In place, row by row
        (arrays), or on core.dual.DualRows with its tangent map written out: c = t / A,
        dc = -c (p·dp) / A, dq += dc p + c dp."""
        if isinstance(Q, DualRows):
            p, dp = P.value, P.tangent
            A = 0.5 * np.einsum("ij,ij->j", p, p) - self.H0
            c = t / A
            dc = (-c / A) * np.einsum("ij,kij->kj", p, dp)
            Q.tangent += c * dp
            Q.tangent += dc[:, None, :] * p
            Q.value += c * p
            return
        if is_array(P):
            c = t / (0.5 * np.einsum("ij,ij->j", P, P) - self.H0)
        else:  # rows of Duals
            c = t / (0.5 * (P[0] * P[0] + P[1] * P[1] + P[2] * P[2]) - self.H0)
        for i in range(3):
            Q[i] += c * P[i]

    def value_soa(self, Q: np.ndarray, P: np.ndarray) -> np.ndarray:
        """Λ(q, p), (N,)."""
        n, _ = self.model.index_gradient_soa(Q)
        with np.errstate(all="ignore"):
            return np.log(0.5 * np.einsum("ij,ij->j", P, P) - self.H0) - np.log(
                self.H0 * (n * n - 1.0)
            )

    def gradient_soa(self, Q: np.ndarray, P: np.ndarray, wrt: str = "qp"):
        """(∂Λ/∂q or None, ∂Λ/∂p or None), each (3, N)."""
        dq = -self._force(Q) if "q" in wrt else None
        dp = None
        if "p" in wrt:
            dp = P / (0.5 * np.einsum("ij,ij->j", P, P) - self.H0)
        return dq, dp

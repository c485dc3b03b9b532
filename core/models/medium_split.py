"""The explicit split of an optical medium in Poincaré time.

With the time transformation g(q) (ds = g dτ), K = g (H − H0) has the rays of H on the
level set H = H0. For the physical optical Hamiltonian H = |p|² / (2 n²) and g = n², and
for the seed's literal H = n |p|² / 2 and g = 1/n,

    K = |p|² / 2 − H0 w(q),    w = g = n² (physical) or 1/n (literal),

a kinetic part T(p) = |p|²/2 and a potential V(q) = −H0 w(q), each solved exactly:
the drift of T moves q by t p, the kick of V moves p by t H0 ∇w (q fixed). With the
parameter s as a fourth coordinate (``clocked``, momentum p_s = −H0):
K = |p|²/2 + p_s w(q), whose kick also advances s by t w, the ds = g dτ of the ray.
∇w comes from dual numbers over the user's n(x, y, z).
"""

from __future__ import annotations

import numpy as np

from ..backend import asarray
from ..integrators.splitting import SplitSystem


class OpticalSplit(SplitSystem):
    """K = |p|²/2 − H0 w(q) of a medium (see the module), with exact kick and drift flows."""

    nystrom = True  # T = |p|²/2; V = -p_s w(q) in the clocked form, p_s conserved

    def __init__(self, medium, H0, clocked: bool = False) -> None:
        self.medium = medium
        self.H0 = asarray(H0, dtype=np.float64)
        self.clocked = clocked
        self.dim = 4 if clocked else 3
        self.separable = not clocked  # clocked: V depends on p_s; its kick is still exact

    def subset(self, keep) -> OpticalSplit:
        """The split for the rays keep (per-ray H0)."""
        H0 = self.H0 if self.H0.ndim == 0 else self.H0[keep]
        return OpticalSplit(self.medium, H0, self.clocked)

    def _ps(self, P: np.ndarray):
        return P[3] if self.clocked else -self.H0

    def kick(self, Q: np.ndarray, P: np.ndarray, t) -> None:
        """Exact flow of the potential over t, in place: p -= t p_s ∇w (and s += t w)."""
        w, dw = self.medium.split_weight_soa(Q[:3])
        c = t * self._ps(P)
        P[:3] -= c * dw
        if self.clocked:
            Q[3] += t * w

    def drift(self, Q: np.ndarray, P: np.ndarray, t) -> None:
        """Exact flow of T = |p|²/2 over t, in place: q += t p."""
        Q[:3] += t * P[:3]

    def value_soa(self, Q: np.ndarray, P: np.ndarray) -> np.ndarray:
        """K(q, p), (N,)."""
        w, _ = self.medium.split_weight_soa(Q[:3], derivatives=False)
        return 0.5 * np.einsum("ij,ij->j", P[:3], P[:3]) + self._ps(P) * w

    def gradient_soa(self, Q: np.ndarray, P: np.ndarray, wrt: str = "qp"):
        """(∂K/∂q or None, ∂K/∂p or None), each (dim, N)."""
        dq = dp = None
        w, dw = self.medium.split_weight_soa(Q[:3], derivatives="q" in wrt)
        if "q" in wrt:
            dq = np.zeros_like(Q)
            dq[:3] = self._ps(P) * dw
        if "p" in wrt:
            dp = P.copy()
            if self.clocked:
                dp[3] = w
        return dq, dp

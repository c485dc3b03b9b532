"""Poincaré time transformation: adaptive steps with a symplectic method.

K(q, p) = g(q) (H(q, p) − H0) has the same rays as H on the level set H = H0, traversed
with ds = g(q) dτ: a fixed step dτ is a step g(q) dτ in s, small where g is small.
`Clocked` appends the parameter s as a coordinate (momentum p_s), so that s is integrated
by the same method and to the same order as the ray: with K = g (H + p_s) and
p_s = −H0, ds/dτ = ∂K/∂p_s = g.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ._common import restrict


class PoincareTransformed:
    """The Hamiltonian K = g(q) (H(q, p) − H0); H0 scalar or per ray (N,), see subset()."""

    separable = False

    def __init__(self, H: Any, H0: Any = 0.0) -> None:
        self.H = H
        self.H0 = np.asarray(H0, dtype=np.float64)
        self.dim = H.dim
        for name in ("coords", "momenta"):
            if hasattr(H, name):
                setattr(self, name, getattr(H, name))

    def subset(self, keep: np.ndarray) -> PoincareTransformed:
        """K for the rays keep (bool mask or index array) of the current batch."""
        if self.H0.ndim == 0 and not hasattr(self.H, "subset"):
            return self
        H0 = self.H0 if self.H0.ndim == 0 else self.H0[keep]
        return PoincareTransformed(restrict(self.H, keep), H0)

    def value_soa(self, Q: np.ndarray, P: np.ndarray) -> np.ndarray:
        """K(q, p), (N,)."""
        g, _ = self.H.time_scale_soa(Q)
        return g * (self.H.value_soa(Q, P) - self.H0)

    def value_gradient_soa(self, Q: np.ndarray, P: np.ndarray):
        """(K, ∂K/∂q = ∇g (H − H0) + g ∂H/∂q, ∂K/∂p = g ∂H/∂p)."""
        fused = getattr(self.H, "poincare_soa", None)
        if fused is not None:  # the model evaluates g with H (e.g. Kerr–Schild: g = r)
            return fused(Q, P, self.H0)
        g, dg = self.H.time_scale_soa(Q)
        Hv, dq, dp = self.H.value_gradient_soa(Q, P)
        dH = Hv - self.H0
        return g * dH, dg * dH + g * dq, g * dp

    def gradient_soa(self, Q: np.ndarray, P: np.ndarray, wrt: str = "qp"):
        """(∂K/∂q or None, ∂K/∂p or None), each (n, N)."""
        if wrt == "p":
            fused = getattr(self.H, "poincare_soa", None)
            if fused is not None:
                return None, fused(Q, P, self.H0, wrt="p")[2]
            g, _ = self.H.time_scale_soa(Q)
            _, dp = self.H.gradient_soa(Q, P, wrt="p")
            return None, g * dp
        _, dq, dp = self.value_gradient_soa(Q, P)
        return dq, (dp if "p" in wrt else None)

    def frozen_q(self, Q: np.ndarray) -> Any:
        """∂K/∂q at fixed Q for any momenta (the model's FrozenQ), or None if it has none."""
        frozen = getattr(self.H, "frozen_q", None)
        return None if frozen is None else frozen(Q, self.H0)

    def time_scale_soa(self, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """g = 1: K is already transformed."""
        return np.ones(Q.shape[1]), np.zeros_like(Q)


class Clocked:
    """H(q, p) + p_s on the extended coordinates (q, s), momenta (p, p_s): dim = H.dim + 1."""

    def __init__(self, H: Any) -> None:
        self.H = H
        self.dim = H.dim + 1
        self.separable = getattr(H, "separable", False)

    def subset(self, keep: np.ndarray) -> Clocked:
        """The clocked H for the rays keep."""
        return Clocked(restrict(self.H, keep))

    def value_soa(self, Q: np.ndarray, P: np.ndarray) -> np.ndarray:
        """H(q, p) + p_s."""
        return self.H.value_soa(Q[:-1], P[:-1]) + P[-1]

    def gradient_soa(self, Q: np.ndarray, P: np.ndarray, wrt: str = "qp"):
        """(∂/∂(q, s), ∂/∂(p, p_s)): a zero row for s, a row of ones for p_s."""
        dq, dp = self.H.gradient_soa(Q[:-1], P[:-1], wrt=wrt)
        return _extend(dq, 0.0), _extend(dp, 1.0)

    def value_gradient_soa(self, Q: np.ndarray, P: np.ndarray):
        """(H + p_s, ∂/∂(q, s), ∂/∂(p, p_s))."""
        Hv, dq, dp = self.H.value_gradient_soa(Q[:-1], P[:-1])
        return Hv + P[-1], _extend(dq, 0.0), _extend(dp, 1.0)

    def time_scale_soa(self, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """H's g(q), independent of s."""
        g, dg = self.H.time_scale_soa(Q[:-1])
        return g, _extend(dg, 0.0)


def _extend(a: np.ndarray | None, fill: float) -> np.ndarray | None:
    """a (n, N) with one more row filled with `fill`."""
    if a is None:
        return None
    out = np.empty((a.shape[0] + 1,) + a.shape[1:])
    out[:-1] = a
    out[-1] = fill
    return out

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

from ..backend import asarray
from .system import FrozenQ, Gradient, System, ValueGradient, as_system


class PoincareTransformed(System):
    """The Hamiltonian K = g(q) (H(q, p) − H0); H0 scalar or per ray (N,), see subset()."""

    separable = False

    def __init__(self, H: Any, H0: Any = 0.0) -> None:
        self.H = as_system(H)
        self.H0 = asarray(H0, dtype=np.float64)
        self.dim = self.H.dim

    def subset(self, keep: np.ndarray) -> PoincareTransformed:
        """K for the rays keep (bool mask or index array) of the current batch."""
        H0 = self.H0 if self.H0.ndim == 0 else self.H0[keep]
        return PoincareTransformed(self.H.subset(keep), H0)

    def value_soa(self, Q: np.ndarray, P: np.ndarray) -> np.ndarray:
        """K(q, p), (N,)."""
        g, _ = self.H.time_scale_soa(Q)
        return g * (self.H.value_soa(Q, P) - self.H0)

    def value_gradient_soa(self, Q: np.ndarray, P: np.ndarray) -> ValueGradient:
        """(K, ∂K/∂q = ∇g (H − H0) + g ∂H/∂q, ∂K/∂p = g ∂H/∂p): the model's poincare_soa
        (fused where the model evaluates g with H, e.g. Kerr–Schild: g = r)."""
        return self.H.poincare_soa(Q, P, self.H0)

    def gradient_soa(self, Q: np.ndarray, P: np.ndarray, wrt: str = "qp") -> Gradient:
        """(∂K/∂q or None, ∂K/∂p or None), each (n, N)."""
        if wrt == "p":
            return None, self.H.poincare_soa(Q, P, self.H0, wrt="p")[2]
        _, dq, dp = self.value_gradient_soa(Q, P)
        return dq, (dp if "p" in wrt else None)

    def frozen_q(self, Q: np.ndarray, H0: Any = None) -> FrozenQ | None:
        """∂K/∂q at fixed Q for any momenta (the model's FrozenQ), or None if it has none."""
        return self.H.frozen_q(Q, self.H0)

    def time_scale_soa(self, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """g = 1: K is already transformed."""
        return np.ones(Q.shape[1]), np.zeros_like(Q)

    def capture_test(self) -> Any:
        """The model's horizon test (positions are the model's)."""
        return self.H.capture_test()


class Clocked(System):
    """H(q, p) + p_s on the extended coordinates (q, s), momenta (p, p_s): dim = H.dim + 1."""

    def __init__(self, H: Any) -> None:
        self.H = as_system(H)
        self.dim = self.H.dim + 1
        self.separable = self.H.separable

    def subset(self, keep: np.ndarray) -> Clocked:
        """The clocked H for the rays keep."""
        return Clocked(self.H.subset(keep))

    def value_soa(self, Q: np.ndarray, P: np.ndarray) -> np.ndarray:
        """H(q, p) + p_s."""
        return self.H.value_soa(Q[:-1], P[:-1]) + P[-1]

    def gradient_soa(self, Q: np.ndarray, P: np.ndarray, wrt: str = "qp") -> Gradient:
        """(∂/∂(q, s), ∂/∂(p, p_s)): a zero row for s, a row of ones for p_s."""
        dq, dp = self.H.gradient_soa(Q[:-1], P[:-1], wrt=wrt)
        return _extend(dq, 0.0), _extend(dp, 1.0)

    def value_gradient_soa(self, Q: np.ndarray, P: np.ndarray) -> ValueGradient:
        """(H + p_s, ∂/∂(q, s), ∂/∂(p, p_s))."""
        Hv, dq, dp = self.H.value_gradient_soa(Q[:-1], P[:-1])
        return Hv + P[-1], _extend(dq, 0.0), _extend(dp, 1.0)

    def time_scale_soa(self, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """H's g(q), independent of s."""
        g, dg = self.H.time_scale_soa(Q[:-1])
        return g, _extend(dg, 0.0)  # type: ignore[return-value]


def _extend(a: np.ndarray | None, fill: float) -> np.ndarray | None:
    """a (n, N) with one more row filled with `fill`."""
    if a is None:
        return None
    out = np.empty((a.shape[0] + 1,) + a.shape[1:])
    out[:-1] = a
    out[-1] = fill
    return out

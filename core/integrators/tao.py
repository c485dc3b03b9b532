"""Tao's (2016) explicit symplectic integrator for non-separable H in extended phase space.

H̄(q, p, x, y) = H(q, y) + H(x, p) + ω ½ (|q − x|² + |p − y|²). The flows of the three terms
are exact and explicit: A = H(q, y) moves p and x, B = H(x, p) moves q and y, and ωH_C
rotates (q − x, p − y) by the angle 2ωδ. One tao2 step is A(δ/2) B(δ/2) C(δ) B(δ/2) A(δ/2).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ._common import Method, Pattern, State, as_soa, quiet
from .implicit import run_splitting


class Tao2(Method):
    """Tao's 2nd-order symmetric scheme. State (q, p, x, y); omega couples the two copies.

    omega sets how tightly the copies (q, y) and (x, p) are bound; the error constants grow
    with omega h, so keep omega h below ~0.3 (a larger omega binds better over long runs).
    """

    name, order, symplectic, explicit = "tao2", 2, True, True
    error_constant = None  # with the default binding it does not follow rays around a mass
    follows_time_scale = False
    _pattern: Pattern = (("A", 0.5), ("B", 0.5), ("C", 1.0), ("B", 0.5), ("A", 0.5))

    def __init__(self, omega: float = 5.0) -> None:
        super().__init__(omega=omega)
        self.omega = float(omega)

    def init(self, H: Any, Q: np.ndarray, P: np.ndarray) -> State:
        """(q, p, x, y) with the copies x = q, y = p."""
        Q, P = as_soa(Q), as_soa(P)
        return Q, P, Q.copy(), P.copy()

    def pattern(self, H: Any) -> Pattern:
        """The splitting as (flow, coefficient) pairs (compositions merge neighbouring flows)."""
        return self._pattern

    def apply(self, kind: str, H: Any, state: State, ch: Any) -> None:
        """Advance state in place by the exact flow `kind` ("A", "B" or "C") over ch."""
        Q, P, X, Y = state
        if kind == "A":
            dq, dp = H.gradient_soa(Q, Y)
            P -= ch * dq
            X += ch * dp
        elif kind == "B":
            dq, dp = H.gradient_soa(X, P)
            Q += ch * dp
            Y -= ch * dq
        else:
            # rotate (u, v) = (q - x, p - y) by 2 omega ch; q + x and p + y are unchanged:
            # q += du, x -= du, p += dv, y -= dv with du = a u + b v, dv = a v - b u
            angle = 2.0 * self.omega * ch
            if np.ndim(angle):
                a, b = 0.5 * (np.cos(angle) - 1.0), 0.5 * np.sin(angle)
            else:
                a, b = 0.5 * (math.cos(angle) - 1.0), 0.5 * math.sin(angle)
            u, v = Q - X, P - Y
            du = a * u
            du += b * v
            v *= a
            v -= b * u
            Q += du
            X -= du
            P += v
            Y -= v

    @quiet
    def step(self, H: Any, state: State, h: Any) -> tuple[State, np.ndarray]:
        """One explicit step (four gradient evaluations)."""
        return run_splitting(self, H, state, self._pattern, h)

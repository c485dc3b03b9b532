"""Symplectic Euler, Störmer–Verlet, implicit midpoint and Gauss–Legendre 4.

Symplectic Euler and Störmer–Verlet are explicit for separable H = T(p) + V(q) (kick/drift
splitting) and implicit in one half otherwise; the midpoint and Gauss rules are always
implicit. Implicit stages go through `_solve.solve` (per-ray fixed point, Newton fallback).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ._common import Method, State, finite_rays, flow, quiet, restrict, take
from ._solve import SolverOptions, solve

Pattern = tuple[tuple[str, float], ...]


class _Implicit(Method):
    """A method with implicit stages: options tol, max_iter, max_newton."""

    def __init__(self, tol: float = 1e-14, max_iter: int = 50, max_newton: int = 12) -> None:
        super().__init__(tol=tol, max_iter=max_iter, max_newton=max_newton)
        self.solver = SolverOptions(tol=tol, max_iter=max_iter, max_newton=max_newton)


class _KickDrift(_Implicit):
    """Exact flows of the two halves of a separable H: kick ("K", by V) and drift ("D", by T)."""

    def pattern(self, H: Any) -> Pattern | None:
        """The splitting as (flow, coefficient) pairs when H is separable, else None."""
        return self._pattern if getattr(H, "separable", False) else None

    def apply(self, kind: str, H: Any, state: State, ch: Any) -> None:
        """Advance state in place by the exact flow `kind` over the step ch."""
        Q, P = state
        if kind == "K":
            dq, _ = H.gradient_soa(Q, P, wrt="q")
            P -= ch * dq
        else:
            _, dp = H.gradient_soa(Q, P, wrt="p")
            Q += ch * dp


def run_splitting(method: Any, H: Any, state: State, seq: Pattern,
                  h: Any) -> tuple[State, np.ndarray]:
    """Apply the exact sub-flows seq = ((kind, c), ...) with steps c*h to a copy of state."""
    state = tuple(a.copy() for a in state)
    for kind, c in seq:
        method.apply(kind, H, state, c * h)
    return state, finite_rays(*state)


def implicit_momentum(H: Any, Q: np.ndarray, P: np.ndarray, h: Any,
                      opts: SolverOptions) -> tuple[np.ndarray, np.ndarray]:
    """Solve P1 = P - h dH/dq(Q, P1) per ray; -> (P1, converged)."""

    def phi(W, idx):
        dq, _ = restrict(H, idx).gradient_soa(take(Q, idx), take(P, idx) + W, wrt="q")
        return dq * -take(h, idx)

    dq0, _ = H.gradient_soa(Q, P, wrt="q")
    W, ok = solve(phi, -h * dq0, 1.0 + np.abs(P), opts)
    return P + W, ok


def implicit_position(H: Any, Q: np.ndarray, P: np.ndarray, h: Any,
                      opts: SolverOptions) -> tuple[np.ndarray, np.ndarray]:
    """Solve Q1 = Q + h/2 (dH/dp(Q, P) + dH/dp(Q1, P)) per ray; -> (Q1, converged)."""
    _, a = H.gradient_soa(Q, P, wrt="p")
    half = 0.5 * h

    def phi(W, idx):
        _, dp = restrict(H, idx).gradient_soa(take(Q, idx) + W, take(P, idx), wrt="p")
        out = dp + take(a, idx)
        out *= take(half, idx)
        return out

    W, ok = solve(phi, h * a, 1.0 + np.abs(Q), opts)
    return Q + W, ok


class SymplecticEuler(_KickDrift):
    """Symplectic Euler (seed Eq. 11): p1 = p - h H_q(q, p1), q1 = q + h H_p(q, p1). Order 1."""

    name, order, symplectic = "symplectic_euler", 1, True
    _pattern: Pattern = (("K", 1.0), ("D", 1.0))

    @quiet
    def step(self, H: Any, state: State, h: Any) -> tuple[State, np.ndarray]:
        """One step; explicit when H is separable."""
        if getattr(H, "separable", False):
            return run_splitting(self, H, state, self._pattern, h)
        Q, P = state
        P1, ok = implicit_momentum(H, Q, P, h, self.solver)
        _, dp = H.gradient_soa(Q, P1, wrt="p")
        Q1 = Q + h * dp
        return (Q1, P1), ok & finite_rays(Q1, P1)


class StormerVerlet(_KickDrift):
    """Störmer–Verlet; generalized (implicit) Störmer–Verlet for non-separable H. Order 2."""

    name, order, symplectic = "stormer_verlet", 2, True
    _pattern: Pattern = (("K", 0.5), ("D", 1.0), ("K", 0.5))

    @quiet
    def step(self, H: Any, state: State, h: Any) -> tuple[State, np.ndarray]:
        """One step: kick-drift-kick when H is separable, else the generalized scheme."""
        if getattr(H, "separable", False):
            return run_splitting(self, H, state, self._pattern, h)
        Q, P = state
        half = 0.5 * h
        Ph, ok = implicit_momentum(H, Q, P, half, self.solver)
        Q1, ok2 = implicit_position(H, Q, Ph, h, self.solver)
        dq, _ = H.gradient_soa(Q1, Ph, wrt="q")
        P1 = Ph - half * dq
        return (Q1, P1), ok & ok2 & finite_rays(Q1, P1)


class ImplicitMidpoint(_Implicit):
    """Implicit midpoint rule z1 = z0 + h f((z0 + z1)/2). Order 2, symmetric, symplectic."""

    name, order, symplectic = "implicit_midpoint", 2, True

    @quiet
    def step(self, H: Any, state: State, h: Any) -> tuple[State, np.ndarray]:
        """One step; W = z_mid - z0 solved per ray."""
        Z0 = np.concatenate(state)
        half = 0.5 * h

        def phi(W, idx):
            f = flow(restrict(H, idx), take(Z0, idx) + W)
            f *= take(half, idx)
            return f

        W, ok = solve(phi, half * flow(H, Z0), 1.0 + np.abs(Z0), self.solver)
        Z1 = Z0 + h * flow(H, Z0 + W)
        n = Z0.shape[0] // 2
        return (Z1[:n], Z1[n:]), ok & finite_rays(Z1)


_S3 = np.sqrt(3.0)
GAUSS4_A = np.array([[0.25, 0.25 - _S3 / 6.0], [0.25 + _S3 / 6.0, 0.25]])
GAUSS4_B = np.array([0.5, 0.5])
GAUSS4_C = np.array([0.5 - _S3 / 6.0, 0.5 + _S3 / 6.0])


class Gauss4(_Implicit):
    """2-stage Gauss–Legendre collocation. Order 4, symmetric, symplectic."""

    name, order, symplectic = "gauss4", 4, True

    @staticmethod
    def _stage_flows(H: Any, Z0: np.ndarray, W: np.ndarray, idx: Any) -> np.ndarray:
        """(2, 2n, M): f at both stages Z_i = Z0 + W_i, in one gradient call on 2M rays."""
        m2, M = Z0.shape[0], W.shape[1]
        Zs = np.concatenate((Z0 + W[:m2], Z0 + W[m2:]), axis=1)
        rays = np.tile(np.arange(M) if idx is None else idx, 2)
        f = flow(restrict(H, rays), Zs)
        return f.reshape(m2, 2, M).transpose(1, 0, 2)

    @quiet
    def step(self, H: Any, state: State, h: Any) -> tuple[State, np.ndarray]:
        """One step; the stage increments W_i = Z_i - z0 (4n unknowns) solved per ray."""
        Z0 = np.concatenate(state)
        A = GAUSS4_A

        def phi(W, idx):
            F = self._stage_flows(H, take(Z0, idx), W, idx)
            hh = take(h, idx)
            return np.concatenate(((A[0, 0] * F[0] + A[0, 1] * F[1]) * hh,
                                   (A[1, 0] * F[0] + A[1, 1] * F[1]) * hh))

        f0 = h * flow(H, Z0)
        W0 = np.concatenate((GAUSS4_C[0] * f0, GAUSS4_C[1] * f0))
        W, ok = solve(phi, W0, np.tile(1.0 + np.abs(Z0), (2, 1)), self.solver)
        F = self._stage_flows(H, Z0, W, None)
        Z1 = Z0 + (GAUSS4_B[0] * F[0] + GAUSS4_B[1] * F[1]) * h
        n = Z0.shape[0] // 2
        return (Z1[:n], Z1[n:]), ok & finite_rays(Z1)

"""Symplectic Euler, Störmer–Verlet, implicit midpoint and Gauss–Legendre 4.

Symplectic Euler and Störmer–Verlet are explicit for separable H = T(p) + V(q) (kick/drift
splitting) and implicit in one half otherwise; the midpoint and Gauss rules are always
implicit. Implicit stages go through `_solve.solve` (per-ray fixed point, Newton fallback).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ._common import (
    Method,
    Pattern,
    PerRay,
    State,
    as_soa,
    finite_rays,
    flow,
    gradient_drift,
    gradient_kick,
    quiet,
    restrict,
    take,
)
from ._solve import SolverOptions, solve
from .system import FrozenQ, as_system


class _Implicit(Method):
    """A method with implicit stages: options tol, max_iter, max_newton."""

    def __init__(self, tol: float = 1e-14, max_iter: int = 50, max_newton: int = 12) -> None:
        super().__init__(tol=tol, max_iter=max_iter, max_newton=max_newton)
        self.solver = SolverOptions(tol=tol, max_iter=max_iter, max_newton=max_newton)


class _KickDrift(_Implicit):
    """Exact flows of the two halves of a separable H: kick ("K", by V) and drift ("D", by T)."""

    _pattern: Pattern

    def pattern(self, H: Any) -> Pattern | None:
        """The splitting as (flow, coefficient) pairs when H is separable, else None."""
        return self._pattern if H.separable else None

    def apply(self, kind: str, H: Any, state: State, ch: Any) -> None:
        """Advance state in place by the exact flow `kind` over the step ch."""
        Q, P = state
        (gradient_kick if kind == "K" else gradient_drift)(H, Q, P, ch)


def run_splitting(
    method: Method, H: Any, state: State, seq: Pattern, h: Any
) -> tuple[State, np.ndarray]:
    """Apply the exact sub-flows seq = ((kind, c), ...) with steps c*h to a copy of state."""
    state = tuple(a.copy() for a in state)
    for kind, c in seq:
        method.apply(kind, H, state, c * h)
    return state, finite_rays(*state)


def implicit_momentum(
    H: Any, Q: np.ndarray, P: np.ndarray, h: Any, opts: SolverOptions, frozen: Any = None
) -> tuple[np.ndarray, np.ndarray]:
    """Solve P1 = P - h dH/dq(Q, P1) per ray; -> (P1, converged).

    Q is fixed during the solve: where H has a FrozenQ (``H.frozen_q(Q)``, or ``frozen``
    given), its q-dependence is evaluated once and each iterate costs products in p only.
    """
    if frozen is None:
        frozen = frozen_q(H, Q)
    if frozen is not None:
        per_ray = PerRay(frozen, P, -h)

        def phi(W, idx):
            F, Ps, minus_h = per_ray(idx)
            dq = F.grad_q(Ps + W)
            dq *= minus_h
            return dq

        dq0 = frozen.grad_q(P)
    else:
        per_ray = PerRay(H, Q, P, -h)

        def phi(W, idx):
            Hs, Qs, Ps, minus_h = per_ray(idx)
            dq, _ = Hs.gradient_soa(Qs, Ps + W, wrt="q")
            dq *= minus_h
            return dq

        dq0, _ = H.gradient_soa(Q, P, wrt="q")
    W, ok = solve(phi, -h * dq0, 1.0 + np.abs(P), opts)
    return P + W, ok


def frozen_q(H: Any, Q: np.ndarray) -> FrozenQ | None:
    """H's FrozenQ at Q (dH/dq for any momenta at fixed Q), or None if H has none."""
    return as_system(H).frozen_q(Q)


def implicit_position(
    H: Any, Q: np.ndarray, P: np.ndarray, h: Any, opts: SolverOptions
) -> tuple[np.ndarray, np.ndarray]:
    """Solve Q1 = Q + h/2 (dH/dp(Q, P) + dH/dp(Q1, P)) per ray; -> (Q1, converged)."""
    _, a = H.gradient_soa(Q, P, wrt="p")
    per_ray = PerRay(H, Q, P, a, 0.5 * h)

    def phi(W, idx):
        Hs, Qs, Ps, as_, half = per_ray(idx)
        _, dp = Hs.gradient_soa(Qs + W, Ps, wrt="p")
        dp += as_
        dp *= half
        return dp

    W, ok = solve(phi, h * a, 1.0 + np.abs(Q), opts)
    return Q + W, ok


class SymplecticEuler(_KickDrift):
    """Symplectic Euler (seed Eq. 11): p1 = p - h H_q(q, p1), q1 = q + h H_p(q, p1). Order 1."""

    name, order, symplectic = "symplectic_euler", 1, True
    error_constant = 0.3
    _pattern: Pattern = (("K", 1.0), ("D", 1.0))

    @quiet
    def step(self, H: Any, state: State, h: Any) -> tuple[State, np.ndarray]:
        """One step; explicit when H is separable."""
        if H.separable:
            return run_splitting(self, H, state, self._pattern, h)
        Q, P = state
        P1, ok = implicit_momentum(H, Q, P, h, self.solver)
        _, dp = H.gradient_soa(Q, P1, wrt="p")
        Q1 = Q + h * dp
        return (Q1, P1), ok & finite_rays(Q1, P1)


class StormerVerlet(_KickDrift):
    """Störmer–Verlet; generalized (implicit) Störmer–Verlet for non-separable H. Order 2."""

    name, order, symplectic = "stormer_verlet", 2, True
    error_constant = 0.11
    _pattern: Pattern = (("K", 0.5), ("D", 1.0), ("K", 0.5))

    @quiet
    def step(self, H: Any, state: State, h: Any) -> tuple[State, np.ndarray]:
        """One step: kick-drift-kick when H is separable, else the generalized scheme."""
        if H.separable:
            return run_splitting(self, H, state, self._pattern, h)
        return self.steps(H, state, (h,))

    @quiet
    def steps(self, H: Any, state: State, hs: Any) -> tuple[State, np.ndarray]:
        """Consecutive generalized steps of sizes hs (a composition's substeps).

        A step's last half kick and the next step's first one are both at the same
        positions, so H's FrozenQ there (when it has one) serves both.
        """
        Q, P = state
        frozen = frozen_q(H, Q)
        ok = np.ones_like(Q[0], dtype=bool)
        for h in hs:
            half = 0.5 * h
            Ph, ok1 = implicit_momentum(H, Q, P, half, self.solver, frozen)
            Q, ok2 = implicit_position(H, Q, Ph, h, self.solver)
            frozen = frozen_q(H, Q)
            dq = frozen.grad_q(Ph) if frozen is not None else H.gradient_soa(Q, Ph, wrt="q")[0]
            P = Ph - half * dq
            ok &= ok1 & ok2
        return (Q, P), ok & finite_rays(Q, P)


class ImplicitMidpoint(_Implicit):
    """Implicit midpoint rule z1 = z0 + h f((z0 + z1)/2). Order 2, symmetric, symplectic."""

    name, order, symplectic = "implicit_midpoint", 2, True
    error_constant = 0.07

    @quiet
    def step(self, H: Any, state: State, h: Any) -> tuple[State, np.ndarray]:
        """One step; W = z_mid - z0 solved per ray."""
        Z0 = np.concatenate(state)
        half = 0.5 * h
        per_ray = PerRay(H, Z0, half)

        def phi(W, idx):
            Hs, Z0s, halfs = per_ray(idx)
            f = flow(Hs, Z0s + W)
            f *= halfs
            return f

        W, ok = solve(phi, half * flow(H, Z0), 1.0 + np.abs(Z0), self.solver)
        Z1 = Z0 + h * flow(H, Z0 + W)
        n = Z0.shape[0] // 2
        return (Z1[:n], Z1[n:]), ok & finite_rays(Z1)


_S3 = np.sqrt(3.0)
GAUSS4_A = np.array([[0.25, 0.25 - _S3 / 6.0], [0.25 + _S3 / 6.0, 0.25]])
GAUSS4_B = np.array([0.5, 0.5])
GAUSS4_C = np.array([0.5 - _S3 / 6.0, 0.5 + _S3 / 6.0])
GAUSS4_D = GAUSS4_B @ np.linalg.inv(GAUSS4_A)  # z1 = z0 + sum d_i W_i = (-sqrt 3, sqrt 3)
# the stage increments W_i = u(c_i h) - z0 of the collocation polynomial u(t) = z0 + a t + b t^2
# give (a h, b h^2) = _GAUSS4_FIT @ (W_1, W_2)
_GAUSS4_FIT = np.linalg.inv(np.array([[c, c * c] for c in GAUSS4_C]))


class Gauss4(_Implicit):
    """2-stage Gauss–Legendre collocation. Order 4, symmetric, symplectic.

    State (q, p, Y): Y (4n, N) holds the last step's collocation polynomial at its end,
    velocity u' and half its second derivative (NaN before the first step). The next
    step's stages are predicted from it to O(h^3) (Hairer, Lubich & Wanner, GNI VIII.6.1),
    which saves fixed-point iterations and the evaluation of f at the start point.
    """

    name, order, symplectic = "gauss4", 4, True
    error_constant = 0.01

    def init(self, H: Any, Q: np.ndarray, P: np.ndarray) -> State:
        """(q, p, Y) with no polynomial yet (Y NaN)."""
        Q, P = as_soa(Q), as_soa(P)
        return Q, P, np.full_like(Q, np.nan, shape=(2 * (Q.shape[0] + P.shape[0]),) + Q.shape[1:])

    @staticmethod
    def _stage_flows(H: Any, Z0: np.ndarray, W: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """f at both stages Z_i = Z0 + W_i (each (2n, M))."""
        m2 = Z0.shape[0]
        return flow(H, Z0 + W[:m2]), flow(H, Z0 + W[m2:])

    @staticmethod
    def _predict(H: Any, Z0: np.ndarray, Y: np.ndarray, h: Any) -> np.ndarray:
        """Stage increments (4n, M) from the last polynomial; f(z0) where there is none."""
        m2 = Z0.shape[0]
        velocity, curvature = Y[:m2], Y[m2:]
        W0 = np.empty_like(Z0, shape=(2 * m2,) + Z0.shape[1:])
        for i, rows in ((0, slice(0, m2)), (1, slice(m2, None))):
            ch = GAUSS4_C[i] * h
            np.multiply(velocity, ch, out=W0[rows])
            W0[rows] += curvature * (ch * ch)
        fresh = np.flatnonzero(~np.isfinite(Y[0]))
        if fresh.size:
            hf = take(h, fresh) * flow(restrict(H, fresh), Z0[:, fresh])
            W0[:m2, fresh] = GAUSS4_C[0] * hf
            W0[m2:, fresh] = GAUSS4_C[1] * hf
        return W0

    @quiet
    def step(self, H: Any, state: State, h: Any) -> tuple[State, np.ndarray]:
        """One step; the stage increments W_i = Z_i - z0 (4n unknowns) solved per ray."""
        Q, P, Y = state
        Z0 = np.concatenate((Q, P))
        m2 = Z0.shape[0]
        A = GAUSS4_A
        per_ray = PerRay(H, Z0, h)

        def phi(W, idx):
            Hs, Z0s, hh = per_ray(idx)
            F0, F1 = self._stage_flows(Hs, Z0s, W)
            out = np.empty_like(W)
            for i, rows in ((0, slice(0, m2)), (1, slice(m2, None))):
                np.multiply(F0, A[i, 0], out=out[rows])
                out[rows] += A[i, 1] * F1
            out *= hh
            return out

        W0 = self._predict(H, Z0, Y, h)
        W, ok = solve(phi, W0, np.tile(1.0 + np.abs(Z0), (2, 1)), self.solver)
        W1, W2 = W[:m2], W[m2:]
        Z1 = Z0 + GAUSS4_D[0] * W1 + GAUSS4_D[1] * W2  # = z0 + h sum b_i f(Z_i) at the solution
        fit = _GAUSS4_FIT
        ah = fit[0, 0] * W1 + fit[0, 1] * W2  # a h
        bh2 = fit[1, 0] * W1 + fit[1, 1] * W2  # b h^2
        Y1 = np.concatenate(((ah + 2.0 * bh2) / h, bh2 / (h * h)))  # u'(h), b
        ok &= finite_rays(Z1)
        Y1[:, ~ok] = np.nan
        n = m2 // 2
        return (Z1[:n], Z1[n:], Y1), ok

"""Per-ray solver of the implicit stage equations W = phi(W): fixed point, then Newton.

W is (k, N): k unknowns per ray, rays on the last axis. `phi(W, idx)` evaluates the map for
the rays idx (an integer index array into the batch, possibly with repeats) or, with
idx None, for the whole batch. Only rays that have not converged keep iterating.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..backend import array_module

Phi = Callable[[np.ndarray, "np.ndarray | None"], np.ndarray]

_EPS = np.finfo(np.float64).eps
_FD_STEP = _EPS ** (1.0 / 3.0)  # central differences: truncation ~ round-off


@dataclass(frozen=True)
class SolverOptions:
    """Tolerances of the implicit solves.

    tol: per-ray bound on the error of W, measured as max_i |δW_i| / scale_i with
    scale = 1 + |state| (relative for large coordinates, absolute below 1). The fixed-point
    error is estimated from the increments as θ/(1-θ) |ΔW| with the observed contraction
    θ (Hairer, Lubich & Wanner, GNI VIII.6). max_iter: fixed-point iterations; a ray moves
    to Newton's method earlier when its contraction predicts more iterations than a Newton
    solve costs (or diverges). max_newton: Newton iterations (finite-difference Jacobian).
    """

    tol: float = 1e-14
    max_iter: int = 50
    max_newton: int = 12


def _increment(new: np.ndarray, old: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """(M,) scaled max-norm of new - old per ray (one temporary: big ones are costly)."""
    d = np.subtract(new, old)
    np.abs(d, out=d)
    d /= scale
    return d.max(axis=0)


def _assess(
    err: np.ndarray, prev: np.ndarray | None, tol: float, newton_cost: float
) -> tuple[np.ndarray, np.ndarray]:
    """(converged, hand over to Newton) per ray from this and the previous increment."""
    if prev is None:
        return err <= tol, ~np.isfinite(err)
    theta = err / prev
    contracting = theta < 1.0
    done = (err <= tol) | (contracting & (err * theta <= tol * (1.0 - theta)))
    # fixed-point iterations still needed: log(tol / err) / log(theta)
    remaining = np.log(tol / err) / np.log(np.where(contracting, theta, 0.5))
    stuck = ~done & (~contracting | ~np.isfinite(err) | (remaining > newton_cost))
    return done, stuck


_NARROW = 0.5
"""The solver narrows its batch to the rays still iterating once at least this share of it
has settled (converged or handed to Newton). Until then settled rays are evaluated along
(cheaper than re-indexing every per-ray input at each iteration) but keep their iterate,
so every ray gets exactly the iterations it would get on its own."""


def solve(
    phi: Phi, W0: np.ndarray, scale: np.ndarray, opts: SolverOptions
) -> tuple[np.ndarray, np.ndarray]:
    """Solve W = phi(W) per ray from the predictor W0; -> (W (k, N), converged (N,) bool)."""
    k, N = W0.shape
    # ~3 Newton iterations, each 2k + 1 phi evaluations (the finite-difference Jacobian) and
    # a batched linear solve, counted as much again: at 3 (2k + 1) two thirds of the rays of
    # a cheap H (Volterra, h = 0.25) went to Newton every step, 1.7x slower than iterating
    newton_cost = 6.0 * (2 * k + 1)
    xp = array_module(W0)
    ok = xp.zeros(N, dtype=bool)
    to_newton = xp.zeros(N, dtype=bool)
    W_all: Any = None  # every ray's iterate, once the batch was narrowed
    ids, W, sc, prev = None, W0, scale, None
    active = xp.ones(N, dtype=bool)  # rays of the current batch still iterating
    for _ in range(opts.max_iter):
        Wn = phi(W, ids)
        if not active.all():
            np.copyto(Wn, W, where=~active)  # settled rays keep their iterate
        err = _increment(Wn, W, sc)
        W = Wn
        done, stuck = _assess(err, prev, opts.tol, newton_cost)
        done &= active
        stuck &= active & ~done
        ok[done if ids is None else ids[done]] = True
        to_newton[stuck if ids is None else ids[stuck]] = True
        active &= ~(done | stuck)
        n_active = np.count_nonzero(active)
        if n_active == 0:
            break
        if n_active <= _NARROW * active.size:
            if ids is None:
                W_all, ids = W, np.flatnonzero(active)
            else:
                W_all[:, ids] = W
                ids = ids[active]
            W, sc, prev = W[:, active], scale[:, ids], err[active]
            active = xp.ones(ids.size, dtype=bool)
        else:
            prev = err
    else:
        to_newton[active if ids is None else ids[active]] = True
    if ids is None:
        W_all = W if W is not W0 else W0.copy()
    else:
        W_all[:, ids] = W
    if to_newton.any():
        idx = np.flatnonzero(to_newton)
        Wp = W_all[:, idx]
        bad = ~np.isfinite(Wp).all(axis=0)
        Wp[:, bad] = W0[:, idx[bad]]  # restart diverged rays from the predictor
        Wp, ok[idx] = newton(phi, Wp, idx, scale[:, idx], opts)
        W_all[:, idx] = Wp
    return W_all, ok


def newton(
    phi: Phi, W: np.ndarray, idx: np.ndarray, scale: np.ndarray, opts: SolverOptions
) -> tuple[np.ndarray, np.ndarray]:
    """Newton's method on W - phi(W) = 0 for the rays idx; -> (W (k, M), converged (M,))."""
    M = idx.size
    xp = array_module(W)
    ok = xp.zeros(M, dtype=bool)
    loc = xp.arange(M)
    prev = xp.full(M, np.inf)
    for _ in range(opts.max_newton):
        Wa, rays, sc = W[:, loc], idx[loc], scale[:, loc]
        F = Wa - phi(Wa, rays)
        J = fd_jacobian(phi, Wa, rays, sc)
        dW, solved = batched_solve(J, F)
        Wa -= dW
        W[:, loc] = Wa
        err = np.max(np.abs(dW) / sc, axis=0)
        # converged, or stagnating at the round-off level just above tol
        conv = solved & ((err <= opts.tol) | ((err <= 100 * opts.tol) & (err > 0.5 * prev[loc])))
        ok[loc[conv]] = True
        prev[loc] = err
        loc = loc[solved & ~conv & np.isfinite(err)]
        if loc.size == 0:
            break
    return W, ok


def fd_jacobian(phi: Phi, W: np.ndarray, idx: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """(M, k, k) Jacobian of W - phi(W) by central differences, all 2k perturbations in one call."""
    k, M = W.shape
    d = _FD_STEP * scale
    xp = array_module(W)
    E = xp.eye(k)[:, :, None] * d[None]  # E[j, r] = delta_jr d_r
    pert = np.concatenate((W[None] + E, W[None] - E))  # (2k, k, M)
    pert = pert.transpose(1, 0, 2).reshape(k, 2 * k * M)
    out = phi(pert, xp.tile(idx, 2 * k)).reshape(k, 2 * k, M)
    dphi = (out[:, :k] - out[:, k:]) / (2.0 * d[None])  # dphi[r, j] = d phi_r / d W_j
    J = -dphi.transpose(2, 0, 1)
    J[:, xp.arange(k), xp.arange(k)] += 1.0
    return J


def batched_solve(J: np.ndarray, rhs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Solve J x = rhs per ray (J (M, k, k), rhs (k, M)); -> (x (k, M), solved (M,) bool)."""
    good = np.isfinite(J).all(axis=(1, 2)) & np.isfinite(rhs).all(axis=0)
    x = np.full_like(rhs, np.nan)
    if not good.any():
        return x, good
    Jg, bg = J[good], rhs[:, good].T[..., None]
    try:
        xg = np.linalg.solve(Jg, bg)[..., 0]
    except np.linalg.LinAlgError:  # a singular matrix in the stack: drop those rays
        fine = np.linalg.cond(Jg) < 1.0 / _EPS
        good[np.flatnonzero(good)[~fine]] = False
        if not fine.any():
            return x, good
        try:
            xg = np.linalg.solve(Jg[fine], bg[fine])[..., 0]
        except np.linalg.LinAlgError:
            good[:] = False
            return x, good
    x[:, good] = xg.T
    return x, good

"""Non-symplectic references: classical Runge–Kutta 4 and Dormand–Prince 5(4).

State is the stacked (2n, N) array Z = (q; p) (and for dopri5 also f(Z), first same as last).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ._common import Method, State, as_soa, finite_rays, flow, quiet


class _Stacked(Method):
    """Methods whose state stacks q over p."""

    def init(self, H: Any, Q: np.ndarray, P: np.ndarray) -> State:
        """State (Z,) with Z = (q; p)."""
        return (np.concatenate((as_soa(Q), as_soa(P))),)

    def qp(self, state: State) -> tuple[np.ndarray, np.ndarray]:
        """Views of q and p in Z."""
        Z = state[0]
        n = Z.shape[0] // 2
        return Z[:n], Z[n:]


class RK4(_Stacked):
    """Classical 4th-order Runge–Kutta."""

    name, order, symplectic, explicit = "rk4", 4, False, True
    error_constant = 0.125

    def __init__(self) -> None:
        super().__init__()

    @quiet
    def step(self, H: Any, state: State, h: Any) -> tuple[State, np.ndarray]:
        """One step (four gradient evaluations)."""
        Z = state[0]
        half = 0.5 * h
        k1 = flow(H, Z)
        k2 = flow(H, Z + half * k1)
        k3 = flow(H, Z + half * k2)
        k4 = flow(H, Z + h * k3)
        k2 += k3
        k2 *= 2.0
        k1 += k2
        k1 += k4
        Z1 = Z + (h / 6.0) * k1
        return (Z1,), finite_rays(Z1)


# Dormand & Prince (1980) RK5(4)7M.
DP_C = np.array([0.0, 1 / 5, 3 / 10, 4 / 5, 8 / 9, 1.0, 1.0])
DP_A = (
    (),
    (1 / 5,),
    (3 / 40, 9 / 40),
    (44 / 45, -56 / 15, 32 / 9),
    (19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729),
    (9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656),
    (35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84),
)
DP_B5 = DP_A[6] + (0.0,)
DP_B4 = (5179 / 57600, 0.0, 7571 / 16695, 393 / 640, -92097 / 339200, 187 / 2100, 1 / 40)
DP_E = tuple(b5 - b4 for b5, b4 in zip(DP_B5, DP_B4, strict=True))


class Dopri5(_Stacked):
    """Dormand–Prince 5(4) with an embedded error estimate; per-ray step sizes in `attempt`.

    rtol/atol weigh the local error estimate: err = rms((y5 - y4) / (atol + rtol |y|)) per
    ray; a step is accepted when err <= 1. `step` takes a fixed step (order 5).
    """

    name, order, symplectic, explicit = "dopri5", 5, False, True
    error_constant = 0.1
    adaptive = True

    def __init__(
        self,
        rtol: float = 1e-8,
        atol: float | None = None,
        safety: float = 0.9,
        min_factor: float = 0.2,
        max_factor: float = 5.0,
    ) -> None:
        super().__init__(
            rtol=rtol, atol=atol, safety=safety, min_factor=min_factor, max_factor=max_factor
        )
        self.rtol = float(rtol)
        self.atol = self.rtol if atol is None else float(atol)
        self.safety, self.min_factor, self.max_factor = safety, min_factor, max_factor

    def init(self, H: Any, Q: np.ndarray, P: np.ndarray) -> State:
        """State (Z, f(Z)): the derivative is reused by the next step (FSAL)."""
        (Z,) = super().init(H, Q, P)
        with np.errstate(all="ignore"):
            return Z, flow(H, Z)

    @quiet
    def attempt(self, H: Any, state: State, h: Any) -> tuple[State, np.ndarray, np.ndarray]:
        """Trial step of size h; -> (new state, error norm (N,), finite (N,)). err <= 1: accept."""
        Z, f0 = state
        k = [f0]
        for i in range(1, 7):
            Zi = Z.copy()
            for a, kj in zip(DP_A[i], k, strict=True):
                if a:
                    Zi += (a * h) * kj
            k.append(flow(H, Zi))
        Z1 = Zi  # the 7th stage point is the 5th-order solution (FSAL)
        e = sum(c * kj for c, kj in zip(DP_E, k, strict=True) if c)
        e *= h
        scale = self.atol + self.rtol * np.maximum(np.abs(Z), np.abs(Z1))
        e /= scale
        err = np.sqrt(np.mean(e * e, axis=0))
        ok = finite_rays(Z1, k[6])
        err[~ok] = np.inf
        return (Z1, k[6]), err, ok

    def step(self, H: Any, state: State, h: Any) -> tuple[State, np.ndarray]:
        """One fixed step (the error estimate is discarded)."""
        new, _, ok = self.attempt(H, state, h)
        return new, ok

    def factor(self, err: np.ndarray) -> np.ndarray:
        """Step-size factor for the next attempt from the error norm (N,)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            f = self.safety * err**-0.2
        f = np.clip(f, self.min_factor, self.max_factor)
        f[~np.isfinite(err)] = self.min_factor
        return f

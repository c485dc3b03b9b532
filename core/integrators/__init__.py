"""Symplectic (and reference) integrators of Hamilton's equations, batched over rays.

A method is a small object (diffrax style) with `name`, `order`, `symplectic` and

    init(H, Q, P) -> state               # tuple of arrays, rays on the last axis
    step(H, state, h) -> (state, ok)     # h float or (N,); ok False: non-finite / not converged
    qp(state) -> (Q, P)                  # each (n, N)

looked up by name in METHODS (get_method also takes options, e.g. tol, base, omega).
`integrate` is the public driver; `PoincareTransformed` gives adaptive symplectic steps.
"""

from ._common import Method
from ._solve import SolverOptions
from .compose import (
    BASES,
    Composition,
    suzuki4,
    suzuki6,
    suzuki_weights,
    tao4,
    yoshida4,
    yoshida6,
    yoshida8,
    yoshida_weights,
)
from .driver import IntegrationResult, Trajectory, integrate
from .implicit import Gauss4, ImplicitMidpoint, StormerVerlet, SymplecticEuler
from .poincare import Clocked, PoincareTransformed
from .registry import METHODS, get_method
from .rk import RK4, Dopri5
from .splitting import (
    SplitRequired,
    SplitSystem,
    Splitting,
    blanes_moan4,
    blanes_moan6,
    leapfrog,
)
from .tao import Tao2

__all__ = [
    "BASES",
    "METHODS",
    "RK4",
    "Clocked",
    "Composition",
    "Dopri5",
    "Gauss4",
    "ImplicitMidpoint",
    "IntegrationResult",
    "Method",
    "PoincareTransformed",
    "SolverOptions",
    "SplitRequired",
    "SplitSystem",
    "Splitting",
    "blanes_moan4",
    "blanes_moan6",
    "leapfrog",
    "StormerVerlet",
    "SymplecticEuler",
    "Tao2",
    "Trajectory",
    "get_method",
    "integrate",
    "suzuki4",
    "suzuki6",
    "suzuki_weights",
    "tao4",
    "yoshida4",
    "yoshida6",
    "yoshida8",
    "yoshida_weights",
]

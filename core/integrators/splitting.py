"""Explicit symplectic splitting methods for K = T(p) + V(q).

A model that can be written as two exactly solvable parts offers them through its split
(``Hamiltonian.split_parts``): a :class:`SplitSystem`, with the exact flows
``drift(Q, P, t)`` (of T) and ``kick(Q, P, t)`` (of V), each advancing the state in place
over a time t (a float or per ray (N,)). The methods here compose those flows in the BAB form

    kick(b_0 h) drift(a_0 h) kick(b_1 h) ... drift(a_{s-1} h) kick(b_s h),

so every step is explicit: s force evaluations, no solve. They are symplectic because each
flow is exact and a composition of symplectic maps is symplectic; symmetric coefficient
lists make them time-reversible. A model without a split is refused with a message: these
methods need it (``SplitRequired``). A separable H = T(p) + V(q) is its own split.

Coefficients:
- leapfrog (Störmer–Verlet as kick-drift-kick), order 2.
- blanes_moan4: Blanes & Moan (2002), "Practical symplectic partitioned Runge–Kutta and
  Runge–Kutta–Nyström methods", J. Comput. Appl. Math. 142, Table 3, SRKN_6^b: order 4,
  6 stages, for T quadratic in p (Runge–Kutta–Nyström), with an error constant far below
  the triple jump's.
- blanes_moan6: the same paper, SRKN_11^b: order 6, 11 stages.
- blanes_moan_s6, blanes_moan_s10: the same paper, Table 2, the partitioned Runge–Kutta
  methods S_6 (order 4, 6 stages) and S_10 (order 6, 10 stages) for a *general* split
  A + B. blanes_moan6 is order 6 only where [V, [V, [V, T]]] = 0 (T quadratic in p),
  order 4 on a split whose kinetic part is not (Kerr's square-root Hamiltonian,
  core/models/kerr_split.py: measured 3.98; Schwarzschild's logarithmic one: 4.00);
  blanes_moan4's order 4 holds for any split (a symmetric method's order-4 conditions do
  not depend on it). A split says which it is (``SplitSystem.nystrom``); a method's
  ``order_on(split)`` is the order it reaches there, which the renderer's step rule and
  error estimate use.
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np

from ..dual import DualRows
from ._common import (
    Method,
    State,
    as_soa,
    finite_rays,
    gradient_drift,
    gradient_kick,
    quiet,
)
from .system import System


class SplitRequired(ValueError):
    """A splitting method was asked to integrate a Hamiltonian that offers no split."""


class SplitSystem(System):
    """A system written as two exactly solvable parts K = T(p) + V(q) (a model's split).

    Besides the System members (value and gradient of K, for the other methods), it gives
    the exact flow of each part over a time t, in place.
    """

    nystrom: bool = False
    """Whether the split is of Runge–Kutta–Nyström type (T quadratic in p, V free of p:
    [V, [V, [V, T]]] = 0), where the SRKN splittings reach their nominal order."""
    tangents: bool = False
    """Whether ``kick`` and ``drift`` also take core.dual.DualRows (rows with derivatives):
    then a step carries the tangent map along (``Splitting.step`` on a state with tangents)."""

    def kick(self, Q: np.ndarray, P: np.ndarray, t: Any) -> None:
        """Exact flow of the position part V over t (q fixed)."""
        raise NotImplementedError

    def drift(self, Q: np.ndarray, P: np.ndarray, t: Any) -> None:
        """Exact flow of the momentum part T over t (p fixed)."""
        raise NotImplementedError

    def gauge_tangents(self, Q: np.ndarray, P: np.ndarray, dQ: np.ndarray, dP: np.ndarray) -> None:
        """In place on the tangents (k, n, N) a state (Q, P) starts with: make them the
        cheapest to carry that give the same derivatives of what is read from them (by
        default they are left as they are)."""

    def value_gradient_soa(self, Q: np.ndarray, P: np.ndarray) -> tuple[Any, Any, Any]:
        """(K, dK/dq, dK/dp) from value_soa and gradient_soa."""
        dq, dp = self.gradient_soa(Q, P)
        return self.value_soa(Q, P), dq, dp


def _bm4() -> tuple[tuple[float, ...], tuple[float, ...]]:
    """SRKN_6^b of Blanes & Moan (2002): (kicks b_0..b_6, drifts a_0..a_5)."""
    b1, b2, b3 = 0.0829844064174052, 0.396309801498368, -0.0390563049223486
    a1, a2 = 0.245298957184271, 0.604872665711080
    a3 = 0.5 - (a1 + a2)
    b4 = 1.0 - 2.0 * (b1 + b2 + b3)
    return (b1, b2, b3, b4, b3, b2, b1), (a1, a2, a3, a3, a2, a1)


def _bm6() -> tuple[tuple[float, ...], tuple[float, ...]]:
    """SRKN_11^b of Blanes & Moan (2002): (kicks b_0..b_11, drifts a_0..a_10)."""
    b5 = (
        0.0414649985182624,
        0.198128671918067,
        -0.0400061921041533,
        0.0752539843015807,
        -0.0115113874206879,
    )
    a5 = (
        0.123229775946271,
        0.290553797799558,
        -0.127049212625417,
        -0.246331761062075,
        0.357208872795928,
    )
    b: tuple[float, ...] = b5 + (0.5 - sum(b5),)
    a: tuple[float, ...] = a5 + (1.0 - 2.0 * sum(a5),) + a5[::-1]
    return b + b[::-1], a


def _s6() -> tuple[tuple[float, ...], tuple[float, ...]]:
    """S_6 of Blanes & Moan (2002), Table 2 (order 4, general splits): (kicks, drifts)."""
    b = (0.0792036964311957, 0.353172906049774, -0.0420650803577195)
    a = (0.209515106613362, -0.143851773179818)
    kicks = b + (1.0 - 2.0 * sum(b),) + b[::-1]
    drifts = a + (0.5 - sum(a),) + (0.5 - sum(a),) + a[::-1]
    return kicks, drifts


def _s10() -> tuple[tuple[float, ...], tuple[float, ...]]:
    """S_10 of Blanes & Moan (2002), Table 2 (order 6, general splits): (kicks, drifts)."""
    b = (
        0.0502627644003922,
        0.413514300428344,
        0.0450798897943977,
        -0.188054853819569,
        0.541960678450780,
    )
    a = (0.148816447901042, -0.132385865767784, 0.067307604692185, 0.432666402578175)
    kicks = b + (1.0 - 2.0 * sum(b),) + b[::-1]
    drifts = a + (0.5 - sum(a),) + (0.5 - sum(a),) + a[::-1]
    return kicks, drifts


class Splitting(Method):
    """An explicit symmetric splitting (BAB form) of a model's split K = T(p) + V(q)."""

    symplectic = True
    explicit = True
    needs_split = True

    def __init__(
        self,
        name: str,
        order: int,
        kicks: tuple[float, ...],
        drifts: tuple[float, ...],
        error_constant: float | None = None,
        general_order: int | None = None,
    ) -> None:
        super().__init__()
        if len(kicks) != len(drifts) + 1:
            raise ValueError("a BAB splitting has one kick more than drifts")
        if abs(sum(kicks) - 1.0) > 1e-12 or abs(sum(drifts) - 1.0) > 1e-12:
            raise ValueError(f"{name}: kick and drift coefficients must each sum to 1")
        self.name, self.order = name, order
        self.kicks, self.drifts = tuple(kicks), tuple(drifts)
        self.error_constant = error_constant
        self.general_order = order if general_order is None else general_order
        """Order on a split not of Runge–Kutta–Nyström type (``SplitSystem.nystrom``)."""

    def order_on(self, system: Any) -> int:
        """``order`` on a Runge–Kutta–Nyström split (T quadratic in p: ``nystrom``), else
        ``general_order`` (a separable H's own split counts as general)."""
        nystrom = isinstance(system, SplitSystem) and system.nystrom
        return self.order if nystrom else self.general_order

    @property
    def stages(self) -> int:
        """Force evaluations per step (the kicks; the last and the first of two consecutive
        steps act at the same positions)."""
        return len(self.drifts)

    def init(self, H: Any, Q: np.ndarray, P: np.ndarray) -> State:
        """(Q, P) copies; refuses a Hamiltonian without a split."""
        split_flows(H, self.name)
        return as_soa(Q), as_soa(P)

    @quiet
    def step(self, H: Any, state: State, h: Any) -> tuple[State, np.ndarray]:
        """One step of the composition of H's exact kick and drift flows. A state (Q, P,
        dQ, dP) with tangents (k, n, N) (``with_tangents``) gets them carried through the
        step's own tangent map (forward mode, core.dual.DualRows)."""
        kick, drift = split_flows(H, self.name)
        if len(state) == 4:
            rows = [DualRows(state[i].copy(), state[i + 2].copy()) for i in (0, 1)]
            self._compose(kick, drift, rows[0], rows[1], h)
            new = (rows[0].value, rows[1].value, rows[0].tangent, rows[1].tangent)
            return new, finite_rays(*new[:2], *new[2], *new[3])
        Q, P = (a.copy() for a in state[:2])
        self._compose(kick, drift, Q, P, h)
        return (Q, P), finite_rays(Q, P)

    def _compose(self, kick: Any, drift: Any, Q: Any, P: Any, h: Any) -> None:
        """The step's kicks and drifts in place on Q, P (arrays, or DualRows)."""
        for b, a in zip(self.kicks, self.drifts, strict=False):
            kick(Q, P, b * h)
            drift(Q, P, a * h)
        kick(Q, P, self.kicks[-1] * h)

    def tangents_of(self, state: State) -> tuple[np.ndarray, ...]:
        """(dQ, dP) of a state with tangents, else ()."""
        return tuple(state[2:4])

    def with_tangents(self, H: Any, state: State, dQ: np.ndarray, dP: np.ndarray) -> State:
        """``state`` with tangents dQ, dP (k, n, N) to carry along; ValueError where H's
        flows cannot carry them (``SplitSystem.tangents``)."""
        if not (isinstance(H, SplitSystem) and H.tangents):
            raise ValueError(
                f"ray differentials (the magnification pass, point stars) need a split whose "
                f"flows carry derivatives; {type(H).__name__} has none: they are available "
                "for Schwarzschild, Kerr with |a| < M and flat space"
            )
        dQ, dP = as_soa(dQ), as_soa(dP)
        H.gauge_tangents(state[0], state[1], dQ, dP)
        return (*state[:2], dQ, dP)

    def with_options(self, **options: Any) -> Splitting:
        """No options: the method itself."""
        if options:
            raise TypeError(f"{self.name}: takes no options, got {sorted(options)}")
        return self

    def __repr__(self) -> str:
        return f"Splitting({self.name!r}, order={self.order}, stages={self.stages})"


def split_flows(H: Any, method: str) -> tuple[Any, Any]:
    """H's exact (kick, drift) flows, each f(Q, P, t) in place: a model's split (``kick``,
    ``drift``), or for a separable H = T(p) + V(q) its two halves through the gradient
    (q fixed: p -= t dV/dq; p fixed: q += t dT/dp). Raises SplitRequired otherwise."""
    if isinstance(H, SplitSystem):
        return H.kick, H.drift
    if H is not None and H.separable:
        return _gradient_kick(H), _gradient_drift(H)
    raise SplitRequired(
        f"method '{method}' is an explicit splitting: it needs the model's split into "
        "two exactly solvable parts K = T(p) + V(q), which this Hamiltonian does not offer "
        "(media do, traced with the Poincaré time transformation: core.render, or "
        "core.integrate(..., adaptive=True); so do Schwarzschild and Kerr–Schild Kerr with "
        "|a| < M in core.render); use an implicit symplectic method such as gauss4 for it"
    )


def _gradient_kick(H: Any):
    return functools.partial(gradient_kick, H)


def _gradient_drift(H: Any):
    return functools.partial(gradient_drift, H)


# Error constants: calibrated like the others (core.tracing.steps), on the ray tracing's own
# use of the splittings: Schwarzschild in its isotropic optical form (the logarithmic split,
# core/models/schwarzschild_optical.py), a/M = 0 seen from 30 rg; measured C: leapfrog
# 5.3e-3, blanes_moan4 3.3e-5 (gauss4 8.7e-4 and rk4 9.4e-3 there), times 1.5
# (benchmarks/bench_perf.py --only calibrate). blanes_moan6's is C at its nominal order 6,
# for Runge–Kutta–Nyström splits; the splits of Schwarzschild and Kerr, where it is order 4,
# have their own (core.tracing.steps.FORM_CALIBRATIONS).


def leapfrog() -> Splitting:
    """Kick-drift-kick Störmer–Verlet on the model's split, order 2."""
    return Splitting("leapfrog", 2, (0.5, 0.5), (1.0,), error_constant=8e-3)


def blanes_moan4() -> Splitting:
    """Blanes & Moan (2002) SRKN_6^b, order 4, 6 force evaluations per step."""
    return Splitting("blanes_moan4", 4, *_bm4(), error_constant=5e-5)


def blanes_moan6() -> Splitting:
    """Blanes & Moan (2002) SRKN_11^b, order 6 (4 on a general split), 11 force
    evaluations per step."""
    return Splitting("blanes_moan6", 6, *_bm6(), error_constant=2e-5, general_order=4)


# Error constants of the general splittings: measured on the split they are for, Kerr's
# square-root split (core/models/kerr_split.py), a/M = 0.9 from 30 rg (bench_perf.py
# --only calibrate, 800 rays): C = 2.1e-3 (blanes_moan_s6), 2.7e-4 (blanes_moan_s10), x 1.5.


def blanes_moan_s6() -> Splitting:
    """Blanes & Moan (2002) S_6, order 4 for any split A + B, 6 stages per step."""
    return Splitting("blanes_moan_s6", 4, *_s6(), error_constant=3e-3)


def blanes_moan_s10() -> Splitting:
    """Blanes & Moan (2002) S_10, order 6 for any split A + B, 10 stages per step."""
    return Splitting("blanes_moan_s10", 6, *_s10(), error_constant=4e-4)

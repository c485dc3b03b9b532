"""Shared helpers of the integrators: per-ray subsets, finiteness checks, the method base class."""

from __future__ import annotations

import functools
from typing import Any

import numpy as np

from ..backend import array_module
from .system import FrozenQ, System, as_system

State = tuple[np.ndarray, ...]


def take(a: Any, idx: np.ndarray | None) -> Any:
    """Per-ray subset of a scalar or of an array with rays on its last axis (idx None: all rays)."""
    if idx is None or np.ndim(a) == 0:
        return a
    return a[..., idx]


def restrict(H: Any, idx: np.ndarray | None) -> Any:
    """H (a system or a FrozenQ) for the rays idx: H.subset(idx) (H itself where it
    carries no per-ray data)."""
    if idx is None:
        return H
    if isinstance(H, FrozenQ):
        return H.subset(idx)
    return as_system(H).subset(idx)


class PerRay:
    """Per-ray inputs of an implicit solve (H and arrays), restricted to the rays idx.

    The solver passes the same idx object until it narrows its batch, so the restriction
    is computed once per narrowing, not at every iteration. Call with idx (None: all rays).
    """

    def __init__(self, H: Any, *arrays: Any) -> None:
        self.full = (H, *arrays)
        self._idx: Any = None
        self._sub = self.full

    def __call__(self, idx: np.ndarray | None) -> tuple:
        if idx is None:
            return self.full
        if idx is not self._idx:
            H, *arrays = self.full
            self._sub = (restrict(H, idx), *(take(a, idx) for a in arrays))
            self._idx = idx
        return self._sub


def finite_rays(*arrays: np.ndarray) -> np.ndarray:
    """(N,) bool: True for the rays (last axis) whose entries are all finite in every array."""
    ok = np.isfinite(arrays[0]).all(axis=0)
    for a in arrays[1:]:
        ok &= np.isfinite(a).all(axis=0)
    return ok


def as_soa(a: Any) -> np.ndarray:
    """A C-ordered float64 copy of a state block (n, N): rows are contiguous rays.

    (Row order matters: per-ray reductions over the n rows, and every row view, are several
    times slower on a transposed (Fortran-ordered) block.)"""
    return array_module(a).array(a, dtype=np.float64, order="C")


def flow(H: System, Z: np.ndarray) -> np.ndarray:
    """Hamilton's vector field (dH/dp, -dH/dq) of the stacked state Z = (q; p), shape (2n, N)."""
    n = Z.shape[0] // 2
    dq, dp = H.gradient_soa(Z[:n], Z[n:])
    out = np.empty_like(Z)
    out[:n] = dp
    np.negative(dq, out=out[n:])
    return out


def gradient_kick(H: Any, Q: np.ndarray, P: np.ndarray, t: Any) -> None:
    """The exact flow of a separable H's V(q) over t, in place: p -= t dV/dq."""
    dq, _ = H.gradient_soa(Q, P, wrt="q")
    P -= t * dq


def gradient_drift(H: Any, Q: np.ndarray, P: np.ndarray, t: Any) -> None:
    """The exact flow of a separable H's T(p) over t, in place: q += t dT/dp."""
    _, dp = H.gradient_soa(Q, P, wrt="p")
    Q += t * dp


def quiet(fn):
    """Run fn with floating-point warnings off: failing rays are reported through `ok`."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with np.errstate(all="ignore"):
            return fn(*args, **kwargs)

    return wrapper


Pattern = tuple[tuple[str, float], ...]
"""A splitting: the exact sub-flows (kind, coefficient) of one step, in order."""


class Method:
    """Base of the one-step rules (what the drivers and the tracer rely on).

    Every method has a ``name``, an ``order`` (nominal: ``order_on(system)`` is the order
    on a given system), ``symplectic``, ``explicit`` (no implicit
    solve for any H) and ``error_constant`` (C in err = C h^order around a mass, see
    core.tracing.steps; None where it was not calibrated), and

        init(H, Q, P) -> state; step(H, state, h) -> (state, ok); qp(state) -> (Q, P)
        steps(H, state, hs)        # consecutive steps of sizes hs (default: one by one)
        accepts(option) / with_options(**options)

    Splittings also give ``pattern(H)`` (their sub-flows for this H, else None) and
    ``apply``; methods with an embedded error estimate (``adaptive``) give ``attempt``
    and ``factor`` for per-ray step sizes.
    """

    name: str = ""
    order: int = 0
    symplectic: bool = False
    explicit: bool = False
    error_constant: float | None = None
    adaptive: bool = False
    follows_time_scale: bool = True
    """Whether it follows rays of a Poincaré-transformed K = g (H - H0) (Tao's binding of
    two copies does not: the renderer refuses it for black holes)."""
    needs_split: bool = False
    """Whether it steps the model's split (``split_parts``, a SplitSystem) rather than H
    itself: the explicit splittings (diffrax's ``term_structure``, as a flag)."""

    def order_on(self, system: Any) -> int:
        """The order this method reaches on ``system`` (the nominal ``order`` unless the
        system's form lowers it: Splitting)."""
        return self.order

    def error_constant_on(self, system: Any) -> float | None:
        """C in err = C h^order_on(system) around a mass, from the method alone: its own
        ``error_constant``, measured at its nominal order, so None where the system lowers
        it (the renderer's measurements per model form take precedence:
        core.tracing.steps.FORM_CALIBRATIONS)."""
        return self.error_constant if self.order_on(system) == self.order else None

    def __init__(self, **options: Any) -> None:
        self.options = dict(options)

    def init(self, H: Any, Q: np.ndarray, P: np.ndarray) -> State:
        """Initial state (Q, P) (copies, float64) for the rays in the columns of Q and P."""
        return as_soa(Q), as_soa(P)

    def step(self, H: Any, state: State, h: Any) -> tuple[State, np.ndarray]:
        """One step of size h (float or (N,)); -> (new state, ok (N,))."""
        raise NotImplementedError

    def steps(self, H: Any, state: State, hs: Any) -> tuple[State, np.ndarray]:
        """Consecutive steps of sizes hs (a composition's substeps); ok of all of them."""
        ok = None
        for h in hs:
            state, okh = self.step(H, state, h)
            ok = okh if ok is None else ok & okh
        assert ok is not None, "steps needs at least one step size"
        return state, ok

    def qp(self, state: State) -> tuple[np.ndarray, np.ndarray]:
        """Positions and momenta (each (n, N)) of a state."""
        return state[0], state[1]

    def tangents_of(self, state: State) -> tuple[np.ndarray, ...]:
        """(dQ, dP) (k, n, N) a state carries (``Splitting.with_tangents``), or ()."""
        return ()

    def pattern(self, H: Any) -> Pattern | None:
        """A splitting's sub-flows for H (compositions merge neighbours); None: not one."""
        return None

    def apply(self, kind: str, H: Any, state: State, ch: Any) -> None:
        """Advance state in place by the exact sub-flow ``kind`` over ch (splittings)."""
        raise NotImplementedError(f"{self.name} is not a splitting")

    def attempt(self, H: Any, state: State, h: Any) -> tuple[State, np.ndarray, np.ndarray]:
        """Trial step with an error norm per ray (``adaptive`` methods)."""
        raise NotImplementedError(f"{self.name} has no embedded error estimate")

    def factor(self, err: np.ndarray) -> np.ndarray:
        """Step-size factor from the error norm (``adaptive`` methods)."""
        raise NotImplementedError(f"{self.name} has no embedded error estimate")

    def accepts(self, option: str) -> bool:
        """Whether with_options takes this option."""
        return option in self.options

    def with_options(self, **options: Any) -> Method:
        """A copy of this method with some constructor options replaced."""
        unknown = set(options) - set(self.options)
        if unknown:
            raise TypeError(
                f"{self.name}: unknown option(s) {sorted(unknown)}; it takes {sorted(self.options)}"
            )
        return type(self)(**{**self.options, **options})

    def __repr__(self) -> str:
        opts = ", ".join(f"{k}={v!r}" for k, v in self.options.items())
        return f"{type(self).__name__}({opts})"

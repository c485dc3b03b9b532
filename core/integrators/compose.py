"""Compositions Φ_{w_m h} … Φ_{w_1 h} Φ_{w_0 h} Φ_{w_1 h} … Φ_{w_m h} of a symmetric 2nd-order base.

Yoshida (1990) and Suzuki (1990) coefficients; each order uses its own table. When the base
is a splitting (Störmer–Verlet on separable H, Tao's scheme) neighbouring sub-flows of the
same kind are merged, so a composition of s base steps costs s + 1 kicks, not 2s.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ._common import Method, Pattern, State, quiet
from .implicit import ImplicitMidpoint, StormerVerlet, run_splitting
from .tao import Tao2

_CBRT2 = 2.0 ** (1.0 / 3.0)
# Triple jump (Yoshida 1990, Creutz & Gocksch 1989): w1, w0.
YOSHIDA4 = (1.0 / (2.0 - _CBRT2), -_CBRT2 / (2.0 - _CBRT2))
# Yoshida 1990, solution A: w1, w2, w3 (w0 = 1 - 2 sum).
YOSHIDA6_W = (-1.17767998417887, 0.235573213359357, 0.784513610477560)
# Yoshida 1990, solution D: w1 .. w7 (w0 = 1 - 2 sum).
YOSHIDA8_W = (
    0.102799849391985,
    -1.96061023297549,
    1.93813913762276,
    -0.158240635368243,
    -1.44485223686048,
    0.253693336566229,
    0.914844246229740,
)

BASES: dict[str, type[Method]] = {
    "stormer_verlet": StormerVerlet,
    "implicit_midpoint": ImplicitMidpoint,
    "tao2": Tao2,
}


def symmetric_weights(w0: float, sides: tuple[float, ...]) -> tuple[float, ...]:
    """(w_m, …, w_1, w0, w_1, …, w_m) from w0 and (w_1, …, w_m)."""
    return tuple(reversed(sides)) + (w0,) + tuple(sides)


def yoshida_weights(sides: tuple[float, ...]) -> tuple[float, ...]:
    """Yoshida's symmetric composition with w0 = 1 - 2 (w_1 + … + w_m)."""
    return symmetric_weights(1.0 - 2.0 * float(np.sum(sides)), sides)


def suzuki_weights(order: int) -> tuple[float, ...]:
    """Suzuki's fractal S_2k(h) = S(p h)^2 S((1 - 4p) h) S(p h)^2, p_k = 1/(4 - 4^(1/(2k-1)))."""
    if order == 2:
        return (1.0,)
    inner = suzuki_weights(order - 2)
    p = 1.0 / (4.0 - 4.0 ** (1.0 / (order - 1)))
    outer = tuple(p * w for w in inner)
    return outer * 2 + tuple((1.0 - 4.0 * p) * w for w in inner) + outer * 2


def merge_pattern(pattern: Pattern, weights: tuple[float, ...]) -> Pattern:
    """The composed splitting, with neighbouring sub-flows of the same kind merged."""
    seq: list[tuple[str, float]] = []
    for w in weights:
        for kind, c in pattern:
            if seq and seq[-1][0] == kind:
                seq[-1] = (kind, seq[-1][1] + w * c)
            else:
                seq.append((kind, w * c))
    return tuple(seq)


def resolve_base(base: str | Method) -> Method:
    """A base method from its name (see BASES) or a method object."""
    if isinstance(base, str):
        if base not in BASES:
            raise ValueError(f"unknown base {base!r}; choose from {sorted(BASES)}")
        return BASES[base]()
    return base


class Composition(Method):
    """Symmetric composition of a symmetric 2nd-order base step (default Störmer–Verlet)."""

    def __init__(
        self,
        name: str,
        weights: tuple[float, ...],
        order: int,
        base: str | Method = "stormer_verlet",
        error_constant: float | None = None,
    ) -> None:
        self.base = resolve_base(base)
        super().__init__(base=self.base)
        self.name, self.order = name, order
        self.error_constant = error_constant
        self.weights = tuple(float(w) for w in weights)
        self._merged: dict[Pattern, Pattern] = {}

    @property
    def symplectic(self) -> bool:  # type: ignore[override]
        """Symplectic when the base is."""
        return self.base.symplectic

    @property
    def explicit(self) -> bool:  # type: ignore[override]
        """Explicit when the base is."""
        return self.base.explicit

    @property
    def follows_time_scale(self) -> bool:  # type: ignore[override]
        """As the base does."""
        return self.base.follows_time_scale

    def init(self, H: Any, Q: np.ndarray, P: np.ndarray) -> State:
        """The base method's initial state."""
        return self.base.init(H, Q, P)

    def qp(self, state: State) -> tuple[np.ndarray, np.ndarray]:
        """The base method's (Q, P)."""
        return self.base.qp(state)

    def accepts(self, option: str) -> bool:
        """base, or any option of the base."""
        return option == "base" or self.base.accepts(option)

    def with_options(self, base: str | Method | None = None, **options: Any) -> Composition:
        """A copy with another base and/or options passed on to the base (tol, omega, ...)."""
        new_base = self.base if base is None else resolve_base(base)
        if options:
            new_base = new_base.with_options(**options)
        return Composition(self.name, self.weights, self.order, new_base, self.error_constant)

    def __repr__(self) -> str:
        return f"Composition({self.name!r}, order={self.order}, base={self.base!r})"

    @quiet
    def step(self, H: Any, state: State, h: Any) -> tuple[State, np.ndarray]:
        """One composed step (merged splitting when the base is one for this H)."""
        pat = self.base.pattern(H)
        if pat is not None:
            seq = self._merged.get(pat)
            if seq is None:
                seq = self._merged[pat] = merge_pattern(pat, self.weights)
            return run_splitting(self.base, H, state, seq, h)
        # the base runs its substeps (Störmer–Verlet shares work between them)
        return self.base.steps(H, state, [w * h for w in self.weights])


def yoshida4(base: str | Method = "stormer_verlet") -> Composition:
    """Triple jump, order 4."""
    w1, w0 = YOSHIDA4
    return Composition("yoshida4", symmetric_weights(w0, (w1,)), 4, base, error_constant=1.0)


def yoshida6(base: str | Method = "stormer_verlet") -> Composition:
    """Yoshida's solution A, 7 base steps, order 6."""
    return Composition("yoshida6", yoshida_weights(YOSHIDA6_W), 6, base, error_constant=0.9)


def yoshida8(base: str | Method = "stormer_verlet") -> Composition:
    """Yoshida's solution D, 15 base steps, order 8."""
    return Composition("yoshida8", yoshida_weights(YOSHIDA8_W), 8, base, error_constant=350.0)


def suzuki4(base: str | Method = "stormer_verlet") -> Composition:
    """Suzuki's fractal, 5 base steps, order 4."""
    return Composition("suzuki4", suzuki_weights(4), 4, base, error_constant=0.013)


def suzuki6(base: str | Method = "stormer_verlet") -> Composition:
    """Suzuki's fractal, 25 base steps, order 6."""
    return Composition("suzuki6", suzuki_weights(6), 6, base, error_constant=5e-3)


def tao4(omega: float = 5.0) -> Composition:
    """Triple jump of Tao's scheme, order 4."""
    w1, w0 = YOSHIDA4
    return Composition("tao4", symmetric_weights(w0, (w1,)), 4, Tao2(omega))

"""What an integration method needs of the Hamiltonian it steps: the ``System`` interface.

Arrays are structure-of-arrays, rays on the last axis: ``Q``, ``P`` of shape (n, N).

Required of every system (docs/architecture.md, "Models"):

    dim: int
    separable: bool                               # H = T(p) + V(q): splittings are explicit
    value_soa(Q, P) -> (N,)
    gradient_soa(Q, P, wrt="qp") -> (dH/dq | None, dH/dp | None)    # each (n, N)
    value_gradient_soa(Q, P) -> (H, dH/dq, dH/dp)

Optional, with the defaults of :class:`System`:

    time_scale_soa(Q) -> (g (N,), dg/dq (n, N))   # Poincaré g(q); default g = 1
    poincare_soa(Q, P, H0, wrt) -> (K, dK/dq, dK/dp) of K = g (H - H0); default from the above
    frozen_q(Q, H0=None) -> FrozenQ | None        # dH/dq at fixed q for any p; default None
    subset(idx) -> System                         # the system for rays idx; default itself
    capture_test() -> (Q -> (N,) bool) | None     # rays past a horizon; default None
    split_parts(H0, clocked=False) -> SplitSystem | None  # K in two exact parts; default None

Models (core.models) and the wrappers here (PoincareTransformed, Clocked) subclass
:class:`System`. An object written to the required part only (duck-typed, as the tests'
analytic Hamiltonians are) is wrapped by :func:`as_system`, the one place that looks its
optional members up.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from .. import dual

CaptureTest = Callable[[np.ndarray], np.ndarray]
Gradient = tuple[np.ndarray | None, np.ndarray | None]
ValueGradient = tuple[Any, Any, Any]


class FrozenQ:
    """dH/dq at fixed positions Q for any momenta P: the q-dependence evaluated once.

    For H quadratic in p (a metric), an implicit kick P' = P - c dH/dq(Q, P') iterates over
    P' at fixed Q. The model's coefficients and their q-derivatives (dual numbers over q,
    the costly part) are its *form* at Q, computed once; each iterate then costs a few
    products in p. With H0 given, the gradient is that of K = g (H - H0) (Poincaré).
    """

    def __init__(
        self, apply: Callable[..., ValueGradient], form: list[Any], H0: Any = None
    ) -> None:
        self.apply, self.form, self.H0 = apply, form, H0

    def grad_q(self, P: np.ndarray) -> np.ndarray:
        """dH/dq (or dK/dq) at the frozen Q for momenta P, (n, N)."""
        return self.apply(self.form, P, "q", self.H0)[1]

    def subset(self, idx: np.ndarray) -> FrozenQ:
        """The same for the rays idx."""
        H0 = self.H0 if self.H0 is None or np.ndim(self.H0) == 0 else self.H0[idx]
        return FrozenQ(self.apply, [dual.subset(x, idx) for x in self.form], H0)


class System:
    """Base of everything a method steps: the required members and the optional defaults."""

    dim: int
    separable: bool = False

    def value_soa(self, Q: np.ndarray, P: np.ndarray) -> np.ndarray:
        """H at each ray, (N,)."""
        raise NotImplementedError

    def gradient_soa(self, Q: np.ndarray, P: np.ndarray, wrt: str = "qp") -> Gradient:
        """(dH/dq, dH/dp), each (n, N); the half not in ``wrt`` may be None."""
        raise NotImplementedError

    def value_gradient_soa(self, Q: np.ndarray, P: np.ndarray) -> ValueGradient:
        """(H, dH/dq, dH/dp) in one evaluation."""
        raise NotImplementedError

    def time_scale_soa(self, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Poincaré time-transformation g(q) and dg/dq; default g = 1."""
        return np.ones(Q.shape[-1]), np.zeros_like(Q)

    def poincare_soa(self, Q: np.ndarray, P: np.ndarray, H0: Any, wrt: str = "qp") -> ValueGradient:
        """(K = g (H - H0), dK/dq, dK/dp); with wrt="p" only dK/dp (the others None).

        This default combines g, dg/dq and H's own gradient; a model that evaluates g
        with H (Kerr–Schild: g = r) overrides it with one fused evaluation.
        """
        if wrt == "p":
            g, _ = self.time_scale_soa(Q)
            _, dp = self.gradient_soa(Q, P, wrt="p")
            return None, None, g * dp
        g, dg = self.time_scale_soa(Q)
        Hv, dq, dp = self.value_gradient_soa(Q, P)
        dH = Hv - H0
        return g * dH, dg * dH + g * dq, g * dp

    def frozen_q(self, Q: np.ndarray, H0: Any = None) -> FrozenQ | None:
        """dH/dq at Q for any momenta (dK/dq of K = g (H - H0) with H0); None: no fast form."""
        return None

    def subset(self, idx: np.ndarray) -> System:
        """The system for the rays idx of the batch (itself unless it holds per-ray data)."""
        return self

    def capture_test(self) -> CaptureTest | None:
        """Q (n, N) -> (N,) bool: rays past the model's horizon; None where there is none."""
        return None

    def split_parts(self, H0: Any = 0.0, clocked: bool = False) -> System | None:
        """The Poincaré-transformed K of rays with H = H0 written as two exactly solvable
        parts, a :class:`core.integrators.SplitSystem` for the explicit splittings (and the
        other methods); with ``clocked``, the parameter s as a last coordinate (momentum
        p_s = -H0). None: no split is offered (the default; media and Schwarzschild's
        optical form offer one)."""
        return None


class DuckSystem(System):
    """A duck-typed Hamiltonian (the required members only) seen as a System."""

    def __init__(self, H: Any) -> None:
        self.H = H
        self.dim = H.dim
        self.separable = bool(H.separable)
        # The only capability probes of the integrators: an object that is not a System
        # (docs/architecture.md allows any object with the required members) may still
        # offer some optional members; each is looked up once, here.
        self._optional = {
            name: getattr(H, name, None)
            for name in ("time_scale_soa", "poincare_soa", "frozen_q", "subset", "captured_soa")
        }

    def value_soa(self, Q: np.ndarray, P: np.ndarray) -> np.ndarray:
        return self.H.value_soa(Q, P)

    def gradient_soa(self, Q: np.ndarray, P: np.ndarray, wrt: str = "qp") -> Gradient:
        return self.H.gradient_soa(Q, P, wrt=wrt)

    def value_gradient_soa(self, Q: np.ndarray, P: np.ndarray) -> ValueGradient:
        return self.H.value_gradient_soa(Q, P)

    def time_scale_soa(self, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        own = self._optional["time_scale_soa"]
        return super().time_scale_soa(Q) if own is None else own(Q)

    def poincare_soa(self, Q: np.ndarray, P: np.ndarray, H0: Any, wrt: str = "qp") -> ValueGradient:
        own = self._optional["poincare_soa"]
        return super().poincare_soa(Q, P, H0, wrt) if own is None else own(Q, P, H0, wrt=wrt)

    def frozen_q(self, Q: np.ndarray, H0: Any = None) -> FrozenQ | None:
        own = self._optional["frozen_q"]
        if own is None:
            return None
        return own(Q) if H0 is None else own(Q, H0)

    def subset(self, idx: np.ndarray) -> System:
        own = self._optional["subset"]
        return self if own is None else as_system(own(idx))

    def capture_test(self) -> CaptureTest | None:
        return self._optional["captured_soa"]


def as_system(H: Any) -> System:
    """H itself when it is a System, else H wrapped as one (see DuckSystem)."""
    return H if isinstance(H, System) else DuckSystem(H)

"""Method instances by name: METHODS and get_method."""

from __future__ import annotations

from typing import Any

from . import compose
from ._common import Method
from .implicit import Gauss4, ImplicitMidpoint, StormerVerlet, SymplecticEuler
from .rk import RK4, Dopri5
from .splitting import blanes_moan4, blanes_moan6, blanes_moan_s6, blanes_moan_s10, leapfrog
from .tao import Tao2

METHODS: dict[str, Method] = {
    "symplectic_euler": SymplecticEuler(),
    "stormer_verlet": StormerVerlet(),
    "implicit_midpoint": ImplicitMidpoint(),
    "gauss4": Gauss4(),
    "yoshida4": compose.yoshida4(),
    "yoshida6": compose.yoshida6(),
    "yoshida8": compose.yoshida8(),
    "suzuki4": compose.suzuki4(),
    "suzuki6": compose.suzuki6(),
    "tao2": Tao2(),
    "tao4": compose.tao4(),
    "leapfrog": leapfrog(),
    "blanes_moan4": blanes_moan4(),
    "blanes_moan6": blanes_moan6(),
    "blanes_moan_s6": blanes_moan_s6(),
    "blanes_moan_s10": blanes_moan_s10(),
    "rk4": RK4(),
    "dopri5": Dopri5(),
}


def get_method(method: str | Method, **options: Any) -> Method:
    """A method object from its name or an object, with constructor options replaced.

    e.g. get_method("gauss4", tol=1e-12), get_method("yoshida6", base="implicit_midpoint"),
    get_method("tao4", omega=50.0), get_method("dopri5", rtol=1e-10).
    """
    if isinstance(method, str):
        if method not in METHODS:
            raise ValueError(f"unknown method {method!r}; choose from {sorted(METHODS)}")
        method = METHODS[method]
    elif not isinstance(method, Method):
        raise TypeError(f"not an integration method (a core.integrators.Method): {method!r}")
    return method.with_options(**options) if options else method

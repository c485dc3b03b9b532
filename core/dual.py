"""Vectorized, structurally sparse dual numbers (forward-mode automatic differentiation).

A :class:`Dual` holds a value (a float or an ``(N,)`` array: one entry per ray) and a
dict of first partial derivatives keyed by variable index. Only the partials a quantity
can depend on are stored: a metric coefficient of (r, theta) carries two entries, a
cyclic coordinate such as t or phi never gets one. Seeds are plain floats (``{i: 1.0}``),
so a bare variable allocates no derivative array at all.

The functions below (``sqrt``, ``sin``, ...) accept floats, arrays and Duals alike, so
one piece of model code evaluates either values or values with gradients.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from .backend import is_array

Partials = dict[int, "float | np.ndarray"]


class Dual:
    """A value with its sparse first partial derivatives: f, {i: df/dx_i}."""

    __slots__ = ("v", "d")
    __array_ufunc__ = None  # make `ndarray (op) Dual` defer to Dual's reflected operators

    def __init__(self, v, d: Partials):
        self.v = v
        self.d = d

    @classmethod
    def variable(cls, value, index: int) -> Dual:
        """The independent variable number ``index`` at ``value`` (scalar seed 1)."""
        return cls(value, {index: 1.0})

    def __repr__(self) -> str:
        return f"Dual({self.v!r}, partials={sorted(self.d)})"

    # arithmetic --------------------------------------------------------------------
    def __neg__(self) -> Dual:
        return Dual(-self.v, {k: -g for k, g in self.d.items()})

    def __pos__(self) -> Dual:
        return self

    def __add__(self, other) -> Dual:
        if isinstance(other, Dual):
            shared = _shared(self.d, other.d)
            if shared is not None:  # the hot path of DualRows: no products by 1
                k, ga, gb = shared
                return Dual(self.v + other.v, {k: ga + gb})
            return Dual(self.v + other.v, _combine(self.d, 1.0, other.d, 1.0))
        return Dual(self.v + other, self.d)

    __radd__ = __add__

    def __sub__(self, other) -> Dual:
        if isinstance(other, Dual):
            shared = _shared(self.d, other.d)
            if shared is not None:
                k, ga, gb = shared
                return Dual(self.v - other.v, {k: ga - gb})
            return Dual(self.v - other.v, _combine(self.d, 1.0, other.d, -1.0))
        return Dual(self.v - other, self.d)

    def __rsub__(self, other) -> Dual:
        return Dual(other - self.v, _scale(self.d, -1.0))

    def __mul__(self, other) -> Dual:
        if isinstance(other, Dual):
            return Dual(self.v * other.v, _combine(self.d, other.v, other.d, self.v))
        return Dual(self.v * other, _scale(self.d, other))

    __rmul__ = __mul__

    def __truediv__(self, other) -> Dual:
        if isinstance(other, Dual):
            inv = 1.0 / other.v
            value = self.v * inv
            return Dual(value, _combine(self.d, inv, other.d, -value * inv))
        inv = 1.0 / other
        return Dual(self.v * inv, _scale(self.d, inv))

    def __rtruediv__(self, other) -> Dual:
        inv = 1.0 / self.v
        value = other * inv
        return Dual(value, _scale(self.d, -value * inv))

    def __pow__(self, exponent) -> Dual:
        if isinstance(exponent, Dual):
            return exp(exponent * log(self))
        return power(self, exponent)

    def __rpow__(self, base) -> Dual:
        value = np.power(base, self.v)
        return Dual(value, _scale(self.d, value * np.log(base)))


def _times(g, factor):
    """g * factor, where a seed g = 1.0 (a plain float) costs no array operation."""
    return factor if g.__class__ is float and g == 1.0 else g * factor


def _scale(d: Partials, factor) -> Partials:
    """Partials times a common factor (the chain rule for a unary function)."""
    return {k: _times(g, factor) for k, g in d.items()}


def _shared(da: Partials, db: Partials):
    """(key, da's, db's) where both hold that one key alone (core.dual.DualRows), else None."""
    if len(da) == 1 and len(db) == 1:
        ((k, ga),) = da.items()
        gb = db.get(k)
        if gb is not None:
            return k, ga, gb
    return None


def _combine(da: Partials, fa, db: Partials, fb) -> Partials:
    """fa * da + fb * db, touching only the partials that exist."""
    shared = _shared(da, db)
    if shared is not None:
        k, ga, gb = shared
        return {k: _times(ga, fa) + _times(gb, fb)}
    out = {k: _times(g, fa) for k, g in da.items()}
    for k, g in db.items():
        if k in out:
            out[k] = out[k] + _times(g, fb)
        else:
            out[k] = _times(g, fb)
    return out


def subset(x, idx):
    """The rays idx (last axis) of a Dual, an array or a float (floats are shared)."""
    if isinstance(x, Dual):
        return Dual(subset(x.v, idx), {k: subset(g, idx) for k, g in x.d.items()})
    return x[..., idx] if is_array(x) and x.ndim else x


def value_of(x):
    """The value part of a Dual, or ``x`` itself."""
    return x.v if isinstance(x, Dual) else x


def where(condition, x, y):
    """np.where on values, each branch's partials kept where it is chosen (a branch that
    is a plain number or array contributes none)."""
    value = np.where(condition, value_of(x), value_of(y))
    if not isinstance(x, Dual) and not isinstance(y, Dual):
        return value
    dx = x.d if isinstance(x, Dual) else {}
    dy = y.d if isinstance(y, Dual) else {}
    partials: Partials = {
        k: np.where(condition, dx.get(k, 0.0), dy.get(k, 0.0)) for k in {*dx, *dy}
    }
    return Dual(value, partials)


class DualRows:
    """A block of rows (n, N) with the derivatives of every entry along k directions
    (k, n, N): row i reads as the Dual of ``value[i]`` with the one partial {0: tangent[:,
    i]} ((k, N): the k directions together, broadcast against the value's (N,) in every
    operation), and assigning a Dual (or an array) to row i writes both back. Code written
    row by row with this module's functions (a split's flows) then carries its tangent map
    along (forward mode), while the same code on a plain array does the plain flow."""

    __slots__ = ("value", "tangent")

    def __init__(self, value: np.ndarray, tangent: np.ndarray) -> None:
        self.value, self.tangent = value, tangent

    def __len__(self) -> int:
        return self.value.shape[0]

    def __getitem__(self, i: int) -> Dual:
        return Dual(self.value[i], {0: self.tangent[:, i]})

    def __setitem__(self, i: int, x) -> None:
        self.value[i] = value_of(x)
        self.tangent[:, i] = x.d.get(0, 0.0) if isinstance(x, Dual) else 0.0


def _unary(x, f, df):
    """Apply f with derivative df(value, f(value)) to a Dual or a plain number/array."""
    if not isinstance(x, Dual):
        return f(x)
    value = f(x.v)
    return Dual(value, _scale(x.d, df(x.v, value)))


def power(x, exponent):
    """x ** c for a constant c; integer c uses repeated products (exact, fast)."""
    if isinstance(exponent, Dual):
        return exp(exponent * log(x))
    if not isinstance(x, Dual):
        return _plain_power(x, exponent)
    c = float(exponent)
    if c == 0.0:
        return 1.0
    if c == 1.0:
        return x
    if c == 2.0:
        return Dual(x.v * x.v, _scale(x.d, 2.0 * x.v))
    lower = _plain_power(x.v, c - 1.0)
    return Dual(lower * x.v, _scale(x.d, c * lower))


def _plain_power(x, c):
    """x ** c on floats/arrays, using products for small integer exponents."""
    c = float(c)
    if c == 2.0:
        return x * x
    if c == 3.0:
        return x * x * x
    if c == 1.0:
        return x
    if c == -1.0:
        return 1.0 / x
    if c == 0.5:
        return np.sqrt(x)
    return np.power(x, c)


def sqrt(x):
    """Square root; derivative 1 / (2 sqrt x)."""
    return _unary(x, np.sqrt, lambda v, f: 0.5 / f)


def exp(x):
    """Exponential."""
    return _unary(x, np.exp, lambda v, f: f)


def log(x):
    """Natural logarithm."""
    return _unary(x, np.log, lambda v, f: 1.0 / v)


def sin(x):
    """Sine."""
    return _unary(x, np.sin, lambda v, f: np.cos(v))


def cos(x):
    """Cosine."""
    return _unary(x, np.cos, lambda v, f: -np.sin(v))


def tan(x):
    """Tangent; derivative 1 + tan^2."""
    return _unary(x, np.tan, lambda v, f: 1.0 + f * f)


def arcsin(x):
    """Inverse sine; derivative 1 / sqrt(1 - x^2)."""
    return _unary(x, np.arcsin, lambda v, f: 1.0 / np.sqrt(1.0 - v * v))


def arccos(x):
    """Inverse cosine; derivative -1 / sqrt(1 - x^2)."""
    return _unary(x, np.arccos, lambda v, f: -1.0 / np.sqrt(1.0 - v * v))


def arctan(x):
    """Inverse tangent; derivative 1 / (1 + x^2)."""
    return _unary(x, np.arctan, lambda v, f: 1.0 / (1.0 + v * v))


def sinh(x):
    """Hyperbolic sine."""
    return _unary(x, np.sinh, lambda v, f: np.cosh(v))


def cosh(x):
    """Hyperbolic cosine."""
    return _unary(x, np.cosh, lambda v, f: np.sinh(v))


def tanh(x):
    """Hyperbolic tangent; derivative 1 - tanh^2."""
    return _unary(x, np.tanh, lambda v, f: 1.0 - f * f)


def absolute(x):
    """|x|. Its kink: the derivative used at exactly x = 0 is 0 (numpy's sign(0))."""
    return _unary(x, np.abs, lambda v, f: np.sign(v))


def arctan2(y, x):
    """Angle of the point (x, y); d = (x dy - y dx) / (x^2 + y^2)."""
    yv, xv = value_of(y), value_of(x)
    value = np.arctan2(yv, xv)
    if not isinstance(y, Dual) and not isinstance(x, Dual):
        return value
    inv_r2 = 1.0 / (xv * xv + yv * yv)
    dy = y.d if isinstance(y, Dual) else {}
    dx = x.d if isinstance(x, Dual) else {}
    return Dual(value, _combine(dy, xv * inv_r2, dx, -yv * inv_r2))


FUNCTIONS: dict[str, Callable[..., Any]] = {
    "sqrt": sqrt,
    "exp": exp,
    "log": log,
    "sin": sin,
    "cos": cos,
    "tan": tan,
    "arcsin": arcsin,
    "arccos": arccos,
    "arctan": arctan,
    "arctan2": arctan2,
    "asin": arcsin,
    "acos": arccos,
    "atan": arctan,
    "atan2": arctan2,
    "sinh": sinh,
    "cosh": cosh,
    "tanh": tanh,
    "abs": absolute,
}
"""Every function the expression language may call, by name (with common aliases)."""

FUNCTION_ARITY = {name: (2 if name in ("arctan2", "atan2") else 1) for name in FUNCTIONS}

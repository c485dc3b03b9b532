"""Checks of numeric inputs where they enter the core (and the add-on).

Every check raises a ValueError that names the parameter and its allowed range, and
returns the value as the core uses it. Nothing is clamped: a value out of range is an
error, never silently replaced by the nearest allowed one.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

TOLERANCE_RANGE = (1e-14, 0.1)
"""Allowed image tolerances (radians), both ends included: above 0.1 rad the error
estimates lose their meaning, below 1e-14 float64 rays cannot be that accurate (and the
steps take hours). The add-on's Tolerance property has the same range."""


def time_scale_refusal(name: str) -> str:
    """Why a method that does not follow time-scaled rays (``Method.follows_time_scale``
    False: Tao's) is refused for a black hole."""
    return (
        f"method '{name}' cannot render a black hole (or any model with a Poincaré time "
        "scale g(q)): Tao's method binds two copies of each ray with a fixed strength, and "
        "on the time-transformed Hamiltonian K = g (H - H0) that the renderer integrates "
        "the copies drift apart and the rays fail (on a Kerr frame, every one); choose "
        "gauss4 (the default), a Yoshida or Suzuki composition or rk4 (media, metrics "
        "without a time scale and core.integrate still accept it)"
    )


def _interval(lo: float, hi: float, lo_open: bool, hi_open: bool) -> str:
    """Human form of an interval: ' in (0, 0.1]', ' > 0 (positive)', ' >= 1', or '' (any)."""
    if math.isinf(lo) and math.isinf(hi):
        return ""
    if lo == 0 and lo_open and math.isinf(hi):
        return " > 0 (positive)"
    if math.isinf(hi):
        return f" {'>' if lo_open else '>='} {lo:g}"
    if math.isinf(lo):
        return f" {'<' if hi_open else '<='} {hi:g}"
    return f" in {'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"


def _scalar(name: str, value: Any, what: str) -> float:
    """float(value) for a real scalar (bool and text refused), else a ValueError."""
    if isinstance(value, (str, bytes, bool, np.bool_)) or np.ndim(value) != 0:
        raise ValueError(f"{name} must be {what}, got {value!r}")
    try:
        return float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be {what}, got {value!r}") from None


def check_range(
    name: str,
    value: Any,
    lo: float = -math.inf,
    hi: float = math.inf,
    *,
    lo_open: bool = False,
    hi_open: bool = False,
) -> float:
    """A finite number within [lo, hi] (ends excluded where open) -> float, else ValueError."""
    what = "a finite number" + _interval(lo, hi, lo_open, hi_open)
    x = _scalar(name, value, what)
    below = x <= lo if lo_open else x < lo
    above = x >= hi if hi_open else x > hi
    if not math.isfinite(x) or below or above:
        raise ValueError(f"{name} must be {what}, got {x:g}")
    return x


def check_positive(name: str, value: Any) -> float:
    """A finite number > 0 -> float, else ValueError."""
    return check_range(name, value, 0.0, lo_open=True)


def check_int(name: str, value: Any, lo: int = 1, hi: float = math.inf) -> int:
    """An integer in [lo, hi] (an integral float is accepted) -> int, else ValueError."""
    what = "an integer" + _interval(lo, hi, False, False)
    x = _scalar(name, value, what)
    if not math.isfinite(x) or x != math.floor(x) or not lo <= x <= hi:
        raise ValueError(f"{name} must be {what}, got {value}")
    return int(x)


def check_optional(check, name: str, value: Any, *args: Any) -> Any:
    """None stays None; anything else goes through ``check(name, value, *args)``."""
    return None if value is None else check(name, value, *args)


def check_finite_array(name: str, value: Any, nonzero: bool = False) -> np.ndarray:
    """A float64 array of finite numbers (and no zero where ``nonzero``), else ValueError."""
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be finite numbers, got {value!r}") from None
    if not np.all(np.isfinite(a)) or (nonzero and np.any(a == 0)):
        what = "finite non-zero numbers" if nonzero else "finite numbers"
        raise ValueError(f"{name} must be {what}, got {a.tolist()}")
    return a


def check_vector(name: str, value: Any, size: int = 3) -> np.ndarray:
    """A float64 vector of ``size`` finite numbers, else ValueError."""
    a = check_finite_array(name, value)
    if a.size != size:
        raise ValueError(f"{name} must be {size} finite numbers, got {a.tolist()}")
    return a.reshape(size)


def check_box(name: str, bounds: Any) -> tuple[np.ndarray, np.ndarray] | None:
    """None, or (lo, hi): two finite 3-vectors with lo < hi in every axis, else ValueError."""
    if bounds is None:
        return None
    lo, hi = (check_vector(f"{name} {end}", v) for end, v in zip(("lo", "hi"), bounds, strict=True))
    if np.any(hi <= lo):
        raise ValueError(
            f"{name} must have lo < hi in every axis, got lo {lo.tolist()}, hi {hi.tolist()}"
        )
    return lo, hi


def check_parameters(parameters: Mapping[str, Any] | None) -> dict[str, float]:
    """A model's named parameters -> {name: float}, each a finite number, else ValueError."""
    return {str(k): check_range(f"parameter '{k}'", v) for k, v in (parameters or {}).items()}


def check_tolerance(tolerance: Any, name: str = "tolerance") -> float:
    """An image tolerance within TOLERANCE_RANGE -> float, else ValueError."""
    return check_range(name, tolerance, *TOLERANCE_RANGE)


def check_render_method(method: Any, time_scaled: bool) -> None:
    """ValueError if ``method`` (a method object; None: the default, nothing to refuse)
    cannot render a model with a Poincaré time scale (``time_scaled``): its
    ``follows_time_scale``."""
    if time_scaled and method is not None and not method.follows_time_scale:
        raise ValueError(time_scale_refusal(method.name))


def check_render_options(tolerance: Any, step: Any, max_steps: Any) -> None:
    """The numeric options of core.render and the tracer (ValueError naming the bad one)."""
    check_tolerance(tolerance)
    check_optional(check_positive, "step", step)
    check_int("max_steps", max_steps)


def check_integrate_options(
    step: Any, steps: Any, tol: Any, record_every: Any, energy_every: Any, max_steps: Any
) -> None:
    """The numeric options of core.integrate (ValueError naming the bad one).

    ``step`` may be negative (integration backwards) or per ray, never zero or non-finite.
    """
    check_finite_array("step", step, nonzero=True)
    check_int("steps", steps)
    check_optional(check_positive, "tol", tol)
    check_optional(check_int, "record_every", record_every, 0)
    check_int("energy_every", energy_every, 0)
    check_optional(check_int, "max_steps", max_steps)

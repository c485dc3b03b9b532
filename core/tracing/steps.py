"""How long the tracer's steps are: the default method, the step rule and the solve tolerance.

The step in the Poincaré-transformed fictitious time comes from the method's error
constant (``Method.error_constant``, C in err = C h^order) around a mass, otherwise from
the size of the model's region; implicit stage equations are solved to a share of the
image tolerance.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

from ..integrators import METHODS

DEFAULT_METHOD = "gauss4"
"""The default integrator of images where the model offers no split (Kerr in BL as text,
extremal Kerr, user metrics and Hamiltonians): around a black hole Gauss–Legendre 4
reaches a given escape accuracy at about a third of yoshida4's cost (smaller error
constant, so fewer, longer steps; see ERROR_CONSTANTS and benchmarks/bench_perf.py).
Where the model (or its form for the tracer) offers an explicit split, the splitting
FORM_CALIBRATIONS names for it (default_method): Schwarzschild blanes_moan6, media
blanes_moan4, Kerr with |a| < M blanes_moan_s10 (README, "Error against run time");
core.render falls back to this one where the split cannot start rays at the camera."""
SOLVE_SHARE = 1e-4
"""Implicit stage equations are solved to tolerance x SOLVE_SHARE, within [1e-14, 1e-8]
(solver_tolerance). Measured on the Kerr frame (3000 rays; tolerances 1e-4, 1e-6, 1e-8):
the solve then moves escape directions by at most 0.06 % of the tolerance (counted, like
the tolerance, as the equivalent error of the initial direction; 100x looser moves them
by 6-24 %), while solving to 1e-14 regardless took 1.2-2.3x as long."""

ERROR_CONSTANTS = MappingProxyType(
    {
        name: method.error_constant
        for name, method in METHODS.items()
        if method.error_constant is not None
    }
)
"""Read-only view of ``METHODS[name].error_constant``: C in err = C h^order, each method's
escape-direction error around a mass, per step h of the Poincaré time (g = r). err is the
*equivalent* error of the ray's initial direction (radians): the escape error over the
lens's own magnification there, when that exceeds 1 (rays grazing the photon region have
their forward error magnified without bound, like any perturbation of their starting
direction). The largest of 3000 rays on Kerr a/M = 0.9 seen from 30 rg, times 1.5
(``benchmarks/bench_perf.py --only calibrate``). Tao's methods have none: with the default
binding they do not follow these rays."""

FAR_FIELD_CONSTANT = 30.0
"""The first-order far field leaves a forward escape error of at most ~ C (M / R)^2 for a
region of radius R (measured as above: 28.4)."""
FAR_FIELD_SHARE = 0.05
"""The region around a mass is large enough that the far field beyond it leaves at most
this share of the tolerance (its radius grows as share^-1/2, its steps only as the log: a
ray's step covers a distance proportional to r). The error pass adds that bound to every
escaped ray: at a share of 1/2 it dominated the estimate and over-reported the far field
up to ~4x (Kerr board scene, 0.25 px: 84 % of the pixels with an error above a tenth of
the tolerance estimated within 3x)."""

MAX_STEP = 0.25
"""Largest default step in the Poincaré time (a step that the implicit solve cannot take
near a horizon is split, see core.tracing.stepping)."""
MAX_SPLIT_STEP = 1.0
"""Largest default step of the explicit splittings (the logarithmic split's steps shrink
near the horizon by themselves; measured: blanes_moan4 at 0.8 keeps 99 % of a 64²
Schwarzschild frame within 0.04 px)."""


@dataclass(frozen=True)
class FormCalibration:
    """What was measured on one form a model is traced in (its split, for the splittings)."""

    method: str | None = None
    """The splitting measured cheapest at equal image accuracy on this form's split."""
    largest_step: float | None = None
    """The splittings' largest default step on it; None: MAX_SPLIT_STEP."""
    error_constants: Mapping[str, float] = field(default_factory=dict)
    """C in err = C h^order_on, measured on this form, by method name (in place of the
    methods' own, ERROR_CONSTANTS)."""


FORM_CALIBRATIONS: Mapping[str, FormCalibration] = MappingProxyType(
    {
        "KerrBoyerLindquist": FormCalibration(
            method="blanes_moan_s10",
            largest_step=0.7,
            error_constants=MappingProxyType(
                {
                    "leapfrog": 1.2,
                    "blanes_moan4": 7e-3,
                    "blanes_moan6": 5.5e-4,
                    "blanes_moan_s6": 3e-3,
                    "blanes_moan_s10": 4e-4,
                }
            ),
        ),
        "SchwarzschildOptical": FormCalibration(
            method="blanes_moan6", error_constants=MappingProxyType({"blanes_moan6": 7e-6})
        ),
        "Medium": FormCalibration(method="blanes_moan4"),
    }
)
"""The renderer's calibrations per (model form, method), by the class of the form a model
is traced in (the nearest class of its MRO listed here):

- Kerr in Boyer–Lindquist (its square-root split, core/models/kerr_split.py): blanes_moan_s10
  measured cheapest (README, "Error against run time"). Constants measured on this split
  like ERROR_CONSTANTS (a/M = 0.9 from 30 rg, 800 rays, the largest equivalent direction
  error over h^order, times 1.5; bench_perf.py --only calibrate); blanes_moan6 is order 4
  on it: its C is at order 4 (1500 rays, h = 0.6 and 0.3: 3.2e-4 and 3.6e-4; --scale 3).
  Largest step 0.7: the constants were measured at steps up to 0.6; at 1.0 (MAX_SPLIT_STEP)
  the step-doubling error pass over-estimates 11 % of the pixels of
  tests/core/test_sampling.py's honesty frame by more than 3x, at 0.7 3 %.
- Schwarzschild as its isotropic optical medium (the logarithmic split): blanes_moan6
  measured cheapest; it is order 4 there, C at order 4 (a/M = 0 from 30 rg, 1500 rays,
  h = 0.6: 4.7e-6, times 1.5; --spin 0 --scale 6).
- Media: an order-4 splitting, their step rule by order (no calibrated constant), hit points
  chords (README, "Error against run time")."""


def form_calibration(traced: Any) -> FormCalibration:
    """The calibration of the form ``traced`` (a model as the tracer follows it); an empty
    one where nothing was measured."""
    for cls in type(traced).__mro__:
        if cls.__name__ in FORM_CALIBRATIONS:
            return FORM_CALIBRATIONS[cls.__name__]
    return FormCalibration()


def error_constant(method: Any, traced: Any, system: Any = None) -> float | None:
    """C of ``method`` on the form ``traced``: measured there (FORM_CALIBRATIONS), else the
    method's own on what it integrates, ``system`` (default ``traced``; a split for the
    splittings: ``Method.error_constant_on``)."""
    measured = form_calibration(traced).error_constants.get(method.name)
    if measured is not None:
        return measured
    return method.error_constant_on(traced if system is None else system)


def default_method(model: Any) -> str:
    """The default method for a model: the splitting measured cheapest on the split of its
    tracing form (FORM_CALIBRATIONS: Schwarzschild, media, Kerr below extremal), else
    DEFAULT_METHOD."""
    if model is None:
        return DEFAULT_METHOD
    traced = model.for_backward_tracing(explicit_split=True)
    return form_calibration(traced).method or DEFAULT_METHOD


def solver_tolerance(tolerance: float) -> float:
    """Tolerance of the implicit solves for an image of ``tolerance`` (see SOLVE_SHARE)."""
    return min(1e-8, max(1e-14, float(tolerance) * SOLVE_SHARE))


def default_step(
    method: Any,
    tolerance: float,
    length: float,
    scaled: bool = False,
    constant: float | None = None,
    largest: float | None = None,
    order: int | None = None,
) -> float:
    """Fictitious-time step for ``method`` to reach ``tolerance`` (radians).

    Around a mass (``scaled``: g(q) grows with the distance) from the method's error
    constant, so that the integration error stays below tolerance / 2 (the far field gets
    FAR_FIELD_SHARE of it, see core.tracing.regions); ``constant`` replaces the method's own
    where one was measured on the traced form (``error_constant``), ``largest`` the
    splittings' largest step where the form sets one (FORM_CALIBRATIONS), and
    ``order`` the method's order on what it integrates (``Method.order_on``; default its
    nominal ``order``). Otherwise
    (media, user models, methods without a constant): h = 0.5 length tol^(1/order).
    """
    tol = min(max(float(tolerance), 1e-14), 1e-1)
    order = max(int(method.order if order is None else order), 1)
    constant, largest = rule_bounds(method, scaled, constant, largest)
    if constant is None:
        return length * min(MAX_STEP, 0.5 * tol ** (1.0 / order))
    return float(min(largest, (0.5 * tol / constant) ** (1.0 / order)))


def rule_bounds(
    method: Any, scaled: bool, constant: float | None = None, largest: float | None = None
) -> tuple[float | None, float]:
    """(error constant C, largest step) default_step takes for ``method`` (``constant`` and
    ``largest`` as there): C None where the rule uses none (not ``scaled``, or no constant
    measured), the largest step MAX_STEP, or for the splittings ``largest`` or
    MAX_SPLIT_STEP."""
    if constant is None:
        constant = method.error_constant
    if not scaled:
        constant = None
    if not method.needs_split:
        largest = MAX_STEP
    elif largest is None:
        largest = MAX_SPLIT_STEP
    return constant, float(largest)

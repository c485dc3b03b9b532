"""The renderer's calibrations: one table per traced model form (core.tracing.steps)."""

from __future__ import annotations

import pytest

from core import hamiltonians as hm
from core.integrators import METHODS
from core.models.medium import Medium
from core.models.schwarzschild_optical import SchwarzschildOptical
from core.trace import Scene, TraceOptions, Tracer
from core.tracing.steps import (
    FORM_CALIBRATIONS,
    MAX_SPLIT_STEP,
    default_method,
    error_constant,
    form_calibration,
)


@pytest.mark.parametrize(
    "model, method",
    [(hm.schwarzschild(1.0), "blanes_moan6"),
     (hm.kerr(rg=1.0, a=0.45, chart="kerr_schild"), "blanes_moan_s10"),
     (hm.kerr(rg=1.0, a=0.5, chart="kerr_schild"), "gauss4"),  # extremal: no split
     (hm.medium("1 + 0.1*x"), "blanes_moan4"),
     (hm.metric([["-1", "0", "0", "0"], ["0", "1", "0", "0"], ["0", "0", "1", "0"],
                 ["0", "0", "0", "1"]]), "gauss4")],
)  # fmt: skip
def test_default_method_per_model(model, method):
    """Each model's default is the splitting measured cheapest on its traced form's split,
    gauss4 where it has none."""
    assert default_method(model) == method


def test_the_form_is_found_by_class_and_models_hold_no_calibration():
    """A form's row is its class's, else its nearest listed base class's (Schwarzschild's
    optical medium has its own, a medium subclass gets the media's); the models themselves
    carry no calibration."""
    assert form_calibration(SchwarzschildOptical(1.0)) is FORM_CALIBRATIONS["SchwarzschildOptical"]

    class Lens(Medium):
        pass

    lens = Lens("1 + 0.1*x", literal=False)
    assert form_calibration(lens) is FORM_CALIBRATIONS["Medium"]
    assert form_calibration(hm.minkowski()).method is None
    for model in (SchwarzschildOptical(1.0), lens, hm.kerr(1.0, 0.45)):
        for name in ("split_method", "max_split_step", "error_constants"):
            assert not hasattr(model, name)


def test_the_tracer_takes_the_forms_constant_and_largest_step():
    """On Kerr's split the tracer's step comes from the form's constant and largest step
    (0.7, not MAX_SPLIT_STEP), on other forms from the method's own constant."""
    kerr = Scene(model=hm.kerr(rg=1.0, a=0.45, chart="kerr_schild"))
    loose = Tracer(kerr, TraceOptions(tolerance=1e-2))
    assert loose.method.name == "blanes_moan_s10" and loose.step == 0.7 < MAX_SPLIT_STEP
    tight = Tracer(kerr, TraceOptions(tolerance=1e-9))
    constant = FORM_CALIBRATIONS["KerrBoyerLindquist"].error_constants["blanes_moan_s10"]
    assert error_constant(tight.method, tight.model) == constant
    assert tight.step == pytest.approx((0.5e-9 / constant) ** (1 / 6))
    gauss = Tracer(kerr, TraceOptions(method="gauss4", tolerance=1e-9))
    assert error_constant(gauss.method, gauss.model) == METHODS["gauss4"].error_constant


def test_a_trace_is_planned_once_in_a_frozen_plan():
    """plan_trace decides the method, form, order, chart, region, step and capture test;
    the tracer holds exactly that plan (frozen), and a flat scene's plan says so with every
    other field None (no attribute left unset)."""
    import dataclasses

    from core.tracing.tracer import TracePlan, plan_trace

    flat = Tracer(Scene(model=None), TraceOptions())
    assert flat.plan == TracePlan(curved=False, model=None)
    assert (flat.method, flat.order, flat.step, flat.region, flat.chart) == (None,) * 5
    kerr = Scene(model=hm.kerr(rg=1.0, a=0.45, chart="kerr_schild"))
    plan = plan_trace(kerr, TraceOptions(tolerance=1e-6), 10.0)
    tracer = Tracer(kerr, TraceOptions(tolerance=1e-6), 10.0)
    assert plan.method.name == tracer.method.name == "blanes_moan_s10"
    assert (plan.order, plan.step, plan.chart.name) == (tracer.order, tracer.step, "kerr_bl")
    assert plan.region.radius == tracer.region.radius and plan.capture_test is not None
    with pytest.raises(dataclasses.FrozenInstanceError):
        plan.step = 1.0


def test_a_methods_own_constant_holds_only_at_its_nominal_order():
    """blanes_moan6's own constant was measured at order 6: it has none on a split where it
    reaches 4 (Kerr's, Schwarzschild's), where the renderer's table has one; it keeps it on a
    medium's split (order 6)."""
    method = METHODS["blanes_moan6"]
    kerr = hm.kerr(rg=1.0, a=0.45, chart="kerr_schild").for_backward_tracing(True)
    assert method.error_constant_on(kerr.split_parts()) is None
    assert error_constant(method, kerr, kerr.split_parts()) == 5.5e-4
    medium = hm.medium("1 + 0.1*x").split_parts(0.5)
    assert method.error_constant_on(medium) == method.error_constant

"""Planning a trace: how a scene's rays are followed, decided once per scene and options.

Interface: ``TraceOptions`` (method, tolerance, step, max_steps, region_radius),
``tracing_model(model, method)`` (the form rays are followed in), ``TracePlan`` (the plan:
form, method and its order, chart, region, step, capture test, the step rule's bounds) and
``plan_trace(scene, options, extent)`` (the one place a plan is made).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .. import checks, integrators
from ..backend import placed
from ..charts import chart_for
from ..models.medium import FACE_SAMPLES
from .regions import BoxRegion, Region, region_for
from .scene import Scene
from .stepping import RayCapture
from .steps import (
    default_method,
    default_step,
    error_constant,
    form_calibration,
    rule_bounds,
    solver_tolerance,
)


@dataclass
class TraceOptions:
    """How rays are integrated."""

    method: Any = None
    """A method name or object; None: the model's default (steps.default_method)."""
    tolerance: float = 1e-8
    step: float | None = None
    max_steps: int = 20_000
    region_radius: float | None = None

    def __post_init__(self) -> None:
        checks.check_render_options(self.tolerance, self.step, self.max_steps)
        checks.check_optional(checks.check_positive, "region_radius", self.region_radius)


def tracing_model(model: Any, method: Any = None) -> Any:
    """The chart rays are followed in: regular where rays followed into the past go
    (``Hamiltonian.for_backward_tracing``; e.g. Kerr–Schild outgoing, and Schwarzschild
    in (t, r, theta, phi) as Kerr–Schild with a = 0, or for an explicit splitting
    ``method`` as its isotropic optical medium)."""
    if model is None:
        return None
    return model.for_backward_tracing(explicit_split=method is not None and method.needs_split)


@dataclass(frozen=True)
class TracePlan:
    """What a tracer decides once for a scene and its options (``plan_trace``): the form rays
    are followed in and how. A flat scene's plan says so (``curved`` False, the rest None)."""

    curved: bool
    model: Any
    """The form rays are followed in (``tracing_model``); None in flat space."""
    method: Any = None
    """The integration method (with its solve tolerance), None where rays go straight."""
    order: int | None = None
    """The method's order on what it integrates here (Richardson, the step rule)."""
    chart: Any = None
    region: Region | None = None
    step: float | None = None
    capture_test: RayCapture | None = None
    """(Q, P) -> (N,) bool: rays that cannot come back out of a horizon (None: no horizon)."""
    error_constant: float | None = None
    """C of the step rule's err = C h^order (radians; None where the rule uses none)."""
    largest_step: float = math.inf
    """The rule's largest step: the constant was measured at steps up to it."""


def plan_trace(scene: Scene, options: TraceOptions, extent: float = 1.0) -> TracePlan:
    """The one place a trace is planned: method (the model's default unless named), the
    form and chart it follows rays in, the method's order there, the region around the mass
    (reaching past the disk), the capture test and the step (the options' or the rule's)."""
    if not scene.curved:
        return TracePlan(curved=False, model=tracing_model(scene.model))
    method = integrators.get_method(options.method or default_method(scene.model))
    model = tracing_model(scene.model, method)
    system = model
    if method.needs_split:  # refused without a split
        system = model.split_parts()
        integrators.splitting.split_flows(system, method.name)
    order = method.order_on(system)
    if not isinstance(options.method, integrators.Method) and method.accepts("tol"):
        method = method.with_options(tol=solver_tolerance(options.tolerance))
    radius = scene.region_radius or options.region_radius
    if scene.disk is not None:  # the disk's hits need the rays' momenta: inside
        extent = max(extent, scene.disk.cartesian_radii()[1])
    region = region_for(model, options.tolerance, extent, radius)
    if isinstance(region, BoxRegion):
        model.check_faces(region.faces(FACE_SAMPLES))  # an interface the box cuts: refused
    constant, largest = rule_bounds(
        method, region.scaled(model), error_constant(method, model, system),
        form_calibration(model).largest_step,
    )  # fmt: skip
    step = options.step or default_step(
        method,
        options.tolerance,
        region.length_scale(model),
        scaled=region.scaled(model),
        constant=constant,
        largest=largest,
        order=order,
    )
    return TracePlan(
        curved=True, model=model, method=method, order=order, chart=chart_for(model),
        region=region, step=step, capture_test=model.ray_capture_test(),
        error_constant=constant, largest_step=largest,
    )  # fmt: skip


class PlacedPlan:
    """A scene's plan with its model's frame: the plan's attributes (``curved``, ``model``,
    ``method``, ``order``, ``chart``, ``region``, ``step``, ``captured``, ``spacetime``,
    ``mass``) and ``rotation`` with ``_to_local`` / ``_to_world``. What a camera check and
    an observer's motion read (core.observer, core.motion): core.render checks a camera and
    finds its motion with this alone, before any geometry is built. A Tracer is one."""

    def __init__(self, scene: Scene, options: TraceOptions, extent: float = 1.0):
        """The plan of ``scene`` with ``options`` (``plan_trace``) and the model's frame."""
        self.scene = scene
        self.options = options
        self.rotation = scene.frame()
        self.plan = plan = plan_trace(scene, options, extent)
        self.curved, self.model = plan.curved, plan.model
        self.method, self.order, self.chart = plan.method, plan.order, plan.chart
        self.region, self.step, self.captured = plan.region, plan.step, plan.capture_test
        self.spacetime = self.curved and self.chart.time_index is not None
        self.mass = self.model.mass if self.curved else 0.0

    def _to_local(self, world: np.ndarray) -> np.ndarray:
        return (world - placed(self.scene.center, world)) @ placed(self.rotation, world)

    def _to_world(self, local: np.ndarray) -> np.ndarray:
        return local @ placed(self.rotation, local).T + placed(self.scene.center, local)

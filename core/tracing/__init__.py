"""Tracing rays through a scene: one subject per module.

``scene`` (Scene, ENDING), ``tracer`` (Tracer, TraceOptions: the batch loop), ``regions``
(where the model bends light: sphere or box), ``stepping`` (one step with retries in
halves), ``steps`` (the step rule, error constants, solve tolerance) and ``segments``
(hits and volume light along straight segments). ``core.trace`` is the public name of
these.
"""

from .regions import BoxRegion, Region, SphereRegion, region_for
from .scene import ENDING, Scene
from .segments import RayResults, SceneGeometry
from .stepping import Stepper
from .steps import (
    DEFAULT_METHOD,
    ERROR_CONSTANTS,
    FAR_FIELD_CONSTANT,
    FAR_FIELD_SHARE,
    MAX_SPLIT_STEP,
    MAX_STEP,
    SOLVE_SHARE,
    default_method,
    default_step,
    solver_tolerance,
)
from .tracer import TraceOptions, Tracer, tracing_model

__all__ = [
    "DEFAULT_METHOD",
    "ENDING",
    "ERROR_CONSTANTS",
    "FAR_FIELD_CONSTANT",
    "FAR_FIELD_SHARE",
    "MAX_SPLIT_STEP",
    "MAX_STEP",
    "SOLVE_SHARE",
    "BoxRegion",
    "RayResults",
    "Region",
    "Scene",
    "SceneGeometry",
    "SphereRegion",
    "Stepper",
    "TraceOptions",
    "Tracer",
    "default_method",
    "default_step",
    "region_for",
    "solver_tolerance",
    "tracing_model",
]

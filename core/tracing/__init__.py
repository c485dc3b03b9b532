"""Tracing rays through a scene: one subject per module.

``scene`` (Scene, ENDING), ``plan`` (TraceOptions, TracePlan, plan_trace: how a scene's
rays are followed), ``tracer`` (Tracer: the coordinating class; ``tracer_state`` what it
holds), the tracer's subjects (``starts``: rays' start states and differentials;
``step_loop``: the batch loop and each step's events; ``near_geometry``: steps near
geometry, halved where bent; ``step_ends``: a step's ends, Newton on its fraction;
``crossings``: chords, first hits, the method's surface crossings; ``disk_landing``: rays
ending on an opaque disk; ``escape``: straight parts, leaving the region, the far field;
``watching``: the clearance recorded per step), ``regions`` (where the model bends light:
sphere or box), ``stepping`` (one step with retries in halves), ``steps`` (the step rule,
the renderer's calibrations per model form, solve tolerance), ``segments`` (hits and
volume light along straight segments), ``dense``, ``clearance``, ``differentials`` and
``disklight``. ``core.trace`` is the public name of these.
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
    FORM_CALIBRATIONS,
    MAX_SPLIT_STEP,
    MAX_STEP,
    SOLVE_SHARE,
    FormCalibration,
    default_method,
    default_step,
    error_constant,
    form_calibration,
    solver_tolerance,
)
from .tracer import TraceOptions, TracePlan, Tracer, plan_trace, tracing_model

__all__ = [
    "DEFAULT_METHOD",
    "ENDING",
    "ERROR_CONSTANTS",
    "FAR_FIELD_CONSTANT",
    "FAR_FIELD_SHARE",
    "FORM_CALIBRATIONS",
    "MAX_SPLIT_STEP",
    "MAX_STEP",
    "SOLVE_SHARE",
    "BoxRegion",
    "FormCalibration",
    "RayResults",
    "Region",
    "Scene",
    "SceneGeometry",
    "SphereRegion",
    "Stepper",
    "TraceOptions",
    "TracePlan",
    "Tracer",
    "default_method",
    "default_step",
    "error_constant",
    "form_calibration",
    "plan_trace",
    "region_for",
    "solver_tolerance",
    "tracing_model",
]

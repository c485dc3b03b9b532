"""Blender settings made from the core's model registry (core.models.registry): one
property per model parameter, with the range, default and description declared there."""

from __future__ import annotations

import math
from typing import Any

import bpy

from ..core.models.registry import Parameter


def parameter_property(parameter: Parameter, **extra: Any) -> Any:
    """A FloatProperty for one of a model's parameters (its name, range, default and
    description from the core's registry)."""
    soft = {
        key: value
        for key, value in (("soft_min", parameter.soft_min), ("soft_max", parameter.soft_max))
        if value is not None
    }
    limits = {
        key: value
        for key, value in (("min", parameter.minimum), ("max", parameter.maximum))
        if math.isfinite(value)
    }
    return bpy.props.FloatProperty(
        name=parameter.label,
        default=parameter.default,
        subtype="DISTANCE" if parameter.unit == "length" else "NONE",
        description=parameter.description,
        **limits,
        **soft,
        **extra,
    )

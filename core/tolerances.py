"""A render's accuracies, made once: ``Tolerances`` (core.render hands it to the tracer's
options and the adaptive sampler; nothing else converts pixels to radians)."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

from .tracing import FAR_FIELD_CONSTANT

TRACE_SHARE = 0.5
"""With ``tolerance_px``, the integration and far field get this share of it (the tracer's
``tolerance``); the image interpolation gets the rest."""


@dataclass(frozen=True)
class Tolerances:
    """What a render may get wrong, in radians: from ``tolerance_px`` (pixels of the camera,
    ``pixel_angle`` radians each) or from ``tolerance`` itself."""

    pixel_angle: float
    """Radians one pixel spans where the scene is (core.Camera.pixel_angle); smaller for a
    moving camera (the tolerances hold in the static frame)."""
    trace: float
    """The integration's (TraceOptions.tolerance): TRACE_SHARE of tolerance_px, or
    ``tolerance``."""
    interpolation: float = 0.0
    """The adaptive image's share (the rest of tolerance_px); 0: every pixel traced."""
    px: float | None = None
    """tolerance_px itself (None: the tolerance was given in radians)."""
    far_field: float = 0.0
    """Error the first-order far field leaves an escaped ray beyond the tracer's region
    (``for_plan``)."""
    budget: float = math.inf
    """Integration error a traced pixel may keep before it is traced again (``for_plan``):
    tolerance_px less the far field's, at least a tenth of ``trace``; no limit without
    tolerance_px."""

    @classmethod
    def of(cls, tolerance: float, tolerance_px: float | None, pixel_angle: float) -> Tolerances:
        """The tolerances of a render asked for ``tolerance`` radians, or ``tolerance_px``
        pixels of ``pixel_angle`` radians (which then replaces it)."""
        if tolerance_px is None:
            return cls(pixel_angle, tolerance)
        trace = TRACE_SHARE * tolerance_px * pixel_angle
        interpolation = (1.0 - TRACE_SHARE) * tolerance_px * pixel_angle
        return cls(pixel_angle, trace, interpolation, tolerance_px)

    def narrowed(self, factor: float, tolerance: float) -> Tolerances:
        """The same in pixels ``factor`` (<= 1) times as wide (a moving camera's smallest
        Doppler factor); ``tolerance`` radians where none was given in pixels."""
        return Tolerances.of(tolerance, self.px, self.pixel_angle * factor)

    def for_plan(self, placed: Any, interpolate: bool = True) -> Tolerances:
        """With the far field and budget of a planned trace (a PlacedPlan or Tracer: its
        mass and region); interpolation only where rays bend and ``interpolate`` (0: the
        sampler traces every pixel)."""
        far_field = 0.0
        if placed.curved and placed.region is not None and placed.region.radius is not None:
            far_field = FAR_FIELD_CONSTANT * (placed.mass / placed.region.radius) ** 2
        budget = math.inf
        if self.px is not None:
            budget = max(self.px * self.pixel_angle - far_field, 0.1 * self.trace)
        interpolation = self.interpolation if placed.curved and interpolate else 0.0
        return replace(self, far_field=far_field, budget=budget, interpolation=interpolation)

"""The passes of a render, declared once: what each holds, its type, whether adaptive
sampling interpolates it, and where it goes.

core.render's frame buffers, the adaptive sampler's tiles, the add-on's render passes and its
passes EXR are all built from PASSES. Adding a pass means a row here and the code that
computes it (``traced_passes`` for rays through pixel centres, core.sampling for tiles).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .tracing.scene import ENDING


@dataclass(frozen=True)
class Pass:
    """One per-pixel output beside the colour."""

    name: str
    """The key in ``RenderResult.passes``."""
    dtype: Any
    """numpy type of its values."""
    fill: float
    """A pixel's value before anything is stored there (not rendered: cancelled)."""
    description: str
    channels: int = 1
    """Values per pixel: 1 (an (h, w) array) or 3 (an (h, w, 3) array)."""
    interpolated: bool = True
    """Whether an adaptive render (core.sampling) fills it at the pixels it interpolates
    rather than traces; False: there it keeps ``fill`` (only a traced pixel centre has
    one)."""
    derived_from: str | None = None
    """The stored pass it is computed from at the end (error_px: error in pixels); None:
    stored itself, chunk by chunk."""
    from_camera: bool = False
    """Computed at the end from each pixel centre's camera ray alone (doppler: the camera's
    motion), not stored."""
    label: str | None = None
    """The add-on's name for it ("SymRay <label>" render pass and passes-EXR layer, toggle
    ``pass_<label>``); None: a core-only pass."""
    shown: bool = False
    """Whether the add-on's toggle is on in a new scene."""
    on_request: bool = False
    """Computed only where asked for (not in core.render's DEFAULT_PASSES)."""
    held_on_request: bool = False
    """Stored per pixel only where asked for (the others are held for every render)."""
    per_ray: bool = False
    """Its value is the traced ray's own field of the same name (core.tracing.RayResults;
    and a sampler node's, core.sampling.lattice.Nodes): stored by ``traced_passes`` and
    the sampler without code of its own."""
    hits_only: bool = False
    """Held only where the ray hit a surface (``fill`` elsewhere)."""

    @property
    def working_dtype(self) -> Any:
        """The type the sampler computes it in: float64 for a float pass, else its own."""
        return np.float64 if np.issubdtype(self.dtype, np.floating) else self.dtype

    @property
    def layer(self) -> str | None:
        """Blender's render pass name (and the passes EXR's layer), e.g. 'SymRay Error'."""
        return None if self.label is None else f"SymRay {self.label}"

    @property
    def toggle(self) -> str | None:
        """The add-on's switch for it in ``scene.symray``, e.g. 'pass_error'."""
        return None if self.label is None else f"pass_{self.label.lower()}"

    def empty(self, n: int) -> np.ndarray:
        """Values of ``n`` pixels not rendered yet."""
        shape = (n,) if self.channels == 1 else (n, self.channels)
        return np.full(shape, self.fill, dtype=self.dtype)


PASSES: tuple[Pass, ...] = (
    Pass("error", np.float32, 0.0,
         "estimated final-direction error (radians): the integration's (Richardson, from a "
         "companion run at twice the step), the far field's and the interpolation's; +inf "
         "where a ray failed"),
    Pass("error_px", np.float32, 0.0,
         "per-pixel error estimate in pixels of this camera (integration, far field, hit "
         "point and interpolation)", derived_from="error", label="Error", shown=True),
    Pass("steps", np.int32, 0,
         "integration steps of the pixel's own ray; 0 where the pixel was interpolated "
         "from traced neighbours (no ray of its own: the adaptive sampler's smooth blocks)",
         interpolated=False, per_ray=True, label="Steps", shown=True),
    Pass("ending", np.int8, -1, "how each ray ended (core.ENDING code; -1: not rendered)",
         per_ray=True, label="Ending"),
    Pass("direction", np.float32, math.nan,
         "what each pixel's centre sees: the escape direction, or the unit vector to the hit "
         "point (NaN where captured or failed)", channels=3, on_request=True,
         held_on_request=True),
    Pass("position", np.float32, math.nan,
         "where each pixel's centre's ray ended on a surface (world coordinates; NaN where it "
         "hit nothing)", channels=3, on_request=True, per_ray=True, hits_only=True),
    Pass("redshift", np.float32, math.nan,
         "g = observed / emitted frequency where a ray ends on the accretion disk (or first "
         "crosses a translucent one; interpolated on an opaque one's smooth blocks), NaN "
         "elsewhere; it includes the doppler pass's g of a moving camera unless colours are "
         "not shifted (core.render's shift_colours)", per_ray=True, label="Redshift"),
    Pass("doppler", np.float32, math.nan,
         "g of the camera's motion along each pixel centre's ray (core.motion): the frequency "
         "it sees over the static (Kerr: zero-angular-momentum) observer's; 1 when static",
         interpolated=False, from_camera=True, on_request=True),
    Pass("magnification", np.float32, math.nan,
         "|μ| where a pixel centre sees the sky: how much brighter a point source (a star) "
         "looks in that image than without the hole, the pixel's solid angle over the sky's "
         "it covers (ray differentials carried through the integration; a moving camera's "
         "own solid angle); NaN where it sees no sky", on_request=True, held_on_request=True,
         per_ray=True, label="Magnification"),
    Pass("transmittance", np.float32, 1.0,
         "the share of the light behind (the sky, or what the ray ends on) that reaches the "
         "camera through what lies in front: volumes, a translucent disk; 1 where nothing "
         "(point stars are dimmed by it)", on_request=True, held_on_request=True, per_ray=True),
)  # fmt: skip
"""Every pass, in its one order."""

BY_NAME = {p.name: p for p in PASSES}
ALL_PASSES = tuple(p.name for p in PASSES)
STORED = tuple(p for p in PASSES if p.derived_from is None and not p.from_camera)
"""The passes held per pixel while a frame renders (the others are computed from them)."""


OPTIONAL = tuple(p.name for p in PASSES if p.held_on_request)
"""Stored passes held (and, magnification, computed) only where asked for."""
ON_REQUEST = tuple(p.name for p in PASSES if p.on_request)
"""Passes computed only when asked for."""
DEFAULT_PASSES = tuple(p.name for p in PASSES if not p.on_request)
"""The passes core.render computes unless asked otherwise."""


def traced_passes(rays: Any, seen: np.ndarray | None, error: np.ndarray | None) -> dict:
    """The stored passes of rays traced through pixel centres (a RayResults), by name:
    ``seen`` the directions they see (or None), ``error`` their estimate (or None)."""
    hit = rays.ending == ENDING["hit"]
    values = {}
    for kind in STORED:
        if not kind.per_ray:
            continue
        value = getattr(rays, kind.name)
        if kind.hits_only:
            value = np.where(hit if value.ndim == 1 else hit[:, None], value, kind.fill)
        values[kind.name] = value
    if seen is not None:
        values["direction"] = seen
    if error is not None:
        values["error"] = error
    return values

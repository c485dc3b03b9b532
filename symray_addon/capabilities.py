"""What each model of the panel can do, asked of the core model it stands for.

The panel's checks and sub-panels need to know, before the user's text is parsed, whether a
model has a mass, a Poincaré time scale, an explicit split, orbits a disk can follow, and
whether its rays start in an observer's frame. Each answer comes from the core: a stand-in of
the model's class (its traits do not depend on the user's expressions), built once.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

from ..core import hamiltonians as hm


@dataclass(frozen=True)
class Capabilities:
    """The traits of one panel model (``scene.symray.model``)."""

    observer: bool
    """Rays start in an observer's frame at the camera (a spacetime): camera checks apply."""
    mass: bool
    """A mass at the centre (its Schwarzschild Radius is used)."""
    time_scaled: bool
    """Traced in Poincaré time (methods that cannot follow it are refused)."""
    split: bool
    """An explicit split the splittings can take (below extremal, for Kerr)."""
    disk: bool
    """An accretion disk can orbit it."""


def _stand_in(model: str, below_extremal: bool):
    """A core model of the class the panel's ``model`` builds (None: flat space)."""
    if model == "SCHWARZSCHILD":
        return hm.schwarzschild(1.0)
    if model == "KERR":
        return hm.kerr(1.0, 0.25 if below_extremal else 0.5, chart="kerr_schild")
    if model == "MEDIUM":
        return hm.medium("1")
    if model == "METRIC":
        return hm.metric([["-1", "0", "0", "0"], ["0", "1", "0", "0"],
                          ["0", "0", "1", "0"], ["0", "0", "0", "1"]])  # fmt: skip
    if model == "CUSTOM":
        return hm.from_expression("0.5*(p_x**2 + p_y**2 + p_z**2)", q=["x", "y", "z"],
                                  p=["p_x", "p_y", "p_z"])  # fmt: skip
    return None


def capabilities(model: str, spin: float = 0.0) -> Capabilities:
    """The traits of the panel's ``model`` (a Kerr hole's split depends on |a/M| < 1)."""
    try:
        below_extremal = abs(float(spin)) < 1.0
    except (TypeError, ValueError):
        below_extremal = False
    return _capabilities(str(model), below_extremal)


@functools.cache
def _capabilities(model: str, below_extremal: bool) -> Capabilities:
    core_model = _stand_in(model, below_extremal)
    if core_model is None:
        return Capabilities(False, False, False, False, False)
    traced = core_model.for_backward_tracing(explicit_split=True)
    return Capabilities(
        observer=core_model.kind == "spacetime",
        mass=core_model.rg > 0,
        time_scaled=core_model.scales_time,
        split=traced.split_parts() is not None,
        disk=core_model.kerr_orbits() is not None,
    )

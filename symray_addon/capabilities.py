"""What each model of the panel can do: the traits its core ModelKind declares
(core.models.registry), read before the user's text is parsed."""

from __future__ import annotations

import functools
from dataclasses import dataclass

from ..core.models.registry import MODELS


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


def capabilities(model: str, spin: float = 0.0) -> Capabilities:
    """The traits of the panel's ``model`` (a Kerr hole's split depends on |a/M| < 1)."""
    try:
        below_extremal = abs(float(spin)) < 1.0
    except (TypeError, ValueError):
        below_extremal = False
    return _capabilities(str(model), below_extremal)


@functools.cache
def _capabilities(model: str, below_extremal: bool) -> Capabilities:
    kind = MODELS.get(model)
    if kind is None:  # Scene Objects before its objects are read, or an unknown name
        return Capabilities(False, False, False, False, False)
    traits = kind.traits
    return Capabilities(
        observer=traits.spacetime,
        mass=traits.mass,
        time_scaled=traits.time_scaled,
        split=traits.has_split(0.0 if below_extremal else 1.0),
        disk=traits.disk,
    )

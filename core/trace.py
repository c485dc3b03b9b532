"""The public name of :mod:`core.tracing` (Scene, Tracer, the step rule, ENDING, ...)."""

from . import tracing as _tracing
from .tracing import *  # noqa: F403 (a facade: every public name of core.tracing, one list)

__all__ = list(_tracing.__all__)

"""The public name of the models (``from core import hamiltonians as hm; hm.kerr(...)``).

The models live in :mod:`core.models`, one kind per module; this module re-exports them.
"""

from . import models as _models
from .models import *  # noqa: F403 (a facade: every public name of core.models, one list)

__all__ = list(_models.__all__)

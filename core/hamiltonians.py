"""The public name of the models (``from core import hamiltonians as hm; hm.kerr(...)``).

The models live in :mod:`core.models`, one kind per module; this module re-exports them.
"""

from .models import (
    BLOCK,
    ExpressionHamiltonian,
    FrozenQ,
    Hamiltonian,
    KerrSchild,
    Medium,
    MetricHamiltonian,
    Minkowski,
    SphericalSpacetime,
    blocked,
    from_expression,
    kerr,
    kerr_horizon,
    medium,
    metric,
    minkowski,
    schwarzschild,
)

__all__ = [
    "BLOCK",
    "ExpressionHamiltonian",
    "FrozenQ",
    "Hamiltonian",
    "KerrSchild",
    "Medium",
    "MetricHamiltonian",
    "Minkowski",
    "SphericalSpacetime",
    "blocked",
    "from_expression",
    "kerr",
    "kerr_horizon",
    "medium",
    "metric",
    "minkowski",
    "schwarzschild",
]

"""Hamiltonian models: user expressions, metrics (seed Eq. 10), black holes and media.

Every model is a :class:`Hamiltonian` (base.py), which is also an integration
:class:`~core.integrators.System`. One kind per module: ``expression`` (H as text),
``metric`` (H = 1/2 g^ij p_i p_j), ``spacetimes`` (Minkowski, Schwarzschild, Kerr),
``kerr_schild`` (Kerr in Kerr–Schild form, evaluated by hand), ``reissner_nordstrom`` (a
charged hole), ``kerr_newman`` (a charged rotating hole) and ``medium`` (optics).
``core.hamiltonians`` is the public name of this package's contents.

``registry`` declares the models a user picks by name (their parameters and traits):
``model_kind('KERR_NEWMAN').build(rg=1.0, spin=0.5, charge=0.3)`` builds any of them.

Signature (-, +, +, +) throughout; photons have H = 1/2 g^ij p_i p_j = 0.
"""

from ..integrators.system import FrozenQ
from .base import BLOCK, Hamiltonian, blocked
from .expression import ExpressionHamiltonian, from_expression
from .kerr_schild import KerrSchild
from .kerr_split import KerrBoyerLindquist
from .medium import Medium, medium
from .metric import MetricHamiltonian, metric
from .registry import MODELS, ModelKind, model_kind
from .reissner_nordstrom import ReissnerNordstrom, reissner_nordstrom
from .spacetimes import (
    Minkowski,
    SphericalSpacetime,
    kerr,
    kerr_horizon,
    minkowski,
    schwarzschild,
)

__all__ = [
    "BLOCK",
    "ExpressionHamiltonian",
    "FrozenQ",
    "Hamiltonian",
    "KerrBoyerLindquist",
    "KerrSchild",
    "MODELS",
    "Medium",
    "MetricHamiltonian",
    "ModelKind",
    "Minkowski",
    "ReissnerNordstrom",
    "SphericalSpacetime",
    "blocked",
    "from_expression",
    "kerr",
    "kerr_horizon",
    "medium",
    "metric",
    "minkowski",
    "model_kind",
    "reissner_nordstrom",
    "schwarzschild",
]

"""SymRay core: symplectic ray tracing in pure numpy (no Blender needed).

See DESIGN.md for the contract; ``import core; core.integrate(...)``.
"""

from . import dual, expressions, hamiltonians
from .expressions import ExpressionError

__all__ = ["dual", "expressions", "hamiltonians", "ExpressionError"]

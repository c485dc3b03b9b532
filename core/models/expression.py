"""H given as one expression of (q, p) over any coordinate and momentum names."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from .. import expressions as ex
from ..backend import array_module
from ..dual import Dual
from .base import Hamiltonian, _value_and_partials, blocked


class ExpressionHamiltonian(Hamiltonian):
    """H given as text over any coordinate and momentum names (any dimension)."""

    def __init__(
        self,
        text: str,
        coords,
        momenta,
        parameters=None,
        definitions=(),
        time_scale=None,
        positive: Sequence[str] = (),
    ):
        Hamiltonian.__init__(self, coords, momenta, parameters=parameters, time_scale=time_scale)
        names = self.coords + self.momenta
        self.text = text
        self.program = ex.compile_program([text], names, self.parameters, definitions)
        self.positive = tuple(positive)
        self.separable = _is_separable(
            text, self.coords, self.momenta, self.parameters, definitions
        )
        self.depends_on = self.program.dependencies[0]

    def _env(self, Q, P, wrt: str):
        env = {}
        for i, name in enumerate(self.coords):
            env[name] = Dual.variable(Q[i], i) if "q" in wrt else Q[i]
        for j, name in enumerate(self.momenta):
            env[name] = Dual.variable(P[j], self.dim + j) if "p" in wrt else P[j]
        return env

    def _evaluate(self, Q, P, wrt: str):
        env = self._env(Q, P, wrt)
        (h,) = self.program.evaluate(env)
        bad = self._invalid(env, Q)
        return h, bad

    def _invalid(self, env, Q):
        """Rays (of coordinates Q (n, N)) where a quantity that must be positive (e.g. n)
        is not: they get NaN."""
        bad, xp = None, array_module(Q)
        for name in self.positive:
            v = env[name]
            v = v.v if isinstance(v, Dual) else v
            mask = ~(xp.asarray(v) > 0)
            bad = mask if bad is None else (bad | mask)
        return None if bad is None else xp.broadcast_to(bad, (Q.shape[-1],))

    @blocked
    def value_soa(self, Q, P):
        h, bad = self._evaluate(Q, P, "")
        xp = array_module(Q)
        h = xp.array(xp.broadcast_to(xp.asarray(h), (Q.shape[-1],)), dtype=np.float64)
        if bad is not None:
            h[bad] = np.nan
        return h

    def _value_gradient(self, Q, P, wrt):
        h, bad = self._evaluate(Q, P, wrt)
        value, dq = _value_and_partials(h, self.dim, Q, 0)
        _, dp = _value_and_partials(h, self.dim, Q, self.dim)
        if bad is not None and bad.any():
            value = value.copy()
            value[bad] = np.nan
            dq[:, bad] = np.nan
            dp[:, bad] = np.nan
        return value, (dq if "q" in wrt else None), (dp if "p" in wrt else None)

    def partials_allocated(self, q, p) -> set[str]:
        """Names of the variables whose partial derivative H's evaluation carries."""
        Q, P, _ = self._soa(q, p)
        h, _ = self._evaluate(Q, P, "qp")
        names = self.coords + self.momenta
        return {names[k] for k in (h.d if isinstance(h, Dual) else {})}


def _is_separable(text, coords, momenta, parameters, definitions) -> bool:
    """True if H is a sum of terms each depending on q alone or on p alone."""
    terms = _additive_terms(text)
    prog = ex.compile_program(terms, tuple(coords) + tuple(momenta), parameters, definitions)
    qs, ps = set(coords), set(momenta)
    return all(dep <= qs or dep <= ps for dep in prog.dependencies)


def _additive_terms(text: str) -> list[str]:
    """Split text at its top-level + and - into terms (signs dropped: they don't matter)."""
    import ast

    tree = ex._parse(text).body
    terms: list[ast.AST] = []

    def walk(node):
        if isinstance(node, ast.BinOp) and isinstance(node.op, (ast.Add, ast.Sub)):
            walk(node.left)
            walk(node.right)
        elif isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
            walk(node.operand)
        else:
            terms.append(node)

    walk(tree)
    return [ast.unparse(t) for t in terms]


def from_expression(
    text: str,
    q: Sequence[str],
    p: Sequence[str],
    parameters: Mapping[str, float] | None = None,
    definitions: Mapping[str, str] | Sequence[tuple[str, str]] = (),
    time_scale: str | None = None,
) -> ExpressionHamiltonian:
    """H from text over coordinates ``q`` and momenta ``p`` (any names, any dimension)."""
    return ExpressionHamiltonian(text, q, p, parameters, definitions, time_scale)

"""A small, safe expression language for user text (Hamiltonians, n(x,y,z), g^ij).

Text is parsed with :mod:`ast` and checked against a whitelist: numbers, declared
names (variables, parameters, earlier definitions), the constants ``pi`` and ``e``,
``+ - * / **``, unary minus/plus, parentheses and the functions of
:data:`core.dual.FUNCTIONS`. Nothing is ever passed to ``eval``/``exec``: the checked
tree is turned into nested Python closures that call :mod:`core.dual`, so one compiled
expression evaluates floats, arrays or dual numbers.

Everything else (attribute access, subscripts, lambdas, comprehensions, calls of
anything not whitelisted, unknown names, non-ASCII characters, absurd sizes or nesting)
raises :class:`ExpressionError`, whose message names the problem and its column; no
other exception escapes, whatever the text (tests/core/test_expressions_fuzz.py).

(Over 400 lines on purpose: the whitelist, its checks and the compiler to closures are one
subject, and reading them together is how the language is audited.)
"""

from __future__ import annotations

import ast
import math
import unicodedata
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, NoReturn

import numpy as np

from . import dual

MAX_LENGTH = 20_000
"""Longest accepted text, in characters."""
MAX_NODES = 4_000
"""Most syntax-tree nodes in one expression."""
MAX_DEPTH = 100
"""Deepest accepted nesting of operations (each + - * / ** sign, call or unary sign is a
level: a sum of n terms nests n - 1 deep). Checking, compiling and evaluating recurse
about three frames per level, well inside Python's limit of 1000 frames."""
MAX_EXPONENT = 1_000.0
"""Largest accepted |constant exponent| (x**c)."""
CONSTANTS = {"pi": math.pi, "e": math.e}
_FOLD_ERRORS: dict[str, Any] = {
    "over": "raise",
    "divide": "raise",
    "invalid": "raise",
    "under": "ignore",
}
"""Folding a constant refuses overflow, division by zero and NaN; underflow to 0 is fine."""

_BINARY = {ast.Add: "+", ast.Sub: "-", ast.Mult: "*", ast.Div: "/", ast.Pow: "**"}
_REFUSED = {
    ast.Attribute: "attribute access",
    ast.Subscript: "subscripts",
    ast.Lambda: "lambdas",
    ast.ListComp: "comprehensions",
    ast.SetComp: "comprehensions",
    ast.DictComp: "comprehensions",
    ast.GeneratorExp: "comprehensions",
    ast.Compare: "comparisons",
    ast.BoolOp: "boolean operators",
    ast.IfExp: "conditionals",
    ast.List: "lists",
    ast.Tuple: "tuples",
    ast.Dict: "dicts",
    ast.Set: "sets",
    ast.JoinedStr: "strings",
    ast.Starred: "starred arguments",
    ast.NamedExpr: "assignments",
    ast.Await: "await",
    ast.Yield: "yield",
    ast.YieldFrom: "yield",
    ast.Slice: "slices",
}


class ExpressionError(ValueError):
    """User text that is not a valid expression; ``column`` is 1-based (or None)."""

    def __init__(self, problem: str, column: int | None = None, text: str | None = None):
        self.problem = problem
        self.column = column
        self.text = text
        where = f" at column {column}" if column is not None else ""
        super().__init__(f"{problem}{where}")


Evaluator = Callable[[Mapping[str, object]], Any]


@dataclass(frozen=True)
class Expression:
    """A checked, compiled expression: ``evaluate(env)`` and the names it reads."""

    text: str
    names: frozenset[str]
    evaluate: Evaluator
    constant: float | None = None

    def __call__(self, env: Mapping[str, object]):
        """Evaluate with ``env`` mapping every name in :attr:`names` to a value."""
        return self.evaluate(env)


def compile_expression(
    text: str, names: Iterable[str], parameters: Mapping[str, float] | None = None
) -> Expression:
    """Check ``text`` against the whitelist and compile it.

    ``names`` are the variables it may read (values come at evaluation time);
    ``parameters`` are named constants folded in at compile time.
    """
    if not isinstance(text, str):
        raise ExpressionError(f"expected text, got {type(text).__name__}")
    if len(text) > MAX_LENGTH:
        raise ExpressionError(
            f"expression is too long ({len(text)} > {MAX_LENGTH} characters)", 1, text
        )
    if not text.strip():
        raise ExpressionError("expression is empty", 1, text)
    _check_ascii(text)
    tree = _parse(text)
    count = sum(1 for _ in ast.walk(tree))
    if count > MAX_NODES:
        raise ExpressionError(
            f"expression is too large ({count} > {MAX_NODES} syntax nodes)", 1, text
        )
    _check_depth(tree.body)
    consts = dict(CONSTANTS)
    consts.update({k: float(v) for k, v in (parameters or {}).items()})
    builder = _Builder(frozenset(names), consts)
    node = builder.build(tree.body)
    const = node.value if node.is_constant else None
    return Expression(text, frozenset(builder.used), node.evaluator(), const)


def check(text: str, names: Iterable[str], parameters: Mapping[str, float] | None = None) -> None:
    """Raise :class:`ExpressionError` if ``text`` is not a valid expression over ``names``."""
    compile_expression(text, names, parameters)


def _check_ascii(text: str) -> None:
    """Refuse any character outside ASCII, naming it and its column.

    Python reads identifiers through NFKC normalisation ('ｘ' is 'x', 'ｓｉｎ' is 'sin'),
    so accepting them would run text whose meaning differs from what is displayed.
    """
    bad = next((i for i, ch in enumerate(text) if ord(ch) > 127), None)
    if bad is None:
        return
    char = text[bad]
    name = unicodedata.name(char, "unnamed character")
    column = bad - (text.rfind("\n", 0, bad) + 1) + 1
    raise ExpressionError(
        f"non-ASCII character '{char}' (U+{ord(char):04X} {name}) not "
        "allowed: type names, digits and operators in plain ASCII",
        column,
        text,
    )


def _parse(text: str) -> ast.Expression:
    """ast.parse in eval mode, turning every parser failure into ExpressionError."""
    try:
        return ast.parse(text, mode="eval")
    except SyntaxError as err:
        column = err.offset if err.offset else None
        raise ExpressionError(f"syntax error: {err.msg}", column, text) from None
    except (RecursionError, MemoryError):  # the parser's own stack (deep nesting)
        raise ExpressionError(
            f"expression is nested too deeply to parse (at most {MAX_DEPTH} levels)", 1, text
        ) from None
    except (ValueError, OverflowError) as err:
        raise ExpressionError(f"cannot parse expression: {err}", 1, text) from None


def _check_depth(root: ast.AST) -> None:
    """Refuse nesting deeper than MAX_DEPTH (iteratively: any depth is safe to check)."""
    stack = [(root, 0)]
    while stack:
        node, depth = stack.pop()
        if not isinstance(node, ast.expr) or isinstance(node, (ast.Name, ast.Constant)):
            continue  # leaves, and operator / context markers
        if depth >= MAX_DEPTH:
            raise ExpressionError(
                f"expression is nested too deeply (more than {MAX_DEPTH} levels; a chain of "
                f"n operators such as + counts n): group long sums in parentheses",
                node.col_offset + 1,
            )  # an ast.expr always has a position
        stack.extend((child, depth + 1) for child in ast.iter_child_nodes(node))


@dataclass
class _Node:
    """A compiled subtree: either a folded constant or an evaluator closure."""

    value: float | None = None
    fn: Evaluator | None = None

    @property
    def is_constant(self) -> bool:
        return self.fn is None

    @property
    def number(self) -> float:
        """The folded constant (only for is_constant nodes)."""
        assert self.value is not None
        return self.value

    def evaluator(self) -> Evaluator:
        if self.fn is not None:
            return self.fn
        value = self.value
        return lambda env: value


class _Builder:
    """Walks a parsed tree, refusing anything off the whitelist, folding constants."""

    def __init__(self, names: frozenset[str], constants: Mapping[str, float]):
        self.names = names
        self.constants = constants
        self.used: set[str] = set()

    def fail(self, node: ast.AST, problem: str) -> NoReturn:
        # not every AST node has a position (ast.AST has no col_offset: only expressions
        # and statements do); -1 + 1 = 0 means "no column"
        column = getattr(node, "col_offset", -1) + 1
        if isinstance(node, ast.Attribute) and node.end_col_offset is not None:
            column = node.end_col_offset - len(node.attr)  # the '.' before the name
        raise ExpressionError(problem, column)

    def build(self, node: ast.AST) -> _Node:
        if isinstance(node, ast.Constant):
            return self.constant(node)
        if isinstance(node, ast.Name):
            return self.name(node)
        if isinstance(node, ast.BinOp):
            return self.binary(node)
        if isinstance(node, ast.UnaryOp):
            return self.unary(node)
        if isinstance(node, ast.Call):
            return self.call(node)
        kind = _REFUSED.get(type(node), type(node).__name__)
        self.fail(node, f"{kind} not allowed")

    def constant(self, node: ast.Constant) -> _Node:
        value = node.value
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            self.fail(node, f"constant {value!r} not allowed (only real numbers)")
        try:
            number = float(value)
        except OverflowError:
            self.fail(node, "number too large")
        if not math.isfinite(number):
            self.fail(node, "number too large")
        return _Node(value=number)

    def name(self, node: ast.Name) -> _Node:
        ident = node.id
        if ident in self.names:
            self.used.add(ident)
            return _Node(fn=lambda env: env[ident])
        if ident in self.constants:
            return _Node(value=self.constants[ident])
        allowed = ", ".join(sorted(self.names | set(self.constants)))
        self.fail(node, f"unknown name '{ident}' (allowed: {allowed})")

    def unary(self, node: ast.UnaryOp) -> _Node:
        operand = self.build(node.operand)
        if isinstance(node.op, ast.UAdd):
            return operand
        if not isinstance(node.op, ast.USub):
            self.fail(node, f"operator {type(node.op).__name__} not allowed")
        if operand.is_constant:
            return _Node(value=-operand.number)
        fn = operand.evaluator()
        return _Node(fn=lambda env: -fn(env))

    def binary(self, node: ast.BinOp) -> _Node:
        symbol = _BINARY.get(type(node.op))
        if symbol is None:
            self.fail(node, f"operator {type(node.op).__name__} not allowed")
        left, right = self.build(node.left), self.build(node.right)
        if symbol == "**" and right.is_constant and abs(right.number) > MAX_EXPONENT:
            self.fail(node, f"exponent {right.number:g} too large (limit {MAX_EXPONENT:g})")
        if left.is_constant and right.is_constant:
            return _Node(value=self.fold(node, symbol, left.number, right.number))
        return _Node(fn=_binary_closure(symbol, left, right))

    def fold(self, node: ast.AST, symbol: str, a: float, b: float) -> float:
        try:
            with np.errstate(**_FOLD_ERRORS):
                value = float(_apply(symbol, np.float64(a), np.float64(b)))
        except (FloatingPointError, ZeroDivisionError, OverflowError):
            self.fail(node, f"constant '{a:g} {symbol} {b:g}' is not a finite real number")
        if not math.isfinite(value):
            self.fail(node, f"constant '{a:g} {symbol} {b:g}' is not a finite real number")
        return value

    def call(self, node: ast.Call) -> _Node:
        if not isinstance(node.func, ast.Name):
            kind = _REFUSED.get(type(node.func), "calling an expression")
            self.fail(node.func, f"{kind} not allowed")
        fname = node.func.id
        if fname not in dual.FUNCTIONS:
            allowed = ", ".join(sorted(dual.FUNCTIONS))
            self.fail(node, f"unknown function '{fname}' (allowed: {allowed})")
        if node.keywords:
            self.fail(node, f"keyword arguments not allowed in {fname}()")
        arity = dual.FUNCTION_ARITY[fname]
        if len(node.args) != arity:
            self.fail(node, f"{fname}() takes {arity} argument(s), got {len(node.args)}")
        args = [self.build(a) for a in node.args]
        func = dual.FUNCTIONS[fname]
        if all(a.is_constant for a in args):
            try:
                with np.errstate(**_FOLD_ERRORS):
                    value = float(func(*[np.float64(a.value) for a in args]))
            except (FloatingPointError, OverflowError):
                value = math.nan
            if not math.isfinite(value):
                self.fail(node, f"constant {fname}(...) is not a finite real number")
            return _Node(value=value)
        fns = [a.evaluator() for a in args]
        if arity == 1:
            (f0,) = fns
            return _Node(fn=lambda env: func(f0(env)))
        f0, f1 = fns
        return _Node(fn=lambda env: func(f0(env), f1(env)))


def _apply(symbol: str, a, b):
    """One binary operation on values, floats, arrays or Duals."""
    if symbol == "+":
        return a + b
    if symbol == "-":
        return a - b
    if symbol == "*":
        return a * b
    if symbol == "/":
        return a / b
    return dual.power(a, b) if not isinstance(b, dual.Dual) else a**b


def _binary_closure(symbol: str, left: _Node, right: _Node) -> Evaluator:
    """A closure for ``left (symbol) right`` with constant operands baked in."""
    lf, rf = left.evaluator(), right.evaluator()
    if symbol == "**" and right.is_constant:
        c = right.value
        return lambda env: dual.power(lf(env), c)
    if symbol == "**":
        return lambda env: _pow_general(lf(env), rf(env))
    op = {"+": _add, "-": _sub, "*": _mul, "/": _div}[symbol]
    if right.is_constant:
        c = right.value
        return lambda env: op(lf(env), c)
    if left.is_constant:
        c = left.value
        return lambda env: op(c, rf(env))
    return lambda env: op(lf(env), rf(env))


def _add(a, b):
    return a + b


def _sub(a, b):
    return a - b


def _mul(a, b):
    return a * b


def _div(a, b):
    return a / b


def _pow_general(base, exponent):
    """base ** exponent where the exponent is not a compile-time constant."""
    if isinstance(exponent, dual.Dual):
        return dual.exp(exponent * dual.log(base))
    if isinstance(base, dual.Dual):
        return dual.Dual(
            np.power(base.v, exponent),
            dual._scale(base.d, exponent * np.power(base.v, exponent - 1.0)),
        )
    return np.power(base, exponent)


@dataclass(frozen=True)
class Program:
    """Named definitions evaluated in order, then outputs: shared subexpressions once."""

    definitions: tuple[tuple[str, Expression], ...]
    outputs: tuple[Expression, ...]
    dependencies: tuple[frozenset[str], ...]
    """For each output, the input variables it depends on (through definitions)."""

    def evaluate(self, env: dict[str, object]) -> list:
        """Evaluate every output; ``env`` holds the inputs and receives the definitions."""
        for name, expr in self.definitions:
            env[name] = expr.evaluate(env)
        return [out.evaluate(env) for out in self.outputs]


def kink_arguments(text: str) -> list[str]:
    """The arguments of every ``abs(...)`` in ``text`` (already checked: compile it first),
    as text: where each changes sign the expression has a kink (a jump in its slope)."""
    tree = _parse(text)
    return [
        ast.unparse(node.args[0])
        for node in ast.walk(tree)
        if isinstance(node, ast.Call)
        and isinstance(node.func, ast.Name)
        and node.func.id == "abs"
        and len(node.args) == 1
    ]


def compile_program(
    outputs: Sequence[str],
    variables: Sequence[str],
    parameters: Mapping[str, float] | None = None,
    definitions: Sequence[tuple[str, str]] | Mapping[str, str] = (),
) -> Program:
    """Compile outputs over ``variables`` that may use named ``definitions`` (in order)."""
    items = list(definitions.items()) if isinstance(definitions, Mapping) else list(definitions)
    reserved = set(variables) | set(CONSTANTS) | set(parameters or {}) | set(dual.FUNCTIONS)
    known = list(variables)
    compiled_defs = []
    depends: dict[str, frozenset[str]] = {v: frozenset([v]) for v in variables}
    for name, text in items:
        if not name.isidentifier() or name in reserved or name in known:
            raise ExpressionError(f"definition name '{name}' is not a new identifier")
        expr = _compile_labelled(text, known, parameters, f"definition '{name}'")
        compiled_defs.append((name, expr))
        depends[name] = frozenset().union(*(depends[n] for n in expr.names))
        known.append(name)
    outs = tuple(
        _compile_labelled(t, known, parameters, f"output {i + 1}") for i, t in enumerate(outputs)
    )
    deps = tuple(frozenset().union(*(depends[n] for n in o.names)) for o in outs)
    return Program(tuple(compiled_defs), outs, deps)


def _compile_labelled(text, names, parameters, label) -> Expression:
    """compile_expression whose error message says which piece of text failed."""
    try:
        return compile_expression(text, names, parameters)
    except ExpressionError as err:
        raise ExpressionError(f"{label}: {err.problem}", err.column, text) from None

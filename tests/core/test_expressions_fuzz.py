"""Property-based fuzzing of the expression language (Hypothesis).

Random texts: compiling either succeeds or raises ExpressionError (never another
exception) and never executes anything. Random syntax trees: an accepted expression
evaluates to exactly what an independent reference evaluator (written here, from the
language's documented rules) gives; a refused one contains a constant that is not a
finite real number or an exponent over the limit. Settings are derandomised: the same
examples run every time, in a few seconds.
"""

from __future__ import annotations

import ast
import builtins
import math
from contextlib import contextmanager
from unittest import mock

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from core import expressions as ex

SETTINGS = settings(
    max_examples=400,
    derandomize=True,
    deadline=None,
    database=None,
    suppress_health_check=[HealthCheck.too_slow],
)
NAMES = ("x", "y")
ENV = {"x": np.array([-2.5, 0.3, 1.7, 0.0]), "y": np.array([0.5, -1.2, 3.0, 1e-3])}
UNARY_FUNCTIONS = {
    "sqrt": np.sqrt,
    "exp": np.exp,
    "log": np.log,
    "sin": np.sin,
    "cos": np.cos,
    "tan": np.tan,
    "arcsin": np.arcsin,
    "asin": np.arcsin,
    "arccos": np.arccos,
    "acos": np.arccos,
    "arctan": np.arctan,
    "atan": np.arctan,
    "sinh": np.sinh,
    "cosh": np.cosh,
    "tanh": np.tanh,
    "abs": np.abs,
}
BINARY_FUNCTIONS = {"arctan2": np.arctan2, "atan2": np.arctan2}
OPERATORS = {"+": ast.Add, "-": ast.Sub, "*": ast.Mult, "/": ast.Div, "**": ast.Pow}

# -- random trees: ("name", n) | ("num", v) | ("neg"|"pos", a) | (op, a, b) | ("call", f, *args)

_leaves = st.one_of(
    st.sampled_from(NAMES + ("pi", "e")).map(lambda n: ("name", n)),
    st.integers(0, 12).map(lambda v: ("num", float(v))),
    st.sampled_from([0.5, -1.0, 2.0, 3.0, 1e-300, 1e300, 1500.0]).map(lambda v: ("num", v)),
    st.floats(0.0, 1e3, allow_nan=False).map(lambda v: ("num", v)),
)


def _extend(children):
    return st.one_of(
        st.tuples(st.sampled_from(["neg", "pos"]), children),
        st.tuples(st.sampled_from(list(OPERATORS)), children, children),
        st.tuples(st.just("call"), st.sampled_from(list(UNARY_FUNCTIONS)), children),
        st.tuples(st.just("call"), st.sampled_from(list(BINARY_FUNCTIONS)), children, children),
    )


TREES = st.recursive(_leaves, _extend, max_leaves=10)


def to_ast(tree) -> ast.expr:
    """The Python syntax tree of a random tree (printed by ast.unparse: fewest brackets)."""
    kind = tree[0]
    if kind == "name":
        return ast.Name(tree[1], ast.Load())
    if kind == "num":
        return (
            ast.UnaryOp(ast.USub(), ast.Constant(-tree[1]))
            if tree[1] < 0
            else ast.Constant(tree[1])
        )
    if kind in ("neg", "pos"):
        return ast.UnaryOp(ast.USub() if kind == "neg" else ast.UAdd(), to_ast(tree[1]))
    if kind == "call":
        return ast.Call(ast.Name(tree[1], ast.Load()), [to_ast(a) for a in tree[2:]], [])
    return ast.BinOp(to_ast(tree[1]), OPERATORS[kind](), to_ast(tree[2]))


def bracketed(tree) -> str:
    """The text of a random tree with every operation in brackets and odd spacing."""
    kind = tree[0]
    if kind == "name":
        return tree[1]
    if kind == "num":
        return f"(-{-tree[1]!r})" if tree[1] < 0 else repr(tree[1])
    if kind in ("neg", "pos"):
        return f"({'-' if kind == 'neg' else '+'} {bracketed(tree[1])})"
    if kind == "call":
        return f"{tree[1]}( {' ,'.join(bracketed(a) for a in tree[2:])} )"
    return f"({bracketed(tree[1])}{kind}  {bracketed(tree[2])})"


class Refused(Exception):
    """The reference says the language refuses this tree."""


def _power(base, exponent, constant_exponent: bool):
    """The language's **: a constant exponent 2, 3, 1, -1, 0.5 means products, 1/x, sqrt."""
    if not constant_exponent:
        return np.power(base, exponent)
    special = {
        2.0: lambda b: b * b,
        3.0: lambda b: b * b * b,
        1.0: lambda b: b,
        -1.0: lambda b: 1.0 / b,
        0.5: np.sqrt,
    }
    rule = special.get(float(exponent))
    return rule(base) if rule is not None else np.power(base, exponent)


def reference(tree, env) -> tuple[object, bool]:
    """(value, whether it is a constant) by the language's rules; Refused where it refuses.

    Every subtree without a variable is a constant and must be a finite real number;
    a constant exponent is at most ex.MAX_EXPONENT in size.
    """
    kind = tree[0]
    if kind == "name":
        if tree[1] in env:
            return env[tree[1]], False
        return np.float64({"pi": math.pi, "e": math.e}[tree[1]]), True
    if kind == "num":
        return np.float64(tree[1]), True
    if kind in ("neg", "pos"):
        value, constant = reference(tree[1], env)
        return (-value if kind == "neg" else value), constant
    args = [reference(a, env) for a in tree[2:] if kind == "call"] or [
        reference(tree[1], env),
        reference(tree[2], env),
    ]
    constant = all(c for _, c in args)
    values = [v for v, _ in args]
    if kind == "call":
        func = UNARY_FUNCTIONS.get(tree[1]) or BINARY_FUNCTIONS[tree[1]]
        value = func(*values)
    elif kind == "**":
        if args[1][1] and abs(values[1]) > ex.MAX_EXPONENT:
            raise Refused("exponent too large")
        value = _power(values[0], values[1], args[1][1])
    else:
        a, b = values
        value = {"+": a + b, "-": a - b, "*": a * b}[kind] if kind != "/" else a / b
    if constant and not np.isfinite(value):
        raise Refused("a constant is not a finite real number")
    return value, constant


@contextmanager
def nothing_executes():
    """eval/exec refuse to run; compile may only build syntax trees."""
    real_compile = builtins.compile

    def only_ast(source, filename, mode, flags=0, *args, **kwargs):
        assert flags & ast.PyCF_ONLY_AST, "compile() asked for code, not a syntax tree"
        return real_compile(source, filename, mode, flags, *args, **kwargs)

    def refuse(*_args, **_kwargs):
        raise AssertionError("eval/exec called")

    with (
        mock.patch.object(builtins, "eval", refuse),
        mock.patch.object(builtins, "exec", refuse),
        mock.patch.object(builtins, "compile", only_ast),
    ):
        yield


def _compile_or_refuse(text: str):
    """compile_expression's result, or None if it raised ExpressionError (with a column
    that is None or a 1-based position in the text)."""
    try:
        with nothing_executes():
            return ex.compile_expression(text, NAMES)
    except ex.ExpressionError as err:
        assert str(err).startswith(err.problem) and err.problem
        assert err.column is None or 1 <= err.column <= max(len(text), 1)
        return None


EXPRESSION_ALPHABET = st.sampled_from(
    list("xy0123456789.+-*/() ,e_ijpsqrtnaolcb'\"[]:=<>!&|^%@~#\\\n\t;{}`$?")
    + [
        "**",
        "sin(",
        "sqrt(",
        "__import__",
        "lambda",
        "pi",
        "1e308",
        "ｘ",
        "−",
        "\u00a0",
        "\u0301",
        "ﬁ",
        "\U0001d465",
        "\x00",
    ]
)


@SETTINGS
@given(st.one_of(st.lists(EXPRESSION_ALPHABET, max_size=30).map("".join), st.text(max_size=30)))
def test_random_text_is_compiled_or_refused_with_an_expression_error(text):
    compiled = _compile_or_refuse(text)
    if compiled is not None:
        assert text.isascii(), "accepted text holding non-ASCII characters"
        assert compiled.names <= set(NAMES)
        with np.errstate(all="ignore"):
            value = compiled({name: ENV[name] for name in compiled.names})
        assert np.shape(value) in ((), (4,))


@SETTINGS
@given(TREES, st.booleans())
def test_random_trees_evaluate_as_the_reference_says(tree, minimal_brackets):
    text = ast.unparse(to_ast(tree)) if minimal_brackets else bracketed(tree)
    try:
        with np.errstate(all="ignore"):
            expected, _ = reference(tree, ENV)
    except Refused:
        expected = None
    compiled = _compile_or_refuse(text)
    assert (compiled is None) == (expected is None), text
    if compiled is not None:
        with np.errstate(all="ignore"):
            got = compiled(ENV)
        np.testing.assert_array_equal(
            np.broadcast_to(got, (4,)), np.broadcast_to(expected, (4,)), err_msg=text
        )

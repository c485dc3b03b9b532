"""The expression language: correct values, and refusal of everything off the whitelist."""

import numpy as np
import pytest

from core import expressions as ex
from core import hamiltonians as hm
from core.dual import Dual


def test_values_and_gradients_match_python_math():
    e = ex.compile_expression("p*q*(p + q - 1) + sin(pi*q)**2 - e**-q + arctan2(p, 2)", ["q", "p"])
    q, p = np.array([0.2, 0.5]), np.array([0.3, -0.7])
    expected = p * q * (p + q - 1) + np.sin(np.pi * q) ** 2 - np.e**-q + np.arctan2(p, 2)
    np.testing.assert_allclose(e({"q": q, "p": p}), expected, rtol=1e-15)
    got = e({"q": Dual.variable(q, 0), "p": p})
    dq = p * (p + q - 1) + p * q + 2 * np.pi * np.sin(np.pi * q) * np.cos(np.pi * q) + np.e**-q
    np.testing.assert_allclose(got.d[0], dq, rtol=1e-14)
    assert e.names == {"q", "p"}


def test_parameters_and_definitions_fold_and_share():
    prog = ex.compile_program(
        ["f * p_x"],
        ["x", "p_x"],
        {"rg": 2.0},
        definitions=[("r", "sqrt(x**2 + 1)"), ("f", "rg / r")],
    )
    out = prog.evaluate({"x": np.array([0.0, 1.0]), "p_x": np.array([1.0, 2.0])})[0]
    np.testing.assert_allclose(out, [2.0, 2 * 2 / np.sqrt(2)])
    assert prog.dependencies == (frozenset({"x", "p_x"}),)


@pytest.mark.parametrize(
    "text, problem, column",
    [
        ("__import__('os').system('echo hacked')", "attribute access", 17),
        ("x.real", "attribute access", 2),
        ("x[0]", "subscripts", 1),
        ("(lambda: 1)()", "lambdas", 2),
        ("lambda: 1", "lambdas", 1),
        ("[x for x in y]", "comprehensions", 1),
        ("x + foo", "unknown name 'foo'", 5),
        ("open('f')", "unknown function 'open'", 1),
        ("x +* 2", "syntax error", None),
        ("9**9**9", "too large", 1),
        ("10**400", "not a finite real number", 1),
        ("x if x else 1", "conditionals", 1),
        ("'text'", "only real numbers", 1),
        ("sin(x, x)", "takes 1 argument", 1),
        ("1/0 + x", "not a finite real number", 1),
        ("", "empty", 1),
    ],
)
def test_refused_with_problem_and_column(text, problem, column):
    # (no wall-clock assert: "9**9**9" refused as "too large" shows nothing was computed)
    with pytest.raises(ex.ExpressionError) as info:
        ex.compile_expression(text, ["x", "y"])
    assert problem in str(info.value)
    if column is not None:
        assert info.value.column == column
        assert f"column {column}" in str(info.value)


def test_nothing_runs_while_refusing(tmp_path, monkeypatch):
    """The classic payload must not execute: no file appears, no import happens."""
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ex.ExpressionError):
        ex.compile_expression("__import__('os').system('touch pwned')", ["x"])
    assert not (tmp_path / "pwned").exists()


def test_absurd_sizes_refused():
    for text, problem in [
        ("x" + "+x" * 30_000, "too long"),
        ("(" * 500 + "x" + ")" * 500, "nested"),
        ("1" * 5000, "digits"),
    ]:
        with pytest.raises(ex.ExpressionError, match=problem):
            ex.compile_expression(text, ["x"])


def test_definition_names_must_be_new():
    with pytest.raises(ex.ExpressionError, match="not a new identifier"):
        ex.compile_program(["x"], ["x"], definitions=[("x", "1")])
    with pytest.raises(ex.ExpressionError, match="definition 'r': unknown name 'q'"):
        ex.compile_program(["r"], ["x"], definitions=[("r", "q + 1")])


@pytest.mark.parametrize(
    "text, column",
    [
        ("+".join(["x"] * 500), 1),  # 999 characters; a left-nested chain of 499 sums
        ("-" * 500 + "x", 101),  # the 101st sign
        ("**".join(["x"] * 400), 301),  # the 101st power, right-nested
        ("-" * 19_999 + "x", 1),  # deeper than Python's parser's own stack
        ("+".join(["x"] * 9_000), 1),  # Python 3.11: deeper than its limit for the tree
    ],
)
def test_deep_nesting_is_refused_with_problem_and_column(text, column):
    """Deep nesting is an ExpressionError naming it, never a RecursionError."""
    with pytest.raises(ex.ExpressionError) as info:
        ex.compile_expression(text, ["x"])
    assert "nested too deeply" in info.value.problem or "too large" in info.value.problem
    assert info.value.column == column and f"at column {column}" in str(info.value)


def test_a_custom_hamiltonian_with_a_500_term_sum_is_refused():
    with pytest.raises(ex.ExpressionError, match="nested too deeply"):
        hm.from_expression("+".join(["p_x**2"] * 500), ["x"], ["p_x"])


def _deep_in_the_stack(frames: int, call):
    """call() from ``frames`` frames further down the stack (as in Blender's threads)."""
    return call() if frames == 0 else _deep_in_the_stack(frames - 1, call)


def test_nesting_at_the_limit_compiles_and_evaluates_far_down_the_stack():
    levels = ex.MAX_DEPTH
    x = np.array([0.3, 1.2])
    total = x
    for _ in range(levels):
        total = total + x
    cases = {
        "+".join(["x"] * (levels + 1)): total,
        "-" * levels + "x": x,  # an even number of signs
        "**".join(["x"] + ["1"] * levels): x,
        "sin(" * (levels - 1) + "x" + ")" * (levels - 1): x,
    }
    iterated = x
    for _ in range(levels - 1):
        iterated = np.sin(iterated)
    cases["sin(" * (levels - 1) + "x" + ")" * (levels - 1)] = iterated
    for text, expected in cases.items():
        compiled = _deep_in_the_stack(500, lambda t=text: ex.compile_expression(t, ["x"]))
        value = _deep_in_the_stack(500, lambda c=compiled: c({"x": Dual.variable(x, 0)}))
        np.testing.assert_allclose(value.v, expected, rtol=1e-15)
    h = _deep_in_the_stack(
        500, lambda: hm.from_expression("+".join(["p_x**2"] * levels), ["x"], ["p_x"])
    )  # 99 sums of a power: 100 levels
    np.testing.assert_allclose(
        h.value(np.zeros((2, 1)), x[:, None]), levels * x**2, rtol=1e-13
    )  # 100 roundings of a sum against one product


@pytest.mark.parametrize(
    "text, char, column",
    [
        ("ｘ + 1", "ｘ", 1),  # fullwidth x: NFKC would read it as x
        ("1 + ｓｉｎ(x)", "ｓ", 5),
        ("x − 1", "−", 3),  # the minus sign U+2212
        ("x\u00a0+ 1", "\u00a0", 2),  # no-break space
        ("\U0001d465 * 2", "\U0001d465", 1),  # mathematical italic x
    ],
)
def test_non_ascii_text_is_refused_naming_the_character(text, char, column):
    """'ｘ' and 'ｓｉｎ' are refused by name, never read as 'x' and 'sin'."""
    with pytest.raises(ex.ExpressionError) as info:
        ex.compile_expression(text, ["x"])
    assert f"non-ASCII character '{char}' (U+{ord(char):04X}" in info.value.problem
    assert info.value.column == column


def test_constants_that_underflow_to_zero_are_accepted():
    assert (
        ex.compile_expression("x + exp(-800) + 1e-200 * 1e-200", ["x"]).evaluate({"x": 1.5}) == 1.5
    )

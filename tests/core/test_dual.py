"""Dual numbers: every operation's derivative against central finite differences."""

import numpy as np
import pytest

from core import dual
from core.dual import Dual

X = np.array([0.3, 0.7, 1.9, 2.6])
UNIT = np.array([-0.8, -0.2, 0.35, 0.9])  # inside (-1, 1) for arcsin/arccos


def numeric_derivative(f, x, h=1e-6):
    """Richardson-extrapolated central difference (error ~h^4)."""
    d1 = (f(x + h) - f(x - h)) / (2 * h)
    d2 = (f(x + 2 * h) - f(x - 2 * h)) / (4 * h)
    return (4 * d1 - d2) / 3


@pytest.mark.parametrize(
    "name", ["sqrt", "exp", "log", "sin", "cos", "tan", "arctan", "sinh", "cosh", "tanh", "abs"]
)
def test_unary_derivatives_match_finite_differences(name):
    f = dual.FUNCTIONS[name]
    x = X if name != "abs" else UNIT
    got = f(Dual.variable(x, 0))
    np.testing.assert_allclose(got.v, f(x), rtol=1e-15)
    np.testing.assert_allclose(got.d[0], numeric_derivative(f, x), rtol=1e-8)


@pytest.mark.parametrize("name", ["arcsin", "arccos"])
def test_inverse_trig_derivatives(name):
    f = dual.FUNCTIONS[name]
    got = f(Dual.variable(UNIT, 0))
    np.testing.assert_allclose(got.d[0], numeric_derivative(f, UNIT), rtol=1e-8)


def test_arithmetic_and_powers():
    """+ - * / and ** with integer, real and dual exponents, on two variables."""

    def f(x, y):
        return (x * y - y / x + 3.0) ** 3 / (2.0 - y) + x**0.5 * y**-2 + x**y - 2.0**y

    x0, y0 = np.array([0.5, 1.3]), np.array([0.2, 0.9])
    got = f(Dual.variable(x0, 0), Dual.variable(y0, 1))
    np.testing.assert_allclose(got.v, f(x0, y0), rtol=1e-14)
    np.testing.assert_allclose(got.d[0], numeric_derivative(lambda x: f(x, y0), x0), rtol=1e-8)
    np.testing.assert_allclose(got.d[1], numeric_derivative(lambda y: f(x0, y), y0), rtol=1e-8)


def test_arctan2_all_quadrants():
    ang = np.linspace(-3.0, 3.0, 7)
    x0, y0 = 2.0 * np.cos(ang), 2.0 * np.sin(ang)
    got = dual.arctan2(Dual.variable(y0, 0), Dual.variable(x0, 1))
    np.testing.assert_allclose(got.v, ang, rtol=1e-14)
    np.testing.assert_allclose(got.d[0], x0 / 4.0, atol=1e-15)
    np.testing.assert_allclose(got.d[1], -y0 / 4.0, atol=1e-15)


def test_partials_are_structurally_sparse():
    """A quantity carries only the partials it depends on; seeds allocate no arrays."""
    r, theta, phi = (Dual.variable(np.full(5, v), i) for i, v in enumerate((3.0, 1.0, 0.5), 1))
    g = 1.0 / (r * r * dual.sin(theta) ** 2)
    assert set(g.d) == {1, 2}
    assert isinstance(phi.d[3], float)  # a scalar seed, not an array
    assert set((phi * 2.0 + 1.0).d) == {3}


def test_abs_kink_uses_zero_derivative():
    got = dual.absolute(Dual.variable(np.array([-1.0, 0.0, 2.0]), 0))
    np.testing.assert_array_equal(got.d[0], [-1.0, 0.0, 1.0])


def test_numpy_arrays_on_the_left_defer_to_dual():
    x = Dual.variable(np.array([1.0, 2.0]), 0)
    got = np.array([3.0, 4.0]) * x + np.array([1.0, 1.0])
    assert isinstance(got, Dual)
    np.testing.assert_array_equal(got.d[0], [3.0, 4.0])

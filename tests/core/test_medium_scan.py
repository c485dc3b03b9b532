"""Poles of a medium's n found in its box before tracing (core/models/medium_scan.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from core import hamiltonians as hm
from core.models.medium_scan import index_pole

BOX = ((-10.0, -10.0, -10.0), (10.0, 10.0, 10.0))


@pytest.mark.parametrize(
    "text, where",
    [
        # the old Add › Medium default: a double pole at z = -0.15 ln(1 + 1/0.003)
        ("1/(1 + 0.003*(1 - exp(-z/0.15)))**2", (0.0, 0.0, -0.15 * math.log(1 + 1 / 0.003))),
        ("1/(z + 0.87)", (0.0, 0.0, -0.87)),  # a simple pole: n changes sign across it
        ("1/(x - 0.3 + y)**2", None),  # a plane of poles: the one nearest the centre
    ],
)
def test_a_pole_in_the_box_is_found_where_it_is(text, where):
    pole = index_pole(hm.medium(text, bounds=BOX), *BOX)
    assert pole is not None
    point, n = pole
    assert n > 1e9
    if where is None:
        assert point[0] + point[1] == pytest.approx(0.3, abs=1e-6)
        assert np.linalg.norm(point) < 1.0  # near the centre: within a grid cell of it
    else:
        assert point[2] == pytest.approx(where[2], abs=1e-6)


@pytest.mark.parametrize(
    "text",
    ["1.5", "1 + 0.003*tanh(z/0.3)", "1 + 0.5*exp(-(x*x + y*y + z*z))", "1/(z + 12)"],
)
def test_smooth_indices_and_poles_outside_the_box_pass(text):
    assert index_pole(hm.medium(text, bounds=BOX), *BOX) is None

"""Reissner–Nordström (core.models.reissner_nordstrom) against its analytic horizon, photon
sphere and shadow, and against Schwarzschild at Q = 0."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import brentq

import core
from core import hamiltonians as hm
from core.trace import TraceOptions, Tracer
from core.tracing.steps import default_method

M = 0.5  # rg = 1


def _analytic(charge: float) -> tuple[float, float, float]:
    """(r+, r_ph, b_c) from the textbook formulas."""
    r_plus = M + math.sqrt(M * M - charge * charge)
    r_ph = 0.5 * (3 * M + math.sqrt(9 * M * M - 8 * charge * charge))
    f = 1 - 2 * M / r_ph + charge * charge / (r_ph * r_ph)
    return r_plus, r_ph, r_ph / math.sqrt(f)


@pytest.mark.parametrize("charge", [0.0, 0.3, 0.45])
def test_the_horizon_is_where_the_hamiltonian_says(charge):
    """The model's r+ is where g^rr = f vanishes in its own H (a radial covector at rest:
    H = f/2, found by root-finding on H along a ray), and matches M + √(M² - Q²); its photon
    sphere and shadow match the formulas."""
    model = hm.reissner_nordstrom(1.0, charge)
    direction = np.array([0.3, -0.5, 0.8]) / math.sqrt(0.98)

    def half_f(r):
        q = np.concatenate([[0.0], r * direction])[:, None]
        p = np.concatenate([[0.0], direction])[:, None]
        return model.value_soa(q, p)[0]

    r_plus, r_ph, b_c = _analytic(charge)
    assert brentq(half_f, r_plus * 0.9 + 0.05, 3.0, xtol=1e-14) == pytest.approx(r_plus, 1e-12)
    assert model.horizon == pytest.approx(r_plus, rel=1e-14)
    assert model.photon_sphere == pytest.approx(r_ph, rel=1e-14)
    assert model.shadow_radius == pytest.approx(b_c, rel=1e-14)
    if charge == 0.0:
        assert b_c == pytest.approx(1.5 * math.sqrt(3), rel=1e-14)  # Schwarzschild's 3√3 M


@pytest.mark.parametrize("charge", [0.3, 0.45])
def test_light_falls_in_below_the_shadow_radius_and_escapes_above(charge):
    """Rays traced from a static camera at 400 rg with impact parameter b = D sin(α)/√f(D):
    captured at 0.99 b_c, escaped at 1.01 b_c (the traced shadow edge is the analytic one
    within 1 %; Schwarzschild's b_c is 14 % larger at Q = 0.45)."""
    model = hm.reissner_nordstrom(1.0, charge)
    _, _, b_c = _analytic(charge)
    distance = 400.0
    f_camera = 1 - 2 * M / distance + charge * charge / distance**2
    scale = np.array([0.97, 0.99, 1.01, 1.03])
    alpha = np.arcsin(scale * b_c * math.sqrt(f_camera) / distance)
    directions = np.stack([np.sin(alpha), np.cos(alpha), np.zeros_like(alpha)], axis=1)
    origins = np.tile([0.0, -distance, 0.0], (alpha.size, 1))
    scene = core.Scene(model=model)
    rays = Tracer(scene, TraceOptions(tolerance=1e-9, region_radius=2 * distance)).trace(
        origins, directions
    )
    captured, escaped = core.ENDING["captured"], core.ENDING["escaped"]
    np.testing.assert_array_equal(rays.ending, [captured, captured, escaped, escaped])


def test_no_charge_is_schwarzschild():
    """At Q = 0, H is outgoing Kerr–Schild Schwarzschild's (core's hand-written form) at
    random states, to rounding."""
    rng = np.random.default_rng(3)
    Q = np.vstack([np.zeros(50), rng.normal(scale=5.0, size=(3, 50))])
    P = rng.normal(size=(4, 50))
    charged = hm.reissner_nordstrom(1.0, 0.0).value_soa(Q, P)
    schwarzschild = hm.KerrSchild(1.0, 0.0, 1.0, outgoing=True).value_soa(Q, P)
    np.testing.assert_allclose(charged, schwarzschild, rtol=1e-12, atol=1e-12)


def test_what_it_declares():
    """Traced as written (no split, gauss4), no disk orbits it, |Q| >= M is refused by name."""
    model = hm.reissner_nordstrom(1.0, 0.3)
    assert model.for_backward_tracing(explicit_split=True) is model
    assert default_method(model) == "gauss4"
    assert model.kerr_orbits() is None and model.scales_time
    with pytest.raises(ValueError, match="accretion disk needs a black hole"):
        core.Scene(model=model, disk=core.AccretionDisk(r_out=10.0))
    for charge in (0.5, -0.7, math.nan):
        with pytest.raises(ValueError, match="charge"):
            hm.reissner_nordstrom(1.0, charge)

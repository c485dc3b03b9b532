"""Kerr–Newman (core.models.kerr_newman) against Kerr at Q = 0, Reissner–Nordström at a = 0,
its analytic horizon, and its shadow against the analytic critical curve (Bardeen 1973's
spherical photon orbits with Δ = r² - rg r + a² + Q²)."""

from __future__ import annotations

import math

import numpy as np
import pytest

import core
from core import hamiltonians as hm
from core.models.kerr_newman import kerr_newman
from core.trace import TraceOptions, Tracer
from core.tracing.steps import default_method

DISTANCE = 1000.0  # rg: the camera, far enough for celestial coordinates (error ~1e-3)


def _random_states(n: int = 50) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(7)
    Q = np.vstack([np.zeros(n), rng.normal(scale=5.0, size=(3, n))])
    return Q, rng.normal(size=(4, n))


def test_no_charge_is_kerr_and_no_spin_is_reissner_nordstrom():
    """At Q = 0, H is outgoing Kerr–Schild Kerr's (core's hand-written form); at a = 0 it is
    Reissner–Nordström's; at random states, to rounding."""
    Q, P = _random_states()
    kerr = hm.KerrSchild(1.0, 0.35, hm.kerr_horizon(1.0, 0.35), outgoing=True)
    np.testing.assert_allclose(
        kerr_newman(1.0, 0.35, 0.0).value_soa(Q, P), kerr.value_soa(Q, P), rtol=1e-12, atol=1e-12
    )
    np.testing.assert_allclose(
        kerr_newman(1.0, 0.0, 0.3).value_soa(Q, P),
        hm.reissner_nordstrom(1.0, 0.3).value_soa(Q, P),
        rtol=1e-12,
        atol=1e-12,
    )


@pytest.mark.parametrize(("a", "charge"), [(0.3, 0.2), (0.45, 0.1), (0.1, 0.45)])
def test_the_horizon_is_where_g_rr_vanishes(a, charge):
    """r+ = M + √(M² - a² - Q²); on the spin axis (x = y = 0, r = z) the radial covector's
    norm g^zz = Δ/(r² + a²) changes sign there."""
    model = kerr_newman(1.0, a, charge)
    m = 0.5
    r_plus = m + math.sqrt(m * m - a * a - charge * charge)
    assert model.horizon == pytest.approx(r_plus, rel=1e-14)
    z = r_plus * np.array([0.999, 1.001])
    q = np.vstack([np.zeros(2), np.zeros(2), np.zeros(2), z])
    p = np.vstack([np.zeros(2), np.zeros(2), np.zeros(2), np.ones(2)])
    half_g_zz = model.value_soa(q, p)
    assert half_g_zz[0] < 0.0 < half_g_zz[1]
    delta = z * z - 2 * m * z + a * a + charge * charge
    np.testing.assert_allclose(half_g_zz, 0.5 * delta / (z * z + a * a), rtol=1e-10)


def _trace_towards(model, inclination: float, alpha: np.ndarray, beta: np.ndarray):
    """Endings of rays from a static camera at DISTANCE and ``inclination`` from the spin
    axis, aimed at celestial coordinates (alpha, beta) (alpha along forward × up)."""
    position = DISTANCE * np.array([0.0, -math.sin(inclination), math.cos(inclination)])
    forward = -position / DISTANCE
    up = np.array([0.0, 0.0, 1.0]) - forward * forward[2]
    up /= np.linalg.norm(up)
    side = np.cross(forward, up)
    directions = forward + (np.outer(alpha, side) + np.outer(beta, up)) / DISTANCE
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    options = TraceOptions(tolerance=1e-8, region_radius=2 * DISTANCE)
    rays = Tracer(core.Scene(model=model), options).trace(
        np.tile(position, (len(alpha), 1)), directions
    )
    return rays.ending


@pytest.mark.parametrize("inclination", [math.pi / 2, math.pi / 3])
def test_the_shadow_is_the_analytic_critical_curve(inclination):
    """Rays aimed 2 % inside the critical curve (towards its centre) fall in, 2 % outside
    escape, at 12 points around it; the curve is lopsided (a/M = 0.8): its mirror image
    fails. Kerr's curve at the same spin lies outside Kerr–Newman's (charge shrinks it)."""
    model = kerr_newman(1.0, 0.4, 0.25)
    curve = model.critical_curve(inclination)
    points = curve[:, np.linspace(0, curve.shape[1] - 1, 12).astype(int)]
    centre = curve.mean(axis=1, keepdims=True)
    captured, escaped = core.ENDING["captured"], core.ENDING["escaped"]
    inside, outside = centre + 0.98 * (points - centre), centre + 1.02 * (points - centre)
    assert np.all(_trace_towards(model, inclination, *inside) == captured)
    assert np.all(_trace_towards(model, inclination, *outside) == escaped)
    mirrored = _trace_towards(model, inclination, -outside[0], outside[1])
    assert np.any(mirrored == captured)
    kerr_curve = kerr_newman(1.0, 0.4, 0.0).critical_curve(inclination)
    assert np.ptp(kerr_curve[0]) > 1.03 * np.ptp(curve[0])


def test_what_it_declares():
    """Traced as written (no split, gauss4), no disk orbits it, a² + Q² >= M² is refused by
    name; the registry builds it from a/M and Q/M."""
    model = kerr_newman(1.0, 0.3, 0.2)
    assert model.for_backward_tracing(explicit_split=True) is model
    assert default_method(model) == "gauss4"
    assert model.kerr_orbits() is None and model.scales_time
    for a, charge in ((0.4, 0.3), (0.0, 0.5), (math.nan, 0.1)):
        with pytest.raises(ValueError, match="Kerr–Newman|spin|charge"):
            kerr_newman(1.0, a, charge)
    built = hm.model_kind("KERR_NEWMAN").build(rg=2.0, spin=0.5, charge=0.3)
    assert (built.rg, built.a, built.charge) == (2.0, 0.5, 0.3)

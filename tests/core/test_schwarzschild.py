"""Schwarzschild light deflection and the photon sphere against exact references.

Model: ``hm.schwarzschild(rg=1)`` in (t, r, theta, phi), H = 1/2 g^ij p_i p_j with
signature (-, +, +, +); photons have E = -p_t = 1, b = p_phi, theta = pi/2, p_theta = 0
and p_r from H = 0.

Reference (independent of the integrator): with u = 1/r the equatorial orbit obeys
(du/dphi)^2 = 1/b^2 - u^2 + rg u^3 = rg (u - u1)(u - u2)(u - u3), u1 < 0 < u2 < u3, so the
angle swept between u_a and the turning point u2 = 1/r_min is

    I(u_a) = int_{u_a}^{u2} du / sqrt(rg (u - u1)(u - u2)(u - u3)).

It is computed twice with mpmath at 40 digits and the two must agree to 1e-25:
(1) by quadrature after the substitution u = u2 - w^2, which removes the inverse-square-
root singularity at the turning point; (2) in closed form with the incomplete elliptic
integral of the first kind (Byrd & Friedman 233.00; Darwin 1959, Chandrasekhar 1983 §20).
The reference itself is then checked against the weak-field series (Keeton & Petters 2005)
and the strong-deflection limit (Bozza 2002), both of which it must reproduce.
"""

import math

import mpmath as mp
import numpy as np
import pytest

import core
from core import hamiltonians as hm

RG = 1.0
B_CRIT = 1.5 * math.sqrt(3.0) * RG  # critical impact parameter 3 sqrt(3) / 2 rg


# ----------------------------------------------------------------------------------
# exact reference


def _roots(b):
    """The three real roots u1 < u2 < u3 of rg u^3 - u^2 + 1/b^2 (b > b_crit), mpmath."""
    with mp.workdps(40):
        rs = mp.polyroots([1 / mp.mpf(b) ** 2, 0, -1, RG], maxsteps=200, extraprec=200, asc=True)
        rs = sorted(mp.re(r) for r in rs)
    return rs


def swept_angle_quad(b, u_a):
    """I(u_a) by quadrature in w, u = u2 - w^2 (no singularity at the turning point)."""
    with mp.workdps(40):
        u1, u2, u3 = _roots(b)
        u_a = mp.mpf(u_a)

        def integrand(w):
            return 2 / mp.sqrt(RG * (u2 - w * w - u1) * (u3 - u2 + w * w))

        return mp.quad(integrand, [0, mp.sqrt(u2 - u_a)])


def swept_angle_elliptic(b, u_a):
    """I(u_a) = 2 / sqrt(rg (u3 - u1)) F(phi | m) (Byrd & Friedman 233.00)."""
    with mp.workdps(40):
        c, bb, a = _roots(b)
        u_a = mp.mpf(u_a)
        m = (bb - c) / (a - c)
        sn2 = (a - c) * (bb - u_a) / ((bb - c) * (a - u_a))
        return 2 / mp.sqrt(RG * (a - c)) * mp.ellipf(mp.asin(mp.sqrt(sn2)), m)


def swept_angle(b, r_start, r_end):
    """Exact phi swept from r_start (incoming) through r_min out to r_end, as a float."""
    with mp.workdps(40):
        total = swept_angle_quad(b, 1 / mp.mpf(r_start)) + swept_angle_quad(b, 1 / mp.mpf(r_end))
        return float(total)


def deflection(b):
    """Total deflection from infinity to infinity, 2 I(0) - pi (mpmath)."""
    with mp.workdps(40):
        return 2 * swept_angle_elliptic(b, 0) - mp.pi


# ----------------------------------------------------------------------------------
# the reference checked on its own


@pytest.mark.parametrize(
    "b, r_a",
    [(b, r) for b in (50.0, 10.0, 6.0, 2.6) for r in (math.inf, 1000.0, 60.0, 7.0, 1.6) if r > b],
)
def test_reference_quadrature_equals_elliptic_form(b, r_a):
    """Both forms of I agree at 40 digits; r_a = inf, far, near and just outside r_min."""
    u_a = 0.0 if math.isinf(r_a) else 1.0 / r_a
    with mp.workdps(40):
        assert u_a < _roots(b)[1]
        assert abs(swept_angle_quad(b, u_a) - swept_angle_elliptic(b, u_a)) < 1e-25


def test_reference_weak_field_series():
    """alpha = 4 M/b + 15 pi/4 (M/b)^2 + 128/3 (M/b)^3 + 3465 pi/64 (M/b)^4 + O(b^-5)."""
    for b in (50.0, 200.0, 1000.0):
        x = RG / 2 / b  # M / b
        series = 4 * x + 15 * math.pi / 4 * x**2 + 128 / 3 * x**3 + 3465 * math.pi / 64 * x**4
        assert abs(float(deflection(b)) - series) < 2e3 * x**5  # next coefficient 3584/5
    assert abs(float(deflection(1e6)) - 2 * RG / 1e6) < 1e-11


def test_reference_strong_deflection_limit():
    """b -> b_c: alpha = -log(b/b_c - 1) + log(216 (7 - 4 sqrt 3)) - pi + O(eps log eps)."""
    const = math.log(216 * (7 - 4 * math.sqrt(3))) - math.pi
    for eps, tol in ((1e-6, 1e-5), (1e-8, 2e-7), (1e-10, 3e-9)):
        with mp.workdps(40):
            b = mp.mpf(3) * mp.sqrt(3) / 2 * (1 + mp.mpf(eps))
            alpha = float(deflection(b))
        assert abs(alpha - (-math.log(eps) + const)) < tol


# ----------------------------------------------------------------------------------
# the integrator against the reference


def equatorial_photon(b, r0, incoming=True):
    """(q0, p0) of photons with E = 1, L = b at radius r0 (H = 0 solved for p_r)."""
    b = np.atleast_1d(np.asarray(b, dtype=np.float64))
    f = 1.0 - RG / r0
    p_r = np.sqrt(1.0 - f * b**2 / r0**2) / f
    n = b.size
    q0 = np.column_stack([np.zeros(n), np.full(n, r0), np.full(n, np.pi / 2), np.zeros(n)])
    p0 = np.column_stack([-np.ones(n), -p_r if incoming else p_r, np.zeros(n), b])
    return q0, p0


def test_deflection_matches_elliptic_integral():
    """phi swept by rays b = 50, 10, 6 rg from r0 = 1000 rg in and back out, to 1e-7 rad.

    The three rays run in one batch: gauss4, adaptive (Poincaré g = r - rg), fixed
    fictitious step dtau = 0.02, 600 steps (they come back out to r ~ 9.2e4, 2.4e3 and
    5.3e2 rg). Measured |phi - phi_exact| (2026-11): 7.0e-10, 7.0e-10, 6.8e-10 rad, with
    |H| <= 3.3e-10; about 0.6 s. (yoshida6 at dtau = 0.04: 1.6e-12 .. 1.0e-11 rad, 4 s.)
    """
    H = hm.schwarzschild(rg=RG)
    r0 = 1000.0
    bs = np.array([50.0, 10.0, 6.0])
    q0, p0 = equatorial_photon(bs, r0)
    assert np.all(np.abs(H.value(q0, p0)) < 1e-15)
    res = core.integrate(H, q0, p0, step=0.02, steps=600, method="gauss4", adaptive=True)
    assert not res.failed.any()
    assert np.all(res.p[:, 1] > 0), "rays must be past their turning point, going out"
    assert np.all(res.q[:, 1] > 300.0)
    assert np.all(np.abs(res.q[:, 2] - np.pi / 2) < 1e-14)  # stays equatorial
    np.testing.assert_array_equal(res.p[:, [0, 3]], p0[:, [0, 3]])  # cyclic: exact
    assert np.all(res.energy_error < 1e-9)
    for i, b in enumerate(bs):
        exact = swept_angle(b, r0, res.q[i, 1])
        assert abs(res.q[i, 3] - exact) < 1e-7, (b, res.q[i, 3] - exact)


def test_total_deflection_consistent_with_far_field():
    """The finite-radius comparison above converges to the total deflection as r -> inf."""
    for b in (50.0, 10.0, 6.0):
        far = swept_angle(b, 1e12, 1e12) - math.pi
        assert abs(far - float(deflection(b))) < 3e-11 * b


def test_far_field_turn_is_exact_down_to_radial_rays():
    """Rays leave the model's region bent by the rest of the first-order deflection,
    (2M/b)(1 − cos ψ) towards the mass (ψ between the position and the direction, b the
    impact): against that at 40 digits (mpmath) for ψ from 1e-9 rad (a ray leaving nearly
    radially, where 1 − cos ψ and b both vanish) to 3 rad, the bent direction's angle from
    the unbent one is right to 1e-12 relative and lies in the plane of the position and
    the direction, turned towards the mass."""
    from core.trace import TraceOptions, Tracer

    tracer = Tracer(core.Scene(model=hm.schwarzschild(RG)), TraceOptions())
    mass, r = 0.5 * RG, 40.0
    psi = np.array([1e-9, 1e-7, 1e-5, 1e-3, 0.1, 1.0, 2.0, 3.0])
    X = np.tile([r, 0.0, 0.0], (psi.size, 1))
    D = np.stack([np.cos(psi), np.sin(psi), np.zeros_like(psi)], axis=1)
    bent = tracer._far_field(X, D)
    angle = np.arctan2(np.linalg.norm(np.cross(D, bent), axis=1), np.einsum("ij,ij->i", D, bent))
    with mp.workdps(40):
        exact = [float(2 * mass / (r * mp.sin(mp.mpf(a))) * (1 - mp.cos(mp.mpf(a)))) for a in psi]
    np.testing.assert_allclose(angle, exact, rtol=1e-12, atol=0)
    assert np.abs(bent[:, 2]).max() == 0.0
    assert (np.cross(D, bent)[:, 2] > 0).all()  # towards the mass (at -x): ψ grows


@pytest.mark.parametrize("inclination", [0.0, 1.0])
def test_photon_sphere_orbit_stays_circular(inclination):
    """r = 1.5 rg, b = 3 sqrt(3)/2 rg, p_r = 0: |r - 1.5 rg| < 1e-6 over one full orbit.

    The orbit is unstable (a perturbation grows by e^(2 pi) ~ 535 per orbit). In the
    equatorial plane (inclination 0, as in the issue) the radial equilibrium (r, p_r) =
    (1.5, 0) is a fixed point of every consistent one-step method, so r stays 1.5 exactly;
    the orbit inclined by 1 rad to the equator (p_theta = -b sin i, p_phi = b cos i) is the
    real test: there the method's error in L^2 = p_theta^2 + p_phi^2/sin^2 theta feeds the
    instability. yoshida8 (implicit Störmer–Verlet base), fixed ds = 0.02, 274 steps, every
    step recorded, until the angle swept in the orbital plane passes 2 pi. Measured max
    |r - 1.5| (2026-11): 0 (equatorial) and 1.3e-12 (inclined); about 1 + 2 s.
    (gauss4, ds = 0.01: 2.5e-8; yoshida6, ds = 0.02: 7.1e-9; yoshida4, ds = 0.005: 1.1e-7.)
    """
    H = hm.schwarzschild(rg=RG)
    r_c = 1.5 * RG
    q0 = np.array([0.0, r_c, np.pi / 2, 0.0])
    p0 = np.array([-1.0, 0.0, -B_CRIT * math.sin(inclination), B_CRIT * math.cos(inclination)])
    assert abs(H.value(q0, p0)) < 1e-15
    step = 0.02
    steps = int(math.ceil(2 * math.pi * r_c**2 / B_CRIT / step)) + 1  # dpsi/ds = b / r^2
    res = core.integrate(H, q0, p0, step=step, steps=steps, method="yoshida8", record_every=1)
    assert not res.failed
    traj = res.trajectory
    assert traj.q.shape == (steps + 1, 4)
    # angle swept in the orbital plane, spanned by the initial position and direction
    th, ph = traj.q[:, 2], traj.q[:, 3]
    n = np.column_stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)])
    e2 = np.array([0.0, math.cos(inclination), math.sin(inclination)])
    psi = np.unwrap(np.arctan2(n @ e2, n[:, 0]))
    assert psi[-1] >= 2 * math.pi
    assert np.max(np.abs(n @ np.cross([1.0, 0.0, 0.0], e2))) < 1e-9  # stays in its plane
    dev = np.max(np.abs(traj.q[:, 1] - r_c))
    assert dev < 1e-6, dev

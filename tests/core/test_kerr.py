"""Kerr photons: conservation of H, p_t, p_phi and the Carter constant near the photon
region, and Kerr–Schild rays over the pole and through the horizon.

Units rg = 2M = 1, so M = 0.5 and a/M = 0.9 and 0.998 are a = 0.45 and 0.499.

Independent references (textbook Kerr geodesics, Bardeen 1973; Teo 2003, Gen. Rel.
Grav. 35, 1909): with E = -p_t = 1, xi = L/E = p_phi, eta = Q/E^2,

    R(r)     = (r^2 + a^2 - a xi)^2 - Delta (eta + (xi - a)^2),   Delta = r^2 - 2Mr + a^2
    Theta(t) = eta + a^2 cos^2 t - xi^2 cot^2 t
    Boyer–Lindquist momenta: p_r = +-sqrt(R)/Delta, p_theta = +-sqrt(Theta)
    Carter constant (photons): Q = p_theta^2 + cos^2 theta (-a^2 p_t^2 + p_phi^2/sin^2 theta)
    spherical photon orbits at radius r:  xi = (M (r^2 - a^2) - r Delta) / (a (r - M)),
                                          eta = r^3 (4 M Delta - r (r - M)^2) / (a^2 (r - M)^2)
    equatorial photon orbits (ends of the photon region): r = 2M (1 + cos(2/3 arccos(-+a/M))).
"""

import math

import numpy as np
import pytest

import core
from core import hamiltonians as hm

RG = 1.0
M = RG / 2


# ----------------------------------------------------------------------------------
# textbook references


def photon_region(a):
    """(prograde, retrograde) equatorial circular photon orbit radii: the photon region."""
    pro = 2 * M * (1 + math.cos(2 / 3 * math.acos(-a / M)))
    retro = 2 * M * (1 + math.cos(2 / 3 * math.acos(a / M)))
    return pro, retro


def horizon(a):
    return M + math.sqrt(M * M - a * a)


def spherical_orbit_constants(a, r):
    """(xi, eta) of the spherical photon orbit at Boyer–Lindquist radius r."""
    delta = r * r - 2 * M * r + a * a
    xi = (M * (r * r - a * a) - r * delta) / (a * (r - M))
    eta = r**3 * (4 * M * delta - r * (r - M) ** 2) / (a * a * (r - M) ** 2)
    return xi, eta


def radial_potential(a, xi, eta):
    """R(r) as polynomial coefficients (highest power first)."""
    A = a * a - a * xi
    K = eta + (xi - a) ** 2
    return np.array([1.0, 0.0, 2 * A - K, 2 * M * K, A * A - a * a * K])


def carter_textbook(a, q, p):
    """Q = p_theta^2 + cos^2 theta (-a^2 p_t^2 + p_phi^2 / sin^2 theta), rows of (t,r,th,ph)."""
    th = q[..., 2]
    return p[..., 2] ** 2 + np.cos(th) ** 2 * (
        -a * a * p[..., 0] ** 2 + p[..., 3] ** 2 / np.sin(th) ** 2
    )


@pytest.mark.parametrize("a", [0.45, 0.499])
def test_reference_spherical_photon_orbits(a):
    """The formulas are consistent: R = R' = 0 on each spherical orbit, eta = 0 at its ends."""
    pro, retro = photon_region(a)
    assert horizon(a) < pro < 3 * M < retro < 4 * M
    for r in np.linspace(pro, retro, 7)[1:-1]:
        xi, eta = spherical_orbit_constants(a, r)
        R = radial_potential(a, xi, eta)
        assert eta > 0
        assert abs(np.polyval(R, r)) < 1e-12 * r**4
        assert abs(np.polyval(np.polyder(R), r)) < 1e-12 * r**3
    for r in (pro, retro):
        assert abs(spherical_orbit_constants(a, r)[1]) < 1e-12


# ----------------------------------------------------------------------------------
# Boyer–Lindquist: invariants along a ray through the photon region


def photon_near_photon_region(a, r0=30.0):
    """A ray from r0 (incoming, theta = pi/2, moving to the north) with the constants of
    the spherical orbit at 20 % of the photon region scaled by 1.08: it turns at r_min
    inside the photon region and oscillates in theta between ~0.43 and ~2.71.
    Returns q0, p0, xi, eta and r_min (largest root of R)."""
    pro, retro = photon_region(a)
    xi_s, eta_s = spherical_orbit_constants(a, pro + 0.2 * (retro - pro))
    xi, eta = 1.08 * xi_s, 1.08**2 * eta_s
    roots = np.roots(radial_potential(a, xi, eta))
    r_min = float(np.max(roots.real[np.abs(roots.imag) < 1e-9]))
    th0 = math.pi / 2
    delta = r0 * r0 - 2 * M * r0 + a * a
    R = np.polyval(radial_potential(a, xi, eta), r0)
    theta = eta + a * a * math.cos(th0) ** 2 - xi**2 / math.tan(th0) ** 2
    q0 = np.array([0.0, r0, th0, 0.0])
    p0 = np.array([-1.0, -math.sqrt(R) / delta, -math.sqrt(theta), xi])
    return q0, p0, xi, eta, r_min


@pytest.mark.parametrize("a", [0.45, 0.499])
def test_kerr_invariants_conserved_near_photon_region(a):
    """H, p_t, p_phi and Q conserved to 1e-8 (relative) on a ray through the photon region.

    gauss4, adaptive (Poincaré g = Delta / r), fictitious step dtau = 0.015, 1300 steps,
    recorded every step; from r0 = 30 rg in, around the hole and back out (to 1.1e4 rg for
    a = 0.45, 1.8e3 rg for 0.499). H error is relative to E^2 = p_t^2 = 1, Q's to Q.
    Measured (2026-11): max |H| 4.2e-10 / 2.6e-10, max |dQ|/Q 8.2e-10 / 5.6e-10 (a = 0.45 /
    0.499); p_t, p_phi exact; the trajectory's r_min (parabola through the three samples
    around the minimum) matches the largest root of R to 4.3e-10 / 3.0e-10. 1.9 s CPU each.
    (dtau = 0.01, 2000 steps: |H| 8.2e-11, |dQ|/Q 1.6e-10; dtau = 0.02: 1.3e-9, 2.6e-9.)
    """
    H = hm.kerr(rg=RG, a=a)
    q0, p0, xi, eta, r_min = photon_near_photon_region(a)
    pro, retro = photon_region(a)
    assert max(pro - r_min, r_min - retro, 0.0) <= 0.5 * RG  # passes within 0.5 rg
    assert r_min > horizon(a)
    # the model's metric against the textbook potentials: H = 0 at the start
    assert abs(H.value(q0, p0)) < 1e-14
    Q0 = carter_textbook(a, q0, p0)
    assert Q0 > 0 and abs(Q0 - eta) < 1e-12 * eta
    assert abs(H.invariants(q0, p0)["carter"] - Q0) < 1e-12 * Q0

    res = core.integrate(
        H, q0, p0, step=0.015, steps=1300, method="gauss4", adaptive=True, record_every=1
    )
    assert not res.failed
    assert res.p[1] > 0 and res.q[1] > 100.0, "the ray must have come back out"
    q, p = res.trajectory.q, res.trajectory.p
    assert np.all(np.isfinite(q)) and np.all(np.isfinite(p))
    th = q[:, 2]
    assert th.min() < 0.5 and th.max() > math.pi - 0.5  # truly non-equatorial

    h_rel = np.max(np.abs(H.value(q, p))) / p0[0] ** 2
    assert h_rel < 1e-8, h_rel
    assert res.energy_error < 1e-8
    Q = carter_textbook(a, q, p)
    assert np.max(np.abs(Q - Q0)) / Q0 < 1e-8
    inv = H.invariants(q, p)
    assert np.max(np.abs(inv["carter"] - Q0)) / Q0 < 1e-8
    for name, k in (("p_t", 0), ("p_phi", 3)):
        assert np.max(np.abs(inv[name] - p0[k])) <= 1e-8 * abs(p0[k])
        assert np.max(np.abs(p[:, k] - p0[k])) <= 1e-8 * abs(p0[k])

    # the turning radius is the largest root of R (parabola through the sampled minimum)
    i = int(np.argmin(q[:, 1]))
    r_m, r_c, r_p = q[i - 1 : i + 2, 1]
    r_turn = r_c - (r_p - r_m) ** 2 / (8 * (r_p - 2 * r_c + r_m))
    assert abs(r_turn - r_min) < 1e-8, r_turn - r_min


# ----------------------------------------------------------------------------------
# Kerr–Schild: over the pole and through the horizon


def kerr_schild_photons(H, positions, directions):
    """p_t = -1 and spatial p = lambda d with H = 0 (H is quadratic in lambda exactly)."""
    positions = np.asarray(positions, dtype=np.float64)
    d = np.asarray(directions, dtype=np.float64)
    n = len(positions)
    q0 = np.column_stack([np.zeros(n), positions])

    def h_of(lam):
        return H.value(q0, np.column_stack([-np.ones(n), lam[:, None] * d]))

    c = h_of(np.zeros(n))
    plus, minus = h_of(np.ones(n)), h_of(-np.ones(n))
    A, B = (plus + minus) / 2 - c, (plus - minus) / 2
    lam = (-B + np.sqrt(B * B - 4 * A * c)) / (2 * A)
    return q0, np.column_stack([-np.ones(n), lam[:, None] * d])


def ks_radius(a, q):
    x, y, z = q[..., 1], q[..., 2], q[..., 3]
    rho2 = x * x + y * y + z * z - a * a
    return np.sqrt(0.5 * (rho2 + np.sqrt(rho2 * rho2 + 4 * a * a * z * z)))


@pytest.mark.parametrize("a", [0.45, 0.499])
def test_kerr_schild_rays_over_the_pole(a):
    """Rays across the spin axis above the hole (where Boyer–Lindquist has its pole),
    along the axis outward, and 1e-12 off it: finite, not failed, H, p_t, L_z conserved.

    gauss4, adaptive (g = r), dtau = 0.02, 400 steps, recorded. Measured (2026-11): the
    crossing rays' samples pass 0.012 - 0.016 rg from the axis at r ~ 2.5 - 3.5 rg; max |H|
    3.4e-10, |dL_z| < 2e-14; 1.2 s CPU each.
    """
    H = hm.kerr(rg=RG, a=a, chart="kerr_schild")
    starts = [
        [-30.0, 0.0, 3.0],
        [-30.0, 1e-12, 3.0],
        [0.0, -30.0, 4.0],
        [0.0, 0.0, 2.0],
        [1e-12, 0.0, 2.0],
    ]
    dirs = [[1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0]]
    q0, p0 = kerr_schild_photons(H, starts, dirs)
    assert np.all(np.abs(H.value(q0, p0)) < 1e-14)
    res = core.integrate(
        H, q0, p0, step=0.02, steps=400, method="gauss4", adaptive=True, record_every=1
    )
    traj = res.trajectory
    assert np.all(np.isfinite(traj.q)) and np.all(np.isfinite(traj.p))
    assert not res.failed.any()
    # the crossing rays really went over the pole: x (or y) changed sign near the axis
    rho = np.hypot(traj.q[:, :3, 1], traj.q[:, :3, 2])
    assert np.all(rho.min(axis=0) < 0.05)
    assert np.all(ks_radius(a, res.q) > 50.0)  # all escaped
    assert np.all(res.energy_error < 1e-8)
    assert np.max(np.abs(H.value(traj.q.reshape(-1, 4), traj.p.reshape(-1, 4)))) < 1e-8
    inv0 = H.invariants(q0, p0)
    inv = H.invariants(res.q, res.p)
    np.testing.assert_array_equal(inv["p_t"], inv0["p_t"])
    np.testing.assert_allclose(inv["L_z"], inv0["L_z"], rtol=0, atol=1e-8)
    captured = getattr(res, "captured", None)
    if captured is not None:
        assert not np.any(captured)


@pytest.mark.parametrize("a", [0.45, 0.499])
def test_kerr_schild_rays_into_the_horizon_are_captured(a):
    """Rays down the spin axis, just off it, and through the equatorial horizon are
    reported captured (res.captured), not failed, with finite final states at or inside
    the horizon; an escaping ray in the same batch is neither. gauss4, adaptive, dtau =
    0.02, 500 steps.
    """
    H = hm.kerr(rg=RG, a=a, chart="kerr_schild")
    starts = [
        [0.0, 0.0, 30.0],
        [1e-9, -1e-9, 30.0],
        [-30.0, 0.0, 0.5],
        [-30.0, 0.0, -1.0],
        [-30.0, 0.0, 6.0],
    ]
    dirs = [[0.0, 0.0, -1.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 0.0, 0.0]]
    q0, p0 = kerr_schild_photons(H, starts, dirs)
    assert np.all(np.abs(H.value(q0, p0)) < 1e-14)
    res = core.integrate(H, q0, p0, step=0.02, steps=500, method="gauss4", adaptive=True)
    assert hasattr(res, "captured"), "integrate must report captured rays (res.captured)"
    assert res.captured.shape == (5,) and res.captured.dtype == bool
    np.testing.assert_array_equal(res.captured, [True, True, True, True, False])
    assert not res.failed.any()
    assert np.all(np.isfinite(res.q)) and np.all(np.isfinite(res.p))
    r = ks_radius(a, res.q)
    assert np.all(r[:4] <= horizon(a) * 1.05)
    assert r[4] > 50.0


def test_boyer_lindquist_ray_into_the_horizon_is_captured():
    """In Boyer–Lindquist the Poincaré step (g = Delta / r) freezes a ray at the horizon
    (r -> r+ only asymptotically in tau, so capture needs a margin: the tracer's 1.01 r+
    is reached at step ~695); it must end as captured, not failed, with finite state.
    gauss4, adaptive, dtau = 0.02, 1000 steps."""
    a = 0.45
    H = hm.kerr(rg=RG, a=a)
    r0 = 30.0
    xi, eta = 0.5, 2.0  # b ~ 1.5 < critical: falls in
    delta = r0 * r0 - 2 * M * r0 + a * a
    R = np.polyval(radial_potential(a, xi, eta), r0)
    q0 = np.array([0.0, r0, math.pi / 2, 0.0])
    p0 = np.array([-1.0, -math.sqrt(R) / delta, math.sqrt(eta), xi])
    assert abs(H.value(q0, p0)) < 1e-14
    roots = np.roots(radial_potential(a, xi, eta))
    assert not np.any((np.abs(roots.imag) < 1e-9) & (roots.real > horizon(a)))  # no turning
    res = core.integrate(H, q0, p0, step=0.02, steps=1000, method="gauss4", adaptive=True)
    assert hasattr(res, "captured"), "integrate must report captured rays (res.captured)"
    assert res.captured and not res.failed
    assert np.all(np.isfinite(res.q)) and res.q[1] < 1.05 * horizon(a)

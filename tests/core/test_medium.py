"""Stratified media n(z): Snell's invariant, the turning (mirage) height, the analytic
parabolic ray of n^2 = 1 + k z, and the seed's literal form of the optical Hamiltonian.

Physical form (default): H = |p|^2 / (2 n^2). On H = 1/2 the momentum is p = n t (t the
unit tangent, since dq/ds = p / n^2), and p_x, p_y are exactly conserved, so Snell's
invariant n cos(alpha) = |p_horizontal| (alpha: angle of the ray to the horizontal).
A ray descending into lower n turns where n(z*) = n(z0) cos(alpha0).
References (exact, independent of the integrator):
    n = 1 + c z:         z* = (n0 cos(alpha0) - 1) / c
    n = sqrt(1 + k z):   z* = ((1 + k z0) cos^2(alpha0) - 1) / k, and the ray is the parabola
                         z(xi) = z0 - tan(alpha0) xi + k xi^2 / (4 C^2), C = n0 cos(alpha0),
                         xi = horizontal distance travelled.
"""

import math

import numpy as np
import pytest

import core
from core import hamiltonians as hm

Z0 = 1.0
ALPHA0 = 0.25  # initial angle below the horizontal
AZIMUTH = 0.5  # horizontal direction of travel, from the x axis

MEDIA = {
    # name: (index text, n(z) in numpy, exact turning height z*)
    "linear": ("1 + 0.1*z", lambda z: 1 + 0.1 * z, (1.1 * math.cos(ALPHA0) - 1) / 0.1),
    "sqrt": (
        "sqrt(1 + 0.2*z)",
        lambda z: np.sqrt(1 + 0.2 * z),
        ((1 + 0.2 * Z0) * math.cos(ALPHA0) ** 2 - 1) / 0.2,
    ),
}


def launch(n0):
    """q0, p0 with |p| = n0 (H = 1/2), going down at ALPHA0 towards AZIMUTH."""
    t = np.array(
        [
            math.cos(ALPHA0) * math.cos(AZIMUTH),
            math.cos(ALPHA0) * math.sin(AZIMUTH),
            -math.sin(ALPHA0),
        ]
    )
    return np.array([0.0, 0.0, Z0]), n0 * t


def snell(n_of_z, q, p):
    """n(z) cos(angle of the tangent dq/ds = p / n^2 to the horizontal), per row."""
    return n_of_z(q[..., 2]) * np.hypot(p[..., 0], p[..., 1]) / np.linalg.norm(p, axis=-1)


def turning_point(H, q, p, method="gauss4"):
    """Refine the recorded trajectory's turning point (p_z = 0, i.e. dz/ds = 0) by secant
    iteration on the length ds of one integrator step from the last sample before it."""
    k = int(np.nonzero((p[:-1, 2] < 0) & (p[1:, 2] >= 0))[0][0])
    qa, pa = q[k], p[k]

    def pz_after(ds):
        if ds == 0.0:
            return pa[2], qa
        res = core.integrate(H, qa, pa, step=ds, steps=1, method=method)
        return res.p[2], res.q

    s0, s1 = 0.0, 1e-3
    f0, _ = pz_after(s0)
    for _ in range(30):
        f1, q1 = pz_after(s1)
        if abs(f1) < 1e-15:
            break
        s0, s1, f0 = s1, s1 - f1 * (s1 - s0) / (f1 - f0), f1
    return q1


@pytest.mark.parametrize("name", sorted(MEDIA))
def test_snell_invariant_and_turning_height(name):
    """n cos(alpha) constant to 1e-10 and z* = analytic to 1e-6 along a mirage ray.

    gauss4, fixed ds = 0.02, 300 steps (the ray turns near s = 2.9 and climbs back),
    recorded every step. Measured (2026-11): max |n cos(alpha) - C| 8.2e-15 (linear) and
    5.1e-15 (sqrt), |z* - exact| 8.3e-14 and 5.1e-14; 0.3 s each. For scale, 2nd-order
    methods at the same step fail: implicit_midpoint 2.4e-8, stormer_verlet 9e-8 in Snell.
    """
    text, n_of_z, z_star = MEDIA[name]
    H = hm.medium(text)
    q0, p0 = launch(n_of_z(Z0))
    assert abs(H.value(q0, p0) - 0.5) < 1e-15
    res = core.integrate(H, q0, p0, step=0.02, steps=300, method="gauss4", record_every=1)
    assert not res.failed
    q, p = res.trajectory.q, res.trajectory.p
    assert p[-1, 2] > 0 and q[:, 2].min() < Z0 - 0.2  # turned and going back up
    C = n_of_z(Z0) * math.cos(ALPHA0)
    s_err = np.max(np.abs(snell(n_of_z, q, p) - C))
    assert s_err < 1e-10, s_err
    np.testing.assert_array_equal(p[:, :2], np.broadcast_to(p0[:2], (len(p), 2)))  # exact
    q_turn = turning_point(H, q, p)
    assert abs(q_turn[2] - z_star) < 1e-6, q_turn[2] - z_star
    assert abs(n_of_z(q_turn[2]) - C) < 1e-6


def test_ray_is_the_analytic_parabola():
    """n^2 = 1 + k z: every recorded point lies on z(xi) = z0 - tan(a0) xi + k xi^2/(4 C^2).

    yoshida6 (implicit Störmer–Verlet base), ds = 0.05, 120 steps. Measured (2026-11):
    max |z - z(xi)| 5.0e-15 (gauss4: 2.1e-12, stormer_verlet: 6.5e-6); the horizontal
    motion stays on its initial azimuth to 1e-15.
    """
    k = 0.2
    H = hm.medium("sqrt(1 + k*z)", parameters={"k": k})
    n0 = math.sqrt(1 + k * Z0)
    q0, p0 = launch(n0)
    res = core.integrate(H, q0, p0, step=0.05, steps=120, method="yoshida6", record_every=1)
    assert not res.failed
    q = res.trajectory.q
    xi = np.hypot(q[:, 0], q[:, 1])
    C = n0 * math.cos(ALPHA0)
    z_exact = Z0 - math.tan(ALPHA0) * xi + k * xi**2 / (4 * C**2)
    assert xi[-1] > 1.5 * 2 * C**2 * math.tan(ALPHA0) / k  # well past the turn
    assert np.max(np.abs(q[:, 2] - z_exact)) < 1e-11
    assert np.max(np.abs(np.arctan2(q[1:, 1], q[1:, 0]) - AZIMUTH)) < 1e-12


def test_literal_form_gives_the_same_ray():
    """The seed's literal H = 1/2 n_lit |p|^2 with n_lit = 1/n^2 traces the physical ray.

    gauss4, ds = 0.02, 300 steps: states agree to 1e-12 (measured: identical positions,
    momenta to 8e-18).
    """
    phys = hm.medium("1 + 0.1*z")
    lit = hm.medium("1/(1 + 0.1*z)**2", literal=True)
    q0, p0 = launch(1.1)
    assert lit.literal and not phys.literal
    assert abs(lit.value(q0, p0) - phys.value(q0, p0)) < 1e-15
    a = core.integrate(phys, q0, p0, step=0.02, steps=300, method="gauss4", record_every=10)
    b = core.integrate(lit, q0, p0, step=0.02, steps=300, method="gauss4", record_every=10)
    assert not a.failed and not b.failed
    np.testing.assert_allclose(b.trajectory.q, a.trajectory.q, rtol=0, atol=1e-12)
    np.testing.assert_allclose(b.trajectory.p, a.trajectory.p, rtol=0, atol=1e-12)
    # and the literal index read as the seed's n (no conversion) bends the other way
    wrong = hm.medium("1 + 0.1*z", literal=True)
    c = core.integrate(wrong, q0, p0, step=0.02, steps=300, method="gauss4")
    assert c.p[2] < 0 < a.p[2]

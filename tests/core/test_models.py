"""Hamiltonian models: AD gradients against finite differences, sparsity, validation."""

import numpy as np
import pytest

from core import hamiltonians as hm

RNG = np.random.default_rng(20261122)


def finite_difference_gradient(H, q, p, h=1e-5):
    """Richardson-extrapolated central differences of H.value, independent of the AD."""

    def partial(x, i, f):
        def shifted(s):
            y = x.copy()
            y[:, i] += s * h * np.maximum(1.0, np.abs(x[:, i]))
            return f(y)

        step = h * np.maximum(1.0, np.abs(x[:, i]))
        d1 = (shifted(1) - shifted(-1)) / (2 * step)
        d2 = (shifted(2) - shifted(-2)) / (4 * step)
        return (4 * d1 - d2) / 3

    gq = np.stack([partial(q, i, lambda y: H.value(y, p)) for i in range(H.dim)], axis=1)
    gp = np.stack([partial(p, i, lambda y: H.value(q, y)) for i in range(H.dim)], axis=1)
    return gq, gp


def spherical_points(n):
    q = np.column_stack(
        [
            RNG.uniform(-5, 5, n),
            RNG.uniform(2.5, 12, n),
            RNG.uniform(0.2, np.pi - 0.2, n),
            RNG.uniform(-3, 3, n),
        ]
    )
    return q, RNG.normal(size=(n, 4))


def cartesian_points(n, scale=6.0):
    return RNG.uniform(-scale, scale, (n, 4)), RNG.normal(size=(n, 4))


USER_METRIC = hm.metric(
    inverse=[
        ["-1/(1 - 2*m/sqrt(x**2+y**2+z**2))", "0", "0", "0"],
        ["0", "1 + 0.1*sin(y)", "0.05*x*z", "0"],
        ["0", "0.05*x*z", "1", "0"],
        ["0", "0", "0", "1 + 0.2*exp(-x**2)"],
    ],
    coords=["t", "x", "y", "z"],
    parameters={"m": 0.5},
)

MODELS = {
    "minkowski_cartesian": (hm.minkowski("cartesian"), cartesian_points),
    "minkowski_spherical": (hm.minkowski("spherical"), spherical_points),
    "schwarzschild": (hm.schwarzschild(rg=1.0), spherical_points),
    "kerr_bl_eq12_0.9": (hm.kerr(rg=1.0, a=0.45), spherical_points),
    "kerr_bl_0.998": (hm.kerr(rg=2.0, a=0.998), spherical_points),
    "kerr_schild_0.9": (hm.kerr(rg=1.0, a=0.45, chart="kerr_schild"), cartesian_points),
    "user_metric": (USER_METRIC, lambda n: cartesian_points(n, 3.0)),
    "medium_physical": (
        hm.medium("0.85 - 0.3*z**3 + 0.03*cos(3*pi*x)"),
        lambda n: (RNG.uniform(-0.6, 0.6, (n, 3)), RNG.normal(size=(n, 3))),
    ),
    "medium_literal": (
        hm.medium("1 + 0.2*tanh(4*z) + 0.01*x*y", literal=True),
        lambda n: (RNG.uniform(-1, 1, (n, 3)), RNG.normal(size=(n, 3))),
    ),
    "volterra_fig4": (
        hm.from_expression("p*q*(p+q-1)", q=["q"], p=["p"]),
        lambda n: (RNG.uniform(0.1, 0.9, (n, 1)), RNG.uniform(0.1, 0.9, (n, 1))),
    ),
    "custom_5d": (
        hm.from_expression(
            "0.5*(a1**2 + b2**2*u**2) + k*sin(u)*cos(v)*w + s*e5**3",
            q=["u", "v", "w", "s", "z5"],
            p=["a1", "b2", "c3", "d4", "e5"],
            parameters={"k": 0.7},
        ),
        lambda n: (RNG.normal(size=(n, 5)), RNG.normal(size=(n, 5))),
    ),
}


@pytest.mark.parametrize("name", sorted(MODELS))
def test_ad_gradient_matches_finite_differences(name):
    H, points = MODELS[name]
    q, p = points(40)
    gq, gp = H.gradient(q, p)
    fq, fp = finite_difference_gradient(H, q, p)
    scale_q = np.maximum(np.abs(fq), 1e-3 * np.abs(fq).max() + 1e-12)
    scale_p = np.maximum(np.abs(fp), 1e-3 * np.abs(fp).max() + 1e-12)
    assert np.max(np.abs(gq - fq) / scale_q) < 1e-6
    assert np.max(np.abs(gp - fp) / scale_p) < 1e-6


def test_single_ray_shapes():
    H = hm.schwarzschild()
    q, p = np.array([0.0, 10.0, 1.0, 0.0]), np.array([-1.0, 0.5, 0.1, 2.0])
    dq, dp = H.gradient(q, p)
    assert dq.shape == dp.shape == (4,)
    assert np.ndim(H.value(q, p)) == 0


def test_cyclic_coordinates_get_no_partials():
    """t and phi are cyclic in Schwarzschild/Kerr BL: their partials are never allocated."""
    q, p = spherical_points(8)
    for H in (hm.schwarzschild(), hm.kerr(1.0, 0.45), hm.minkowski("spherical")):
        assert H.partials_allocated(q, p) == {"r", "theta"}
    # Kerr–Schild: t is cyclic; a medium n(x, z) carries no y
    ks = hm.kerr(1.0, 0.3, chart="kerr_schild")
    assert "t" not in ks.partials_allocated(*cartesian_points(4))
    med = hm.medium("1 + 0.1*z + 0.01*x")
    assert med.partials_allocated(RNG.uniform(size=(3, 3)), RNG.uniform(size=(3, 3))) == {
        "x",
        "z",
        "p_x",
        "p_y",
        "p_z",
    }
    # and the metric's dH/dt is exactly zero without ever being computed
    dq, _ = hm.kerr(1.0, 0.45).gradient(q, p)
    assert np.all(dq[:, [0, 3]] == 0.0)


def test_kerr_reduces_to_schwarzschild():
    """Kerr at a = 0 is Schwarzschild: H equal to round-off. H is a sum of O(1) terms that
    may cancel (a point drew H = 3.8e-4, off by 2.2e-16: relative 5e-13), so the bound is
    relative 1e-13 or absolute 1e-14 (~50 ulps of the terms; the points are drawn from a
    module-wide generator, so which points a test gets depends on the test order)."""
    q, p = spherical_points(20)
    np.testing.assert_allclose(
        hm.kerr(1.0, 0.0).value(q, p), hm.schwarzschild(1.0).value(q, p), rtol=1e-13, atol=1e-14
    )


def test_kerr_schild_principal_null_direction_is_null():
    """l_mu of docs/design.md is null for eta and g: H(q, l) = 0 anywhere (r from the quartic)."""
    a = 0.45
    ks = hm.kerr(1.0, a, chart="kerr_schild")
    q, _ = cartesian_points(30)
    x, y, z = q[:, 1], q[:, 2], q[:, 3]
    rho2 = x**2 + y**2 + z**2 - a**2
    r = np.sqrt(0.5 * (rho2 + np.sqrt(rho2**2 + 4 * a**2 * z**2)))
    assert np.allclose(r**4 - rho2 * r**2 - a**2 * z**2, 0.0, atol=1e-9)
    l_cov = np.column_stack(
        [np.ones_like(r), (r * x + a * y) / (r**2 + a**2), (r * y - a * x) / (r**2 + a**2), z / r]
    )
    np.testing.assert_allclose(ks.value(q, l_cov), 0.0, atol=1e-12)
    np.testing.assert_allclose(ks.value(q, 2.5 * l_cov), 0.0, atol=1e-11)


def test_separability_detection():
    assert hm.from_expression("0.5*p**2 + cos(q)", q=["q"], p=["p"]).separable
    assert not hm.from_expression("p*q*(p+q-1)", q=["q"], p=["p"]).separable
    assert hm.minkowski("cartesian").separable
    assert not hm.schwarzschild().separable


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda: hm.schwarzschild(rg=-1.0), "positive"),
        (lambda: hm.kerr(rg=1.0, a=0.6), "beyond extremal"),
        (lambda: hm.kerr(rg=1.0, a=0.1, chart="polar"), "unknown chart"),
        (lambda: hm.metric([["1", "0"], ["0"]], coords=["a", "b"]), "2x2"),
        (lambda: hm.metric([["1", "x"], ["y", "1"]], coords=["x", "y"]), "symmetric"),
        (lambda: hm.from_expression("p*q", q=["q", "r"], p=["p"]), "as many momenta"),
        (lambda: hm.from_expression("p*pi", q=["pi"], p=["p"]), "clash"),
    ],
)
def test_parameters_validated_with_clear_errors(make, message):
    with pytest.raises(ValueError, match=message):
        make()


def test_medium_requires_positive_index():
    med = hm.medium("1 - z")
    with pytest.raises(ValueError, match="must be positive"):
        med.check_index([[0.0, 0.0, 2.0]])
    q = np.array([[0.0, 0.0, 0.5], [0.0, 0.0, 1.5]])
    h = med.value(q, np.ones_like(q))
    assert np.isfinite(h[0]) and np.isnan(h[1])  # n <= 0 poisons the ray: it will be flagged

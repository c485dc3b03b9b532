"""The public `core.integrate` contract (docs/design.md): shapes of inputs and results."""

import numpy as np
import pytest

import core
from core import hamiltonians as hm

MEDIUM = hm.medium("1 + 0.1*z")


def medium_rays(n):
    rng = np.random.default_rng(7)
    q = np.column_stack([rng.uniform(-1, 1, n), rng.uniform(-1, 1, n), rng.uniform(0.5, 2, n)])
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return q, d * (1 + 0.1 * q[:, 2:3])


def schwarzschild_rays():
    q = np.array([[0.0, 20.0, np.pi / 2, 0.0], [0.0, 15.0, 1.0, 0.3]])
    p = np.array([[-1.0, -0.9, 0.0, 5.0], [-1.0, -0.8, 2.0, 4.0]])
    return q, p


CASES = {
    "medium_gauss4": (MEDIUM, medium_rays(3), dict(step=0.05, steps=20, method="gauss4")),
    "medium_yoshida4_adaptive": (
        MEDIUM,
        medium_rays(3),
        dict(step=0.05, steps=20, method="yoshida4", adaptive=True),
    ),
    "medium_dopri5": (MEDIUM, medium_rays(3), dict(step=0.05, steps=20, method="dopri5")),
    "schwarzschild_adaptive": (
        hm.schwarzschild(),
        schwarzschild_rays(),
        dict(step=0.02, steps=30, method="gauss4", adaptive=True),
    ),
    "schwarzschild_rk4": (
        hm.schwarzschild(),
        schwarzschild_rays(),
        dict(step=0.1, steps=30, method="rk4"),
    ),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_batch_shapes(case):
    H, (q0, p0), kw = CASES[case]
    q_in, p_in = q0.copy(), p0.copy()
    res = core.integrate(H, q0, p0, **kw)
    N, n = q0.shape
    assert res.q.shape == res.p.shape == (N, n)
    assert res.q.dtype == res.p.dtype == np.float64
    assert np.shape(res.energy_error) == np.shape(res.failed) == np.shape(res.s) == (N,)
    assert res.failed.dtype == bool and not res.failed.any()
    assert np.all(np.isfinite(res.energy_error)) and np.all(res.energy_error >= 0)
    assert np.all(res.s > 0)
    np.testing.assert_array_equal(q0, q_in)  # inputs are not modified
    np.testing.assert_array_equal(p0, p_in)
    captured = getattr(res, "captured", None)
    if captured is not None:
        assert np.shape(captured) == (N,) and np.asarray(captured).dtype == bool


@pytest.mark.parametrize("case", sorted(CASES))
def test_single_ray_matches_its_row_in_the_batch(case):
    H, (q0, p0), kw = CASES[case]
    batch = core.integrate(H, q0, p0, **kw)
    for i in range(len(q0)):
        one = core.integrate(H, q0[i], p0[i], **kw)
        assert one.q.shape == one.p.shape == (H.dim,)
        assert np.ndim(one.energy_error) == np.ndim(one.failed) == np.ndim(one.s) == 0
        assert isinstance(one.failed, (bool, np.bool_)) and not one.failed
        assert isinstance(one.energy_error, (float, np.floating))
        np.testing.assert_allclose(one.q, batch.q[i], rtol=1e-12, atol=1e-13)
        np.testing.assert_allclose(one.p, batch.p[i], rtol=1e-12, atol=1e-13)
        assert one.energy_error == pytest.approx(batch.energy_error[i], rel=1e-6, abs=1e-14)
        assert one.s == pytest.approx(batch.s[i], rel=1e-12)


def test_batch_of_one_keeps_its_batch_shape():
    q0, p0 = medium_rays(1)
    res = core.integrate(MEDIUM, q0, p0, step=0.05, steps=5, method="gauss4")
    assert res.q.shape == (1, 3) and res.failed.shape == res.energy_error.shape == (1,)


def test_array_likes_and_integers_accepted():
    res = core.integrate(
        hm.minkowski(), [[0, 0, 0, 0]], [[-1, 1, 0, 0]], step=0.5, steps=4, method="stormer_verlet"
    )
    assert res.q.dtype == np.float64
    np.testing.assert_allclose(res.q, [[2.0, 2.0, 0.0, 0.0]], atol=1e-14)  # straight line


def test_failed_rays_are_flagged_and_do_not_disturb_the_others():
    """A ray walking into n <= 0 (H becomes NaN) is failed; its neighbours are unchanged."""
    H = hm.medium("z")  # n = z: n <= 0 below z = 0
    q0 = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 0.3], [0.0, 0.0, 2.0]])
    p0 = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -0.3], [0.0, 2.0, 0.0]]) * q0[:, 2:3]
    kw = dict(step=0.1, steps=200, method="gauss4")
    res = core.integrate(H, q0, p0, **kw)
    assert res.failed.shape == res.energy_error.shape == (3,)
    assert res.failed.tolist() == [False, True, False]
    for i in (0, 2):
        one = core.integrate(H, q0[i], p0[i], **kw)
        np.testing.assert_allclose(res.q[i], one.q, rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize(
    "q0, p0",
    [
        (np.zeros((2, 3)), np.zeros((3, 3))),  # batch sizes differ
        (np.zeros((2, 4)), np.zeros((2, 4))),  # wrong dimension for the medium
        (np.zeros(3), np.zeros((1, 3))),  # (n,) with (1, n)
        (np.zeros((2, 2, 3)), np.zeros((2, 2, 3))),  # too many axes
    ],
)
def test_bad_shapes_rejected(q0, p0):
    with pytest.raises(ValueError):
        core.integrate(MEDIUM, q0, p0, step=0.1, steps=1)


def test_unknown_method_rejected():
    q0, p0 = medium_rays(1)
    with pytest.raises(ValueError, match="unknown method"):
        core.integrate(MEDIUM, q0, p0, step=0.1, steps=1, method="euler_forward")

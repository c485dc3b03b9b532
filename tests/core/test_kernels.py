"""Fast evaluation paths of the models agree with the plain ones.

Kerr–Schild is evaluated in its Kerr–Schild form with dual numbers over q only, the
Poincaré-transformed K = g (H - H0) in one fused evaluation, and implicit kicks at fixed
q through a FrozenQ; each must give the same numbers as the definitions they replace.
"""

import numpy as np
import pytest

from core import hamiltonians as hm
from core.integrators import PoincareTransformed
from core.models import base as models_base

RNG = np.random.default_rng(6)


def cartesian(n):
    q = np.vstack([RNG.uniform(-5, 5, n), RNG.uniform(-8, 8, (3, n))])
    return q, RNG.normal(size=(4, n))


def spherical(n):
    q = np.vstack(
        [
            RNG.uniform(-5, 5, n),
            RNG.uniform(2.5, 12, n),
            RNG.uniform(0.2, np.pi - 0.2, n),
            RNG.uniform(-3, 3, n),
        ]
    )
    return q, RNG.normal(size=(4, n))


MODELS = {
    "kerr_schild": (hm.kerr(1.0, 0.45, chart="kerr_schild"), cartesian),
    "kerr_schild_outgoing": (
        hm.kerr(1.0, 0.45, chart="kerr_schild").for_backward_tracing(),
        cartesian,
    ),
    "kerr_bl": (hm.kerr(1.0, 0.45), spherical),
    "schwarzschild": (hm.schwarzschild(1.0), spherical),
}


def generic_poincare(H, Q, P, H0):
    """K = g (H - H0) and its gradient from g, dg and H's own gradient (the definition)."""
    g, dg = H.time_scale_soa(Q)
    h, dq, dp = H.value_gradient_soa(Q, P)
    return g * (h - H0), dg * (h - H0) + g * dq, g * dp


@pytest.mark.parametrize("name", sorted(MODELS))
def test_fused_poincare_equals_definition(name):
    H, points = MODELS[name]
    Q, P = points(50)
    H0 = RNG.normal(size=50)
    K, dq, dp = H.poincare_soa(Q, P, H0)
    K_ref, dq_ref, dp_ref = generic_poincare(H, Q, P, H0)
    np.testing.assert_allclose(K, K_ref, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(dq, dq_ref, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(dp, dp_ref, rtol=1e-12, atol=1e-12)
    _, dp_only = PoincareTransformed(H, H0).gradient_soa(Q, P, wrt="p")
    np.testing.assert_allclose(dp_only, dp_ref, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("name", sorted(MODELS))
def test_kerr_schild_form_equals_expression(name):
    """The evaluation in Kerr–Schild form equals H's text evaluated with full duals."""
    H, points = MODELS[name]
    if not isinstance(H, hm.KerrSchild):
        pytest.skip("Kerr–Schild only")
    Q, P = points(40)
    h, dq, dp = H.value_gradient_soa(Q, P)
    h_ref, dq_ref, dp_ref = H.definition().value_gradient_soa(Q, P)
    np.testing.assert_allclose(h, h_ref, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(dq, dq_ref, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(dp, dp_ref, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("name", sorted(MODELS))
@pytest.mark.parametrize("scaled", [False, True])
def test_frozen_q_gradient_and_subset(name, scaled):
    """dH/dq (or dK/dq) at a frozen Q equals the full gradient there, for any P and subset."""
    H, points = MODELS[name]
    Q, P = points(30)
    H0 = RNG.normal(size=30) if scaled else None
    model = PoincareTransformed(H, H0) if scaled else H
    frozen = model.frozen_q(Q)
    for P_try in (P, P + 0.3 * RNG.normal(size=P.shape)):
        expected, _ = model.gradient_soa(Q, P_try, wrt="q")
        np.testing.assert_allclose(frozen.grad_q(P_try), expected, rtol=1e-12, atol=1e-12)
    idx = np.array([3, 1, 1, 17, 29])
    sub = frozen.subset(idx)
    expected, _ = (
        model.gradient_soa(Q[:, idx], P[:, idx], wrt="q")
        if not scaled
        else PoincareTransformed(H, H0[idx]).gradient_soa(Q[:, idx], P[:, idx], wrt="q")
    )
    np.testing.assert_allclose(sub.grad_q(P[:, idx]), expected, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("name", sorted(MODELS))
def test_blocked_evaluation_equals_whole_batch(name, monkeypatch):
    """Big batches are evaluated block by block (core.models.base.BLOCK): same numbers,
    None kept."""
    H, points = MODELS[name]
    Q, P = points(23)
    H0 = RNG.normal(size=23)
    whole = (
        H.value_soa(Q, P),
        H.value_gradient_soa(Q, P),
        H.gradient_soa(Q, P, wrt="p"),
        H.poincare_soa(Q, P, H0),
        H.poincare_soa(Q, P, H0, wrt="p"),
    )
    monkeypatch.setattr(models_base, "BLOCK", 4)
    parts = (
        H.value_soa(Q, P),
        H.value_gradient_soa(Q, P),
        H.gradient_soa(Q, P, wrt="p"),
        H.poincare_soa(Q, P, H0),
        H.poincare_soa(Q, P, H0, wrt="p"),
    )
    assert parts[2][0] is None and parts[4][1] is None
    for a, b in zip(whole, parts, strict=True):
        for x, y in zip(
            a if isinstance(a, tuple) else (a,), b if isinstance(b, tuple) else (b,), strict=True
        ):
            if x is None:
                assert y is None
            else:
                np.testing.assert_array_equal(x, y)


def test_long_steps_into_the_horizon_are_split_not_failed():
    """At the longest default step the implicit solve cannot follow some rays through
    their last steps into the horizon: the tracer splits those steps (core.tracing.stepping) and the
    rays end captured, as a small-step reference says, never failed."""
    import core
    from core.trace import MAX_STEP, TraceOptions, Tracer

    n = 30
    cam = core.Camera.perspective(
        position=(0, -30, 2), look_at=(0, 0, 0), up=(0, 0, 1), fov_deg=12, width=n, height=n
    )
    scene = core.Scene(model=hm.kerr(1.0, 0.45, chart="kerr_schild"))
    origins, directions = cam.rays()
    ref = Tracer(scene, TraceOptions(method="rk4", step=0.03)).trace(origins, directions)
    captured = (ref.ending == core.ENDING["captured"]).reshape(n, n)
    assert captured.sum() > 100
    padded = np.pad(captured, 1, mode="edge")
    edge = np.zeros_like(captured)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            edge |= padded[1 + dy : n + 1 + dy, 1 + dx : n + 1 + dx] != captured
    for method in ("gauss4", "yoshida4"):
        rays = Tracer(scene, TraceOptions(method=method, step=MAX_STEP)).trace(origins, directions)
        assert np.count_nonzero(rays.ending == core.ENDING["failed"]) == 0, method
        # at such a long step the rays grazing the photon region may end either way: any
        # disagreement must be on the shadow's edge (a neighbour pixel ends the other way)
        differ = (rays.ending == core.ENDING["captured"]).reshape(n, n) != captured
        assert np.all(edge[differ]), method
        assert differ.sum() < 0.02 * captured.size, method


def test_rays_drifting_off_the_light_cone_are_flagged_failed():
    """a/M = 0.998 seen edge-on from 200 rg, tolerance 1e-6: two rays skimming the horizon on
    the prograde edge of the shadow drift to |H - H0| ~ 0.3 p_t^2 (no longer light: a bound
    massive orbit that circles at r ~ 1.06 r+ until max_steps). They must end as failed,
    quickly; their neighbours escape or are captured with H kept."""
    import core
    from core.trace import TraceOptions, Tracer

    cam = core.Camera.perspective(
        position=(0, -200, 0), look_at=(0, 0, 0), up=(0, 0, 1), fov_deg=3.6, width=128, height=96
    )
    origins, directions = cam.rays()
    rows = np.array([43 * 128 + 53, 52 * 128 + 53, 43 * 128 + 52, 52 * 128 + 54])
    scene = core.Scene(model=hm.kerr(1.0, 0.499, chart="kerr_schild"))
    rays = Tracer(
        scene, TraceOptions(method="gauss4", tolerance=1e-6, max_steps=3000), 200.0
    ).trace(origins[rows], directions[rows])
    failed, escaped, captured = (core.ENDING[k] for k in ("failed", "escaped", "captured"))
    assert rays.ending[:2].tolist() == [failed, failed], rays.ending
    assert (rays.steps[:2] < 300).all(), rays.steps  # measured 110
    assert set(rays.ending[2:].tolist()) <= {escaped, captured}, rays.ending
    assert (rays.energy_error[2:] < 1e-2).all(), rays.energy_error

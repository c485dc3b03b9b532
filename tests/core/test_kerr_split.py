"""Kerr's explicit split (core/models/kerr_split.py): the model and its chart against the
Boyer–Lindquist and Kerr–Schild metrics, the exact flows of both parts, the observed order
of the general splittings, and images against dopri5 on Kerr–Schild.

References are independent of the hand-written model: the expression form of Kerr in BL
(core.hamiltonians.kerr, dual numbers over its text), the Kerr–Schild model, text forms of
the split's two parts integrated by scipy's DOP853 at rtol 1e-13, dopri5 renders at
1e-11 in Kerr–Schild, and dopri5 on the Boyer–Lindquist text metric from the same photons.
"""

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import core
from core import hamiltonians as hm
from core.charts import CartesianChart, KerrBLChart
from core.integrators import METHODS, SplitRequired
from core.models import KerrBoyerLindquist
from core.models.kerr_split import C0
from core.observer import check_camera, inverse_metric_soa, spacetime_momenta
from core.trace import TraceOptions, Tracer

RG, A = 1.0, 0.45  # a/M = 0.9
M = 0.5 * RG
B = math.sqrt(M * M - A * A)
MODEL = KerrBoyerLindquist(RG, A)
CHART = KerrBLChart(M, A)

# the split's parts as text over (t, s, theta, phi), with E = -p_t, L = p_phi (the module)
_DEFS = [
    ("r", "m + b*cosh(s)"),
    ("delta", "(b*sinh(s))**2"),
    ("pr", "(r**2 + a**2)*(-p_t) - a*p_phi"),
    ("cc", "c0*m**2*p_t**2"),
]
_V = "pr**2/(2*delta) - a*p_t*p_phi - 0.5*(a*p_t*sin(theta))**2"
_T = "0.5*(p_s**2 + p_theta**2 + p_phi**2/sin(theta)**2)"
_PARAMS = {"m": M, "b": B, "a": A, "c0": C0}
_NAMES = (("t", "s", "theta", "phi"), ("p_t", "p_s", "p_theta", "p_phi"))


def _text(expr):
    return hm.from_expression(expr, *_NAMES, parameters=_PARAMS, definitions=_DEFS)


DRIFT_H = _text(f"2*sqrt({_T} + cc)")
KICK_H = _text(f"-2*sqrt({_V} + cc)")
LAMBDA_H = _text(f"2*sqrt({_T} + cc) - 2*sqrt({_V} + cc)")


def dop853(H, q, p, s):
    """(q, p) after a time s of H's flow, by DOP853 at rtol 1e-13 (one ray, (4,) each)."""

    def f(_, y):
        dq, dp = H.gradient_soa(y[:4, None], y[4:, None])
        return np.concatenate((dp[:, 0], -dq[:, 0]))

    y = solve_ivp(f, (0.0, s), np.concatenate((q, p)), method="DOP853", rtol=1e-13, atol=1e-14).y
    return y[:4, -1], y[4:, -1]


def photon(s, theta, phi, p_s, p_theta, p_phi):
    """(q, p) of a photon (H = 0) with these coordinates and momenta: p_t solved for."""
    q = np.array([0.0, s, theta, phi])
    ginv = inverse_metric_soa(MODEL, q[:, None])[0]
    p = np.array([0.0, p_s, p_theta, p_phi])
    # g^tt p_t^2 + 2 p_t (g^ti p_i) + p.g.p = 0, the root with E = -p_t > 0
    qa, qb, qc = ginv[0, 0], 2 * ginv[0] @ p, p @ ginv @ p
    p[0] = (-qb + math.sqrt(qb * qb - 4 * qa * qc)) / (2 * qa)
    return q, p


def test_model_is_kerr_in_boyer_lindquist():
    """H(t, s, theta, phi) = H_BL(t, r(s), theta, phi; p_t, p_s / sqrt(Delta), ...) for random
    states, and its gradient against central differences."""
    rng = np.random.default_rng(1)
    Q = np.stack([rng.uniform(-1, 1, 8), rng.uniform(0.2, 4, 8), rng.uniform(0.1, 3, 8),
                  rng.uniform(-3, 3, 8)])  # fmt: skip
    P = rng.normal(size=(4, 8))
    bl = hm.kerr(RG, A, chart="boyer_lindquist")
    r = M + B * np.cosh(Q[1])
    sq = B * np.sinh(Q[1])
    Qb, Pb = np.stack([Q[0], r, Q[2], Q[3]]), np.stack([P[0], P[1] / sq, P[2], P[3]])
    assert MODEL.value_soa(Q, P) == pytest.approx(bl.value_soa(Qb, Pb), rel=1e-11)
    dq, dp = MODEL.gradient_soa(Q, P)
    eps = 1e-6
    for i in range(4):
        e = np.zeros((4, 1))
        e[i] = eps
        fd_q = (MODEL.value_soa(Q + e, P) - MODEL.value_soa(Q - e, P)) / (2 * eps)
        fd_p = (MODEL.value_soa(Q, P + e) - MODEL.value_soa(Q, P - e)) / (2 * eps)
        assert dq[i] == pytest.approx(fd_q, rel=1e-6, abs=1e-7)
        assert dp[i] == pytest.approx(fd_p, rel=1e-6, abs=1e-7)


def test_chart_carries_the_kerr_schild_metric():
    """The chart's map to the tracer's (outgoing Kerr–Schild) frame, with t_KS = t - T(r),
    T' = 2 M r / Delta, pulls the Kerr–Schild inverse metric back to the model's; and
    to_coords inverts to_cartesian."""
    ks = hm.kerr(RG, A, chart="kerr_schild", outgoing=True)
    S = np.array([[0.3, 1.2, 2.5, 4.0], [0.4, 1.3, 2.0, 2.9], [-2.0, 0.5, 2.0, 3.0]])
    X = CHART.to_cartesian(S)
    back = CHART.to_coords(X)
    assert back[:2] == pytest.approx(S[:2], abs=1e-12)
    assert np.cos(back[2] - S[2]) == pytest.approx(1.0, abs=1e-12)
    n = S.shape[1]
    J = np.zeros((n, 4, 4))  # d(t_KS, x, y, z) / d(t, s, theta, phi)
    J[:, 0, 0] = 1.0
    r = M + B * np.cosh(S[0])
    J[:, 0, 1] = -2 * M * r / (B * B * np.sinh(S[0]) ** 2) * (B * np.sinh(S[0]))
    eps = 1e-6
    for j in range(3):
        e = np.zeros((3, 1))
        e[j] = eps
        J[:, 1:, j + 1] = ((CHART.to_cartesian(S + e) - CHART.to_cartesian(S - e)) / (2 * eps)).T
    assert J[:, 1:, 1:] == pytest.approx(CHART.jacobian(S), rel=1e-7, abs=1e-8)
    g_ks = inverse_metric_soa(ks, np.vstack([np.zeros((1, n)), X]))
    Ji = np.linalg.inv(J)
    pulled = np.einsum("nia,nab,njb->nij", Ji, g_ks, Ji)
    mine = inverse_metric_soa(MODEL, np.vstack([np.zeros((1, n)), S]))
    assert pulled == pytest.approx(mine, rel=1e-6, abs=1e-7)


def test_camera_momenta_are_the_kerr_schild_ones():
    """A camera's photon momenta built in the BL chart are its Kerr–Schild ones, transformed
    as covectors: p_BL = p_KS . d x_KS / d q (the same observer, the same directions)."""
    ks = hm.kerr(RG, A, chart="kerr_schild", outgoing=True)
    rng = np.random.default_rng(3)
    D = rng.normal(size=(3, 6))
    D /= np.linalg.norm(D, axis=0)
    X = np.tile(np.array([[0.0], [-30.0], [2.0]]), (1, 6))
    Qk, Pk = spacetime_momenta(ks, CartesianChart(0), X, D)
    S = CHART.to_coords(X)
    Qb, Pb = spacetime_momenta(MODEL, CHART, S, D)
    r = M + B * np.cosh(S[0])
    dt_ds = -2 * M * r / (B * np.sinh(S[0]))
    J = CHART.jacobian(S)  # (N, 3, 3)
    expect = np.empty_like(Pb)
    expect[0] = Pk[0]
    expect[1:] = np.einsum("in,nij->jn", Pk[1:], J)
    expect[1] += Pk[0] * dt_ds
    assert Pb == pytest.approx(expect, rel=1e-9, abs=1e-10)


STATES = [  # (s, theta, phi, p_s, p_theta, p_phi): ordinary, near the pole, falling in
    (2.0, 1.2, 0.3, -1.5, 0.7, 2.0),
    (1.5, 0.15, -1.0, -0.8, -1.1, 0.05),
    (0.9, 2.0, 2.0, -3.0, 0.4, -1.0),
]


@pytest.mark.parametrize("state", STATES)
def test_each_part_flows_exactly(state):
    """The drift (a great circle on the sphere and s moving at p_s / sqrt(T + c)) and the
    kick agree with DOP853 on the text form of each part alone (near the pole too)."""
    q, p = photon(*state)
    split = MODEL.split_parts(0.0)
    for flow, H in ((split.drift, DRIFT_H), (split.kick, KICK_H)):
        Q, P = q[:, None].copy(), p[:, None].copy()
        flow(Q, P, 0.7)
        q_ref, p_ref = dop853(H, q, p, 0.7)
        assert Q[:3, 0] == pytest.approx(q_ref[:3], abs=1e-10)
        assert math.cos(Q[3, 0] - q_ref[3]) == pytest.approx(1.0, abs=1e-18)
        assert P[:, 0] == pytest.approx(p_ref, abs=1e-10)


@pytest.mark.parametrize("name, steps", [("blanes_moan_s6", (6, 8, 12, 16)),
                                         ("blanes_moan_s10", (6, 8, 10, 12)),
                                         ("blanes_moan6", (6, 8, 12, 16)),
                                         ("blanes_moan4", (6, 8, 12, 16))])  # fmt: skip
def test_observed_order_against_dop853(name, steps):
    """A ray passing the hole at a few r+ (Λ's flow over σ = 4 by DOP853 on its text form):
    the error falls at the method's order on this split, ``order_on`` (fitted slope within
    0.3): blanes_moan6 reaches 4 here (Λ is not of Runge–Kutta–Nyström type), not 6."""
    q, p = photon(*STATES[0])
    q_ref, p_ref = dop853(LAMBDA_H, q, p, 4.0)
    split = MODEL.split_parts(0.0)
    method = METHODS[name]
    errs = []
    for n in steps:
        state = method.init(split, q[:, None], p[:, None])
        for _ in range(n):
            state, _ = method.step(split, state, 4.0 / n)
        Q, P = method.qp(state)
        errs.append(max(np.abs(Q[:, 0] - q_ref).max(), np.abs(P[:, 0] - p_ref).max()))
    slope = np.polyfit(np.log(4.0 / np.array(steps)), np.log(errs), 1)[0]
    assert not split.nystrom
    assert method.order_on(split) == (6 if name == "blanes_moan_s10" else 4)
    assert slope == pytest.approx(method.order_on(split), abs=0.3), errs


def _kerr_pixels(a, method, tolerance, size=16):
    scene = core.Scene(
        model=hm.kerr(rg=RG, a=a, chart="kerr_schild"),
        objects=[core.Sphere(center=(0, 8, 0), radius=1, color=(1, 0, 0, 1))],
    )
    cam = core.Camera.perspective(position=(0, -30, 2), look_at=(0, 0, 0), up=(0, 0, 1),
                                  fov_deg=40, width=size, height=size)  # fmt: skip
    opts = TraceOptions(method=method, tolerance=tolerance, region_radius=2000.0,
                             max_steps=10**5)  # fmt: skip
    origins, dirs = cam.rays()
    with np.errstate(all="ignore"):
        return Tracer(scene, opts, 30.0).trace(origins, dirs), math.radians(40) / size


@pytest.mark.parametrize("a", [0.45, 0.499])
def test_images_agree_with_dopri5_on_kerr_schild(a):
    """a/M = 0.9 and 0.998, 16x16 pixels: the split's endings are dopri5's at 1e-11 in
    Kerr–Schild (the same captured set: BL's capture radius against KS's horizon), and
    99 % of the escaped directions within 0.1 px; no ray failed."""
    ref, pixel = _kerr_pixels(a, "dopri5", 1e-11)
    run, _ = _kerr_pixels(a, "blanes_moan_s6", 1e-6)
    assert np.array_equal(run.ending, ref.ending)
    assert not np.any(run.ending == core.ENDING["failed"])
    esc = ref.ending == core.ENDING["escaped"]
    cos = np.clip(np.einsum("ij,ij->i", run.direction[esc], ref.direction[esc]), -1, 1)
    err = np.arccos(cos) / pixel
    assert np.percentile(err, 99) < 0.1


def test_splittings_refuse_kerr_without_the_split():
    """BL Kerr as text (no split) and an extremal Kerr–Schild hole (BL's s needs |a| < M)
    keep the implicit methods: the splittings are refused with a message."""
    for model in (hm.kerr(RG, A, chart="boyer_lindquist"), hm.kerr(RG, 0.5, chart="kerr_schild")):
        scene = core.Scene(model=model)
        with pytest.raises(SplitRequired, match="split"):
            Tracer(scene, TraceOptions(method="blanes_moan_s6"), 30.0)


def test_default_method_falls_back_where_the_split_cannot_start():
    """A Kerr–Schild camera on the polar axis: the default method is then gauss4 in
    Kerr–Schild (the split is refused there when asked for by name); elsewhere, between r+
    and BL's capture radius too, it is the split's."""
    from core.render import tracer_for_camera

    scene = core.Scene(model=hm.kerr(RG, A, chart="kerr_schild"))
    r_c = MODEL.r_capture
    assert MODEL.horizon < 0.5 * (MODEL.horizon + r_c) < r_c
    for position, expect in (
        ((0.0, -30.0, 2.0), "blanes_moan_s10"),
        ((0.0, 0.0, 30.0), "gauss4"),
        ((0.0, 0.0, 0.5 * (MODEL.horizon + r_c)), "gauss4"),
        (_equatorial(0.5 * (MODEL.horizon + r_c)), "blanes_moan_s10"),
    ):
        tracer = tracer_for_camera(scene, TraceOptions(), 30.0, position)
        assert tracer.method.name == expect, position
    with pytest.raises(core.CoordinateAxisError, match="gauss4"):
        check_camera(Tracer(scene, TraceOptions(method="blanes_moan_s10"), 30.0), (0.0, 0.0, 30.0))


def _equatorial(r):
    """A Kerr–Schild point (0, -sqrt(r^2 + a^2), 0) at BL radius r in the equatorial plane."""
    return (0.0, -math.sqrt(r * r + A * A), 0.0)


def _bl_endings(camera, scene):
    """Escaped (0) or captured (1) of each pixel's photon, followed by dopri5 at 1e-11 on the
    Boyer–Lindquist text metric (core.hamiltonians.kerr) from the camera's momenta (the
    Kerr–Schild observer's, through the split's chart: test_camera_momenta_are_the_kerr_schild_
    ones): captured at its 1.01 r+, escaped moving out beyond 20 rg (past every photon orbit,
    no turning point), 4 (undecided) otherwise."""
    tracer = Tracer(scene, TraceOptions(), 30.0)
    origins, dirs = camera.rays()
    X = ((origins - scene.center) @ tracer.rotation).T
    Q, P = spacetime_momenta(MODEL, CHART, CHART.to_coords(X), (dirs @ tracer.rotation).T)
    sh = np.sinh(Q[1])
    q0 = np.stack([Q[0], M + B * np.cosh(Q[1]), Q[2], Q[3]]).T
    p0 = np.stack([P[0], P[1] / (B * sh), P[2], P[3]]).T
    bl = hm.kerr(RG, A, chart="boyer_lindquist")
    with np.errstate(all="ignore"):
        res = core.integrate(bl, q0, p0, 0.05, 20_000, "dopri5", tol=1e-11, max_steps=10**5)
    escaped = ~res.captured & (res.q[:, 1] > 20.0) & (res.p[:, 1] > 0)
    return np.where(res.captured, 1, np.where(escaped, 0, 4))


def test_camera_just_outside_the_horizon_sees_out():
    """a/M = 0.9, a camera at 1.02 r+ (below BL's capture radius, in the ergoregion)
    looking out, 32x24: the default method is the split, and every pixel escapes or is
    captured as its photon does on the Boyer–Lindquist metric by dopri5 (280 of 768
    escape); no ray failed."""
    r_cam = 1.02 * MODEL.horizon
    assert r_cam < MODEL.r_capture
    scene = core.Scene(model=hm.kerr(RG, A, chart="kerr_schild"))
    position = _equatorial(r_cam)
    camera = core.Camera.perspective(position=position, look_at=(0, -30, 0), up=(0, 0, 1),
                                     fov_deg=90, width=32, height=24)  # fmt: skip
    result = core.render(scene, camera, passes=("ending",), workers=1)
    assert result.summary["method"] == "blanes_moan_s10"
    ending = result.passes["ending"].reshape(-1)
    ref = _bl_endings(camera, scene)
    assert not np.any(ref == 4)
    assert np.array_equal(ending, ref), np.flatnonzero(ending != ref)
    assert np.sum(ending == core.ENDING["escaped"]) == 280


def test_split_refuses_a_camera_only_inside_the_horizon():
    """The split's camera check: a camera at 1.001 r+ is outside (no error), one at 0.98 r+
    inside ("inside the black hole's horizon"); a render from there raises it too."""
    scene = core.Scene(model=hm.kerr(RG, A, chart="kerr_schild"))
    split = Tracer(scene, TraceOptions(method="blanes_moan_s10"), 30.0)
    check_camera(split, _equatorial(1.001 * MODEL.horizon))
    inside = _equatorial(0.98 * MODEL.horizon)
    with pytest.raises(core.InsideHorizonError, match="inside the black hole's horizon"):
        check_camera(split, inside)
    camera = core.Camera.perspective(position=inside, look_at=(0, -30, 0), up=(0, 0, 1),
                                     fov_deg=90, width=4, height=3)  # fmt: skip
    with pytest.raises(core.InsideHorizonError, match="inside the black hole's horizon"):
        core.render(scene, camera, passes=("ending",), workers=1)


def test_split_keeps_a_bound_orbit_on_its_level_set():
    """A bound timelike orbit (m = 1, inclined, r = 12.0 ... 12.4 rg) around a/M = 0.9, 4000
    leapfrog steps of 0.5 on the split with H0 = -1/2: |Λ| over the last three quarters stays
    within 1.5x of its level over the first quarter (bounded, no drift; benchmarks/stress.py
    long_split_kerr runs 10^6 steps: the same level), and E, L are kept exactly."""
    model, q0, p0, H0 = stress_orbit()
    split = model.split_parts(H0)
    method = METHODS["leapfrog"]
    state = method.init(split, q0, p0)
    lam = []
    r = []
    for _ in range(4000):
        state, ok = method.step(split, state, 0.5)
        Q, P = method.qp(state)
        lam.append(abs(split.value_soa(Q, P)[0]))
        r.append(M + B * math.cosh(Q[1, 0]))
    assert ok.all()
    assert 11.9 < min(r) and max(r) < 12.5  # bound: r = 12.0 ... 12.42 rg
    assert max(lam[1000:]) < 1.5 * max(lam[:1000])
    assert P[0, 0] == p0[0, 0] and P[3, 0] == p0[3, 0]


def stress_orbit():
    """benchmarks/stress.py's kerr_bound_orbit."""
    import importlib.util
    from pathlib import Path

    path = Path(__file__).parents[2] / "benchmarks" / "stress.py"
    spec = importlib.util.spec_from_file_location("stress_for_kerr", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.kerr_bound_orbit(A)

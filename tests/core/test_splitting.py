"""Explicit symplectic splittings: coefficients, observed order, the exact flows
of a medium's split, the refusal where a model offers none, and images against dopri5.

References are independent of the methods: the exact circular Kepler orbit, the analytic
parabola of n^2 = 1 + k z (tests/core/test_medium.py), a tight dopri5 integration of each
split part on its own, and dopri5 renders at 1e-11.
"""

import math

import numpy as np
import pytest

import core
from core import hamiltonians as hm
from core.integrators import METHODS, PoincareTransformed, SplitRequired, Splitting

SPLITTINGS = ("leapfrog", "blanes_moan4", "blanes_moan6", "blanes_moan_s6", "blanes_moan_s10")


@pytest.mark.parametrize("name", SPLITTINGS)
def test_coefficients_are_consistent_and_symmetric(name):
    m = METHODS[name]
    assert m.symplectic and m.explicit and isinstance(m, Splitting)
    assert math.fsum(m.kicks) == pytest.approx(1.0, abs=1e-14)
    assert math.fsum(m.drifts) == pytest.approx(1.0, abs=1e-14)
    assert m.kicks == m.kicks[::-1] and m.drifts == m.drifts[::-1]
    stages = {"leapfrog": 1, "blanes_moan4": 6, "blanes_moan6": 11}
    assert m.stages == {**stages, "blanes_moan_s6": 6, "blanes_moan_s10": 10}[name]


KEPLER = hm.from_expression(
    "0.5*(px**2 + py**2) - 1/sqrt(x**2 + y**2)", q=["x", "y"], p=["px", "py"]
)


@pytest.mark.parametrize(
    "name, steps",
    [
        ("leapfrog", [80, 160, 320, 640]),
        ("blanes_moan4", [40, 80, 160, 320]),
        ("blanes_moan6", [40, 60, 80, 120]),
        ("blanes_moan_s6", [40, 80, 160, 320]),
        ("blanes_moan_s10", [40, 60, 80, 120]),
    ],
)
def test_observed_order_on_a_kepler_ellipse(name, steps):
    """Separable Kepler (its own split), eccentricity 0.44, one period T = 2 pi a^(3/2):
    the exact orbit is back at its start; the error falls at the nominal order (fitted
    slope within 0.3)."""
    assert KEPLER.separable
    q0, p0 = np.array([1.0, 0.0]), np.array([0.0, 1.2])
    a = 1.0 / (2.0 * (1.0 - 0.5 * 1.2**2))
    T = 2 * math.pi * a**1.5
    errs = []
    for n in steps:
        res = core.integrate(KEPLER, q0, p0, step=T / n, steps=n, method=name)
        errs.append(np.abs(np.concatenate([res.q - q0, res.p - p0])).max())
    slope = np.polyfit(np.log(T / np.array(steps)), np.log(errs), 1)[0]
    assert slope == pytest.approx(METHODS[name].order, abs=0.3), errs


def test_blanes_moan4_error_constant_is_far_below_the_triple_jump():
    """At equal force evaluations (BM4: 6 per step, Yoshida's triple jump of leapfrog: 3),
    BM4 is over 50x more accurate on Kepler (measured: ~500x)."""
    T = 2 * math.pi  # the circular orbit
    bm = core.integrate(
        KEPLER, [1.0, 0.0], [0.0, 1.0], step=T / 40, steps=40, method="blanes_moan4"
    )
    yo = core.integrate(KEPLER, [1.0, 0.0], [0.0, 1.0], step=T / 80, steps=80, method="yoshida4")
    err = [np.hypot(r.q[0] - 1.0, r.q[1]) for r in (bm, yo)]
    assert err[0] * 50 < err[1], err


def test_refused_without_a_split():
    """Non-separable H without a split (a metric) is refused with a message naming why."""
    with pytest.raises(SplitRequired, match="explicit splitting.*gauss4"):
        core.integrate(
            hm.schwarzschild(1.0),
            [0, 10, 1.5, 0],
            [-1, -1, 0, 4],
            step=0.1,
            steps=3,
            method="blanes_moan4",
        )
    scene = core.Scene(model=hm.kerr(1.0, 0.45))  # Boyer–Lindquist as text: no split
    cam = core.Camera.perspective(
        position=(0, -30, 2), look_at=(0, 0, 0), up=(0, 0, 1), fov_deg=40, width=4, height=4
    )
    with pytest.raises(SplitRequired, match="leapfrog"):
        core.render(scene, cam, method="leapfrog")
    assert issubclass(SplitRequired, ValueError)


MEDIUM = hm.medium("1 + 0.1*z + 0.05*cos(x)*sin(2*y)")
LITERAL = hm.medium("1/(1 + 0.1*z + 0.05*cos(x)*sin(2*y))**2", literal=True)


@pytest.mark.parametrize("model", [MEDIUM, LITERAL], ids=["physical", "literal"])
def test_split_is_the_poincare_transformed_hamiltonian(model):
    """The split K = |p|^2/2 - H0 w equals g (H - H0) of the general transformation
    (value and gradient), and its q-gradient matches central finite differences."""
    rng = np.random.default_rng(1)
    Q = rng.uniform(-1, 1, (3, 50))
    P = rng.normal(size=(3, 50))
    H0 = rng.uniform(0.3, 0.7, 50)
    split = model.split_parts(H0)
    general = PoincareTransformed(model, H0)
    np.testing.assert_allclose(
        split.value_soa(Q, P), general.value_soa(Q, P), rtol=1e-13, atol=1e-13
    )
    dq, dp = split.gradient_soa(Q, P)
    gq, gp = general.gradient_soa(Q, P)
    np.testing.assert_allclose(dq, gq, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(dp, gp, rtol=1e-12, atol=1e-12)
    eps = 1e-6
    for i in range(3):
        e = np.zeros((3, 1))
        e[i] = eps
        fd = (split.value_soa(Q + e, P) - split.value_soa(Q - e, P)) / (2 * eps)
        np.testing.assert_allclose(dq[i], fd, rtol=1e-7, atol=1e-8)


@pytest.mark.parametrize("part", ["kick", "drift"])
def test_each_split_part_flows_exactly(part):
    """kick(t) and drift(t) are the exact flows of V = -H0 w(q) and T = |p|^2/2: they match
    a dopri5 integration (1e-13) of that part alone over t = 0.7 to 1e-10."""
    H0 = 0.5
    split = MEDIUM.split_parts(H0)
    q0, p0 = np.array([0.3, -0.2, 0.4]), np.array([0.8, 0.5, -0.3])
    Q, P = q0[:, None].copy(), p0[:, None].copy()
    getattr(split, part)(Q, P, 0.7)
    if part == "kick":
        text = f"-{H0}*(1 + 0.1*z + 0.05*cos(x)*sin(2*y))**2 + 0*(px + py + pz)"
    else:
        text = "0.5*(px**2 + py**2 + pz**2) + 0*(x + y + z)"
    alone = hm.from_expression(text, q=["x", "y", "z"], p=["px", "py", "pz"])
    ref = core.integrate(alone, q0, p0, step=0.7, steps=1, method="dopri5", tol=1e-13)
    np.testing.assert_allclose(Q[:, 0], ref.q, rtol=0, atol=1e-10)
    np.testing.assert_allclose(P[:, 0], ref.p, rtol=0, atol=1e-10)


@pytest.mark.parametrize("name", SPLITTINGS[1:])
def test_clocked_split_follows_the_analytic_parabola_and_its_parameter(name):
    """n^2 = 1 + k z, adaptive (Poincaré) steps: every recorded point lies on the analytic
    parabola of tests/core/test_medium.py, and the parameter s reached (the clock, a fourth
    coordinate) is the one a tight fixed-step gauss4 run needs to reach the same point."""
    k, z0, a0, az = 0.2, 1.0, 0.25, 0.5
    H = hm.medium("sqrt(1 + k*z)", parameters={"k": k})
    n0 = math.sqrt(1 + k * z0)
    t = np.array([math.cos(a0) * math.cos(az), math.cos(a0) * math.sin(az), -math.sin(a0)])
    q0, p0 = np.array([0.0, 0.0, z0]), n0 * t
    res = core.integrate(
        H, q0, p0, step=0.05, steps=120, method=name, adaptive=True, record_every=1
    )
    assert not res.failed
    q = res.trajectory.q
    xi = np.hypot(q[:, 0], q[:, 1])
    C = n0 * math.cos(a0)
    assert xi[-1] > 2 * C**2 * math.tan(a0) / k  # past the turn
    z_exact = z0 - math.tan(a0) * xi + k * xi**2 / (4 * C**2)
    assert np.max(np.abs(q[:, 2] - z_exact)) < 1e-9
    assert res.energy_error < 1e-10
    ref = core.integrate(H, q0, p0, step=res.s / 2000, steps=2000, method="gauss4")
    np.testing.assert_allclose(res.q, ref.q, rtol=0, atol=1e-9)


@pytest.mark.parametrize("name", ["leapfrog", "blanes_moan4"])
def test_energy_stays_bounded_over_long_runs(name):
    """A ray guided in a graded-index fibre, n^2 = 2 - (x^2 + y^2), 16 000 steps of 0.25
    (over 1000 oscillations): a splitting's |H - H0| after 100x the time stays within 2x of
    its level over the first 160 steps, while rk4's grows by over 30x (linearly; measured:
    leapfrog 1.06x, blanes_moan4 1.02x, rk4 97x)."""
    H = hm.medium("sqrt(2 - (x**2 + y**2))")
    q0, p0 = np.array([0.3, 0.0, 0.0]), np.array([0.0, 0.2, 1.0])
    p0 *= math.sqrt(2 - 0.09) / np.linalg.norm(p0)
    growth = {}
    for method in (name, "rk4"):
        short, long = (
            core.integrate(
                H, q0, p0, step=0.25, steps=n, method=method, adaptive=True, energy_every=10
            )
            for n in (160, 16_000)
        )
        assert not long.failed
        growth[method] = long.energy_error / short.energy_error
    assert growth[name] < 2.0 and growth["rk4"] > 30.0, growth


def _mirage(width: int, height: int):
    """The seed's Fig. 10 view (hot ground, Eq. 17, literal form) and its pixel angle."""
    scene, cam = core.presets.mirage_view("fig10", width, height)
    return scene, cam, math.radians(core.presets.MIRAGE_VIEWS["fig10"][4]) / width


@pytest.mark.parametrize("name", ["leapfrog", "blanes_moan4"])
def test_mirage_image_agrees_with_dopri5(name):
    """40x30 mirage: every ray ends as with dopri5 (1e-11), and 99 % of the hit points and
    escape directions lie within 0.1 px of it (pixels of this camera at the hit distance)."""
    from core.trace import TraceOptions, Tracer

    scene, cam, pixel = _mirage(40, 30)
    origins, directions = cam.rays()
    ref = Tracer(scene, TraceOptions(method="dopri5", tolerance=1e-11)).trace(origins, directions)
    out = Tracer(scene, TraceOptions(method=name, step=0.1)).trace(origins, directions)
    np.testing.assert_array_equal(out.ending, ref.ending)
    hit = ref.ending == core.ENDING["hit"]
    assert hit.sum() > 300 and (~hit).sum() > 300
    dist = np.linalg.norm(ref.position[hit] - origins[hit], axis=1)
    err_hit = np.linalg.norm(out.position[hit] - ref.position[hit], axis=1) / (dist * pixel)
    cos = np.clip(np.einsum("ij,ij->i", out.direction[~hit], ref.direction[~hit]), -1, 1)
    err = np.concatenate([err_hit, np.arccos(cos) / pixel])
    assert np.percentile(err, 99) < 0.1, np.percentile(err, 99)


# --------------------------------------------------------------------------------------
# Schwarzschild as the isotropic optical medium (core/schwarzschild_optical.py)


def test_isotropic_chart_round_trip_and_radius():
    """r = rho (1 + M/2 rho)^2 both ways, directions kept, and the horizon at rho = M/2."""
    from core.charts import IsotropicChart

    chart = IsotropicChart(0.5)
    rng = np.random.default_rng(3)
    X = rng.normal(size=(3, 200)) * 20
    X *= (1.05 + np.abs(rng.normal(size=200))) / np.linalg.norm(X, axis=0)  # r > 1.05 rg
    S = chart.to_coords(X)
    rho, r = np.linalg.norm(S, axis=0), np.linalg.norm(X, axis=0)
    np.testing.assert_allclose(rho * (1 + 0.25 / rho) ** 2, r, rtol=1e-13)
    np.testing.assert_allclose(chart.to_cartesian(S), X, rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(S / rho, X / r, rtol=1e-13, atol=1e-15)
    # the world velocity is the Jacobian of to_cartesian (central differences)
    dS = rng.normal(size=(3, 200))
    eps = 1e-6
    fd = (chart.to_cartesian(S + eps * dS) - chart.to_cartesian(S - eps * dS)) / (2 * eps)
    np.testing.assert_allclose(chart.cartesian_velocity(S, dS), fd, rtol=1e-7, atol=1e-8)


def test_logarithmic_split_is_tangent_to_the_optical_rays():
    """Lambda = ln A - ln B moves along K's flow divided by A: on the rays (K = 0) its
    gradient is K's scaled by 1/A, and each part's flow matches dopri5 on that part alone."""
    from core.models.schwarzschild_optical import SchwarzschildOptical

    model = SchwarzschildOptical(1.0)
    rng = np.random.default_rng(4)
    Q = rng.normal(size=(3, 40)) * 6
    D = rng.normal(size=(3, 40))
    _, P = core.observer.medium_momenta(model, Q, D)  # H = 1/2: on the rays
    split = model.split_parts(0.5)
    K = PoincareTransformed(model, 0.5)
    A = 0.5 * np.einsum("ij,ij->j", P, P) - 0.5
    for mine, theirs in zip(split.gradient_soa(Q, P), K.gradient_soa(Q, P), strict=True):
        np.testing.assert_allclose(mine, theirs / A, rtol=1e-10, atol=1e-12)


def _schwarzschild_rays(width):
    cam = core.Camera.perspective(
        position=(0, -30, 2), look_at=(0, 0, 0), up=(0, 0, 1), fov_deg=40, width=width, height=width
    )
    board = core.Plane(
        point=(0, 12, 0),
        normal=(0, -1, 0),
        u_axis=(1, 0, 0),
        extent=(16, 16),
        color=(0.9, 0.7, 0.2, 1),
    )
    scene = core.Scene(model=hm.schwarzschild(1.0), objects=[board])
    origins, directions = cam.rays()
    return scene, origins, directions, math.radians(40) / width


@pytest.mark.parametrize("name", SPLITTINGS[1:3])  # Kerr's: tests/core/test_kerr_split.py
def test_schwarzschild_image_agrees_with_dopri5(name):
    """A 24x24 Schwarzschild frame with a board behind the hole, traced explicitly in the
    isotropic medium at the default step for tolerance 1e-8, against dopri5 (1e-11) in
    Kerr–Schild coordinates: the same endings, 99 % of escape directions and hit points
    within 0.1 px (measured: ~1e-4 px)."""
    from core.trace import TraceOptions, Tracer

    scene, origins, directions, pixel = _schwarzschild_rays(24)
    ref = Tracer(scene, TraceOptions(method="dopri5", tolerance=1e-11), extent=30).trace(
        origins, directions
    )
    tracer = Tracer(scene, TraceOptions(method=name, tolerance=1e-8), extent=30)
    assert tracer.model.chart.name == "isotropic"
    out = tracer.trace(origins, directions)
    np.testing.assert_array_equal(out.ending, ref.ending)
    counts = np.bincount(ref.ending, minlength=3)
    assert counts[0] > 50 and counts[1] > 20 and counts[2] > 50  # escaped, captured, hit
    esc, hit = ref.ending == 0, ref.ending == 2
    cos = np.clip(np.einsum("ij,ij->i", out.direction[esc], ref.direction[esc]), -1, 1)
    dist = np.linalg.norm(ref.position[hit] - origins[hit], axis=1)
    err = np.concatenate(
        [
            np.arccos(cos) / pixel,
            np.linalg.norm(out.position[hit] - ref.position[hit], axis=1) / (dist * pixel),
        ]
    )
    assert np.percentile(err, 99) < 0.1, np.percentile(err, 99)


def test_schwarzschild_shadow_edge_at_the_critical_impact():
    """Rays from r = 60 rg with impact b = b_c (1 -+ 1e-4), b_c = 3 sqrt(3) M: the inner one
    is captured, the outer one escapes (explicit blanes_moan6 at its default step). A static
    observer at r sees a ray of impact b at sin(alpha) = (b / r) sqrt(1 - 2M/r) from the
    inward radial direction."""
    from core.trace import TraceOptions, Tracer

    scene = core.Scene(model=hm.schwarzschild(1.0))
    bc, r = 3 * math.sqrt(3) * 0.5, 60.0
    sin_a = bc * np.array([1 - 1e-4, 1 + 1e-4]) / r * math.sqrt(1 - 1.0 / r)
    origins = np.array([[-r, 0.0, 0.0], [-r, 0.0, 0.0]])
    directions = np.stack([np.sqrt(1 - sin_a**2), sin_a, np.zeros(2)], axis=1)
    out = Tracer(scene, TraceOptions(tolerance=1e-10), extent=60).trace(origins, directions)
    assert out.ending.tolist() == [core.ENDING["captured"], core.ENDING["escaped"]]


def test_default_method_per_model():
    """Explicit splittings where the model offers a split, gauss4 elsewhere."""
    from core.trace import default_method

    assert default_method(hm.schwarzschild(1.0)) == "blanes_moan6"
    assert default_method(hm.medium("1 + 0.1*z")) == "blanes_moan4"
    assert default_method(hm.kerr(1.0, 0.45, chart="kerr_schild")) == "blanes_moan_s10"
    assert default_method(hm.kerr(1.0, 0.5, chart="kerr_schild")) == "gauss4"  # extremal
    assert default_method(hm.kerr(1.0, 0.3)) == "gauss4"  # Boyer–Lindquist chart
    assert default_method(hm.kerr(1.0, 0.0)) == "blanes_moan6"  # that is Schwarzschild


def _split_and_ray(form: str):
    """(split, Q, P, duration) of one ray: Schwarzschild's logarithmic split from 20 rg past
    the hole, or a medium's optical split in a smooth index field (Kerr's square-root
    split: tests/core/test_kerr_split.py)."""
    if form == "medium":
        model = hm.medium("1 + 0.2*sin(x) + 0.1*y*y")
        Q, D = np.array([[0.3], [-0.5], [0.2]]), np.array([[0.6], [1.0], [0.05]])
        _, P = core.observer.medium_momenta(model, Q, D)
        return model.split_parts(0.5), Q, P, 3.0
    if form == "schwarzschild":
        from core.models.schwarzschild_optical import SchwarzschildOptical

        model = SchwarzschildOptical(1.0)
        Q, D = np.array([[-3.0], [-20.0], [0.5]]), np.array([[0.12], [1.0], [0.0]])
        _, P = core.observer.medium_momenta(model, Q, D)
        return model.split_parts(0.5), Q, P, 4.0
    raise ValueError(form)


@pytest.mark.parametrize("form, nystrom", [("medium", True), ("schwarzschild", False)])
@pytest.mark.parametrize("name", ["blanes_moan4", "blanes_moan6", "blanes_moan_s10"])
def test_a_splittings_order_on_each_split_is_the_observed_one(form, nystrom, name):
    """``order_on(split)`` is the order observed on that split (fitted slope within 0.3,
    against the same ray at 4000 steps of blanes_moan_s10): blanes_moan6 reaches its 6 on a
    Runge–Kutta–Nyström split (a medium's |p|²/2) and 4 on Schwarzschild's logarithmic
    split; the others keep their order everywhere."""
    split, Q, P, duration = _split_and_ray(form)
    assert split.nystrom is nystrom
    method = METHODS[name]

    def run(m, n):
        state = m.init(split, Q, P)
        for _ in range(n):
            state, ok = m.step(split, state, duration / n)
        assert ok.all()
        return np.concatenate(m.qp(state))

    reference = run(METHODS["blanes_moan_s10"], 4000)
    steps = np.array((8, 12, 16, 24) if form == "medium" else (20, 28, 40, 56))
    errors = [np.abs(run(method, n) - reference).max() for n in steps]
    slope = np.polyfit(np.log(duration / steps), np.log(errors), 1)[0]
    expected = 4 if name == "blanes_moan4" or (name == "blanes_moan6" and not nystrom) else 6
    assert method.order_on(split) == expected
    assert slope == pytest.approx(expected, abs=0.3), errors

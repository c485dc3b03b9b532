"""Ray differentials (core/tracing/differentials.py): each escaped ray's final direction's
derivative with respect to the image coordinates, carried through the integration by dual
numbers, against finite differences of the traced flow, and the magnification it gives
against the exact Schwarzschild lens (deflection by quadrature) and the weak-field point
lens."""

import math

import numpy as np
import pytest

import core
from core import hamiltonians as hm
from core.motion import Motion
from core.trace import TraceOptions, Tracer
from tests.exact_lens import exact_magnification

CAMERA = np.array([0.0, -30.0, 3.0])


def _fan(n: int, seed: int = 1):
    """Unit directions (n, 3) around the hole as seen from CAMERA, with two random tangents
    each (n, 2, 3), perpendicular to them, of a pixel's size."""
    rng = np.random.default_rng(seed)
    look = -CAMERA / np.linalg.norm(CAMERA)
    d = look + 0.25 * rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    t = rng.normal(size=(n, 2, 3))
    t -= np.einsum("nkj,nj->nk", t, d)[..., None] * d[:, None]
    return d, 1e-3 * t


@pytest.mark.parametrize(
    "model",
    [hm.schwarzschild(1.0), hm.kerr(rg=1.0, a=0.45, chart="kerr_schild")],
    ids=["schwarzschild", "kerr_a0.9"],
)
def test_sky_jacobian_is_the_derivative_of_the_traced_flow(model):
    """The propagated derivative of the escape direction equals central differences of the
    traced rays themselves (the same discrete flow: rays that took the same steps), to
    1e-6 relative on every ray (measured, Kerr: median 3e-8, largest 8e-8; the central
    differences' own error is larger at steps 10x either way: truncation on a strongly
    lensed ray, round-off)."""
    tracer = Tracer(core.Scene(model=model), TraceOptions(tolerance=1e-8))
    d, t = _fan(200)
    origins = np.broadcast_to(CAMERA, d.shape).copy()
    out = tracer.trace(origins, d, tangents=t)
    plain = tracer.trace(origins, d)
    escaped = out.ending == core.ENDING["escaped"]
    assert escaped.sum() > 150
    # the tangents ride along: the rays themselves are the plain trace's
    assert np.abs(out.direction - plain.direction)[escaped].max() < 1e-12
    eps = 1e-3  # of the tangent: 1e-6 rad; FD truncation ~1e-12, round-off ~1e-10
    for k in range(2):
        ends = []
        for sign in (1, -1):
            moved = d + sign * eps * t[:, k]
            ends.append(tracer.trace(origins, moved / np.linalg.norm(moved, axis=1)[:, None]))
        alike = [(e.ending == out.ending) & (e.steps == out.steps) for e in ends]
        same = escaped & np.all(alike, axis=0)
        fd = (ends[0].direction - ends[1].direction) / (2 * eps)
        error = np.linalg.norm(fd - out.sky_jacobian[:, k], axis=1) / np.linalg.norm(fd, axis=1)
        assert same.sum() > 150
        assert np.median(error[same]) < 1e-7
        assert error[same].max() < 1e-6


def _in_plane_rays(alpha: np.ndarray, r_obs: float):
    """Rays from (0, -r_obs, 0) at angles alpha from the hole's direction (+y), in the
    z = 0 plane, with two orthonormal tangents each (the camera's solid angle rate 1)."""
    zero = np.zeros_like(alpha)
    d = np.stack([np.sin(alpha), np.cos(alpha), zero], axis=1)
    along = np.stack([np.cos(alpha), -np.sin(alpha), zero], axis=1)
    across = np.stack([zero, zero, np.ones_like(alpha)], axis=1)
    origins = np.tile([0.0, -r_obs, 0.0], (alpha.size, 1))
    return origins, d, np.stack([along, across], axis=1)


def test_magnification_is_the_exact_schwarzschild_lens():
    """A static camera at 60 M: the magnification of the images at 5.2° (beside the
    shadow: μ ~ 8e-4, the higher-order images' side) to 140° (behind the camera: the far
    field's 1 − 2M/r) against the exact lens within 1 % (measured: 1e-6 and better)."""
    mass, r_obs = 0.5, 30.0
    alpha = np.radians([5.2, 6.0, 8.0, 12.0, 20.0, 35.0, 60.0, 100.0, 140.0])
    tracer = Tracer(core.Scene(model=hm.schwarzschild(2 * mass)), TraceOptions(tolerance=1e-9))
    origins, d, t = _in_plane_rays(alpha, r_obs)
    out = tracer.trace(origins, d, tangents=t)
    assert np.all(out.ending == core.ENDING["escaped"])
    exact = np.array([exact_magnification(a, mass, r_obs) for a in alpha])
    assert np.abs(out.magnification / exact - 1).max() < 0.01


@pytest.mark.parametrize(
    "distance, images", [(1e4, [1.2, 1.5, 2.0, 4.0]), (1e6, [0.3, 0.5, 0.7, 0.85, 1.2, 2.0])]
)
def test_magnification_far_from_the_hole_is_the_point_lens(distance, images):
    """A camera far from the hole: images at angle θ from it have the point lens's
    μ = 1 / |1 − (θ_E/θ)⁴|, θ_E = √(4M/D) (the source at infinity), i.e. μ± = (u² + 2) /
    (2u√(u² + 4)) ± ½ for the source at u θ_E, within 2 %. At 10⁴ rg the primary images
    (θ > θ_E; measured 1.3 % at 1.2 θ_E, 0.02 % at 4 θ_E); the secondary ones pass closer
    (b ~ 40-120 rg), where the formula's neglected second-order deflection 15πM²/(4b²)
    moves their μ by 5-10 % (the exact lens above covers them). At 10⁶ rg both (those
    terms shrink as 1/√D: measured at most 1.0 %)."""
    theta_e = math.sqrt(2.0 / distance)
    theta = theta_e * np.array(images)
    tracer = Tracer(core.Scene(model=hm.schwarzschild(1.0)), TraceOptions(tolerance=1e-9))
    origins, d, t = _in_plane_rays(theta, distance)
    out = tracer.trace(origins, d, tangents=t)
    assert np.all(out.ending == core.ENDING["escaped"])
    u = np.abs(theta / theta_e - theta_e / theta)  # the source's angle over θ_E
    sign = np.where(theta > theta_e, 0.5, -0.5)  # the primary image, or the secondary
    point_lens = (u * u + 2) / (2 * u * np.sqrt(u * u + 4)) + sign
    assert np.abs(point_lens * np.abs(1.0 - (theta_e / theta) ** 4) - 1).max() < 1e-12
    assert np.abs(out.magnification / point_lens - 1).max() < 0.02


def test_a_moving_camera_magnifies_by_the_aberration():
    """Flat space, a camera at β = 0.9: the aberration maps the camera's solid angle onto
    the sky's with dΩ_sky / dΩ_camera = g² (the map is conformal with scale g), so
    μ = 1 / g² in every direction (1e-8), and the sky Jacobian is perpendicular to the
    direction it belongs to."""
    velocity = np.array([0.9, 0.0, 0.0])
    tracer = Tracer(core.Scene(model=None), TraceOptions())
    tracer.set_motion(Motion(velocity))
    d, t = _fan(500, seed=4)
    t = t / np.linalg.norm(t, axis=2, keepdims=True)
    t[:, 1] = np.cross(d, t[:, 0])  # orthonormal: the camera's rate 1
    out = tracer.trace(np.zeros_like(d), d, tangents=t)
    g = Motion(velocity).doppler(d)
    assert np.abs(out.magnification * g * g - 1).max() < 1e-8
    assert np.abs(np.einsum("nkj,nj->nk", out.sky_jacobian, out.direction)).max() < 1e-8


def test_rays_that_cannot_carry_derivatives_are_refused_by_name():
    """An implicit method (here Kerr–Schild Kerr with gauss4) has no tangent flow: the trace
    refuses with a message naming what can; a camera without solid angles too."""
    scene = core.Scene(model=hm.kerr(rg=1.0, a=0.45, chart="kerr_schild"))
    tracer = Tracer(scene, TraceOptions(method="gauss4"))
    d, t = _fan(4)
    with pytest.raises(ValueError, match="Schwarzschild, Kerr with"):
        tracer.trace(np.broadcast_to(CAMERA, d.shape).copy(), d, tangents=t)
    ortho = core.Camera.orthographic((0, -30, 0), (0, 0, 0), (0, 0, 1), 10.0, 8, 8)
    with pytest.raises(ValueError, match="orthographic"):
        ortho.direction_tangents(np.zeros((1, 2)))


@pytest.mark.parametrize(
    "sampling", [{}, {"tolerance_px": 0.5, "samples": 4}], ids=["dense", "adaptive"]
)
def test_the_magnification_pass_is_the_exact_lens(sampling):
    """core.render's magnification pass of a Schwarzschild frame (camera at 60 M, the hole
    in view), dense and adaptive (traced and interpolated pixels): each pixel centre's |μ|
    against the exact lens at its angle from the hole (the lens is symmetric about that
    axis) within 1 % away from caustics (μ < 30: the Einstein ring behind the hole has
    μ → ∞, where any direction error is magnified without bound); NaN in the shadow."""
    mass, r_obs = 0.5, 30.0
    scene = core.Scene(model=hm.schwarzschild(2 * mass))
    camera = core.Camera.perspective((0, -r_obs, 0), (0.3, 0, 0.2), (0, 0, 1), 30.0, 48, 32)
    image = core.render(scene, camera, passes=("magnification", "ending"), workers=1, **sampling)
    mu = image.passes["magnification"].reshape(-1).astype(np.float64)
    ending = image.passes["ending"].reshape(-1)
    assert np.isnan(mu[ending != core.ENDING["escaped"]]).all()
    assert (ending == core.ENDING["captured"]).sum() > 20
    _, seen = camera.rays()
    alpha = np.arccos(seen @ np.array([0.0, 1.0, 0.0]))
    pick = np.flatnonzero(np.isfinite(mu) & (mu < 30))[::7]
    assert pick.size > 150
    exact = np.array([exact_magnification(a, mass, r_obs) for a in alpha[pick]])
    far = exact < 30
    assert np.abs(mu[pick][far] / exact[far] - 1).max() < 0.01


class _PlainRows:
    """Rows with derivatives that are not core.dual.DualRows: a split's kick and drift then
    run their plain code on them, entry by entry on core.dual Duals (forward-mode automatic
    differentiation), instead of their written-out tangent maps."""

    def __init__(self, rows) -> None:
        self.rows = rows

    def __getitem__(self, i: int):
        return self.rows[i]

    def __setitem__(self, i: int, x) -> None:
        self.rows[i] = x


@pytest.mark.parametrize("name", ["kick", "drift"])
@pytest.mark.parametrize(
    "form", ["kerr_bl_split", "kerr_bl_split_fixed_E", "schwarzschild_log_split"]
)
def test_written_out_tangent_maps_are_forward_mode_ad(form, name):
    """The splits' kick and drift tangent maps, written out by hand for speed
    (SqrtSplit._kick_tangents with V's Hessian, _drift_tangents and
    sphere_geodesic_tangents; LogarithmicSplit's), equal dual numbers carried through
    their own plain code (an independent derivation) to 1e-12 relative, on random states in
    both hemispheres with per-ray steps and energies, rays with L = 0 among them, and
    for Kerr with tangents along which E varies and along which it does not (the maps
    then skip E's terms: ``gauge_tangents``). Kerr's
    flows leave t's derivative as it was (t is cyclic and read by nothing the derivatives
    give: core/models/kerr_split.py), so that row is checked to be untouched instead."""
    from core.dual import DualRows
    from core.models.kerr_split import KerrBoyerLindquist
    from core.models.schwarzschild_optical import SchwarzschildOptical

    rng = np.random.default_rng(7)
    n = 60
    if form.startswith("kerr_bl_split"):
        split = KerrBoyerLindquist(rg=1.0, a=0.45).split_parts(rng.uniform(-0.05, 0.05, n))
        q = np.stack([np.zeros(n), rng.uniform(0.5, 3, n), rng.uniform(0.1, 3.0, n),
                      rng.uniform(0, 6, n)])  # fmt: skip
        p = np.stack([-rng.uniform(0.5, 1.5, n), *rng.normal(size=(3, n))])
        p[3, :6] = 0.0
    else:
        split = SchwarzschildOptical(rg=1.0).split_parts(rng.uniform(0.3, 0.7, n))
        q, p = 4.0 * rng.normal(size=(3, n)), rng.normal(size=(3, n))
    dq, dp = rng.normal(size=(2, *q.shape)), rng.normal(size=(2, *p.shape))
    if form == "kerr_bl_split_fixed_E":
        dp[:, 0] = 0.0
    t = rng.uniform(0.01, 0.3, n)
    generic = DualRows(q.copy(), dq.copy()), DualRows(p.copy(), dp.copy())
    getattr(split, name)(*(_PlainRows(rows) for rows in generic), t)
    written = DualRows(q.copy(), dq.copy()), DualRows(p.copy(), dp.copy())
    getattr(split, name)(*written, t)
    if form.startswith("kerr_bl_split"):
        np.testing.assert_array_equal(written[0].tangent[:, 0], dq[:, 0])
        written[0].tangent[:, 0] = generic[0].tangent[:, 0]
    for ours, theirs in zip(written, generic, strict=True):
        for field in ("value", "tangent"):
            got, want = getattr(ours, field), getattr(theirs, field)
            assert np.isfinite(got).all()
            np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * np.abs(want).max())


def test_kerr_tangents_lose_only_their_scale_part():
    """Kerr's gauge (SqrtSplit.gauge_tangents) takes out of each tangent its part along
    (0, p), which a homogeneous Λ carries to (0, p'): after ten steps of blanes_moan_s10,
    the gauged tangents' positions (s, theta, phi) equal the full tangents' to 1e-10
    relative, and their momenta differ by that part, (dE / E) p' (checked to 1e-10), while
    dp_t stays exactly 0; rays with E = 0 keep their tangents."""
    from core.integrators import get_method
    from core.models.kerr_split import KerrBoyerLindquist

    rng = np.random.default_rng(3)
    n = 40
    split = KerrBoyerLindquist(rg=1.0, a=0.45).split_parts(0.0)
    q = np.stack([np.zeros(n), rng.uniform(1.5, 3, n), rng.uniform(0.3, 2.8, n),
                  rng.uniform(0, 6, n)])  # fmt: skip
    p = np.stack([-rng.uniform(0.5, 1.5, n), *rng.normal(size=(3, n))])
    dq, dp = rng.normal(size=(2, *q.shape)), rng.normal(size=(2, *p.shape))
    method = get_method("blanes_moan_s10")
    full = (q.copy(), p.copy(), dq.copy(), dp.copy())
    gauged = method.with_tangents(split, method.init(split, q, p), dq, dp)
    assert (gauged[3][:, 0] == 0).all()
    scale = dp[:, 0] / p[0]  # (k, N): the part along (0, p) taken out
    h = rng.uniform(0.05, 0.2, n)
    for _ in range(10):
        full, _ = method.step(split, full, h)
        gauged, _ = method.step(split, gauged, h)
    np.testing.assert_array_equal(gauged[0], full[0])
    assert (gauged[3][:, 0] == 0).all()
    positions, momenta = gauged[2][:, 1:], gauged[3] + scale[:, None, :] * full[1]
    np.testing.assert_allclose(positions, full[2][:, 1:], rtol=0,
                               atol=1e-10 * np.abs(full[2][:, 1:]).max())  # fmt: skip
    np.testing.assert_allclose(momenta, full[3], rtol=0, atol=1e-10 * np.abs(full[3]).max())
    # rays with E = 0 (a camera in the ergoregion) have no scale part to take: left as is
    p[0, :3] = 0.0
    dP = dp.copy()
    split.gauge_tangents(q, p, dq.copy(), dP)
    np.testing.assert_array_equal(dP[..., :3], dp[..., :3])
    assert (dP[:, 0, 3:] == 0).all()


def _axis_fan(camera: np.ndarray, seed: int = 5):
    """Unit directions from ``camera``: around the hole, behind the camera, along the axis
    through the hole both ways and at 1e-9 to 1e-2 rad from it (the spherical reduction's
    two regimes and the threshold between them), with two random tangents each, ⟂ d."""
    rng = np.random.default_rng(seed)
    axis = camera / np.linalg.norm(camera)
    across = np.cross(axis, [1.0, 0.0, 0.0])
    across /= np.linalg.norm(across)
    offsets = (0, 1e-9, 1e-8, 1e-7, 2e-7, 1e-6, 1e-4, 1e-2)
    near = [sign * axis + s * across for sign in (1, -1) for s in offsets]
    d = np.concatenate([-axis + 0.25 * rng.normal(size=(150, 3)), rng.normal(size=(50, 3)), near])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    t = rng.normal(size=(d.shape[0], 2, 3))
    t -= np.einsum("nkj,nj->nk", t, d)[..., None] * d[:, None]
    return d, 1e-3 * t


def test_spherical_models_trace_one_tangent_and_turn_the_other(monkeypatch):
    """Schwarzschild is symmetric about any axis through the hole: a ray's differential
    across the plane of the camera's axis and the ray is a turn of the whole path about that
    axis, known in closed form at the end (â × d per radian), so one tangent is traced, not
    two (core/tracing/differentials.py axial_tangents). Against both tangents traced (the
    model's symmetry switched off), on rays around the hole, behind the camera, along the
    axis both ways and at 1e-9 to 1e-2 rad from it: the same endings, the sky Jacobian to
    1e-7 relative (measured: median 2e-10, largest 7e-9 at 1e-7 rad from the axis, where
    the turn's share is known to ~1e-16 / 1e-7); the camera's tangents are rebuilt from the
    traced one and the turn exactly off the axis, to O(angle) < 1e-7 within RADIAL of it."""
    from core.models.schwarzschild_optical import SchwarzschildOptical
    from core.tracing.differentials import axial_final, axial_tangents

    d, t = _axis_fan(CAMERA)
    origins = np.broadcast_to(CAMERA, d.shape).copy()
    shares, traced = axial_tangents(origins, d, t)
    axis = origins / np.linalg.norm(origins, axis=1, keepdims=True)
    rebuilt = axial_final(shares, traced, d, axis)  # the turn's derivative at the camera: â × d
    radial = (shares[2] != 0).any(axis=0)
    assert radial.sum() == 8  # both ways: on the axis and 1e-9 to 1e-7 rad (normalised: < RADIAL)
    assert np.abs(rebuilt - t)[~radial].max() < 1e-12 * np.abs(t).max()
    assert np.abs(rebuilt - t)[radial].max() < 1e-7 * np.abs(t).max()  # to O(|â × d|)
    scene = core.Scene(model=hm.schwarzschild(1.0))
    one = Tracer(scene, TraceOptions(tolerance=1e-8)).trace(origins, d, tangents=t)
    monkeypatch.setattr(SchwarzschildOptical, "spherical", property(lambda self: False))
    two = Tracer(scene, TraceOptions(tolerance=1e-8)).trace(origins, d, tangents=t)
    np.testing.assert_array_equal(one.ending, two.ending)
    escaped = one.ending == core.ENDING["escaped"]
    assert escaped.sum() > 120 and escaped[-16:].sum() == 8  # outwards along the axis
    error = np.linalg.norm(one.sky_jacobian - two.sky_jacobian, axis=2)
    error /= np.linalg.norm(two.sky_jacobian, axis=2)
    assert error[escaped].max() < 1e-7
    assert np.median(error[escaped]) < 1e-9

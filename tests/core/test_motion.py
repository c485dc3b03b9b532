"""A moving observer (core.motion): aberration and Doppler shift against special
relativity's formulas, Schwarzschild's shadow for a falling camera, and the observers'
four-velocities against Kerr's geodesic constants."""

import math

import numpy as np
import pytest

import core
from core import blackbody
from core import hamiltonians as hm
from core.geometry.disk import keplerian_omega
from core.motion import Motion, NoOrbitError, observer_motion
from core.observer import ObserverError, observer_frame
from core.trace import TraceOptions, Tracer

BETA = 0.9


def _unit_directions(n: int, seed: int = 3) -> np.ndarray:
    d = np.random.default_rng(seed).normal(size=(n, 3))
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def test_flat_space_aberration_and_doppler_are_special_relativitys():
    """Flat space, a camera at β = 0.9: a pixel looking at θ' from the direction of motion
    sees what the static observer sees at θ, cos θ = (cos θ' − β) / (1 − β cos θ') (a star
    at θ is seen at θ', cos θ' = (cos θ + β) / (1 + β cos θ)), in the same plane through
    the velocity, shifted by g = 1 / (γ (1 − β cos θ')) = γ (1 + β cos θ). The tracer's
    float64 results to 1e-9 over the whole sphere; the float32 passes of a render to their
    resolution."""
    velocity = BETA * np.array([1.0, 2.0, -0.5]) / math.sqrt(5.25)
    unit = velocity / BETA
    gamma = 1.0 / math.sqrt(1.0 - BETA * BETA)
    tracer = Tracer(core.Scene(model=None), TraceOptions())
    tracer.set_motion(Motion(velocity))
    seen = _unit_directions(4000)
    out = tracer.trace(np.zeros_like(seen), seen)
    cos_seen, cos_rest = seen @ unit, out.direction @ unit
    assert np.abs(cos_rest - (cos_seen - BETA) / (1 - BETA * cos_seen)).max() < 1e-9
    assert np.abs(cos_seen - (cos_rest + BETA) / (1 + BETA * cos_rest)).max() < 1e-9
    coplanar = np.cross(seen, out.direction) @ unit
    assert np.abs(coplanar).max() < 1e-9
    g = 1.0 / (gamma * (1.0 - BETA * cos_seen))
    assert np.abs(out.doppler / g - 1).max() < 1e-9
    assert np.abs(out.doppler / (gamma * (1 + BETA * cos_rest)) - 1).max() < 1e-9

    camera = core.Camera.perspective((0, 0, 0), (1, 0.3, 0.2), (0, 0, 1), 90.0, 48, 32)
    image = core.render(core.Scene(model=None), camera, observer=tuple(velocity),
                        passes=("direction", "doppler"), workers=1)  # fmt: skip
    _, pixel = camera.rays()
    cos_pixel = pixel @ unit
    direction = image.passes["direction"].reshape(-1, 3).astype(np.float64)
    expected = (cos_pixel - BETA) / (1 - BETA * cos_pixel)
    assert np.abs(direction @ unit - expected).max() < 4 * np.finfo(np.float32).eps
    doppler = image.passes["doppler"].reshape(-1)
    relative = doppler / (1.0 / (gamma * (1.0 - BETA * cos_pixel))) - 1
    assert np.abs(relative).max() < 2 * np.finfo(np.float32).eps


@pytest.mark.parametrize("method", [None, "gauss4"])  # isotropic medium; Kerr–Schild spacetime
def test_a_falling_camera_sees_the_shadow_shrunk_by_aberration(method):
    """Schwarzschild, a camera falling from rest at infinity through r = 8 rg: the static
    observer's shadow edge sin α = (3√3 M / r) √(1 − 2M/r), seen at β = √(2M/r) towards
    the hole, is at cos α' = (cos α + β) / (1 + β cos α): rays at α' (1 ∓ 1e-4) are captured
    and escape."""
    mass, r = 0.5, 8.0
    scene = core.Scene(model=hm.schwarzschild(1.0))
    tracer = Tracer(scene, TraceOptions(method=method, tolerance=1e-10), extent=r)
    position = np.array([-r, 0.0, 0.0])
    motion = observer_motion("infall", tracer, position)
    beta = math.sqrt(2 * mass / r)
    assert np.allclose(motion.velocity, [beta, 0.0, 0.0], rtol=0, atol=1e-12)
    sin_a = 3 * math.sqrt(3) * mass / r * math.sqrt(1 - 2 * mass / r)
    cos_a = math.sqrt(1 - sin_a**2)
    edge = math.acos((cos_a + beta) / (1 + beta * cos_a))
    angles = edge * np.array([1 - 1e-4, 1 + 1e-4])
    directions = np.stack([np.cos(angles), np.sin(angles), np.zeros(2)], axis=1)
    tracer.set_motion(motion)
    out = tracer.trace(np.stack([position, position]), directions)
    assert out.ending.tolist() == [core.ENDING["captured"], core.ENDING["escaped"]]


@pytest.mark.parametrize(
    "chart, method",
    [("boyer_lindquist", None), ("kerr_schild", None), ("kerr_schild", "gauss4")],
)  # Kerr traced in its Boyer–Lindquist chart, Kerr–Schild's BL split, Kerr–Schild
def test_kerr_observers_move_on_their_geodesics(chart, method):
    """Kerr a/M = 0.9, the hole turned and moved: the "infall" observer's four-velocity
    u = γ (u_ZAMO + v^a e_a) has E = −u·ξ_t = 1, L = u·ξ_φ = 0 and keeps its
    Boyer–Lindquist θ (Carter's Q = 0: d cos θ / dτ = 0, cos θ = z / r); the "orbit"
    observer's is u^t (ξ_t + Ω ξ_φ), Ω = √M / (r^{3/2} + a √M) (Bardeen et al. 1972)."""
    scene = core.Scene(model=hm.kerr(rg=1.0, a=0.45, chart=chart), center=(1, 2, 3),
                       axis=(0.3, 0.2, 1.0))  # fmt: skip
    tracer = Tracer(scene, TraceOptions(method=method, tolerance=1e-9), extent=20)
    chart_of = tracer.chart
    xi_t = np.array([1.0, 0.0, 0.0, 0.0])

    def four_velocity(observer, local):
        position = scene.center + tracer.rotation @ local
        motion = observer_motion(observer, tracer, position)
        S = chart_of.to_coords(local.reshape(3, 1))
        g, u0, E = observer_frame(tracer.model, chart_of, S)
        xi_phi = np.concatenate([[0.0], chart_of.axial_killing(S)[:, 0]])
        return S, g, motion.gamma * (u0 + E @ (motion.velocity @ tracer.rotation)), xi_phi

    S, g, u, xi_phi = four_velocity("infall", np.array([3.0, 4.0, 5.0]))
    assert u @ g @ u == pytest.approx(-1.0, abs=1e-12)
    assert -(u @ g @ xi_t) == pytest.approx(1.0, abs=1e-9)
    assert u @ g @ xi_phi == pytest.approx(0.0, abs=1e-9)

    def cos_theta(coords):
        X = chart_of.to_cartesian(coords)
        return X[2] / tracer.model.radius_at(X)

    step = 1e-6 * np.eye(3)  # central differences of cos θ along each coordinate
    change = [(cos_theta(S + step[:, [i]]) - cos_theta(S - step[:, [i]]))[0] for i in range(3)]
    assert abs(u[1:] @ np.array(change) / 2e-6) < 1e-9

    local = np.array([4.0, 5.0, 0.0])
    S, g, u, xi_phi = four_velocity("orbit", local)
    mass, a = tracer.model.kerr_orbits()
    omega = keplerian_omega(tracer.model.radius_at(local.reshape(3, 1))[0], mass, a)
    circular = xi_t + omega * xi_phi
    assert np.abs(u - circular / math.sqrt(-(circular @ g @ circular))).max() < 1e-12


def test_observers_that_cannot_be_are_refused_by_name():
    """Off the equator or inside the photon orbit no circular orbit passes; flat space and
    media have no orbits; a velocity must be three finite numbers below c."""
    scene = core.Scene(model=hm.kerr(rg=1.0, a=0.45, chart="kerr_schild"))
    tracer = Tracer(scene, TraceOptions(method="gauss4"), extent=20)
    with pytest.raises(NoOrbitError, match="equatorial plane"):
        observer_motion("orbit", tracer, (6.0, 0.0, 0.5))
    schwarzschild = Tracer(core.Scene(model=hm.schwarzschild(1.0)), TraceOptions(), extent=20)
    with pytest.raises(NoOrbitError, match="photon orbit"):  # at r = 1.3 rg < 1.5 rg
        observer_motion("orbit", schwarzschild, (1.3, 0.0, 0.0))
    assert observer_motion("orbit", schwarzschild, (1.7, 0.0, 0.0)).gamma > 1.0
    flat = Tracer(core.Scene(model=None), TraceOptions())
    with pytest.raises(ObserverError, match="flat space"):
        observer_motion("infall", flat, (0.0, 0.0, 0.0))
    camera = core.Camera.perspective((0, -10, 0), (0, 0, 0), (0, 0, 1), 40.0, 8, 6)
    for bad, words in [((1.0, 0.0, 0.0), "speed of light"), ((0.1, float("nan"), 0.0), "speed"),
                       ((0.1, 0.2), "3-velocity"), ("moving", "one of")]:  # fmt: skip
        with pytest.raises(ValueError, match=words):
            core.render(core.Scene(model=None), camera, observer=bad)
    assert observer_motion("static", tracer, (6.0, 0.0, 0.0)) is None


def test_a_refused_velocity_shows_plain_numbers():
    """Numbers in the message as written, not numpy's "np.float64(1.0)" (issue 45)."""
    camera = core.Camera.perspective((0, -10, 0), (0, 0, 0), (0, 0, 1), 40.0, 8, 6)
    for bad in (np.array([1.0, 0.0, 0.0]), tuple(np.array([1.0, 0.0, 0.0]))):
        with pytest.raises(ValueError) as info:
            core.render(core.Scene(model=None), camera, observer=bad)
        assert "velocity (1, 0, 0) has speed 1 c" in str(info.value)
    with pytest.raises(ValueError) as info:
        core.render(core.Scene(model=None), camera, observer=(np.float64(0.1), 0.2))
    assert "got (0.1, 0.2)" in str(info.value) and "np." not in str(info.value)


def test_a_black_bodys_colour_shifts_to_the_black_body_at_g_t():
    """shifted_colour of a black body's colour at T, seen with g, is the black body's at g T
    (chromaticity), its luminance × g³; g = 1 leaves any colour as it is."""
    T = np.array([2500.0, 4000.0, 6500.0, 12_000.0])
    g = np.array([1.7, 0.6, 1.25, 0.8])
    rgb = blackbody.xyz_to_rgb(blackbody.planck_xyz(T))
    shifted = blackbody.shifted_colour(rgb, g)
    expected = blackbody.chromaticity(blackbody.planck_xyz(g * T))
    got = blackbody.chromaticity(shifted @ blackbody.XYZ_FROM_RGB.T)
    assert np.abs(got - expected).max() < 1e-6
    luminance = blackbody.XYZ_FROM_RGB[1]
    assert np.allclose(shifted @ luminance, g**3 * (rgb @ luminance), rtol=1e-6)
    colours = np.random.default_rng(1).uniform(0, 1, size=(50, 3))
    assert np.allclose(blackbody.shifted_colour(colours, np.ones(50)), colours, atol=1e-12)


@pytest.mark.parametrize("shift_colours", [True, False])
def test_sky_colours_take_each_pixels_doppler_shift(shift_colours):
    """A uniform sky behind a Schwarzschild hole, an adaptive render (traced and interpolated
    pixels) from a camera moving at 0.6 c across the view: every sky pixel is the sky's
    colour shifted by that pixel's doppler pass (shift_colours), or the sky's own."""
    sky = (0.2, 0.3, 0.4)
    scene = core.Scene(model=hm.schwarzschild(1.0), background=sky)
    camera = core.Camera.perspective((0, -30, 0), (0, 0, 0), (0, 0, 1), 60.0, 64, 40)
    image = core.render(scene, camera, tolerance_px=1.0, observer=(0.6, 0.0, 0.0),
                        shift_colours=shift_colours, passes=("ending", "doppler"))  # fmt: skip
    on_sky = image.passes["ending"] == core.ENDING["escaped"]
    assert on_sky.sum() > 0.8 * on_sky.size
    g = image.passes["doppler"][on_sky].astype(np.float64)
    assert g.min() < 0.9 and g.max() > 1.1  # the shift varies across the frame
    colours = np.broadcast_to(sky, (g.size, 3))
    expected = blackbody.shifted_colour(colours, g) if shift_colours else colours
    assert np.abs(image.rgba[on_sky][:, :3] - expected).max() < 1e-5


@pytest.mark.parametrize(
    "chart, method",
    [("boyer_lindquist", None), ("kerr_schild", None), ("kerr_schild", "gauss4")],
)
def test_an_orbiting_camera_sees_the_disk_shifted_by_the_circular_orbit_formula(chart, method):
    """Kerr a/M = 0.9, a camera on the prograde circular orbit at r_o = 10 M over a disk out
    to 8 M. Photons of zero angular momentum (L = 0: the pixels looking at
    n'·v̂ = β, where the static frame sees no azimuthal momentum) have
    g = E_o / E_e = u^t(r_o) / u^t(r_e) for both on circular orbits (E − Ω L = E), with
    u^t = (r^{3/2} + a √M) / (r^{3/4} √(r^{3/2} − 3M √r + 2a √M)) (Bardeen et al. 1972)."""
    mass, a = 0.5, 0.45
    scene = core.Scene(model=hm.kerr(rg=1.0, a=a, chart=chart), disk=core.AccretionDisk(r_out=4.0))
    tracer = Tracer(scene, TraceOptions(method=method, tolerance=1e-10), extent=20)
    r_o = 5.0
    position = np.array([math.hypot(r_o, a), 0.0, 0.0])
    motion = observer_motion("orbit", tracer, position)
    tracer.set_motion(motion)
    beta = float(np.linalg.norm(motion.velocity))
    along = motion.velocity / beta
    angle = np.linspace(0.05, 1.5, 60)  # inwards and down, off the velocity
    across = np.stack([-np.cos(angle), np.zeros_like(angle), -np.sin(angle)], axis=1)
    across -= (across @ along)[:, None] * along
    across /= np.linalg.norm(across, axis=1, keepdims=True)
    seen = beta * along + math.sqrt(1 - beta**2) * across
    out = tracer.trace(np.tile(position, (angle.size, 1)), seen)
    on_disk = np.isfinite(out.redshift)
    assert on_disk.sum() >= 5
    r_e = tracer.model.radius_at(((out.position[on_disk] - scene.center) @ tracer.rotation).T)
    assert r_e.max() - r_e.min() > 1.0  # hits across the disk

    def u_t(r):
        root_m = math.sqrt(mass)
        return (r**1.5 + a * root_m) / (
            r**0.75 * np.sqrt(r**1.5 - 3 * mass * np.sqrt(r) + 2 * a * root_m)
        )

    assert np.abs(out.redshift[on_disk] / (u_t(r_o) / u_t(r_e)) - 1).max() < 1e-9

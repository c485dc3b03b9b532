"""The relativistic thin accretion disk: redshift, temperature, black-body colour.

Independent references (computed here, not by the code under test):

- Kerr circular equatorial orbits in Boyer–Lindquist form (Bardeen, Press & Teukolsky
  1972): Ω = √M / (r^{3/2} + a√M), u^t = (r^{3/2} + a√M) / (r^{3/4} √(r^{3/2} − 3M√r + 2a√M)),
  so p·u_disk = u^t (p_t + Ω p_φ); the zero-angular-momentum observer at (r, θ):
  p·u = (p_t + ω p_φ) / α, ω = 2Mar / A, α² = ΣΔ / A, A = (r² + a²)² − a² Δ sin²θ. p_t and
  p_φ (= x p_y − y p_x) are the ray's constants of motion, the same in Kerr–Schild and
  Boyer–Lindquist coordinates (the charts differ by functions of r added to t and φ).
- Schwarzschild, a photon from the disk point at angle γ from the camera's direction
  n̂ to a static camera at distance D: its orbit sweeps γ, ∫_{1/D}^{1/r} du /
  √(1/b² − u² (1 − 2Mu)) = γ (no turning point for the points used), which fixes the
  impact parameter b; its L_z / E = λ = b (ê × n̂)_z / sin γ, and
  g = √(1 − 3M/r) / (√(1 − 2M/D) (1 − Ω λ)) with Ω = √(M/r³) (line of nodes, γ = 90°:
  λ = ∓ b sin i, the weak-field g ≈ √(1 − 3M/r) / (1 ± √(M/r) sin i)).
- Novikov–Thorne: Page & Thorne (1974) F ∝ −Ω' (E − ΩL)⁻² ∫_{r_in}^r (E − ΩL) L' dr / r,
  with the circular orbits' E and L, by quadrature.
- The Planckian locus (CIE 015:2018; Wyszecki & Stiles 1982, table 1(3.11)): x, y of black
  bodies at 3000, 6500 and 10000 K.
"""

import dataclasses
import math

import numpy as np
import pytest
from scipy import integrate, optimize

import core
from core import blackbody
from core import hamiltonians as hm
from core.geometry import disk as diskmod
from core.observer import spacetime_momenta
from core.render import disk_exposure, summary_text
from core.trace import ENDING, TraceOptions, Tracer

INCLINATION = math.radians(80.0)


def camera_at(distance, width, height, fov=40.0):
    """A camera at inclination 80 deg, distance D, looking at the hole (x to the right)."""
    pos = distance * np.array([0.0, -math.sin(INCLINATION), math.cos(INCLINATION)])
    return core.Camera.perspective(
        position=pos, look_at=(0, 0, 0), up=(0, 0, 1), fov_deg=fov, width=width, height=height
    )


def trace(scene, camera, method=None, tolerance=1e-8):
    """(tracer, origins, directions, RayResults) of every pixel, traced once."""
    tracer = Tracer(scene, TraceOptions(method=method, tolerance=tolerance), 100.0)
    origins, directions = camera.rays()
    return tracer, origins, directions, tracer.trace(origins, directions)


# --- (a) Kerr a/M = 0.9 at 80 deg: g against the constants of motion, Boyer–Lindquist ----


def kerr_g_reference(M, a, r, cam, p_t, p_phi):
    """g from the BL circular-orbit u^t and the ZAMO at the camera (see the module); the
    co-rotating orbit: for a < 0 the lower signs, Ω = −√M / (r^{3/2} − a√M)."""
    sq, s = math.sqrt(M), math.copysign(1.0, a)
    k = abs(a) * sq
    u_t = (r**1.5 + k) / (r**0.75 * np.sqrt(r**1.5 - 3 * M * np.sqrt(r) + 2 * k))
    emitted = u_t * (p_t + s * sq / (r**1.5 + k) * p_phi)
    x, y, z = cam
    rho2 = x * x + y * y + z * z - a * a
    rc = math.sqrt(0.5 * (rho2 + math.sqrt(rho2 * rho2 + 4 * a * a * z * z)))
    cos2 = (z / rc) ** 2
    sigma, delta = rc * rc + a * a * cos2, rc * rc - 2 * M * rc + a * a
    big_a = (rc * rc + a * a) ** 2 - a * a * delta * (1 - cos2)
    omega, alpha = 2 * M * a * rc / big_a, math.sqrt(sigma * delta / big_a)
    return ((p_t + omega * p_phi) / alpha) / emitted


@pytest.mark.parametrize(
    "chart, a", [("kerr_schild", 0.45), ("boyer_lindquist", 0.45), ("kerr_schild", -0.45)]
)  # traced in either chart; a < 0: the hole and the gas turn clockwise about +z
def test_kerr_redshift_matches_constants_of_motion(chart, a):
    M = 0.5  # rg = 1, |a|/M = 0.9
    scene = core.Scene(
        model=hm.kerr(rg=2 * M, a=a, chart=chart), disk=core.AccretionDisk(r_out=8.0)
    )
    cam = camera_at(20.0, 12, 8)
    tracer, origins, directions, res = trace(scene, cam)
    on = np.isfinite(res.redshift)
    assert on.sum() >= 30 and np.all(res.ending[on] == ENDING["hit"])
    # the rays' constants at the camera (inside the region: rays start there)
    X = (origins[on] - scene.center) @ tracer.rotation
    S = tracer.chart.to_coords(X.T.copy())
    Q, P = spacetime_momenta(
        tracer.model, tracer.chart, S, (directions[on] @ tracer.rotation).T.copy()
    )
    # p_phi = p.xi_phi in the tracing chart (x p_y - y p_x in Kerr–Schild, p_phi itself in
    # Boyer–Lindquist, also the form Kerr–Schild Kerr takes for the default explicit split)
    p_phi = np.einsum("ij,ij->j", tracer.chart.axial_killing(S), P[1:])
    p_t = P[0]
    hit = res.position[on]
    assert np.allclose(hit[:, 2], 0.0, atol=1e-9)  # on the equatorial plane
    r = np.sqrt(np.sum(hit[:, :2] ** 2, axis=1) - a * a)  # BL r on the equator
    assert np.all((r >= diskmod.isco(M, a) - 1e-9) & (r <= 8.0 + 1e-9))
    expected = kerr_g_reference(M, a, r, X[0], p_t, p_phi)
    np.testing.assert_allclose(res.redshift[on], expected, rtol=1e-6)
    assert expected.min() < 0.8 and expected.max() > 1.1  # both shifts are in the sample


# --- (b) Schwarzschild, line of nodes: the analytic circular-orbit formula -----------


def sweep_b(M, r, D, gamma):
    """Impact parameter of the outgoing photon from r to D that sweeps the angle gamma."""

    def sweep(b):
        # u = 1/r - t^2 (smooth where b is near a turning point at r)
        def f(t):
            u = 1.0 / r - t * t
            return 2.0 * t / math.sqrt(1.0 / b**2 - u * u * (1 - 2 * M * u))

        top = math.sqrt(1.0 / r - 1.0 / D)
        return integrate.quad(f, 0.0, top, epsabs=0.0, epsrel=1e-12)[0] - gamma

    b_max = r / math.sqrt(1 - 2 * M / r) * (1 - 1e-9)  # (a turning point at r)
    return optimize.brentq(sweep, 1e-3 * r, b_max, xtol=1e-14, rtol=1e-14)


def schwarzschild_g(M, hit, D, doppler=True):
    """g of direct-image disk points hit (K, 3) seen by a static camera at D n-hat."""
    n = np.array([0.0, -math.sin(INCLINATION), math.cos(INCLINATION)])
    out = []
    for p in hit:
        r = float(np.hypot(p[0], p[1]))
        e = p / r
        gamma = math.acos(float(e @ n))
        lam = sweep_b(M, r, D, gamma) * np.cross(e, n)[2] / math.sin(gamma)
        omega = math.sqrt(M / r**3) if doppler else 0.0
        emitted = (1 - omega * lam) / math.sqrt(1 - (3 * M if doppler else 2 * M) / r)
        out.append(1.0 / (math.sqrt(1 - 2 * M / D) * emitted))
    return np.array(out)


@pytest.mark.parametrize("method", ["blanes_moan6", "gauss4"])  # isotropic / Kerr–Schild
def test_schwarzschild_line_of_nodes(method):
    # far enough that no ray from the disk to the camera has a turning point (sweep_b)
    M, D = 1.0, 1e4
    scene = core.Scene(model=hm.schwarzschild(rg=2 * M), disk=core.AccretionDisk(r_out=16.0))
    # the middle row: rays in the plane of the camera and the x axis, which meets the disk
    # on its line of nodes (y = 0)
    # g_ref takes the ray through the camera and the traced hit point: the hit point's own
    # error (~ tolerance x D) enters it, hence the tight tolerance
    tolerance = {"blanes_moan6": 1e-11, "gauss4": 1e-10}[method]  # both take ~0.5 s
    _, _, directions, res = trace(scene, camera_at(D, 24, 1, fov=0.2), method, tolerance)
    right = directions[:, 0] > 0
    primary = np.isfinite(res.redshift) & ((res.position[:, 0] > 0) == right)
    assert primary.sum() >= 8
    hit = res.position[primary]
    assert np.allclose(hit[:, 1:], 0.0, atol=1e-7)
    expected = schwarzschild_g(M, hit, D)
    np.testing.assert_allclose(res.redshift[primary], expected, rtol=1e-6)
    receding = hit[:, 0] > 0  # counter-clockwise gas moves away from the camera at x > 0
    assert receding.any() and (~receding).any()
    assert res.redshift[primary][~receding].min() > res.redshift[primary][receding].max()


def test_doppler_off_is_the_gravitational_shift():
    """Without Doppler (gas static where a = 0): g = √(1 − 2M/r) / √(1 − 2M/D) everywhere."""
    M, D = 1.0, 50.0
    scene = core.Scene(
        model=hm.schwarzschild(rg=2 * M), disk=core.AccretionDisk(r_out=16.0, doppler=False)
    )
    _, _, _, res = trace(scene, camera_at(D, 16, 6), "blanes_moan6")
    on = np.isfinite(res.redshift)
    r = np.hypot(res.position[on, 0], res.position[on, 1])
    expected = np.sqrt(1 - 2 * M / r) / math.sqrt(1 - 2 * M / D)
    assert on.sum() >= 20
    np.testing.assert_allclose(res.redshift[on], expected, rtol=1e-9)


# --- the render: passes, beaming ----------------------------------------------------------


def test_render_redshift_pass_and_beaming():
    scene = core.Scene(
        model=hm.kerr(rg=1.0, a=0.45, chart="kerr_schild"),
        disk=core.AccretionDisk(r_out=8.0, temperature=8000.0),
        background=(0.0, 0.0, 0.0),
    )
    out = core.render(scene, camera_at(20.0, 24, 12), tolerance=1e-4, workers=1,
                      parallel="threads")  # fmt: skip
    g, ending = out.passes["redshift"], out.passes["ending"]
    on = np.isfinite(g)
    assert on.any() and np.all(ending[on] == ENDING["hit"])
    assert np.all(np.isnan(g[ending != ENDING["hit"]]))
    # the approaching side (x < 0: the image's left half) is bluer and brighter
    left, right = on.copy(), on.copy()
    left[:, 12:] = False
    right[:, :12] = False
    assert np.median(g[left]) > 1.0 > np.median(g[right])
    luminance = out.rgba[..., :3] @ (blackbody.XYZ_FROM_RGB[1])
    assert luminance[left].sum() > 2 * luminance[right].sum()
    blue = out.rgba[..., 2] / np.maximum(out.rgba[..., 0], 1e-30)
    assert np.median(blue[left]) > np.median(blue[right])


# --- orbits, ISCO, temperature profile ----------------------------------------------


def test_isco_values():
    assert diskmod.isco(1.0, 0.0) == pytest.approx(6.0, rel=1e-14)
    assert diskmod.isco(1.0, 1.0) == pytest.approx(1.0, rel=1e-12)
    assert diskmod.isco(1.0, 0.9) == pytest.approx(2.320883041761887, rel=1e-9)
    assert diskmod.isco(0.5, -0.45) == diskmod.isco(0.5, 0.45)  # prograde either way


def page_thorne_flux(r, M, a, r_in):
    """F(r) (relative) by quadrature of the Page–Thorne integral (see the module)."""
    sq = math.sqrt(M)

    def orbit(x):
        den = math.sqrt(1 - 3 * M / x + 2 * a * sq / x**1.5)
        e = (1 - 2 * M / x + a * sq / x**1.5) / den
        ell = sq * math.sqrt(x) * (1 - 2 * a * sq / x**1.5 + a * a / x**2) / den
        return e, ell, sq / (x**1.5 + a * sq)

    def deriv(f, x, h=1e-5):
        return (f(x + h) - f(x - h)) / (2 * h)

    def integrand(x):
        e, ell, om = orbit(x)
        return (e - om * ell) * deriv(lambda y: orbit(y)[1], x)

    e, ell, om = orbit(r)
    dom = deriv(lambda y: orbit(y)[2], r)
    inner = integrate.quad(integrand, r_in, r, epsabs=1e-13, epsrel=1e-11)[0]
    return -dom / (e - om * ell) ** 2 * inner / r


@pytest.mark.parametrize("a_over_m", [0.0, 0.9])
def test_novikov_thorne_closed_form(a_over_m):
    M = 1.0
    a = a_over_m * M
    r_in = diskmod.isco(M, a)
    rs = r_in * np.array([1.05, 1.4, 2.0, 5.0, 20.0])
    closed = diskmod.novikov_thorne_flux(rs, M, a, r_in)
    numeric = np.array([page_thorne_flux(r, M, a, r_in) for r in rs])
    ratio = closed / numeric
    np.testing.assert_allclose(ratio, ratio[0], rtol=1e-6)  # same shape, any normalisation


def test_temperature_profiles():
    model = hm.schwarzschild(rg=2.0)
    nt = core.AccretionDisk(r_out=40.0, temperature=1e4).bind(model)
    r = np.linspace(6.0, 40.0, 3401)
    T = nt.temperature_at(r)
    assert T[0] == 0.0 and T.max() == pytest.approx(1e4, rel=1e-6)
    assert r[np.argmax(T)] == pytest.approx(9.55, abs=0.02)  # Page & Thorne: 9.55 M, a = 0
    pl = core.AccretionDisk(r_out=40.0, r_in=8.0, temperature=5e3, profile="power_law")
    pl = pl.bind(model)
    assert pl.temperature_at(np.array([8.0, 16.0])) == pytest.approx([5e3, 5e3 * 2**-0.75])
    assert pl.temperature_at(np.array([7.9, 40.1])).tolist() == [0.0, 0.0]


def test_keplerian_orbit_is_a_geodesic_in_the_tracing_charts():
    """The circular-orbit condition ∂_r g_tt + 2Ω ∂_r g_tφ + Ω² ∂_r g_φφ = 0 holds for the
    code's Ω in the outgoing Kerr–Schild chart the tracer uses (finite differences)."""
    from core.charts import chart_for
    from core.observer import killing_block

    M, a = 0.5, 0.45
    model = hm.kerr(rg=1.0, a=a, chart="kerr_schild").for_backward_tracing()
    chart = chart_for(model)
    for r in (2.0, 4.0, 9.0):
        h = 1e-5 * r
        rho = np.array([math.hypot(r - h, a), math.hypot(r + h, a)])  # Cartesian on z = 0
        S = np.stack([rho, np.zeros(2), np.zeros(2)])
        gtt, gtp, gpp = killing_block(model, chart, S)
        omega = float(diskmod.keplerian_omega(r, M, a))
        d = lambda v, h=h: (v[1] - v[0]) / (2 * h)  # noqa: E731
        scale = abs(d(gtt)) + 2 * abs(omega * d(gtp)) + omega**2 * abs(d(gpp))
        assert abs(d(gtt) + 2 * omega * d(gtp) + omega**2 * d(gpp)) < 1e-8 * scale


# --- CIE colour of black bodies -------------------------------------------------------


@pytest.mark.parametrize(
    "T, xy", [(3000.0, (0.4369, 0.4041)), (6500.0, (0.3135, 0.3236)), (10000.0, (0.2807, 0.2884))]
)
def test_planckian_locus(T, xy):
    assert blackbody.chromaticity(blackbody.planck_xyz(T)) == pytest.approx(xy, abs=3e-4)


def test_planck_xyz_table_against_the_sum():
    """planck_xyz interpolates a table (log XYZ in log T): against the Planck spectrum
    summed here over the CIE table at 5 nm, within 3e-6 relative from 1 K to 1e7 K (the
    table spans 400 K - 1e6 K; outside, the sum), 0 at T <= 0; far above the visible
    (Rayleigh-Jeans) XYZ grows as T."""
    T = np.concatenate([np.geomspace(1.0, 1e7, 20001), [400.0, 1e6, 6500.0]])
    lam = blackbody.WAVELENGTHS_NM * 1e-9
    c2 = 6.62607015e-34 * 299_792_458.0 / 1.380649e-23
    with np.errstate(over="ignore"):
        summed = ((lam / 555e-9) ** -5 / np.expm1(c2 / (lam * T[:, None]))) @ blackbody.CMF
    seen = summed[:, 1] > 1e-300
    got = blackbody.planck_xyz(T)
    assert np.all(np.abs(got[seen] - summed[seen]) <= 3e-6 * summed[seen])
    assert np.all(blackbody.planck_xyz(np.array([0.0, -5.0])) == 0.0)
    assert blackbody.planck_xyz(6500.0).shape == (3,)
    ratio = blackbody.planck_xyz(4e7) / blackbody.planck_xyz(2e7)
    assert ratio == pytest.approx([2, 2, 2], rel=2e-3)


def test_blackbody_colours():
    # equal-energy white is x = y = 1/3; D65 white is (1, 1, 1) in linear sRGB
    assert blackbody.chromaticity(blackbody.CMF.sum(axis=0)) == pytest.approx(
        (1 / 3, 1 / 3), abs=1e-4
    )
    d65 = np.array([0.3127 / 0.3290, 1.0, (1 - 0.3127 - 0.3290) / 0.3290])
    assert blackbody.xyz_to_rgb(d65) == pytest.approx([1, 1, 1], abs=1e-12)
    rgb = blackbody.xyz_to_rgb(blackbody.planck_xyz(np.array([2000.0, 4000, 6500, 1e4, 3e4])))
    near_white = rgb[2] / rgb[2].mean()
    assert np.all(np.abs(near_white - 1) < 0.04)
    blue_over_red = rgb[:, 2] / rgb[:, 0]
    assert np.all(np.diff(blue_over_red) > 0)  # hotter is bluer


# --- refusals ---------------------------------------------------------------------------


def test_disk_refusals():
    with pytest.raises(ValueError, match="disk r_in must be"):
        core.Scene(model=hm.schwarzschild(rg=2.0), disk=core.AccretionDisk(r_in=5.0))
    with pytest.raises(ValueError, match="disk r_in must be"):
        core.Scene(model=hm.schwarzschild(rg=2.0), disk=core.AccretionDisk(r_out=5.0))
    with pytest.raises(ValueError, match="needs a black hole"):
        core.Scene(model=hm.medium("1.0"), disk=core.AccretionDisk())
    with pytest.raises(ValueError, match="needs a black hole"):
        core.Scene(model=None, disk=core.AccretionDisk())
    with pytest.raises(ValueError, match="disk temperature must be"):
        core.AccretionDisk(temperature=float("nan"))
    with pytest.raises(ValueError, match="disk opacity must be"):
        core.AccretionDisk(opacity=0.0)
    with pytest.raises(ValueError, match="disk profile must be"):
        core.AccretionDisk(profile="shakura")
    scene = core.Scene(
        model=hm.schwarzschild(rg=2.0), disk=core.AccretionDisk(r_out=30.0), region_radius=20.0
    )
    with pytest.raises(ValueError, match="region_radius must exceed"):
        Tracer(scene, TraceOptions())


@pytest.mark.parametrize("spin", [1.0, -1.0])
def test_an_extremal_hole_refuses_the_disk_by_name(spin):
    """|a/M| = 1: the prograde ISCO meets the horizon (r = M); a disk there is refused with a
    message naming the spin and why (never a bare ZeroDivisionError at the first disk
    hit); just below, the Novikov–Thorne closed form still matches the Page–Thorne
    quadrature and a render has every disk pixel's g finite."""
    message = r"spin a/M must lie in \(-1, 1\) with an accretion disk, got -?1: at ±1 the disk's"
    with pytest.raises(ValueError, match=message):
        core.Scene(model=hm.kerr(rg=1.0, a=0.5 * spin, chart="kerr_schild"),
                   disk=core.AccretionDisk(r_out=8.0))  # fmt: skip
    with pytest.raises(ValueError, match=message):
        diskmod.novikov_thorne_flux(np.array([2.0]), 0.5, 0.5 * spin, 1.0)
    M, a = 1.0, 0.9999 * spin  # the near-extremal spin the message suggests
    r_in = diskmod.isco(M, a)
    rs = r_in * np.array([1.05, 1.4, 2.0, 5.0])
    ratio = diskmod.novikov_thorne_flux(rs, M, a, r_in) / [
        page_thorne_flux(r, M, abs(a), r_in) for r in rs
    ]
    np.testing.assert_allclose(ratio, ratio[0], rtol=1e-6)  # 1.7e-8 measured
    scene = core.Scene(model=hm.kerr(rg=1.0, a=0.5 * 0.9999 * spin, chart="kerr_schild"),
                       disk=core.AccretionDisk(r_out=8.0), background=(0.0, 0.0, 0.0))  # fmt: skip
    out = core.render(scene, camera_at(20.0, 16, 8), tolerance=1e-6, workers=1,
                      parallel="threads")  # fmt: skip
    hit = out.passes["ending"] == ENDING["hit"]
    assert hit.sum() > 40 and np.all(np.isfinite(out.passes["redshift"][hit]))
    assert out.summary["failed"] == 0


def test_a_disk_hit_without_a_finite_g_is_flagged_failed():
    """A ray whose g cannot be computed (here: a NaN momentum) is counted failed and gets no
    disk colour, never a plausible one."""
    from core.geometry import Hits
    from core.render import shade
    from core.trace import RayResults
    from core.tracing.scene import DISK_ID

    scene = core.Scene(model=hm.schwarzschild(rg=2.0), disk=core.AccretionDisk(r_out=16.0))
    tracer = Tracer(scene, TraceOptions(method="gauss4"), 50.0)
    hits = Hits.miss(2)
    hits.hit[:] = True
    hits.object_id[:] = DISK_ID
    hits.position[:] = [[8.0, 0.0, 0.0], [-8.0, 0.0, 0.0]]
    Q = np.array([[0.0, 0.0], [20.0, -20.0], [0.0, 0.0], [5.0, 5.0]])
    P = np.array([[1.0, np.nan], [0.0, 0.0], [0.9, 0.9], [0.0, 0.0]])
    camera = np.array([[0.0, 0.0], [-50.0, -50.0], [0.0, 0.0]])
    out = RayResults.empty(2, np.zeros((2, 3)), np.zeros((2, 3)))
    up = np.array([0.0, 0.0, 1.0])
    ends = hits.position + up, hits.position - up  # the chords through the hit points
    tracer.disk.record_hits(np.arange(2), *ends, hits, [Q, P, camera], out)
    assert np.isfinite(out.redshift[0]) and out.ending[0] == ENDING["hit"]
    assert np.isnan(out.redshift[1]) and out.ending[1] == ENDING["failed"]
    assert np.all(out.surface[1, :3] == 0.0)
    rgba = shade(out, core.Background((0.0, 0.0, 0.0)))
    assert tuple(rgba[1]) == core.FAILED_COLOR


def test_translucent_disk_adds_its_light_to_what_lies_behind():
    """opacity a: a ray crossing the disk once and escaping shows a x (the opaque disk's
    colour) + (1 - a) x the background; its redshift is the same g."""
    background = (0.2, 0.3, 0.4)
    cam = camera_at(50.0, 32, 12)
    images = {}
    for alpha in (1.0, 0.4):
        scene = core.Scene(
            model=hm.schwarzschild(rg=2.0),
            disk=core.AccretionDisk(r_out=16.0, opacity=alpha, brightness=0.7),
            background=background,
        )
        images[alpha] = core.render(scene, cam, tolerance=1e-6, workers=1, parallel="threads")
    opaque, thin = images[1.0], images[0.4]
    ending = thin.passes["ending"]
    on = np.isfinite(opaque.passes["redshift"])
    outer = on & (np.abs(np.arange(32) - 15.5) > 11)[None, :]  # once through, then away
    assert outer.sum() >= 6 and np.all(ending[outer] == ENDING["escaped"])
    expected = 0.4 * opaque.rgba[..., :3] + 0.6 * np.array(background)
    np.testing.assert_allclose(thin.rgba[outer][:, :3], expected[outer], atol=2e-6)
    np.testing.assert_array_equal(thin.passes["redshift"][on], opaque.passes["redshift"][on])
    # the near side in front of the shadow: its light, over the (black) shadow's
    front = on & (opaque.passes["ending"] == ENDING["hit"]) & (ending == ENDING["captured"])
    assert front.any()
    np.testing.assert_allclose(
        thin.rgba[front][:, :3], 0.4 * opaque.rgba[front][:, :3], rtol=1e-6, atol=1e-7
    )


@pytest.mark.usefixtures("tiles_refined")
def test_adaptive_sampling_interpolates_the_disk_within_the_tolerance():
    """With tolerance_px (tiles, interpolated blocks) an opaque disk's blocks interpolate
    its radius and g (core/sampling.py): every disk pixel has its g and the disk's light
    (never the annulus's plain white: 1244 of this frame's pixels when hits were simply
    interpolated), and its g is what a point within the tolerance (1 px) shows: within
    one pixel's change of g (the dense render's own gradient) of the traced centre's.
    Anti-aliased pixels keep their centre's g."""
    scene = core.Scene(
        model=hm.kerr(rg=1.0, a=0.45, chart="kerr_schild"),
        disk=core.AccretionDisk(r_out=8.0, temperature=6000.0, brightness=0.5),
        background=(0.0, 0.0, 0.0),
    )
    cam = camera_at(20.0, 96, 48)
    # gauss4, with which the bounds below were measured: the sampling is under test here,
    # not the method
    tiled = core.render(scene, cam, tolerance_px=1.0, samples=4, workers=1, parallel="threads",
                        method="gauss4")  # fmt: skip
    plain = core.render(scene, cam, tolerance=1e-6, passes=("ending", "redshift"), workers=1,
                        parallel="threads", method="gauss4")  # fmt: skip
    g, ending = tiled.passes["redshift"], tiled.passes["ending"]
    hit = ending == ENDING["hit"]
    assert hit.sum() > 1000 and np.all(np.isfinite(g[hit])) and np.all(np.isnan(g[~hit]))
    assert not np.any(np.all(tiled.rgba[hit][:, :3] == 1.0, axis=1))
    g_plain = plain.passes["redshift"]
    step_y, step_x = np.gradient(g_plain)  # NaN beside the disk's edges: left out
    per_pixel = np.hypot(step_x, step_y)
    both = hit & np.isfinite(g_plain) & np.isfinite(per_pixel)
    # measured: all 2728 within a pixel's change (+ 1e-3 relative: the integration's share);
    # p99 of |g / g_plain - 1| 1.3e-2 here (2.3e-4 when every disk pixel was traced)
    within = np.abs(g - g_plain)[both] <= per_pixel[both] + 1e-3 * g_plain[both]
    assert within.mean() >= 0.99


def test_kerr_split_redshift_agrees_with_dopri5_to_float32():
    """a/M = 0.9 at 80 deg with a disk to 8 rg, 24x16: g of the default method (the explicit
    split, tolerance 1e-8) is dopri5's at 1e-11 within 1e-8 relative, so the redshift pass
    (float32) agrees to one float32 unit (the split's long steps put the disk's crossing off
    by ~1e-5 on the step's cubic Hermite path: g off by up to 8e-6)."""
    scene = core.Scene(
        model=hm.kerr(rg=1.0, a=0.45, chart="kerr_schild"), disk=core.AccretionDisk(r_out=8.0)
    )
    cam = camera_at(20.0, 24, 16)
    tracer, _, _, split = trace(scene, cam)
    assert tracer.method.name == "blanes_moan_s10"
    ref = trace(scene, cam, method="dopri5", tolerance=1e-11)[3]
    on = np.isfinite(ref.redshift)
    assert on.sum() > 150 and np.array_equal(np.isfinite(split.redshift), on)
    assert np.max(np.abs(split.redshift[on] / ref.redshift[on] - 1)) < 1e-8
    g, g_ref = (x.redshift[on].astype(np.float32) for x in (split, ref))  # the pass's type
    assert np.max(np.abs(g / g_ref - 1)) <= np.finfo(np.float32).eps


# --- a camera in the disk's plane ---------------------------------------------------------


def _in_plane_view(z, look, opacity):
    """A 16 x 12 camera at (0, -5, z), inside the disk (r_out 8), looking up, down or
    along the plane (towards the hole); (render, ray directions' z)."""
    scene = core.Scene(
        model=hm.kerr(rg=1.0, a=0.45, chart="kerr_schild"),
        disk=core.AccretionDisk(r_out=8.0, opacity=opacity),
        background="procedural",
    )
    target, up = {"up": ((0, -5, 1), (0, 1, 0)), "down": ((0, -5, -1), (0, 1, 0)),
                  "along": ((0, 0, 0), (0, 0, 1))}[look]  # fmt: skip
    cam = core.Camera.perspective(position=(0, -5, z), look_at=np.add(target, (0, 0, z)),
                                  up=up, fov_deg=60, width=16, height=12)  # fmt: skip
    out = core.render(scene, cam, tolerance=1e-6, workers=1, parallel="threads")
    return out, cam.rays()[1][:, 2].reshape(12, 16)


@pytest.mark.parametrize("opacity", [1.0, 0.6])
def test_a_camera_in_the_disk_plane_sees_what_a_camera_beside_it_sees(opacity):
    """A camera exactly in the disk's plane (z = 0) inside its outer radius: a ray leaving
    the plane does not cross the disk where it starts (every pixel was disk, even looking
    straight up). Each ray sees what it sees from z = 1e-9 on its side of the plane (the
    limit): up and down away from the disk, along the plane the halves of the two."""
    for look in ("up", "down", "along"):
        at, dz = _in_plane_view(0.0, look, opacity)
        above, _ = _in_plane_view(1e-9, look, opacity)
        below, _ = _in_plane_view(-1e-9, look, opacity)
        assert np.all(dz != 0)
        side = (dz > 0)[..., None]
        expected = np.where(side, above.rgba, below.rgba)
        np.testing.assert_allclose(at.rgba, expected, atol=1e-6)
        ending = np.where(side[..., 0], above.passes["ending"], below.passes["ending"])
        np.testing.assert_array_equal(at.passes["ending"], ending)
        if look != "along":  # looking away from the plane: no disk at all, only sky
            assert np.all(at.passes["ending"] == ENDING["escaped"])
            assert np.all(np.isnan(at.passes["redshift"]))


# --- looks and automatic exposure (issue 24) ----------------------------------------------


def _bound_disk(**kwargs):
    """A disk to 8 rg around a Kerr hole a/M = 0.9 (rg 1), bound (r_in = the ISCO)."""
    scene = core.Scene(model=hm.kerr(rg=1.0, a=0.45, chart="kerr_schild"),
                       disk=core.AccretionDisk(r_out=8.0, **kwargs))  # fmt: skip
    return scene.disk


def _disk_points(disk, n=2000, seed=24):
    """n random (g, BL r) on the disk: g from deep red- to blue-shift."""
    rng = np.random.default_rng(seed)
    return rng.uniform(0.2, 1.8, n), rng.uniform(disk.r_in, disk.r_out, n)


def test_the_physical_look_at_exposure_1_is_the_black_body_as_before():
    """AccretionDisk() without a look is the physical look at exposure 1, whose colours are
    those before looks existed bit for bit (issue 15's formula, written out); an exposure
    multiplies them; core.render leaves such a disk alone (no probe) and says so."""
    disk = _bound_disk(temperature=8000.0, brightness=0.7)
    assert (disk.look, disk.exposure) == ("physical", 1.0)
    g, r = _disk_points(disk)
    shifted = g * disk.temperature_at(r)
    reference = float(blackbody.planck_xyz(8000.0)[1])
    before = np.maximum(blackbody.xyz_to_rgb(blackbody.planck_xyz(shifted)) * (0.7 / reference), 0)
    np.testing.assert_array_equal(disk.colour(g, r), before)
    same = dataclasses.replace(disk, look="physical", exposure=1.0, beaming=0.0)
    np.testing.assert_array_equal(same.colour(g, r), before)
    np.testing.assert_allclose(dataclasses.replace(disk, exposure=2.5).colour(g, r),
                               2.5 * before, rtol=1e-15, atol=0)  # fmt: skip
    scene = core.Scene(model=hm.kerr(rg=1.0, a=0.45, chart="kerr_schild"),
                       disk=core.AccretionDisk(r_out=8.0), background=(0.0, 0.0, 0.0))  # fmt: skip
    cam = camera_at(20.0, 12, 6)
    assert disk_exposure(scene, cam) is scene
    out = core.render(scene, cam, tolerance=1e-4, workers=1, parallel="threads")
    assert out.summary["disk_exposure"] == 1.0
    assert "disk exposure 1" in summary_text(out.summary)


def _view(inclination, width=96, height=54, distance=14.0):
    """A camera at ``inclination`` (deg) from the spin axis, looking at the hole."""
    inc = math.radians(inclination)
    pos = distance * np.array([0.0, -math.sin(inc), math.cos(inc)])
    return core.Camera.perspective(position=pos, look_at=(0, 0, 0), up=(0, 0, 1),
                                   fov_deg=40.0, width=width, height=height)  # fmt: skip


def _disk_median(out):
    """Median scene-linear luminance of the pixels showing the disk (finite redshift)."""
    on = np.isfinite(out.passes["redshift"])
    assert on.sum() > 500
    return float(np.median(out.rgba[on, :3].astype(np.float64) @ blackbody.XYZ_FROM_RGB[1]))


@pytest.mark.parametrize(
    "look, inclination, spin",
    [("physical", 5.0, 0.9), ("cinematic", 70.0, 0.0), ("eht", 85.0, 0.5),
     ("cinematic", 85.0, -0.6), ("eht", 5.0, 0.0), ("physical", 70.0, -0.6)],
)  # fmt: skip
def test_automatic_exposure_puts_the_disk_median_at_its_target(look, inclination, spin):
    """exposure=None: core.render's probe (a 64 x 36 render of the frame here) chooses the
    exposure that puts the median luminance of the disk's pixels at the look's target; the
    full render's median lies within 8 % of it (measured: within 5 %) face-on, at 70 deg and
    nearly edge-on, for spins 0, ±0.6 and 0.9 (a/M; exposures from 0.7 to 60 measured)."""
    M = 0.25
    scene = core.Scene(
        model=hm.kerr(rg=2 * M, a=spin * M, chart="kerr_schild"),
        disk=core.AccretionDisk(r_out=4.3, temperature=6000.0, look=look, exposure=None),
        background=(0.0, 0.0, 0.0),
    )
    out = core.render(scene, _view(inclination), tolerance_px=1.0, workers=2,
                      passes=("redshift",))  # fmt: skip
    target = diskmod.EXPOSURE_TARGETS[look]
    assert _disk_median(out) == pytest.approx(target, rel=0.08)
    exposure = out.summary["disk_exposure"]
    assert exposure > 0 and f"disk exposure {exposure:.3g}" in summary_text(out.summary)


@pytest.mark.parametrize("look", ["physical", "eht"])
def test_brightness_multiplies_the_automatic_exposure_of_the_whole_frame(look):
    """The probe renders the disk at brightness 1: brightness 2 doubles the image (in every
    look, the EHT's colour map included); a border region of the frame gets the frame's
    exposure (the probe sees the whole frame), and the same scene the same exposure again
    (deterministic)."""
    M = 0.25
    scene = core.Scene(
        model=hm.kerr(rg=2 * M, a=0.9 * M, chart="kerr_schild"),
        disk=core.AccretionDisk(r_out=4.3, exposure=None, look=look),
        background=(0.0, 0.0, 0.0),
    )
    cam = _view(75.0, 64, 36)
    one = core.render(scene, cam, tolerance=1e-4, workers=1, parallel="threads")
    brighter = dataclasses.replace(scene, disk=dataclasses.replace(scene.disk, brightness=2.0))
    two = core.render(brighter, cam, tolerance=1e-4, workers=1, parallel="threads")
    assert one.summary["disk_exposure"] == two.summary["disk_exposure"]
    on = np.isfinite(one.passes["redshift"])
    np.testing.assert_allclose(two.rgba[on, :3], 2.0 * one.rgba[on, :3], rtol=1e-6, atol=0)
    if look != "physical":
        return
    inc = math.radians(75.0)
    matrix = np.eye(4)
    matrix[:3, :3] = [[1, 0, 0], [0, math.cos(inc), -math.sin(inc)],
                      [0, math.sin(inc), math.cos(inc)]]  # fmt: skip
    matrix[:3, 3] = 14.0 * np.array([0.0, -math.sin(inc), math.cos(inc)])
    frame = dict(lens=50.0, resolution_x=64, resolution_y=36, matrix_world=matrix)
    full, part = (
        disk_exposure(scene, core.Camera.blender(**frame, border=border))
        for border in (None, (0.5, 1.0, 0.0, 0.5))
    )
    assert (
        full.disk.exposure
        == part.disk.exposure
        == disk_exposure(scene, core.Camera.blender(**frame)).disk.exposure
    )


def test_automatic_exposure_without_the_disk_in_sight():
    """No pixel shows the disk (the camera looks away): the exposure puts the disk's
    hottest point seen without shift at the target (the median taken as 1)."""
    scene = core.Scene(model=hm.kerr(rg=1.0, a=0.45, chart="kerr_schild"),
                       disk=core.AccretionDisk(r_out=8.0, exposure=None))  # fmt: skip
    cam = core.Camera.perspective(position=(0, -20, 2), look_at=(0, -40, 2), up=(0, 0, 1),
                                  fov_deg=30.0, width=16, height=8)  # fmt: skip
    out = core.render(scene, cam, tolerance=1e-4, workers=1, parallel="threads")
    assert np.all(np.isnan(out.passes["redshift"]))
    assert out.summary["disk_exposure"] == diskmod.EXPOSURE_TARGETS["physical"]


def test_the_redshift_pass_is_the_same_in_every_look():
    """The look colours the light only: g (the redshift pass) and the endings are the same
    bit for bit in every look, beaming and exposure, while the colours differ (adaptive
    sampling with anti-aliasing: the looks' contrasts ask for different samples, the
    pixel centres' g stay)."""
    scene = core.Scene(model=hm.kerr(rg=1.0, a=0.45, chart="kerr_schild"),
                       disk=core.AccretionDisk(r_out=8.0), background=(0.0, 0.0, 0.0))  # fmt: skip
    cam = camera_at(20.0, 32, 16)
    renders = []
    for look, beaming, exposure in [("physical", 0.3, 1.0), ("cinematic", 0.0, None),
                                    ("cinematic", 0.6, 3.0), ("eht", 0.3, None)]:  # fmt: skip
        disk = dataclasses.replace(scene.disk, look=look, beaming=beaming, exposure=exposure)
        renders.append(core.render(dataclasses.replace(scene, disk=disk), cam, tolerance_px=0.5,
                                   samples=4, workers=1, parallel="threads"))  # fmt: skip
    first = renders[0].passes
    on = np.isfinite(first["redshift"])
    assert on.sum() > 100
    for out in renders[1:]:
        np.testing.assert_array_equal(out.passes["redshift"], first["redshift"])
        np.testing.assert_array_equal(out.passes["ending"], first["ending"])
        assert not np.allclose(out.rgba[on], renders[0].rgba[on])


def _afmhot(v):
    """matplotlib's afmhot, from its definition: red 2v, green 2v - 1/2, blue 2v - 1."""
    v = np.clip(v, 0.0, 1.0)
    return np.stack([np.clip(2 * v, 0, 1), np.clip(2 * v - 0.5, 0, 1),
                     np.clip(2 * v - 1, 0, 1)], axis=-1)  # fmt: skip


def _srgb_decode(c):
    """IEC 61966-2-1: display value -> linear."""
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def test_eht_colours_lie_on_the_afmhot_map():
    """The EHT look: v = (g T(r) / temperature)⁴ x exposure (the bolometric intensity,
    relative), through afmhot made scene-linear (Standard shows afmhot itself), white v
    beyond 1, times brightness: black -> red -> orange -> yellow -> white, red >= green >=
    blue."""
    disk = _bound_disk(temperature=7000.0, look="eht", brightness=1.3, exposure=0.8)
    g, r = _disk_points(disk)
    v = (g * disk.temperature_at(r) / 7000.0) ** 4 * 0.8
    assert v.min() < 0.05 and np.mean(v > 1) > 0.05  # the whole ramp and beyond
    expected = 1.3 * np.where(v[:, None] > 1, v[:, None], _srgb_decode(_afmhot(v)))
    rgb = disk.colour(g, r)
    np.testing.assert_allclose(rgb, expected, rtol=1e-12, atol=1e-15)
    assert np.all((rgb[:, 0] >= rgb[:, 1]) & (rgb[:, 1] >= rgb[:, 2]))
    ramp = np.linspace(0.0, 1.0, 1001)
    np.testing.assert_allclose(diskmod.afmhot(ramp), _afmhot(ramp), rtol=0, atol=1e-15)
    luminance = diskmod.eht_colour(ramp) @ blackbody.XYZ_FROM_RGB[1]
    assert np.all(np.diff(luminance) > 0)  # the median pixel stays the median one
    for y in (0.01, 0.3, 0.99, 4.0):
        level = diskmod.eht_level(y)
        assert diskmod.eht_colour(level) @ blackbody.XYZ_FROM_RGB[1] == pytest.approx(y, 1e-12)


def test_afmhot_is_matplotlibs():
    """diskmod.afmhot is matplotlib's afmhot (a 256-entry table there: within 2/255)."""
    matplotlib = pytest.importorskip("matplotlib")
    ramp = np.linspace(0.0, 1.0, 1001)
    lut = matplotlib.colormaps["afmhot"](ramp)[:, :3]
    np.testing.assert_allclose(diskmod.afmhot(ramp), lut, rtol=0, atol=2 / 255)


@pytest.mark.parametrize("profile", ["novikov_thorne", "power_law"])
def test_the_cinematic_look_is_a_warm_black_body_with_reduced_beaming(profile):
    """Cinematic: the black body at g**beaming T(r) x CINEMATIC_HOT / temperature, scaled
    so that the hottest point seen without shift has luminance brightness x exposure: at
    beaming 1 the physical look of a disk at CINEMATIC_HOT; at 0, the same light at every g;
    in between, g**beaming's; the hottest point orange-white (red > green > blue)."""
    hot = diskmod.CINEMATIC_HOT
    kwargs = dict(profile=profile, brightness=0.8, exposure=1.5)
    disk = _bound_disk(temperature=9000.0, look="cinematic", beaming=1.0, **kwargs)
    g, r = _disk_points(disk)
    physical = _bound_disk(temperature=hot, **kwargs)
    scale = 1e-13 * physical.colour(g, r).max()  # the deep red's RGB cancels digits
    np.testing.assert_allclose(disk.colour(g, r), physical.colour(g, r), rtol=1e-12, atol=scale)
    flat = dataclasses.replace(disk, beaming=0.0)
    np.testing.assert_array_equal(flat.colour(g, r), flat.colour(np.ones_like(g), r))
    half = dataclasses.replace(disk, beaming=0.4)
    np.testing.assert_allclose(half.colour(g, r), disk.colour(g**0.4, r), rtol=1e-12, atol=scale)
    peak = disk.r_in if profile == "power_law" else physical.r_in * 1.5  # near the NT maximum
    hottest = disk.colour(np.array([1.0]), np.array([peak]))[0]
    assert hottest[0] > hottest[1] > hottest[2] > 0
    if profile == "power_law":  # T(r_in) = temperature: luminance brightness x exposure
        assert hottest @ blackbody.XYZ_FROM_RGB[1] == pytest.approx(0.8 * 1.5, rel=1e-12)


def test_look_refusals():
    """A look, beaming or exposure out of range is refused, by name."""
    with pytest.raises(ValueError, match="disk look must be one of"):
        core.AccretionDisk(look="interstellar")
    for beaming in (-0.1, 1.5, float("nan")):
        with pytest.raises(ValueError, match="disk beaming"):
            core.AccretionDisk(beaming=beaming)
    for exposure in (0.0, -1.0, float("inf"), float("nan")):
        with pytest.raises(ValueError, match="disk exposure"):
            core.AccretionDisk(exposure=exposure)
    assert core.AccretionDisk(exposure=None).exposure is None


def test_auto_exposure_is_the_renders_own_choice():
    """core.render.auto_exposure (the add-on's Pin Exposure) gives the exposure the render
    with the same options chooses (its summary's), options outside the probe's ignored;
    None where there is nothing to choose (a set exposure, no disk)."""
    from core.render import auto_exposure

    M = 0.25
    scene = core.Scene(
        model=hm.kerr(rg=2 * M, a=0.6 * M, chart="kerr_schild"),
        disk=core.AccretionDisk(r_out=4.3, exposure=None, look="cinematic"),
    )
    cam = _view(70.0, 64, 36)
    options = {"tolerance_px": 1.0, "workers": 1, "parallel": "threads"}
    out = core.render(scene, cam, **options)
    assert auto_exposure(scene, cam, samples=4, **options) == out.summary["disk_exposure"]
    assert out.summary["disk_exposure"] != 1.0
    fixed = dataclasses.replace(scene, disk=dataclasses.replace(scene.disk, exposure=2.0))
    assert auto_exposure(fixed, cam) is None
    assert auto_exposure(dataclasses.replace(scene, disk=None), cam) is None

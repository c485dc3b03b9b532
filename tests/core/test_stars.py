"""Point stars (core.StarField, core/star_images.py): each lensed image where the exact lens
puts it with the exact lens's flux, flux conserved, no flicker when the camera moves a tenth
of a pixel, a moving camera's aberration and g², catalogues read and refused by name."""

import importlib
import math
import warnings

import numpy as np
import pytest
from scipy import ndimage

import core
from core import hamiltonians as hm
from core.stars import StarField, star_rgb, temperature_from_bv
from tests.exact_lens import exact_magnification, image_angles

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


def _flux_image(out, camera) -> np.ndarray:
    """Each pixel's luminance times its solid angle (h, w): a star's pixels sum to its flux.
    The solid angle from central differences of the camera's own rays (1e-3 px apart)."""
    h, w = camera.height, camera.width
    xy = np.stack(np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5), -1).reshape(-1, 2)

    def along(step):
        return (camera.rays_at(xy + step)[1] - camera.rays_at(xy - step)[1]) / (2 * 1e-3)

    area = np.linalg.norm(np.cross(along([1e-3, 0.0]), along([0.0, 1e-3])), axis=1)
    return (out.rgba[..., :3].astype(np.float64) @ LUMINANCE) * area.reshape(h, w)


def _window(image, point, half=1) -> float:
    """The flux in the 3x3 pixels around an image point (the filter's 1.5 px footprint)."""
    c, r = int(point[0]), int(point[1])
    return float(image[r - half : r + half + 1, c - half : c + half + 1].sum())


@pytest.mark.parametrize("method", [None, "gauss4"], ids=["differentials", "differences"])
def test_each_image_has_the_exact_lens_flux(method):
    """A static camera at 60 M sees 24 stars 6°-30° behind a Schwarzschild hole (adaptive,
    tolerance_px 0.25): each has its two images (the secondary inside the Einstein ring, μ
    down to 0.036) at the angles the exact lens (deflection by quadrature) gives, each with
    flux F μ_exact within 1 % (measured: 0.6 %), and the frame's total flux is Σ F (μ₁ + μ₂)
    within 1 %. μ from the ray differentials (the default split), or, with gauss4 (which
    carries none), from central differences of traced rays."""
    mass, r_obs = 0.5, 30.0
    camera = core.Camera.perspective((0, -r_obs, 0), (0, 0, 0), (0, 0, 1), 80, 160, 160)
    psi = np.radians(15.0 * np.arange(24) + 3)
    theta = np.radians(np.linspace(6, 30, 24))
    stars = np.stack(
        [np.sin(theta) * np.cos(psi), np.cos(theta), np.sin(theta) * np.sin(psi)], axis=1
    )
    field = StarField(stars, np.zeros(24), 6000.0, diffuse=(0, 0, 0))
    scene = core.Scene(model=hm.schwarzschild(2 * mass), background=field)
    out = core.render(scene, camera, tolerance_px=0.25, method=method, workers=1)
    assert out.summary["star_images"] == 48
    image = _flux_image(out, camera)
    expected = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # quad's round-off notes near the photon sphere
        for th, ps in zip(theta, psi, strict=True):
            for alpha, sign in zip(image_angles(th, mass, r_obs), (1, -1), strict=True):
                d = [
                    sign * np.sin(alpha) * np.cos(ps),
                    np.cos(alpha),
                    sign * np.sin(alpha) * np.sin(ps),
                ]
                mu = exact_magnification(alpha, mass, r_obs)
                point = camera.image_points(np.array([d]))[0]
                assert _window(image, point) == pytest.approx(field.flux[0] * mu, rel=0.01)
                expected.append(field.flux[0] * mu)
    assert image.sum() == pytest.approx(sum(expected), rel=0.01)


def test_the_images_of_every_band_share_one_magnification_batch(monkeypatch):
    """draw_stars finds the images band by band (BAND_ROWS) but traces their
    magnifications together, up to TRACE_CHUNK at once (each batch pays its rounds'
    per-step cost whatever its rays): one batch for a frame of many bands, and the image
    the same to the last bit as with a batch a band."""
    star_images = importlib.import_module("core.star_images")
    camera = core.Camera.perspective((0, -30, 0), (0, 0, 0), (0, 0, 1), 80, 96, 160)
    field = core.StarField.random(400, seed=5, diffuse=(0, 0, 0))
    scene = core.Scene(model=hm.schwarzschild(1.0), background=field)
    batches = []
    traced, draw_found = star_images.image_magnification, star_images._draw_found

    def counted(tracer, cam, xy):
        batches.append(xy.shape[0])
        return traced(tracer, cam, xy)

    def band_by_band(found, *args):
        return sum(draw_found([band], *args) for band in found)

    monkeypatch.setattr(star_images, "image_magnification", counted)
    together = core.render(scene, camera, tolerance_px=1, workers=1)
    assert len(batches) == 1 and batches[0] >= together.summary["star_images"] > 20
    assert camera.height > 4 * star_images.BAND_ROWS  # several bands
    batches.clear()
    monkeypatch.setattr(star_images, "_draw_found", band_by_band)
    apart = core.render(scene, camera, tolerance_px=1, workers=1)
    assert len(batches) > 4 and apart.summary["star_images"] == together.summary["star_images"]
    assert np.array_equal(together.rgba, apart.rgba)


def _blobs(image):
    """(flux, centroid (2,)) of each group of lit pixels."""
    labels, count = ndimage.label(image > 0, structure=np.ones((3, 3)))
    index = np.arange(1, count + 1)
    flux = ndimage.sum(image, labels, index)
    centre = np.array(ndimage.center_of_mass(image, labels, index))
    size = ndimage.sum(np.ones_like(image), labels, index)
    return flux, centre, size


def test_stars_do_not_flicker_when_the_camera_turns_a_tenth_of_a_pixel():
    """A random star field behind a Schwarzschild hole at 60 M (Preview, tolerance_px 1),
    then the camera turned by 0.1 px: every star image standing alone (its pixels' flux)
    changes by < 2 % (measured: at most 8e-4, typically 3e-5) and stays where it was (its
    pixels' centroid moves by at most a pixel: the filter's 1.5 px footprint covers one or
    two pixels a side); the frame's total star flux by < 0.5 %."""
    field = StarField.random(4000, seed=3, diffuse=(0, 0, 0))
    scene = core.Scene(model=hm.schwarzschild(1.0), background=field)
    base = core.Camera.perspective((0, -30, 0), (0, 0, 0), (0, 0, 1), 60, 240, 180)
    turn = 0.1 * base.pixel_angle()
    moved = core.Camera.perspective(
        (0, -30, 0), (30 * math.tan(turn), 0, 0), (0, 0, 1), 60, 240, 180
    )
    before = _blobs(_flux_image(core.render(scene, base, tolerance_px=1.0, workers=1), base))
    after = _blobs(_flux_image(core.render(scene, moved, tolerance_px=1.0, workers=1), moved))
    assert abs(after[0].sum() / before[0].sum() - 1) < 0.005
    apart = np.linalg.norm(before[1][:, None] - before[1][None], axis=2)
    np.fill_diagonal(apart, np.inf)
    distance = np.linalg.norm(before[1][:, None] - after[1][None], axis=2)
    match = np.argmin(distance, axis=1)
    # one star's image: at most 2x2 pixels (the filter's 1.5 px), 4 px from any other
    alone = (apart.min(axis=1) > 4) & (before[2] <= 4) & (after[2][match] <= 4)
    alone &= before[0] > 1e-3 * before[0].max()
    inner = np.all((before[1] > 2) & (before[1] < np.array([180, 240]) - 3), axis=1)
    alone &= inner  # not cut by the frame's edge
    assert alone.sum() > 100
    assert np.all(distance[np.arange(len(match)), match][alone] < 1.5)
    change = after[0][match] / before[0] - 1
    assert np.abs(change[alone]).max() < 0.02


def test_flat_space_stars_are_points_of_their_flux_and_colour():
    """No hole: with the box filter each star lands in the one pixel holding
    camera.image_points(its direction), with flux F = flux_zero 10^(−0.4 m) (to 1e-3: the
    differences of the float32 direction pass) and the chromaticity of its black body."""
    rng = np.random.default_rng(5)
    d = np.stack([rng.uniform(-0.3, 0.3, 30), np.ones(30), rng.uniform(-0.2, 0.2, 30)], 1)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    temperature = rng.uniform(3000, 20000, 30)
    field = StarField(d, rng.uniform(-1, 4, 30), temperature, diffuse=(0, 0, 0), flux_zero=2e-6)
    camera = core.Camera.perspective((0, -30, 0), (0, 0, 0), (0, 0, 1), 50, 200, 150)
    out = core.render(core.Scene(background=field), camera, pixel_filter="box", workers=1)
    image = _flux_image(out, camera)
    points = camera.image_points(d)
    col, row = points[:, 0].astype(int), points[:, 1].astype(int)
    np.testing.assert_allclose(image[row, col], field.flux, rtol=1e-3)
    assert np.count_nonzero(image) == 30
    rgb = out.rgba[row, col, :3].astype(np.float64)
    expected = star_rgb(temperature)
    np.testing.assert_allclose(rgb / rgb.sum(1, keepdims=True),
                               expected / expected.sum(1, keepdims=True), atol=1e-4)  # fmt: skip


@pytest.mark.parametrize("shift", [True, False])
def test_a_moving_camera_sees_stars_aberrated_and_brighter_by_g_squared(shift):
    """Flat space, a camera at β = 0.9 along +x: a star at angle θ from the motion is seen at
    θ' with cos θ' = (cos θ + β) / (1 + β cos θ), with flux F μ g⁴ = F g² (μ = 1/g²: the
    aberration's solid angle; g = 1 / (γ (1 − β cos θ'))) in the colour of its black body at
    g T, to 1e-3; with colours unshifted, F μ = F / g² in its own colour."""
    beta = 0.9
    theta = np.radians([60.0, 75.0, 90.0, 105.0, 120.0])
    d = np.stack([np.cos(theta), np.sin(theta), np.zeros(5)], axis=1)
    field = StarField(d, np.zeros(5), 5000.0, diffuse=(0, 0, 0))
    camera = core.Camera.perspective((0, 0, 0), (1, 0.6, 0), (0, 0, 1), 120, 300, 100)
    out = core.render(core.Scene(background=field), camera, observer=(beta, 0, 0),
                      shift_colours=shift, pixel_filter="box", workers=1)  # fmt: skip
    seen_cos = (np.cos(theta) + beta) / (1 + beta * np.cos(theta))
    seen = np.stack([seen_cos, np.sqrt(1 - seen_cos**2), np.zeros(5)], axis=1)
    g = 1.0 / ((1 - seen_cos * beta) / math.sqrt(1 - beta * beta))
    points = camera.image_points(seen)
    col, row = points[:, 0].astype(int), points[:, 1].astype(int)
    image = _flux_image(out, camera)
    assert np.count_nonzero(image) == 5
    expected = field.flux * (g**2 if shift else 1 / g**2)
    np.testing.assert_allclose(image[row, col], expected, rtol=1e-3)
    rgb = out.rgba[row, col, :3].astype(np.float64)
    colour = star_rgb(5000.0 * g if shift else np.full(5, 5000.0))
    np.testing.assert_allclose(rgb / rgb.sum(1, keepdims=True),
                               colour / colour.sum(1, keepdims=True), atol=1e-4)  # fmt: skip


def test_stars_behind_a_translucent_disk_are_dimmed_by_it():
    """Kerr a/M 0.9 seen nearly face-on with a disk of opacity 0.4: the transmittance pass is
    0.6 on the disk and 1 on clear sky, and a star behind the disk's annulus keeps 0.6 of the
    flux it has without the disk (the same lensing otherwise)."""
    theta = np.radians(25.0)
    d = np.array([[np.sin(theta), 0.0, np.cos(theta)]])  # behind the annulus, seen from above
    field = StarField(d, [0.0], diffuse=(0, 0, 0))
    camera = core.Camera.perspective((0, 0, 40), (0, 0, 0), (0, 1, 0), 60, 120, 120)
    model = hm.kerr(rg=1.0, a=0.45, chart="kerr_schild")
    fluxes = []
    for opacity in (None, 0.4):
        disk = None if opacity is None else core.AccretionDisk(r_out=30.0, opacity=opacity,
                                                                brightness=0.0)  # fmt: skip
        out = core.render(core.Scene(model=model, background=field, disk=disk), camera,
                          passes=("transmittance", "ending"), workers=1)  # fmt: skip
        fluxes.append(_flux_image(out, camera).sum())
        if opacity is not None:
            t = out.passes["transmittance"]
            crossed = t < 1  # once (0.6), or twice (0.36: a ray bent back through it)
            assert crossed.sum() > 1000 and np.mean(np.abs(t[crossed] - 0.6) < 1e-6) > 0.9
            crossings = np.log(t[crossed]) / math.log(0.6)
            np.testing.assert_allclose(crossings, np.round(crossings), atol=1e-5)
    assert fluxes[1] == pytest.approx(0.6 * fluxes[0], rel=1e-3)


def test_catalogues_are_read_and_refused_by_name(tmp_path):
    """A CSV with RA/Dec/mag/B−V (any case, any column order) gives the stars' directions
    (RA 90°, Dec 0 is +y; Dec 90° is +z), magnitudes and Ballesteros temperatures (Vega,
    B−V 0: 10 125 K; the Sun, 0.65: ~5 800 K); a missing column or a bad number is named
    with its line; StarField.random is reproducible from its seed, with counts growing as
    10^(0.5 m)."""
    good = tmp_path / "stars.csv"
    good.write_text("Vmag,RA,Dec,B-V\n0.03,90,0,0.0\n4.8,0,90,0.65\n")
    field = StarField.from_csv(good)
    np.testing.assert_allclose(field.directions, [[0, 1, 0], [0, 0, 1]], atol=1e-12)
    np.testing.assert_allclose(field.magnitudes, [0.03, 4.8])
    assert field.temperatures[0] == pytest.approx(10125, rel=1e-3)
    assert 5600 < field.temperatures[1] < 6000
    assert temperature_from_bv(0.65) == pytest.approx(field.temperatures[1])
    missing = tmp_path / "missing.csv"
    missing.write_text("ra,mag\n1,2\n")
    with pytest.raises(ValueError, match="missing dec"):
        StarField.from_csv(missing)
    bad = tmp_path / "bad.csv"
    bad.write_text("ra,dec,mag\n1,2,3\n1,x,3\n")
    with pytest.raises(ValueError, match="line 3: column 'dec'"):
        StarField.from_csv(bad)
    with pytest.raises(ValueError, match="2 star directions but 1 magnitudes"):
        StarField([[1, 0, 0], [0, 1, 0]], [1.0])
    with pytest.raises(ValueError, match="star 1"):
        StarField([[1, 0, 0], [0, 0, 0]], [1.0, 2.0])
    a, b = StarField.random(2000, seed=7), StarField.random(2000, seed=7)
    np.testing.assert_array_equal(a.directions, b.directions)
    counts = [np.sum(a.magnitudes < m) for m in (4.5, 6.5)]
    assert counts[1] / counts[0] == pytest.approx(10.0, rel=0.15)
    ortho = core.Camera.orthographic((0, -30, 0), (0, 0, 0), (0, 0, 1), 10.0, 8, 8)
    with pytest.raises(ValueError, match="point stars"):
        core.render(core.Scene(background=a), ortho, workers=1)


def _catalogue(tmp_path, data: bytes, name: str = "stars.csv"):
    path = tmp_path / name
    path.write_bytes(data)
    return path


def test_a_catalogue_with_a_byte_order_mark_or_a_blank_last_line_is_read(tmp_path):
    """Excel's "CSV UTF-8" starts with a byte-order mark, and many files end in a blank
    line: both read as the plain file does (issue 45)."""
    plain = StarField.from_csv(_catalogue(tmp_path, b"ra,dec,mag\n90,0,1\n0,90,2\n", "a.csv"))
    for data in (
        b"\xef\xbb\xbfra,dec,mag\r\n90,0,1\r\n0,90,2\r\n",
        b"ra,dec,mag\n90,0,1\n0,90,2\n\n",
        b"ra,dec,mag\n90,0,1\n\n0,90,2\n \n",
    ):
        field = StarField.from_csv(_catalogue(tmp_path, data))
        np.testing.assert_array_equal(field.directions, plain.directions)
        np.testing.assert_array_equal(field.magnitudes, plain.magnitudes)


@pytest.mark.parametrize(
    "data, message",
    [
        (b"ra,dec,mag\n90,0,1\n0,90,nan\n", r"bad\.csv, line 3: column 'mag' is nan, not a finite"),
        (b"ra,dec,mag\n90,0,1\n\n0,inf,2\n", r"bad\.csv, line 4: column 'dec' is inf, not a fini"),
        (b"ra,dec,mag\n90,0,-1000\n", r"bad\.csv, line 2: magnitude -1000 is brighter than -30"),
        (b"ra,dec,mag\n90,0,1\n0,90,\xe9\n", r"bad\.csv, line 3: not UTF-8 text \(byte 0xe9\)"),
        (b"ra,dec,mag\n90,0,1\n0,90\n", r"bad\.csv, line 3: column 'mag' is not a number"),
    ],
)
def test_a_bad_catalogue_names_its_file_and_line(tmp_path, data, message):
    """NaN or infinite numbers, a magnitude brighter than any star (its light overflows
    32-bit floats: it was blamed on Disk Brightness), a file not in UTF-8: each refused
    with the file and the line (issue 45)."""
    with pytest.raises(ValueError, match=message):
        StarField.from_csv(_catalogue(tmp_path, data, "bad.csv"))

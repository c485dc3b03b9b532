"""Environment lookups (Blender's equirectangular convention) and the procedural sky."""

import json
from pathlib import Path

import numpy as np
import pytest

import core.sky as sky_module
from core.camera import Camera
from core.sky import (
    Background,
    direction_to_equirect,
    equirect_lookup,
    equirect_to_direction,
    procedural_sky,
    star_color,
)

REF = Path(__file__).parent / "data" / "blender_reference.npz"


def _coded_image(h, w):
    """R = u of the pixel centre, G = row-from-top fraction, B = 0.5 (the reference env)."""
    img = np.zeros((h, w, 3))
    img[..., 0] = (np.arange(w) + 0.5)[None, :] / w
    img[..., 1] = (np.arange(h) + 0.5)[:, None] / h
    img[..., 2] = 0.5
    return img


def test_equirect_axes_follow_blender():
    d = np.array([[1, 0, 0], [0, 1, 0], [-1e-9, -1, 0], [0, 0, 1], [0, 0, -1], [1, 0, 1]], float)
    uv = direction_to_equirect(d)
    assert np.allclose(uv[0], [0.5, 0.5])  # +X: image centre
    assert np.allclose(uv[1], [0.25, 0.5])  # +Y: left of centre
    assert np.allclose(uv[2], [0.75, 0.5])
    assert uv[3, 1] == pytest.approx(1.0) and uv[4, 1] == pytest.approx(0.0)
    assert np.allclose(uv[5], [0.5, 0.75])


def test_equirect_round_trip():
    rng = np.random.default_rng(3)
    d = rng.normal(size=(1000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    assert np.allclose(equirect_to_direction(direction_to_equirect(d)), d, atol=1e-12)
    uv = rng.uniform(0, 1, (1000, 2))
    assert np.allclose(direction_to_equirect(equirect_to_direction(uv)), uv, atol=1e-12)


def test_lookup_at_pixel_centres_is_exact_and_bilinear_between():
    h, w = 8, 16
    img = np.random.default_rng(1).random((h, w, 4))
    u = (np.arange(w) + 0.5) / w
    v = 1 - (np.arange(h) + 0.5) / h
    uu, vv = np.meshgrid(u, v)
    d = equirect_to_direction(np.stack([uu, vv], -1).reshape(-1, 2))
    assert np.allclose(equirect_lookup(img, d).reshape(h, w, 4), img, atol=1e-12)
    assert np.allclose(equirect_lookup(img, d, "closest").reshape(h, w, 4), img)
    # half-way between columns 3 and 4 of row 2: the average
    mid = equirect_to_direction(np.array([[4 / w, v[2]]]))
    assert np.allclose(equirect_lookup(img, mid)[0], (img[2, 3] + img[2, 4]) / 2)
    # across the seam u = 0 / 1: wraps between the last and first columns
    seam = equirect_to_direction(np.array([[1e-12, v[5]]]))
    assert np.allclose(equirect_lookup(img, seam)[0], (img[5, 0] + img[5, -1]) / 2)
    # above the top row's centre: clamped, not wrapped to the bottom
    pole = np.array([[0.0, 0.0, 1.0]])
    assert np.all(np.isfinite(equirect_lookup(img, pole)))


@pytest.mark.parametrize("case", [0, 1])
def test_lookup_matches_blender_environment_render(case):
    """Cycles rendered this coded environment (Closest) through a panorama/perspective camera."""
    ref = np.load(REF)
    cfg = json.loads(str(ref[f"env{case}_config"]))
    cam = Camera.blender(resolution_x=cfg["res"][0], resolution_y=cfg["res"][1],
                         matrix_world=ref[f"env{case}_matrix"], **cfg["cam"])  # fmt: skip
    _, d = cam.rays()
    mine = equirect_lookup(_coded_image(32, 64), d, "closest").reshape(cam.height, cam.width, 3)
    expected = ref[f"env{case}_color"]
    assert np.abs(mine - expected).max() < 1e-5


def test_procedural_sky_is_deterministic_and_chunkable():
    cam = Camera.perspective((0, 0, 0), (1, 0.2, 0.3), (0, 0, 1), 30, 96, 64)
    _, d = cam.rays()
    a = procedural_sky(d)
    b = np.concatenate([procedural_sky(d[:1000]), procedural_sky(d[1000:])])
    assert np.array_equal(a, b) and np.allclose(a, procedural_sky(d * 3.0), rtol=1e-9)
    assert a.shape == d.shape and np.all(np.isfinite(a)) and np.all(a >= 0)
    assert a.max() > 50 * np.median(a)  # point-like stars on a dark background


def test_stars_looked_up_only_near_their_centres_lose_no_light(monkeypatch):
    """_star_layer works out a star's brightness and colour only for the directions
    within 3 of its widest sigma: with every direction counted near, the sky is the same
    to the last bit (also a sky of wide stars, sigma 30x; a NaN direction stays NaN)."""
    cam = Camera.perspective((0, 0, 0), (1, 0.2, 0.3), (0, 0, 1), 8, 160, 120)
    _, d = cam.rays()
    d[7] = (np.inf, 0.0, 0.0)  # NaN once normalised
    for size in (1.0, 30.0):
        cut = procedural_sky(d, star_size=size, galaxy=False)
        monkeypatch.setattr(sky_module, "_WIDEST_SIGMA", 1e6)
        every = procedural_sky(d, star_size=size, galaxy=False)
        monkeypatch.undo()
        assert np.array_equal(cut, every, equal_nan=True)
        assert np.count_nonzero(cut[:, 0] > 1e-3) > 10  # stars in view


def test_procedural_sky_parts():
    d = equirect_to_direction(np.random.default_rng(5).uniform(0, 1, (20000, 2)))
    bare = procedural_sky(d, stars=False, galaxy=False)
    assert bare.max() < 0.01  # dim gradient only
    stars = procedural_sky(d, galaxy=False) - bare
    lit = np.any(stars > 1e-3, axis=1)
    assert 0.002 < lit.mean() < 0.2  # small stars cover a small fraction of the sky
    galaxy = procedural_sky(d, stars=False) - bare
    assert galaxy.max() > 10 * bare.max() and np.median(galaxy[:, 0]) < 1e-3  # a band
    on_grid = procedural_sky(np.array([[1.0, 0, np.tan(np.radians(30))]]), grid=True,
                             stars=False, galaxy=False)  # fmt: skip
    off_grid = procedural_sky(equirect_to_direction([[0.5 - 7 / 360, 0.5 + 37.5 / 180]]),
                              grid=True, stars=False, galaxy=False)  # fmt: skip
    assert on_grid.sum() > 0.1 and off_grid.sum() < 0.02


def test_star_colour_temperatures():
    c = star_color([3000.0, 5800.0, 20000.0])
    assert c[0, 0] > c[0, 2] and c[2, 2] > c[2, 0]  # red cool stars, blue hot stars


def test_background_specs():
    d = np.array([[1.0, 0, 0], [0, 0, 1]])
    const = Background((0.1, 0.2, 0.3), strength=2)(d)
    assert np.allclose(const, [[0.2, 0.4, 0.6, 1]] * 2)
    img = _coded_image(8, 16)
    arr = Background(img)(d)
    assert np.allclose(arr[:, :3], equirect_lookup(img, d)) and np.all(arr[:, 3] == 1)
    rgba = np.concatenate([img, np.full((8, 16, 1), 0.5)], axis=2)
    assert np.allclose(Background(rgba)(d)[:, 3], 0.5)
    rot = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1.0]])  # rotate the environment 90 deg
    turned = Background(img, matrix=rot)(np.array([[0.0, 1, 0]]))
    assert np.allclose(turned[0, :3], equirect_lookup(img, [[1.0, 0, 0]])[0])
    proc = Background("procedural", grid=True)(d)
    assert np.allclose(proc[:, :3], procedural_sky(d, grid=True))
    assert np.allclose(Background(lambda x: x * 0 + 1)(d), 1)
    with pytest.raises(ValueError):
        Background("stars")
    with pytest.raises(ValueError):
        Background(np.zeros((4, 4)))

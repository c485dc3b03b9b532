"""Big skies held once (issue 45.7): a float32 equirect image is looked up as it is, its
pyramid built in float32 band by band; lookups equal today's float64 ones within float32
rounding, point lookups bit for bit."""

import tracemalloc

import numpy as np
import pytest

import core
from core import mipmap
from core.mipmap import MipMap, flip_rows, halve, wrap_index
from core.sky import Background

RNG = np.random.default_rng(457)
WRAPS = [("repeat", "extend"), ("mirror", "mirror"), ("extend", "repeat")]


def halve_whole(image, wrap):
    """The halving as it was: the whole (padded) level's 2x2 means at once, float64."""
    h, w = image.shape[:2]
    if w > 1 and w % 2:
        image = np.concatenate([image, image[:, wrap_index(np.array([w]), w, wrap[0])]], axis=1)
    if h > 1 and h % 2:
        image = np.concatenate([image, image[wrap_index(np.array([h]), h, wrap[1])]], axis=0)
    h, w = image.shape[:2]
    rows, columns = max(h // 2, 1), max(w // 2, 1)
    return image.reshape(rows, h // rows, columns, w // columns, -1).mean(axis=(1, 3))


def sky(h=96, w=192, channels=4):
    """A float32 sky with detail at every scale (noise) and values up to 50 (an HDR sun)."""
    image = RNG.uniform(0, 1, (h, w, channels)).astype(np.float32)
    image[h // 3 : h // 3 + 3, w // 2 : w // 2 + 4, :3] = 50.0
    return image


def directions_and_footprints(n=4000):
    """Unit directions and footprints from sub-texel to hundreds of texels wide."""
    d = RNG.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    jacobian = RNG.normal(size=(n, 2, 3)) * 10.0 ** RNG.uniform(-4, 0, (n, 1, 1))
    return d, jacobian


def rounding_bound(image) -> float:
    """How far a float32 pyramid's lookups may be from a float64 one's: each halving rounds
    its means to float32 once (at most 2^-24 of the largest value, relative), and a level's
    error passes to the next through means (not grown); lookups are convex combinations of
    texels. So: the number of levels x 2^-24 x the largest |value|."""
    levels = int(np.ceil(np.log2(max(image.shape[:2])))) + 1
    return levels * 2.0**-24 * float(np.abs(image).max())


@pytest.mark.parametrize("shape", [(1, 1, 4), (1, 7, 3), (7, 1, 4), (5, 9, 4), (33, 65, 4)])
@pytest.mark.parametrize("wrap", WRAPS)
def test_halving_band_by_band_equals_the_whole_level(monkeypatch, shape, wrap):
    monkeypatch.setattr(mipmap, "HALVE_BAND", 20)  # a few rows a band
    image = RNG.uniform(0, 3, shape)
    assert np.array_equal(halve(image, wrap), halve_whole(image, wrap))  # float64: bit for bit
    small = image.astype(np.float32)
    got = halve(small, wrap)
    assert got.dtype == np.float32
    exact = halve_whole(small.astype(np.float64), wrap)
    assert np.abs(got - exact).max() <= 2.0**-24 * np.abs(exact).max()  # one float32 rounding


def test_the_pyramid_keeps_the_image_and_its_type():
    image = sky()
    background = Background(image)
    pyramid = background._mipmap
    assert pyramid.levels[0] is image  # no copy of the full-size image
    assert all(level.dtype == np.float32 for level in pyramid.levels)
    assert pyramid.levels[-1].shape[:2] == (1, 1)
    assert Background(image.astype(np.float64))._mipmap.levels[1].dtype == np.float64


@pytest.mark.parametrize("interpolation", ["linear", "closest"])
def test_point_lookups_equal_the_float64_ones_bit_for_bit(interpolation):
    image = sky()
    d, _ = directions_and_footprints()
    new = Background(image, interpolation=interpolation)(d)
    old = Background(image.astype(np.float64), interpolation=interpolation)(d)
    assert np.array_equal(new, old)


def test_filtered_lookups_within_float32_rounding_of_the_float64_pyramid():
    image = sky()
    d, jacobian = directions_and_footprints()
    new = Background(image)(d, jacobian)
    old = Background(image.astype(np.float64))(d, jacobian)
    wide = np.abs(new - old).max(axis=1) > 0
    assert wide.any()  # coarse levels were used (and rounded)
    assert np.abs(new - old).max() <= rounding_bound(image)
    for wrap in WRAPS:  # a surface texture's pyramid
        uv = RNG.uniform(-0.5, 1.5, (2000, 2))
        footprint = RNG.normal(size=(2000, 2, 2)) * 10.0 ** RNG.uniform(-1, 2, (2000, 1, 1))
        got = MipMap(image, wrap).lookup(uv, footprint)
        ref = MipMap(image.astype(np.float64), wrap).lookup(uv, footprint)
        assert np.abs(got - ref).max() <= rounding_bound(image)


def test_building_the_pyramid_allocates_a_third_of_the_image(monkeypatch):
    """numpy reports its buffers to tracemalloc: a float32 sky's pyramid and its filtered
    lookups take a third of the image more (the halvings 1/4 + 1/16 + ... in float32) and
    one band's float64 work (its 4 inputs a value, 8 bytes each: 32 bytes per value of
    HALVE_BAND), not a float64 copy (2x the image) and float64 levels (2/3 more)."""
    monkeypatch.setattr(mipmap, "HALVE_BAND", 1 << 16)
    image = sky(512, 1024)
    d, jacobian = directions_and_footprints(1000)
    tracemalloc.start()
    try:
        Background(image)(d, jacobian)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak <= image.nbytes / 3 + 32 * mipmap.HALVE_BAND < 0.6 * image.nbytes


def test_flip_rows_in_place():
    for h in (0, 1, 2, 3, 255, 256, 257, 1001):
        image = RNG.normal(size=(h, 3, 4)).astype(np.float32)
        flipped = image[::-1].copy()
        assert flip_rows(image, band=100) is image
        assert np.array_equal(image, flipped)


def test_renders_of_a_float32_sky_within_rounding_of_float64():
    """A dense render (sky footprints on) and an adaptive one, flat and around a hole."""
    image = sky(128, 256)
    camera = core.Camera.perspective(position=(0, -30, 2), look_at=(0, 0, 0), up=(0, 0, 1),
                                     fov_deg=60, width=32, height=24)  # fmt: skip
    for model in (None, core.hamiltonians.schwarzschild(rg=1.0)):
        renders = [
            core.render(core.Scene(model=model, background=sky_image), camera, workers=1).rgba
            for sky_image in (image, image.astype(np.float64))
        ]
        # rgba is float32: the float64 pyramid's result rounded once more
        bound = rounding_bound(image) + 2.0**-24 * float(np.abs(renders[1]).max())
        assert np.abs(renders[0] - renders[1]).max() <= bound

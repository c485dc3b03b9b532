"""Adaptive image sampling (core/sampling.py): interpolation stays inside one ending and one
object, anti-aliasing converges to the area average, the error pass tells the truth, and
the tiles shown progressively are the image."""

import math

import numpy as np
import pytest

import core
from core import hamiltonians as hm
from core import sampling
from core.render import TRACE_SHARE


def _board(y: float = 12.0, extent: float = 16.0) -> core.Plane:
    return core.Plane(
        point=(0, y, 0), normal=(0, -1, 0), u_axis=(1, 0, 0), extent=(extent, extent),
        color=core.checker(8, 8),
    )  # fmt: skip


def _hole_camera(width: int, height: int) -> core.Camera:
    return core.Camera.perspective((0, -30, 2), (0, 0, 0), (0, 0, 1), 40, width, height)


def _kerr_board() -> core.Scene:
    sphere = core.Sphere(center=(6, 6, 1), radius=1.5, color=(1, 0, 0, 1), object_id=1)
    return core.Scene(
        model=hm.kerr(rg=1.0, a=0.45, chart="kerr_schild"),
        objects=[_board(), sphere],
        background="procedural",
    )


def test_tolerance_px_is_pixels_of_this_camera():
    """tolerance_px p gives the tracer tolerance TRACE_SHARE x p x (the pixel's angle at
    the image centre): the same step as tolerance in radians; a pixel's angle is the
    window's width over the image width (fov 40 deg over 64 px)."""
    cam = _hole_camera(64, 36)
    scene = core.Scene(model=hm.schwarzschild(rg=1.0))
    assert cam.pixel_angle() == pytest.approx(2 * np.tan(np.radians(20)) / 64, rel=1e-12)
    px = core.render(scene, cam, tolerance_px=0.5, passes=())
    rad = core.render(scene, cam, tolerance=0.25 * cam.pixel_angle(), passes=())
    assert px.summary["step"] == rad.summary["step"]
    assert px.summary["pixel_angle"] == cam.pixel_angle()


@pytest.mark.usefixtures("rounds_free")
def test_interpolation_never_crosses_an_ending_or_an_object():
    """At a loose 2 px, against one ray through every pixel with the same method (the
    model's default: Kerr's explicit split) at the same step: every pixel ends the same way
    (sky, shadow, board, sphere), though most are interpolated. Rays that passed an object
    within their error are traced again at half the step (core.sampling NEAR_MISS) and
    report a possible flip: where such a pixel differs from the same-step render (one ray
    grazing the sphere, measured), it is what a render at 1/16 the tolerance shows."""
    scene, cam = _kerr_board(), _hole_camera(96, 54)
    adaptive = core.render(scene, cam, tolerance_px=2.0, passes=("ending", "error_px"))
    tolerance = TRACE_SHARE * 2.0 * cam.pixel_angle()
    full = core.render(scene, cam, tolerance=tolerance, passes=("ending",))
    tight = core.render(scene, cam, tolerance=tolerance / 16, passes=("ending",))
    # interpolation happened; not 0.8: at 96 x 54 the board's cells are a few pixels wide
    # and most centres next to their edges are traced where their error could change their
    # colour (core.sampling.COLOUR_STEP): 4066 rays without that, 4387 with it, of 5184
    assert adaptive.summary["rays"] < 0.92 * full.summary["rays"]
    red = lambda image: (image[..., 0] > 0.9) & (image[..., 1] < 0.1)  # noqa: E731
    assert red(full.rgba).sum() > 20
    ending, is_red = adaptive.passes["ending"], red(adaptive.rgba)
    apart = (ending != full.passes["ending"]) | (is_red != red(full.rgba))
    assert np.count_nonzero(apart) <= 3
    assert np.all(adaptive.passes["error_px"][apart] >= 1.0)
    np.testing.assert_array_equal(ending[apart], tight.passes["ending"][apart])
    np.testing.assert_array_equal(is_red[apart], red(tight.rgba)[apart])


def _edge_scene(slope: float):
    """A white square, one of whose edges is the line x = slope y, covering x > slope y in
    view, in front of a black background: a pixel's exact colour is its area on that side."""
    across = np.array([1.0, -slope, 0.0]) / np.hypot(1.0, slope)  # towards x > slope y
    white = core.Plane(
        point=50.0 * across, normal=(0, 0, 1), u_axis=across, extent=(100, 100),
        color=(1, 1, 1, 1),
    )  # fmt: skip
    return core.Scene(objects=[white], background=(0, 0, 0))


def _coverage(cam: core.Camera, slope: float, offset: float) -> np.ndarray:
    """Exact area fraction of each pixel with x > slope * y + offset (world = window)."""
    n = 64  # per-pixel integration of the straight edge, exact to 1/n^2 in area
    w, h = cam.width, cam.height
    sub = (np.arange(n) + 0.5) / n
    cols = (np.arange(w)[:, None] + sub[None, :]).ravel()
    rows = (np.arange(h)[:, None] + sub[None, :]).ravel()
    xy = cam.image_window_coords(np.stack(np.meshgrid(cols, rows), -1).reshape(-1, 2))
    inside = xy[:, 0] > slope * xy[:, 1] + offset
    return inside.reshape(h, n, w, n).mean(axis=(1, 3))


def test_anti_aliasing_converges_to_the_area_average():
    """Box-filtered samples on an analytic slanted edge: the colour of the edge's pixels
    approaches their covered area as samples grow. Each pixel's samples are jittered within
    the cells of a k x k grid, differently per pixel (core.sampling.pixel_samples): the
    mean error along an edge falls like k^-1.5, 0.098 (4), 0.035 (16), 0.014 (64) measured.
    (One fixed centred grid for all pixels did better on this edge, 0.088, 0.014, 0.0054,
    but covered a strip 0.3 px wide with the same grid columns in every pixel: 0.25 or 0.5
    of its light, test_a_thin_strip_keeps_its_light; the bounds below are that trade.)"""
    cam = core.Camera.orthographic((0, 0, 5), (0, 0, 0), (0, 1, 0), 8.0, 32, 32)
    scene = _edge_scene(0.3)
    truth = _coverage(cam, slope=0.3, offset=0.0)
    edge = (truth > 0.02) & (truth < 0.98)
    assert edge.sum() > 30
    errors = {}
    for samples in (4, 16, 64):
        image = core.render(scene, cam, samples=samples, pixel_filter="box", passes=())
        errors[samples] = float(np.abs(image.rgba[..., 0] - truth)[edge].mean())
    assert errors[16] < errors[4] / 2.5 and errors[64] < errors[16] / 2
    assert errors[16] < 0.045 and errors[64] < 0.02


def test_a_thin_strip_keeps_its_light():
    """Final (0.25 px, 16 samples, box): a white strip 0.3 px wide along a column, lensed
    by a Schwarzschild hole beside it (its image bent by ~0.1 rad) and in flat space, keeps
    its light: the image's total is within 10 % of the strip's exact coverage (flat: 0.3
    px x its rows) or of a 16 x 16 supersampled dense render (curved: its quantisation,
    1/16 px, is 2 % of the strip's 0.3 px on average over its rows). One fixed sample
    pattern in every pixel gave 0.83 or 1.67 x (the same one or two grid columns cover the
    strip in every row), and pixels whose centres all missed it got no samples: 0.
    """
    width, height = 24, 16
    cams = [core.Camera.perspective(position=(0, -30, 0), look_at=(0, 0, 0), up=(0, 0, 1),
                                    fov_deg=10, width=k * width, height=k * height)
            for k in (1, 16)]  # fmt: skip
    cam, fine = cams
    across = 0.3 * cam.pixel_angle() * 70.0  # 0.3 px at 70 from the camera
    for model in (None, hm.schwarzschild(rg=1.0)):
        strip = core.Plane(point=(1.53, 40, 0), normal=(0, -1, 0), u_axis=(1, 0, 0),
                           extent=(across, 20), color=(1, 1, 1, 1))  # fmt: skip
        extra = {} if model is None else {"model": model, "center": (-16, 0, 0)}
        scene = core.Scene(objects=[strip], background=(0, 0, 0), **extra)
        run = core.render(scene, cam, tolerance_px=0.25, samples=16, pixel_filter="box",
                          passes=())  # fmt: skip
        light = float(run.rgba[..., 0].sum())
        if model is None:
            truth = 0.3 * height
        else:
            dense = core.render(scene, fine, tolerance_px=4.0, passes=())
            truth = float(dense.rgba[..., 0].sum()) / 256
        assert truth > 0.25 * height
        assert 0.9 * truth <= light <= 1.1 * truth, (model, light, truth)


def true_error_px(ref, run, eye) -> np.ndarray:
    """Per pixel, how far (pixels) what ``run`` shows is from what ``ref`` shows
    (tolerance_px's measure, docs/design.md; core.sampling.seen_apart): for a hit, the
    distance between the hit points over the pixel's footprint there; for the sky, the
    angle between the escape directions; +inf where the endings differ; NaN where both are
    captured."""
    ending = ref.passes["ending"]
    flat = [r.passes[name].reshape(-1, 3).astype(float) for r in (ref, run)
            for name in ("direction", "position")]  # fmt: skip
    with np.errstate(all="ignore"):
        apart = sampling.seen_apart(*flat, ending.ravel(), np.asarray(eye, float))
    truth = apart.reshape(ending.shape) / run.summary["pixel_angle"]
    same = ending == run.passes["ending"]
    truth = np.where(same, truth, np.inf)
    return np.where(same & (ending == core.ENDING["captured"]), np.nan, truth)


@pytest.mark.usefixtures("rounds_free")
def test_error_pass_tells_the_truth_on_a_small_frame():
    """Kerr a/M = 0.9, a board and a sphere at 1 px (Preview), against dopri5 at 1e-11 rad
    with a far region: of the pixels whose true error exceeds a tenth of the tolerance, >= 90 %
    are estimated within 3x; fewer than 2 % of all pixels are under-reported by > 3x (the
    issue's 1 % is met on the benchmark's larger frame, benchmarks/image_quality.py; a
    small frame has few pixels to spread the interpolated edge pixels over); a pixel that
    ends apart from the reference reports a flip (error_px >= 1). A hit's error is its hit
    point's distance over the pixel footprint (tolerance_px's measure), not the direction
    to it: measured so, 66 of 66 pixels above a tenth of the tolerance are within 3x. (At
    64x36 only 18 pixels are above it since centres whose error could change their colour
    are traced, core.sampling.COLOUR_STEP: too few; the reference takes as long at 96x54.)"""
    scene, cam = _kerr_board(), _hole_camera(96, 54)
    passes = ("error_px", "ending", "direction", "position")
    ref = core.render(scene, cam, method="dopri5", tolerance=1e-11, passes=passes,
                      max_steps=10**6)  # fmt: skip
    run = core.render(scene, cam, tolerance_px=1.0, passes=passes)
    truth = true_error_px(ref, run, cam.frame.position)
    est = run.passes["error_px"].astype(float)
    seen = np.isfinite(truth)
    big = seen & (truth > 0.1)
    assert big.sum() > 25
    within = (est[big] <= 3 * truth[big]) & (est[big] >= truth[big] / 3)
    assert within.mean() >= 0.9
    assert np.count_nonzero(seen & (est < truth / 3)) / truth.size < 0.02
    apart = np.isinf(truth)
    assert np.count_nonzero(apart) <= 2  # at most a grazing pixel or two ends apart
    assert np.all(est[apart] >= 1.0)


def test_a_lens_maps_interpolation_error_is_not_hidden_by_its_harmonic_part():
    """A lens map's deflection is a potential's gradient, so its components are nearly
    harmonic: f_xx + f_yy ~ 0, and a block's centre deviates little from its corners' mean
    while its edges bend (f = x^2 - y^2: the centre exact, each edge's midpoint off by a
    quarter). The blocks measure their edges' midpoints: the estimate is the bilinear error
    there, and the centre's alone would have missed it."""
    x, y = np.meshgrid([0.0, 0.5, 1.0], [0.0, 0.5, 1.0])
    saddle = x**2 - y**2  # rows: y; columns: x
    nine = [(0, 0), (0, 2), (2, 0), (2, 2), (0, 1), (2, 1), (1, 0), (1, 2), (1, 1)]

    def apart(k, ends):
        value = saddle[nine[k]]
        return np.array([abs(value - np.mean([saddle[nine[e]] for e in ends]))])

    deviation = sampling._edge_deviations(apart)
    np.testing.assert_allclose(deviation[0], [0.25, 0.25, 0.25, 0.25, 0.0])
    centre_alone = abs(saddle[1, 1] - np.mean([saddle[p] for p in nine[:4]]))
    assert centre_alone == 0.0
    # the estimate at (u, v) against the bilinear interpolation's true error there: equal
    # on the edges, a bound inside (it adds the two directions' parts, which cancel here)
    u, v = np.array([0.5, 0.0, 0.25, 0.5, 0.5]), np.array([0.0, 0.5, 0.25, 0.75, 0.5])
    bilinear = u * (1 - v) * 1.0 + (1 - u) * v * -1.0
    true = np.abs(u**2 - v**2 - bilinear)
    estimate = sampling._error_shape(u, v) @ deviation[0]
    np.testing.assert_allclose(estimate[:2], true[:2])
    assert np.all(estimate >= true - 1e-12)
    assert sampling._worst(deviation)[0] == 0.5


def _against_dopri5(scene, cam, tolerance_px: float):
    """(run at ``tolerance_px`` with error_px and steps passes, its true error in pixels
    against dopri5 at 1e-10 rad, its error_px estimate as float)."""
    passes = ("ending", "direction", "position")
    ref = core.render(scene, cam, method="dopri5", tolerance=1e-10, max_steps=10**6,
                      passes=passes)  # fmt: skip
    run = core.render(scene, cam, tolerance_px=tolerance_px,
                      passes=(*passes, "error_px", "steps"))  # fmt: skip
    truth = true_error_px(ref, run, cam.frame.position)
    return run, truth, run.passes["error_px"].astype(float)


@pytest.mark.usefixtures("rounds_free")
def test_interpolated_sky_around_a_lens_is_not_under_reported():
    """Schwarzschild from 30 rg, the procedural sky only, 1 px (Preview), against dopri5 at
    1e-10 rad: of the interpolated pixels whose true error exceeds a tenth of the tolerance,
    none is estimated below a third of it (27 of 1895 were, the centre alone measured),
    and no pixel exceeds the tolerance."""
    cam = _hole_camera(96, 54)
    scene = core.Scene(model=hm.schwarzschild(rg=1.0), background="procedural")
    run, truth, est = _against_dopri5(scene, cam, 1.0)
    seen = np.isfinite(truth)
    interpolated = seen & (run.passes["steps"] == 0) & (truth > 0.1)
    assert interpolated.sum() > 100
    assert np.count_nonzero(est[interpolated] < truth[interpolated] / 3) == 0
    assert np.all(truth[seen] <= 1.0)


def test_tiles_shown_progressively_are_the_image():
    """on_tile hands over every pixel once, and the pieces put together are the result."""
    scene, cam = _kerr_board(), _hole_camera(40, 30)
    seen = np.zeros((30, 40), dtype=int)
    canvas = np.zeros((30, 40, 4), dtype=np.float32)

    calls = [0]

    def on_tile(rect, part):
        calls[0] += 1
        x0, y0, x1, y1 = rect
        seen[y0:y1, x0:x1] += 1
        canvas[y0:y1, x0:x1] = part.rgba

    old = sampling.lattice.STRIDE
    sampling.lattice.STRIDE = 4  # bands of 7 rows: several on a small frame (read per render)
    try:
        result = core.render(scene, cam, tolerance_px=1.0, on_tile=on_tile, passes=())
    finally:
        sampling.lattice.STRIDE = old
    assert np.all(seen == 1) and calls[0] >= 2
    np.testing.assert_array_equal(canvas, result.rgba)
    assert result.summary["pixels"] == 1200 and 0 < result.summary["rays"]


def test_threads_share_the_sampler_safely():
    """Two threads render tiles at once (the sampler is shared): the image is exactly the
    one-worker image (each tile had kept its own origin only since the race was found: two
    16-row bands drew each other's rows)."""
    cam = core.Camera.orthographic((0, 0, 5), (0, 0, 0), (0, 1, 0), 8.0, 32, 64)
    scene = _edge_scene(0.3)
    one = core.render(scene, cam, samples=4, pixel_filter="box", passes=(), workers=1)
    two = core.render(scene, cam, samples=4, pixel_filter="box", passes=(), workers=2,
                      parallel="threads")  # fmt: skip
    assert two.summary["parallel"] == "2 threads"
    np.testing.assert_array_equal(two.rgba, one.rgba)


def _aa_scene():
    """A checker board and a sphere, flat space: many edges, every pixel traced."""
    sphere = core.Sphere(center=(1, 6, 1), radius=1.5, color=(1, 0, 0, 1), object_id=1)
    return core.Scene(objects=[_board(), sphere], background="procedural")


def test_samples_in_groups_are_the_image_in_one_batch(monkeypatch):
    """Anti-aliasing works through SAMPLE_POINTS points at a time. Groups
    of whole pixels' samples give the very image of one batch (and the same ray count), on a
    flat scene and on Kerr's (interpolated blocks); groups of 40 points, which split a
    pixel's 64 samples, the same within 1e-12 (the weighted sum is accumulated in another
    order)."""
    flat = core.Camera.perspective((0, -20, 2), (0, 0, 0), (0, 0, 1), 50, 32, 24)
    cases = [
        (_aa_scene(), flat, dict(samples=64), (3 * 64, 40)),
        (_kerr_board(), _hole_camera(24, 18), dict(samples=16, tolerance_px=1.0), (6 * 16,)),
    ]  # fmt: skip
    for scene, cam, options, groups in cases:
        one = core.render(scene, cam, passes=(), workers=1, **options)
        assert one.summary["rays"] - cam.n_pixels > 20 * options["samples"]  # supersampled
        for points in groups:
            monkeypatch.setattr(sampling.supersample, "SAMPLE_POINTS", points)
            grouped = core.render(scene, cam, passes=(), workers=1, **options)
            monkeypatch.undo()
            assert grouped.summary["rays"] == one.summary["rays"]
            if points % options["samples"] == 0:
                np.testing.assert_array_equal(grouped.rgba, one.rgba)
            else:
                np.testing.assert_allclose(grouped.rgba, one.rgba, rtol=0, atol=1e-12)


def test_anti_aliasing_memory_does_not_grow_with_samples(monkeypatch):
    """The peak of numpy's memory (tracemalloc) rendering a frame at 1024 samples stays
    within 1.5x the peak at 64, with groups of 4096 points (all the sub-pixel points of a
    tile in one batch grow with the samples: 1.3 GiB at 128x96 and 1024 samples)."""
    import tracemalloc

    scene = _aa_scene()
    cam = core.Camera.perspective((0, -20, 2), (0, 0, 0), (0, 0, 1), 50, 24, 18)
    monkeypatch.setattr(sampling.supersample, "SAMPLE_POINTS", 4096)
    peaks, rays = {}, {}
    for samples in (64, 1024):
        tracemalloc.start()
        try:
            out = core.render(scene, cam, samples=samples, passes=(), workers=1)
            peaks[samples] = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        rays[samples] = out.summary["rays"]
    assert rays[1024] > 8 * rays[64]  # 16x the samples were traced
    assert peaks[1024] < 1.5 * peaks[64], peaks


def test_grazing_ground_hits_are_where_the_method_meets_the_ground():
    """The seed's Fig. 10 mirage, its ground seen from 0.4 m at a grazing 3.4 deg down
    (96x54, 16 deg wide), at 0.25 px against dopri5 at 1e-10 rad: surface hits are moved
    from the step's cubic to where the method's own partial step meets the ground
    (Tracer._surface_crossing). On the cubic (constant 1/384, far above the method's) 1460
    of 2673 traced ground pixels were 1e-3 px or more off and 246 of them estimated below
    a third of that; now every traced hit is within 1e-3 px, none under-reported, and no
    pixel exceeds the tolerance."""
    scene, _ = core.presets.mirage_view("fig10", 96, 54)
    cam = core.Camera.perspective((0, 0, 0.4), (1, 0, 0.34), (0, 0, 1), 16.0, 96, 54)
    run, truth, est = _against_dopri5(scene, cam, 0.25)
    traced = (run.passes["steps"] > 0) & (run.passes["ending"] == core.ENDING["hit"])
    assert traced.sum() > 2000 and np.all(np.isfinite(truth[traced]))
    assert np.count_nonzero(traced & (truth > 1e-3)) <= 0.01 * traced.sum()
    assert np.count_nonzero(traced & (truth > 1e-3) & (est < truth / 3)) == 0
    assert np.nanmax(truth[np.isfinite(truth)]) <= 0.25


def test_the_companion_run_keeps_its_own_steps_near_geometry():
    """Kerr a/M 0.99 with its disk seen from 25 rg at 0.05 px: near the disk both runs of
    the error pass halve their steps (Tracer._bent_steps); with one absolute limit the
    companion (twice the step) was halved to the main run's steps and hit the disk at the
    same point: a third of the traced disk pixels reported 0 while 3e-4 px off dopri5 at
    1e-10 rad. The limits scale with the run's step: the estimates are not 0. (How far
    they are from the truth is not asserted: 42 % of these pixels, 1e-4 to 1e-3 px off the
    reference, estimate ~1e-7 px: a floor that does not fall with the step, not found.)"""
    inc = math.radians(75.0)
    cam = core.Camera.perspective((0, -25 * math.sin(inc), 25 * math.cos(inc)), (0, 0, 0),
                                  (0, 0, 1), 40.0, 80, 45)  # fmt: skip
    disk = core.AccretionDisk(r_out=8.0, temperature=8000.0, brightness=0.7)
    scene = core.Scene(model=hm.kerr(rg=1.0, a=0.495, chart="kerr_schild"), disk=disk)
    run, truth, est = _against_dopri5(scene, cam, 0.05)
    on_disk = (run.passes["ending"] == core.ENDING["hit"]) & (run.passes["steps"] > 0)
    measured = on_disk & np.isfinite(truth) & (truth > 1e-4)
    assert measured.sum() > 500  # the runs are really off the reference there
    assert np.count_nonzero(est[on_disk] == 0) <= 0.02 * on_disk.sum()  # 625 of 1803 were


def test_a_pixels_neighbour_change_is_its_largest_step_to_its_four_neighbours():
    """core.sampling._neighbour_change (the colour test's first stage, COLOUR_STEP): a lone
    bright pixel and its four neighbours differ by its largest channel; diagonal
    neighbours do not; a ramp's change is its slope."""
    rgb = np.zeros((3, 4, 3))
    rgb[1, 2] = [0.5, 0.0, 0.2]
    expected = np.zeros((3, 4))
    expected[1, 2] = expected[0, 2] = expected[2, 2] = expected[1, 1] = expected[1, 3] = 0.5
    np.testing.assert_array_equal(sampling._neighbour_change(rgb), expected)
    ramp = np.broadcast_to(np.arange(5.0)[None, :, None] * 0.1, (2, 5, 3))
    np.testing.assert_allclose(sampling._neighbour_change(ramp), 0.1)


def _blackman_harris_pixels(fine: np.ndarray, factor: int, size: float) -> np.ndarray:
    """(h, w) Blackman-Harris-filtered pixels (width ``size`` px) of a render ``fine``
    (factor h, factor w) ``factor`` x finer: each pixel the window-weighted mean of the fine
    pixels' centres within its footprint (the dense reference of Final's filter)."""
    a0, a1, a2, a3 = sampling.BLACKMAN_HARRIS
    reach = int(np.ceil(size * factor / 2))
    k = np.arange(-reach, reach) + 0.5  # fine centres' offsets from a coarse centre
    t = k / (size * factor) + 0.5
    w1 = np.where((t >= 0) & (t <= 1), a0 - a1 * np.cos(2 * np.pi * t)
                  + a2 * np.cos(4 * np.pi * t) - a3 * np.cos(6 * np.pi * t), 0.0)  # fmt: skip
    kernel = np.outer(w1, w1) / np.sum(np.outer(w1, w1))
    h, w = fine.shape[0] // factor, fine.shape[1] // factor
    padded = np.pad(fine, reach)
    out = np.zeros((h, w))
    for j in range(h):
        for i in range(w):
            y, x = j * factor + factor // 2 + reach, i * factor + factor // 2 + reach
            out[j, i] = np.sum(kernel * padded[y - reach : y + reach, x - reach : x + reach])
    return out


def test_final_keeps_a_tiny_lensed_image_its_centre_hit():
    """Final (0.25 px, 16 samples, Blackman-Harris 1.5): a sphere 0.27 px across, lensed by
    a Schwarzschild hole, on the ray through a pixel's centre, keeps >= 50 % of its light
    against a dense render 16x finer filtered with the same window (issue 50: the centre's
    own hit was not among the averaged samples, and the samples, stratified over the
    filter's square, missed it: 0 of its light; Preview shows it whole)."""
    width, height, factor = 24, 16, 16
    cams = [core.Camera.perspective(position=(0, -30, 0), look_at=(0, 0, 0), up=(0, 0, 1),
                                    fov_deg=10, width=k * width, height=k * height)
            for k in (1, factor)]  # fmt: skip
    cam, fine = cams
    hole = {"model": hm.schwarzschild(rg=1.0), "center": (-16, 0, 0)}
    wall = core.Plane(point=(0, 40, 0), normal=(0, -1, 0), u_axis=(1, 0, 0), extent=(100, 100))
    seen = core.render(core.Scene(objects=[wall], **hole), cam, tolerance=1e-10,
                       passes=("position",))  # fmt: skip
    j, i = 7, 15
    radius = 0.135 * cam.pixel_angle() * 70.0  # 0.27 px across at 70 from the camera
    ball = core.Sphere(center=tuple(seen.passes["position"][j, i]), radius=radius,
                       color=(1, 1, 1, 1))  # fmt: skip
    scene = core.Scene(objects=[ball], background=(0, 0, 0), **hole)
    run = core.render(scene, cam, tolerance_px=0.25, samples=16, passes=())
    dense = core.render(scene, fine, tolerance_px=4.0, passes=())
    truth = _blackman_harris_pixels(dense.rgba[..., 0].astype(float), factor, 1.5)
    around = (slice(j - 2, j + 3), slice(i - 2, i + 3))
    light, expected = float(run.rgba[..., 0][around].sum()), float(truth[around].sum())
    assert expected > 0.05  # the image is there, and within the patch
    assert light >= 0.5 * expected, (light, expected)


def test_a_frame_too_small_to_interpolate_with_profit_is_traced_at_every_pixel():
    """The cost guard (core.sampling.ROUND_RAYS): refining a 48 x 32 frame would cost more
    rounds of tracing than the rays interpolation spares, so every pixel centre is traced
    (none has 0 steps) and is the dense render's pixel at the same step, to the last bit
    where it was not traced again (its error over the budget); with rounds free
    (rounds_free) the same frame interpolates a share of its pixels (17 %: its lattice's
    border and the shadow's edge take the rest)."""
    scene = core.Scene(model=hm.schwarzschild(rg=1.0), background="procedural")
    cam = _hole_camera(48, 32)
    passes = ("steps", "ending")
    run = core.render(scene, cam, tolerance_px=1.0, passes=passes, workers=1)
    dense = core.render(scene, cam, tolerance=TRACE_SHARE * cam.pixel_angle(), passes=passes)
    assert np.all(run.passes["steps"] > 0)
    np.testing.assert_array_equal(run.passes["ending"], dense.passes["ending"])
    same = run.passes["steps"] == dense.passes["steps"]  # not traced again
    assert same.mean() > 0.95
    np.testing.assert_array_equal(run.rgba[same], dense.rgba[same])
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(sampling.quadtree, "ROUND_RAYS", 0)
        refined = core.render(scene, cam, tolerance_px=1.0, passes=passes, workers=1)
    assert np.mean(refined.passes["steps"] == 0) > 0.1


def test_a_tile_where_refining_cannot_pay_is_traced_as_interpolate_false_traces_it():
    """The tile cost guard (core.sampling.quadtree.refining_pays): refining a tile adds
    REFINE_ROUNDS - DENSE_ROUNDS rounds of ROUND_RAYS each and spares at best 1 -
    REFINED_SHARE of its pixels' rays, so a tile under 12 000 pixels is traced at every
    pixel from the start: the Kerr board at 160 x 90 on two workers (two tiles of 7200
    pixels) is the every-pixel render's (interpolate=False) image, passes and ray counts to
    the last bit. A tile of 28 800 pixels (320 x 180 in two) is still refined."""
    from core.sampling import quadtree

    assert not quadtree.refining_pays(12_000)  # the figure docs/architecture.md gives
    assert quadtree.refining_pays(12_001)
    scene, cam = _kerr_board(), _hole_camera(160, 90)
    passes = ("steps", "ending", "error_px", "direction")
    kw = {"tolerance_px": 1.0, "passes": passes, "workers": 2}
    run, every = core.render(scene, cam, **kw), core.render(scene, cam, interpolate=False, **kw)
    np.testing.assert_array_equal(run.rgba, every.rgba)
    for name in passes:
        np.testing.assert_array_equal(run.passes[name], every.passes[name])
    for key in ("rays", "error_rays", "companion_rays", "steps"):
        assert run.summary[key] == every.summary[key], key
    assert np.all(run.passes["steps"] > 0)  # every pixel centre traced
    large = core.render(scene, _hole_camera(320, 180), tolerance_px=1.0, passes=(), workers=1)
    assert large.summary["rays"] < 0.8 * large.summary["pixels"]  # refined: interpolated

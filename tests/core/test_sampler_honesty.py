"""The adaptive image against dense references on scenes unlike the Kerr board: what the
error pass and the sampler promise (core/sampling.py) holds where the board did not show
it fails. Each reference traces every pixel centre with dopri5 at a tight tolerance."""

import functools
import importlib.util
import math
import pathlib
import sys

import numpy as np
import pytest

import core
from core import hamiltonians as hm
from core.presets import mirage_view
from core.sky import procedural_sky
from core.tolerances import TRACE_SHARE
from tests.core.test_sampling import true_error_px

REFERENCE = dict(method="dopri5", tolerance=1e-10, max_steps=10**6)
PASSES = ("ending", "direction", "position", "error_px")


def _camera(position, look_at, width, height, fov_deg):
    return core.Camera.perspective(position=position, look_at=look_at, up=(0, 0, 1),
                                   fov_deg=fov_deg, width=width, height=height)  # fmt: skip


@pytest.mark.usefixtures("tiles_refined")
def test_small_objects_far_behind_a_hole_are_not_lost():
    """Six spheres of 4 rg, 400 rg behind a Schwarzschild hole seen from 30 rg: their lensed
    arcs span a few pixels. At Preview (1 px) every pixel the dense render sees them in is
    theirs too (long splitting steps passed them between their ends, and one box around
    all of them stood for each: 23 of 210 pixels were sky, estimated 0.05-0.3 px)."""
    spots = [(20, 10), (-25, -5), (5, -22), (-10, 18), (30, -15), (0, 0)]
    objects = [core.Sphere(center=(x, 400, z), radius=4, color=(1, 0.2, 0.1, 1))
               for x, z in spots]  # fmt: skip
    scene = core.Scene(model=hm.schwarzschild(rg=1.0), objects=objects, background="procedural")
    cam = _camera((0, -30, 2), (0, 0, 0), 160, 90, 40)
    ref = core.render(scene, cam, passes=PASSES, **REFERENCE)
    run = core.render(scene, cam, tolerance_px=1.0, passes=PASSES)
    hit = ref.passes["ending"] == core.ENDING["hit"]
    assert hit.sum() > 150
    assert np.all(run.passes["ending"][hit] == core.ENDING["hit"])
    assert run.summary["rays"] < run.summary["pixels"]  # still interpolated elsewhere


def test_grazing_ground_hits_are_within_the_tolerance():
    """The mirage's hot ground at grazing angles (the seed's Fig. 10 scene seen from 0.4 m,
    3.4 deg down) with a 0.1 m checker: at 1 px, pixels whose hit point is more than a pixel
    footprint from the dense render's <= 0.5 %, none beyond 3 px (the block test measured
    the direction to the hit, 0.014 px, where the renderer interpolates the hit point: 3 px
    off in one 32 px block). The error pass still under-estimates these traced hits ~6x
    (their error does not fall at the method's order between the step and twice it:
    1.8x measured, then 20x below it), so no bound on it here."""
    scene, _ = mirage_view("fig10", 96, 54)
    ground = scene.objects[-1]
    cells = int(ground.extent[0] / 0.1)
    checker = core.checker(cells, cells, (0.35, 0.3, 0.25, 1), (0.15, 0.12, 0.1, 1))
    objects = [
        *scene.objects[:-1],
        core.Plane(
            ground.point, ground.normal, checker, u_axis=ground.u_axis, extent=ground.extent
        ),
    ]
    scene = core.Scene(model=scene.model, objects=objects, background=scene.background)
    cam = _camera((0, 0, 0.4), (1, 0, 0.34), 96, 54, 16)
    ref = core.render(scene, cam, passes=PASSES, **REFERENCE)
    run = core.render(scene, cam, tolerance_px=1.0, passes=PASSES)
    truth = true_error_px(ref, run, cam.frame.position)
    seen = ~np.isnan(truth)
    assert np.count_nonzero(ref.passes["ending"] == core.ENDING["hit"]) > 1000
    assert np.count_nonzero(seen & (truth > 1.0)) <= 0.005 * truth.size
    assert np.count_nonzero(seen & (truth > 3.0)) == 0


def test_a_ray_whose_path_dips_onto_hot_ground_between_its_steps_is_not_lost():
    """The mirage (the seed's Fig. 10 scene) seen from 0.4 m, 3.4 deg down, 160 x 90 at
    1 px: rays of row 53 graze the hot ground 7.7 m away and turn up. The true path dips
    below z = 0 between two steps while the hit test's cubic and chords pass above it, so
    18 of them showed sky with an error of 2e-5 px. A ray's clearance is now measured on
    its cubic path less the slack of the chords the hit test casts, so these report a
    near miss and are traced again at half the step while they stay near: the row matches
    the dense render (its three rows rendered alone: the reference of a region)."""
    scene, _ = mirage_view("fig10", 160, 90)
    cam = _camera((0, 0, 0.4), (1, 0, 0.34), 160, 90, 16)
    rows = cam.resized(160, 90, region=(0, 160, 35, 38))  # rows 52-54 from the top
    ref = core.render(scene, rows, passes=PASSES, **REFERENCE)
    run = core.render(scene, cam, tolerance_px=1.0, passes=PASSES)
    ending = run.passes["ending"][52:55]
    assert np.count_nonzero(ref.passes["ending"] == core.ENDING["hit"]) > 200
    assert np.count_nonzero(ref.passes["ending"] == core.ENDING["escaped"]) > 100
    assert np.array_equal(ending, ref.passes["ending"])


def _plummer_lens() -> core.hamiltonians.Hamiltonian:
    """A user metric without a mass (benchmarks/honesty.py's plummer_lens): the
    exponential metric of a Plummer potential, m = 0.5, b = 1."""
    space = "exp(2*phi)"
    inverse = [["-exp(-2*phi)", "0", "0", "0"], ["0", space, "0", "0"],
               ["0", "0", space, "0"], ["0", "0", "0", space]]  # fmt: skip
    return hm.metric(inverse=inverse, parameters={"m": 0.5, "b": 1.0},
                     definitions=[("phi", "-m/sqrt(x**2 + y**2 + z**2 + b**2)")])  # fmt: skip


def test_rays_of_a_massless_user_metric_leave_its_region_on_its_sphere():
    """A massless user metric has no far field: a ray leaving at its step's end took in
    the field up to there, which its step decided, so its direction's error was erratic in
    the step (0.0015, 0.0004, 0.0002 px at h, h/2, h/4) and the error pass (Richardson at
    order 4) under-read it 3x on 1.4 % of benchmarks/honesty.py user_metric's pixels at 1 px.
    Rays now leave where the method crosses the region's sphere: the error falls at the
    method's order, and the estimate is not below a third of it."""
    from core.render import _scene_extent
    from core.sampling import richardson_error
    from core.trace import TraceOptions, Tracer

    board = core.Plane((0, 15, 0), (0, -1, 0), core.checker(12, 12), u_axis=(1, 0, 0),
                       extent=(24, 24))  # fmt: skip
    ball = core.Sphere((1.5, 6, 0.8), 0.8, (0.3, 0.5, 1.0, 1))
    scene = core.Scene(model=_plummer_lens(), objects=[board, ball])
    cam = _camera((0, -25, 1), (0, 0, 0), 160, 90, 40)
    extent = _scene_extent(scene, cam)
    xy = np.array([[70.5, 30.5], [80.5, 35.5], [90.5, 40.5]])  # past the board's edge
    origins, directions = cam.rays_at(xy)
    exact = Tracer(scene, TraceOptions(**REFERENCE), extent).trace(origins, directions)
    tracer = Tracer(scene, TraceOptions(tolerance=0.5 * cam.pixel_angle()), extent)
    runs = [tracer.trace(origins, directions, step=s * tracer.step) for s in (2.0, 1.0)]
    assert all(np.all(r.ending == core.ENDING["escaped"]) for r in runs)
    errors = [_angle(r.direction, exact.direction) for r in runs]
    assert np.all(errors[0] / errors[1] > 8.0)  # order 4: 16 (measured 15-58; before, 5-69)
    estimate = richardson_error(runs[1], runs[0], origins, 4)
    assert np.all(estimate > errors[1] / 3)  # not under-read (over: up to 18x, measured)


def _angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(N,) angles between the rows of a and b."""
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=1), np.sum(a * b, axis=1))


def test_an_ending_flip_is_reported_large():
    """Kerr a/M = 0.9, a board and a sphere at a loose 2 px: a pixel whose ray ends on
    something else than the dense render's (sky for an object, one object for another: hit
    points metres apart) reports an error of at least a pixel. One ray grazing the sphere
    flipped between runs at two steps, then its last two runs agreed: it reported 0.01 px;
    another, hitting the board, passed the sphere within its error: 0.008 px. Near misses
    are now traced again at half the step, which ends those at 2 and 1 px as the dense
    render does, and a hit the method's own path does not confirm is undone, which ended
    the last one at 4 px: the default method flips nowhere at 4, 2 or 1 px (measured).
    Leapfrog (order 2) at 2 px still flips 3 pixels (measured), each reported."""
    board = core.Plane(point=(0, 12, 0), normal=(0, -1, 0), u_axis=(1, 0, 0), extent=(16, 16),
                       color=core.checker(8, 8))  # fmt: skip
    sphere = core.Sphere(center=(6, 6, 1), radius=1.5, color=(1, 0, 0, 1))
    scene = core.Scene(model=hm.kerr(rg=1.0, a=0.45, chart="kerr_schild"),
                       objects=[board, sphere], background="procedural")  # fmt: skip
    cam = _camera((0, -30, 2), (0, 0, 0), 96, 54, 40)
    ref = core.render(scene, cam, passes=PASSES, **REFERENCE)
    flips = 0
    for tolerance, method in ((4.0, None), (2.0, None), (1.0, None), (2.0, "leapfrog")):
        run = core.render(scene, cam, tolerance_px=tolerance, passes=PASSES, method=method)
        ending = ref.passes["ending"]
        apart = np.linalg.norm(ref.passes["position"] - run.passes["position"], axis=-1) > 0.5
        flipped = (ending != run.passes["ending"]) | ((ending == core.ENDING["hit"]) & apart)
        assert np.all(run.passes["error_px"][flipped] >= 1.0), run.passes["error_px"][flipped]
        flips += np.count_nonzero(flipped)
        flagged = run.passes["error_px"] >= 100.0  # flips (pi radians), not just loose pixels
        if method is None:  # leapfrog flags 25 % (true errors: median 0.025 px), as before
            assert np.count_nonzero(flagged) <= 0.02 * flagged.size  # not every pixel
    assert flips >= 1  # the scene does flip some


@functools.cache
def _high_spin_disk() -> tuple:
    """(scene, camera, dense reference) of benchmarks/honesty.py's disk_high_spin: Kerr
    a/M = 0.99 with a thin disk seen at 70 deg from 25 rg, 160 x 90."""
    inc = math.radians(70.0)
    cam = _camera((0, -25 * math.sin(inc), 25 * math.cos(inc)), (0, 0, 0), 160, 90, 40.0)
    disk = core.AccretionDisk(r_out=8.0, temperature=8000.0, brightness=0.7)
    scene = core.Scene(model=hm.kerr(rg=1.0, a=0.495, chart="kerr_schild"), disk=disk)
    return scene, cam, core.render(scene, cam, passes=PASSES, **REFERENCE)


def test_a_hit_near_its_objects_edge_reports_a_possible_flip():
    """The high-spin disk (_high_spin_disk): a traced ray that hits the disk within twice
    its error of the disk's edge (its inner or outer rim, or past the disk seen edge-on) may
    have missed it; every pixel whose ray ends elsewhere than the dense render's reports at
    least a pixel, at 1 and 0.25 px (before: 2 of the 4 at 1 px reported 0.015 px;
    core.sampling.judging.near_edge moves each hit across and along its surface by the error and
    casts again). Since a disk hit the method's own crossing does not confirm is undone
    (Tracer._land_on_disk: the cubic's hit lay within its slack of the rim), no pixel ends
    elsewhere at 1 or 0.25 px (before: 3 and 1, reported; measured); the rims' rays that
    may still flip are flagged (measured 28 and 24 pixels)."""
    scene, cam, ref = _high_spin_disk()
    for tolerance in (1.0, 0.25):
        run = core.render(scene, cam, tolerance_px=tolerance, passes=PASSES)
        flipped = ref.passes["ending"] != run.passes["ending"]
        assert np.all(run.passes["error_px"][flipped] >= 1.0), run.passes["error_px"][flipped]
        flagged = run.passes["error_px"] >= 100.0  # possible flips (pi radians)
        assert 10 <= np.count_nonzero(flagged) <= 0.02 * flagged.size  # the rims, not all


@pytest.mark.usefixtures("tiles_refined")
def test_runs_that_shared_their_steps_are_traced_again():
    """The high-spin disk at 0.25 px: rays that hit the disk's near side take a handful of
    steps, halved near it to the same sizes in the run at twice the step, so the two runs
    agree to 1e-8 rg while both are 1.2e-4 rg off (Richardson read 1e-11 rad). Such rays
    (the companion taking >= 3/4 of the steps, agreeing within 1e-5 of the budget) are traced
    again at half the step: under-reported 3x on at most 1 % of the pixels (before: 3.5 %;
    measured 0.01 %), the true error above a tenth of the tolerance estimated within 3x on
    >= 85 % (measured 91 %; 100 % of 714 since a disk block's deviations count the move on
    the disk, acceptance.radius_deviations: fewer of its pixels are interpolated and far
    off, 714 above a tenth of the tolerance where 1877 were, hence > 500 now, not 1000)."""
    scene, cam, ref = _high_spin_disk()
    run = core.render(scene, cam, tolerance_px=0.25, passes=PASSES)
    truth = true_error_px(ref, run, cam.frame.position)
    est = run.passes["error_px"]
    finite = np.isfinite(truth)
    under = finite & (truth > 1e-3) & (est < truth / 3)
    assert np.count_nonzero(under) <= 0.01 * truth.size
    big = finite & (truth > 0.025)
    within = big & (est >= truth / 3) & (est <= 3 * truth)
    assert big.sum() > 500 and within.sum() >= 0.85 * big.sum()


def _disk_view(opacity: float = 1.0, inclination: float = 80.0):
    """A Kerr a/M 0.9 hole with a disk to 12 horizon radii, seen ``inclination`` from its
    axis (80 deg: 10 deg above its plane across ~70 % of a 128 x 72 frame, the disk
    preset's framing), on a black sky."""
    spin, size = 0.9, 1.0
    rg = 2 * size / (1 + math.sqrt(1 - spin**2))
    inc, distance = math.radians(inclination), 48.6
    camera = core.Camera.perspective(
        position=(0.0, -distance * math.sin(inc), distance * math.cos(inc)),
        look_at=(0, 0, 0), up=(0, 0, 1), fov_deg=39.6, width=128, height=72,
    )  # fmt: skip
    disk = core.AccretionDisk(r_out=12.0, temperature=6000.0, opacity=opacity)
    model = hm.kerr(rg=rg, a=spin * rg / 2, chart="kerr_schild")
    return core.Scene(model=model, background=(0.0, 0.0, 0.0, 1.0), disk=disk), camera


@pytest.mark.usefixtures("tiles_refined")
def test_an_opaque_disk_is_interpolated_within_the_tolerance():
    """Blocks on an opaque disk interpolate its radius and g (tested like directions, as
    the angle the block's gradient needs): colours as the dense render's, g within what
    a pixel's offset makes, and fewer rays than the same disk traced pixel by pixel. Seen
    30 deg above its plane: at the preset's 10 deg a block's move on the disk,
    foreshortened ~6x on screen, exceeds the 1 px tolerance almost everywhere at this size
    (80 rays saved), since the deviations count it (acceptance.radius_deviations)."""
    scene, camera = _disk_view(inclination=60.0)
    passes = ("redshift", "ending")
    dense = core.render(scene, camera, tolerance=1e-7, passes=passes)  # every centre traced
    run = core.render(scene, camera, tolerance_px=1.0, samples=1, passes=passes)
    off = np.abs(run.rgba[..., :3] - dense.rgba[..., :3]).max(axis=-1) > 0.1
    assert off.mean() <= 0.002  # issue 23's target: colour off by > 0.1 on <= 0.2 %
    g, g_dense = run.passes["redshift"], dense.passes["redshift"]
    both = np.isfinite(g) & np.isfinite(g_dense)
    assert both.sum() > 0.15 * g.size  # the disk fills a good part of the frame
    # g changes by ~1 % a pixel across the disk here: within the 1 px tolerance
    assert np.percentile(np.abs(g[both] / g_dense[both] - 1), 99) < 0.03
    scene_traced, _ = _disk_view(opacity=0.999, inclination=60.0)  # translucent: traced
    traced = core.render(scene_traced, camera, tolerance_px=1.0, samples=1, passes=passes)
    # measured: 2187 rays fewer with the opaque disk's blocks interpolated, of 4043 disk
    # pixels (its 4 px blocks at this size; at 1080p its larger ones too)
    assert traced.summary["rays"] - run.summary["rays"] > 0.1 * both.sum()


@functools.cache
def _honesty():
    """benchmarks/honesty.py (its scenes' own builders and image counts)."""
    benchmarks = pathlib.Path(__file__).resolve().parents[2] / "benchmarks"
    sys.path.insert(0, str(benchmarks))  # honesty.py imports its sibling modules
    spec = importlib.util.spec_from_file_location("honesty", benchmarks / "honesty.py")
    assert spec is not None and spec.loader is not None
    honesty = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(honesty)
    return honesty


def _thin_front() -> tuple:
    """(scene, camera) of benchmarks/honesty.py's thin_front, 160 x 90: Schwarzschild from
    30 rg with strips 0.06-0.1 rg wide, an edge-on disk and small spheres near the hole."""
    return _honesty().thin_front(160, 90)


def _pixel_rays(scene, cam, pixels, step_share: float = 1.0):
    """(rays at step_share x the rule's step of a 1 px render, the dense reference's) of
    the pixel centres ``pixels`` [(row, column)]."""
    from core.render import TRACE_SHARE, _scene_extent
    from core.trace import TraceOptions, Tracer

    xy = np.array([[i + 0.5, j + 0.5] for j, i in pixels])
    origins, directions = cam.rays_at(xy)
    extent = _scene_extent(scene, cam)
    tracer = Tracer(scene, TraceOptions(tolerance=TRACE_SHARE * cam.pixel_angle()), extent)
    rays = tracer.trace(origins, directions, step=step_share * tracer.step)
    exact = Tracer(scene, TraceOptions(**REFERENCE), extent).trace(origins, directions)
    return rays, exact


def test_a_hit_the_methods_own_path_does_not_confirm_is_undone():
    """Hits are found on chords of a step's cubic, then moved to where the method's own
    path meets the surface; where that path passes beside the object, the cubic's hit
    stood (a strip 0.07 rg wide hit 0.002 rg inside its edge while the path passes 0.001
    outside; an edge-on disk's rim grazed within 1e-4 rg; the high-spin disk hit at r 8.01,
    past its rim at 8): quiet flips (0.00003-0.0003 px) or flagged ones, in
    benchmarks/honesty.py thin_front and disk_high_spin at 1 px. Such a hit is undone and
    the ray goes on: each of these rays escapes at the rule's step, as the dense render's."""
    for (scene, cam), pixels in (
        (_thin_front(), [(52, 117), (60, 54)]),
        (_high_spin_disk()[:2], [(18, 37), (31, 17)]),
    ):
        rays, exact = _pixel_rays(scene, cam, pixels)
        assert np.all(exact.ending == core.ENDING["escaped"])
        assert np.array_equal(rays.ending, exact.ending), rays.ending


def test_a_retraced_near_miss_has_its_hit_tests_slack_fall_with_its_step():
    """A near miss is traced again at half the step, up to three times; the chords of its
    hit test kept the rule's allowance whatever the step, so rays passing within that of a
    thin strip's edge stayed near, and wrong, at 1/8 of the step (thin_front at 1 px: two
    pixels that hit a strip in the dense render showed sky, reported as flips). A run below
    the rule's step has the allowance scaled as its error, (h / h_rule)^order: at 1/8 of
    the step both rays hit the strip, as the dense render's."""
    scene, cam = _thin_front()
    rays, exact = _pixel_rays(scene, cam, [(27, 142), (54, 114)], step_share=0.125)
    assert np.all(exact.ending == core.ENDING["hit"])
    assert np.array_equal(rays.ending, exact.ending), rays.ending
    assert np.array_equal(rays.object_id, exact.object_id)


def test_a_run_at_the_rules_largest_step_reports_at_least_its_bound():
    """benchmarks/honesty.py's schwarzschild (a board 20 rg behind the hole, seen from 17 rg
    off axis): the step rule's step is its cap (1.0) at every tolerance, and the error
    pass's companion at twice it runs outside the range its constant was measured on:
    errors at 2 h were 0.3-4x those at h (at h / 2, 1/16 of them), and Richardson read
    0.03-0.3 of the truth on 2.6-2.8 % of the pixels (true errors ~1e-3 px). Such a run
    reports at least the rule's bound C h^order: under a third of the truth on at most
    0.25 % of the pixels at 128 x 72 (measured 0.01 %; before, 1.27 %)."""
    cam = _camera((8, -14, 5), (0, 0, 0), 128, 72, 60)
    board = core.Plane((0, 20, 0), (0, -1, 0), core.checker(24, 16), u_axis=(1, 0, 0),
                       extent=(60, 40))  # fmt: skip
    scene = core.Scene(model=hm.schwarzschild(rg=1.0), objects=[board])
    ref = core.render(scene, cam, passes=PASSES, **REFERENCE)
    run = core.render(scene, cam, tolerance_px=1.0, passes=PASSES)
    truth = true_error_px(ref, run, cam.frame.position)
    est = run.passes["error_px"]
    measurable = np.isfinite(truth) & (truth > 1e-3)
    under = measurable & (est < truth / 3)
    assert measurable.sum() > 1000
    assert np.count_nonzero(under) <= 0.0025 * truth.size, np.count_nonzero(under)


def test_a_ray_whose_companion_ran_past_the_rules_range_is_traced_again():
    """The high-spin disk (_high_spin_disk) at 0.05 px: the step is the rule's cap (0.7),
    and the companion at twice it is outside the range the rule's constant was measured
    on; the escaped rays' errors at 2 h were 40-50x those at h, read by Richardson as 3x
    the truth: 87 % of the pixels with a true error above a tenth of the tolerance were
    estimated within 3x. Rays whose estimate exceeds 0.3 of the budget (LOOSE_SHARE) are
    traced again at half the step, their first run the companion: >= 90 % (measured 100 %
    of 960)."""
    scene, cam, ref = _high_spin_disk()
    run = core.render(scene, cam, tolerance_px=0.05, passes=PASSES)
    truth = true_error_px(ref, run, cam.frame.position)
    est = run.passes["error_px"]
    big = np.isfinite(truth) & (truth > 0.005)
    within = big & (est >= truth / 3) & (est <= 3 * truth)
    assert big.sum() > 100 and within.sum() >= 0.9 * big.sum(), (within.sum(), big.sum())


@pytest.mark.usefixtures("tiles_refined")
def test_an_interpolated_pixels_estimate_adds_its_deviations_as_vectors():
    """benchmarks/honesty.py's stars (the procedural stars behind Schwarzschild seen from
    20 rg, 50 deg): a block's bilinear error is its edges' midpoint deviations weighted by
    where the pixel lies, plus the centre's excess; added as lengths, a lens map's x and y
    curvatures (opposite where its deflection is harmonic) made the estimate 3-3.9x the
    truth on interpolated pixels (88 % within 3x at 1 px, 91.7 % at 0.25). Added as vectors
    (acceptance.deviation_vectors): >= 95 % of the pixels with a true error above a tenth of the
    tolerance are estimated within 3x (measured 100 %), and under a third of the truth on
    at most 1 % of all pixels (measured 0)."""
    cam = _camera((0, -20, 1), (0, 0, 0), 160, 90, 50)

    def stars(directions):
        return procedural_sky(directions, galaxy=False, star_size=2.5)

    scene = core.Scene(model=hm.schwarzschild(rg=1.0), background=stars)
    ref = core.render(scene, cam, passes=PASSES, **REFERENCE)
    for tolerance in (1.0, 0.25):
        run = core.render(scene, cam, tolerance_px=tolerance, passes=PASSES)
        truth = true_error_px(ref, run, cam.frame.position)
        est = run.passes["error_px"]
        finite = np.isfinite(truth)
        big = finite & (truth > tolerance / 10)
        within = big & (est >= truth / 3) & (est <= 3 * truth)
        assert big.sum() > 500 and within.sum() >= 0.95 * big.sum(), (within.sum(), big.sum())
        under = finite & (truth > 1e-3) & (est < truth / 3)
        assert np.count_nonzero(under) <= 0.01 * truth.size


def test_steps_are_near_geometry_by_each_objects_own_box():
    """thin_front (_thin_front): its strips, rod and spheres lie around the hole, so the
    box around them all held the photon ring; rays winding there, far from every object,
    had their steps halved as near geometry (where their chords turn), to the same sizes
    in the error pass's companion: errors 0.12-0.33 px, read by Richardson as 0.003-0.007
    (thin_front at 1 px: 47 % of the pixels above a tenth of the tolerance within 3x). A
    step is near geometry where it may pass one object's own box: the estimate is at
    least a third of the truth on these rays."""
    from core.sampling import richardson_error

    scene, cam = _thin_front()
    pixels = [(26, 74), (30, 67), (40, 61), (50, 98)]
    rays, exact = _pixel_rays(scene, cam, pixels)
    companion, _ = _pixel_rays(scene, cam, pixels, step_share=2.0)
    origins, _ = cam.rays_at(np.array([[i + 0.5, j + 0.5] for j, i in pixels]))
    assert np.all(rays.ending == core.ENDING["escaped"])
    truth = _angle(rays.direction, exact.direction)
    estimate = richardson_error(rays, companion, origins, 4)
    assert np.all(estimate >= truth / 3), (estimate / cam.pixel_angle(), truth / cam.pixel_angle())


def test_an_interpolated_disk_pixels_hit_point_is_within_the_tolerance():
    """The Kerr board with a disk to 10 rg (benchmarks/frame.py --disk) at 160 x 90, 1 px:
    a block on the opaque disk was interpolated where its radius r and redshift g were
    bilinear enough, and its pixels' hit point (the position and direction passes) put at
    the interpolated r along the blended hit points' direction, which a lensed block's
    azimuth does not follow: 98 pixels over the tolerance, 13 over 3x, under-read 3x on
    1.9 %. The azimuth is tested as r and g are and the point placed at the interpolated
    (r, azimuth): 10 over the tolerance, none over 3x, 0.47 % under-read (measured). The
    disk, seen from 2 rg above its plane, moves a hit point far for a small move on
    screen: r's and the azimuth's deviations count that move too (over the distance from
    the camera, as a hit's error is measured): none over the tolerance, none under-read
    (interpolated disk pixels estimated at 1.0x their error, median; 0.47x before, when
    65 pixels, 0.45 %, were under-read: at most 0.1 % now, measured 0)."""
    board = core.Plane(point=(0, 12, 0), normal=(0, -1, 0), u_axis=(1, 0, 0), extent=(16, 16),
                       color=core.checker(8, 8))  # fmt: skip
    scene = core.Scene(model=hm.kerr(rg=1.0, a=0.45, chart="kerr_schild"), objects=[board],
                       disk=core.AccretionDisk(r_out=10.0))  # fmt: skip
    cam = _camera((0, -30, 2), (0, 0, 0), 160, 90, 40)
    ref = core.render(scene, cam, passes=PASSES, **REFERENCE)
    run = core.render(scene, cam, tolerance_px=1.0, passes=PASSES)
    truth = true_error_px(ref, run, cam.frame.position)
    est = run.passes["error_px"]
    finite = np.isfinite(truth)
    assert np.count_nonzero(finite & (truth > 1.0)) <= 0.005 * truth.size
    assert not np.any(finite & (truth > 3.0))
    under = finite & (truth > 1e-3) & (est < truth / 3)
    assert np.count_nonzero(under) <= 0.001 * truth.size


@pytest.mark.usefixtures("tiles_refined")
def test_an_interpolated_centre_whose_colour_its_error_could_change_is_traced():
    """benchmarks/honesty.py's near_tangent (a 15 x 15 checker seen from 5 rg of a Kerr
    hole, looking along the orbit) and schwarzschild (a 24 x 16 checker), 160 x 90 at 1 px:
    interpolated checker edges moved by ~0.2 px, within the tolerance, changed the colour of
    1.5 % and 0.3 % of the pixels by more than 0.1. A centre whose colour could change by
    more than COLOUR_STEP over its error is traced (shaky.shaky): <= 0.2 % now (measured 0.01 %
    and 0.06 %), while most pixels are still interpolated. The references at 1e-8 rad (1e-5
    px; half the time of 1e-10): a colour changes here where a point moves ~0.1 px."""
    for name in ("near_tangent", "schwarzschild"):
        scene, cam = getattr(_honesty(), name)(160, 90)
        ref = core.render(scene, cam, passes=PASSES, **{**REFERENCE, "tolerance": 1e-8})
        run = core.render(scene, cam, tolerance_px=1.0, passes=PASSES)
        off = np.max(np.abs(run.rgba - ref.rgba), axis=-1) > 0.1
        assert np.count_nonzero(off) <= 0.002 * off.size, (name, np.count_nonzero(off))
        assert run.summary["rays"] < 0.7 * run.summary["pixels"]


def test_a_sub_pixel_star_moved_by_less_than_the_tolerance_is_not_lost():
    """benchmarks/honesty.py's stars (the procedural stars at 2.5x their size, about a
    third of a pixel, behind Schwarzschild), 160 x 90 at 1 px: 3 of the 561 star images
    the dense render shows at a pixel centre were lost, their interpolated directions
    moved off them by less than the tolerance, with no neighbour showing them. Where the
    sky's detail is finer than a pixel (Background.detail: a callable's is unknown) the sky
    is looked up moved by the error (shaky.shaky_sky): none lost."""
    honesty = _honesty()
    scene, cam = honesty.stars(160, 90)
    ref = core.render(scene, cam, passes=PASSES, **REFERENCE)
    run = core.render(scene, cam, tolerance_px=1.0, passes=PASSES)
    level = honesty.BRIGHT["stars"]
    count, lost = honesty.lost_images(
        honesty._luminance(ref.rgba) > level, honesty._luminance(run.rgba) > level / 2
    )
    assert count > 500 and lost == 0, (count, lost)


def test_hits_far_behind_a_hole_at_long_steps_are_within_the_tolerance():
    """benchmarks/honesty.py's far_small at 0.05 px: spheres 400 rg behind Schwarzschild,
    reached in steps at the rule's cap (1.0) that each span a stretch of r. Against dopri5
    at 1e-10 rad, no pixel is off by more than 3x the tolerance and none above a tenth of
    it is estimated below a third of its error. A step near geometry whose pace (speed in
    the fictitious time, ~ r) changes more than PACE_LIMIT (2x) over it is halved; at 3x,
    4 hit pixels were 0.3-0.5 px off, estimated 0.002 px: the runs at h and 2 h (steps
    spanning r 2-3x) missed the hit point alike, and Richardson saw nothing."""
    scene, cam = _honesty().far_small(160, 90)
    ref = core.render(scene, cam, passes=PASSES, **REFERENCE)
    run = core.render(scene, cam, tolerance_px=0.05, passes=PASSES)
    truth = true_error_px(ref, run, cam.frame.position)
    est = run.passes["error_px"]
    hit = (run.passes["ending"] == core.ENDING["hit"]) & np.isfinite(truth)
    assert hit.sum() > 100
    assert np.nanmax(truth[np.isfinite(truth)]) <= 3 * 0.05
    assert not np.any(hit & (truth > 0.005) & (est < truth / 3))


def test_a_trace_records_clearance_only_for_the_rays_it_is_asked_to():
    """The error pass's companion run records no clearance (the sampler never reads it:
    Tracer.trace(clearance=mask)): rays left out keep an infinite clearance inside the
    region, the others the same as in a trace that records every ray's, and every ray's
    ending and hit point are those of the full trace."""
    from core.render import TRACE_SHARE, _scene_extent
    from core.trace import TraceOptions, Tracer

    scene, cam = _thin_front()
    jj, ii = np.mgrid[20:70:5, 30:130:5]
    xy = np.stack([ii.ravel() + 0.5, jj.ravel() + 0.5], axis=1)
    origins, directions = cam.rays_at(xy)
    tracer = Tracer(
        scene, TraceOptions(tolerance=TRACE_SHARE * cam.pixel_angle()), _scene_extent(scene, cam)
    )
    tracer.watch_geometry(0.3)
    full = tracer.trace(origins, directions)
    mask = np.arange(xy.shape[0]) % 2 == 0
    part = tracer.trace(origins, directions, clearance=mask)
    assert np.isfinite(full.clearance[~mask]).sum() > 20  # the left-out rays passed objects
    assert np.all(np.isinf(part.clearance[~mask]))
    np.testing.assert_array_equal(part.clearance[mask], full.clearance[mask])
    np.testing.assert_array_equal(part.ending, full.ending)
    np.testing.assert_array_equal(part.position, full.position)


def test_spared_companions_leave_no_pixel_near_geometry_under_reported():
    """The error pass runs its companions at the anchors (core.sampling.ANCHOR) and where
    a node's anchors disagree, it or they near geometry, or it ends unlike them; the other
    nodes take their anchors' largest error (core.sampling.anchors.settle). On thin_front (thin
    strips, a rod, an edge-on disk and small spheres before a hole) at 1 px against
    dopri5: companions are spared (fewer than 0.8 a ray), and of the pixels within 2 of an
    ending or object change in the reference whose true error is measurable (> 1e-3 px;
    919 of them, measured), none is estimated below a third of it, and every pixel that
    ends apart from the reference reports a flip (>= 1 px)."""
    scene, cam = _honesty().thin_front(96, 54)
    run = core.render(scene, cam, tolerance_px=1.0, passes=PASSES)
    assert run.summary["companion_rays"] < 0.8 * run.summary["rays"]
    _edges_estimated_within_3x(scene, cam, run, at_least=500)


def _edges_estimated_within_3x(scene, cam, run, at_least: int) -> None:
    """Against dopri5: of the pixels within 2 of an ending or object change in the
    reference whose true error is measurable (> 1e-3 px; more than ``at_least``), none
    is estimated below a third of it; every pixel that ends apart reports a flip."""
    from scipy import ndimage

    ref = core.render(scene, cam, passes=PASSES[:3], **REFERENCE)
    truth = true_error_px(ref, run, cam.frame.position)
    est = run.passes["error_px"].astype(float)
    ending = ref.passes["ending"]
    edge = ndimage.maximum_filter(ending, 5) != ndimage.minimum_filter(ending, 5)
    near = np.isfinite(truth) & edge & (truth > 1e-3)
    assert near.sum() > at_least
    assert np.count_nonzero(est[near] < truth[near] / 3) == 0
    assert np.all(est[np.isinf(truth)] >= 1.0)


def test_every_pixel_traced_keeps_the_promise_a_plain_dense_render_breaks():
    """core.render(interpolate=False): every pixel centre traced, with tolerance_px's promise
    (clearance watched, near misses and rays over budget traced again). Rows 52-54 of the
    mirage at 160 x 90 (rays grazing the hot ground 7.7 m away): its endings are the
    dopri5 reference's at every pixel, and every other pixel is within 3x the tolerance;
    a plain render of every pixel at the same step (``tolerance`` = TRACE_SHARE px, no
    companions' retraces) shows sky where the reference hits the ground: the bar
    benchmarks/honesty.py weighs the adaptive image against is the former."""
    scene, _ = mirage_view("fig10", 160, 90)
    cam = _camera((0, 0, 0.4), (1, 0, 0.34), 160, 90, 16)
    rows = cam.resized(160, 90, region=(0, 160, 35, 38))  # rows 52-54 from the top
    ref = core.render(scene, rows, passes=PASSES, **REFERENCE)
    every = core.render(scene, rows, tolerance_px=1.0, interpolate=False, passes=PASSES)
    step = TRACE_SHARE * 1.0 * every.summary["pixel_angle"]
    plain = core.render(scene, rows, tolerance=step, passes=PASSES)
    assert every.summary["rays"] >= rows.n_pixels  # every centre traced, none interpolated
    assert np.array_equal(every.passes["ending"], ref.passes["ending"])
    truth = true_error_px(ref, every, rows.frame.position)
    assert np.nanmax(truth) <= 3.0
    lost = np.count_nonzero(plain.passes["ending"] != ref.passes["ending"])
    assert lost > 0, "the plain render no longer loses grazing hits here: pick a harder row"
    with np.testing.assert_raises(TypeError):
        core.render(scene, rows, tolerance_px=1.0, interpolate="no")


def test_nodes_beside_a_silhouette_take_their_sides_anchors_error(monkeypatch):
    """Issue 48: where an object's silhouette (a disk's edge, a sphere's) crosses an anchor
    cell, the nodes clear of the geometry take the largest error of the anchors on their
    side (core.sampling.anchors.by_side) instead of a companion of their own: on the disk
    of a high-spin hole (benchmarks/honesty.py disk_high_spin) at 1 px, 96 x 54, fewer
    companion rays than without the rule (1655 against 2264, measured), and against dopri5
    no pixel within 2 of an ending change whose true error is measurable (> 1e-3 px: 520,
    the least estimate 1.39x its truth, measured) is estimated below a third of it; every
    pixel that ends apart reports a flip."""
    from core.sampling import anchors

    scene, cam = _honesty().disk_high_spin(96, 54)
    run = core.render(scene, cam, tolerance_px=1.0, passes=PASSES)
    with monkeypatch.context() as patch:
        patch.setattr(anchors, "by_side", lambda ctx, nodes, jj, ii, side: (
            np.zeros(jj.size, bool), np.zeros(jj.size)))  # fmt: skip
        whole = core.render(scene, cam, tolerance_px=1.0, passes=PASSES)
    assert run.summary["companion_rays"] < 0.9 * whole.summary["companion_rays"]
    _edges_estimated_within_3x(scene, cam, run, at_least=300)


def _under_reported(scene, cam, run) -> tuple[int, int]:
    """Against dopri5: (pixels whose true error is measurable (> 1e-3 px), of them those
    estimated below a third of it)."""
    ref = core.render(scene, cam, passes=PASSES[:3], **REFERENCE)
    truth = true_error_px(ref, run, cam.frame.position)
    est = run.passes["error_px"].astype(float)
    measurable = np.isfinite(truth) & (truth > 1e-3)
    return int(measurable.sum()), int(np.count_nonzero(est[measurable] < truth[measurable] / 3))


@pytest.mark.usefixtures("tiles_refined")
def test_anchors_and_late_centres_judged_by_their_cells_keep_the_estimate_honest():
    """Issue 48: an anchor takes the largest first-run error of the roots at its ROOT
    cell's corners (core.sampling.anchors.settle) and a pixel centre traced late (the
    colour test's) its cell's, where those agree, instead of a companion of its own.
    benchmarks/honesty.py near_tangent (Kerr a/M = 0.9 from 5 rg, a checker board and a
    sphere) at 160 x 90, every tile refined, 1 px: fewer companions than a ray's half
    (0.51 a ray measured; 0.68 with a companion at every anchor and late centre), and
    against dopri5 no pixel of measurable error (11 348) estimated below a third of its
    truth (the least 0.92 of it, measured). A late centre that took its cell's corners'
    errors after their retraces (finer runs than its own) read 0.07 of its truth on
    544 pixels: it takes their first runs' (Nodes.first)."""
    scene, cam = _honesty().near_tangent(160, 90)
    run = core.render(scene, cam, tolerance_px=1.0, passes=PASSES)
    assert run.summary["companion_rays"] < 0.6 * run.summary["rays"]
    measurable, under = _under_reported(scene, cam, run)
    assert measurable > 10_000
    assert under == 0


@pytest.mark.usefixtures("tiles_refined")
def test_an_anchor_on_a_surface_keeps_its_own_companion_under_a_roots_cell():
    """Issue 48: hit points' errors vary from ray to ray more than a 16-pixel cell's
    corners show (where each crossing falls in its step; Schwarzschild's board 20 rg
    behind the hole, at the rule's largest step: the roots read 0.001 px where the
    anchors between them read 0.005), so an anchor that hits keeps its own companion
    (core.sampling.anchors._by_cell's ``rough``); judged by the roots, 205 of its 9032
    measurable pixels were estimated below a third of their truth (benchmarks/honesty.py
    schwarzschild, 160 x 90, every tile refined, 1 px). At most 0.2 % (8 measured; 9 with
    a companion at every anchor)."""
    scene, cam = _honesty().schwarzschild(160, 90)
    run = core.render(scene, cam, tolerance_px=1.0, passes=PASSES)
    measurable, under = _under_reported(scene, cam, run)
    assert measurable > 8000
    assert under <= 0.002 * measurable

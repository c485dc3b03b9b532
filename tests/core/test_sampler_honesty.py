"""The adaptive image against dense references on scenes unlike the Kerr board: what the
error pass and the sampler promise (core/sampling.py) holds where the board did not show
it fails. Each reference traces every pixel centre with dopri5 at a tight tolerance."""

import numpy as np

import core
from core import hamiltonians as hm
from core.presets import mirage_view
from tests.core.test_sampling import true_error_px

REFERENCE = dict(method="dopri5", tolerance=1e-10, max_steps=10**6)
PASSES = ("ending", "direction", "position", "error_px")


def _camera(position, look_at, width, height, fov_deg):
    return core.Camera.perspective(position=position, look_at=look_at, up=(0, 0, 1),
                                   fov_deg=fov_deg, width=width, height=height)  # fmt: skip


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


def test_an_ending_flip_is_reported_large():
    """Kerr a/M = 0.9, a board and a sphere at a loose 2 px: a pixel whose ray ends on
    something else than the dense render's (sky for an object, one object for another: hit
    points metres apart) reports an error of at least a pixel. One ray grazing the sphere
    flipped between runs at two steps, then its last two runs agreed: it reported 0.01 px;
    another, hitting the board, passed the sphere within its error: 0.008 px."""
    board = core.Plane(point=(0, 12, 0), normal=(0, -1, 0), u_axis=(1, 0, 0), extent=(16, 16),
                       color=core.checker(8, 8))  # fmt: skip
    sphere = core.Sphere(center=(6, 6, 1), radius=1.5, color=(1, 0, 0, 1))
    scene = core.Scene(model=hm.kerr(rg=1.0, a=0.45, chart="kerr_schild"),
                       objects=[board, sphere], background="procedural")  # fmt: skip
    cam = _camera((0, -30, 2), (0, 0, 0), 96, 54, 40)
    ref = core.render(scene, cam, passes=PASSES, **REFERENCE)
    flips = 0
    for tolerance in (2.0, 1.0):
        run = core.render(scene, cam, tolerance_px=tolerance, passes=PASSES)
        ending = ref.passes["ending"]
        apart = np.linalg.norm(ref.passes["position"] - run.passes["position"], axis=-1) > 0.5
        flipped = (ending != run.passes["ending"]) | ((ending == core.ENDING["hit"]) & apart)
        assert np.all(run.passes["error_px"][flipped] >= 1.0), run.passes["error_px"][flipped]
        flips += np.count_nonzero(flipped)
        flagged = run.passes["error_px"] >= 100.0  # flips (pi radians), not just loose pixels
        assert np.count_nonzero(flagged) <= 0.02 * flagged.size  # not every pixel
    assert flips >= 1  # the scene does flip some

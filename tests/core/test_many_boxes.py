"""Many objects near a hole: a step is near geometry by the objects' own boxes, tested all at
once (core.geometry.boxcells), not anywhere in their union's box; the error bars hold."""

import numpy as np
import pytest

import core
from core import hamiltonians as hm
from core.geometry import boxcells
from core.geometry.boxcells import BoxCells, ManyBoxes
from core.tracing import tracer_state
from tests.core.test_sampling import true_error_px

RNG = np.random.default_rng(61)
REFERENCE = dict(method="dopri5", tolerance=1e-10, max_steps=10**6)
PASSES = ("ending", "direction", "position", "error_px", "steps")


def _meets_brute(low, high, lo, hi) -> np.ndarray:
    """(M,) whether each query box overlaps one of the boxes, box by box."""
    overlap = (low.T[:, None, :] <= hi[None]) & (high.T[:, None, :] >= lo[None])
    return np.any(np.all(overlap, axis=2), axis=1)


def _boxes_and_queries(case: int):
    """Random boxes (flat on z in every third case, half of them points in some, a tenth
    20x wider and a hundredth 100x in others: few wide boxes, or many swept apart) and
    query boxes in and around them, 300 of which touch a box's low corner with their high
    one."""
    count = int(RNG.integers(1, 300))
    centre, half = RNG.uniform(-10, 10, (count, 3)), RNG.uniform(0.0, 2.0, (count, 3))
    if case % 3 == 0:
        half[:, 2], centre[:, 2] = 0.0, 1.0
    if case % 4 == 1:
        half[: count // 2] = 0.0
    if case % 5 == 2:
        half[: count // 10] *= 20.0  # wide ones: a few, or many (swept apart)
        half[: count // 100] *= 5.0
    lo, hi = centre - half, centre + half
    q, w = RNG.uniform(-13, 13, (3, 3000)), RNG.uniform(0.0, 3.0, (3, 3000))
    low, high = q - w, q + w
    k = RNG.integers(0, count, 300)
    low[:, :300], high[:, :300] = lo[k].T - 1.0, lo[k].T
    return lo, hi, low, high


@pytest.mark.parametrize("case", range(12))
def test_box_cells_never_miss_a_box_a_query_meets(case):
    """Every query that overlaps a box, as the brute force finds them, meets a marked
    cell (the prefilter); those that meet one are mostly real (the cells' share of space
    around the boxes)."""
    lo, hi, low, high = _boxes_and_queries(case)
    grid = BoxCells(lo, hi, cells=int(RNG.integers(2, 70)))
    truth, found = _meets_brute(low, high, lo, hi), grid.meets(low, high)
    assert not np.any(truth & ~found)
    assert np.count_nonzero(found) <= 4 * max(1, np.count_nonzero(truth)) + 50


@pytest.mark.parametrize("case", range(12))
def test_many_boxes_answer_as_testing_each_box_in_turn(case, monkeypatch):
    """ManyBoxes.meets equals the brute force exactly (touching counts), also with the
    candidate pairs taken a few at a time (PAIRS 7)."""
    lo, hi, low, high = _boxes_and_queries(case)
    truth = _meets_brute(low, high, lo, hi)
    np.testing.assert_array_equal(ManyBoxes(lo, hi).meets(low, high), truth)
    monkeypatch.setattr(boxcells, "PAIRS", 7)
    np.testing.assert_array_equal(ManyBoxes(lo, hi).meets(low, high), truth)


@pytest.mark.parametrize("case", range(0, 12, 2))
def test_many_boxes_pairs_are_every_overlapping_query_and_box_once(case):
    """ManyBoxes.pairs lists exactly the (query, box) pairs that overlap, each once, as
    testing every pair does (the clearance's broad phase: core.tracing.clearance)."""
    lo, hi, low, high = _boxes_and_queries(case)
    overlap = (low.T[:, None, :] <= hi[None]) & (high.T[:, None, :] >= lo[None])
    query, box = np.nonzero(np.all(overlap, axis=2))
    got = ManyBoxes(lo, hi).pairs(low, high)
    np.testing.assert_array_equal(np.stack(got), np.stack([query, box]))


def _cloud(count: int) -> tuple[core.Scene, core.Camera]:
    """``count`` spheres (radius 0.4-1.2 rg) in a shell 4 < r < 12 rg around a
    Schwarzschild hole, seen from 30 rg."""
    rng = np.random.default_rng(count)
    direction = rng.normal(size=(count, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    centre = (rng.uniform(4.0**3, 12.0**3, count) ** (1 / 3))[:, None] * direction
    radius, colour = rng.uniform(0.4, 1.2, count), rng.uniform(0.2, 1.0, (count, 3))
    spheres = [core.Sphere(c, r, color=(*k, 1.0))
               for c, r, k in zip(centre, radius, colour, strict=True)]  # fmt: skip
    cam = core.Camera.perspective((0, -30, 2), (0, 0, 0), (0, 0, 1), 40.0, 64, 36)
    return core.Scene(model=hm.schwarzschild(rg=1.0), objects=spheres), cam


def test_many_objects_near_a_hole_cost_the_steps_their_own_boxes_do_with_honest_errors():
    """40 spheres around a Schwarzschild hole (more than NEAR_BOXES): the render is the one
    that tests each sphere's box in turn (NEAR_BOXES raised to 40) to the last bit, with
    far fewer steps than near the whole shell's box (NEAR_MANY lowered to 16: 2.4x here);
    against dopri5 at 1e-10 every pixel ends as the reference's or reports a flip (error_px
    >= 1), and none is off by more than the tolerance with more than 3x its estimate."""
    scene, cam = _cloud(40)
    kw = {"tolerance_px": 1.0, "passes": PASSES, "workers": 1}
    many = core.render(scene, cam, **kw)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(tracer_state, "NEAR_BOXES", 40)
        own = core.render(scene, cam, **kw)
        patch.setattr(tracer_state, "NEAR_BOXES", 16)
        patch.setattr(tracer_state, "NEAR_MANY", 16)
        union = core.render(scene, cam, **kw)
    np.testing.assert_array_equal(many.rgba, own.rgba)
    for name in PASSES:
        np.testing.assert_array_equal(many.passes[name], own.passes[name])
    assert union.summary["steps"] > 1.5 * many.summary["steps"]
    ref = core.render(scene, cam, passes=PASSES, **REFERENCE)
    truth = true_error_px(ref, many, cam.frame.position)
    estimate = many.passes["error_px"]
    flipped = np.isinf(truth)
    assert np.all(estimate[flipped] >= 1.0), np.count_nonzero(flipped & (estimate < 1.0))
    over = np.isfinite(truth) & (truth > 1.0) & (truth > 3.0 * estimate)
    assert not np.any(over), np.count_nonzero(over)

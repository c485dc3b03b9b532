"""Shared by every test: each test draws the same random numbers wherever it runs."""

import copy

import numpy as np
import pytest

_SEEDED: dict[str, dict] = {}


@pytest.fixture(autouse=True)
def _module_rng_restarts_at_its_seed(request: pytest.FixtureRequest) -> None:
    """A test module's ``RNG`` (a numpy Generator) is put back to its seeded state before
    each of its tests: under pytest-xdist the tests that ran earlier on a worker (so the
    numbers left to draw) depend on how the run was split, and a test must not pass or fail
    with that (a checker-filter bound once failed on CI this way)."""
    module = request.module
    rng = getattr(module, "RNG", None)
    if not isinstance(rng, np.random.Generator):
        return
    state = _SEEDED.setdefault(module.__name__, copy.deepcopy(rng.bit_generator.state))
    rng.bit_generator.state = copy.deepcopy(state)


@pytest.fixture
def rounds_free(monkeypatch: pytest.MonkeyPatch) -> None:
    """The sampler refines a small frame as it would a large one: a round of tracing costs
    it nothing beyond its rays (core.sampling.quadtree.ROUND_RAYS 0, where the sampler and
    core.render read it), so a test of interpolation on a frame of a few thousand pixels
    still interpolates (the cost guard traces such a frame's every pixel; forked workers
    inherit the setting)."""
    from core.sampling import quadtree

    monkeypatch.setattr(quadtree, "ROUND_RAYS", 0)


@pytest.fixture
def tiles_refined(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every tile is refined, however small (core.sampling.quadtree.refining_pays, the cost
    guard, patched True; the rounds cost as much as ever): a test of the interpolation's
    honesty on a 160 x 90 frame (two tiles of 7200 pixels, which the guard traces at
    every pixel) tests the interpolation still (forked workers inherit the setting)."""
    from core.sampling import quadtree

    monkeypatch.setattr(quadtree, "refining_pays", lambda pixels: True)

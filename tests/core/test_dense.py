"""The step's path between its ends (core/tracing/dense.py): the cubic Hermite interpolant
follows a curved ray to fourth order, and the number of chords keeps their deviation
within what is allowed."""

import math

import numpy as np
import pytest

from core.tracing import dense


def test_hermite_follows_a_circle_to_fourth_order():
    """On the unit circle X(s) = (cos s, sin s, 0), V = (-sin s, cos s, 0), the cubic's
    error at the step's middle falls 16x per halving (fitted order within 0.3 of 4); the
    chord's midpoint only 4x (order 2), its deviation being |h (V0 - V1)| / 8 to leading
    order."""
    errs, chord_errs = [], []
    hs = np.array([0.4, 0.2, 0.1, 0.05])
    for h in hs:
        s0, s1 = 0.3, 0.3 + h
        X0, X1 = (
            np.array([[math.cos(s0)], [math.sin(s0)], [0.0]]),
            np.array([[math.cos(s1)], [math.sin(s1)], [0.0]]),
        )
        V0, V1 = (
            np.array([[-math.sin(s0)], [math.cos(s0)], [0.0]]),
            np.array([[-math.sin(s1)], [math.cos(s1)], [0.0]]),
        )
        mid = np.array([math.cos(s0 + h / 2), math.sin(s0 + h / 2), 0.0])
        errs.append(np.linalg.norm(dense.hermite(X0, V0, X1, V1, h, 0.5)[:, 0] - mid))
        chord_errs.append(np.linalg.norm(0.5 * (X0 + X1)[:, 0] - mid))
        deviation = dense.chord_deviation(X0, X1, V0, V1, h)[0]
        assert deviation == pytest.approx(chord_errs[-1], rel=0.05)
    order = np.polyfit(np.log(hs), np.log(errs), 1)[0]
    chord_order = np.polyfit(np.log(hs), np.log(chord_errs), 1)[0]
    assert order == pytest.approx(4.0, abs=0.3) and chord_order == pytest.approx(2.0, abs=0.1)
    # the ends are reproduced exactly
    np.testing.assert_array_equal(dense.hermite(X0, V0, X1, V1, h, 0.0), X0)
    np.testing.assert_allclose(dense.hermite(X0, V0, X1, V1, h, 1.0), X1, atol=1e-15)


def test_a_straight_path_at_a_changing_pace_lies_on_its_chord():
    """A ray's speed in the fictitious time changes over a step (as r does): along a
    straight line at speeds 1 and 3 the cubic runs along its chord, so its deviation is 0
    (|h (V0 - V1)| / 8 read 0.25 of the step's length); a chord's hit at a fraction of it
    is where the cubic reaches that fraction (on_cubic), not at that fraction of the
    step. Bent, the bound holds the cubic's largest distance from the chord's line on a
    fine grid of t, within a factor 2 of it, for random end velocities (its two terms peak
    at different t: 1.0-1.64x over 5000 such steps)."""
    X0, X1 = np.zeros((3, 1)), np.array([[0.0], [2.0], [0.0]])
    V0, V1 = np.array([[0.0], [1.0], [0.0]]), np.array([[0.0], [3.0], [0.0]])
    assert dense.chord_deviation(X0, X1, V0, V1, 1.0)[0] == 0.0
    path = dense.CubicPath(X0, V0, X1, V1, 1.0)
    t = dense.on_cubic(path, np.array([0]), 0.0, 1.0, np.array([0.5]))
    assert path.at(t, np.array([0]))[1, 0] == pytest.approx(1.0, abs=1e-8)
    assert abs(t[0] - 0.5) > 0.05  # the pace differs from the chord's
    rng = np.random.default_rng(3)
    X0, X1 = rng.normal(size=(3, 200)), rng.normal(size=(3, 200))
    V0, V1 = rng.normal(size=(3, 200)), rng.normal(size=(3, 200))
    bound = dense.chord_deviation(X0, X1, V0, V1, 0.7)
    ts = np.linspace(0.0, 1.0, 2001)[:, None, None]
    points = dense.hermite(X0, V0, X1, V1, 0.7, ts)  # (T, 3, M)
    unit = (X1 - X0) / np.linalg.norm(X1 - X0, axis=0)
    off = points - X0
    across = off - np.einsum("tim,im->tm", off, unit)[:, None, :] * unit
    largest = np.linalg.norm(across, axis=1).max(axis=0)
    assert np.all(largest <= bound * (1 + 1e-12)) and np.all(bound <= 2.0 * largest)


def test_pieces_are_powers_of_two_within_the_allowance():
    deviation = np.array([0.0, 1e-9, 1.0, 4.0, 17.0, 1e6, np.inf])
    k = dense.pieces(deviation, np.full(deviation.shape, 1.0))
    assert k.tolist() == [1, 1, 1, 2, 8, dense.MAX_PIECES, dense.MAX_PIECES]
    assert np.all(deviation[:5] / k[:5] ** 2 <= 1.0)


@pytest.mark.parametrize("name", ["leapfrog", "blanes_moan4"])
def test_hit_points_converge_at_the_methods_order(name):
    """Mirage rays grazing the hot ground (the seed's Fig. 10 view, 24x18): the hit points'
    largest error against dopri5 (1e-11) falls at the method's order with the step, since
    surfaces are found on the step's cubic path (refined where a chord hits), not on its
    chord (order 2 whatever the method). Fitted slope over h = 1, 1/2, 1/4 within 0.6 of
    the order (measured: leapfrog 1.95, blanes_moan4 4.46; the chord alone gave 2.1 for
    blanes_moan4)."""
    import core
    from core.trace import TraceOptions, Tracer

    scene, cam = core.presets.mirage_view("fig10", 24, 18)
    origins, directions = cam.rays()
    ref = Tracer(scene, TraceOptions(method="dopri5", tolerance=1e-11)).trace(origins, directions)
    hit = ref.ending == core.ENDING["hit"]
    assert hit.sum() > 100
    steps = np.array([1.0, 0.5, 0.25])
    errs = []
    for h in steps:
        out = Tracer(scene, TraceOptions(method=name, step=h, tolerance=1e-12)).trace(
            origins, directions
        )
        np.testing.assert_array_equal(out.ending, ref.ending)
        errs.append(np.abs(out.position[hit] - ref.position[hit]).max())
    order = core.METHODS[name].order
    assert np.polyfit(np.log(steps), np.log(errs), 1)[0] == pytest.approx(order, abs=0.6), errs

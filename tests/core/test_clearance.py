"""A ray's clearance from the scene's shapes (core/tracing/clearance.py) against brute force."""

import numpy as np

import core
from core import hamiltonians as hm
from core.tracing.clearance import shape_distance

RNG = np.random.default_rng(48)


def test_a_finite_planes_distance_is_the_nearest_of_its_points():
    """A tilted 3 x 0.5 rectangle's distance (exact: a strip's box holds much sky, and a
    ray through it kept a clearance of 0) equals the least distance to a fine grid of its
    points, to the grid's spacing, from points all around and on it."""
    plane = core.Plane((1.0, -2.0, 0.5), normal=(0.3, -1, 0.4), u_axis=(1, 0, 1),
                       extent=(3.0, 0.5))  # fmt: skip
    distance = shape_distance(plane)
    assert distance is not None
    su, sv = np.meshgrid(np.linspace(-1.5, 1.5, 601), np.linspace(-0.25, 0.25, 101))
    grid = plane.point + su.reshape(-1, 1) * plane.u_axis + sv.reshape(-1, 1) * plane.v_axis
    points = plane.point + RNG.normal(scale=2.0, size=(200, 3))
    points[:20] = grid[RNG.integers(0, len(grid), 20)]  # on the rectangle: 0
    brute = np.min(np.linalg.norm(points[:, None, :] - grid[None, :, :], axis=2), axis=1)
    spacing = np.hypot(3.0 / 600, 0.5 / 100)
    assert np.all(np.abs(distance(points) - brute) <= spacing)
    np.testing.assert_allclose(distance(points[:20]), 0.0, atol=1e-12)


def test_a_ray_through_a_tilted_strips_box_clear_of_the_strip_keeps_its_clearance():
    """A ray through the box of a strip tilted 45 degrees, 1 unit beside the strip itself,
    records that gap (seen from the camera), not 0 (the box's), so it is not taken for a
    near miss of the strip and traced again at every retrace."""
    from core.trace import TraceOptions, Tracer

    strip = core.Plane((0.0, 0.0, 0.0), normal=(0, -1, 0), u_axis=(1, 0, 1), extent=(4.0, 0.1))
    scene = core.Scene(model=hm.schwarzschild(rg=0.01), objects=[strip])
    tracer = Tracer(scene, TraceOptions(tolerance=1e-6), 30.0)
    tracer.watch_geometry(10.0)
    origin = np.array([[1.0, -20.0, -1.0]])  # the box spans x, z in [-1.45, 1.45]
    rays = tracer.trace(origin, np.array([[0.0, 1.0, 0.0]]))
    assert rays.ending[0] == core.ENDING["escaped"]
    gap = np.sqrt(2.0)  # (x, z) = (1, -1) from the strip's centre line x = z
    assert 0.5 * gap / 20 < rays.clearance[0] < 1.5 * gap / 20

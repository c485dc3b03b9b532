"""One ray record (issue 46): the pass table (core.passes) declares what a ray carries to
the image, and the tracer's, the sampler's and the frame's containers agree with it."""

from __future__ import annotations

import inspect

import numpy as np

import core
from core.passes import DEFAULT_PASSES, ON_REQUEST, OPTIONAL, PASSES, STORED, traced_passes
from core.sampling.interpolation import POINT_VALUES, Points
from core.sampling.lattice import RAY_PASSES, Nodes
from core.tracing import RayResults


def test_every_per_ray_pass_is_the_rays_own_field_with_its_type_and_start():
    """A per_ray pass is the RayResults field of its name: same channels, the pass's
    working type, and a ray not traced yet holds the pass's fill (position: its origin)."""
    origins, directions = np.full((3, 3), 7.0), np.tile([0.0, 0.0, 1.0], (3, 1))
    rays = RayResults.empty(3, origins, directions)
    for kind in RAY_PASSES:
        value = getattr(rays, kind.name)
        assert value.dtype == kind.working_dtype, kind.name
        assert value.shape == kind.empty(3).shape, kind.name
        expected = origins if kind.name == "position" else kind.empty(3)
        np.testing.assert_array_equal(value, expected)
    assert {k.name for k in RAY_PASSES} == {"steps", "ending", "position", "redshift",
                                             "magnification", "transmittance"}  # fmt: skip


def test_the_samplers_containers_hold_every_pass_they_carry():
    """Nodes hold every per_ray pass (fill where not traced); Points every interpolated
    stored pass, besides the colour and what a hit is cast again with."""
    nodes = Nodes(2, 3)
    for kind in RAY_PASSES:
        np.testing.assert_array_equal(getattr(nodes, kind.name), np.full(
            (2, 3) + kind.empty(0).shape[1:], kind.fill, kind.working_dtype))  # fmt: skip
    points = Points(4)
    interpolated = [k.name for k in STORED if k.interpolated]
    assert [v.name for v in POINT_VALUES] == ["rgba", *interpolated, "object_id", "tangent",
                                              "surface"]  # fmt: skip
    for kind in STORED:
        if kind.interpolated:
            np.testing.assert_array_equal(getattr(points, kind.name), kind.empty(4))


def test_the_lists_of_passes_follow_the_table():
    """What is computed by default, on request, held on request: read off the rows."""
    assert set(DEFAULT_PASSES) | set(ON_REQUEST) == {p.name for p in PASSES}
    assert set(OPTIONAL) <= set(ON_REQUEST)
    assert ON_REQUEST == ("direction", "position", "doppler", "magnification", "transmittance")
    default = inspect.signature(core.render).parameters["passes"].default
    assert default == DEFAULT_PASSES


def test_traced_passes_are_the_rays_fields_with_hits_only_masked():
    """traced_passes gives each per_ray pass from the ray's field, position only where it
    hit (NaN elsewhere), plus the seen direction and the error given."""
    origins, directions = np.zeros((2, 3)), np.tile([0.0, 1.0, 0.0], (2, 1))
    rays = RayResults.empty(2, origins, directions)
    rays.ending[:] = (core.ENDING["hit"], core.ENDING["escaped"])
    rays.position[:] = ((1.0, 2.0, 3.0), (4.0, 5.0, 6.0))
    seen, error = np.ones((2, 3)), np.array([0.1, 0.2])
    values = traced_passes(rays, seen, error)
    assert set(values) == {k.name for k in RAY_PASSES} | {"direction", "error"}
    np.testing.assert_array_equal(values["position"], [[1.0, 2.0, 3.0], [np.nan] * 3])
    assert values["direction"] is seen and values["error"] is error
    np.testing.assert_array_equal(values["steps"], rays.steps)

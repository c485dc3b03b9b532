"""A medium's box (issue 50): rays leave it exactly at its faces, and a box that cuts an
interface (the index at its faces is not 1, the vacuum outside) is refused by name.

The reference is independent of the tracer: scipy's RK45 (Dormand–Prince 5(4), dopri5)
on the optical Hamiltonian's own equations at rtol 1e-12, stopped at the box's faces by
its event location; from there the ray goes straight along dq/ds.
"""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import core
from core import hamiltonians as hm
from core.tracing import TraceOptions, Tracer

GAUSS = "1 + 0.5*exp(-(x*x + y*y + z*z))"
"""A graded-index ball whose index at the box (+-2.3) is within 2.5e-3 of 1: no
interface, but a ray leaving a step past the face still bends by ~1e-4 rad there."""
HALF = 2.3
WALL = HALF + 2.0  # a plane beyond the box's +y face: where the rays end, to compare


def dopri5_exit(model, q0: np.ndarray, d0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(exit point, unit exit direction) of the ray from q0 (just inside the box) along d0."""
    p0 = d0 * model.index_soa(q0[:, None])[0]  # H = |p|^2 / (2 n^2) = 1/2

    def rhs(_, z):
        dq, dp = model.gradient_soa(z[:3, None], z[3:, None])
        return np.concatenate([dp[:, 0], -dq[:, 0]])

    faces = []
    for axis in range(3):
        for end in (-HALF, HALF):

            def face(_, z, axis=axis, end=end):
                return z[axis] - end

            face.terminal = True
            faces.append(face)
    sol = solve_ivp(rhs, (0, 100), np.concatenate([q0, p0]), method="RK45", rtol=1e-12,
                    atol=1e-13, events=faces)  # fmt: skip
    q, p = sol.y[:3, -1], sol.y[3:, -1]
    v = model.gradient_soa(q[:, None], p[:, None])[1][:, 0]
    return q, v / np.linalg.norm(v)


def test_a_ray_leaves_a_medium_box_at_its_face():
    """Exit point and direction against dopri5 cut at the face: the hit points on a wall
    2 units beyond agree to 1e-6 (before: 2e-5 to 7e-5 at 1e-5 rad, the ray leaving at its
    first step end past the face, bent by the index there)."""
    model = hm.medium(GAUSS, bounds=((-HALF,) * 3, (HALF,) * 3))
    wall = core.Plane((0, WALL, 0), (0, -1, 0), (1, 1, 1, 1), u_axis=(1, 0, 0),
                      extent=(1e3, 1e3))  # fmt: skip
    rng = np.random.default_rng(1)
    origins = np.column_stack(
        [rng.uniform(-0.8, 0.8, 8), np.full(8, -HALF - 3.0), rng.uniform(-0.8, 0.8, 8)]
    )
    directions = np.tile([0.0, 1.0, 0.0], (8, 1)) + rng.normal(0.0, 0.05, (8, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    out = Tracer(core.Scene(model=model, objects=[wall]), TraceOptions(tolerance=1e-5)).trace(
        origins, directions
    )
    assert np.all(out.ending == core.ENDING["hit"])
    for k in range(8):
        t_in = (-HALF - origins[k, 1]) / directions[k, 1] + 1e-9
        q, d = dopri5_exit(model, origins[k] + t_in * directions[k], directions[k])
        assert abs(q[1] - HALF) < 1e-9  # it left through the +y face
        expected = q + (WALL - q[1]) / d[1] * d
        assert np.linalg.norm(out.position[k] - expected) < 1e-6


@pytest.mark.parametrize(
    "index, half",
    [("2/(1 + (x*x + y*y + z*z)/4)", 3.0),  # Maxwell's fish-eye: n 0.26-0.62 at the box
     ("sqrt(2 - (x*x + y*y + z*z))", 0.5)],  # Luneburg's lens cut inside its ball
)  # fmt: skip
def test_a_box_cutting_an_interface_is_refused_by_name(index, half):
    """An index that is not 1 anywhere on the box's faces: refused before tracing, the
    message naming the jump."""
    scene = core.Scene(model=hm.medium(index, bounds=((-half,) * 3, (half,) * 3)))
    cam = core.Camera.perspective((0, -12, 0), (0, 0, 0), (0, 0, 1), 40, 8, 6)
    with pytest.raises(ValueError, match="jumps at the medium's box"):
        core.render(scene, cam, tolerance_px=1.0, workers=1)


def test_a_ray_leaving_where_the_index_jumps_is_failed():
    """A box one of whose faces cuts the index (n = 1.3 on the +y face, 1 on the others):
    rays leaving through it are failed, never drawn as plausible colour; rays leaving
    through the matched faces escape."""
    model = hm.medium("1 + 0.3*exp(-(x*x + z*z + (y - 1)*(y - 1))*8)",
                      bounds=((-1, -1, -1), (1, 1, 1)))  # fmt: skip
    tracer = Tracer(core.Scene(model=model), TraceOptions(tolerance=1e-5))
    origins = np.array([[0.0, -3.0, 0.0], [0.0, -3.0, 0.0]])
    directions = np.array([[0.0, 1.0, 0.0], [0.0, 0.6, 0.8]])
    out = tracer.trace(origins, directions)
    assert out.ending[0] == core.ENDING["failed"]
    assert out.ending[1] == core.ENDING["escaped"]

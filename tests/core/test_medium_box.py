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
from tests.core.test_sampling import true_error_px

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


def _through_the_box(model, half: float, wall_y: float, n: int, spread: float, tilt: float,
                     seed: int):  # fmt: skip
    """(origins, directions, traced): ``n`` rays from 3 before the box (+-``half``), about
    along +y (offsets within ``spread``, directions tilted by ~``tilt``), traced at 1e-5 rad
    onto a wall at y = ``wall_y``."""
    wall = core.Plane((0, wall_y, 0), (0, -1, 0), (1, 1, 1, 1), u_axis=(1, 0, 0),
                      extent=(1e3, 1e3))  # fmt: skip
    rng = np.random.default_rng(seed)
    origins = np.column_stack(
        [rng.uniform(-spread, spread, n), np.full(n, -half - 3.0), rng.uniform(-spread, spread, n)]
    )
    directions = np.tile([0.0, 1.0, 0.0], (n, 1)) + rng.normal(0.0, tilt, (n, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    out = Tracer(core.Scene(model=model, objects=[wall]), TraceOptions(tolerance=1e-5)).trace(
        origins, directions
    )
    return origins, directions, out


def test_kinks_crossed_where_scipy_stops_at_them():
    """Luneburg's lens with n = 1 outside r = 1 (a kink in n there, written with abs): rays
    through it leave its box (+-1.5) as scipy's DOP853 says, stopped at the kink and at the
    faces by its event location, to 1e-6 on a wall 2 beyond (before: 1e-3 at every
    tolerance, the splitting's kicks sampling the force across the kink)."""
    index = "sqrt(2 - ((x*x + y*y + z*z) + 1 - abs((x*x + y*y + z*z) - 1))/2)"
    half, wall_y = 1.5, 3.5
    model = hm.medium(index, bounds=((-half,) * 3, (half,) * 3))
    origins, directions, out = _through_the_box(model, half, wall_y, 6, 0.6, 0.03, seed=2)
    checked = 0
    for k in range(6):
        t_in = (-half - origins[k, 1]) / directions[k, 1] + 1e-9
        q, d = _dop853_through_kinks(model, origins[k] + t_in * directions[k], directions[k],
                                     half)  # fmt: skip
        if abs(q[1] - half) > 1e-9 or out.ending[k] != core.ENDING["hit"]:
            continue  # left through another face: not towards the wall
        expected = q + (wall_y - q[1]) / d[1] * d
        assert np.linalg.norm(out.position[k] - expected) < 1e-6
        checked += 1
    assert checked >= 4


def _dop853_through_kinks(model, q0, d0, half: float) -> tuple[np.ndarray, np.ndarray]:
    """(exit point, unit direction) of a ray through a lens with n's kink at r = 1: scipy's
    DOP853 restarted at each crossing of the kink (event location), stopped at the faces."""
    p0 = d0 * model.index_soa(q0[:, None])[0]

    def rhs(_, z):
        dq, dp = model.gradient_soa(z[:3, None], z[3:, None])
        return np.concatenate([dp[:, 0], -dq[:, 0]])

    def kink(_, z):
        return z[0] ** 2 + z[1] ** 2 + z[2] ** 2 - 1.0

    kink.terminal = True
    faces = []
    for axis in range(3):
        for end in (-half, half):

            def face(_, z, axis=axis, end=end):
                return z[axis] - end

            face.terminal = True
            faces.append(face)
    z, t = np.concatenate([q0, p0]), 0.0
    for _ in range(8):  # in and out of the lens, then a face
        sol = solve_ivp(rhs, (t, 100), z, method="DOP853", rtol=1e-13, atol=1e-14,
                        events=[kink, *faces])  # fmt: skip
        z, t = sol.y[:, -1], sol.t[-1]
        if any(len(e) for e in sol.t_events[1:]):
            break
        z = z + 1e-9 * rhs(t, z)  # off the kink (an Euler step's error: 1e-18)
    v = model.gradient_soa(z[:3, None], z[3:, None])[1][:, 0]
    return z[:3], v / np.linalg.norm(v)


def test_a_ray_leaves_a_medium_box_at_its_face():
    """Exit point and direction against dopri5 cut at the face: the hit points on a wall
    2 units beyond agree to 1e-6 (before: 2e-5 to 7e-5 at 1e-5 rad, the ray leaving at its
    first step end past the face, bent by the index there)."""
    model = hm.medium(GAUSS, bounds=((-HALF,) * 3, (HALF,) * 3))
    origins, directions, out = _through_the_box(model, HALF, WALL, 8, 0.8, 0.05, seed=1)
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


FISH_EYE = "2/(1 + ((x*x + y*y + z*z) + 4 - abs((x*x + y*y + z*z) - 4))/8)"
"""Maxwell's fish-eye n = 2 / (1 + r^2/4) inside r = 2, and 1 (its value there) outside:
a kink in n at r = 2, the box's faces at n = 1."""


def _fish_eye(width: int, height: int) -> tuple[core.Scene, core.Camera]:
    """The fish-eye in a box of +-3 with a checker ball inside and a board behind."""
    model = hm.medium(FISH_EYE, bounds=((-3,) * 3, (3,) * 3))
    ball = core.Sphere((0.9, 0.6, -0.6), 0.45, core.checker(8, 4))
    board = core.Plane((0, 7.5, 0), (0, -1, 0), core.checker(16, 16), u_axis=(1, 0, 0),
                       extent=(24, 24))  # fmt: skip
    cam = core.Camera.perspective((0, -12, 0.9), (0, 0, 0), (0, 0, 1), 40, width, height)
    return core.Scene(model=model, objects=[ball, board], background=(0.2, 0.3, 0.5)), cam


def test_fish_eye_error_pass_within_3x_of_the_truth():
    """The fish-eye at 1 px and 0.25 px against a dense gauss4 render at 1e-10 rad (not
    dopri5: a Runge-Kutta method's stages near a kink lie across it, 0.02-0.06 px off; the
    tracer's kinks are checked against scipy above): of the pixels whose true error
    exceeds a tenth of the tolerance, >= 90 % are estimated within 3x, and at most 2 % of
    all pixels are under-reported by more than 3x (the issue's 1 % is the benchmark's,
    benchmarks/honesty.py fisheye_matched, on a larger frame). Before: a step of the
    splitting across the kink sampled the force on one side, first order in the step, and
    the estimate read 1/15 of it (benchmarks/honesty.py at 1 px: 28 % under-reported)."""
    scene, cam = _fish_eye(32, 18)
    ref = core.render(scene, cam, method="gauss4", tolerance=1e-10, max_steps=10**6,
                      passes=("ending", "direction", "position"), workers=1)  # fmt: skip
    for tol in (1.0, 0.25):
        run = core.render(scene, cam, tolerance_px=tol, workers=1,
                          passes=("ending", "direction", "position", "error_px"))  # fmt: skip
        truth = true_error_px(ref, run, cam.frame.position)
        est = run.passes["error_px"].astype(float)
        seen = ~np.isnan(truth)
        with np.errstate(invalid="ignore"):
            under = seen & (est < truth / 3) & (truth > 1e-3)
            big = seen & (truth > tol / 10)
            within = big & (est >= truth / 3) & (est <= 3 * truth)
        assert within.sum() >= 0.9 * big.sum(), (tol, within.sum(), big.sum())
        assert under.sum() <= 0.02 * seen.sum(), (tol, under.sum())


def test_an_unbounded_medium_leaves_its_sphere_as_before():
    """A medium without bounds (its region a sphere, not a box): its rays leave the sphere
    straight on wherever n is there, never failed for a jump (the box's rule is the box's)."""
    scene = core.Scene(model=hm.medium("1 + 0.02*z"))
    origins = np.array([[0.0, -10.0, 0.5], [0.0, -10.0, 0.5]])
    directions = np.array([[0.0, 1.0, 0.0], [0.0, 0.8, 0.6]])
    out = Tracer(scene, TraceOptions(tolerance=1e-6), extent=10.0).trace(origins, directions)
    assert np.all(out.ending == core.ENDING["escaped"])

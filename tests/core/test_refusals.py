"""Bad input is refused with a message that says what and why.

Item 2: textured primitives with no hit in a batch; item 3: numeric inputs of core.render,
core.integrate and the models are range-checked (no silent clamping); item 7: Tao's
methods are refused where they cannot trace, and a summary never reports an error of 0
without an estimate; item 8: each reason a camera cannot start rays has its own message.
"""

import math

import numpy as np
import pytest

import core
from core import hamiltonians as hm
from core.render import check_scene_camera, summary_text

BOARD = core.checker(8, 8, (0.9, 0.8, 0.2, 1), (0.1, 0.2, 0.6, 1))
CELL_A, CELL_B = np.array([0.9, 0.8, 0.2, 1]), np.array([0.1, 0.2, 0.6, 1])


def small_camera(position=(0, -30, 2), size=(8, 6), up=(0, 0, 1)):
    return core.Camera.perspective(
        position=position, look_at=(0, 0, 0), up=up, fov_deg=30, width=size[0], height=size[1]
    )


def kerr_scene(**kw):
    return core.Scene(model=hm.kerr(rg=1.0, a=0.45, chart="kerr_schild"), **kw)


# -- item 2: a textured primitive asked about a batch without a hit -------------------------


@pytest.mark.parametrize(
    "make",
    [
        lambda: core.Plane(point=(0, 0, 0), normal=(0, 0, 1), extent=(2, 2), color=BOARD),
        lambda: core.Sphere(center=(0, 0, 0), radius=1.0, color=BOARD),
        lambda: core.Disk(center=(0, 0, 0), normal=(0, 0, 1), r_in=0.2, r_out=1.0, color=BOARD),
    ],
)
def test_textured_primitive_with_no_hit_in_the_batch(make):
    obj = make()
    a, b = np.array([[5.0, 5.0, 2.0]]), np.array([[5.0, 5.0, -2.0]])  # passes beside it
    hits = obj.intersect(a, b)
    assert not hits.hit.any() and np.all(hits.color == 0.0) and np.all(hits.object_id == -1)
    empty = obj.intersect(np.zeros((0, 3)), np.zeros((0, 3)))
    assert len(empty) == 0 and empty.color.shape == (0, 4)


def test_textured_plane_colours_its_hits_by_the_checker_cells():
    plane = core.Plane(
        point=(0, 0, 0), normal=(0, 0, 1), u_axis=(1, 0, 0), extent=(2, 2), color=BOARD
    )
    x = np.array([-0.9, -0.6, 0.1, 0.4, 5.0])  # the last one misses
    a = np.column_stack([x, np.full(5, 0.1), np.ones(5)])
    b = a - [0, 0, 2]
    hits = plane.intersect(a, b)
    np.testing.assert_array_equal(hits.hit, [True, True, True, True, False])
    # u = (x + 1) / 2, v = (y + 1) / 2 = 0.55: cells iu = floor(8 u), iv = 4
    iu = np.floor(8 * (x[:4] + 1) / 2).astype(int)
    expected = np.where(((iu + 4) % 2 == 0)[:, None], CELL_A, CELL_B)
    np.testing.assert_array_equal(hits.color[:4], expected)


def test_textured_board_beside_the_view_renders():
    """Segments whose bounds meet the board but miss it (the whole batch): the image is the
    background, as without the board (no ValueError from _shade)."""
    board = core.Plane(
        point=(30, 10, 0), normal=(0, -1, 0), u_axis=(1, 0, 0), extent=(4, 4), color=BOARD
    )
    cam = core.Camera.perspective(
        position=(0, 0, 0), look_at=(0, 1, 0), up=(0, 0, 1), fov_deg=20, width=8, height=6
    )
    out = core.render(core.Scene(objects=[board], background=(0.2, 0.3, 0.4)), cam, workers=1)
    assert np.all(out.passes["ending"] == core.ENDING["escaped"])
    assert np.all(out.rgba == np.float32([0.2, 0.3, 0.4, 1.0]))


# -- item 3: numeric inputs are checked, never clamped ----------------------------------------


@pytest.mark.parametrize(
    "options, message",
    [
        (dict(tolerance=math.nan), r"tolerance must be a finite number in \[1e-14, 0.1\], got nan"),
        (dict(tolerance=0.0), r"tolerance .* got 0"),
        (dict(tolerance=1.0), r"tolerance .* got 1"),
        (dict(tolerance=-1e-6), "tolerance"),
        (dict(tolerance=math.inf), "tolerance"),
        (dict(tolerance=1e-15), "tolerance"),
        (dict(tolerance="1e-4"), "tolerance"),
        (dict(step=0.0), r"step must be a finite number > 0 \(positive\), got 0"),
        (dict(step=-0.1), "step must be"),
        (dict(step=math.nan), "step must be"),
        (dict(max_steps=0), r"max_steps must be an integer >= 1, got 0"),
        (dict(max_steps=2.5), "max_steps must be an integer"),
        (dict(max_steps=math.nan), "max_steps must be an integer"),
        (dict(chunk_size=0), "chunk_size must be an integer >= 1"),
        (dict(workers=0), "workers must be an integer >= 1"),
        (dict(cores=math.nan), "cores must be an integer"),
    ],
)
def test_render_refuses_out_of_range_options(options, message):
    with pytest.raises(ValueError, match=message):
        core.render(kerr_scene(), small_camera(), **options)


def test_render_accepts_the_ends_of_the_ranges():
    cam = small_camera(size=(4, 3))
    loose = core.render(kerr_scene(), cam, tolerance=0.1, max_steps=1, step=0.5, workers=1)
    assert loose.summary["step"] == 0.5 and loose.summary["steps"] <= cam.n_pixels
    tight = core.trace.TraceOptions(tolerance=1e-14)  # accepted (not traced here: slow)
    assert tight.tolerance == 1e-14


@pytest.mark.parametrize(
    "options, message",
    [
        (dict(step=0.0), "step must be finite non-zero"),
        (dict(step=math.nan), "step must be finite non-zero"),
        (dict(step=[0.1, 0.0]), "step must be finite non-zero"),
        (dict(steps=0), r"steps must be an integer >= 1, got 0"),
        (dict(steps=1.5), "steps must be an integer"),
        (dict(tol=math.nan), r"tol must be a finite number > 0"),
        (dict(tol=0.0), "tol must be"),
        (dict(energy_every=-1), r"energy_every must be an integer >= 0"),
        (dict(record_every=-2), r"record_every must be an integer >= 0"),
        (dict(max_steps=0, method="dopri5"), r"max_steps must be an integer >= 1"),
    ],
)
def test_integrate_refuses_out_of_range_options(options, message):
    H = hm.from_expression("0.5*(p**2 + q**2)", q=["q"], p=["p"])
    kw = dict(step=0.1, steps=10, method="yoshida4") | options
    q0, p0 = np.array([[1.0], [0.5]]), np.array([[0.0], [0.2]])
    with pytest.raises(ValueError, match=message):
        core.integrate(H, q0, p0, **kw)


def test_integrate_still_runs_backwards():
    """A negative step is integration backwards (not refused): the harmonic oscillator
    returns to its start."""
    H = hm.from_expression("0.5*(p**2 + q**2)", q=["q"], p=["p"])
    fwd = core.integrate(H, [1.0], [0.0], step=0.01, steps=100, method="yoshida4")
    back = core.integrate(H, fwd.q, fwd.p, step=-0.01, steps=100, method="yoshida4")
    np.testing.assert_allclose(back.q, [1.0], atol=1e-12)
    np.testing.assert_allclose(fwd.q, [math.cos(1.0)], atol=1e-8)


@pytest.mark.parametrize(
    "make, message",
    [
        (
            lambda: hm.from_expression("k*q*p", q=["q"], p=["p"], parameters={"k": math.nan}),
            r"parameter 'k' must be a finite number, got nan",
        ),
        (
            lambda: hm.metric(
                [["-1", "0"], ["0", "c"]], coords=["t", "x"], parameters={"c": math.inf}
            ),
            "parameter 'c' must be a finite number",
        ),
        (lambda: hm.medium("1 + k*z", parameters={"k": math.nan}), "parameter 'k'"),
        (lambda: hm.medium("1", bounds=((0, 0, math.nan), (1, 1, 1))), "medium bounds lo must be"),
        (lambda: hm.medium("1", bounds=((0, 0, 0), (1, 0, 1))), "lo < hi in every axis"),
        (lambda: hm.schwarzschild(rg=math.nan), r"rg \(Schwarzschild radius\) must be a finite"),
        (lambda: hm.kerr(rg=1.0, a=math.nan), r"a \(Kerr spin\) must be a finite number, got nan"),
        (lambda: core.Scene(center=(0, math.nan, 0)), "scene center must be finite numbers"),
        (lambda: core.Scene(region_radius=0.0), "region_radius must be a finite number > 0"),
    ],
)
def test_models_and_scenes_refuse_non_finite_numbers(make, message):
    with pytest.raises(ValueError, match=message):
        make()


# -- item 7: Tao's methods and summaries without an estimate --------------------------------


@pytest.mark.parametrize("method", ["tao2", "tao4"])
@pytest.mark.parametrize(
    "model",
    [hm.kerr(rg=1.0, a=0.45, chart="kerr_schild"), hm.schwarzschild(1.0), hm.kerr(rg=1.0, a=0.3)],
)
def test_tao_is_refused_for_time_scaled_models(method, model):
    """An all-magenta image (every ray failed) has no error estimate, never error_max 0."""
    with pytest.raises(ValueError, match=f"method '{method}' cannot render a black hole"):
        core.render(core.Scene(model=model), small_camera(position=(1, -30, 2)), method=method)
    with pytest.raises(ValueError, match="cannot render"):
        core.render(core.Scene(model=model), small_camera(), method=core.get_method(method))


def test_a_composition_of_tao_is_refused_like_tao():
    """The refusal reads the method's interface (``follows_time_scale``, a composition asks
    its base), not its name: yoshida4 with Tao's base fails on black holes like tao4."""
    method = core.get_method("yoshida4", base="tao2")
    assert not method.follows_time_scale and core.get_method("yoshida4").follows_time_scale
    with pytest.raises(ValueError, match="method 'yoshida4' cannot render a black hole"):
        core.render(core.Scene(model=hm.schwarzschild(1.0)), small_camera(), method=method)


def test_tao_still_renders_a_medium_like_gauss4():
    """Without a time scale Tao's rays are right: the same endings and colours as gauss4."""
    scene = core.Scene(
        model=hm.medium("1 + 0.2*exp(-(x*x + y*y + z*z))", bounds=((-3, -3, -3), (3, 3, 3))),
        objects=[core.Sphere(center=(0, 5, 0), radius=1, color=(1, 0, 0, 1))],
        background=(0.0, 0.0, 1.0),
    )
    cam = small_camera(position=(0, -8, 0.5), size=(12, 9))
    ref = core.render(scene, cam, method="gauss4", tolerance=1e-4, workers=1)
    out = core.render(scene, cam, method="tao2", tolerance=1e-4, workers=1)
    assert 0 < np.count_nonzero(ref.passes["ending"] == core.ENDING["hit"]) < cam.n_pixels
    np.testing.assert_array_equal(out.passes["ending"], ref.passes["ending"])
    np.testing.assert_array_equal(out.rgba, ref.rgba)


def test_summary_without_estimate_is_none_not_zero():
    """No error estimate where no ray had one (every ray ran out of steps): None, never 0."""
    out = core.render(kerr_scene(), small_camera(), tolerance=1e-3, max_steps=1, workers=1)
    assert out.summary["endings"]["max_steps"] == out.summary["rays"]
    assert out.summary["error_median"] is None and out.summary["error_max"] is None
    assert out.summary["energy_error_max"] is None  # no ray ended where H says anything
    assert "max error n/a" in summary_text(out.summary)
    no_pass = core.render(
        kerr_scene(), small_camera(), tolerance=1e-3, passes=("ending",), workers=1
    )
    assert no_pass.summary["error_max"] is None
    flat = core.render(core.Scene(background=(0, 0, 1)), small_camera(), workers=1)
    assert flat.summary["error_max"] is None and flat.summary["energy_error_max"] is None


def test_summary_with_estimate_is_positive():
    out = core.render(kerr_scene(), small_camera(), tolerance=1e-3, workers=1)
    s = out.summary
    assert 0 < s["error_median"] <= s["error_max"] < math.inf
    # in the Error pass's unit, pixels, and said so (a bare 3.14 read as pixels was radians)
    assert f"max error {s['error_px_max']:.3g} px" in summary_text(s)
    assert s["error_px_max"] == s["error_max"] / s["pixel_angle"]
    bare = {k: v for k, v in s.items() if not k.startswith("error_px")}
    assert f"max error {s['error_max']:.3g} rad" in summary_text(bare)


# -- item 8: why rays cannot start at the camera --------------------------------------------

MINUS = [["1", "0", "0", "0"], ["0", "-1", "0", "0"], ["0", "0", "-1", "0"], ["0", "0", "0", "-1"]]
ZERO = [["0"] * 4 for _ in range(4)]
DEGENERATE = [
    ["-1", "0", "0", "0"],
    ["0", "1", "0", "0"],
    ["0", "0", "1", "0"],
    ["0", "0", "0", "0"],
]
XS = ("x", "y", "z")
# Schwarzschild (rg = 1) in Kerr–Schild form as a user metric: no captured_soa, no rg
KS_USER = hm.metric(
    inverse=[["-1 - f"] + [f"f*{c}/r" for c in XS]]
    + [
        [f"f*{i}/r"] + [("1 - " if i == j else "-") + f"f*{min(i, j)}*{max(i, j)}/r**2" for j in XS]
        for i in XS
    ],
    definitions=[("r", "sqrt(x**2 + y**2 + z**2)"), ("f", "1/r")],
)


@pytest.mark.parametrize(
    "model, position, error, words",
    [
        (hm.kerr(rg=1.0, a=0.45), (0, 0, 30), core.CoordinateAxisError, "polar axis"),
        (hm.minkowski("spherical"), (0, 0, 5), core.CoordinateAxisError, "polar axis"),
        (
            hm.metric(MINUS),
            (0, -30, 2),
            core.MetricSignatureError,
            r"signature \(-, -, -, \+\) .* needs \(-, \+, \+, \+\).* must be negated",
        ),
        (hm.metric(ZERO), (0, -30, 2), core.SingularMetricError, "singular at the camera"),
        (hm.metric(DEGENERATE), (0, -30, 2), core.SingularMetricError, "determinant 0"),
        (
            hm.kerr(rg=1.0, a=0.45, chart="kerr_schild"),
            (0, 0.3, 0.2),
            core.InsideHorizonError,
            "inside the black hole's horizon",
        ),
        (
            hm.schwarzschild(1.0),
            (0, -0.3, 0.5),
            core.InsideHorizonError,
            "inside the black hole's horizon",
        ),
        (KS_USER, (0, -0.5, 0.1), core.InsideHorizonError, "no observer can stay at rest"),
    ],
)
def test_each_camera_problem_has_its_own_message(model, position, error, words):
    """Each is named, never 'inside the black hole's horizon' for all of them, or numpy's bare
    'Singular matrix'. Raised before any ray is traced."""
    calls = []
    up = (0, 1, 0) if position[:2] == (0, 0) else (0, 0, 1)
    cam = small_camera(position=position, up=up)
    with pytest.raises(error, match=words) as info:
        core.render(core.Scene(model=model), cam, progress=lambda *a: calls.append(a))
    assert calls == []
    assert isinstance(info.value, core.ObserverError) and isinstance(info.value, ValueError)
    others = {
        core.CoordinateAxisError,
        core.MetricSignatureError,
        core.SingularMetricError,
        core.InsideHorizonError,
    } - {error}
    assert not isinstance(info.value, tuple(others))
    with pytest.raises(error, match=words):
        check_scene_camera(core.Scene(model=model), np.array(position, dtype=float))


def test_cameras_off_the_axis_and_outside_the_horizon_pass():
    for model, position in [
        (hm.kerr(rg=1.0, a=0.45), (1e-3, 0, 30)),
        (hm.kerr(rg=1.0, a=0.45, chart="kerr_schild"), (0, 0, 1.0)),
        (KS_USER, (0, -2.5, 0.1)),
        (
            hm.metric(
                [
                    list(r)
                    for r in (
                        ("-1", "0", "0", "0"),
                        ("0", "1", "0", "0"),
                        ("0", "0", "1", "0"),
                        ("0", "0", "0", "1"),
                    )
                ]
            ),
            (0, -30, 2),
        ),
    ]:
        check_scene_camera(core.Scene(model=model), np.array(position, dtype=float))

"""The seed's figure captions, checked on the data behind examples/figures.py at tiny sizes.

Closed Volterra orbits and bounded H for the symplectic method (Figs. 4, 5), capture
inside the critical impact parameter (Fig. 3), flat space integrated in spherical
coordinates equals straight rays (Fig. 6), the inverted image below the board and the
ghost above it (Figs. 10, 11), and the Kerr shadow's position (Bardeen 1973).
"""

import importlib.util
import math
import pathlib
import sys

import numpy as np
import pytest

import core

EXAMPLES = pathlib.Path(__file__).resolve().parents[2] / "examples"
sys.path.insert(0, str(EXAMPLES))
_spec = importlib.util.spec_from_file_location("figures", EXAMPLES / "figures.py")
figures = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(figures)


def section_spread(s, q, p):
    """Spread of p where each orbit crosses q = 1/3 upwards (a Poincaré section; cubic
    splines through the recorded states): zero for a closed orbit. -> (N,), crossings (N,)."""
    from scipy.interpolate import CubicSpline

    spreads, counts = [], []
    for k in range(q.shape[1]):
        sq, sp = CubicSpline(s, q[:, k] - 1 / 3), CubicSpline(s, p[:, k])
        roots = sq.roots(extrapolate=False)
        up = roots[sq(roots, 1) > 0]
        spreads.append(np.ptp(sp(up)))
        counts.append(up.size)
    return np.array(spreads), np.array(counts)


def test_volterra_symplectic_orbits_close_and_h_stays_bounded():
    """Figs. 4/5: gauss4 (step 0.5) returns to the same section point every period and its
    |H - H0| does not grow; rk4 at the same step drifts (its orbits spiral)."""
    s, q, p, dH, _ = figures.volterra_run("gauss4", 0.5, 600, record_every=1)
    spread, count = section_spread(s, q, p)
    assert (count >= 20).all()  # ~26 periods of ~11.4
    assert spread.max() < 1e-5, spread  # measured ~1e-6 (spline interpolation)
    third = len(s) // 3
    first, last = np.abs(dH[:third]).max(0), np.abs(dH[-third:]).max(0)
    assert (last < 1.5 * first).all() and first.max() < 1e-5
    s, q, p, dH, _ = figures.volterra_run("rk4", 0.5, 4500, record_every=1)
    grow = np.abs(dH[-1]) / np.abs(dH[len(s) // 10]).clip(1e-300)
    assert (grow > 5).all(), grow  # linear drift: ~10x over the run
    rk_spread, _ = section_spread(s, q, p)
    assert (rk_spread > 100 * spread).all()  # measured ~1.5e-3


def test_blackhole_paths_captured_inside_critical_impact():
    """Fig. 3: rays with b < 3 sqrt(3)/2 rg fall in, rays outside are deflected and leave."""
    bc = 1.5 * math.sqrt(3)
    impacts = [2.0, 0.99 * bc, 1.01 * bc, 4.0]
    xy, captured = figures.blackhole_paths(impacts, tau_steps=1500)
    assert captured.tolist() == [True, True, False, False]
    r_end = np.hypot(*xy[-1].T)
    assert (r_end[2:] > 20).all() and (r_end[:2] < 1.02).all()


def test_flat_space_in_spherical_coordinates_equals_straight_rays():
    """Fig. 6: Eq. 14 (spherical coordinates, integrated) gives the straight-ray image."""
    cam = figures.camera((0, -20, 2), (0, 0, 0), 45, 20, 15)
    objs = [figures.checker_board(10.0, 16.0), *figures.textured_spheres()]
    straight = core.render(
        figures.lens_scene(core.hamiltonians.minkowski("cartesian"), objs), cam, passes=("ending",)
    )
    curved = core.render(
        figures.lens_scene(core.hamiltonians.minkowski("spherical"), objs, region_radius=8.0),
        cam,
        method="gauss4",
        tolerance=1e-4,
        passes=("ending",),
    )
    assert curved.summary["steps"] > 0
    np.testing.assert_array_equal(curved.passes["ending"], straight.passes["ending"])
    assert np.abs(curved.rgba - straight.rgba).max() < 1e-3


def column(name, medium=True):
    out = figures.mirage_view(name, 1, 96, "gauss4", with_medium=medium)
    assert out.summary["failed"] == 0
    return figures.column_letters(out.rgba[:, 0, :3])


def test_fig10_inferior_mirage_inverted_image_below_the_board():
    """Fig. 10: straight: sky, R G W board, ground; through Eq. 17: below the upright R G
    the board's top R again (inverted), then mirrored sky, then ground."""
    assert column("fig10", medium=False) == ".RGW_"
    assert column("fig10") == ".RGR._"


def test_fig11_vince_ghost_above_the_board():
    """Fig. 11: through Eq. 18 an inverted ghost (W G R from the top) sits above the upright
    board (R G W), which stays at the bottom on the ground."""
    assert column("fig11", medium=False) == ".RGW_"
    seen = column("fig11")
    assert seen.endswith("RGW_"), seen
    ghost = seen.rfind("WGR")
    assert 0 <= ghost < len(seen) - 4, seen  # the ghost is above the upright board


@pytest.mark.parametrize("a", [0.0, 0.499])
def test_kerr_shadow_edges_match_bardeen(a):
    """Fig. 12: the shadow seen edge-on from 1000 rg spans Bardeen's curve (far observer):
    a/M = 0 symmetric about the centre, a/M = 0.998 flattened on the left (prograde side,
    x = -1.0 rg) and reaching x = +3.5 rg on the right: its centre shifts by +1.2 rg."""
    w, h = 48, 24
    out, pix = figures.kerr_shadow(
        a, w, h, distance=1000.0, fov_deg=0.6, method="gauss4", tolerance=1e-5
    )
    left, right = figures.shadow_edges(out.passes["ending"], pix, 1000.0)
    x, _ = figures.bardeen_shadow(a)
    px = pix * 1000.0
    assert abs(left - x.min()) < 1.5 * px and abs(right - x.max()) < 1.5 * px
    assert out.summary["failed"] == 0
    centre = 0.5 * (left + right)
    if a == 0.0:
        assert abs(centre) < px
    else:
        assert 0.5 * (x.min() + x.max()) > 1.0 and centre > 1.0 - px


def test_disk_beamed_and_bent_over_the_shadow():
    """Fig. 13 (a/M = 0.9, inclination 80 deg): the approaching side (left half) has g > 1
    and is brighter than the receding one; the middle column reads disk (its far side, lensed
    up over the shadow), shadow, disk (the near side, in front) from the top."""
    out = figures.disk_view(0.45, 48, 27, tolerance=1e-4)
    g, ending = out.passes["redshift"], out.passes["ending"]
    on = np.isfinite(g)
    left, right = on & (np.arange(48) < 24), on & (np.arange(48) >= 24)
    assert np.median(g[left]) > 1.0 > np.median(g[right])
    luminance = out.rgba[..., :3] @ core.blackbody.XYZ_FROM_RGB[1]
    assert luminance[left].mean() > 2 * luminance[right].mean()
    codes = core.ENDING
    column = ending[:, 24]
    runs = [int(c) for i, c in enumerate(column) if i == 0 or c != column[i - 1]]
    assert runs[:3] == [codes["hit"], codes["captured"], codes["hit"]]


def test_fig14_moving_observers_shrink_what_lies_ahead_and_shift_it():
    """At 6 M from an a/M = 0.9 hole the falling camera sees a smaller shadow than the
    static one (aberration towards the hole); the orbiting camera's Doppler factor is above
    1 on the side it moves to (right) and below on the other; in flat space at 0.9 c towards
    the view the spheres ahead shrink, the point stars crowd into the view (more than 3x as
    many images as at rest: the rest frame's solid angle ahead is compressed up to
    (1 + β)/(1 - β) = 19x) and the camera sees every pixel blueshifted."""
    views = figures.observer_views(48, 36, tolerance=1e-5)
    captured = {name: np.count_nonzero(views[name].passes["ending"] == core.ENDING["captured"])
                for name in ("static", "infall")}  # fmt: skip
    assert captured["infall"] < 0.8 * captured["static"]
    g = views["orbit"].passes["doppler"]
    assert g[:, -1].min() > 1.0 > g[:, 0].max()
    hits = {name: np.count_nonzero(views[name].passes["ending"] == core.ENDING["hit"])
            for name in ("flat", "flat 0.9c")}  # fmt: skip
    assert 0 < hits["flat 0.9c"] < 0.25 * hits["flat"]
    assert views["flat 0.9c"].passes["doppler"].min() > 1.0
    stars = {name: views[name].summary["star_images"] for name in ("flat", "flat 0.9c")}
    assert 0 < 3 * stars["flat"] < stars["flat 0.9c"]

"""Fast versions of the important stiff and extreme cases of benchmarks/stress.py.

Each checks the outcome a ray gets (completed, captured, flagged failed), the drift of
its invariants, and, where it renders, that no NaN reaches the image and failed rays are
drawn in the failed colour.
"""

import importlib.util
import math
import pathlib
import sys

import numpy as np

BENCHMARKS = pathlib.Path(__file__).resolve().parents[2] / "benchmarks"
sys.path.insert(0, str(BENCHMARKS))
_spec = importlib.util.spec_from_file_location("stress", BENCHMARKS / "stress.py")
stress = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(stress)


def test_impact_within_1e6_of_critical():
    """b = b_c (1 + 1e-6) winds 2.62 times and escapes, exactly as the orbit integral says;
    b = b_c (1 - 1e-6) is captured; H drifts < 1e-9, p_t and p_phi not at all."""
    out = stress.near_critical(delta=1e-6, step=0.01, steps=3500)
    res = out["result"]
    assert res.captured.tolist() == [False, True] and not res.failed.any()
    turns, exact = float(out["turns"][0]), float(out["escaping_turns_exact"].split()[0])
    assert abs(turns - exact) < 1e-5
    assert out["drift"]["H"] < 1e-9 and out["drift"]["p_t"] == 0 and out["drift"]["p_phi"] == 0


def test_steps_past_the_stability_limit_are_flagged_not_drawn():
    """Störmer–Verlet on the oscillator: limit h = 2 found, bounded below it, flagged failed
    (overflow) above it; rk4's limit is 2 sqrt(2)."""
    assert abs(stress.stability_limit("stormer_verlet") - 2.0) < 2e-3
    assert abs(stress.stability_limit("rk4") - 2 * math.sqrt(2)) < 2e-3
    H = stress.hm.from_expression("0.5*(p**2 + q**2)", q=["q"], p=["p"])
    ok = stress.core.integrate(H, [1.0], [0.0], step=1.98, steps=2000, method="stormer_verlet")
    assert not ok.failed and ok.energy_error < 1.0
    with np.errstate(all="ignore"):
        bad = stress.core.integrate(H, [1.0], [0.0], step=2.02, steps=2000, method="stormer_verlet")
    assert bad.failed and bad.steps < 2000


def test_index_jump_within_1e3_snell_and_no_nan_image():
    """n from 1 to 1.3 within 1e-3: p_x exactly conserved, Snell's law to 1e-6 at h = 1e-3;
    at h = 0.05 the image has no NaN and its failed rays are magenta."""
    out = stress.index_jump(steps_sizes=(1e-3,), methods=("gauss4",))
    line = out["gauss4 h=0.001"]
    assert line.startswith("completed") and "p_x drift 0e+00" in line
    assert float(line.split("|p_z - Snell| ")[1].split(",")[0]) < 1e-6
    assert out["image"].startswith("no NaN")


def test_index_going_to_zero_is_flagged_failed():
    """n = z: a ray falling to z = 0 is flagged failed there, and the image has no NaN."""
    out = stress.n_zero(size=6)
    assert out["n = z"].startswith("flagged failed")
    assert out["n = z (literal)"].startswith("flagged failed")
    assert out["image"].startswith("no NaN")


def test_positions_at_1e8_rg_weak_field_deflection():
    """A ray from 1e8 rg with b = 1e4 rg: deflection 2 rg/b + 15 pi/16 (rg/b)^2 to 1e-6."""
    H = stress.hm.schwarzschild(rg=1.0)
    q0, p0 = stress.schwarzschild_ray([1e4], r0=1e8)
    res = stress.core.integrate(H, q0, p0, step=0.01, steps=2000, method="gauss4", adaptive=True)
    r_end = res.q[0, 1]
    bend = res.q[0, 3] - (math.pi - math.asin(1e-4) - math.asin(1e4 / r_end))
    exact = 2e-4 + 15 * math.pi / 16 * 1e-8
    assert not res.failed and r_end > 1e8
    assert abs(bend - exact) < 1e-6 * exact


def test_rays_over_the_kerr_pole_in_boyer_lindquist():
    """a/M = 0.998: rays with L_z = 0 and 1e-6 cross the pole (theta through 0) and complete;
    H and the Carter constant drift < 1e-5, p_phi not at all."""
    out = stress.pole_rays()
    res = out["result"]
    assert not res.failed.any() and (res.q[:, 2] < 0).all()
    assert out["drift"]["H"] < 1e-5 and out["drift"]["carter"] < 1e-4
    assert out["drift"]["p_phi"] == 0


def test_spin_09999_and_grazing_rays():
    """a/M = 0.9999: a small image without failures or NaN; rays grazing the horizon of
    a/M = 0.9 (Kerr–Schild) are captured inside r+ with p_t and L_z conserved."""
    cam = stress.core.Camera.perspective(
        position=(0, -30, 1), look_at=(0, 0, 0), up=(0, 0, 1), fov_deg=25, width=8, height=8
    )
    scene = stress.core.Scene(model=stress.hm.kerr(rg=1.0, a=0.49995, chart="kerr_schild"))
    out = stress.core.render(scene, cam, method="gauss4", tolerance=1e-6, passes=("ending",))
    assert stress.image_check(out).startswith("no NaN") and out.summary["failed"] == 0
    assert out.summary["endings"]["captured"] > 0
    H = stress.hm.kerr(rg=1.0, a=0.45, chart="kerr_schild")
    b = stress.BC * (1 - np.array([1e-6, 1e-3]))
    q0 = np.stack([np.zeros(2), np.full(2, -30.0), b, np.zeros(2)], 1)
    p0 = np.stack([np.zeros(2), np.ones(2), np.zeros(2), np.zeros(2)], 1)
    p0[:, 0] = stress._null_pt(H, q0, p0)
    assert np.abs(H.value(q0, p0)).max() < 1e-12
    res = stress.core.integrate(H, q0, p0, step=0.01, steps=2500, method="gauss4", adaptive=True)
    assert res.captured.all() and not res.failed.any()
    assert (H.radius_soa(res.q.T) < H.horizon).all()
    d = stress.drift(H, q0, p0, res)
    assert d["p_t"] == 0 and d["L_z"] < 1e-12 and d["H"] < 1e-5

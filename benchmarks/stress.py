"""Stiff and extreme cases: what the core does at the edges, and that no NaN reaches an image.

    PYTHONPATH=. python benchmarks/stress.py [--only pole,index_jump] [--long-steps 10000000]

(`make stress` runs it in the project's environment.) Each case prints its outcome
(completed, captured, flagged failed), the drift of its invariants, and for cases that
render, that every pixel is finite and failed rays carry the failed colour.

Cases: near_critical (b within 1e-6 of critical), horizon (rays grazing and crossing the
horizon), spin (a/M = 0.9999), pole (rays over the Kerr pole in both charts), index_jump
(an index step 1e-3 thick), stability (step sizes at and past stability limits), long
(1e7 steps of one ray), long_split (10⁶ steps of a medium's split), long_split_kerr
(10⁶ steps of Kerr's split on a bound orbit, ~10 min), n_zero (an index going to zero),
far (positions at 1e8 rg), tao_render (Tao's methods in the renderer: a known weakness,
reported, not hidden).
The fast versions of the important cases are tests in tests/core/test_stress.py.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

import core
from core import hamiltonians as hm
from core.render import shade
from core.trace import TraceOptions, Tracer

RG, M = 1.0, 0.5
BC = 1.5 * math.sqrt(3.0) * RG


def report(case: str, data: dict | None = None, **items) -> dict:
    """Print a case's outcome line by line; return the items and the extra data."""
    print(f"{case}:")
    for k, v in items.items():
        print(f"  {k}: {v}")
    return {**items, **(data or {})}


def outcome(res, k: int | None = None) -> str:
    """'completed', 'captured' or 'flagged failed' of ray k of an IntegrationResult."""
    failed = np.atleast_1d(res.failed)
    captured = np.atleast_1d(res.captured) if res.captured is not None else failed * False
    idx = range(len(failed)) if k is None else [k]
    words = [
        "flagged failed" if failed[i] else "captured" if captured[i] else "completed" for i in idx
    ]
    return ", ".join(words)


def image_check(out) -> str:
    """Every pixel finite; failed pixels magenta (core.FAILED_COLOR); counts."""
    rgba = out.rgba
    finite = bool(np.isfinite(rgba).all())
    failed = out.passes["ending"] == core.ENDING["failed"]
    magenta = bool(np.allclose(rgba[failed], core.FAILED_COLOR)) if failed.any() else True
    assert finite and magenta, "a NaN or an unflagged failed ray reached the image"
    return (
        f"no NaN in the image ({rgba.shape[1]}x{rgba.shape[0]}), "
        f"{int(failed.sum())} failed pixels drawn magenta, endings {out.summary['endings']}"
    )


def schwarzschild_ray(b, r0: float = 30.0):
    """(q0, p0) of equatorial rays (BL) from r0 inwards with E = 1 and impact b."""
    b = np.atleast_1d(np.asarray(b, dtype=float))
    f = 1 - RG / r0
    n = b.size
    q0 = np.stack([np.zeros(n), np.full(n, r0), np.full(n, np.pi / 2), np.zeros(n)], 1)
    p0 = np.stack(
        [-np.ones(n), -np.sqrt(np.maximum(1 / f**2 - b**2 / (f * r0**2), 0)), np.zeros(n), b], 1
    )
    return q0, p0


def drift(H, q0, p0, res) -> dict:
    """|H - H0| and the invariants' drift at the end."""
    out = {"H": np.abs(H.value(res.q, res.p) - H.value(q0, p0))}
    inv0, inv1 = H.invariants(q0, p0), H.invariants(res.q, res.p)
    for k in inv0:  # relative to the invariant's size, or absolute where it is below 1
        out[k] = np.abs(inv1[k] - inv0[k]) / np.maximum(np.abs(inv0[k]), 1.0)
    return {k: float(np.max(v)) for k, v in out.items()}


# ----------------------------------------------------------------------------------
# the cases


def near_critical(delta: float = 1e-6, step: float = 0.01, steps: int = 6000):
    """Impact b = b_c (1 +- delta): one winds around the photon sphere and escapes, one is
    captured; gauss4 in Poincaré time."""
    H = hm.schwarzschild(rg=RG)
    q0, p0 = schwarzschild_ray([BC * (1 + delta), BC * (1 - delta)])
    start = time.perf_counter()
    res = core.integrate(H, q0, p0, step=step, steps=steps, method="gauss4", adaptive=True)
    from work_precision import _schwarzschild_integrals

    turns = res.q[:, 3] / (2 * np.pi)
    phi_in, _, _, _ = _schwarzschild_integrals(BC * (1 + delta), 30.0)
    phi_out, _, _, _ = _schwarzschild_integrals(BC * (1 + delta), float(res.q[0, 1]))
    exact = (phi_in + phi_out) / (2 * np.pi)
    return report(
        f"near_critical (b = b_c (1 +- {delta:g}))",
        outcome=outcome(res),
        turns=np.round(turns, 6).tolist(),
        escaping_turns_exact=f"{exact:.6f} (orbit integral to the final r = {res.q[0, 1]:.3g})",
        drift=drift(H, q0, p0, res),
        seconds=round(time.perf_counter() - start, 2),
        data={"result": res},
    )


def horizon(size: int = 24):
    """Rays that graze the horizon: b just below critical (they spiral in and cross r+ at a
    grazing angle) in Kerr–Schild a/M = 0.9 and Boyer–Lindquist; and a camera at 1.5 rg."""
    a = 0.45
    H = hm.kerr(rg=RG, a=a, chart="kerr_schild")
    b = BC * (1 - np.logspace(-8, -2, 5))
    x0 = -30.0
    q0 = np.stack([np.zeros(5), np.full(5, x0), b, np.zeros(5)], 1)
    p0 = np.stack([np.zeros(5), np.ones(5), np.zeros(5), np.zeros(5)], 1)
    p0[:, 0] = _null_pt(H, q0, p0)
    res = core.integrate(H, q0, p0, step=0.01, steps=4000, method="gauss4", adaptive=True)
    r_end = H.radius_soa(res.q.T) if hasattr(H, "radius_soa") else None
    Hs = hm.schwarzschild(rg=RG)
    qs, ps = schwarzschild_ray(b)
    rs = core.integrate(Hs, qs, ps, step=0.01, steps=4000, method="gauss4", adaptive=True)
    scene = core.Scene(model=hm.schwarzschild(rg=RG), background="procedural")
    cam = core.Camera.perspective(
        position=(0, -1.5, 0), look_at=(0, 0, 0), up=(0, 0, 1), fov_deg=120, width=size, height=size
    )
    out = core.render(scene, cam, method="gauss4", tolerance=1e-6, passes=("ending",))
    return report(
        "horizon (rays grazing and crossing the horizon)",
        kerr_schild=outcome(res),
        final_r_over_r_plus=np.round(r_end / H.horizon, 4).tolist() if r_end is not None else "n/a",
        kerr_schild_drift=drift(H, q0, p0, res),
        boyer_lindquist_schwarzschild=outcome(rs),
        bl_drift=drift(Hs, qs, ps, rs),
        camera_at_1_5_rg=image_check(out),
        data={"result": res, "image": out},
    )


def _null_pt(H, q0, p0):
    """p_t < 0 making H = 0: H is quadratic in p_t, sampled at p_t = 0, -1, -2."""
    h = []
    for pt in (0.0, -1.0, -2.0):
        p = p0.copy()
        p[:, 0] = pt
        h.append(H.value(q0, p))
    A = (h[2] - 2 * h[1] + h[0]) / 2.0  # H(x) = A x^2 + B x + C
    B = A + h[0] - h[1]
    disc = np.sqrt(B * B - 4 * A * h[0])
    return np.minimum((-B - disc) / (2 * A), (-B + disc) / (2 * A))


def spin(size: int = 32, a_over_m: float = 0.9999):
    """a/M = 0.9999: a small image (Kerr–Schild) and rays through the photon region (BL)."""
    a = a_over_m * M
    scene = core.Scene(model=hm.kerr(rg=RG, a=a, chart="kerr_schild"), background="procedural")
    cam = core.Camera.perspective(
        position=(0, -30, 1), look_at=(0, 0, 0), up=(0, 0, 1), fov_deg=25, width=size, height=size
    )
    start = time.perf_counter()
    out = core.render(scene, cam, method="gauss4", tolerance=1e-6, passes=("ending",))
    from work_precision import _kerr_rays

    H = hm.kerr(rg=RG, a=a)
    q0, p0 = _kerr_rays(8, a, 30.0)
    res = core.integrate(H, q0, p0, step=0.01, steps=2500, method="gauss4", adaptive=True)
    return report(
        f"spin (a/M = {a_over_m})",
        image=image_check(out),
        energy_error_max=out.summary["energy_error_max"],
        bl_photon_region_rays=outcome(res),
        bl_drift=drift(H, q0, p0, res),
        seconds=round(time.perf_counter() - start, 1),
        data={"result": res, "render": out},
    )


def pole(height: int = 41, tolerance: float = 1e-7):
    """Rays over the pole of a/M = 0.998 in both charts (pole_charts) and straight over it
    in Boyer–Lindquist (pole_rays)."""
    return {**pole_charts(height, tolerance), **pole_rays()}


def pole_charts(height: int = 41, tolerance: float = 1e-7):
    """A camera in the equatorial plane: the middle column of pixels (L_z = 0, through the
    axis) and its neighbours, traced in Boyer–Lindquist and in Kerr–Schild coordinates."""
    cam = core.Camera.perspective(
        position=(0, -30, 0), look_at=(0, 0, 0), up=(0, 0, 1), fov_deg=30, width=3, height=height
    )
    o, d = cam.rays()
    results = {}
    for chart in ("boyer_lindquist", "kerr_schild"):
        for tol in (tolerance, tolerance * 1e-2):
            sc = core.Scene(model=hm.kerr(rg=RG, a=0.499, chart=chart))
            r = Tracer(sc, TraceOptions(method="gauss4", tolerance=tol), 30.0).trace(o, d)
            results[chart, tol] = r
    lines = {}
    pix = math.radians(30) / height
    for chart in ("boyer_lindquist", "kerr_schild"):
        a, b = results[chart, tolerance], results[chart, tolerance * 1e-2]
        esc = ((a.ending == 0) & (b.ending == 0)).reshape(height, 3)
        cols = np.where(esc, (_angles(a.direction, b.direction) / pix).reshape(height, 3), 0.0)
        lines[chart] = (
            f"endings {np.bincount(a.ending, minlength=5).tolist()}; tolerance "
            f"{tolerance:g} against {tolerance * 1e-2:g}: on the axis column "
            f"{cols[:, 1].max():.2e} px, beside it {cols[:, [0, 2]].max():.2e} px"
        )
    bl = results["boyer_lindquist", tolerance * 1e-2]
    ks = results["kerr_schild", tolerance * 1e-2]
    both = (bl.ending == 0) & (ks.ending == 0)
    between = _angles(bl.direction, ks.direction)[both] / pix
    return report(
        "pole: rays over the Kerr pole (a/M = 0.998) in both charts",
        **lines,
        charts=f"Boyer–Lindquist and Kerr–Schild escape directions differ by "
        f"{np.median(between):.2e} px (median), up to {between.max():.2e} px "
        "next to the shadow (the observers' frames differ at O(a/r^2))",
        data={"tracer": results},
    )


def pole_rays(steps: int = 700):
    """Boyer–Lindquist rays with L_z = 0 and 1e-6 from theta = 0.3 straight over the pole."""
    H = hm.kerr(rg=RG, a=0.499)
    q0 = np.array([[0.0, 30.0, 0.3, 0.0], [0.0, 30.0, 0.3, 0.0]])
    p0 = np.array([[-1.0, 0.0, -3.0, 0.0], [-1.0, 0.0, -3.0, 1e-6]])
    p0[:, 1] = _null_pr(H, q0, p0)
    res = core.integrate(H, q0, p0, step=0.01, steps=steps, method="gauss4", adaptive=True)
    return report(
        "pole: Boyer–Lindquist rays over the pole",
        outcome=f"L_z = 0: {outcome(res, 0)}, L_z = 1e-6: {outcome(res, 1)}; "
        f"final theta {np.round(res.q[:, 2], 4).tolist()} (theta < 0: past "
        "the pole, the same points as theta > 0 with phi + pi)",
        drift=drift(H, q0, p0, res),
        data={"result": res, "q0": q0, "p0": p0},
    )


def _angles(u, v):
    cross = np.linalg.norm(np.cross(u, v), axis=1)
    return np.arctan2(cross, np.einsum("ij,ij->i", u, v))


def _null_pr(H, q0, p0):
    """p_r < 0 (ingoing) making H = 0 (H is quadratic in p_r with no cross term in BL)."""
    base = p0.copy()
    base[:, 1] = 0.0
    one = p0.copy()
    one[:, 1] = 1.0
    h0, h1 = H.value(q0, base), H.value(q0, one)
    return -np.sqrt(-h0 / (h1 - h0))


JUMP_INDEX = "1.0 + 0.15*(1 + tanh((z - 0.5)/0.001))"
"""A refractive index from 1 to 1.3 within about 1e-3 of z = 0.5 (physical form)."""


def index_jump(steps_sizes=(0.05, 1e-2, 1e-3, 1e-4), methods=("gauss4", "rk4", "tao4")):
    """Rays crossing a 1e-3-thick index step at 30 degrees: Snell's law (p_x is conserved
    exactly: H does not depend on x) and |H - H0| for steps at, above and below the jump."""
    H = hm.medium(JUMP_INDEX)
    alpha = math.radians(30)
    q0 = np.array([[0.0, 0.0, 0.0]])
    p0 = np.array([[math.cos(alpha), 0.0, math.sin(alpha)]])
    rows = {}
    for m in methods:
        for h in steps_sizes:
            n = int(round(2.0 / h))
            start = time.perf_counter()
            res = core.integrate(H, q0, p0, step=h, steps=n, method=m, energy_every=1)
            pz_snell = math.sqrt(1.3**2 - math.cos(alpha) ** 2)
            above = res.q[0, 2] > 0.6
            err = f"{abs(res.p[0, 2] - pz_snell):.1e}" if above else "(not through the layer)"
            rows[f"{m} h={h:g}"] = (
                f"{outcome(res)}, |p_z - Snell| {err}, max |H - H0| "
                f"{res.energy_error[0]:.1e}, p_x drift "
                f"{abs(res.p[0, 0] - p0[0, 0]):.0e} "
                f"({time.perf_counter() - start:.2f} s)"
            )
    scene = core.Scene(
        model=hm.medium(JUMP_INDEX, bounds=((-5, -5, -1), (5, 5, 2))),
        objects=[core.Plane(point=(0, 0, 1.5), normal=(0, 0, -1), color=core.checker(8, 8))],
        background=(0, 0, 1),
    )
    cam = core.Camera.perspective(
        position=(0, -2, 0), look_at=(0, 0, 1.5), up=(0, 0, 1), fov_deg=60, width=16, height=16
    )
    out = core.render(scene, cam, method="gauss4", step=0.05, passes=("ending",))
    return report("index_jump (n from 1 to 1.3 within 1e-3)", **rows, image=image_check(out))


def stability_limit(method: str, hmax: float = 4.0, n: int = 4000) -> float:
    """Largest h with a stable one-step matrix on H = (p^2 + q^2)/2 (spectral radius <= 1),
    scanning h on a grid: one integrate call on the unit vectors for every h."""
    H = hm.from_expression("0.5*(p**2 + q**2)", q=["q"], p=["p"])
    h = np.linspace(hmax / n, hmax, n)
    q0 = np.tile([[1.0], [0.0]], (n, 1))
    p0 = np.tile([[0.0], [1.0]], (n, 1))
    res = core.integrate(H, q0, p0, step=np.repeat(h, 2), steps=1, method=method)
    mats = np.stack([res.q[:, 0], res.p[:, 0]], 1).reshape(n, 2, 2).transpose(0, 2, 1)
    with np.errstate(all="ignore"):
        rho = np.abs(np.linalg.eigvals(mats)).max(axis=1)
    bad = np.flatnonzero(~(rho <= 1 + 1e-9))
    return float(h[bad[0] - 1]) if bad.size else math.inf


def stability(
    steps: int = 2000,
    methods=("symplectic_euler", "stormer_verlet", "yoshida4", "yoshida6", "rk4", "gauss4"),
):
    """H = (p^2 + q^2)/2 at 0.99 and 1.01 times each method's stability limit, and a Kerr
    render at an absurd step (tau step 2)."""
    H = hm.from_expression("0.5*(p**2 + q**2)", q=["q"], p=["p"])
    rows = {}
    for m in methods:
        limit = stability_limit(m)
        if not math.isfinite(limit):
            res = core.integrate(H, [1.0], [0.0], step=3.9, steps=steps, method=m)
            rows[m] = (
                f"stable up to h = 4 (the scan's end); at h = 3.9: {outcome(res)}, max "
                f"|H - H0| {res.energy_error:.2e}"
            )
            continue
        for f in (0.99, 1.01):
            with np.errstate(all="ignore"):
                res = core.integrate(H, [1.0], [0.0], step=f * limit, steps=steps, method=m)
            grows = res.failed or not res.energy_error < 1e3
            rows[f"{m} h = {f:g} x {limit:.4g}"] = (
                f"{outcome(res)} after {res.steps} steps, max |H - H0| {res.energy_error:.2e}"
                f" ({'unstable' if grows else 'bounded'})"
            )
    scene = core.Scene(
        model=hm.kerr(rg=RG, a=0.45, chart="kerr_schild"),
        objects=[core.Sphere(center=(0, 8, 0), radius=1, color=(1, 0, 0, 1))],
    )
    cam = core.Camera.perspective(
        position=(0, -30, 2), look_at=(0, 0, 0), up=(0, 0, 1), fov_deg=40, width=16, height=16
    )
    for m in ("rk4", "gauss4"):  # a tau step of 2: 2 r per step in s
        out = core.render(scene, cam, method=m, step=2.0, passes=("ending",))
        rows[f"render {m} at tau step 2"] = image_check(out)
    return report("stability (steps at and past the limits)", **rows)


class Kepler(hm.Hamiltonian):
    """H = |p|^2/2 - 1/|q| in the plane, hand-written in numpy (cheap: for 1e7 steps)."""

    def __init__(self):
        super().__init__(("x", "y"), ("p_x", "p_y"), separable=True)

    def value_soa(self, Q, P):
        """H (N,)."""
        return 0.5 * (P[0] ** 2 + P[1] ** 2) - 1.0 / np.hypot(Q[0], Q[1])

    def gradient_soa(self, Q, P, wrt: str = "qp"):
        """(dH/dq, dH/dp)."""
        dq = Q / np.hypot(Q[0], Q[1]) ** 3 if "q" in wrt else None
        return dq, (P.copy() if "p" in wrt else None)

    def value_gradient_soa(self, Q, P):
        """(H, dH/dq, dH/dp)."""
        dq, dp = self.gradient_soa(Q, P)
        return self.value_soa(Q, P), dq, dp

    def invariants_soa(self, Q, P):
        """Angular momentum."""
        return {"L": Q[0] * P[1] - Q[1] * P[0]}


def long(steps: int = 10_000_000, step: float = 0.01):
    """One Kepler orbit (e = 0.5) for `steps` Störmer–Verlet steps: energy stays bounded,
    angular momentum is conserved to round-off; prints the time per step."""
    H = Kepler()
    q0, p0 = np.array([0.5, 0.0]), np.array([0.0, math.sqrt(3.0)])  # e = 0.5, a = 1
    start = time.perf_counter()
    res = core.integrate(
        H, q0, p0, step=step, steps=steps, method="stormer_verlet", energy_every=1000
    )
    sec = time.perf_counter() - start
    d = drift(H, q0, p0, res)
    return report(
        f"long ({steps:.0e} steps, one ray, stormer_verlet, Kepler e = 0.5)",
        outcome=outcome(res),
        orbits=round(steps * step / (2 * math.pi)),
        max_energy_error=f"{res.energy_error:.2e} (sampled every 1000 steps)",
        final_drift=d,
        seconds=f"{sec:.1f} ({1e6 * sec / steps:.1f} us per step)",
        data={"result": res},
    )


def long_split(steps: int = 1_000_000, step: float = 0.25):
    """A ray in a graded-index fibre, n^2 = 2 - (x^2 + y^2), for 10^6 Poincaré steps of the
    medium's explicit split (over 60 000 oscillations): |H - H0| after 1 % of the run and
    at the end, for the splittings and rk4 (bounded against growing linearly)."""
    H = hm.medium("sqrt(2 - (x**2 + y**2))")
    q0, p0 = np.array([0.3, 0.0, 0.0]), np.array([0.0, 0.2, 1.0])
    p0 *= math.sqrt(2 - 0.09) / np.linalg.norm(p0)
    rows = {}
    for method in ("leapfrog", "blanes_moan4", "rk4"):
        start = time.perf_counter()
        early, late = (
            core.integrate(
                H, q0, p0, step=step, steps=n, method=method, adaptive=True, energy_every=100
            )
            for n in (steps // 100, steps)
        )
        sec = time.perf_counter() - start
        growth = late.energy_error / early.energy_error
        rows[method] = (
            f"|H - H0| {early.energy_error:.2e} after {steps // 100} steps, "
            f"{late.energy_error:.2e} after {steps} ({growth:.2f}x), "
            f"{outcome(late)}, {sec:.0f} s"
        )
    return report(f"long_split ({steps:.0e} steps of {step}, one ray, graded-index fibre)", **rows)


def kerr_bound_orbit(a: float = 0.45):
    """(model, q, p, H0) of a bound, inclined timelike orbit (m = 1, H0 = -1/2; r 12 to 12.4)
    around Kerr in the split's BL (t, s, theta, phi): E = 0.98, L = 2.2, from r = 12 rg at
    its radial turning point, 0.5 rad above the equator."""
    from core.models import KerrBoyerLindquist

    model = KerrBoyerLindquist(RG, a)
    r0, theta0, E, L, H0 = 12.0, 0.5 * math.pi - 0.5, 0.98, 2.2, -0.5
    q = np.array([[0.0], [math.acosh((r0 - M) / model.b)], [theta0], [0.0]])
    p = np.array([[-E], [0.0], [0.0], [L]])
    V, _ = model.parts(q, p, H0, derivatives=False)
    T_free = 0.5 * L * L / math.sin(theta0) ** 2
    p[2] = math.sqrt(2.0 * (float(V[0]) - T_free))
    return model, q, p, H0


def long_split_kerr(steps: int = 1_000_000, step: float = 0.5) -> dict:
    """A bound timelike orbit around Kerr a/M = 0.9 (kerr_bound_orbit) on the BL square-root
    split (core/models/kerr_split.py): |Λ| and |H - H0| after 1 % of the run and at its end,
    leapfrog over ``steps`` steps, blanes_moan_s10 over a tenth of them (one ray: the
    per-call cost of numpy dominates, ~0.1 ms per flow)."""
    model, q0, p0, H0 = kerr_bound_orbit()
    split = model.split_parts(H0)
    rows = {}
    for name, n in (("leapfrog", steps), ("blanes_moan_s10", steps // 10)):
        method = core.METHODS[name]
        state = method.init(split, q0, p0)
        start = time.perf_counter()
        worst = {}
        every = max(1, n // 10_000)
        for k in range(1, n + 1):
            state, ok = method.step(split, state, step)
            if k % every == 0:
                Q, P = method.qp(state)
                lam = float(abs(split.value_soa(Q, P)[0]))
                dh = float(abs(model.value_soa(Q, P)[0] - H0))
                label = "early" if k <= n // 100 else "late"
                old = worst.get(label, (0.0, 0.0))
                worst[label] = (max(old[0], lam), max(old[1], dh))
        Q, P = method.qp(state)
        r = model.mass + model.b * np.cosh(Q[1, 0])
        rows[f"kerr bound orbit, {name}"] = (
            f"max |Λ| {worst['early'][0]:.2e} over the first {n // 100} steps, "
            f"{worst['late'][0]:.2e} over the rest of {n}; max |H - H0| {worst['early'][1]:.2e}"
            f" / {worst['late'][1]:.2e}; r = {r:.3f} rg at the end, "
            f"{'ok' if ok.all() else 'flagged failed'}, {time.perf_counter() - start:.0f} s"
        )
    return report(f"long_split_kerr ({steps:.0e} steps of {step}, one bound orbit, Kerr)", **rows)


def n_zero(size: int = 12):
    """An index that goes to zero: n = 1e-3 + z^2 (physical; rays speed up as 1/n), n = z
    (non-positive below z = 0: flagged failed), literal n = z (rays stall)."""
    rows = {}
    q0 = np.array([[0.0, 0.0, 1.0]])
    d = np.array([[0.0, 0.0, -1.0]])  # straight down (oblique rays turn back up before)
    for text, literal in (("1e-3 + z**2", False), ("z", False), ("z", True)):
        H = hm.medium(text, literal=literal)
        p0 = d / (np.sqrt(H.index_soa(q0.T)) if literal else 1.0 / H.index_soa(q0.T))[:, None]
        with np.errstate(all="ignore"):
            res = core.integrate(H, q0, p0, step=1e-3, steps=3000, method="rk4")
        rows[f"n = {text}{' (literal)' if literal else ''}"] = (
            f"{outcome(res)} at z = {res.q[0, 2]:.3g} after {res.steps} steps, max |H - H0| "
            f"{res.energy_error[0]:.1e}"
        )
    scene = core.Scene(
        model=hm.medium("z"),  # unbounded: a box would cut n = z at its faces (refused)
        objects=[core.Plane(point=(0, 0, -0.5), normal=(0, 0, 1), color=(0.5, 0.5, 0.5, 1))],
        background=(0, 0, 1),
    )
    cam = core.Camera.perspective(
        position=(0, 0, 1), look_at=(0, 0, 0), up=(0, 1, 0), fov_deg=10, width=size, height=size
    )
    with np.errstate(all="ignore"):
        out = core.render(scene, cam, method="rk4", step=0.01, passes=("ending",))
    return report("n_zero (an index going to zero)", **rows, image=image_check(out))


def far(size: int = 16, distance: float = 1e8):
    """Positions at 1e8 rg: a Schwarzschild ray with b = 1e4 rg from 1e8 rg and back
    (deflection against 2 rg/b + 15 pi/16 (rg/b)^2 / 2), and a render of the shadow from 1e8 rg."""
    H = hm.schwarzschild(rg=RG)
    b = 1e4
    q0, p0 = schwarzschild_ray([b], r0=distance)
    res = core.integrate(H, q0, p0, step=0.01, steps=2000, method="gauss4", adaptive=True)
    r_end = res.q[0, 1]
    straight = np.pi - math.asin(b / distance) - math.asin(min(b / r_end, 1.0))
    bend = float(res.q[0, 3] - straight)
    bend_exact = 2 * RG / b + (15 * math.pi / 16) * (RG / b) ** 2
    scene = core.Scene(model=hm.kerr(rg=RG, a=0.45, chart="kerr_schild"), background=(0, 0, 1))
    fov = math.degrees(4 * BC / distance)
    cam = core.Camera.perspective(
        position=(0, -distance, 0),
        look_at=(0, 0, 0),
        up=(0, 0, 1),
        fov_deg=fov,
        width=size,
        height=size,
    )
    out = core.render(scene, cam, method="gauss4", tolerance=1e-8, passes=("ending",))
    captured = int(np.count_nonzero(out.passes["ending"] == core.ENDING["captured"]))
    expect = math.pi * (size / 4) ** 2  # a disc of radius b_c: a quarter of the image width
    return report(
        f"far (positions at {distance:.0e} rg)",
        ray=f"{outcome(res)}, from r = {distance:.0e} to r = {r_end:.3e}",
        deflection=f"{bend:.8e} rad against {bend_exact:.8e} (2nd order weak field)",
        drift=drift(H, q0, p0, res),
        shadow=f"{captured} captured pixels, about {expect:.0f} expected for a "
        f"disc of radius b_c (a/M = 0.9 shrinks and shifts it a little)",
        image=image_check(out),
        data={
            "result": res,
            "bend": bend,
            "bend_exact": bend_exact,
            "captured": captured,
            "expected": expect,
        },
    )


def tao_render(size: int = 8):
    """tao2/tao4 in the renderer (they integrate the Poincaré-transformed K, where they are
    known to misbehave): how many rays end as plausible colours with a wrong H."""
    scene = core.Scene(
        model=hm.kerr(rg=RG, a=0.45, chart="kerr_schild"),
        objects=[core.Sphere(center=(0, 8, 0), radius=1, color=(1, 0, 0, 1))],
    )
    cam = core.Camera.perspective(
        position=(0, -30, 2), look_at=(0, 0, 0), up=(0, 0, 1), fov_deg=40, width=size, height=size
    )
    o, d = cam.rays()
    ref = Tracer(scene, TraceOptions(method="rk4", tolerance=1e-8), 30.0).trace(o, d)
    rows = {}
    for m in ("tao2", "tao4"):
        with np.errstate(all="ignore"):
            r = Tracer(scene, TraceOptions(method=m, tolerance=1e-6), 30.0).trace(o, d)
        drawn = (r.ending != core.ENDING["failed"]) & (r.ending != core.ENDING["max_steps"])
        wrong = drawn & ~(r.energy_error < 1e-3)
        esc = (r.ending == 0) & (ref.ending == 0)
        err = _angles(r.direction[esc], ref.direction[esc])
        rows[m] = (
            f"{int(np.sum(~drawn))} flagged failed, {int(wrong.sum())} of "
            f"{int(drawn.sum())} drawn rays have |H - H0| > 1e-3 (NOT flagged); escape "
            f"directions off by {np.median(err):.2g} rad (median) against rk4"
        )
        rgba = shade(r, core.Background("procedural"))  # the colours core.render gives them
        out = core.RenderResult(
            rgba.reshape(size, size, 4),
            passes={"ending": r.ending.reshape(size, size)},
            summary={"endings": np.bincount(r.ending, minlength=5).tolist()},
        )
        rows[f"{m} image"] = image_check(out)
    return report(
        "tao_render (Tao's methods on the Poincaré-transformed K in the renderer)", **rows
    )


CASES = {
    "near_critical": near_critical,
    "horizon": horizon,
    "spin": spin,
    "pole": pole,
    "index_jump": index_jump,
    "stability": stability,
    "long": long,
    "long_split": long_split,
    "long_split_kerr": long_split_kerr,
    "n_zero": n_zero,
    "far": far,
    "tao_render": tao_render,
}


def main(argv: list[str] | None = None) -> None:
    """Run the chosen cases (default: all)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", default="", help=f"comma list of {', '.join(CASES)}")
    parser.add_argument("--long-steps", type=int, default=10_000_000)
    args = parser.parse_args(argv)
    chosen = [c for c in args.only.split(",") if c] or list(CASES)
    total = time.perf_counter()
    for name in chosen:
        start = time.perf_counter()
        kwargs = {"steps": args.long_steps} if name == "long" else {}
        CASES[name](**kwargs)
        print(f"  ({time.perf_counter() - start:.1f} s)")
    print(f"all stress cases in {time.perf_counter() - total:.0f} s: no NaN reached an image")


if __name__ == "__main__":
    main()

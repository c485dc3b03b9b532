"""Error against run time for every integrator: per problem, and per image.

    PYTHONPATH=. python benchmarks/work_precision.py [--quick] [--only volterra,kerr,image]

(`make bench` runs it in full, `make bench QUICK=1` or `make bench-quick` with --quick.)

Problems (a batch of 128 distinct rays each, 16 in quick mode; error = max and median over
the rays against a tight reference, wall time of ``core.integrate``; full mode integrates 8
copies of the batch at once, 1024 rays, so that per-call overhead weighs as in a render's
chunks):

- ``volterra``: H = pq(p + q - 1) to t = 1000 (about 88 periods); reference: scipy DOP853,
  rtol = atol = 1e-13, on the hand-written equations. Error: |(q, p) - reference|.
- ``schwarzschild``: rays from r = 30 rg with impact b = b_c (1 + d), d in [1e-4, 1e-2],
  around the hole and back out to r = 30 rg; reference: the orbit integrals in closed form
  (mpmath quadrature). Error: |phi - phi_exact(r)| at the ray's final r.
- ``kerr``: a/M = 0.998 (Boyer–Lindquist), rays turning inside the photon region (constants
  of spherical photon orbits scaled by 1 + e, e in [1e-3, 1e-1]); reference: DOP853 at
  rtol = 1e-12 (time ds = Delta/r^2 dlambda). Error: angle between positions on the sky at
  the final r.
- ``mirage``: the seed's Eq. 17 medium (literal form), rays from an eye 0.4 m high at
  -0.05 .. -0.01 rad to x = 20 m; reference: DOP853, rtol = 1e-13. Error: position (m).

Modes: ``fixed`` (steps in s of S/steps, S the reference length), ``poincare`` (fixed steps in
the Poincaré time tau, adaptive in s: black holes only; the media and Volterra have g = 1),
and dopri5 with tolerances (``tol``).

Image: the README's Kerr scene (a/M = 0.9, camera at 30 rg, a red sphere behind the hole)
at 256x256 (--quick: 64x64, fewer methods and tolerances), traced with core's Tracer.
Error: pixel displacement = angle between a pixel's escape direction and the reference's,
over the pixel's angular size (escaped rays; pixels whose ending differs are counted).
The renderer always steps in Poincaré time; ``dopri5_adaptive`` adds per-ray embedded error
control inside each of the tracer's steps.

Writes out/bench/work_precision.csv, out/bench/wp_<problem>.png, out/bench/throughput.csv,
out/bench/image_error.csv and out/bench/image_error.png, and prints the verdicts.
"""

from __future__ import annotations

import argparse
import csv
import math
import os
import time
from dataclasses import dataclass, fields

import image_precision
import numpy as np

import core
from core import hamiltonians as hm
from core.integrators import Dopri5, Method, Splitting
from core.presets import MIRAGE_EQ17_INDEX
from core.trace import TraceOptions, Tracer

OUT = os.path.join("out", "bench")
RG, M = 1.0, 0.5
ALL_METHODS = tuple(
    name
    for name, method in core.METHODS.items()
    if not method.adaptive and not isinstance(method, Splitting)
)
"""The fixed-step methods of the registry (dopri5 runs on tolerances; the splittings need a
model's split: the image-level study, image_precision.py, compares them)."""
QUICK_METHODS = ("stormer_verlet", "gauss4", "yoshida4", "tao4", "rk4")
POINCARE_METHODS = (
    "stormer_verlet",
    "implicit_midpoint",
    "gauss4",
    "yoshida4",
    "yoshida6",
    "tao4",
    "rk4",
)
QUICK_POINCARE = ("gauss4", "yoshida4", "rk4")


# ----------------------------------------------------------------------------------
# problems

PROBLEM_INFO = {  # name: (error measure, accuracy levels of the verdict)
    "volterra": ("|(q, p) - ref|", (1e-3, 1e-6, 1e-9)),
    "schwarzschild": ("|phi - phi_exact(r)| (rad)", (1e-3, 1e-6, 1e-9)),
    "kerr": ("angle on the sky at r (rad)", (1e-3, 1e-6, 1e-9)),
    "mirage": ("|position - ref| (m)", (1e-4, 1e-7, 1e-10)),
}


@dataclass
class Problem:
    """A batch of rays, the reference lengths S (in s) and T (in tau), and an error measure."""

    name: str
    H: object
    q0: np.ndarray
    p0: np.ndarray
    S: np.ndarray
    T: np.ndarray | None
    error: object  # (q, p) final states -> per-ray error
    steps: tuple  # step counts tried, ascending
    tols: tuple  # dopri5 tolerances tried (error measure, levels:
    # PROBLEM_INFO)


def _dop853(rhs, y0, t_end, rtol):
    """scipy DOP853 with dense output on a stacked system (one time for all rays)."""
    from scipy.integrate import solve_ivp

    sol = solve_ivp(rhs, (0.0, t_end), y0, method="DOP853", rtol=rtol, atol=rtol, dense_output=True)
    if not sol.success:
        raise RuntimeError(f"reference integration failed: {sol.message}")
    return sol


def volterra(n: int, t_end: float, quick: bool) -> Problem:
    """Volterra orbits H = pq(p + q - 1) to t_end; reference DOP853 on the explicit equations."""
    rng = np.random.default_rng(1)
    q0 = rng.uniform(0.06, 0.3, (n, 1))
    p0 = rng.uniform(0.06, 0.3, (n, 1))

    def rhs(t, y):
        q, p = y[:n], y[n:]
        return np.concatenate([q * (2 * p + q - 1), -p * (p + 2 * q - 1)])

    sol = _dop853(rhs, np.concatenate([q0[:, 0], p0[:, 0]]), t_end, 1e-13)
    ref = sol.y[:, -1]
    qr, pr = ref[:n], ref[n:]

    def error(q, p):
        return np.hypot(q[:, 0] - qr, p[:, 0] - pr)

    steps = tuple(2000 * 2**k for k in range(0, 4 if quick else 7))  # h = 0.5 (Fig. 4) down
    return Problem(
        "volterra",
        hm.from_expression("p*q*(p + q - 1)", q=["q"], p=["p"]),
        q0,
        p0,
        np.full(n, t_end),
        None,
        error,
        steps,
        (1e-4, 1e-6, 1e-8, 1e-10) if quick else (1e-3, 1e-5, 1e-7, 1e-9, 1e-11),
    )


def _schwarzschild_integrals(b: float, r0: float):
    """(phi, S, T) from r0 in to the turning point of a ray of impact b (E = 1, rg = 1),
    and dphi/dr at r0: the orbit integrals over u = 1/r, with u = u_max - w^2."""
    import mpmath as mp

    mp.mp.dps = 30
    b = mp.mpf(b)

    def G(u):
        return 1 / b**2 - u**2 + RG * u**3

    roots = np.roots([RG, -1.0, 0.0, 1.0 / float(b) ** 2])
    real = np.sort(roots.real[(np.abs(roots.imag) < 1e-9) & (roots.real > 0)])
    umax = mp.findroot(G, mp.mpf(real[0]))
    u0 = 1 / mp.mpf(r0)
    w0 = mp.sqrt(umax - u0)
    d1 = 2 * umax - 3 * RG * umax**2  # -G'(umax) > 0
    d2 = -1 + 3 * RG * umax  # G''(umax) / 2

    def integral(weight):
        # G(umax - x) = x (d1 + d2 x - rg x^2) exactly: the 1/sqrt endpoint cancels
        def f(w):
            x = w * w
            return 2 * weight(umax - x) / mp.sqrt(d1 + d2 * x - RG * x * x)

        return mp.quad(f, [0, min(mp.sqrt(d1), w0 / 2), w0])

    phi = integral(lambda u: 1)
    S = integral(lambda u: 1 / (u * u * b))
    T = integral(lambda u: 1 / (u * (1 - RG * u) * b))
    dphi_dr = u0**2 / mp.sqrt(G(u0))
    return float(phi), float(S), float(T), float(dphi_dr)


def schwarzschild(n: int, quick: bool, r0: float = 30.0) -> Problem:
    """Rays near the critical impact parameter, in and out to r0 (exact orbit integrals)."""
    bc = 1.5 * math.sqrt(3.0) * RG
    b = bc * (1 + np.logspace(-4, -2, n))
    ints = np.array([_schwarzschild_integrals(bi, r0) for bi in b])
    phi_end, S, T, dphi = 2 * ints[:, 0], 2 * ints[:, 1], 2 * ints[:, 2], ints[:, 3]
    f = 1 - RG / r0
    q0 = np.stack([np.zeros(n), np.full(n, r0), np.full(n, np.pi / 2), np.zeros(n)], 1)
    p0 = np.stack([-np.ones(n), -np.sqrt(1 / f**2 - b**2 / (f * r0**2)), np.zeros(n), b], 1)

    def error(q, p):
        exact = phi_end + dphi * (q[:, 1] - r0)
        err = np.hypot(q[:, 3] - exact, q[:, 2] - np.pi / 2)
        return np.where(p[:, 1] > 0, err, np.pi)  # not on its way out: off by half a turn

    steps = tuple(64 * 2**k for k in range(0, 8 if quick else 11))
    return Problem(
        "schwarzschild",
        hm.schwarzschild(rg=RG),
        q0,
        p0,
        S,
        T,
        error,
        steps,
        (1e-4, 1e-6, 1e-8, 1e-10) if quick else (1e-3, 1e-5, 1e-7, 1e-9, 1e-11),
    )


def _kerr_rays(n: int, a: float, r0: float):
    """(q0, p0) of rays from r0 turning inside the photon region (Bardeen's R, Theta)."""
    rng = np.random.default_rng(2)
    pro = 2 * M * (1 + math.cos(2 / 3 * math.acos(-a / M)))
    retro = 2 * M * (1 + math.cos(2 / 3 * math.acos(a / M)))
    r = pro + rng.uniform(0.1, 0.9, n) * (retro - pro)
    delta = r * r - 2 * M * r + a * a
    xi = (M * (r * r - a * a) - r * delta) / (a * (r - M))
    eta = r**3 * (4 * M * delta - r * (r - M) ** 2) / (a * a * (r - M) ** 2)
    scale = 1 + np.logspace(-3, -1, n)
    xi, eta = xi * scale, eta * scale**2
    d0 = r0 * r0 - 2 * M * r0 + a * a
    R = (r0 * r0 + a * a - a * xi) ** 2 - d0 * (eta + (xi - a) ** 2)
    q0 = np.stack([np.zeros(n), np.full(n, r0), np.full(n, np.pi / 2), np.zeros(n)], 1)
    p0 = np.stack([-np.ones(n), -np.sqrt(R) / d0, -np.sqrt(eta), xi], 1)
    return q0, p0


def kerr(n: int, quick: bool, a: float = 0.499, r0: float = 30.0) -> Problem:
    """a/M = 0.998 rays through the photon region, in and out to r0; DOP853 reference."""
    H = hm.kerr(rg=RG, a=a)
    q0, p0 = _kerr_rays(n, a, r0)

    def rhs(t, y):
        # reference time lambda with d s / d lambda = Delta / r^2 (-> 1 far out, so that rays
        # that are out early do not run away exponentially); tau of the Poincaré runs
        # (g = Delta / r) is carried along: d tau / d lambda = 1 / r
        q, p = y[: 4 * n].reshape(n, 4), y[4 * n : 8 * n].reshape(n, 4)
        dq, dp = H.gradient(q, p)
        r = q[:, 1]
        gg = ((r * r - RG * r + a * a) / (r * r))[:, None]
        return np.concatenate([(gg * dp).ravel(), (-gg * dq).ravel(), gg[:, 0], 1.0 / r])

    y0 = np.concatenate([q0.ravel(), p0.ravel(), np.zeros(2 * n)])
    sol = _dop853(rhs, y0, 400.0, 1e-12)
    lam = np.array([_last_crossing(sol, i, n, r0) for i in range(n)])
    ends = np.array([sol.sol(t) for t in lam])  # (n, 10n)
    rows = np.arange(n)
    q_ref = ends[rows][:, : 4 * n].reshape(n, n, 4)[rows, rows]
    p_ref = ends[rows][:, 4 * n : 8 * n].reshape(n, n, 4)[rows, rows]
    S = ends[rows, 8 * n + rows]
    T = ends[rows, 9 * n + rows]
    _, vel = H.gradient(q_ref, p_ref)  # dq/ds
    dth, dph = vel[:, 2] / vel[:, 1], vel[:, 3] / vel[:, 1]

    def error(q, p):
        dr = q[:, 1] - q_ref[:, 1]
        th = q[:, 2] - (q_ref[:, 2] + dth * dr)
        ph = q[:, 3] - (q_ref[:, 3] + dph * dr)
        err = np.hypot(th, np.sin(q_ref[:, 2]) * ph)
        return np.where(p[:, 1] > 0, err, np.pi)

    steps = tuple(128 * 2**k for k in range(0, 7 if quick else 10))
    return Problem(
        "kerr",
        H,
        q0,
        p0,
        S,
        T,
        error,
        steps,
        (1e-4, 1e-6, 1e-8, 1e-10) if quick else (1e-3, 1e-5, 1e-7, 1e-9, 1e-11),
    )


def _last_crossing(sol, i: int, n: int, r0: float) -> float:
    """Time at which ray i comes back out through r = r0 (dense output, then brentq)."""
    from scipy.optimize import brentq

    taus = np.linspace(0.0, sol.t[-1], 20001)
    r = sol.sol(taus)[4 * i + 1]
    up = np.flatnonzero((r[:-1] < r0) & (r[1:] >= r0))
    if up.size == 0:
        raise RuntimeError(f"kerr reference: ray {i} does not come back out to r = {r0}")
    k = up[-1]
    return brentq(lambda t: sol.sol(t)[4 * i + 1] - r0, taus[k], taus[k + 1], xtol=1e-14)


def mirage(n: int, quick: bool, x_end: float = 20.0) -> Problem:
    """Seed Eq. 17 (literal H = n |p|^2 / 2): rays from 0.4 m, turned up above hot ground."""
    angles = np.random.default_rng(3).uniform(-0.05, -0.01, n)
    H = hm.medium(MIRAGE_EQ17_INDEX, literal=True)
    q0 = np.stack([np.zeros(n), np.zeros(n), np.full(n, 0.4)], 1)
    d = np.stack([np.cos(angles), np.zeros(n), np.sin(angles)], 1)
    p0 = d / np.sqrt(H.index_soa(q0.T))[:, None]

    def index(z):
        m = 1 + 0.003 * (1 - np.exp(-z / 0.15))
        return m**-2, -2 * m**-3 * 0.02 * np.exp(-z / 0.15)

    def rhs(t, y):
        q, p = y[: 3 * n].reshape(n, 3), y[3 * n :].reshape(n, 3)
        nz, dn = index(q[:, 2])
        dp = np.zeros_like(p)
        dp[:, 2] = -0.5 * dn * np.einsum("ij,ij->i", p, p)
        return np.concatenate([(nz[:, None] * p).ravel(), dp.ravel()])

    sol = _dop853(rhs, np.concatenate([q0.ravel(), p0.ravel()]), 1.2 * x_end, 1e-13)
    S = np.array([_crossing_x(sol, i, x_end) for i in range(n)])
    q_ref = np.array([sol.sol(s)[3 * i : 3 * i + 3] for i, s in enumerate(S)])

    def error(q, p):
        return np.linalg.norm(q - q_ref, axis=1)

    steps = tuple(25 * 2**k for k in range(0, 7 if quick else 10))
    return Problem(
        "mirage",
        H,
        q0,
        p0,
        S,
        None,
        error,
        steps,
        (1e-4, 1e-6, 1e-8, 1e-10) if quick else (1e-3, 1e-5, 1e-7, 1e-9, 1e-11),
    )


def _crossing_x(sol, i: int, x_end: float) -> float:
    """s at which ray i reaches x = x_end."""
    from scipy.optimize import brentq

    return brentq(lambda s: sol.sol(s)[3 * i] - x_end, 0.5 * x_end, sol.t[-1], xtol=1e-14)


# ----------------------------------------------------------------------------------
# runs


@dataclass
class Run:
    """One (method, mode, parameter) point of a work-precision curve."""

    problem: str
    method: str
    mode: str
    param: float
    rays: int
    steps_per_ray: float
    seconds: float
    error_max: float
    error_median: float
    energy_drift: float
    failed: int

    @property
    def label(self) -> str:
        """method/mode as plotted."""
        return self.method if self.mode in ("fixed", "tol") else f"{self.method}/{self.mode}"

    @property
    def ns_per_ray_step(self) -> float:
        """Wall time per ray and step (accepted step for dopri5), ns."""
        return 1e9 * self.seconds / max(self.rays * self.steps_per_ray, 1)


def run_one(prob: Problem, method: str, mode: str, param, copies: int = 1) -> Run:
    """Integrate `copies` copies of the problem's batch at once; measure error and time.

    Copies make the batch as wide as a render's chunk (per-call overhead then weighs as it
    does there); every copy is checked against the reference.
    """
    n = len(prob.S)
    kw = dict(energy_every=0)
    S, T = np.tile(prob.S, copies), None if prob.T is None else np.tile(prob.T, copies)
    if mode == "tol":
        kw.update(step=S, steps=1, tol=param, max_steps=2_000_000)
    elif mode == "poincare":
        kw.update(step=T / param, steps=int(param), adaptive=True)
    else:
        kw.update(step=S / param, steps=int(param))
    q0, p0 = np.tile(prob.q0, (copies, 1)), np.tile(prob.p0, (copies, 1))
    start = time.perf_counter()
    with np.errstate(all="ignore"):
        res = core.integrate(prob.H, q0, p0, method=method, **kw)
    seconds = time.perf_counter() - start
    with np.errstate(all="ignore"):
        err = np.concatenate(
            [
                prob.error(res.q[k * n : (k + 1) * n], res.p[k * n : (k + 1) * n])
                for k in range(copies)
            ]
        )
    err = np.where(np.asarray(res.failed) | ~np.isfinite(err), np.inf, err)
    return Run(
        prob.name,
        method,
        mode,
        float(param),
        len(err),
        float(np.mean(res.steps)),
        seconds,
        float(np.max(err)),
        float(np.median(err)),
        float(np.nanmax(res.energy_error)),
        int(np.sum(res.failed)),
    )


def curve(
    prob: Problem, method: str, mode: str, budget: float, copies: int = 1, floor: float = 1e-13
):
    """Runs of one method/mode over the problem's steps (or tolerances) within a time budget."""
    params = prob.tols if mode == "tol" else prob.steps
    runs, spent = [], 0.0
    for param in params:
        if runs and runs[-1].seconds * (2.2 if mode != "tol" else 3.0) > budget - spent:
            break
        run = run_one(prob, method, mode, param, copies)
        runs.append(run)
        spent += run.seconds
        print(
            f"  {prob.name:13s} {run.label:24s} {mode:8s} {param:>9g}: error {run.error_max:9.2e}"
            f" in {run.seconds:7.3f} s ({run.ns_per_ray_step:8.0f} ns/ray-step)"
            + (f", {run.failed} failed" if run.failed else ""),
            flush=True,
        )
        if run.error_max < floor:
            break
    return runs


def throughput(prob: Problem, methods, batch: int = 4096, steps: int = 20) -> dict:
    """ns per ray-step (dopri5: per accepted step) of each method on `batch` copies of the
    problem's rays (the cost of a step hardly depends on where a ray is)."""
    reps = -(-batch // len(prob.S))
    q0, p0 = np.tile(prob.q0, (reps, 1))[:batch], np.tile(prob.p0, (reps, 1))[:batch]
    h = np.tile(prob.S, reps)[:batch] / prob.steps[len(prob.steps) // 2]  # mid-curve step
    out = {}
    for m in methods:
        start = time.perf_counter()
        with np.errstate(all="ignore"):
            res = core.integrate(prob.H, q0, p0, step=h, steps=steps, method=m, energy_every=0)
        out[m] = 1e9 * (time.perf_counter() - start) / max(int(np.sum(res.steps)), 1)
    return out


def cheapest(runs: list[Run], level: float, key: str = "error_max"):
    """{label: seconds} to reach error <= level, log-log interpolated along each curve."""
    best = {}
    for label in dict.fromkeys(r.label for r in runs):
        # a run with failed rays reaches no level (their energy is NaN, not counted in the drift)
        pts = sorted(
            (r.seconds, getattr(r, key) if not r.failed else math.inf)
            for r in runs
            if r.label == label
        )
        prev = None
        for t, e in pts:
            if e <= level:
                best[label] = t
                if prev is not None and math.isfinite(prev[1]) and e > 0:
                    w = math.log(prev[1] / level) / math.log(prev[1] / e)
                    best[label] = math.exp((1 - w) * math.log(prev[0]) + w * math.log(t))
                break
            prev = (t, e)
    return best


ENERGY_LEVELS = {"volterra": (1e-6, 1e-9, 1e-12)}
"""|H - H0| levels of the energy verdict (the seed's claim for long runs: bounded H)."""
_WHAT = {"error_max": "max error", "error_median": "median error", "energy_drift": "max |H - H0|"}


def verdicts(name: str, runs: list[Run]) -> list[str]:
    """The verdicts of one problem: max and median error, and energy where it is judged."""
    out = verdict(name, runs) + verdict(name, runs, "error_median")
    if name in ENERGY_LEVELS:
        out += verdict(name, runs, "energy_drift", ENERGY_LEVELS[name])
    return out


def verdict(name: str, runs: list[Run], key: str = "error_max", levels=None) -> list[str]:
    """Lines naming the cheapest method at each accuracy level (and the best of each kind)."""
    lines = []
    symplectic = {m for m, obj in core.METHODS.items() if obj.symplectic}
    for level in levels or PROBLEM_INFO[name][1]:
        best = cheapest(runs, level, key)
        head = f"  {name}: {_WHAT[key]} <= {level:g}:"
        if not best:
            lines.append(f"{head} reached by no method within the budget")
            continue
        ranked = sorted(best.items(), key=lambda kv: kv[1])
        sym = [kv for kv in ranked if kv[0].split("/")[0] in symplectic]
        non = [kv for kv in ranked if kv[0].split("/")[0] not in symplectic]
        text = f"{head} cheapest {ranked[0][0]} {ranked[0][1]:.3g} s"
        if sym and non:
            s, n = sym[0], non[0]
            who = "symplectic wins" if s[1] < n[1] else "symplectic does NOT win"
            text += (
                f"; best symplectic {s[0]} {s[1]:.3g} s vs best non-symplectic {n[0]} "
                f"{n[1]:.3g} s ({who}, x{max(s[1], n[1]) / min(s[1], n[1]):.2g})"
            )
        elif non:
            text += "; no symplectic method got there within the budget"
        else:
            text += "; no non-symplectic method got there within the budget"
        lines.append(text)
    return lines


def plot_problem(name: str, runs: list[Run], path: str) -> None:
    """Log-log error (max and median over the rays) against wall time, a line per method."""
    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=(15, 6), sharex=True, sharey=True)
    for ax, key, what in zip(axes, ("error_max", "error_median"), ("max", "median"), strict=True):
        for k, label in enumerate(dict.fromkeys(r.label for r in runs)):
            pts = [(r.seconds, min(getattr(r, key), 10.0)) for r in runs if r.label == label]
            style = "--" if "/" in label else ("-." if label == "dopri5" else "-")
            ax.loglog(
                *zip(*pts, strict=True),
                style,
                marker="o",
                ms=3,
                color=plt.get_cmap("tab20")(k % 20),
                label=label,
            )
        ax.set(
            xlabel="wall time (s)",
            ylabel=f"{what} error over the rays: {PROBLEM_INFO[name][0]}",
            title=f"{name}: {what} over the rays (failed or > 10: drawn at 10)",
        )
        _plain_ticks(ax)
        ax.grid(True, which="major", alpha=0.3)
    axes[0].legend(fontsize=7, ncol=2)
    fig.savefig(path, dpi=100, bbox_inches="tight")
    plt.close(fig)


def _plain_ticks(ax) -> None:
    """No minor tick labels on the log time axis (they overlap)."""
    from matplotlib.ticker import NullFormatter

    ax.xaxis.set_minor_formatter(NullFormatter())


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


# ----------------------------------------------------------------------------------
# image level


class AdaptiveDopri5(Method):
    """dopri5 with per-ray embedded error control inside each of the tracer's steps.

    A step of length h (Poincaré time) is covered by as many accepted dopri5 sub-steps as
    each ray needs for rtol = atol = tol; a ray that needs more than max_sub is not ok.
    """

    name, order, symplectic = "dopri5_adaptive", 5, False

    def __init__(self, tol: float = 1e-8, max_sub: int = 400):
        super().__init__(tol=tol, max_sub=max_sub)
        self.rk = Dopri5(rtol=tol, atol=tol)
        self.max_sub = max_sub

    def init(self, H, Q, P):
        """(Z, f(Z), last step size per ray)."""
        Z, F = self.rk.init(H, Q, P)
        return Z, F, np.full(Z.shape[1], np.inf)

    def qp(self, state):
        """Positions and momenta."""
        return self.rk.qp(state[:2])

    def step(self, H, state, h):
        """Cover h by accepted sub-steps, per ray."""
        Z, F, last = (a.copy() for a in state)
        left = np.full(Z.shape[1], float(h))
        for _ in range(self.max_sub):
            idx = np.flatnonzero(left > 0)
            if idx.size == 0:
                break
            hh = np.minimum(last[idx], left[idx])
            sub = H.subset(idx) if hasattr(H, "subset") else H
            (Z1, F1), err, fin = self.rk.attempt(sub, (Z[:, idx], F[:, idx]), hh)
            acc = fin & (err <= 1.0)
            Z[:, idx[acc]], F[:, idx[acc]] = Z1[:, acc], F1[:, acc]
            left[idx[acc]] = np.where(hh[acc] >= left[idx[acc]], 0.0, left[idx[acc]] - hh[acc])
            last[idx] = hh * self.rk.factor(err)
            left[idx[hh < 1e-14 * abs(h)]] = -1.0  # step size collapsed: give up on the ray
        ok = (left == 0.0) & np.isfinite(Z).all(axis=0)
        return (Z, F, last), ok


def trace_image(
    size: int, method, tolerance: float, step=None, region_radius=None, chunk: int = 8192
):
    """Trace every pixel of the Kerr scene; -> (ending, direction, steps, seconds)."""
    scene = image_precision.kerr_scene()
    cam = core.Camera.perspective(
        position=(0, -30, 2), look_at=(0, 0, 0), up=(0, 0, 1), fov_deg=40, width=size, height=size
    )
    extent = float(np.linalg.norm(cam.frame.position - scene.center))
    options = TraceOptions(
        method=method, tolerance=tolerance, step=step, region_radius=region_radius
    )
    tracer = Tracer(scene, options, extent)
    n = cam.n_pixels
    ending, steps = np.empty(n, np.int8), np.empty(n, np.int64)
    direction = np.empty((n, 3))
    start = time.perf_counter()
    for a in range(0, n, chunk):
        b = min(a + chunk, n)
        origins, dirs = cam.rays(a, b)
        with np.errstate(all="ignore"):
            r = tracer.trace(origins, dirs)
        ending[a:b], steps[a:b], direction[a:b] = r.ending, r.steps, r.direction
    return ending, direction, steps, time.perf_counter() - start


def displacement(ref, run, pixel: float):
    """(pixel displacement of escaped rays (K,), pixels whose ending differs)."""
    both = (ref[0] == core.ENDING["escaped"]) & (run[0] == core.ENDING["escaped"])
    u, v = ref[1][both], run[1][both]
    cross = np.linalg.norm(np.cross(u, v), axis=1)
    ang = np.arctan2(cross, np.einsum("ij,ij->i", u, v))
    return ang / pixel, int(np.count_nonzero(ref[0] != run[0]))


IMAGE_REF = ("dopri5", 1e-11)
REGION = 2000.0
"""Region radius (rg) of every image run and of the reference: the far-field approximation
beyond it is then common to all, and the displacement measures the integration alone."""


def image_reference(size: int, out: str):
    """The tight reference render (cached in out/bench/image_ref_<size>.npz)."""
    path = os.path.join(out, f"image_ref_{size}.npz")
    key = f"{IMAGE_REF[0]} {IMAGE_REF[1]:g} {REGION:g}"
    if os.path.exists(path):
        data = np.load(path)
        if "key" in data.files and str(data["key"]) == key:
            print(f"  reference {key} from {path} ({float(data['seconds']):.1f} s)")
            return (data["ending"], data["direction"]), float(data["seconds"])
    print(f"  reference render ({key}) at {size}x{size} ...", flush=True)
    e, d, s, sec = trace_image(size, *IMAGE_REF, region_radius=REGION)
    np.savez(path, ending=e, direction=d, steps=s, seconds=sec, key=key)
    print(f"  reference: {sec:.1f} s, {s.sum()} steps")
    return (e, d), sec


def image_runs(quick: bool):
    """(label, method name or class, tolerances, outer step, region radius) to compare."""
    if quick:
        return [
            ("rk4", "rk4", (1e-3, 1e-5, 1e-7), None, REGION),
            ("gauss4", "gauss4", (1e-5, 1e-7), None, REGION),
            ("yoshida4", "yoshida4", (1e-4, 1e-6), None, REGION),
            ("dopri5", "dopri5", (1e-4, 1e-6, 1e-8), None, REGION),
            ("dopri5_adaptive", AdaptiveDopri5, (1e-4, 1e-8), 0.1, REGION),
            ("rk4, default region", "rk4", (1e-4, 1e-6, 1e-8), None, None),
        ]
    return [
        ("rk4", "rk4", (1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8), None, REGION),
        ("gauss4", "gauss4", (1e-4, 1e-5, 1e-6, 1e-7, 1e-8), None, REGION),
        ("yoshida4", "yoshida4", (1e-4, 1e-6, 1e-8), None, REGION),
        ("yoshida6", "yoshida6", (1e-4, 1e-6), None, REGION),
        ("dopri5", "dopri5", (1e-4, 1e-5, 1e-6, 1e-7, 1e-8), None, REGION),
        ("dopri5_adaptive", AdaptiveDopri5, (1e-4, 1e-6, 1e-8, 1e-10), 0.1, REGION),
        ("rk4, default region", "rk4", (1e-4, 1e-6, 1e-8), None, None),
    ]


def image_level(size: int, quick: bool, out: str):
    """Image error (pixel displacement) against trace time; CSV rows and a plot."""
    pixel = math.radians(40.0) / size
    ref, ref_seconds = image_reference(size, out)
    rows = []
    for label, method, tols, step, region in image_runs(quick):
        for tol in tols:
            meth = method(tol=tol) if isinstance(method, type) else method
            e, d, s, sec = trace_image(size, meth, tol, step, region)
            disp, mismatched = displacement(ref, (e, d), pixel)
            row = dict(
                method=label,
                tolerance=tol,
                size=size,
                region_rg=region or "default",
                seconds=round(sec, 3),
                steps=int(s.sum()),
                ns_per_ray_step=round(1e9 * sec / max(s.sum(), 1)),
                disp_median_px=float(np.median(disp)),
                disp_p99_px=float(np.percentile(disp, 99)),
                disp_max_px=float(disp.max()),
                mismatched_pixels=mismatched,
                failed=int(np.count_nonzero(e == core.ENDING["failed"])),
            )
            rows.append(row)
            print(
                f"  image {label:16s} tol {tol:7.0e}: {sec:7.1f} s, displacement median "
                f"{row['disp_median_px']:.2e} p99 {row['disp_p99_px']:.2e} max "
                f"{row['disp_max_px']:.2e} px, {mismatched} pixels end differently, "
                f"{row['failed']} failed",
                flush=True,
            )
    image_precision.write_csv(os.path.join(out, "image_error.csv"), rows)
    _plot_image(rows, size, os.path.join(out, "image_error.png"))
    return rows, ref_seconds


def _plot_image(rows, size: int, path: str) -> None:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(8, 5.5))
    for k, label in enumerate(dict.fromkeys(r["method"] for r in rows)):
        rr = [r for r in rows if r["method"] == label]
        t = [r["seconds"] for r in rr]
        ax.loglog(
            t,
            [max(r["disp_max_px"], 1e-8) for r in rr],
            "-o",
            ms=3,
            color=f"C{k}",
            label=f"{label}",
        )
        ax.loglog(t, [max(r["disp_p99_px"], 1e-8) for r in rr], ":", color=f"C{k}", lw=0.8)
    ax.set(
        xlabel="trace time (s)",
        ylabel="pixel displacement against the reference (px)",
        title=f"Kerr a/M = 0.9 scene, {size}x{size}: solid = max over pixels, dotted = "
        "99th percentile",
    )
    _plain_ticks(ax)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)


def _image_verdict(rows) -> list[str]:
    """Cheapest run with 99 % of pixels within 0.1, 0.01, 0.001 px and at most 1e-4 of the
    pixels ending differently (the max is set by a few pixels on the shadow's edge)."""
    lines = []
    for level in (0.1, 0.01, 0.001):
        ok = [
            r
            for r in rows
            if r["disp_p99_px"] <= level
            and r["region_rg"] != "default"
            and r["mismatched_pixels"] <= 1e-4 * r["size"] ** 2
        ]
        if ok:
            r = min(ok, key=lambda r: r["seconds"])
            lines.append(
                f"  image: 99% of pixels within {level:g} px: cheapest {r['method']} "
                f"at tolerance {r['tolerance']:g}, {r['seconds']:.1f} s (max "
                f"{r['disp_max_px']:.2g} px)"
            )
        else:
            lines.append(f"  image: 99% of pixels within {level:g} px: no run got there")
    return lines


# ----------------------------------------------------------------------------------
# main


def _kept_rows(path: str, rerun: set) -> list[dict]:
    """Rows of an existing CSV whose problem is not in `rerun` (an --only run keeps them)."""
    if not os.path.exists(path):
        return []
    with open(path) as f:
        return [row for row in csv.DictReader(f) if row["problem"] not in rerun]


def build_problems(names, quick: bool):
    """The chosen problems (batch size 16 in quick mode, 128 otherwise)."""
    n = 16 if quick else 128
    makers = {
        "volterra": lambda: volterra(n, 300.0 if quick else 1000.0, quick),
        "schwarzschild": lambda: schwarzschild(n, quick),
        "kerr": lambda: kerr(n, quick),
        "mirage": lambda: mirage(n, quick),
    }
    return [makers[name]() for name in names if name in makers]


def run_problem(prob: Problem, quick: bool, budget: float, copies: int) -> list[Run]:
    """All method/mode curves of one problem."""
    methods = QUICK_METHODS if quick else ALL_METHODS
    runs = []
    for m in methods:
        runs += curve(prob, m, "fixed", budget, copies)
    runs += curve(prob, "dopri5", "tol", budget, copies)
    if prob.T is not None:
        for m in QUICK_POINCARE if quick else POINCARE_METHODS:
            runs += curve(prob, m, "poincare", budget, copies)
    return runs


def main(argv: list[str] | None = None) -> None:
    """Run the chosen parts and write CSVs, plots and verdicts under --out."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--quick", action="store_true", help="fewer methods, steps and rays; a 64x64 image"
    )
    parser.add_argument("--only", default="volterra,schwarzschild,kerr,mirage,image")
    parser.add_argument(
        "--budget",
        type=float,
        default=None,
        help="seconds per method curve (default 3 quick, 25 full)",
    )
    parser.add_argument("--image-size", type=int, default=None)
    parser.add_argument(
        "--copies",
        type=int,
        default=None,
        help="copies of each problem's rays per timed batch (default 1 "
        "quick, 8 full: 1024 rays, a render chunk's regime)",
    )
    parser.add_argument("--out", default=OUT)
    parser.add_argument(
        "--from-csv",
        action="store_true",
        help="only redraw the plots and verdicts from the CSVs in --out",
    )
    args = parser.parse_args(argv)
    os.makedirs(args.out, exist_ok=True)
    if args.from_csv:
        return replot(args.out)
    names = [n for n in args.only.split(",") if n]
    budget = args.budget or (3.0 if args.quick else 25.0)
    copies = args.copies or (1 if args.quick else 8)
    mode = (
        "QUICK mode: 16 rays, fewer methods and steps, 64x64 image"
        if args.quick
        else f"full mode: 128 rays x {copies} copies, every method, 256x256 image"
    )
    print(f"work-precision ({mode}; budget {budget:g} s per curve)")
    start = time.perf_counter()
    all_runs, found, tput = [], [], []
    for prob in build_problems(names, args.quick):
        print(f"{prob.name}: {len(prob.S)} rays, S = {prob.S.min():.4g} .. {prob.S.max():.4g}")
        runs = run_problem(prob, args.quick, budget, copies)
        all_runs += runs
        plot_problem(prob.name, runs, os.path.join(args.out, f"wp_{prob.name}.png"))
        found += verdicts(prob.name, runs)
        methods = (QUICK_METHODS if args.quick else ALL_METHODS) + ("dopri5",)
        for m, ns in throughput(prob, methods, batch=1024 if args.quick else 4096).items():
            tput.append(dict(problem=prob.name, method=m, ns_per_ray_step=round(ns, 1)))
    if all_runs:
        rerun = {r.problem for r in all_runs}  # other problems' rows in the CSVs are kept
        image_precision.write_csv(
            os.path.join(args.out, "work_precision.csv"),
            _kept_rows(os.path.join(args.out, "work_precision.csv"), rerun)
            + [
                dict(vars(r), label=r.label, ns_per_ray_step=round(r.ns_per_ray_step, 1))
                for r in all_runs
            ],
        )
        tput = _kept_rows(os.path.join(args.out, "throughput.csv"), rerun) + tput
        image_precision.write_csv(os.path.join(args.out, "throughput.csv"), tput)
        _print_throughput(tput)
    if "image" in names:
        size = args.image_size or (64 if args.quick else 256)
        print(
            f"image: Kerr scene {size}x{size}"
            + (" (QUICK mode: 64x64, fewer methods and tolerances)" if args.quick else "")
        )
        rows, _ = image_level(size, args.quick, args.out)
        found += _image_verdict(rows)
        print("image: Schwarzschild, mirage and Kerr scenes (benchmarks/image_precision.py)")
        scenes = ["schwarzschild", "mirage", "kerr", "kerr998"]
        found += image_precision.run_scenes(scenes, args.quick, args.out)
    print("verdict (cheapest method at each accuracy):")
    print("\n".join(found))
    print(f"done in {time.perf_counter() - start:.0f} s; results in {args.out}/")


def replot(out: str) -> None:
    """Plots, tables and verdicts again from work_precision.csv, throughput.csv and
    image_error.csv in `out` (no integration)."""
    found = []
    path = os.path.join(out, "work_precision.csv")
    if os.path.exists(path):
        names = [f.name for f in fields(Run)]
        with open(path) as f:
            runs = [
                Run(
                    **{
                        k: (
                            v
                            if k in ("problem", "method", "mode")
                            else int(v)
                            if k in ("rays", "failed")
                            else float(v)
                        )
                        for k, v in row.items()
                        if k in names
                    }
                )
                for row in csv.DictReader(f)
            ]
        for name in dict.fromkeys(r.problem for r in runs):
            mine = [r for r in runs if r.problem == name]
            plot_problem(name, mine, os.path.join(out, f"wp_{name}.png"))
            found += verdicts(name, mine)
    path = os.path.join(out, "throughput.csv")
    if os.path.exists(path):
        with open(path) as f:
            _print_throughput(list(csv.DictReader(f)))
    path = os.path.join(out, "image_error.csv")
    if os.path.exists(path):
        with open(path) as f:
            rows = [
                {k: (v if k in ("method", "region_rg") else float(v)) for k, v in r.items()}
                for r in csv.DictReader(f)
            ]
        _plot_image(rows, int(rows[0]["size"]), os.path.join(out, "image_error.png"))
        found += _image_verdict(rows)
    print("verdict (cheapest method at each accuracy):")
    print("\n".join(found))


def _print_throughput(rows) -> None:
    problems = list(dict.fromkeys(r["problem"] for r in rows))
    methods = list(dict.fromkeys(r["method"] for r in rows))
    table = {(r["problem"], r["method"]): float(r["ns_per_ray_step"]) for r in rows}
    print("ns per ray-step (batch of 4096 rays; 1024 in quick mode):")
    print(f"  {'method':18s}" + "".join(f"{p:>15s}" for p in problems))
    for m in methods:
        print(f"  {m:18s}" + "".join(f"{table.get((p, m), float('nan')):15.0f}" for p in problems))


if __name__ == "__main__":
    main()

"""`integrate`: the public driver (fixed steps, Poincaré-adaptive steps, or dopri5)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..checks import check_integrate_options
from ._common import Method
from .batch import Batch, run_batch
from .poincare import Clocked, PoincareTransformed
from .registry import get_method
from .system import CaptureTest, System, as_system


@dataclass
class Trajectory:
    """States recorded every `record_every` steps (the first is the initial state).

    s: (M, N) parameter reached, q and p: (M, N, n); for a single ray (M,), (M, n).
    Rays that ended keep their last state.
    """

    s: np.ndarray
    q: np.ndarray
    p: np.ndarray


@dataclass
class IntegrationResult:
    """Result of `integrate`; per-ray arrays are (N,), or scalars for a single ray."""

    q: np.ndarray  # final positions, shape of q0
    p: np.ndarray  # final momenta, shape of p0
    s: Any  # parameter reached (failed rays: where they stopped)
    energy_error: Any  # max |H - H(q0, p0)| seen
    failed: Any  # NaN/Inf, implicit solve not converged, step too small
    steps: Any  # steps taken (accepted steps for dopri5)
    trajectory: Trajectory | None = None
    captured: Any = None  # reached the model's horizon (frozen there, not failed)


class _Run:
    """Book-keeping of ``integrate``: the rays still going (a Batch: their state, the system
    and per-ray arrays) and the frozen outputs of the rays that ended.

    mode: "fixed" (s = steps * h), "clock" (s is the last coordinate of the clocked state)
    or "adaptive" (s tracked per ray in arrays["s"]).
    """

    def __init__(
        self,
        method: Method,
        H: Any,
        Henergy: Any,
        Q: np.ndarray,
        P: np.ndarray,
        n: int,
        E0: np.ndarray,
        mode: str,
        h: Any,
    ) -> None:
        N = Q.shape[1]
        self.method, self.n, self.mode = method, n, mode
        self.capture = capture_test(Henergy)
        self.per_ray_h = bool(np.ndim(h))
        self.out = {
            "q": Q[:n].copy(),
            "p": P[:n].copy(),
            "s": np.zeros(N),
            "err": np.zeros(N),
            "steps": np.zeros(N, dtype=np.int64),
            "failed": np.zeros(N, dtype=bool),
            "captured": np.zeros(N, dtype=bool),
        }
        arrays = {
            "act": np.arange(N),
            "s": np.zeros(N),
            "err": np.zeros(N),
            "E0": E0,
            "steps": np.zeros(N, dtype=np.int64),
            "h": np.broadcast_to(np.asarray(h, dtype=np.float64), (N,)).copy(),
        }
        self.fixed_h = None if self.per_ray_h else float(h)
        self.batch = Batch(method, method.init(H, Q, P), {"H": H, "energy": Henergy}, arrays)
        self.record_list: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []

    @property
    def live(self) -> dict[str, Any]:
        """Per-ray arrays of the rays still going."""
        return self.batch.arrays

    @property
    def h(self) -> Any:
        """The fixed step: one for all rays, or per ray."""
        return self.live["h"] if self.per_ray_h else self.fixed_h

    def s_now(self, state: Any = None) -> np.ndarray:
        """(M,) parameter of the rays still going (at ``state``, default the current one)."""
        if self.mode == "clock":
            return self.method.qp(self.batch.state if state is None else state)[0][-1]
        if self.mode == "fixed":
            return self.live["steps"] * self.live["h"]
        return self.live["s"]

    def freeze(self, mask: np.ndarray, failed: bool, captured: bool = False, state=None) -> None:
        """Record the outputs of the rays ``mask`` ((M,) bool) at ``state`` (default the
        current one); the batch drops them afterwards."""
        state = self.batch.state if state is None else state
        ids = self.live["act"][mask]
        Q, P = self.method.qp(state)
        out = self.out
        out["q"][:, ids] = Q[: self.n, mask]
        out["p"][:, ids] = P[: self.n, mask]
        out["s"][ids] = self.s_now(state)[mask]
        out["err"][ids] = self.live["err"][mask]
        out["steps"][ids] = self.live["steps"][mask]
        out["failed"][ids] = failed
        out["captured"][ids] = captured

    def retire(self, mask: np.ndarray, failed: bool) -> None:
        """Freeze the rays ``mask`` and drop them (outside the loop)."""
        self.freeze(mask, failed)
        self.batch.drop(mask)

    def energy_events(self, going: np.ndarray) -> np.ndarray:
        """Update max |H - H0| of the rays ``going``; -> those whose H is no longer finite
        (frozen as failed)."""
        Q, P = self.method.qp(self.batch.state)
        with np.errstate(all="ignore"):
            e = np.abs(
                self.batch.systems["energy"].value_soa(Q[: self.n], P[: self.n]) - self.live["E0"]
            )
        err = self.live["err"]
        err[going] = np.fmax(err[going], e[going])
        bad = going & ~np.isfinite(e)
        if bad.any():
            self.freeze(bad, failed=True)
        return bad

    def capture_events(self, going: np.ndarray) -> np.ndarray:
        """The rays ``going`` that crossed the model's capture surface (frozen as captured,
        not failed, with their energy error brought up to date)."""
        if self.capture is None:
            return np.zeros_like(going)
        inside = self._inside() & going
        if not inside.any():
            return inside
        bad = self.energy_events(going)
        inside = self._inside() & going & ~bad
        self.freeze(inside, failed=False, captured=True)
        return inside | bad

    def _inside(self) -> np.ndarray:
        assert self.capture is not None
        with np.errstate(all="ignore"):
            return np.asarray(self.capture(self.method.qp(self.batch.state)[0][: self.n]))

    def record(self, going: np.ndarray | None = None) -> None:
        """Append every ray's state to the trajectory (ended rays: as frozen)."""
        going = np.ones(self.batch.size, dtype=bool) if going is None else going
        Q, P = self.method.qp(self.batch.state)
        act = self.live["act"][going]
        q, p, s = self.out["q"].copy(), self.out["p"].copy(), self.out["s"].copy()
        q[:, act] = Q[: self.n, going]
        p[:, act] = P[: self.n, going]
        s[act] = self.s_now()[going]
        self.record_list.append((s, q, p))

    def check_energy(self) -> None:
        """energy_events over every ray still going, those failing dropped (outside the loop)."""
        if self.batch.size:
            bad = self.energy_events(np.ones(self.batch.size, dtype=bool))
            if bad.any():
                self.batch.drop(bad)

    def finish(self) -> None:
        """Freeze the rays still going (not failed)."""
        if self.batch.size:
            self.retire(np.ones(self.batch.size, dtype=bool), failed=False)


def _run_fixed(run: _Run, steps: int, energy_every: int, record_every: int) -> None:
    """`steps` fixed steps run.h (float or per ray)."""

    def step(batch: Batch):
        new, ok = batch.method.step(batch.systems["H"], batch.state, run.h)
        return new, ok, None

    def events(batch: Batch, k: int, start, ok: np.ndarray, _extra) -> np.ndarray:
        failed = ~ok
        if failed.any():  # frozen where they were before the step that failed
            run.freeze(failed, failed=True, state=start)
        run.live["steps"] += ok
        ended = failed | run.capture_events(ok)
        if energy_every and k % energy_every == 0:
            ended |= run.energy_events(~ended)
        if record_every and k % record_every == 0:
            run.record(~ended)
        return ended

    taken = run_batch(run.batch, step, events, steps)
    if not (energy_every and taken % energy_every == 0):
        run.check_energy()


def _run_adaptive(
    run: _Run, s_end: np.ndarray, max_steps: int, energy_every: int, record_every: int
) -> None:
    """Per-ray step sizes up to s_end (either sign) with the method's attempt()/factor()."""
    method = run.method
    live = run.live
    live["s_end"] = s_end
    live["sign"] = np.where(s_end < 0, -1.0, 1.0)
    live["h"] = np.abs(live["h"])
    live["h_min"] = 1e-13 * np.abs(s_end)

    def step(batch: Batch):
        live = batch.arrays
        s, rest = live["s"], np.abs(live["s_end"] - live["s"])
        hh = np.minimum(live["h"], rest)
        new, err, ok = method.attempt(batch.systems["H"], batch.state, hh * live["sign"])
        acc = ok & (err <= 1.0)
        arrived = acc & (hh >= rest)
        state = tuple(np.where(acc, a1, a0) for a1, a0 in zip(new, batch.state, strict=True))
        live["s"] = np.where(arrived, live["s_end"], np.where(acc, s + hh * live["sign"], s))
        live["steps"] += acc
        live["h"] = hh * method.factor(err)
        live["arrived"] = arrived
        return state, np.ones(arrived.size, dtype=bool), None

    def events(batch: Batch, k: int, start, ok: np.ndarray, _extra) -> np.ndarray:
        ended = run.capture_events(ok)
        if energy_every and k % energy_every == 0:
            ended |= run.energy_events(~ended)
        if record_every and k % record_every == 0:
            run.record(~ended)
        arrived = batch.arrays["arrived"] & ~ended
        if arrived.any():
            ended |= run.energy_events(~ended)  # the final state of the rays that arrive
            arrived &= ~ended
            run.freeze(arrived, failed=False)
            ended |= arrived
        tiny = (batch.arrays["h"] < batch.arrays["h_min"]) & ~ended
        if tiny.any():
            run.freeze(tiny, failed=True)
            ended |= tiny
        return ended

    run_batch(run.batch, step, events, max_steps)
    if run.batch.size:
        run.check_energy()
        if run.batch.size:
            run.retire(np.ones(run.batch.size, dtype=bool), failed=True)  # out of steps


def capture_test(H: Any) -> CaptureTest | None:
    """Q (n, N) -> (N,) bool: inside the model's horizon; None if it has none."""
    return as_system(H).capture_test()


def _to_soa(q0: Any, p0: Any, dim: int | None) -> tuple[np.ndarray, np.ndarray, bool]:
    """(N, n) or (n,) public arrays -> (n, N) float64, and whether it was a single ray."""
    q0 = np.asarray(q0, dtype=np.float64)
    p0 = np.asarray(p0, dtype=np.float64)
    if q0.shape != p0.shape or q0.ndim not in (1, 2):
        raise ValueError(f"q0 and p0 must both be (N, n) or (n,); got {q0.shape}, {p0.shape}")
    single = q0.ndim == 1
    if dim is not None and q0.shape[-1] != dim:
        raise ValueError(f"the Hamiltonian has {dim} coordinates, the rays {q0.shape[-1]}")
    Q = np.ascontiguousarray(np.atleast_2d(q0).T)
    P = np.ascontiguousarray(np.atleast_2d(p0).T)
    return Q, P, single


def integrate(
    H: Any,
    q0: Any,
    p0: Any,
    step: float | np.ndarray = 0.01,
    steps: int = 10_000,
    method: str | Method = "yoshida4",
    *,
    adaptive: bool = False,
    tol: float | None = None,
    record_every: int | None = None,
    energy_every: int = 1,
    max_steps: int | None = None,
    **options: Any,
) -> IntegrationResult:
    """Integrate Hamilton's equations for a batch of rays; see IntegrationResult.

    step: float or per-ray (N,). Fixed-step methods take `steps` steps of size `step`; with
    adaptive=True they integrate the Poincaré-transformed K = g(q) (H − H0) instead, `step`
    being the fictitious-time step dτ (the s reached is in res.s). dopri5 integrates to
    s = step * steps adaptively (rtol = atol = tol unless given as options; at most
    `max_steps` attempts per ray, default 10 * steps + 100). `tol` is also the implicit
    solver tolerance of implicit methods. energy_every: check |H − H0| every that many steps
    (0: only at the end). Rays are frozen where they fail (res.failed) or cross the model's
    horizon (res.captured, see capture_test). Further keyword options go to the method
    (get_method), e.g. base="implicit_midpoint", omega=20.0, max_iter=20.
    """
    check_integrate_options(step, steps, tol, record_every, energy_every, max_steps)
    meth = get_method(method, **options)
    H = as_system(H)
    is_rk_adaptive = meth.adaptive
    if tol is not None and is_rk_adaptive:
        meth = meth.with_options(rtol=tol, **({} if "atol" in options else {"atol": tol}))
    elif tol is not None and meth.accepts("tol"):
        meth = meth.with_options(tol=tol)
    Q, P, single = _to_soa(q0, p0, H.dim)
    n, N = Q.shape
    with np.errstate(all="ignore"):
        E0 = H.value_soa(Q, P)
    mode = "adaptive" if is_rk_adaptive else "clock" if adaptive else "fixed"
    Hk: System = H
    if mode == "clock":  # the splittings integrate the model's split of K (with s)
        split = H.split_parts(0.0, clocked=True) if meth.needs_split else None
        Hk = split or PoincareTransformed(Clocked(H), 0.0)
        Q = np.concatenate((Q, np.zeros((1, N))))
        P = np.concatenate((P, -E0[None]))
    run = _Run(meth, Hk, H, Q, P, n, E0.copy(), mode, step)
    if not np.isfinite(E0).all():
        run.retire(~np.isfinite(E0), failed=True)
    if record_every:
        run.record()
    if mode == "adaptive":
        _run_adaptive(
            run,
            run.live["h"] * steps,
            10 * steps + 100 if max_steps is None else max_steps,
            energy_every,
            record_every or 0,
        )
    else:
        _run_fixed(run, steps, energy_every, record_every or 0)
    run.finish()
    return _result(run, single)


def _result(run: _Run, single: bool) -> IntegrationResult:
    """Public shapes: (N, n) / (N,), or (n,) / scalars for a single ray."""
    out = run.out
    traj = None
    if run.record_list:
        s, q, p = (np.stack(x) for x in zip(*run.record_list, strict=True))
        traj = Trajectory(s=s, q=q.transpose(0, 2, 1), p=p.transpose(0, 2, 1))
        if single:
            traj = Trajectory(s=traj.s[:, 0], q=traj.q[:, 0], p=traj.p[:, 0])
    q, p = out["q"].T.copy(), out["p"].T.copy()
    if single:
        return IntegrationResult(
            q[0],
            p[0],
            float(out["s"][0]),
            float(out["err"][0]),
            bool(out["failed"][0]),
            int(out["steps"][0]),
            traj,
            bool(out["captured"][0]),
        )
    return IntegrationResult(
        q, p, out["s"], out["err"], out["failed"], out["steps"], traj, out["captured"]
    )

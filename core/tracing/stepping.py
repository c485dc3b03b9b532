"""One step of a batch of rays, with retries: a failed or far-off-shell step is redone in halves.

A fixed step can be too long where K is stiff (the last steps of a ray falling into a
horizon, steep index gradients): the implicit solve fails, or converges to a wrong root
far off the light cone (|H - H0| > OFF_SHELL (|H0| + |p|^2), where a good step is orders
of magnitude closer). Those rays redo the step as two steps of h/2 (at most SPLITS
halvings deep); a ray captured at the midpoint stops there (the capture test ends it).
Rays inside the horizon are not checked.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from ..backend import array_module, placed
from ..integrators import Method, PoincareTransformed
from ..integrators._common import take

RayCapture = Callable[[np.ndarray, np.ndarray], np.ndarray]
"""(Q, P) -> (N,) bool: rays that can no longer come out of a horizon (ray_capture_test)."""


SPLITS = 3  # a failed step is retried as 2, then 4, then 8 shorter steps
OFF_SHELL = 1e-3  # |H - H0| / (|H0| + |p|^2) after one step that has it retried in halves
OFF_CONE, OFF_CONE_STEPS = 1e-2, 16
"""Spacetimes: a ray whose |H - H0| stays above OFF_CONE p_t^2 for OFF_CONE_STEPS steps in a
row has stopped being light (a bound massive orbit, m^2/E^2 ~ 2 |H|/p_t^2, can circle a
near-extremal horizon until max_steps) and is flagged failed. |p|^2 cannot tell: near the
horizon it grows without bound while p_t stays fixed; and a ray falling in may be that far
off for a step or two before the capture test ends it."""

State = tuple[np.ndarray, ...]

KINK_ITERATIONS, KINK_SHARE, KINK_GAP = 8, 1e-10, 1e-7
"""A step across a kink of the model (``Stepper.advance``) finds the fraction u of the step
where the method's own partial step meets it by the secant method (at most KINK_ITERATIONS
partial steps, until u moves by under KINK_SHARE), then is taken again as three steps:
to u - KINK_GAP, across (2 KINK_GAP of the step), and on to its end."""
KINK_HALVINGS = 6
"""A step whose path dips across a kink and back is halved at most this deep (1/64)."""
KINK_LEVELS = 8
"""A step's pieces are searched for further crossings (a grazing ray in, out and in again
within one step) at most this deep; deeper, a piece is taken as it comes."""
DIP_POINTS = np.linspace(0.0, 1.0, 17)[1:-1]
"""Where a step's cubic of a kink's value is read for a dip across it (_dips)."""


class Stepper:
    """Steps of ``method`` on K = g (H - H0) of ``model``, retried in halves where they fail."""

    def __init__(self, method: Method, model: Any, captured: RayCapture | None) -> None:
        self.method, self.model, self.captured = method, model, captured
        self.kinks: Callable[..., Any] | None = model.kinks_soa if model.has_kinks else None

    def advance(
        self, K: Any, state: State, h: Any, depth: int = 0
    ) -> tuple[State, np.ndarray, np.ndarray, np.ndarray]:
        """``step`` (with its retries), where the model has kinks (a jump in its force's
        slope: ``kinks_soa``, the arguments of abs in a medium's n) those steps crossing
        one split at the crossing, on the method's own path (``_across``): a splitting's
        kick samples the force on one side of a kink for the whole step, an error first
        order in the step and erratic in where the kink falls, which the error pass's run
        at twice the step cannot estimate (Luneburg's lens with n = 1 outside r = 1: 1e-3
        at every tolerance; issue 50). Each piece is then smooth, of the method's order. A
        step whose ends lie on one side but whose path dips across (the cubic through its
        ends' values and slopes: a ray grazing a lens's edge) is taken as two halves, each
        advanced so (up to KINK_HALVINGS deep). -> (state, ok, |H - H0|, the kinks each ray
        crossed (M,) int64: bit k for kink k; the sampler interpolates no block whose rays
        crossed different kinks: the image's map has a kink between them)."""
        new, ok, shell = self.step(K, state, h)
        crossings = np.zeros_like(ok, dtype=np.int64)
        if self.kinks is None or self.kinks(self.method.qp(state)[0][:3]) is None:
            return new, ok, shell, crossings
        with np.errstate(all="ignore"):
            f0, d0 = self._kink_slopes(K, state, h)
            f1, d1 = self._kink_slopes(K, new, h)
            change = np.sign(f0) * np.sign(f1) < 0
            crossed = ok & np.any(change, axis=0)
            crossings[crossed] = _bits(change[:, crossed])
            crossed &= depth < KINK_LEVELS  # deeper: taken as it comes
            dipped = ok & ~crossed & _dips(f0, d0, f1, d1) & (depth < KINK_HALVINGS)
        rows = np.flatnonzero(crossed)
        if rows.size:
            sub = tuple(a[..., rows] for a in state)
            end, ok_end, shell_end, more = self._across(
                K.subset(rows), sub, take(h, rows), f0[:, rows], f1[:, rows], depth
            )
            _put(new, ok, shell, rows, end, ok_end, shell_end)
            crossings[rows] |= more
        rows = np.flatnonzero(dipped)
        if rows.size:
            Kd, half = K.subset(rows), 0.5 * take(h, rows)
            sub = tuple(a[..., rows] for a in state)
            mid, ok_mid, _, first = self.advance(Kd, sub, half, depth + 1)
            end, ok_end, shell_end, second = self.advance(Kd, mid, half, depth + 1)
            _put(new, ok, shell, rows, end, ok_mid & ok_end, shell_end)
            crossings[rows] = first | second
        return new, ok, shell, crossings

    def _kink_slopes(self, K: Any, state: State, h: Any) -> tuple[np.ndarray, np.ndarray]:
        """(k, M) the kinks' values at the rays' positions in ``state`` and their slopes
        along the step h (d/du of the value at the fraction u: h grad f . dq/dtau)."""
        assert self.kinks is not None
        Q, P = self.method.qp(state)
        found = self.kinks(Q[:3], derivatives=True)
        assert found is not None
        values, grad = found
        _, dp = K.gradient_soa(Q, P, wrt="p")
        return values, np.einsum("kim,im->km", grad, dp[:3]) * h

    def _kink_values(self, state: State) -> np.ndarray:
        """(k, M) the model's kink expressions at the rays' positions in ``state``."""
        assert self.kinks is not None
        values = self.kinks(self.method.qp(state)[0][:3])
        assert values is not None  # a model with kinks has them everywhere
        return values

    def _across(
        self, K: Any, state: State, h: Any, f0: np.ndarray, f1: np.ndarray, depth: int
    ) -> tuple[State, np.ndarray, np.ndarray, np.ndarray]:
        """The step h of rays crossing a kink ((k, M) values f0, f1 of the kinks at its ends)
        as three: to where the method's partial step meets the kink crossed first (the
        secant method on the fraction u of the step), across it, and on to the end; the
        pieces before and after advanced as steps are (``advance``: a grazing ray may cross
        in, out and in again within one step). -> as ``advance``, with the kinks crossed
        in the pieces before and after."""
        assert self.kinks is not None
        m = f0.shape[1]
        change = np.sign(f0) * np.sign(f1) < 0
        with np.errstate(all="ignore"):
            u_lin = np.where(change, f0 / (f0 - f1), np.inf)
        k = np.argmin(u_lin, axis=0)
        xp = array_module(f0)
        cols = xp.arange(m)
        a, fa = xp.zeros(m), f0[k, cols]
        b, fb = xp.ones(m), f1[k, cols]
        u = u_lin[k, cols]
        done = xp.zeros(m, dtype=bool)
        for _ in range(KINK_ITERATIONS):
            mid, _, _ = self.step(K, state, u * h, 0)
            with np.errstate(all="ignore"):
                fu = self._kink_values(mid)[k, cols]
                left = np.sign(fu) == np.sign(fa)
                a, fa = np.where(left, u, a), np.where(left, fu, fa)
                b, fb = np.where(left, b, u), np.where(left, fb, fu)
                nxt = a - fa * (b - a) / (fb - fa)
            nxt = np.where(np.isfinite(nxt) & (nxt > a) & (nxt < b), nxt, 0.5 * (a + b))
            nxt = np.where(done, u, nxt)  # a ray there stays there
            done |= np.abs(nxt - u) < KINK_SHARE
            u = nxt
            if done.all():
                break
        lo = np.clip(u - KINK_GAP, 0.0, 1.0)
        hi = np.clip(u + KINK_GAP, 0.0, 1.0)
        first, ok1, _, before = self.advance(K, state, lo * h, depth + 1)
        second, ok2, _ = self.step(K, first, (hi - lo) * h)
        end, ok3, shell, after = self.advance(K, second, (1.0 - hi) * h, depth + 1)
        return end, ok1 & ok2 & ok3, shell, before | after

    def step(
        self, K: PoincareTransformed, state: State, h: Any, splits: int = SPLITS
    ) -> tuple[State, np.ndarray, np.ndarray]:
        """One step of every ray -> (state, ok, |H - H0| of the state) per ray."""
        method = self.method
        new, ok = method.step(K, state, h)
        shell = self.shell_error(K, new)
        if splits == 0:
            return new, ok, shell
        ok &= ~self._off_shell(new, shell, K.H0)
        if ok.all():
            return new, ok, shell
        bad = np.flatnonzero(~ok)
        K_bad = K.subset(bad)
        h = take(h, bad)
        mid, ok_mid, shell_mid = self.step(
            K_bad, tuple(a[..., bad] for a in state), 0.5 * h, splits - 1
        )
        go = ok_mid.copy()
        if self.captured is not None:
            with np.errstate(all="ignore"):
                go &= ~self.captured(*method.qp(mid))
        end, ok_end, shell_end = mid, ok_mid, shell_mid
        if go.any():
            g = np.flatnonzero(go)
            e2, o2, d2 = self.step(
                K_bad.subset(g), tuple(a[..., g] for a in mid), 0.5 * take(h, g), splits - 1
            )
            for a, b in zip(end, e2, strict=True):
                a[..., g] = b
            ok_end[g], shell_end[g] = o2, d2
        for a, b in zip(new, end, strict=True):
            a[..., bad] = b
        ok[bad], shell[bad] = ok_end, shell_end
        return new, ok, shell

    def shell_error(self, K: PoincareTransformed, state: State) -> np.ndarray:
        """(M,) |H - H0| of each ray's state (NaN where a failed ray holds anything)."""
        Q, P = self.method.qp(state)
        with np.errstate(all="ignore"):
            return np.abs(self.model.value_soa(Q, P) - K.H0)

    def _off_shell(self, state: State, shell: np.ndarray, H0: np.ndarray) -> np.ndarray:
        """(M,) rays a step left far off the light cone, |H - H0| > OFF_SHELL (|H0| + |p|^2);
        rays inside the horizon are not judged."""
        Q, P = self.method.qp(state)
        with np.errstate(all="ignore"):
            off = shell > OFF_SHELL * (np.abs(H0) + np.einsum("ij,ij->j", P, P))
            if self.captured is not None:
                off &= ~self.captured(Q, P)
        return off


def _dips(f0: np.ndarray, d0: np.ndarray, f1: np.ndarray, d1: np.ndarray) -> np.ndarray:
    """(M,) whether the cubic Hermite through a step's kink values f0, f1 (k, M) with slopes
    d0, d1 along the step changes sign inside it, its ends on one side: a dip across."""
    u = placed(DIP_POINTS, f0)[:, None, None]
    h00, h10 = (1 + 2 * u) * (1 - u) ** 2, u * (1 - u) ** 2
    h01, h11 = u * u * (3 - 2 * u), u * u * (u - 1)
    cubic = h00 * f0 + h10 * d0 + h01 * f1 + h11 * d1  # (points, k, M)
    return np.any(np.any(np.sign(cubic) * np.sign(f0) < 0, axis=0), axis=0)


def _put(new: State, ok, shell, rows, end: State, ok_end, shell_end) -> None:
    """In place: the rays ``rows`` of a step's (state, ok, shell) replaced."""
    for a, b in zip(new, end, strict=True):
        a[..., rows] = b
    ok[rows], shell[rows] = ok_end, shell_end


def _bits(change: np.ndarray) -> np.ndarray:
    """(M,) int64 with bit k set where kink k changed sign ((k, M) bool; the first 63)."""
    count = min(change.shape[0], 63)
    weights = np.left_shift(np.int64(1), array_module(change).arange(count, dtype=np.int64))
    return (change[: weights.size] * weights[:, None]).sum(axis=0).astype(np.int64)

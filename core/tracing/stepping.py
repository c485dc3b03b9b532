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

from ..integrators import Method, PoincareTransformed
from ..integrators._common import take

RayCapture = Callable[[np.ndarray, np.ndarray], np.ndarray]
"""(Q, P) -> (N,) bool: rays that can no longer come out of a horizon (ray_capture_test)."""


def ray_capture_test(model: Any) -> RayCapture | None:
    """The tracer's capture test of a model: its ``falling_soa(Q, P)`` where it has one
    (a capture that depends on the ray's direction), else its ``capture_test()`` on Q."""
    falling = getattr(model, "falling_soa", None)
    if falling is not None:
        return falling
    captured = model.capture_test()
    if captured is None:
        return None
    return lambda Q, P: captured(Q)


SPLITS = 3  # a failed step is retried as 2, then 4, then 8 shorter steps
OFF_SHELL = 1e-3  # |H - H0| / (|H0| + |p|^2) after one step that has it retried in halves
OFF_CONE, OFF_CONE_STEPS = 1e-2, 16
"""Spacetimes: a ray whose |H - H0| stays above OFF_CONE p_t^2 for OFF_CONE_STEPS steps in a
row has stopped being light (a bound massive orbit, m^2/E^2 ~ 2 |H|/p_t^2, can circle a
near-extremal horizon until max_steps) and is flagged failed. |p|^2 cannot tell: near the
horizon it grows without bound while p_t stays fixed; and a ray falling in may be that far
off for a step or two before the capture test ends it."""

State = tuple[np.ndarray, ...]


class Stepper:
    """Steps of ``method`` on K = g (H - H0) of ``model``, retried in halves where they fail."""

    def __init__(self, method: Method, model: Any, captured: RayCapture | None) -> None:
        self.method, self.model, self.captured = method, model, captured

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

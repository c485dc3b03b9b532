"""One loop for rays stepped together: ``core.integrate`` and the tracer both run it.

A :class:`Batch` holds the method's state of the rays still going, the systems they are
stepped on and any per-ray arrays; ``run_batch`` steps it, asks the caller's ``events``
which rays ended (the caller records what it needs of them: a hit, an escape, a capture, a
failure, a frozen output) and drops those, until none is left or the steps run out.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from ._common import State, restrict, take

Step = Callable[["Batch"], tuple[State, np.ndarray, Any]]
"""batch -> (new state, ok (M,) bool, anything the events need, e.g. |H - H0|)."""
Events = Callable[["Batch", int, State, np.ndarray, Any], np.ndarray]
"""(batch, steps taken, state before the step, ok, extra) -> (M,) bool: the rays that ended."""
CANCEL_EVERY = 32
"""Steps between two polls of ``cancel``."""


class Batch:
    """Rays stepped together: the method's ``state``, the ``systems`` they are stepped on
    (restricted as rays end) and per-ray ``arrays`` (rays on the last axis; scalars are
    shared), all shrunk together by ``drop``."""

    def __init__(
        self, method: Any, state: State, systems: dict[str, Any], arrays: dict[str, Any]
    ) -> None:
        self.method, self.state = method, state
        self.systems = systems
        self.arrays = arrays

    @property
    def size(self) -> int:
        """Rays still going."""
        return int(self.state[0].shape[-1])

    def drop(self, ended: np.ndarray) -> None:
        """Remove the rays ``ended`` ((M,) bool) from the state, systems and arrays."""
        keep = np.flatnonzero(~ended)
        self.state = tuple(a[..., keep] for a in self.state)
        self.systems = {name: restrict(s, keep) for name, s in self.systems.items()}
        self.arrays = {name: take(a, keep) for name, a in self.arrays.items()}


def run_batch(
    batch: Batch,
    step: Step,
    events: Events,
    max_steps: int,
    cancel: Callable[[], bool] | None = None,
) -> int:
    """Step every ray of ``batch`` until it ends or ``max_steps`` are taken: each step the
    state becomes ``step(batch)``'s, ``events`` says which rays ended and they are dropped.
    Returns the steps taken (none for an empty batch; the last complete one where
    ``cancel()`` said stop: it is asked before every CANCEL_EVERY-th step)."""
    taken = 0
    while taken < max_steps and batch.size:
        if cancel is not None and (taken + 1) % CANCEL_EVERY == 0 and cancel():
            break
        taken += 1
        start = batch.state
        batch.state, ok, extra = step(batch)
        ended = events(batch, taken, start, ok, extra)
        if ended.any():
            batch.drop(ended)
    return taken

"""The one batch loop (core.integrators.batch) that core.integrate and the tracer run."""

from __future__ import annotations

import numpy as np

from core.integrators.batch import CANCEL_EVERY, Batch, run_batch
from core.integrators.system import System


class _Counter:
    """A stand-in method: every step adds h to q."""

    def qp(self, state):
        return state

    def step(self, system, state, h):
        Q, P = state
        return (Q + h, P.copy()), np.isfinite(Q[0] + h)


class _System(System):
    """A system whose per-ray data is a list of ray ids."""

    def __init__(self, ids):
        self.ids = np.asarray(ids)

    def subset(self, keep):
        return _System(self.ids[keep])


def _batch(targets):
    n = len(targets)
    state = (np.zeros((1, n)), np.zeros((1, n)))
    arrays = {"id": np.arange(n), "target": np.asarray(targets, float), "h": 1.0}
    return Batch(_Counter(), state, {"S": _System(np.arange(n))}, arrays)


def test_rays_end_when_their_events_say_and_everything_shrinks_together():
    """Each ray ends at the step its event fires; the state, the systems and the per-ray
    arrays are cut together (scalars shared); the loop stops when none is left."""
    batch = _batch([3, 1, 5, 2])
    ended_at = {}

    def step(b):
        new, ok = b.method.step(b.systems["S"], b.state, b.arrays["h"])
        return new, ok, None

    def events(b, taken, start, ok, _):
        assert np.array_equal(b.systems["S"].ids, b.arrays["id"])
        assert np.all(start[0][0] == taken - 1)  # the state before this step
        done = b.state[0][0] >= b.arrays["target"]
        for ray in b.arrays["id"][done]:
            ended_at[int(ray)] = taken
        return done

    taken = run_batch(batch, step, events, max_steps=100)
    assert taken == 5 and batch.size == 0
    assert ended_at == {0: 3, 1: 1, 2: 5, 3: 2}


def test_max_steps_and_cancel_leave_the_rest_going():
    """Out of steps: the rays still going stay in the batch, at the last step; cancel is
    asked every CANCEL_EVERY steps and stops after the last complete one."""
    batch = _batch([2, 1000, 1000])

    def step(b):
        new, ok = b.method.step(None, b.state, b.arrays["h"])
        return new, ok, None

    def events(b, taken, start, ok, _):
        return b.state[0][0] >= b.arrays["target"]

    assert run_batch(batch, step, events, max_steps=10) == 10
    assert list(batch.arrays["id"]) == [1, 2] and np.all(batch.state[0] == 10)
    asked = []

    def cancel():
        asked.append(True)
        return len(asked) == 2

    assert run_batch(batch, step, events, 1000, cancel) == 2 * CANCEL_EVERY - 1
    assert np.all(batch.state[0] == 10 + 2 * CANCEL_EVERY - 1)


def test_an_empty_batch_takes_no_step():
    """A batch whose rays all ended before the loop (integrate: every initial H not finite)
    takes no step; integrate returns at once, the rays failed where they started."""
    import core
    from core import hamiltonians as hm

    batch = _batch([])
    assert run_batch(batch, lambda b: 1 / 0, lambda *a: 1 / 0, max_steps=10**6) == 0
    res = core.integrate(hm.from_expression("0.5*(p**2 + q**2)", q=["q"], p=["p"]),
                         [[np.nan]], [[1.0]], step=0.01, steps=10**6, record_every=1)  # fmt: skip
    assert res.failed[0] and res.steps[0] == 0 and res.trajectory.s.shape[0] == 1

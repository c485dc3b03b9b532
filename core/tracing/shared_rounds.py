"""Rounds shared by several tiles: their ``Tracer.trace`` calls traced as one batch.

A tile's quadtree traces its rays in rounds (a lattice, its levels, retraces), and each
round is one batch whose step loop pays ~1000 numpy calls a step whatever its size (~4 ms a
step for Kerr's split: docs/performance.md, issue 47). Small tiles (many workers) pay that
per tile and round. ``SharedRounds`` lets a worker render several tiles at once, one
thread each (the sampler's logic takes turns under the GIL, as core.workers' threads do):
every ``Tracer.trace`` call a member thread makes waits until every other member is
waiting on one too (or has finished its tile), and then all of them are traced in one
batch per tracer (``Tracer.trace``'s per-ray steps and shares of the margin let calls at
different steps share it), each call getting its own rows back. Rays are traced
independently of the batch they ride in, so every result equals the call's own, bit for
bit (tests/core/test_shared_rounds.py).

Offers ``SharedRounds`` (``run``: calls on threads, their traces shared) and ``joined``
(the SharedRounds the calling thread belongs to, if any; ``Tracer.trace`` asks it).
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from .segments import RayResults

_member = threading.local()  # .rounds: the SharedRounds this thread's traces join


def joined() -> SharedRounds | None:
    """The SharedRounds whose member the calling thread is (None: trace on its own)."""
    return getattr(_member, "rounds", None)


@dataclass
class _Call:
    """One member's ``Tracer.trace`` call, waiting for its rows of a shared batch."""

    tracer: Any  # a core.tracing.Tracer (it asks ``joined``: not imported here)
    origins: np.ndarray
    directions: np.ndarray
    options: dict[str, Any]
    result: Any = None
    error: BaseException | None = None
    done: bool = field(default=False)

    def key(self) -> tuple:
        """Calls of one key can share a batch: the same tracer, tangents alike."""
        tangents = self.options["tangents"]
        return (id(self.tracer), None if tangents is None else tangents.shape[1:])


class SharedRounds:
    """Members (threads) whose ``Tracer.trace`` calls are traced together: see the
    module docstring."""

    def __init__(self) -> None:
        self._lock = threading.Condition()
        self._live = 0
        self._waiting: list[_Call] = []

    def __getstate__(self) -> dict:
        """Pickled (a cluster's job, core.cluster) without members: a fresh one there."""
        return {}

    def __setstate__(self, state: dict) -> None:
        self.__init__()  # type: ignore[misc]

    def run(self, calls: Sequence[Callable[[], Any]]) -> list[Any]:
        """Each of ``calls`` on a thread of its own, their traces shared (with those of
        any other member); their results in order (the first exception any raised is
        raised once all have ended)."""
        results: list[Any] = [None] * len(calls)
        errors: list[BaseException] = []
        with self._lock:
            self._live += len(calls)  # all joined before any traces

        def member(k: int) -> None:
            _member.rounds = self
            try:
                results[k] = calls[k]()
            except BaseException as exc:  # raised in the caller's thread below
                errors.append(exc)
            finally:
                _member.rounds = None
                self._leave()

        threads = [threading.Thread(target=member, args=(k,)) for k in range(len(calls))]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()
        if errors:
            raise errors[0]
        return results

    @contextmanager
    def member(self) -> Iterator[None]:
        """The calling thread a member while the block runs (a worker thread's tile: the
        tiles of core.workers' threads share their rounds)."""
        with self._lock:
            self._live += 1
        before, _member.rounds = joined(), self
        try:
            yield
        finally:
            _member.rounds = before
            self._leave()

    def trace(
        self, tracer: Any, origins: np.ndarray, directions: np.ndarray, **options: Any
    ) -> RayResults:
        """``tracer.trace(origins, directions, **options)`` (step, cancel, tangents,
        clearance), traced in a batch with every other member's waiting call."""
        call = _Call(tracer, origins, directions, options)
        with self._lock:
            self._waiting.append(call)
            if len(self._waiting) >= self._live:
                self._flush()
            while not call.done:
                self._lock.wait()
        if call.error is not None:
            raise call.error
        return call.result

    def _leave(self) -> None:
        """A member has ended: the others' calls go if they were waiting only for it."""
        with self._lock:
            self._live -= 1
            if self._waiting and len(self._waiting) >= self._live:
                self._flush()

    def _flush(self) -> None:
        """Trace every waiting call (the lock held: every live member is waiting), one
        batch per key, and wake their members."""
        calls, self._waiting = self._waiting, []
        groups: dict[tuple, list[_Call]] = {}
        for call in calls:
            groups.setdefault(call.key(), []).append(call)
        before, _member.rounds = joined(), None  # the batch itself is traced on its own
        try:
            for group in groups.values():
                _trace_together(group)
        finally:
            _member.rounds = before
        self._lock.notify_all()


def _trace_together(calls: list[_Call]) -> None:
    """One ``Tracer.trace`` of every call's rays; each call gets its rows (or the error)."""
    tracer = calls[0].tracer
    try:
        if len(calls) == 1:
            call = calls[0]
            results = [tracer.trace(call.origins, call.directions, **call.options)]
        else:
            results = _split(tracer.trace(*_joined_rays(calls), **_joined_options(calls)), calls)
    except BaseException as exc:
        for call in calls:
            call.error, call.done = exc, True
        return
    for call, result in zip(calls, results, strict=True):
        call.result, call.done = result, True


def _joined_rays(calls: list[_Call]) -> tuple[np.ndarray, np.ndarray]:
    """The calls' origins and directions, one after another."""
    return (
        np.concatenate([c.origins for c in calls]),
        np.concatenate([c.directions for c in calls]),
    )


def _joined_options(calls: list[_Call]) -> dict[str, Any]:
    """The options of one trace of every call's rays: steps and clearance shares per ray
    where the calls' differ (None stands for the tracer's step, and for every ray's whole
    margin), one cancel asking all of theirs."""
    sizes = [len(c.origins) for c in calls]
    tracer = calls[0].tracer
    options: dict[str, Any] = {}
    steps = [tracer.step if c.options["step"] is None else c.options["step"] for c in calls]
    if all(np.ndim(s) == 0 for s in steps) and len(set(steps)) == 1:
        options["step"] = calls[0].options["step"]
    else:
        options["step"] = np.concatenate(
            [np.broadcast_to(np.asarray(s, dtype=np.float64), (n,))
             for s, n in zip(steps, sizes, strict=True)]
        )  # fmt: skip
    shares = [c.options["clearance"] for c in calls]
    if any(s is not None for s in shares):
        options["clearance"] = np.concatenate(
            [np.ones(n) if s is None else np.asarray(s, dtype=np.float64)
             for s, n in zip(shares, sizes, strict=True)]
        )  # fmt: skip
    tangents = [c.options["tangents"] for c in calls]
    if tangents[0] is not None:
        options["tangents"] = np.concatenate(tangents)
    cancels = [c.options["cancel"] for c in calls if c.options["cancel"] is not None]
    if cancels:
        options["cancel"] = lambda: any(cancel() for cancel in cancels)
    return options


def _split(out: RayResults, calls: list[_Call]) -> list[RayResults]:
    """Each call's rows of ``out``."""
    ends = np.cumsum([len(c.origins) for c in calls])
    return [out.take(slice(end - len(c.origins), end)) for c, end in zip(calls, ends, strict=True)]

"""core.workers: where an image's chunks run — forked worker processes, or threads.

Threads share one GIL. A chunk's tracing is thousands of numpy operations of a few
microseconds each on 16384-ray arrays, with Python in between, so two threads mostly
take turns (1.0-1.3x on two cores, docs/architecture.md "Parallel chunks"); the tiles
of an adaptive render that threads render at once trace their rounds as shared batches
instead (core.tracing.shared_rounds: 5-30 % less time on two threads). Processes
do not share a GIL: forked workers inherit the tracer as it is (no pickling of models,
textures or Blender's BVH trees), trace the chunks they are handed and send the results
back through a pipe (1.6-2.0x on two cores).

``fork`` exists on Linux (and is unsafe on macOS, absent on Windows); elsewhere, or when
a pool cannot be started (no /dev/shm, say), the chunks run in threads.
"""

from __future__ import annotations

import ctypes
import itertools
import mmap
import multiprocessing
import os
import sys
import threading
import time
import warnings
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import (
    FIRST_COMPLETED,
    Future,
    ProcessPoolExecutor,
    ThreadPoolExecutor,
    wait,
)
from typing import Any, Self, TypeVar

import numpy as np

PARALLEL = ("auto", "processes", "threads")
"""How chunks run: "auto" = processes where fork exists and the image is big enough."""
PROCESS_MIN_RAYS = 4096
"""Under "auto", images of fewer rays (one or two chunks) run in threads. Forking costs
~20 ms; small chunks are where threads do worst: a 96x96 Kerr frame took 2.8 s in two
threads, 0.9 s in two processes (48x48: 0.8-1.0 s against 0.5 s)."""
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3  # glibc's mallopt parameters (malloc.h)
_POLL_S = 0.1  # how often the parent polls for cancellation while processes work
IN_FLIGHT_PER_WORKER = 2
"""Chunks handed to the pool and not yet taken by the caller, per worker: one traced,
one queued. Finished chunks wait for the caller (its shading and storing), so this bounds
the results held in memory (measured: a 4096x4096 flat frame peaked at 2.1 GB in two
processes, 0.75 GB inline, before)."""

BLAS_BUFFER = 33 << 20
"""Address space (bytes) a BLAS buffer takes (OpenBLAS maps 32 MiB and a page)."""
_BLAS_WARM_S = 0.05  # how long the threads of _prepare_blas call BLAS together
_blas_callers = 1  # concurrent BLAS callers the BLAS library holds buffers for

Span = tuple[int, int]
Cancel = Callable[[], bool]
T = TypeVar("T")

_JOBS: dict[int, tuple[Callable[[Span, Cancel], Any], Any]] = {}
"""The jobs of running process pools by token, from before their workers are forked
(they inherit them: only a token and a span go through the pipe) until they are done."""
_TOKENS = itertools.count()


def available_cores() -> int:
    """The cores this process may run on (its affinity mask where the OS tells it)."""
    if hasattr(os, "sched_getaffinity"):  # a platform check: Linux has it, macOS does not
        return max(1, len(os.sched_getaffinity(0)))
    return max(1, os.cpu_count() or 1)


def can_fork() -> bool:
    """Whether worker processes can be forked here (Linux; fork is unsafe on macOS)."""
    return sys.platform.startswith("linux") and "fork" in multiprocessing.get_all_start_methods()


def choose(
    parallel: str, workers: int | None, n_rays: int, cores: int | None = None
) -> tuple[str, int]:
    """-> ("processes" | "threads" | "inline", worker count) for an image of n_rays.

    Default worker count: one process per core (``cores``, default: the available ones),
    or two threads (more threads only queue for the GIL).
    """
    if parallel not in PARALLEL:
        raise ValueError(f"unknown parallel mode {parallel!r}; choose from {PARALLEL}")
    if workers is not None and workers < 1:
        raise ValueError(f"workers must be at least 1, not {workers}")
    if cores is not None and cores < 1:
        raise ValueError(f"cores must be at least 1, not {cores}")
    cores = cores or available_cores()
    use_processes = can_fork() and (
        parallel == "processes" or (parallel == "auto" and n_rays >= PROCESS_MIN_RAYS)
    )
    kind = "processes" if use_processes else "threads"
    count = workers or (cores if use_processes else min(2, cores))
    if count == 1 and parallel == "auto":
        kind = "inline"  # one worker: no pool at all
    return kind, count


class CancelLatch:
    """Polls a caller's ``should_cancel`` (serialised: it may touch a UI) and stays true
    once it has said so."""

    def __init__(self, should_cancel: Cancel | None) -> None:
        self._poll = should_cancel
        self._event = threading.Event()
        self._lock = threading.Lock()

    def __call__(self) -> bool:
        if not self._event.is_set() and self._poll is not None:
            with self._lock:
                if self._poll():
                    self._event.set()
        return self._event.is_set()


class BackgroundTask:
    """Work run once in a daemon thread, cancellable: a subclass's ``_work()`` (which checks
    ``cancelled`` or hands ``self._cancel.is_set`` to core.render); an exception it raises
    is kept in ``error`` for the caller (the add-on's render operator, the viewport)."""

    def __init__(self, name: str) -> None:
        self.error: BaseException | None = None
        self._cancel = threading.Event()
        self._thread = threading.Thread(target=self._guarded, name=name, daemon=True)

    def _work(self) -> None:
        raise NotImplementedError

    def _guarded(self) -> None:
        try:
            self._work()
        except Exception as err:  # handed to the caller's thread, which decides what to do
            self.error = err

    def start(self) -> Self:
        """Start the work in its thread (returns at once, with the task)."""
        self._thread.start()
        return self

    def cancel(self) -> None:
        """Ask the work to stop at its next check."""
        self._cancel.set()

    @property
    def cancelled(self) -> bool:
        """Whether cancel() was called."""
        return self._cancel.is_set()

    @property
    def finished(self) -> bool:
        """Whether the thread has ended (finished, cancelled or failed; False before start)."""
        return self._thread.ident is not None and not self._thread.is_alive()

    def join(self, timeout: float | None = None) -> bool:
        """Wait for the thread to end; -> whether it has."""
        self._thread.join(timeout)
        return not self._thread.is_alive()


def run_chunks(
    job: Callable[[Span, Cancel], T],
    spans: Iterable[Span],
    kind: str,
    workers: int,
    cancelled: CancelLatch,
) -> Iterator[tuple[Span, T]]:
    """Run job(span, cancel) for every span; yield (span, result) as each one finishes.

    ``kind`` and ``workers`` come from ``choose`` (a Dask cluster's chunks run through
    core.cluster.run_on_client instead). Threads and inline jobs poll
    ``cancelled`` themselves; worker processes get a shared event that the caller's
    thread sets once ``cancelled`` turns true. Stops yielding once cancelled (a job may
    return early when its cancel turns true); closing the iterator early stops the jobs.
    Back-pressure: at most ``IN_FLIGHT_PER_WORKER * workers`` chunks are handed out and
    not yet taken by the caller, so a caller slower than its workers holds a fixed number
    of results, whatever the image's size.
    """
    spans = list(spans)
    if kind == "inline":
        for span in spans:
            if cancelled():
                return
            yield span, job(span, cancelled)
        return
    limit = IN_FLIGHT_PER_WORKER * workers
    if kind == "processes" and spans:
        token = next(_TOKENS)
        try:
            pool, started, stop = _start_processes(token, job, spans[0], workers, len(spans))
        except _PoolUnavailable:
            pass  # no process pool here: threads
        else:
            try:
                with pool:
                    yield from _bounded(
                        lambda span: pool.submit(_run_job, token, span),
                        spans,
                        limit,
                        cancelled,
                        stop.set,
                        started,
                    )
            finally:
                _JOBS.pop(token, None)
            return
    _prepare_blas(workers + 1)  # and the caller's thread: it shades finished chunks
    with ThreadPoolExecutor(max_workers=workers) as pool:
        yield from _bounded(
            lambda span: _submit_to_thread(pool, job, span, cancelled),
            spans,
            limit,
            cancelled,
            lambda: None,
        )


def _submit_to_thread(pool: ThreadPoolExecutor, job, span: Span, cancelled: Cancel) -> Future:
    """pool.submit(job, span, cancelled); a thread that cannot start for want of memory
    (its stack) raises MemoryError, as the job's own arrays would."""
    try:
        return pool.submit(job, span, cancelled)
    except RuntimeError as exc:
        if "start new thread" not in str(exc):
            raise
        raise MemoryError(f"no memory for a worker thread ({exc})") from exc


def _prepare_blas(callers: int) -> None:
    """Have numpy's BLAS map a buffer for each of ``callers`` threads calling it at once.

    OpenBLAS maps a buffer for a call that finds all its buffers in use, and keeps it for
    the process's life; where that map fails, it ends the process (0.3.34: "Memory
    allocation still failed after 10 retries", exit 1) or retries forever (0.3.23). Worker
    threads calling BLAS together (matmul, solve) need one each: mapped here, before the
    chunks' arrays take the memory, they are there when the memory runs out, and numpy's
    MemoryError reaches the caller instead. Where even this headroom is missing:
    MemoryError. Forked workers need none: each inherits its parent's buffer.
    """
    global _blas_callers
    if callers <= _blas_callers:
        return
    together = threading.Barrier(callers)
    small = np.ones((48, 48))  # below OpenBLAS's threading threshold: the caller's buffer

    def call_blas() -> None:
        try:
            together.wait()
        except threading.BrokenBarrierError:  # no headroom: _prepare_blas raises
            return
        end = time.perf_counter() + _BLAS_WARM_S
        while time.perf_counter() < end:  # inside BLAS ~all the time: the calls overlap
            small @ small

    helpers = [threading.Thread(target=call_blas, daemon=True) for _ in range(callers - 1)]
    try:
        for thread in helpers:
            thread.start()  # their stacks are mapped before the headroom is looked at
        # map the address space the new buffers need, and release it for them
        mmap.mmap(-1, (callers - _blas_callers) * BLAS_BUFFER).close()
    except (OSError, RuntimeError) as exc:  # RuntimeError: a thread could not start
        together.abort()
        raise MemoryError(f"no memory for {callers} threads' BLAS buffers") from exc
    finally:
        if together.broken:
            for thread in helpers:
                if thread.ident is not None:
                    thread.join()
    call_blas()
    for thread in helpers:
        thread.join()
    _blas_callers = callers


class _PoolUnavailable(Exception):
    """A process pool cannot be started here (no semaphores, no fork)."""


def _start_processes(token: int, job, first: Span, workers: int, n_spans: int):
    """Fork the workers (they inherit ``job`` as _JOBS[token]) and hand them ``first``.

    -> (pool, {its future: first}, the event that stops the workers' jobs).
    """
    context = multiprocessing.get_context("fork")
    pool = None
    try:
        stop = context.Event()
        _JOBS[token] = (job, stop)
        pool = ProcessPoolExecutor(
            max_workers=min(workers, n_spans), mp_context=context, initializer=keep_freed_memory
        )
        with warnings.catch_warnings():
            # Python >= 3.12 warns when a process with threads forks: a lock another
            # thread holds at that moment stays locked in the child. The workers only
            # run numpy and the tracer (no such lock) and leave with os._exit.
            warnings.filterwarnings(
                "ignore", message=r".*fork\(\) may lead to deadlocks", category=DeprecationWarning
            )
            future = pool.submit(_run_job, token, first)  # forks every worker
    except (OSError, NotImplementedError) as exc:  # no /dev/shm for semaphores, fork: ENOMEM
        _JOBS.pop(token, None)
        if pool is not None:
            # workers forked before the failure wait for work that never comes; the pool's
            # processes are private to concurrent.futures (and absent before the first fork)
            for process in list((getattr(pool, "_processes", None) or {}).values()):
                process.terminate()
            pool.shutdown(wait=False, cancel_futures=True)
        raise _PoolUnavailable(str(exc)) from exc
    return pool, {future: first}, stop


def keep_freed_memory() -> None:
    """In a worker process: let glibc's malloc keep freed memory for the next array.

    By default it returns the top of its heap to the OS once 2x its (adaptive) mmap
    threshold is free, and a chunk's numpy temporaries come and go in megabytes: the
    next ones are page-faulted in afresh (about a million faults for a 512x512 frame;
    two workers 12.0 s -> 10.1 s without). Only the worker is tuned, never the
    process that forked it (Blender); the worker exits when the image is done.
    """
    try:
        mallopt = ctypes.CDLL(None).mallopt  # glibc (musl has a no-op one)
    except (OSError, AttributeError):
        return
    mallopt(_M_MMAP_THRESHOLD, 32 << 20)  # glibc's largest; arrays below it use the heap
    mallopt(_M_TRIM_THRESHOLD, 256 << 20)


def _run_job(token: int, span: Span):
    """In a worker process: run the inherited job on one span."""
    job, stop = _JOBS[token]
    return job(span, stop.is_set)


def _bounded(
    submit: Callable[[Span], Future],
    spans: list[Span],
    limit: int,
    cancelled: Cancel,
    stop: Callable[[], None],
    started: dict[Future, Span] | None = None,
) -> Iterator[tuple[Span, Any]]:
    """Yield finished chunks' (span, result), keeping at most ``limit`` submitted and not
    yet yielded (``started``: those already submitted, first in ``spans``; emptied as
    they finish). Polls ``cancelled`` in between; on cancellation, an error or an early
    close: call ``stop`` and drop what has not begun."""
    futures = started if started is not None else {}
    waiting = iter(spans[len(futures) :])
    try:
        while True:
            for span in itertools.islice(waiting, max(limit - len(futures), 0)):
                futures[submit(span)] = span
            if not futures:
                return
            done, _ = wait(futures, timeout=_POLL_S, return_when=FIRST_COMPLETED)
            while done:  # a finished future holds its chunk: keep no reference to it
                future = done.pop()
                span, result = futures.pop(future), future.result()
                del future
                yield span, result
            if cancelled():
                return
    finally:
        if futures:
            stop()
            for future in futures:
                future.cancel()

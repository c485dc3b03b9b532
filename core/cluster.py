"""core.cluster: an image's chunks as tasks on a Dask cluster (``core.render(client=...)``).

Dask (``distributed``) is optional: numpy stays SymRay's only requirement, and only a
render handed a ``client`` imports it. The chunks' job (the tracer or the tile sampler,
with the scene) is sent to the workers once (``Client.scatter``, to every worker); each
chunk is then one small task naming it and a span, submitted most expensive first (its
``priority``). Results come back as they finish, in the order they finish, into the
caller's bounded buffers: the caller keeps at most what it has not stored yet.

A worker lost mid-render costs its tasks a rerun elsewhere (Dask's scheduler reschedules
them, up to its ``allowed-failures``). Where it held the job's last copy (Dask's memory
manager keeps one of a broadcast where no task waits for more), the scheduler cancels the
tasks instead: the job is scattered again and they are resubmitted. A task that raises
stops the render with its error.
A cancel (``should_cancel``) cancels the tasks not yet finished; a chunk already running
finishes on its worker and is dropped. The workers import ``core`` (SymRay installed, or
its folder on their ``PYTHONPATH``): only the job's data travels.
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable, Generator, Iterator, Sequence
from typing import Any

from .workers import keep_freed_memory

INSTALL = "pip install 'dask[distributed]==2026.8.0'"
"""What the error for a missing Dask says to run (the version the tests pin)."""
_POLL_S = 0.05  # how often the caller checks for finished tasks and for a cancel
_TOKENS = itertools.count()

Span = tuple[int, int]
Task = tuple[int, tuple[Span, float]]  # a chunk's index, its span and its priority


def require_dask():
    """The ``distributed`` module, or ImportError saying how to install it."""
    try:
        import distributed
    except ImportError as exc:
        raise ImportError(
            f"core.render(client=...) runs on a Dask cluster and needs Dask's distributed "
            f"scheduler, which is not installed here: {INSTALL}"
        ) from exc
    return distributed


def check_client(client: Any) -> int:
    """The threads of the cluster behind ``client`` (a distributed.Client); a clear error
    before any work where Dask is missing, ``client`` is not a Client, or its cluster
    cannot be reached or has no workers."""
    distributed = require_dask()
    if not isinstance(client, distributed.Client):
        raise TypeError(f"client must be a dask.distributed Client, not {type(client).__name__}")
    if client.status != "running":
        raise ConnectionError(
            f"the Dask client is not connected to its cluster (status '{client.status}'): "
            "start it (Client(address)) or reconnect before rendering"
        )
    try:
        threads = sum(client.nthreads().values())
    except (OSError, TimeoutError) as exc:
        raise ConnectionError(f"the Dask scheduler cannot be reached: {exc}") from exc
    if threads < 1:
        raise ConnectionError(
            f"the Dask cluster at {client.scheduler.address} has no workers: start some "
            "(dask worker <address>) before rendering"
        )
    return threads


def _run_chunk(job: Callable[[Span, Callable[[], bool]], Any], span: Span) -> Any:
    """On a worker: one chunk of the scattered job (its cancel is the task's own)."""
    on_worker()
    return job(span, _never)


_tuned = False


def on_worker() -> None:
    """Once per worker process: keep freed memory for the next arrays (core.workers.
    keep_freed_memory). Dask's nanny starts its workers with MALLOC_TRIM_THRESHOLD_=65536,
    so that glibc hands every freed page back at once, and a chunk's numpy temporaries are
    page-faulted in afresh: a tile took 2.5x its CPU time there (640x360 Final: 4.5-8.4 s
    against 2.1-3.2 s in SymRay's own worker processes)."""
    global _tuned
    if not _tuned:
        keep_freed_memory()
        _tuned = True


def _never() -> bool:
    """A chunk on a worker is cancelled by its task, not from inside."""
    return False


def run_on_client(
    client: Any,
    job: Callable[[Span, Callable[[], bool]], Any],
    spans: Sequence[Span],
    priorities: Sequence[float],
    cancelled: Callable[[], bool],
) -> Iterator[tuple[Span, Any]]:
    """Run job(span, cancel) for every span as Dask tasks (higher ``priorities`` first);
    yield (span, result) as each finishes. Stops once ``cancelled()`` (the tasks not yet
    finished are cancelled), and on a task's error (raised here, the rest cancelled).
    Tasks whose job was lost with a worker are sent again (``_LOST_JOB_RETRIES``)."""
    distributed = require_dask()
    token = next(_TOKENS)
    finished = distributed.as_completed()
    futures: dict[Any, Task] = {}
    todo: list[Task] = list(enumerate(zip(spans, priorities, strict=True)))
    shared = None
    try:
        for attempt in range(_LOST_JOB_RETRIES + 1):
            shared = _send(client, job, shared)
            for k, (span, p) in todo:
                key = f"symray-{token}-{k}" + (f"-{attempt}" if attempt else "")
                future = client.submit(_run_chunk, shared, span, key=key, priority=p, pure=False)
                futures[future] = (k, (span, p))
                finished.add(future)
            todo = yield from _collect(finished, futures, cancelled)
            if not todo:
                return
        raise RuntimeError(
            f"the cluster lost this render's scene {_LOST_JOB_RETRIES + 1} times (its workers "
            "keep dying): see the Dask workers' logs"
        )
    finally:
        if futures:
            client.cancel(list(futures))
        if shared is not None:
            shared.release()


_LOST_JOB_RETRIES = 3
"""How many times tasks whose job was lost are sent again before the render fails."""


def _send(client: Any, job: Any, previous: Any) -> Any:
    """The job on every worker (Client.scatter, broadcast), replacing ``previous``."""
    if previous is not None:
        previous.release()
    [shared] = client.scatter([job], broadcast=True, hash=False)
    return shared


def _collect(
    finished: Any, futures: dict[Any, Task], cancelled: Callable[[], bool]
) -> Generator[tuple[Span, Any], None, list[Task]]:
    """Yield (span, result) as ``futures`` finish, until none is left or ``cancelled()``;
    return the (index, (span, priority)) of those cancelled by the cluster. A scattered job
    has no lineage: once Dask's memory manager has dropped its extra copies, a worker that
    dies takes the last one, and the scheduler cancels every task needing it ("already
    forgotten") instead of rerunning them."""
    from distributed.client import FutureCancelledError

    lost: list[Task] = []
    while futures:
        if cancelled():
            return []
        if not finished.has_ready():
            time.sleep(_POLL_S)
            continue
        for future in finished.next_batch(block=False):
            item = futures.pop(future)
            try:
                result = future.result()
            except FutureCancelledError:  # also when lost between finishing and gathering
                lost.append(item)
                continue
            del future  # the result lives in the caller's buffers, not on the cluster
            yield item[1][0], result
    return lost


def connect(address: str, timeout_s: float = 10.0) -> Any:
    """A dask.distributed Client connected to the scheduler at ``address`` ("tcp://host:
    8786"); ConnectionError naming the address where none answers within ``timeout_s``."""
    distributed = require_dask()
    try:
        return distributed.Client(address, timeout=f"{timeout_s}s")
    except (OSError, TimeoutError) as exc:
        raise ConnectionError(
            f"no Dask scheduler answers at {address} within {timeout_s:g} s ({exc}): start "
            "one there (dask scheduler), or check the address and the firewall"
        ) from exc

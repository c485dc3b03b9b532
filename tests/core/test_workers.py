"""Chunks in forked processes and in threads: the same image, progress, cancellation,
errors and the fallback (core.workers)."""

import errno
import multiprocessing
import os
import subprocess
import sys
import threading
import time
import weakref

import numpy as np
import pytest

import core
from core import hamiltonians as hm
from core import workers

needs_fork = pytest.mark.skipif(not workers.can_fork(), reason="worker processes need fork")


def mirage_scene():
    """A custom medium from text (its model is a closure over parsed expressions: it
    cannot be pickled, so processes must inherit it) with a textured object."""
    model = hm.medium("1 + 0.4*exp(-(x**2 + y**2 + z**2)/4)", bounds=((-6,) * 3, (6,) * 3))
    board = core.Plane(
        point=(0, 6, 0), normal=(0, -1, 0), u_axis=(1, 0, 0), color=core.checker(8, 8)
    )
    return core.Scene(model=model, objects=[board], background="procedural")


def camera(size=64):
    return core.Camera.perspective(
        position=(0, -12, 1), look_at=(0, 0, 0), up=(0, 0, 1), fov_deg=50, width=size, height=size
    )


@needs_fork
def test_processes_threads_and_inline_give_the_same_image():
    scene, cam = mirage_scene(), camera()
    options = dict(method="rk4", tolerance=1e-4)  # 2 chunks (2048 + 2048 rays)
    inline = core.render(scene, cam, workers=1, **options)
    assert inline.summary["parallel"] == "inline"
    assert inline.summary["steps"] > 10 * cam.n_pixels  # the rays were integrated
    for parallel in ("processes", "threads"):
        out = core.render(scene, cam, workers=2, parallel=parallel, **options)
        assert out.summary["parallel"] == f"2 {parallel}"
        np.testing.assert_array_equal(out.rgba, inline.rgba)
        for name in ("steps", "ending", "error"):
            np.testing.assert_array_equal(out.passes[name], inline.passes[name])
        assert out.summary["steps"] == inline.summary["steps"]
    assert not workers._JOBS and not multiprocessing.active_children()  # nothing left over


@needs_fork
def test_processes_report_progress_of_every_ray_and_cancel():
    scene, cam = mirage_scene(), camera(128)  # 8 chunks of 2048 rays
    seen = []
    out = core.render(
        scene,
        cam,
        workers=2,
        parallel="processes",
        method="rk4",
        tolerance=1e-4,
        chunk_size=2048,
        passes=("steps",),
        progress=lambda done, total: seen.append((done, total)),
    )
    assert not out.cancelled
    assert [t for _, t in seen] == [cam.n_pixels] * 8
    assert [d for d, _ in seen] == sorted(d for d, _ in seen) and seen[-1][0] == cam.n_pixels
    caller = threading.get_ident()
    polled_from = set()

    def cancel_after_first_chunk():
        polled_from.add(threading.get_ident())
        return len(seen) > 8

    out = core.render(
        scene,
        cam,
        workers=2,
        parallel="processes",
        method="rk4",
        tolerance=1e-4,
        chunk_size=2048,
        passes=("steps", "ending"),
        should_cancel=cancel_after_first_chunk,
        progress=lambda done, total: seen.append((done, total)),
    )
    assert out.cancelled
    assert polled_from == {caller}  # never from a worker process (it may touch a UI)
    traced = out.passes["ending"] >= 0
    assert 0 < traced.sum() < cam.n_pixels  # what finished is kept, the rest never traced
    assert np.all(out.passes["steps"][~traced] == 0)


@needs_fork
def test_an_error_in_a_worker_process_reaches_the_caller():
    def job(span, cancel):
        if span[0] == 2:
            raise ValueError(f"bad span {span}")
        return span[0]

    latch = workers.CancelLatch(None)
    with pytest.raises(ValueError, match=r"bad span \(2, 3\)"):
        list(workers.run_chunks(job, [(0, 1), (1, 2), (2, 3), (3, 4)], "processes", 2, latch))
    results = dict(workers.run_chunks(job, [(0, 1), (1, 2)], "processes", 2, latch))
    assert results == {(0, 1): 0, (1, 2): 1}


@needs_fork
def test_without_a_process_pool_the_chunks_run_in_threads(monkeypatch):
    """No working semaphores (a container without /dev/shm): threads, same results."""

    def no_pool(*args):
        raise workers._PoolUnavailable("no semaphores")

    monkeypatch.setattr(workers, "_start_processes", no_pool)
    where = set()

    def job(span, cancel):
        where.add(threading.current_thread().name)
        return span[1] - span[0]

    spans = [(0, 3), (3, 5), (5, 9)]
    out = dict(workers.run_chunks(job, spans, "processes", 2, workers.CancelLatch(None)))
    assert out == {(0, 3): 3, (3, 5): 2, (5, 9): 4}
    assert where and threading.main_thread().name not in where


@needs_fork
def test_a_fork_that_fails_falls_back_to_threads(monkeypatch):
    """fork() can fail (ENOMEM under strict overcommit, say): the second worker does not
    start, the first is stopped, the chunks run in threads."""
    real_fork, forks = os.fork, []

    def fork_once():
        if forks:
            raise OSError(errno.ENOMEM, "Cannot allocate memory")
        forks.append(1)
        return real_fork()

    monkeypatch.setattr(os, "fork", fork_once)
    spans = [(0, 3), (3, 5), (5, 9)]
    out = dict(
        workers.run_chunks(
            lambda span, cancel: span[1] - span[0], spans, "processes", 2, workers.CancelLatch(None)
        )
    )
    assert out == {(0, 3): 3, (3, 5): 2, (5, 9): 4} and forks == [1]
    monkeypatch.undo()
    for child in multiprocessing.active_children():
        child.join(5)
    assert not multiprocessing.active_children() and not workers._JOBS


_LOW_MEMORY_CHILD = """
import resource, sys
import core
from tests.core.test_workers import camera, mirage_scene

def address_space():
    with open("/proc/self/status") as status:
        return next(int(line.split()[1]) << 10 for line in status if line.startswith("VmSize"))

scene = mirage_scene()
core.render(scene, camera(8), method="rk4", tolerance=1e-2, workers=1)  # numpy and BLAS warm
limit = address_space() + (int(sys.argv[1]) << 20)
resource.setrlimit(resource.RLIMIT_AS, (limit, resource.RLIM_INFINITY))
try:  # 48 x 48: two chunks, one per thread
    out = core.render(scene, camera(48), method="rk4", tolerance=1e-2, workers=2,
                      parallel="threads")
except MemoryError:
    print("MemoryError")
else:
    print("rendered", out.summary["parallel"], int(out.summary["steps"]))
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="RLIMIT_AS and /proc")
def test_threads_out_of_memory_raise_memory_error_never_exit():
    """Threads under an address-space limit (16, 32, 48 MiB above the warm process) end
    with MemoryError (the add-on's "ran out of memory"), never by OpenBLAS ending the process
    ("Memory allocation still failed after 10 retries", exit 1). With room enough the image
    is the one rendered inline."""
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    env = dict(os.environ, PYTHONPATH=root)
    outcomes = {}
    for mib in (16, 32, 48, 512):
        child = subprocess.run(
            [sys.executable, "-c", _LOW_MEMORY_CHILD, str(mib)],
            capture_output=True, text=True, cwd=root, env=env, timeout=120,
        )  # fmt: skip
        assert child.returncode == 0, (mib, child.returncode, child.stdout, child.stderr)
        outcomes[mib] = child.stdout.split()
    assert all(outcomes[mib] == ["MemoryError"] for mib in (16, 32))
    assert outcomes[48][0] in ("MemoryError", "rendered")
    inline = core.render(mirage_scene(), camera(48), method="rk4", tolerance=1e-2, workers=1)
    assert outcomes[512] == ["rendered", "2", "threads", str(int(inline.summary["steps"]))]


def test_a_thread_that_cannot_start_is_out_of_memory(monkeypatch):
    """A worker thread whose stack cannot be mapped raises MemoryError (the add-on's "ran
    out of memory"), not Python's RuntimeError("can't start new thread")."""

    def no_thread(self):
        raise RuntimeError("can't start new thread")

    monkeypatch.setattr(threading.Thread, "start", no_thread)
    monkeypatch.setattr(workers, "_blas_callers", 1)  # as in a fresh process
    with pytest.raises(MemoryError, match="BLAS buffers"):  # _prepare_blas's helper thread
        list(workers.run_chunks(_chunk_of_rays, [(0, 10)], "threads", 1, workers.CancelLatch(None)))
    monkeypatch.setattr(workers, "_blas_callers", 2)  # as if prepared: the pool's thread
    with pytest.raises(MemoryError, match="worker thread"):
        list(workers.run_chunks(_chunk_of_rays, [(0, 10)], "threads", 1, workers.CancelLatch(None)))


def _chunk_of_rays(span, cancel):
    return np.zeros((span[1] - span[0], 16))


@pytest.mark.parametrize("kind", ["threads", pytest.param("processes", marks=needs_fork)])
def test_finished_chunks_are_not_kept_by_the_pool(kind):
    """Memory stays bounded by the chunks in flight: once the caller has stored a chunk,
    nothing in the pool holds it (a 1080p frame's results are 260 MB)."""
    spans = [(s, s + 1000) for s in range(0, 8000, 1000)]
    alive = []
    for _span, result in workers.run_chunks(
        _chunk_of_rays, spans, kind, 2, workers.CancelLatch(None)
    ):
        assert result.shape == (1000, 16)
        alive.append(weakref.ref(result))
        del result
        assert sum(ref() is not None for ref in alive[:-2]) == 0


@pytest.mark.parametrize("kind", ["threads", pytest.param("processes", marks=needs_fork)])
@pytest.mark.parametrize("count", [1, 2, 3])
def test_chunks_handed_out_are_bounded_by_what_the_caller_took(kind, count):
    """Back-pressure: workers faster than the caller never run more than
    IN_FLIGHT_PER_WORKER chunks per worker ahead of it, whatever the number of chunks
    (before, every chunk was handed out at once and the results piled up)."""
    started = multiprocessing.get_context("fork" if kind == "processes" else None).Value("i", 0)

    def job(span, cancel):
        with started.get_lock():
            started.value += 1
        return np.zeros((span[1] - span[0], 16))

    spans = [(s, s + 100) for s in range(0, 6000, 100)]
    limit = workers.IN_FLIGHT_PER_WORKER * count
    taken = 0
    for span, result in workers.run_chunks(job, spans, kind, count, workers.CancelLatch(None)):
        taken += 1
        assert result.shape == (100, 16) and span[0] % 100 == 0
        assert started.value <= taken - 1 + limit, (started.value, taken)
        if taken < 4:
            time.sleep(0.05)  # a slow caller: the workers could run far ahead
    assert taken == len(spans) and started.value == len(spans)


def test_choose_picks_processes_for_big_images_where_fork_exists(monkeypatch):
    monkeypatch.setattr(workers, "available_cores", lambda: 8)
    big, small = workers.PROCESS_MIN_RAYS, workers.PROCESS_MIN_RAYS - 1
    if workers.can_fork():
        assert workers.choose("auto", None, big) == ("processes", 8)  # every core
    assert workers.choose("auto", None, small) == ("threads", 2)  # threads: at most two
    assert workers.choose("threads", None, big) == ("threads", 2)
    assert workers.choose("threads", 5, big) == ("threads", 5)
    assert workers.choose("auto", 1, big) == ("inline", 1)
    if workers.can_fork():
        assert workers.choose("auto", None, big, cores=3) == ("processes", 3)  # e.g. -t 3
    assert workers.choose("auto", None, big, cores=1) == ("inline", 1)
    assert workers.choose("threads", None, big, cores=1) == ("threads", 1)
    monkeypatch.setattr(workers, "can_fork", lambda: False)
    assert workers.choose("processes", 3, big) == ("threads", 3)
    with pytest.raises(ValueError, match="parallel"):
        workers.choose("gpu", None, big)
    with pytest.raises(ValueError, match="workers"):
        workers.choose("auto", 0, big)
    with pytest.raises(ValueError, match="cores"):
        workers.choose("auto", None, big, cores=0)

"""core.render(client=) on a real Dask cluster (distributed.LocalCluster: worker processes,
TCP on localhost), core.sweep, and the errors for what cannot work (issue 49)."""

from __future__ import annotations

import json
import os
import signal
import sys
import time

import numpy as np
import pytest

import core
from benchmarks import cluster as bench
from benchmarks import frame
from core.render import expected_cost_rank
from core.sweep import read_table

distributed = pytest.importorskip("distributed")
dask = pytest.importorskip("dask")

PREVIEW = {"tolerance_px": 1.0}


def _cluster(workers: int = 2):
    """A LocalCluster of single-thread worker processes and its client."""
    local = distributed.LocalCluster(
        n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=":0"
    )
    return local, distributed.Client(local)


@pytest.fixture(scope="module")
def client():
    """One cluster for the tests that do not harm it."""
    local, client = _cluster()
    yield client
    client.close()
    local.close()


def _board(width: int = 96, height: int = 54):
    """The Kerr board and its camera (benchmarks/frame.py)."""
    return frame.kerr_board_scene(), frame.camera(width, height)


def _same(a: core.RenderResult, b: core.RenderResult) -> None:
    """Two renders equal bit for bit: colour, every pass, rays and steps."""
    np.testing.assert_array_equal(a.rgba, b.rgba)
    assert a.passes.keys() == b.passes.keys()
    for name in a.passes:
        np.testing.assert_array_equal(a.passes[name], b.passes[name], err_msg=name)
    for key in ("rays", "steps", "failed", "error_rays"):
        assert a.summary[key] == b.summary[key], key


@pytest.mark.parametrize("options", [PREVIEW, {"tolerance_px": 0.5, "samples": 4}, {}])
def test_the_clusters_image_equals_the_local_one(client, options):
    """Adaptive (Preview, anti-aliased) and dense renders on the cluster equal a local
    render with the same worker count, bit for bit; progress reaches every pixel."""
    scene, camera = _board()
    seen = []
    on_cluster = core.render(
        scene, camera, client=client, progress=lambda d, t: seen.append((d, t)), **options
    )
    local = core.render(scene, camera, workers=2, **options)
    _same(on_cluster, local)
    assert on_cluster.summary["parallel"] == "2 dask" and not on_cluster.cancelled
    assert seen[-1] == (camera.n_pixels, camera.n_pixels)
    assert [d for d, _ in seen] == sorted(d for d, _ in seen)


def test_the_costliest_tiles_go_first():
    """Chunks through the middle of the frame (rays passing nearest the hole) rank highest."""
    _, camera = _board(64, 36)
    middles = [(32, 2), (32, 18), (2, 18), (60, 30)]
    rank = expected_cost_rank(camera, (0, 0, 0), middles)
    assert rank[1] == max(rank) and sorted(rank) == [0, 1, 2, 3]


def _symray_tasks(client) -> list[str]:
    """The scheduler's SymRay tasks (core.cluster names them symray-<render>-<chunk>)."""

    def names(dask_scheduler) -> list[str]:
        return [str(k) for k in dask_scheduler.tasks if str(k).startswith("symray-")]

    return client.run_on_scheduler(names)


def test_a_cancel_cancels_the_clusters_tasks(client):
    """should_cancel turning true after the first tile: a cancelled result, fewer pixels
    done than the image, and no SymRay task left on the scheduler."""
    scene, camera = _board(128, 72)
    done = []
    result = core.render(
        scene, camera, client=client, workers=4, progress=lambda d, t: done.append(d),
        should_cancel=lambda: bool(done), **PREVIEW,
    )  # fmt: skip
    assert result.cancelled and done and done[-1] < camera.n_pixels
    deadline = time.monotonic() + 10
    while _symray_tasks(client) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert _symray_tasks(client) == []


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="kills a process by pid")
@pytest.mark.parametrize("victim", [0, 1])
def test_a_worker_killed_mid_render_costs_only_a_retry(victim):
    """Either of two worker processes killed (SIGKILL) once the first tile is in: its tiles
    are rerun elsewhere; the image is complete and equal to the local render. Dask's memory
    manager runs every 20 ms, so the scattered scene is kept on one worker only (as it is
    on a long render): one of the two kills takes its last copy, which is sent again."""
    with dask.config.set({"distributed.scheduler.active-memory-manager.interval": "20ms"}):
        local, client = _cluster()
    try:
        scene, camera = _board()
        pids = client.run(os.getpid)
        killed = sorted(pids.values())[victim]
        kills = []

        def kill_once(done: int, total: int) -> None:
            if not kills:
                time.sleep(0.1)  # the memory manager's turn
                os.kill(killed, signal.SIGKILL)
                kills.append(done)

        result = core.render(scene, camera, client=client, workers=4, progress=kill_once,
                             **PREVIEW)  # fmt: skip
        assert kills and kills[0] < camera.n_pixels  # killed while tiles were left
        assert not result.cancelled
        _same(result, core.render(scene, camera, workers=4, **PREVIEW))
        assert killed not in client.run(os.getpid).values()
    finally:
        client.close()
        local.close()


def test_a_cluster_that_cannot_be_reached_is_named_before_any_work():
    """A client whose cluster has gone, an address nobody answers at, and something that
    is not a Client: clear errors, and nothing traced (progress never called)."""
    scene, camera = _board(16, 9)
    local, client = _cluster(1)
    local.close()
    client.close()
    calls = []
    with pytest.raises(ConnectionError, match="not connected to its cluster"):
        core.render(scene, camera, client=client, progress=lambda *a: calls.append(a))
    assert calls == []
    with pytest.raises(ConnectionError, match=r"no Dask scheduler answers at tcp://127\.0\.0"):
        core.cluster.connect("tcp://127.0.0.1:9", timeout_s=1.0)
    with pytest.raises(TypeError, match="must be a dask.distributed Client, not str"):
        core.render(scene, camera, client="tcp://127.0.0.1:9")


def test_without_dask_client_names_the_package(monkeypatch):
    """Dask is optional: where it is missing, client= says what to install."""
    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed fails
    scene, camera = _board(16, 9)
    with pytest.raises(ImportError, match=r"pip install 'dask\[distributed\]==2026\.8\.0'"):
        core.render(scene, camera, client=object())


GRID = {"spin": [0.0, 0.5, 0.9], "inclination": [30, 60, 85], "size": [16]}


class _Stop(Exception):
    """Stands for a sweep interrupted (a killed job, Ctrl-C)."""


def test_a_sweep_interrupted_after_four_images_resumes(tmp_path):
    """A 3x3 sweep stopped after 4 images, then rerun: 9 images, the 4 not redone; each
    image equals its own render; the table holds every image's figures."""
    written = []

    def stop_after_four(point, row) -> None:
        written.append(point.index)
        if len(written) == 4:
            raise _Stop

    with pytest.raises(_Stop):
        core.sweep(bench.kerr_view, GRID, tmp_path, fmt="npz", on_image=stop_after_four,
                   **PREVIEW)  # fmt: skip
    assert len(list(tmp_path.glob("*.npz"))) == 4
    rerun = []
    rows = core.sweep(bench.kerr_view, GRID, tmp_path, fmt="npz",
                      on_image=lambda p, r: rerun.append(p.index), **PREVIEW)  # fmt: skip
    assert len(rows) == 9 and len(list(tmp_path.glob("*.npz"))) == 9
    assert sorted(rerun) == sorted(set(range(9)) - set(written))  # the 4 not redone
    table = read_table(tmp_path)
    assert [(float(r["spin"]), float(r["inclination"])) for r in table] == [
        (s, i) for s in GRID["spin"] for i in GRID["inclination"]
    ]
    assert all(int(r["rays"]) > 0 and float(r["error_px_max"]) >= 0 for r in table)
    record = json.loads(next(tmp_path.glob("00004-*.json")).read_text())
    assert record["params"] == {"spin": 0.5, "inclination": 60, "size": 16}
    image = np.load(tmp_path / record["image"])
    own = core.render(*bench.kerr_view(0.5, 60, 16), **PREVIEW)
    np.testing.assert_array_equal(image["rgba"], own.rgba)
    np.testing.assert_array_equal(image["error_px"], own.passes["error_px"])


def test_a_damaged_image_is_made_again(tmp_path):
    """A rerun checks each image's bytes against its record: a truncated file is redone."""
    grid = {"spin": [0.0, 0.9], "size": [12]}
    core.sweep(bench.kerr_view, grid, tmp_path, **PREVIEW)
    victim = sorted(tmp_path.glob("*.exr"))[1]
    victim.write_bytes(victim.read_bytes()[:100])
    redone = []
    core.sweep(bench.kerr_view, grid, tmp_path, on_image=lambda p, r: redone.append(p.index),
               **PREVIEW)  # fmt: skip
    assert redone == [1]


def test_a_sweep_on_the_cluster_writes_what_a_local_one_does(client, tmp_path):
    """Each image a task: the table's figures and the images equal a local sweep's with
    the same workers (the image's tiling)."""
    grid = {"spin": [0.0, 0.9], "tolerance_px": [1.0, 0.5], "size": [16]}
    local = core.sweep(bench.kerr_view, grid, tmp_path / "here", fmt="npz", workers=2)
    remote = core.sweep(bench.kerr_view, grid, tmp_path / "there", fmt="npz", workers=2,
                        client=client)  # fmt: skip
    assert [{k: v for k, v in r.items() if k != "time_s"} for r in remote] == [
        {k: v for k, v in r.items() if k != "time_s"} for r in local
    ]
    for here in sorted((tmp_path / "here").glob("*.npz")):
        there = np.load(tmp_path / "there" / here.name)
        np.testing.assert_array_equal(np.load(here)["rgba"], there["rgba"])


def test_a_sweep_refuses_what_it_cannot_do(tmp_path):
    """Unknown render options, an empty grid and a bad format are named."""
    with pytest.raises(TypeError, match="no option"):
        core.sweep(bench.kerr_view, GRID, tmp_path, tolerance_pix=1.0)
    with pytest.raises(ValueError, match="non-empty list"):
        core.sweep(bench.kerr_view, {"spin": []}, tmp_path)
    with pytest.raises(ValueError, match="fmt must be one of"):
        core.sweep(bench.kerr_view, GRID, tmp_path, fmt="png")

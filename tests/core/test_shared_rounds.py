"""Shared rounds (core.tracing.shared_rounds): the Tracer.trace calls of a worker's tiles,
each tile on a thread of its own, traced together in one batch per tracer; every call
gets exactly (bitwise) what tracing it on its own gives, and an image rendered with its
tiles grouped equals one rendered tile by tile."""

from __future__ import annotations

import importlib
import threading

import numpy as np
import pytest

import core
from core import hamiltonians as hm
from core.trace import TraceOptions, Tracer
from core.tracing import shared_rounds
from core.tracing.segments import RayResults
from core.tracing.shared_rounds import SharedRounds

render_module = importlib.import_module("core.render")  # core.render is the function
FIELDS = [name for name in RayResults.__dataclass_fields__]


def _board_scene() -> core.Scene:
    board = core.Plane(point=(0, 12, 0), normal=(0, -1, 0), u_axis=(1, 0, 0), extent=(16, 16),
                       color=(0.9, 0.7, 0.2, 1))  # fmt: skip
    ball = core.Sphere(center=(3, 4, 1), radius=0.5, color=(0.2, 0.4, 0.9, 1))
    return core.Scene(model=hm.kerr(rg=1.0, a=0.45, chart="kerr_schild"), objects=[board, ball])


def _camera(width: int = 24, height: int = 18) -> core.Camera:
    return core.Camera.perspective(position=(0, -30, 2), look_at=(0, 0, 0), up=(0, 0, 1),
                                   fov_deg=40, width=width, height=height)  # fmt: skip


def _calls(tracer: Tracer, origins, directions) -> list[list[dict]]:
    """Three members' trace calls (rounds of unlike size, step and clearance share; the
    third has one round fewer than the others)."""
    n, h = len(origins), tracer.step
    rows = np.array_split(np.random.default_rng(3).permutation(n), 6)
    share = np.linspace(0.0, 1.0, rows[1].size)
    return [
        [dict(rows=rows[0], step=None, clearance=None),
         dict(rows=rows[3], step=2 * h, clearance=rows[3] % 2 == 0)],
        [dict(rows=rows[1], step=np.full(rows[1].size, 0.5 * h), clearance=share),
         dict(rows=rows[4], step=None, clearance=None)],
        [dict(rows=np.concatenate([rows[2], rows[5]]), step=h, clearance=None)],
    ]  # fmt: skip


def _own(tracer: Tracer, origins, directions, call: dict) -> RayResults:
    rows = call["rows"]
    return tracer.trace(origins[rows], directions[rows], step=call["step"],
                        clearance=call["clearance"])  # fmt: skip


def test_calls_of_several_threads_traced_together_equal_their_own_traces(monkeypatch):
    """Three members, five calls at three steps, with and without clearance shares: traced
    in two shared batches (the members' first calls, then their second), and every
    field of every call's results equals that call traced alone."""
    tracer = Tracer(_board_scene(), TraceOptions(method="blanes_moan_s10", tolerance=1e-6),
                    extent=30)  # fmt: skip
    tracer.watch_geometry(0.05)
    origins, directions = _camera().rays()
    members = _calls(tracer, origins, directions)
    alone = [[_own(tracer, origins, directions, call) for call in calls] for calls in members]
    batches = []
    traced = tracer.trace

    def counted(*args, **kwargs):
        if shared_rounds.joined() is None:  # the shared batch itself
            batches.append(len(args[0]))
        return traced(*args, **kwargs)

    monkeypatch.setattr(tracer, "trace", counted)

    def member(calls):
        return lambda: [_own(tracer, origins, directions, call) for call in calls]

    together = SharedRounds().run([member(calls) for calls in members])
    assert batches == [sum(len(calls[0]["rows"]) for calls in members),
                       sum(len(calls[1]["rows"]) for calls in members[:2])]  # fmt: skip
    endings = np.concatenate([r.ending for rs in alone for r in rs])
    assert len(np.unique(endings)) >= 3  # hits, escapes and captures among them
    for own_results, shared_results in zip(alone, together, strict=True):
        for own, shared in zip(own_results, shared_results, strict=True):
            for name in FIELDS:
                np.testing.assert_array_equal(getattr(shared, name), getattr(own, name),
                                              err_msg=name)  # fmt: skip


def test_calls_with_and_without_tangents_are_traced_apart_and_exactly():
    """A call with ray differentials and one without cannot share a batch: each is traced
    on its own, and each equals its own trace."""
    tracer = Tracer(_board_scene(), TraceOptions(method="blanes_moan_s10", tolerance=1e-6),
                    extent=30)  # fmt: skip
    camera = _camera(8, 6)
    origins, directions = camera.rays()
    tangents = camera.direction_tangents(camera.pixel_centres(0, camera.n_pixels))
    calls = [lambda: tracer.trace(origins, directions, tangents=tangents),
             lambda: tracer.trace(origins[::-1], directions[::-1])]  # fmt: skip
    together = SharedRounds().run(calls)
    alone = [call() for call in calls]
    for own, shared in zip(alone, together, strict=True):
        for name in FIELDS:
            np.testing.assert_array_equal(getattr(shared, name), getattr(own, name),
                                          err_msg=name)  # fmt: skip


class _FailingTracer:
    step = 1.0

    def trace(self, origins, directions, **options):
        raise RuntimeError("the batch failed")


def test_an_error_reaches_the_caller_and_no_member_waits_forever():
    """A member that raises before tracing lets the others' calls go; an error in the
    shared batch reaches every member whose call was in it; run raises the first."""
    tracer = Tracer(_board_scene(), TraceOptions(tolerance=1e-6), extent=30)
    origins, directions = _camera(6, 4).rays()
    results = []

    def fails():
        raise ValueError("this tile's own error")

    def traces():
        results.append(tracer.trace(origins, directions))

    runner = threading.Thread(target=lambda: pytest.raises(ValueError, SharedRounds().run,
                                                           [fails, traces]))  # fmt: skip
    runner.start()
    runner.join(timeout=60)
    assert not runner.is_alive() and len(results) == 1
    assert np.array_equal(results[0].ending, tracer.trace(origins, directions).ending)

    failing, errors = _FailingTracer(), []

    def member():
        try:
            SharedRounds.trace(rounds, failing, origins, directions, step=None, cancel=None,
                               tangents=None, clearance=None)  # fmt: skip
        except RuntimeError as exc:
            errors.append(exc)
            raise

    rounds = SharedRounds()
    with pytest.raises(RuntimeError, match="the batch failed"):
        rounds.run([member, member])
    assert len(errors) == 2


def test_an_image_of_grouped_tiles_equals_one_rendered_tile_by_tile(
    monkeypatch, tiles_refined, rounds_free
):
    """core.render by one worker renders its tiles together in shared rounds, and gives
    the image, every pass and the ray counts of a render tile by tile, to the last bit."""
    scene, camera = _board_scene(), _camera(96, 64)
    passes = ("error_px", "steps", "ending", "position", "direction")
    options = dict(tolerance_px=0.5, passes=passes, workers=1)
    grouped_by = render_module.tile_groups
    tiles = render_module._tiles_for(camera, 1)
    assert len(tiles) >= 2 and len(grouped_by(tiles, list(range(len(tiles))), 1)) == 1
    grouped = core.render(scene, camera, **options)
    monkeypatch.setattr(render_module, "tile_groups",
                        lambda tiles, ranks, workers: [[k] for k in range(len(tiles))])  # fmt: skip
    alone = core.render(scene, camera, **options)
    np.testing.assert_array_equal(grouped.rgba, alone.rgba)
    for name in passes:
        np.testing.assert_array_equal(grouped.passes[name], alone.passes[name], err_msg=name)
    for key in ("rays", "error_rays", "companion_rays"):
        assert grouped.summary[key] == alone.summary[key], key


def test_one_worker_groups_its_tiles_within_the_memory_bound_and_many_take_them_alone():
    """tile_groups: one worker's tiles in groups of at most MAX_TILE_PIXELS pixels (each
    tile once, the costliest first); with several workers every tile alone, costliest
    first."""
    tile = render_module.sampling_module.tiling.Tile
    most = render_module.sampling_module.tiling.MAX_TILE_PIXELS
    tiles = [tile(0, 0, 512, most // 512 // 3)] * 7  # three to a group
    ranks = [3, 6, 0, 5, 1, 4, 2]
    groups = render_module.tile_groups(tiles, ranks, 1)
    assert groups == [[1, 3, 5], [0, 6, 4], [2]]
    assert render_module.tile_groups(tiles, ranks, 4) == [[1], [3], [5], [0], [6], [4], [2]]


def test_a_pool_of_threads_shares_its_tiles_rounds_and_draws_the_same_image(
    monkeypatch, tiles_refined, rounds_free
):
    """With parallel="threads" the tiles the pool's threads render at once trace their
    rounds in shared batches (SharedRounds.member): some batches hold two tiles' calls,
    and the image and passes equal those of the same tiles rendered one by one inline, to
    the last bit."""
    scene, camera = _board_scene(), _camera(96, 64)
    passes = ("error_px", "steps", "ending", "direction")
    shared_calls = []
    together = shared_rounds._trace_together

    def counted(calls):
        shared_calls.append(len(calls))
        together(calls)

    monkeypatch.setattr(shared_rounds, "_trace_together", counted)
    threads = core.render(scene, camera, tolerance_px=0.5, passes=passes, workers=2,
                          parallel="threads")  # fmt: skip
    assert threads.summary["parallel"] == "2 threads" and max(shared_calls) >= 2
    monkeypatch.setattr(render_module, "tile_groups",
                        lambda tiles, ranks, workers: [[k] for k in range(len(tiles))])  # fmt: skip
    monkeypatch.setattr(render_module.workers_module, "choose", lambda *a, **k: ("inline", 2))
    inline = core.render(scene, camera, tolerance_px=0.5, passes=passes)  # the same tiles
    np.testing.assert_array_equal(threads.rgba, inline.rgba)
    for name in passes:
        np.testing.assert_array_equal(threads.passes[name], inline.passes[name], err_msg=name)

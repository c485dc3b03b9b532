"""core.sweep: many renders from one description, written as they finish, resumable.

A sweep is a function that builds a scene and a camera from parameters (``make(**p) ->
(Scene, Camera)``) and a grid of values: every combination is one image. A grid name that
is one of core.render's keywords (``tolerance_px``, ``observer``, ``samples``, ...) goes to
core.render; every other name to ``make``. Each image is written to ``out`` as
``<index>-<hash>.exr`` (or ``.npz``; its colour and passes) with ``<index>-<hash>.json``
(its parameters, summary and the image file's SHA-256) written after it, both atomically;
``sweep.csv`` tabulates the parameters and the error figures of every finished image
and is rewritten as each finishes. The hash is of the parameters, so a rerun finds an
image it already made, checks that its file is intact (the JSON parses, the hash of the
bytes on disk matches) and skips it; a changed grid makes new names.

With a ``client`` (dask.distributed) each image is one task, the scene built on the
worker (``make`` and the render options are sent, pickled by cloudpickle), rendered
there in the task's thread (``workers`` N: N threads, tiled as N local processes tile it,
so the image equals a local sweep's with the same ``workers``), and written here as it
comes back: many small images fill a cluster better than one image's tiles. Without one
the images are rendered here one after another, each with core.render's own workers.
"""

from __future__ import annotations

import csv
import hashlib
import inspect
import io
import itertools
import json
import math
import os
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from . import cluster
from .imageio import atomic_write, exr_bytes
from .render import RenderResult, render

FORMATS = ("exr", "npz")
TABLE = "sweep.csv"
"""The table of a sweep's finished images, in ``out``."""
FIGURES = ("time_s", "rays", "steps", "failed", "error_px_median", "error_px_max")
"""The summary's figures each row of the table gives (core.render's summary keys)."""
_RENDER_KEYWORDS = frozenset(
    name for name in inspect.signature(render).parameters if name not in ("scene", "camera")
)


@dataclass(frozen=True)
class Point:
    """One image of a sweep: its index, parameters and file stem."""

    index: int
    params: dict[str, Any]
    stem: str


def points(grid: Mapping[str, Sequence[Any]]) -> list[Point]:
    """Every combination of ``grid``'s values (the last name varying fastest), named
    ``<index>-<hash of the parameters>``."""
    if not grid:
        raise ValueError("a sweep's grid needs at least one parameter with values")
    names = list(grid)
    for name in names:
        if isinstance(grid[name], str) or not len(grid[name]):
            raise ValueError(f"grid '{name}' must be a non-empty list of values")
    out = []
    for k, values in enumerate(itertools.product(*(grid[name] for name in names))):
        params = dict(zip(names, values, strict=True))
        digest = hashlib.sha256(_canonical(params).encode()).hexdigest()[:10]
        out.append(Point(k, params, f"{k:05d}-{digest}"))
    return out


def _canonical(params: Mapping[str, Any]) -> str:
    """The parameters as JSON, keys sorted (values JSON can hold, numpy scalars as such)."""
    try:
        return json.dumps(params, sort_keys=True, default=_plain)
    except TypeError as exc:
        raise TypeError(f"sweep parameters must be numbers, strings or lists: {exc}") from None


def _plain(value: Any) -> Any:
    """numpy scalars and arrays as Python numbers and lists (for JSON)."""
    if isinstance(value, np.generic | np.ndarray):
        return value.tolist()
    raise TypeError(f"{type(value).__name__} is not JSON")


def sweep(
    make: Callable[..., tuple[Any, Any]],
    grid: Mapping[str, Sequence[Any]],
    out: str | os.PathLike,
    *,
    client: Any = None,
    fmt: str = "exr",
    on_image: Callable[[Point, dict], None] | None = None,
    **render_options: Any,
) -> list[dict]:
    """Render every combination of ``grid`` (module doc) into ``out``; -> the table's rows
    (parameters and FIGURES, in grid order). Images already in ``out`` and intact are not
    rendered again. ``render_options``: core.render's keywords for every image (a grid
    name overrides one). ``on_image(point, row)`` is called as each image is written."""
    if fmt not in FORMATS:
        raise ValueError(f"fmt must be one of {FORMATS}, not {fmt!r}")
    unknown = set(render_options) - _RENDER_KEYWORDS
    if unknown:
        raise TypeError(f"core.render has no option {sorted(unknown)}")
    folder = Path(out)
    folder.mkdir(parents=True, exist_ok=True)
    todo, rows = [], {}
    for point in points(grid):
        row = _finished_row(folder, point, fmt)
        if row is None:
            todo.append(point)
        else:
            rows[point.index] = row
    if client is not None:
        cluster.check_client(client)
        results = _on_cluster(client, make, todo, render_options)
    else:
        results = ((p, _render_point(make, p.params, render_options)) for p in todo)
    for point, result in results:
        rows[point.index] = _write_point(folder, point, result, fmt)
        _write_table(folder, [rows[k] for k in sorted(rows)])
        if on_image is not None:
            on_image(point, rows[point.index])
    if not todo:  # nothing rendered: the table as the records say
        _write_table(folder, [rows[k] for k in sorted(rows)])
    return [rows[k] for k in sorted(rows)]


def _render_point(make, params: Mapping[str, Any], options: Mapping[str, Any]) -> RenderResult:
    """Build one point's scene and camera and render it."""
    for_render = {k: v for k, v in params.items() if k in _RENDER_KEYWORDS}
    scene, camera = make(**{k: v for k, v in params.items() if k not in _RENDER_KEYWORDS})
    return render(scene, camera, **{**options, **for_render})


def _render_on_worker(make, params, options) -> RenderResult:
    """A task on a cluster's worker: _render_point, the worker's memory kept (on_worker)."""
    cluster.on_worker()
    return _render_point(make, params, options)


def _on_cluster(client, make, todo: Sequence[Point], options) -> Iterator[tuple[Point, Any]]:
    """Each point rendered as a task on ``client``'s cluster (one worker thread each);
    yields (point, result) as they finish; the rest cancelled if the caller stops."""
    distributed = cluster.require_dask()
    # in the task's own thread (threads: workers=N tiles the image as N local processes do)
    options = {"workers": 1, **options, "parallel": "threads"}
    futures = {
        client.submit(_render_on_worker, make, p.params, options, pure=False): p for p in todo
    }
    try:
        for future in distributed.as_completed(list(futures)):
            point = futures.pop(future)
            yield point, future.result()
    finally:
        if futures:
            client.cancel(list(futures))


def _image_bytes(result: RenderResult, fmt: str) -> bytes:
    """The image file's bytes: RGBA and every numeric (h, w) pass, float32 (EXR channels
    by name; npz arrays ``rgba`` and the passes)."""
    passes = {
        name: np.asarray(value, dtype=np.float32)
        for name, value in result.passes.items()
        if np.ndim(value) == 2 and np.issubdtype(np.asarray(value).dtype, np.number)
    }
    rgba = np.asarray(result.rgba, dtype=np.float32)
    if fmt == "exr":
        channels = {c: rgba[..., i] for i, c in enumerate("RGBA")}
        return exr_bytes({**channels, **passes})
    buffer = io.BytesIO()
    arrays: dict[str, Any] = {"rgba": rgba, **passes}
    np.savez_compressed(buffer, **arrays)
    return buffer.getvalue()


def _write_point(folder: Path, point: Point, result: RenderResult, fmt: str) -> dict:
    """Write one image and then its JSON record (atomically, each); -> its table row."""
    data = _image_bytes(result, fmt)
    atomic_write(folder / f"{point.stem}.{fmt}", _writer(data))
    row = {**point.params, **_figures(result.summary)}
    record = {
        "params": point.params,
        "row": row,
        "image": f"{point.stem}.{fmt}",
        "sha256": hashlib.sha256(data).hexdigest(),
        "cancelled": result.cancelled,
    }
    atomic_write(folder / f"{point.stem}.json", _writer(_canonical(record).encode()))
    return row


def _writer(data: bytes) -> Callable[[str], None]:
    """A write(temp_path) for atomic_write that writes ``data``."""

    def write(path: str) -> None:
        with open(path, "wb") as f:
            f.write(data)

    return write


def _figures(summary: Mapping[str, Any]) -> dict[str, Any]:
    """FIGURES from a render's summary (None where it has none, finite numbers only)."""
    out = {}
    for key in FIGURES:
        value = summary.get(key)
        if isinstance(value, np.generic):
            value = value.item()
        if isinstance(value, float) and not math.isfinite(value):
            value = None
        out[key] = value
    return out


def _finished_row(folder: Path, point: Point, fmt: str) -> dict | None:
    """The table row of an image already written for ``point`` and intact (its record
    parses, names these parameters, was not cancelled, and its file's hash matches)."""
    try:
        record = json.loads((folder / f"{point.stem}.json").read_text())
        data = (folder / record["image"]).read_bytes()
    except (OSError, ValueError, KeyError, TypeError):
        return None
    intact = (
        record.get("image") == f"{point.stem}.{fmt}"
        and record.get("params") == json.loads(_canonical(point.params))
        and not record.get("cancelled")
        and record.get("sha256") == hashlib.sha256(data).hexdigest()
    )
    return record["row"] if intact else None


def _write_table(folder: Path, rows: Sequence[Mapping[str, Any]]) -> None:
    """sweep.csv: one row per finished image (atomically replaced)."""
    names: list[str] = []
    for row in rows:
        names += [k for k in row if k not in names]
    text = io.StringIO()
    table = csv.DictWriter(text, fieldnames=names, lineterminator="\n")
    table.writeheader()
    table.writerows(rows)
    atomic_write(folder / TABLE, _writer(text.getvalue().encode()))


def read_table(out: str | os.PathLike) -> list[dict[str, str]]:
    """The rows of a sweep's table (``out``/sweep.csv) as strings."""
    with open(Path(out) / TABLE, newline="") as f:
        return list(csv.DictReader(f))


__all__ = ["FIGURES", "FORMATS", "TABLE", "Point", "points", "read_table", "sweep"]

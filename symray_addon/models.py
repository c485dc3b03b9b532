"""SymRay settings -> the core's model (a Hamiltonian) and where it sits in the world.

Pure Python apart from reading property values, so the same code serves the operator
and the render engine. Every problem is raised as a ValueError with a message meant for
the user (``core.expressions.ExpressionError`` is one).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any

import numpy as np

from ..core import AccretionDisk, Scene, expressions
from ..core import hamiltonians as hm
from ..core.models.medium_scan import index_pole
from ..core.models.registry import model_kind, parameters
from ..core.render import check_scene_camera
from . import objects, validation
from .capabilities import capabilities


@dataclass(frozen=True)
class Placement:
    """Where the model sits: centre (3,), unit spin axis (3,), rotation (3, 3) local->world."""

    center: np.ndarray
    axis: np.ndarray
    rotation: np.ndarray


def placement(matrix_world: Any | None) -> Placement:
    """Placement from the centre object's world matrix (None = the world origin, +Z up)."""
    if matrix_world is None:
        return Placement(np.zeros(3), np.array([0.0, 0.0, 1.0]), np.eye(3))
    m = np.array(matrix_world, dtype=np.float64)
    if m.shape != (4, 4) or not np.all(np.isfinite(m)):
        raise ValueError("The SymRay centre object has an invalid transform")
    basis = m[:3, :3]
    norms = np.linalg.norm(basis, axis=0)
    if np.any(norms < 1e-12):
        raise ValueError("The SymRay centre object has zero scale")
    q, r = np.linalg.qr(basis)
    q = q * np.sign(np.diag(r))  # orthonormal rotation closest to the object's axes
    if np.linalg.det(q) < 0:  # a mirrored centre object: keep a proper rotation, same Z
        q[:, 0] = -q[:, 0]
    return Placement(m[:3, 3].copy(), q[:, 2].copy(), q)


def _expression(text: str, names: tuple[str, ...], what: str) -> str:
    """``text`` if valid over ``names``; else a ValueError naming ``what`` and the problem."""
    try:
        expressions.check(text, names)
    except expressions.ExpressionError as err:
        raise expressions.ExpressionError(f"Invalid {what}: {err}", None) from None
    return text


def build_model(settings: Any, metric_source: str) -> Any | None:
    """The core Hamiltonian for ``settings`` (a scene.symray), or None for flat space: a
    kind of core.models.registry built from its parameters, or from its text inputs."""
    settings = objects.effective(settings)
    kind = model_kind(settings.model)
    if kind.inputs:
        return _FROM_TEXT[kind.inputs](settings, metric_source)
    if kind.build is None:
        return None
    values = {name: float(getattr(settings, name)) for name in kind.parameter_names()}
    problem = kind.problem(values)
    if problem:
        raise ValueError(problem)
    return kind.build(**values)


def _medium(settings: Any, _metric_source: str) -> Any:
    """A medium from the Refractive Index text, its optical form and its box."""
    index = _expression(
        settings.refractive_index, validation.INDEX_NAMES, "refractive index n(x, y, z)"
    )
    bounds = None
    if settings.use_medium_bounds:
        lo, hi = np.array(settings.medium_min), np.array(settings.medium_max)
        if np.any(hi <= lo):
            raise ValueError("The medium's box is empty: every Box Max must exceed Box Min")
        bounds = (lo, hi)
    model = hm.medium(index, literal=settings.index_form == "SEED", bounds=bounds)
    if bounds is not None:
        check_index_in_box(model, *bounds)
    return model


def _metric(_settings: Any, metric_source: str) -> Any:
    """A spacetime from the inverse-metric text."""
    try:
        spec = validation.parse_metric(metric_source)
    except expressions.ExpressionError as err:
        raise expressions.ExpressionError(f"Invalid metric: {err}", None) from None
    return hm.metric(
        inverse=[list(row) for row in spec.rows],
        coords=validation.METRIC_NAMES,
        definitions=list(spec.definitions),
    )


def _hamiltonian(settings: Any, _metric_source: str) -> Any:
    """A Hamiltonian from its text over (x, y, z, p_x, p_y, p_z)."""
    text = _expression(settings.hamiltonian, validation.HAMILTONIAN_NAMES, "Hamiltonian")
    return hm.from_expression(
        text, q=list(validation.HAMILTONIAN_COORDS), p=list(validation.HAMILTONIAN_MOMENTA)
    )


_FROM_TEXT = {"index": _medium, "metric": _metric, "hamiltonian": _hamiltonian}
"""A registry kind's ``inputs`` -> its reader (settings, metric text) -> the core model."""


def _point(p: Any) -> str:
    """(x, y, z) as the user reads it: plain numbers."""
    return "(" + ", ".join(f"{float(v):.3g}" for v in p) + ")"


def check_index_in_box(model: Any, lo: Any, hi: Any) -> None:
    """ValueError naming the Refractive Index where n has a pole in the medium's box, or
    is not a positive finite number at a point of it (sampled before any ray is traced:
    rays there fail or crawl)."""
    box = (tuple(map(float, lo)), tuple(map(float, hi)))
    problem = _index_problem(model.index_text, model.literal, *box)
    if problem:
        raise ValueError(problem)


@functools.lru_cache(maxsize=16)
def _index_problem(text: str, literal: bool, lo: tuple, hi: tuple) -> str:
    """check_index_in_box's message ("" if none) on plain values: cached, as the Rendered
    viewport prepares a render at every change of the scene."""
    model = hm.medium(text, literal=literal, bounds=(lo, hi))
    remedy = "change n(x, y, z), or the box (the Medium object's size, or Box Min / Max)"
    pole = index_pole(model, lo, hi)
    if pole is not None:
        where, n = pole
        return (
            f"Refractive Index '{text}' has a pole inside the medium's box, at (x, y, z) = "
            f"{_point(where)} in the medium's axes (n reaches {n:.3g} there): light cannot "
            f"be traced through it; {remedy}"
        )
    axes = [np.linspace(lo[i], hi[i], 9) for i in range(3)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    try:
        model.check_index(grid)
    except ValueError as err:
        return f"Refractive Index: {err} inside the medium's box; {remedy}"
    return ""


def check_camera(settings: Any, model: Any, where: Placement, camera_position: Any) -> None:
    """ValueError (a core.ObserverError) if rays of ``model`` cannot start at the camera:
    inside a horizon, on a coordinate axis, where the metric is singular or of the wrong
    signature."""
    if not capabilities(settings.model).observer:
        return
    scene = Scene(model=model, center=where.center, rotation=where.rotation)
    check_scene_camera(scene, camera_position, validation.typed_float(settings.tolerance))


def camera_problem(
    settings: Any, metric_source: str, center_matrix: Any | None, camera_position: Any
) -> str:
    """The message check_camera raises, "" if none (or if the settings themselves are
    invalid: their own messages say so). Cached: the panel asks at every redraw."""
    settings = objects.effective(settings)
    if not capabilities(settings.model).observer or validation.settings_problems(settings):
        return ""
    center = None if center_matrix is None else tuple(map(tuple, center_matrix))
    return _camera_problem(
        settings.model,
        tuple((p.name, float(getattr(settings, p.name))) for p in parameters()),
        float(settings.tolerance),
        metric_source,
        center,
        tuple(float(v) for v in camera_position),
    )


@functools.lru_cache(maxsize=16)
def _camera_problem(
    model: str,
    values: tuple[tuple[str, float], ...],
    tolerance: float,
    metric_source: str,
    center: tuple | None,
    camera: tuple,
) -> str:
    """camera_problem on plain (hashable) values (``values``: the model parameters)."""
    settings = SimpleNamespace(model=model, tolerance=tolerance, **dict(values))
    try:
        check_camera(
            settings, build_model(settings, metric_source), placement(center), np.array(camera)
        )
    except expressions.ExpressionError:
        return ""  # shown with the expression
    except (ValueError, ArithmeticError) as err:
        return str(err)
    return ""


def build_disk(settings: Any) -> AccretionDisk | None:
    """The core disk of the settings (None when off); the Scene binds it to the model."""
    disk = settings.disk
    if not disk.enabled:
        return None
    return AccretionDisk(
        r_out=float(disk.outer_radius),
        r_in=None if disk.use_isco else float(disk.inner_radius),
        temperature=float(disk.temperature),
        profile=disk.profile.lower(),
        doppler=bool(disk.doppler),
        brightness=float(disk.brightness),
        opacity=float(disk.opacity),
        look=disk.look.lower(),
        beaming=float(disk.beaming),
        exposure=None if disk.auto_exposure else float(disk.exposure),
    )

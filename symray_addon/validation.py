"""Checking the user's expressions (n(x,y,z), g^ij, H) as they are typed, and the numeric
settings a .blend or a script can carry past the properties' own limits (settings_problems).

Nothing here imports bpy: it works on plain strings and attribute access, so it is shared
by the property update callbacks, the panel, the operator and the render engine, and is
testable on its own.

The inverse metric is one text (the ``metric`` property, or a Text data-block named by
``metric_text``): statements separated by newlines or ``;``. A statement ``name = expr``
defines a helper quantity usable by later statements; every other statement is one row of
g^ij: four comma-separated expressions over t, x, y, z. Exactly four rows are required,
and ``#`` starts a comment. Example (Minkowski)::

    -1, 0, 0, 0; 0, 1, 0, 0; 0, 0, 1, 0; 0, 0, 0, 1
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from ..core import backend, checks, expressions
from ..core.geometry.disk import check_spin, isco
from ..core.integrators import METHODS
from ..core.models.registry import MODELS
from . import objects
from .capabilities import capabilities

INDEX_NAMES: tuple[str, ...] = ("x", "y", "z")
"""Names a refractive index n(x, y, z) may use (the centre object's local frame)."""
METRIC_NAMES: tuple[str, ...] = ("t", "x", "y", "z")
"""Coordinates of a user metric g^ij(t, x, y, z)."""
HAMILTONIAN_COORDS: tuple[str, ...] = ("x", "y", "z")
HAMILTONIAN_MOMENTA: tuple[str, ...] = ("p_x", "p_y", "p_z")
HAMILTONIAN_NAMES: tuple[str, ...] = HAMILTONIAN_COORDS + HAMILTONIAN_MOMENTA
"""Names a user Hamiltonian H(x, y, z, p_x, p_y, p_z) may use."""
METRIC_SIZE = 4


ACCURACY_PX = (1e-6, 100.0)
"""Accuracy (px), the limits of its property (core.render accepts [1e-9, 100])."""
SAMPLES = (1, 1024)
"""Samples per pixel (core.render's limits; the property's too)."""
DISK_BRIGHTNESS = (0.0, 1e6)
"""Disk Brightness (the property's limits): far beyond any scene, far below float32's
largest value (3.4e38), which a larger brightness reaches (inf pixels)."""
STAR_BRIGHTNESS = (0.0, 1e6)
"""Star Brightness: far beyond any scene (its soft limit is 100), far below what takes the
brightest catalogue star (core.stars.BRIGHTEST) beyond 32-bit floats."""
FILTER_SIZE = (0.01, 2.0)
"""Film › Filter Size SymRay's sampler honours, in pixels (Blender's property allows 0-500)."""


@dataclass(frozen=True)
class MetricSpec:
    """A parsed inverse metric: helper definitions (in order) and the 4x4 entry texts."""

    definitions: tuple[tuple[str, str], ...]
    rows: tuple[tuple[str, ...], ...]


def describe(err: expressions.ExpressionError) -> str:
    """One-line message for an ExpressionError, naming the column when known."""
    return str(err)


def check_expression(text: str, names: tuple[str, ...]) -> str:
    """Return "" if ``text`` is a valid expression over ``names``, else the error message."""
    try:
        expressions.check(text, names)
    except expressions.ExpressionError as err:
        return describe(err)
    return ""


def _split_top_level(text: str, separators: str, start: int) -> list[tuple[int, str]]:
    """Split at separator characters outside parentheses; pieces keep their start offset."""
    pieces: list[tuple[int, str]] = []
    depth, begin = 0, 0
    for i, ch in enumerate(text):
        if ch in "([":
            depth += 1
        elif ch in ")]":
            depth = max(depth - 1, 0)
        elif ch in separators and depth == 0:
            pieces.append((start + begin, text[begin:i]))
            begin = i + 1
    pieces.append((start + begin, text[begin:]))
    return pieces


def _statements(text: str) -> list[tuple[int, str]]:
    """Statements of a metric text with their 0-based offsets; comments and blanks dropped."""
    out: list[tuple[int, str]] = []
    offset = 0
    for line in text.splitlines(keepends=True):
        body = line.split("#", 1)[0]
        for start, piece in _split_top_level(body, ";", offset):
            if piece.strip():
                out.append((start, piece))
        offset += len(line)
    return out


def _located(text: str, problem: str, offset: int | None) -> expressions.ExpressionError:
    """An error at 0-based ``offset`` of ``text``: a column, and a line if text has several."""
    if offset is None:
        return expressions.ExpressionError(problem)
    if "\n" not in text.rstrip("\n"):
        return expressions.ExpressionError(problem, offset + 1)
    line = text.count("\n", 0, offset) + 1
    column = offset - (text.rfind("\n", 0, offset) + 1) + 1
    return expressions.ExpressionError(f"line {line}: {problem}", column)


def _shifted(
    text: str, err: expressions.ExpressionError, offset: int, label: str
) -> expressions.ExpressionError:
    """The error of a piece starting at ``offset`` of ``text``, relocated and labelled."""
    where = None if err.column is None else offset + err.column - 1
    return _located(text, f"{label}: {err.problem}", where)


def _is_definition(piece: str) -> tuple[str, str, int] | None:
    """(name, expression, offset of the expression) if ``piece`` reads ``name = expr``."""
    head, sep, tail = piece.partition("=")
    if not sep or tail.startswith("=") or head.rstrip().endswith(("<", ">", "!", "=")):
        return None
    name = head.strip()
    if not name.isidentifier():
        return None
    return name, tail, len(head) + 1


# noqa: C901 below: one pass over the text's lines, each kind of line (definition, row,
# comment) with its own message at its own column; the checks read best in order
def parse_metric(text: str) -> MetricSpec:  # noqa: C901
    """Parse and check an inverse-metric text (format: module docstring).

    Raises expressions.ExpressionError whose column counts from the start of ``text``.
    """
    if len(text) > expressions.MAX_LENGTH:
        raise expressions.ExpressionError(
            f"metric is too long ({len(text)} > {expressions.MAX_LENGTH} characters)"
        )
    known = list(METRIC_NAMES)
    definitions: list[tuple[str, str]] = []
    rows: list[tuple[str, ...]] = []
    for start, piece in _statements(text):
        definition = _is_definition(piece)
        if definition is not None:
            name, expr, shift = definition
            if rows:
                raise _located(text, f"definition '{name}' must come before the metric rows", start)
            if name in known or name in expressions.CONSTANTS:
                raise _located(text, f"'{name}' is already defined or reserved", start)
            try:
                expressions.check(expr.strip(), known)
            except expressions.ExpressionError as err:
                lead = len(expr) - len(expr.lstrip())
                raise _shifted(text, err, start + shift + lead, f"definition '{name}'") from None
            definitions.append((name, expr.strip()))
            known.append(name)
            continue
        row_number = len(rows) + 1
        entries = _split_top_level(piece, ",", start)
        if len(entries) != METRIC_SIZE:
            raise _located(
                text,
                f"metric row {row_number} has {len(entries)} entries, needs {METRIC_SIZE}",
                start,
            )
        row = []
        for j, (estart, entry) in enumerate(entries):
            lead = len(entry) - len(entry.lstrip())
            try:
                expressions.check(entry.strip(), known)
            except expressions.ExpressionError as err:
                raise _shifted(text, err, estart + lead, f"g^{row_number - 1}{j}") from None
            row.append(entry.strip())
        rows.append(tuple(row))
    if len(rows) != METRIC_SIZE:
        raise expressions.ExpressionError(
            f"metric has {len(rows)} rows, needs {METRIC_SIZE} (rows are separated by ';' "
            "or new lines, entries by ',')"
        )
    for i in range(METRIC_SIZE):
        for j in range(i):
            if rows[i][j].replace(" ", "") != rows[j][i].replace(" ", ""):
                raise expressions.ExpressionError(
                    f"metric must be symmetric: g^{i}{j} = '{rows[i][j]}' but "
                    f"g^{j}{i} = '{rows[j][i]}'"
                )
    return MetricSpec(tuple(definitions), tuple(rows))


def check_metric(text: str) -> str:
    """Return "" if ``text`` is a valid inverse metric, else the error message."""
    try:
        parse_metric(text)
    except expressions.ExpressionError as err:
        return describe(err)
    return ""


def typed_float(value: float) -> float:
    """A FloatProperty's value as typed: Blender stores float32 (0.1 reads back as
    0.10000000149), and 7 significant digits give the decimal back."""
    return float(f"{float(value):.7g}")


def parameter_problem(settings: Any) -> str:
    """Why the model's parameters build no model ("" when they do, or when its Size is
    itself the problem: the Size check names it): the core registry's own message, e.g. a
    spin beyond extremal."""
    kind = MODELS.get(settings.model)
    if kind is None or not kind.parameters:
        return ""
    values = {name: getattr(settings, name) for name in kind.parameter_names()}
    try:
        checks.check_positive("Size", values.get("rg", 1.0))
    except ValueError:
        return ""
    return kind.problem(values)


def _has_spin(settings: Any) -> bool:
    """Whether the settings' model takes a spin (Kerr, Kerr–Newman)."""
    kind = MODELS.get(settings.model)
    return kind is not None and "spin" in kind.parameter_names()


def _check_split(method: str, model: str, spin: Any = 0.0) -> None:
    """ValueError if an explicit splitting is chosen for a model that offers no split."""
    chosen = METHODS.get(method)  # "AUTO" is no method: the model's default
    if chosen is None or not chosen.needs_split:
        return
    if not capabilities(model, spin).split:
        raise ValueError(
            f"method '{method}' is an explicit splitting: only Schwarzschild, Kerr below "
            "extremal (|a/M| < 1) and media offer the split it needs; choose Automatic or "
            "gauss4"
        )


def _settings_checks(settings: Any) -> list[Callable[[], Any]]:
    """The checks of every numeric setting (and the method) that the model uses."""
    model = settings.model
    traits = capabilities(model, settings.spin)
    found = [
        lambda: checks.check_tolerance(typed_float(settings.tolerance), "Tolerance"),
        lambda: checks.check_range(
            "Accuracy (px)", typed_float(settings.tolerance_px), *ACCURACY_PX
        ),
        lambda: checks.check_int("Samples", settings.samples, *SAMPLES),
        lambda: checks.check_int("Max Steps", settings.max_steps),
        lambda: checks.check_int("Workers", settings.workers, 0),
        lambda: checks.check_render_method(
            METHODS.get(settings.method), traits.time_scaled
        ),  # "AUTO" is no method: the model's default, nothing to refuse
        lambda: _check_split(settings.method, model, settings.spin),
    ]
    if settings.lighting != "UNLIT":
        found.append(lambda: checks.check_range("Texel Size", settings.bake_texel_size, 0.0))
        found.append(lambda: checks.check_int("Max Resolution", settings.bake_max_resolution, 8))
        found.append(lambda: checks.check_int("Bake Samples", settings.bake_samples))
    if settings.background == "STARS":
        found.extend(_star_checks(settings))
    if traits.mass:  # a hole object's own Size (its rg also holds its Spin: NaN with it)
        size = getattr(settings, "hole_size", settings.rg)
        found.append(lambda: checks.check_positive("Size", size))
    kind = MODELS.get(model)
    if kind is not None and kind.inputs == "index" and settings.use_medium_bounds:  # a box
        found.append(lambda: checks.check_vector("Box Min", settings.medium_min))
        found.append(lambda: checks.check_vector("Box Max", settings.medium_max))
    return found


def _star_checks(settings: Any) -> list[Callable[[], Any]]:
    """The checks of Point Stars' numbers, named as in the panel (a .blend or a script can
    set them beyond the properties' ranges)."""
    found = [
        lambda: checks.check_range("Star Brightness", settings.star_brightness, *STAR_BRIGHTNESS)
    ]
    if not settings.star_catalog.strip():  # the random field
        found.append(lambda: checks.check_int("Stars", settings.star_count, 0))
        found.append(lambda: checks.check_int("Seed", settings.star_seed, 0))
    return found


def settings_problems(settings: Any) -> list[str]:
    """Messages for settings a render would refuse: values a .blend or a script can set
    beyond the properties' own ranges (NaN, 0, ...), a Kerr spin beyond extremal, a method
    that cannot trace the model, two black holes in the scene. Empty when every setting is
    usable."""
    settings = objects.effective(settings)
    problems = enum_problems(settings) + enum_problems(settings.disk)
    if settings.object_problem:
        problems.append(settings.object_problem)
    for check in _settings_checks(settings):
        try:
            check()
        except ValueError as err:
            problems.append(str(err))
    if parameter_problem(settings):
        problems.append(parameter_problem(settings))
    return problems + disk_problems(settings) + device_problems(settings)


def device_problems(settings: Any) -> list[str]:
    """Why the Device chosen cannot render here (GPU without CuPy or a CUDA GPU)."""
    if getattr(settings, "device", "CPU") != "GPU":
        return []
    problem = gpu_problem()
    if problem is None:
        return []
    return [f"Device GPU cannot render here (CuPy: {problem}). Set Device to CPU, or install "
            "CuPy into Blender's Python (README: GPU rendering)"]  # fmt: skip


def gpu_problem() -> str | None:
    """Why no GPU renders in this Blender (core.backend.cuda_problem), or None."""
    return backend.cuda_problem()


def disk_problems(settings: Any) -> list[str]:
    """Messages for disk settings a render would refuse (names as in the panel)."""
    settings = objects.effective(settings)
    disk = settings.disk
    if not disk.enabled:
        return []
    if not capabilities(settings.model).disk:
        kind = MODELS.get(settings.model)
        if kind is not None and kind.traits.hole:
            return [
                f"The Accretion Disk needs a Schwarzschild or Kerr hole: its gas follows "
                f"their orbits, which a {kind.label} hole does not have; set the hole's "
                "Charge to 0 or turn the disk off"
            ]
        if settings.follows_objects:
            return ["The Accretion Disk needs a black hole: Add › SymRay › Black Hole"]
        return ["Accretion Disk needs a Schwarzschild or Kerr model"]
    problems = []
    for check in _disk_checks(settings):
        try:
            check()
        except ValueError as err:
            problems.append(str(err))
    return problems


def _disk_checks(settings: Any) -> list[Callable[[], Any]]:
    """The checks of the disk's numbers (ValueError naming the setting and its range)."""
    disk = settings.disk
    found = [
        lambda: checks.check_positive("Disk Outer Radius", disk.outer_radius),
        lambda: checks.check_range("Disk Temperature", disk.temperature, 100.0, 1e9),
        lambda: checks.check_range("Disk Brightness", disk.brightness, *DISK_BRIGHTNESS),
        lambda: checks.check_range("Disk Opacity", disk.opacity, 0.0, 1.0, lo_open=True),
        lambda: checks.check_range("Disk Beaming", disk.beaming, 0.0, 1.0),
    ]
    if _has_spin(settings) and not parameter_problem(settings):
        found.append(lambda: check_spin(settings.spin, "Spin"))
    if not disk.auto_exposure:
        found.append(lambda: checks.check_positive("Disk Exposure", disk.exposure))
    if not disk.use_isco:
        found.append(
            lambda: checks.check_range(
                "Disk Inner Radius",
                disk.inner_radius,
                inner_edge(settings),
                disk.outer_radius,
                hi_open=True,
            )  # fmt: skip
        )
    elif math.isfinite(float(settings.rg)) and float(settings.rg) > 0:
        found.append(
            lambda: checks.check_range(
                "Disk Outer Radius (beyond the innermost orbit)",
                disk.outer_radius,
                inner_edge(settings),
                lo_open=True,
            )  # fmt: skip
        )
    return found


def inner_edge(settings: Any) -> float:
    """The prograde ISCO of the settings' hole, in scene units (Boyer–Lindquist r)."""
    settings = objects.effective(settings)
    mass = 0.5 * float(settings.rg)
    spin = float(settings.spin) if _has_spin(settings) else 0.0
    return isco(mass, spin * mass)


def enum_problems(settings: Any) -> list[str]:
    """Messages for enum settings that hold none of their choices (a .blend or a script
    writing the ID property, ``scene.symray["quality"] = 99``: Blender reads those as ''
    and a render would silently use a default)."""
    problems = []
    for prop in settings.bl_rna.properties:
        if prop.type != "ENUM" or prop.is_enum_flag:
            continue
        raw = settings.get(prop.identifier)
        items = prop.enum_items
        if raw is None or raw in {item.value for item in items}:
            continue
        choices = ", ".join(item.name for item in items)
        problems.append(
            f"{prop.name} holds {raw!r}, which is none of its choices ({choices}): choose "
            "one in the SymRay panel"
        )
    return problems


def filter_size(value: Any, warnings: list[str]) -> float:
    """Film › Filter Size as the sampler uses it: clamped to FILTER_SIZE, with a warning
    in ``warnings`` when it was outside (ValueError when it is not a finite number)."""
    size = checks.check_range("Film › Filter Size", typed_float(value), 0.0)
    lo, hi = FILTER_SIZE
    used = min(max(size, lo), hi)
    if used != size:
        warnings.append(
            f"Film › Filter Size {size:g} px is outside the {lo:g}–{hi:g} px SymRay "
            f"supports: {used:g} px used"
        )
    return used


def ignored_settings(scene: Any, view_layer: Any, camera: Any) -> list[str]:
    """Warnings naming each setting of ``scene``, ``view_layer`` and ``camera`` (an
    object) that SymRay does not support yet and so ignores: one line each."""
    found = []
    dof = getattr(getattr(camera, "data", None), "dof", None)
    if getattr(dof, "use_dof", False):
        found.append(
            f"Depth of Field (camera '{camera.name}') is not supported by SymRay yet: the "
            "image is rendered in focus everywhere"
        )
    if getattr(scene.render, "use_motion_blur", False):
        found.append("Motion Blur is not supported by SymRay yet: the frame is rendered without it")
    layer = getattr(view_layer, "name", "")
    for toggle, name in IGNORED_PASSES:
        if getattr(view_layer, toggle, False):
            found.append(
                f"The {name} pass (View Layer '{layer}' › Passes) is not supported by "
                "SymRay yet: it is not written"
            )
    return found


IGNORED_PASSES = (
    ("use_pass_z", "Z"),
    ("use_pass_normal", "Normal"),
    ("use_pass_cryptomatte_object", "Cryptomatte Object"),
    ("use_pass_cryptomatte_material", "Cryptomatte Material"),
    ("use_pass_cryptomatte_asset", "Cryptomatte Asset"),
)
"""(view layer toggle, pass name) of Blender's passes SymRay does not write yet."""

"""The model registry (core.models.registry): each kind's declared traits are what the model
its constructor builds answers, numbers are never shared, a hole object's values pick the
simplest kind that takes them, and bad values get the core's own message."""

from __future__ import annotations

import math
import re

import pytest

from core import hamiltonians as hm
from core.models.registry import MODELS, hole_kind, hole_parameters, parameters

TEXT_MODELS = {  # kinds built from text: a representative model of each
    "index": lambda: hm.medium("1 + 0.01*z"),
    "metric": lambda: hm.metric([["-1", "0", "0", "0"], ["0", "1", "0", "0"],
                                 ["0", "0", "1", "0"], ["0", "0", "0", "1"]]),
    "hamiltonian": lambda: hm.from_expression("0.5*(p_x**2 + p_y**2 + p_z**2)",
                                              q=["x", "y", "z"], p=["p_x", "p_y", "p_z"]),
}  # fmt: skip


def _built(kind, spin: float = 0.5):
    """The model of ``kind`` at default parameters (spin a/M = ``spin``), None for flat."""
    if kind.inputs:
        return TEXT_MODELS[kind.inputs]()
    if kind.build is None:
        return None
    if "charge" in kind.parameter_names():  # a charged hole's spin stays below extremal
        spin = min(spin, 0.5)
    values = {p.name: p.default for p in kind.parameters} | {"spin": spin, "charge": 0.3}
    return kind.build(**{name: values[name] for name in kind.parameter_names()})


@pytest.mark.parametrize("name", list(MODELS))
@pytest.mark.parametrize("spin", [0.5, 1.0])
def test_declared_traits_are_what_the_built_model_answers(name, spin):
    """Observer frame (a spacetime), mass, Poincaré time, explicit split (Kerr only below
    extremal), disk orbits: as the core model itself says."""
    kind = MODELS[name]
    model = _built(kind, spin)
    if model is None:
        assert kind.traits == type(kind.traits)()
        return
    traits = kind.traits
    traced = model.for_backward_tracing(explicit_split=True)
    assert traits.spacetime == (model.kind == "spacetime")
    assert traits.mass == (model.rg > 0)
    assert traits.time_scaled == model.scales_time
    assert traits.has_split(spin) == (traced.split_parts() is not None)
    assert traits.disk == (model.kerr_orbits() is not None)
    assert traits.hole == (model.horizon > 0 if traits.mass else False)


def test_numbers_and_parameters_are_one_each():
    """A .blend stores a model by number: never two kinds on one (6 is the add-on's Scene
    Objects). A parameter shared by kinds is one declaration."""
    numbers = [kind.number for kind in MODELS.values()]
    assert len(set(numbers)) == len(numbers) and 6 not in numbers
    names = [p.name for p in parameters()]
    assert len(set(names)) == len(names) and {"rg", "spin", "charge"} <= set(names)
    assert [p.name for p in hole_parameters()] == ["spin", "charge"]


@pytest.mark.parametrize(
    ("spin", "charge", "expected"),
    [(0.0, 0.0, "SCHWARZSCHILD"), (0.6, 0.0, "KERR"), (0.0, -0.4, "REISSNER_NORDSTROM"),
     (0.5, 0.3, "KERR_NEWMAN")],
)  # fmt: skip
def test_a_hole_is_the_simplest_kind_that_takes_its_values(spin, charge, expected):
    """Zero spin and charge: Schwarzschild; either alone: Kerr or Reissner–Nordström; both:
    Kerr–Newman."""
    assert hole_kind({"rg": 1.0, "spin": spin, "charge": charge}).name == expected


@pytest.mark.parametrize(
    ("name", "values", "words"),
    [("KERR", {"rg": 1.0, "spin": 1.2}, "beyond extremal"),
     ("KERR", {"rg": 1.0, "spin": math.nan}, "finite"),
     ("REISSNER_NORDSTROM", {"rg": 1.0, "charge": 1.0}, "Spin² \\+ Charge² < 1"),
     ("KERR_NEWMAN", {"rg": 1.0, "spin": 0.8, "charge": 0.7}, "Spin² \\+ Charge² < 1"),
     ("SCHWARZSCHILD", {"rg": -1.0}, "rg"),
     ("KERR_NEWMAN", {"rg": 1.0, "spin": 0.8, "charge": 0.5}, "")],
)  # fmt: skip
def test_bad_values_get_the_cores_message(name, values, words):
    """ModelKind.problem: "" for values that build a model, else the message, naming it."""
    problem = MODELS[name].problem(values)
    if words:
        assert problem and re.search(words, problem)
    else:
        assert problem == ""

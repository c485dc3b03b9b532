"""The models a user picks by name, declared once: each a ModelKind with its parameters,
its traits and its constructor.

The add-on builds its model menu, its settings, its panel rows and its checks from
MODELS (symray_addon/capabilities.py, properties.py, models.py, panel.py); a new model is
its module, a line here and its test. A kind's traits are what the renderer and the panel
need to know before any user text is parsed (tests/core/test_registry.py checks each
against the model its constructor builds).

Parameters are plain numbers in units a user reads: lengths in scene units (``rg``, the
Schwarzschild radius 2M), spin and charge as fractions of the mass (a/M, Q/M). A kind whose
inputs are text (a refractive index, a metric, a Hamiltonian) names them in ``inputs``: the
add-on reads and checks those itself.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

from .kerr_newman import kerr_newman
from .reissner_nordstrom import reissner_nordstrom
from .spacetimes import kerr, schwarzschild


@dataclass(frozen=True)
class Parameter:
    """One number a model is built from."""

    name: str
    """Its keyword in ModelKind.build and the add-on's setting of the same name."""
    label: str
    description: str
    default: float
    unit: str = ""
    """'length' (scene units) or '' (a pure number)."""
    minimum: float = -math.inf
    maximum: float = math.inf
    soft_min: float | None = None
    soft_max: float | None = None


@dataclass(frozen=True)
class Traits:
    """What a kind of model can do, declared (not probed)."""

    spacetime: bool = False
    """Rays start in an observer's frame at the camera: camera checks apply."""
    mass: bool = False
    """A mass at the centre (its Schwarzschild radius rg sets the far field and the step)."""
    time_scaled: bool = False
    """Traced in Poincaré time (methods that cannot follow it are refused)."""
    split: str = ""
    """An explicit split the splittings take: 'always', 'below_extremal' (|a/M| < 1) or ''."""
    disk: bool = False
    """An accretion disk can orbit it (Kerr's circular orbits)."""
    hole: bool = False
    """A black hole: the add-on's Black Hole object can be one."""

    def has_split(self, spin: float = 0.0) -> bool:
        """Whether the explicit splittings can trace it at spin a/M."""
        return self.split == "always" or (self.split == "below_extremal" and abs(spin) < 1.0)


@dataclass(frozen=True)
class ModelKind:
    """One model a user picks by name."""

    name: str
    """The identifier (the add-on's enum item, stored in .blend files by ``number``)."""
    label: str
    description: str
    number: int
    """What a .blend stores: never reused."""
    build: Callable[..., Any] | None
    """Keyword arguments ``parameters`` -> the core Hamiltonian; None: flat space, or a
    kind built from text ``inputs`` by its reader."""
    parameters: tuple[Parameter, ...] = ()
    traits: Traits = field(default_factory=Traits)
    inputs: str = ""
    """'' for a kind built from its parameters alone; else what text it is read from
    ('index', 'metric', 'hamiltonian')."""

    def parameter_names(self) -> tuple[str, ...]:
        """Names of its parameters, in order."""
        return tuple(p.name for p in self.parameters)

    def problem(self, values: Mapping[str, float]) -> str:
        """Why ``values`` build no model ("" when they do): the core's own message."""
        if self.build is None:
            return ""
        try:
            self.build(**{name: values[name] for name in self.parameter_names()})
        except (ValueError, TypeError, ArithmeticError) as err:
            return str(err)
        return ""


RG = Parameter(
    "rg", "Size", "Size of the black hole, in scene units: its horizon's radius when it does "
    "not spin (physics: the Schwarzschild radius rg = 2GM/c²)", 1.0, "length", 1e-6,
    soft_max=100.0,
)  # fmt: skip
SPIN = Parameter(
    "spin", "Spin", "How fast the hole turns, -1 to 1 (1: the fastest possible). Physics: "
    "Kerr's a/M (1 = extremal)", 0.9, "", -1e6, 1e6, -1.0, 1.0,
)  # fmt: skip
CHARGE = Parameter(
    "charge", "Charge", "Electric charge of the hole, -1 to 1 (with the spin, spin² + "
    "charge² < 1). Physics: Q/M in geometrised units (G = c = 4πε0 = 1)", 0.0, "", -1e6,
    1e6, -1.0, 1.0,
)  # fmt: skip


def _kerr(rg: float, spin: float) -> Any:
    """Kerr in Kerr–Schild form from rg and a/M."""
    _spin_within_extremal(spin)
    return kerr(rg=rg, a=float(spin) * float(rg) / 2.0, chart="kerr_schild")


def _spin_within_extremal(spin: float) -> None:
    """ValueError when |a/M| > 1 (or spin is not a number), in the panel's words."""
    spin = float(spin)
    if not math.isfinite(spin):
        raise ValueError(f"Spin a/M must be a finite number, got {spin}")
    if abs(spin) > 1.0:
        raise ValueError(f"Kerr spin a/M = {spin:g} is beyond extremal: it must lie in [-1, 1]")


def _below_extremal(spin: float, charge: float) -> None:
    """ValueError unless spin² + charge² < 1 (a/M and Q/M; both finite), in the panel's
    words."""
    spin, charge = float(spin), float(charge)
    if not (math.isfinite(spin) and math.isfinite(charge)):
        raise ValueError(f"Spin and Charge must be finite numbers, got {spin}, {charge}")
    if spin * spin + charge * charge >= 1.0:
        raise ValueError(
            f"A charged hole needs Spin² + Charge² < 1 (here {spin:g}² + {charge:g}² = "
            f"{spin * spin + charge * charge:.4g}): beyond it there is no horizon"
        )


def _reissner_nordstrom(rg: float, charge: float) -> Any:
    """Reissner–Nordström from rg and Q/M."""
    _below_extremal(0.0, charge)
    return reissner_nordstrom(rg=rg, charge=float(charge) * float(rg) / 2.0)


def _kerr_newman(rg: float, spin: float, charge: float) -> Any:
    """Kerr–Newman from rg, a/M and Q/M."""
    _below_extremal(spin, charge)
    mass = float(rg) / 2.0
    return kerr_newman(rg=rg, a=float(spin) * mass, charge=float(charge) * mass)


_HOLE = Traits(spacetime=True, mass=True, time_scaled=True, hole=True)

MODELS: Mapping[str, ModelKind] = MappingProxyType({
    kind.name: kind for kind in (
        ModelKind("FLAT", "Flat", "No bending: straight rays, an ordinary ray tracer", 0, None),
        ModelKind("SCHWARZSCHILD", "Schwarzschild", "Non-rotating black hole of size rg at "
                  "the centre object", 1, schwarzschild, (RG,),
                  Traits(spacetime=True, mass=True, time_scaled=True, split="always",
                         disk=True, hole=True)),
        ModelKind("KERR", "Kerr", "Rotating black hole at the centre object; spin axis = its "
                  "local Z", 2, _kerr, (RG, SPIN),
                  Traits(spacetime=True, mass=True, time_scaled=True,
                         split="below_extremal", disk=True, hole=True)),
        ModelKind("MEDIUM", "Medium", "Refractive index n(x, y, z) in the centre's local "
                  "frame (mirages)", 3, None, (), Traits(split="always"), "index"),
        ModelKind("METRIC", "Metric", "Any spacetime given by its inverse metric "
                  "g^ij(t, x, y, z)", 4, None, (), Traits(spacetime=True), "metric"),
        ModelKind("CUSTOM", "Custom Hamiltonian", "Any Hamiltonian H(x, y, z, p_x, p_y, "
                  "p_z)", 5, None, (), Traits(), "hamiltonian"),
        ModelKind("REISSNER_NORDSTROM", "Reissner–Nordström", "Charged, non-rotating black "
                  "hole at the centre object", 7, _reissner_nordstrom, (RG, CHARGE), _HOLE),
        ModelKind("KERR_NEWMAN", "Kerr–Newman", "Charged, rotating black hole at the centre "
                  "object; spin axis = its local Z", 8, _kerr_newman, (RG, SPIN, CHARGE),
                  _HOLE),
    )
})  # fmt: skip
"""Every model a user picks by name, in menu order (the add-on's number 6 is its own
'Scene Objects')."""


def model_kind(name: str) -> ModelKind:
    """The kind named ``name`` (ValueError naming the known ones otherwise)."""
    try:
        return MODELS[name]
    except KeyError:
        raise ValueError(f"Unknown SymRay model '{name}' (known: {', '.join(MODELS)})") from None


def parameters() -> tuple[Parameter, ...]:
    """Every kind's parameters, each once, in order of first use."""
    seen: dict[str, Parameter] = {}
    for kind in MODELS.values():
        for p in kind.parameters:
            seen.setdefault(p.name, p)
    return tuple(seen.values())


def hole_kind(values: Mapping[str, float]) -> ModelKind:
    """The simplest black-hole kind whose parameters hold every non-zero one of ``values``
    (a hole object's rg, spin, charge, ...): spin alone -> Kerr, charge alone ->
    Reissner–Nordström, both -> Kerr–Newman, neither -> Schwarzschild."""
    needed = {name for name, value in values.items() if name != "rg" and value != 0.0}
    holes = [k for k in MODELS.values() if k.traits.hole and needed <= set(k.parameter_names())]
    if not holes:
        raise ValueError(f"no black-hole model takes {', '.join(sorted(needed))}")
    return min(holes, key=lambda k: len(k.parameters))


def hole_parameters() -> tuple[Parameter, ...]:
    """The parameters of the black-hole kinds but rg (a hole object's own settings)."""
    return tuple(
        p for p in parameters() if p.name != "rg" and any(
            p in k.parameters for k in MODELS.values() if k.traits.hole)
    )  # fmt: skip

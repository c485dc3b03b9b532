"""The relativistic thin accretion disk: its parameters, orbits and temperature.

A geometrically thin disk (opaque, or translucent below opacity 1) in the equatorial plane
of a Schwarzschild or Kerr hole (the model's local z = 0 plane), between the Boyer–Lindquist
radii ``r_in`` (default: the prograde innermost stable circular orbit, ISCO) and ``r_out``.
Its gas moves on prograde
circular equatorial geodesics, Ω = ±√M / (r^{3/2} ± |a| √M) (co-rotating with the hole;
a = 0: counter-clockwise about +z), and shines as a black body at T(r): the Novikov–Thorne
profile (Page & Thorne 1974, flux F ∝ T⁴, zero torque at r_in) or a power law
T = T_in (r / r_in)^(-3/4).

What the camera sees of a disk point (core/tracing/disklight.py) is the black body at
g T(r), with g = ν_obs / ν_emit = (p·u)_obs / (p·u)_emit: the observed specific intensity is
I_ν = g³ B_ν(ν/g, T) = B_ν(ν, g T) (I_ν / ν³ is invariant along a ray), integrated against
the CIE colour-matching functions (core/blackbody.py). The g³ is per frequency; the colour
and brightness of the whole visible band follow from the spectrum itself (no extra
bolometric g⁴ factor). ``brightness`` scales the result so that a disk point at the
``temperature`` parameter seen without shift (g = 1) has luminance Y = brightness.

Looks (``look``; g itself, the redshift pass, is the same in every look; only the
profile's shape T(r) / temperature enters the cinematic and EHT looks):

- ``"physical"``: the black body at g T(r), as above.
- ``"cinematic"`` (Interstellar-like): the same law with the shift reduced and a warm
  palette: the black body at g**beaming T(r) x CINEMATIC_HOT / temperature (``beaming``
  in [0, 1]: 1 = the physical shift, 0 = none), scaled so that the hottest point seen
  without shift has luminance ``brightness``: the hot gas orange-white, cooler gas
  deeper orange and fainter.
- ``"eht"`` (EHT-like): the bolometric intensity I = g⁴ σ T(r)⁴ / π (I / ν⁴ integrated
  over ν is invariant), relative to the hottest point's, v = (g T(r) / temperature)⁴ x
  exposure, through the ``afmhot`` colour map of the EHT's 230 GHz images
  (``eht_colour``: made scene-linear, white v beyond v = 1), times ``brightness``.

``exposure`` multiplies the disk's light (EHT: v, where it falls on the colour map) and
``brightness`` multiplies the result in every look; exposure None asks core.render for an
automatic one (``exposure_for``: a probe render puts the median luminance of the pixels
showing the disk, rendered at brightness 1, at its look's EXPOSURE_TARGETS, so brightness
still scales the result: 2 = twice as bright as automatic).

Geometric units: lengths in the scene's units, M = rg / 2, a = spin × M.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .. import blackbody, checks

PROFILES = ("novikov_thorne", "power_law")
"""Temperature profiles: Novikov–Thorne, or T_in (r / r_in)^(-3/4)."""
LOOKS = ("physical", "cinematic", "eht")
"""How the disk's light is coloured (see the module); g is the same in all."""
EXPOSURE_TARGETS = {"physical": 0.24, "cinematic": 0.3, "eht": 0.3}
"""Scene-linear luminance that automatic exposure puts the disk's median pixel at, per
look: about 0.5 on screen (Rec.709 luma of the display values) after Blender's AgX or
Standard view transform (measured 0.48-0.52 on views from face-on to edge-on; the warm
looks' saturated colours show darker than a grey of their luminance)."""
CINEMATIC_HOT = 3500.0
"""Palette temperature (K) of the cinematic look's hottest gas: an orange that Blender's
view transforms take to white where it is bright."""


def afmhot(v: Any) -> np.ndarray:
    """matplotlib's ``afmhot`` colour map (..., 3) at v (clipped to [0, 1]), display
    values: red 2v, green 2v − ½, blue 2v − 1, each clipped to [0, 1]."""
    v = np.asarray(v, dtype=np.float64)[..., None]
    return np.clip(2.0 * v - np.array([0.0, 0.5, 1.0]), 0.0, 1.0)


def srgb_to_linear(c: Any) -> np.ndarray:
    """The sRGB transfer function's inverse (IEC 61966-2-1): display values -> linear."""
    c = np.asarray(c, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def eht_colour(v: Any) -> np.ndarray:
    """Scene-linear RGB (..., 3) of the EHT look at brightness v >= 0: ``afmhot(v)`` made
    linear (shown through Blender's Standard view transform it is afmhot itself), and
    white v (1, 1, 1) beyond v = 1 (continuous there)."""
    v = np.maximum(np.asarray(v, dtype=np.float64), 0.0)
    ramp = srgb_to_linear(afmhot(v))
    return np.where(v[..., None] > 1.0, v[..., None], ramp)


def eht_level(luminance: float) -> float:
    """The EHT look's brightness v whose colour has luminance Y (``eht_colour``'s
    luminance increases with v; beyond v = 1 it is v), by bisection to float precision."""
    if luminance >= 1.0:
        return float(luminance)
    weights = blackbody.XYZ_FROM_RGB[1]
    lo, hi = 0.0, 1.0
    for _ in range(64):  # a scalar, once per render
        mid = 0.5 * (lo + hi)
        if float(eht_colour(mid) @ weights) < luminance:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def isco(mass: float, a: float) -> float:
    """Prograde ISCO radius (Bardeen, Press & Teukolsky 1972) for spin length |a| <= mass."""
    chi = min(abs(a) / mass, 1.0)
    z1 = 1 + (1 - chi * chi) ** (1 / 3) * ((1 + chi) ** (1 / 3) + (1 - chi) ** (1 / 3))
    z2 = math.sqrt(3 * chi * chi + z1 * z1)
    return mass * (3 + z2 - math.sqrt((3 - z1) * (3 + z1 + 2 * z2)))


def check_spin(spin: Any, name: str = "Kerr spin a/M") -> float:
    """``spin`` (a/M) as a float if a disk can orbit the hole: |a/M| < 1, else ValueError.

    At |a/M| = 1 the prograde ISCO meets the horizon (Boyer–Lindquist r = M): the inner
    edge's gas has u^t = ∞ (g = 0), and the Novikov–Thorne flux's roots x³ − 3x + 2 = 0
    coincide. Below it everything is finite (a/M = 1 − 1e-12 measured).
    """
    x = checks.check_range(name, spin)
    if not -1.0 < x < 1.0:
        raise ValueError(
            f"{name} must lie in (-1, 1) with an accretion disk, got {x:g}: at ±1 the "
            "disk's innermost stable orbit meets the horizon (choose 0.9999 for a "
            "near-extremal hole, or turn the disk off)"
        )
    return x


def keplerian_omega(r: Any, mass: float, a: float) -> np.ndarray:
    """Angular velocity dφ/dt of prograde circular equatorial geodesics at BL radius r."""
    sign = -1.0 if a < 0 else 1.0
    sqrt_m = math.sqrt(mass)
    return sign * sqrt_m / (np.asarray(r, dtype=np.float64) ** 1.5 + abs(a) * sqrt_m)


def novikov_thorne_flux(r: Any, mass: float, a: float, r_in: float) -> np.ndarray:
    """Flux of a Novikov–Thorne disk at BL radius r, relative units (Page & Thorne 1974,
    closed form in x = √(r/M), zero torque at r_in); 0 inside r_in. |a| < mass."""
    chi = abs(check_spin(a / mass))
    x = np.sqrt(np.asarray(r, dtype=np.float64) / mass)
    x0 = math.sqrt(r_in / mass)
    phase = math.acos(max(-1.0, min(1.0, chi)))
    roots = (
        2 * math.cos((phase - math.pi) / 3),
        2 * math.cos((phase + math.pi) / 3),
        -2 * math.cos(phase / 3),
    )  # of x³ − 3x + 2χ = 0
    with np.errstate(divide="ignore", invalid="ignore"):
        bracket = x - x0 - 1.5 * chi * np.log(x / x0)
        for i, xi in enumerate(roots):
            others = [roots[j] for j in range(3) if j != i]
            if abs(xi) < 1e-12:  # χ = 0: (xi − χ)² / xi -> 0
                continue
            coeff = 3 * (xi - chi) ** 2 / (xi * (xi - others[0]) * (xi - others[1]))
            bracket = bracket - coeff * np.log((x - xi) / (x0 - xi))
        flux = bracket / (x**4 * (x**3 - 3 * x + 2 * chi))
    return np.where(x > x0, flux, 0.0)


@dataclass(frozen=True)
class AccretionDisk:
    """A thin accretion disk around the scene's black hole (see the module).

    ``r_in`` None: the prograde ISCO of the scene's model (filled in by ``bind``).
    ``temperature`` (K): the hottest point of the profile (the inner edge for the power
    law; the Novikov–Thorne maximum, at r = 9.55 M = 1.59 r_in for a = 0). ``doppler``
    False: the gas is at rest in the local zero-angular-momentum frame (static where
    a = 0) instead of orbiting, so only the gravitational (and frame-dragging) shift
    remains, no beaming.
    ``opacity`` in (0, 1]: below 1 a ray crossing the disk takes ``opacity`` x its light
    and goes on with (1 - opacity) of what lies behind (core/tracing/disklight.py).
    ``look`` in LOOKS, ``beaming`` in [0, 1] (the cinematic look's share of the shift:
    g -> g**beaming), ``exposure`` > 0 multiplies the light (after brightness; None:
    automatic, chosen by core.render, see ``exposure_for``; a tracer used alone takes 1).
    """

    r_out: float = 20.0
    r_in: float | None = None
    temperature: float = 10_000.0
    profile: str = "novikov_thorne"
    doppler: bool = True
    brightness: float = 1.0
    opacity: float = 1.0
    mass: float = 0.0
    """M of the hole (set by ``bind``; 0: not bound to a model yet)."""
    spin: float = 0.0
    """a (length) of the hole (set by ``bind``)."""
    look: str = "physical"
    beaming: float = 0.3
    exposure: float | None = 1.0

    def __post_init__(self) -> None:
        checks.check_positive("disk r_out", self.r_out)
        checks.check_optional(checks.check_positive, "disk r_in", self.r_in)
        checks.check_range("disk temperature", self.temperature, 100.0, 1e9)
        if self.profile not in PROFILES:
            raise ValueError(f"disk profile must be one of {PROFILES}, got {self.profile!r}")
        checks.check_range("disk brightness", self.brightness, 0.0)
        checks.check_range("disk opacity", self.opacity, 0.0, 1.0, lo_open=True)
        if self.look not in LOOKS:
            raise ValueError(f"disk look must be one of {LOOKS}, got {self.look!r}")
        checks.check_range("disk beaming", self.beaming, 0.0, 1.0)
        checks.check_optional(checks.check_positive, "disk exposure", self.exposure)

    def bind(self, model: Any) -> AccretionDisk:
        """This disk around ``model`` (Schwarzschild or Kerr): mass, spin and r_in filled in
        and checked (ValueError naming the parameter and its range)."""
        orbits = None if model is None else model.kerr_orbits()
        if orbits is None:
            raise ValueError(
                "an accretion disk needs a black hole whose orbits it knows: a Schwarzschild "
                f"or Kerr model (rg > 0), got {type(model).__name__}"
            )
        mass, spin = (float(v) for v in orbits)
        check_spin(spin / mass)
        inner = isco(mass, spin)
        r_in = inner if self.r_in is None else float(self.r_in)
        checks.check_range("disk r_in", r_in, inner * (1 - 1e-12), self.r_out, hi_open=True)
        return dataclasses.replace(self, r_in=r_in, mass=mass, spin=spin)

    def _bound(self) -> tuple[float, float, float]:
        if self.mass <= 0 or self.r_in is None:
            raise ValueError("the accretion disk is not bound to a model yet (Scene does that)")
        return self.mass, self.spin, self.r_in

    def cartesian_radii(self) -> tuple[float, float]:
        """Inner and outer radius in the local Cartesian z = 0 plane: √(r² + a²) (the
        Kerr–Schild and Boyer–Lindquist Cartesian images of BL r on the equator)."""
        _, a, r_in = self._bound()
        return math.hypot(r_in, a), math.hypot(self.r_out, a)

    def orbit_omega(self, r: Any) -> np.ndarray:
        """Keplerian (prograde circular geodesic) angular velocity at BL radius r."""
        mass, a, _ = self._bound()
        return keplerian_omega(r, mass, a)

    def temperature_at(self, r: Any) -> np.ndarray:
        """T(r) in K at BL radius r (0 outside [r_in, r_out])."""
        mass, a, r_in = self._bound()
        r = np.asarray(r, dtype=np.float64)
        if self.profile == "power_law":
            T = self.temperature * (r / r_in) ** -0.75
        else:
            peak = _nt_peak(mass, a, r_in)
            T = self.temperature * (novikov_thorne_flux(r, mass, a, r_in) / peak) ** 0.25
        return np.where((r >= r_in) & (r <= self.r_out), T, 0.0)

    def colour(self, g: Any, r: Any) -> np.ndarray:
        """Linear Rec.709 RGB (M, 3) seen of disk points at BL radius r with redshift g, in
        the disk's look (see the module): physical, the black body at g T(r) scaled by
        brightness x exposure / Y(temperature). Components below 0 (a black body redder
        than the gamut) are set to 0."""
        g = np.asarray(g, dtype=np.float64)
        exposure = 1.0 if self.exposure is None else self.exposure
        if self.look == "eht":
            bolometric = (g * self.temperature_at(r) / self.temperature) ** 4
            return eht_colour(bolometric * exposure) * self.brightness
        if self.look == "cinematic":
            g = g**self.beaming
            shifted = g * self.temperature_at(r) * (CINEMATIC_HOT / self.temperature)
            reference = float(blackbody.planck_xyz(CINEMATIC_HOT)[1])
        else:
            shifted = g * self.temperature_at(r)
            reference = float(blackbody.planck_xyz(self.temperature)[1])
        rgb = blackbody.xyz_to_rgb(blackbody.planck_xyz(shifted))
        rgb = rgb * (self.brightness * exposure / reference)
        return np.maximum(rgb, 0.0)

    def exposure_for(self, median: float, target: float | None = None) -> float:
        """The exposure that puts the median luminance of the pixels showing this disk at
        ``target`` (None: EXPOSURE_TARGETS[look]), ``median`` being theirs rendered at
        brightness 1 and exposure 1 (no finite positive median, no disk in sight: as if it
        were 1, the luminance of the disk's hottest point seen without shift). Physical
        and cinematic light is linear in the exposure; the EHT look's colour map is not,
        but its luminance increases with v, so the median pixel stays the median one
        (``eht_level``)."""
        if not (math.isfinite(median) and median > 0):
            median = 1.0
        if target is None:
            target = EXPOSURE_TARGETS[self.look]
        if self.look == "eht":
            return eht_level(target) / eht_level(median)
        return target / median


@functools.lru_cache(maxsize=16)
def _nt_peak(mass: float, a: float, r_in: float) -> float:
    """Largest Novikov–Thorne flux over r >= r_in (on a fine grid; the peak is smooth, at
    1.2-1.6 r_in, so the grid's relative error is below 1e-8)."""
    r = r_in * np.exp(np.linspace(0.0, math.log(20.0), 20_001))
    return float(np.max(novikov_thorne_flux(r, mass, a, r_in)))

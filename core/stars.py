"""Point stars: a catalogue of directions, magnitudes and colour temperatures drawn as points
over a diffuse sky (core.star_images finds and draws each star's lensed images).

A star is a point of flux F = flux_zero × 10^(−0.4 m) (m its visual magnitude; flux in linear
radiance × steradians, so a star's pixels sum, each times its solid angle, to F) and the
colour of a black body at its temperature, normalised to luminance Y = 1.
"""

from __future__ import annotations

import csv
import io
import math
from pathlib import Path
from typing import Any

import numpy as np

from .blackbody import planck_xyz, xyz_to_rgb
from .sky import Background

FLUX_ZERO = 1e-6
"""Default flux of a magnitude-0 star (linear radiance × sr): at 1920 px over 40°, whose
pixels span 1.3e-7 sr each, its pixels sum to ~8 (a magnitude-6 star's to ~0.03)."""
SUN_KELVIN = 5800.0
"""The temperature of a star given none."""
BRIGHTEST = -30.0
"""The brightest magnitude a catalogue may hold (the Sun is −26.7): brighter ones reach
fluxes beyond 32-bit floats (inf pixels)."""
_COLUMNS = {
    "ra": ("ra", "ra_deg", "raj2000"),
    "dec": ("dec", "de", "dec_deg", "dej2000"),
    "mag": ("mag", "vmag", "v", "magnitude"),
    "bv": ("bv", "b-v", "b_v", "ci", "color_index"),
}
"""Accepted CSV header names (case-insensitive) of each column StarField.from_csv reads."""


def temperature_from_bv(bv: Any) -> np.ndarray:
    """A star's effective temperature (K) from its B−V colour index (Ballesteros 2012,
    EPL 97, 34008: T = 4600 (1 / (0.92 BV + 1.7) + 1 / (0.92 BV + 0.62)))."""
    bv = np.clip(np.asarray(bv, dtype=np.float64), -0.4, 2.0)
    return 4600.0 * (1.0 / (0.92 * bv + 1.7) + 1.0 / (0.92 * bv + 0.62))


def star_rgb(temperature: Any) -> np.ndarray:
    """Linear Rec.709 colour (N, 3) of black bodies at ``temperature`` (N,) K, luminance
    Y = 1 (components out of gamut clipped to 0)."""
    xyz = planck_xyz(np.asarray(temperature, dtype=np.float64).reshape(-1))
    return np.maximum(xyz_to_rgb(xyz / xyz[:, 1:2]), 0.0)


def radec_to_direction(ra_deg: Any, dec_deg: Any) -> np.ndarray:
    """Unit vectors (N, 3) of right ascensions and declinations (degrees): x towards RA 0,
    z towards the celestial north pole."""
    ra, dec = np.radians(np.asarray(ra_deg, float)), np.radians(np.asarray(dec_deg, float))
    return np.stack([np.cos(dec) * np.cos(ra), np.cos(dec) * np.sin(ra), np.sin(dec)], axis=-1)


class StarField(Background):
    """Point stars over a diffuse sky: ``background=core.StarField(...)``.

    ``directions`` (S, 3) in the environment's axes (``matrix`` rotates them into the world
    as it does the diffuse sky), ``magnitudes`` (S,) and ``temperatures`` (S,) K (or one
    for all). ``diffuse``: what lies between the stars (a Background spec; "milky_way": the
    procedural sky's galaxy band and gradient without its own stars). ``flux_zero``: the
    flux of a magnitude-0 star (FLUX_ZERO); ``strength`` scales stars and diffuse sky alike.
    """

    def __init__(
        self,
        directions: Any,
        magnitudes: Any,
        temperatures: Any = SUN_KELVIN,
        *,
        diffuse: Any = "milky_way",
        flux_zero: float = FLUX_ZERO,
        strength: float = 1.0,
        matrix: Any = None,
    ) -> None:
        """Check and hold the catalogue (ValueError naming the problem)."""
        super().__init__(diffuse, strength=strength, matrix=matrix)
        d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
        m = np.asarray(magnitudes, dtype=np.float64).reshape(-1)
        t = np.broadcast_to(np.asarray(temperatures, dtype=np.float64), m.shape).copy()
        if d.shape[0] != m.shape[0]:
            raise ValueError(f"{d.shape[0]} star directions but {m.shape[0]} magnitudes")
        length = np.linalg.norm(d, axis=1)
        bad = ~(np.isfinite(length) & (length > 0) & np.isfinite(m) & np.isfinite(t) & (t > 0))
        if bad.any():
            raise ValueError(
                f"star {int(np.argmax(bad))}: direction, magnitude and temperature must be "
                "finite, the direction non-zero and the temperature positive"
            )
        if not (math.isfinite(flux_zero) and flux_zero >= 0):
            raise ValueError(f"flux_zero must be a number >= 0, got {flux_zero!r}")
        self.local_directions = d / length[:, None]
        self.magnitudes, self.temperatures = m, t
        self.flux_zero = float(flux_zero)

    @property
    def directions(self) -> np.ndarray:
        """The stars' unit world directions (S, 3)."""
        d = self.local_directions
        return d if self.matrix is None else d @ self.matrix.T

    @property
    def flux(self) -> np.ndarray:
        """Each star's flux (S,), luminance × sr: strength × flux_zero × 10^(−0.4 m)."""
        return self.strength * self.flux_zero * 10.0 ** (-0.4 * self.magnitudes)

    @classmethod
    def random(
        cls,
        count: int = 9000,
        seed: int = 0,
        *,
        brightest: float = -1.5,
        faintest: float = 6.5,
        **options: Any,
    ) -> StarField:
        """``count`` stars uniform over the sphere (reproducible from ``seed``): magnitudes
        between ``brightest`` and ``faintest`` with counts growing as 10^(0.5 m) (about the
        naked-eye sky's), temperatures 2 500–25 000 K, most of them cool."""
        if count < 0 or not brightest <= faintest:
            raise ValueError("count must be >= 0 and brightest <= faintest")
        rng = np.random.default_rng(seed)
        z = rng.uniform(-1.0, 1.0, count)
        phi = rng.uniform(-math.pi, math.pi, count)
        ring = np.sqrt(1.0 - z * z)
        directions = np.stack([ring * np.cos(phi), ring * np.sin(phi), z], axis=1)
        lowest = 10.0 ** (0.5 * (brightest - faintest))  # the CDF 10^(0.5 (m - faintest))
        magnitudes = faintest + 2.0 * np.log10(rng.uniform(lowest, 1.0, count))
        u = rng.uniform(0.0, 1.0, count)
        temperatures = np.exp(math.log(2500.0) + math.log(10.0) * u**1.6)
        return cls(directions, magnitudes, temperatures, **options)

    @classmethod
    def from_csv(cls, path: str | Path, **options: Any) -> StarField:
        """Stars from a CSV file (UTF-8, with or without a byte-order mark) with a header
        naming right ascension and declination (degrees), visual magnitude and, optionally,
        the B−V colour index (_COLUMNS' names, any case; without B−V the stars are
        SUN_KELVIN); blank lines are skipped. ValueError naming the file and the line."""
        rows = _csv_rows(path)
        if not rows:
            raise ValueError(f"{path}: empty star catalogue")
        columns = _header_columns(rows[0][1], path)
        values = np.full((len(rows) - 1, 4), np.nan)
        for i, (number, row) in enumerate(rows[1:]):
            for k, name in enumerate(("ra", "dec", "mag", "bv")):
                if name in columns:
                    values[i, k] = _cell(row, columns[name], name, f"{path}, line {number}")
        temperatures = np.where(
            np.isnan(values[:, 3]), SUN_KELVIN, temperature_from_bv(np.nan_to_num(values[:, 3]))
        )
        directions = radec_to_direction(values[:, 0], values[:, 1])
        return cls(directions, values[:, 2], temperatures, **options)


def _csv_rows(path: str | Path) -> list[tuple[int, list[str]]]:
    """(line number, cells) of a CSV file's non-blank lines; ValueError naming the file and
    line when it is not UTF-8 text (a byte-order mark, as Excel's "CSV UTF-8" writes, is not
    part of the first name)."""
    data = Path(path).read_bytes()
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        line = data[: err.start].count(b"\n") + 1
        raise ValueError(
            f"{path}, line {line}: not UTF-8 text (byte {data[err.start]:#04x}): save the "
            "catalogue as CSV UTF-8"
        ) from None
    reader = csv.reader(io.StringIO(text, newline=""))
    return [(reader.line_num, row) for row in reader if any(c.strip() for c in row)]


def _cell(row: list[str], column: int, name: str, where: str) -> float:
    """The number in ``row[column]``, a finite one (and, for a magnitude, no brighter than
    BRIGHTEST); ValueError naming ``where`` (file and line) and the column."""
    try:
        value = float(row[column])
    except (ValueError, IndexError):
        raise ValueError(f"{where}: column {name!r} is not a number") from None
    if not math.isfinite(value):
        raise ValueError(f"{where}: column {name!r} is {value}, not a finite number")
    if name == "mag" and value < BRIGHTEST:
        raise ValueError(
            f"{where}: magnitude {value:g} is brighter than {BRIGHTEST:g} (the Sun is -26.7): "
            "its light would overflow the image"
        )
    return value


def _header_columns(header: list[str], path: Any) -> dict[str, int]:
    """Column index of each of _COLUMNS found in ``header`` (ra, dec and mag required)."""
    names = [h.strip().lower() for h in header]
    found = {}
    for key, aliases in _COLUMNS.items():
        for alias in aliases:
            if alias in names:
                found[key] = names.index(alias)
                break
    missing = [key for key in ("ra", "dec", "mag") if key not in found]
    if missing:
        raise ValueError(
            f"{path}: the header must name columns ra, dec and mag (degrees, degrees, visual "
            f"magnitude; b-v optional), missing {', '.join(missing)} in {header!r}"
        )
    return found

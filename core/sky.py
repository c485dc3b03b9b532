"""Backgrounds: a deterministic procedural star field and equirectangular environment maps.

Direction convention (Blender's world/environment, checked against Cycles'
``direction_to_equirectangular`` and the GPU ``node_tex_environment_equirectangular``):
for a world direction d = (x, y, z), z up,

    u = 0.5 - atan2(y, x) / (2 pi)        (image centre u = 0.5 looks along +X, +Y is at u = 0.25)
    v = 0.5 + atan2(z, hypot(x, y)) / pi  (v = 1 at the zenith)

Images here are (h, w, c) arrays with row 0 at the TOP (v = 1) and column 0 at u = 0.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from .mipmap import MipMap, bilinear, point_or_filtered, texel_footprint

__all__ = [
    "Background",
    "direction_to_equirect",
    "equirect_lookup",
    "equirect_to_direction",
    "procedural_sky",
    "star_color",
]

# -- equirectangular mapping --------------------------------------------------------------


def _normalize(d: Any) -> np.ndarray:
    d = np.asarray(d, dtype=np.float64)
    n = np.linalg.norm(d, axis=-1, keepdims=True)
    return np.where(n > 0, d / np.where(n > 0, n, 1.0), np.array([0.0, 0.0, 1.0]))


def direction_to_equirect(directions: Any) -> np.ndarray:
    """Directions (N, 3) -> Blender equirectangular (u, v) in [0, 1] (N, 2)."""
    d = np.asarray(directions, dtype=np.float64)
    u = 0.5 - np.arctan2(d[..., 1], d[..., 0]) / (2 * np.pi)
    v = 0.5 + np.arctan2(d[..., 2], np.hypot(d[..., 0], d[..., 1])) / np.pi
    return np.stack([u, v], axis=-1)


def equirect_to_direction(uv: Any) -> np.ndarray:
    """Blender equirectangular (u, v) (N, 2) -> unit directions (N, 3)."""
    uv = np.asarray(uv, dtype=np.float64)
    lon = (0.5 - uv[..., 0]) * 2 * np.pi
    lat = (uv[..., 1] - 0.5) * np.pi
    c = np.cos(lat)
    return np.stack([c * np.cos(lon), c * np.sin(lon), np.sin(lat)], axis=-1)


def equirect_lookup(image: Any, directions: Any, interpolation: str = "linear") -> np.ndarray:
    """Sample an equirectangular image (h, w, c), row 0 at the top, along directions (N, 3).

    ``interpolation``: "linear" (bilinear; wraps in longitude, clamps at the poles) or
    "closest". Pixel centres sit at ((i + 0.5) / w, 1 - (j + 0.5) / h), as in Blender.
    """
    img = np.asarray(image)
    if img.ndim == 2:
        img = img[:, :, None]
    if img.ndim != 3:
        raise ValueError(f"image must be (h, w) or (h, w, c), got shape {np.shape(image)}")
    h, w = img.shape[:2]
    uv = direction_to_equirect(directions)
    x = uv[..., 0] * w - 0.5
    y = (1.0 - uv[..., 1]) * h - 0.5
    if interpolation == "closest":
        xi = np.floor(x + 0.5).astype(np.int64) % w
        yi = np.clip(np.floor(y + 0.5).astype(np.int64), 0, h - 1)
        return img[yi, xi].astype(np.float64)
    if interpolation != "linear":
        raise ValueError(f"interpolation must be 'linear' or 'closest', got {interpolation!r}")
    return bilinear(img, x, y).astype(np.float64)


# -- hashing (deterministic, stateless) ----------------------------------------------------

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)
_P1, _P2, _P3 = np.uint64(0x8DA6B343), np.uint64(0xD8163841), np.uint64(0xCB1AB31F)


def _hash(x: np.ndarray) -> np.ndarray:
    """splitmix64 finaliser of a uint64 array (wrapping arithmetic)."""
    with np.errstate(over="ignore"):
        x = x.astype(np.uint64) + _GOLDEN
        x = (x ^ (x >> np.uint64(30))) * _MIX1
        x = (x ^ (x >> np.uint64(27))) * _MIX2
    return x ^ (x >> np.uint64(31))


def _key(*ints: np.ndarray) -> np.ndarray:
    """Hash several integer arrays into one uint64 key."""
    k = np.zeros(np.shape(ints[0]), dtype=np.uint64)
    for v in ints:
        k = _hash(k ^ np.asarray(v).astype(np.int64).astype(np.uint64))
    return k


def _uniform(key: np.ndarray, salt: int) -> np.ndarray:
    """Uniform floats in [0, 1) from keys and a salt."""
    return (_hash(key ^ np.uint64(salt)) >> np.uint64(11)).astype(np.float64) * 2.0**-53


def _value_noise(p: np.ndarray, salt: int) -> np.ndarray:
    """Smooth 3-D value noise in [0, 1] at points p (N, 3)."""
    i = np.floor(p)
    f = p - i
    f = f * f * (3 - 2 * f)
    i = i.astype(np.int64).astype(np.uint64)
    weights = [(1 - f[:, k], f[:, k]) for k in range(3)]  # per axis: the cell's two sides
    with np.errstate(over="ignore"):  # wrapping: (i + 1) P = i P + P
        parts = [(i[:, k] * prime, i[:, k] * prime + prime)
                 for k, prime in enumerate((_P1, _P2, _P3))]  # fmt: skip
    out = np.zeros(p.shape[0])
    for corner in range(8):
        o = [(corner >> k) & 1 for k in range(3)]
        wgt = weights[0][o[0]] * weights[1][o[1]] * weights[2][o[2]]
        key = parts[0][o[0]] ^ parts[1][o[1]] ^ parts[2][o[2]]
        out += wgt * _uniform(key, salt)
    return out


def _fbm(d: np.ndarray, freq: float, octaves: int, salt: int) -> np.ndarray:
    """Fractal sum of value noise on the unit sphere, in [0, 1]."""
    total, amp, norm = np.zeros(d.shape[0]), 1.0, 0.0
    for k in range(octaves):
        total += amp * _value_noise(d * freq * 2.0**k, salt + 7919 * k)
        norm += amp
        amp *= 0.5
    return total / norm


# -- stars ----------------------------------------------------------------------------------

# approximate linear-RGB colours of black bodies, by temperature (K)
_TEMPS = np.array([2500.0, 3500.0, 4500.0, 5800.0, 7500.0, 10000.0, 20000.0])
_TEMP_RGB = np.array([
    [1.00, 0.42, 0.12], [1.00, 0.60, 0.30], [1.00, 0.78, 0.55], [1.00, 0.93, 0.85],
    [0.86, 0.90, 1.00], [0.70, 0.80, 1.00], [0.58, 0.70, 1.00],
])  # fmt: skip

# (cells per cube face, probability of a star, brightness scale, brightness exponent, sigma deg)
_STAR_LAYERS = (
    (150, 0.8, 0.5, 6.0, 0.035),
    (48, 0.6, 3.0, 4.0, 0.05),
    (12, 0.5, 10.0, 3.0, 0.07),
)


_WIDEST_SIGMA = 1.51
"""A star's sigma over its layer's (``_star_layer``): 1 + sqrt(bright / scale) / 2, at most
1 + sqrt(1.02) / 2 < 1.51."""


def star_color(temperature: Any) -> np.ndarray:
    """Approximate linear RGB (N, 3) of a black body of the given temperature(s) in K."""
    lt = np.log(np.asarray(temperature, dtype=np.float64))
    return np.stack([np.interp(lt, np.log(_TEMPS), _TEMP_RGB[:, c]) for c in range(3)], -1)


@dataclass(frozen=True)
class _CubePlaces:
    """Directions' places on an equal-angle cube map, whatever its cells: each one's face
    (N,), the face's axis (N,) and sign (N,), its in-face coordinates ``a`` (N, 2) in
    [-1, 1], and the columns (N, 3) of the face's axis and its two in-face axes."""

    face: np.ndarray
    sign: np.ndarray
    a: np.ndarray
    columns: np.ndarray

    @classmethod
    def of(cls, d: np.ndarray) -> _CubePlaces:
        """The places of unit directions ``d`` (N, 3)."""
        axis = np.argmax(np.abs(d), axis=1)
        columns = np.stack([axis, (axis + 1) % 3, (axis + 2) % 3], axis=1)
        rows = np.arange(d.shape[0])
        major = d[rows, axis]
        s = d[rows, columns[:, 1]] / np.abs(major)
        t = d[rows, columns[:, 2]] / np.abs(major)
        a = np.arctan(np.stack([s, t], axis=1)) * (4 / np.pi)  # in [-1, 1]
        return cls(axis * 2 + (major < 0), np.sign(major), a, columns)

    def cells(self, cells: int) -> np.ndarray:
        """Each direction's cell (N, 2) on a map of ``cells`` a face's side."""
        return np.clip(np.floor((self.a + 1) * 0.5 * cells), 0, cells - 1).astype(np.int64)


def _star_layer(d: np.ndarray, layer: int, size: float, places: _CubePlaces) -> np.ndarray:
    """Radiance (N, 3) of one layer of hashed stars, each inside its own cube-map cell
    (``places``: d's on the map): a star's light reaches 3 sigma, so only the directions
    within 3 of its widest sigma look up more (its brightness, size and colour) than
    where it lies."""
    cells, prob, scale, expo, sigma_deg = _STAR_LAYERS[layer]
    ij = places.cells(cells)
    key = _key(places.face, ij[:, 0], ij[:, 1], np.full(places.face.shape, layer))
    jitter = 0.2 + 0.6 * np.stack([_uniform(key, 1), _uniform(key, 2)], axis=1)
    st = np.tan((-1 + (ij + jitter) * (2.0 / cells)) * (np.pi / 4))
    star = np.zeros_like(d)
    rows = np.arange(d.shape[0])
    star[rows, places.columns[:, 0]] = places.sign
    star[rows, places.columns[:, 1]] = st[:, 0]
    star[rows, places.columns[:, 2]] = st[:, 1]
    star /= np.linalg.norm(star, axis=1, keepdims=True)
    apart2 = np.sum((d - star) ** 2, axis=1)
    widest = np.radians(sigma_deg * size) * _WIDEST_SIGMA
    near = np.flatnonzero(~(apart2 >= 9.0 * widest**2))  # NaN kept: it shows as NaN
    key = key[near]
    u = _uniform(key, 3)
    bright = scale * (0.02 + _uniform(key, 4) ** expo) * (_uniform(key, 5) < prob)
    sigma = np.radians(sigma_deg * size) * (1 + 0.5 * np.sqrt(bright / scale))
    r2 = apart2[near] / sigma**2
    window = np.clip(1.0 - r2 / 9.0, 0.0, 1.0) ** 2  # smooth cut-off at 3 sigma
    profile = np.exp(-0.5 * r2) * window
    temp = np.exp(np.log(2500.0) + (np.log(20000.0) - np.log(2500.0)) * u**1.6)
    out = np.zeros_like(d)
    out[near] = star_color(temp) * (bright * profile)[:, None]
    return out


# -- galaxy band, background, grid ------------------------------------------------------------

_BAND_NORMAL = np.array([np.sin(1.05) * np.cos(0.5), np.sin(1.05) * np.sin(0.5), np.cos(1.05)])
_BAND_E1 = np.cross(_BAND_NORMAL, [0.0, 0.0, 1.0])
_BAND_E1 /= np.linalg.norm(_BAND_E1)
_BAND_E2 = np.cross(_BAND_NORMAL, _BAND_E1)


def _galaxy(d: np.ndarray) -> np.ndarray:
    """A tilted great-circle band with noise structure, a bulge and a dust lane (N, 3)."""
    out = np.zeros_like(d)
    b = np.arcsin(np.clip(d @ _BAND_NORMAL, -1, 1))
    near = np.flatnonzero(np.abs(b) < 0.6)  # beyond, the band is below 1e-6
    if near.size == 0:
        return out
    d, b = d[near], b[near]
    lon = np.arctan2(d @ _BAND_E2, d @ _BAND_E1)
    n1 = _fbm(d, 4.0, 4, 101)
    n2 = _fbm(d, 9.0, 3, 202)
    width = 0.14 * (0.7 + 0.6 * n1)
    band = np.exp(-((b / width) ** 2)) * (0.35 + 0.65 * n2)
    bulge = 1.6 * np.exp(-((lon / 0.45) ** 2) - (b / 0.16) ** 2)
    lane = 1 - 0.75 * np.exp(-((b / 0.03) ** 2)) * (0.4 + 0.6 * n1)
    glow = (band + bulge) * lane * 0.06
    warm, cool = np.array([1.0, 0.82, 0.62]), np.array([0.72, 0.80, 1.0])
    mix = np.clip(0.3 + 0.7 * np.exp(-((lon / 1.2) ** 2)), 0, 1)[:, None]
    out[near] = glow[:, None] * (mix * warm + (1 - mix) * cool)
    return out


def _gradient(d: np.ndarray) -> np.ndarray:
    """Dim background: a faint blue gradient, brighter towards +Z."""
    return np.array([0.0012, 0.0016, 0.0032]) * (1.0 + 0.6 * d[:, 2:3])


def _grid(d: np.ndarray, step_deg: float = 15.0, width_deg: float = 0.25) -> np.ndarray:
    """Latitude/longitude lines every step_deg (equator and lon 0 = +X brighter) (N, 3)."""
    lat = np.degrees(np.arcsin(np.clip(d[:, 2], -1, 1)))
    lon = np.degrees(np.arctan2(d[:, 1], d[:, 0]))
    dlat = np.abs(lat - step_deg * np.round(lat / step_deg))
    dlon = np.abs(lon - step_deg * np.round(lon / step_deg)) * np.cos(np.radians(lat))
    line = np.clip(1.0 - np.minimum(dlat, dlon) / width_deg, 0, 1)
    major = (np.abs(lat) < width_deg) | ((np.abs(lon) < 1) & (dlon < width_deg))
    color = np.where(major[:, None], [0.6, 0.25, 0.1], [0.15, 0.15, 0.15])
    return line[:, None] * color


def procedural_sky(
    directions: Any,
    *,
    grid: bool = False,
    stars: bool = True,
    galaxy: bool = True,
    star_size: float = 1.0,
) -> np.ndarray:
    """Deterministic linear RGB (N, 3) of a star field, galaxy band and dim gradient.

    Hash-based (no RNG state, no files): the same direction always gives the same colour.
    ``star_size`` scales the stars' angular size (about 0.035-0.1 degrees by default);
    ``grid`` adds latitude/longitude lines every 15 degrees.
    """
    d = _normalize(directions)
    shape = d.shape
    d = d.reshape(-1, 3)
    rgb = _gradient(d)
    if galaxy:
        rgb = rgb + _galaxy(d)
    if stars:
        places = _CubePlaces.of(d)
        for layer in range(len(_STAR_LAYERS)):
            rgb = rgb + _star_layer(d, layer, star_size, places)
    if grid:
        rgb = rgb + _grid(d)
    return rgb.reshape(shape)


# -- Background helper -------------------------------------------------------------------------


class Background:
    """What rays that escape see: "procedural" ("milky_way": without its stars), a constant
    rgb(a), an equirect array or callable.

    ``matrix`` (3x3, optional) rotates the environment: a world direction d is looked up
    at ``matrix.T @ d``. ``strength`` scales the colour (not the alpha).
    """

    def __init__(
        self,
        spec: Any = "procedural",
        *,
        strength: float = 1.0,
        matrix: Any = None,
        grid: bool = False,
        star_size: float = 1.0,
        interpolation: str = "linear",
    ) -> None:
        """Build from a spec: "procedural", (r, g, b[, a]), (h, w, 3|4) array or callable."""
        self.strength = float(strength)
        self.matrix = None if matrix is None else np.asarray(matrix, dtype=np.float64)
        self._fn, self._mipmap = self._make(spec, grid, star_size, interpolation)
        self.detail = self._detail(spec, grid, star_size)

    @classmethod
    def of(cls, spec: Any) -> Background:
        """``spec`` itself when it is a Background, else the Background it describes."""
        return spec if isinstance(spec, Background) else cls(spec)

    @property
    def filters(self) -> bool:
        """Whether a footprint changes what this background shows (a bilinear equirect
        texture: core.mipmap), so a render looks its sky up over each pixel's footprint."""
        return self._mipmap is not None or (isinstance(self._fn, Background) and self._fn.filters)

    @staticmethod
    def _detail(spec: Any, grid: bool, star_size: float) -> float:
        """The angle (radians) across the smallest detail the background shows: the
        procedural sky's faintest star's radius (its profile is cut at 3 sigma; a grid line
        is 0.5 deg wide), an equirect texture's texel, inf for a constant or the galaxy
        band alone (its noise spans degrees), 0 for a callable (unknown)."""
        if isinstance(spec, Background):
            return spec.detail
        if isinstance(spec, str):
            sigma = math.radians(min(layer[4] for layer in _STAR_LAYERS) * star_size)
            stars = 3.0 * sigma if spec == "procedural" else math.inf
            return min(stars, math.radians(0.5)) if grid else stars
        if callable(spec):
            return 0.0
        shape = np.shape(spec)
        return math.pi / shape[0] if len(shape) == 3 else math.inf

    @staticmethod
    def _make(spec: Any, grid: bool, star_size: float, interp: str) -> tuple[Callable, Any]:
        """(the lookup of directions, the pyramid of a bilinear equirect texture or None)."""
        if isinstance(spec, Background):
            return spec, None
        if isinstance(spec, str):
            if spec not in ("procedural", "milky_way"):
                raise ValueError(
                    f"background string must be 'procedural' or 'milky_way', got {spec!r}"
                )
            stars = spec == "procedural"  # milky_way: the galaxy band and gradient only
            return lambda d: procedural_sky(d, grid=grid, stars=stars, star_size=star_size), None
        if callable(spec):
            return spec, None
        arr = np.asarray(spec)  # a float image keeps its type: no float64 copy of a big sky
        if not np.issubdtype(arr.dtype, np.floating):
            arr = arr.astype(np.float64)
        if arr.ndim == 1 and arr.shape[0] in (3, 4):
            return lambda d: np.broadcast_to(arr, (d.shape[0], arr.shape[0])), None
        if arr.ndim == 3 and arr.shape[2] in (3, 4):
            mipmap = MipMap(arr) if interp == "linear" else None
            return lambda d: equirect_lookup(arr, d, interp), mipmap
        raise ValueError(
            "background must be 'procedural', an rgb(a) tuple, an (h, w, 3|4) array or a "
            f"callable, got an array of shape {arr.shape}"
        )

    def __call__(self, directions: Any, footprint: np.ndarray | None = None) -> np.ndarray:
        """Linear RGBA (N, 4) seen along world directions (N, 3); alpha 1 unless given.
        ``footprint`` (N, 2, 3): the directions' derivatives along image x and y (each
        pixel's footprint on the sky); a texture is then averaged over it (core.mipmap; NaN
        rows: a point, as without)."""
        d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
        if self.matrix is not None:
            d = d @ self.matrix
            footprint = None if footprint is None else footprint @ self.matrix
        c = np.asarray(self._lookup(d, footprint), dtype=np.float64)
        out = np.ones((d.shape[0], 4))
        out[:, :3] = c[:, :3] * self.strength
        if c.shape[1] == 4:
            out[:, 3] = c[:, 3]
        return out

    def _lookup(self, d: np.ndarray, footprint: np.ndarray | None) -> np.ndarray:
        if footprint is None or not self.filters:
            return self._fn(d)
        if self._mipmap is None:  # a Background wrapping a filtering one
            return self._fn(d, footprint)
        pyramid = self._mipmap
        texels = texel_footprint(d, footprint, pyramid.size)
        return point_or_filtered(
            texels,
            lambda rows: self._fn(d[rows]),
            lambda rows: pyramid.lookup(direction_to_equirect(d[rows]), texels[rows]),
            pyramid.levels[0].shape[2],
        )

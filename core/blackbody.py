"""Colour of black-body light: the Planck spectrum integrated against the CIE 1931 colour-
matching functions, in linear Rec.709 / sRGB primaries (Blender's scene-linear space).

The colour-matching functions are the CIE 1931 2° standard observer x̄, ȳ, z̄ from the
CIE's table (CIE 015:2018, *Colorimetry*, table T.4; the same values as the 1 nm file
``ciexyz31_1.csv`` of the Colour & Vision Research Laboratory, cvrl.org), every 5 nm from
380 to 780 nm. XYZ -> linear sRGB is derived from the Rec.709 primaries (0.64, 0.33),
(0.30, 0.60), (0.15, 0.06) and the D65 white point (0.3127, 0.3290) (IEC 61966-2-1).
"""

from __future__ import annotations

import numpy as np

WAVELENGTHS_NM = np.arange(380.0, 781.0, 5.0)
"""The wavelengths of the table below: 380, 385, ..., 780 nm (81)."""

# fmt: off
_CMF = np.array([
    # x̄          ȳ          z̄           every 5 nm from 380 nm
    0.001368, 0.000039, 0.006450, 0.002236, 0.000064, 0.010550, 0.004243, 0.000120, 0.020050,
    0.007650, 0.000217, 0.036210, 0.014310, 0.000396, 0.067850, 0.023190, 0.000640, 0.110200,
    0.043510, 0.001210, 0.207400, 0.077630, 0.002180, 0.371300, 0.134380, 0.004000, 0.645600,
    0.214770, 0.007300, 1.039050, 0.283900, 0.011600, 1.385600, 0.328500, 0.016840, 1.622960,
    0.348280, 0.023000, 1.747060, 0.348060, 0.029800, 1.782600, 0.336200, 0.038000, 1.772110,
    0.318700, 0.048000, 1.744100, 0.290800, 0.060000, 1.669200, 0.251100, 0.073900, 1.528100,
    0.195360, 0.090980, 1.287640, 0.142100, 0.112600, 1.041900, 0.095640, 0.139020, 0.812950,
    0.058010, 0.169300, 0.616200, 0.032010, 0.208020, 0.465180, 0.014700, 0.258600, 0.353300,
    0.004900, 0.323000, 0.272000, 0.002400, 0.407300, 0.212300, 0.009300, 0.503000, 0.158200,
    0.029100, 0.608200, 0.111700, 0.063270, 0.710000, 0.078250, 0.109600, 0.793200, 0.057250,
    0.165500, 0.862000, 0.042160, 0.225750, 0.914850, 0.029840, 0.290400, 0.954000, 0.020300,
    0.359700, 0.980300, 0.013400, 0.433450, 0.994950, 0.008750, 0.512050, 1.000000, 0.005750,
    0.594500, 0.995000, 0.003900, 0.678400, 0.978600, 0.002750, 0.762100, 0.952000, 0.002100,
    0.842500, 0.915400, 0.001800, 0.916300, 0.870000, 0.001650, 0.978600, 0.816300, 0.001400,
    1.026300, 0.757000, 0.001100, 1.056700, 0.694900, 0.001000, 1.062200, 0.631000, 0.000800,
    1.045600, 0.566800, 0.000600, 1.002600, 0.503000, 0.000340, 0.938400, 0.441200, 0.000240,
    0.854450, 0.381000, 0.000190, 0.751400, 0.321000, 0.000100, 0.642400, 0.265000, 0.000050,
    0.541900, 0.217000, 0.000030, 0.447900, 0.175000, 0.000020, 0.360800, 0.138200, 0.000010,
    0.283500, 0.107000, 0.000000, 0.218700, 0.081600, 0.000000, 0.164900, 0.061000, 0.000000,
    0.121200, 0.044580, 0.000000, 0.087400, 0.032000, 0.000000, 0.063600, 0.023200, 0.000000,
    0.046770, 0.017000, 0.000000, 0.032900, 0.011920, 0.000000, 0.022700, 0.008210, 0.000000,
    0.015840, 0.005723, 0.000000, 0.011359, 0.004102, 0.000000, 0.008111, 0.002929, 0.000000,
    0.005790, 0.002091, 0.000000, 0.004109, 0.001484, 0.000000, 0.002899, 0.001047, 0.000000,
    0.002049, 0.000740, 0.000000, 0.001440, 0.000520, 0.000000, 0.001000, 0.000361, 0.000000,
    0.000690, 0.000249, 0.000000, 0.000476, 0.000172, 0.000000, 0.000332, 0.000120, 0.000000,
    0.000235, 0.000085, 0.000000, 0.000166, 0.000060, 0.000000, 0.000117, 0.000042, 0.000000,
    0.000083, 0.000030, 0.000000, 0.000059, 0.000021, 0.000000, 0.000042, 0.000015, 0.000000,
]).reshape(81, 3)
# fmt: on
CMF = _CMF
"""(81, 3) x̄, ȳ, z̄ at WAVELENGTHS_NM (CIE 1931 2° observer, see the module)."""

_H, _C, _K = 6.62607015e-34, 299_792_458.0, 1.380649e-23  # SI, exact (2019 definitions)
_C2 = _H * _C / _K  # second radiation constant, m K


def _rgb_from_xyz() -> np.ndarray:
    """3x3 matrix XYZ -> linear Rec.709 from the primaries' and D65's chromaticities."""
    xy = np.array([[0.64, 0.33], [0.30, 0.60], [0.15, 0.06]])
    primaries = np.stack([xy[:, 0] / xy[:, 1], np.ones(3), (1 - xy.sum(axis=1)) / xy[:, 1]])
    white = np.array([0.3127 / 0.3290, 1.0, (1 - 0.3127 - 0.3290) / 0.3290])
    return np.linalg.inv(primaries * np.linalg.solve(primaries, white))


RGB_FROM_XYZ = _rgb_from_xyz()
"""XYZ -> linear Rec.709 / sRGB (D65), 3x3."""
XYZ_FROM_RGB = np.linalg.inv(RGB_FROM_XYZ)
"""Linear Rec.709 / sRGB -> XYZ (its row 1: the luminance Y of an RGB colour)."""


def _planck_sum(T: np.ndarray) -> np.ndarray:
    """∑ B_λ(λ) x̄(λ) Δλ (M, 3) at temperatures T (M,) (see planck_xyz), summed."""
    lam = WAVELENGTHS_NM * 1e-9
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        spectrum = (lam / 555e-9) ** -5 / np.expm1(_C2 / (lam * T[:, None]))
    return np.where(T[:, None] > 0, spectrum, 0.0) @ CMF


TABLE_KELVIN = np.geomspace(400.0, 1e6, 1 << 14)
"""Temperatures of the table planck_xyz interpolates (log XYZ linear in log T between
these; outside them the sum is taken): within 3e-6 relative of the sum (test_disk)."""
_TABLE_LOG_T = np.log(TABLE_KELVIN)
_TABLE_LOG_XYZ = np.log(_planck_sum(TABLE_KELVIN))


def planck_xyz(temperature) -> np.ndarray:
    """CIE XYZ (..., 3) of black-body radiance B_λ at ``temperature`` (K), relative units:
    ∑ B_λ(λ) x̄(λ) Δλ with B_λ ∝ λ⁻⁵ / (exp(c₂/λT) − 1); 0 at T <= 0 (interpolated in a
    table of the sum, TABLE_KELVIN: a disk's every pixel is one)."""
    T = np.asarray(temperature, dtype=np.float64)
    flat = T.reshape(-1)
    xyz = np.empty(flat.shape + (3,))
    inside = (flat >= TABLE_KELVIN[0]) & (flat <= TABLE_KELVIN[-1])
    log_t = np.log(flat[inside])
    for channel in range(3):
        xyz[inside, channel] = np.exp(np.interp(log_t, _TABLE_LOG_T, _TABLE_LOG_XYZ[:, channel]))
    xyz[~inside] = _planck_sum(flat[~inside])
    return xyz.reshape(T.shape + (3,))


def chromaticity(xyz) -> np.ndarray:
    """CIE (x, y) (..., 2) of XYZ (..., 3)."""
    xyz = np.asarray(xyz, dtype=np.float64)
    return xyz[..., :2] / xyz.sum(axis=-1, keepdims=True)


def xyz_to_rgb(xyz) -> np.ndarray:
    """Linear Rec.709 / sRGB (..., 3) of XYZ (..., 3); colours outside the gamut (a deep
    red black body) keep their negative components (the caller decides)."""
    return np.asarray(xyz, dtype=np.float64) @ RGB_FROM_XYZ.T


COLOUR_KELVIN = (1000.0, 40_000.0)
"""The colour temperatures a colour may be given (shifted_colour): colours redder or bluer
than the black bodies of these count as these."""


def colour_temperature(rgb) -> np.ndarray:
    """The temperature (...,) of the black body whose CIE Z/X ratio is that of linear RGB
    (..., 3), clipped to COLOUR_KELVIN (Z/X grows with T along the Planckian locus)."""
    xyz = np.asarray(rgb, dtype=np.float64) @ XYZ_FROM_RGB.T
    with np.errstate(all="ignore"):
        key = np.log(np.maximum(xyz[..., 2], 1e-300) / np.maximum(xyz[..., 0], 1e-300))
    return np.exp(np.interp(key, _LOCUS_KEY, _LOCUS_LOG_T))


def shifted_colour(rgb, g, power: float = 3.0) -> np.ndarray:
    """Linear RGB (N, 3) of colours (N, 3) seen with frequency ratio g (N,) (observed /
    emitted): each treated as a black body of its colour_temperature T, its XYZ scaled
    channel by channel as the black body's from T to g T and its luminance by g^power (3:
    the specific intensity of an image, I_ν / ν³ invariant). A documented approximation:
    exact for black-body colours, a hue off the Planckian locus keeps its offset. Out of
    gamut components are clipped to 0."""
    rgb = np.asarray(rgb, dtype=np.float64)
    g = np.asarray(g, dtype=np.float64)
    T = colour_temperature(rgb)
    before, after = planck_xyz(T), planck_xyz(np.clip(g * T, TABLE_KELVIN[0], TABLE_KELVIN[-1]))
    ratio = (after / after[:, 1:2]) / (before / before[:, 1:2])
    xyz = (rgb @ XYZ_FROM_RGB.T) * ratio * (g**power)[:, None]
    return np.maximum(xyz_to_rgb(xyz), 0.0)


def _locus() -> tuple[np.ndarray, np.ndarray]:
    """log(Z/X) and log T along the Planckian locus over COLOUR_KELVIN (increasing)."""
    T = np.geomspace(*COLOUR_KELVIN, 4096)
    xyz = planck_xyz(T)
    return np.log(xyz[:, 2] / xyz[:, 0]), np.log(T)


_LOCUS_KEY, _LOCUS_LOG_T = _locus()

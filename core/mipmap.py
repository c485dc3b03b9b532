"""Footprint filtering of textures (issue 26): what a pixel sees of a texture is the texture
averaged over the pixel's footprint on it, not one bilinear texel: an equirectangular sky,
and image textures on surfaces.

The footprint J (N, 2, 3) is the seen direction's derivatives along image x and y: from a
map of the pixel centres' own directions (``map_footprint``, ``span_footprint``: screen-space
differences, as a GPU takes them; no rays traced for it), or the ray differentials a render
carries anyway (``RayResults.sky_jacobian``, the magnification pass). Taken into the
texture's texel space at full size, J gives two vectors a = ∂(X, Y)/∂x and
b = ∂(X, Y)/∂y (X = u w, Y = (1 − v) h, sky.direction_to_equirect's u, v), whose 2×2 matrix
has singular values σ₁ ≥ σ₂ (the footprint's long and short extents, texels) along U's
columns. The texture is looked up as GPUs filter anisotropically: n = ⌈σ₁/σ₂⌉ taps
(at most MAX_ANISOTROPY) spread evenly over the long extent, each a trilinear lookup in the
pyramid of box-filtered halvings (MipMap) at the level whose texel is max(σ₁/n, σ₂) wide,
averaged. A footprint of at most one texel (a magnified sky) is the plain bilinear lookup,
exactly: filtering changes nothing where the texture is resolved.

Surfaces (core.geometry.hits' ``filters``): the footprint on a surface is the hit point's
derivatives along image x and y (``surface_footprint``, differences of neighbouring hit
points on the same object); each surface takes it into its own uv, and an image texture
on it is a MipMap of its own wrap (``WRAP_MODES``), looked up the same way (``texels``).

Approximations: a box filter along the long axis (not an elliptical Gaussian); at odd sizes
a halving pads one column (wrapped in longitude) or row (repeated at a pole), so a coarse
level's texels sit up to half a texel off their span; lookups past a pole clamp to it.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

MAX_ANISOTROPY = 8
"""Taps along a footprint's long axis at most (a longer one is taken blurrier across)."""


WRAP_MODES = ("repeat", "extend", "mirror")
"""How texel indices past an image's edge are taken (Blender's Image Texture extensions:
REPEAT tiles, EXTEND clamps to the edge, MIRROR reflects; CLIP is EXTEND then zero outside,
left to the caller)."""
SKY_WRAP = ("repeat", "extend")
"""An equirectangular sky: longitude wraps, latitude stops at the poles."""


def wrap_index(i: np.ndarray, n: int, mode: str) -> np.ndarray:
    """Integer texel indices ``i`` taken into [0, n) by ``mode`` (WRAP_MODES)."""
    if mode == "repeat":
        return np.mod(i, n)
    if mode == "mirror":
        period = np.mod(i, 2 * n)
        return np.where(period < n, period, 2 * n - 1 - period)
    return np.clip(i, 0, n - 1)


HALVE_BAND = 1 << 21
"""Values of a halving computed at once (float64): a big image's pyramid is built band by
band of rows, never as a float64 copy of a whole level."""


def halve(image: np.ndarray, wrap: tuple[str, str] = SKY_WRAP) -> np.ndarray:
    """An image (h, w, c) at half its size per side (rounded up): the mean of each 2×2
    block, an odd width (height) padded by the texel that follows its last by ``wrap`` (x, y):
    the first column (row) where it repeats, else the last. Means are taken in float64 and
    kept in the image's float type, at least float32 (HALVE_BAND values at a time)."""
    h, w = image.shape[:2]
    rows, columns = (h + 1) // 2, (w + 1) // 2
    out = np.empty((rows, columns, *image.shape[2:]), np.result_type(image.dtype, np.float32))
    band = max(1, HALVE_BAND // max(1, out[0].size))
    for start in range(0, rows, band):
        stop = min(rows, start + band)
        out[start:stop] = _halve_rows(image, 2 * start, 2 * stop, wrap)
    return out


def _halve_rows(image: np.ndarray, first: int, end: int, wrap: tuple[str, str]) -> np.ndarray:
    """``halve`` of the image's rows [first, end) (float64; ``end`` past the last row of an
    odd height pads it)."""
    h, w = image.shape[:2]
    part = image[first : min(end, h)]
    if h > 1 and end > h:
        part = np.concatenate([part, image[wrap_index(np.array([h]), h, wrap[1])]], axis=0)
    if w > 1 and w % 2:
        part = np.concatenate([part, part[:, wrap_index(np.array([w]), w, wrap[0])]], axis=1)
    ph, pw = part.shape[:2]
    rows, columns = max(ph // 2, 1), max(pw // 2, 1)
    blocks = part.reshape(rows, ph // rows, columns, pw // columns, -1)
    return blocks.mean(axis=(1, 3), dtype=np.float64)


def flip_rows(image: np.ndarray, band: int = 256) -> np.ndarray:
    """``image`` (h, ...) with its rows reversed, in place (``band`` rows of each end
    swapped at a time: no second copy of a big image); returns it."""
    h = image.shape[0]
    for top in range(0, h // 2, band):
        stop = min(top + band, h // 2)
        upper = image[top:stop].copy()
        image[top:stop] = image[h - stop : h - top][::-1]
        image[h - stop : h - top] = upper[::-1]
    return image


def bilinear(
    image: np.ndarray, x: np.ndarray, y: np.ndarray, wrap: tuple[str, str] = SKY_WRAP
) -> np.ndarray:
    """Bilinear samples (N, c) of ``image`` (h, w, c) at texel coordinates x, y (texel
    centres at integers, row 0 at the top), indices past the edges taken by ``wrap`` (x, y)."""
    h, w = image.shape[:2]
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = (x - x0)[..., None], (y - y0)[..., None]
    xi, yi = x0.astype(np.int64), y0.astype(np.int64)
    xa, xb = wrap_index(xi, w, wrap[0]), wrap_index(xi + 1, w, wrap[0])
    ya, yb = wrap_index(yi, h, wrap[1]), wrap_index(yi + 1, h, wrap[1])
    top = image[ya, xa] * (1 - fx) + image[ya, xb] * fx
    bottom = image[yb, xa] * (1 - fx) + image[yb, xb] * fx
    return top * (1 - fy) + bottom * fy


def texel_footprint(directions: np.ndarray, jacobian: np.ndarray, size: tuple[int, int]):
    """The footprint matrices (N, 2, 2) in full-size texels: column k = ∂(X, Y)/∂(image
    coordinate k), for unit ``directions`` (N, 3) and their derivatives ``jacobian``
    (N, 2, 3) on an equirectangular texture of ``size`` (h, w)."""
    h, w = size
    x, y, z = (directions[:, i, None] for i in range(3))
    jx, jy, jz = (jacobian[:, :, i] for i in range(3))
    rho2 = x * x + y * y
    with np.errstate(divide="ignore", invalid="ignore"):
        d_lon = (x * jy - y * jx) / rho2
        d_lat = (jz * rho2 - z * (x * jx + y * jy)) / (np.sqrt(rho2) * (rho2 + z * z))
    # X = u w with u = 1/2 - lon / 2π; Y = (1 - v) h with v = 1/2 + lat / π
    return np.stack([-w / (2 * math.pi) * d_lon, -h / math.pi * d_lat], axis=1)


def extents(m: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A footprint's long and short extents: the singular values σ₁ ≥ σ₂ (N,) of 2×2
    matrices m (N, 2, 2), and the unit vector (N, 2) along which m stretches most (the first
    left singular vector), in closed form: from the eigenvalues of m mᵀ = [[p, r], [r, q]]."""
    p = m[:, 0, 0] ** 2 + m[:, 0, 1] ** 2
    q = m[:, 1, 0] ** 2 + m[:, 1, 1] ** 2
    r = m[:, 0, 0] * m[:, 1, 0] + m[:, 0, 1] * m[:, 1, 1]
    mean, spread = 0.5 * (p + q), np.hypot(0.5 * (p - q), r)
    angle = 0.5 * np.arctan2(2.0 * r, p - q)
    long = np.sqrt(mean + spread)
    short = np.sqrt(np.maximum(mean - spread, 0.0))
    return long, short, np.stack([np.cos(angle), np.sin(angle)], axis=1)


def point_or_filtered(
    texels: np.ndarray,
    point: Callable[[np.ndarray], np.ndarray],
    filtered: Callable[[np.ndarray], np.ndarray],
    channels: int,
) -> np.ndarray:
    """(N, channels): ``point(rows)`` at the rows whose footprint ``texels`` (N, 2, 2) spans
    at most a texel (or is NaN: none), ``filtered(rows)`` at the rest: a resolved texture
    is its plain lookup itself, bit for bit (the pyramid's level 0 computes its texel
    coordinates another way: 6e-15 apart on one CPU)."""
    wide = extents(texels)[0] > 1.0
    out = np.empty((texels.shape[0], channels))
    out[~wide] = point(np.flatnonzero(~wide))
    out[wide] = filtered(np.flatnonzero(wide))
    return out


DEPTH_JUMP = 4.0
"""Where both one-sided differences are on the same surface but one is more than this many
times the other, the surface folds or hides part of itself between them (a depth jump):
the smaller is the footprint (``screen_differences`` with ``jumps``)."""


def screen_differences(
    values: np.ndarray, label: np.ndarray, jumps: bool = False, rows: np.ndarray | None = None
) -> np.ndarray:
    """Derivatives (H, W, 2, c) along image x and y of a map of ``values`` (H, W, c) by
    differences between neighbours of the same ``label`` (H, W; below 0: none): central
    where both neighbours share it, one-sided towards the one that does, NaN where neither
    (screen-space derivatives, as a GPU takes them); with ``jumps``, the smaller one-sided
    difference where the two differ more than DEPTH_JUMP-fold. With ``rows`` (flat pixel
    indices (K,)), only theirs (K, 2, c): the same numbers."""
    if rows is not None:
        return _differences_at(values, label, jumps, rows)
    out = []
    for axis in (1, 0):
        step = np.diff(values, axis=axis)
        ends = np.delete(label, 0, axis=axis)
        both = (ends == np.delete(label, -1, axis=axis)) & (ends >= 0)
        step = np.where(both[..., None], step, np.nan)
        pad = [(0, 0)] * values.ndim
        pad[axis] = (1, 0)
        before = np.pad(step, pad, constant_values=np.nan)
        pad[axis] = (0, 1)
        after = np.pad(step, pad, constant_values=np.nan)
        out.append(_derivative(before, after, jumps))
    return np.stack(out, axis=-2)


def _differences_at(values: np.ndarray, label: np.ndarray, jumps: bool, rows) -> np.ndarray:
    """screen_differences at the flat pixels ``rows`` alone: (K, 2, c)."""
    height, width = label.shape
    flat, labels = values.reshape(height * width, -1), label.ravel()
    j, i = np.divmod(rows, width)
    out = []
    for at, size, stride in ((i, width, 1), (j, height, width)):
        sides = []
        for offset, inside in ((-stride, at > 0), (stride, at < size - 1)):
            other = np.where(inside, rows + offset, rows)
            same = inside & (labels[other] == labels[rows]) & (labels[rows] >= 0)
            step = flat[other] - flat[rows] if offset > 0 else flat[rows] - flat[other]
            sides.append(np.where(same[:, None], step, np.nan))
        out.append(_derivative(sides[0], sides[1], jumps))
    return np.stack(out, axis=-2)


def _derivative(before: np.ndarray, after: np.ndarray, jumps: bool) -> np.ndarray:
    """A derivative (..., c) from the one-sided differences before and after a pixel
    (NaN: none): their mean, else the one there is (``screen_differences``)."""
    central = 0.5 * (before + after)
    one_sided = np.where(np.isnan(before), after, before)
    if jumps:
        nb, na = np.linalg.norm(before, axis=-1), np.linalg.norm(after, axis=-1)
        jump = (np.maximum(nb, na) > DEPTH_JUMP * np.minimum(nb, na))[..., None]
        central = np.where(jump, np.where((nb <= na)[..., None], before, after), central)
    return np.where(np.isnan(central), one_sided, central)


def map_footprint(
    directions: np.ndarray, sky: np.ndarray, rows: np.ndarray | None = None
) -> np.ndarray:
    """Footprints (H, W, 2, 3) from a map of pixel centres' unit ``directions`` (H, W, 3)
    where they see the sky (``sky`` (H, W)): screen_differences among the sky's pixels (no
    ray differentials needed); with ``rows``, only theirs (K, 2, 3)."""
    return screen_differences(directions, np.where(sky, 0, -1), rows=rows)


def span_differences(
    values: np.ndarray, label: np.ndarray, start: int, width: int, jumps: bool = False
) -> np.ndarray:
    """screen_differences (n, 2, c) of the pixels [start, start + n) of an image ``width``
    wide (row by row), from their own ``values`` (n, c) and ``label`` (n,), on the rows the
    span covers; a neighbour outside the span is taken as unlabelled."""
    n, c = values.shape
    first = start % width
    rows = -(-(first + n) // width)
    grid = np.full((rows * width, c), np.nan)
    grid[first : first + n] = values
    labels = np.full(rows * width, -1, dtype=np.int64)
    labels[first : first + n] = label
    shape = (rows, width)
    out = screen_differences(grid.reshape(shape + (c,)), labels.reshape(shape), jumps)
    return out.reshape(-1, 2, c)[first : first + n]


def span_footprint(directions: np.ndarray, sky: np.ndarray, start: int, width: int) -> np.ndarray:
    """Footprints (n, 2, 3) of the pixels [start, start + n) of an image ``width`` wide (row
    by row) from their own ``directions`` (n, 3) where they see the sky (``sky`` (n,)):
    map_footprint on the rows the span covers, a neighbour outside the span taken as not
    seeing the sky."""
    return span_differences(directions, np.where(sky, 0, -1), start, width)


def surface_footprint(
    position: np.ndarray, surface: np.ndarray, start: int, width: int
) -> np.ndarray:
    """Footprints (n, 2, 3) on surfaces (∂(hit point)/∂(image x, y), world units) of the
    pixels [start, start + n) of an image ``width`` wide from their hit points ``position``
    (n, 3) and the ``surface`` (n,) each is on (an object id; below 0: none):
    span_differences among pixels on the same surface, a depth jump taken as one."""
    return span_differences(position, surface, start, width, jumps=True)


class MipMap:
    """An image (h, w, c), row 0 at the top, and its halvings down to one texel
    (``levels``); ``lookup`` filters it over footprints (the module). ``wrap`` (x, y)
    (WRAP_MODES): an equirectangular sky's by default; a surface's texture its own."""

    def __init__(self, image: np.ndarray, wrap: tuple[str, str] = SKY_WRAP) -> None:
        if wrap[0] not in WRAP_MODES or wrap[1] not in WRAP_MODES:
            raise ValueError(f"wrap must be two of {WRAP_MODES}, got {wrap}")
        self.wrap = wrap
        self.levels = [np.asarray(image)]
        while self.levels[-1].shape[0] > 1 or self.levels[-1].shape[1] > 1:
            self.levels.append(halve(self.levels[-1], wrap))

    @property
    def size(self) -> tuple[int, int]:
        """(h, w) of the full-size image."""
        h, w = self.levels[0].shape[:2]
        return h, w

    def texels(self, uv_footprint: np.ndarray) -> np.ndarray:
        """Footprints (N, 2, 2) in full-size texels from footprints in uv (column k =
        ∂(u, v)/∂(image coordinate k); v up, as ``lookup`` takes it)."""
        h, w = self.size
        return uv_footprint * np.array([w, -h], dtype=np.float64)[None, :, None]

    def lookup(self, uv: np.ndarray, footprint: np.ndarray) -> np.ndarray:
        """The image (N, c) at ``uv`` (N, 2; u across, v up from the bottom row) averaged
        over ``footprint`` (N, 2, 2, in texels: texel_footprint, ``texels``); a footprint
        that is not finite is taken as a point."""
        footprint = np.where(np.isfinite(footprint), footprint, 0.0)
        long, short, axis = extents(footprint)
        with np.errstate(divide="ignore", invalid="ignore"):
            taps = np.where(long > 1.0, np.ceil(long / short), 1.0)
        taps = np.clip(np.nan_to_num(taps, nan=1.0), 1, MAX_ANISOTROPY).astype(np.int64)
        texel = np.maximum(np.maximum(long / taps, short), 1.0)
        level = np.minimum(np.log2(texel), len(self.levels) - 1.0)
        owner, rank = np.nonzero(np.arange(MAX_ANISOTROPY)[None, :] < taps[:, None])
        along = ((rank + 0.5) / taps[owner] - 0.5) * long[owner]
        h, w = self.size
        x = uv[owner, 0] * w + along * axis[owner, 0]
        y = (1.0 - uv[owner, 1]) * h + along * axis[owner, 1]
        samples = self._trilinear(x / w, y / h, level[owner])
        out = np.zeros((uv.shape[0], samples.shape[1]))
        np.add.at(out, owner, samples / taps[owner, None])
        return out

    def _trilinear(self, across: np.ndarray, down: np.ndarray, level: np.ndarray) -> np.ndarray:
        """Samples at fractions (across, down) of the image's width and height, blended
        between the two levels around ``level``."""
        out = np.zeros((across.size, self.levels[0].shape[2]))
        lower = np.floor(level).astype(np.int64)
        blend = level - lower
        for k in np.unique(lower):
            at = np.flatnonzero(lower == k)
            out[at] = self._at_level(int(k), across[at], down[at])
            mixed = at[blend[at] > 0.0]
            if mixed.size and k + 1 < len(self.levels):
                upper = self._at_level(int(k) + 1, across[mixed], down[mixed])
                out[mixed] += blend[mixed, None] * (upper - out[mixed])
        return out

    def _at_level(self, k: int, across: np.ndarray, down: np.ndarray) -> np.ndarray:
        image = self.levels[k]
        h, w = image.shape[:2]
        return bilinear(image, across * w - 0.5, down * h - 0.5, self.wrap)

"""Each point star's lensed images in a rendered frame, drawn with the pixel filter.

The frame's pixel centres see sky directions d(x, y) (the direction pass, where they
escaped). Between each 2x2 of neighbouring centres (a *cell*) the map from the image to the
sky is taken bilinear in the gnomonic plane of the star looked for; a star's images are the
points of the image where that map reaches it (at most two per cell: a cell folded over a
caustic has two). Cells share their edges, on which the map depends on the edge's two
centres only, so an image moving across an edge is found in exactly one cell (half-open
cells): stars neither vanish nor double as the camera moves. A ray is then traced through
each image point for its magnification μ (image_magnification: the camera's solid angle
over the sky's, from its ray differentials); an image whose ray does not reach the sky there
is not drawn. A star of flux F adds F μ g⁴ (g: the moving camera's Doppler factor,
core.motion; 1 when static or with colours unshifted), coloured as a black body at g T,
times the transmittance of what lies in front, spread over the pixels around the image with
the render's pixel filter (weights summing to 1, each divided by its pixel's solid angle:
the image's pixels, times their solid angles, sum to its flux).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from functools import partial
from typing import Any

import numpy as np

from .sampling import sample_offsets
from .stars import StarField, star_rgb
from .tracing.differentials import magnification, solid_angle_rate
from .tracing.scene import ENDING

CELL_LIMIT = 0.1
"""Cells whose corners' directions lie more than this (radians) from their mean are skipped:
neighbouring pixel centres that far apart on the sky (beside the shadow, where the higher
images pile up) make the bilinear map meaningless, and an image there is demagnified below
(pixel angle / CELL_LIMIT)² ~ 1e-5 at 1080p."""
BAND_ROWS = 32
"""Rows of cells handled at once (memory stays bounded for any resolution)."""
TRACE_CHUNK = 16_384
"""Images whose magnification is traced at once."""
FD_PIXELS = 0.25
"""Where the tracer carries no ray differentials: half the spacing (pixels) of the central
differences of traced rays that give an image's magnification (second order: ~1e-3 of μ
where it varies over tens of pixels)."""
STARS_PER_BIN = 2.0
"""The star index's cells (equal-area in z and longitude) hold about this many stars."""


class SkyIndex:
    """Stars binned on an equal-area grid (z = cos θ and longitude) for cap queries."""

    def __init__(self, directions: np.ndarray) -> None:
        """Bin the unit vectors ``directions`` (S, 3)."""
        self.directions = directions
        count = directions.shape[0]
        self.nz = max(1, int(math.ceil(math.sqrt(count / (2.0 * STARS_PER_BIN)))))
        self.nphi = 2 * self.nz
        bins = self._bin(directions)
        self.order = np.argsort(bins, kind="stable")
        self.start = np.searchsorted(bins[self.order], np.arange(self.nz * self.nphi + 1))

    def _bin(self, d: np.ndarray) -> np.ndarray:
        iz = np.clip(((d[:, 2] + 1.0) * 0.5 * self.nz).astype(np.int64), 0, self.nz - 1)
        phi = np.arctan2(d[:, 1], d[:, 0])
        ip = np.clip(
            ((phi + math.pi) / (2 * math.pi) * self.nphi).astype(np.int64), 0, self.nphi - 1
        )
        return iz * self.nphi + ip

    def near(self, centre: np.ndarray, radius: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(cap k, star s) pairs of stars within ``radius`` (C,) radians of the unit vectors
        ``centre`` (C, 3), each cap's stars once."""
        z = np.clip(centre[:, 2], -1.0, 1.0)
        z0 = np.clip(((z - radius + 1.0) * 0.5 * self.nz).astype(np.int64), 0, self.nz - 1)
        z1 = np.clip(((z + radius + 1.0) * 0.5 * self.nz).astype(np.int64), 0, self.nz - 1)
        polar = np.arccos(z)
        pole = (polar <= radius) | (polar >= math.pi - radius)
        with np.errstate(all="ignore"):
            half = np.arcsin(np.minimum(1.0, np.sin(radius) / np.sin(polar))) * 1.001 + 1e-12
        phi = np.arctan2(centre[:, 1], centre[:, 0])
        width = 2 * math.pi / self.nphi
        p0 = np.floor((phi - half + math.pi) / width).astype(np.int64)
        p1 = np.floor((phi + half + math.pi) / width).astype(np.int64)
        nphi = np.where(pole, self.nphi, np.minimum(self.nphi, p1 - p0 + 1))
        p0 = np.where(pole, 0, p0)
        cap, rank = ragged((z1 - z0 + 1) * nphi)
        iz = z0[cap] + rank // nphi[cap]
        ip = np.mod(p0[cap] + rank % nphi[cap], self.nphi)
        bins = iz * self.nphi + ip
        first, counts = self.start[bins], self.start[bins + 1] - self.start[bins]
        pair, offset = ragged(counts)
        return cap[pair], self.order[first[pair] + offset]


def ragged(counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(owner, rank) of sum(counts) items: item i belongs to owner[i], its rank-th."""
    counts = np.asarray(counts, dtype=np.int64)
    owner = np.repeat(np.arange(counts.size), counts)
    first = np.cumsum(counts) - counts
    return owner, np.arange(owner.size) - first[owner]


def draw_stars(
    rgba: np.ndarray,
    seen: np.ndarray,
    sky: np.ndarray,
    transmittance: np.ndarray,
    camera: Any,
    stars: StarField,
    tracer: Any,
    motion: Any = None,
    pixel_filter: str = "blackman_harris",
    filter_size: float = 1.5,
) -> int:
    """Add the lensed images of ``stars`` to ``rgba`` (h, w, 4), in place (module docstring):
    ``seen`` (h, w, 3) the pixel centres' directions, ``sky`` (h, w) where they escaped,
    ``transmittance`` (h, w) of what lies in front; ``tracer`` the render's (with the
    camera's motion), which traces each image's magnification. -> the number drawn."""
    h, w = sky.shape
    if h < 2 or w < 2 or stars.magnitudes.size == 0:
        return 0
    index = SkyIndex(stars.directions)
    splat = partial(_splat, rgba, stars=stars, camera=camera, motion=motion,
                    pixel_filter=pixel_filter, filter_size=filter_size)  # fmt: skip
    drawn, pending = 0, []
    for r0 in range(0, h + 1, BAND_ROWS):
        r1 = min(r0 + BAND_ROWS, h + 1)  # cells r0..r1-1 between padded rows r0..r1
        d, clear, light = _padded_rows(seen, sky, transmittance, r0, r1 + 1)
        found = _images_in_band(d, clear, light, index, r0)
        if found is not None:
            pending.append(found)
        if sum(p[0].shape[0] for p in pending) >= TRACE_CHUNK or r1 > h:
            drawn += _draw_found(pending, tracer, camera, splat)
            pending = []
    return drawn


def _draw_found(found: list, tracer: Any, camera: Any, splat: Callable) -> int:
    """Splat the images ``found`` (bands' (image points, dimming, star numbers), in the
    order of their bands) whose own rays see the sky, their magnifications traced in one
    batch (a batch's rounds cost the same whatever its rays: a band at a time paid them per
    band) -> the number drawn."""
    if not found:
        return 0
    mu = image_magnification(tracer, camera, np.concatenate([xy for xy, _, _ in found]))
    drawn, start = 0, 0
    for xy, dimming, star in found:
        band_mu, start = mu[start : start + xy.shape[0]], start + xy.shape[0]
        there = np.isfinite(band_mu)  # the image point's own ray sees the sky
        splat(xy[there], band_mu[there], dimming[there], star=star[there])
        drawn += int(np.count_nonzero(there))
    return drawn


def _padded_rows(seen, sky, transmittance, r0: int, r1: int) -> tuple[np.ndarray, ...]:
    """Rows [r0, r1) of the frame's centres padded by one extrapolated centre on each side
    (padded row r is pixel row r - 1; an extrapolated centre continues its two neighbours
    linearly, and is sky where both are): directions (R, w + 2, 3), sky, transmittance."""
    h, w = sky.shape

    def extend(values, along_rows, rows):
        n = values.shape[0] if along_rows else values.shape[1]
        p = rows - 1
        a = np.clip(p, 0, n - 1)
        b = np.where(p < 0, 1, np.where(p >= n, n - 2, a))
        t = (a != p).astype(np.float64)
        take = (lambda k: values[k]) if along_rows else (lambda k: values[:, k])
        va, vb = take(a), take(b)  # only the rows (columns) needed
        if va.dtype == bool:
            return va & vb
        va, vb = va.astype(np.float64), vb.astype(np.float64)
        shape = (-1,) + (1,) * (va.ndim - 1) if along_rows else (1, -1) + (1,) * (va.ndim - 2)
        return (1 + t.reshape(shape)) * va - t.reshape(shape) * vb

    rows = np.arange(r0, r1)
    columns = np.arange(w + 2)
    d = extend(extend(seen, True, rows), False, columns)
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    clear = extend(extend(sky, True, rows), False, columns)
    light = extend(extend(transmittance, True, rows), False, columns)
    return d, clear & np.all(np.isfinite(d), axis=-1), light


def _images_in_band(d: np.ndarray, clear: np.ndarray, light: np.ndarray, index, r0: int):
    """The images found in the cells between the rows of padded centres (padded row r0
    first) that see directions ``d`` (R, W, 3), clear sky where ``clear``, through
    transmittance ``light``: (image points (M, 2), transmittance there (M,), star numbers
    (M,)), or None."""
    corners = (d[:-1, :-1], d[:-1, 1:], d[1:, :-1], d[1:, 1:])  # (x, y): 00, 10, 01, 11
    ok = clear[:-1, :-1] & clear[:-1, 1:] & clear[1:, :-1] & clear[1:, 1:]
    centre = sum(corners)
    centre = centre / np.linalg.norm(centre, axis=-1, keepdims=True)
    closest = np.min([np.sum(centre * c, axis=-1) for c in corners], axis=0)
    radius = np.arccos(np.clip(closest, -1.0, 1.0))
    cj, ci = np.nonzero(ok & (radius < CELL_LIMIT))
    if cj.size == 0:
        return None
    cap, star = index.near(centre[cj, ci], radius[cj, ci])
    s = index.directions[star]
    reach = radius[cj[cap], ci[cap]] * 1.001 + 1e-12
    near = np.sum(s * centre[cj[cap], ci[cap]], axis=1) >= np.cos(reach)
    cap, star, s = cap[near], star[near], s[near]
    j, i = cj[cap], ci[cap]
    u, v, which = inverse_bilinear([c[j, i] for c in corners], s)
    j, i, star = j[which], i[which], star[which]
    xy = np.stack([i - 0.5 + u, r0 + j - 0.5 + v], axis=1)
    lights = (light[:-1, :-1], light[:-1, 1:], light[1:, :-1], light[1:, 1:])
    weights = [(1 - u) * (1 - v), u * (1 - v), (1 - u) * v, u * v]
    dimming = sum(wk * lk[j, i] for wk, lk in zip(weights, lights, strict=True))
    return xy, dimming, star


def inverse_bilinear(corners: list, s: np.ndarray) -> tuple[np.ndarray, ...]:
    """Where in their cells the bilinear maps through the gnomonic projections (about the
    unit vectors ``s`` (M, 3)) of ``corners`` [(M, 3) at (0, 0), (1, 0), (0, 1), (1, 1)] reach
    s: (u, v, the pair each solution belongs to); u, v in [0, 1), up to two per pair."""
    ref = np.where(np.abs(s[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    e1 = np.cross(s, ref)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(s, e1)
    p = [
        np.stack([np.sum(c * e1, 1), np.sum(c * e2, 1)], 1) / np.sum(c * s, 1, keepdims=True)
        for c in corners
    ]
    a, e, f = p[0], p[1] - p[0], p[2] - p[0]
    g = p[0] - p[1] - p[2] + p[3]
    hh = -a

    def cross(x, y):
        return x[:, 0] * y[:, 1] - x[:, 1] * y[:, 0]

    k2, k1, k0 = cross(g, f), cross(e, f) + cross(hh, g), cross(hh, e)
    disc = k1 * k1 - 4.0 * k0 * k2
    real = disc >= 0
    root = np.sqrt(np.where(real, disc, 0.0))
    q = -0.5 * (k1 + np.where(k1 >= 0, root, -root))
    with np.errstate(all="ignore"):
        candidates = [q / k2, k0 / q]
    us, vs, owners = [], [], []
    scale = np.maximum(np.hypot(*e.T), np.hypot(*f.T))
    for k, v in enumerate(candidates):
        if k == 1:  # a double root (q = k0 / q = q / k2) is one image
            v = np.where(np.isclose(candidates[0], candidates[1], rtol=0, atol=1e-12), np.nan, v)
        with np.errstate(all="ignore"):
            along = e + g * v[:, None]
            u = np.sum((hh - f * v[:, None]) * along, 1) / np.sum(along * along, 1)
            miss = a + e * u[:, None] + f * v[:, None] + g * (u * v)[:, None]
            inside = real & (u >= 0) & (u < 1) & (v >= 0) & (v < 1)
            inside &= np.hypot(*miss.T) <= 1e-6 * scale
        hit = np.flatnonzero(inside)
        us.append(u[hit])
        vs.append(v[hit])
        owners.append(hit)
    return np.concatenate(us), np.concatenate(vs), np.concatenate(owners)


def image_magnification(tracer: Any, camera: Any, xy: np.ndarray) -> np.ndarray:
    """|μ| (M,) of the images at points xy (M, 2): a ray traced through each point carrying
    its ray differentials (Tracer.trace's tangents), or where the tracer cannot, central
    differences of rays traced FD_PIXELS either side; NaN where a ray does not escape. The
    positions come from the (possibly interpolated) direction map, whose differences are not
    accurate enough for μ (an interpolated block's bilinear map is within the tolerance in
    direction, not in its derivative: 11 % off at tolerance_px 1, measured)."""
    mu = np.full(xy.shape[0], np.nan)
    for a in range(0, xy.shape[0], TRACE_CHUNK):
        b = min(a + TRACE_CHUNK, xy.shape[0])
        mu[a:b] = _traced_magnification(tracer, camera, xy[a:b])
    return mu


def _traced_magnification(tracer, camera, xy) -> np.ndarray:
    escaped = ENDING["escaped"]
    if tracer.supports_tangents:
        origins, directions = camera.rays_at(xy)
        rays = tracer.trace(origins, directions, tangents=camera.direction_tangents(xy))
        return np.where(rays.ending == escaped, rays.magnification, np.nan)
    m = xy.shape[0]
    shifts = FD_PIXELS * np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])
    points = (xy[None, :, :] + shifts[:, None, :]).reshape(-1, 2)
    origins, directions = camera.rays_at(points)
    rays = tracer.trace(origins, directions)
    ends = rays.direction.reshape(4, m, 3)
    ok = np.all((rays.ending == escaped).reshape(4, m), axis=0)
    sky_jacobian = np.stack([ends[0] - ends[1], ends[2] - ends[3]], axis=1) / (2 * FD_PIXELS)
    return np.where(ok, magnification(camera.direction_tangents(xy), sky_jacobian), np.nan)


def _splat(rgba, xy, mu, dimming, stars, star, camera, motion, pixel_filter, filter_size):
    """Add each image (points xy (M, 2), magnifications mu (M,)) of star numbers ``star`` to
    ``rgba`` (h, w, 4)."""
    if star.size == 0:
        return
    h, w = rgba.shape[:2]
    _, look = camera.rays_at(xy)
    g = np.ones(star.size) if motion is None else motion.colour_shift(look)
    flux = stars.flux[star] * mu * g**4 * dimming
    colour = star_rgb(g * stars.temperatures[star]) * flux[:, None]  # (M, 3) luminance × sr
    half = 0 if pixel_filter == "box" else int(math.ceil(filter_size / 2)) + 1
    k = np.arange(-half, half + 1, dtype=np.float64)
    offsets = np.stack(np.meshgrid(k, k), axis=-1).reshape(-1, 2)
    px = np.floor(xy)[:, None, :] + offsets[None, :, :]  # (M, K, 2) pixel (column, row)
    if pixel_filter == "box":
        weight = np.ones(px.shape[:2])
    else:
        unit = (px + 0.5 - xy[:, None, :]) / filter_size + 0.5
        _, weight = sample_offsets(unit, pixel_filter, filter_size)
        weight = np.where(np.all((unit >= 0) & (unit <= 1), axis=-1), weight, 0.0)
    weight /= np.sum(weight, axis=1, keepdims=True)
    col, row = px[..., 0].astype(np.int64), px[..., 1].astype(np.int64)
    inside = (col >= 0) & (col < w) & (row >= 0) & (row < h) & (weight > 0)
    m, kk = np.nonzero(inside)
    centres = np.stack([col[m, kk] + 0.5, row[m, kk] + 0.5], axis=1)
    pixel_area = solid_angle_rate(camera.direction_tangents(centres))
    value = colour[m] * (weight[m, kk] / pixel_area)[:, None]
    flat = rgba.reshape(-1, 4)
    target = row[m, kk] * w + col[m, kk]
    if target.size == 0:
        return
    low = int(target.min())
    span = int(target.max()) - low + 1
    for channel in range(3):
        added = np.bincount(target - low, value[:, channel], minlength=span)
        flat[low : low + span, channel] += added.astype(flat.dtype)

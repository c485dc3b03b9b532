"""The opaque accretion disk: interpolating its radius, redshift and azimuth.

Offers ``opaque_disk`` (whether the scene's disk may be interpolated), ``interpolate_disk``
(points inside blocks on the disk, shaded at the interpolated radius and g),
``disk_azimuth`` and ``on_disk_at`` (between world points and the disk's (r, azimuth)),
and ``wrapped`` (angles into [-pi, pi)). Needs a TileContext (its tracer's disk, camera)
and the lattice's Nodes.
"""

from __future__ import annotations

import numpy as np

from .context import TileContext
from .lattice import Nodes


def opaque_disk(ctx: TileContext) -> bool:
    """Whether the scene's disk can be interpolated: opaque (a translucent one shows
    what lies behind it, ray by ray)."""
    light = ctx.tracer.disk
    return light is not None and light.disk.opacity >= 1.0


def interpolate_disk(
    ctx: TileContext,
    nodes: Nodes,
    corners: list[tuple[np.ndarray, np.ndarray]],
    weights: list[np.ndarray],
    y: np.ndarray,
    x: np.ndarray,
) -> tuple[np.ndarray, ...]:
    """Points (y, x) inside blocks on the opaque accretion disk (``corners``: the blocks'
    corner nodes, ``weights``: the points' bilinear weights): -> (RGB (M, 3), on (M,),
    g, hit point, seen direction); the light at the interpolated radius and g. A point
    whose radius falls off the disk (an edge between the nodes) is not ``on``: traced."""
    light = ctx.tracer.disk
    assert light is not None  # only blocks on the disk come here
    pairs = list(zip(weights, corners, strict=True))
    radius = sum(wk * nodes.radius[j, i] for wk, (j, i) in pairs)
    g = sum(wk * nodes.redshift[j, i] for wk, (j, i) in pairs)
    first = disk_azimuth(ctx, nodes.position[corners[0]])
    azimuth = first + sum(
        wk * wrapped(disk_azimuth(ctx, nodes.position[j, i]) - first) for wk, (j, i) in pairs
    )
    position = on_disk_at(ctx, radius, azimuth)
    on = (radius >= light.disk.r_in) & (radius <= light.disk.r_out)
    rgb = light.disk.colour(np.where(on, g, 0.0), radius)
    origins, _ = ctx.camera.rays_at(ctx.image_xy(y, x))
    seen = position - origins
    seen /= np.linalg.norm(seen, axis=1, keepdims=True)
    return rgb, on, g, position, seen


def disk_azimuth(ctx: TileContext, position: np.ndarray) -> np.ndarray:
    """(M,) the azimuth on the disk's plane (its local frame) of world points (M, 3)."""
    light = ctx.tracer.disk
    assert light is not None
    local = light.to_local(position)
    return np.arctan2(local[:, 1], local[:, 0])


def on_disk_at(ctx: TileContext, radius: np.ndarray, azimuth: np.ndarray) -> np.ndarray:
    """World points (M, 3) on the disk's plane at BL ``radius`` (Cartesian √(r² + a²))
    and ``azimuth``: the hit point pass holds the interpolated place the pixel is shaded
    at (before, the blended hit points' direction stood for the azimuth: a lensed
    block's points moved 2-7 px, on the Kerr disk frame at 1 px, under an estimate of
    less than one)."""
    light = ctx.tracer.disk
    assert light is not None
    across = np.hypot(radius, light.disk.spin)
    local = np.stack([across * np.cos(azimuth), across * np.sin(azimuth),
                      np.zeros_like(across)], axis=1)  # fmt: skip
    return ctx.tracer._to_world(local)


def wrapped(angle: np.ndarray) -> np.ndarray:
    """Angles (radians) brought into [-pi, pi)."""
    return (angle + np.pi) % (2 * np.pi) - np.pi

"""Richardson error: a ray's integration error from a companion run at a larger step.

Offers ``richardson_error`` (a run's error from its companion's), ``richardson`` (the same
from how far apart the two runs' ends are), ``seen_direction`` and ``seen_apart`` (what a
pixel's ray sees, and how far apart two such are, in radians), ``angle_between``,
``shared_steps`` (runs that took the same steps), and the constants ``COMPANION_RATIO``,
``FLIP``, ``HIT_ORDER``, ``SHARED_STEPS``, ``DOUBTED`` and ``DOUBT_BELOW``. Needs
core.tracing's RayResults and endings.
"""

from __future__ import annotations

import math

import numpy as np

from ..tracing import ENDING, RayResults

COMPANION_RATIO = 2.0
"""The error pass traces each camera ray again at COMPANION_RATIO x the step: for a method
of order p the ray's error is |d_h - d_rh| / (r^p - 1) (Richardson); 1 / r of the cost."""
FLIP = math.pi
"""The error (radians) of a pixel whose runs at two steps ended on different things (sky,
shadow, another object): what it shows may be wrong whatever its last runs agree on (its
ray passes within the integration's error of an edge); it keeps this error."""
SHARED_STEPS = 0.75
"""A companion run taking at least this share of the checked run's steps (not about
1 / COMPANION_RATIO of them) took the same steps for part of its way (shared_steps)."""
DOUBTED, DOUBT_BELOW = 2.0, 1e-5
"""... and whose estimate is below DOUBT_BELOW x the retrace budget (runs that shared their
steps agree to rounding: 1e-8 of the budget measured; at 1e-2 more rays go, +34 % steps on
a Kerr disk frame against +13 % here, for Schwarzschild's ring's rays too) has it raised to
DOUBTED x the budget:
the ray is traced again at half the step (RETRACE), where the runs part, and that run's
estimate, against this one, is taken as it is."""


def seen_direction(rays: RayResults, origins: np.ndarray) -> np.ndarray:
    """(N, 3) what a pixel's ray points at: the escape direction of an escaped ray, else
    the unit vector from the ray's origin to where it ended (a hit point)."""
    escaped = rays.ending == ENDING["escaped"]
    to_end = rays.position - origins
    with np.errstate(all="ignore"):
        to_end /= np.linalg.norm(to_end, axis=1, keepdims=True)
    return np.where(escaped[:, None], rays.direction, to_end)


HIT_ORDER = 4
"""Highest order assumed of a hit point's error in the step: a hit is where the method's
own partial step meets the surface (Tracer._surface_crossing), at the method's order, but
one whose crossing did not converge keeps the cubic Hermite path's point (tracing/dense.py,
fourth order). Conservative for a sixth-order method's hits (over-reported <= 63/15)."""


def shared_steps(fine: np.ndarray, coarse: np.ndarray) -> np.ndarray:
    """(N,) whether a run at COMPANION_RATIO x a ray's step took at least SHARED_STEPS x
    the steps of the run it checks (``fine``, ``coarse``: steps taken): near geometry both
    runs halve their steps, and where they halved to the same steps they share their error,
    which Richardson then does not see (measured: a disk hit 1.2e-4 rg off in both runs,
    estimated 1e-11 rad, benchmarks/honesty.py disk_high_spin)."""
    return coarse >= SHARED_STEPS * fine


def richardson_error(
    fine: RayResults, coarse: RayResults, origins: np.ndarray, order: int
) -> np.ndarray:
    """Richardson estimate of the fine run's error (radians, (N,)) from a run at
    COMPANION_RATIO x its step: the escape direction's, or for a hit its hit point's over
    its distance from the camera (``seen_apart``); pi where the endings or the objects hit
    differ, +inf where failed."""
    apart = seen_apart(
        seen_direction(fine, origins), fine.position, seen_direction(coarse, origins),
        coarse.position, fine.ending, origins,
    )  # fmt: skip
    alike = (fine.ending == coarse.ending) & (fine.object_id == coarse.object_id)
    return richardson(apart, fine.ending, alike, order)


def seen_apart(
    seen_a: np.ndarray,
    position_a: np.ndarray,
    seen_b: np.ndarray,
    position_b: np.ndarray,
    ending: np.ndarray,
    origins: np.ndarray,
) -> np.ndarray:
    """(N,) radians between what two rays from ``origins`` see: for a hit (``ending``), the
    distance between the hit points over the first's distance from the camera (the pixel
    footprint there, at any angle of incidence: a grazing surface's hit point moves far
    while its direction barely turns); else the angle between the directions."""
    hit = ending == ENDING["hit"]
    with np.errstate(all="ignore"):
        gap = np.linalg.norm(position_a - position_b, axis=-1)
        moved = gap / np.linalg.norm(position_a - origins, axis=-1)
    return np.where(hit, moved, angle_between(seen_a, seen_b))


def richardson(
    apart: np.ndarray,
    ending_fine: np.ndarray,
    alike: np.ndarray,
    order: int,
    ratio: np.ndarray | float = COMPANION_RATIO,
) -> np.ndarray:
    """richardson_error from how far apart the two runs' ends are (radians, ``seen_apart``)
    and whether they end ``alike``, the coarse run's step ``ratio`` x the fine one's. A
    hit point's error is taken to fall at most at HIT_ORDER, whatever the method's
    order."""
    orders = np.where(ending_fine == ENDING["hit"], min(order, HIT_ORDER), order)
    with np.errstate(all="ignore"):
        err = apart / (ratio**orders - 1.0)
    err = np.where(ending_fine == ENDING["captured"], 0.0, err)
    err = np.where(alike, err, FLIP)  # an ending flip, captured or not
    bad = (ending_fine == ENDING["failed"]) | (ending_fine == ENDING["max_steps"])
    return np.where(bad | ~np.isfinite(err), np.inf, err)


def angle_between(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Angle between vectors (..., 3), accurate for tiny angles (atan2 of |u x v| and u.v)."""
    cross = np.linalg.norm(np.cross(u, v), axis=-1)
    return np.arctan2(cross, np.einsum("...i,...i->...", u, v))

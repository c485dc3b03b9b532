"""Surface hits along a step's path near geometry: chords, first hits, the method's crossing.

Interface (each takes the ``Tracer`` whose rays they are): ``along_paths`` (a step's
surface hits and volume light along the paths near geometry: -> the rays that hit),
``first_hits`` (all of a group's chords cast at once, each ray's first hit refined on the
cubic: ``refine``), ``record_chords`` (the chords recorded in order up to the hit) and
``surface_crossing`` (hits moved to where the method's own path meets the surface:
``StepEnds.crossing``). ``ChordGroup`` and ``FirstHits`` carry them between these.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from ..backend import array_module
from ..geometry import Hits
from . import dense
from .disk_landing import land_on_disk
from .near_geometry import NearPaths
from .scene import DISK_ID
from .segments import RayResults
from .step_ends import StepEnds

if TYPE_CHECKING:
    from .tracer_state import TracerState


@dataclass
class ChordGroup:
    """The rays of a step that follow their cubic paths on n chords (along_paths)."""

    cols: np.ndarray  # (M,) batch rows
    path: dense.CubicPath
    n: int
    limits: tuple  # (a chord's deviation (M,), allowed (M,))
    start: np.ndarray  # (M,) the first chord each ray casts
    going: np.ndarray  # the rays (indices into cols) still to cast


@dataclass
class FirstHits:
    """Each ray's first hit on its chords from its start (first_hits)."""

    ends: np.ndarray  # (n + 1, K, 3) the chords' ends, world
    stop: np.ndarray  # (K,) the chord of the first hit (n - 1 where none)
    found: np.ndarray  # (K,) bool: a hit was found there (the method's path may miss it)
    hits: Hits  # (K,) the hit, refined on the cubic
    guess: np.ndarray  # (K,) the hit's fraction of the step on the cubic


def along_paths(
    tracer: TracerState,
    idx: np.ndarray,
    paths: NearPaths,
    out: RayResults,
    step_ends: StepEnds,
    until: np.ndarray,
) -> np.ndarray:
    """Surface hits and volume emission along this step's path near geometry.

    The path between X_prev and X is followed on chords through its cubic Hermite
    interpolant (core/tracing/dense.py), as many per ray as keep the chords within
    the tolerance at the ray's distance from the camera (one where the path is
    straight enough). All rays' chords are cast at once and each ray's first hit is
    refined and moved onto the method's path together (one partial-step Newton for the
    whole step: each partial step costs a whole step's per-call overhead); the chords
    are then recorded in order up to the hit. A ray whose hit the method's path misses,
    or that goes on through a translucent disk, is cast again from the next chord. An
    opaque disk's hits are placed on it and lit once for the whole step
    (disklight.land_on_disk). -> (M,) bool: the rays that hit a surface (recorded in ``out``);
    ``until`` (M,) takes, in place, the fraction of the step at each one's hit.
    """
    hit_rows = np.zeros_like(idx, dtype=bool)
    c, X0, X1, V0, V1, h = paths.rows, paths.X0, paths.X1, paths.V0, paths.V1, paths.h
    if c.size == 0:
        return hit_rows
    landed: list[tuple[np.ndarray, np.ndarray]] = []  # (batch rows, u) on an opaque disk
    groups = []
    for n in np.unique(paths.pieces):
        g = np.flatnonzero(paths.pieces == n)
        hg = h if np.ndim(h) == 0 else h[g]
        path = dense.CubicPath(X0[:, g], V0[:, g], X1[:, g], V1[:, g], hg)
        limits = (paths.deviation[g] / (n * n), paths.allowed[g])
        groups.append(ChordGroup(c[g], path, int(n), limits, np.zeros_like(g, np.int64),
                                 array_module(g).arange(g.size)))  # fmt: skip
    while groups := [group for group in groups if group.going.size]:
        firsts = [first_hits(tracer, group) for group in groups]
        hits = Hits.concatenate([first.hits for first in firsts])
        cols = np.concatenate([group.cols[group.going] for group in groups])
        guess = np.concatenate([f.guess for f in firsts])
        surface_crossing(tracer, cols, guess, hits, step_ends)
        offset = 0
        for group, first in zip(groups, firsts, strict=True):
            first.hits = hits.take(slice(offset, offset + group.going.size))
            offset += group.going.size
            ended, again = record_chords(tracer, idx, group, first, out, step_ends, landed)
            hit_rows[group.cols[group.going[ended]]] = True
            until[group.cols[group.going[ended]]] = first.guess[ended]
            group.start[group.going[again]] = first.stop[again] + 1
            group.going = group.going[again]
    if landed:
        cols, u = (np.concatenate([x[i] for x in landed]) for i in (0, 1))
        off = land_on_disk(tracer, idx, cols, u, out, step_ends)
        hit_rows[cols[off]] = False
        until[cols[off]] = 1.0
    return hit_rows


def record_chords(
    tracer: TracerState, idx: np.ndarray, group: ChordGroup, first: FirstHits, out: RayResults,
    step_ends: StepEnds, landed: list,
) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Record the chords of ``group``'s going rays in order, from each one's start to
    its first hit (``first``; its last chord where none), with the volumes' light up to
    the hit. Hits on an opaque disk are left in ``landed`` as (batch rows, fraction of
    the step); a translucent disk's are found by the method itself at once
    (StepEnds.plane_crossing) and lit. -> (ended, again) (K,) bool: the rays that hit
    a surface; those to cast again from the chord after their hit (it did not end them).
    """
    rays = group.going
    start, cols = group.start[rays], group.cols[rays]
    ended = np.zeros_like(rays, dtype=bool)
    for j in range(int(start.min()), group.n):
        live = np.flatnonzero((start <= j) & (first.stop >= j))
        if live.size == 0:
            break
        a, b = first.ends[j, live], first.ends[j + 1, live]
        hits = Hits.miss(live.size, live)
        at = np.flatnonzero(first.stop[live] == j)
        hits.assign(at, first.hits, live[at])
        if tracer.disk is None or tracer.disk.opaque:
            got = tracer.geometry.record_hits(idx[cols[live]], a, b, hits, out)
            on = np.flatnonzero(got & (hits.object_id == DISK_ID))
            if on.size:
                landed.append((cols[live[on]], first.guess[live[on]]))
        else:
            on = np.flatnonzero(hits.hit & (hits.object_id == DISK_ID))
            if on.size:
                X, ok = step_ends.plane_crossing(cols[live[on]], first.guess[live[on]])
                hits.position[on[ok]] = tracer._to_world(X[:, ok].T)
            got = tracer.disk.record_hits(
                idx[cols[live]], a, b, hits, step_ends.state(cols[live]), out
            )
        ended[live[got]] = True
    again = first.found & ~ended & (first.stop + 1 < group.n)
    return ended, again


def first_hits(tracer: TracerState, group: ChordGroup) -> FirstHits:
    """Cast the chords of ``group``'s going rays all at once, each ray's from its start;
    each ray's first hit refined on the cubic (refine)."""
    rays = group.going
    n, k, xp = group.n, rays.size, array_module(rays)
    points = group.path.points(xp.arange(n + 1) / n, rays).reshape(3, -1)
    ends = tracer._to_world(points.T).reshape(n + 1, k, 3)
    cast = tracer.geometry.cast(ends[:-1].reshape(-1, 3), ends[1:].reshape(-1, 3))
    got = cast.hit.reshape(n, k) & (xp.arange(n)[:, None] >= group.start[rays])
    found = got.any(axis=0)
    stop = np.where(found, got.argmax(axis=0), n - 1)
    hits = cast.take(stop * k + xp.arange(k))
    guess = stop / n
    on = np.flatnonzero(found)
    guess[on] = dense.on_cubic(group.path, rays[on], stop[on] / n, 1.0 / n, hits.t[on])
    if found.any():
        limits = [x[rays] for x in group.limits]
        guess = refine(tracer, group.path, rays, hits, guess, stop / n, 1.0 / n, limits)
    return FirstHits(ends, stop, found, hits, guess)


def refine(
    tracer: TracerState, path: dense.CubicPath, live: np.ndarray, hits: Hits, guess: np.ndarray,
    t0: Any, width: float, limits: Sequence[np.ndarray],
) -> np.ndarray:  # fmt: skip
    """Where the chord [t0, t0 + width] (t0 a float or per ray) of the rays ``live`` hit,
    find the hit again on REFINE_PIECES finer chords of the cubic, all cast at once
    (REFINE_LEVELS times at most, while they deviate more than allowed); ``hits`` takes
    the refined hits, in place. A ray whose finer chords all miss (a grazing edge) keeps
    its chord's hit.
    -> ``guess`` (the hits' fractions of the step on the cubic) refined."""
    deviation, allowed = limits
    allowed = allowed * dense.HIT_SHARE
    todo = np.flatnonzero(hits.hit & (deviation > allowed))
    xp = array_module(live)
    lo = xp.broadcast_to(xp.asarray(t0, dtype=np.float64), live.shape)[todo]
    guess = guess.copy()
    m = dense.REFINE_PIECES
    for _ in range(dense.REFINE_LEVELS):
        if todo.size == 0:
            break
        width /= m
        ta = (xp.arange(m + 1) * width)[:, None] + lo  # (m + 1, R): sub-chords' ends
        ends = tracer._to_world(path.points(ta, live[todo]).reshape(3, -1).T)
        ends = ends.reshape(m + 1, todo.size, 3)  # sub-chord i of ray k: i -> i + 1
        sub = tracer.geometry.cast(ends[:-1].reshape(-1, 3), ends[1:].reshape(-1, 3))
        ta = ta[:-1].ravel()
        got = sub.hit.reshape(m, todo.size)
        ok = got.any(axis=0)
        first = got.argmax(axis=0)[ok] * todo.size + np.flatnonzero(ok)
        hits.assign(todo[ok], sub, first)
        guess[todo[ok]] = ta[first] + sub.t[first] * width
        deviation = deviation / (m * m)
        keep = deviation[todo[ok]] > allowed[todo[ok]]
        todo, lo = todo[ok][keep], ta[first][keep]
    return guess


def surface_crossing(
    tracer: TracerState, cols: np.ndarray, u: np.ndarray, hits: Hits, step_ends: StepEnds
) -> None:
    """Surface hits (``hits`` of the batch rows ``cols``, not the disk's) moved to where
    the method itself meets the surface, in place (StepEnds.crossing from the cubic's
    fraction ``u``; each straight move cast along the velocity both ways, the nearer
    hit on the same object taken; where it does not converge the cubic's hit stands).
    The cubic follows the path to O(h^4) with a constant far above the symplectic
    methods' (1/384 against ~1e-5) and varying with where in a step the surface falls:
    its hits converged erratically (observed order 1-7 on Schwarzschild and the mirage)
    and step doubling misjudged their error (under 1/3 of it on 40-55 % of them)."""
    on = np.flatnonzero(hits.hit & (hits.object_id != DISK_ID))
    if on.size == 0:
        return
    found = Hits.miss(on.size, on)
    h = step_ends.h if np.ndim(step_ends.h) == 0 else step_ends.h[cols[on]]
    beside = np.zeros_like(on, dtype=bool)  # the method's point passes the object by

    def to_surface(todo, X, V):
        # both ways along V, as far as the step reaches: the nearer hit on the object
        reach = np.abs(h if np.ndim(h) == 0 else h[todo]) * V
        ahead = tracer.geometry.cast(tracer._to_world(X.T), tracer._to_world((X + reach).T))
        back = tracer.geometry.cast(tracer._to_world(X.T), tracer._to_world((X - reach).T))
        same = hits.object_id[on[todo]]
        ahead.hit &= ahead.object_id == same
        back.hit &= back.object_id == same
        take_back = back.hit & (~ahead.hit | (back.t < ahead.t))
        pick = np.where(take_back[:, None], back.position, ahead.position)
        move = tracer._to_local(pick).T - X
        missed = ~(ahead.hit | back.hit)
        move[:, missed] = np.nan
        beside[todo] |= missed & np.isfinite(X).all(axis=0) & np.isfinite(V).all(axis=0)
        found.assign(todo[take_back], back, np.flatnonzero(take_back))
        rest = ahead.hit & ~take_back
        found.assign(todo[rest], ahead, np.flatnonzero(rest))
        return move

    _, ok = step_ends.crossing(cols[on], u[on], to_surface)
    hits.assign(on[ok], found, np.flatnonzero(ok))
    hits.hit[on[beside & ~ok]] = False  # the method's own path misses it: not a hit

"""Batch tracing of curved rays through a scene (no Blender).

A ray starts as a straight line from the camera. Where the model bends light (inside
its *region*: a sphere around a black hole, a medium's box) it follows Hamilton's
equations, integrated in the Poincaré-transformed fictitious time with a fixed step;
outside it moves straight, analytically. Every step's straight segment is tested
against the scene's intersector, only where the segment's bounds meet the geometry's.
Rays end as escaped, captured, hit, failed or max_steps (``ENDING``); ended rays leave
the batch, so the work per step shrinks as the image resolves.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from . import hamiltonians, integrators
from .charts import chart_for
from .intersect import Group, segment_overlaps
from .observer import medium_momenta, spacetime_momenta

ENDING = {"escaped": 0, "captured": 1, "hit": 2, "failed": 3, "max_steps": 4}
"""Ending codes of the ``ending`` pass (int8)."""

_FAR = 1e12  # length of the straight segment cast after a ray leaves the model's region


@dataclass
class Scene:
    """What is rendered: a model placed in the world, objects, volumes and a background."""

    model: object = None
    center: tuple = (0.0, 0.0, 0.0)
    axis: tuple = (0.0, 0.0, 1.0)
    objects: list = field(default_factory=list)
    background: object = "procedural"
    volumes: list = field(default_factory=list)
    region_radius: float | None = None
    """Radius of the model's region (world units); default from the model and tolerance."""
    rotation: object = None
    """Optional 3x3 matrix: columns = the model's local x, y, z axes in the world (its z
    must be ``axis``); default: z = axis with x, y chosen. Needed to turn a medium or a
    user metric about the axis."""

    def __post_init__(self):
        self.center = np.asarray(self.center, dtype=np.float64).reshape(3)
        axis = np.asarray(self.axis, dtype=np.float64).reshape(3)
        norm = np.linalg.norm(axis)
        if not (np.isfinite(norm) and norm > 0):
            raise ValueError(f"scene axis must be a non-zero vector, got {axis.tolist()}")
        self.axis = axis / norm
        if self.rotation is not None:
            R = np.asarray(self.rotation, dtype=np.float64).reshape(3, 3)
            if not np.allclose(R.T @ R, np.eye(3), atol=1e-9) or np.linalg.det(R) < 0:
                raise ValueError("scene rotation must be a proper rotation matrix")
            self.rotation = R
            self.axis = R[:, 2].copy()

    @property
    def curved(self) -> bool:
        """False when nothing bends light: rays are traced straight, no integration."""
        m = self.model
        if m is None:
            return False
        return not (getattr(m, "chart", None) == "cartesian" and getattr(m, "rg", 1.0) == 0.0)

    def frame(self) -> np.ndarray:
        """3x3 matrix whose columns are the model's local x, y, z axes in the world."""
        if self.rotation is not None:
            return self.rotation
        z = self.axis
        helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        x = helper - z * (helper @ z)
        x /= np.linalg.norm(x)
        return np.stack([x, np.cross(z, x), z], axis=1)


@dataclass
class TraceOptions:
    """How rays are integrated."""

    method: str = "yoshida4"
    tolerance: float = 1e-8
    step: float | None = None
    max_steps: int = 20_000
    region_radius: float | None = None


@dataclass
class RayResults:
    """Per-ray outcome of a batch (rays on the first axis, world space)."""

    ending: np.ndarray          # (N,) int8
    direction: np.ndarray       # (N, 3) final direction (escape direction for escaped rays)
    position: np.ndarray        # (N, 3) final position (hit point for hit rays)
    surface: np.ndarray         # (N, 4) surface colour where hit
    radiance: np.ndarray        # (N, 3) volume emission collected in front of the ending
    transmittance: np.ndarray   # (N,) volume transmittance
    steps: np.ndarray           # (N,) int32 integration steps
    energy_error: np.ndarray    # (N,) |H - H0| at the end


class Tracer:
    """Traces batches of world-space rays through one scene with fixed options."""

    def __init__(self, scene: Scene, options: TraceOptions, extent: float = 1.0):
        self.scene = scene
        self.options = options
        self.rotation = scene.frame()
        self.objects = scene.objects if hasattr(scene.objects, "intersect") else \
            Group(list(scene.objects))
        self.volumes = list(scene.volumes)
        model = scene.model
        self.model = model = tracing_model(model)
        self.curved = scene.curved
        if not self.curved:
            return
        self.chart = chart_for(model)
        self.spacetime = self.chart.time_index is not None
        self.mass = 0.5 * float(getattr(model, "rg", 0.0)) if self.spacetime else 0.0
        self.method = integrators.get_method(options.method)
        self.region = _Region.for_model(model, options, extent, scene.region_radius)
        self.captured = getattr(model, "captured_soa", None)
        self.step = options.step if options.step else default_step(
            self.method.order, options.tolerance, self.region.length_scale(model))

    # --- public ----------------------------------------------------------------------
    def trace(self, origins: np.ndarray, directions: np.ndarray, step: float | None = None,
              cancel=None) -> RayResults:
        """Trace rays (N, 3) from world origins along unit world directions."""
        n = origins.shape[0]
        out = _empty_results(n, origins, directions)
        if not self.curved:
            self._straight(np.arange(n), origins, directions, out)
            return out
        X = self._to_local(origins)
        D = directions @ self.rotation  # (N, 3) local components
        start, inside = self.region.entry(X, D)
        outside = np.flatnonzero(~inside)
        if outside.size:
            self._straight_to_region(outside, origins, directions, start, out)
        todo = np.flatnonzero(np.isfinite(start[:, 0]) & (out.ending < 0))
        if todo.size:
            self._integrate(todo, start[todo].T.copy(), D[todo].T.copy(), out,
                            step or self.step, cancel)
        return out

    # --- straight parts --------------------------------------------------------------
    def _straight(self, rows, a, d, out: RayResults, far: float = _FAR):
        """Rays that stay straight from a along d: one cast each, ending hit or escaped."""
        b = a + far * d
        hits = self._cast(a, b)
        rad, trans = self._volumes(a, b, hits)
        _accumulate(out, rows, rad, trans)
        h = hits.hit
        out.ending[rows[h]] = ENDING["hit"]
        out.position[rows[h]] = hits.position[h]
        out.surface[rows[h]] = hits.color[h]
        out.ending[rows[~h]] = ENDING["escaped"]
        out.direction[rows] = d

    def _straight_to_region(self, rows, origins, directions, start, out):
        """Rays starting outside the region: straight to its boundary (or forever)."""
        X_entry = start[rows]
        enters = np.isfinite(X_entry[:, 0])
        a = origins[rows]
        b = np.where(enters[:, None], self._to_world(X_entry), a + _FAR * directions[rows])
        hits = self._cast(a, b)
        rad, trans = self._volumes(a, b, hits)
        _accumulate(out, rows, rad, trans)
        h = hits.hit
        out.ending[rows[h]] = ENDING["hit"]
        out.position[rows[h]] = hits.position[h]
        out.surface[rows[h]] = hits.color[h]
        miss = ~h & ~enters
        if miss.any():
            X0 = self._to_local(a[miss])
            D0 = directions[rows[miss]] @ self.rotation
            out.direction[rows[miss]] = self._far_field(X0, D0) @ self.rotation.T
            out.ending[rows[miss]] = ENDING["escaped"]

    # --- the integration ---------------------------------------------------------------
    def _integrate(self, rows, X, D, out: RayResults, h: float, cancel):
        """Follow rays from local positions X (3, M) along local directions D (3, M)."""
        model, chart, off = self.model, self.chart, self.chart.offset
        S = chart.to_coords(X)
        if self.spacetime:
            Q, P = spacetime_momenta(model, chart, S, D)
        else:
            Q, P = medium_momenta(model, S, D)
        H0 = model.value_soa(Q, P)
        K = integrators.PoincareTransformed(model, H0)
        method = self.method
        state = method.init(K, Q, P)
        idx = rows.copy()
        world_prev = self._to_world(X.T)
        local_prev = X.T.copy()
        max_steps = self.options.max_steps
        for step in range(1, max_steps + 1):
            if cancel is not None and step % 32 == 0 and cancel():
                break
            state, ok = method.step(K, state, h)
            Q, P = method.qp(state)
            S = Q[off:]
            local = chart.to_cartesian(S).T
            world = self._to_world(local)
            ok &= np.isfinite(world).all(axis=1)
            ended = np.zeros(idx.size, dtype=bool)
            # surfaces along this step's straight segment
            hits = self._cast(world_prev, world, ok)
            rad, trans = self._volumes(world_prev, world, hits)
            _accumulate(out, idx, rad, trans)
            hit = hits.hit & ok
            out.ending[idx[hit]] = ENDING["hit"]
            out.position[idx[hit]] = hits.position[hit]
            out.surface[idx[hit]] = hits.color[hit]
            ended |= hit
            out.ending[idx[~ok]] = ENDING["failed"]
            out.position[idx[~ok]] = world_prev[~ok]
            ended |= ~ok
            if self.captured is not None:
                captured = ~ended & self.captured(Q)
                out.ending[idx[captured]] = ENDING["captured"]
                out.position[idx[captured]] = world[captured]
                ended |= captured
            leaving = ~ended & self.region.left(local, local - local_prev)
            if leaving.any():
                self._escape(idx[leaving], S[:, leaving], Q[:, leaving], P[:, leaving],
                             local[leaving], world[leaving], out)
                ended |= leaving
            out.steps[idx] = step
            if ended.any():
                keep = np.flatnonzero(~ended)
                self._finish_energy(out, idx[ended], Q[:, ended], P[:, ended], H0[ended])
                if keep.size == 0:
                    return
                idx, world, local = idx[keep], world[keep], local[keep]
                state = tuple(a[..., keep] for a in state)
                K = K.subset(keep)
                H0 = H0[keep]
            world_prev, local_prev = world, local
        out.ending[idx] = ENDING["max_steps"]
        Q, P = method.qp(state)
        out.position[idx] = world_prev
        self._finish_energy(out, idx, Q, P, H0)

    def _finish_energy(self, out, rows, Q, P, H0):
        with np.errstate(all="ignore"):
            out.energy_error[rows] = np.abs(self.model.value_soa(Q, P) - H0)

    def _escape(self, rows, S, Q, P, local, world, out: RayResults):
        """Rays leaving the region: direction from dq/ds, far-field correction, straight on."""
        _, dHdp = self.model.gradient_soa(Q, P, wrt="p")
        V = self.chart.cartesian_velocity(S, dHdp[self.chart.offset:])
        D = (V / np.linalg.norm(V, axis=0)).T
        D = self._far_field(local, D)
        d_world = D @ self.rotation.T
        self._straight(rows, world, d_world, out)
        failed = ~np.isfinite(d_world).all(axis=1)
        out.ending[rows[failed]] = ENDING["failed"]

    def _far_field(self, X, D):
        """Bend directions D (M, 3) at X by the rest of the first-order deflection of a mass.

        A straight ray from X along D passes the mass M at impact b; it still turns by
        (2M/b)(1 - cos psi) towards the mass (cos psi = X.D/|X|, impulse approximation).
        """
        if self.mass == 0.0:
            return D
        r = np.linalg.norm(X, axis=1)
        along = np.einsum("ij,ij->i", X, D)
        perp = X - along[:, None] * D              # from the ray's line to X, ⟂ D
        b = np.linalg.norm(perp, axis=1)
        with np.errstate(all="ignore"):
            angle = np.where(b > 0, 2 * self.mass / b * (1 - along / r), 0.0)
            toward = np.where(b[:, None] > 0, -perp / b[:, None], 0.0)
        return np.cos(angle)[:, None] * D + np.sin(angle)[:, None] * toward

    # --- geometry helpers ------------------------------------------------------------
    def _to_local(self, world):
        return (world - self.scene.center) @ self.rotation

    def _to_world(self, local):
        return local @ self.rotation.T + self.scene.center

    def _cast(self, a, b, mask=None):
        """Nearest surface hits of segments a -> b, querying only segments near geometry."""
        from .intersect import Hits

        hits = Hits.miss(a.shape[0])
        lo, hi = self.objects.bounds
        if np.any(lo > hi):  # an empty group; infinite planes have infinite bounds
            return hits
        near = segment_overlaps(a, b, lo, hi)
        if mask is not None:
            near &= mask
        rows = np.flatnonzero(near)
        if rows.size:
            hits.merge(rows, self.objects.intersect(a[rows], b[rows]))
        return hits

    def _volumes(self, a, b, hits):
        """Emission and transmittance of every volume along a -> (b or the hit point)."""
        n = a.shape[0]
        radiance, trans = np.zeros((n, 3)), np.ones(n)
        if not self.volumes:
            return radiance, trans
        end = np.where(hits.hit[:, None], hits.position, b)
        for vol in self.volumes:
            rows = np.flatnonzero(segment_overlaps(a, end, vol.lo, vol.hi))
            if rows.size:
                r, t = vol.segment(a[rows], end[rows])
                radiance[rows] += trans[rows, None] * r
                trans[rows] *= t
        return radiance, trans


def tracing_model(model):
    """The chart rays are followed in: regular where rays followed into the past go.

    Kerr–Schild: the outgoing chart (regular on the past horizon). Schwarzschild in
    (t, r, theta, phi): Kerr–Schild with a = 0, which has the same r, theta, phi but no
    coordinate pole and no horizon singularity; the picture is the same.
    """
    if model is None:
        return None
    if getattr(model, "chart", None) == "spherical" and getattr(model, "a", None) == 0.0 \
            and getattr(model, "rg", 0.0) > 0:
        model = hamiltonians.kerr(model.rg, 0.0, chart="kerr_schild")
    backward = getattr(model, "for_backward_tracing", None)
    return backward() if backward is not None else model


def _accumulate(out: RayResults, rows, radiance, trans):
    """Composite a segment's volume emission behind what the ray has collected so far."""
    out.radiance[rows] += out.transmittance[rows, None] * radiance
    out.transmittance[rows] *= trans


def _empty_results(n, origins, directions) -> RayResults:
    return RayResults(
        ending=np.full(n, -1, dtype=np.int8), direction=directions.copy(),
        position=origins.copy(), surface=np.zeros((n, 4)), radiance=np.zeros((n, 3)),
        transmittance=np.ones(n), steps=np.zeros(n, dtype=np.int32),
        energy_error=np.zeros(n))


def default_step(order: int, tolerance: float, length: float) -> float:
    """Fictitious-time step for a method of ``order`` to reach ``tolerance`` (radians)."""
    tol = min(max(float(tolerance), 1e-14), 1e-1)
    return length * min(0.25, 0.5 * tol ** (1.0 / max(order, 1)))


class _Region:
    """Where the model bends light: a sphere (radius R) or a box, in local coordinates."""

    def __init__(self, radius=None, lo=None, hi=None, scale_time=True):
        self.radius, self.lo, self.hi = radius, lo, hi
        self.scale_time = scale_time

    @classmethod
    def for_model(cls, model, options: TraceOptions, extent: float, radius=None):
        """The region for a model: around a mass, M/sqrt(tol) (first-order far field)."""
        radius = radius or options.region_radius
        bounds = getattr(model, "bounds", None)
        if bounds is not None and radius is None:
            return cls(lo=np.asarray(bounds[0], float), hi=np.asarray(bounds[1], float),
                       scale_time=False)
        if radius is None:
            rg = float(getattr(model, "rg", 0.0))
            if rg > 0:
                radius = min(max(0.5 * rg / math.sqrt(options.tolerance), 100 * rg), 1e6 * rg)
                radius = max(radius, 1.5 * extent)
            else:
                radius = 2.0 * extent
        return cls(radius=float(radius), scale_time=getattr(model, "rg", 0.0) > 0)

    def length_scale(self, model) -> float:
        """Step unit: 1 where the model's g(q) already scales with distance, else the size."""
        if self.scale_time and getattr(model, "_time_scale", None) is not None:
            return 1.0
        if self.radius is not None:
            return self.radius / 20.0
        return float(np.linalg.norm(self.hi - self.lo)) / 20.0

    def entry(self, X, D):
        """Start points (N, 3) inside the region and whether the ray enters it at all.

        Rays starting inside start where they are; others at their first entry point;
        rays that never enter get NaN start points and inside False.
        """
        if self.radius is not None:
            r2 = np.einsum("ij,ij->i", X, X)
            inside = r2 < self.radius ** 2
            along = np.einsum("ij,ij->i", X, D)
            disc = along ** 2 - (r2 - self.radius ** 2)
            t = -along - np.sqrt(np.maximum(disc, 0.0))
            enters = ~inside & (disc > 0) & (t > 0)
        else:
            inside = np.all((X >= self.lo) & (X <= self.hi), axis=1)
            with np.errstate(divide="ignore", invalid="ignore"):
                ta, tb = (self.lo - X) / D, (self.hi - X) / D
            t0 = np.nanmax(np.fmin(ta, tb), axis=1)
            t1 = np.nanmin(np.fmax(ta, tb), axis=1)
            enters = ~inside & (t1 >= t0) & (t0 > 0)
            t = t0
        start = np.where(inside[:, None], X, np.nan)
        start[enters] = X[enters] + (t[enters, None] * (1 + 1e-12)) * D[enters]
        return start, inside

    def left(self, local, moved):
        """Rays (M,) now outside the region and moving away from it."""
        if self.radius is not None:
            r2 = np.einsum("ij,ij->i", local, local)
            return (r2 > self.radius ** 2) & (np.einsum("ij,ij->i", local, moved) > 0)
        return ~np.all((local >= self.lo) & (local <= self.hi), axis=1)

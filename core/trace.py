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

from . import checks, hamiltonians, integrators
from .charts import chart_for
from .intersect import Group, segment_overlaps
from .observer import medium_momenta, spacetime_momenta

ENDING = {"escaped": 0, "captured": 1, "hit": 2, "failed": 3, "max_steps": 4}
"""Ending codes of the ``ending`` pass (int8)."""

DEFAULT_METHOD = "gauss4"
"""The default integrator of images: around a black hole Gauss–Legendre 4 reaches a given
escape accuracy at about a third of yoshida4's cost (smaller error constant, so fewer,
longer steps; see ERROR_CONSTANTS and benchmarks/bench_perf.py)."""
SOLVE_SHARE = 1e-4
"""Implicit stage equations are solved to tolerance x SOLVE_SHARE, within [1e-14, 1e-8]
(solver_tolerance). Measured on the Kerr frame (3000 rays; tolerances 1e-4, 1e-6, 1e-8):
the solve then moves escape directions by at most 0.06 % of the tolerance (counted, like
the tolerance, as the equivalent error of the initial direction; 100x looser moves them
by 6-24 %), while solving to 1e-14 regardless took 1.2-2.3x as long."""
_FAR = 1e12  # length of the straight segment cast after a ray leaves the model's region
_SPLITS = 3  # a failed step is retried as 2, then 4, then 8 shorter steps
_OFF_SHELL = 1e-3  # |H - H0| / (|H0| + |p|^2) after one step that has it retried in halves
_DRIFT, _DRIFT_STEPS = 1e-2, 16
"""Spacetimes: a ray whose |H - H0| stays above _DRIFT p_t^2 for _DRIFT_STEPS steps in a
row has stopped being light (a bound massive orbit, m^2/E^2 ~ 2 |H|/p_t^2, can circle a
near-extremal horizon until max_steps) and is flagged failed. |p|^2 cannot tell: near the
horizon it grows without bound while p_t stays fixed; and a ray falling in may be that far
off for a step or two before the capture test ends it."""


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
        self.center = checks.check_vector("scene center", self.center)
        checks.check_optional(checks.check_positive, "region_radius", self.region_radius)
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

    method: str = DEFAULT_METHOD
    tolerance: float = 1e-8
    step: float | None = None
    max_steps: int = 20_000
    region_radius: float | None = None

    def __post_init__(self):
        checks.check_render_options(self.tolerance, self.step, self.max_steps)
        checks.check_optional(checks.check_positive, "region_radius", self.region_radius)


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
        if isinstance(options.method, str) and self.method.accepts("tol"):
            self.method = self.method.with_options(tol=solver_tolerance(options.tolerance))
        self.region = _Region.for_model(model, options, extent, scene.region_radius)
        self.captured = getattr(model, "captured_soa", None)
        self._near = self._local_box()
        self.step = options.step if options.step else default_step(
            self.method, options.tolerance, self.region.length_scale(model),
            scaled=self.region.scaled(model))

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
        h = self._record_segments(rows, a, a + far * d, out)
        out.ending[rows[~h]] = ENDING["escaped"]
        out.direction[rows] = d

    def _straight_to_region(self, rows, origins, directions, start, out):
        """Rays starting outside the region: straight to its boundary (or forever)."""
        X_entry = start[rows]
        enters = np.isfinite(X_entry[:, 0])
        a = origins[rows]
        b = np.where(enters[:, None], self._to_world(X_entry), a + _FAR * directions[rows])
        h = self._record_segments(rows, a, b, out)
        miss = ~h & ~enters
        if miss.any():
            X0 = self._to_local(a[miss])
            D0 = directions[rows[miss]] @ self.rotation
            out.direction[rows[miss]] = self._far_field(X0, D0) @ self.rotation.T
            out.ending[rows[miss]] = ENDING["escaped"]

    # --- the integration ---------------------------------------------------------------
    def _integrate(self, rows, X, D, out: RayResults, h: float, cancel):
        """Follow rays from local positions X (3, M) along local directions D (3, M).

        Per step, everything is done in the model's local frame on (3, M) arrays; world
        coordinates are computed only for the rays that need them: segments near geometry
        (a local box around the objects and volumes), and rays that end.
        """
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
        X_prev = X
        step = 0
        streak = np.zeros(idx.size, dtype=np.int64)  # steps in a row off the light cone
        for step in range(1, self.options.max_steps + 1):
            if cancel is not None and step % 32 == 0 and cancel():
                step -= 1
                break
            state, ok, drift = self._step(K, state, h, _SPLITS)
            Q, P = method.qp(state)
            if self.spacetime:
                with np.errstate(invalid="ignore"):
                    streak = np.where(drift > _DRIFT * P[0] * P[0], streak + 1, 0)
                ok &= streak < _DRIFT_STEPS
            S = Q[off:]
            X = chart.to_cartesian(S)
            ok &= np.isfinite(X).all(axis=0)
            ended = ~ok
            if not ok.all():
                out.ending[idx[ended]] = ENDING["failed"]
                out.position[idx[ended]] = self._to_world(X_prev[:, ended].T)
            if self._near is not None:  # surfaces and volumes along this step's segment
                ended |= self._segments(idx, X_prev, X, ok, out)
            if self.captured is not None:
                captured = ~ended & self.captured(Q)
                if captured.any():
                    out.ending[idx[captured]] = ENDING["captured"]
                    out.position[idx[captured]] = self._to_world(X[:, captured].T)
                    ended |= captured
            leaving = ~ended & self.region.left_soa(X, X_prev)
            if leaving.any():
                local = X[:, leaving].T
                self._escape(idx[leaving], S[:, leaving], Q[:, leaving], P[:, leaving],
                             local, self._to_world(local), out)
                ended |= leaving
            if ended.any():
                out.steps[idx[ended]] = step
                self._finish_energy(out, idx[ended], Q[:, ended], P[:, ended], H0[ended])
                keep = np.flatnonzero(~ended)
                if keep.size == 0:
                    return
                idx, X = idx[keep], X[:, keep]
                state = tuple(a[..., keep] for a in state)
                K = K.subset(keep)
                H0, streak = H0[keep], streak[keep]
            X_prev = X
        out.ending[idx] = ENDING["max_steps"]
        out.steps[idx] = step
        Q, P = method.qp(state)
        out.position[idx] = self._to_world(X_prev.T)
        self._finish_energy(out, idx, Q, P, H0)

    def _step(self, K, state, h, splits: int):
        """One step of every ray; rays whose step fails are retried as two half steps.

        -> (state, ok, |H - H0| of the state) per ray.

        A fixed step can be too long where K is stiff (the last steps of a ray falling
        into a horizon, steep index gradients): the implicit solve fails, or converges to
        a wrong root far off the light cone (|H - H0| > _OFF_SHELL (|H0| + |p|^2), where a
        good step is orders of magnitude closer). Those rays redo the step as two steps of
        h/2 (at most ``splits`` halvings deep); a ray captured at the midpoint stops there
        (the capture test ends it). Rays inside the horizon are not checked.
        """
        method = self.method
        new, ok = method.step(K, state, h)
        drift = self._drift(K, new)
        if splits == 0:
            return new, ok, drift
        ok &= ~self._off_shell(new, drift, K.H0)
        if ok.all():
            return new, ok, drift
        bad = np.flatnonzero(~ok)
        K_bad = K.subset(bad)
        mid, ok_mid, drift_mid = self._step(K_bad, tuple(a[..., bad] for a in state), 0.5 * h,
                                            splits - 1)
        go = ok_mid.copy()
        if self.captured is not None:
            with np.errstate(all="ignore"):
                go &= ~self.captured(method.qp(mid)[0])
        end, ok_end, drift_end = mid, ok_mid, drift_mid
        if go.any():
            g = np.flatnonzero(go)
            e2, o2, d2 = self._step(K_bad.subset(g), tuple(a[..., g] for a in mid), 0.5 * h,
                                    splits - 1)
            for a, b in zip(end, e2, strict=True):
                a[..., g] = b
            ok_end[g], drift_end[g] = o2, d2
        for a, b in zip(new, end, strict=True):
            a[..., bad] = b
        ok[bad], drift[bad] = ok_end, drift_end
        return new, ok, drift

    def _segments(self, idx, X_prev, X, ok, out: RayResults) -> np.ndarray:
        """Surface hits and volume emission along the segments X_prev -> X near geometry.

        -> (M,) bool: the rays that hit a surface (their ending is recorded in ``out``).
        """
        lo, hi = self._near
        near = ok.copy()
        for i in range(3):
            near &= (np.minimum(X_prev[i], X[i]) <= hi[i]) & (np.maximum(X_prev[i], X[i]) >= lo[i])
        hit_rows = np.zeros(ok.shape[0], dtype=bool)
        c = np.flatnonzero(near)
        if c.size == 0:
            return hit_rows
        a, b = self._to_world(X_prev[:, c].T), self._to_world(X[:, c].T)
        hit_rows[c] = self._record_segments(idx[c], a, b, out)
        return hit_rows

    def _record_segments(self, rows, a, b, out: RayResults) -> np.ndarray:
        """Cast world segments a -> b of rays ``rows``: composite the volumes crossed and
        record surface hits in ``out``. Returns which segments hit a surface (M,)."""
        hits = self._cast(a, b)
        rad, trans = self._volumes(a, b, hits)
        _accumulate(out, rows, rad, trans)
        h = hits.hit
        out.ending[rows[h]] = ENDING["hit"]
        out.position[rows[h]] = hits.position[h]
        out.surface[rows[h]] = hits.color[h]
        return h

    def _drift(self, K, state) -> np.ndarray:
        """(M,) |H - H0| of each ray's state (NaN where a failed ray holds anything)."""
        Q, P = self.method.qp(state)
        with np.errstate(all="ignore"):
            return np.abs(self.model.value_soa(Q, P) - K.H0)

    def _off_shell(self, state, drift, H0) -> np.ndarray:
        """(M,) rays a step left far off the light cone, |H - H0| > _OFF_SHELL (|H0| + |p|^2);
        rays inside the horizon are not judged."""
        Q, P = self.method.qp(state)
        with np.errstate(all="ignore"):
            off = drift > _OFF_SHELL * (np.abs(H0) + np.einsum("ij,ij->j", P, P))
            if self.captured is not None:
                off &= ~self.captured(Q)
        return off

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
    def _local_box(self):
        """(lo, hi) in local coordinates around every object and volume (None: nothing)."""
        boxes = [(np.asarray(v.lo, float), np.asarray(v.hi, float)) for v in self.volumes]
        lo, hi = self.objects.bounds
        if not np.any(np.asarray(lo) > np.asarray(hi)):
            boxes.append((np.asarray(lo, float), np.asarray(hi, float)))
        if not boxes:
            return None
        lo = np.min([b[0] for b in boxes], axis=0)
        hi = np.max([b[1] for b in boxes], axis=0)
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
            return np.full(3, -np.inf), np.full(3, np.inf)
        corners = np.array(np.meshgrid(*zip(lo, hi, strict=True))).reshape(3, -1).T
        local = self._to_local(corners)
        return local.min(axis=0), local.max(axis=0)

    def _to_local(self, world):
        return (world - self.scene.center) @ self.rotation

    def _to_world(self, local):
        return local @ self.rotation.T + self.scene.center

    def _cast(self, a, b):
        """Nearest surface hits of segments a -> b, querying only segments near geometry.

        When most segments are near, all of them go (an intersector answers misses for the
        others; cheaper than gathering the near ones and scattering their hits back).
        """
        from .intersect import Hits

        lo, hi = self.objects.bounds
        if np.any(lo > hi):  # an empty group; infinite planes have infinite bounds
            return Hits.miss(a.shape[0])
        near = segment_overlaps(a, b, lo, hi)
        rows = np.flatnonzero(near)
        if rows.size > 0.5 * a.shape[0]:
            return self.objects.intersect(a, b)
        hits = Hits.miss(a.shape[0])
        if rows.size:
            hits.merge(rows, self.objects.intersect(a[rows], b[rows]))
        return hits

    def _volumes(self, a, b, hits):
        """Emission and transmittance of every volume along a -> (b or the hit point)."""
        if not self.volumes:
            return None, None
        n = a.shape[0]
        radiance, trans = np.zeros((n, 3)), np.ones(n)
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
    if radiance is None:  # no volumes in the scene
        return
    out.radiance[rows] += out.transmittance[rows, None] * radiance
    out.transmittance[rows] *= trans


def _empty_results(n, origins, directions) -> RayResults:
    return RayResults(
        ending=np.full(n, -1, dtype=np.int8), direction=directions.copy(),
        position=origins.copy(), surface=np.zeros((n, 4)), radiance=np.zeros((n, 3)),
        transmittance=np.ones(n), steps=np.zeros(n, dtype=np.int32),
        energy_error=np.zeros(n))


ERROR_CONSTANTS = {
    "symplectic_euler": 0.3, "stormer_verlet": 0.11, "implicit_midpoint": 0.07,
    "gauss4": 0.01, "yoshida4": 1.0, "yoshida6": 0.9, "yoshida8": 350.0, "suzuki4": 0.013,
    "suzuki6": 5e-3, "rk4": 0.125, "dopri5": 0.1,
}
"""C in err = C h^order: each method's escape-direction error around a mass, per step h of
the Poincaré time (g = r). err is the *equivalent* error of the ray's initial direction
(radians): the escape error over the lens's own magnification there, when that exceeds 1
(rays grazing the photon region have their forward error magnified without bound, like
any perturbation of their starting direction). The largest of 3000 rays on Kerr a/M = 0.9
seen from 30 rg, times 1.5 (``benchmarks/bench_perf.py --only calibrate``). Tao's methods
have none: with the default binding they do not follow these rays."""

FAR_FIELD_CONSTANT = 30.0
"""The first-order far field leaves a forward escape error of at most ~ C (M / R)^2 for a
region of radius R (measured as above: 28.4)."""

MAX_STEP = 0.25
"""Largest default step in the Poincaré time (a step that the implicit solve cannot take
near a horizon is split, see Tracer._step)."""


def solver_tolerance(tolerance: float) -> float:
    """Tolerance of the implicit solves for an image of ``tolerance`` (see SOLVE_SHARE)."""
    return min(1e-8, max(1e-14, float(tolerance) * SOLVE_SHARE))


def default_step(method, tolerance: float, length: float, scaled: bool = False) -> float:
    """Fictitious-time step for ``method`` to reach ``tolerance`` (radians).

    Around a mass (``scaled``: g(q) grows with the distance) from the method's error
    constant, so that the integration error stays below tolerance / 2 (the far field gets
    the other half, see _Region). Otherwise (media, user models, methods without a
    constant): h = 0.5 length tol^(1/order).
    """
    tol = min(max(float(tolerance), 1e-14), 1e-1)
    order = max(int(method.order), 1)
    constant = ERROR_CONSTANTS.get(method.name) if scaled else None
    if constant is None:
        return length * min(MAX_STEP, 0.5 * tol ** (1.0 / order))
    return min(MAX_STEP, (0.5 * tol / constant) ** (1.0 / order))


class _Region:
    """Where the model bends light: a sphere (radius R) or a box, in local coordinates."""

    def __init__(self, radius=None, lo=None, hi=None, scale_time=True):
        self.radius, self.lo, self.hi = radius, lo, hi
        self.scale_time = scale_time

    @classmethod
    def for_model(cls, model, options: TraceOptions, extent: float, radius=None):
        """The region for a model: around a mass, sqrt(2 C / tol) M (first-order far field).

        Beyond R the far field leaves an error ~ C (M / R)^2 (FAR_FIELD_CONSTANT): R keeps
        it below tolerance / 2, and at least 1.5x beyond the camera and the objects.
        """
        radius = radius or options.region_radius
        bounds = getattr(model, "bounds", None)
        if bounds is not None and radius is None:
            return cls(lo=np.asarray(bounds[0], float), hi=np.asarray(bounds[1], float),
                       scale_time=False)
        if radius is None:
            rg = float(getattr(model, "rg", 0.0))
            if rg > 0:
                tol = min(max(float(options.tolerance), 1e-14), 1e-1)
                radius = min(0.5 * rg * math.sqrt(2 * FAR_FIELD_CONSTANT / tol), 1e6 * rg)
                radius = max(radius, 1.5 * extent)
            else:
                radius = 2.0 * extent
        return cls(radius=float(radius), scale_time=getattr(model, "rg", 0.0) > 0)

    def scaled(self, model) -> bool:
        """Whether the model's Poincaré g(q) grows with the distance from a mass."""
        return bool(self.scale_time and getattr(model, "_time_scale", None) is not None)

    def length_scale(self, model) -> float:
        """Step unit: 1 where the model's g(q) already scales with distance, else the size."""
        if self.scaled(model):
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

    def left_soa(self, X, X_prev):
        """Rays (M,) at X (3, M), coming from X_prev, outside the region and moving away."""
        if self.radius is not None:
            r2 = X[0] * X[0] + X[1] * X[1] + X[2] * X[2]
            away = X[0] * (X[0] - X_prev[0]) + X[1] * (X[1] - X_prev[1]) + \
                X[2] * (X[2] - X_prev[2])
            return (r2 > self.radius ** 2) & (away > 0)
        return ~np.all((X >= self.lo[:, None]) & (X <= self.hi[:, None]), axis=0)

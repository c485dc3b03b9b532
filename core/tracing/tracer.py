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

import copy
import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np

from .. import checks, integrators
from ..charts import chart_for
from ..geometry import Hits, segment_overlaps
from ..integrators.batch import Batch, run_batch
from ..models.medium import FACE_SAMPLES
from ..motion import Motion
from ..observer import medium_momenta, spacetime_momenta
from . import dense
from .clearance import ClearanceBoxes, clear_radius
from .differentials import (
    axial_final,
    axial_tangents,
    directional,
    magnification,
    unit_directional,
)
from .disklight import DiskLight
from .regions import BoxRegion, Region, SphereRegion, region_for
from .scene import DISK_ID, ENDING, Scene
from .segments import RayResults, SceneGeometry
from .stepping import OFF_CONE, OFF_CONE_STEPS, RayCapture, Stepper, ray_capture_test
from .steps import (
    default_method,
    default_step,
    error_constant,
    form_calibration,
    rule_bounds,
    solver_tolerance,
)

CROSSING_SHARE, CROSSING_ITERATIONS = 1e-3, 4
"""The disk's crossing is found to |z| <= CROSSING_SHARE x tolerance x |X| (a share of the
integration's own error there) in at most CROSSING_ITERATIONS Newton steps."""
CROSSING_REACH = 1.0
"""A crossing's last Newton step is taken along the velocity instead of by the method
(one partial step fewer: each costs a whole step's per-call overhead, ~45 % of a disk
scene's time before) where it moves the point by at most CROSSING_REACH x sqrt(allowed
share) x |X|: a light ray's path outside a horizon bends with a radius of at least ~|X|/2
(Schwarzschild: curvature <= 3M/r^2, r > 2M), so the straight step is then off by at
most CROSSING_REACH^2 x the allowance (|X| x the share, what a point found by the
method may miss the plane by). At 0.1 (before) 88 % of crossings took a second partial
step; at 1, ~40 % (the first step's move, over sqrt(share) |X|: median 0.56, p90 3.4,
the Kerr-with-disk preset)."""
_FAR = 1e12  # length of the straight segment cast after a ray leaves the model's region
NEAR_BOXES = 16
"""Up to this many objects and volumes, steps are near geometry by each one's own box
(Tracer._near_boxes); more, by their union's (one test per step)."""
BEND_LIMIT = 64.0
"""A step near geometry whose cubic path deviates from its chord by more than BEND_LIMIT
chord allowances is taken again at half the step (Tracer._bent_steps): hits are found on
the cubic, and a long step whose bend is not a cubic's (far from a small hole, where the
steps grow with r and the bending happened near one end) misplaced them by pixels while
the step-doubling estimate, one step either way, saw nothing."""
PACE_LIMIT = 2.0
"""With geometry, a step whose end speeds (in the fictitious time: a ray's pace there
changes as r does) differ by more than this factor is taken again at half the step
(Tracer._bent_steps): it spans a stretch of the path as long as its distance from the
hole, whose bending (~1/r^2) the cubic through its ends does not follow. (The bend limit
once counted the change of pace as a bend: 17 % of a Kerr board frame's steps were taken
again for it; without any limit on the pace, hits on spheres 400 rg behind a hole were
0.3-0.5 px off at 0.05 px with both runs agreeing, benchmarks/honesty.py far_small.)"""
TURN_LIMIT = 0.1
"""With geometry, a step whose chord turns from the ray's heading by more than this
(radians) is taken again at half the step (Tracer._bent_steps)."""
MAX_HALVINGS = 10
"""At most this many halvings of a ray's step (1/1024 of the rule's)."""
CHORD_SHARE = 0.5
"""Chords near geometry stay within CHORD_SHARE x tolerance x (distance from the camera) of
the ray's cubic path: half the tolerance, as the integration gets (core/tracing/steps.py)."""


@dataclass
class TraceOptions:
    """How rays are integrated."""

    method: Any = None
    """A method name or object; None: the model's default (steps.default_method)."""
    tolerance: float = 1e-8
    step: float | None = None
    max_steps: int = 20_000
    region_radius: float | None = None

    def __post_init__(self) -> None:
        checks.check_render_options(self.tolerance, self.step, self.max_steps)
        checks.check_optional(checks.check_positive, "region_radius", self.region_radius)


def tracing_model(model: Any, method: Any = None) -> Any:
    """The chart rays are followed in: regular where rays followed into the past go
    (``Hamiltonian.for_backward_tracing``; e.g. Kerr–Schild outgoing, and Schwarzschild
    in (t, r, theta, phi) as Kerr–Schild with a = 0, or for an explicit splitting
    ``method`` as its isotropic optical medium)."""
    if model is None:
        return None
    return model.for_backward_tracing(explicit_split=isinstance(method, integrators.Splitting))


@dataclass(frozen=True)
class TracePlan:
    """What a tracer decides once for a scene and its options (``plan_trace``): the form rays
    are followed in and how. A flat scene's plan says so (``curved`` False, the rest None)."""

    curved: bool
    model: Any
    """The form rays are followed in (``tracing_model``); None in flat space."""
    method: Any = None
    """The integration method (with its solve tolerance), None where rays go straight."""
    order: int | None = None
    """The method's order on what it integrates here (Richardson, the step rule)."""
    chart: Any = None
    region: Region | None = None
    step: float | None = None
    capture_test: RayCapture | None = None
    """(Q, P) -> (N,) bool: rays that cannot come back out of a horizon (None: no horizon)."""
    error_constant: float | None = None
    """C of the step rule's err = C h^order (radians; None where the rule uses none)."""
    largest_step: float = math.inf
    """The rule's largest step: the constant was measured at steps up to it."""


def plan_trace(scene: Scene, options: TraceOptions, extent: float = 1.0) -> TracePlan:
    """The one place a trace is planned: method (the model's default unless named), the
    form and chart it follows rays in, the method's order there, the region around the mass
    (reaching past the disk), the capture test and the step (the options' or the rule's)."""
    if not scene.curved:
        return TracePlan(curved=False, model=tracing_model(scene.model))
    method = integrators.get_method(options.method or default_method(scene.model))
    model = tracing_model(scene.model, method)
    system = model
    if isinstance(method, integrators.Splitting):  # refused without a split
        system = model.split_parts()
        integrators.splitting.split_flows(system, method.name)
    order = method.order_on(system)
    if not isinstance(options.method, integrators.Method) and method.accepts("tol"):
        method = method.with_options(tol=solver_tolerance(options.tolerance))
    radius = scene.region_radius or options.region_radius
    if scene.disk is not None:  # the disk's hits need the rays' momenta: inside
        extent = max(extent, scene.disk.cartesian_radii()[1])
    region = region_for(model, options.tolerance, extent, radius)
    if isinstance(region, BoxRegion) and hasattr(model, "check_faces"):
        model.check_faces(region.faces(FACE_SAMPLES))  # an interface the box cuts: refused
    constant, largest = rule_bounds(
        method, region.scaled(model), error_constant(method, model, system),
        form_calibration(model).largest_step,
    )  # fmt: skip
    step = options.step or default_step(
        method,
        options.tolerance,
        region.length_scale(model),
        scaled=region.scaled(model),
        constant=constant,
        largest=largest,
        order=order,
    )
    return TracePlan(
        curved=True, model=model, method=method, order=order, chart=chart_for(model),
        region=region, step=step, capture_test=ray_capture_test(model),
        error_constant=constant, largest_step=largest,
    )  # fmt: skip


class Tracer:
    """Traces batches of world-space rays through one scene with fixed options (its plan:
    ``plan_trace``)."""

    disk: DiskLight | None = None
    motion: Motion | None = None
    """The camera's motion (set_motion): rays start along the static observer's directions."""
    _watch: ClearanceBoxes | None = None  # Tracer.watch_geometry
    _clear = 0.0
    """Inside an accretion disk's inner edge (or a nearer object's) no step is near geometry
    (_near_paths). Only with a disk: without one, a ball out to the nearest object let the
    steps near the hole grow to the rule's and the error pass under-reported them
    (benchmarks/honesty.py thin_front at 0.05 px: 1 -> 9 pixels over 3x the tolerance);
    inside a disk's inner edge (rays captured or winding in the photon ring) the
    honesty family showed no loss (disk_high_spin: under-reported 3.71 -> 3.60 %)."""
    _watch_near: tuple[np.ndarray, np.ndarray] = (np.full(3, -np.inf), np.full(3, np.inf))
    _near_boxes: list[tuple[np.ndarray, np.ndarray]] | None = None
    """Each object's (and volume's) local box, where there are 2 to NEAR_BOXES: a step is
    near geometry where its path may pass one of them, not only their union's box."""

    def __init__(self, scene: Scene, options: TraceOptions, extent: float = 1.0):
        self.scene = scene
        self.options = options
        self.rotation = scene.frame()
        self.geometry = SceneGeometry(scene.intersector(), list(scene.volumes))
        self.plan = plan = plan_trace(scene, options, extent)
        self.curved, self.model = plan.curved, plan.model
        self.method, self.order, self.chart = plan.method, plan.order, plan.chart
        self.region, self.step, self.captured = plan.region, plan.step, plan.capture_test
        self.spacetime = self.curved and self.chart.time_index is not None
        self.mass = self.model.mass if self.curved else 0.0
        self.stepper: Stepper | None = None
        self._near: tuple[np.ndarray, np.ndarray] | None = None
        if not self.curved:
            return
        if scene.disk is not None:
            self.disk = self._disk_light(scene)
        self.stepper = Stepper(self.method, self.model, self.captured)
        self._near = self.geometry.local_box(self._to_local)
        if self._near is not None and 1 < self.geometry.box_count() <= NEAR_BOXES:
            self._near_boxes = self.geometry.local_boxes(self._to_local)
        if scene.disk is not None:  # the disk's inner edge, or a nearer object
            self._clear = clear_radius(self.geometry.boxes(), np.asarray(scene.center, float))

    def _disk_light(self, scene: Scene) -> DiskLight:
        """The disk's light; ValueError if the disk reaches past the model's region (an
        explicit region_radius: its hits there would have no momentum to take g from)."""
        assert scene.disk is not None and self.region is not None
        outer = scene.disk.cartesian_radii()[1]
        if self.region.radius is None or not self.region.radius > outer:
            raise ValueError(
                f"region_radius must exceed the accretion disk's outer radius {outer:g} "
                f"(Cartesian), got {self.region.radius}"
            )
        behind = SceneGeometry(scene.intersector(disk=False), list(scene.volumes))
        return DiskLight(scene.disk, self.model, self.chart, self._to_local, self.geometry, behind)

    def watch_geometry(self, margin: float) -> None:
        """Record each ray's clearance (``RayResults.clearance``): the smallest angle, seen
        from the camera, between any chord of its path and any object's or volume's bounds
        (core.tracing.clearance; adaptive sampling interpolates a block of pixels only
        where its rays kept clear by more than the block's spread). Chords farther than
        ``margin`` (world units) from every box count as clear."""
        boxes = self.geometry.boxes()
        if boxes:
            self._watch = ClearanceBoxes(boxes, margin)
            local = self.geometry.local_box(self._to_local)
            if local is not None:
                self._watch_near = (local[0] - margin, local[1] + margin)

    def without_clearance(self) -> Tracer:
        """This tracer, sharing all it holds, but recording no clearance (rays whose
        colour alone is wanted: sub-pixel samples; their ``clearance`` stays inf)."""
        plain = copy.copy(self)
        plain._watch = None
        return plain

    def set_motion(self, motion: Motion | None) -> None:
        """Trace for a camera moving with ``motion`` (core.motion; None: the static / ZAMO
        observer): each ray starts along the direction the static observer sees its photon
        from, and carries the Doppler factor its colours (and the disk's g) take."""
        self.motion = motion

    @property
    def objects(self) -> Any:
        """The scene's objects as one intersector."""
        return self.geometry.objects

    # --- public ----------------------------------------------------------------------
    def trace(
        self,
        origins: np.ndarray,
        directions: np.ndarray,
        step: float | np.ndarray | None = None,
        cancel: Callable[[], bool] | None = None,
        tangents: np.ndarray | None = None,
        clearance: np.ndarray | None = None,
    ) -> RayResults:
        """Trace rays (N, 3) from world origins along unit world directions, at ``step``
        (the tracer's by default; one for all, or (N,) per ray: runs at several steps share
        one batch, and its per-step overhead). With ``tangents`` (N, k, 3), the directions'
        derivatives with respect to k image coordinates, each escaped ray's final
        direction gets its derivatives too (``RayResults.sky_jacobian``) and its image's
        magnification (``RayResults.magnification``, per the camera's solid angle: a moving
        camera's own) (core/tracing/differentials.py; ValueError where the method cannot
        carry them: ``supports_tangents``). Where the tracer watches the geometry,
        ``clearance`` (N,) says which rays' paths record it inside the model's region
        (default all; the others' stays inf there: a companion run's is never read):
        bool, or each ray's share of the margin (0 none, 1 all: core.sampling's nodes need
        their largest block's, not a coarsest block's)."""
        n = origins.shape[0]
        if np.ndim(step) and np.shape(step) != (n,):
            raise ValueError(f"step: one for all rays or one per ray ({n}), got {np.shape(step)}")
        if tangents is not None:
            self.check_tangents()
        out, static_tangents = self._start_results(origins, directions, tangents)
        directions = out.direction.copy()  # the static observer's
        if not self.curved:
            self._straight(np.arange(n), origins, directions, out)
            if tangents is not None:
                out.sky_jacobian[:] = static_tangents
        else:
            self._trace_curved(origins, directions, step, cancel, static_tangents, out, clearance)
        if tangents is not None:  # per the camera's own solid angle (a moving one's)
            out.sky_jacobian[out.ending != ENDING["escaped"]] = np.nan
            out.magnification = magnification(tangents, out.sky_jacobian)
        return self._besides_hit(out)

    def _start_results(self, origins, directions, tangents) -> tuple[RayResults, Any]:
        """The results of rays not traced yet, along the static observer's directions (a
        moving camera's aberrated, with their Doppler factor), and those directions'
        tangents (None without ``tangents``)."""
        shift = None
        if self.motion is not None:
            shift = self.motion.colour_shift(directions)
            if tangents is not None:
                tangents = unit_directional(self._aberrated, directions, tangents)
            directions, _ = self.motion.aberrate(directions)
        out = RayResults.empty(origins.shape[0], origins, directions)
        if shift is not None:
            out.doppler = shift
        if tangents is not None:
            out.sky_jacobian = np.full(tangents.shape, np.nan)
        return out, tangents

    def _trace_curved(
        self, origins, directions, step, cancel, tangents, out, clearance=None
    ) -> None:
        """Rays straight to the model's region, then integrated through it (``trace``)."""
        assert self.region is not None
        X = self._to_local(origins)
        D = directions @ self.rotation  # (N, 3) local components
        start, inside = self.region.entry(X, D)
        outside = np.flatnonzero(~inside)
        if outside.size:
            self._straight_to_region(outside, origins, directions, start, out, tangents)
        todo = np.flatnonzero(np.isfinite(start[:, 0]) & (out.ending < 0))
        h = self.step if step is None else step
        assert h is not None  # a curved scene's tracer has a step
        if todo.size:
            camera = self._to_local(origins[todo]).T  # (3, M): where each ray is seen from
            if np.ndim(h):
                h = np.asarray(h, dtype=np.float64)[todo]
            local_tangents = None if tangents is None else tangents[todo] @ self.rotation
            watch = None if clearance is None else np.asarray(clearance, np.float64)[todo]
            self._integrate(
                todo, start[todo].T.copy(), D[todo].T.copy(), out, h, cancel, camera,
                local_tangents, watch,
            )  # fmt: skip

    @property
    def supports_tangents(self) -> bool:
        """Whether ``trace`` can carry ray differentials here: flat space, or a splitting on
        a split whose flows take derivatives (``SplitSystem.tangents``)."""
        if not self.curved:
            return True
        if not isinstance(self.method, integrators.Splitting):
            return False
        return bool(getattr(self.model.split_parts(0.0), "tangents", False))

    def check_tangents(self) -> None:
        """ValueError naming why this trace cannot carry ray differentials, if it cannot."""
        if not self.supports_tangents:
            raise ValueError(
                "ray differentials (the magnification pass, point stars) need the rays "
                "carried by an explicit splitting on a split whose flows take derivatives: "
                "Schwarzschild, Kerr with |a| < M (their default methods) and flat space; "
                f"this scene's rays are integrated by {self.method!r} on "
                f"{type(self.model).__name__}"
            )

    def _aberrated(self, directions: np.ndarray) -> np.ndarray:
        assert self.motion is not None
        return self.motion.aberrate(directions)[0]

    def _besides_hit(self, out: RayResults) -> RayResults:
        """``out`` with each hit ray's clearance from everything but what it hit."""
        if self._watch is not None:
            out.clearance = self._watch.besides_hit(out)
        return out

    # --- straight parts --------------------------------------------------------------
    def _straight(self, rows, a, d, out: RayResults, eye=None):
        """Rays that stay straight from a along d: one cast each, ending hit or escaped
        (``eye``: where they are seen from, default a)."""
        self._watch_segments(rows, a, a + _FAR * d, out, eye)
        h = self.geometry.record(rows, a, a + _FAR * d, out)
        out.ending[rows[~h]] = ENDING["escaped"]
        out.direction[rows] = d

    def _straight_to_region(self, rows, origins, directions, start, out, tangents=None):
        """Rays starting outside the region: straight to its boundary (or forever); those
        that miss it get their far-field direction (and its derivatives along the
        ``tangents`` of ``directions``, if given)."""
        X_entry = start[rows]
        enters = np.isfinite(X_entry[:, 0])
        a = origins[rows]
        b = np.where(enters[:, None], self._to_world(X_entry), a + _FAR * directions[rows])
        self._watch_segments(rows, a, b, out)
        h = self.geometry.record(rows, a, b, out)
        miss = ~h & ~enters
        if miss.any():
            X0 = self._to_local(a[miss])

            def far(d_world: np.ndarray) -> np.ndarray:
                return self._far_field(X0, d_world @ self.rotation) @ self.rotation.T

            out.direction[rows[miss]] = far(directions[rows[miss]])
            out.ending[rows[miss]] = ENDING["escaped"]
            if tangents is not None:
                seen = tangents[rows[miss]]
                out.sky_jacobian[rows[miss]] = unit_directional(far, directions[rows[miss]], seen)

    # --- the integration ---------------------------------------------------------------
    def _integrate(
        self, rows, X, D, out: RayResults, h: float | np.ndarray, cancel, camera, tangents=None,
        watch=None,
    ):  # fmt: skip
        """Follow rays from local positions X (3, M) along local directions D (3, M) (with
        ``tangents`` (M, k, 3): the directions' derivatives, carried along; ``watch`` (M,)
        each ray's share of the margin its clearance is recorded within, default all).

        Per step, everything is done in the model's local frame on (3, M) arrays; world
        coordinates are computed only for the rays that need them: segments near geometry
        (a local box around the objects and volumes), and rays that end.
        """
        model = self.model
        Q, P = self._start_state(X, D)
        H0 = model.value_soa(Q, P)
        K = model.split_parts(H0) or integrators.PoincareTransformed(model, H0)
        state = self.method.init(K, Q, P)
        shares = None
        if tangents is not None:
            if self._axial:  # one tangent traced, the other by symmetry
                shares, tangents = axial_tangents(camera.T, D.T, tangents)
            dQ, dP = self._start_tangents(camera, D, tangents, Q.shape[0])
            state = self.method.with_tangents(K, state, dQ, dP)
        batch = Batch(
            self.method,
            state,
            {"K": K},
            {"idx": rows.copy(), "X": X, "camera": camera, "H0": H0,
             "h": np.broadcast_to(np.asarray(h, dtype=np.float64), rows.shape).copy(),
             "h0": np.broadcast_to(np.asarray(h, dtype=np.float64), rows.shape).copy(),
             "heading": D / np.linalg.norm(D, axis=0),  # the last chord's direction
             "streak": np.zeros(rows.size, dtype=np.int64),  # steps in a row off the cone
             "watch": np.ones(rows.size) if watch is None else watch,
             "kinks": np.zeros(rows.size, dtype=np.int64)},  # the model's kinks crossed
        )  # fmt: skip
        if shares is not None:
            batch.arrays["axial"] = shares

        def step(batch: Batch):
            assert self.stepper is not None  # a curved scene's tracer has one
            K, h = batch.systems["K"], batch.arrays["h"]
            state, ok, shell, crossings = self.stepper.advance(K, batch.state, h)
            batch.arrays["kinks"] |= crossings
            return state, ok, shell

        def events(batch: Batch, taken: int, start, ok, shell) -> np.ndarray:
            return self._step_events(batch, taken, start, ok, shell, out)

        taken = run_batch(batch, step, events, self.options.max_steps, cancel)
        if batch.size == 0:
            return
        idx, X_last = batch.arrays["idx"], batch.arrays["X"]
        out.ending[idx] = ENDING["max_steps"]
        out.steps[idx] = taken
        out.kinks[idx] = batch.arrays["kinks"]
        Q, P = self.method.qp(batch.state)
        out.position[idx] = self._to_world(X_last.T)
        self._finish_energy(out, idx, Q, P, batch.arrays["H0"])

    def _start_state(self, X: np.ndarray, D: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(Q, P) of rays starting at local positions X (3, M) along local directions D
        (3, M): the chart's coordinates and the observer frame's momenta."""
        S = self.chart.to_coords(X)
        if self.spacetime:
            return spacetime_momenta(self.model, self.chart, S, D)
        return medium_momenta(self.model, S, D)

    @property
    def _axial(self) -> bool:
        """Whether rays' differentials go by the model's spherical symmetry: one traced,
        the other a turn about the camera's axis (core/tracing/differentials.py
        axial_tangents): a spherical model in a ball about its centre."""
        return self.model.spherical and isinstance(self.region, SphereRegion)

    def _start_tangents(self, camera, D, tangents, n: int) -> tuple[np.ndarray, np.ndarray]:
        """(dQ, dP) (k, n, M): the start state's derivatives along the directions' tangents
        (M, k, 3), through the region's entry point, the chart and the observer's frame
        (central differences, core/tracing/differentials.py)."""
        region = self.region
        assert region is not None

        def state(d: np.ndarray) -> np.ndarray:
            X, _ = region.entry(camera.T, d)
            Q, P = self._start_state(X.T.copy(), d.T.copy())
            return np.concatenate([Q, P]).T

        periodic = [i + self.chart.offset for i in getattr(self.chart, "periodic", ())]
        dZ = directional(state, D.T, tangents, periodic)  # unit directions: |d| = 1 each side
        dZ = np.moveaxis(dZ, 0, -1)  # (k, 2n, M)
        return dZ[:, :n].copy(), dZ[:, n:].copy()

    def _step_events(self, batch: Batch, taken: int, start, ok, shell, out: RayResults):
        """After a step: which rays failed, hit something, were captured or left the
        region ((M,) bool), each recorded in ``out``; the batch's X becomes the step's end."""
        chart, arrays = self.chart, batch.arrays
        idx, X_prev, camera = arrays["idx"], arrays["X"], arrays["camera"]
        raw_start, start = start, self.method.qp(start)
        Q, P = self.method.qp(batch.state)
        if self.spacetime:
            with np.errstate(invalid="ignore"):
                streak = np.where(shell > OFF_CONE * P[0] * P[0], arrays["streak"] + 1, 0)
            arrays["streak"] = streak
            ok &= streak < OFF_CONE_STEPS
        S = Q[chart.offset :]
        X = chart.to_cartesian(S)
        ok &= np.isfinite(X).all(axis=0)
        ended = ~ok
        if not ok.all():
            out.ending[idx[ended]] = ENDING["failed"]
            out.position[idx[ended]] = self._to_world(X_prev[:, ended].T)
        paths, going = None, ok
        h_taken = arrays["h"].copy()  # the step taken (a copy: _bent_steps sets the next one)
        if self._near is not None:  # surfaces and volumes along this step's segment
            step_ends = _StepEnds(self, batch.systems["K"], start, (Q, P), h_taken, camera)
            chord, turn = _turn(X_prev, X, arrays["heading"])
            paths = self._near_paths(X_prev, X, ok, step_ends, camera, turn, arrays["h0"])
            redo = self._bent_steps(paths, chord, turn, ok, arrays)
            if redo.any():  # back to the step's start, at half the step
                batch.state = tuple(
                    np.where(redo, a, b) for a, b in zip(raw_start, batch.state, strict=True)
                )
                Q, P = self.method.qp(batch.state)
                S, X = Q[chart.offset :], np.where(redo, X_prev, X)
                paths, going = paths.without(redo), ok & ~redo
        if self._watch is not None:  # the steps within the margin of the objects' box
            near = segment_overlaps(X_prev.T, X.T, *self._watch_near)
            r = np.flatnonzero(near & (arrays["watch"] > 0))
            if r.size:
                world = [self._to_world(x[:, r].T) for x in (X_prev, X, camera)]
                *bends, slack = _bends(paths, X.shape[1])
                bend = (*(b[:, r].T @ self.rotation.T for b in bends), slack[r])
                self._watch_segments(idx[r], world[0], world[1], out, world[2], bend,
                                     arrays["watch"][r])  # fmt: skip
        if paths is not None:
            ended |= self._segments(idx, paths, out, step_ends)
        if self.captured is not None:
            captured = ~ended & going & self.captured(Q, P)
            if captured.any():
                out.ending[idx[captured]] = ENDING["captured"]
                out.position[idx[captured]] = self._to_world(X[:, captured].T)
                ended |= captured
        assert self.region is not None
        leaving = ~ended & going & self.region.left_soa(X, X_prev)
        if leaving.any():
            ends = _StepEnds(self, batch.systems["K"], start, (Q, P), h_taken, camera)
            self._leave(batch, leaving, X_prev, X, ends, out)
            ended |= leaving
        if ended.any():
            out.steps[idx[ended]] = taken
            out.kinks[idx[ended]] = arrays["kinks"][ended]
            self._finish_energy(out, idx[ended], Q[:, ended], P[:, ended], arrays["H0"][ended])
        arrays["X"] = X
        return ended

    def _near_paths(self, X_prev, X, ok, step_ends: _StepEnds, camera, turn, h0) -> _NearPaths:
        """The steps whose path X_prev -> X may pass the geometry's box, and one object's
        own box where there are few (``_near_boxes``) (their chord's bounds widened by how
        far a path turning by ``turn`` from its heading can stray from it) and may leave
        the ball around the hole that holds no geometry (with an
        accretion disk: ``_clear``; a path from X_prev to X stays within the larger |X|
        plus its stray; a camera inside that ball keeps its rays' steps checked: halved
        where they turn, which near the camera keeps the error pass's estimate honest:
        where a ball reached past the camera, benchmarks/honesty.py near_tangent, it
        under-reported 3x on 2.2 % of the pixels instead of 0.4 %), with their ends'
        velocities, their cubics' deviation from the chord and the deviation the chords may
        keep at their distance from the camera (core/tracing/dense.py)."""
        assert self._near is not None
        stray = np.linalg.norm(X - X_prev, axis=0) * np.sin(np.minimum(turn, 0.5 * np.pi))
        near = ok.copy()
        if self._clear > 0.0:
            out = np.maximum(np.linalg.norm(X_prev, axis=0), np.linalg.norm(X, axis=0)) + stray
            near &= (out >= self._clear) | (np.linalg.norm(camera, axis=0) <= self._clear)
        low = np.minimum(X_prev, X) - stray
        high = np.maximum(X_prev, X) + stray
        near &= segment_overlaps(low.T, high.T, *self._near)  # their bounds, as boxes
        if self._near_boxes is not None and near.any():  # each object's own box
            rows = np.flatnonzero(near)
            any_box = np.zeros(rows.size, dtype=bool)
            for lo, hi in self._near_boxes:
                any_box |= segment_overlaps(low[:, rows].T, high[:, rows].T, lo, hi)
            near[rows[~any_box]] = False
        c = np.flatnonzero(near)
        X0, X1 = X_prev[:, c], X[:, c]
        V0, V1, h = step_ends.velocities(c)
        allowed = CHORD_SHARE * self.options.tolerance * np.linalg.norm(X0 - camera[:, c], axis=0)
        allowed = allowed * self._allowance_scale(h0[c])
        return _NearPaths(c, X0, X1, V0, V1, h, dense.chord_deviation(X0, X1, V0, V1, h), allowed)

    def error_bound(self, step: float) -> float:
        """The step rule's bound C step^order (radians) on a run at ``step``, where it has a
        constant and ``step`` is within the steps it was measured at (0 elsewhere)."""
        constant = self.plan.error_constant
        if constant is None or self.order is None or step > self.plan.largest_step:
            return 0.0
        return constant * step**self.order

    def _allowance_scale(self, h0: np.ndarray) -> np.ndarray | float:
        """(K,) what the chords' allowance is scaled by on a run at a step below the rule's
        (a retrace, core.sampling): (h0 / step)^order, as its integration error is; 1 at
        the rule's step and above (the error pass's companion). A near miss traced again
        at half the step then has its hit test's slack fall with its error: at the rule's
        allowance a ray passing within it of an edge stayed near, and wrong, whatever the
        step (benchmarks/honesty.py thin_front: strips 0.07 rg wide missed after three
        retraces by rays the reference sees hit)."""
        if self.options.step is not None or self.method.adaptive or not self.order:
            return 1.0
        return np.minimum(h0 / self.step, 1.0) ** self.order

    def _bent_steps(self, paths: _NearPaths, chord, turn, ok, arrays) -> np.ndarray:
        """(M,) the steps near geometry to take again at half the step (down to
        2^-MAX_HALVINGS of the rule's): those whose chord turns from the ray's heading (its
        last chord's direction, ``turn``) by more than TURN_LIMIT, or whose cubic path
        deviates from its chord by more than BEND_LIMIT chord allowances, or whose pace
        changes by more than PACE_LIMIT over it. Hits are found on the cubic through a
        step's ends; a step in the Poincaré time covers a distance ~ r / M, so far from a
        small hole one step can jump past it (or back out of the region), and the cubic is
        then no path at all. A ray's step grows back (doubling) after a step at which twice
        the step would stay within all three (the bend grows 4x with it, the pace's log 2x;
        the turn is given 4x); its heading follows its accepted chords. A run at another
        step than the rule's (the error pass's companion, a retrace) has its limits scaled
        with it (the turn and the pace's log as the step, the bend as its square), so near
        geometry its steps stay in the ratio of its start's: two runs halved to the same
        steps there would agree on an error they share, and Richardson would see none.
        None with an explicit ``TraceOptions.step`` (step studies) or an adaptive method
        (its own control)."""
        h, h0, heading = arrays["h"], arrays["h0"], arrays["heading"]
        if self.options.step is not None or self.method.adaptive:
            return np.zeros(h.shape, dtype=bool)  # a step given is taken as given; dopri5
        near = np.zeros(h.shape, dtype=bool)
        near[paths.rows] = True
        scale = h0 / self.step  # a run at r x the rule's step keeps r x its steps here
        turn_limit, bend_limit = TURN_LIMIT * scale, BEND_LIMIT * scale[paths.rows] ** 2
        bent = near & (turn > turn_limit)
        allowed = paths.allowed / self._allowance_scale(h0[paths.rows])  # the rule's
        bent[paths.rows] |= paths.deviation > bend_limit * allowed
        with np.errstate(divide="ignore", invalid="ignore"):  # ln of the end speeds' ratio
            pace = np.abs(
                np.log(np.linalg.norm(paths.V1, axis=0) / np.linalg.norm(paths.V0, axis=0))
            )
        pace_limit = math.log(PACE_LIMIT) * scale[paths.rows]
        bent[paths.rows] |= pace > pace_limit
        close = near & (turn > 0.25 * turn_limit)
        close[paths.rows] |= (paths.deviation > 0.25 * bend_limit * allowed) | (
            pace > 0.5 * pace_limit
        )
        redo = ok & bent & (h > h0 * 0.5**MAX_HALVINGS)
        h[redo] *= 0.5
        grow = ok & ~redo & ~close & (h < h0)
        h[grow] = np.minimum(2.0 * h[grow], h0[grow])
        taken = ok & ~redo & np.isfinite(chord).all(axis=0)
        heading[:, taken] = chord[:, taken]
        return redo

    def _segments(self, idx, paths: _NearPaths, out: RayResults, step_ends: _StepEnds):
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
        (_land_on_disk). -> (M,) bool: the rays that hit a surface (recorded in ``out``).
        """
        hit_rows = np.zeros(idx.shape[0], dtype=bool)
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
            groups.append(_ChordGroup(c[g], path, int(n), limits, np.zeros(g.size, np.int64),
                                      np.arange(g.size)))  # fmt: skip
        while groups := [group for group in groups if group.going.size]:
            firsts = [self._first_hits(group) for group in groups]
            hits = Hits.concatenate([first.hits for first in firsts])
            cols = np.concatenate([group.cols[group.going] for group in groups])
            self._surface_crossing(cols, np.concatenate([f.guess for f in firsts]), hits,
                                   step_ends)  # fmt: skip
            offset = 0
            for group, first in zip(groups, firsts, strict=True):
                first.hits = hits.take(slice(offset, offset + group.going.size))
                offset += group.going.size
                ended, again = self._record_chords(idx, group, first, out, step_ends, landed)
                hit_rows[group.cols[group.going[ended]]] = True
                group.start[group.going[again]] = first.stop[again] + 1
                group.going = group.going[again]
        if landed:
            cols, u = (np.concatenate([x[i] for x in landed]) for i in (0, 1))
            off = self._land_on_disk(idx, cols, u, out, step_ends)
            hit_rows[cols[off]] = False
        return hit_rows

    def _record_chords(
        self, idx, group: _ChordGroup, first: _FirstHits, out: RayResults,
        step_ends: _StepEnds, landed: list,
    ) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
        """Record the chords of ``group``'s going rays in order, from each one's start to
        its first hit (``first``; its last chord where none), with the volumes' light up to
        the hit. Hits on an opaque disk are left in ``landed`` as (batch rows, fraction of
        the step); a translucent disk's are found by the method itself at once
        (_StepEnds.plane_crossing) and lit. -> (ended, again) (K,) bool: the rays that hit
        a surface; those to cast again from the chord after their hit (it did not end them).
        """
        rays = group.going
        start, cols = group.start[rays], group.cols[rays]
        ended = np.zeros(rays.size, dtype=bool)
        for j in range(int(start.min()), group.n):
            live = np.flatnonzero((start <= j) & (first.stop >= j))
            if live.size == 0:
                break
            a, b = first.ends[j, live], first.ends[j + 1, live]
            hits = Hits.miss(live.size)
            at = np.flatnonzero(first.stop[live] == j)
            hits.assign(at, first.hits, live[at])
            if self.disk is None or self.disk.opaque:
                got = self.geometry.record_hits(idx[cols[live]], a, b, hits, out)
                on = np.flatnonzero(got & (hits.object_id == DISK_ID))
                if on.size:
                    landed.append((cols[live[on]], first.guess[live[on]]))
            else:
                on = np.flatnonzero(hits.hit & (hits.object_id == DISK_ID))
                if on.size:
                    X, ok = step_ends.plane_crossing(cols[live[on]], first.guess[live[on]])
                    hits.position[on[ok]] = self._to_world(X[:, ok].T)
                got = self.disk.record_hits(
                    idx[cols[live]], a, b, hits, step_ends.state(cols[live]), out
                )
            ended[live[got]] = True
        again = first.found & ~ended & (first.stop + 1 < group.n)
        return ended, again

    def _first_hits(self, group: _ChordGroup) -> _FirstHits:
        """Cast the chords of ``group``'s going rays all at once, each ray's from its start;
        each ray's first hit refined on the cubic (_refine)."""
        rays = group.going
        n, k = group.n, rays.size
        points = group.path.points(np.arange(n + 1) / n, rays).reshape(3, -1)
        ends = self._to_world(points.T).reshape(n + 1, k, 3)
        cast = self.geometry.cast(ends[:-1].reshape(-1, 3), ends[1:].reshape(-1, 3))
        got = cast.hit.reshape(n, k) & (np.arange(n)[:, None] >= group.start[rays])
        found = got.any(axis=0)
        stop = np.where(found, got.argmax(axis=0), n - 1)
        hits = cast.take(stop * k + np.arange(k))
        guess = stop / n
        on = np.flatnonzero(found)
        guess[on] = dense.on_cubic(group.path, rays[on], stop[on] / n, 1.0 / n, hits.t[on])
        if found.any():
            limits = [x[rays] for x in group.limits]
            guess = self._refine(group.path, rays, hits, guess, stop / n, 1.0 / n, limits)
        return _FirstHits(ends, stop, found, hits, guess)

    def _land_on_disk(self, idx, cols, u, out: RayResults, step_ends: _StepEnds) -> np.ndarray:
        """The rays of the batch rows ``cols`` ended on an opaque disk at the fraction ``u``
        of this step (the cubic's): their hit points where the method crosses the disk
        (_StepEnds.plane_crossing; the cubic's stands where it does not converge), and the
        disk's light there. Where the method crosses the disk's plane off the disk (the
        cubic's hit lay within its slack of an edge), the ray did not hit it: its hit is
        undone and it goes on from the step's end. -> (M,) bool: those undone."""
        assert self.disk is not None
        X, ok = step_ends.plane_crossing(cols, u)
        rows = idx[cols]
        world = self._to_world(X.T)
        off = np.zeros(cols.size, dtype=bool)
        if ok.any():
            # across the plane (found to share |X|), along its normal
            near = 1e-3 * np.linalg.norm(X[:, ok], axis=0)[:, None] * self.rotation[:, 2]
            across = self.geometry.cast(world[ok] - near, world[ok] + near)
            off[ok] = ~(across.hit & (across.object_id == DISK_ID))
        out.position[rows[ok]] = world[ok]
        undone = rows[off]
        out.ending[undone], out.object_id[undone], out.surface[undone] = -1, -1, 0.0
        on = ~off
        self.disk.shade(rows[on], out.position[rows[on]], step_ends.state(cols[on]), out)
        return off

    def _refine(self, path: dense.CubicPath, live, hits, guess, t0, width: float, limits):
        """Where the chord [t0, t0 + width] (t0 a float or per ray) of the rays ``live`` hit,
        find the hit again on REFINE_PIECES finer chords of the cubic, all cast at once
        (REFINE_LEVELS times at most, while they deviate more than allowed); ``hits`` takes
        the refined hits, in place. A ray whose finer chords all miss (a grazing edge) keeps
        its chord's hit.
        -> ``guess`` (the hits' fractions of the step on the cubic) refined."""
        deviation, allowed = limits
        allowed = allowed * dense.HIT_SHARE
        todo = np.flatnonzero(hits.hit & (deviation > allowed))
        lo = np.broadcast_to(np.asarray(t0, dtype=np.float64), live.shape)[todo]
        guess = guess.copy()
        m = dense.REFINE_PIECES
        for _ in range(dense.REFINE_LEVELS):
            if todo.size == 0:
                break
            width /= m
            ta = (np.arange(m + 1) * width)[:, None] + lo  # (m + 1, R): sub-chords' ends
            ends = self._to_world(path.points(ta, live[todo]).reshape(3, -1).T)
            ends = ends.reshape(m + 1, todo.size, 3)  # sub-chord i of ray k: i -> i + 1
            sub = self.geometry.cast(ends[:-1].reshape(-1, 3), ends[1:].reshape(-1, 3))
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

    def _surface_crossing(self, cols, u, hits, step_ends: _StepEnds) -> None:
        """Surface hits (``hits`` of the batch rows ``cols``, not the disk's) moved to where
        the method itself meets the surface, in place (_StepEnds.crossing from the cubic's
        fraction ``u``; each straight move cast along the velocity both ways, the nearer
        hit on the same object taken; where it does not converge the cubic's hit stands).
        The cubic follows the path to O(h^4) with a constant far above the symplectic
        methods' (1/384 against ~1e-5) and varying with where in a step the surface falls:
        its hits converged erratically (observed order 1-7 on Schwarzschild and the mirage)
        and step doubling misjudged their error (under 1/3 of it on 40-55 % of them)."""
        on = np.flatnonzero(hits.hit & (hits.object_id != DISK_ID))
        if on.size == 0:
            return
        found = Hits.miss(on.size)
        h = step_ends.h if np.ndim(step_ends.h) == 0 else step_ends.h[cols[on]]
        beside = np.zeros(on.size, dtype=bool)  # the method's point passes the object by

        def to_surface(todo, X, V):
            # both ways along V, as far as the step reaches: the nearer hit on the object
            reach = np.abs(h if np.ndim(h) == 0 else h[todo]) * V
            ahead = self.geometry.cast(self._to_world(X.T), self._to_world((X + reach).T))
            back = self.geometry.cast(self._to_world(X.T), self._to_world((X - reach).T))
            same = hits.object_id[on[todo]]
            ahead.hit &= ahead.object_id == same
            back.hit &= back.object_id == same
            take_back = back.hit & (~ahead.hit | (back.t < ahead.t))
            pick = np.where(take_back[:, None], back.position, ahead.position)
            move = self._to_local(pick).T - X
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

    def _watch_segments(self, rows, a, b, out: RayResults, eye=None, bend=None, share=None):
        """Lower the clearance of the rays ``rows`` to that of their world chords a -> b
        seen from ``eye`` (default: a, the camera), bent into their cubic paths by
        ``bend``, within ``share`` (M,) of the margin each (see ClearanceBoxes.record)."""
        if self._watch is not None:
            self._watch.record(rows, a, b, a if eye is None else eye, out, bend, share)

    def _finish_energy(self, out, rows, Q, P, H0):
        with np.errstate(all="ignore"):
            out.energy_error[rows] = np.abs(self.model.value_soa(Q, P) - H0)

    def _leave(self, batch: Batch, leaving, X_prev, X, ends: _StepEnds, out) -> None:
        """The rays ``leaving`` ((M,) bool) left the region in this step (from X_prev to X,
        ``ends``): out along their escape direction (``_escape``), or where a model without a
        mass crosses the sphere (``_leave_at_boundary``)."""
        idx, camera = batch.arrays["idx"], ends.camera
        rest = leaving.copy()
        if self._cut_at_boundary:
            rest &= ~self._leave_at_boundary(idx, np.flatnonzero(leaving), X_prev, X, ends, out)
        if rest.any():
            Q, P = ends.end
            shares = batch.arrays.get("axial")
            self._escape(
                idx[rest], Q[:, rest], P[:, rest], self._to_world(X[:, rest].T), out,
                self._to_world(camera[:, rest].T),
                [d[..., rest] for d in self.method.tangents_of(batch.state)],
                None if shares is None else shares[..., rest],
            )  # fmt: skip

    @property
    def _cut_at_boundary(self) -> bool:
        """Whether rays leave the region where they cross its boundary
        (``_leave_at_boundary``): models without a mass (user metrics' spheres, media's
        boxes), whose field beyond the region no far field stands for."""
        return self.mass == 0.0

    def _leave_at_boundary(self, idx, cols, X_prev, X, ends: _StepEnds, out) -> np.ndarray:
        """The rays of the batch rows ``cols``, past the region's boundary at this step's
        end, leave it where the method itself crosses it (``_StepEnds.crossing``), along
        their velocity there, straight on. A model without a mass has no far field for the
        rest of its field: a ray leaving at its step's end took in the field up to there,
        which the step's size decided (benchmarks/honesty.py user_metric at 1 px: errors
        of 1e-3 px, erratic in the step, 3x above the estimate on 1.4 % of the pixels; a
        Maxwell fish-eye's box, where n is 0.62: first order in the step, and the run at
        twice the step, leaving at the same step end, estimated 1e-7 of it, issue 50); at
        the boundary every run leaves at the same place. A medium's ray leaving its box where
        its index jumps (``Medium.face_jump``) is failed (an unbounded medium's sphere is
        not its box: its rays go on straight there, as before). -> (M,) bool: the rows done (where
        the crossing did not converge the step's end stands: ``_escape``)."""
        region = self.region
        assert region is not None
        done = np.zeros(X.shape[1], dtype=bool)
        u = region.exit_time(X_prev[:, cols], X[:, cols] - X_prev[:, cols])
        crossing, ok, V = ends.crossing(
            cols, np.clip(np.nan_to_num(u, nan=1.0), 0.0, 1.0),
            lambda todo, Xt, Vt: region.exit_time(Xt, Vt) * Vt, with_velocity=True,
            strict=True,
        )  # fmt: skip
        ok &= np.isfinite(V).all(axis=0) & (np.linalg.norm(V, axis=0) > 0)
        if not ok.any():
            return done
        rows = cols[ok]
        bad = np.zeros(rows.size, dtype=bool)
        if isinstance(region, BoxRegion) and hasattr(self.model, "face_jump"):  # a medium's box
            bad = self.model.face_jump(crossing[:, ok])
        if bad.any():  # an interface the medium's box cuts: no plausible colour
            out.ending[idx[rows[bad]]] = ENDING["failed"]
            out.position[idx[rows[bad]]] = self._to_world(crossing[:, ok][:, bad].T)
        go = ~bad
        D = (V[:, ok][:, go] / np.linalg.norm(V[:, ok][:, go], axis=0)).T @ self.rotation.T
        world = self._to_world(crossing[:, ok][:, go].T)
        eye = self._to_world(ends.camera[:, rows[go]].T)
        self._straight(idx[rows[go]], world, D, out, eye)
        done[rows] = True
        return done

    def _escape(self, rows, Q, P, world, out: RayResults, eye, tangents=(), shares=None):
        """Rays leaving the region: direction from dq/ds, far-field correction, straight on
        (with ``tangents`` (dQ, dP) (k, n, M): the escape direction's derivatives too; with
        ``shares``, the traced tangent's expanded into the camera's k: axial_final)."""
        d_world = self._escape_direction(Q, P)
        self._straight(rows, world, d_world, out, eye)
        failed = ~np.isfinite(d_world).all(axis=1)
        out.ending[rows[failed]] = ENDING["failed"]
        if len(tangents) == 2:
            n = Q.shape[0]

            def escape(z: np.ndarray) -> np.ndarray:
                return self._escape_direction(z[:, :n].T.copy(), z[:, n:].T.copy())

            Z = np.concatenate([Q, P]).T
            dZ = np.moveaxis(np.concatenate(tangents, axis=1), -1, 0)  # (M, k, 2n)
            jacobian = directional(escape, Z, dZ)
            if shares is not None:  # the cameras' axes: eye - centre, in world axes
                axis = eye - self.scene.center
                axis /= np.linalg.norm(axis, axis=1, keepdims=True)
                jacobian = axial_final(shares, jacobian, d_world, axis)
            sky = out.ending[rows] == ENDING["escaped"]
            out.sky_jacobian[rows[sky]] = jacobian[sky]

    def _escape_direction(self, Q: np.ndarray, P: np.ndarray) -> np.ndarray:
        """Unit world directions (M, 3) rays leave the region along from (Q, P) (n, M): the
        velocity dX/dσ, bent by the rest of the far field (``_far_field``)."""
        S = Q[self.chart.offset :]
        _, dHdp = self.model.gradient_soa(Q, P, wrt="p")
        V = self.chart.cartesian_velocity(S, dHdp[self.chart.offset :])
        D = (V / np.linalg.norm(V, axis=0)).T
        return self._far_field(self.chart.to_cartesian(S).T, D) @ self.rotation.T

    def _far_field(self, X, D):
        """Bend directions D (M, 3) at X by the rest of the first-order deflection of a mass.

        A straight ray from X along D passes the mass M at impact b; it still turns by
        (2M/b)(1 - cos psi) towards the mass (cos psi = X.D/|X|, impulse approximation),
        i.e. by 2M b / (r (r + X.D)) (1 - cos psi = b^2 / (r (r + X.D))): written so, the
        turn (its angle times the unit vector towards the mass) is -2M perp / (r (r + X.D))
        with perp = X - (X.D) D, free of the cancellations of 1 - cos psi and of perp / b
        on rays leaving nearly radially.
        """
        if self.mass == 0.0:
            return D
        r = np.linalg.norm(X, axis=1)
        along = np.einsum("ij,ij->i", X, D)
        perp = X - along[:, None] * D  # from the ray's line to X, ⟂ D
        with np.errstate(all="ignore"):
            turn = (-2.0 * self.mass / (r * (r + along)))[:, None] * perp
        angle = np.linalg.norm(turn, axis=1)
        return np.cos(angle)[:, None] * D + np.sinc(angle / np.pi)[:, None] * turn

    # --- frames ------------------------------------------------------------------------
    def _to_local(self, world):
        return (world - self.scene.center) @ self.rotation

    def _to_world(self, local):
        return local @ self.rotation.T + self.scene.center


def _bends(paths: _NearPaths | None, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(P, R) (3, n) that bend each of a batch's n step chords X0 -> X1 into the cubic
    path the hit test follows (core/tracing/dense.py), P = X0 - X1 + h V0 and R = X0 - X1
    + h V1, and (n,) the slack of its hit test: how far the chords it casts stray from the
    cubic (dense.pieces), where the step passes near geometry (``paths``); elsewhere 0
    (the chord). A path curving towards an object between its ends comes closer to it
    than its chord (a mirage's ray dips below it over hot ground), and an object within
    the slack of the cubic may be hit or missed whatever the chords cast say."""
    P, R, slack = np.zeros((3, n)), np.zeros((3, n)), np.zeros(n)
    if paths is not None:
        P[:, paths.rows] = paths.X0 - paths.X1 + paths.h * paths.V0
        R[:, paths.rows] = paths.X0 - paths.X1 + paths.h * paths.V1
        slack[paths.rows] = paths.deviation / (paths.pieces * paths.pieces)
    return P, R, slack


def _turn(X_prev: np.ndarray, X: np.ndarray, heading: np.ndarray) -> tuple:
    """(unit chords X_prev -> X (3, M), their angles from ``heading`` (M,); 0 where not
    finite)."""
    with np.errstate(all="ignore"):
        chord = (X - X_prev) / np.linalg.norm(X - X_prev, axis=0)
        turn = np.arccos(np.clip(np.einsum("im,im->m", chord, heading), -1.0, 1.0))
    return chord, np.where(np.isfinite(turn), turn, 0.0)


@dataclass
class _ChordGroup:
    """The rays of a step that follow their cubic paths on n chords (Tracer._segments)."""

    cols: np.ndarray  # (M,) batch rows
    path: dense.CubicPath
    n: int
    limits: tuple  # (a chord's deviation (M,), allowed (M,))
    start: np.ndarray  # (M,) the first chord each ray casts
    going: np.ndarray  # the rays (indices into cols) still to cast


@dataclass
class _FirstHits:
    """Each ray's first hit on its chords from its start (Tracer._first_hits)."""

    ends: np.ndarray  # (n + 1, K, 3) the chords' ends, world
    stop: np.ndarray  # (K,) the chord of the first hit (n - 1 where none)
    found: np.ndarray  # (K,) bool: a hit was found there (the method's path may miss it)
    hits: Hits  # (K,) the hit, refined on the cubic
    guess: np.ndarray  # (K,) the hit's fraction of the step on the cubic


@dataclass
class _NearPaths:
    """Steps near geometry (Tracer._near_paths): their rows in the batch, local ends and
    velocities (3, K), step sizes, cubic deviations from the chords and allowances (K,)."""

    rows: np.ndarray
    X0: np.ndarray
    X1: np.ndarray
    V0: np.ndarray
    V1: np.ndarray
    h: Any
    deviation: np.ndarray
    allowed: np.ndarray

    def without(self, rows: np.ndarray) -> _NearPaths:
        """These paths less those of the batch rows ``rows`` ((M,) bool)."""
        keep = ~rows[self.rows]
        h = self.h if np.ndim(self.h) == 0 else self.h[keep]
        return _NearPaths(
            self.rows[keep], self.X0[:, keep], self.X1[:, keep], self.V0[:, keep],
            self.V1[:, keep], h, self.deviation[keep], self.allowed[keep],
        )  # fmt: skip

    @cached_property
    def pieces(self) -> np.ndarray:
        """(K,) chords the hit test casts per step (dense.pieces), shared by the hit test
        (Tracer._segments) and the clearance's slack (_bends)."""
        return dense.pieces(self.deviation, self.allowed)


class _StepEnds:
    """A step's two ends (Q, P) and size, with the local Cartesian velocities dX/dσ there
    for the rays that need them (surfaces near their path)."""

    def __init__(
        self, tracer: Tracer, K: Any, start: tuple, end: tuple, h: Any, camera: np.ndarray
    ) -> None:
        self.tracer, self.K, self.start, self.end, self.h = tracer, K, start, end, h
        self.camera = camera

    def state(self, rows: np.ndarray) -> list[np.ndarray]:
        """(Q, P, camera) at the step's end of the rays ``rows`` (the disk's light)."""
        Q, P = self.end
        return [Q[:, rows], P[:, rows], self.camera[:, rows]]

    def velocities(self, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, Any]:
        """(V at the start, V at the end, h) of the rays ``rows``, each V (3, M)."""
        both = np.concatenate([rows, rows])  # one call for both ends: one call's overhead
        Q, P = (np.concatenate([a[:, rows], b[:, rows]], axis=1)
                for a, b in zip(self.start, self.end, strict=True))  # fmt: skip
        V = self._velocity(self.K.subset(both), Q, P)
        h = self.h if np.ndim(self.h) == 0 else self.h[rows]
        return V[:, : rows.size], V[:, rows.size :], h

    def plane_crossing(self, rows: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Where the rays ``rows`` cross the local plane z = 0 within this step (``crossing``
        from the cubic's estimate u): -> (X (3, M), ok (M,)); not ok where it did not
        converge inside the step (the cubic's point stands). The disk's g depends on where
        the ray crosses it, which the cubic only finds to O(h^4) (long split steps)."""

        def to_plane(todo, X, V):
            with np.errstate(all="ignore"):
                return -(X[2] / V[2]) * V

        return self.crossing(rows, u, to_plane)

    def crossing(
        self, rows: np.ndarray, u: np.ndarray, offset, with_velocity: bool = False,
        strict: bool = False,
    ):  # fmt: skip
        """Newton's method on the fraction u of this step where the rays ``rows`` meet a
        surface: X(u) by the method's own partial step from the step's start, then
        ``offset(todo, X, V)`` -> the straight move (3, M) along the velocity V from X to the
        surface (NaN: none), u moved by its length. -> (X + move (3, M), ok (M,)): ok once
        the move is at most CROSSING_REACH sqrt(share) |X| (or |X| share) with u inside the
        step, within CROSSING_ITERATIONS; a straight move that short is off the path by
        at most CROSSING_REACH^2 share |X| (share = CROSSING_SHARE x tolerance). With
        ``with_velocity``, also V (3, M) there; ``strict``: ok only once the move is at most
        share |X| (V turns over a longer move by more than the tolerance allows)."""
        K = self.K.subset(rows)
        Q0, P0 = (x[:, rows] for x in self.start)
        h = self.h if np.ndim(self.h) == 0 else self.h[rows]
        u = np.asarray(u, dtype=np.float64).copy()
        X = np.full((3, rows.size), np.nan)
        velocity = np.full((3, rows.size), np.nan)
        ok = np.zeros(rows.size, dtype=bool)
        share = CROSSING_SHARE * self.tracer.options.tolerance
        reach = 0.0 if strict else CROSSING_REACH * math.sqrt(share)
        todo = np.arange(rows.size)  # the rays not yet there
        with np.errstate(all="ignore"):
            for _ in range(CROSSING_ITERATIONS):
                Kt = K.subset(todo) if todo.size < rows.size else K
                ht = h if np.ndim(h) == 0 else h[todo]
                Xt, V, good = self._partial(Kt, Q0[:, todo], P0[:, todo], u[todo] * ht)
                move = offset(todo, Xt, V)
                finite = good & np.isfinite(move).all(axis=0)
                du = np.einsum("im,im->m", move, V) / (ht * np.einsum("im,im->m", V, V))
                size, length = np.linalg.norm(Xt, axis=0), np.linalg.norm(move, axis=0)
                inside = (u[todo] + du >= 0.0) & (u[todo] + du <= 1.0)
                there = finite & ((length <= share * size) | (inside & (length <= reach * size)))
                X[:, todo], ok[todo], velocity[:, todo] = Xt + move, there, V
                left = ~there
                u[todo[left]] = np.clip(u[todo[left]] + np.where(finite, du, 0.0)[left], 0, 1)
                todo = todo[left]
                if todo.size == 0:
                    break
        return (X, ok, velocity) if with_velocity else (X, ok)

    def _partial(self, K: Any, Q0: np.ndarray, P0: np.ndarray, step) -> tuple:
        method, chart = self.tracer.method, self.tracer.chart
        state, good = method.step(K, method.init(K, Q0.copy(), P0.copy()), step)
        Q, P = method.qp(state)
        return chart.to_cartesian(Q[chart.offset :]), self._velocity(K, Q, P), good

    def _velocity(self, K: Any, Q: np.ndarray, P: np.ndarray) -> np.ndarray:
        chart = self.tracer.chart
        _, dp = K.gradient_soa(Q, P, wrt="p")
        with np.errstate(all="ignore"):
            return chart.cartesian_velocity(Q[chart.offset :], dp[chart.offset :])

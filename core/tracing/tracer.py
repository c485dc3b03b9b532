"""Batch tracing of curved rays through a scene (no Blender): the coordinating ``Tracer``.

A ray starts as a straight line from the camera. Where the model bends light (inside
its *region*: a sphere around a black hole, a medium's box) it follows Hamilton's
equations, integrated in the Poincaré-transformed fictitious time with a fixed step;
outside it moves straight, analytically. Every step's straight segment is tested
against the scene's intersector, only where the segment's bounds meet the geometry's.
Rays end as escaped, captured, hit, failed or max_steps (``ENDING``); ended rays leave
the batch, so the work per step shrinks as the image resolves.

Interface: ``Tracer(scene, options, extent, objects=None)``: ``trace``, ``watch_geometry``,
``without_clearance``, ``set_motion``, ``supports_tangents`` / ``check_tangents``,
``error_bound``, ``objects`` and what it holds (``TracerState``: the plan's attributes,
frame, geometry, disk, motion). ``TraceOptions``, ``TracePlan``, ``plan_trace`` and
``tracing_model`` (core/tracing/plan.py) and the step rule's and crossings' constants are
re-exported here. The work is done by one module per subject, functions of the tracer:
``starts`` (rays' start states and differentials, the camera's motion), ``step_loop`` (the
batch loop and each step's events), ``near_geometry`` (steps near geometry, halved where
bent), ``crossings`` (chords, first hits, the method's surface crossings), ``step_ends``
(a step's ends, Newton on the fraction of a step), ``disk_landing`` (rays ending on an
opaque disk), ``escape`` (straight parts, leaving the region, the far field) and
``watching`` (the clearance recorded per step).
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from typing import Any

import numpy as np

from ..backend import array_module
from ..motion import Motion
from . import shared_rounds, starts
from .clearance import ClearanceBoxes
from .differentials import magnification
from .escape import far_field, straight
from .near_geometry import BEND_LIMIT, CHORD_SHARE, MAX_HALVINGS, PACE_LIMIT, TURN_LIMIT
from .plan import TraceOptions, TracePlan, plan_trace, tracing_model
from .scene import ENDING
from .segments import RayResults
from .starts import start_results
from .step_ends import CROSSING_ITERATIONS, CROSSING_REACH, CROSSING_SHARE
from .step_loop import trace_curved
from .tracer_state import NEAR_BOXES, TracerState

__all__ = [
    "BEND_LIMIT",
    "CHORD_SHARE",
    "CROSSING_ITERATIONS",
    "CROSSING_REACH",
    "CROSSING_SHARE",
    "MAX_HALVINGS",
    "NEAR_BOXES",
    "PACE_LIMIT",
    "TURN_LIMIT",
    "TraceOptions",
    "TracePlan",
    "Tracer",
    "plan_trace",
    "tracing_model",
]


class Tracer(TracerState):
    """Traces batches of world-space rays through one scene with fixed options (its plan:
    ``plan_trace``; what it holds: ``TracerState``)."""

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
        shared = shared_rounds.joined()
        if shared is not None:  # a member of shared rounds: traced with the others' calls
            return shared.trace(self, origins, directions, step=step, cancel=cancel,
                                tangents=tangents, clearance=clearance)  # fmt: skip
        out, static_tangents = start_results(self, origins, directions, tangents)
        directions = out.direction.copy()  # the static observer's
        if not self.curved:
            straight(self, array_module(origins).arange(n), origins, directions, out)
            if tangents is not None:
                out.sky_jacobian[:] = static_tangents
        else:
            trace_curved(self, origins, directions, step, cancel, static_tangents, out, clearance)
        if tangents is not None:  # per the camera's own solid angle (a moving one's)
            out.sky_jacobian[out.ending != ENDING["escaped"]] = np.nan
            out.magnification = magnification(tangents, out.sky_jacobian)
        return self._besides_hit(out)

    @property
    def supports_tangents(self) -> bool:
        """Whether ``trace`` can carry ray differentials here: flat space, or a splitting on
        a split whose flows take derivatives (``SplitSystem.tangents``)."""
        return starts.supports_tangents(self)

    def check_tangents(self) -> None:
        """ValueError naming why this trace cannot carry ray differentials, if it cannot."""
        starts.check_tangents(self)

    def error_bound(self, step: float) -> float:
        """The step rule's bound C step^order (radians) on a run at ``step``, where it has a
        constant and ``step`` is within the steps it was measured at (0 elsewhere)."""
        constant = self.plan.error_constant
        if constant is None or self.order is None or step > self.plan.largest_step:
            return 0.0
        return constant * step**self.order

    def _besides_hit(self, out: RayResults) -> RayResults:
        """``out`` with each hit ray's clearance from everything but what it hit."""
        if self._watch is not None:
            out.clearance = self._watch.besides_hit(out)
        return out

    def _far_field(self, X: np.ndarray, D: np.ndarray) -> np.ndarray:
        """Directions D (M, 3) at X bent by the rest of the mass's deflection
        (escape.far_field)."""
        return far_field(self.mass, X, D)

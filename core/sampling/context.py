"""A tile's context: the sampler's settings, the tile's state, and tracing image points.

Offers ``TileContext``: what every step of rendering a tile reads (the tracer, camera,
background and shading, the render's Tolerances (core.tolerances: interpolation, the error
pass's budget, the far field), samples and filter), the tile's state (its lattice's
origin in the image, its ray counts), ``image_xy`` (lattice points to image points) and
``trace_points`` (camera rays through image points, with their Richardson error from a
companion run: ``companion_error``, ``bound_applies``). The steps themselves
(core.sampling's other modules) are functions of a TileContext; core.sampling's
TileSampler is one. Needs core.tracing's Tracer and core.sampling.error.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from ..sky import Background
from ..tolerances import Tolerances
from ..tracing import ENDING, RayResults, Tracer
from .error import (
    COMPANION_RATIO,
    DOUBT_BELOW,
    DOUBTED,
    richardson_error,
    seen_direction,
    shared_steps,
)
from .filters import stratified_points

Cancel = Callable[[], bool] | None
"""A tile's cancel test (None: never cancelled)."""


class TileContext:
    """The settings of a tile sampler and the state of the tile it renders (see the module
    docstring)."""

    def __init__(
        self,
        tracer: Tracer,
        camera,
        background: Background,
        shade: Callable[[RayResults, Background], np.ndarray],
        tolerances: Tolerances,
        *,
        samples: int = 1,
        pixel_filter: str = "box",
        filter_size: float = 1.0,
        with_error: bool = False,
        tangents: bool = False,
        magnification: bool = False,
    ) -> None:
        self.tracer, self.camera, self.background, self.shade = tracer, camera, background, shade
        self._colour_tracer = (
            tracer.without_clearance()
        )  # for sub-pixel samples (supersample.sample)
        self.tolerances = tolerances  # made once by core.render; its radians, read below
        self.interpolation = tolerances.interpolation  # 0: trace every pixel
        self.samples = int(samples)
        self.unit = stratified_points(self.samples)  # (S, 2), jittered per pixel
        self.pixel_filter, self.filter_size = pixel_filter, filter_size
        extent = 1.0 if pixel_filter == "box" else filter_size
        self.footprint = extent / math.sqrt(2)  # pixels from the centre to its corners
        self.with_error = with_error and tracer.curved
        self.step = tracer.step  # a node's first run's (retraces halve it)
        self.far_field = tolerances.far_field  # error of escaped rays beyond the region
        self.pixel_angle = tolerances.pixel_angle  # radians a pixel (core.Camera.pixel_angle)
        self.budget = tolerances.budget  # a traced ray's integration error above it is redone
        self.with_tangents = tangents  # ray differentials: sky footprints, magnification
        self.with_magnification = magnification  # the pass: blocks where ln |μ| is bilinear
        self.origin = (0, 0)  # image (row, column) of the current tile's node (0, 0)
        self.rays = 0
        self.error_rays = 0  # companions and retraces
        self.companion_rays = 0

    def trace_points(
        self,
        xy: np.ndarray,
        cancel: Cancel,
        companion: bool | np.ndarray = True,
        step: float | np.ndarray | None = None,
        node: bool = True,
        margin: np.ndarray | float = 1.0,
    ) -> tuple[RayResults, np.ndarray, np.ndarray | None]:
        """Trace camera rays through image points xy (M, 2) at ``step`` (default: the
        tracer's) -> (rays, seen directions, and with the error pass (and ``companion``)
        their Richardson error in radians from a companion run at COMPANION_RATIO x the
        step; sub-pixel samples need none: the pass reports pixel centres). Nodes (``node``)
        carry ray differentials where the sampler takes them; other points (samples) no
        clearance (Tracer.without_clearance: their colour is all the sampler takes); nodes
        record it within ``margin`` of the tracer's (a share, one or per point:
        lattice.node_margin). ``companion`` may name the points (M,) bool that get one: the
        others' error is NaN."""
        origins, directions = self.camera.rays_at(xy)
        n = xy.shape[0]
        share = np.broadcast_to(np.asarray(margin, np.float64), (n,))
        self.rays += n if step is None else 0
        step = self.step if step is None else step
        seen = self.camera.direction_tangents(xy) if self.with_tangents and node else None
        if not self.with_error or companion is False:
            tracer = self.tracer if node else self._colour_tracer  # a sample's colour alone
            rays = tracer.trace(origins, directions, step=step, cancel=cancel, tangents=seen,
                                clearance=share if node else None)  # fmt: skip
            return rays, seen_direction(rays, origins), None
        assert isinstance(step, float)  # a first run's (retraces run one a ray, alone)
        some = np.flatnonzero(np.broadcast_to(companion, (n,)))
        if seen is None:  # one batch: the companion shares the main run's per-step overhead
            both = self.tracer.trace(
                np.concatenate([origins, origins[some]]),
                np.concatenate([directions, directions[some]]),
                step=np.repeat([step, COMPANION_RATIO * step], [n, some.size]),
                cancel=cancel,
                clearance=np.concatenate([share, np.zeros(some.size)]),  # the companion's: unread
            )
            rays, coarse = both.take(slice(0, n)), both.take(slice(n, None))
        else:  # the companion needs no differentials: a batch of its own costs less than
            # carrying them through its half of a shared batch (benchmarks/frame.py)
            rays = self.tracer.trace(origins, directions, step=step, cancel=cancel,
                                     tangents=seen, clearance=share)  # fmt: skip
            coarse = self.tracer.trace(origins[some], directions[some],
                                       step=COMPANION_RATIO * step, cancel=cancel,
                                       clearance=np.zeros(some.size))  # fmt: skip
        self.error_rays += some.size
        self.companion_rays += some.size
        error = np.full(n, np.nan)
        error[some] = self.companion_error(rays.take(some), coarse, origins[some], step)
        return rays, seen_direction(rays, origins), error

    def companion_error(
        self, rays: RayResults, coarse: RayResults, origins: np.ndarray, step: float
    ) -> np.ndarray:
        """(M,) the error of ``rays`` run at ``step`` from their companion ``coarse``
        (Richardson; doubted where both took the same steps; at least the rule's bound
        where the companion ran past its range); captured rays neither."""
        assert self.tracer.order is not None  # a companion run: the scene is curved
        error = richardson_error(rays, coarse, origins, self.tracer.order)
        seen = rays.ending != ENDING["captured"]  # the shadow's inside has no direction
        error = np.where(seen, self._doubted(error, rays.steps, coarse.steps), error)
        return np.where(seen, np.maximum(error, self._bound(step)), error)

    @property
    def first_step(self) -> float:
        """A node's first run's step (the tracer's), where there is one: a curved scene's."""
        assert self.step is not None
        return self.step

    def _bound(self, step: float) -> float:
        """The least error a run at ``step`` reports from its companion: where the companion
        runs past the steps the rule's constant was measured at (the step at the rule's
        cap), Richardson compares with a run outside its asymptotic range (Schwarzschild
        at the cap, 1.0: errors at 2 h were 0.3-4x those at h, at h / 2 1/16 of them; the
        estimate read 0.03-0.3 of the truth on 2.6-2.8 % of benchmarks/honesty.py
        schwarzschild's pixels at every tolerance), and the rule's bound C h^order at h
        stands in; within the rule's range, none (Richardson's own)."""
        return self.tracer.error_bound(step) if self.bound_applies(step) else 0.0

    def bound_applies(self, step: float | None) -> bool:
        """Whether a run at ``step``'s companion runs past the rule's largest step."""
        return step is not None and COMPANION_RATIO * step > self.tracer.plan.largest_step

    def _doubted(self, error: np.ndarray, steps: np.ndarray, other_steps: np.ndarray) -> np.ndarray:
        """``error`` raised above the retrace budget where the two runs it compares took
        about as many steps (shared_steps) and agree within DOUBT_BELOW x the budget:
        Richardson then compared a run with itself. Not asked of captured rays (by
        trace_points): the shadow's inside has no direction to be wrong, its runs agree
        exactly whatever their steps, and a ray near its edge circles the photon orbit in
        steps of its own (a flip shows as one); doubted, every captured ray of a camera at
        3 rg was traced again (benchmarks/honesty.py orbit_disk: 2 error runs an image ray)."""
        shared = shared_steps(steps, other_steps) & (error < DOUBT_BELOW * self.budget)
        if not math.isfinite(self.budget):
            return error
        return np.where(shared, np.maximum(error, DOUBTED * self.budget), error)

    def image_xy(self, y: np.ndarray, x: np.ndarray) -> np.ndarray:
        """Image points (M, 2) (column, row) of lattice points (y, x) of the current tile."""
        return np.stack([self.origin[1] + x + 0.5, self.origin[0] + y + 0.5], axis=1)

"""What a tracer holds for one scene and options (the state the tracing modules share).

Interface: ``TracerState(scene, options, extent, objects=None)`` (``objects``: the scene's
intersector, where made already): a PlacedPlan (core/tracing/plan.py: the
plan, ``plan``, and its ``curved``, ``model``, ``method``, ``order``, ``chart``, ``region``,
``step``, ``captured``; the scene's ``rotation`` and frame, ``_to_local`` / ``_to_world``),
its ``geometry`` and the local boxes
a step is near geometry by (``_near``, ``_near_boxes``: up to NEAR_BOXES; ``_clear``), the
``stepper``, the disk's light (``disk``), the camera's ``motion`` and the clearance watched
(``_watch``, ``_watch_near``, ``_watch_segments``). ``Tracer`` (core/tracing/tracer.py) is
one, with the public methods; the tracing modules take it as ``tracer``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..geometry.boxcells import ManyBoxes
from ..motion import Motion
from .clearance import ClearanceBoxes, clear_radius
from .disklight import DiskLight
from .plan import PlacedPlan, TraceOptions
from .scene import Scene
from .segments import RayResults, SceneGeometry
from .stepping import Stepper

NEAR_BOXES = 16
"""Up to this many objects and volumes, steps are near geometry by each one's own box
(TracerState._near_boxes), one test a box ..."""
NEAR_MANY = 1 << 20
"""... up to this many, by each one's own box still, tested all at once
(TracerState._near_many: core.geometry.boxcells.ManyBoxes); more, by their union's box
(10^5 spheres around a Schwarzschild hole, 40 x 30: 5.4 s by their own boxes, 12.4 s by
their union's)."""


class TracerState(PlacedPlan):
    """What a tracer holds for one scene and options: its plan's attributes, the model's
    frame (``_to_local`` / ``_to_world``), the geometry and the local boxes steps are near
    geometry by, the disk's light, the camera's motion and the clearance being watched."""

    disk: DiskLight | None = None
    motion: Motion | None = None
    """The camera's motion (set_motion): rays start along the static observer's directions."""
    _watch: ClearanceBoxes | None = None  # Tracer.watch_geometry
    _clear = 0.0
    """Inside an accretion disk's inner edge (or a nearer object's) no step is near geometry
    (near_geometry.near_paths). Only with a disk: without one, a ball out to the nearest
    object let the steps near the hole grow to the rule's and the error pass under-reported them
    (benchmarks/honesty.py thin_front at 0.05 px: 1 -> 9 pixels over 3x the tolerance);
    inside a disk's inner edge (rays captured or winding in the photon ring) the
    honesty family showed no loss (disk_high_spin: under-reported 3.71 -> 3.60 %)."""
    _watch_near: tuple[np.ndarray, np.ndarray] = (np.full(3, -np.inf), np.full(3, np.inf))
    _near_boxes: list[tuple[np.ndarray, np.ndarray]] | None = None
    """Each object's (and volume's) local box, where there are 2 to NEAR_BOXES: a step is
    near geometry where its path may pass one of them, not only their union's box."""

    def __init__(
        self, scene: Scene, options: TraceOptions, extent: float = 1.0, objects: Any = None
    ) -> None:
        """The plan of ``scene`` with ``options`` (PlacedPlan), and what it needs;
        ``objects``: the scene's intersector (``scene.intersector()``) where already made."""
        objects = scene.intersector() if objects is None else objects
        self.geometry = SceneGeometry(objects, list(scene.volumes))
        super().__init__(scene, options, extent)
        self.stepper: Stepper | None = None
        self._near: tuple[np.ndarray, np.ndarray] | None = None
        if not self.curved:
            return
        if scene.disk is not None:
            self.disk = self._disk_light(scene)
        self.stepper = Stepper(self.method, self.model, self.captured)
        self._near = self.geometry.local_box(self._to_local)
        count = 0 if self._near is None else self.geometry.box_count()
        if 1 < count <= NEAR_BOXES:
            self._near_boxes = self.geometry.local_boxes(self._to_local)
        elif NEAR_BOXES < count <= NEAR_MANY:
            self._near_many = _near_many(self.geometry, self._to_local)
        if scene.disk is not None:  # the disk's inner edge, or a nearer object
            self._clear = clear_radius(self.geometry.boxes(), np.asarray(scene.center, float))

    _near_many: ManyBoxes | None = None
    """From NEAR_BOXES to NEAR_MANY objects and volumes, their local boxes, tested at once
    (the same answers as _near_boxes': a step is near where its path may pass one), not
    their union's box (60 spheres around a Schwarzschild hole, benchmarks/honesty.py
    sphere_cloud: every step in the shell they fill was near, its steps halved by the
    bend, turn and pace limits; 3-4x the time, and no more honest)."""

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

    def _watch_segments(
        self, rows, a, b, out: RayResults, eye=None, bend=None, share=None, until=None
    ):
        """Lower the clearance of the rays ``rows`` to that of their world chords a -> b
        seen from ``eye`` (default: a, the camera), bent into their cubic paths by
        ``bend``, within ``share`` (M,) of the margin each, up to ``until`` (M,) of each
        chord (its ray's hit; see ClearanceBoxes.record)."""
        if self._watch is not None:
            self._watch.record(rows, a, b, a if eye is None else eye, out, bend, share, until)


def _near_many(geometry: SceneGeometry, to_local: Any) -> ManyBoxes | None:
    """The geometry's local boxes, to test at once (None where one is not finite: its
    union's box is then all there is)."""
    lo, hi = geometry.local_box_arrays(to_local)
    if not (np.isfinite(lo).all() and np.isfinite(hi).all()):
        return None
    return ManyBoxes(lo, hi)

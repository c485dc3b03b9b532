"""What is rendered: the Scene (a model placed in the world, objects, volumes, background)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .. import checks
from ..geometry import Disk, Group, Intersector
from ..geometry.disk import AccretionDisk

DISK_ID = -2
"""Object id of the accretion disk's hits (-1 means no hit; other objects use ids >= 0)."""

ENDING = {"escaped": 0, "captured": 1, "hit": 2, "failed": 3, "max_steps": 4}
"""Ending codes of the ``ending`` pass (int8)."""


@dataclass
class Scene:
    """What is rendered: a model placed in the world, objects, volumes and a background."""

    model: Any = None
    center: Any = (0.0, 0.0, 0.0)
    axis: Any = (0.0, 0.0, 1.0)
    objects: Any = field(default_factory=list)
    """An intersector (core.intersect.Intersector) or a list of them."""
    background: Any = "procedural"
    volumes: list = field(default_factory=list)
    region_radius: float | None = None
    """Radius of the model's region (world units); default from the model and tolerance."""
    rotation: Any = None
    """Optional 3x3 matrix: columns = the model's local x, y, z axes in the world (its z
    must be ``axis``); default: z = axis with x, y chosen. Needed to turn a medium or a
    user metric about the axis."""
    disk: AccretionDisk | None = None
    """A thin accretion disk in the model's equatorial plane (core.AccretionDisk); bound to
    the model here (its r_in defaults to the ISCO)."""

    def __post_init__(self) -> None:
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
        if self.disk is not None:
            if not isinstance(self.disk, AccretionDisk):
                raise ValueError(f"disk must be a core.AccretionDisk, got {self.disk!r}")
            self.disk = self.disk.bind(self.model)

    @property
    def curved(self) -> bool:
        """False when nothing bends light: rays are traced straight, no integration."""
        return self.model is not None and not self.model.flat

    def intersector(self, disk: bool = True) -> Intersector:
        """The objects as one intersector (a list of them becomes a Group), with the disk's
        annulus (object id DISK_ID) when there is one (and ``disk``)."""
        annulus = self.disk_annulus() if disk else None
        if isinstance(self.objects, Intersector):
            if annulus is None:
                return self.objects
            return Group([self.objects, annulus], ids=[None, DISK_ID])
        objects = list(self.objects)
        if annulus is None:
            return Group(objects)  # ids: their positions
        ids: list[int | None] = [*range(len(objects)), DISK_ID]
        return Group([*objects, annulus], ids=ids)

    def disk_annulus(self) -> Disk | None:
        """The disk as a flat annulus in the world (None without a disk)."""
        if self.disk is None:
            return None
        r_in, r_out = self.disk.cartesian_radii()
        frame = self.frame()
        return Disk(self.center, frame[:, 2], r_in, r_out, u_axis=frame[:, 0], object_id=DISK_ID)

    def disk_radius(self, world: Any) -> np.ndarray:
        """Boyer–Lindquist radius of world points (..., 3) on the disk (the model's local
        frame: ``frame``)."""
        world = np.asarray(world, dtype=np.float64)
        local = (world.reshape(-1, 3) - self.center) @ self.frame()
        radius = self.model.for_backward_tracing().radius_at(local.T)
        return np.asarray(radius).reshape(world.shape[:-1])

    def frame(self) -> np.ndarray:
        """3x3 matrix whose columns are the model's local x, y, z axes in the world."""
        if self.rotation is not None:
            return self.rotation
        z = self.axis
        helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        x = helper - z * (helper @ z)
        x /= np.linalg.norm(x)
        return np.stack([x, np.cross(z, x), z], axis=1)

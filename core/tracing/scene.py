"""What is rendered: the Scene (a model placed in the world, objects, volumes, background)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .. import checks
from ..geometry import Group, Intersector

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

    @property
    def curved(self) -> bool:
        """False when nothing bends light: rays are traced straight, no integration."""
        return self.model is not None and not self.model.flat

    def intersector(self) -> Intersector:
        """The objects as one intersector (a list of them becomes a Group)."""
        if isinstance(self.objects, Intersector):
            return self.objects
        return Group(list(self.objects))

    def frame(self) -> np.ndarray:
        """3x3 matrix whose columns are the model's local x, y, z axes in the world."""
        if self.rotation is not None:
            return self.rotation
        z = self.axis
        helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        x = helper - z * (helper @ z)
        x /= np.linalg.norm(x)
        return np.stack([x, np.cross(z, x), z], axis=1)

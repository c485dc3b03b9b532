"""Intersectors: which straight segment a -> b hits which object first (the core/Blender seam).

The public name of :mod:`core.geometry` (hits, primitives, meshes, groups, textures,
volumes; one subject per module there); see core/geometry/hits.py for the contract.
"""

from . import geometry as _geometry
from .geometry import *  # noqa: F403 (a facade: every public name of core.geometry, one list)

__all__ = list(_geometry.__all__)

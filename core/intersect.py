"""Intersectors: which straight segment a -> b hits which object first (the core/Blender seam).

The public name of :mod:`core.geometry` (hits, primitives, meshes, groups, textures,
volumes; one subject per module there); see core/geometry/hits.py for the contract.
"""

from .geometry import (
    AccretionDisk,
    Disk,
    Group,
    Hits,
    Intersector,
    Plane,
    Sphere,
    Texture,
    TriangleMesh,
    Volume,
    checker,
    colormap,
    segment_overlaps,
)

__all__ = [
    "AccretionDisk",
    "Disk",
    "Group",
    "Hits",
    "Intersector",
    "Plane",
    "Sphere",
    "Texture",
    "TriangleMesh",
    "Volume",
    "checker",
    "colormap",
    "segment_overlaps",
]

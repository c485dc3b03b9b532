"""What rays can hit and pass through: hits, primitives, meshes, groups, textures, volumes,
and the accretion disk.

``core.intersect`` is the public name of this package's contents (the core/Blender seam:
an intersector has ``bounds`` and ``intersect(a, b) -> Hits``, see hits.py).
"""

from .disk import AccretionDisk
from .group import Group
from .hits import Hits, Intersector, filters, segment_meets_box, segment_overlaps
from .mesh import TriangleMesh, barycentric_gradients
from .primitives import Disk, Plane, Sphere
from .textures import Checker, Texture, checker, colormap
from .volumes import Volume

__all__ = [
    "AccretionDisk",
    "Checker",
    "Disk",
    "Group",
    "Hits",
    "Intersector",
    "Plane",
    "Sphere",
    "Texture",
    "TriangleMesh",
    "Volume",
    "barycentric_gradients",
    "checker",
    "colormap",
    "filters",
    "segment_meets_box",
    "segment_overlaps",
]

"""SymRay core: symplectic ray tracing in pure numpy (no Blender needed).

The contract (docs/design.md): ``core.integrate``, ``core.hamiltonians``, ``core.Camera``,
``core.Scene``, ``core.render``, ``core.ENDING`` and the intersectors.
"""

from . import (
    blackbody,
    camera,
    checks,
    cluster,
    dual,
    expressions,
    hamiltonians,
    imageio,
    integrators,
    intersect,
    presets,
    sky,
    workers,
)
from .camera import Camera, Frame
from .expressions import ExpressionError
from .imageio import FAILED_COLOR, ImageWriteError, read_png, write_exr, write_png
from .integrators import METHODS, IntegrationResult, PoincareTransformed, get_method, integrate
from .intersect import (
    AccretionDisk,
    Disk,
    Group,
    Hits,
    Plane,
    Sphere,
    TriangleMesh,
    Volume,
    checker,
    colormap,
)
from .observer import (
    CoordinateAxisError,
    InsideHorizonError,
    MetricSignatureError,
    ObserverError,
    SingularMetricError,
)
from .render import MAX_STEPS_COLOR, RenderResult, render
from .sky import Background, equirect_lookup, procedural_sky
from .stars import StarField
from .sweep import sweep
from .trace import ENDING, Scene

__all__ = [
    "blackbody",
    "camera",
    "checks",
    "cluster",
    "dual",
    "expressions",
    "hamiltonians",
    "imageio",
    "integrators",
    "intersect",
    "presets",
    "sky",
    "workers",
    "Camera",
    "Frame",
    "ExpressionError",
    "FAILED_COLOR",
    "MAX_STEPS_COLOR",
    "ImageWriteError",
    "read_png",
    "write_exr",
    "write_png",
    "METHODS",
    "IntegrationResult",
    "PoincareTransformed",
    "get_method",
    "integrate",
    "AccretionDisk",
    "Disk",
    "Group",
    "Hits",
    "Plane",
    "Sphere",
    "TriangleMesh",
    "Volume",
    "checker",
    "colormap",
    "InsideHorizonError",
    "ObserverError",
    "CoordinateAxisError",
    "MetricSignatureError",
    "SingularMetricError",
    "RenderResult",
    "render",
    "sweep",
    "Background",
    "StarField",
    "equirect_lookup",
    "procedural_sky",
    "ENDING",
    "Scene",
]

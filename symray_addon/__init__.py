"""SymRay's Blender half: settings, panels, presets, the render operator and engine.

Everything here may import bpy/mathutils; the numpy core (``..core``) never does.
"""

from __future__ import annotations

from . import (
    engine,
    migration,
    objects,
    observer,
    operator,
    overlay,
    panel,
    presets,
    properties,
)

_MODULES = (objects, properties, observer, presets, operator, engine, panel, overlay, migration)


def register() -> None:
    """Register every class and property of the add-on."""
    for module in _MODULES:
        module.register()


def unregister() -> None:
    """Unregister everything register() added, in reverse order."""
    for module in reversed(_MODULES):
        module.unregister()

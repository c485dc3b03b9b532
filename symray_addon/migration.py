"""Files saved by earlier SymRay versions keep rendering what they rendered.

Every save stamps ``scene.symray.file_version`` (FILE_VERSION); a scene loaded with SymRay
settings but no stamp was saved before the black hole became an object (issue 24). Its
settings are made explicit where a default changed (model Schwarzschild, quality Final,
Background › Auto over a plain world = the procedural sky, the disk's outer radius 10 and
its physical look at exposure 1), and a centre Empty of a Schwarzschild or Kerr model
becomes the scene's black hole object with the same size and spin. Scenes saved before
version 2 (issue 45) that left Refractive Index at its default keep that default then
(the seed's Eq. 17; the new default has no pole in the medium's box).
"""

from __future__ import annotations

import bpy
from bpy.app.handlers import persistent

from ..core.models.registry import MODELS
from ..core.presets import MIRAGE_EQ17_INDEX
from . import objects, world

FILE_VERSION = 2
"""The settings' layout this version writes (0: before black hole objects; 1: before the
pole-free default Refractive Index)."""
OLD_INDEX = MIRAGE_EQ17_INDEX
"""Refractive Index's default before version 2."""


def _centre_to_hole(settings: bpy.types.PropertyGroup) -> None:
    """A Schwarzschild/Kerr model at a centre Empty -> that Empty as the scene's hole."""
    centre = settings.center
    kind = MODELS.get(settings.model)
    if centre is None or centre.type != "EMPTY" or kind is None or not kind.traits.hole:
        return
    spin = float(settings.spin) if "spin" in kind.parameter_names() else 0.0
    if not -1.0 <= spin <= 1.0 or centre.symray.kind not in ("NONE", "BLACK_HOLE"):
        return
    size = objects.size_of(settings.rg, spin)
    if centre.symray.kind == "BLACK_HOLE":  # shared with a scene migrated before
        same = (centre.symray.size, centre.symray.spin) == (size, spin)
        if not same:
            return
    centre.symray.size, centre.symray.spin = size, spin  # before kind: no disk rescaling
    centre.symray.kind = "BLACK_HOLE"
    centre.empty_display_type = "SPHERE"
    settings.model, settings.center = "OBJECTS", None


def _any_set(settings: bpy.types.PropertyGroup) -> bool:
    """Whether the file holds any of these settings (a scene SymRay never touched holds
    none: it is new, not old)."""
    for group in (settings, settings.disk):
        for prop in group.bl_rna.properties:
            if prop.identifier in ("rna_type", "disk"):
                continue
            if prop.type == "POINTER":  # reported set even when empty
                if getattr(group, prop.identifier) is not None:
                    return True  # a centre object or a metric text
            elif group.is_property_set(prop.identifier):
                return True
    return False


def _world_is_read(scene: bpy.types.Scene) -> bool:
    """Whether Background › Auto shows the scene's world (not the procedural sky); a world
    refused by name (a Mirror Ball image) is the render's to report."""
    try:
        return not isinstance(world.world_background(scene, "AUTO"), str)
    except ValueError:
        return False


def migrate(scene: bpy.types.Scene) -> bool:
    """Bring a scene's settings saved before FILE_VERSION to it, keeping its image; True if
    anything was done."""
    settings = getattr(scene, "symray", None)
    if settings is None or settings.file_version >= FILE_VERSION or not _any_set(settings):
        return False
    if settings.file_version < 1:
        _before_objects(scene, settings)
    if not settings.is_property_set("refractive_index"):
        settings.refractive_index = OLD_INDEX  # the default before version 2
    settings.file_version = FILE_VERSION
    return True


def _before_objects(scene: bpy.types.Scene, settings: bpy.types.PropertyGroup) -> None:
    """Version 0 -> 1: the defaults that changed when holes became objects (issue 24)."""
    for name, old_default in (("model", "SCHWARZSCHILD"), ("quality", "FINAL")):
        if not settings.is_property_set(name):
            setattr(settings, name, old_default)
    if settings.background == "AUTO" and _world_is_read(scene):
        settings.background = "PROCEDURAL"  # Auto showed the stars over a plain world
    disk = settings.disk
    if not disk.is_property_set("outer_radius"):
        disk.outer_radius = 10.0  # the default then
    disk.look, disk.auto_exposure, disk.exposure = "PHYSICAL", False, 1.0  # no looks then
    _centre_to_hole(settings)


@persistent
def migrate_on_load(_dummy: object = None) -> None:
    """After a .blend loads, migrate every unstamped scene."""
    for scene in bpy.data.scenes:
        migrate(scene)


@persistent
def stamp_on_save(_dummy: object = None) -> None:
    """Before a .blend is saved, stamp every scene's settings with FILE_VERSION."""
    for scene in bpy.data.scenes:
        settings = getattr(scene, "symray", None)
        if settings is not None and settings.file_version != FILE_VERSION:
            settings.file_version = FILE_VERSION


_HANDLERS = (
    (bpy.app.handlers.load_post, migrate_on_load),
    (bpy.app.handlers.save_pre, stamp_on_save),
)


def register() -> None:
    """Add the load and save handlers."""
    for handlers, handler in _HANDLERS:
        if handler not in handlers:
            handlers.append(handler)


def unregister() -> None:
    """Remove the handlers."""
    for handlers, handler in _HANDLERS:
        if handler in handlers:
            handlers.remove(handler)

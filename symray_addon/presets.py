"""Presets for the seed paper's scenes, and the operator that applies them.

The refractive-index expressions of the seed's mirage figures (Satoh, "Symplectic Ray
Tracing", Eq. 17 and 18) live in ``core/presets.py`` and nowhere else. They are written for
the seed's literal optical Hamiltonian H = n |p|^2 / 2 (``index_form = 'SEED'``), so the
figures can be reproduced as printed; see docs/design.md, "Models and conventions".
"""

from __future__ import annotations

import bpy

from ..core.presets import MIRAGE_EQ17_INDEX, MIRAGE_EQ18_INDEX

MINKOWSKI_METRIC = "-1, 0, 0, 0; 0, 1, 0, 0; 0, 0, 1, 0; 0, 0, 0, 1"
"""Flat spacetime in Cartesian coordinates (seed Eq. 13): the default user metric."""

PRESETS: dict[str, tuple[str, str, dict[str, object]]] = {
    "SCHWARZSCHILD_LENS": (
        "Schwarzschild Lens",
        "Non-rotating black hole (seed Eq. 15) lensing the sky and the objects behind it",
        {"model": "SCHWARZSCHILD", "rg": 1.0, "method": "AUTO", "tolerance": 1e-6},
    ),
    "KERR": (
        "Kerr Black Hole",
        "Rotating black hole, a/M = 0.9 (seed Eq. 12), spin axis = the centre's local Z",
        {"model": "KERR", "rg": 1.0, "spin": 0.9, "method": "AUTO", "tolerance": 1e-6},
    ),
    "KERR_DISK": (
        "Kerr with Accretion Disk",
        "Rotating black hole, a/M = 0.9, rg = 0.5, with a hot thin disk from the ISCO to "
        "3 units in the centre's XY plane (Novikov–Thorne, 6000 K, Doppler; framed for "
        "the default camera) and the SymRay Redshift pass",
        {
            "model": "KERR",
            "rg": 0.5,
            "spin": 0.9,
            "method": "AUTO",
            "tolerance": 1e-6,
            "pass_redshift": True,
            "disk.enabled": True,
            "disk.use_isco": True,
            "disk.outer_radius": 3.0,
            "disk.profile": "NOVIKOV_THORNE",
            "disk.temperature": 6000.0,
            "disk.doppler": True,
            "disk.brightness": 0.6,
            "disk.opacity": 1.0,
        },
    ),
    "MIRAGE_EQ17": (
        "Mirage (Eq. 17)",
        "Refractive index of the seed's Eq. 17 with its literal Hamiltonian H = n|p|^2/2",
        {
            "model": "MEDIUM",
            "refractive_index": MIRAGE_EQ17_INDEX,
            "index_form": "SEED",
            "use_medium_bounds": False,
            "method": "AUTO",
            "tolerance": 1e-6,
        },
    ),
    "MIRAGE_EQ18": (
        "Mirage (Eq. 18)",
        "Refractive index of the seed's Eq. 18 with its literal Hamiltonian H = n|p|^2/2",
        {
            "model": "MEDIUM",
            "refractive_index": MIRAGE_EQ18_INDEX,
            "index_form": "SEED",
            "use_medium_bounds": False,
            "method": "AUTO",
            "tolerance": 1e-6,
        },
    ),
}
"""identifier -> (label, description, settings to assign to scene.symray; "disk.x" is
scene.symray.disk.x)."""


def apply_preset(settings: bpy.types.PropertyGroup, identifier: str) -> None:
    """Assign the values of preset ``identifier`` to ``settings`` (a scene.symray); a
    preset without a disk switches the disk off."""
    values = PRESETS[identifier][2]
    if "disk.enabled" not in values:
        settings.disk.enabled = False
    for key, value in values.items():
        *group, name = key.split(".")
        setattr(getattr(settings, group[0]) if group else settings, name, value)


class SYMRAY_OT_apply_preset(bpy.types.Operator):
    """Set the SymRay model and its parameters to one of the seed paper's scenes"""

    bl_idname = "symray.apply_preset"
    bl_label = "Apply SymRay Preset"
    bl_options = {"REGISTER", "UNDO"}

    preset: bpy.props.EnumProperty(  # type: ignore[valid-type]
        name="Preset",
        items=[(key, label, desc) for key, (label, desc, _) in PRESETS.items()],
    )
    add_center: bpy.props.BoolProperty(  # type: ignore[valid-type]
        name="Add Centre",
        description="Create an Empty at the world origin as the model's centre if none is set",
        default=True,
    )

    def execute(self, context: bpy.types.Context) -> set[str]:
        """Apply the preset to the active scene."""
        settings = context.scene.symray
        apply_preset(settings, self.preset)
        if self.add_center and settings.center is None:
            empty = bpy.data.objects.new("SymRay Centre", None)
            empty.empty_display_type = "SPHERE"
            context.scene.collection.objects.link(empty)
            settings.center = empty
        return {"FINISHED"}


class SYMRAY_MT_presets(bpy.types.Menu):
    """Menu of the seed paper's scenes"""

    bl_idname = "SYMRAY_MT_presets"
    bl_label = "Presets"

    def draw(self, context: bpy.types.Context) -> None:
        """One entry per preset."""
        for key, (label, _desc, _values) in PRESETS.items():
            self.layout.operator(SYMRAY_OT_apply_preset.bl_idname, text=label).preset = key


CLASSES = (SYMRAY_OT_apply_preset, SYMRAY_MT_presets)


register, unregister = bpy.utils.register_classes_factory(CLASSES)
"""Register / unregister the preset operator and menu (in order, and in reverse)."""

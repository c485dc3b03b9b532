"""The accretion disk's settings (``scene.symray.disk``); checked in validation.py, made a
core.AccretionDisk in models.py.

Radii are Boyer–Lindquist radii in scene units (the same units as the Schwarzschild
radius rg); the disk lies in the centre object's local XY plane (core.AccretionDisk).
"""

from __future__ import annotations

import bpy

LOOK_ITEMS = [
    ("PHYSICAL", "Physical", "The black body the gas is, with its Doppler and gravitational "
     "shifts (beaming: the approaching side bluer and far brighter)"),
    ("CINEMATIC", "Cinematic", "Interstellar-like: a warm orange-white glow, the Doppler "
     "beaming reduced by Beaming"),
    ("EHT", "EHT-like", "The Event Horizon Telescope's colours: the disk's total "
     "brightness through their orange 'afmhot' colour map"),
]  # fmt: skip
"""The disk's looks (core.AccretionDisk.look); the redshift pass is the same in all."""

PROFILE_ITEMS = [
    ("NOVIKOV_THORNE", "Novikov–Thorne", "Relativistic thin-disk profile (zero torque at "
     "the inner edge); Temperature is its hottest point"),
    ("POWER_LAW", "Power Law", "T = Temperature x (r / inner radius)^(-3/4)"),
]  # fmt: skip


class SymRayDiskSettings(bpy.types.PropertyGroup):
    """A relativistic thin accretion disk around the black hole"""

    enabled: bpy.props.BoolProperty(  # type: ignore[valid-type]
        name="Accretion Disk",
        default=False,
        description="A thin black-body disk in the centre's XY plane, on "
        "Keplerian orbits, with gravitational and Doppler shifts",
    )
    use_isco: bpy.props.BoolProperty(  # type: ignore[valid-type]
        name="Inner Edge at Innermost Orbit",
        default=True,
        description="Start the disk at the innermost orbit gas can keep around the hole "
        "(physics: the innermost stable circular orbit, ISCO, of the spin)",
    )
    inner_radius: bpy.props.FloatProperty(  # type: ignore[valid-type]
        name="Inner Radius",
        default=3.0,
        min=0.0,
        soft_max=100.0,
        subtype="DISTANCE",
        description="Radius of the inner edge in scene units, at least the innermost orbit "
        "(physics: Boyer–Lindquist r, at least the ISCO)",
    )
    outer_radius: bpy.props.FloatProperty(  # type: ignore[valid-type]
        name="Outer Radius",
        default=12.0,
        min=0.0,
        soft_max=1000.0,
        subtype="DISTANCE",
        description="Radius of the outer edge in scene units (Add Black Hole: 12× its size; "
        "physics: Boyer–Lindquist r)",
    )
    profile: bpy.props.EnumProperty(  # type: ignore[valid-type]
        name="Temperature Profile", items=PROFILE_ITEMS, default="NOVIKOV_THORNE"
    )
    temperature: bpy.props.FloatProperty(  # type: ignore[valid-type]
        name="Temperature",
        default=10_000.0,
        subtype="TEMPERATURE",
        min=100.0,
        max=1e9,
        soft_max=100_000.0,
        description="Hottest temperature of the disk in kelvin (the inner edge for the "
        "power law), before any shift",
    )
    doppler: bpy.props.BoolProperty(  # type: ignore[valid-type]
        name="Doppler",
        default=True,
        description="The gas orbits (beaming: the approaching side bluer and brighter); "
        "off: it is at rest in the local non-rotating frame (gravitational shift only)",
    )
    brightness: bpy.props.FloatProperty(  # type: ignore[valid-type]
        name="Brightness",
        default=1.0,
        min=0.0,
        max=1e6,
        soft_max=100.0,
        description="Factor on the disk's light after its exposure (with Auto Exposure "
        "off and Exposure 1: the luminance of a disk point at Temperature seen without "
        "shift; at most 1e6)",
    )
    look: bpy.props.EnumProperty(  # type: ignore[valid-type]
        name="Look",
        items=LOOK_ITEMS,
        default="PHYSICAL",
        description="How the disk's light is coloured; its shifts (the SymRay Redshift "
        "pass) are the same in every look",
    )
    beaming: bpy.props.FloatProperty(  # type: ignore[valid-type]
        name="Beaming",
        default=0.3,
        min=0.0,
        max=1.0,
        description="Cinematic look: how much of the Doppler and gravitational shift "
        "brightens and colours the disk (1: all of it, as Physical; 0: none, even on "
        "both sides)",
    )
    auto_exposure: bpy.props.BoolProperty(  # type: ignore[valid-type]
        name="Auto Exposure",
        default=True,
        description="Expose the disk so that its median pixel shows as middle grey on "
        "screen (a quick probe render before each frame); Brightness multiplies the "
        "result. Off: Exposure (pin the value a render reported to keep it fixed over an "
        "animation)",
    )
    exposure: bpy.props.FloatProperty(  # type: ignore[valid-type]
        name="Exposure",
        default=1.0,
        min=1e-6,
        max=1e9,
        soft_min=0.001,
        soft_max=1000.0,
        description="Factor on the disk's light when Auto Exposure is off (a factor, "
        "not stops; 1: Brightness alone sets the light, as before looks)",
    )
    opacity: bpy.props.FloatProperty(  # type: ignore[valid-type]
        name="Opacity",
        default=1.0,
        min=0.001,
        max=1.0,
        description="1: opaque; below 1 the disk adds Opacity x its light to (1 - Opacity) "
        "x what lies behind it (seen through it, the sky and its other images)",
    )

"""``scene.symray``: every SymRay setting of a scene (the Blender contract of docs/design.md)."""

from __future__ import annotations

import bpy
from bpy.app.handlers import persistent

from ..core import passes as core_passes
from ..core.integrators import METHODS
from ..core.models.registry import MODELS, parameters
from . import disk_properties, presets, validation
from .model_settings import parameter_property

PASSES = tuple((p.name, p.label, p.toggle) for p in core_passes.PASSES if p.label)
"""(core pass, label, toggle) of the passes the add-on writes, in their one order (the
core's table, core.passes): 'SymRay <label>' render passes and the operator's passes EXR
layers. 'SymRay Error' is the core's ``error_px`` (pixels of the camera)."""

DEVICE_ITEMS = [
    ("CPU", "CPU", "Trace on the CPU's cores (adaptive sampling, anti-aliasing)"),
    (
        "GPU",
        "GPU",
        "Trace every pixel on an NVIDIA GPU through CuPy in Blender's Python (one ray per "
        "pixel; meshes' hits and shading on the CPU)",
    ),
]
"""Render Properties › Device, as Cycles has it (core.render's device "cpu" / "cuda")."""

QUALITY_ITEMS = [
    ("PREVIEW", "Preview", "Every pixel within 1 px, one ray per pixel at most: quick look"),
    ("FINAL", "Final", "Every pixel within 0.25 px, up to 16 rays per pixel (anti-aliased)"),
    ("CUSTOM", "Custom", "Accuracy (pixels) and samples per pixel set below"),
    ("RADIANS", "Radians", "Tolerance in radians, one ray through every pixel's centre "
     "(no adaptive sampling)"),
]  # fmt: skip
QUALITY_PRESETS = {"PREVIEW": (1.0, 1), "FINAL": (0.25, 16)}
"""Quality -> (tolerance in pixels, samples per pixel)."""

MODEL_ITEMS = [
    ("OBJECTS", "Scene Objects", "The scene's black hole or medium object (Add › SymRay); "
     "flat space without one", "OUTLINER_OB_EMPTY", 6),
    *((k.name, k.label, k.description, "NONE", k.number) for k in MODELS.values()),
]  # fmt: skip
"""(identifier, label, description, icon, number): Scene Objects, then the core's models
(core.models.registry); the number is what a .blend stores."""


METHOD_TEXT = {
    "symplectic_euler": (0, "Symplectic Euler", "1st order, seed Eq. 11"),
    "stormer_verlet": (1, "Störmer–Verlet", "2nd order, symmetric"),
    "implicit_midpoint": (2, "Implicit Midpoint", "2nd order, implicit"),
    "gauss4": (3, "Gauss–Legendre 4", "4th order, implicit (2-stage Gauss–Legendre)"),
    "yoshida4": (4, "Yoshida 4", "4th order composition (triple jump)"),
    "yoshida6": (5, "Yoshida 6", "6th order composition"),
    "yoshida8": (6, "Yoshida 8", "8th order composition"),
    "suzuki4": (7, "Suzuki 4", "4th order fractal composition"),
    "suzuki6": (8, "Suzuki 6", "6th order fractal composition"),
    "tao2": (9, "Tao 2", "2nd order, explicit for non-separable H (extended phase space); "
             "media and metrics only: it cannot trace black holes"),
    "tao4": (10, "Tao 4", "4th order, explicit for non-separable H (extended phase space); "
             "media and metrics only: it cannot trace black holes"),
    "rk4": (11, "Runge–Kutta 4", "Non-symplectic reference, 4th order"),
    "dopri5": (12, "Dormand–Prince 5", "Non-symplectic reference, adaptive"),
    "leapfrog": (13, "Leapfrog", "2nd order, explicit splitting (needs a model with a split: "
                 "Schwarzschild, Kerr, media)"),
    "blanes_moan4": (14, "Blanes–Moan 4", "4th order, explicit splitting (Schwarzschild, "
                     "Kerr, media)"),
    "blanes_moan6": (15, "Blanes–Moan 6", "Explicit splitting: 6th order for media, 4th on "
                     "Schwarzschild's and Kerr's splits"),
    "AUTO": (16, "Automatic", "The measured cheapest for the model: Blanes–Moan 6 for "
             "Schwarzschild, Blanes–Moan S10 for Kerr below extremal, Blanes–Moan 4 for media "
             "(explicit symplectic splittings), Gauss–Legendre 4 otherwise"),
    "blanes_moan_s6": (17, "Blanes–Moan S6", "4th order, explicit splitting for any split "
                       "(Kerr, Schwarzschild, media)"),
    "blanes_moan_s10": (18, "Blanes–Moan S10", "6th order, explicit splitting for any split "
                        "(Kerr, Schwarzschild, media)"),
}  # fmt: skip
"""Method name -> (number, label, description). The number is what a .blend stores (it was
each item's position when the list was kept by hand): a new method takes the next free
number, and no number is ever reused."""


def _method_items() -> list[tuple[str, str, str, str, int]]:
    """The Method enum: Automatic, then every method of core.METHODS, each with its number."""
    names = ("AUTO", *METHODS)
    missing = [name for name in names if name not in METHOD_TEXT]
    if missing:
        raise RuntimeError(f"methods without a label in METHOD_TEXT: {missing}")
    return [(name, *METHOD_TEXT[name][1:], "NONE", METHOD_TEXT[name][0]) for name in names]


METHOD_ITEMS = _method_items()

MEDIUM_INDEX = "1 + 0.003*tanh(z/0.3)"
"""The default n(x, y, z): air over hot ground at z = 0 of the medium's axes, n rising by
0.6 % through a layer ~0.3 thick and level above and below, with no pole at any z: any box
renders, and rays grazing z = 0 from above turn up (an inferior mirage). The default
before (the seed's Eq. 17 in the physical form) had a pole at z = -0.87 inside the ±10
box: a third of the rays failed (migration.py keeps it for files that used it)."""

INDEX_FORM_ITEMS = [
    ("PHYSICAL", "Physical", "H = |p|² / 2n²: rays obey the ray equation of optics"),
    ("SEED", "Seed (literal)", "H = n|p|² / 2 as printed in the seed paper (Eq. 8/16)"),
]

BACKGROUND_ITEMS = [
    (
        "AUTO",
        "Auto",
        "The world's environment texture or colour; the procedural sky when the scene has no world",
    ),
    ("WORLD", "World", "The world: its environment texture or its background colour"),
    ("PROCEDURAL", "Procedural Sky", "SymRay's procedural star field and grid"),
    (
        "STARS",
        "Point Stars",
        "Stars as points, each lensed image with its magnification (a seeded random sky or a "
        "CSV catalogue), over the Milky Way band",
    ),
]

LIGHTING_ITEMS = [
    (
        "AUTO",
        "Auto",
        "Bake with Cycles when the scene has lights, else Unlit",
    ),
    (
        "BAKE",
        "Bake",
        "Cycles bakes each object's view-independent light (diffuse direct + indirect, "
        "emission; no glossy or refraction; light reaches surfaces on straight paths) into "
        "a temporary texture that curved rays then see",
    ),
    (
        "UNLIT",
        "Unlit",
        "Surfaces show their colour plus emission, as under uniform white light",
    ),
]

# Blender 5 warns when a path property holding '//' does not declare it supports that
# (4.2 does not know the option; 5.0 is the first version it is known to be in)
_PATH_OPTIONS = {"ANIMATABLE"} | (
    {"PATH_SUPPORTS_BLEND_RELATIVE"} if bpy.app.version >= (5, 0, 0) else set()
)

PARALLEL_ITEMS = [
    (
        "AUTO",
        "Auto",
        "Worker processes where the OS can fork them (Linux), threads "
        "elsewhere and for the smallest images",
    ),
    (
        "PROCESSES",
        "Processes",
        "Forked worker processes: every core works (Linux; threads elsewhere)",
    ),
    (
        "THREADS",
        "Threads",
        "Threads in Blender's process: they share Python's lock, so two cores give about 1.2x",
    ),
]

# Each expression property -> (validator, name of its error property).
_EXPRESSIONS = {
    "refractive_index": (
        lambda s: validation.check_expression(s.refractive_index, validation.INDEX_NAMES),
        "refractive_index_error",
    ),
    "metric": (lambda s: validation.check_metric(metric_source(s)), "metric_error"),
    "hamiltonian": (
        lambda s: validation.check_expression(s.hamiltonian, validation.HAMILTONIAN_NAMES),
        "hamiltonian_error",
    ),
}


def metric_source(settings: bpy.types.PropertyGroup) -> str:
    """The inverse-metric text in use: the Text data-block if one is set, else ``metric``."""
    text = settings.metric_text
    return text.as_string() if text is not None else settings.metric


def validate_expressions(settings: bpy.types.PropertyGroup) -> None:
    """Re-check every expression of ``settings`` and store the error strings."""
    for check, error_prop in _EXPRESSIONS.values():
        _store(settings, error_prop, check(settings))


def _store(settings: bpy.types.PropertyGroup, error_prop: str, message: str) -> None:
    """Set an error property only when it changes (avoids needless redraws)."""
    if getattr(settings, error_prop) != message:
        setattr(settings, error_prop, message)


def _validator(prop: str):
    """Update callback for expression property ``prop``."""
    check, error_prop = _EXPRESSIONS[prop]

    def update(self: bpy.types.PropertyGroup, _context: bpy.types.Context) -> None:
        _store(self, error_prop, check(self))

    return update


def _update_passes(self: bpy.types.PropertyGroup, context: bpy.types.Context) -> None:
    """Tell the view layers that SymRay's passes changed, so the compositor sees them."""
    scene = self.id_data
    for view_layer in getattr(scene, "view_layers", ()):
        view_layer.update_render_passes()


def _center_poll(_self: bpy.types.PropertyGroup, obj: bpy.types.Object) -> bool:
    return obj.type == "EMPTY"


class SymRaySettings(bpy.types.PropertyGroup):
    """SymRay settings of one scene (``scene.symray``)"""

    model: bpy.props.EnumProperty(  # type: ignore[valid-type]
        name="Model", items=MODEL_ITEMS, default="OBJECTS", description="What bends the light"
    )
    center: bpy.props.PointerProperty(  # type: ignore[valid-type]
        name="Centre",
        type=bpy.types.Object,
        poll=_center_poll,
        description="Empty placing the model (all models but Scene Objects): its position is "
        "the black hole's centre, its local Z the spin axis, its local axes the frame of "
        "n(x, y, z) and g^ij; none = the world origin",
    )
    refractive_index: bpy.props.StringProperty(  # type: ignore[valid-type]
        name="Refractive Index",
        default=MEDIUM_INDEX,
        update=_validator("refractive_index"),
        description="n(x, y, z) in the centre's local frame; + - * / **, sin, exp, sqrt, pi "
        "(plain ASCII, at most 100 nested operations)",
    )
    refractive_index_error: bpy.props.StringProperty(  # type: ignore[valid-type]
        name="Refractive Index Error", default=""
    )
    index_form: bpy.props.EnumProperty(  # type: ignore[valid-type]
        name="Optical Form",
        items=INDEX_FORM_ITEMS,
        default="PHYSICAL",
        description="Optical Hamiltonian built from n",
    )
    use_medium_bounds: bpy.props.BoolProperty(  # type: ignore[valid-type]
        name="Bounded Medium",
        default=True,
        description="Outside the box the medium is uniform and rays travel straight",
    )
    medium_min: bpy.props.FloatVectorProperty(  # type: ignore[valid-type]
        name="Box Min",
        size=3,
        default=(-10.0, -10.0, -10.0),
        subtype="XYZ_LENGTH",
        description="Lower corner of the medium's box, in the centre's local frame",
    )
    medium_max: bpy.props.FloatVectorProperty(  # type: ignore[valid-type]
        name="Box Max",
        size=3,
        default=(10.0, 10.0, 10.0),
        subtype="XYZ_LENGTH",
        description="Upper corner of the medium's box, in the centre's local frame",
    )
    metric: bpy.props.StringProperty(  # type: ignore[valid-type]
        name="Inverse Metric",
        default=presets.MINKOWSKI_METRIC,
        update=_validator("metric"),
        description="g^ij(t, x, y, z): 4 rows separated by ';', entries by ','; "
        "'name = expr;' statements before the rows define helpers",
    )
    metric_text: bpy.props.PointerProperty(  # type: ignore[valid-type]
        name="Metric Text",
        type=bpy.types.Text,
        update=_validator("metric"),
        description="Text data-block holding the inverse metric (one row or definition per "
        "line); overrides the one-line field",
    )
    metric_error: bpy.props.StringProperty(  # type: ignore[valid-type]
        name="Metric Error", default=""
    )
    hamiltonian: bpy.props.StringProperty(  # type: ignore[valid-type]
        name="Hamiltonian",
        default="0.5*(p_x**2 + p_y**2 + p_z**2)",
        update=_validator("hamiltonian"),
        description="H(x, y, z, p_x, p_y, p_z) in the centre's local frame (plain ASCII, "
        "at most 100 nested operations)",
    )
    hamiltonian_error: bpy.props.StringProperty(  # type: ignore[valid-type]
        name="Hamiltonian Error", default=""
    )
    method: bpy.props.EnumProperty(  # type: ignore[valid-type]
        name="Method",
        items=METHOD_ITEMS,
        default="AUTO",
        description="Integrator for Hamilton's equations",
    )
    device: bpy.props.EnumProperty(  # type: ignore[valid-type]
        name="Device",
        items=DEVICE_ITEMS,
        default="CPU",
        description="Where rays are traced: the CPU's cores, or an NVIDIA GPU through CuPy "
        "(README: GPU rendering)",
    )
    quality: bpy.props.EnumProperty(  # type: ignore[valid-type]
        name="Quality",
        items=QUALITY_ITEMS,
        default="PREVIEW",
        description="How accurate the image is, in pixels of the camera: Preview or Final",
    )
    tolerance_px: bpy.props.FloatProperty(  # type: ignore[valid-type]
        name="Accuracy (px)",
        default=0.25,
        min=1e-6,
        max=100.0,
        precision=3,
        step=1,
        description="Target accuracy of every pixel's final direction or hit point, in "
        "pixels (Custom quality)",
    )
    samples: bpy.props.IntProperty(  # type: ignore[valid-type]
        name="Samples",
        default=16,
        min=1,
        max=1024,
        description="Most camera rays per pixel, spent where the contrast asks for them "
        "(Custom quality; 1 = no anti-aliasing)",
    )
    tolerance: bpy.props.FloatProperty(  # type: ignore[valid-type]
        name="Tolerance",
        default=1e-6,
        min=1e-14,
        max=0.1,
        precision=6,
        step=0.0001,
        description="Target accuracy of the rays' directions (radians), 1e-14 to 0.1; sets "
        "the integration step (Radians quality)",
    )
    max_steps: bpy.props.IntProperty(  # type: ignore[valid-type]
        name="Max Steps",
        default=20000,
        min=1,
        max=100_000_000,
        description="Steps after which a ray is given up (ending 'max_steps')",
    )
    parallel: bpy.props.EnumProperty(  # type: ignore[valid-type]
        name="Parallel",
        items=PARALLEL_ITEMS,
        default="AUTO",
        description="How the image's chunks share the cores",
    )
    workers: bpy.props.IntProperty(  # type: ignore[valid-type]
        name="Workers",
        default=0,
        min=0,
        max=256,
        description="Worker processes or threads (0 = automatic: one process per "
        "thread Blender renders with, or two threads)",
    )
    disk: bpy.props.PointerProperty(  # type: ignore[valid-type]
        type=disk_properties.SymRayDiskSettings,
        description="The accretion disk around the black hole",
    )
    background: bpy.props.EnumProperty(  # type: ignore[valid-type]
        name="Background",
        items=BACKGROUND_ITEMS,
        default="AUTO",
        description="What rays that escape to infinity see",
    )
    star_count: bpy.props.IntProperty(  # type: ignore[valid-type]
        name="Stars",
        default=9000,
        min=0,
        soft_max=200_000,
        description="How many random stars (magnitudes -1.5 to 6.5, about the naked-eye sky)",
    )
    star_seed: bpy.props.IntProperty(  # type: ignore[valid-type]
        name="Seed", default=0, min=0, description="The random star field's seed"
    )
    star_catalog: bpy.props.StringProperty(  # type: ignore[valid-type]
        name="Catalogue",
        default="",
        subtype="FILE_PATH",
        description="A CSV of stars (header: ra, dec in degrees, mag, optional b-v); empty: "
        "the random field",
    )
    star_brightness: bpy.props.FloatProperty(  # type: ignore[valid-type]
        name="Star Brightness",
        default=1.0,
        min=0.0,
        soft_max=100.0,
        description="Scales every star's flux (a magnitude-0 star: 1e-6 radiance x sr)",
    )
    lighting: bpy.props.EnumProperty(  # type: ignore[valid-type]
        name="Surface Lighting",
        items=LIGHTING_ITEMS,
        default="AUTO",
        description="How surfaces are lit: Blender (Cycles) bakes the light on them, or "
        "they show their colour unlit",
    )
    bake_texel_size: bpy.props.FloatProperty(  # type: ignore[valid-type]
        name="Texel Size",
        default=0.0,
        min=0.0,
        soft_max=1.0,
        subtype="DISTANCE",
        description="Size of one baked texel on a surface, in scene units (smaller = sharper "
        "shadows and textures, longer bakes). 0 = automatic: about 1.5 pixels of the render "
        "where the object is seen through the scene camera",
    )
    bake_max_resolution: bpy.props.IntProperty(  # type: ignore[valid-type]
        name="Max Resolution",
        default=512,
        min=8,
        max=8192,
        description="Largest side of an object's baked texture, in texels (bounds the time "
        "a bake of a large or close object takes)",
    )
    bake_samples: bpy.props.IntProperty(  # type: ignore[valid-type]
        name="Bake Samples",
        default=16,
        min=1,
        max=1 << 20,
        description="Cycles samples per texel of a bake, which Cycles then denoises "
        "(more = less noise, longer bakes)",
    )
    file_version: bpy.props.IntProperty(  # type: ignore[valid-type]
        name="File Version",
        default=0,
        options={"HIDDEN"},
        description="SymRay's file version when the .blend was saved (migration.py)",
    )
    image_name: bpy.props.StringProperty(  # type: ignore[valid-type]
        name="Image",
        default="SymRay Result",
        description="Image the Render SymRay Image button writes (created if missing; not "
        "Blender's own Render Result or Viewer Node). F12 writes the Render Result",
    )
    exr_path: bpy.props.StringProperty(  # type: ignore[valid-type]
        name="EXR Path",
        default="",
        subtype="FILE_PATH",
        options=_PATH_OPTIONS,
        description="The Render SymRay Image button also writes its result as OpenEXR here "
        "(F12 uses Output Properties), a path ending in "
        ".exr (none: .exr is added), with <name>.passes.exr beside it (empty = no EXR; "
        "'//' = next to the .blend, which must be saved)",
    )

    def accuracy(self) -> dict:
        """core.render's accuracy options for the chosen quality: tolerance_px and samples,
        or (Radians) tolerance."""
        if self.quality == "RADIANS":
            return {"tolerance": float(self.tolerance)}
        px, samples = QUALITY_PRESETS.get(self.quality, (self.tolerance_px, self.samples))
        return {"tolerance_px": float(px), "samples": int(samples)}

    def passes(self) -> tuple[str, ...]:
        """Names of the core passes to compute (PASSES switched on here)."""
        return tuple(name for name, _label, toggle in PASSES if getattr(self, toggle))


@persistent
def _revalidate_on_load(_dummy: object = None) -> None:
    """After a .blend loads, refresh the stored expression errors of every scene."""
    for scene in bpy.data.scenes:
        settings = getattr(scene, "symray", None)
        if settings is not None:
            validate_expressions(settings)


def _add_pass_toggles(cls: type) -> None:
    """A ``pass_<label>`` switch in ``cls`` for each pass of the core's table the add-on
    writes (its name, default and description from there)."""
    for kind in core_passes.PASSES:
        if kind.label is None:
            continue
        cls.__annotations__[kind.toggle] = bpy.props.BoolProperty(
            name=kind.label,
            default=kind.shown,
            update=_update_passes,
            description=f"{kind.description[0].upper()}{kind.description[1:]}: '{kind.layer}' pass",
        )


_add_pass_toggles(SymRaySettings)
for _parameter in parameters():  # rg, spin, charge, ...: one setting per model parameter
    SymRaySettings.__annotations__[_parameter.name] = parameter_property(_parameter)


def register() -> None:
    """Register SymRaySettings as ``bpy.types.Scene.symray``."""
    bpy.utils.register_class(disk_properties.SymRayDiskSettings)
    bpy.utils.register_class(SymRaySettings)
    bpy.types.Scene.symray = bpy.props.PointerProperty(type=SymRaySettings)
    if _revalidate_on_load not in bpy.app.handlers.load_post:
        bpy.app.handlers.load_post.append(_revalidate_on_load)


def unregister() -> None:
    """Remove ``bpy.types.Scene.symray`` and the load handler."""
    if _revalidate_on_load in bpy.app.handlers.load_post:
        bpy.app.handlers.load_post.remove(_revalidate_on_load)
    del bpy.types.Scene.symray
    bpy.utils.unregister_class(SymRaySettings)
    bpy.utils.unregister_class(disk_properties.SymRayDiskSettings)

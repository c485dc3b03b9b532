"""SymRay objects: a black hole or a refractive medium is an object of the scene.

Each is an Empty marked by ``object.symray.kind`` ('BLACK_HOLE' or 'MEDIUM'), added with
*Add › SymRay* (``bpy.ops.symray.add_black_hole()``, ``bpy.ops.symray.add_medium()``) at
the 3D cursor, drawn at its true size (overlay.py) and set in Object Properties. With the
scene's model *Scene Objects* (``scene.symray.model == 'OBJECTS'``, the default) what
bends the light follows them: the black hole (one per scene), else the medium, else flat
space. ``effective(settings)`` is what every reader of the model uses: the scene's
settings with model, rg, spin, centre and medium box as the objects make them.
"""

from __future__ import annotations

import math
from typing import Any

import bpy

from ..core.models.registry import hole_kind, hole_parameters
from .model_settings import parameter_property

KIND_ITEMS = [
    ("NONE", "None", "An ordinary object"),
    ("BLACK_HOLE", "Black Hole", "A black hole: its position is the hole's centre, its local "
     "Z the spin axis"),
    ("MEDIUM", "Medium", "A refractive volume: its cube is the medium's box, its local axes "
     "the frame of n(x, y, z)"),
]  # fmt: skip

DISK_OUTER_SIZES = 12.0
"""A new hole's disk reaches this many times its Size."""


def rg_of(size: float, spin: float, charge: float = 0.0) -> float:
    """rg = 2M of a hole whose horizon has Boyer–Lindquist radius ``size`` at spin a/M and
    charge Q/M: r₊ = M (1 + √(1 − χ² − q²))."""
    left = max(1.0 - float(spin) ** 2 - float(charge) ** 2, 0.0)
    return 2.0 * float(size) / (1.0 + math.sqrt(left))


def hole_values(hole: Any) -> dict[str, float]:
    """A hole object's model parameters (core.models.registry): rg from its Size, and its
    spin, charge, ... as set."""
    values = {p.name: float(getattr(hole.symray, p.name)) for p in hole_parameters()}
    values["rg"] = rg_of(hole.symray.size, values.get("spin", 0.0), values.get("charge", 0.0))
    return values


def size_of(rg: float, spin: float, charge: float = 0.0) -> float:
    """The horizon radius r₊ of a hole of rg = 2M, spin a/M and charge Q/M (inverse of
    ``rg_of``)."""
    left = max(1.0 - float(spin) ** 2 - float(charge) ** 2, 0.0)
    return 0.5 * float(rg) * (1.0 + math.sqrt(left))


def _size_changed(self: bpy.types.PropertyGroup, _context: bpy.types.Context) -> None:
    """Size of a hole changed: its Empty draws the horizon, its disk keeps its proportions."""
    obj = self.id_data
    if self.kind != "BLACK_HOLE" or not isinstance(obj, bpy.types.Object):
        return
    old = float(obj.empty_display_size) if obj.type == "EMPTY" else 0.0
    if obj.type == "EMPTY":
        obj.empty_display_size = self.size
    if old <= 0.0 or not math.isfinite(old) or old == self.size:
        return
    for scene in bpy.data.scenes:
        if hole_of(scene) == obj:
            disk = scene.symray.disk
            disk.outer_radius *= self.size / old
            disk.inner_radius *= self.size / old


SIZE_TEXT = (
    "Radius of the black hole's horizon, in scene units: its shadow looks about 2.6× as large "
    "(physics: the Boyer–Lindquist horizon radius r₊; Schwarzschild radius rg = 2GM/c² at "
    "spin 0). Scaling the object does not change it"
)
SPIN_TEXT = (
    "How fast the hole turns, 0 (still) to 1 (the fastest possible); negative turns the "
    "other way. Physics: Kerr's a/M, about the object's local Z"
)


def size_property(**extra: Any) -> Any:
    """The hole's Size (object setting and Add operator option alike)."""
    return bpy.props.FloatProperty(
        name="Size", default=0.5, min=1e-6, soft_max=100.0, subtype="DISTANCE",
        description=SIZE_TEXT, **extra,
    )  # fmt: skip


def spin_property() -> Any:
    """The hole's Spin (object setting and Add operator option alike)."""
    return bpy.props.FloatProperty(
        name="Spin", default=0.6, min=-1.0, max=1.0, soft_min=0.0, subtype="FACTOR",
        description=SPIN_TEXT,
    )  # fmt: skip


class SymRayObjectSettings(bpy.types.PropertyGroup):
    """SymRay settings of one object (``object.symray``)"""

    kind: bpy.props.EnumProperty(  # type: ignore[valid-type]
        name="SymRay", items=KIND_ITEMS, default="NONE", description="What this object is to SymRay"
    )
    size: size_property(update=_size_changed)  # type: ignore[valid-type]
    spin: spin_property()  # type: ignore[valid-type]


for _parameter in hole_parameters():  # a hole's charge, ...: what the registry's holes take
    if _parameter.name not in SymRayObjectSettings.__annotations__:
        SymRayObjectSettings.__annotations__[_parameter.name] = parameter_property(_parameter)


def rendering_collections(view_layer: Any) -> set[int]:
    """Pointers of the collections whose objects render in ``view_layer``: not excluded
    from it and not disabled in renders, nor under a collection that is."""
    found: set[int] = set()
    stack = [view_layer.layer_collection]
    while stack:
        layer = stack.pop()
        if layer.exclude or layer.collection.hide_render:
            continue
        found.add(layer.collection.as_pointer())
        stack.extend(layer.children)
    return found


def _view_layer(scene: bpy.types.Scene) -> Any:
    """The view layer a scene's objects are judged in without a depsgraph: the context's
    when it shows ``scene`` (the panel, the Add operators), else the scene's first."""
    context_scene = getattr(bpy.context, "scene", None)
    layer = getattr(bpy.context, "view_layer", None)
    if context_scene is not None and context_scene.original == scene.original and layer:
        return layer
    return scene.view_layers[0] if len(scene.view_layers) else None


def of_kind(
    scene: bpy.types.Scene, kind: str, depsgraph: bpy.types.Depsgraph | None = None
) -> list[bpy.types.Object]:
    """The scene's objects of SymRay ``kind`` that render: not hidden in renders, in a
    collection that renders in the view layer. With ``depsgraph`` its evaluated objects
    (settings as animated at its frame, keyed visibility included), else the originals."""
    if depsgraph is not None:
        candidates, view_layer = list(depsgraph.objects), depsgraph.view_layer
    else:
        candidates, view_layer = list(scene.objects), _view_layer(scene)
    chosen = [
        obj
        for obj in candidates
        if getattr(getattr(obj, "symray", None), "kind", "NONE") == kind and not obj.hide_render
    ]
    if not chosen or view_layer is None:
        return chosen
    shown = rendering_collections(view_layer)
    return [obj for obj in chosen if in_collections(obj, shown)]


def in_collections(obj: bpy.types.Object, collections: set[int]) -> bool:
    """Whether ``obj`` (original or evaluated) is in one of ``collections`` (pointers, as
    rendering_collections gives them)."""
    return any(c.as_pointer() in collections for c in obj.original.users_collection)


def hole_of(
    scene: bpy.types.Scene, depsgraph: bpy.types.Depsgraph | None = None
) -> bpy.types.Object | None:
    """The scene's black hole object, if it has exactly one (see of_kind)."""
    holes = of_kind(scene, "BLACK_HOLE", depsgraph)
    return holes[0] if len(holes) == 1 else None


def objects_problem(scene: bpy.types.Scene, depsgraph: bpy.types.Depsgraph | None = None) -> str:
    """Why the scene's SymRay objects cannot render ("" when they can; see of_kind)."""
    holes = of_kind(scene, "BLACK_HOLE", depsgraph)
    media = of_kind(scene, "MEDIUM", depsgraph)
    if len(holes) > 1:
        names = ", ".join(f"'{o.name}'" for o in holes)
        return (
            f"The scene has {len(holes)} black holes ({names}): SymRay renders one per "
            "scene; delete one or turn off its Render visibility"
        )
    if len(media) > 1:
        names = ", ".join(f"'{o.name}'" for o in media)
        return f"The scene has {len(media)} media ({names}): SymRay renders one per scene"
    if holes and media:
        return (
            f"The scene has a black hole ('{holes[0].name}') and a medium "
            f"('{media[0].name}'): SymRay renders one of them per scene"
        )
    return ""


def enclosing(scene: bpy.types.Scene, hole: bpy.types.Object) -> list[str]:
    """Names of the scene's rendered mesh objects whose bounding box holds ``hole``'s centre
    (a hole added at the cursor inside the factory cube: the cube would hide it)."""
    from mathutils import Vector

    centre = hole.matrix_world.translation
    names = []
    for obj in scene.objects:
        if obj.type != "MESH" or obj.hide_render or obj is hole:
            continue
        local = obj.matrix_world.inverted_safe() @ centre
        corners = [Vector(c) for c in obj.bound_box]
        lo = Vector(min(c[i] for c in corners) for i in range(3))
        hi = Vector(max(c[i] for c in corners) for i in range(3))
        if all(lo[i] <= local[i] <= hi[i] for i in range(3)):
            names.append(obj.name)
    return names


def inside_warning(scene: bpy.types.Scene, hole: bpy.types.Object) -> str:
    """A warning when the hole sits inside objects ("" when it does not)."""
    names = enclosing(scene, hole)
    if not names:
        return ""
    listed = ", ".join(f"'{name}'" for name in names)
    return (
        f"The black hole '{hole.name}' is inside {listed}: its surfaces hide it; move the "
        "hole or the object (G)"
    )


def medium_box(obj: bpy.types.Object) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """(min, max) of a medium's box in its local frame: its Empty's cube, scaled."""
    half = [float(obj.empty_display_size) * abs(float(s)) for s in obj.scale]
    return tuple(-h for h in half), tuple(half)


class Effective:
    """A scene's ``symray`` settings as rendered: with model 'OBJECTS', model, rg, spin,
    centre and medium box come from the scene's hole or medium object (the depsgraph's
    evaluated one when given: animated settings at its frame); every other setting (and
    everything under any other model) reads through unchanged."""

    def __init__(self, settings: Any, depsgraph: bpy.types.Depsgraph | None = None) -> None:
        self._settings = settings
        self.object_problem = ""
        if getattr(settings, "model", None) != "OBJECTS":
            return
        scene = settings.id_data
        self.object_problem = objects_problem(scene, depsgraph)
        hole, media = hole_of(scene, depsgraph), of_kind(scene, "MEDIUM", depsgraph)
        if self.object_problem or (hole is None and not media):
            self.model, self.center = "FLAT", None
        elif hole is not None:
            values = hole_values(hole)
            self.model = hole_kind(values).name
            for name, value in values.items():
                setattr(self, name, value)
            self.center = hole
            self.hole_size = hole.symray.size  # Size as set (rg is NaN where Spin is)
        else:
            self.model, self.center = "MEDIUM", media[0]
            self.use_medium_bounds = True
            self.medium_min, self.medium_max = medium_box(media[0])

    def __getattr__(self, name: str) -> Any:
        return getattr(self._settings, name)

    @property
    def follows_objects(self) -> bool:
        """Whether the model comes from the scene's objects (model 'OBJECTS')."""
        return self._settings.model == "OBJECTS"


def effective(settings: Any, depsgraph: bpy.types.Depsgraph | None = None) -> Any:
    """``settings`` (a scene.symray) as rendered (see Effective): with ``depsgraph``, from
    its evaluated objects (what a frame renders); itself if already so."""
    return settings if isinstance(settings, Effective) else Effective(settings, depsgraph)


def _new_empty(
    scene: bpy.types.Scene,
    name: str,
    display: str,
    size: float,
    collection: bpy.types.Collection | None = None,
) -> bpy.types.Object:
    """An Empty at the scene's 3D cursor, in ``collection`` (the scene's own if None)."""
    obj = bpy.data.objects.new(name, None)
    obj.empty_display_type = display
    obj.empty_display_size = size
    obj.location = scene.cursor.location
    (collection or scene.collection).objects.link(obj)
    return obj


def _make_active(context: bpy.types.Context, obj: bpy.types.Object) -> None:
    """Select ``obj`` alone and make it the active object (as Add does)."""
    for other in context.view_layer.objects:
        other.select_set(False)
    obj.select_set(True)
    context.view_layer.objects.active = obj


def ensure_hole(scene: bpy.types.Scene) -> bpy.types.Object:
    """The scene's black hole object; a new one at the 3D cursor if it has none."""
    hole = hole_of(scene)
    return hole if hole is not None else _new_hole(scene, 1.0)


def _new_hole(
    scene: bpy.types.Scene, size: float, collection: bpy.types.Collection | None = None
) -> bpy.types.Object:
    """A black hole object of ``size`` at the 3D cursor (its Empty's sphere: the horizon)."""
    hole = _new_empty(scene, "Black Hole", "SPHERE", size, collection)
    hole.symray.size = size  # before its kind: no disk to rescale yet
    hole.symray.kind = "BLACK_HOLE"
    return hole


def _refused_second(operator: bpy.types.Operator, scene: bpy.types.Scene, kinds) -> bool:
    """Report (an error) and True when ``scene`` already has an object of ``kinds``: SymRay
    renders one black hole or medium per scene."""
    existing = [obj for kind in kinds for obj in of_kind(scene, kind)]
    if not existing:
        return False
    label = {"BLACK_HOLE": "a black hole", "MEDIUM": "a medium"}[existing[0].symray.kind]
    operator.report(
        {"ERROR"},
        f"The scene already has {label} ('{existing[0].name}'): SymRay renders one black "
        "hole or medium per scene",
    )
    return True


class SYMRAY_OT_add_black_hole(bpy.types.Operator):
    """Add a black hole at the 3D cursor: SymRay renders the scene's light bent by it"""

    bl_idname = "symray.add_black_hole"
    bl_label = "Black Hole"
    bl_options = {"REGISTER", "UNDO"}

    size: size_property()  # type: ignore[valid-type]
    spin: spin_property()  # type: ignore[valid-type]
    disk: bpy.props.BoolProperty(  # type: ignore[valid-type]
        name="Accretion Disk",
        default=True,
        description="A glowing disk of gas around it, from its innermost stable orbit to "
        f"{DISK_OUTER_SIZES:g}× its size (the Cinematic look)",
    )

    def execute(self, context: bpy.types.Context) -> set[str]:
        """Add the hole; refused (with a message) when the scene has one."""
        scene = context.scene
        if _refused_second(self, scene, ("BLACK_HOLE",)):
            return {"CANCELLED"}
        if self.disk and abs(self.spin) >= 1.0:
            self.report({"ERROR"}, "A disk needs a spin below 1 (at 1 its inner edge meets "
                        "the horizon): choose 0.999, or no disk")  # fmt: skip
            return {"CANCELLED"}
        obj = _new_hole(scene, self.size, context.collection)
        _make_active(context, obj)
        obj.symray.spin = self.spin
        settings = scene.symray
        settings.model = "OBJECTS"
        settings.center = None
        disk = settings.disk
        disk.enabled = self.disk
        disk.use_isco = True
        disk.outer_radius = DISK_OUTER_SIZES * self.size
        disk.look, disk.auto_exposure = "CINEMATIC", True  # the glow people know
        context.view_layer.update()
        warning = inside_warning(scene, obj)
        if warning:
            self.report({"WARNING"}, warning)
        return {"FINISHED"}


class SYMRAY_OT_add_medium(bpy.types.Operator):
    """Add a refractive medium at the 3D cursor: a box of air whose index n(x, y, z) bends
    light (mirages)"""

    bl_idname = "symray.add_medium"
    bl_label = "Medium"
    bl_options = {"REGISTER", "UNDO"}

    size: bpy.props.FloatProperty(  # type: ignore[valid-type]
        name="Size",
        default=10.0,
        min=1e-6,
        subtype="DISTANCE",
        description="Half the edge of the medium's box, in scene units",
    )

    def execute(self, context: bpy.types.Context) -> set[str]:
        """Add the medium; refused (with a message) when the scene has a hole or medium."""
        scene = context.scene
        if _refused_second(self, scene, ("MEDIUM", "BLACK_HOLE")):
            return {"CANCELLED"}
        obj = _new_empty(scene, "Medium", "CUBE", self.size, context.collection)
        _make_active(context, obj)
        obj.symray.kind = "MEDIUM"
        scene.symray.model = "OBJECTS"
        scene.symray.center = None
        return {"FINISHED"}


class VIEW3D_MT_symray_add(bpy.types.Menu):
    """SymRay's objects in Add"""

    bl_idname = "VIEW3D_MT_symray_add"
    bl_label = "SymRay"

    def draw(self, _context: bpy.types.Context) -> None:
        """Black Hole and Medium."""
        self.layout.operator(SYMRAY_OT_add_black_hole.bl_idname, icon="SHADING_SOLID")
        self.layout.operator(SYMRAY_OT_add_medium.bl_idname, icon="MOD_FLUID")


def _add_menu(self: bpy.types.Menu, _context: bpy.types.Context) -> None:
    self.layout.menu(VIEW3D_MT_symray_add.bl_idname, icon="LIGHT_SUN")


CLASSES = (
    SymRayObjectSettings,
    SYMRAY_OT_add_black_hole,
    SYMRAY_OT_add_medium,
    VIEW3D_MT_symray_add,
)


def register() -> None:
    """Register ``object.symray``, the Add operators and the Add › SymRay menu."""
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Object.symray = bpy.props.PointerProperty(type=SymRayObjectSettings)
    bpy.types.VIEW3D_MT_add.append(_add_menu)


def unregister() -> None:
    """Remove what register() added."""
    bpy.types.VIEW3D_MT_add.remove(_add_menu)
    del bpy.types.Object.symray
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)

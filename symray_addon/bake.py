"""Surfaces lit by Blender: Cycles bakes of each rendered object's view-independent radiance.

``bake_surfaces(scene, depsgraph)`` bakes, with Cycles, the radiance every rendered object
sends out in all directions alike (Combined with Diffuse direct + indirect and Emission;
no Glossy, no Transmission) into a float image per object, on the object's active UV map,
or, where it has none (or is no mesh, or a slot has no node material, or its UVs leave
[0, 1]² or cover it more than once: tiled or mirrored UVs cannot hold a bake), on a
temporary Smart UV Project of a copy of its evaluated mesh. The SymRay renderer then shows
that texture where a curved ray hits (``export_meshes.BakedSurface``). Light reaches the
surfaces on straight paths (Cycles' flat-space lighting); what a surface sends towards
the camera through curved space is SymRay's.

Nothing of the user's scene changes for good: the bake runs in a temporary scene that
links the scene's collections (its own render engine, samples, selection and active
object), the image nodes it adds to materials are removed, a copied object's original is
hidden from rendering only while the copy bakes, and every temporary datablock is removed
(``finally``). Bakes are cached by a key over everything that can change the light on a
surface (every rendered object's mesh, transform and materials, the lights, the world, the
samples): a new frame, camera or SymRay model reuses them while they are at least as fine
as the render asks (``bake_texels``: with *Texel Size* 0 the texels follow the object's
size on screen), an edit bakes again. Cycles runs through ``bpy.ops``, so baking needs
Blender's main thread: the operator, ``blender -b`` and scripts bake; F12 in the UI renders
on another thread and can only reuse a bake (the *Bake Lighting* button makes one).

Cycles samples each texel *Bake Samples* times (16 by default) and then denoises the bake
(OpenImageDenoise, ``DENOISE_QUALITY``): in a 640x360 render of five simple objects
under the factory light this is within 0.003 (mean absolute, linear) of a bake of 256
samples without denoising, where 16 samples without denoising are 0.0065 off and show
grain, and 64 samples 0.0035. The progress (object k of n) goes to ``reporting``'s
callback and the window's progress indicator; the operators' console chatter is held back
(``quiet``).
"""

from __future__ import annotations

import hashlib
import math
import os
import threading
from collections import OrderedDict
from collections.abc import Callable, Iterable, Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from typing import Any, NamedTuple

import bpy
import numpy as np

from . import bake_texels, quiet
from .export_meshes import (
    GEOMETRY_TYPES,
    BakedSurface,
    _is_rendered,
    _mesh_arrays,
    non_finite_warning,
)
from .materials import DEFAULT_COLOR, image_pixels, node_tree_of

PASS_FILTER = {"EMIT", "DIRECT", "INDIRECT", "DIFFUSE"}
"""Cycles' Combined bake restricted to what does not depend on the viewing direction."""
DENOISE = True
"""Whether Cycles denoises a bake (OpenImageDenoise, guided by albedo and normals)."""
DENOISE_PREFILTER = "NONE"
DENOISE_QUALITY = "BALANCED"
"""Cycles' denoiser settings for bakes (its guides, albedo and normals, taken as they are;
OpenImageDenoise's balanced model). Measured on flat text lit by a Sun (exactly Lambert
without denoising), the fraction of hits within 5 % of Lambert at the glyphs' UV island
edges: 96 % with these, 67 % with Cycles' defaults ('ACCURATE', 'HIGH'; three times the
time), 49 % with the 'FAST' prefilter."""
MARGIN = 4
"""Texels the bake extends past the UV islands (bilinear sampling reads one beyond)."""
CACHE_BYTES = 512 * 2**20
"""Baked pixels kept between renders, at most (least recently used go first)."""
TEMP_NAME = "SymRay Bake"

Progress = Callable[[int, int, str], None]
"""progress(done, total, name): ``done`` of ``total`` objects baked, ``name`` baking next
(empty when all are done)."""


@dataclass
class Baked(BakedSurface):
    """A cached bake: the surface, and the world units its UV square spans."""

    extent: float = 0.0
    """Root of the surface's world area over the UV area it covers."""


_cache: OrderedDict[str, Baked] = OrderedDict()
stats = {"baked": 0, "reused": 0}
"""Objects baked and bakes reused since the add-on loaded (for tests and the console)."""
_reporters: list[Progress] = []
COARSE_WARNING = (
    "The lighting was baked for a smaller image or a farther camera than this render's: "
    "press Bake Lighting in the SymRay panel again for sharper surfaces"
)


def clear_cache() -> None:
    """Forget every cached bake."""
    _cache.clear()


@contextmanager
def reporting(progress: Progress) -> Iterator[None]:
    """Send the progress of the bakes made in the block to ``progress`` too (a render
    engine's status line); the innermost reporter is told."""
    _reporters.append(progress)
    try:
        yield
    finally:
        _reporters.remove(progress)


@contextmanager
def _progress(total: int) -> Iterator[Progress]:
    """A progress(done, total, name) that tells the innermost ``reporting`` callback and,
    in Blender's UI, the window's progress indicator (ended however the block ends)."""
    window_manager = None
    if not bpy.app.background and threading.current_thread() is threading.main_thread():
        window_manager = getattr(bpy.context, "window_manager", None)
    if window_manager is not None and bpy.context.window is not None:
        window_manager.progress_begin(0, max(total, 1))
    else:
        window_manager = None

    def tell(done: int, count: int, name: str) -> None:
        if window_manager is not None:
            window_manager.progress_update(done)
        if _reporters:
            _reporters[-1](done, count, name)

    try:
        yield tell
    finally:
        if window_manager is not None:
            window_manager.progress_end()


def scene_has_lights(depsgraph: bpy.types.Depsgraph) -> bool:
    """Whether a light object is rendered in ``depsgraph``."""
    return any(
        inst.object.type == "LIGHT" and inst.show_self and not inst.object.original.hide_render
        for inst in depsgraph.object_instances
    )


def wants_baking(settings: Any, depsgraph: bpy.types.Depsgraph) -> bool:
    """Whether a render bakes its surfaces (Surface Lighting: Bake, or Auto with lights)."""
    if settings.lighting == "BAKE":
        return True
    return settings.lighting == "AUTO" and scene_has_lights(depsgraph)


def bake_surfaces(
    scene: bpy.types.Scene,
    depsgraph: bpy.types.Depsgraph,
    warnings: list[str] | None = None,
    bake: bool = True,
) -> dict[str, BakedSurface]:
    """Baked radiance of every rendered (non-instanced) object with faces, by object name.

    Reuses cached bakes at least as fine as asked; bakes the others with Cycles (main
    thread only; off it, a coarser cached bake is used, with COARSE_WARNING). An object
    with non-finite vertices is left out (and out of the others' bakes), named in
    ``warnings``. Raises ValueError when Cycles is missing, a bake fails, or one is needed
    off the main thread. ``bake`` False (the viewport): as off the main thread, never bake.
    """
    settings = scene.symray
    targets, keys, missing, broken, texels = _lookup(scene, depsgraph)
    for obj in broken:
        _note(warnings, non_finite_warning(obj.name))
    if missing and (not bake or threading.current_thread() is not threading.main_thread()):
        if any(keys[obj.name] not in _cache for obj in missing):
            raise ValueError(
                "Surface lighting is baked by Cycles on Blender's main thread, which F12 "
                "does not run on: press Bake Lighting in the SymRay panel first (or use "
                "Render SymRay Image), or set Surface Lighting to Unlit"
            )
        _note(warnings, COARSE_WARNING)
        missing = []
    baking = {obj.name for obj in missing}
    found: dict[str, Baked] = {
        obj.name: _cache[keys[obj.name]] for obj in targets if obj.name not in baking
    }
    if missing:
        with ExitStack() as stack:
            tell = stack.enter_context(_progress(len(missing)))
            temp = stack.enter_context(_bake_scene(scene, depsgraph))
            stack.enter_context(_hidden(obj.original for obj in broken))
            for done, obj in enumerate(missing):
                tell(done, len(missing), obj.name)
                found[obj.name] = _bake_object(temp, depsgraph, obj, settings, texels[obj.name])
            tell(len(missing), len(missing), "")
    for obj in targets:
        _remember(keys[obj.name], found[obj.name])
    stats["baked"] += len(missing)
    stats["reused"] += len(targets) - len(missing)
    return found


def can_bake_now(scene: bpy.types.Scene, depsgraph: bpy.types.Depsgraph) -> bool:
    """Whether bake_surfaces would succeed here: on the main thread, or all bakes cached
    (finely enough or not)."""
    if threading.current_thread() is threading.main_thread():
        return True
    return all_cached(scene, depsgraph)


def all_cached(scene: bpy.types.Scene, depsgraph: bpy.types.Depsgraph) -> bool:
    """Whether every object to bake has a cached bake (finely enough or not): bake_surfaces
    would then bake nothing off the main thread (the viewport's condition)."""
    plan = _lookup(scene, depsgraph)
    return all(plan.keys[obj.name] in _cache for obj in plan.missing)


def _note(warnings: list[str] | None, text: str) -> None:
    """Add ``text`` to ``warnings`` (when given) unless it is there already."""
    if warnings is not None and text not in warnings:
        warnings.append(text)


def automatic(settings: Any) -> bool:
    """Whether the texel size follows the objects' size on screen (Texel Size 0)."""
    return float(settings.bake_texel_size) == 0.0


class _Plan(NamedTuple):
    """What a render's bakes are: found in the cache, or to be made."""

    targets: list[bpy.types.Object]
    """The objects to bake (rendered, with faces, finite)."""
    keys: dict[str, str]
    """Their cache keys, by name."""
    missing: list[bpy.types.Object]
    """Those without a cached bake as fine as asked."""
    broken: list[bpy.types.Object]
    """Objects left out for non-finite vertices."""
    texels: dict[str, float | None]
    """The texel size asked for each target (None: automatic without a camera)."""


def _lookup(scene: bpy.types.Scene, depsgraph: bpy.types.Depsgraph) -> _Plan:
    """Which objects a render bakes, their keys, and which are not cached finely enough."""
    settings = scene.symray
    auto = automatic(settings)
    camera = bake_texels.scene_camera(scene, depsgraph) if auto else None
    candidates = _candidates(depsgraph)
    meshes = {obj.name: _mesh_key(obj, camera) for obj in candidates}
    targets = [obj for obj in candidates if meshes[obj.name].faces and meshes[obj.name].finite]
    broken = [obj for obj in candidates if meshes[obj.name].faces and not meshes[obj.name].finite]
    base = _scene_key(scene, depsgraph, meshes)
    keys = {obj.name: _digest(base, obj.name) for obj in targets}
    texels: dict[str, float | None] = {}
    for obj in targets:
        footprint = meshes[obj.name].footprint
        if not auto:
            texels[obj.name] = float(settings.bake_texel_size)
        elif footprint is not None:
            texels[obj.name] = bake_texels.TEXEL_PIXELS * footprint
        else:
            texels[obj.name] = None
    max_resolution = int(settings.bake_max_resolution)

    def fine_enough(obj: bpy.types.Object) -> bool:
        baked = _cache.get(keys[obj.name])
        if baked is None:
            return False
        wanted = bake_texels.side(baked.extent, texels[obj.name], max_resolution, auto)
        return baked.pixels.shape[0] >= wanted

    missing = [obj for obj in targets if not fine_enough(obj)]
    return _Plan(targets, keys, missing, broken, texels)


def _candidates(depsgraph: bpy.types.Depsgraph) -> list[bpy.types.Object]:
    """The evaluated objects that may be baked: rendered geometry that is not an instance
    (a curve or text object as itself: its mesh is the surface it renders)."""
    return [
        inst.object
        for inst in depsgraph.object_instances
        if not inst.is_instance
        and inst.show_self
        and inst.object.type in GEOMETRY_TYPES
        and not inst.object.original.hide_render
    ]


@contextmanager
def _hidden(objects: Iterable[bpy.types.Object]) -> Iterator[None]:
    """Hide ``objects`` (originals) from rendering until the block ends."""
    with ExitStack() as stack:
        for obj in objects:
            stack.callback(setattr, obj, "hide_render", obj.hide_render)
            obj.hide_render = True
        yield


def _remember(key: str, surface: Baked) -> None:
    """Keep ``surface`` under ``key``, dropping the least recently used past CACHE_BYTES."""
    _cache[key] = surface
    _cache.move_to_end(key)
    while len(_cache) > 1 and sum(s.pixels.nbytes for s in _cache.values()) > CACHE_BYTES:
        _cache.popitem(last=False)


# -- the cache key ----------------------------------------------------------------------


def _digest(*parts: object) -> str:
    """A short hash of the parts' reprs."""
    return hashlib.blake2b(repr(parts).encode(), digest_size=20).hexdigest()


def _plain(value: Any) -> Any:
    """``value`` as plain data with a stable repr, or None (structs have addresses)."""
    if isinstance(value, (bool, int, float, str)):
        return value
    if isinstance(value, bpy.types.ID):
        return ("ID", value.name_full, getattr(value, "filepath", ""))
    if isinstance(value, (set, frozenset)):
        return tuple(sorted(str(v) for v in value))
    try:
        items = tuple(value)
    except TypeError:
        return None
    if all(isinstance(v, (bool, int, float)) for v in items):
        return items
    return None


def _own_properties(struct: Any, base: Any = None) -> tuple:
    """(name, plain value) of ``struct``'s RNA properties not defined on ``base``."""
    skip = set(base.bl_rna.properties.keys()) if base is not None else set()
    skip |= {"rna_type", "name", "location", "width", "height", "select", "dimensions"}
    skip.add("use_nodes")  # deprecated on lights in Blender 5; their tree is hashed instead
    return tuple(
        (prop.identifier, _plain(getattr(struct, prop.identifier, None)))
        for prop in struct.bl_rna.properties
        if prop.identifier not in skip
    )


def _tree_key(tree: bpy.types.NodeTree | None, depth: int = 0) -> tuple:
    """Everything of a node tree that changes what it computes (nested groups included)."""
    if tree is None or depth > 16:
        return ()
    nodes = []
    for node in tree.nodes:
        inputs = tuple(_plain(getattr(s, "default_value", None)) for s in node.inputs)
        ramp = getattr(node, "color_ramp", None)
        stops = tuple((e.position, tuple(e.color)) for e in ramp.elements) if ramp else ()
        group = _tree_key(node.node_tree, depth + 1) if node.type == "GROUP" else ()
        own = _own_properties(node, bpy.types.Node)
        image = _image_key(getattr(node, "image", None))
        nodes.append((node.name, node.bl_idname, node.mute, own, inputs, stops, group, image))
    links = tuple(
        (lk.from_node.name, lk.from_socket.identifier, lk.to_node.name, lk.to_socket.identifier)
        for lk in tree.links
        if not lk.is_muted
    )
    return tuple(nodes), links


def _material_key(material: bpy.types.Material | None) -> tuple:
    """A material's colour settings and node tree."""
    if material is None:
        return ()
    return material.name_full, tuple(material.diffuse_color), _tree_key(node_tree_of(material))


def _matrix(matrix: Any) -> tuple:
    """A 4x4 matrix as a flat tuple."""
    return tuple(np.array(matrix, dtype=np.float64).ravel().tolist())


class _Mesh(NamedTuple):
    """An evaluated object's mesh as the cache sees it."""

    key: str
    """Hash of its triangles, UVs, normals (smooth or flat) and material slots."""
    faces: bool
    """Whether it has a surface (a path or a wire has none: nothing to bake or hit)."""
    finite: bool
    """Whether its world-space vertices are all finite numbers."""
    footprint: float | None = None
    """World size of a pixel of the camera over its surface (None: no camera asked)."""


def _mesh_key(obj: bpy.types.Object, camera: Any = None) -> _Mesh:
    """The cache's view of an evaluated object's mesh (an empty one if it has none), with
    its on-screen pixel size through ``camera`` (a core.Camera) when one is given."""
    try:
        mesh = obj.to_mesh()
    except RuntimeError:
        mesh = None
    if mesh is None:
        return _Mesh("", False, True)
    try:
        arrays = _mesh_arrays(mesh)
        normals = np.empty(len(mesh.loop_triangles) * 9, dtype=np.float32)
        mesh.loop_triangles.foreach_get("split_normals", normals)
    finally:
        obj.to_mesh_clear()
    h = hashlib.blake2b(digest_size=20)
    for array in (*arrays, normals):
        h.update(np.ascontiguousarray(array).tobytes())
    co, tri = arrays[0], arrays[1]
    matrix = np.array(obj.matrix_world, dtype=np.float64)
    finite = bool(np.all(np.isfinite(co)) and np.all(np.isfinite(matrix)))
    footprint = None
    if camera is not None and finite and len(tri) > 0:
        world = (co @ matrix[:3, :3].T + matrix[:3, 3])[tri]
        footprint = bake_texels.pixel_footprint(camera, world)
    return _Mesh(h.hexdigest(), len(tri) > 0, finite, footprint)


OBJECT_FLAGS = (
    "visible_camera",
    "visible_diffuse",
    "visible_glossy",
    "visible_transmission",
    "visible_volume_scatter",
    "visible_shadow",
    "visible_raycast",
    "is_holdout",
    "is_shadow_catcher",
    "pass_index",
)
"""Object settings that change what Cycles bakes (ray visibility, holdout, ...)."""


def _flags(obj: bpy.types.Object) -> tuple:
    """An object's ray-visibility settings and colour (read by Object Info nodes)."""
    original = obj.original
    return tuple(getattr(original, name, None) for name in OBJECT_FLAGS) + tuple(obj.color)


def _file_stamp(image: bpy.types.Image) -> tuple:
    """(modification time, size) of an image's file, or () where it has none."""
    try:
        stat = os.stat(bpy.path.abspath(image.filepath, library=image.library))
    except (OSError, ValueError):
        return ()
    return stat.st_mtime_ns, stat.st_size


def _image_key(image: bpy.types.Image | None) -> tuple:
    """What an image's pixels depend on: its settings and contents (the pixels when edited
    in Blender, the packed file when packed, the file's time and size when on disk)."""
    if image is None:
        return ()
    settings = (
        image.name_full,
        image.source,
        image.filepath,
        image.colorspace_settings.name,
        image.alpha_mode,
        image.generated_type,
        tuple(image.generated_color),
        image.generated_width,
        image.generated_height,
        image.use_generated_float,
    )
    if image.is_dirty:
        pixels = np.empty(len(image.pixels), dtype=np.float32)
        image.pixels.foreach_get(pixels)
        content: Any = hashlib.blake2b(pixels.tobytes(), digest_size=20).hexdigest()
    elif image.packed_file is not None:
        content = hashlib.blake2b(image.packed_file.data, digest_size=20).hexdigest()
    elif image.source == "GENERATED":
        content = ()
    else:
        content = _file_stamp(image)
    return settings, content


def _scene_key(
    scene: bpy.types.Scene, depsgraph: bpy.types.Depsgraph, meshes: dict[str, _Mesh]
) -> str:
    """One key over everything that can change the light on any surface, and the settings.
    ``meshes``: the objects' meshes known so far by name (the others are added)."""
    settings = scene.symray
    parts: list[Any] = [  # the texel size is not here: a finer bake serves a coarser ask
        settings.bake_samples,
        DENOISE,
        DENOISE_PREFILTER,
        DENOISE_QUALITY,
        bpy.app.version,
    ]
    for inst in depsgraph.object_instances:
        obj = inst.object
        if obj.type == "LIGHT" and inst.show_self and not obj.original.hide_render:
            light = obj.data
            tree = _tree_key(getattr(light, "node_tree", None))
            own = _own_properties(light, bpy.types.ID)  # not users, tags, ...
            parts.append(("light", _matrix(inst.matrix_world), own, tree, _flags(obj)))
        elif _is_rendered(inst):
            if obj.name not in meshes:
                meshes[obj.name] = _mesh_key(obj)
            slots = tuple(_material_key(slot.material) for slot in obj.material_slots)
            flags = _flags(obj)
            parts.append((obj.name, inst.is_instance, _matrix(inst.matrix_world), slots, flags))
    parts.append(sorted((name, mesh.key) for name, mesh in meshes.items()))
    world = scene.world
    if world is not None:
        parts.append(("world", tuple(world.color), _tree_key(node_tree_of(world))))
    return _digest(*parts)


# -- baking -----------------------------------------------------------------------------


def _link_collections(scene: bpy.types.Scene, temp: bpy.types.Scene) -> None:
    """Link ``scene``'s objects and child collections into ``temp`` (no copies)."""
    for obj in scene.collection.objects:
        temp.collection.objects.link(obj)
    for child in scene.collection.children:
        temp.collection.children.link(child)


def _copy_exclusion(source: bpy.types.LayerCollection, target: bpy.types.LayerCollection):
    """Exclude in ``target`` the collections excluded in ``source`` (same tree)."""
    for child in source.children:
        twin = target.children.get(child.name)
        if twin is not None:
            twin.exclude = child.exclude
            _copy_exclusion(child, twin)


def _copy_view_layer(
    scene: bpy.types.Scene, depsgraph: bpy.types.Depsgraph, temp: bpy.types.Scene
) -> None:
    """Exclude in ``temp``'s view layer the collections the rendered view layer excludes.

    A new scene's view layer has its layer collections only once it is synced with the
    collections linked to it (``frame_set`` or ``update``), and its objects are those of
    the collections left only once it is synced again (``update``)."""
    layer = scene.view_layers.get(depsgraph.view_layer.name) if depsgraph.view_layer else None
    target = temp.view_layers[0]
    if layer is None or layer.layer_collection is None or target.layer_collection is None:
        raise ValueError(f"The view layers of '{scene.name}' could not be read for baking")
    _copy_exclusion(layer.layer_collection, target.layer_collection)
    target.update()


def _sync_view_layers() -> None:
    """Bring every scene's view layers up to date with their collections again.

    Adding or removing datablocks (the temporary scene, images, copies) marks the view
    layers of every scene out of sync, and Blender syncs them lazily. An animation render
    keeps one depsgraph of its scene for all frames; at the next frame it copies the scene
    again, and a copy of an out-of-sync view layer syncs itself into bases that point to
    no original, which crashes Blender 5 (``render(animation=True)``, ``blender -b -a``).
    Iterating a layer collection's children syncs its view layer, evaluating nothing.
    """
    for scene in bpy.data.scenes:
        for layer in scene.view_layers:
            if layer.layer_collection is not None:
                for _child in layer.layer_collection.children:
                    break


@contextmanager
def _bake_scene(scene: bpy.types.Scene, depsgraph: bpy.types.Depsgraph) -> Iterator[Any]:
    """A temporary Cycles scene holding ``scene``'s objects, removed afterwards."""
    temp = bpy.data.scenes.new(TEMP_NAME)
    try:
        if not hasattr(temp, "cycles"):
            raise ValueError(
                "Surface lighting is baked with Cycles, which is not enabled: enable the "
                "Cycles add-on, or set Surface Lighting to Unlit"
            )
        _link_collections(scene, temp)
        temp.world = scene.world
        temp.render.engine = "CYCLES"
        temp.render.threads_mode = scene.render.threads_mode
        temp.render.threads = scene.render.threads
        temp.cycles.device = "CPU"
        temp.cycles.samples = int(scene.symray.bake_samples)
        # adaptive sampling stopped no texel early at 16 samples (measured): fixed counts
        temp.cycles.use_adaptive_sampling = False
        temp.cycles.use_denoising = DENOISE
        temp.cycles.denoising_input_passes = "RGB_ALBEDO_NORMAL"
        temp.cycles.denoising_prefilter = DENOISE_PREFILTER
        temp.cycles.denoising_quality = DENOISE_QUALITY
        temp.frame_set(scene.frame_current, subframe=scene.frame_subframe)
        _copy_view_layer(scene, depsgraph, temp)
        yield temp
    finally:
        bpy.data.scenes.remove(temp)
        _sync_view_layers()


def extent(area: float, uv_area: float) -> float:
    """World units the UV square spans: the root of a surface's ``area`` over the UV area
    it covers (at least 1e-6 of it, at most all)."""
    return math.sqrt(max(area, 0.0) / min(max(uv_area, 1e-6), 1.0))


def _areas(mesh: bpy.types.Mesh, matrix: Any, loop_uv: np.ndarray | None) -> tuple[float, float]:
    """World-space area of a mesh under ``matrix`` and the area its UVs cover."""
    co, tri, _slots, uv = _mesh_arrays(mesh, loop_uv)
    m = np.array(matrix, dtype=np.float64)
    world = (co @ m[:3, :3].T)[tri]
    area = 0.5 * np.linalg.norm(
        np.cross(world[:, 1] - world[:, 0], world[:, 2] - world[:, 0]), axis=1
    )
    e1, e2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    uv_area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    return float(area.sum()), float(uv_area.sum())


def _usable(material: bpy.types.Material | None) -> bool:
    """Whether Cycles can bake into ``material`` as it is: a local node material (an image
    node is added to it for the bake)."""
    return material is not None and material.library is None and node_tree_of(material) is not None


def _needs_copy(obj: bpy.types.Object) -> bool:
    """Whether ``obj`` (evaluated) must be baked as a temporary copy: no mesh, no UV map,
    or a material slot Cycles cannot bake into."""
    original = obj.original
    if original.type != "MESH" or not obj.data.uv_layers:
        return True
    slots = original.material_slots
    return not slots or not all(_usable(slot.material) for slot in slots)


def _unique_uvs(mesh: bpy.types.Mesh) -> bool:
    """Whether the active UV map can hold a bake: inside [0, 1]², not covering more than
    its area (tiled or mirrored UVs would share texels; smaller overlaps go unnoticed), and
    no more than 1 % of the triangles collapsed to a line or a point (a curve's default
    UVs, an unfinished unwrap)."""
    uv = _mesh_arrays(mesh)[3]
    if uv.size == 0 or np.any(uv < -1e-6) or np.any(uv > 1.0 + 1e-6):
        return False
    e1, e2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    return float(area.sum()) <= 1.001 and float(np.mean(area <= 1e-12)) <= 0.01


def _bake_object(
    temp: bpy.types.Scene,
    depsgraph: bpy.types.Depsgraph,
    obj: bpy.types.Object,
    settings: Any,
    texel: float | None,
) -> Baked:
    """Bake one evaluated object in the temporary scene at ``texel`` world units a texel
    (None: automatic without a camera); everything added is removed."""
    with ExitStack() as stack:
        target, loop_uv = None, None
        if not _needs_copy(obj):
            mesh = obj.to_mesh()
            stack.callback(obj.to_mesh_clear)
            if _unique_uvs(mesh):
                target = obj.original
        if target is None:
            target = _temporary_copy(stack, temp, depsgraph, obj)
            mesh, loop_uv = target.data, _loop_uv(target.data)
        span = extent(*_areas(mesh, obj.matrix_world, loop_uv))
        side = bake_texels.side(span, texel, int(settings.bake_max_resolution), automatic(settings))
        image = bpy.data.images.new(TEMP_NAME, side, side, alpha=True, float_buffer=True)
        stack.callback(bpy.data.images.remove, image)
        _add_image_nodes(stack, target, image)
        _run_bake(temp, target)
        pixels = image_pixels(image)
        if pixels is None:
            raise ValueError(f"Cycles baked no pixels for '{obj.name}'")
        pixels = pixels.copy()
        pixels[..., 3] = 1.0
    return Baked(pixels, loop_uv, span)


def _loop_uv(mesh: bpy.types.Mesh) -> np.ndarray:
    """The active UV map of ``mesh`` as (L, 2)."""
    uv = np.empty(len(mesh.loops) * 2, dtype=np.float64)
    mesh.uv_layers.active.data.foreach_get("uv", uv)
    return uv.reshape(-1, 2)


def _temporary_copy(
    stack: ExitStack, temp: bpy.types.Scene, depsgraph: bpy.types.Depsgraph, obj: bpy.types.Object
) -> bpy.types.Object:
    """A copy of ``obj``'s evaluated mesh in ``temp`` with a UV map and node materials; the
    original is hidden from rendering until the stack closes."""
    mesh = bpy.data.meshes.new_from_object(obj, preserve_all_data_layers=True, depsgraph=depsgraph)
    stack.callback(bpy.data.meshes.remove, mesh)
    copy = bpy.data.objects.new(TEMP_NAME, mesh)
    stack.callback(bpy.data.objects.remove, copy)
    copy.matrix_world = obj.matrix_world
    temp.collection.objects.link(copy)
    _copy_materials(stack, obj.original, copy)
    original = obj.original
    stack.callback(setattr, original, "hide_render", original.hide_render)
    original.hide_render = True
    if not mesh.uv_layers or not _unique_uvs(mesh):
        mesh.uv_layers.active = mesh.uv_layers.new(name=TEMP_NAME)
        _smart_project(copy)
    return copy


def _temporary_material(stack: ExitStack, color: Any) -> bpy.types.Material:
    """A diffuse node material of ``color`` (what Cycles shows for a slot without nodes)."""
    material = bpy.data.materials.new(TEMP_NAME)
    stack.callback(bpy.data.materials.remove, material)
    if bpy.app.version < (5, 0, 0):
        material.use_nodes = True
    tree = material.node_tree
    for node in list(tree.nodes):
        if node.type != "OUTPUT_MATERIAL":
            tree.nodes.remove(node)
    output = next(n for n in tree.nodes if n.type == "OUTPUT_MATERIAL")
    diffuse = tree.nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.inputs["Color"].default_value = (*tuple(color)[:3], 1.0)
    tree.links.new(diffuse.outputs[0], output.inputs["Surface"])
    return material


def _copy_materials(stack: ExitStack, original: bpy.types.Object, copy: bpy.types.Object) -> None:
    """Give ``copy`` the original's slot materials (linked ones as local copies, node-less
    ones as diffuse stand-ins)."""
    materials = [slot.material for slot in original.material_slots] or [None]
    while len(copy.material_slots) < len(materials):
        copy.data.materials.append(None)
    for slot, material in zip(copy.material_slots, materials, strict=False):
        if material is not None and material.library is not None:  # linked: a local copy
            material = material.copy()
            stack.callback(bpy.data.materials.remove, material)
        if not _usable(material):
            color = DEFAULT_COLOR if material is None else material.diffuse_color
            material = _temporary_material(stack, color)
        slot.link = "OBJECT"
        slot.material = material


def _context(temp: bpy.types.Scene, obj: bpy.types.Object, editing: bool = False) -> Any:
    """A context override making ``obj`` the one selected, active (``editing``: edited)
    object of ``temp``'s view layer (the user's own selection is another layer's)."""
    layer = temp.view_layers[0]
    for other in layer.objects:
        other.select_set(other == obj, view_layer=layer)
    layer.objects.active = obj
    extra = {"edit_object": obj} if editing else {}
    return bpy.context.temp_override(
        scene=temp,
        view_layer=layer,
        active_object=obj,
        object=obj,
        selected_objects=[obj],
        selected_editable_objects=[obj],
        **extra,
    )


def _smart_project(obj: bpy.types.Object) -> None:
    """Smart UV Project the whole mesh of ``obj`` (a temporary object) in a scene of its
    own: leaving Edit Mode leaves it for every object of the scene, none of the user's."""
    scratch = bpy.data.scenes.new(TEMP_NAME)
    try:
        scratch.collection.objects.link(obj)
        with quiet.silenced():
            with _context(scratch, obj):
                bpy.ops.object.mode_set(mode="EDIT")
            try:
                with _context(scratch, obj, editing=True):
                    bpy.ops.mesh.select_all(action="SELECT")
                    bpy.ops.uv.smart_project(island_margin=0.02)
            finally:
                with _context(scratch, obj, editing=True):
                    bpy.ops.object.mode_set(mode="OBJECT")
    finally:
        bpy.data.scenes.remove(scratch)


def _add_image_nodes(stack: ExitStack, obj: bpy.types.Object, image: bpy.types.Image) -> None:
    """Add an active Image Texture node of ``image`` to each of ``obj``'s materials."""
    done: set[str] = set()
    for slot in obj.material_slots:
        material = slot.material
        if material is None or material.name_full in done:
            continue
        done.add(material.name_full)
        tree = node_tree_of(material)
        node = tree.nodes.new("ShaderNodeTexImage")
        previous = tree.nodes.active
        stack.callback(_remove_node, tree, node, previous)
        node.image = image
        tree.nodes.active = node


def _remove_node(tree: bpy.types.NodeTree, node: bpy.types.Node, previous: Any) -> None:
    """Remove a node added for baking and give the active node back."""
    tree.nodes.remove(node)
    if previous is not None:
        tree.nodes.active = previous


def _run_bake(temp: bpy.types.Scene, obj: bpy.types.Object) -> None:
    """Cycles' Combined bake (diffuse direct + indirect, emission) of ``obj`` in ``temp``."""
    try:
        with quiet.silenced(), _context(temp, obj):
            bpy.ops.object.bake(
                type="COMBINED",
                pass_filter=PASS_FILTER,
                margin=MARGIN,
                margin_type="EXTEND",
                use_clear=True,
                use_selected_to_active=False,
                target="IMAGE_TEXTURES",
            )
    except RuntimeError as err:
        raise ValueError(f"Cycles could not bake '{obj.name}': {err}".strip()) from None

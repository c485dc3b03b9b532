"""Real scene shapes, starting from Blender's factory startup scene.

The factory file (Cube, Light, Camera in "Collection") gains what users' files hold:
nested and excluded collections, a collection instance, a modifier, a NURBS path with a
camera following it, a Text object, a linked duplicate (two objects sharing one mesh) and
an object left in Edit Mode. That scene is rendered by F12 and by the *Render SymRay Image*
operator, lit (Auto, the factory light) and unlit. Checked each time:

- nothing of the user's file changes: every datablock of every ``bpy.data`` collection,
  its RNA properties (two levels deep) compared before and after, the result images aside;
- what the flat model draws is what Blender renders: SymRay's coverage (alpha, film
  transparent, one ray through each pixel centre) against Cycles' coverage of the same
  scene (filter 0.01 px: pixel centres); an excluded collection's object stays hidden;
- lit surfaces differ from unlit ones (the bake is used).
"""

from __future__ import annotations

import warnings

import bpy
import mathutils
import numpy as np
import pytest

from tests.addon.exr_output import exr_output

ARRAYS = (
    bpy.types.bpy_prop_array,
    mathutils.Vector,
    mathutils.Matrix,
    mathutils.Color,
    mathutils.Euler,
    mathutils.Quaternion,
    tuple,
    list,
    set,
)
RESULT_IMAGES = {"SymRay Result", "Render Result", "Viewer Node"}
UI_DATA = {"window_managers", "screens", "workspaces", "all_ids"}
VOLATILE = {"rna_type", "depsgraph", "is_evaluated", "original", "users", "session_uid"}
VOLATILE |= {"is_runtime_data", "tool_settings"}
"""Properties not compared: runtime state, and tool settings (editing tools' UI state, whose
walk crashes Blender 4.2 at UvSculpt.brush)."""


def _plain(value):
    """A comparable plain value, or None for what is not one."""
    if isinstance(value, bool | int | float | str) or value is None:
        return value
    if isinstance(value, bpy.types.ID):
        return ("ID", value.name_full)
    if isinstance(value, ARRAYS):
        return tuple(_plain(v) for v in value)
    return None


def _rna(struct, depth: int) -> tuple:
    """(identifier, value) of a struct's properties; nested structs ``depth`` levels down."""
    out = []
    for prop in struct.bl_rna.properties:
        name = prop.identifier
        if name in VOLATILE:
            continue
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", DeprecationWarning)
                value = getattr(struct, name)
        except (AttributeError, RuntimeError, TypeError):
            continue
        if prop.type == "POINTER" and value is not None and not isinstance(value, bpy.types.ID):
            out.append((name, _rna(value, depth - 1) if depth > 0 else ()))
        elif prop.type == "COLLECTION":
            items = list(value)[:64]
            if depth > 0:
                out.append((name, tuple(_rna_item(v, depth - 1) for v in items)))
            else:
                out.append((name, len(value)))
        else:
            out.append((name, _plain(value)))
    return tuple(out)


def _rna_item(item, depth: int):
    """A collection item: an ID by name, a struct by its properties."""
    if item is None or isinstance(item, bpy.types.ID):
        return _plain(item)
    return _rna(item, depth)


def _blend_state() -> dict:
    """Every datablock of the file and its properties (two levels deep), result images aside."""
    state = {}
    for kind in dir(bpy.data):
        collection = getattr(bpy.data, kind, None)
        if not isinstance(collection, bpy.types.bpy_prop_collection) or kind in UI_DATA:
            continue
        for block in collection:
            if not isinstance(block, bpy.types.ID) or block.name in RESULT_IMAGES:
                continue
            state[(kind, block.name_full)] = _rna(block, 2)
    for obj in bpy.data.objects:  # selection lives on the view layer
        state[("selected", obj.name)] = obj.select_get()
    return state


def _differences(before: dict, after: dict) -> list[str]:
    """Readable differences between two ``_blend_state`` results."""
    lines = [f"new {k}" for k in after.keys() - before.keys()]
    lines += [f"removed {k}" for k in before.keys() - after.keys()]
    for key in before.keys() & after.keys():
        if before[key] != after[key]:
            old, new = dict(before[key]) if isinstance(before[key], tuple) else {}, {}
            if isinstance(after[key], tuple):
                new = dict(after[key])
            changed = [n for n in old if old.get(n) != new.get(n)] or ["value"]
            where = _diff_path(old.get(changed[0]), new.get(changed[0]))
            lines.append(f"changed {key}: {changed[:6]}, first at {changed[0]}{where}")
    return sorted(lines)


def _diff_path(a, b, path: str = "") -> tuple:
    """Where two nested tuples first differ, and the two values there."""
    if isinstance(a, tuple) and isinstance(b, tuple) and len(a) == len(b):
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            if x != y:
                return _diff_path(x, y, f"{path}[{i}]")
    return path, str(a)[:300], str(b)[:300]


def _collection(name: str, parent: bpy.types.Collection) -> bpy.types.Collection:
    """A new collection linked under ``parent``."""
    coll = bpy.data.collections.new(name)
    parent.children.link(coll)
    return coll


def _mesh_object(name: str, mesh: bpy.types.Mesh, coll, location) -> bpy.types.Object:
    """An object of ``mesh`` at ``location`` in ``coll``."""
    obj = bpy.data.objects.new(name, mesh)
    obj.location = location
    coll.objects.link(obj)
    return obj


def _box_mesh(name: str, half: float) -> bpy.types.Mesh:
    """A closed box mesh of half-edge ``half``."""
    h = half
    verts = [(x, y, z) for x in (-h, h) for y in (-h, h) for z in (-h, h)]
    faces = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(verts, [], faces)
    return mesh


def _shapes(scene) -> None:
    """Add the scene shapes to the factory scene, each in its own place in the camera's view."""
    cam = scene.camera.matrix_world
    right, up = np.array(cam.col[0][:3]), np.array(cam.col[1][:3])

    def at(x: float, y: float) -> tuple:
        return tuple(x * right + y * up)

    top = bpy.data.collections["Collection"]
    nested = _collection("Nested", _collection("Outer", top))
    ball = _mesh_object("Ball", _box_mesh("BallMesh", 0.6), nested, at(-2.8, 0.0))
    ball.modifiers.new("Subsurf", "SUBSURF").levels = 2
    hidden = _collection("Excluded", scene.collection)
    _mesh_object("Hidden", _box_mesh("HiddenMesh", 0.9), hidden, at(0.0, 2.2))
    props = _collection("Props", scene.collection)
    _mesh_object("Prop", _box_mesh("PropMesh", 0.4), props, (0.0, 0.0, 0.0))
    instancer = bpy.data.objects.new("Instancer", None)
    instancer.instance_type = "COLLECTION"
    instancer.instance_collection = props
    instancer.location = at(2.8, 1.6)
    top.objects.link(instancer)
    twin = _mesh_object("Twin", bpy.data.objects["Cube"].data, top, at(2.8, -1.6))
    twin.scale = (0.35, 0.35, 0.35)
    text = bpy.data.objects.new("Label", bpy.data.curves.new("Label", "FONT"))
    text.data.body = "Hi"
    text.data.extrude = 0.05
    text.location, text.rotation_euler = at(-3.0, 1.7), scene.camera.rotation_euler
    top.objects.link(text)
    path = bpy.data.objects.new("Path", bpy.data.curves.new("Path", "CURVE"))
    spline = path.data.splines.new("NURBS")
    spline.points.add(3)
    for point, co in zip(spline.points, [(-1, 0, 0), (0, 1, 0), (1, 0, 0), (2, 1, 0)], strict=True):
        point.co = (*co, 1.0)
    path.data.use_path = True
    path.location = at(0.0, -2.2)
    top.objects.link(path)
    edited = _mesh_object("Edited", _box_mesh("EditedMesh", 0.4), top, at(-2.4, -1.8))
    layer = bpy.context.view_layer
    layer.layer_collection.children["Excluded"].exclude = True
    layer.layer_collection.children["Props"].exclude = True
    layer.update()
    layer.objects.active = edited
    edited.select_set(True)
    bpy.ops.object.mode_set(mode="EDIT")


def _read_exr(path) -> np.ndarray:
    """An EXR file's RGBA pixels (row 0 at the top), read by Blender."""
    image = bpy.data.images.load(str(path))
    try:
        w, h = image.size
        flat = np.empty(w * h * 4, dtype=np.float32)
        image.pixels.foreach_get(flat)
    finally:
        bpy.data.images.remove(image)
    return flat.reshape(h, w, 4)[::-1]


def _cycles_alpha(scene, tmp_path) -> np.ndarray:
    """Cycles' coverage of the scene at pixel centres (row 0 at the top); the scene's
    engine and output path are given back."""
    engine, filepath = scene.render.engine, scene.render.filepath
    scene.render.engine = "CYCLES"
    scene.cycles.device, scene.cycles.samples = "CPU", 1
    scene.cycles.filter_width = 0.01
    scene.render.filepath = str(tmp_path / "cycles.exr")
    bpy.ops.render.render(write_still=True)
    scene.render.engine, scene.render.filepath = engine, filepath
    return _read_exr(tmp_path / "cycles.exr")[..., 3]


def _render(way: str, helpers) -> np.ndarray:
    """Render the scene with F12 (to its EXR output path) or the operator; linear RGBA,
    row 0 at the top."""
    if way == "operator":
        assert bpy.ops.symray.render() == {"FINISHED"}
        return helpers.image_array("SymRay Result")
    assert bpy.ops.render.render(write_still=True) == {"FINISHED"}
    return _read_exr(bpy.context.scene.render.filepath)


@pytest.fixture
def shapes_scene(factory_scene, tmp_path):
    """The factory scene with the shapes, flat model, film transparent, pixel centres."""
    scene = factory_scene
    _shapes(scene)
    scene.symray.model = "FLAT"
    scene.symray.quality = "RADIANS"
    scene.symray.bake_texel_size = 0.25
    scene.symray.bake_samples = 4
    scene.render.resolution_x, scene.render.resolution_y = 96, 72
    scene.render.film_transparent = True
    scene.render.filter_size = 0.01
    exr_output(scene, tmp_path / "f12.exr")
    return scene


@pytest.mark.parametrize("way", ["f12", "operator"])
def test_scene_shapes_render_as_blender_sees_them(addon, shapes_scene, helpers, tmp_path, way):
    """F12 and the operator, unlit then lit: the file is left as it was, SymRay covers the
    pixels Cycles covers (all but edge ties), and the bake changes the surfaces."""
    scene = shapes_scene
    want = _cycles_alpha(scene, tmp_path) > 0.5
    addon.module("symray_addon.bake").clear_cache()
    before = _blend_state()
    images = {}
    for lighting in ("UNLIT", "AUTO"):
        scene.symray.lighting = lighting
        before = _blend_state()
        images[lighting] = _render(way, helpers)
        assert _differences(before, _blend_state()) == []
        covered = images[lighting][..., 3] > 0.5
        mismatch = np.mean(covered != want)
        print(f"{way} {lighting}: coverage differs from Cycles on {mismatch:.2%} of pixels")
        assert want.mean() > 0.15
        assert mismatch < 0.02
    assert bpy.context.object.mode == "EDIT"
    surface = want & (images["UNLIT"][..., 3] > 0.99) & (images["AUTO"][..., 3] > 0.99)
    change = np.abs(images["AUTO"][..., :3] - images["UNLIT"][..., :3]).max(axis=-1)[surface]
    assert np.mean(change > 0.05) > 0.5


ANIMATION_SCRIPT = """
import sys
import bpy

bpy.ops.preferences.addon_enable(module=sys.argv[1])
bpy.ops.wm.open_mainfile(filepath=sys.argv[2])
assert bpy.ops.render.render(animation=True) == {"FINISHED"}
"""


@pytest.mark.parametrize("lighting", ["UNLIT", "AUTO"])
def test_scene_shapes_animation(addon, shapes_scene, helpers, tmp_path, lighting):
    """``render(animation=True)`` of the shapes with an animated camera, in a separate
    Blender (a crash would end it, not the test): it exits cleanly, each frame file equals
    F12 of that frame here, and the frames differ (the camera moved)."""
    import os
    import subprocess
    import sys

    scene = shapes_scene
    bpy.ops.object.mode_set(mode="OBJECT")
    scene.symray.lighting = lighting
    camera = scene.camera
    camera.keyframe_insert("location", frame=1)
    camera.location.z += 0.6
    camera.keyframe_insert("location", frame=2)
    scene.frame_start, scene.frame_end = 1, 2
    scene.render.filepath, scene.render.use_file_extension = str(tmp_path / "frame_####"), True
    blend = tmp_path / "shapes.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend), copy=True)
    run = subprocess.run(
        [sys.executable, "-c", ANIMATION_SCRIPT, addon.package, str(blend)],
        capture_output=True,
        text=True,
        timeout=300,
        env=dict(os.environ),
    )
    assert run.returncode == 0, run.stderr[-2000:]
    frames = [_read_exr(tmp_path / f"frame_{n:04d}.exr") for n in (1, 2)]
    exr_output(scene, tmp_path / "f12.exr")
    for n, frame in zip((1, 2), frames, strict=True):
        scene.frame_set(n)
        here = _render("f12", helpers)
        assert np.abs(frame - here).max() < 1e-5, f"frame {n}"
    assert np.mean(frames[0][..., 3] != frames[1][..., 3]) > 0.01

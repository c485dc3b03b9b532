"""What Blender hides and animates is what SymRay renders (issue 45, points 1 and 2).

A black hole in a collection disabled in renders, or excluded from the view layer, bends
no light and counts for no "one hole per scene"; a hole's animated Size (and keyed
Render visibility) is read at the frame rendered, from the evaluated depsgraph, by
``render(animation=True)`` as by a still. Images are compared with independent renders
of the same frame: without the hidden hole, or a still set to the keyed value.
"""

from __future__ import annotations

import bpy
import numpy as np
import pytest


def _scene(scene):
    """The factory scene at 32x24, its cube moved behind the origin (where holes go),
    before the procedural sky: light to bend."""
    camera = np.array(scene.camera.location)
    bpy.data.objects["Cube"].location = tuple(-0.8 * camera)
    scene.render.resolution_x, scene.render.resolution_y = 32, 24
    scene.symray.quality = "RADIANS"
    scene.symray.tolerance = 1e-3
    scene.symray.background = "PROCEDURAL"  # stars and a band: lensing shows
    return scene


def _f12(scene, tmp_path, name: str) -> np.ndarray:
    """Render ``scene`` as F12 does; its float RGBA (h, w, 4)."""
    assert bpy.ops.render.render(scene=scene.name) == {"FINISHED"}
    return _saved(scene, tmp_path, name)


def _saved(scene, tmp_path, name: str) -> np.ndarray:
    """The Render Result saved as a float EXR and read back, (h, w, 4)."""
    settings = scene.render.image_settings
    settings.file_format, settings.color_depth = "OPEN_EXR", "32"
    path = tmp_path / f"{name}.exr"
    bpy.data.images["Render Result"].save_render(str(path), scene=scene)
    return _read(path)


def _read(path) -> np.ndarray:
    """An image file's float RGBA (h, w, 4)."""
    image = bpy.data.images.load(str(path))
    w, h = image.size
    pixels = np.array(image.pixels[:], dtype=np.float32).reshape(h, w, 4)
    bpy.data.images.remove(image)
    return pixels


def _operator(scene) -> np.ndarray:
    """Render ``scene`` with Render SymRay Image (the viewport's depsgraph); (h, w, 4)."""
    assert bpy.ops.symray.render() == {"FINISHED"}
    image = bpy.data.images[scene.symray.image_name]
    w, h = image.size
    return np.array(image.pixels[:], dtype=np.float32).reshape(h, w, 4)


def _add_hole(location, size=0.5):
    """A black hole (no disk) at ``location``; the active object."""
    bpy.context.scene.cursor.location = location
    assert bpy.ops.symray.add_black_hole(size=size, spin=0.0, disk=False) == {"FINISHED"}
    return bpy.context.active_object


def _hide(obj, how: str) -> None:
    """Move ``obj`` into a new collection hidden ``how``: disabled in renders, or excluded
    from the view layer."""
    scene = bpy.context.scene
    collection = bpy.data.collections.new(f"Hidden {how}")
    scene.collection.children.link(collection)
    for user in list(obj.users_collection):
        user.objects.unlink(obj)
    collection.objects.link(obj)
    if how == "render":
        collection.hide_render = True
    else:
        bpy.context.view_layer.layer_collection.children[collection.name].exclude = True
    bpy.context.view_layer.update()


@pytest.mark.parametrize("how", ["render", "exclude"])
def test_a_hole_in_a_hidden_collection_bends_no_light(factory_scene, tmp_path, how):
    scene = _scene(factory_scene)
    flat_f12, flat_op = _f12(scene, tmp_path, "flat"), _operator(scene)
    hole = _add_hole((0.0, 0.0, 0.0))
    assert not np.array_equal(_f12(scene, tmp_path, "hole"), flat_f12)  # it shows when seen
    _hide(hole, how)
    np.testing.assert_array_equal(_f12(scene, tmp_path, "hidden"), flat_f12)
    np.testing.assert_array_equal(_operator(scene), flat_op)


@pytest.mark.parametrize("how", ["render", "exclude"])
def test_a_second_hole_hidden_in_a_collection_is_not_counted(factory_scene, tmp_path, how):
    scene = _scene(factory_scene)
    hidden = _add_hole((1.0, 0.0, 1.0), size=0.8)
    _hide(hidden, how)
    _add_hole((0.0, 0.0, 0.0))
    with_both = _f12(scene, tmp_path, "both")  # no "2 black holes"
    with_both_op = _operator(scene)
    bpy.data.objects.remove(hidden)
    np.testing.assert_array_equal(_f12(scene, tmp_path, "one"), with_both)
    np.testing.assert_array_equal(_operator(scene), with_both_op)


def _animation(scene, tmp_path) -> dict[int, np.ndarray]:
    """``render(animation=True)`` of frames 1-3 into EXRs; {frame: (h, w, 4)}."""
    scene.frame_start, scene.frame_end = 1, 3
    settings = scene.render.image_settings
    settings.file_format, settings.color_depth = "OPEN_EXR", "32"
    scene.render.filepath = str(tmp_path / "anim_####")
    scene.render.use_file_extension = True
    scene.frame_set(1)
    assert bpy.ops.render.render(animation=True) == {"FINISHED"}
    return {f: _read(tmp_path / f"anim_{f:04d}.exr") for f in (1, 2, 3)}


def test_an_animated_size_renders_at_each_frame(factory_scene, tmp_path):
    scene = _scene(factory_scene)
    hole = _add_hole((0.0, 0.0, 0.0), size=0.3)
    hole.symray.keyframe_insert("size", frame=1)
    hole.symray.size = 1.5
    hole.symray.keyframe_insert("size", frame=3)
    frames = _animation(scene, tmp_path)
    hole.animation_data_clear()  # the stills: Size set by hand
    for size, frame in ((1.5, 3), (0.3, 1)):
        hole.symray.size = size
        scene.frame_set(frame)
        np.testing.assert_array_equal(frames[frame], _f12(scene, tmp_path, f"still{frame}"))
    assert not np.array_equal(frames[1], frames[3])


def test_a_keyed_render_visibility_hides_the_hole_at_its_frames(factory_scene, tmp_path):
    scene = _scene(factory_scene)
    flat = _f12(scene, tmp_path, "flat")
    hole = _add_hole((0.0, 0.0, 0.0))
    seen = _f12(scene, tmp_path, "seen")
    hole.keyframe_insert("hide_render", frame=1)
    hole.hide_render = True
    hole.keyframe_insert("hide_render", frame=3)
    frames = _animation(scene, tmp_path)
    np.testing.assert_array_equal(frames[1], seen)
    np.testing.assert_array_equal(frames[3], flat)


@pytest.mark.parametrize("how", ["render", "exclude"])
def test_a_mesh_in_a_hidden_collection_is_not_rendered(factory_scene, tmp_path, how):
    """The factory cube hidden by its collection: Render SymRay Image (the viewport's
    depsgraph, which still holds it) renders what F12 does, the scene without it."""
    scene = _scene(factory_scene)
    scene.symray.lighting = "UNLIT"
    _add_hole((0.0, 0.0, 0.0))
    cube = bpy.data.objects["Cube"]
    seen = _operator(scene)
    _hide(cube, how)
    hidden_op, hidden_f12 = _operator(scene), _f12(scene, tmp_path, "hidden")
    assert not np.array_equal(hidden_op, seen)  # the cube showed before
    bpy.data.objects.remove(cube)
    np.testing.assert_array_equal(_operator(scene), hidden_op)
    np.testing.assert_array_equal(_f12(scene, tmp_path, "removed"), hidden_f12)

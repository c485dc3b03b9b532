"""Every failure of a render is a clear error and nothing good is lost.

F12 (``bpy.ops.render.render(write_still=True)``) and the SymRay operator, failing in
every way a frame can fail: a worker process killed, no memory, Python's recursion limit,
an expression too deeply nested. Each must raise/report an error naming the problem,
leave the previous output file byte-identical and the previous image as it was. Also: the
operator's image survives saving the .blend, and a '//' path needs a saved file.
"""

from __future__ import annotations

import os
import signal

import bpy
import numpy as np
import pytest

from tests.exr_faults import fail_passes_file

FAILURES = ["killed worker", "MemoryError", "RecursionError", "deep expression"]


def _flat_scene(scene, helpers):
    helpers.add_camera(scene)
    helpers.add_cube(scene, "Cube", material=helpers.solid_material("Red", (0.8, 0.1, 0.1, 1)))
    scene.symray.model = "FLAT"


def _break_the_next_render(addon, scene, monkeypatch, failure: str) -> str:
    """Make the next render fail as ``failure`` says; returns a phrase of the message."""
    render_module = addon.module("core.render")
    real_trace = render_module._trace_chunk
    parent = os.getpid()

    def killed_in_worker(*args, **kwargs):
        if os.getpid() != parent:
            os.kill(os.getpid(), signal.SIGKILL)  # what the OOM killer or `kill -9` does
        return real_trace(*args, **kwargs)

    def raising(error):
        def trace(*_args, **_kwargs):
            raise error

        return trace

    if failure == "killed worker":
        if not addon.core.workers.can_fork():
            pytest.skip("worker processes need fork")
        scene.symray.parallel, scene.symray.workers = "PROCESSES", 2
        monkeypatch.setattr(render_module, "_trace_chunk", killed_in_worker)
        return "worker process stopped unexpectedly"
    if failure == "MemoryError":
        monkeypatch.setattr(render_module, "_trace_chunk", raising(MemoryError()))
        return "ran out of memory"
    if failure == "RecursionError":
        monkeypatch.setattr(
            render_module,
            "_trace_chunk",
            raising(RecursionError("maximum recursion depth exceeded")),
        )
        return "recursion limit"
    scene.symray.model = "CUSTOM"
    scene.symray.hamiltonian = "+".join(["p_x"] * 500)  # RecursionError before
    return "nested too deeply"


@pytest.mark.parametrize("failure", FAILURES)
def test_a_failed_f12_keeps_the_previous_file(
    addon, scene, helpers, tmp_path, monkeypatch, failure
):
    _flat_scene(scene, helpers)
    scene.render.engine = "SYMRAY"
    addon.module("symray_addon.output").set_png_format(scene.render.image_settings)
    scene.render.filepath = str(tmp_path / "frame")
    scene.render.use_file_extension = True
    bpy.ops.render.render(write_still=True)
    frame = tmp_path / "frame.png"
    before = frame.read_bytes()
    assert len(before) > 100
    phrase = _break_the_next_render(addon, scene, monkeypatch, failure)
    with pytest.raises(RuntimeError) as info:
        bpy.ops.render.render(write_still=True)
    assert phrase in str(info.value), str(info.value)
    assert "Traceback" not in str(info.value)
    assert frame.read_bytes() == before
    assert sorted(os.listdir(tmp_path)) == ["frame.png"]
    monkeypatch.undo()
    if failure == "killed worker":  # the next F12 works again (new worker processes)
        assert bpy.ops.render.render(write_still=True) == {"FINISHED"}


def test_an_animation_stops_at_a_failed_frame_and_writes_no_blank_one(
    addon, scene, helpers, tmp_path, monkeypatch
):
    """What `blender -b file.blend -E SYMRAY -a` does when frame 2 fails."""
    _flat_scene(scene, helpers)
    scene.render.engine = "SYMRAY"
    addon.module("symray_addon.output").set_png_format(scene.render.image_settings)
    scene.render.filepath = str(tmp_path / "frame_####")
    scene.frame_start, scene.frame_end = 1, 3
    render_job = addon.module("symray_addon.render_job")
    real_prepare = render_job.prepare

    def prepare(frame_scene, *args, **kwargs):
        if frame_scene.frame_current == 2:
            raise MemoryError()
        return real_prepare(frame_scene, *args, **kwargs)

    monkeypatch.setattr(render_job, "prepare", prepare)
    with pytest.raises(RuntimeError, match="ran out of memory"):
        bpy.ops.render.render(animation=True)
    assert sorted(os.listdir(tmp_path)) == ["frame_0001.png"]


@pytest.mark.parametrize("failure", FAILURES)
def test_a_failed_operator_render_is_a_report_and_keeps_the_image(
    addon, scene, helpers, monkeypatch, failure
):
    _flat_scene(scene, helpers)
    assert bpy.ops.symray.render() == {"FINISHED"}
    before = helpers.image_array(scene.symray.image_name).copy()
    phrase = _break_the_next_render(addon, scene, monkeypatch, failure)
    message = helpers.operator_error(lambda: bpy.ops.symray.render())
    assert phrase in message and "Traceback" not in message, message
    np.testing.assert_array_equal(helpers.image_array(scene.symray.image_name), before)


def test_the_panel_shows_the_new_error_not_the_previous_one(addon, scene):
    settings = scene.symray
    settings.hamiltonian = "p_x**2 +"
    assert "syntax error" in settings.hamiltonian_error
    settings.hamiltonian = "+".join(["p_x"] * 500)  # a RecursionError kept the old one
    assert "nested too deeply" in settings.hamiltonian_error
    settings.hamiltonian = "0.5*ｐ_x**2"  # fullwidth p: was read as p_x
    assert "non-ASCII character 'ｐ'" in settings.hamiltonian_error
    assert "column 5" in settings.hamiltonian_error
    settings.hamiltonian = "0.5*p_x**2"
    assert settings.hamiltonian_error == ""


def _image_pixels(name: str) -> np.ndarray:
    image = bpy.data.images[name]
    pixels = np.empty(len(image.pixels), dtype=np.float32)
    image.pixels.foreach_get(pixels)
    return pixels.reshape(image.size[1], image.size[0], 4)


def test_the_operators_image_survives_saving_the_blend(addon, scene, helpers, tmp_path):
    """The generated float image keeps its pixels (above 1 too) through a save and reload."""
    _flat_scene(scene, helpers)
    helpers.set_world_color(scene, (0.2, 0.3, 1.7, 1.0))  # a float value above 1
    blend = str(tmp_path / "scene.blend")
    for width, transparent in ((64, False), (40, True)):  # the second replaces the first
        scene = bpy.context.scene
        scene.render.resolution_x = width
        scene.render.film_transparent = transparent  # alpha 0 around the cube
        assert bpy.ops.symray.render() == {"FINISHED"}
        name = scene.symray.image_name
        rendered = _image_pixels(name).copy()
        assert rendered.shape == (48, width, 4)
        assert (rendered[..., 2].max() == np.float32(1.7)) != transparent  # the world or 0
        assert (rendered[..., 3].min() == 0.0) == transparent
        bpy.ops.wm.save_as_mainfile(filepath=blend)
        bpy.ops.wm.read_homefile(use_empty=True)
        bpy.ops.wm.open_mainfile(filepath=blend)
        np.testing.assert_array_equal(_image_pixels(name), rendered)


def test_a_blend_relative_exr_path_needs_a_saved_file(addon, scene, helpers, tmp_path, monkeypatch):
    """'//x.exr' in an unsaved file is refused, never written to the working directory."""
    monkeypatch.chdir(tmp_path)
    _flat_scene(scene, helpers)
    assert bpy.ops.symray.render() == {"FINISHED"}
    before = helpers.image_array(scene.symray.image_name).copy()
    scene.symray.exr_path = "//x.exr"
    message = helpers.operator_error(lambda: bpy.ops.symray.render())
    assert "not saved yet" in message and "//x.exr" in message
    np.testing.assert_array_equal(helpers.image_array(scene.symray.image_name), before)
    assert os.listdir(tmp_path) == []
    saved = tmp_path / "project"
    saved.mkdir()
    bpy.ops.wm.save_as_mainfile(filepath=str(saved / "scene.blend"))
    assert bpy.ops.symray.render() == {"FINISHED"}
    assert (saved / "x.exr").is_file() and not (tmp_path / "x.exr").exists()


def _exr_pair(scene, helpers, tmp_path):
    """A flat scene rendered once by the operator with an EXR path: the pair's bytes."""
    _flat_scene(scene, helpers)
    scene.symray.pass_steps = True
    scene.symray.exr_path = str(tmp_path / "out.exr")
    assert bpy.ops.symray.render() == {"FINISHED"}
    files = [tmp_path / "out.exr", tmp_path / "out.passes.exr"]
    return files, [f.read_bytes() for f in files]


@pytest.mark.parametrize("stage", ["write", "replace"])
def test_a_failed_passes_write_keeps_both_exr_files(
    addon, scene, helpers, tmp_path, monkeypatch, stage
):
    """The passes EXR failing to be written or renamed: both files stay as they were (never
    a new RGBA file beside the old passes file), and so does the image; the message names
    the file and what failed."""
    files, before = _exr_pair(scene, helpers, tmp_path)
    image = helpers.image_array(scene.symray.image_name).copy()
    cube = bpy.data.materials["Red"].node_tree.nodes["Principled BSDF"]
    cube.inputs["Base Color"].default_value = (0.1, 0.2, 0.9, 1.0)  # a different image
    reason = fail_passes_file(monkeypatch, addon.module("core.imageio"), stage)
    message = helpers.operator_error(lambda: bpy.ops.symray.render())
    assert f"cannot write image '{files[1]}': {reason}; no file was changed" in message
    assert [f.read_bytes() for f in files] == before
    assert sorted(os.listdir(tmp_path)) == ["out.exr", "out.passes.exr"]
    np.testing.assert_array_equal(helpers.image_array(scene.symray.image_name), image)
    monkeypatch.undo()
    assert bpy.ops.symray.render() == {"FINISHED"}  # and the next render writes the pair
    assert files[0].read_bytes() != before[0]  # the new colour


@pytest.mark.parametrize("name", ["Render Result", "Viewer Node"])
@pytest.mark.parametrize("exists", [False, True])
def test_blenders_own_images_are_refused_before_anything_is_written(
    addon, scene, helpers, tmp_path, name, exists
):
    """Image "Render Result" (or "Viewer Node") is refused by name before anything is
    written: the EXR pair and the image stay as they were."""
    files, before = _exr_pair(scene, helpers, tmp_path)
    image = helpers.image_array(scene.symray.image_name).copy()
    if exists:  # Blender makes both once something is rendered and composited
        scene.render.engine = "SYMRAY"
        bpy.ops.render.render()
        assert bpy.data.images.get("Render Result") is not None
        if bpy.data.images.get(name) is None:
            bpy.data.images.new(name, 4, 4).source  # noqa: B018 - a plain image of that name
    previous = scene.symray.image_name
    scene.symray.image_name = name
    message = helpers.operator_error(lambda: bpy.ops.symray.render())
    assert f"Image '{name}' is Blender's" in message and "choose another name" in message
    assert "TypeError" not in message and "nothing was written" in message
    assert [f.read_bytes() for f in files] == before
    np.testing.assert_array_equal(helpers.image_array(previous), image)


def test_an_image_failing_after_the_exr_pair_says_what_was_written(
    addon, scene, helpers, tmp_path, monkeypatch
):
    """An image failing after the EXR pair was written says which files were written."""
    files, _before = _exr_pair(scene, helpers, tmp_path)
    output = addon.module("symray_addon.output")

    def broken(_name, _rgba):
        raise TypeError("no such image type")

    monkeypatch.setattr(output, "write_image", broken)
    message = helpers.operator_error(lambda: bpy.ops.symray.render())
    assert (
        "SymRay could not write image 'SymRay Result' (TypeError: no such image type); "
        f"'{files[0]}' and '{files[1]}' were written"
    ) in message
    assert "nothing was written" not in message

"""Every bad input is an ERROR report + CANCELLED, and the previous image stays as it was."""

from __future__ import annotations

import os

import bpy
import numpy as np
import pytest


@pytest.fixture
def rendered(scene, helpers):
    """A flat scene rendered once by the operator (the 'previous image')."""
    helpers.add_camera(scene)
    helpers.add_cube(scene, "Cube", location=(0, 0, 0),
                     material=helpers.solid_material("Red", (0.8, 0.1, 0.1, 1)))
    scene.symray.model = "FLAT"
    assert bpy.ops.symray.render() == {"FINISHED"}
    before = helpers.image_array(scene.symray.image_name).copy()
    assert before[..., 3].min() == 1.0 and before[..., :3].max() > 0.5
    return before


def _fails(helpers, scene, before, match: str) -> str:
    message = helpers.operator_error(lambda: bpy.ops.symray.render())
    assert match.lower() in message.lower(), message
    np.testing.assert_array_equal(helpers.image_array(scene.symray.image_name), before)
    return message


def test_invalid_index_expression(scene, helpers, rendered):
    scene.symray.model = "MEDIUM"
    scene.symray.refractive_index = "1 + 0.1*w"
    _fails(helpers, scene, rendered, "unknown name 'w'")


def test_invalid_metric(scene, helpers, rendered):
    scene.symray.model = "METRIC"
    scene.symray.metric = "-1, 0, 0; 0, 1, 0, 0; 0, 0, 1, 0; 0, 0, 0, 1"
    _fails(helpers, scene, rendered, "row 1 has 3 entries")


def test_invalid_hamiltonian(scene, helpers, rendered):
    scene.symray.model = "CUSTOM"
    scene.symray.hamiltonian = "p_x**2 + __import__('os')"
    _fails(helpers, scene, rendered, "Invalid Hamiltonian")


@pytest.mark.parametrize("spin", [1.5, -1.01])
def test_spin_beyond_extremal(scene, helpers, rendered, spin):
    scene.symray.model = "KERR"
    scene.symray.spin = spin
    _fails(helpers, scene, rendered, "beyond extremal")


@pytest.mark.parametrize("model", ["SCHWARZSCHILD", "KERR"])
def test_camera_inside_horizon(scene, helpers, rendered, model):
    scene.symray.model = model
    scene.symray.rg = 2.0
    scene.symray.center = helpers.add_empty(scene, location=(0.0, -29.5, 0.3))
    bpy.context.view_layer.update()
    _fails(helpers, scene, rendered, "inside the black hole's horizon")


def test_no_camera(scene, helpers, rendered):
    scene.camera = None
    _fails(helpers, scene, rendered, "no active camera")


def test_empty_scene(scene, helpers, rendered):
    bpy.data.objects.remove(bpy.data.objects["Cube"])
    _fails(helpers, scene, rendered, "Nothing to render")


def test_exr_folder_missing(scene, helpers, rendered, tmp_path):
    scene.symray.exr_path = str(tmp_path / "missing" / "out.exr")
    _fails(helpers, scene, rendered, "does not exist")


def test_exr_path_is_a_folder(scene, helpers, rendered, tmp_path):
    scene.symray.exr_path = str(tmp_path)
    _fails(helpers, scene, rendered, "is a folder")


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() == 0,
                    reason="root may write anywhere")
def test_exr_folder_read_only(scene, helpers, rendered, tmp_path):
    folder = tmp_path / "ro"
    folder.mkdir()
    folder.chmod(0o500)
    try:
        scene.symray.exr_path = str(folder / "out.exr")
        _fails(helpers, scene, rendered, "not writable")
    finally:
        folder.chmod(0o700)


def test_engine_reports_bad_input(addon, scene, helpers, rendered):
    """F12 with a bad setup: Blender shows the error (RuntimeError from Python), no crash."""
    scene.render.engine = "SYMRAY"
    scene.symray.model = "KERR"
    scene.symray.spin = 3.0
    render_job = addon.module("symray_addon.render_job")
    render_job.last_summary.clear()
    with pytest.raises(RuntimeError, match="beyond extremal"):
        bpy.ops.render.render()
    assert render_job.last_summary == {}
    np.testing.assert_array_equal(helpers.image_array(scene.symray.image_name), rendered)

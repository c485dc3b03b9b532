"""Every bad input is an ERROR report + CANCELLED, and the previous image stays as it was."""

from __future__ import annotations

import math
import os

import bpy
import numpy as np
import pytest


@pytest.fixture
def rendered(scene, helpers):
    """A flat scene rendered once by the operator (the 'previous image')."""
    helpers.add_camera(scene)
    helpers.add_cube(
        scene,
        "Cube",
        location=(0, 0, 0),
        material=helpers.solid_material("Red", (0.8, 0.1, 0.1, 1)),
    )
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


@pytest.mark.skipif(
    not hasattr(os, "geteuid") or os.geteuid() == 0, reason="root may write anywhere"
)
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


# -- values beyond the properties' ranges, methods and cameras that cannot render ------------

KERR_METHODS_REFUSED = ("tao2", "tao4")
SIGNATURE_MINUS = "1, 0, 0, 0; 0, -1, 0, 0; 0, 0, -1, 0; 0, 0, 0, -1"
ALL_ZERO = "0, 0, 0, 0; 0, 0, 0, 0; 0, 0, 0, 0; 0, 0, 0, 0"


@pytest.mark.parametrize(
    "prop, value, model, match",
    [
        (
            "tolerance",
            math.nan,
            "KERR",
            "Tolerance must be a finite number in [1e-14, 0.1], got nan",
        ),
        ("rg", math.nan, "SCHWARZSCHILD", "Size must be a finite number > 0"),
        ("spin", math.nan, "KERR", "Spin a/M must be a finite number, got nan"),
        ("medium_min", (math.nan, 0.0, 0.0), "MEDIUM", "Box Min must be finite numbers"),
    ],
)
def test_non_finite_settings_are_refused(scene, helpers, rendered, prop, value, model, match):
    """Blender's properties let NaN through: a NaN tolerance is refused, not rendered unbent."""
    scene.symray.model = model
    setattr(scene.symray, prop, value)
    _fails(helpers, scene, rendered, match)


@pytest.mark.parametrize(
    "prop, value, match",
    [
        ("max_steps", 0, "Max Steps must be an integer >= 1, got 0"),
        ("tolerance", 5.0, "Tolerance must be a finite number in [1e-14, 0.1], got 5"),
        ("tolerance", 0.0, "Tolerance must be a finite number in [1e-14, 0.1], got 0"),
        ("workers", -3, "Workers must be an integer >= 0, got -3"),
    ],
)
def test_values_beyond_the_property_range_are_refused(scene, helpers, rendered, prop, value, match):
    """A .blend (or a script writing the ID property) bypasses the properties' min/max."""
    scene.symray.model = "KERR"
    scene.symray[prop] = value
    _fails(helpers, scene, rendered, match)


def test_nan_tolerance_from_a_saved_file(scene, helpers, rendered, tmp_path):
    scene.symray.model = "KERR"
    scene.symray.tolerance = math.nan
    path = str(tmp_path / "nan.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.open_mainfile(filepath=path)
    message = helpers.operator_error(lambda: bpy.ops.symray.render())
    assert "Tolerance must be a finite number" in message


def test_the_ends_of_the_tolerance_range_are_accepted(addon, scene):
    """Blender keeps floats in float32 (0.1 reads back as 0.10000000149): the typed
    decimal is what is checked."""
    validation = addon.module("symray_addon.validation")
    scene.symray.model = "KERR"
    for value in (0.1, 1e-14):
        scene.symray.tolerance = value
        assert float(scene.symray.tolerance) != value
        assert validation.settings_problems(scene.symray) == []


@pytest.mark.parametrize("method", KERR_METHODS_REFUSED)
@pytest.mark.parametrize("model", ["SCHWARZSCHILD", "KERR"])
def test_tao_is_refused_for_black_holes(scene, helpers, rendered, method, model):
    """An all-magenta image (every ray failed) is a failure, never reported as a success."""
    scene.symray.model = model
    scene.symray.method = method
    _fails(helpers, scene, rendered, f"method '{method}' cannot render a black hole")


def test_tao_is_accepted_for_a_medium(addon, scene):
    validation = addon.module("symray_addon.validation")
    scene.symray.model = "MEDIUM"
    scene.symray.method = "tao2"
    assert validation.settings_problems(scene.symray) == []


@pytest.mark.parametrize(
    "metric, match",
    [
        (SIGNATURE_MINUS, r"signature (-, -, -, +) at the camera"),
        (ALL_ZERO, "g^ij is singular at the camera"),
    ],
)
def test_metric_problems_at_the_camera(scene, helpers, rendered, metric, match):
    """Each camera problem is named, never a false 'inside the black hole's horizon' or numpy's bare
    'Singular matrix'."""
    scene.symray.model = "METRIC"
    scene.symray.metric = metric
    message = _fails(helpers, scene, rendered, match)
    assert "horizon" not in message and message.strip() != "Singular matrix"


def test_engine_reports_out_of_range_settings(addon, scene, helpers, rendered):
    """F12 with a NaN tolerance: an error, the previous image untouched."""
    scene.render.engine = "SYMRAY"
    scene.symray.model = "KERR"
    scene.symray.tolerance = math.nan
    with pytest.raises(RuntimeError, match="Tolerance must be a finite number"):
        bpy.ops.render.render()
    np.testing.assert_array_equal(helpers.image_array(scene.symray.image_name), rendered)


# -- settings that must not be handled silently -------------------------------------------


@pytest.mark.parametrize(
    "group, prop, label",
    [("", "quality", "Quality"), ("", "method", "Method"), ("", "lighting", "Surface Lighting"),
     ("disk", "profile", "Temperature Profile")],
)  # fmt: skip
def test_an_enum_holding_no_choice_is_refused(scene, helpers, rendered, group, prop, label):
    """scene.symray["quality"] = 99 (a script, a damaged .blend) read as '' and rendered
    with a default."""
    settings = getattr(scene.symray, group) if group else scene.symray
    settings[prop] = 99
    assert getattr(settings, prop) == ""  # what Blender reads
    message = _fails(helpers, scene, rendered, f"{label} holds 99, which is none of its choices")
    assert "choose one in the SymRay panel" in message


@pytest.mark.parametrize(
    "prop, value, match",
    [
        ("tolerance_px", 1e-12, "Accuracy (px) must be a finite number in [1e-06, 100], got 1e-12"),
        ("tolerance_px", 500.0, "Accuracy (px) must be a finite number in [1e-06, 100], got 500"),
        ("samples", 5000, "Samples must be an integer in [1, 1024], got 5000"),
    ],
)
def test_accuracy_and_samples_are_named_as_in_the_panel(
    scene, helpers, rendered, prop, value, match
):
    """The core's "tolerance_px must lie in [1e-9, 100]" named no setting the panel shows."""
    scene.symray.quality = "CUSTOM"
    scene.symray[prop] = value
    message = _fails(helpers, scene, rendered, match)
    assert "tolerance" not in message.lower() and "samples must lie" not in message


def _disk_scene(scene, helpers):
    """Schwarzschild (rg 1) with its disk (ISCO to 10), seen from 30 units at 80 deg."""
    scene.symray.model = "SCHWARZSCHILD"
    scene.symray.center = helpers.add_empty(scene, "Hole")
    scene.symray.disk.enabled = True
    scene.symray.quality = "PREVIEW"
    inc = math.radians(80.0)
    helpers.add_camera(scene, location=(0.0, -30 * math.sin(inc), 30 * math.cos(inc)),
                       rotation=(inc, 0.0, 0.0))  # fmt: skip
    scene.render.resolution_x, scene.render.resolution_y = 16, 12


def test_disk_brightness_never_makes_inf_pixels(scene, helpers, rendered):
    """Brightness 3e38 gave inf pixels: the property stops at 1e6 (finite pixels), and a
    value past it (a script writing the ID property) is refused."""
    _disk_scene(scene, helpers)
    scene.symray.disk.brightness = 3e38
    assert scene.symray.disk.brightness == 1e6
    assert bpy.ops.symray.render() == {"FINISHED"}
    image = helpers.image_array(scene.symray.image_name)
    assert np.isfinite(image).all() and image[..., :3].max() > 1e3  # the disk, bright
    scene.symray.disk["brightness"] = 3e38
    _fails(helpers, scene, image, "Disk Brightness must be a finite number in [0, 1e+06]")


def test_no_inf_pixel_is_ever_written(addon, scene, helpers, rendered, tmp_path, monkeypatch):
    """Whatever makes a colour overflow, neither the operator (image, EXR) nor F12 writes
    it: an error naming the problem, the previous outputs kept."""
    render_job = addon.module("symray_addon.render_job")
    real_run = render_job.run

    def overflowing(*args, **kwargs):
        result = real_run(*args, **kwargs)
        result.rgba[3, 5, 0] = np.inf
        return result

    monkeypatch.setattr(render_job, "run", overflowing)
    scene.symray.exr_path = str(tmp_path / "x.exr")
    _fails(helpers, scene, rendered, "1 pixels have a colour beyond 32-bit floats")
    assert os.listdir(tmp_path) == []
    scene.render.engine = "SYMRAY"
    scene.render.filepath = str(tmp_path / "frame.png")
    with pytest.raises(RuntimeError, match="beyond 32-bit floats"):
        bpy.ops.render.render(write_still=True)
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize("name", ["picture.png", "picture.jpg", "picture.exr.png"])
def test_an_exr_path_not_ending_in_exr_is_refused(scene, helpers, rendered, tmp_path, name):
    """An EXR Path ending in .png overwrote the user's PNG with OpenEXR data. Refused
    (rather than '.exr' appended: 'picture.png.exr' would surprise as much)."""
    user_file = tmp_path / name
    user_file.write_bytes(b"the user's picture")
    scene.symray.exr_path = str(user_file)
    ext = os.path.splitext(name)[1]
    _fails(helpers, scene, rendered, f"ends in '{ext}', not '.exr'")
    assert os.listdir(tmp_path) == [name] and user_file.read_bytes() == b"the user's picture"


def test_exr_paths_that_are_accepted(scene, helpers, rendered, tmp_path):
    """'.EXR' in capitals is an EXR path; a path without extension gets '.exr'."""
    for path, written in (("A.EXR", ["A.EXR", "A.passes.EXR"]), ("b", ["b.exr", "b.passes.exr"])):
        scene.symray.exr_path = str(tmp_path / path)
        assert bpy.ops.symray.render() == {"FINISHED"}
        assert set(written) <= set(os.listdir(tmp_path))


@pytest.mark.parametrize(
    "prop, value, match",
    [
        ("star_brightness", -1.0, "Star Brightness must be a finite number in [0, 1e+06], got -1"),
        ("star_brightness", math.nan, "Star Brightness must be a finite number in [0, 1e+06]"),
        ("star_count", -5, "Stars must be an integer >= 0, got -5"),
        ("star_seed", -2, "Seed must be an integer >= 0, got -2"),
    ],
)
def test_point_star_settings_are_named_as_in_the_panel(
    scene, helpers, rendered, prop, value, match
):
    """Values a .blend or a script writes past the properties' ranges are refused naming
    the setting (not the core's flux_zero, count or seed) (issue 45, point 10)."""
    scene.symray.background = "STARS"
    scene.symray[prop] = value
    message = _fails(helpers, scene, rendered, match)
    assert "flux_zero" not in message


def test_a_magnitude_beyond_any_star_names_the_catalogue_not_the_disk(
    scene, helpers, rendered, tmp_path
):
    """A catalogue magnitude of -1000 (its flux beyond 32-bit floats) is refused naming the
    file and line, not blamed on Disk Brightness (issue 45, point 10)."""
    catalogue = tmp_path / "stars.csv"
    catalogue.write_text("ra,dec,mag\n90,0,1\n0,0,-1000\n\n")
    scene.symray.background = "STARS"
    scene.symray.star_catalog = str(catalogue)
    message = _fails(helpers, scene, rendered, "stars.csv, line 3: magnitude -1000")
    assert "Disk Brightness" not in message


def test_a_nan_spin_of_a_hole_names_spin(addon, scene, helpers, rendered):
    """A hole object's NaN Spin is reported as Spin's, not as "Size must be a finite number
    > 0" (its rg, computed from both, was NaN) (issue 45, point 11)."""
    scene.symray.model = "OBJECTS"
    scene.cursor.location = (0.0, 0.0, 0.0)
    assert bpy.ops.symray.add_black_hole(size=0.5, disk=False) == {"FINISHED"}
    hole = bpy.context.active_object
    hole.symray["spin"] = math.nan  # as a .blend can hold it (the property lets NaN by)
    hole.update_tag()  # an ID property written directly tags nothing
    message = _fails(helpers, scene, rendered, "Spin a/M must be a finite number, got nan")
    assert "Size" not in message


def test_an_image_name_longer_than_blender_keeps_is_refused(scene, helpers, rendered):
    """Blender cuts names at 255 bytes (63 before 5.0): a longer Image name would never
    find its image again and packed a new one at every render (issue 45, point 12)."""
    longest = bpy.types.ID.bl_rna.properties["name"].length_max - 1
    images = len(bpy.data.images)
    scene.symray.image_name = "x" * 300
    for _ in range(2):  # no image made, none at a second render either
        message = helpers.operator_error(lambda: bpy.ops.symray.render())
        assert "SymRay › Output › Image is 300 bytes long" in message
        assert f"at most {longest} bytes" in message
        assert len(bpy.data.images) == images
    np.testing.assert_array_equal(helpers.image_array("SymRay Result"), rendered)
    scene.symray.image_name = "é" * (longest // 2)  # two bytes each: the longest kept
    assert bpy.ops.symray.render() == {"FINISHED"}
    assert bpy.ops.symray.render() == {"FINISHED"}
    assert len(bpy.data.images) == images + 1


@pytest.mark.parametrize(
    "kind, match",
    [
        ("VELOCITY", "› SymRay Observer › Velocity (0.8, 0.8, 0) has speed 1.13137 c"),
        ("ANIMATION", "(From Animation): the camera moves at 2.4 c"),
    ],
)
def test_observer_messages_show_plain_numbers(addon, scene, helpers, rendered, kind, match):
    """A camera at or above c is refused naming its setting with plain numbers, not numpy's
    "(np.float64(0.8), ...)" (issue 45, point 13)."""
    camera = scene.camera
    camera.data.symray.kind = kind
    camera.data.symray.velocity = (0.8, 0.8, 0.0)
    camera.data.symray.speed_of_light = 10.0
    camera.keyframe_insert("location", frame=1)
    camera.location.x += 2.0  # 1 unit a frame at 24 fps: 24 units/s, 2.4 c at c = 10/s
    camera.keyframe_insert("location", frame=3)
    scene.render.fps, scene.render.fps_base = 24, 1.0
    scene.frame_set(2)
    message = _fails(helpers, scene, rendered, match)
    assert "np.float64" not in message and "array(" not in message

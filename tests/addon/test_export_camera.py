"""Camera export: core.Camera.blender(**kwargs) sees exactly Blender's camera frame."""

from __future__ import annotations

import math

import numpy as np
import pytest

CASES = [
    dict(res=(64, 48), data={}),
    dict(res=(48, 64), data={"sensor_fit": "AUTO", "lens": 35.0}),
    dict(res=(64, 48), data={"sensor_fit": "VERTICAL", "sensor_height": 20.0}),
    dict(res=(40, 60), data={"sensor_fit": "HORIZONTAL", "shift_x": 0.2, "shift_y": -0.1}),
    dict(res=(64, 48), data={"shift_y": 0.3}, aspect=(2.0, 1.0)),
    dict(res=(50, 50), data={"lens": 85.0}, aspect=(1.0, 1.5), percentage=50),
    dict(res=(64, 32), data={"type": "ORTHO", "ortho_scale": 7.5, "shift_x": 0.1}),
]


@pytest.mark.parametrize("case", CASES, ids=[str(i) for i in range(len(CASES))])
def test_rays_match_view_frame(addon, scene, helpers, case):
    render = scene.render
    render.resolution_x, render.resolution_y = case["res"]
    render.resolution_percentage = case.get("percentage", 100)
    render.pixel_aspect_x, render.pixel_aspect_y = case.get("aspect", (1.0, 1.0))
    cam = helpers.add_camera(
        scene,
        location=(1.0, -9.0, 2.5),
        rotation=(math.radians(75), 0.2, math.radians(10)),
        **case["data"],
    )
    export = addon.module("symray_addon.export_camera")
    kwargs = export.camera_kwargs(scene, cam)
    camera = addon.core.Camera.blender(**kwargs)
    w, h = export.full_size(scene)
    assert (camera.width, camera.height) == (w, h)
    rows = np.array([0, 0, h - 1, h - 1, h // 2, 3])
    cols = np.array([0, w - 1, 0, w - 1, w // 2, 5])
    origins, directions = camera.rays()
    flat = rows * w + cols
    expected = helpers.frame_directions(scene, cam, rows, cols)
    if cam.data.type == "ORTHO":
        np.testing.assert_allclose(origins[flat], np.array(cam.location) + expected, atol=1e-6)
        forward = -np.array(cam.matrix_world)[:3, 2]
        np.testing.assert_allclose(directions[flat], np.tile(forward, (len(flat), 1)), atol=1e-9)
    else:
        np.testing.assert_allclose(directions[flat], expected, atol=1e-6)
        np.testing.assert_allclose(origins[flat], np.tile(cam.location, (len(flat), 1)), atol=1e-6)


def test_kwargs_contract(addon, scene, helpers):
    cam = helpers.add_camera(scene, lens=42.0)
    kwargs = addon.module("symray_addon.export_camera").camera_kwargs(scene, cam)
    assert set(kwargs) == {
        "type",
        "lens",
        "sensor_width",
        "sensor_height",
        "sensor_fit",
        "shift_x",
        "shift_y",
        "ortho_scale",
        "resolution_x",
        "resolution_y",
        "resolution_percentage",
        "pixel_aspect_x",
        "pixel_aspect_y",
        "matrix_world",
        "border",
    }
    assert kwargs["lens"] == pytest.approx(42.0)
    assert kwargs["matrix_world"].shape == (4, 4)
    assert kwargs["border"] is None


def test_border_region(addon, scene, helpers):
    cam = helpers.add_camera(scene)
    render = scene.render
    render.use_border = True
    render.border_min_x, render.border_max_x = 0.25, 0.75
    render.border_min_y, render.border_max_y = 0.5, 1.0
    export = addon.module("symray_addon.export_camera")
    kwargs = export.camera_kwargs(scene, cam)
    assert kwargs["border"] == pytest.approx((0.25, 0.75, 0.5, 1.0))
    camera = addon.core.Camera.blender(**kwargs)
    assert (camera.width, camera.height) == (32, 24)
    full = addon.core.Camera.blender(**export.camera_kwargs(scene, cam, use_border=False))
    # the region's pixels are the full frame's pixels (row 0 = top of the frame)
    _, d_region = camera.rays()
    _, d_full = full.rays()
    d_full = d_full.reshape(48, 64, 3)[0:24, 16:48].reshape(-1, 3)
    np.testing.assert_allclose(d_region, d_full, atol=1e-12)


def test_no_camera_is_a_clear_error(addon, scene):
    export = addon.module("symray_addon.export_camera")
    with pytest.raises(ValueError, match="no active camera"):
        export.camera_kwargs(scene, None)

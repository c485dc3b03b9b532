"""Camera rays against Blender's documented frame and against rays rendered by Blender."""

import json
import math
from pathlib import Path

import numpy as np
import pytest

from core.camera import Camera
from core.sky import direction_to_equirect

REF = Path(__file__).parent / "data" / "blender_reference.npz"


def _angle(u, v):
    u = np.asarray(u) / np.linalg.norm(u, axis=-1, keepdims=True)
    v = np.asarray(v) / np.linalg.norm(v, axis=-1, keepdims=True)
    return np.arccos(np.clip(np.sum(u * v, axis=-1), -1, 1))


def _grid(cam):
    o, d = cam.rays()
    return o.reshape(cam.height, cam.width, 3), d.reshape(cam.height, cam.width, 3)


def _local(cam, d):
    f = cam.frame
    return np.stack([d @ f.right, d @ f.up, d @ f.forward], axis=-1)


# -- Blender's documented frame ------------------------------------------------------------


def test_edge_ray_angle_36mm_sensor_50mm_lens():
    w, h = 64, 33  # odd height: the middle row lies on the optical axis
    cam = Camera.blender(lens=50, sensor_width=36, resolution_x=w, resolution_y=h)
    assert cam.window[1] == pytest.approx(18 / 50)
    _, d = _grid(cam)
    loc = _local(cam, d)
    mid = loc[h // 2]
    # pixel centres: the outermost is half a pixel inside the frame edge at tan = 18/50
    assert math.atan2(mid[-1, 0], mid[-1, 2]) == pytest.approx(math.atan(18 / 50 * (w - 1) / w))
    assert math.atan2(mid[0, 0], mid[0, 2]) == pytest.approx(-math.atan(18 / 50 * (w - 1) / w))
    assert np.allclose(mid[:, 1], 0, atol=1e-15)


def test_perspective_fov_matches_blender_lens_landscape_and_portrait():
    for w, h in [(40, 30), (30, 40), (25, 25)]:
        a = Camera.perspective((1, 2, 3), (0, 0, 0), (0, 0, 1), 40, w, h)
        lens = 18 / math.tan(math.radians(20))
        ref = np.linalg.norm(np.array([-1.0, -2, -3]))
        assert a.frame.forward == pytest.approx(np.array([-1.0, -2, -3]) / ref)
        b = Camera.blender(lens=lens, sensor_width=36, resolution_x=w, resolution_y=h)
        assert np.allclose(a.window, b.window, rtol=1e-12, atol=1e-15)
        half = max(abs(v) for v in a.window)
        assert half == pytest.approx(math.tan(math.radians(20)))  # larger dimension


def test_vertical_fit_uses_sensor_height_for_the_height():
    cam = Camera.blender(lens=50, sensor_width=36, sensor_height=24, sensor_fit="VERTICAL",
                         resolution_x=40, resolution_y=30)  # fmt: skip
    xmin, xmax, ymin, ymax = cam.window
    assert ymax == pytest.approx(12 / 50) and ymin == pytest.approx(-12 / 50)
    assert xmax == pytest.approx(12 / 50 * 40 / 30)


def test_horizontal_fit_portrait_uses_width():
    cam = Camera.blender(lens=50, sensor_width=30, sensor_fit="HORIZONTAL",
                         resolution_x=30, resolution_y=40)  # fmt: skip
    assert cam.window[1] == pytest.approx(15 / 50)
    assert cam.window[3] == pytest.approx(15 / 50 * 40 / 30)


def test_auto_fit_portrait_spans_sensor_width_vertically():
    cam = Camera.blender(lens=50, sensor_width=36, resolution_x=30, resolution_y=40)
    assert cam.window[3] == pytest.approx(18 / 50)
    assert cam.window[1] == pytest.approx(18 / 50 * 30 / 40)


@pytest.mark.parametrize("res", [(41, 31), (31, 41)])
def test_shift_moves_frame_by_shift_times_larger_dimension(res):
    sx, sy = 0.25, -0.1
    base = Camera.blender(lens=50, sensor_width=36, resolution_x=res[0], resolution_y=res[1])
    cam = Camera.blender(lens=50, sensor_width=36, shift_x=sx, shift_y=sy,
                         resolution_x=res[0], resolution_y=res[1])  # fmt: skip
    larger = 36 / 50  # the larger dimension spans the sensor width (AUTO fit)
    assert np.allclose(np.subtract(cam.window, base.window), [sx * larger] * 2 + [sy * larger] * 2)
    _, d = _grid(cam)
    centre = _local(cam, d[res[1] // 2, res[0] // 2])  # odd sizes: the central pixel
    assert centre[0] / centre[2] == pytest.approx(sx * larger)
    assert centre[1] / centre[2] == pytest.approx(sy * larger)


def test_pixel_aspect_switches_fit_and_stretches_pixels():
    # 40 x 30 pixels twice as tall as wide: 40 x 60 in aspect units -> vertical fit (AUTO)
    cam = Camera.blender(lens=50, sensor_width=36, resolution_x=40, resolution_y=30,
                         pixel_aspect_x=1, pixel_aspect_y=2)  # fmt: skip
    xmin, xmax, ymin, ymax = cam.window
    assert ymax == pytest.approx(18 / 50)
    assert xmax == pytest.approx(18 / 50 * 40 / 60)
    pix_w, pix_h = (xmax - xmin) / 40, (ymax - ymin) / 30
    assert pix_h / pix_w == pytest.approx(2.0)


def test_resolution_percentage_and_identity_matrix():
    cam = Camera.blender(resolution_x=1920, resolution_y=1080, resolution_percentage=10)
    assert (cam.width, cam.height, cam.n_pixels) == (192, 108, 192 * 108)
    f = cam.frame  # identity matrix: Blender's camera looks down -Z with +Y up
    assert np.allclose(f.forward, [0, 0, -1]) and np.allclose(f.up, [0, 1, 0])
    assert np.allclose(f.right, [1, 0, 0]) and np.allclose(f.position, 0)


def test_matrix_world_scale_is_removed():
    m = np.diag([2.0, 3.0, 0.5, 1.0])
    m[:3, 3] = (1, 2, 3)
    cam = Camera.blender(matrix_world=m, resolution_x=8, resolution_y=6)
    ref = Camera.blender(matrix_world=np.eye(4), resolution_x=8, resolution_y=6)
    o, d = cam.rays()
    o_ref, d_ref = ref.rays()
    assert np.allclose(d, d_ref) and np.allclose(o, o_ref + [1, 2, 3])


# -- pixel order, chunks, frames -------------------------------------------------------------


def test_row_zero_is_the_top_and_rays_are_unit():
    cam = Camera.perspective((0, 0, 0), (0, 1, 0), (0, 0, 1), 60, 16, 12)
    o, d = cam.rays()
    assert np.allclose(np.linalg.norm(d, axis=1), 1, atol=1e-15)
    first, last = d[0], d[-1]
    assert first[2] > 0 and first[0] < 0  # top left: up and to the left (right = +X)
    assert last[2] < 0 and last[0] > 0
    assert np.allclose(o, 0)


def test_chunks_concatenate_to_the_whole_image():
    cam = Camera.blender(resolution_x=13, resolution_y=7, shift_x=0.1)
    o, d = cam.rays()
    parts = [cam.rays(a, b) for a, b in [(0, 5), (5, 50), (50, 91)]]
    assert np.array_equal(np.concatenate([p[1] for p in parts]), d)
    assert np.array_equal(np.concatenate([p[0] for p in parts]), o)
    with pytest.raises(IndexError):
        cam.rays(0, 92)


def test_frame_is_orthonormal_right_handed():
    cam = Camera.perspective((1, -3, 2), (0, 0, 0), (0, 0, 1), 30, 10, 10)
    f = cam.frame
    m = f.matrix
    assert np.allclose(m.T @ m, np.eye(3), atol=1e-14)
    assert np.allclose(np.cross(f.forward, f.up), f.right)
    v = np.array([[0.3, -0.2, 0.9]])
    assert np.allclose(f.to_world(f.to_local(v)), v)
    assert f.up[2] > 0


def test_orthographic_parallel_rays_spanning_ortho_scale():
    cam = Camera.orthographic((0, -10, 0), (0, 0, 0), (0, 0, 1), 4.0, 20, 10)
    o, d = _grid(cam)
    assert np.allclose(d, [0, 1, 0])
    assert o[0, -1, 0] - o[0, 0, 0] == pytest.approx(4.0 * 19 / 20)
    assert o[0, 0, 2] - o[-1, 0, 2] == pytest.approx(4.0 * 9 / 20)  # square pixels
    assert np.allclose(o[..., 1], -10)


def test_panorama_matches_blender_environment_convention():
    # looking along +X with +Z up, the panorama is the environment map itself
    w, h = 36, 18
    cam = Camera.panorama((0, 0, 0), (1, 0, 0), (0, 0, 1), w, h)
    _, d = cam.rays()
    uv = direction_to_equirect(d).reshape(h, w, 2)
    u_centres = (np.arange(w) + 0.5) / w
    v_centres = 1 - (np.arange(h) + 0.5) / h  # row 0 at the top
    assert np.allclose(uv[..., 0], u_centres[None, :], atol=1e-12)
    assert np.allclose(uv[..., 1], v_centres[:, None], atol=1e-12)


def test_panorama_centre_left_and_top():
    cam = Camera.panorama((0, 0, 0), (0, 1, 0), (0, 0, 1), 8, 5)
    _, d = _grid(cam)
    lat = np.radians([72, 36, 0, -36, -72])  # row centres, row 0 at the top
    assert np.allclose(d[..., 2], np.sin(lat)[:, None])
    assert _angle(d[2, 4] + d[2, 3], [0, 1, 0]) < 1e-12  # image centre: the view direction
    # column boundary at u = 0.25 (between columns 1 and 2): directly to the left (-X)
    mid = d[2]
    left = (mid[1] + mid[2]) / 2
    assert _angle(left, [-1, 0, 0]) < 1e-12


def test_border_selects_a_region_of_the_full_frame():
    full = Camera.blender(resolution_x=40, resolution_y=20, shift_y=0.05)
    part = Camera.blender(resolution_x=40, resolution_y=20, shift_y=0.05,
                          border=(0.25, 0.75, 0.5, 1.0))  # fmt: skip
    assert (part.width, part.height, part.offset) == (20, 10, (10, 0))
    _, d_full = _grid(full)
    _, d_part = _grid(part)
    assert np.allclose(d_part, d_full[0:10, 10:30], atol=1e-15)  # the top half


def test_border_truncates_in_float32_like_blender():
    # Blender multiplies float32 border * size and truncates; bpy 5.2 renders these widths
    # (in float64, 0.29 * 100 = 28.999999999999996 would give 71 and 0.57 * 100 give 44)
    for (lo, hi), width in [((0.29, 0.999), 70), ((0.57, 1.0), 43), ((0.0, 0.29), 29)]:
        cam = Camera.blender(resolution_x=100, resolution_y=10, border=(lo, hi, 0, 1))
        assert cam.width == width


@pytest.mark.parametrize(
    "kwargs",
    [dict(fov_deg=0), dict(fov_deg=180), dict(up=(0, 1, 0)), dict(width=0), dict(height=2.5)],
)
def test_invalid_perspective_arguments(kwargs):
    args = dict(position=(0, 0, 0), look_at=(0, 1, 0), up=(0, 0, 1), fov_deg=40,
                width=8, height=8) | kwargs  # fmt: skip
    with pytest.raises(ValueError):
        Camera.perspective(**args)


def test_invalid_blender_arguments():
    with pytest.raises(ValueError):
        Camera.blender(type="FISHEYE")
    with pytest.raises(ValueError):
        Camera.blender(type="PANO", panorama_type="MIRRORBALL")
    with pytest.raises(ValueError):
        Camera.blender(border=(0.5, 0.5, 0, 1))


# -- against Blender itself ------------------------------------------------------------------


def camera_from_config(cfg, matrix):
    """The Camera.blender call matching a reference render's configuration."""
    asp = cfg.get("asp", (1, 1))
    return Camera.blender(
        resolution_x=cfg["res"][0], resolution_y=cfg["res"][1],
        resolution_percentage=cfg.get("pct", 100), pixel_aspect_x=asp[0],
        pixel_aspect_y=asp[1], matrix_world=matrix, border=cfg.get("border"), **cfg["cam"],
    )  # fmt: skip


@pytest.mark.parametrize("case", range(11))
def test_rays_match_directions_rendered_by_blender(case):
    """Directions rendered by Cycles (world shader emitting the ray direction), float32."""
    ref = np.load(REF)
    key = f"cam{case}"
    cfg = json.loads(str(ref[f"{key}_config"]))
    cam = camera_from_config(cfg, ref[f"{key}_matrix"])
    _, d = _grid(cam)
    expected = ref[f"{key}_dirs"].astype(np.float64)
    assert d.shape == expected.shape
    assert np.degrees(_angle(d, expected)).max() < 1e-3

"""Point stars in Blender (Background › Point Stars): from the factory scene, a catalogue's
stars land on the pixels Blender's own camera puts them at, each with its flux; a bad
catalogue is refused naming its line."""

import math

import bpy
import numpy as np
import pytest


def _job(addon):
    return addon.module("symray_addon.render_job")


def _render(addon, scene):
    job = _job(addon)
    return job.run(job.prepare(scene, bpy.context.evaluated_depsgraph_get()))


def test_catalogue_stars_land_where_blenders_camera_looks(addon, factory_scene, helpers, tmp_path):
    """Flat space, three stars of a CSV catalogue placed on pixel centres (directions from
    Blender's camera.view_frame, away from the factory cube): each adds its flux
    F = brightness × 1e-6 × 10^(−0.4 m) to its pixel alone (a point on a pixel centre: the
    1.5 px Blackman-Harris filter's neighbours get 0), as radiance F / Ω (Ω: the pixel's
    solid angle from central differences of view_frame's directions), to 1e-3; the rest of the frame
    is the Milky Way without stars."""
    scene = factory_scene
    scene.symray.model = "FLAT"
    scene.symray.background = "STARS"
    scene.symray.star_brightness = 50.0
    rows, cols = np.array([5, 40, 8]), np.array([6, 10, 58])
    d = helpers.frame_directions(scene, scene.camera, rows, cols)
    ra = np.degrees(np.arctan2(d[:, 1], d[:, 0]))
    dec = np.degrees(np.arcsin(d[:, 2]))
    catalogue = tmp_path / "stars.csv"
    lines = [
        f"{a:.12f},{b:.12f},{m},0.65" for a, b, m in zip(ra, dec, (0.0, 1.0, 2.5), strict=True)
    ]
    catalogue.write_text("RA,Dec,Vmag,B-V\n" + "\n".join(lines) + "\n")
    scene.symray.star_catalog = str(catalogue)
    with_stars = _render(addon, scene).rgba
    scene.symray.star_brightness = 0.0
    without = _render(addon, scene).rgba
    added = (with_stars[..., :3] - without[..., :3]).astype(np.float64) @ [0.2126, 0.7152, 0.0722]
    assert np.count_nonzero(np.abs(added) > 1e-6) == 3

    def along(dr, dc):  # central differences of Blender's directions
        ahead = helpers.frame_directions(scene, scene.camera, rows + dr, cols + dc)
        return 0.5 * (ahead - helpers.frame_directions(scene, scene.camera, rows - dr, cols - dc))

    side, down = along(0, 1), along(1, 0)
    solid_angle = np.linalg.norm(np.cross(side, down), axis=1)
    flux = 50.0 * 1e-6 * 10 ** (-0.4 * np.array([0.0, 1.0, 2.5]))
    np.testing.assert_allclose(added[rows, cols] * solid_angle, flux, rtol=1e-3)


def test_a_bad_catalogue_is_refused_naming_its_line(addon, factory_scene, tmp_path):
    """A catalogue with a word where a declination should be: the render is refused before
    anything is traced, with the file and line named; a missing file names the file."""
    scene = factory_scene
    scene.symray.background = "STARS"
    bad = tmp_path / "bad.csv"
    bad.write_text("ra,dec,mag\n10,20,3\n10,north,3\n")
    scene.symray.star_catalog = str(bad)
    with pytest.raises(ValueError, match="line 3: column 'dec'"):
        _job(addon).prepare(scene, bpy.context.evaluated_depsgraph_get())
    scene.symray.star_catalog = str(tmp_path / "none.csv")
    with pytest.raises(ValueError, match="cannot read the star catalogue"):
        _job(addon).prepare(scene, bpy.context.evaluated_depsgraph_get())
    assert math.isfinite(scene.symray.star_brightness)

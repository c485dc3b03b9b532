"""An animation on a farm: frames rendered in separate processes, in chunks of frames, are
the frames of one process's render (issue 49, README "Beyond one machine")."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import bpy
import numpy as np
import pytest

from tests.addon.exr_output import exr_output, read_exr

CHUNK = Path(__file__).with_name("farm_chunk.py")
FRAMES = 4


def _farm_scene(path: Path) -> None:
    """The factory scene with a Kerr hole and disk (its exposure pinned at frame 1, as the
    README's recipe says), the camera flying past and the hole's Size keyed, lit surfaces baked
    (the factory cube under its light); saved to ``path``."""
    bpy.ops.wm.read_homefile(use_factory_startup=True)
    scene = bpy.context.scene
    scene.render.engine = "SYMRAY"
    scene.render.resolution_x, scene.render.resolution_y = 48, 27
    scene.render.resolution_percentage = 100
    scene.symray.quality = "PREVIEW"
    scene.symray.lighting = "AUTO"
    scene.symray.bake_texel_size, scene.symray.bake_samples = 0.25, 4
    scene.cursor.location = (0.0, 6.0, 0.0)
    assert bpy.ops.symray.add_black_hole(size=0.5, spin=0.6, disk=True) == {"FINISHED"}
    hole = bpy.context.active_object
    camera = bpy.data.objects["Camera"]
    for frame, x, size in ((1, 7.4, 0.5), (FRAMES, 3.0, 0.8)):
        camera.location.x = x
        camera.keyframe_insert("location", index=0, frame=frame)
        hole.symray.size = size
        hole.symray.keyframe_insert("size", frame=frame)
    scene.frame_start, scene.frame_end = 1, FRAMES
    scene.frame_set(1)
    assert bpy.ops.symray.pin_exposure() == {"FINISHED"}  # the recipe: one exposure for all
    exr_output(scene)
    scene.render.use_file_extension = True
    bpy.ops.wm.save_as_mainfile(filepath=str(path))


def _chunk(zip_path: Path, blend: Path, out: Path, start: int, end: int) -> subprocess.Popen:
    """A farm worker rendering frames start..end, with its own Blender user folder."""
    user = out / "user"
    user.mkdir(parents=True)
    env = {**os.environ, "BLENDER_USER_RESOURCES": str(user)}
    command = [sys.executable, str(CHUNK), str(zip_path), str(blend), str(out)]
    frames = ["--start", str(start), "--end", str(end)]
    return subprocess.Popen(
        [*command, *frames], env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
    )


def test_chunks_on_two_workers_are_the_frames_of_one_render(addon, extension_zip, tmp_path):
    """Frames 1-2 on one worker process and 3-4 on another equal, bit for bit, the frames
    of one process rendering 1-4; the frames differ from each other (the camera and the
    hole's Size move)."""
    blend = tmp_path / "shot.blend"
    _farm_scene(blend)
    jobs = {
        "whole": _chunk(extension_zip, blend, tmp_path / "whole", 1, FRAMES),
        "first": _chunk(extension_zip, blend, tmp_path / "first", 1, 2),
        "second": _chunk(extension_zip, blend, tmp_path / "second", 3, FRAMES),
    }
    for name, job in jobs.items():
        output, _ = job.communicate(timeout=400)
        assert job.returncode == 0, f"{name}: {output[-3000:]}"
    whole = {f: read_exr(tmp_path / "whole" / f"frame_{f:04d}.exr") for f in range(1, FRAMES + 1)}
    for f in range(1, FRAMES + 1):
        chunk = tmp_path / ("first" if f <= 2 else "second") / f"frame_{f:04d}.exr"
        np.testing.assert_array_equal(read_exr(chunk), whole[f], err_msg=f"frame {f}")
    assert np.abs(whole[1] - whole[FRAMES]).max() > 0.1
    assert not (tmp_path / "first" / f"frame_{3:04d}.exr").exists()


def test_pin_exposure_keeps_what_the_frame_chose(addon, factory_scene):
    """Pin Exposure: Auto Exposure off, Exposure what this frame's render chose, and the
    render with it the automatic one's (to the float32 the setting holds); then there is
    nothing left to pin."""
    scene = factory_scene
    scene.render.resolution_x, scene.render.resolution_y = 48, 27
    scene.symray.quality, scene.symray.lighting = "PREVIEW", "UNLIT"
    scene.cursor.location = (0.0, 6.0, 0.0)
    assert bpy.ops.symray.add_black_hole(size=0.5, spin=0.6, disk=True) == {"FINISHED"}
    job = addon.module("symray_addon.render_job")
    auto = job.run(job.prepare(scene, bpy.context.evaluated_depsgraph_get()))
    chosen = auto.summary["disk_exposure"]
    assert bpy.ops.symray.pin_exposure() == {"FINISHED"}
    disk = scene.symray.disk
    assert not disk.auto_exposure
    assert disk.exposure == pytest.approx(chosen, rel=1e-6) and chosen != 1.0
    pinned = job.run(job.prepare(scene, bpy.context.evaluated_depsgraph_get()))
    assert pinned.summary["disk_exposure"] == pytest.approx(chosen, rel=1e-6)
    np.testing.assert_allclose(pinned.rgba, auto.rgba, rtol=1e-5, atol=1e-6)
    assert not bpy.ops.symray.pin_exposure.poll()

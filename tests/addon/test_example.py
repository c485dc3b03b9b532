"""examples/render_scene.py runs with the bpy module and writes PNG + multi-layer EXR."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from .conftest import REPO

OpenEXR = pytest.importorskip("OpenEXR")


def test_render_scene_example(addon, tmp_path):
    png, blend = tmp_path / "x.png", tmp_path / "scene.blend"
    env = dict(os.environ)  # BLENDER_USER_RESOURCES: this session's folder, extension installed
    run = subprocess.run(
        [
            sys.executable,
            str(REPO / "examples" / "render_scene.py"),
            "--out",
            str(png),
            "--width",
            "20",
            "--height",
            "15",
            "--tolerance",
            "1e-4",
            "--save-blend",
            str(blend),
        ],
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert run.returncode == 0, run.stdout + run.stderr
    assert "render_scene:" in run.stdout and "rays" in run.stdout
    assert png.stat().st_size > 0 and blend.stat().st_size > 0
    with OpenEXR.File(str(tmp_path / "x.exr"), separate_channels=True) as f:
        names = {n for part in f.parts for n in part.channels}
    assert any(n.endswith("SymRay Error.X") for n in names), names
    assert any(n.endswith("Combined.R") for n in names), names
    again = subprocess.run(
        [
            sys.executable,
            str(REPO / "examples" / "render_scene.py"),
            "--blend",
            str(blend),
            "--out",
            str(tmp_path / "y.png"),
        ],
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert again.returncode == 0, again.stdout + again.stderr
    assert (tmp_path / "y.png").stat().st_size > 0


def test_render_scene_device_gpu_without_a_gpu_fails_by_name(addon, tmp_path):
    """--device GPU where CuPy or a GPU is missing: the run fails naming CuPy and writes no
    image (a farm script learns why, not a wrong frame)."""
    if addon.core.backend.cuda_problem() is None:
        pytest.skip("a GPU renders here")
    png = tmp_path / "gpu.png"
    run = subprocess.run(
        [sys.executable, str(REPO / "examples" / "render_scene.py"), "--out", str(png),
         "--width", "8", "--height", "6", "--tolerance", "1e-4", "--device", "GPU"],
        env=dict(os.environ), capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert run.returncode != 0 and "CuPy" in run.stdout + run.stderr
    assert not png.exists()

"""Baking in Blender's own factory scene: child collections, animations.

The factory scene keeps its objects in the "Collection" child collection, which the
temporary bake scene must link and whose exclusions it must copy; an animation render
bakes inside the render job, frame after frame. Animations run in a process of their
own (animation_job.py), so that a crash of Blender fails the test instead of pytest.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import bpy
import numpy as np

from tests.addon.exr_output import exr_output, read_exr

JOB = Path(__file__).with_name("animation_job.py")


def _f12(scene, path: Path) -> np.ndarray:
    """An F12 still of ``scene`` (its engine) as linear RGBA."""
    exr_output(scene, path)
    assert bpy.ops.render.render(write_still=True) == {"FINISHED"}
    return read_exr(path)


def _diffuse_factory(scene) -> None:
    """The factory scene made comparable with Cycles: flat model, one ray a pixel centre,
    no specular layer on the cube (a bake holds only what is alike in all directions)."""
    bsdf = next(
        n for n in bpy.data.materials["Material"].node_tree.nodes if n.type == "BSDF_PRINCIPLED"
    )
    bsdf.inputs["Specular IOR Level"].default_value = 0.0
    scene.symray.model = "FLAT"
    scene.symray.quality = "RADIANS"
    scene.symray.bake_texel_size = 0.1
    scene.symray.bake_samples = 64
    scene.render.filter_size = 0.01


def _cycles(scene, path: Path) -> np.ndarray:
    """Cycles' render of ``scene`` (pixel centres, no denoising), then SymRay back."""
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = 128
    scene.cycles.use_denoising = False
    scene.cycles.use_adaptive_sampling = False
    scene.cycles.filter_width = 0.01
    try:
        return _f12(scene, path)
    finally:
        scene.render.engine = "SYMRAY"


def test_factory_scene_bakes_by_every_path(addon, factory_scene, tmp_path):
    """Bake Lighting (then F12 reusing its bake), Render SymRay Image and F12 bake the
    factory scene (objects in a child collection) alike; the lit cube matches Cycles'
    render of the same scene, and differs from the unlit cube."""
    scene = factory_scene
    _diffuse_factory(scene)
    bake = addon.module("symray_addon.bake")
    bake.clear_cache()
    want = _cycles(scene, tmp_path / "cycles.exr")

    baked, reused = bake.stats["baked"], bake.stats["reused"]
    assert bpy.ops.symray.bake_lighting() == {"FINISHED"}
    assert bake.stats["baked"] - baked == 1  # the cube
    f12 = _f12(scene, tmp_path / "f12.exr")  # reuses that bake
    assert (bake.stats["baked"] - baked, bake.stats["reused"] - reused) == (1, 1)
    bake.clear_cache()
    assert bpy.ops.symray.render() == {"FINISHED"}  # bakes again
    assert bake.stats["baked"] - baked == 2
    operator = _result()
    bake.clear_cache()
    fresh = _f12(scene, tmp_path / "fresh.exr")  # F12 bakes itself
    assert bake.stats["baked"] - baked == 3
    scene.symray.lighting = "UNLIT"
    unlit = _f12(scene, tmp_path / "unlit.exr")

    cube = np.abs(unlit[..., :3] - unlit[0, 0, :3]).max(axis=-1) > 0.01
    assert cube.sum() > 100
    np.testing.assert_allclose(operator, f12, atol=1e-6)
    np.testing.assert_allclose(fresh, f12, atol=1e-6)
    diff = np.abs(f12[..., :3] - want[..., :3])[cube]
    print(f"factory cube: mean |SymRay - Cycles| {diff.mean():.4f} on {cube.sum()} pixels")
    assert diff.mean() < 0.04  # 0.005 measured (64 bake samples, denoised; 128 Cycles samples)
    assert np.abs(f12[..., :3] - unlit[..., :3])[cube].mean() > 0.1


def _result() -> np.ndarray:
    """The operator's image ("SymRay Result") as linear RGBA, row 0 at the top."""
    image = bpy.data.images["SymRay Result"]
    w, h = image.size
    flat = np.empty(w * h * 4, dtype=np.float32)
    image.pixels.foreach_get(flat)
    return flat.reshape(h, w, 4)[::-1]


def _nested_collections(scene) -> None:
    """Under "Collection": "Inner" (included) holding a glowing panel beside the cube, and
    "Hidden" (excluded in the view layer) holding a roof between the light and the cube."""
    outer = bpy.data.collections["Collection"]
    for name, (obj, location, size) in {
        "Inner": ("Glow", (2.2, 0.0, 0.0), 1.0),
        "Hidden": ("Roof", (0.0, 0.0, 2.5), 8.0),
    }.items():
        child = bpy.data.collections.new(name)
        outer.children.link(child)
        bpy.ops.mesh.primitive_plane_add(size=size, location=location)
        plane = bpy.context.object
        plane.name = obj
        for collection in list(plane.users_collection):
            collection.objects.unlink(plane)
        child.objects.link(plane)
    glow = bpy.data.objects["Glow"]
    glow.rotation_euler = (0.0, np.pi / 2, 0.0)
    material = bpy.data.materials.new("Glow")
    if bpy.app.version < (5, 0, 0):
        material.use_nodes = True
    bsdf = next(n for n in material.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    bsdf.inputs["Base Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    bsdf.inputs["Emission Color"].default_value = (1.0, 0.2, 0.1, 1.0)
    bsdf.inputs["Emission Strength"].default_value = 20.0
    glow.data.materials.append(material)
    layer = bpy.context.view_layer.layer_collection.children["Collection"]
    layer.children["Hidden"].exclude = True
    bpy.context.view_layer.update()


def test_bake_copies_nested_collections_and_exclusions(addon, factory_scene):
    """A collection excluded inside "Collection" stays out of the bake (the cube's bake
    equals one without the roof at all; with the roof, the cube is in its shadow), and a
    nested included one is in (its glowing panel is baked and lights the cube)."""
    scene = factory_scene
    scene.symray.bake_texel_size = 0.2
    scene.symray.bake_samples = 16
    _nested_collections(scene)
    bake = addon.module("symray_addon.bake")

    def cube_bake() -> tuple[list[str], np.ndarray]:
        bake.clear_cache()
        surfaces = bake.bake_surfaces(scene, bpy.context.evaluated_depsgraph_get())
        return sorted(surfaces), surfaces["Cube"].pixels[..., :3]

    names, excluded = cube_bake()
    assert names == ["Cube", "Glow"]
    roof = bpy.data.objects["Roof"]
    bpy.data.collections["Hidden"].objects.unlink(roof)
    _names, without = cube_bake()
    np.testing.assert_allclose(excluded, without, atol=1e-5)
    scene.collection.objects.link(roof)  # in the scene, not excluded: it shades the cube
    bpy.context.view_layer.update()
    _names, shaded = cube_bake()
    assert without.mean() - shaded.mean() > 0.05
    bpy.data.collections["Inner"].objects.unlink(bpy.data.objects["Glow"])
    bpy.context.view_layer.update()
    names, unglowed = cube_bake()
    assert names == ["Cube", "Roof"]
    assert (shaded[..., 0] - unglowed[..., 0]).max() > 0.1  # the panel's red light


def _animate(extension_zip, tmp_path: Path, *args: str) -> tuple[Path, dict]:
    """Run animation_job.py in a Python process of its own (its own Blender user folder);
    return its output folder and its report."""
    out, user = tmp_path / "out", tmp_path / "user"
    out.mkdir()
    user.mkdir()
    proc = subprocess.run(
        [sys.executable, str(JOB), str(extension_zip), str(out), *args],
        env=dict(os.environ, BLENDER_USER_RESOURCES=str(user)),
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, f"exit {proc.returncode}\n{proc.stdout[-3000:]}\n{proc.stderr}"
    return out, json.loads((out / "report.json").read_text(encoding="utf-8"))


def test_animation_bakes_every_frame_without_crashing(addon, extension_zip, tmp_path):
    """render(animation=True) with a Sun and a moving cube, baking inside the render job
    (a farm's `blender -b -a`): Blender exits normally, each frame is written, baked
    anew, and equals an F12 still of that frame from a fresh bake; lit differs from
    unlit, and the cube moves."""
    out, report = _animate(
        extension_zip, tmp_path, "--frames", "3", "--stills", "1,3", "--unlit", "3"
    )
    assert report["baked_in_animation"] == 3 and report["scenes"] == 1
    frames = [read_exr(out / f"frame_{k:04d}.exr") for k in (1, 2, 3)]
    for k in (1, 3):
        still = read_exr(out / f"still_{k:04d}.exr")
        np.testing.assert_allclose(frames[k - 1], still, atol=1e-4)
    unlit = read_exr(out / "unlit_0003.exr")
    cube = np.abs(unlit[..., :3] - unlit[0, 0, :3]).max(axis=-1) > 0.01
    assert cube.sum() > 20
    assert np.abs(frames[2][..., :3] - unlit[..., :3])[cube].mean() > 0.1
    assert np.abs(frames[0] - frames[2]).max() > 0.2


def test_animation_soak_memory(addon, extension_zip, tmp_path):
    """30 frames of the lit animation at the default Bake Texel Size, a bake in each:
    resident memory at the last frame is within 10 % of that at the fifth.

    One frame's figure moves by up to ~50 MiB between runs (the allocators keep and give
    back blocks as they like), so each end is the median of five frames (3-7 and 26-30),
    after glibc's malloc_trim; the raw figures are printed too."""
    out, report = _animate(extension_zip, tmp_path, "--frames", "30", "--texel", "0.05")
    assert report["baked_in_animation"] == 30
    assert all((out / f"frame_{k:04d}.exr").is_file() for k in range(1, 31))
    raw, trimmed = (
        {int(k): v / 2**20 for k, v in report[key].items()} for key in ("rss", "trimmed_rss")
    )
    assert sorted(trimmed) == list(range(1, 31))
    fifth = float(np.median([trimmed[k] for k in range(3, 8)]))
    last = float(np.median([trimmed[k] for k in range(26, 31)]))
    print(
        f"soak RSS (MiB): frame 5 {raw[5]:.1f}, frame 30 {raw[30]:.1f}; trimmed, median of "
        f"5 frames: around 5 {fifth:.1f}, last 5 {last:.1f} ({last / fifth - 1:+.1%}); "
        f"bakes kept in the cache {report['cached_bytes'] / 2**20:.1f} MiB"
    )
    assert last <= 1.10 * fifth


STILL_ANIMATION = """
import importlib, json, sys
import bpy

zip_path, out = sys.argv[1], sys.argv[2]
assert bpy.ops.extensions.package_install_files(
    filepath=zip_path, repo="user_default", enable_on_install=True
) == {"FINISHED"}
bake = importlib.import_module("bl_ext.user_default.symray.symray_addon.bake")
bpy.ops.wm.read_homefile(use_factory_startup=True)
scene = bpy.context.scene
scene.render.engine = "SYMRAY"
scene.render.resolution_x, scene.render.resolution_y = 32, 24
scene.symray.model = "FLAT"
scene.symray.quality = "RADIANS"
scene.symray.bake_samples = 4
camera = bpy.data.objects["Camera"]
scene.frame_start, scene.frame_end = 1, 3
for frame, scale in ((1, 1.0), (3, 0.97)):  # the camera comes 3 % closer
    camera.location = tuple(scale * c for c in camera.location)
    camera.keyframe_insert("location", frame=frame)
scene.render.image_settings.file_format = "OPEN_EXR"
scene.render.filepath = out + "/frame_"
scene.frame_set(1)
assert bpy.ops.render.render(animation=True) == {"FINISHED"}
json.dump(bake.stats, open(out + "/stats.json", "w"))
"""


def test_an_animation_of_still_objects_bakes_once(addon, extension_zip, tmp_path):
    """An animation whose objects do not change (the factory scene, lighting Auto, the
    camera coming a little closer) bakes the cube at its first frame and reuses that bake
    at the others."""
    script = tmp_path / "still_animation.py"
    script.write_text(STILL_ANIMATION, encoding="utf-8")
    user = tmp_path / "user"
    user.mkdir()
    proc = subprocess.run(
        [sys.executable, str(script), str(extension_zip), str(tmp_path)],
        env=dict(os.environ, BLENDER_USER_RESOURCES=str(user)),
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, f"exit {proc.returncode}\n{proc.stdout[-3000:]}\n{proc.stderr}"
    assert sorted(path.name for path in tmp_path.glob("frame_*")) == [
        "frame_0001.exr",
        "frame_0002.exr",
        "frame_0003.exr",
    ]
    stats = json.loads((tmp_path / "stats.json").read_text(encoding="utf-8"))
    assert stats == {"baked": 1, "reused": 2}
    assert "Baking map saved" not in proc.stdout + proc.stderr

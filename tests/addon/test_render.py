"""Renders through core.render: the operator, the SYMRAY engine and their outputs.

Small images (64x48 at most) and a coarse tolerance keep this quick.
"""

from __future__ import annotations

import math
import os

import bpy
import numpy as np
import pytest
from mathutils import Vector
from mathutils.bvhtree import BVHTree

OpenEXR = pytest.importorskip("OpenEXR")

WORLD = (0.2, 0.3, 0.5, 1.0)
TAN_HALF_FOV = 18.0 / 50.0  # default camera: 36 mm sensor, 50 mm lens, horizontal fit


def read_exr(path) -> dict[str, np.ndarray]:
    """Channels of an EXR (all parts: Blender 5 writes one per pass) by full name, (h, w)
    arrays with row 0 at the top."""
    with OpenEXR.File(str(path), separate_channels=True) as f:
        return {name: np.array(ch.pixels) for part in f.parts for name, ch in part.channels.items()}


def look_at(obj, target=(0.0, 0.0, 0.0)) -> None:
    """Point an object's -Z at a target, +Y up."""
    direction = Vector(target) - obj.location
    obj.rotation_euler = direction.to_track_quat("-Z", "Y").to_euler()
    bpy.context.view_layer.update()


def flat_scene(scene, helpers):
    """Three coloured objects in front of a plain world colour."""
    helpers.set_world_color(scene, WORLD)
    helpers.add_cube(
        scene, "Red", size=4.0, material=helpers.solid_material("R", (0.8, 0.1, 0.1, 1.0))
    )
    helpers.add_quad(
        scene, "Green", half=6.0, y=8.0, material=helpers.solid_material("G", (0.1, 0.7, 0.2, 1.0))
    )
    helpers.add_cube(
        scene,
        "Blue",
        size=2.0,
        location=(5.0, 2.0, 3.0),
        rotation=(0.4, 0.3, 0.2),
        material=helpers.solid_material("B", (0.1, 0.2, 0.9, 1.0)),
    )
    cam = helpers.add_camera(scene, location=(7.0, -22.0, 5.0))
    look_at(cam)
    scene.symray.model = "FLAT"
    return cam


def reference_image(scene, cam, helpers) -> np.ndarray:
    """Straight-ray reference: Blender's camera frame + one BVH cast per pixel."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    w, h = scene.render.resolution_x, scene.render.resolution_y
    rows, cols = np.divmod(np.arange(w * h), w)
    dirs = helpers.frame_directions(scene, cam, rows, cols)
    origin = Vector(cam.matrix_world.translation)
    colors = {
        "Red": (0.8, 0.1, 0.1, 1.0),
        "Green": (0.1, 0.7, 0.2, 1.0),
        "Blue": (0.1, 0.2, 0.9, 1.0),
    }
    trees = []
    for name in colors:
        obj = bpy.data.objects[name].evaluated_get(depsgraph)
        trees.append((name, BVHTree.FromObject(obj, depsgraph), obj.matrix_world.copy()))
    image = np.empty((w * h, 4))
    for i, d in enumerate(dirs):
        best, color = math.inf, WORLD
        for name, tree, m in trees:
            inv = m.inverted()
            lo = inv @ origin
            ld = inv.to_3x3() @ Vector(d)
            loc, _n, _i, _dist = tree.ray_cast(lo, ld)
            if loc is not None:
                dist = ((m @ loc) - origin).length
                if dist < best:
                    best, color = dist, colors[name]
        image[i] = color
    return image.reshape(h, w, 4)


def test_flat_render_matches_straight_ray_reference(scene, helpers):
    cam = flat_scene(scene, helpers)
    assert bpy.ops.symray.render() == {"FINISHED"}
    got = helpers.image_array(scene.symray.image_name)
    want = reference_image(scene, cam, helpers)
    assert got.shape == want.shape == (48, 64, 4)
    close = np.all(np.abs(got - want) <= 1.0 / 255.0, axis=2)
    assert close.mean() >= 0.999, f"{(~close).sum()} pixels differ"
    for color in ((0.8, 0.1, 0.1), (0.1, 0.7, 0.2), (0.1, 0.2, 0.9), WORLD[:3]):
        assert np.any(np.all(np.abs(want[..., :3] - color) < 1e-6, axis=2))


def _hole_scene(scene, helpers, model="SCHWARZSCHILD"):
    helpers.add_camera(scene)  # at (0, -30, 0) looking along +Y
    scene.symray.model = model
    scene.symray.rg = 1.0
    scene.symray.center = helpers.add_empty(scene, "Hole")
    scene.symray.pass_ending = True
    helpers.set_world_color(scene, (0.0, 0.0, 0.0, 1.0))


def _render_with_ending(addon, scene):
    """Render with the operator's code path, returning the core result (with passes)."""
    job = addon.module("symray_addon.render_job")
    prepared = job.prepare(scene, bpy.context.evaluated_depsgraph_get())
    return job.run(prepared)


def ring_angle(rg: float, observer: float, source: float) -> float:
    """Exact Schwarzschild Einstein-ring angle (static observer) of a source on the axis.

    Integrates the photon orbit u'' = 1.5 rg u^2 - u (u = 1/r) from the observer over
    phi in [0, pi] and bisects the viewing angle until the ray reaches the axis at r = source.
    """

    def r_at_pi(theta: float) -> float:
        u0 = 1.0 / observer
        b = observer * math.sin(theta) / math.sqrt(1.0 - rg / observer)
        y = np.array([u0, math.sqrt(1.0 / b**2 - u0**2 * (1.0 - rg * u0))])
        n = 4000
        h = math.pi / n

        def f(y):
            return np.array([y[1], 1.5 * rg * y[0] ** 2 - y[0]])

        for _ in range(n):
            k1 = f(y)
            k2 = f(y + 0.5 * h * k1)
            k3 = f(y + 0.5 * h * k2)
            k4 = f(y + h * k3)
            y = y + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
            if y[0] > 1.0 / rg:
                return 0.0  # captured
            if y[0] <= 0.0:
                return math.inf  # escaped before reaching the far axis
        return 1.0 / y[0]

    lo, hi = 0.086, 0.5  # the shadow's edge (0.0852 rad at D = 30) .. far outside
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        if r_at_pi(mid) < source:  # bent too much: look further out
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def _radius(h: int, w: int) -> np.ndarray:
    rows, cols = np.mgrid[0:h, 0:w]
    return np.hypot(rows + 0.5 - h / 2, cols + 0.5 - w / 2)


def test_schwarzschild_shadow_and_einstein_ring(addon, scene, helpers):
    _hole_scene(scene, helpers)
    red = helpers.solid_material("Source", (1.0, 0.0, 0.0, 1.0))
    helpers.add_quad(scene, "Source", half=1.0, y=12.0, material=red)
    result = _render_with_ending(addon, scene)
    ending = result.passes["ending"]
    codes = addon.core.ENDING
    h, w = ending.shape
    px = (w / 2) / TAN_HALF_FOV  # pixels per unit of tan(angle)
    radius = _radius(h, w)
    # shadow: sin(alpha) = (3 sqrt(3) / 2) rg sqrt(1 - rg / D) / D for a static observer
    d = 30.0
    alpha = math.asin(1.5 * math.sqrt(3.0) * math.sqrt(1.0 - 1.0 / d) / d)
    r_shadow = math.tan(alpha) * px
    captured = ending == codes["captured"]
    assert captured.sum() == pytest.approx(math.pi * r_shadow**2, rel=0.12)
    assert captured[radius < 0.8 * r_shadow].all()
    assert not captured[radius > 1.2 * r_shadow].any()
    # Einstein ring of the source behind the hole, from the exact photon orbit
    theta_e = ring_angle(1.0, 30.0, 12.0)
    ring = (ending == codes["hit"]) & (result.rgba[..., 0] > 0.5)
    r_ring = np.median(radius[ring])
    assert r_ring == pytest.approx(math.tan(theta_e) * px, rel=0.08)
    assert not ring[radius < r_shadow].any()
    rows, cols = np.nonzero(ring)
    quadrants = {(r < h / 2, c < w / 2) for r, c in zip(rows, cols, strict=True)}
    assert len(quadrants) == 4


def test_schwarzschild_lenses_the_board(addon, scene, helpers):
    _hole_scene(scene, helpers)
    board = helpers.solid_material("Board", (0.9, 0.9, 0.9, 1.0))
    helpers.add_quad(scene, "Board", half=8.0, y=12.0, material=board)
    curved = _render_with_ending(addon, scene).passes["ending"]
    scene.symray.model = "FLAT"
    flat = _render_with_ending(addon, scene).passes["ending"]
    hit = addon.core.ENDING["hit"]
    h, w = flat.shape
    mid = h // 2

    def half_width(ending):
        cols = np.flatnonzero(ending[mid] == hit)
        return (cols.max() - cols.min() + 1) / 2

    flat_half = half_width(flat)
    px = (w / 2) / TAN_HALF_FOV
    assert flat_half == pytest.approx(8.0 / 42.0 * px, abs=1.0)
    # lens equation: the board's edge (beta = 8/42) appears at theta = (b + sqrt(b^2 + 4 tE^2))/2
    beta, theta_e2 = math.atan(8.0 / 42.0), 2.0 * 12.0 / (30.0 * 42.0)
    theta = 0.5 * (beta + math.sqrt(beta**2 + 4 * theta_e2))
    assert half_width(curved) == pytest.approx(math.tan(theta) * px, rel=0.1)
    assert flat[mid, w // 2] == hit
    assert curved[mid, w // 2] == addon.core.ENDING["captured"]


def test_worker_processes_render_blender_meshes_as_threads_do(addon, scene, helpers):
    """Forked workers inherit the scene as built in Blender (the mesh's BVH tree from
    mathutils, the model, the world): the same image as threads, pixel for pixel."""
    if not addon.core.workers.can_fork():
        pytest.skip("worker processes need fork")
    _hole_scene(scene, helpers)
    board = helpers.solid_material("Board", (0.9, 0.2, 0.1, 1.0))
    helpers.add_quad(scene, "Board", half=8.0, y=12.0, material=board)
    scene.symray.workers = 2
    results = {}
    for parallel in ("PROCESSES", "THREADS"):
        scene.symray.parallel = parallel
        results[parallel] = _render_with_ending(addon, scene)
        assert results[parallel].summary["parallel"] == f"2 {parallel.lower()}"
    ending = results["PROCESSES"].passes["ending"]
    assert (ending == addon.core.ENDING["hit"]).sum() > 100  # the board is in the picture
    np.testing.assert_array_equal(ending, results["THREADS"].passes["ending"])
    np.testing.assert_array_equal(results["PROCESSES"].rgba, results["THREADS"].rgba)


def test_worker_processes_forked_from_the_operators_thread(addon, scene, helpers):
    """The modal operator traces in a Python thread of Blender's process: workers forked
    from there finish, report progress to that thread and give the threads' image."""
    if not addon.core.workers.can_fork():
        pytest.skip("worker processes need fork")
    _hole_scene(scene, helpers)
    operator = addon.module("symray_addon.operator")
    job = addon.module("symray_addon.render_job")
    images = {}
    for parallel in ("PROCESSES", "THREADS"):
        scene.symray.parallel = parallel
        task = operator.RenderTask(job.prepare(scene, bpy.context.evaluated_depsgraph_get()))
        task.start()
        task.join(120)
        result = task.collect()
        assert task.fraction == 1.0 and result.summary["parallel"].endswith(parallel.lower())
        images[parallel] = result.rgba
    np.testing.assert_array_equal(images["PROCESSES"], images["THREADS"])


def test_blenders_thread_count_bounds_the_worker_processes(addon, scene, helpers):
    """`blender -b -t N` (or Performance › Threads: Fixed) caps the automatic worker
    count, as it caps Cycles: a farm sharing a node between jobs keeps its promise."""
    if not addon.core.workers.can_fork():
        pytest.skip("worker processes need fork")
    _hole_scene(scene, helpers)
    scene.render.resolution_x, scene.render.resolution_y = 128, 64  # 4 chunks of 2048
    scene.render.threads_mode = "FIXED"
    runs = {}
    for threads, workers in ((1, 0), (3, 0), (1, 2)):
        scene.render.threads, scene.symray.workers = threads, workers
        result = _render_with_ending(addon, scene)
        runs[(threads, workers)] = result
    assert runs[(1, 0)].summary["parallel"] == "inline"
    assert runs[(3, 0)].summary["parallel"] == "3 processes"
    assert runs[(1, 2)].summary["parallel"] == "2 processes"  # Workers set: taken as given
    for result in runs.values():
        np.testing.assert_array_equal(result.rgba, runs[(1, 0)].rgba)


def test_kerr_renders(addon, scene, helpers):
    _hole_scene(scene, helpers, model="KERR")
    scene.symray.spin = 0.9
    scene.render.resolution_x, scene.render.resolution_y = 32, 24
    result = _render_with_ending(addon, scene)
    codes = addon.core.ENDING
    assert (result.passes["ending"] == codes["captured"]).any()
    assert (result.passes["ending"] == codes["escaped"]).any()


def _engine_exr(scene, tmp_path, name="frame") -> str:
    scene.render.engine = "SYMRAY"
    settings = scene.render.image_settings
    if "media_type" in settings.bl_rna.properties:
        settings.media_type = "MULTI_LAYER_IMAGE"
    settings.file_format = "OPEN_EXR_MULTILAYER"
    settings.color_depth = "32"
    scene.render.filepath = str(tmp_path / name)
    scene.render.use_file_extension = True
    return str(tmp_path / f"{name}.exr")


@pytest.mark.parametrize("parallel", ["AUTO", "PROCESSES"])
def test_f12_writes_exr_with_error_pass(addon, scene, helpers, tmp_path, parallel):
    if parallel == "PROCESSES" and not addon.core.workers.can_fork():
        pytest.skip("worker processes need fork")
    _hole_scene(scene, helpers)
    scene.symray.parallel = parallel  # PROCESSES: forked from Blender's render thread
    scene.symray.center.location = (1.5, 0.0, 2.0)  # off-centre: a flipped pass would show
    bpy.context.view_layer.update()
    scene.render.resolution_x, scene.render.resolution_y = 32, 24
    scene.symray.pass_error = True
    scene.symray.pass_steps = True
    path = _engine_exr(scene, tmp_path)
    bpy.ops.render.render(write_still=True)
    channels = read_exr(path)
    error = next(v for k, v in channels.items() if k.endswith("SymRay Error.X"))
    steps = next(v for k, v in channels.items() if k.endswith("SymRay Steps.X"))
    assert error.shape == steps.shape == (24, 32)
    # The documented meaning: the core's estimate of each ray's final-direction error in
    # pixels (error_px; 0 for captured rays). EXR rows, like the core's, run top-down.
    # rtol 1e-4: F12 reads the render depsgraph and the reference the viewport's; their
    # float32 camera matrices differ in the last bits (measured agreement ~1e-6 relative).
    reference = _render_with_ending(addon, scene)
    np.testing.assert_allclose(error, reference.passes["error_px"], rtol=1e-4, atol=1e-9)
    np.testing.assert_array_equal(steps, reference.passes["steps"].astype(np.float32))
    captured = reference.passes["ending"] == 1
    assert captured.sum() > 20 and np.all(error[captured] == 0.0)
    assert not np.array_equal(captured, captured[::-1])  # the check sees orientation
    escaped_error = error[reference.passes["ending"] == 0]
    tolerance_px = float(scene.symray.tolerance) / reference.summary["pixel_angle"]
    assert 0 < np.median(escaped_error) < tolerance_px
    assert any(k.endswith("Combined.R") for k in channels)
    summary = addon.module("symray_addon.render_job").last_summary
    assert summary["rays"] == 32 * 24


def test_engine_border_percentage_and_crop(addon, scene, helpers, tmp_path):
    flat_scene(scene, helpers)
    full_path = _engine_exr(scene, tmp_path, "full")
    bpy.ops.render.render(write_still=True)
    full = np.stack(
        [v for k, v in sorted(read_exr(full_path).items()) if ".Combined." in k], axis=-1
    )  # A, B, G, R
    assert full.shape == (48, 64, 4)
    render = scene.render
    render.use_border = True
    render.border_min_x, render.border_max_x = 0.25, 0.75
    render.border_min_y, render.border_max_y = 0.5, 1.0
    render.use_crop_to_border = True
    crop_path = _engine_exr(scene, tmp_path, "crop")
    bpy.ops.render.render(write_still=True)
    crop = np.stack(
        [v for k, v in sorted(read_exr(crop_path).items()) if ".Combined." in k], axis=-1
    )
    assert crop.shape == (24, 32, 4)
    np.testing.assert_allclose(crop, full[0:24, 16:48], atol=1e-6)
    render.use_border = False
    render.resolution_percentage = 50
    half_path = _engine_exr(scene, tmp_path, "half")
    bpy.ops.render.render(write_still=True)
    assert next(iter(read_exr(half_path).values())).shape == (24, 32)


def test_engine_animation_and_blend_file(addon, scene, helpers, tmp_path):
    """What `blender -b file.blend -E SYMRAY -a` does: open a .blend, render every frame."""
    cam = flat_scene(scene, helpers)
    cam.animation_data_create()
    cam.keyframe_insert("location", frame=1)
    cam.location.x += 2.0
    cam.keyframe_insert("location", frame=2)
    scene.frame_start, scene.frame_end = 1, 2
    scene.render.engine = "BLENDER_WORKBENCH"  # -E SYMRAY overrides what the file says
    blend = str(tmp_path / "scene.blend")
    bpy.ops.wm.save_as_mainfile(filepath=blend)
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.wm.open_mainfile(filepath=blend)
    scene = bpy.context.scene
    _engine_exr(scene, tmp_path, "anim_####")
    bpy.ops.render.render(animation=True)
    frames = [read_exr(tmp_path / f"anim_{i:04d}.exr") for i in (1, 2)]
    reds = [next(v for k, v in f.items() if k.endswith("Combined.R")) for f in frames]
    assert not np.allclose(reds[0], reds[1])  # the camera moved


def test_operator_writes_exr(addon, scene, helpers, tmp_path):
    _hole_scene(scene, helpers)
    scene.render.resolution_x, scene.render.resolution_y = 32, 24
    scene.symray.pass_steps = True
    scene.symray.exr_path = str(tmp_path / "result.exr")
    assert bpy.ops.symray.render() == {"FINISHED"}
    image = helpers.image_array(scene.symray.image_name)
    rgba = read_exr(tmp_path / "result.exr")
    stacked = np.stack([rgba["R"], rgba["G"], rgba["B"], rgba["A"]], axis=-1)
    np.testing.assert_array_equal(stacked, image)  # 32-bit float, same orientation
    passes = read_exr(tmp_path / "result.passes.exr")
    assert passes["SymRay Steps.X"].max() > 0
    codes = {float(c) for c in addon.core.ENDING.values()}
    assert set(passes["SymRay Ending.X"].ravel()) <= codes
    assert sorted(os.listdir(tmp_path)) == ["result.exr", "result.passes.exr"]  # no temporaries
    umask = os.umask(0)
    os.umask(umask)
    assert (tmp_path / "result.exr").stat().st_mode & 0o777 == 0o666 & ~umask
    # Blender reads the files back as they were written
    loaded = bpy.data.images.load(str(tmp_path / "result.exr"))
    pixels = np.empty(32 * 24 * 4, dtype=np.float32)
    loaded.pixels.foreach_get(pixels)
    np.testing.assert_array_equal(pixels.reshape(24, 32, 4)[::-1], image)
    bpy.data.images.remove(loaded)


@pytest.mark.parametrize("transparent", [False, True])
def test_passes_exr_holds_the_passes_switched_on_by_name(
    addon, scene, helpers, tmp_path, transparent
):
    """Each pass switched on is a layer named as the engine's pass, and a pass switched off
    has none (never zeros a reader would take for values; Film › Transparent computes the
    ending pass for itself: still not written when it is off)."""
    _hole_scene(scene, helpers)
    scene.render.resolution_x, scene.render.resolution_y = 16, 12
    scene.render.film_transparent = transparent
    settings = scene.symray
    settings.pass_error, settings.pass_steps = True, True
    settings.pass_ending, settings.pass_redshift = False, False
    settings.exr_path = str(tmp_path / "r.exr")
    assert bpy.ops.symray.render() == {"FINISHED"}
    reference = _render_with_ending(addon, scene)
    passes = read_exr(tmp_path / "r.passes.exr")
    assert set(passes) == {"SymRay Error.X", "SymRay Steps.X"}
    np.testing.assert_array_equal(passes["SymRay Steps.X"], reference.passes["steps"])
    np.testing.assert_array_equal(passes["SymRay Error.X"], reference.passes["error_px"])
    settings.pass_error, settings.pass_steps = False, False
    settings.pass_ending, settings.pass_redshift = True, True
    assert bpy.ops.symray.render() == {"FINISHED"}
    reference = _render_with_ending(addon, scene)
    passes = read_exr(tmp_path / "r.passes.exr")
    assert set(passes) == {"SymRay Ending.X", "SymRay Redshift.X"}
    assert np.isnan(passes["SymRay Redshift.X"]).all()  # no disk: NaN everywhere
    np.testing.assert_array_equal(passes["SymRay Ending.X"], reference.passes["ending"])


def test_render_task_cancel_keeps_previous_image(addon, scene, helpers):
    """The modal operator's worker: cancelling yields nothing to write."""
    flat_scene(scene, helpers)
    assert bpy.ops.symray.render() == {"FINISHED"}
    before = helpers.image_array(scene.symray.image_name).copy()
    operator = addon.module("symray_addon.operator")
    job = addon.module("symray_addon.render_job").prepare(
        scene, bpy.context.evaluated_depsgraph_get()
    )
    task = operator.RenderTask(job)
    task.cancel()
    task.start()
    task.join(60)
    assert task.finished and task.collect() is None
    np.testing.assert_array_equal(helpers.image_array(scene.symray.image_name), before)
    task = operator.RenderTask(job)
    task.start()
    task.join(60)
    result = task.collect()
    assert result is not None and result.rgba.shape == (48, 64, 4)
    assert task.fraction == 1.0


def test_core_render_honours_should_cancel(addon, scene, helpers):
    """should_cancel (Esc, test_break) stops a render: the result says cancelled."""
    _hole_scene(scene, helpers)
    job = addon.module("symray_addon.render_job")
    prepared = job.prepare(scene, bpy.context.evaluated_depsgraph_get())
    result = job.run(prepared, should_cancel=lambda: True)
    assert result.cancelled


@pytest.mark.parametrize("model", ["METRIC", "CUSTOM", "MEDIUM"])
def test_flat_equivalent_models_match_flat(addon, scene, helpers, model):
    """Minkowski metric, free-particle H and n = 1 bend nothing: same image as FLAT."""
    flat_scene(scene, helpers)
    scene.render.resolution_x, scene.render.resolution_y = 16, 12
    assert bpy.ops.symray.render() == {"FINISHED"}
    flat = helpers.image_array(scene.symray.image_name).copy()
    s = scene.symray
    s.model = model
    s.metric = "-1, 0, 0, 0; 0, 1, 0, 0; 0, 0, 1, 0; 0, 0, 0, 1"
    s.hamiltonian = "0.5*(p_x**2 + p_y**2 + p_z**2)"
    s.refractive_index = "1 + 0*x"
    s.medium_min, s.medium_max = (-3, -3, -3), (3, 3, 3)
    assert bpy.ops.symray.render() == {"FINISHED"}
    curved = helpers.image_array(scene.symray.image_name)
    close = np.all(np.abs(curved - flat) <= 1.0 / 255.0, axis=2)
    assert close.mean() >= 0.97, f"{(~close).sum()} of {close.size} pixels differ"


def test_image_resized_and_reused(addon, scene, helpers):
    output = addon.module("symray_addon.output")
    first = output.write_image("SymRay Result", np.full((4, 6, 4), 0.25, np.float32))
    assert tuple(first.size) == (6, 4) and first.is_float
    rgba = np.random.default_rng(1).random((5, 3, 4)).astype(np.float32)
    second = output.write_image("SymRay Result", rgba)
    assert second == first and tuple(second.size) == (3, 5)
    np.testing.assert_array_equal(helpers.image_array("SymRay Result"), rgba)


def test_film_transparent_clears_the_background(scene, helpers):
    flat_scene(scene, helpers)
    scene.render.film_transparent = True
    assert bpy.ops.symray.render() == {"FINISHED"}
    image = helpers.image_array(scene.symray.image_name)
    sky = np.all(np.abs(image[..., :3] - WORLD[:3]) < 1e-6, axis=2)
    assert not sky.any()
    assert (image[..., 3] == 0).any() and (image[..., 3] == 1).any()


class _FakeWM:
    def __init__(self):
        self.progress: list[int] = []
        self.ended = False

    def progress_update(self, value: int) -> None:
        self.progress.append(value)

    def event_timer_remove(self, _timer) -> None:
        pass

    def progress_end(self) -> None:
        self.ended = True


def _drive_modal(addon, scene, cancel: bool):
    """Run the modal operator's event handling by hand (the bpy wheel has no event loop)."""
    from types import SimpleNamespace

    operator = addon.module("symray_addon.operator")
    job = addon.module("symray_addon.render_job").prepare(
        scene, bpy.context.evaluated_depsgraph_get()
    )
    reports: list = []
    status: list = []
    wm = _FakeWM()
    context = SimpleNamespace(
        window_manager=wm, scene=scene, workspace=SimpleNamespace(status_text_set=status.append)
    )
    cls = operator.SYMRAY_OT_render
    fake = SimpleNamespace(
        _task=operator.RenderTask(job),
        _timer=object(),
        _image_name=scene.symray.image_name,
        _exr_path="",
        _passes=(),
        report=lambda kind, text: reports.append((kind, text)),
    )
    fake._status = lambda ctx, text: cls._status(ctx, text)
    fake._cleanup = lambda ctx: cls._cleanup(fake, ctx)
    if cancel:
        esc = SimpleNamespace(type="ESC", value="PRESS")
        assert cls.modal(fake, context, esc) == {"RUNNING_MODAL"}
    fake._task.start()
    timer = SimpleNamespace(type="TIMER", value="NOTHING")
    mouse = SimpleNamespace(type="MOUSEMOVE", value="NOTHING")
    assert cls.modal(fake, context, mouse) == {"PASS_THROUGH"}
    fake._task.join(120)
    outcome = cls.modal(fake, context, timer)
    return outcome, reports, wm, status


def test_modal_operator_finishes_and_cancels(addon, scene, helpers):
    flat_scene(scene, helpers)
    assert bpy.ops.symray.render() == {"FINISHED"}
    before = helpers.image_array(scene.symray.image_name).copy()
    outcome, reports, wm, status = _drive_modal(addon, scene, cancel=True)
    assert outcome == {"CANCELLED"} and wm.ended and status[-1] is None
    assert reports and reports[-1][0] == {"WARNING"}
    np.testing.assert_array_equal(helpers.image_array(scene.symray.image_name), before)
    scene.render.resolution_x = 32
    outcome, reports, wm, status = _drive_modal(addon, scene, cancel=False)
    assert outcome == {"FINISHED"} and reports[-1][0] == {"INFO"}
    assert helpers.image_array(scene.symray.image_name).shape == (48, 32, 4)


def _prepared(addon, scene):
    return addon.module("symray_addon.render_job").prepare(
        scene, bpy.context.evaluated_depsgraph_get()
    )


@pytest.mark.parametrize("size, used", [(0.0, 0.01), (500.0, 2.0), (1.5, 1.5), (0.01, 0.01)])
def test_film_filter_size_outside_the_supported_range_is_clamped_visibly(
    addon, scene, helpers, size, used
):
    """Filter Size outside 0.01–2 px is clamped with a warning naming both values."""
    flat_scene(scene, helpers)
    scene.render.filter_size = size
    job = _prepared(addon, scene)
    assert job.options["filter_size"] == pytest.approx(used)
    notes = [w for w in job.warnings if "Filter Size" in w]
    if size == used:
        assert notes == []
    else:
        assert notes == [
            f"Film › Filter Size {size:g} px is outside the 0.01–2 px SymRay supports: "
            f"{used:g} px used"
        ]


IGNORED = {
    "dof": "Depth of Field (camera 'Camera')",
    "motion_blur": "Motion Blur",
    "use_pass_z": "The Z pass",
    "use_pass_normal": "The Normal pass",
    "use_pass_cryptomatte_object": "The Cryptomatte Object pass",
    "use_pass_cryptomatte_material": "The Cryptomatte Material pass",
    "use_pass_cryptomatte_asset": "The Cryptomatte Asset pass",
}


def _switch_on(scene, what: str) -> None:
    if what == "dof":
        scene.camera.data.dof.use_dof = True
    elif what == "motion_blur":
        scene.render.use_motion_blur = True
    else:
        setattr(bpy.context.view_layer, what, True)


def test_unsupported_settings_are_named_once_per_render(addon, factory_scene):
    """Depth of field, motion blur and the Z, Normal and Cryptomatte passes, which SymRay
    does not render: each one switched on is a warning of its own, once per render, for
    the operator and for F12."""
    factory_scene.symray.lighting = "UNLIT"
    assert [w for w in _prepared(addon, factory_scene).warnings if "not supported" in w] == []
    for what, name in IGNORED.items():  # one more each time
        _switch_on(factory_scene, what)
        warnings = [w for w in _prepared(addon, factory_scene).warnings if "not supported" in w]
        assert sum(w.startswith(name) for w in warnings) == 1, warnings
    warnings = _prepared(addon, factory_scene).warnings
    ignored = [w for w in warnings if "not supported by SymRay yet" in w]
    assert len(ignored) == len(IGNORED)  # all on: one each, nothing twice
    for name in IGNORED.values():
        assert sum(w.startswith(name) for w in ignored) == 1, ignored


def test_the_engine_reports_the_unsupported_settings(addon, factory_scene, capfd):
    """F12 reports each of them as a warning (Blender prints reports in background mode),
    once per frame."""
    factory_scene.symray.lighting = "UNLIT"
    factory_scene.symray.quality = "PREVIEW"
    for what in IGNORED:
        _switch_on(factory_scene, what)
    capfd.readouterr()
    assert bpy.ops.render.render() == {"FINISHED"}
    printed = capfd.readouterr().out.splitlines()
    for name in IGNORED.values():
        assert sum(line.startswith(f"Warning: {name}") for line in printed) == 1, printed


WARNED_JOBS_SCRIPT = """
import sys
import bpy

bpy.ops.preferences.addon_enable(module=sys.argv[1])
bpy.ops.wm.open_mainfile(filepath=sys.argv[2])
assert bpy.ops.render.render(animation=True) == {"FINISHED"}
print("SYMRAY-MARK stills")
for _ in range(2):
    assert bpy.ops.render.render(write_still=False) == {"FINISHED"}
"""


def test_a_warning_is_given_once_per_render_job(addon, factory_scene, tmp_path):
    """A material node the unbaked reader ignores is named once in a 3-frame animation (not
    once a frame), and again in each later still: once per render job."""
    import os
    import subprocess
    import sys

    scene = factory_scene
    scene.symray.lighting = "UNLIT"
    tree = bpy.data.objects["Cube"].active_material.node_tree
    checker = tree.nodes.new("ShaderNodeTexChecker")
    principled = next(n for n in tree.nodes if n.type == "BSDF_PRINCIPLED")
    tree.links.new(checker.outputs["Color"], principled.inputs["Base Color"])
    scene.render.resolution_x, scene.render.resolution_y = 16, 12
    scene.frame_start, scene.frame_end = 1, 3
    scene.render.filepath = str(tmp_path / "frame_####")
    blend = tmp_path / "warned.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend), copy=True)
    run = subprocess.run(
        [sys.executable, "-c", WARNED_JOBS_SCRIPT, addon.package, str(blend)],
        capture_output=True, text=True, timeout=300, env=dict(os.environ),
    )  # fmt: skip
    assert run.returncode == 0, run.stderr[-2000:]
    text = run.stdout + run.stderr
    animation, stills = text.split("SYMRAY-MARK stills")
    assert sorted(tmp_path.glob("frame_*.png")) and len(list(tmp_path.glob("frame_*"))) == 3

    def warned(part: str) -> int:
        return sum("Checker" in line and "arning" in line for line in part.splitlines())

    assert (warned(animation), warned(stills)) == (1, 2), text[-3000:]

"""The Rendered viewport (symray_addon/viewport.py) without a window: its drawing path into
a GPUOffScreen (bpy 5.x: ``gpu.init()`` gives an offscreen EGL context; bpy 4.2 has no GPU
in background mode: skipped there), and the view session from Blender's factory scene."""

from __future__ import annotations

from contextlib import contextmanager
from types import SimpleNamespace

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
gpu = pytest.importorskip("gpu")


def _offscreen_gpu() -> bool:
    try:
        getattr(gpu, "init", lambda: None)()
        gpu.types.GPUOffScreen(4, 4).free()
        return True
    except (SystemError, RuntimeError, AttributeError):
        return False


needs_gpu = pytest.mark.skipif(
    not _offscreen_gpu(), reason="no offscreen GPU in this Blender's background mode"
)


def _draw_into(offscreen, draw) -> np.ndarray:
    """Run ``draw()`` in ``offscreen`` with a pixel projection; -> its pixels (h, w, 4),
    row 0 at the bottom."""
    from mathutils import Matrix

    w, h = offscreen.width, offscreen.height
    with offscreen.bind():
        fb = gpu.state.active_framebuffer_get()
        fb.clear(color=(0.0, 0.0, 0.0, 0.0))
        with gpu.matrix.push_pop(), gpu.matrix.push_pop_projection():
            gpu.matrix.load_matrix(Matrix.Identity(4))
            gpu.matrix.load_projection_matrix(
                Matrix(((2 / w, 0, 0, -1), (0, 2 / h, 0, -1), (0, 0, 1, 0), (0, 0, 0, 1)))
            )
            draw()
        pixels = fb.read_color(0, 0, w, h, 4, 0, "FLOAT")
    return np.array(pixels.to_list(), dtype=np.float32).reshape(h, w, 4)


@needs_gpu
def test_an_image_is_drawn_as_it_is(addon):
    """A known float image (row 0 at the top, premultiplied) uploaded and drawn over the
    region comes back pixel for pixel (float16 texture: 1e-3), flipped to GPU rows."""
    viewport = addon.module("symray_addon.viewport")
    rng = np.random.default_rng(3)
    image = rng.random((9, 16, 4)).astype(np.float32)
    image[..., 3] = 1.0
    offscreen = gpu.types.GPUOffScreen(16, 9, format="RGBA32F")
    try:
        texture = viewport.texture_of(image)
        got = _draw_into(offscreen, lambda: viewport.draw_image(texture, 16, 9))
    finally:
        offscreen.free()
    np.testing.assert_allclose(got[::-1], image, atol=1e-3)


def _view_context(scene, width: int, height: int):
    """A context whose 3D view looks through the scene camera (its view and projection
    matrices, as a RegionView3D in camera view), width x height pixels."""
    core = pytest.importorskip("bl_ext.user_default.symray.core")
    cam = scene.camera
    matrix = np.array(cam.matrix_world)
    camera = core.Camera.blender(
        lens=cam.data.lens, sensor_width=cam.data.sensor_width, resolution_x=width,
        resolution_y=height, matrix_world=matrix,
    )  # fmt: skip
    xmin, xmax, ymin, ymax = camera.window
    near, far = 0.1, 1000.0
    proj = np.zeros((4, 4))
    proj[0, 0], proj[0, 2] = 2 / (xmax - xmin), (xmax + xmin) / (xmax - xmin)
    proj[1, 1], proj[1, 2] = 2 / (ymax - ymin), (ymax + ymin) / (ymax - ymin)
    proj[2, 2], proj[2, 3] = -(far + near) / (far - near), -2 * far * near / (far - near)
    proj[3, 2] = -1.0
    region = SimpleNamespace(width=width, height=height)
    view = SimpleNamespace(view_matrix=np.linalg.inv(matrix), window_matrix=proj)
    return SimpleNamespace(region=region, region_data=view), camera


class _Engine:
    """What the viewport asks of a RenderEngine (headless: no window to redraw)."""

    def __init__(self):
        self.stats, self.redraws = [], 0

    def update_stats(self, _stats, info):
        self.stats.append(info)

    def tag_redraw(self):
        self.redraws += 1

    def bind_display_space_shader(self, _scene):
        pass

    def unbind_display_space_shader(self):
        pass


def _hole_in_view(scene):
    """SymRay the engine, *Add › Black Hole* moved to (0, 8, 0) behind the cube; -> the
    96 x 54 view context through the scene camera and its core camera."""
    scene.render.engine = "SYMRAY"
    bpy.ops.symray.add_black_hole()
    bpy.context.active_object.location = (0.0, 8.0, 0.0)
    bpy.context.view_layer.update()
    return _view_context(scene, 96, 54)


def _fresh_render(render_job, core, scene, camera):
    """The scene read again and rendered through ``camera`` at its own quality, as F12
    renders it (the reference a re-shade must give)."""
    job = render_job.prepare(scene, bpy.context.evaluated_depsgraph_get(), view_camera=camera)
    options = job.options
    out = core.render(job.scene, camera, tolerance_px=options["tolerance_px"],
                      samples=options["samples"])  # fmt: skip
    return out.rgba.reshape(camera.height, camera.width, 4)


@contextmanager
def _viewing(addon, scene):
    """The view of ``_hole_in_view`` started by view_update on a stand-in engine: yields
    (viewport module, render_job module, core, context, camera, engine, session); the
    engine's session is freed after."""
    viewport = addon.module("symray_addon.viewport")
    render_job = addon.module("symray_addon.render_job")
    context, camera = _hole_in_view(scene)
    engine = _Engine()
    try:
        viewport.update(engine, context, bpy.context.evaluated_depsgraph_get())
        session = viewport._session(engine)
        yield viewport, render_job, addon.core, context, camera, engine, session
    finally:
        viewport.free(engine)


def test_the_view_renders_as_f12_and_a_look_change_only_reshades(addon, factory_scene):
    """From the factory scene with Add Black Hole (its disk) at 96 x 54: view_update starts
    the view (cached bakes only: the cube unlit, with F12's hint); its last level is the
    image core.render gives the same scene and view camera; a change of the disk's look
    starts no new render and shows the re-shaded image, the disk recoloured."""
    scene = factory_scene
    with _viewing(addon, scene) as (viewport, render_job, core, context, camera, engine,
                                    session):  # fmt: skip
        assert session.error == "" and session.view is not None
        assert any("unlit" in line for line in engine.stats)  # the cube: no bake cached
        assert session.view.join(300) and session.view.error is None
        final = session.view.latest
        assert final.final
        ref = _fresh_render(render_job, core, scene, camera)
        # rtol 1e-4: the automatic exposure's probe runs in another order of chunks (2e-5)
        np.testing.assert_allclose(final.rgba, ref, rtol=1e-4, atol=1e-6)
        before = final.rgba.copy()
        view = session.view
        objects = addon.module("symray_addon.objects")
        objects.effective(scene.symray).disk.look = "EHT"
        viewport.update(engine, context, bpy.context.evaluated_depsgraph_get())
        assert session.view is view  # nothing new traced
        disk = np.isfinite(final.passes["redshift"])
        assert disk.any()
        changed = np.abs(session.shown - before).max(axis=-1) > 1e-3
        assert changed[disk].mean() > 0.9 and not changed[~disk].any()
        # against a fresh render of the new look (as F12 would give it): interpolated disk
        # pixels take r from their hit point (core.viewport.reshade), so a few may differ
        fresh = _fresh_render(render_job, core, scene, camera)
        off = np.abs(session.shown - fresh).max(axis=-1) > 0.1
        assert off.mean() <= 0.002


def _update_in_handler(viewport, engine, context, change) -> None:
    """Make ``change()`` and call view_update with the depsgraph Blender reports it in (its
    ``updates`` are filled only inside a depsgraph handler)."""
    handlers = bpy.app.handlers.depsgraph_update_post

    def handler(_scene, depsgraph):
        handlers.remove(handler)
        viewport.update(engine, context, depsgraph)

    handlers.append(handler)
    change()
    bpy.context.view_layer.update()
    assert handler not in handlers  # it ran


def test_a_material_change_only_reshades_and_a_move_renders_again(addon, factory_scene):
    """From the factory scene with Add Black Hole at 96 x 54, its view rendered: a change
    of the cube's material colour (Blender reports the material, its node tree, the cube's
    object and mesh, none moved) starts no new render and shows the cube's pixels
    recoloured, the same image as a fresh render of the new colour; moving the cube
    renders the view again."""
    scene = factory_scene
    with _viewing(addon, scene) as (viewport, render_job, core, context, camera, engine,
                                    session):  # fmt: skip
        assert session.view.join(300) and session.view.error is None
        view, before = session.view, session.view.latest.rgba.copy()
        passes = view.latest.passes
        cube = (passes["ending"] == core.ENDING["hit"]) & ~np.isfinite(passes["redshift"])
        assert cube.mean() > 0.05
        bsdf = bpy.data.materials["Material"].node_tree.nodes["Principled BSDF"]

        def recolour():
            bsdf.inputs["Base Color"].default_value = (0.9, 0.1, 0.05, 1.0)

        _update_in_handler(viewport, engine, context, recolour)
        assert session.view is view  # nothing new traced
        changed = np.abs(session.shown - before).max(axis=-1) > 1e-3
        assert changed[cube].all() and not changed[~cube].any()
        fresh = _fresh_render(render_job, core, scene, camera)
        np.testing.assert_allclose(session.shown, fresh, atol=1e-5)

        def move():
            bpy.data.objects["Cube"].location.x += 0.5

        _update_in_handler(viewport, engine, context, move)
        assert session.view is not view  # rendered again

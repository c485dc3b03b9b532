"""The camera's SymRay Observer: From Animation's velocity against the keyframes' slope, and
a moving camera's sky against special relativity's Doppler shift, from the factory scene."""

import math

import bpy
import numpy as np
import pytest


def _job(addon):
    return addon.module("symray_addon.render_job")


def test_from_animation_is_the_keyframes_slope_over_the_speed_of_light(addon, factory_scene):
    """The factory camera keyed at frames 1 and 11 (linear): at frame 5, 24 fps, with the
    speed of light 10 units/s, its velocity is (Δlocation / 10 frames) x 24 / 10 in c."""
    scene = factory_scene
    camera = scene.camera
    start = np.array(camera.location)
    move = np.array([1.0, -2.0, 0.5])
    for frame, where in ((1, start), (11, start + move)):
        camera.location = where.tolist()
        camera.keyframe_insert("location", frame=frame)
    for curve in addon.module("symray_addon.observer").location_curves(camera).values():
        for key in curve.keyframe_points:
            key.interpolation = "LINEAR"
    scene.render.fps, scene.render.fps_base = 24, 1.0
    scene.frame_set(5)
    camera.data.symray.kind = "ANIMATION"
    camera.data.symray.speed_of_light = 10.0
    prepared = _job(addon).prepare(scene, bpy.context.evaluated_depsgraph_get())
    expected = move / 10 * 24 / 10.0
    # Blender keeps locations and keyframes in float32: ~5e-7 of the factory camera's 7 m
    np.testing.assert_allclose(prepared.options["observer"], expected, rtol=0, atol=1e-6)
    assert prepared.options["shift_colours"] is True


def test_a_velocity_at_or_above_c_is_refused_by_name(addon, factory_scene):
    scene = factory_scene
    scene.camera.data.symray.kind = "VELOCITY"
    scene.camera.data.symray.velocity = (0.8, 0.8, 0.0)
    with pytest.raises(ValueError, match="Camera.*Observer.*speed of light"):
        _job(addon).prepare(scene, bpy.context.evaluated_depsgraph_get())


@pytest.mark.parametrize("shift_colours", [True, False])
def test_a_moving_cameras_sky_takes_each_pixels_doppler_shift(
    addon, factory_scene, helpers, shift_colours
):
    """Flat space (the factory scene's cube and grey world), the camera moving at 0.5 c to
    its right: each pixel that sees the world is its colour shifted by g = 1 / (γ (1 − v·n'))
    (n' the pixel's direction) as a black body of its colour temperature (core.blackbody),
    or the world's own colour with Shift Colours off."""
    scene = factory_scene
    scene.symray.model = "FLAT"
    camera = scene.camera
    right = np.array(camera.matrix_world)[:3, 0]
    camera.data.symray.kind = "VELOCITY"
    camera.data.symray.velocity = (0.5 * right).tolist()
    camera.data.symray.shift_colours = shift_colours
    job = _job(addon)
    image = job.run(job.prepare(scene, bpy.context.evaluated_depsgraph_get())).rgba
    world = np.array(scene.world.node_tree.nodes["Background"].inputs["Color"].default_value)[:3]
    rows, cols = np.array([0, 0, 47, 47]), np.array([0, 63, 0, 63])  # the corners see the world
    n = helpers.frame_directions(scene, camera, rows, cols)
    g = 1.0 / ((1.0 / math.sqrt(1 - 0.25)) * (1.0 - n @ (0.5 * right)))
    blackbody = addon.module("core.blackbody")
    colours = np.broadcast_to(world, (4, 3))
    expected = blackbody.shifted_colour(colours, g) if shift_colours else colours
    np.testing.assert_allclose(image[rows, cols, :3], expected, rtol=1e-5, atol=1e-6)
    assert g.max() - g.min() > 0.2  # the shift differs across the frame


def test_the_magnification_pass_of_a_moving_camera_is_its_aberration(addon, factory_scene, helpers):
    """Flat space, the camera moving at 0.5 c to its right, the SymRay Magnification pass
    on: the aberration maps the camera's solid angle onto the sky's scaled by g², so each
    pixel seeing the world has |μ| = 1 / g² (core/tracing/differentials.py against special
    relativity; at 0.5 c the aberration moves the factory cube out of this frame: every
    pixel sees the world)."""
    scene = factory_scene
    scene.symray.model = "FLAT"
    scene.symray.pass_magnification = scene.symray.pass_ending = True
    camera = scene.camera
    right = np.array(camera.matrix_world)[:3, 0]
    camera.data.symray.kind = "VELOCITY"
    camera.data.symray.velocity = (0.5 * right).tolist()
    job = _job(addon)
    result = job.run(job.prepare(scene, bpy.context.evaluated_depsgraph_get()))
    mu = result.passes["magnification"]
    assert (result.passes["ending"] == addon.module("core").ENDING["escaped"]).all()
    rows, cols = (a.ravel() for a in np.mgrid[0:48, 0:64])  # every pixel sees the world
    n = helpers.frame_directions(scene, camera, rows, cols)
    g = 1.0 / ((1.0 / math.sqrt(1 - 0.25)) * (1.0 - n @ (0.5 * right)))
    np.testing.assert_allclose(mu[rows, cols], 1.0 / g**2, rtol=1e-5)
    assert g.max() / g.min() > 1.3  # μ differs across the frame

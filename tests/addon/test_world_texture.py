"""A world's Environment Texture around a black hole (issue 26): from the factory scene, the
sky squeezed around the shadow shows the texture's mean over each pixel's footprint, not
moiré; the node's Closest interpolation looks it up at one point, as asked."""

import bpy
import numpy as np
import pytest


def _checker_world(scene, interpolation: str) -> None:
    """The factory World's Background fed by an Environment Texture of a 1-texel black and
    white checker (512 x 256; mean 0.5)."""
    image = bpy.data.images.get("Checker") or bpy.data.images.new(
        "Checker", 512, 256, float_buffer=True
    )
    rows, cols = np.mgrid[0:256, 0:512]
    cells = ((rows + cols) % 2).astype(np.float32)
    pixels = np.repeat(cells[..., None], 4, axis=2)
    pixels[..., 3] = 1.0
    image.colorspace_settings.name = "Non-Color"  # before the pixels: it reloads them
    image.pixels.foreach_set(pixels.ravel())
    tree = scene.world.node_tree
    env = tree.nodes.new("ShaderNodeTexEnvironment")
    env.image, env.interpolation = image, interpolation
    tree.links.new(env.outputs["Color"], tree.nodes["Background"].inputs["Color"])


def _render(addon, scene):
    job = addon.module("symray_addon.render_job")
    return job.run(job.prepare(scene, bpy.context.evaluated_depsgraph_get()))


@pytest.mark.parametrize("interpolation", ["Linear", "Closest"])
def test_the_sky_squeezed_around_a_hole_is_the_textures_mean(addon, factory_scene, interpolation):
    """A hole (Size 0.5) at the factory cube's place, seen by the factory camera at Preview:
    where the SymRay Magnification pass says the sky is squeezed 100x or more in area (a
    0.25° pixel covering ≥ 3.5 texels a side of the 0.7° checker), a Linear texture's
    pixels are the checker's mean 0.5 within 0.05 (measured: 1e-3); looked up at one point
    (Closest) they scatter (spread ≥ 0.25: the checker aliased)."""
    scene = factory_scene
    bpy.data.objects.remove(bpy.data.objects["Cube"])
    scene.cursor.location = (0.0, 0.0, 0.0)
    assert bpy.ops.symray.add_black_hole(size=0.5, spin=0.0, disk=False) == {"FINISHED"}
    scene.render.resolution_x, scene.render.resolution_y = 160, 120
    scene.symray.pass_magnification = scene.symray.pass_ending = True
    _checker_world(scene, interpolation)
    result = _render(addon, scene)
    squeezed = np.isfinite(result.passes["magnification"])
    squeezed[squeezed] = result.passes["magnification"][squeezed] < 0.01
    assert squeezed.sum() >= 200
    grey = result.rgba[..., :3][squeezed].astype(np.float64).mean(axis=1)
    if interpolation == "Linear":
        assert np.abs(grey - 0.5).max() < 0.05
    else:
        assert grey.std() >= 0.25


def _plain_image(name: str, rgba) -> bpy.types.Image:
    """A 16 x 8 float image of one colour."""
    image = bpy.data.images.new(name, 16, 8, float_buffer=True, alpha=True)
    image.pixels.foreach_set(np.tile(np.asarray(rgba, np.float32), 16 * 8))
    return image


def _environment(scene, image, projection: str = "EQUIRECTANGULAR") -> None:
    """The factory World's Background fed by an Environment Texture of ``image``."""
    tree = scene.world.node_tree
    env = tree.nodes.new("ShaderNodeTexEnvironment")
    env.image, env.projection = image, projection
    tree.links.new(env.outputs["Color"], tree.nodes["Background"].inputs["Color"])


def _operator_image(scene) -> np.ndarray:
    """Render SymRay Image's pixels, (h, w, 4)."""
    assert bpy.ops.symray.render() == {"FINISHED"}
    image = bpy.data.images[scene.symray.image_name]
    w, h = image.size
    return np.array(image.pixels[:], dtype=np.float32).reshape(h, w, 4)


def _small(scene):
    """The factory scene at 32 x 24, flat space, unlit (the sky is what is tested)."""
    scene.render.resolution_x, scene.render.resolution_y = 32, 24
    scene.symray.quality, scene.symray.lighting = "RADIANS", "UNLIT"
    return scene


def test_an_environment_textures_alpha_is_not_the_renders(factory_scene):
    """Film › Transparent off: a sky image of alpha 0 renders opaque, as Cycles does, the
    same image as the sky of alpha 1 (issue 45, point 3)."""
    scene = _small(factory_scene)
    _environment(scene, _plain_image("Clear", (0.2, 0.4, 0.6, 0.0)))
    clear = _operator_image(scene)
    scene.world.node_tree.nodes["Environment Texture"].image = _plain_image(
        "Opaque", (0.2, 0.4, 0.6, 1.0)
    )
    np.testing.assert_array_equal(clear, _operator_image(scene))
    assert np.all(clear[..., 3] == 1.0)
    np.testing.assert_allclose(clear[-1, 0], (0.2, 0.4, 0.6, 1.0), rtol=1e-6)  # the sky


def _missing_image() -> bpy.types.Image:
    """An image whose file is gone (no pixels), as a moved .blend's sky."""
    image = bpy.data.images.new("Gone", 16, 8, float_buffer=True)
    image.source = "FILE"
    image.filepath = "/nonexistent/symray-sky.exr"
    image.reload()
    return image


@pytest.mark.parametrize("projection", ["EQUIRECTANGULAR", "MIRROR_BALL"])
@pytest.mark.parametrize("mode", ["AUTO", "WORLD"])
def test_a_missing_environment_image_renders_magenta(addon, factory_scene, mode, projection):
    """A missing sky image is Blender's magenta (× Strength), as in Cycles and as SymRay's
    own missing material images, with a warning naming it; not the procedural sky (Auto)
    nor black (World) (issue 45, point 4). Reference: the world of plain magenta."""
    scene = _small(factory_scene)
    scene.symray.background = mode
    background = scene.world.node_tree.nodes["Background"]
    background.inputs["Strength"].default_value = 0.5
    background.inputs["Color"].default_value = (1.0, 0.0, 1.0, 1.0)
    magenta = _operator_image(scene)
    _environment(scene, _missing_image(), projection)
    np.testing.assert_array_equal(_operator_image(scene), magenta)
    np.testing.assert_allclose(magenta[-1, 0], (0.5, 0.0, 0.5, 1.0), rtol=1e-6)
    job = addon.module("symray_addon.render_job")
    warnings = job.prepare(scene, bpy.context.evaluated_depsgraph_get()).warnings
    assert any("'Gone'" in w and "symray-sky.exr" in w and "magenta" in w for w in warnings)


def test_a_mirror_ball_image_is_refused_by_name(factory_scene, helpers):
    """SymRay reads equirectangular skies: a Mirror Ball image is refused by name, not
    shown as the procedural sky."""
    scene = _small(factory_scene)
    _environment(scene, _plain_image("Ball", (0.2, 0.4, 0.6, 1.0)), "MIRROR_BALL")
    message = helpers.operator_error(lambda: bpy.ops.symray.render())
    assert "'Ball'" in message and "Mirror Ball projection" in message
    assert "Equirectangular" in message

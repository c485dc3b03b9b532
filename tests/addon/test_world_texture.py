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

"""An image-textured floor seen at a grazing angle (issue 26): from the factory scene, its
far part shows the texture's mean over each pixel's footprint, not moiré; the Image Texture
node's Closest interpolation looks it up at one point, as asked."""

import bpy
import numpy as np
import pytest


def _checker_floor(interpolation: str) -> bpy.types.Object:
    """A 200 x 200 plane 1 below the origin, its Principled BSDF's Base Color an Image
    Texture of a 1-texel black and white checker (512 x 512, mean 0.5) on its UV map."""
    bpy.ops.mesh.primitive_plane_add(size=200.0, location=(0.0, 0.0, -1.0))
    floor = bpy.context.active_object
    image = bpy.data.images.new("Floor Checker", 512, 512, float_buffer=True)
    rows, cols = np.mgrid[0:512, 0:512]
    pixels = np.repeat(((rows + cols) % 2).astype(np.float32)[..., None], 4, axis=2)
    pixels[..., 3] = 1.0
    image.colorspace_settings.name = "Non-Color"  # before the pixels: it reloads them
    image.pixels.foreach_set(pixels.ravel())
    material = bpy.data.materials.new("Floor")
    if bpy.app.version < (5, 0, 0):
        material.use_nodes = True
    tree = material.node_tree
    texture = tree.nodes.new("ShaderNodeTexImage")
    texture.image, texture.interpolation = image, interpolation
    tree.links.new(texture.outputs["Color"], tree.nodes["Principled BSDF"].inputs["Base Color"])
    floor.data.materials.append(material)
    return floor


@pytest.mark.parametrize("interpolation", ["Linear", "Closest"])
def test_a_floor_seen_at_a_grazing_angle_is_the_textures_mean(addon, factory_scene, interpolation):
    """The factory camera (6 above the floor) tilted up to look 8° down, over the floor,
    unlit, at Preview: where the floor is more than 85 away (the Position pass; a pixel's
    footprint there ≥ 13 texels along the view and 1 across), a Linear texture's pixels are
    the checker's mean 0.5 within 0.1 (measured 0.03); looked up at one point (Closest)
    they scatter (spread ≥ 0.25: the checker aliased; measured 0.5)."""
    scene = factory_scene
    bpy.data.objects.remove(bpy.data.objects["Cube"])
    _checker_floor(interpolation)
    scene.symray.lighting = "UNLIT"
    scene.camera.rotation_euler[0] = np.radians(82.0)  # 8° below the horizon
    scene.render.resolution_x, scene.render.resolution_y = 160, 120
    render_job = addon.module("symray_addon.render_job")
    job = render_job.prepare(scene, bpy.context.evaluated_depsgraph_get())
    job.options["passes"] = tuple(job.options["passes"]) + ("position",)
    result = render_job.run(job)
    eye = np.array(scene.camera.matrix_world.translation)
    distance = np.linalg.norm(result.passes["position"].reshape(-1, 3) - eye, axis=1)
    far = np.isfinite(distance) & (distance > 85.0)
    grey = result.rgba.reshape(-1, 4)[far, :3].astype(np.float64).mean(axis=1)
    assert far.sum() >= 300
    if interpolation == "Linear":
        assert np.abs(grey - 0.5).max() < 0.1
    else:
        assert grey.std() >= 0.25


@pytest.mark.parametrize("extension", ["REPEAT", "EXTEND", "CLIP", "MIRROR"])
def test_a_material_texture_is_filtered_only_where_its_footprint_covers_texels(addon, extension):
    """MaterialSampler: a footprint within a tenth of a texel gives exactly the bilinear
    sample (the texture is resolved there), NaN (no neighbour) too; one of 16 texels a side
    on a 1-texel checker its mean 0.5 within 0.02 (inside the image); Closest is never
    filtered; CLIP is zero outside the image either way."""
    materials = addon.module("symray_addon.materials")
    rows, cols = np.mgrid[0:64, 0:32]
    image = np.repeat(((rows + cols) % 2).astype(np.float32)[..., None], 4, axis=2)
    sampler = materials.MaterialSampler(np.ones(4), image, extension=extension)
    rng = np.random.default_rng(3)
    uv = rng.uniform(-0.5, 1.5, size=(500, 2))
    plain = sampler.sample(uv)
    small = rng.normal(size=(500, 2, 2)) * 1e-3
    np.testing.assert_array_equal(sampler.sample(uv, small), plain)
    np.testing.assert_array_equal(sampler.sample(uv, np.full_like(small, np.nan)), plain)
    wide = np.broadcast_to(np.diag([16 / 32, 16 / 64]), (500, 2, 2)).copy()
    filtered = sampler.sample(uv, wide)
    inside = np.all((uv > 0.3) & (uv < 0.7), axis=1)
    assert inside.sum() > 20
    assert np.abs(filtered[inside, :3] - 0.5).max() < 0.02
    assert np.abs(plain[inside, :3] - 0.5).max() > 0.3
    if extension == "CLIP":
        outside = np.any((uv < 0) | (uv > 1), axis=1)
        assert not filtered[outside].any()
    closest = materials.MaterialSampler(np.ones(4), image, closest=True, extension=extension)
    np.testing.assert_array_equal(closest.sample(uv, wide), closest.sample(uv))

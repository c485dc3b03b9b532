"""The BVH intersector agrees with direct BVHTree.ray_cast and reads materials/UVs."""

from __future__ import annotations

import math

import bpy
import numpy as np
import pytest
from mathutils import Matrix, Vector
from mathutils.bvhtree import BVHTree


@pytest.fixture
def objects(scene, helpers):
    """A bevelled cube, a rotated scaled quad and a linked duplicate of the cube."""
    red = helpers.solid_material("Red", (1.0, 0.0, 0.0, 1.0))
    cube = helpers.add_cube(scene, "Cube", material=red, location=(0.5, 0.0, 0.0))
    bevel = cube.modifiers.new("Bevel", "BEVEL")
    bevel.width = 0.2
    twin = bpy.data.objects.new("Twin", cube.data)
    twin.location, twin.rotation_euler, twin.scale = (-3.0, 2.0, 1.0), (0.3, 0.2, 0.1), (0.5,) * 3
    scene.collection.objects.link(twin)
    quad = helpers.add_quad(
        scene,
        "Quad",
        half=2.0,
        y=0.0,
        location=(0.0, 6.0, 0.0),
        rotation=(0.2, 0.0, 0.4),
        scale=(1.5, 1.5, 1.5),
    )
    hidden = helpers.add_cube(scene, "Hidden", location=(0.0, -4.0, 0.0))
    hidden.hide_render = True
    bpy.context.view_layer.update()
    return [cube, twin, quad]


def _reference(depsgraph, objects, a, b):
    """Nearest hit per segment over per-object BVHTree.FromObject trees (local space)."""
    trees = []
    for obj in objects:
        ev = obj.evaluated_get(depsgraph)
        trees.append((obj.name, BVHTree.FromObject(ev, depsgraph), Matrix(ev.matrix_world)))
    out = []
    for pa, pb in zip(a, b, strict=True):
        best = None
        for name, tree, m in trees:
            inv = m.inverted()
            la, lb = inv @ Vector(pa), inv @ Vector(pb)
            loc, nor, _index, _dist = tree.ray_cast(la, lb - la, (lb - la).length)
            if loc is None:
                continue
            world = m @ loc
            t = (world - Vector(pa)).length / (Vector(pb) - Vector(pa)).length
            normal = (m.to_3x3().inverted().transposed() @ nor).normalized()
            if best is None or t < best[1]:
                best = (name, t, np.array(world), np.array(normal))
        out.append(best)
    return out


def test_hits_agree_with_direct_ray_cast(addon, scene, objects):
    depsgraph = bpy.context.evaluated_depsgraph_get()
    meshes = addon.module("symray_addon.export_meshes")
    intersector = meshes.build_intersector(depsgraph)
    assert intersector.names == ["Cube", "Twin", "Quad"] or sorted(intersector.names) == [
        "Cube",
        "Quad",
        "Twin",
    ]
    rng = np.random.default_rng(7)
    a = rng.uniform(-8, 8, (400, 3))
    targets = np.array([o.matrix_world.translation[:] for o in objects])
    aim = targets[rng.integers(0, len(objects), 400)] + rng.normal(0, 1.2, (400, 3))
    b = a + (aim - a) * rng.uniform(0.3, 2.0, (400, 1))
    hits = intersector.intersect(a, b)
    assert hits.hit.shape == (400,) and hits.color.shape == (400, 4)
    ref = _reference(depsgraph, objects, a, b)
    expected_hit = np.array([r is not None for r in ref])
    assert 40 < expected_hit.sum() < 360  # a meaningful mix of hits and misses
    np.testing.assert_array_equal(hits.hit, expected_hit)
    for i in np.flatnonzero(expected_hit):
        name, t, pos, normal = ref[i]
        assert intersector.names[hits.object_id[i]] == name
        assert hits.t[i] == pytest.approx(t, abs=1e-5)
        np.testing.assert_allclose(hits.position[i], pos, atol=1e-4)
        assert abs(np.dot(hits.normal[i], normal)) == pytest.approx(1.0, abs=1e-4)
    assert np.all(np.isinf(hits.t[~hits.hit])) and np.all(hits.object_id[~hits.hit] == -1)
    assert np.all((hits.t[hits.hit] >= 0) & (hits.t[hits.hit] <= 1))


def test_bounds_cover_evaluated_world_geometry(addon, scene, objects):
    depsgraph = bpy.context.evaluated_depsgraph_get()
    intersector = addon.module("symray_addon.export_meshes").build_intersector(depsgraph)
    points = []
    for obj in objects:
        ev = obj.evaluated_get(depsgraph)
        m = np.array(ev.matrix_world)
        co = np.array([v.co[:] for v in ev.to_mesh().vertices])
        ev.to_mesh_clear()
        points.append(co @ m[:3, :3].T + m[:3, 3])
    points = np.concatenate(points)
    lo, hi = intersector.bounds
    np.testing.assert_allclose(lo, points.min(axis=0), atol=1e-9)
    np.testing.assert_allclose(hi, points.max(axis=0), atol=1e-9)


def test_hidden_and_empty_scene(addon, scene, helpers):
    meshes = addon.module("symray_addon.export_meshes")
    helpers.add_cube(scene, "Hidden").hide_render = True
    assert meshes.build_intersector(bpy.context.evaluated_depsgraph_get()) is None


def test_material_colors_and_texture_uv(addon, scene, helpers):
    """Base colour from the Principled BSDF; an image texture sampled at the hit's UV."""
    img = bpy.data.images.new("Quadrants", 2, 2, alpha=True, float_buffer=True)
    # bottom-left, bottom-right, top-left, top-right (Blender rows go bottom-up)
    colors = np.array([[1, 0, 0, 1], [0, 1, 0, 1], [0, 0, 1, 1], [1, 1, 0, 1]], np.float32)
    img.pixels.foreach_set(colors.ravel())
    textured = helpers.solid_material("Textured", (1, 1, 1, 1))
    tree = textured.node_tree
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image, tex.interpolation = img, "Closest"
    bsdf = next(n for n in tree.nodes if n.type == "BSDF_PRINCIPLED")
    tree.links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
    helpers.add_quad(scene, "Board", half=1.0, y=5.0, material=textured)
    helpers.add_cube(
        scene,
        "Green",
        size=1.0,
        location=(0, 0, 5),
        material=helpers.solid_material("G", (0.1, 0.6, 0.2, 1.0)),
    )
    helpers.add_cube(scene, "Plain", size=1.0, location=(0, 0, -5))
    intersector = addon.module("symray_addon.export_meshes").build_intersector(
        bpy.context.evaluated_depsgraph_get()
    )
    # quad corners: (-1,5,-1) uv (0,0); (1,5,-1) uv (1,0) ... u along +x, v along +z
    a = np.array(
        [[-0.5, 0, -0.5], [0.5, 0, -0.5], [-0.5, 0, 0.5], [0.5, 0, 0.5], [0, 0, 5], [0, 0, -5]],
        float,
    )
    a[4], a[5] = (0, -3, 5), (0, -3, -5)
    b = a + np.array([0.0, 10.0, 0.0])
    hits = intersector.intersect(a, b)
    assert hits.hit.all()
    np.testing.assert_allclose(hits.uv[0], (0.25, 0.25), atol=1e-6)
    np.testing.assert_allclose(hits.uv[3], (0.75, 0.75), atol=1e-6)
    np.testing.assert_allclose(hits.color[:4], colors, atol=1e-6)
    np.testing.assert_allclose(hits.color[4], (0.1, 0.6, 0.2, 1.0), atol=1e-6)
    np.testing.assert_allclose(hits.color[5], (0.8, 0.8, 0.8, 1.0), atol=1e-6)


def test_srgb_byte_texture_is_linearised(addon):
    materials = addon.module("symray_addon.materials")
    img = bpy.data.images.new("Bytes", 1, 1, alpha=True, float_buffer=False)
    img.pixels.foreach_set(np.array([0.5, 0.5, 0.5, 1.0], np.float32))
    pix = materials.image_pixels(img)
    stored = img.pixels[0]  # 8-bit quantised
    expected = ((stored + 0.055) / 1.055) ** 2.4
    assert pix[0, 0, 0] == pytest.approx(expected, rel=1e-5)
    assert pix[0, 0, 3] == pytest.approx(1.0)
    assert math.isclose(materials.srgb_to_linear(np.array(1.0)), 1.0)


def _render(addon, scene):
    """The operator's code path (prepare + run): the job and the core result."""
    job = addon.module("symray_addon.render_job")
    prepared = job.prepare(scene, bpy.context.evaluated_depsgraph_get())
    return prepared, job.run(prepared)


@pytest.mark.parametrize("bad", [math.nan, math.inf])
def test_a_non_finite_vertex_leaves_out_only_its_object(addon, scene, helpers, bad):
    """One NaN or infinite vertex: that object is left out with a warning naming it; the
    others render exactly as they do without it (not: every object gone, bounds NaN)."""
    helpers.add_cube(scene, "Good", size=6.0, material=helpers.solid_material("R", (1, 0, 0, 1)))
    verts = [(-2.0, -5.0, -2.0), (2.0, -5.0, -2.0), (2.0, -5.0, 2.0), (bad, -5.0, 2.0)]
    helpers.add_mesh(scene, "Broken", verts, [(0, 1, 2, 3)])
    helpers.add_camera(scene)
    scene.symray.model = "FLAT"
    scene.symray.lighting = "UNLIT"
    scene.symray.pass_ending = True
    job, result = _render(addon, scene)
    assert len(job.warnings) == 1 and "'Broken'" in job.warnings[0], job.warnings
    assert job.scene.objects.names == ["Good"]
    bpy.data.objects.remove(bpy.data.objects["Broken"])
    _job, want = _render(addon, scene)
    hit = want.passes["ending"] == addon.core.ENDING["hit"]
    assert hit.sum() > 300
    np.testing.assert_array_equal(result.rgba, want.rgba)
    np.testing.assert_allclose(result.rgba[hit][:, :3], np.tile((1.0, 0.0, 0.0), (hit.sum(), 1)))


def test_bvh_intersector_refuses_non_finite_vertices(addon):
    """Built directly with a NaN vertex, the intersector says so (its bounds would be NaN)."""
    meshes = addon.module("symray_addon.export_meshes")
    verts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [np.nan, 0, 0]], float)
    with pytest.raises(ValueError, match="finite"):
        meshes.BVHIntersector(
            verts, [[0, 1, 2], [1, 2, 3]], [0, 0], [0, 0], np.zeros((2, 3, 2)), [None], ["A"]
        )


def _unit_cube(meshes):
    """A BVHIntersector of the cube [-1, 1]^3 (12 triangles, one white material)."""
    corners = [(x, y, z) for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    triangles = [t for q in quads for t in ((q[0], q[1], q[2]), (q[0], q[2], q[3]))]
    sampler = meshes.MaterialSampler(np.array([1.0, 1.0, 1.0, 1.0]))
    return meshes.BVHIntersector(
        np.array(corners, float), np.array(triangles), np.zeros(12), np.zeros(12),
        np.zeros((12, 3, 2)), [sampler],
    )  # fmt: skip


@pytest.mark.parametrize("few", [32, 0], ids=["numpy", "bvhtree"])
def test_segments_from_a_surface_see_it_both_ways(addon, monkeypatch, few):
    """Segments that start within 1e-8 of a face (the tracer moves a hit point onto the
    method's path and casts from there both ways) hit it at t ~ 0 going in and going out:
    a float32 BVHTree alone missed both ways on thousands of them, and the tracer took the
    ray to pass the object by: isolated pixels of another face (issue 51's specks). Both
    narrow phases: numpy for few triangles, Blender's BVHTree for more."""
    meshes = addon.module("symray_addon.export_meshes")
    monkeypatch.setattr(meshes, "NUMPY_TRIANGLES", few)
    cube = _unit_cube(meshes)
    assert (cube._few is not None) == (few > 0)
    rng = np.random.default_rng(3)
    n = 4000
    on = np.c_[rng.uniform(-0.95, 0.95, (n, 2)), np.ones(n)]  # the top face, z = 1
    on[:, 2] += rng.uniform(-1e-8, 1e-8, n)
    along = rng.normal(size=(n, 3))
    along[:, 2] = -np.abs(along[:, 2]) - 0.2  # downwards, into the cube
    along *= 0.02 / np.linalg.norm(along, axis=1, keepdims=True)
    for a, b in ((on, on + along), (on, on - along)):  # in, and out
        hits = cube.intersect(a, b)
        assert hits.hit.all()
        assert np.all(hits.t < 1e-3)
        np.testing.assert_allclose(hits.position[:, 2], 1.0, atol=1e-6)
        np.testing.assert_allclose(np.abs(hits.normal[:, 2]), 1.0)
    far = cube.intersect(on + 1e-3 * np.array([0, 0, 1.0]), on + 0.02 * np.array([0, 0, 1.0]))
    assert not far.hit.any()  # a segment wholly outside, 1e-3 away, is no hit


def test_few_triangles_hit_in_numpy_as_the_bvhtree_hits_them(addon, monkeypatch):
    """A few triangles are hit in numpy (float64), not one ray_cast per segment: the same
    hits, faces and distances as Blender's float32 BVHTree (to its precision) on segments
    in every direction, through and past the cube and along its faces' planes."""
    meshes = addon.module("symray_addon.export_meshes")
    few = _unit_cube(meshes)
    monkeypatch.setattr(meshes, "NUMPY_TRIANGLES", 0)
    tree = _unit_cube(meshes)
    assert few._few is not None and tree._few is None
    rng = np.random.default_rng(51)
    a = rng.uniform(-3, 3, (3000, 3))
    aim = rng.normal(0.0, 0.8, (3000, 3))  # most towards the cube, some stopping short
    b = a + (aim - a) * rng.uniform(0.3, 2.0, (3000, 1))
    b[:200, 2] = a[:200, 2] = 1.0 + rng.uniform(-1e-3, 1e-3, 200)  # grazing the top face
    mine, theirs = few.intersect(a, b), tree.intersect(a, b)
    assert 600 < mine.hit.sum() < 2400
    edge = np.abs(np.abs(np.c_[mine.position, theirs.position]) - 1.0).min(axis=1) < 1e-9
    same = mine.hit == theirs.hit
    assert same.mean() > 0.999 and np.all(same | edge)  # a miss only where a ray grazes
    both = mine.hit & theirs.hit
    length = np.linalg.norm(b - a, axis=1)[both]
    # the BVHTree's float32: distances within 2e-6 (all but a grazing few: 2e-5 measured)
    off = np.abs(mine.t[both] - theirs.t[both]) * length
    assert np.quantile(off, 0.999) < 2e-6 and off.max() < 1e-4
    np.testing.assert_allclose(mine.normal[both], theirs.normal[both], atol=1e-12)
    moved = np.abs(mine.position[both] - theirs.position[both]).max(axis=1)
    assert np.quantile(moved, 0.999) < 2e-6 and moved.max() < 1e-4


def test_a_medium_of_index_one_renders_the_cube_as_flat_space_does(addon, factory_scene):
    """The factory cube seen through a medium of n = 1 (curved-ray machinery, straight
    rays) hits the same face at every pixel as flat space (the exact reference): issue 51's
    specks were pixels of the next face, 8 % of the cube in the Mirage preset."""
    job = addon.module("symray_addon.render_job")
    scene = factory_scene
    scene.symray.quality, scene.symray.lighting = "RADIANS", "UNLIT"
    scene.symray.pass_ending = True

    def faces(model: str) -> np.ndarray:
        scene.symray.model = model
        prepared = job.prepare(scene, bpy.context.evaluated_depsgraph_get())
        prepared.options["passes"] = ("position", "ending")
        out = addon.core.render(prepared.scene, prepared.camera, **prepared.options)
        hit = out.passes["ending"] == addon.core.ENDING["hit"]
        return np.where(hit, np.argmax(np.abs(out.passes["position"]), axis=-1), -1)

    scene.symray.refractive_index = "1.0"
    scene.symray.use_medium_bounds = False
    flat, medium = faces("FLAT"), faces("MEDIUM")
    assert (flat >= 0).sum() > 400  # of 3072 pixels
    assert np.count_nonzero(medium != flat) <= 2, np.argwhere(medium != flat)  # grazing edges


def test_part_bounds_one_box_per_object_then_shared(addon, monkeypatch):
    """The clearances see each object's own box (its hits then measure only the others);
    past PART_BOXES objects (16 here, 4096 in use), neighbours share a box (id -3: none's
    own), every triangle inside its box."""
    meshes = addon.module("symray_addon.export_meshes")
    monkeypatch.setattr(meshes, "PART_BOXES", 16)
    rng = np.random.default_rng(5)
    for count in (3, meshes.PART_BOXES + 5):
        centres = rng.uniform(-10, 10, (count, 3))
        corners = centres[:, None, None, :] + rng.uniform(-0.5, 0.5, (count, 2, 3, 3))
        corners = corners.reshape(-1, 3, 3)
        tri_object = np.repeat(np.arange(count), 2)
        boxes = meshes.part_bounds(corners, tri_object)
        assert len(boxes) == min(count, meshes.PART_BOXES)
        for k in range(count):
            own = [b for b in boxes if b[2] == k]
            inside = [
                b for b in boxes
                if np.all(corners[tri_object == k] >= b[0] - 1e-12)
                and np.all(corners[tri_object == k] <= b[1] + 1e-12)
            ]  # fmt: skip
            assert inside  # every object lies in some box
            if count <= meshes.PART_BOXES:
                np.testing.assert_array_equal(own[0][0], corners[tri_object == k].min(axis=(0, 1)))
                np.testing.assert_array_equal(own[0][1], corners[tri_object == k].max(axis=(0, 1)))


def _cubes(meshes, centres: np.ndarray, half: float):
    """A BVHIntersector of cubes of half-width ``half`` around ``centres`` (C, 3), one
    object each (12 triangles, one white material)."""
    unit = _unit_cube(meshes)
    count = centres.shape[0]
    vertices = (centres[:, None, :] + half * unit.vertices[None]).reshape(-1, 3)
    triangles = (unit.triangles[None] + 8 * np.arange(count)[:, None, None]).reshape(-1, 3)
    sampler = meshes.MaterialSampler(np.array([1.0, 1.0, 1.0, 1.0]))
    return meshes.BVHIntersector(
        vertices, triangles, np.repeat(np.arange(count), 12), np.zeros(12 * count),
        np.zeros((12 * count, 3, 2)), [sampler],
    )  # fmt: skip


def test_many_objects_keep_their_own_boxes_and_are_found_at_once(addon, monkeypatch):
    """300 small cubes (a scattered crowd: 4 % of the space their boxes' union spans) keep
    a box each (PART_BOXES), so steps between them are not near geometry; their boxes are
    tested all at once (ManyBoxes): the same segments near a part and the same hits as
    testing each box in turn, on segments of every length among and past them."""
    meshes = addon.module("symray_addon.export_meshes")
    rng = np.random.default_rng(45)
    centres = rng.uniform(-10, 10, (300, 3))
    crowd = _cubes(meshes, centres, 0.2)
    assert len(crowd.part_bounds) == 300 and crowd._parts is not None
    monkeypatch.setattr(meshes, "FEW_PARTS", 10**6)
    in_turn = _cubes(meshes, centres, 0.2)
    assert in_turn._parts is None
    a = rng.uniform(-12, 12, (4000, 3))
    b = a + rng.normal(size=(4000, 3)) * rng.choice([0.1, 1.0, 10.0], (4000, 1))
    b[:300] = centres + rng.normal(scale=0.1, size=(300, 3))  # ending in or beside a cube
    slack = rng.uniform(0.0, 0.05, 4000)
    near = crowd._near_parts(a, b, slack)
    np.testing.assert_array_equal(near, in_turn._near_parts(a, b, slack))
    assert 300 <= np.count_nonzero(near) < 0.7 * near.size  # most segments pass clear
    mine, theirs = crowd.intersect(a, b), in_turn.intersect(a, b)
    np.testing.assert_array_equal(mine.hit, theirs.hit)
    np.testing.assert_array_equal(mine.t[mine.hit], theirs.t[theirs.hit])
    assert mine.hit.sum() > 100

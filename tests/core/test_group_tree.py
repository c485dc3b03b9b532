"""The Group's broad phase (issue 45.6: a BVH over objects) against the brute force it
replaces: every member asked in turn about the segments whose bounds overlap its box."""

import pickle
from dataclasses import fields

import numpy as np
import pytest

import core
from core.geometry import boxgrid
from core.geometry import group as group_module
from core.intersect import Disk, Group, Hits, Plane, Sphere, TriangleMesh, checker, segment_overlaps

RNG = np.random.default_rng(4545)


def brute_force(objects, ids, a, b, footprint=None):
    """The original Group.intersect: each member in turn, nearer hits kept (an earlier
    member wins a tie: strict <)."""
    out = Hits.miss(a.shape[0])
    for obj, oid in zip(objects, ids, strict=True):
        rows = np.flatnonzero(segment_overlaps(a, b, *obj.bounds))
        if rows.size == 0:
            continue
        if footprint is not None and getattr(obj, "filters", False):
            hits = obj.intersect(a[rows], b[rows], footprint[rows])
        else:
            hits = obj.intersect(a[rows], b[rows])
        out.merge(rows, hits, oid)
    return out


UV_ROUNDING = 1e-12
"""Texture coordinates agree to this, the other fields bit for bit: a sphere's uv comes from
arctan2 / arccos, whose numpy 1.26 SIMD loops round the last bit differently by the length
of the batch a hit is computed in (the tree's windows and the brute force's batches differ);
CI on Blender 4.2 saw uv differ so while every hit, t and object agreed."""


def assert_same(h: Hits, ref: Hits) -> None:
    """Every field bit for bit (uv to UV_ROUNDING)."""
    for f in fields(Hits):
        got, want = getattr(h, f.name), getattr(ref, f.name)
        if f.name == "uv":
            assert np.allclose(got, want, rtol=0, atol=UV_ROUNDING, equal_nan=True), f.name
        else:
            assert np.array_equal(got, want), f.name


def _mesh(centre, size, rng):
    """A closed octahedron: faces meet at edges and corners (ties between faces)."""
    v = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float)
    f = [[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]]
    return TriangleMesh(centre + size * v, f, color=rng.uniform(0, 1, 4))


def mixed_scene(count=600, rng=RNG):
    """Many small spheres (plain, textured, twins at one place for exact ties), thin
    rectangles (axis-aligned: a box of zero thickness), an infinite plane, annuli,
    meshes and a nested group; ids mixed with None (the member's own)."""
    centres = rng.uniform(-6, 6, (count, 3))
    objects = [Sphere(c, rng.uniform(0.02, 0.4), color=rng.uniform(0, 1, 4), object_id=7)
               for c in centres]  # fmt: skip
    for k in (3, 9):  # an equal sphere at the same place, another colour and id
        objects.append(Sphere(objects[k].center, objects[k].radius, color=(1, 0, 0, 1)))
        objects[-1].twin = objects[k]
    objects += [Sphere(c, 0.3, color=checker(4, 4)) for c in rng.uniform(-6, 6, (20, 3))]
    objects += [Plane(rng.uniform(-5, 5, 3), np.eye(3)[k % 3], extent=(1.5, 0.7), object_id=3)
                for k in range(12)]  # fmt: skip
    objects += [
        Plane(rng.uniform(-5, 5, 3), rng.normal(size=3), extent=(1, 2), color=checker(3, 3))
    ]
    objects += [Plane((0, 0, -5.5), (0, 0, 1), color=checker(8, 8))]  # infinite bounds
    objects += [Disk(rng.uniform(-5, 5, 3), rng.normal(size=3), 0.1, 0.6) for _ in range(6)]
    objects += [_mesh(rng.uniform(-5, 5, 3), 0.5, rng) for _ in range(4)]
    objects += [Group([Sphere(rng.uniform(-5, 5, 3), 0.2) for _ in range(12)], ids=[None] * 12)]
    ids = [None if k % 5 == 0 else 100 + k for k in range(len(objects))]
    order = rng.permutation(len(objects))  # kinds interleaved in the list
    return [objects[k] for k in order], [ids[k] for k in order]


def segments(rng=RNG, n=6000):
    """Short and long, zero-length, grazing and straight-to-far segments."""
    a = rng.uniform(-7, 7, (n, 3))
    b = a + rng.normal(size=(n, 3)) * rng.choice([0.3, 2.0, 20.0], size=(n, 1))
    b[:200] = a[:200]  # zero length
    b[200:400] = a[200:400] + 1e12 * rng.normal(size=(200, 3))  # a straight ray's cast
    return a, b


def grazing(objects, rng=RNG):
    """Segments along the faces of the members' boxes and tangent to spheres."""
    a, b = [], []
    for obj in objects[:300]:
        lo, hi = (np.asarray(x, float) for x in obj.bounds)
        if not np.all(np.isfinite(lo) & np.isfinite(hi)):
            continue
        axis = rng.integers(3)
        p = rng.uniform(lo, hi)
        p[axis] = hi[axis]  # on the box's face
        d = rng.normal(size=3)
        d[axis] = 0.0
        a += [p - d, hi, lo]
        b += [p + d, hi + np.eye(3)[axis], lo - 1e-300]
        if isinstance(obj, Sphere):
            n = rng.normal(size=3)
            n /= np.linalg.norm(n)
            t = np.cross(n, rng.normal(size=3))
            touch = obj.center + obj.radius * n
            a += [touch - t]
            b += [touch + t]
    return np.array(a), np.array(b)


def test_tree_equals_brute_force_on_mixed_scenes():
    objects, ids = mixed_scene()
    group = Group(objects, ids=ids)
    assert group._broad is not None  # the tree is in use
    a, b = segments()
    ga, gb = grazing(objects)
    a, b = np.concatenate([a, ga]), np.concatenate([b, gb])
    h = group.intersect(a, b)
    ref = brute_force(objects, ids, a, b)
    assert_same(h, ref)
    assert_same(group.intersect_each(a, b), ref)
    assert ref.hit.sum() > 1000 and (ref.object_id == 7).any()  # the test sees hits
    for twin in (k for k, o in enumerate(objects) if getattr(o, "twin", None) is not None):
        first = min(twin, objects.index(objects[twin].twin))  # exact ties: the earlier wins
        tied = objects[twin].intersect(a, b).hit & (ref.t == objects[twin].intersect(a, b).t)
        assert tied.any()
        expect = objects[first].object_id if ids[first] is None else ids[first]
        assert np.all(h.object_id[tied] == expect)


def test_tree_equals_brute_force_with_footprints():
    objects, ids = mixed_scene(count=200, rng=np.random.default_rng(7))
    group = Group(objects, ids=ids)
    assert group.filters
    a, b = segments(np.random.default_rng(8), 3000)
    footprint = np.random.default_rng(9).normal(scale=0.01, size=(a.shape[0], 2, 3))
    assert_same(group.intersect(a, b, footprint), brute_force(objects, ids, a, b, footprint))


@pytest.mark.parametrize("count", [9, 100, 5000])
def test_many_small_spheres_equal_brute_force(count):
    rng = np.random.default_rng(count)
    centres = rng.uniform(-10, 10, (count, 3))
    objects = [Sphere(c, 11.8 / np.sqrt(count), color=rng.uniform(0, 1, 4)) for c in centres]
    ids = list(range(count))
    a = np.tile([0.0, -30.0, 2.0], (4000, 1))
    b = a + 1e12 * np.column_stack([rng.uniform(-0.4, 0.4, 4000), np.ones(4000),
                                    rng.uniform(-0.4, 0.4, 4000)])  # fmt: skip
    c, d = segments(rng, 4000)
    a, b = np.concatenate([a, c * 1.5]), np.concatenate([b, d * 1.5])
    h = Group(objects).intersect(a, b)
    assert_same(h, brute_force(objects, ids, a, b))
    assert h.hit.mean() > 0.2


def test_windows_walk_long_segments_nearest_first(monkeypatch):
    """Windows of one leaf, or one cell, (many per segment) find the same hits as one
    window for all."""
    objects, ids = mixed_scene(count=400, rng=np.random.default_rng(3))
    a, b = segments(np.random.default_rng(4), 3000)
    ref = brute_force(objects, ids, a, b)
    with monkeypatch.context() as m:
        m.setattr(boxgrid, "WINDOW", 1)
        m.setattr(boxgrid, "LONGEST", 1)
        group = Group(objects, ids=ids)
        assert isinstance(group._broad.index, boxgrid.BoxGrid)
        assert_same(group.intersect(a, b), ref)
    monkeypatch.setattr(core.geometry.boxtree, "WINDOW", 1)
    monkeypatch.setattr(boxgrid, "CROWD", 0.0)  # the tree instead of the grid
    group = Group(objects, ids=ids)
    assert isinstance(group._broad.index, core.geometry.boxtree.BoxTree)
    assert_same(group.intersect(a, b), ref)


def test_grid_with_mixed_sizes_equals_brute_force():
    """Many small spheres, a few big ones (beside the grid, in its own tree), rectangles,
    annuli, meshes and an infinite plane: the grid's hits equal the brute force's."""
    rng = np.random.default_rng(451)
    objects, ids = mixed_scene(count=3000, rng=rng)
    radii = (1.5, 2.0, 2.5, 3.0, 1.2, 4.0)
    big = [Sphere(c, r, color=rng.uniform(0, 1, 4))
           for c, r in zip(rng.uniform(-5, 5, (6, 3)), radii, strict=True)]  # fmt: skip
    objects, ids = [*big, *objects], [*range(900, 906), *ids]
    group = Group(objects, ids=ids)
    index = group._broad.index
    assert isinstance(index, boxgrid.BoxGrid) and index.tree is not None
    assert {0, 1, 2, 3, 5} <= set(group._broad.boxed[index.rest].tolist())
    a, b = segments(rng, 5000)
    ga, gb = grazing(objects, rng)
    a, b = np.concatenate([a, ga]), np.concatenate([b, gb])
    ref = brute_force(objects, ids, a, b)
    assert_same(group.intersect(a, b), ref)
    assert np.isin(ref.object_id, range(900, 906)).any()  # the big ones are hit


def test_grid_sends_far_segments_to_a_tree():
    """Segments starting farther than the grid's margin covers (1e-4 cell widths over
    boxtree.PAD) walk a tree over its boxes: the same hits as the brute force, near and
    far segments mixed. (From 1e6 away, tree and grid alike lose a few grazing hits of
    these small spheres, whose arithmetic rounds at 1e-3 there.)"""
    rng = np.random.default_rng(452)
    objects = [Sphere(c, 0.05, color=rng.uniform(0, 1, 4)) for c in rng.uniform(-3, 3, (4000, 3))]
    ids = list(range(len(objects)))
    group = Group(objects)
    index = group._broad.index
    assert isinstance(index, boxgrid.BoxGrid)
    target = rng.uniform(-3, 3, (3000, 3))
    away = rng.normal(size=(3000, 3))
    away *= 3e4 / np.linalg.norm(away, axis=1, keepdims=True)
    a = np.where(np.arange(3000)[:, None] % 2, target * 2, away)
    b = a + 3 * (target - a)
    ref = brute_force(objects, ids, a, b)
    far = core.geometry.boxtree.segments(a, b).reach > index.near
    assert far.sum() == 1500
    assert_same(group.intersect(a, b), ref)
    assert ref.hit[far].any() and ref.hit[~far].any()


def test_crowded_boxes_take_the_tree():
    """Boxes clustered far from the rest crowd a grid's cells: the tree is used, with the
    brute force's hits."""
    rng = np.random.default_rng(453)
    centres = np.concatenate(
        [rng.normal(scale=0.01, size=(2000, 3)), rng.uniform(-50, 50, (20, 3))]
    )
    objects = [Sphere(c, 0.005, color=rng.uniform(0, 1, 4)) for c in centres]
    group = Group(objects)
    assert isinstance(group._broad.index, core.geometry.boxtree.BoxTree)
    a = rng.normal(scale=0.02, size=(3000, 3)) + (0, -1, 0)
    b = a + (0, 2, 0)
    ref = brute_force(objects, list(range(len(objects))), a, b)
    assert_same(group.intersect(a, b), ref)
    assert ref.hit.mean() > 0.1


def test_render_unchanged_by_the_tree(monkeypatch):
    """Images of a sphere cloud through the tree equal those of the brute force, flat and
    around a hole."""
    rng = np.random.default_rng(45)
    centres = rng.normal(size=(14, 3)) * 5
    centres = centres[np.linalg.norm(centres, axis=1) > 3]  # 10 (> FEW), off the hole
    spheres = [Sphere(c, 1.2, color=rng.uniform(0, 1, 4)) for c in centres]
    assert len(spheres) > group_module.FEW
    camera = core.Camera.perspective(position=(0, -25, 3), look_at=(0, 0, 0), up=(0, 0, 1),
                                     fov_deg=45, width=12, height=8)  # fmt: skip
    for model in (None, core.hamiltonians.schwarzschild(rg=1.0)):
        scene = core.Scene(model=model, objects=spheres, background="procedural")
        tree = core.render(scene, camera, workers=1)
        with monkeypatch.context() as m:
            m.setattr(group_module, "FEW", 10**9)
            each = core.render(scene, camera, workers=1)
        assert np.array_equal(tree.rgba, each.rgba)
        assert np.array_equal(tree.passes["ending"], each.passes["ending"])
        assert (tree.passes["ending"] == core.ENDING["hit"]).mean() > 0.1


def test_few_members_are_asked_in_turn():
    objects = [Sphere((k, 0, 0), 0.4) for k in range(group_module.FEW)]
    assert Group(objects)._broad is None
    assert Group([*objects, Sphere((9, 0, 0), 0.4)])._broad is not None


def test_sphere_records_follow_their_attributes():
    """What a Group reads of a Sphere (its record, Sphere._row) follows its centre, radius
    and colour as set, its centre as written in place, and survives pickling."""
    rng = np.random.default_rng(46)
    objects = [Sphere(c, 0.3, color=rng.uniform(0, 1, 3)) for c in rng.uniform(-4, 4, (60, 3))]
    objects[0].center = (0.5, 0.5, 0.5)
    objects[1].radius = 0.9
    objects[2].color = checker(2, 2)  # a texture: asked in turn
    objects[3].color = (1, 0, 0)
    objects[4] = pickle.loads(pickle.dumps(objects[4]))
    old = Sphere.__new__(Sphere)  # as pickled before the record
    old.__setstate__({"center": objects[6].center.copy(), "radius": 0.3, "object_id": 0,
                      "color": objects[6].color.copy(), "bounds": objects[6].bounds})  # fmt: skip
    assert np.array_equal(old._row, objects[6]._row)
    objects[5].center[1] += 0.25
    assert objects[5].center[1] == objects[5]._row[1] and objects[4]._view.obj is objects[4]._row
    broad = Group(objects)._broad
    assert np.array_equal(broad.centre, [o.center for k, o in enumerate(objects) if k != 2])
    assert broad.radius2[1] == 0.9**2 and np.array_equal(broad.colour[2], (1, 0, 0, 1))
    a, b = segments(rng, 3000)
    ids = list(range(len(objects)))
    objects[5].center = objects[5].center  # its bounds too, as the brute force reads them
    assert_same(Group(objects).intersect(a, b), brute_force(objects, ids, a, b))

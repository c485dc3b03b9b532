"""Intersectors against analytic and brute-force references; volumes against scipy quad."""

import numpy as np
import pytest

from core.intersect import (
    Disk,
    Group,
    Hits,
    Plane,
    Sphere,
    TriangleMesh,
    Volume,
    checker,
    colormap,
    segment_overlaps,
)

RNG = np.random.default_rng(12345)


def _random_segments(n, scale=3.0, length=4.0):
    a = RNG.uniform(-scale, scale, (n, 3))
    b = a + RNG.normal(size=(n, 3)) * length / np.sqrt(3)
    return a, b


# -- spheres -------------------------------------------------------------------------------


def _sphere_reference(a, b, c, r):
    """Geometric construction (closest approach along the unit direction), one segment."""
    d = b - a
    length = np.linalg.norm(d)
    u = d / length
    m = a - c
    t_ca = -m @ u
    dist2 = m @ m - t_ca**2
    if dist2 > r * r:
        return None
    thc = np.sqrt(r * r - dist2)
    for s in (t_ca - thc, t_ca + thc):
        if 0 <= s <= length:
            return s / length
    return None


def test_sphere_hits_match_geometric_reference():
    c, r = np.array([0.3, -0.2, 0.1]), 1.3
    sph = Sphere(c, r, color=(1, 0, 0, 1), object_id=7)
    a, b = _random_segments(2000)
    h = sph.intersect(a, b)
    for i in range(len(a)):
        t = _sphere_reference(a[i], b[i], c, r)
        assert h.hit[i] == (t is not None)
        if t is not None:
            assert h.t[i] == pytest.approx(t, abs=1e-12)
    assert h.hit.sum() > 100
    p = h.position[h.hit]
    assert np.allclose(np.linalg.norm(p - c, axis=1), r)
    assert np.allclose(h.normal[h.hit], (p - c) / r)
    assert np.all(h.object_id[h.hit] == 7) and np.all(h.object_id[~h.hit] == -1)
    assert np.all(h.color[h.hit] == [1, 0, 0, 1]) and np.all(np.isinf(h.t[~h.hit]))


def test_sphere_simple_cases():
    sph = Sphere((0, 0, 0), 1.0)
    a = np.array([[0, 0, -5.0], [0, 0, 0], [0, 0, -5], [0, 2, -5]])
    b = np.array([[0, 0, 5.0], [0, 0, 4], [0, 0, -2], [0, 2, 5]])
    h = sph.intersect(a, b)
    assert h.hit.tolist() == [True, True, False, False]
    assert h.t[0] == pytest.approx(0.4) and np.allclose(h.normal[0], [0, 0, -1])
    assert h.t[1] == pytest.approx(0.25)  # from inside: the exit point
    assert np.allclose(h.uv[0], [0.5, 0.0])  # south pole


# -- planes and disks ------------------------------------------------------------------------


def test_plane_infinite_and_finite():
    inf = Plane((0, 0, 1), (0, 0, 1), color=(0, 1, 0))
    a = np.array([[0.2, 0.3, 3.0], [5, 5, 3], [0, 0, 0.5]])
    b = np.array([[0.2, 0.3, -1.0], [5, 5, -1], [1, 0, 0.5]])
    h = inf.intersect(a, b)
    assert h.hit.tolist() == [True, True, False]
    assert h.t[0] == pytest.approx(0.5) and np.allclose(h.position[0], [0.2, 0.3, 1])
    assert np.allclose(h.color[0], [0, 1, 0, 1])
    assert inf.bounds[0][2] == 1 and inf.bounds[1][2] == 1 and np.isinf(inf.bounds[0][0])
    fin = Plane((0, 0, 1), (0, 0, 1), u_axis=(1, 0, 0), extent=(2.0, 1.0))
    h = fin.intersect(a, b)
    assert h.hit.tolist() == [True, False, False]
    assert np.allclose(h.uv[0], [0.2 / 2 + 0.5, 0.3 / 1 + 0.5])
    assert np.allclose(fin.bounds[0], [-1, -0.5, 1]) and np.allclose(fin.bounds[1], [1, 0.5, 1])


def test_disk_annulus_uv():
    disk = Disk((0, 0, 0), (0, 0, 1), 1.0, 3.0, u_axis=(1, 0, 0))
    pts = np.array([[2.0, 0, 0], [0, 2.0, 0], [0.5, 0, 0], [0, -2.9, 0], [3.1, 0, 0]])
    h = disk.intersect(pts + [0, 0, 1], pts - [0, 0, 1])
    assert h.hit.tolist() == [True, True, False, True, False]
    assert np.allclose(h.uv[0], [0.5, 0.0])
    assert np.allclose(h.uv[1], [0.5, 0.25])
    assert np.allclose(h.uv[3], [0.95, 0.75])
    tilted = Disk((1, 2, 3), (0, 1, 1), 0.0, 2.0)
    a, b = _random_segments(3000, scale=4)
    hit = tilted.intersect(a, b)
    p = hit.position[hit.hit]
    assert hit.hit.sum() > 20
    assert np.all((p >= tilted.bounds[0] - 1e-12) & (p <= tilted.bounds[1] + 1e-12))


def test_checker_texture_and_texture_callback():
    tex = checker(4, 2, (1, 1, 1), (0, 0, 0))
    uv = np.array([[0.1, 0.1], [0.3, 0.1], [0.3, 0.6], [0.9, 0.9]])
    c = tex(uv, np.zeros((4, 3)), np.zeros((4, 3)))
    assert c[:, 0].tolist() == [1, 0, 1, 1] and np.all(c[:, 3] == 1)
    seen = {}

    def texture(uv, position, normal):
        seen["n"] = len(uv)
        return np.concatenate([uv, position[:, :1]], axis=1)  # rgb: alpha becomes 1

    plane = Plane((0, 0, 0), (0, 0, 1), color=texture, extent=(2, 2), u_axis=(1, 0, 0))
    h = plane.intersect([[0.5, 0.5, 1], [9, 9, 1]], [[0.5, 0.5, -1], [9, 9, -1]])
    assert seen["n"] == 1  # evaluated at hit points only
    assert np.allclose(h.color[0], [0.75, 0.75, 0.5, 1])


# -- triangle meshes -------------------------------------------------------------------------


def _triangle_reference(a, b, tri):
    """Plane intersection + inside test by edge cross products (one segment, one triangle)."""
    v0, v1, v2 = tri
    n = np.cross(v1 - v0, v2 - v0)
    d = b - a
    den = n @ d
    if abs(den) < 1e-300:
        return None
    t = n @ (v0 - a) / den
    if not 0 <= t <= 1:
        return None
    p = a + t * d
    for e0, e1 in [(v0, v1), (v1, v2), (v2, v0)]:
        if np.cross(e1 - e0, p - e0) @ n < -1e-12 * (n @ n):
            return None
    return t


def test_moller_trumbore_matches_brute_force_loop():
    tri = RNG.uniform(-2, 2, (200, 1, 3)) + RNG.normal(size=(200, 3, 3)) * 0.6
    verts = tri.reshape(-1, 3)
    faces = np.arange(verts.shape[0]).reshape(-1, 3)
    mesh = TriangleMesh(verts, faces, block=32, max_pairs=500)  # many blocks and chunks
    a, b = _random_segments(60, scale=2.5)
    h = mesh.intersect(a, b)
    for i in range(len(a)):
        ts = [(t, f) for f in range(len(faces))
              if (t := _triangle_reference(a[i], b[i], verts[faces[f]])) is not None]  # fmt: skip
        assert h.hit[i] == bool(ts), i
        if ts:
            t, f = min(ts)
            assert h.t[i] == pytest.approx(t, abs=1e-10)
            n = np.cross(*(verts[faces[f]][1:] - verts[faces[f]][0]))
            assert np.allclose(h.normal[i], n / np.linalg.norm(n))
    assert 15 < h.hit.sum() < 60


def test_flat_axis_aligned_mesh_matches_plane():
    """Zero-thickness boxes and axis-parallel segments (1/d infinite) in the BVH traversal."""
    n = 12
    x, y = np.meshgrid(np.linspace(-1, 1, n + 1), np.linspace(-1, 1, n + 1))
    verts = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
    idx = np.arange(verts.shape[0]).reshape(n + 1, n + 1)
    q = [idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel(), idx[1:, :-1].ravel()]
    faces = np.concatenate([np.stack([q[0], q[1], q[2]], 1), np.stack([q[0], q[2], q[3]], 1)])
    mesh = TriangleMesh(verts, faces, block=4)
    plane = Plane((0, 0, 0), (0, 0, 1), extent=(2, 2), u_axis=(1, 0, 0))
    top = np.column_stack([RNG.uniform(-1.2, 1.2, (500, 2)), np.full(500, 0.7)])
    for bottom in (top * [1, 1, -1], top * [1, 1, -1] + RNG.normal(size=(500, 3)) * [0.5, 0.5, 0]):
        h, ref = mesh.intersect(top, bottom), plane.intersect(top, bottom)
        inside = np.all(np.abs(ref.position[:, :2]) < 1 - 1e-9, axis=1) | ~ref.hit
        assert np.array_equal(h.hit[inside], ref.hit[inside])
        assert np.allclose(h.t[h.hit], 0.5) and np.allclose(np.abs(h.normal[h.hit, 2]), 1)
    along = mesh.intersect([[-2, 0.1, 0.0]], [[2, 0.1, 0.0]])  # in the plane: no hit
    assert not along.hit[0]


def test_mesh_uvs_bounds_and_degenerate_faces():
    verts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 2, 0]], float)
    faces = np.array([[0, 1, 2], [0, 3, 3]])  # the second is degenerate
    uvs = np.array([[[0, 0], [1, 0], [0, 1]], [[0, 0], [0, 0], [0, 0]]], float)
    mesh = TriangleMesh(verts, faces, uvs=uvs, color=(0, 0, 1, 1))
    centroid = verts[:3].mean(axis=0)
    a = [centroid + [0, 0, 1], [1.5, 1.5, 1]]
    h = mesh.intersect(a, [centroid - [0, 0, 1], [1.5, 1.5, -1]])
    assert h.hit.tolist() == [True, False]
    assert np.allclose(h.uv[0], [1 / 3, 1 / 3]) and np.allclose(h.normal[0], [0, 0, 1])
    assert np.allclose(mesh.bounds[0], 0) and np.allclose(mesh.bounds[1], [2, 2, 0])
    with pytest.raises(ValueError):
        TriangleMesh(verts, [[0, 1, 9]])


# -- groups --------------------------------------------------------------------------------------


class _Spy:
    def __init__(self, obj):
        self.obj, self.bounds, self.rows = obj, obj.bounds, 0

    def intersect(self, a, b):
        self.rows += len(a)
        return self.obj.intersect(a, b)


def test_group_nearest_hit_ids_and_aabb_culling():
    objs = [Sphere((0, 0, 0), 1.0), Sphere((0, 0, 2.5), 1.0), Plane((0, 0, -3), (0, 0, 1)),
            Disk((5, 5, 5), (1, 0, 0), 0.2, 0.5)]  # fmt: skip
    spies = [_Spy(o) for o in objs]
    group = Group(spies, ids=[10, 11, 12, 13])
    a, b = _random_segments(4000, scale=4, length=2)
    h = group.intersect(a, b)
    ref = [o.intersect(a, b) for o in objs]
    t_all = np.stack([r.t for r in ref])
    nearest = np.argmin(t_all, axis=0)
    any_hit = np.isfinite(t_all).any(axis=0)
    assert np.array_equal(h.hit, any_hit)
    assert np.allclose(h.t[any_hit], t_all.min(axis=0)[any_hit])
    assert np.array_equal(h.object_id[any_hit], 10 + nearest[any_hit])
    for spy, obj in zip(spies, objs, strict=True):
        assert spy.rows == segment_overlaps(a, b, *obj.bounds).sum() < len(a)
    assert np.allclose(group.bounds[0][2], -3) and np.allclose(group.bounds[1][2], 5.5)


def test_group_default_ids_and_empty():
    g = Group([Sphere((0, 0, 0), 1), Sphere((3, 0, 0), 1)])
    h = g.intersect([[3, 0, -5]], [[3, 0, 5]])
    assert h.object_id[0] == 1
    empty = Group([]).intersect(np.zeros((2, 3)), np.ones((2, 3)))
    assert not empty.hit.any() and len(Hits.miss(3)) == 3


# -- volumes ---------------------------------------------------------------------------------


def _field(p):
    p = np.atleast_2d(p)
    return 0.5 + 0.3 * np.sin(p[:, 0]) * np.cos(2 * p[:, 1]) + 0.2 * p[:, 2] ** 2


def _emission(p):
    p = np.atleast_2d(p)
    x, y, z = p.T
    return np.stack([1 + x**2, np.exp(-(y**2)), 0.5 + 0.4 * np.cos(3 * z)], axis=1)


def _quad_reference(a, b, lo, hi, absorption, emission):
    """Radiance and transmittance along a -> b by nested scipy quad, clipped to the box."""
    quad = pytest.importorskip("scipy.integrate").quad
    d = b - a
    length = np.linalg.norm(d)
    with np.errstate(divide="ignore"):
        t_lo, t_hi = (lo - a) / d, (hi - a) / d
    t0 = max(0.0, np.max(np.minimum(t_lo, t_hi)))
    t1 = min(1.0, np.min(np.maximum(t_lo, t_hi)))

    def sigma(s):
        return absorption * _field(a + s / length * d)[0]

    def tau(s):
        return quad(sigma, t0 * length, s, epsabs=1e-13, epsrel=1e-13)[0]

    rad = [quad(lambda s, c=c: np.exp(-tau(s)) * emission(a + s / length * d)[0, c],
                t0 * length, t1 * length, epsabs=1e-12, epsrel=1e-12)[0]
           for c in range(3)]  # fmt: skip
    return np.array(rad), np.exp(-tau(t1 * length))


def test_volume_matches_scipy_quad():
    lo, hi = np.array([-1.0, -1.5, -1.0]), np.array([2.0, 1.0, 1.5])
    vol = Volume(lo, hi, _field, _emission, absorption=0.8)
    a = np.array([[-3.0, -0.4, 0.2], [0.5, 0.0, 0.0], [-2.0, -2.0, -2.0]])
    b = np.array([[4.0, 0.5, -0.3], [1.5, 0.8, 1.2], [3.0, 2.0, 2.5]])
    rad, trans = vol.segment(a, b)
    for i in range(len(a)):
        ref_rad, ref_trans = _quad_reference(a[i], b[i], lo, hi, 0.8, _emission)
        assert np.allclose(rad[i], ref_rad, rtol=1e-6, atol=1e-6)
        assert trans[i] == pytest.approx(ref_trans, rel=1e-6, abs=1e-6)
    assert np.all(trans < 0.9)


def test_volume_accumulate_composites_front_to_back():
    cmap = colormap([(0.0, (0, 0, 0)), (1.0, (1, 0.5, 0.25))])
    vol = Volume((-1, -1, -1), (1, 1, 1), _field, colormap=cmap, absorption=1.3)
    a = np.array([[-2.0, 0.1, 0.2], [-2, 5, 5]])
    b = np.array([[2.0, -0.3, 0.1], [2, 5, 5]])
    whole = vol.accumulate(a, b, np.zeros((2, 3)), np.ones(2))
    mid = a + 0.37 * (b - a)
    first = vol.accumulate(a, mid, np.zeros((2, 3)), np.ones(2))
    split = vol.accumulate(mid, b, *first)
    assert np.allclose(split[0], whole[0], rtol=1e-10) and np.allclose(split[1], whole[1])
    assert np.all(whole[0][1] == 0) and whole[1][1] == 1  # the miss is untouched
    ref_rad, ref_trans = _quad_reference(a[0], b[0], -np.ones(3), np.ones(3), 1.3,
                                         lambda p: cmap(_field(p)))  # fmt: skip
    assert np.allclose(whole[0][0], ref_rad, rtol=1e-6) and whole[1][0] == pytest.approx(ref_trans)


def test_volume_validation():
    with pytest.raises(ValueError):
        Volume((0, 0, 0), (1, 0, 1), _field, _emission)
    with pytest.raises(ValueError):
        Volume((0, 0, 0), (1, 1, 1), _field)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_vertices_and_bounds_are_refused(bad):
    """A mesh with one non-finite vertex is refused by name, never built with NaN bounds
    (which would make every segment miss everything); so is a group member whose bounds
    are NaN (an intersector made elsewhere)."""
    verts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [bad, 2, 0]], float)
    with pytest.raises(ValueError, match="vertices must be finite"):
        TriangleMesh(verts, [[0, 1, 2], [1, 2, 3]])

    class Broken:
        bounds = (np.array([0.0, np.nan, 0.0]), np.ones(3))

        def intersect(self, a, b):
            return Hits.miss(len(a))

    with pytest.raises(ValueError, match="object 1 has NaN bounds"):
        Group([Sphere((0, 0, 0), 1.0), Broken()])

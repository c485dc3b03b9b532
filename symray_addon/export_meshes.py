"""Evaluated meshes -> a BVH intersector implementing the core's Intersector seam.

``build_intersector(depsgraph)`` reads every visible object's evaluated mesh (modifiers,
geometry nodes and instances applied) on the main thread, in world space, triangulated,
into one ``mathutils.bvhtree.BVHTree``. An object with a ``BakedSurface`` (bake.py) shows
its baked radiance texture on the UV map it was baked on; the others show their materials
as ``materials.material_sampler`` reads them. The ``BVHIntersector`` it returns holds no bpy
data (only numpy arrays, material samplers and the tree), so the core may call
``intersect`` from a worker thread.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import bpy
import numpy as np
from mathutils.bvhtree import BVHTree

from ..core.geometry.boxcells import ManyBoxes
from ..core.geometry.boxtree import morton
from ..core.intersect import Hits, TriangleMesh, barycentric_gradients
from .materials import MaterialSampler, material_sampler, unsupported_nodes
from .objects import in_collections, rendering_collections

GEOMETRY_TYPES = {"MESH", "CURVE", "SURFACE", "FONT", "META"}
CURVE_TYPES = {"CURVE", "FONT"}
"""Objects whose surface the depsgraph lists again as a mesh instance of their own."""
_UNUSED_LEVEL = 2**31 - 1
"""``persistent_id`` entry of the instancing levels below a dupli's own."""


@dataclass
class BakedSurface:
    """An object's baked radiance: an image on a UV map of its evaluated mesh."""

    pixels: np.ndarray
    """(h, w, 4) float32 linear RGBA, row 0 at the bottom (Blender's order)."""
    loop_uv: np.ndarray | None = None
    """(L, 2) UVs per loop of the evaluated mesh it was baked on; None: its active UV map."""

    def sampler(self) -> MaterialSampler:
        """The texture as a material sampler (bilinear, clamped at the image's edges)."""
        return MaterialSampler(np.ones(4), self.pixels, extension="EXTEND")


FLOAT32_SLACK = 4e-6
"""Distance (relative to the coordinates' size, 1 + max |x|) within which a float32
BVHTree cannot tell which side of a surface a point is on: 30 float32 epsilons."""


NUMPY_TRIANGLES = 32
"""Scenes' meshes of at most this many triangles in all (a floor, a cube) are hit in numpy,
all of a batch's segments at once (core.TriangleMesh: float64 Möller–Trumbore); more go
through Blender's BVHTree, one ray_cast per segment in a Python loop, ~1.9 us a segment
against 0.15 us in numpy for a few triangles (2000 segments; 64 triangles: on a par). A
floor under the hole and disk made 3.5 million such calls in a 480x270 frame (issue 51)."""
PART_BOXES = 4096
"""Boxes the clearances and the near tests see at most (beyond FEW_PARTS tested all at once:
core.geometry.boxcells.ManyBoxes; the clearance's broad phase likewise): beyond, objects
share boxes (in the order of their centres along a Morton curve)."""
FEW_PARTS = 16
"""Up to this many part boxes, a segment is tested against each in turn."""


def part_bounds(corners: np.ndarray, tri_object: np.ndarray) -> list[tuple]:
    """(lo, hi, id) boxes of the objects whose triangles have ``corners`` (T, 3, 3) and ids
    ``tri_object`` (T,): one per object, or PART_BOXES of neighbouring objects when there
    are more (id -3, no object's own: a hit there counts as near the others)."""
    ids, inverse = np.unique(tri_object, return_inverse=True)
    lo = np.full((ids.size, 3), np.inf)
    hi = np.full((ids.size, 3), -np.inf)
    np.minimum.at(lo, inverse, corners.min(axis=1))
    np.maximum.at(hi, inverse, corners.max(axis=1))
    if ids.size <= PART_BOXES:
        return [(lo[k], hi[k], int(ids[k])) for k in range(ids.size)]
    centres = 0.5 * (lo + hi)
    order = np.argsort(morton(centres, centres.min(axis=0), centres.max(axis=0)), kind="stable")
    boxes = []
    for chunk in np.array_split(order, PART_BOXES):
        own = int(ids[chunk[0]]) if chunk.size == 1 else -3
        boxes.append((lo[chunk].min(axis=0), hi[chunk].max(axis=0), own))
    return boxes


class BVHIntersector:
    """Straight-segment queries against triangles in a BVH (core Intersector protocol)."""

    def __init__(
        self,
        vertices: np.ndarray,
        triangles: np.ndarray,
        tri_object: np.ndarray,
        tri_material: np.ndarray,
        tri_uv: np.ndarray,
        materials: Sequence[MaterialSampler],
        names: Sequence[str] = (),
    ) -> None:
        """Build from world-space ``vertices`` (V, 3) and ``triangles`` (T, 3) indices.

        ``tri_object`` (T,) object ids, ``tri_material`` (T,) indices into ``materials``,
        ``tri_uv`` (T, 3, 2) UVs of each triangle's corners, ``names`` object names by id.
        """
        self.vertices = np.ascontiguousarray(vertices, dtype=np.float64).reshape(-1, 3)
        if not np.all(np.isfinite(self.vertices)):
            raise ValueError("BVHIntersector needs finite vertices (NaN or infinity found)")
        self.triangles = np.ascontiguousarray(triangles, dtype=np.int64).reshape(-1, 3)
        if len(self.triangles) == 0:
            raise ValueError("BVHIntersector needs at least one triangle")
        self.tri_object = np.asarray(tri_object, dtype=np.int32)
        self.tri_material = np.asarray(tri_material, dtype=np.int64)
        self.tri_uv = np.asarray(tri_uv, dtype=np.float64).reshape(-1, 3, 2)
        self.materials = list(materials)
        self.names = list(names)
        self.bounds = (self.vertices.min(axis=0), self.vertices.max(axis=0))
        self.part_bounds = part_bounds(self.vertices[self.triangles], self.tri_object)
        """(lo, hi, object id) of the objects (core.tracing.segments: clearances)."""
        self._parts = None
        """Beyond FEW_PARTS, the part boxes indexed to be tested at once (_near_parts)."""
        if len(self.part_bounds) > FEW_PARTS:
            lo, hi = (np.array([box[k] for box in self.part_bounds]) for k in (0, 1))
            self._parts = ManyBoxes(lo, hi)
        tri = self.vertices[self.triangles]
        e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
        normal = np.cross(e1, e2)
        norm = np.linalg.norm(normal, axis=1, keepdims=True)
        self.face_normals = normal / np.where(norm > 0.0, norm, 1.0)  # as ray_cast reports
        # per face: barycentric weights w1, w2 of a point p are rows of _bary @ (p - v0)
        self._bary = barycentric_gradients(e1, e2)
        self.filters = any(m.filters for m in self.materials)
        """Whether a material averages over footprints (core.geometry.hits)."""
        self._tree = BVHTree.FromPolygons(
            self.vertices.tolist(), self.triangles.tolist(), all_triangles=True, epsilon=0.0
        )
        self._few = None
        if len(self.triangles) <= NUMPY_TRIANGLES:
            self._few = TriangleMesh(self.vertices, self.triangles)

    def __len__(self) -> int:
        """Number of triangles."""
        return len(self.triangles)

    def ray_cast(
        self, origin: Sequence[float], direction: Sequence[float], distance: float
    ) -> tuple:
        """``BVHTree.ray_cast`` on the underlying tree (location, normal, index, distance)."""
        return self._tree.ray_cast(origin, direction, distance)

    def intersect(self, a: np.ndarray, b: np.ndarray, footprint: np.ndarray | None = None) -> Hits:
        """First hit along each straight segment a -> b ((N, 3) world space), as Hits;
        coloured over each segment's ``footprint`` (N, 2, 3: ∂(hit point)/∂(image x, y))
        where given."""
        a = np.asarray(a, dtype=np.float64).reshape(-1, 3)
        b = np.asarray(b, dtype=np.float64).reshape(-1, 3)
        n = a.shape[0]
        d = b - a
        length = np.sqrt(np.einsum("ij,ij->i", d, d))
        slack = FLOAT32_SLACK * (1.0 + np.abs(a).max(axis=1))
        rows = np.flatnonzero(self._near_parts(a, b, slack) & (length > 0.0))
        # BVHTree works in float32: a segment starting on a surface (a hit point moved onto
        # the method's path: core.tracing.crossings.surface_crossing) may miss it either way. Each
        # cast starts ``slack`` before a; a hit in that slack is a hit at a.
        unit = d[rows] / length[rows, None]
        origins = a[rows] - slack[rows, None] * unit
        found = self._cast(origins, unit, length[rows] + slack[rows])
        hit = ~np.isnan(found[:, 0])
        seen = None if footprint is None else footprint[rows[hit]]
        face = found[hit, 0].astype(np.int64)
        dist = np.maximum(found[hit, 1] - slack[rows[hit]], 0.0)
        return self._hits(n, a, d, length, rows[hit], face, dist, seen)

    def _near_parts(self, a: np.ndarray, b: np.ndarray, slack: np.ndarray) -> np.ndarray:
        """(N,) whether each segment's box meets, within ``slack``, the box of one of the
        objects (``part_bounds``: at most PART_BOXES): only those are cast. A floor under a
        small object made their union's box a slab around everything (issue 51: 3.4 M
        segments cast where 0.2 M were without the floor)."""
        top, bottom = np.maximum(a, b), np.minimum(a, b)
        if self._parts is not None:
            return self._parts.meets((bottom - slack[:, None]).T, (top + slack[:, None]).T)
        near = np.zeros(a.shape[0], dtype=bool)
        for lo, hi, _ in self.part_bounds:
            near |= np.all(top >= lo - slack[:, None], axis=1) & np.all(
                bottom <= hi + slack[:, None], axis=1
            )
        return near

    def _cast(self, origins: np.ndarray, unit: np.ndarray, limit: np.ndarray) -> np.ndarray:
        """(M, 2): the face index and distance of each ray's first hit within ``limit``
        (NaN, NaN on a miss): in numpy for few triangles (NUMPY_TRIANGLES), else one
        BVHTree.ray_cast per ray, keeping only (face index, distance): the hit point and
        the face normal follow in numpy (Vectors are costly to convert)."""
        if self._few is not None:
            found = np.full((origins.shape[0], 2), np.nan)
            rows, t, face = self._few.nearest_faces(origins, origins + limit[:, None] * unit)
            found[rows, 0] = face
            found[rows, 1] = t * limit[rows]
            return found
        cast = self._tree.ray_cast
        hits = [
            cast(origin, direction, far)[2:]
            for origin, direction, far in zip(
                origins.tolist(), unit.tolist(), limit.tolist(), strict=True
            )
        ]
        return np.array(hits, dtype=np.float64).reshape(-1, 2)

    def _hits(
        self,
        n: int,
        a: np.ndarray,
        d: np.ndarray,
        length: np.ndarray,
        rows: np.ndarray,
        face: np.ndarray,
        dist: np.ndarray,
        footprint: np.ndarray | None = None,
    ) -> Hits:
        """Hits for ``n`` segments a -> a + d from the faces and distances of ``rows``,
        coloured over the hits' ``footprint`` (M, 2, 3) where given."""
        hits = Hits.miss(n)
        if len(rows):
            loc = a[rows] + (dist / length[rows])[:, None] * d[rows]
            nor = self.face_normals[face]
            uv = self._uv_at(face, loc)
            hits.hit[rows] = True
            hits.t[rows] = np.clip(dist / length[rows], 0.0, 1.0)
            hits.object_id[rows] = self.tri_object[face]
            hits.position[rows] = loc
            hits.normal[rows] = nor
            hits.uv[rows] = uv
            hits.color[rows] = self._color(face, uv, self._uv_footprint(face, nor, footprint))
        return hits

    def _uv_at(self, face: np.ndarray, point: np.ndarray) -> np.ndarray:
        """UVs at points on triangles ``face``, by barycentric interpolation."""
        r = point - self.vertices[self.triangles[face, 0]]
        w = np.einsum("mkj,mj->mk", self._bary[face], r)  # (M, 2): w1, w2
        corners = self.tri_uv[face]  # (M, 3, 2)
        return (
            corners[:, 0]
            + w[:, :1] * (corners[:, 1] - corners[:, 0])
            + w[:, 1:] * (corners[:, 2] - corners[:, 0])
        )

    def _uv_footprint(self, face: np.ndarray, normal: np.ndarray, footprint) -> np.ndarray | None:
        """∂(u, v)/∂(image x, y) (M, 2, 2) on faces ``face`` from the hit points' derivatives
        ``footprint`` (M, 2, 3), taken into each face's plane; None where not given."""
        if footprint is None:
            return None
        footprint = (
            footprint - np.einsum("mkj,mj->mk", footprint, normal)[..., None] * normal[:, None]
        )
        weights = np.einsum("mij,mkj->mik", self._bary[face], footprint)  # (M, w1 w2, x y)
        corners = self.tri_uv[face]
        edges = np.stack([corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]], axis=2)
        return edges @ weights

    def _color(self, face: np.ndarray, uv: np.ndarray, footprint=None) -> np.ndarray:
        """Material colours (M, 4) at the given hits, over their uv ``footprint`` (M, 2, 2)
        where given."""
        mat = self.tri_material[face]
        out = np.empty((len(face), 4))
        for index in np.unique(mat).tolist():
            mask = mat == index
            seen = None if footprint is None else footprint[mask]
            out[mask] = self.materials[index].sample(uv[mask], seen)
        return out


def _mesh_arrays(mesh: bpy.types.Mesh, loop_uv: np.ndarray | None = None) -> tuple[np.ndarray, ...]:
    """Vertices (V, 3), triangles (T, 3), material slots (T,) and UVs (T, 3, 2): from
    ``loop_uv`` (L, 2) if given and it fits the mesh, else from the active UV map."""
    mesh.calc_loop_triangles()
    nv, nt = len(mesh.vertices), len(mesh.loop_triangles)
    co = np.empty(nv * 3, dtype=np.float64)
    mesh.vertices.foreach_get("co", co)
    tris = np.empty(nt * 3, dtype=np.int32)
    mesh.loop_triangles.foreach_get("vertices", tris)
    loops = np.empty(nt * 3, dtype=np.int32)
    mesh.loop_triangles.foreach_get("loops", loops)
    slots = np.empty(nt, dtype=np.int32)
    mesh.loop_triangles.foreach_get("material_index", slots)
    layer = mesh.uv_layers.active
    if loop_uv is not None and len(loop_uv) == len(mesh.loops):
        uv = np.asarray(loop_uv, dtype=np.float64)[loops].reshape(nt, 3, 2)
    elif layer is not None and len(mesh.loops):
        loop_uv = np.empty(len(mesh.loops) * 2, dtype=np.float64)
        layer.data.foreach_get("uv", loop_uv)
        uv = loop_uv.reshape(-1, 2)[loops].reshape(nt, 3, 2)
    else:
        uv = np.zeros((nt, 3, 2))
    return co.reshape(nv, 3), tris.reshape(nt, 3), slots, uv


def _is_rendered(
    instance: bpy.types.DepsgraphObjectInstance, collections: set[int] | None = None
) -> bool:
    """Whether an instance's own geometry shows in a render (as Cycles decides: a curve or
    text object shows through the mesh instance of its surface, not as itself). An object
    of its own must be in one of ``collections`` when given (a viewport's depsgraph holds
    the collections disabled in renders too; a render's leaves them out)."""
    obj = instance.object
    if obj.type not in GEOMETRY_TYPES or not instance.show_self:
        return False
    if obj.type in CURVE_TYPES and not isinstance(obj.data, bpy.types.Mesh):
        return False
    if instance.is_instance and not own_surface(instance):
        return True
    if collections is not None and not in_collections(obj, collections):
        return False
    return not obj.original.hide_render


def own_surface(instance: bpy.types.DepsgraphObjectInstance) -> bool:
    """Whether an instance is the mesh of a (not instanced) curve or text object's surface:
    its own geometry, rendered and baked as that object."""
    parent = instance.parent
    return (
        instance.is_instance
        and parent is not None
        and parent.original == instance.object.original
        and parent.original.type in CURVE_TYPES
        and instance.persistent_id[1] == _UNUSED_LEVEL
    )


def non_finite_warning(name: str) -> str:
    """The warning for an object left out because of non-finite vertices."""
    return f"Object '{name}' has NaN or infinite vertex coordinates: it is not rendered"


def _note(warnings: list[str] | None, text: str) -> None:
    """Append ``text`` to ``warnings`` unless it is there already."""
    if warnings is not None and text not in warnings:
        warnings.append(text)


def build_intersector(
    depsgraph: bpy.types.Depsgraph,
    baked: Mapping[str, BakedSurface] | None = None,
    warnings: list[str] | None = None,
) -> BVHIntersector | None:
    """A BVHIntersector over every rendered object of ``depsgraph``, or None if there is none.

    ``baked`` maps object names to their bakes (instances are never baked); what the
    unbaked materials use and cannot evaluate is appended to ``warnings``, once each.
    """
    verts, tris, objects, mats, uvs = [], [], [], [], []
    samplers: list[MaterialSampler] = []
    sampler_index: dict[str, int] = {}
    names: list[str] = []
    offset = 0
    collections = None
    if depsgraph.mode == "VIEWPORT" and depsgraph.view_layer is not None:
        collections = rendering_collections(depsgraph.view_layer)
    for instance in depsgraph.object_instances:
        if not _is_rendered(instance, collections):
            continue
        obj = instance.object
        instanced = instance.is_instance and not own_surface(instance)
        surface = None if instanced or not baked else baked.get(obj.name)
        try:
            mesh = obj.to_mesh()
        except RuntimeError:
            continue
        if mesh is None:
            continue
        try:
            co, tri, slots, uv = _mesh_arrays(mesh, None if surface is None else surface.loop_uv)
            materials = [slot.material for slot in obj.material_slots] or list(mesh.materials)
        finally:
            obj.to_mesh_clear()
        if len(tri) == 0:
            continue
        matrix = np.array(instance.matrix_world, dtype=np.float64)
        with np.errstate(invalid="ignore", over="ignore"):  # checked just below
            co = co @ matrix[:3, :3].T + matrix[:3, 3]
        if not np.all(np.isfinite(co)):
            _note(warnings, non_finite_warning(obj.name))
            continue
        if np.linalg.det(matrix[:3, :3]) < 0.0:  # mirrored: keep faces pointing outwards
            tri, uv = tri[:, ::-1], uv[:, ::-1]
        if baked and instanced:
            _note(warnings, "Instanced objects are not baked: they show their materials unlit")
        if surface is not None:
            samplers.append(surface.sampler())
            slot_map = np.array([len(samplers) - 1], dtype=np.int64)
        else:
            slot_map = _material_slots(materials, samplers, sampler_index, warnings)
        object_id = len(names)
        names.append(obj.name)
        verts.append(co)
        tris.append(tri.astype(np.int64) + offset)
        objects.append(np.full(len(tri), object_id, dtype=np.int32))
        mats.append(slot_map[np.clip(slots, 0, len(slot_map) - 1)])
        uvs.append(uv)
        offset += len(co)
    if not tris:
        return None
    return BVHIntersector(
        np.concatenate(verts),
        np.concatenate(tris),
        np.concatenate(objects),
        np.concatenate(mats),
        np.concatenate(uvs),
        samplers,
        names,
    )


def _material_slots(
    materials: Sequence[bpy.types.Material | None],
    samplers: list[MaterialSampler],
    sampler_index: dict[str, int],
    warnings: list[str] | None,
) -> np.ndarray:
    """Sampler index per material slot; new materials are read (and their warnings noted)."""
    slot_to_sampler = []
    for material in materials or [None]:
        key = material.name_full if material is not None else ""
        if key not in sampler_index:
            sampler_index[key] = len(samplers)
            samplers.append(material_sampler(material))
            if warnings is not None and material is not None:
                warnings.extend(unsupported_warning(material))
        slot_to_sampler.append(sampler_index[key])
    return np.asarray(slot_to_sampler, dtype=np.int64)


def unsupported_warning(material: bpy.types.Material) -> list[str]:
    """The warning for the nodes of ``material`` the unbaked reader ignores ([] if none)."""
    nodes = unsupported_nodes(material)
    if not nodes:
        return []
    listed = ", ".join(f"'{name}'" for name in nodes)
    return [
        f"Material '{material.name}': node(s) {listed} are not evaluated without baking and "
        "are ignored (Surface Lighting: Bake evaluates every node)"
    ]

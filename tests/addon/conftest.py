"""Fixtures for the add-on tests: the bpy module with the SymRay extension installed.

Once per session (per xdist worker) the extension zip is built (or dist/ reused when it is
newer than every source file), installed with ``bpy.ops.extensions.package_install_files``
into a temporary Blender user folder (BLENDER_USER_RESOURCES, set here before bpy is
imported) and enabled. Each test starts from an empty scene (``scene``) or from Blender's
own factory startup file (``factory_scene``: the cube, the light and the camera in the
"Collection" child collection, as a new user sees it).

Without the bpy module the whole folder is skipped.
"""

from __future__ import annotations

import importlib
import importlib.util
import os
import shutil
import subprocess
import sys
import tempfile
import tomllib
from collections.abc import Callable, Iterator
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[2]
MODULE = "bl_ext.user_default.symray"
SOURCES = ("__init__.py", "blender_manifest.toml", "core", "symray_addon")

if importlib.util.find_spec("bpy") is None:
    collect_ignore_glob = ["test_*.py"]
else:
    if "bpy" in sys.modules:
        raise RuntimeError("bpy was imported before tests/addon/conftest.py could isolate it")
    _USER_FOLDER = tempfile.mkdtemp(prefix="symray-blender-user-")
    os.environ["BLENDER_USER_RESOURCES"] = _USER_FOLDER


def _newest_source() -> float:
    """Latest modification time of the files that go into the zip."""
    newest = 0.0
    for name in SOURCES:
        path = REPO / name
        files = [path] if path.is_file() else path.rglob("*.py")
        newest = max([newest, *(f.stat().st_mtime for f in files)])
    return newest


def _zip_name() -> str:
    manifest = tomllib.loads((REPO / "blender_manifest.toml").read_text(encoding="utf-8"))
    return f"{manifest['id']}-{manifest['version']}.zip"


@pytest.fixture(scope="session")
def extension_zip(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The extension zip: dist/ if it is fresh, else built into a temporary folder."""
    dist = REPO / "dist" / _zip_name()
    if dist.is_file() and dist.stat().st_mtime >= _newest_source():
        return dist
    out = tmp_path_factory.mktemp("dist")
    subprocess.run(
        [sys.executable, str(REPO / "tools" / "build_extension.py"), "--output-dir", str(out)],
        check=True,
        stdout=subprocess.DEVNULL,
    )
    return out / _zip_name()


class Addon:
    """The installed extension: its package name and access to its modules."""

    package = MODULE

    def module(self, name: str) -> ModuleType:
        """Import a module of the installed extension, e.g. 'symray_addon.output'."""
        return importlib.import_module(f"{MODULE}.{name}")

    @property
    def core(self) -> ModuleType:
        """The extension's own copy of the core."""
        return self.module("core")


@pytest.fixture(scope="session")
def addon(extension_zip: Path) -> Iterator[Addon]:
    """Install the zip into the isolated user folder and enable it (once per session)."""
    import bpy

    addon_utils = importlib.import_module("addon_utils")  # importable once bpy is

    result = bpy.ops.extensions.package_install_files(
        filepath=str(extension_zip), repo="user_default", enable_on_install=True
    )
    assert result == {"FINISHED"}
    if not addon_utils.check(MODULE)[1]:
        bpy.ops.preferences.addon_enable(module=MODULE)
    assert addon_utils.check(MODULE) == (True, True)
    installed = Path(os.environ["BLENDER_USER_RESOURCES"], "extensions", "user_default", "symray")
    assert installed.is_dir(), installed
    yield Addon()
    shutil.rmtree(os.environ["BLENDER_USER_RESOURCES"], ignore_errors=True)


@pytest.fixture
def scene(addon: Addon):
    """An empty scene (no objects, no world) with a camera-less SymRay setup."""
    import bpy

    bpy.ops.wm.read_homefile(use_empty=True)
    sc = bpy.context.scene
    sc.render.resolution_x, sc.render.resolution_y = 64, 48
    sc.render.resolution_percentage = 100
    sc.symray.pass_error = False
    sc.symray.tolerance = 1e-4
    sc.symray.quality = "RADIANS"  # the tests below were written for radians, one ray a pixel
    return sc


@pytest.fixture
def factory_scene(addon: Addon):
    """Blender's factory startup scene (Cube, Light, Camera in "Collection", the grey
    World) with SymRay as the render engine at a small resolution; nothing else changed.
    No bake is cached from an earlier test (the cache lives as long as the process)."""
    import bpy

    addon.module("symray_addon.bake").clear_cache()
    bpy.ops.wm.read_homefile(use_factory_startup=True)
    sc = bpy.context.scene
    sc.render.engine = "SYMRAY"
    sc.render.resolution_x, sc.render.resolution_y = 64, 48
    sc.render.resolution_percentage = 100
    return sc


# -- scene building helpers ------------------------------------------------------------


def add_camera(scene, location=(0.0, -30.0, 0.0), rotation=(np.pi / 2, 0.0, 0.0), **data):
    """A camera object made the scene camera; ``data`` sets camera properties."""
    import bpy

    cam = bpy.data.cameras.new("Camera")
    for key, value in data.items():
        setattr(cam, key, value)
    obj = bpy.data.objects.new("Camera", cam)
    obj.location = location
    obj.rotation_euler = rotation
    scene.collection.objects.link(obj)
    scene.camera = obj
    bpy.context.view_layer.update()  # matrix_world
    return obj


def solid_material(name: str, color) -> object:
    """A Principled BSDF material of the given base colour (linear RGBA)."""
    import bpy

    mat = bpy.data.materials.new(name)
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = True
    bsdf = next(n for n in mat.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    bsdf.inputs["Base Color"].default_value = color
    return mat


def add_mesh(
    scene,
    name: str,
    verts,
    faces,
    material=None,
    uvs=None,
    location=(0, 0, 0),
    rotation=(0, 0, 0),
    scale=(1, 1, 1),
):
    """A mesh object from vertices/faces (optional per-loop UVs, material, transform)."""
    import bpy

    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata([tuple(v) for v in verts], [], [tuple(f) for f in faces])
    if uvs is not None:
        layer = mesh.uv_layers.new(name="UVMap")
        for loop, uv in zip(layer.data, uvs, strict=True):
            loop.uv = uv
    if material is not None:
        mesh.materials.append(material)
    obj = bpy.data.objects.new(name, mesh)
    obj.location, obj.rotation_euler, obj.scale = location, rotation, scale
    scene.collection.objects.link(obj)
    bpy.context.view_layer.update()  # matrix_world
    return obj


def add_cube(scene, name: str, size: float = 2.0, **kwargs):
    """A cube mesh of edge ``size`` centred on its origin."""
    h = size / 2
    verts = [(x, y, z) for x in (-h, h) for y in (-h, h) for z in (-h, h)]
    faces = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    return add_mesh(scene, name, verts, faces, **kwargs)


def add_quad(scene, name: str, half: float, y: float, **kwargs):
    """A square in the XZ plane at depth ``y`` facing -Y, with UVs (0,0)..(1,1)."""
    verts = [(-half, y, -half), (half, y, -half), (half, y, half), (-half, y, half)]
    uvs = [(0, 0), (0, 1), (1, 1), (1, 0)]
    return add_mesh(scene, name, verts, [(0, 3, 2, 1)], uvs=uvs, **kwargs)


def set_world_color(scene, color) -> None:
    """Give the scene a world whose Background node has a constant colour."""
    import bpy

    world = bpy.data.worlds.new("World")
    if bpy.app.version < (5, 0, 0):
        world.use_nodes = True
    bg = next(n for n in world.node_tree.nodes if n.type == "BACKGROUND")
    bg.inputs["Color"].default_value = color
    bg.inputs["Strength"].default_value = 1.0
    scene.world = world
    scene.symray.background = "WORLD"


def add_empty(scene, name: str = "Centre", location=(0.0, 0.0, 0.0)):
    """An Empty (the model's centre)."""
    import bpy

    obj = bpy.data.objects.new(name, None)
    obj.location = location
    scene.collection.objects.link(obj)
    return obj


def image_array(name: str) -> np.ndarray:
    """Pixels of bpy.data.images[name] as (h, w, 4), row 0 at the TOP."""
    import bpy

    img = bpy.data.images[name]
    w, h = img.size
    flat = np.empty(w * h * 4, dtype=np.float32)
    img.pixels.foreach_get(flat)
    return flat.reshape(h, w, 4)[::-1]


def frame_directions(scene, camera_obj, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """World ray directions through pixel centres, from Blender's own camera.view_frame."""
    w = scene.render.resolution_x * scene.render.resolution_percentage // 100
    h = scene.render.resolution_y * scene.render.resolution_percentage // 100
    corners = np.array([tuple(v) for v in camera_obj.data.view_frame(scene=scene)])
    # view_frame order: top-right, bottom-right, bottom-left, top-left (camera local)
    tr, br, bl, tl = corners
    fx = (cols + 0.5) / w
    fy = 1.0 - (rows + 0.5) / h
    local = bl + fx[:, None] * (br - bl) + fy[:, None] * (tl - bl)
    m = np.array(camera_obj.matrix_world)
    rot = m[:3, :3] / np.linalg.norm(m[:3, :3], axis=0)
    if camera_obj.data.type == "ORTHO":
        local[:, 2] = 0.0
        return local @ rot.T  # offsets on the camera plane
    d = local @ rot.T
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def operator_error(call: Callable[[], object]) -> str:
    """Run an operator call expected to report an error; return the error text."""
    with pytest.raises(RuntimeError) as info:
        call()
    return str(info.value)


def symray_outputs(scene) -> Callable[[], set[str]]:
    """A compositor Render Layers node of ``scene`` -> a function giving its enabled
    "SymRay ..." outputs (the passes update_render_passes declared)."""
    import bpy

    if hasattr(scene, "compositing_node_group"):  # Blender 5
        tree = bpy.data.node_groups.new("Compositing", "CompositorNodeTree")
        scene.compositing_node_group = tree
    else:
        scene.use_nodes = True
        tree = scene.node_tree
    node = tree.nodes.new("CompositorNodeRLayers")
    return lambda: {o.name for o in node.outputs if o.enabled and o.name.startswith("SymRay")}


@pytest.fixture
def helpers():
    """The scene-building helpers above, for test modules (conftest is not importable)."""
    from types import SimpleNamespace

    return SimpleNamespace(
        add_camera=add_camera,
        solid_material=solid_material,
        add_mesh=add_mesh,
        add_cube=add_cube,
        add_quad=add_quad,
        set_world_color=set_world_color,
        add_empty=add_empty,
        image_array=image_array,
        frame_directions=frame_directions,
        operator_error=operator_error,
        symray_outputs=symray_outputs,
    )

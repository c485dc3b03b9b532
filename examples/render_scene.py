"""Render SymRay's default scene (or a .blend) with the SYMRAY engine to PNG and EXR.

    blender -b -P examples/render_scene.py -- --out out/default.png
    python examples/render_scene.py --out out/default.png          (bpy wheel)

The SymRay extension must be installed and enabled (``make render`` does both, into an
isolated user folder). The default scene follows the seed paper's Fig. 8: a black hole
(Add › SymRay › Black Hole at the origin, rg = 1; spinning with ``--spin``, charged with
``--charge``) in front of the
procedural sky, with a checkerboard behind it that the hole lenses into an Einstein ring.
``--blend FILE`` renders a saved scene instead (its own SymRay settings are kept).
The EXR (``--exr``, default: the PNG's name with .exr) is multi-layer, with the passes
"SymRay Error" and "SymRay Steps".
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys

import bpy

MODULE = "bl_ext.user_default.symray"
BOARD_SIZE = 16.0
BOARD_DISTANCE = 12.0
CAMERA_DISTANCE = 30.0


def parse_args(argv: list[str]) -> argparse.Namespace:
    """Options after '--' (inside Blender) or all of them (plain Python)."""
    if "--" in argv:
        argv = argv[argv.index("--") + 1 :]
    elif bpy.app.binary_path:  # inside Blender without '--': Blender's own options only
        argv = []
    else:  # plain Python with the bpy module
        argv = argv[1:]
    parser = argparse.ArgumentParser(description="Render SymRay's default scene.")
    parser.add_argument("--out", default="out/default.png", help="PNG to write")
    parser.add_argument("--exr", default=None, help="multi-layer EXR (default: next to --out)")
    parser.add_argument("--blend", default=None, help="render this .blend instead")
    parser.add_argument("--save-blend", default=None, help="also save the built scene here")
    parser.add_argument("--width", type=int, default=160)
    parser.add_argument("--height", type=int, default=120)
    parser.add_argument("--spin", type=float, default=0.0, help="a/M; nonzero = Kerr")
    parser.add_argument(
        "--charge",
        type=float,
        default=0.0,
        help="Q/M; nonzero = Reissner–Nordström, or Kerr–Newman with --spin (spin² + charge² < 1)",
    )
    parser.add_argument(
        "--quality",
        default="FINAL",
        choices=("PREVIEW", "FINAL", "CUSTOM", "RADIANS"),
        help="Preview (1 px), Final (0.25 px, anti-aliased; the default), Custom "
        "(--tolerance-px, --samples) or Radians (--tolerance, one ray a pixel)",
    )
    parser.add_argument("--tolerance-px", type=float, default=0.25, help="Custom quality")
    parser.add_argument("--samples", type=int, default=16, help="Custom quality")
    parser.add_argument(
        "--tolerance", type=float, default=None, help="radians (sets quality Radians)"
    )
    parser.add_argument(
        "--device",
        default=None,
        choices=("CPU", "GPU"),
        help="Render Properties › Device (GPU: CuPy in this Python, README: GPU rendering); "
        "default: the scene's (CPU for a built scene)",
    )
    parser.add_argument(
        "--method",
        default="AUTO",
        help="integrator (AUTO: the add-on's default, the measured cheapest for the model)",
    )
    return parser.parse_args(argv)


def addon_module(name: str):
    """A module of the installed SymRay extension, e.g. 'symray_addon.output'."""
    return importlib.import_module(f"{MODULE}.{name}")


def enable_extension() -> None:
    """Enable the installed extension (a fresh bpy session starts with it disabled)."""
    if hasattr(bpy.types.Scene, "symray"):
        return
    try:
        bpy.ops.preferences.addon_enable(module=MODULE)
    except (RuntimeError, ModuleNotFoundError) as err:
        sys.exit(
            f"render_scene: the SymRay extension is not installed ({err}); run "
            "'make render', or install dist/symray-*.zip first"
        )
    if not hasattr(bpy.types.Scene, "symray"):
        sys.exit("render_scene: the SymRay extension could not be enabled")


def checker_image(name: str, size: int = 512, squares: int = 8) -> bpy.types.Image:
    """A packed float checkerboard image (linear light values 0.9 / 0.1, reddish corner)."""
    import numpy as np

    image = bpy.data.images.new(name, width=size, height=size, alpha=True, float_buffer=True)
    idx = np.arange(size) * squares // size
    light = (idx[:, None] + idx[None, :]) % 2 == 0
    pixels = np.ones((size, size, 4), dtype=np.float32)
    pixels[..., :3] = np.where(light[..., None], 0.9, 0.1)
    pixels[: size // squares, : size // squares, :3] = (0.9, 0.2, 0.1)  # marks the UV origin
    image.pixels.foreach_set(pixels.ravel())
    image.pack()
    return image


def board_object(scene: bpy.types.Scene) -> bpy.types.Object:
    """The textured board behind the hole: a square in the XZ plane at y = BOARD_DISTANCE."""
    half = BOARD_SIZE / 2
    mesh = bpy.data.meshes.new("Board")
    mesh.from_pydata(
        [
            (-half, BOARD_DISTANCE, -half),
            (half, BOARD_DISTANCE, -half),
            (half, BOARD_DISTANCE, half),
            (-half, BOARD_DISTANCE, half),
        ],
        [],
        [(0, 3, 2, 1)],
    )
    uv = mesh.uv_layers.new(name="UVMap")
    for loop, (u, v) in zip(uv.data, [(0, 0), (0, 1), (1, 1), (1, 0)], strict=True):
        loop.uv = (u, v)
    material = bpy.data.materials.new("Checker")
    if bpy.app.version < (5, 0, 0):  # node-based materials are the only kind from 5.0 on
        material.use_nodes = True
    tree = material.node_tree
    bsdf = next(n for n in tree.nodes if n.type == "BSDF_PRINCIPLED")
    texture = tree.nodes.new("ShaderNodeTexImage")
    texture.image = checker_image("Checker")
    texture.interpolation = "Closest"
    tree.links.new(texture.outputs["Color"], bsdf.inputs["Base Color"])
    mesh.materials.append(material)
    obj = bpy.data.objects.new("Board", mesh)
    scene.collection.objects.link(obj)
    return obj


def build_scene(args: argparse.Namespace) -> bpy.types.Scene:
    """Replace the current scene's content with the default SymRay scene."""
    scene = bpy.context.scene
    for obj in list(scene.objects):
        bpy.data.objects.remove(obj, do_unlink=True)
    scene.cursor.location = (0.0, 0.0, 0.0)
    objects = addon_module("symray_addon.objects")
    # Add › SymRay › Black Hole at the cursor; Size is the horizon's radius (rg = 1)
    size = objects.size_of(1.0, args.spin, args.charge)
    bpy.ops.symray.add_black_hole(size=size, spin=args.spin, disk=False)
    bpy.context.active_object.symray.charge = args.charge
    board_object(scene)
    camera_data = bpy.data.cameras.new("Camera")
    camera_data.lens = 50.0
    camera = bpy.data.objects.new("Camera", camera_data)
    camera.location = (0.0, -CAMERA_DISTANCE, 0.0)
    camera.rotation_euler = (1.5707963267948966, 0.0, 0.0)  # look along +Y, Z up
    scene.collection.objects.link(camera)
    scene.camera = camera
    scene.symray.background = "PROCEDURAL"
    return scene


def save_result(scene: bpy.types.Scene, png: str, exr: str) -> None:
    """Save the Render Result as PNG and multi-layer EXR (temp file, then os.replace)."""
    output = addon_module("symray_addon.output")
    result = bpy.data.images["Render Result"]
    settings = scene.render.image_settings
    for path, choose in ((png, output.set_png_format), (exr, output.set_exr_format)):
        os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
        if choose is output.set_exr_format:
            output.set_exr_format(settings, multilayer=True)
        else:
            choose(settings)
        output.save_render_atomic(result, os.path.abspath(path), scene)
        print(f"render_scene: wrote {path}")


def main() -> None:
    """Build or open the scene, render it with SYMRAY, save PNG + EXR, print the summary."""
    args = parse_args(sys.argv)
    if args.blend:
        bpy.ops.wm.open_mainfile(filepath=os.path.abspath(args.blend), load_ui=False)
    enable_extension()
    if args.blend:
        scene = bpy.context.scene
    else:
        scene = build_scene(args)
        scene.render.resolution_x, scene.render.resolution_y = args.width, args.height
        scene.render.resolution_percentage = 100
        scene.symray.quality = "RADIANS" if args.tolerance is not None else args.quality
        scene.symray.tolerance = args.tolerance or 1e-5
        scene.symray.tolerance_px = args.tolerance_px
        scene.symray.samples = args.samples
        scene.symray.method = args.method
    if args.device is not None:
        scene.symray.device = args.device
    scene.render.engine = "SYMRAY"
    scene.view_settings.view_transform = "Standard"
    if args.save_blend:
        bpy.ops.wm.save_as_mainfile(filepath=os.path.abspath(args.save_blend), copy=True)
    bpy.ops.render.render()
    summary = addon_module("symray_addon.render_job").last_summary
    if not summary:
        sys.exit("render_scene: the render produced no image (see the errors above)")
    exr = args.exr or os.path.splitext(args.out)[0] + ".exr"
    save_result(scene, args.out, exr)
    text = addon_module("symray_addon.render_job").summary_text(summary)
    print(f"render_scene: {text}")
    print(f"render_scene: endings {summary.get('endings')}")


if __name__ == "__main__":
    main()

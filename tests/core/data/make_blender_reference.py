"""Regenerate blender_reference.npz: camera rays and environment lookups rendered by Blender.

Run with the bpy wheel (``.venv/bin/python tests/core/data/make_blender_reference.py``).
Each case renders a tiny image with Cycles in a fresh Blender process: either the world
shader emits the incoming ray direction (-Incoming) or a coded equirectangular environment
(Closest interpolation). tests/core compares core.camera / core.sky against the result
without needing Blender.
"""

import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).parent
ENV_SIZE = (32, 64)  # h, w of the coded environment: R = u, G = row-from-top, B = 0.5

CAMERA_CASES = [
    dict(res=[8, 6], cam=dict(type="PERSP", lens=50.0, sensor_width=36.0)),
    dict(res=[6, 9], cam=dict(type="PERSP", lens=35.0, sensor_width=36.0, shift_x=0.2,
                              shift_y=-0.15)),
    dict(res=[8, 6], cam=dict(type="PERSP", lens=30.0, sensor_width=36.0, sensor_height=20.0,
                              sensor_fit="VERTICAL", shift_x=0.1, shift_y=0.3)),
    dict(res=[6, 8], cam=dict(type="PERSP", lens=30.0, sensor_width=30.0, sensor_height=20.0,
                              sensor_fit="HORIZONTAL", shift_y=0.3)),
    dict(res=[8, 6], asp=[1.0, 2.5], cam=dict(type="PERSP", lens=30.0, sensor_width=36.0,
                                              shift_x=0.1)),
    dict(res=[8, 8], asp=[3.0, 1.0], cam=dict(type="PERSP", lens=30.0, sensor_width=36.0,
                                              shift_y=0.1)),
    dict(res=[40, 30], pct=35, cam=dict(type="PERSP", lens=30.0, sensor_width=36.0)),
    dict(res=[40, 30], border=[0.13, 0.71, 0.29, 0.83],
         cam=dict(type="PERSP", lens=30.0, sensor_width=36.0, shift_x=0.05)),
    dict(res=[16, 8], cam=dict(type="PANO", panorama_type="EQUIRECTANGULAR")),
    dict(res=[16, 8], cam=dict(type="PANO", panorama_type="EQUIRECTANGULAR", latitude_min=-0.5,
                               latitude_max=1.0, longitude_min=-2.0, longitude_max=1.5)),
    dict(res=[16, 8], cam=dict(type="PANO", panorama_type="EQUIRECTANGULAR", shift_x=0.1,
                               shift_y=0.05)),
]  # fmt: skip
ENV_CASES = [
    dict(res=[24, 12], cam=dict(type="PANO", panorama_type="EQUIRECTANGULAR")),
    dict(res=[24, 16], cam=dict(type="PERSP", lens=20.0)),
]


def coded_environment() -> np.ndarray:
    """The environment image, row 0 at the top."""
    h, w = ENV_SIZE
    img = np.zeros((h, w, 3), np.float32)
    img[..., 0] = (np.arange(w) + 0.5)[None, :] / w
    img[..., 1] = (np.arange(h) + 0.5)[:, None] / h
    img[..., 2] = 0.5
    return img


def render_in_blender(cfg: dict, out: str) -> None:
    """Inside a Blender process: build the scene of ``cfg`` and write an EXR to ``out``."""
    import bpy

    sc = bpy.context.scene
    for ob in list(bpy.data.objects):
        bpy.data.objects.remove(ob)
    sc.render.engine = "CYCLES"
    sc.cycles.device, sc.cycles.samples, sc.cycles.use_denoising = "CPU", 1, False
    sc.cycles.filter_width = 0.01  # sample at the pixel centre
    sc.cycles.use_adaptive_sampling = False
    sc.view_settings.view_transform = "Standard"
    r = sc.render
    r.image_settings.file_format, r.image_settings.color_depth = "OPEN_EXR", "32"
    r.resolution_x, r.resolution_y = cfg["res"]
    r.resolution_percentage = cfg.get("pct", 100)
    r.pixel_aspect_x, r.pixel_aspect_y = cfg.get("asp", (1, 1))
    if cfg.get("border"):
        r.use_border = r.use_crop_to_border = True
        r.border_min_x, r.border_max_x, r.border_min_y, r.border_max_y = cfg["border"]
    data = bpy.data.cameras.new("C")
    for key, value in cfg["cam"].items():
        setattr(data, key, value)
    cam = bpy.data.objects.new("C", data)
    sc.collection.objects.link(cam)
    sc.camera = cam
    cam.location, cam.rotation_euler = cfg["loc"], cfg["rot"]
    world = bpy.data.worlds.new("W")
    sc.world = world
    world.use_nodes = True
    nt = world.node_tree
    nt.nodes.clear()
    bg = nt.nodes.new("ShaderNodeBackground")
    nt.links.new(bg.outputs[0], nt.nodes.new("ShaderNodeOutputWorld").inputs["Surface"])
    if cfg.get("env"):
        env = nt.nodes.new("ShaderNodeTexEnvironment")
        env.interpolation = "Closest"
        env.image = bpy.data.images.load(cfg["env"])
        env.image.colorspace_settings.name = "Non-Color"
        nt.links.new(env.outputs["Color"], bg.inputs["Color"])
    else:
        neg = nt.nodes.new("ShaderNodeVectorMath")
        neg.operation = "SCALE"
        neg.inputs["Scale"].default_value = -1.0
        nt.links.new(nt.nodes.new("ShaderNodeNewGeometry").outputs["Incoming"], neg.inputs[0])
        nt.links.new(neg.outputs["Vector"], bg.inputs["Color"])
    r.filepath, r.use_file_extension = out, False
    bpy.ops.render.render(write_still=True)
    np.save(out + ".matrix.npy", np.array(cam.matrix_world))


def render(cfg: dict, tmp: Path) -> tuple[np.ndarray, np.ndarray]:
    """Render one case in a fresh process -> (rgb (h, w, 3) row 0 at the top, matrix_world)."""
    import OpenEXR

    out = str(tmp / "render.exr")
    subprocess.run([sys.executable, __file__, json.dumps(cfg), out], check=True,
                   capture_output=True)  # fmt: skip
    with OpenEXR.File(out, separate_channels=True) as f:
        ch = f.channels()
        rgb = np.stack([np.asarray(ch[c].pixels) for c in "RGB"], axis=-1)
    return rgb, np.load(out + ".matrix.npy")


def main() -> None:
    import bpy
    import OpenEXR

    result = {"version": np.array(bpy.app.version_string)}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for i, case in enumerate(CAMERA_CASES):
            cfg = dict(case, loc=[1, 2, 3], rot=[1.2, 0.1, 0.3])
            rgb, matrix = render(cfg, tmp)
            result |= {f"cam{i}_config": np.array(json.dumps(cfg)), f"cam{i}_matrix": matrix,
                       f"cam{i}_dirs": rgb.astype(np.float32)}  # fmt: skip
        env = str(tmp / "env.exr")
        header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
        OpenEXR.File(header, {"RGB": coded_environment()}).write(env)
        for i, case in enumerate(ENV_CASES):
            cfg = dict(case, loc=[0, 0, 0], rot=[1.1, 0.2, 0.4])
            rgb, matrix = render(dict(cfg, env=env), tmp)
            result |= {f"env{i}_config": np.array(json.dumps(cfg)), f"env{i}_matrix": matrix,
                       f"env{i}_color": rgb.astype(np.float32)}  # fmt: skip
    np.savez_compressed(HERE / "blender_reference.npz", **result)
    print("wrote", HERE / "blender_reference.npz", "with Blender", result["version"])


if __name__ == "__main__":
    if len(sys.argv) == 3:
        render_in_blender(json.loads(sys.argv[1]), sys.argv[2])
    else:
        main()

"""Results -> Blender images (Blender's image API) and the operator's OpenEXR files.

The operator's EXR files are encoded by core.imageio (numpy + zlib: 32-bit float, ZIP;
Blender does not bundle the OpenEXR package, and its own writer names no channels).
``<path>`` holds R, G, B, A; when passes are switched on, ``<stem>.passes.exr`` next to it
holds one layer per pass switched on, named as the engine's passes: "SymRay Error.X"
(pixels), "SymRay Steps.X", "SymRay Ending.X" (core.ENDING code), "SymRay Redshift.X"
(NaN off the accretion disk); a pass switched off has no layer. Both files are written to
temporary names in the target folder and then moved over the targets together: a failed
write leaves both previous files as they were.

Renders through the SYMRAY engine (F12, ``blender -b``) use Blender's output settings
instead: choose OpenEXR MultiLayer there to get every pass ("SymRay Error", ...) in one file.
"""

from __future__ import annotations

import os
import shutil
import uuid
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager

import bpy
import numpy as np

from ..core import imageio
from ..core import passes as core_passes

PASS_LAYERS = {p.name: f"{p.layer}.X" for p in core_passes.PASSES if p.label}
"""Core pass -> its channel in the operator's passes EXR (the engine's pass name + '.X')."""
BLENDER_IMAGES = {"RENDER_RESULT": "render result", "COMPOSITING": "compositor viewer"}
"""Image types Blender fills itself (Image.type) -> what to call them in a message."""
RESERVED_IMAGE_NAMES = ("Render Result", "Viewer Node")
"""Names Blender gives its own images (they may not exist yet)."""


def resolve_path(path: str) -> str:
    """Absolute file path for a user path ('//' = next to the .blend); adds .exr if bare."""
    absolute = os.path.abspath(bpy.path.abspath(path))
    if not os.path.splitext(absolute)[1]:
        absolute += ".exr"
    return absolute


def passes_path(path: str) -> str:
    """Path of the passes EXR that goes with the RGBA EXR at ``path``."""
    stem, ext = os.path.splitext(path)
    return f"{stem}.passes{ext or '.exr'}"


def check_writable(path: str) -> str:
    """Resolve ``path`` and raise OSError with a clear message unless it can be written."""
    if not path.strip():
        raise OSError("EXR path is empty")
    if path.strip().startswith("//") and not bpy.data.filepath:
        raise OSError(
            f"EXR path '{path}' is relative to the .blend file ('//'), which is not "
            "saved yet: save the file first, or choose an absolute path"
        )
    raw = bpy.path.abspath(path)
    if os.path.isdir(raw) or raw.endswith(("/", "\\")):
        raise OSError(f"EXR path '{raw}' is a folder, not a file")
    target = resolve_path(path)
    extension = os.path.splitext(target)[1]
    if extension.lower() != ".exr":
        raise OSError(
            f"EXR path '{path}' ends in '{extension}', not '.exr': SymRay writes OpenEXR "
            "there and would replace that file; end the path in .exr"
        )
    folder = os.path.dirname(target)
    if os.path.isdir(target):
        raise OSError(f"EXR path '{target}' is a folder, not a file")
    if not os.path.isdir(folder):
        raise OSError(f"Cannot write EXR: folder '{folder}' does not exist")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise OSError(f"Cannot write EXR: folder '{folder}' is not writable")
    if os.path.exists(target) and not os.access(target, os.W_OK):
        raise OSError(f"Cannot write EXR: '{target}' is not writable")
    return target


def check_image_name(name: str) -> str:
    """``name`` stripped; ValueError unless the operator can write an image of that name
    (not empty, not one of the images Blender fills itself, not linked from a library)."""
    name = name.strip()
    if not name:
        raise ValueError("Set the name of the image SymRay should write (SymRay › Output › Image)")
    longest = bpy.types.ID.bl_rna.properties["name"].length_max - 1  # bytes, without the NUL
    if len(name.encode("utf-8")) > longest:
        raise ValueError(
            f"The image name in SymRay › Output › Image is {len(name.encode('utf-8'))} bytes "
            f"long: Blender keeps at most {longest} bytes of a name, so the image written "
            "would never be found again (a new one at every render); shorten it; nothing was "
            "written"
        )
    image = bpy.data.images.get(name)
    kind = BLENDER_IMAGES.get(image.type) if image is not None else None
    if kind is None and name in RESERVED_IMAGE_NAMES:
        kind = BLENDER_IMAGES["RENDER_RESULT" if name == "Render Result" else "COMPOSITING"]
    if kind is not None:
        raise ValueError(
            f"Image '{name}' is Blender's {kind}, which only Blender writes: choose another "
            "name in SymRay › Output › Image (e.g. 'SymRay Result'); nothing was written"
        )
    if image is not None and image.library is not None:
        raise ValueError(
            f"Image '{name}' is linked from '{image.library.filepath}' and cannot be "
            "changed: choose another name in SymRay › Output › Image; nothing was written"
        )
    return name


def check_finite(rgba: np.ndarray) -> None:
    """ValueError unless every colour value is finite (an inf or NaN pixel is never written)."""
    bad = ~np.isfinite(rgba).all(axis=-1)
    if bad.any():
        raise ValueError(
            f"{int(bad.sum())} pixels have a colour beyond 32-bit floats (inf or NaN; e.g. "
            "a Disk Brightness, Star Brightness or world strength too large): nothing was "
            "written"
        )


def bottom_up(image: np.ndarray, channels: int) -> np.ndarray:
    """A (h, w[, c]) top-first image as a (h*w, channels) float32 bottom-up buffer, the
    row order of Blender's images and render passes."""
    flipped = np.asarray(image, dtype=np.float32)[::-1]
    return np.ascontiguousarray(flipped.reshape(-1, channels))


def _fill(image: bpy.types.Image, rgba: np.ndarray) -> None:
    """Write a (h, w, 4) top-first array into an image of the same size."""
    image.pixels.foreach_set(bottom_up(rgba, 4).reshape(-1))
    image.update()


def write_image(name: str, rgba: np.ndarray) -> bpy.types.Image:
    """Write ``rgba`` (h, w, 4), row 0 at the top, into float image ``name`` (made if missing).

    The pixels are packed into the .blend (as OpenEXR, 32-bit float) and the image keeps a
    fake user, so saving the file keeps the last render (a generated image alone would come
    back blank).
    """
    h, w = rgba.shape[:2]
    image = bpy.data.images.get(name)
    if image is None:
        image = bpy.data.images.new(name, width=w, height=h, alpha=True, float_buffer=True)
    else:
        if image.packed_file is not None:
            image.unpack(method="REMOVE")  # the previous render's pixels; replaced below
        if image.source != "GENERATED":
            image.source = "GENERATED"
        image.generated_type = "BLANK"
        image.use_generated_float = True
        if tuple(image.size) != (w, h):
            image.generated_width, image.generated_height = w, h
        if tuple(image.size) != (w, h):
            image.scale(w, h)
    _fill(image, rgba)
    image.pack()  # a float image is packed as OpenEXR: no loss
    image.use_fake_user = True
    return image


def set_exr_format(settings: bpy.types.ImageFormatSettings, multilayer: bool = False) -> None:
    """Select (multi-layer) OpenEXR, 32-bit float, ZIP in ``settings`` (Blender 4.2 and 5.x)."""
    if "media_type" in settings.bl_rna.properties:  # Blender 5.0+: pick the media type first
        settings.media_type = "MULTI_LAYER_IMAGE" if multilayer else "IMAGE"
    settings.file_format = "OPEN_EXR_MULTILAYER" if multilayer else "OPEN_EXR"
    settings.color_depth = "32"
    settings.exr_codec = "ZIP"
    if not multilayer:
        settings.color_mode = "RGBA"


def set_png_format(settings: bpy.types.ImageFormatSettings) -> None:
    """Select 8-bit RGBA PNG in ``settings`` (Blender 4.2 and 5.x)."""
    if "media_type" in settings.bl_rna.properties:
        settings.media_type = "IMAGE"
    settings.file_format = "PNG"
    settings.color_depth = "8"
    settings.color_mode = "RGBA"


@contextmanager
def atomic_target(path: str) -> Iterator[str]:
    """Yield a temporary file name next to ``path``; on success move it over ``path``."""
    folder = os.path.dirname(path) or "."
    # A fresh unique name that Blender creates itself (normal permissions, unlike mkstemp).
    temp = os.path.join(folder, f".symray-{uuid.uuid4().hex}{os.path.splitext(path)[1]}")
    try:
        yield temp
        if not os.path.isfile(temp) or os.path.getsize(temp) == 0:
            raise OSError(f"Blender did not write '{path}'")
        os.replace(temp, path)
    finally:
        if os.path.exists(temp):
            os.remove(temp)


def save_render_atomic(image: bpy.types.Image, path: str, scene: bpy.types.Scene) -> None:
    """``image.save_render`` with ``scene``'s image settings, to a temp file, then os.replace."""
    with atomic_target(path) as temp:
        try:
            image.save_render(temp, scene=scene)
        except RuntimeError as err:
            raise OSError(f"Cannot write '{path}': {err}") from None


def exr_layers(
    passes: Mapping[str, np.ndarray], wanted: Sequence[str] = tuple(PASS_LAYERS)
) -> dict[str, np.ndarray]:
    """The passes EXR's channels: the passes in ``wanted`` that were computed, by layer name."""
    return {
        layer: np.asarray(passes[name], dtype=np.float32)
        for name, layer in PASS_LAYERS.items()
        if name in wanted and name in passes
    }


def write_exr(
    path: str,
    rgba: np.ndarray,
    passes: Mapping[str, np.ndarray] | None = None,
    wanted: Sequence[str] = tuple(PASS_LAYERS),
) -> list[str]:
    """Write ``rgba`` and the ``wanted`` passes (module doc) as OpenEXR, both files or
    neither; returns the files written.

    ``path`` may be relative to the .blend ('//'); OSError naming the file that failed.
    """
    target = check_writable(path)
    check_finite(rgba)
    colour = np.asarray(rgba, dtype=np.float32)
    files = [(target, {c: colour[..., i] for i, c in enumerate("RGBA")})]
    layers = exr_layers(passes or {}, wanted)
    if layers:
        files.append((passes_path(target), layers))
    try:
        return imageio.write_exr_files(files)
    except imageio.ImageWriteError as err:
        raise OSError(f"SymRay {err}") from None  # "cannot write image '<path>': ..."


SAVE_MARGIN_BYTES = 1 << 20
"""Room kept beyond a frame's uncompressed size (headers, a codec's worst case)."""


def frame_bytes(scene: bpy.types.Scene, width: int, height: int, passes: int) -> int:
    """An upper bound of the size of the frame Blender's writer will save: its samples
    uncompressed (a codec's output is rarely larger), plus SAVE_MARGIN_BYTES."""
    settings = scene.render.image_settings
    depth = {"32": 4, "16": 2}.get(getattr(settings, "color_depth", ""), 1)
    channels = len(settings.color_mode) if settings.color_mode != "BW" else 1
    if settings.file_format == "OPEN_EXR_MULTILAYER":
        channels = 4 + passes
    return width * height * channels * depth + SAVE_MARGIN_BYTES


def check_room_to_save(scene: bpy.types.Scene, width: int, height: int, passes: int) -> None:
    """OSError when the folder the frame will be saved to has less free space than the
    frame may take (frame_bytes): Blender's writer would cut the file short over the
    previous one and still print 'Saved:'. Raised before the frame is handed over, so the
    previous file stays as it was."""
    path = os.path.abspath(bpy.path.abspath(scene.render.frame_path(frame=scene.frame_current)))
    folder = os.path.dirname(path)
    while folder and not os.path.isdir(folder):  # Blender makes the missing folders
        folder = os.path.dirname(folder) if os.path.dirname(folder) != folder else ""
    if not folder:
        return
    need = frame_bytes(scene, width, height, passes)
    free = shutil.disk_usage(folder).free
    if free < need:
        raise OSError(
            f"Not enough free space to save frame {scene.frame_current} in '{folder}': it may "
            f"take {need / 1e6:.1f} MB and there are {free / 1e6:.1f} MB free. "
            "The frame was not handed to Blender's writer, so any file there keeps its "
            "previous contents; free some space or choose another Output path"
        )

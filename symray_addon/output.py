"""Results -> Blender images and OpenEXR files, through Blender's own image API.

The extension never imports the OpenEXR package (Blender does not bundle it). EXR files
are written by Blender: a float Image saved with a scene's image settings (OpenEXR, 32-bit
float, ZIP). Every file is first written to a temporary name in the target folder and
then moved over the target with ``os.replace``, so a failed or cancelled write never
leaves a half-written file behind.

The operator writes two files: ``<path>`` holds RGBA; when passes were computed,
``<stem>.passes.exr`` next to it holds R = error (pixels), G = steps, B = ending code,
A = redshift (NaN off the accretion disk; 1 when the pass was not computed).
Renders through the SYMRAY engine (F12, ``blender -b``) use Blender's output settings
instead: choose OpenEXR MultiLayer there to get every pass ("SymRay Error", ...) in one file.
"""

from __future__ import annotations

import os
import uuid
from collections.abc import Iterator, Mapping
from contextlib import contextmanager

import bpy
import numpy as np

from .properties import PASSES

PASS_CHANNELS = tuple(name for name, _label, _toggle in PASSES)
"""Order of the passes in the R, G, B, A channels of the operator's passes EXR."""


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
def _scratch_scene() -> Iterator[bpy.types.Scene]:
    """A temporary scene whose image settings drive Image.save_render; removed afterwards."""
    scene = bpy.data.scenes.new("SymRay EXR Writer")
    try:
        yield scene
    finally:
        bpy.data.scenes.remove(scene)


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


def write_exr(
    path: str, rgba: np.ndarray, passes: Mapping[str, np.ndarray] | None = None
) -> list[str]:
    """Write ``rgba`` (and ``passes``, see module doc) as OpenEXR; returns the files written.

    ``path`` may be relative to the .blend ('//'); OSError if a file cannot be written.
    """
    target = check_writable(path)
    h, w = rgba.shape[:2]
    written: list[str] = []
    images: list[bpy.types.Image] = []
    try:
        with _scratch_scene() as scene:
            set_exr_format(scene.render.image_settings)
            color = bpy.data.images.new(
                "SymRay EXR", width=w, height=h, alpha=True, float_buffer=True
            )
            images.append(color)
            _fill(color, rgba)
            save_render_atomic(color, target, scene)
            written.append(target)
            present = [p for p in PASS_CHANNELS if passes and p in passes]
            if present:
                data = np.zeros((h, w, 4), dtype=np.float32)
                data[..., 3] = 1.0
                for channel, name in enumerate(PASS_CHANNELS):
                    if name in present:
                        data[..., channel] = passes[name]
                extra = bpy.data.images.new(
                    "SymRay EXR Passes", width=w, height=h, alpha=True, float_buffer=True
                )
                images.append(extra)
                _fill(extra, data)
                save_render_atomic(extra, passes_path(target), scene)
                written.append(passes_path(target))
    finally:
        for image in images:
            bpy.data.images.remove(image)
    return written

"""Image output: PNG (pure numpy + zlib) and OpenEXR, written atomically.

Images in the core are linear, straight-alpha float arrays (h, w, 4), row 0 at the top.
``write_png`` applies the sRGB transfer function by default (like Blender's "Standard"
view transform) to the colour channels, never to alpha; pass ``srgb=False`` to store the
values as they are. ``write_exr`` stores linear float channels unchanged.

Every write goes to a temporary file in the target's directory, then ``os.replace``: a failed
write never leaves a partial file and never clobbers the previous one.
"""

from __future__ import annotations

import os
import struct
import tempfile
import zlib
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

__all__ = [
    "FAILED_COLOR",
    "ImageWriteError",
    "atomic_write",
    "linear_to_srgb",
    "png_bytes",
    "read_exr",
    "read_png",
    "srgb_to_linear",
    "write_exr",
    "write_png",
]

#: Reserved debug colour (linear RGBA) for pixels whose ray failed: opaque magenta.
FAILED_COLOR = (1.0, 0.0, 1.0, 1.0)

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_CHANNELS_TO_TYPE = {1: 0, 2: 4, 3: 2, 4: 6}  # gray, gray+alpha, rgb, rgba
_TYPE_TO_CHANNELS = {v: k for k, v in _CHANNELS_TO_TYPE.items()}


class ImageWriteError(OSError):
    """An image could not be written; the message names the path."""


# -- colour transfer ------------------------------------------------------------------------


def linear_to_srgb(x: Any) -> np.ndarray:
    """sRGB transfer function (IEC 61966-2-1) applied to linear values (clipped below at 0)."""
    x = np.maximum(np.asarray(x, dtype=np.float64), 0.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def srgb_to_linear(x: Any) -> np.ndarray:
    """Inverse sRGB transfer function."""
    x = np.asarray(x, dtype=np.float64)
    return np.where(x <= 0.04045, x / 12.92, np.power((np.maximum(x, 0) + 0.055) / 1.055, 2.4))


# -- atomic writes --------------------------------------------------------------------------


def _umask() -> int:
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except OSError:
        pass
    return 0o022


def atomic_write(path: str | os.PathLike, write: Callable[[str], None]) -> str:
    """Run ``write(tmp_path)`` then move the temporary file onto path; clean up on failure."""
    path = os.fspath(path)
    directory = os.path.dirname(os.path.abspath(path))
    if os.path.isdir(path):
        raise ImageWriteError(f"cannot write image {path!r}: it is a directory")
    try:
        fd, tmp = tempfile.mkstemp(prefix="." + os.path.basename(path) + ".", suffix=".tmp",
                                   dir=directory)  # fmt: skip
    except OSError as e:
        raise ImageWriteError(f"cannot write image {path!r}: {e.strerror or e}") from e
    os.close(fd)
    try:
        write(tmp)
        mode = os.stat(path).st_mode & 0o777 if os.path.exists(path) else 0o666 & ~_umask()
        os.chmod(tmp, mode)
        os.replace(tmp, path)
    except BaseException as e:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        if isinstance(e, Exception) and not isinstance(e, ImageWriteError):
            raise ImageWriteError(f"cannot write image {path!r}: {e}") from e
        raise
    return path


# -- PNG ------------------------------------------------------------------------------------


def _chunk(kind: bytes, data: bytes) -> bytes:
    crc = zlib.crc32(kind + data) & 0xFFFFFFFF
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", crc)


def _quantize(image: Any, srgb: bool, bits: int) -> np.ndarray:
    """Float image (h, w[, c]) -> unsigned integer array (h, w, c) of the PNG bit depth."""
    img = np.asarray(image, dtype=np.float64)
    if img.ndim == 2:
        img = img[:, :, None]
    if img.ndim != 3 or img.shape[2] not in _CHANNELS_TO_TYPE or 0 in img.shape[:2]:
        raise ValueError(f"PNG image must be (h, w) or (h, w, 1-4), got shape {np.shape(image)}")
    img = np.nan_to_num(img, nan=0.0, posinf=1.0, neginf=0.0)
    if srgb:
        colour = 3 if img.shape[2] >= 3 else 1
        img = img.copy()
        img[:, :, :colour] = linear_to_srgb(img[:, :, :colour])
    top = (1 << bits) - 1
    q = np.rint(np.clip(img, 0.0, 1.0) * top)
    return q.astype(">u2" if bits == 16 else np.uint8)


def png_bytes(image: Any, *, srgb: bool = True, bits: int = 8, level: int = 6) -> bytes:
    """Encode a float image (h, w[, 1-4]) in [0, 1] as PNG bytes (filter 0, zlib)."""
    if bits not in (8, 16):
        raise ValueError(f"PNG bit depth must be 8 or 16, got {bits}")
    q = _quantize(image, srgb, bits)
    h, w, c = q.shape
    raw = np.zeros((h, 1 + w * c * (bits // 8)), dtype=np.uint8)
    raw[:, 1:] = q.reshape(h, -1).view(np.uint8)
    header = struct.pack(">IIBBBBB", w, h, bits, _CHANNELS_TO_TYPE[c], 0, 0, 0)
    chunks = [_chunk(b"IHDR", header)]
    if srgb:
        chunks.append(_chunk(b"sRGB", b"\x00"))
    chunks.append(_chunk(b"IDAT", zlib.compress(raw.tobytes(), level)))
    chunks.append(_chunk(b"IEND", b""))
    return _PNG_SIGNATURE + b"".join(chunks)


def write_png(
    path: str | os.PathLike, image: Any, *, srgb: bool = True, bits: int = 8, level: int = 6
) -> str:
    """Write a linear float image (h, w[, 1-4]) as PNG, atomically; sRGB-encoded by default."""
    data = png_bytes(image, srgb=srgb, bits=bits, level=level)

    def write(tmp: str) -> None:
        with open(tmp, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())

    return atomic_write(path, write)


def _unfilter(raw: np.ndarray, h: int, stride: int, bpp: int) -> np.ndarray:
    """Undo PNG filters 0 (None), 1 (Sub), 2 (Up) row by row -> (h, stride) uint8."""
    rows = raw[: h * (stride + 1)].reshape(h, stride + 1)
    kinds, data = rows[:, 0], rows[:, 1:].astype(np.int64)
    if np.any(kinds > 2):
        raise ValueError("read_png supports PNG filter types 0-2 only (as write_png writes)")
    out = np.zeros((h, stride), dtype=np.int64)
    for y in range(h):
        row = data[y]
        if kinds[y] == 1:
            row = np.cumsum(row.reshape(-1, bpp), axis=0).reshape(-1)
        elif kinds[y] == 2 and y > 0:
            row = row + out[y - 1]
        out[y] = row & 0xFF
    return out.astype(np.uint8)


def read_png(path: str | os.PathLike, *, srgb: bool = True) -> np.ndarray:
    """Read a non-interlaced 8/16-bit PNG -> float (h, w, c) in [0, 1], linearised if srgb."""
    with open(path, "rb") as f:
        data = f.read()
    if data[:8] != _PNG_SIGNATURE:
        raise ValueError(f"{os.fspath(path)!r} is not a PNG file")
    pos, idat, header = 8, [], None
    while pos < len(data):
        (length,) = struct.unpack(">I", data[pos : pos + 4])
        kind, body = data[pos + 4 : pos + 8], data[pos + 8 : pos + 8 + length]
        (crc,) = struct.unpack(">I", data[pos + 8 + length : pos + 12 + length])
        if zlib.crc32(kind + body) & 0xFFFFFFFF != crc:
            raise ValueError(f"{os.fspath(path)!r}: bad CRC in chunk {kind!r}")
        if kind == b"IHDR":
            header = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            idat.append(body)
        elif kind == b"IEND":
            break
        pos += 12 + length
    if header is None:
        raise ValueError(f"{os.fspath(path)!r}: no IHDR chunk")
    w, h, bits, ctype, _, _, interlace = header
    if bits not in (8, 16) or ctype not in _TYPE_TO_CHANNELS or interlace:
        raise ValueError(f"{os.fspath(path)!r}: unsupported PNG (bits={bits}, type={ctype})")
    c, nbytes = _TYPE_TO_CHANNELS[ctype], bits // 8
    raw = np.frombuffer(zlib.decompress(b"".join(idat)), dtype=np.uint8)
    px = _unfilter(raw, h, w * c * nbytes, c * nbytes)
    vals = px.reshape(h, w * c * nbytes).view(">u2" if bits == 16 else np.uint8)
    img = vals.reshape(h, w, c).astype(np.float64) / ((1 << bits) - 1)
    if srgb:
        colour = 3 if c >= 3 else 1
        img[:, :, :colour] = srgb_to_linear(img[:, :, :colour])
    return img


# -- OpenEXR -----------------------------------------------------------------------------------


def _import_openexr():
    try:
        import OpenEXR  # noqa: PLC0415 - optional dependency, imported only when needed
    except ImportError as e:
        raise ImportError(
            "writing EXR files needs the 'OpenEXR' Python package (pip install openexr)"
        ) from e
    return OpenEXR


def _exr_channel(name: str, arr: Any, shape: tuple[int, ...] | None) -> np.ndarray:
    a = np.asarray(arr)
    if a.ndim != 2 or 0 in a.shape:
        raise ValueError(f"EXR channel {name!r} must be a non-empty (h, w) array, got {a.shape}")
    if shape is not None and a.shape != shape:
        raise ValueError(f"EXR channel {name!r} has shape {a.shape}, expected {shape}")
    if a.dtype not in (np.float16, np.uint32):
        a = a.astype(np.float32)
    return np.ascontiguousarray(a)


def write_exr(
    path: str | os.PathLike, channels: Mapping[str, Any], *, compression: str = "zip"
) -> str:
    """Write named (h, w) channels (float32; float16/uint32 kept) to an EXR file, atomically."""
    exr = _import_openexr()
    if not channels:
        raise ValueError("write_exr needs at least one channel")
    shape, arrays = None, {}
    for name, arr in channels.items():
        arrays[str(name)] = _exr_channel(str(name), arr, shape)
        shape = arrays[str(name)].shape
    modes = {"none": "NO_COMPRESSION", "zip": "ZIP_COMPRESSION", "piz": "PIZ_COMPRESSION",
             "zips": "ZIPS_COMPRESSION", "rle": "RLE_COMPRESSION"}  # fmt: skip
    if compression not in modes:
        raise ValueError(f"EXR compression must be one of {sorted(modes)}, got {compression!r}")
    # the compression constant by its name in the OpenEXR module (a lookup, not a probe)
    header = {"compression": getattr(exr, modes[compression]), "type": exr.scanlineimage}

    def write(tmp: str) -> None:
        exr.File(header, arrays).write(tmp)

    return atomic_write(path, write)


def read_exr(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Read an EXR file -> {channel name: (h, w) array} (interleaved RGB(A) split by name)."""
    exr = _import_openexr()
    out = {}
    with exr.File(os.fspath(path), separate_channels=True) as f:
        for name, ch in f.channels().items():
            out[name] = np.array(ch.pixels)
    return out

"""Image output: PNG (pure numpy + zlib) and OpenEXR, written atomically.

Images in the core are linear, straight-alpha float arrays (h, w, 4), row 0 at the top.
``write_png`` applies the sRGB transfer function by default (like Blender's "Standard"
view transform) to the colour channels, never to alpha; pass ``srgb=False`` to store the
values as they are. ``write_exr`` stores linear float channels unchanged (numpy + zlib;
reading an EXR needs the optional OpenEXR package).

Every write goes to a temporary file in the target's directory, then ``os.replace``: a failed
write never leaves a partial file and never clobbers the previous one. ``write_exr_files``
writes several files as one: all are replaced, or none.
"""

from __future__ import annotations

import os
import shutil
import struct
import tempfile
import zlib
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

__all__ = [
    "FAILED_COLOR",
    "ImageWriteError",
    "atomic_write",
    "atomic_write_all",
    "exr_bytes",
    "linear_to_srgb",
    "png_bytes",
    "read_exr",
    "read_png",
    "srgb_to_linear",
    "write_exr",
    "write_exr_files",
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


def _temp_for(path: str) -> str:
    """A fresh temporary file next to ``path`` (ImageWriteError naming path if impossible)."""
    if os.path.isdir(path):
        raise ImageWriteError(f"cannot write image {path!r}: it is a directory")
    directory = os.path.dirname(os.path.abspath(path))
    try:
        fd, tmp = tempfile.mkstemp(prefix="." + os.path.basename(path) + ".", suffix=".tmp",
                                   dir=directory)  # fmt: skip
    except OSError as e:
        raise ImageWriteError(f"cannot write image {path!r}: {e.strerror or e}") from e
    os.close(fd)
    return tmp


def _unlink_quietly(path: str) -> None:
    try:
        os.unlink(path)
    except OSError:
        pass


def _backup(path: str) -> str | None:
    """A copy of ``path`` beside it (a hard link where the file system allows), or None
    when there is no file there yet."""
    if not os.path.exists(path):
        return None
    backup = _temp_for(path)
    os.unlink(backup)
    try:
        os.link(path, backup)
    except OSError:
        shutil.copy2(path, backup)
    return backup


def _replace_all(pairs: Sequence[tuple[str, str]]) -> None:
    """Move every temporary file over its target; if one move fails, put back the targets
    already replaced (from backups) so that either all or none changed."""
    backups = [_backup(path) for _tmp, path in pairs] if len(pairs) > 1 else [None]
    done = 0
    try:
        for tmp, path in pairs:
            os.replace(tmp, path)
            done += 1
    except BaseException:
        for (_tmp, path), backup in zip(pairs[:done], backups, strict=False):
            if backup is None:
                _unlink_quietly(path)
            else:
                os.replace(backup, path)
        raise
    finally:
        for backup in backups:
            if backup is not None:
                _unlink_quietly(backup)


def atomic_write_all(files: Sequence[tuple[str | os.PathLike, Callable[[str], None]]]) -> list[str]:
    """Write several files as one: each ``write(tmp_path)`` writes a temporary file, then
    every temporary file replaces its target, or (on any failure) none does.

    ImageWriteError names the file that failed and says that no file was changed.
    """
    paths = [os.fspath(path) for path, _write in files]
    pairs: list[tuple[str, str]] = []
    current = paths[0] if paths else ""
    try:
        for path, (_p, write) in zip(paths, files, strict=True):
            current = path
            pairs.append((_temp_for(path), path))
            write(pairs[-1][0])
            mode = os.stat(path).st_mode & 0o777 if os.path.exists(path) else 0o666 & ~_umask()
            os.chmod(pairs[-1][0], mode)
        current = ""
        _replace_all(pairs)
    except BaseException as e:
        failed = current or _first_missing(pairs)
        for tmp, _path in pairs:
            _unlink_quietly(tmp)
        if not isinstance(e, Exception):
            raise
        reason = e.strerror if isinstance(e, OSError) and e.strerror else str(e)
        if isinstance(e, ImageWriteError):
            reason = str(e).split(": ", 1)[-1]
        unchanged = "; no file was changed" if len(paths) > 1 else ""
        raise ImageWriteError(f"cannot write image {failed!r}: {reason}{unchanged}") from e
    return paths


def _first_missing(pairs: Sequence[tuple[str, str]]) -> str:
    """The target whose temporary file was not moved (the one a failed replace was on)."""
    return next((path for tmp, path in pairs if os.path.exists(tmp)), pairs[-1][1])


def atomic_write(path: str | os.PathLike, write: Callable[[str], None]) -> str:
    """Run ``write(tmp_path)`` then move the temporary file onto path; clean up on failure."""
    return atomic_write_all([(path, write)])[0]


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
    return atomic_write(path, _bytes_writer(png_bytes(image, srgb=srgb, bits=bits, level=level)))


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
# Written here in numpy + zlib (single-part scanline files, the OpenEXR 2 layout); read
# through the optional OpenEXR package.

_EXR_MAGIC = 20000630
_EXR_TYPES = {np.dtype(np.uint32): 0, np.dtype(np.float16): 1, np.dtype(np.float32): 2}
_EXR_COMPRESSION = {"none": (0, 1), "zips": (2, 1), "zip": (3, 16)}
"""Compression name -> (code in the header, scanlines per block)."""


def _import_openexr():
    try:
        import OpenEXR  # noqa: PLC0415 - optional dependency, imported only when needed
    except ImportError as e:
        raise ImportError(
            "reading EXR files needs the 'OpenEXR' Python package (pip install openexr)"
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


def _exr_attribute(name: str, kind: str, value: bytes) -> bytes:
    return name.encode() + b"\0" + kind.encode() + b"\0" + struct.pack("<i", len(value)) + value


def _exr_header(arrays: Mapping[str, np.ndarray], code: int) -> bytes:
    """Magic number, version 2 (single-part scanline) and the eight required attributes."""
    h, w = next(iter(arrays.values())).shape
    chlist = b"".join(
        name.encode() + b"\0" + struct.pack("<iB3xii", _EXR_TYPES[a.dtype], 0, 1, 1)
        for name, a in arrays.items()
    )
    window = struct.pack("<iiii", 0, 0, w - 1, h - 1)
    attributes = [
        _exr_attribute("channels", "chlist", chlist + b"\0"),
        _exr_attribute("compression", "compression", bytes([code])),
        _exr_attribute("dataWindow", "box2i", window),
        _exr_attribute("displayWindow", "box2i", window),
        _exr_attribute("lineOrder", "lineOrder", b"\0"),
        _exr_attribute("pixelAspectRatio", "float", struct.pack("<f", 1.0)),
        _exr_attribute("screenWindowCenter", "v2f", struct.pack("<ff", 0.0, 0.0)),
        _exr_attribute("screenWindowWidth", "float", struct.pack("<f", 1.0)),
    ]
    return struct.pack("<ii", _EXR_MAGIC, 2) + b"".join(attributes) + b"\0"


def _exr_zip(raw: bytes, level: int) -> bytes:
    """OpenEXR's ZIP block coding: bytes split into even/odd halves, delta-coded, deflated;
    the raw bytes when that is not smaller (as the format allows)."""
    b = np.frombuffer(raw, dtype=np.uint8)
    t = np.concatenate([b[0::2], b[1::2]]).astype(np.int16)
    t[1:] = (t[1:] - t[:-1] + 128) & 0xFF
    packed = zlib.compress(t.astype(np.uint8).tobytes(), level)
    return packed if len(packed) < len(raw) else raw


def exr_bytes(channels: Mapping[str, Any], *, compression: str = "zip", level: int = 6) -> bytes:
    """Encode named (h, w) channels (float32; float16/uint32 kept) as an OpenEXR file."""
    if not channels:
        raise ValueError("write_exr needs at least one channel")
    if compression not in _EXR_COMPRESSION:
        raise ValueError(
            f"EXR compression must be one of {sorted(_EXR_COMPRESSION)}, got {compression!r}"
        )
    shape, arrays = None, {}
    for name in sorted(str(n) for n in channels):  # the format lists channels by name
        if not name or "\0" in name or len(name.encode()) > 255:
            raise ValueError(f"EXR channel name {name!r} must be 1 to 255 bytes, no NUL")
        arrays[name] = _exr_channel(name, channels[name], shape)
        shape = arrays[name].shape
    code, lines = _EXR_COMPRESSION[compression]
    h = next(iter(arrays.values())).shape[0]
    # one row of the file: every channel's values of that scanline, little-endian, in order
    rows = np.concatenate(
        [
            a.astype(a.dtype.newbyteorder("<")).view(np.uint8).reshape(h, -1)
            for a in arrays.values()
        ],
        axis=1,
    )
    header = _exr_header(arrays, code)
    starts = range(0, h, lines)
    position = len(header) + 8 * len(starts)
    offsets, blocks = [], []
    for y in starts:
        raw = rows[y : y + lines].tobytes()
        data = raw if code == 0 else _exr_zip(raw, level)
        offsets.append(position)
        blocks.append(struct.pack("<ii", y, len(data)) + data)
        position += len(blocks[-1])
    return header + struct.pack(f"<{len(offsets)}Q", *offsets) + b"".join(blocks)


def _bytes_writer(data: bytes) -> Callable[[str], None]:
    """write(tmp) for atomic_write: the bytes, flushed to the disk."""

    def write(tmp: str) -> None:
        with open(tmp, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())

    return write


def write_exr(
    path: str | os.PathLike, channels: Mapping[str, Any], *, compression: str = "zip"
) -> str:
    """Write named (h, w) channels (float32; float16/uint32 kept) to an EXR file, atomically."""
    return write_exr_files([(path, channels)], compression=compression)[0]


def write_exr_files(
    files: Sequence[tuple[str | os.PathLike, Mapping[str, Any]]], *, compression: str = "zip"
) -> list[str]:
    """Write several EXR files (path, channels) as one: all are replaced, or none is
    (atomic_write_all); returns their paths."""
    encoded = [(path, exr_bytes(chans, compression=compression)) for path, chans in files]
    return atomic_write_all([(path, _bytes_writer(data)) for path, data in encoded])


def read_exr(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Read an EXR file -> {channel name: (h, w) array} (interleaved RGB(A) split by name)."""
    exr = _import_openexr()
    out = {}
    with exr.File(os.fspath(path), separate_channels=True) as f:
        for name, ch in f.channels().items():
            out[name] = np.array(ch.pixels)
    return out

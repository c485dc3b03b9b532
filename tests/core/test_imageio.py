"""PNG/EXR writing: exact round trips, an independent decoder, atomic replacement."""

import os
import sys

import numpy as np
import pytest

from core import imageio
from core.imageio import (
    FAILED_COLOR,
    ImageWriteError,
    linear_to_srgb,
    read_exr,
    read_png,
    srgb_to_linear,
    write_exr,
    write_png,
)
from tests.exr_faults import fail_passes_file

RNG = np.random.default_rng(7)


def _codes(shape, top=255):
    return RNG.integers(0, top + 1, shape)


def test_srgb_transfer_reference_values():
    assert linear_to_srgb(0.5) == pytest.approx(0.7353569830524495)
    assert linear_to_srgb(0.0031308) == pytest.approx(0.0031308 * 12.92)
    assert linear_to_srgb(1.0) == pytest.approx(1.0) and linear_to_srgb(-1.0) == 0
    x = np.linspace(0, 1, 1001)
    assert np.allclose(srgb_to_linear(linear_to_srgb(x)), x, atol=1e-14)


@pytest.mark.parametrize("channels", [1, 2, 3, 4])
@pytest.mark.parametrize("bits", [8, 16])
def test_png_round_trip_exact(tmp_path, channels, bits):
    top = (1 << bits) - 1
    codes = _codes((7, 5, channels), top)
    path = tmp_path / "a.png"
    write_png(path, codes / top, srgb=False, bits=bits)
    back = read_png(path, srgb=False)
    assert back.shape == (7, 5, channels)
    assert np.array_equal(np.rint(back * top), codes) and np.allclose(back, codes / top)


def test_png_srgb_default_encodes_colour_not_alpha(tmp_path):
    codes = _codes((4, 6, 4))
    linear = srgb_to_linear(codes / 255.0)
    linear[..., 3] = codes[..., 3] / 255.0  # alpha stays linear
    path = tmp_path / "s.png"
    write_png(path, linear)  # srgb=True is the default
    raw = read_png(path, srgb=False)
    assert np.array_equal(np.rint(raw * 255), codes)
    assert np.allclose(read_png(path), linear, atol=1e-12)


def test_png_clips_and_handles_nan(tmp_path):
    img = np.array([[[-1.0, 2.0, np.nan, np.inf]]])
    write_png(tmp_path / "c.png", img, srgb=False)
    assert read_png(tmp_path / "c.png", srgb=False).tolist() == [[[0.0, 1.0, 0.0, 1.0]]]


def test_png_decodes_with_an_independent_reader(tmp_path):
    image_mod = pytest.importorskip("PIL.Image")
    codes = _codes((9, 11, 4))
    write_png(tmp_path / "p.png", codes / 255.0, srgb=False)
    with image_mod.open(tmp_path / "p.png") as im:
        assert im.mode == "RGBA" and im.size == (11, 9)
        assert np.array_equal(np.asarray(im), codes)


def test_failed_color_is_magenta():
    assert FAILED_COLOR == (1.0, 0.0, 1.0, 1.0)


def test_exr_round_trip(tmp_path):
    pytest.importorskip("OpenEXR")
    h, w = 6, 9
    chans = {c: RNG.normal(size=(h, w)).astype(np.float32) for c in "RGBA"}
    chans["SymRay.Error"] = RNG.random((h, w))  # float64 -> stored as float32
    chans["SymRay.Steps"] = RNG.integers(0, 1000, (h, w)).astype(np.uint32)
    path = write_exr(tmp_path / "x.exr", chans)
    back = read_exr(path)
    assert set(back) == set(chans)
    for name, arr in chans.items():
        expected = arr.astype(np.uint32 if arr.dtype == np.uint32 else np.float32)
        assert back[name].dtype == expected.dtype and np.array_equal(back[name], expected)


def test_exr_validation_and_missing_package(tmp_path, monkeypatch):
    """Writing needs numpy alone (Blender does not bundle OpenEXR); reading needs OpenEXR."""
    with pytest.raises(ValueError):
        write_exr(tmp_path / "x.exr", {"R": np.zeros((2, 2)), "G": np.zeros((3, 2))})
    with pytest.raises(ValueError):
        write_exr(tmp_path / "x.exr", {})
    with pytest.raises(ValueError, match="compression"):
        write_exr(tmp_path / "x.exr", {"R": np.zeros((2, 2))}, compression="piz")
    monkeypatch.setitem(sys.modules, "OpenEXR", None)
    path = write_exr(tmp_path / "x.exr", {"R": np.zeros((2, 2))})
    assert open(path, "rb").read(4) == b"\x76\x2f\x31\x01"  # the EXR magic number
    with pytest.raises(ImportError, match="OpenEXR"):
        read_exr(path)


@pytest.mark.parametrize("compression", ["none", "zips", "zip"])
@pytest.mark.parametrize("shape", [(1, 1), (17, 33), (40, 3)])
def test_exr_written_here_reads_back_through_openexr(tmp_path, compression, shape):
    """The numpy encoder against the OpenEXR library's reader: every compression, block
    sizes that do not divide the height, NaN and infinities kept, names as given."""
    pytest.importorskip("OpenEXR")
    chans = {
        "R": RNG.normal(size=shape).astype(np.float32) * 1e30,
        "SymRay Error.X": np.where(RNG.random(shape) < 0.5, np.nan, 1.0).astype(np.float32),
        "Z": np.full(shape, np.inf, np.float32),
        "half": RNG.normal(size=shape).astype(np.float16),
        "count": RNG.integers(0, 2**32 - 1, shape, dtype=np.uint32),
    }
    back = read_exr(write_exr(tmp_path / "x.exr", chans, compression=compression))
    assert set(back) == set(chans)
    for name, arr in chans.items():
        assert back[name].dtype == arr.dtype
        np.testing.assert_array_equal(back[name], arr)


def test_exr_zip_compresses(tmp_path):
    flat = {"R": np.ones((64, 64), np.float32)}
    assert len(imageio.exr_bytes(flat)) < len(imageio.exr_bytes(flat, compression="none")) / 20


def _old_file(tmp_path, name):
    path = tmp_path / name
    path.write_bytes(b"previous contents")
    return path


def test_failed_png_write_keeps_previous_file(tmp_path, monkeypatch):
    path = _old_file(tmp_path, "keep.png")

    def broken_fsync(fd):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(imageio.os, "fsync", broken_fsync)
    with pytest.raises(ImageWriteError, match="keep.png"):
        write_png(path, np.zeros((2, 2, 4)))
    assert path.read_bytes() == b"previous contents"
    assert sorted(os.listdir(tmp_path)) == ["keep.png"]  # no temporary file left


def test_failed_exr_write_keeps_previous_file(tmp_path, monkeypatch):
    pytest.importorskip("OpenEXR")
    path = _old_file(tmp_path, "keep.exr")

    def broken_replace(src, dst):
        raise OSError(5, "Input/output error")

    monkeypatch.setattr(imageio.os, "replace", broken_replace)
    with pytest.raises(ImageWriteError, match="keep.exr"):
        write_exr(path, {"R": np.ones((2, 2))})
    assert path.read_bytes() == b"previous contents"
    assert sorted(os.listdir(tmp_path)) == ["keep.exr"]


def test_successful_write_replaces_and_keeps_mode(tmp_path):
    path = _old_file(tmp_path, "r.png")
    os.chmod(path, 0o640)
    write_png(path, np.ones((1, 1, 3)))
    assert read_png(path).shape == (1, 1, 3) and (os.stat(path).st_mode & 0o777) == 0o640
    fresh = tmp_path / "new.png"
    write_png(fresh, np.ones((1, 1, 3)))
    assert os.stat(fresh).st_mode & 0o777 != 0o600  # not mkstemp's private mode


def test_unwritable_paths_name_the_path(tmp_path):
    missing = tmp_path / "no" / "such" / "dir" / "x.png"
    with pytest.raises(ImageWriteError, match="x.png"):
        write_png(missing, np.zeros((1, 1, 4)))
    with pytest.raises(ImageWriteError, match=str(tmp_path.name)):
        write_png(tmp_path, np.zeros((1, 1, 4)))
    assert isinstance(ImageWriteError("x"), OSError)


def test_bad_png_input_shapes(tmp_path):
    with pytest.raises(ValueError):
        write_png(tmp_path / "b.png", np.zeros((2, 2, 5)))
    with pytest.raises(ValueError):
        write_png(tmp_path / "b.png", np.zeros((2, 2, 3)), bits=12)
    (tmp_path / "n.png").write_bytes(b"not a png")
    with pytest.raises(ValueError):
        read_png(tmp_path / "n.png")


@pytest.mark.parametrize("stage", ["write", "replace"])
def test_a_pair_is_written_whole_or_not_at_all(tmp_path, monkeypatch, stage):
    """The second file failing leaves both previous files as they were, and the message
    names the file that failed."""
    first, second = _old_file(tmp_path, "a.exr"), tmp_path / "a.passes.exr"
    second.write_bytes(b"previous passes")
    reason = fail_passes_file(monkeypatch, imageio, stage)
    files = [(first, {"R": np.ones((2, 2))}), (second, {"G": np.ones((2, 2))})]
    with pytest.raises(ImageWriteError) as info:
        imageio.write_exr_files(files)
    assert str(info.value) == f"cannot write image {str(second)!r}: {reason}; no file was changed"
    assert first.read_bytes() == b"previous contents"
    assert second.read_bytes() == b"previous passes"
    assert sorted(os.listdir(tmp_path)) == ["a.exr", "a.passes.exr"]
    monkeypatch.undo()
    assert imageio.write_exr_files(files) == [str(first), str(second)]
    assert first.read_bytes()[:4] == second.read_bytes()[:4] == b"\x76\x2f\x31\x01"


def test_a_pair_without_previous_files_leaves_none_on_failure(tmp_path, monkeypatch):
    real_replace = os.replace

    def broken_replace(src, dst):
        if str(dst).endswith("passes.exr"):
            raise OSError(5, "Input/output error")
        return real_replace(src, dst)

    monkeypatch.setattr(imageio.os, "replace", broken_replace)
    files = [
        (tmp_path / "a.exr", {"R": np.ones((2, 2))}),
        (tmp_path / "a.passes.exr", {"G": np.ones((2, 2))}),
    ]
    with pytest.raises(ImageWriteError, match="a.passes.exr"):
        imageio.write_exr_files(files)
    assert os.listdir(tmp_path) == []

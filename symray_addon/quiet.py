"""Blender's console chatter held back around the operators a bake runs.

Cycles' bake operator reports "Baking map saved to internal image, save it externally or
pack it" for every object (Python's ``sys.stdout``), and Blender 4.2 prints a status line
("Fra:1 Mem:… | Synchronizing object | …") for every step of it (C's ``stdout``). Neither
says anything to a SymRay user. ``silenced()`` redirects both levels, the file descriptors
1 and 2 included, to a temporary file while its block runs, and restores them however the
block ends; afterwards every held-back line that is not such chatter (``NOISE``) is
written out again, so real warnings and errors still reach the console. An operator's
error raises ``RuntimeError`` with its message as before (reports are not console output).
"""

from __future__ import annotations

import contextlib
import ctypes
import io
import os
import re
import sys
import tempfile
from collections.abc import Iterator

NOISE = re.compile(
    r"^\s*$"
    r"|^Info: Baking map saved to internal image"
    r"|^Fra:\d+ Mem:"  # Blender's render/bake status lines in background mode
)
"""Console lines of a bake that are dropped."""


def _flush_c_streams() -> None:
    """Flush C's stdio buffers (Blender's printf), where the C library can be reached."""
    for name in (None, "ucrtbase", "msvcrt"):
        try:
            libc = ctypes.CDLL(name) if name is None else getattr(ctypes.cdll, name)
            libc.fflush(None)
            return
        except (OSError, AttributeError, TypeError):
            continue


def _flush_python_streams() -> None:
    """Flush Python's standard streams (ignoring closed or missing ones)."""
    for stream in (sys.stdout, sys.stderr, sys.__stdout__, sys.__stderr__):
        with contextlib.suppress(AttributeError, OSError, ValueError):
            stream.flush()


@contextlib.contextmanager
def _descriptors_to(sink: int) -> Iterator[None]:
    """File descriptors 1 and 2 pointed at ``sink`` until the block ends (those that
    cannot be duplicated, as in a process without a console, are left alone)."""
    saved: list[tuple[int, int]] = []
    try:
        for fd in (1, 2):
            try:
                saved.append((fd, os.dup(fd)))
            except OSError:
                continue
        _flush_python_streams()
        _flush_c_streams()
        for fd, _copy in saved:
            os.dup2(sink, fd)
        yield
    finally:
        _flush_python_streams()
        _flush_c_streams()
        for fd, copy in saved:
            os.dup2(copy, fd)
            os.close(copy)


@contextlib.contextmanager
def silenced() -> Iterator[list[str]]:
    """Hold back Blender's and Python's console output until the block ends; yields a list
    that then holds every held-back line. Lines that are not ``NOISE`` are printed again
    (to ``sys.stderr``) once the streams are restored."""
    held: list[str] = []
    python_out, python_err = io.StringIO(), io.StringIO()
    with tempfile.TemporaryFile() as sink:
        try:
            with (
                _descriptors_to(sink.fileno()),
                contextlib.redirect_stdout(python_out),
                contextlib.redirect_stderr(python_err),
            ):
                yield held
        finally:
            sink.seek(0)
            text = sink.read().decode("utf-8", errors="replace")
            held.extend(text.splitlines())
            held.extend(python_out.getvalue().splitlines())
            held.extend(python_err.getvalue().splitlines())
            kept = [line for line in held if not NOISE.match(line)]
            if kept:
                print("\n".join(kept), file=sys.stderr)

"""Faults injected into the writing of an EXR pair (core.imageio), for its tests in the core
and in the add-on."""

from __future__ import annotations

import os
from types import ModuleType
from typing import Any

REASONS = {"write": "No space left on device", "replace": "Input/output error"}
"""What each stage's fault says (the errno's text)."""


def fail_passes_file(monkeypatch: Any, imageio: ModuleType, stage: str) -> str:
    """Make writing any ``*.passes.exr`` fail at ``stage``: "write" (the disk fills half-way
    through its temporary file) or "replace" (renaming it into place fails). Other files
    are written as usual. Returns the fault's reason."""
    if stage == "replace":
        real_replace = os.replace

        def replace(src, dst):
            if str(dst).endswith(".passes.exr"):
                raise OSError(5, REASONS["replace"])
            return real_replace(src, dst)

        monkeypatch.setattr(imageio.os, "replace", replace)
        return REASONS["replace"]
    real_writer = imageio._bytes_writer

    def disk_full_on_passes(data):
        def write(tmp):
            if ".passes.exr." not in os.path.basename(tmp):
                return real_writer(data)(tmp)
            with open(tmp, "wb") as f:
                f.write(data[: len(data) // 2])
            raise OSError(28, REASONS["write"])

        return write

    monkeypatch.setattr(imageio, "_bytes_writer", disk_full_on_passes)
    return REASONS["write"]

"""Tiles: an image's units of work and what a tile adds to the image.

Offers ``Tile`` (a rectangle of pixels), ``tiles`` (the tiles covering an image),
``TileResult`` (a tile's colour, passes and ray counts), and the sizes ``TILE`` and
``MAX_TILE_PIXELS`` (core.render's bands). Needs nothing of the sampler.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

TILE = 512
"""``tiles``' default: squares of TILE - 1 pixels (core.render makes bands instead)."""
MAX_TILE_PIXELS = 1 << 19
"""core.render's tiles are bands of rows of at most this many pixels (memory: ~0.8 kB a
tile pixel at the peak, lattice and temporaries; ~400 MiB a worker, measured)."""


@dataclass(frozen=True)
class Tile:
    """A rectangle of pixels [x0, x1) x [y0, y1) (row 0 at the top)."""

    x0: int
    y0: int
    x1: int
    y1: int

    @property
    def shape(self) -> tuple[int, int]:
        """(height, width) of the tile in pixels."""
        return self.y1 - self.y0, self.x1 - self.x0


def tiles(width: int, height: int, size: int | None = None, rows: int | None = None) -> list[Tile]:
    """The tiles covering a width x height image, ``size`` pixels wide (default TILE - 1)
    and ``rows`` high (default: as wide), row by row from the top."""
    size = size or TILE - 1
    rows = rows or size
    return [
        Tile(x, y, min(x + size, width), min(y + rows, height))
        for y in range(0, height, rows)
        for x in range(0, width, size)
    ]


@dataclass
class TileResult:
    """What a tile adds to the image: per-pixel colour and passes, and its ray counts."""

    rgba: np.ndarray  # (h, w, 4) float32
    passes: dict[str, np.ndarray]
    """The stored passes (core.passes.STORED) by name, (h, w) or (h, w, channels), each of
    its pass's type: the pixel centre's (error: +inf where failed)."""
    energy: np.ndarray  # (h, w) |H - H0|
    rays: int
    error_rays: int  # companions and retraces
    companion_rays: int = 0  # the error pass's companion runs alone

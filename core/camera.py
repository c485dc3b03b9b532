"""Cameras: pixel index -> world-space ray (origin, unit direction), in Blender's conventions.

A camera is a frame (position + orthonormal right/up/back axes, Blender's camera-local X, Y,
Z: it looks down -Z) and a *window*: a linear map from Blender's raster coordinates
(x to the right, y upwards, in pixels of the full frame) to

- perspective: (x, y) on the image plane at distance 1 in front of the camera,
- orthographic: (x, y) offsets in world units on the camera plane,
- panorama (equirectangular): (longitude, latitude) in radians, longitude positive to the
  right of the view direction, latitude positive upwards.

The window follows Blender's ``BKE_camera_params_compute_viewplane`` (sensor fit with pixel
aspect, shift in units of the fitted image dimension) and Cycles' equirectangular camera.
Images are row-major with row 0 at the TOP; rays go through pixel centres.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["Camera", "Frame"]

_KINDS = ("persp", "ortho", "pano")


@dataclass(frozen=True)
class Frame:
    """Observer frame in world space: position and orthonormal forward/right/up axes."""

    position: np.ndarray
    forward: np.ndarray
    right: np.ndarray
    up: np.ndarray

    @property
    def matrix(self) -> np.ndarray:
        """3x3 matrix whose columns are right, up, forward (local -> world)."""
        return np.stack([self.right, self.up, self.forward], axis=1)

    def to_local(self, v: np.ndarray) -> np.ndarray:
        """World vectors (..., 3) -> components along (right, up, forward)."""
        return np.asarray(v, dtype=np.float64) @ self.matrix

    def to_world(self, c: np.ndarray) -> np.ndarray:
        """Components along (right, up, forward) (..., 3) -> world vectors."""
        return np.asarray(c, dtype=np.float64) @ self.matrix.T


def _unit(v: Any, name: str) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64).reshape(3)
    n = float(np.linalg.norm(v))
    if not np.isfinite(n) or n == 0.0:
        raise ValueError(f"{name} must be a finite non-zero 3-vector, got {v.tolist()}")
    return v / n


def _look_at_basis(position: Any, look_at: Any, up: Any) -> tuple[np.ndarray, np.ndarray]:
    """Position and 3x3 basis (columns right, up, back) of a camera looking at a point."""
    pos = np.asarray(position, dtype=np.float64).reshape(3)
    fwd = _unit(np.asarray(look_at, dtype=np.float64).reshape(3) - pos, "look_at - position")
    right = np.cross(fwd, _unit(up, "up"))
    if np.linalg.norm(right) < 1e-12:
        raise ValueError("up must not be parallel to the viewing direction")
    right /= np.linalg.norm(right)
    return pos, np.stack([right, np.cross(right, fwd), -fwd], axis=1)


def _matrix_basis(matrix_world: Any) -> tuple[np.ndarray, np.ndarray]:
    """Position and orthonormal basis (columns X, Y, Z) of a 4x4 world matrix, scale removed."""
    m = np.asarray(matrix_world, dtype=np.float64)
    if m.shape != (4, 4) or not np.all(np.isfinite(m)):
        raise ValueError(f"matrix_world must be a finite 4x4 matrix, got shape {m.shape}")
    z = _unit(m[:3, 2], "matrix_world Z axis")
    y = m[:3, 1] - (m[:3, 1] @ z) * z
    y = _unit(y, "matrix_world Y axis")
    x = np.cross(y, z)
    if m[:3, 0] @ x < 0.0:  # mirrored matrix: keep Blender's X axis
        x = -x
    return m[:3, 3].copy(), np.stack([x, y, z], axis=1)


def _viewplane(
    ortho: bool,
    lens: float,
    sensor_x: float,
    sensor_y: float,
    sensor_fit: str,
    shift: tuple[float, float],
    ortho_scale: float,
    winx: int,
    winy: int,
    aspx: float,
    aspy: float,
) -> tuple[float, float, float, float]:
    """Blender's view plane (xmin, xmax, ymin, ymax) at distance 1 (persp) or in world units."""
    ycor = aspy / aspx
    if ortho:
        pixsize = ortho_scale
    else:
        pixsize = (sensor_y if sensor_fit == "VERTICAL" else sensor_x) / lens
    fit = sensor_fit
    if fit == "AUTO":
        fit = "HORIZONTAL" if aspx * winx >= aspy * winy else "VERTICAL"
    viewfac = winx if fit == "HORIZONTAL" else ycor * winy
    pixsize /= viewfac
    dx, dy = shift[0] * viewfac, shift[1] * viewfac
    return (
        (-0.5 * winx + dx) * pixsize,
        (0.5 * winx + dx) * pixsize,
        (-0.5 * ycor * winy + dy) * pixsize,
        (0.5 * ycor * winy + dy) * pixsize,
    )


def _border_region(border: Any, winx: int, winy: int) -> tuple[int, int, int, int]:
    """Pixel rectangle (x0, x1, y0, y1), y from the bottom, as Blender truncates border * size."""
    if border is None:
        return 0, winx, 0, winy
    b = np.asarray(border, dtype=np.float32).reshape(4)  # Blender stores and multiplies floats
    if not np.all((b >= 0) & (b <= 1)) or b[0] >= b[1] or b[2] >= b[3]:
        raise ValueError(f"border must be (min_x, max_x, min_y, max_y) in [0, 1], got {border}")
    x0, x1 = (int(v) for v in b[:2] * np.float32(winx))
    y0, y1 = (int(v) for v in b[2:] * np.float32(winy))
    if x1 <= x0 or y1 <= y0:
        raise ValueError(f"border {tuple(border)} selects no pixel of a {winx}x{winy} image")
    return x0, x1, y0, y1


def _check_size(width: Any, height: Any) -> tuple[int, int]:
    w, h = int(width), int(height)
    if w < 1 or h < 1 or w != width or h != height:
        raise ValueError(f"image size must be positive integers, got {width}x{height}")
    return w, h


class Camera:
    """A pinhole, orthographic or equirectangular camera producing one ray per pixel."""

    def __init__(
        self,
        kind: str,
        position: Any,
        basis: Any,
        window: tuple[float, float, float, float],
        full_size: tuple[int, int],
        region: tuple[int, int, int, int] | None = None,
    ) -> None:
        """Low-level constructor; prefer the classmethods (see the module docstring)."""
        if kind not in _KINDS:
            raise ValueError(f"camera kind must be one of {_KINDS}, got {kind!r}")
        self.kind = kind
        self._position = np.asarray(position, dtype=np.float64).reshape(3).copy()
        self._basis = np.asarray(basis, dtype=np.float64).reshape(3, 3).copy()
        self.window = tuple(float(v) for v in window)
        self.full_size = _check_size(*full_size)
        self.region = region if region is not None else (0, full_size[0], 0, full_size[1])

    # -- constructors -------------------------------------------------------------------
    @classmethod
    def perspective(
        cls,
        position: Any,
        look_at: Any,
        up: Any,
        fov_deg: float,
        width: int,
        height: int,
    ) -> Camera:
        """Pinhole camera; fov_deg spans the larger image dimension (Blender AUTO fit)."""
        if not 0.0 < fov_deg < 180.0:
            raise ValueError(f"fov_deg must be in (0, 180), got {fov_deg}")
        w, h = _check_size(width, height)
        pos, basis = _look_at_basis(position, look_at, up)
        lens = 0.5 / math.tan(math.radians(fov_deg) / 2)  # sensor width 1 spans the fov
        window = _viewplane(False, lens, 1.0, 1.0, "AUTO", (0.0, 0.0), 1.0, w, h, 1.0, 1.0)
        return cls("persp", pos, basis, window, (w, h))

    @classmethod
    def orthographic(
        cls,
        position: Any,
        look_at: Any,
        up: Any,
        ortho_scale: float,
        width: int,
        height: int,
    ) -> Camera:
        """Parallel projection; ortho_scale (world units) spans the larger image dimension."""
        if not ortho_scale > 0.0:
            raise ValueError(f"ortho_scale must be positive, got {ortho_scale}")
        w, h = _check_size(width, height)
        pos, basis = _look_at_basis(position, look_at, up)
        window = _viewplane(True, 1.0, 1.0, 1.0, "AUTO", (0.0, 0.0), ortho_scale, w, h, 1, 1)
        return cls("ortho", pos, basis, window, (w, h))

    @classmethod
    def panorama(cls, position: Any, look_at: Any, up: Any, width: int, height: int) -> Camera:
        """Full-sphere equirectangular camera (Cycles): image centre = view direction."""
        w, h = _check_size(width, height)
        pos, basis = _look_at_basis(position, look_at, up)
        return cls("pano", pos, basis, (-math.pi, math.pi, -math.pi / 2, math.pi / 2), (w, h))

    @classmethod
    def blender(
        cls,
        *,
        type: str = "PERSP",
        lens: float = 50.0,
        sensor_width: float = 36.0,
        sensor_height: float = 24.0,
        sensor_fit: str = "AUTO",
        shift_x: float = 0.0,
        shift_y: float = 0.0,
        ortho_scale: float = 6.0,
        resolution_x: int = 1920,
        resolution_y: int = 1080,
        resolution_percentage: int = 100,
        pixel_aspect_x: float = 1.0,
        pixel_aspect_y: float = 1.0,
        matrix_world: Any = None,
        border: Any = None,
        panorama_type: str = "EQUIRECTANGULAR",
        latitude_min: float = -math.pi / 2,
        latitude_max: float = math.pi / 2,
        longitude_min: float = -math.pi,
        longitude_max: float = math.pi,
    ) -> Camera:
        """Camera from Blender's camera/render data (defaults are Blender's own defaults)."""
        if type not in ("PERSP", "ORTHO", "PANO"):
            raise ValueError(f"camera type must be 'PERSP', 'ORTHO' or 'PANO', got {type!r}")
        if sensor_fit not in ("AUTO", "HORIZONTAL", "VERTICAL"):
            raise ValueError(f"sensor_fit must be AUTO, HORIZONTAL or VERTICAL: {sensor_fit!r}")
        winx = int(resolution_x) * int(resolution_percentage) // 100
        winy = int(resolution_y) * int(resolution_percentage) // 100
        winx, winy = _check_size(winx, winy)
        pos, basis = _matrix_basis(np.eye(4) if matrix_world is None else matrix_world)
        region = _border_region(border, winx, winy)
        if type == "PANO":
            if panorama_type != "EQUIRECTANGULAR":
                raise ValueError(f"only EQUIRECTANGULAR panoramas are supported: {panorama_type}")
            dlon, dlat = longitude_max - longitude_min, latitude_max - latitude_min
            window = (
                longitude_min + shift_x * dlon,
                longitude_max + shift_x * dlon,
                latitude_min + shift_y * dlat,
                latitude_max + shift_y * dlat,
            )
            return cls("pano", pos, basis, window, (winx, winy), region)
        if not (lens > 0 and sensor_width > 0 and sensor_height > 0 and ortho_scale > 0):
            raise ValueError("lens, sensor size and ortho_scale must be positive")
        if not (pixel_aspect_x > 0 and pixel_aspect_y > 0):
            raise ValueError("pixel aspect must be positive")
        window = _viewplane(
            type == "ORTHO", lens, sensor_width, sensor_height, sensor_fit, (shift_x, shift_y),
            ortho_scale, winx, winy, pixel_aspect_x, pixel_aspect_y,
        )  # fmt: skip
        kind = "ortho" if type == "ORTHO" else "persp"
        return cls(kind, pos, basis, window, (winx, winy), region)

    @classmethod
    def from_view(cls, view_matrix: Any, window_matrix: Any, width: int, height: int) -> Camera:
        """The camera of a 3D view (Blender's RegionView3D): its world-to-view matrix and
        its projection (perspective or orthographic, OpenGL convention) at width x height
        pixels. The window is read off the projection: x in [-1, 1] of clip space spans
        [xmin, xmax] at distance 1 (perspective) or in world units (orthographic)."""
        w, h = _check_size(width, height)
        view = np.asarray(view_matrix, dtype=np.float64).reshape(4, 4)
        proj = np.asarray(window_matrix, dtype=np.float64).reshape(4, 4)
        if not (np.all(np.isfinite(view)) and np.all(np.isfinite(proj))):
            raise ValueError("view and window matrices must be finite 4x4 matrices")
        pos, basis = _matrix_basis(np.linalg.inv(view))
        ortho = proj[3, 3] == 1.0
        shift = (proj[0, 3], proj[1, 3]) if ortho else (-proj[0, 2], -proj[1, 2])
        xmin, xmax = (-1.0 - shift[0]) / proj[0, 0], (1.0 - shift[0]) / proj[0, 0]
        ymin, ymax = (-1.0 - shift[1]) / proj[1, 1], (1.0 - shift[1]) / proj[1, 1]
        return cls("ortho" if ortho else "persp", pos, basis, (xmin, xmax, ymin, ymax), (w, h))

    def resized(
        self, width: int, height: int, region: tuple[int, int, int, int] | None = None
    ) -> Camera:
        """The same view at width x height pixels: the full frame, or the part ``region``
        of it ((x0, x1, y0, y1) in those pixels, y up, as Blender's border)."""
        x0, x1, y0, y1 = self.window
        return Camera(self.kind, self._position, self._basis, (x0, x1, y0, y1),
                      (width, height), region)  # fmt: skip

    # -- image geometry -----------------------------------------------------------------
    @property
    def width(self) -> int:
        """Width in pixels of the rendered image (the border region, if any)."""
        return self.region[1] - self.region[0]

    @property
    def height(self) -> int:
        """Height in pixels of the rendered image (the border region, if any)."""
        return self.region[3] - self.region[2]

    @property
    def n_pixels(self) -> int:
        """Number of pixels (rays) of the rendered image."""
        return self.width * self.height

    @property
    def offset(self) -> tuple[int, int]:
        """(column, row) of this image's top-left pixel in the full frame (row 0 at the top)."""
        return self.region[0], self.full_size[1] - self.region[3]

    @property
    def frame(self) -> Frame:
        """Observer frame: camera position, forward (view direction), right and up, unit."""
        b = self._basis
        return Frame(self._position.copy(), -b[:, 2].copy(), b[:, 0].copy(), b[:, 1].copy())

    # -- rays ---------------------------------------------------------------------------
    def pixel_centres(self, start: int = 0, stop: int | None = None) -> np.ndarray:
        """Image points (M, 2) (as ``rays_at`` takes them) of the pixel centres with flat
        indices [start, stop)."""
        stop = self.n_pixels if stop is None else stop
        if not 0 <= start <= stop <= self.n_pixels:
            raise IndexError(f"pixel range [{start}, {stop}) outside [0, {self.n_pixels})")
        row, col = np.divmod(np.arange(start, stop, dtype=np.int64), self.width)
        return np.stack([col + 0.5, row + 0.5], axis=1)

    def window_coords(self, start: int = 0, stop: int | None = None) -> np.ndarray:
        """Window coordinates (M, 2) of the pixel centres with flat indices [start, stop)."""
        return self.image_window_coords(self.pixel_centres(start, stop))

    def image_window_coords(self, xy: np.ndarray) -> np.ndarray:
        """Window coordinates (M, 2) of image points xy (M, 2): x = column, y = row from
        the top, in pixels of this image (pixel (c, r) spans [c, c + 1) x [r, r + 1))."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        x0, _, _, y1 = self.region
        xb = x0 + xy[:, 0]  # Blender raster: x right, y up, full frame
        yb = y1 - xy[:, 1]
        xmin, xmax, ymin, ymax = self.window
        winx, winy = self.full_size
        sx = xmin + (xmax - xmin) * (xb / winx)
        sy = ymin + (ymax - ymin) * (yb / winy)
        return np.stack([sx, sy], axis=1)

    def pixel_angle(self, distance: float = 1.0) -> float:
        """The angle (radians) one pixel spans at the image centre; for an orthographic
        camera, a pixel's width over ``distance`` (the distance it is seen at)."""
        xmin, xmax, _, _ = self.window
        size = (xmax - xmin) / self.full_size[0]
        if self.kind == "ortho":
            return float(size / distance)
        if self.kind == "pano":
            return float(size)
        cx, cy = self.image_window_coords(np.array([[0.5 * self.width, 0.5 * self.height]]))[0]
        r2 = 1.0 + cx * cx + cy * cy  # a pixel's angle shrinks off axis as 1 / (1 + s^2)
        return float(size / r2)

    def rays(self, start: int = 0, stop: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Origins (M, 3) and unit directions (M, 3) for flat pixel indices [start, stop)."""
        return self.rays_at_window(self.window_coords(start, stop))

    def rays_at(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Origins (M, 3) and unit directions (M, 3) through image points xy (M, 2) (x =
        column, y = row from the top, in pixels; pixel centres at +0.5)."""
        return self.rays_at_window(self.image_window_coords(xy))

    def image_points(self, directions: np.ndarray) -> np.ndarray:
        """Image points xy (M, 2) (as ``rays_at`` takes them) whose rays leave the camera
        along unit world ``directions`` (M, 3): the inverse of rays_at; NaN for directions
        no pixel of the (full) frame's plane looks along (behind a perspective camera; any
        of an orthographic one's but its own)."""
        c = np.asarray(directions, dtype=np.float64).reshape(-1, 3) @ self._basis  # r, u, b
        with np.errstate(all="ignore"):
            if self.kind == "persp":
                ahead = -c[:, 2]
                s = np.where((ahead > 0)[:, None], c[:, :2] / ahead[:, None], np.nan)
            elif self.kind == "pano":
                lon = np.arctan2(c[:, 0], -c[:, 2])
                s = np.stack([lon, np.arcsin(np.clip(c[:, 1], -1.0, 1.0))], axis=1)
            else:
                return np.full((c.shape[0], 2), np.nan)
        xmin, xmax, ymin, ymax = self.window
        winx, winy = self.full_size
        x0, _, _, y1 = self.region
        xb = (s[:, 0] - xmin) / (xmax - xmin) * winx
        yb = (s[:, 1] - ymin) / (ymax - ymin) * winy
        return np.stack([xb - x0, y1 - yb], axis=1)

    def direction_tangents(self, xy: np.ndarray) -> np.ndarray:
        """The derivatives (M, 2, 3) of the unit directions of ``rays_at(xy)`` with respect
        to the image coordinates x (columns) and y (rows, downwards), in world axes; a
        perspective or panoramic camera's (an orthographic one's directions do not vary:
        ValueError)."""
        if self.kind == "ortho":
            raise ValueError(
                "ray differentials (the magnification pass, point stars) need a camera whose "
                "pixels span solid angles (perspective or panoramic), not an orthographic one"
            )
        s = self.image_window_coords(xy)
        xmin, xmax, ymin, ymax = self.window
        winx, winy = self.full_size
        rate = np.array([(xmax - xmin) / winx, -(ymax - ymin) / winy])  # d(window) / d(image)
        right, up, back = self._basis.T
        if self.kind == "persp":
            v = s[:, :1] * right + s[:, 1:] * up - back
            size = np.linalg.norm(v, axis=1, keepdims=True)
            d = v / size
            per_window = [(e - (d @ e)[:, None] * d) / size for e in (right, up)]
        else:
            lon, lat = s[:, :1], s[:, 1:]
            ahead = np.cos(lon) * -back + np.sin(lon) * right
            per_window = [
                np.cos(lat) * (-np.sin(lon) * -back + np.cos(lon) * right),
                -np.sin(lat) * ahead + np.cos(lat) * up,
            ]
        return np.stack([per_window[0] * rate[0], per_window[1] * rate[1]], axis=1)

    def rays_at_window(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Origins (M, 3) and unit directions (M, 3) for window coordinates s (M, 2)."""
        m = s.shape[0]
        right, up, back = self._basis.T
        if self.kind == "persp":
            d = s[:, :1] * right + s[:, 1:] * up - back
            d /= np.linalg.norm(d, axis=1, keepdims=True)
            return np.broadcast_to(self._position, (m, 3)).copy(), d
        if self.kind == "ortho":
            o = self._position + s[:, :1] * right + s[:, 1:] * up
            return o, np.broadcast_to(-back, (m, 3)).copy()
        lon, lat = s[:, :1], s[:, 1:]
        d = np.cos(lat) * (np.cos(lon) * -back + np.sin(lon) * right) + np.sin(lat) * up
        return np.broadcast_to(self._position, (m, 3)).copy(), d

    def __repr__(self) -> str:
        return (
            f"Camera({self.kind!r}, {self.width}x{self.height}, "
            f"position={self._position.tolist()}, window={self.window})"
        )

"""One timed frame of the Kerr board scene, written so that an old checkout runs it too.

    PYTHONPATH=<checkout> python benchmarks/frame.py OUT.npz --width W --height H
        [--method gauss4 --tolerance RAD | --tolerance-px PX [--samples N] [--magnification]]
        [--disk] [--stars COUNT] [--env-sky WIDTH [--unfiltered]]

``--disk`` adds an accretion disk (r_out 10 rg, physical look); ``--stars COUNT`` replaces the
procedural (texture) sky by COUNT random point stars over the Milky Way (core.StarField);
``--env-sky WIDTH`` by an equirect image (filtered over each pixel's footprint, core.mipmap,
unless ``--unfiltered``).

Renders with core.render (error pass on), then saves the time, the rays, and what each
pixel's centre sees (escape direction, or the unit vector to the hit point; NaN where
captured) as that render drew it: for an old checkout, from its tracer at the render's
displayed step (an old checkout's image may show a run at half the step); for this one,
from the ``direction`` pass. Uses only names that exist in every version since the baseline.
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import numpy as np

import core
from core import hamiltonians as hm


class _Textured:
    """A constant-colour primitive recoloured by a texture where it is hit (an old checkout
    asks textures about empty batches and fails there; its figures wrapped textured
    primitives like this)."""

    def __init__(self, obj, texture) -> None:
        self.obj, self.texture, self.bounds = obj, texture, obj.bounds

    def intersect(self, a, b):
        """Nearest hits of segments a -> b, recoloured where they hit."""
        hits = self.obj.intersect(a, b)
        if hits.hit.any():
            h = hits.hit
            hits.color[h] = self.texture(hits.uv[h], hits.position[h], hits.normal[h])
        return hits


def kerr_board_scene(cells: int = 0):
    """Kerr a/M = 0.9 (rg = 1, Kerr-Schild), a 16 rg checker board 12 rg behind the hole
    (the scene of benchmarks/image_quality.py; repeated here for old checkouts); ``cells``
    > 0: a checker of that many cells a side as the plane's own colour (averaged over each
    pixel's footprint where the checkout does that)."""
    if cells:
        return core.Scene(model=hm.kerr(rg=1.0, a=0.45, chart="kerr_schild"),
                          objects=[core.Plane(point=(0, 12, 0), normal=(0, -1, 0),
                                              u_axis=(1, 0, 0), extent=(16, 16),
                                              color=core.checker(cells, cells))],
                          background="procedural")  # fmt: skip
    plane = core.Plane(point=(0, 12, 0), normal=(0, -1, 0), u_axis=(1, 0, 0),
                       extent=(16, 16))  # fmt: skip
    board = _Textured(plane, core.checker(8, 8))
    return core.Scene(model=hm.kerr(rg=1.0, a=0.45, chart="kerr_schild"), objects=[board],
                      background="procedural")  # fmt: skip


def camera(width: int, height: int):
    """The camera of benchmarks/image_precision.py (30 rg, fov 40 degrees)."""
    return core.Camera.perspective(position=(0, -30, 2), look_at=(0, 0, 0), up=(0, 0, 1),
                                   fov_deg=40, width=width, height=height)  # fmt: skip


def _old_directions(scene, cam, method: str, tolerance: float) -> tuple:
    """What an old render drew per pixel: its tracer at half the step (step doubling)."""
    from core.render import _scene_extent
    from core.trace import TraceOptions, Tracer

    extent = _scene_extent(scene, cam)
    tracer = Tracer(scene, TraceOptions(method=method, tolerance=tolerance), extent)
    origins, dirs = cam.rays()
    rays = tracer.trace(origins, dirs, step=0.5 * tracer.step)
    to_end = rays.position - origins
    to_end /= np.linalg.norm(to_end, axis=1, keepdims=True)
    seen = np.where((rays.ending == core.ENDING["escaped"])[:, None], rays.direction, to_end)
    seen[rays.ending == core.ENDING["captured"]] = np.nan
    return seen.reshape(cam.height, cam.width, 3), rays.ending.reshape(cam.height, cam.width)


def _env_sky(width: int, unfiltered: bool):
    """A seeded noise sky (width, width / 2): texel noise over smooth blobs; with
    ``unfiltered`` a callable doing the plain bilinear lookup (which no checkout filters)."""
    rng = np.random.default_rng(3)
    image = 0.4 + 0.3 * rng.random((width // 2, width, 3))
    coarse = rng.random((8, 16, 3))
    image *= np.repeat(np.repeat(coarse, width // 16, axis=0), width // 16, axis=1)
    if unfiltered:
        return lambda d: core.sky.equirect_lookup(image, d)
    return core.Background(image)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out")
    parser.add_argument("--width", type=int, default=512)
    parser.add_argument("--height", type=int, default=288)
    parser.add_argument("--method", default=None)
    parser.add_argument("--tolerance", type=float, default=None)
    parser.add_argument("--tolerance-px", type=float, default=None)
    parser.add_argument("--samples", type=int, default=1)
    parser.add_argument(
        "--magnification",
        action="store_true",
        help="also the magnification pass (ray differentials)",
    )
    parser.add_argument("--disk", action="store_true", help="add an accretion disk")
    parser.add_argument(
        "--stars", type=int, default=0, help="point stars instead of the texture sky"
    )
    parser.add_argument(
        "--env-sky",
        type=int,
        default=0,
        help="an equirect noise image this many texels wide as the sky (filtered over each "
        "pixel's footprint where the checkout does that)",
    )
    parser.add_argument(
        "--unfiltered", action="store_true", help="with --env-sky: looked up at one point"
    )
    parser.add_argument(
        "--board-cells",
        type=int,
        default=0,
        help="the board's checker as the plane's own colour, this many cells a side "
        "(filtered over each pixel's footprint where the checkout does that)",
    )
    args = parser.parse_args()
    scene, cam = kerr_board_scene(args.board_cells), camera(args.width, args.height)
    if args.disk:  # Scene binds the disk to its model
        scene = dataclasses.replace(scene, disk=core.AccretionDisk(r_out=10.0))
    if args.stars:
        scene = dataclasses.replace(scene, background=core.StarField.random(args.stars, seed=1))
    if args.env_sky:
        scene = dataclasses.replace(scene, background=_env_sky(args.env_sky, args.unfiltered))
    kwargs = {"method": args.method} if args.method else {}
    if args.tolerance_px is not None:
        kwargs.update(tolerance_px=args.tolerance_px, samples=args.samples)
        kwargs["passes"] = ("error", "error_px", "steps", "ending", "direction")
        if args.magnification:
            kwargs["passes"] += ("magnification",)
    else:
        kwargs["tolerance"] = args.tolerance
    start = time.perf_counter()
    result = core.render(scene, cam, **kwargs)
    seconds = time.perf_counter() - start
    if "direction" in result.passes:
        seen, ending = result.passes["direction"], result.passes["ending"]
    else:
        seen, ending = _old_directions(scene, cam, args.method or "gauss4", args.tolerance)
    rays = result.summary.get("rays", cam.width * cam.height)
    np.savez(args.out, seconds=seconds, rays=rays, seen=seen, ending=ending,
             steps=result.summary["steps"])  # fmt: skip
    images = result.summary.get("star_images")
    stars = "" if images is None else f", {images} star images"
    print(f"{seconds:.2f} s, {rays} rays, {result.summary['steps']} steps{stars}")


if __name__ == "__main__":
    main()

"""Mirages (seed Figs. 10 and 11): which pixels an object's colours reach.

A vertical board 20 m away is painted in three bands, red (top), green, white (bottom);
the ground is grey, the sky blue. One column of pixels is traced and read top to bottom
as a string of band letters: straight rays see "RGW" once; the mirages add images.
"""

import itertools

import numpy as np

import core
from core import hamiltonians as hm
from core.presets import MIRAGE_EQ17_INDEX, MIRAGE_EQ18_INDEX, band_texture


def banded_board(distance, z0, z1):
    """The mirage scenes' banded board (core.presets.band_texture) as a triangle mesh."""
    paint = band_texture(z0, z1)
    v = np.array(
        [[distance, -0.5, z0], [distance, 0.5, z0], [distance, 0.5, z1], [distance, -0.5, z1]]
    )
    return core.TriangleMesh(vertices=v, faces=np.array([[0, 1, 2], [0, 2, 3]]), color=paint)


def column(model, camera_z, tilt, board, fov_deg):
    """Letters seen top to bottom: R G W (board bands), '.' sky, '_' ground; runs merged."""
    ground = core.Plane(point=(0, 0, 0), normal=(0, 0, 1), color=(0.3, 0.3, 0.3, 1))
    scene = core.Scene(
        model=model, objects=[banded_board(20.0, *board), ground], background=(0, 0, 1)
    )
    cam = core.Camera.perspective(
        position=(0, 0, camera_z),
        look_at=(1, 0, camera_z + tilt),
        up=(0, 0, 1),
        fov_deg=fov_deg,
        width=1,
        height=300,
    )
    out = core.render(scene, cam, method="yoshida4", step=0.05, passes=("ending",))
    assert out.summary["failed"] == 0
    rgb = out.rgba[:, 0, :3]
    letters = np.where(
        rgb.sum(1) > 2.5,
        "W",
        np.where(
            rgb[:, 0] > 0.5,
            "R",
            np.where(rgb[:, 1] > 0.5, "G", np.where(rgb[:, 2] > 0.5, ".", "_")),
        ),
    )
    return "".join(k for k, _ in itertools.groupby("".join(letters)))


def test_without_a_medium_the_board_is_seen_once_upright():
    assert column(None, 0.4, -0.03, (0.1, 0.7), 6) == ".RGW_"


def test_inferior_mirage_eq17_inverted_image_and_sky_below_the_object():
    """Fig. 10: the board's top (R) appears again *below* green, then mirrored sky."""
    seen = column(hm.medium(MIRAGE_EQ17_INDEX, literal=True), 0.4, -0.03, (0.1, 0.7), 6)
    assert seen == ".RGR._", seen  # direct R, G; inverted G, R; the sky's mirror image


def test_vince_phenomenon_eq18_ghosts_above_the_object():
    """Fig. 11: above the upright board (R G W at the bottom) an inverted ghost (W G R)."""
    seen = column(hm.medium(MIRAGE_EQ18_INDEX, literal=True), 0.9, 0.03, (0.2, 0.9), 8)
    assert seen.endswith("WGRGW_"), seen  # ... W G R (inverted ghost) G W ... (upright)
    assert seen.rstrip("_").endswith("RGW") and seen.count("R") == 2

"""Charged black holes on the Black Hole object (issue 46): a Charge beside Size and Spin
makes the hole Reissner–Nordström or Kerr–Newman (core.models.registry), and F12 casts the
analytic shadow: every pixel whose centre is off by more than 1 px from the critical curve
(Bardeen 1973's spherical photon orbits with Δ = r² − rg r + a² + Q², computed here) is
on the right side of it."""

from __future__ import annotations

import math

import bpy
import numpy as np
import pytest

from .test_first_contact import f12

DISTANCE = 40.0  # scene units from the hole (its Size is 1)
WIDTH, HEIGHT, LENS = 96, 72, 160.0  # the shadow ~28 px in radius, whole in the frame


def _critical_curve(mass: float, a: float, charge: float) -> np.ndarray:
    """(2, K) celestial coordinates (α, β) of the shadow's edge seen from the equator,
    in scene units; a circle of Reissner–Nordström's b_c at a = 0."""
    q2 = charge * charge
    if a == 0.0:
        r_ph = 0.5 * (3 * mass + math.sqrt(9 * mass * mass - 8 * q2))
        b = r_ph / math.sqrt(1 - 2 * mass / r_ph + q2 / r_ph**2)
        t = np.linspace(0, 2 * np.pi, 2000)
        return np.stack([b * np.cos(t), b * np.sin(t)])
    r_plus = mass + math.sqrt(mass * mass - a * a - q2)
    r = np.linspace(r_plus * (1 + 1e-9), 4 * mass, 400_000)
    delta = r * r - 2 * mass * r + a * a + q2
    xi = (r * r + a * a - 2 * r * delta / (r - mass)) / a
    eta = 4 * r * r * delta / (r - mass) ** 2 - (xi - a) ** 2
    seen = eta >= 0.0  # β² = η at inclination 90°
    alpha, beta = -xi[seen], np.sqrt(eta[seen])
    return np.stack([np.concatenate([alpha, alpha]), np.concatenate([beta, -beta])])


def _curve_in_pixels(curve: np.ndarray, rg: float, charge_length: float) -> np.ndarray:
    """(K, 2) image positions (column, row from the bottom) of the curve, from a static
    camera at DISTANCE: sin θ = b √f(D) / D (Synge), θ the angle from the image centre."""
    f = 1 - rg / DISTANCE + charge_length**2 / DISTANCE**2
    b = np.hypot(*curve)
    theta = np.arcsin(b * math.sqrt(f) / DISTANCE)
    focal = LENS / 36.0 * WIDTH
    scale = focal * np.tan(theta) / b
    return np.stack([WIDTH / 2 + curve[0] * scale, HEIGHT / 2 + curve[1] * scale], axis=1)


@pytest.mark.parametrize(
    ("spin", "charge", "kind"),
    [(0.0, 0.6, "REISSNER_NORDSTROM"), (0.6, 0.45, "KERR_NEWMAN")],
)
def test_a_charged_hole_casts_the_analytic_shadow(addon, factory_scene, tmp_path, spin, charge,
                                                  kind):  # fmt: skip
    scene = factory_scene
    bpy.data.objects.remove(bpy.data.objects["Cube"])
    scene.world.node_tree.nodes["Background"].inputs["Color"].default_value = (1, 1, 1, 1)
    scene.cursor.location = (0.0, 0.0, 0.0)
    assert bpy.ops.symray.add_black_hole(size=1.0, spin=spin, disk=False) == {"FINISHED"}
    hole = bpy.context.active_object
    hole.symray.charge = charge
    effective = addon.module("symray_addon.objects").effective(scene.symray)
    assert effective.model == kind
    camera = scene.camera
    camera.location, camera.rotation_euler = (0.0, -DISTANCE, 0.0), (math.pi / 2, 0.0, 0.0)
    camera.data.lens, camera.data.sensor_fit = LENS, "HORIZONTAL"
    scene.render.resolution_x, scene.render.resolution_y = WIDTH, HEIGHT
    scene.symray.quality, scene.symray.tolerance_px, scene.symray.samples = "CUSTOM", 0.25, 1
    bpy.context.view_layer.update()
    image = f12(scene, tmp_path)
    shadow = image[..., :3].max(axis=-1) < 1e-3
    # the hole's Size is its horizon r+ = M (1 + √(1 − χ² − q²)): M from it, a and Q from M
    mass = 1.0 / (1 + math.sqrt(1 - spin * spin - charge * charge))
    curve = _curve_in_pixels(
        _critical_curve(mass, spin * mass, charge * mass), 2 * mass, charge * mass
    )
    rows, cols = np.mgrid[0:HEIGHT, 0:WIDTH]
    centres = np.stack([cols.ravel() + 0.5, rows.ravel() + 0.5], axis=1)
    inside = _inside(centres, curve).reshape(HEIGHT, WIDTH)
    wrong = np.argwhere(inside != shadow)
    if len(wrong):
        points = np.stack([wrong[:, 1] + 0.5, wrong[:, 0] + 0.5], axis=1)
        gaps = np.min(np.linalg.norm(points[:, None, :] - curve[None, ::20, :], axis=2), axis=1)
        assert gaps.max() < 1.0, (len(wrong), gaps.max())
    assert shadow.sum() > 1800 and not shadow[[0, -1]].any()  # its whole shape, ~28 px


def _inside(points: np.ndarray, curve: np.ndarray) -> np.ndarray:
    """Whether each point (N, 2) is inside the closed curve (K, 2), by ray casting along +x."""
    loop = _closed(curve)
    x0, y0 = loop[:-1, 0], loop[:-1, 1]
    x1, y1 = loop[1:, 0], loop[1:, 1]
    px, py = points[:, 0:1], points[:, 1:2]
    crosses = (y0 > py) != (y1 > py)
    with np.errstate(divide="ignore", invalid="ignore"):
        at = x0 + (py - y0) * (x1 - x0) / (y1 - y0)
    return np.count_nonzero(crosses & (px < at), axis=1) % 2 == 1


def _closed(curve: np.ndarray) -> np.ndarray:
    """The curve's points in order around it (by angle about its mean), closed."""
    centre = curve.mean(axis=0)
    order = np.argsort(np.arctan2(curve[:, 1] - centre[1], curve[:, 0] - centre[0]))
    ordered = curve[order][::10]
    return np.concatenate([ordered, ordered[:1]])


def test_a_charged_hole_refuses_a_disk_by_name(addon, factory_scene):
    """Kerr's circular orbits are the disk's: a charged hole with the disk on is refused
    with what to change; at charge 0 (Kerr) nothing is refused."""
    scene = factory_scene
    scene.cursor.location = (0.0, 0.0, 5.0)
    assert bpy.ops.symray.add_black_hole(size=0.5, spin=0.6, disk=True) == {"FINISHED"}
    hole = bpy.context.active_object
    validation = addon.module("symray_addon.validation")
    assert validation.settings_problems(scene.symray) == []
    hole.symray.charge = 0.3
    problems = validation.settings_problems(scene.symray)
    assert problems == [
        "The Accretion Disk needs a Schwarzschild or Kerr hole: its gas follows their "
        "orbits, which a Kerr–Newman hole does not have; set the hole's Charge to 0 or turn "
        "the disk off"
    ]


def test_the_overlay_draws_a_charged_holes_photon_orbits(addon):
    """Reissner–Nordström's photon sphere (3M + √(9M² − 8Q²))/2 both ways at spin 0; at a
    vanishing charge, Bardeen, Press & Teukolsky's Kerr orbits; charge shrinks both."""
    overlay = addon.module("symray_addon.overlay")
    mass, charge = 0.5, 0.8
    r_ph = 0.5 * (3 * mass + math.sqrt(9 * mass**2 - 8 * (charge * mass) ** 2))
    np.testing.assert_allclose(overlay.photon_orbit_radii(1.0, 0.0, charge), [r_ph, r_ph],
                               rtol=1e-4)  # fmt: skip
    kerr = overlay.photon_orbit_radii(1.0, 0.7)
    np.testing.assert_allclose(overlay.photon_orbit_radii(1.0, 0.7, 1e-6), kerr, rtol=1e-4)
    charged = overlay.photon_orbit_radii(1.0, 0.7, 0.5)
    assert charged[0] < kerr[0] and charged[1] < kerr[1]

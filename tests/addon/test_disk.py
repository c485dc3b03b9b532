"""The accretion disk in Blender: its settings, checks, preset, and the "SymRay Redshift"
pass reaching the compositor and the EXR written by F12."""

from __future__ import annotations

import math

import bpy
import numpy as np
import pytest

OpenEXR = pytest.importorskip("OpenEXR")


def _disk_scene(scene, helpers):
    """The preset's disk settings on a Kerr a/M = 0.9 hole of rg 0.5 (the explicit model at
    a centre Empty) with its disk to 3 units, seen at inclination 80 deg from 12 units."""
    assert bpy.ops.symray.apply_preset(preset="KERR_DISK", frame_camera=False) == {"FINISHED"}
    for obj in list(scene.objects):
        bpy.data.objects.remove(obj)
    settings = scene.symray
    settings.model, settings.rg, settings.spin = "KERR", 0.5, 0.9
    settings.center = helpers.add_empty(scene)
    settings.disk.outer_radius = 3.0
    settings.disk.look, settings.disk.brightness = "PHYSICAL", 0.6  # as the tests were written
    inc = math.radians(80.0)
    cam = helpers.add_camera(scene, location=(0.0, -12 * math.sin(inc), 12 * math.cos(inc)),
                             rotation=(inc, 0.0, 0.0))  # fmt: skip
    scene.render.resolution_x, scene.render.resolution_y = 32, 16
    scene.symray.tolerance = 1e-4
    helpers.set_world_color(scene, (0.0, 0.0, 0.0, 1.0))
    return cam


def test_preset_sets_the_scene(scene):
    assert bpy.ops.symray.apply_preset(preset="KERR_DISK") == {"FINISHED"}
    settings = scene.symray
    assert settings.model == "OBJECTS" and settings.center is None
    hole = next(o for o in scene.objects if o.symray.kind == "BLACK_HOLE")
    assert (hole.symray.size, hole.symray.spin) == (1.0, pytest.approx(0.9))
    disk = settings.disk
    assert disk.enabled and disk.use_isco and disk.doppler
    assert disk.outer_radius == 12.0 and disk.profile == "NOVIKOV_THORNE"
    assert settings.pass_redshift and "redshift" in settings.passes()
    # another preset turns the disk off again
    assert bpy.ops.symray.apply_preset(preset="KERR") == {"FINISHED"}
    assert not settings.disk.enabled


def test_compositor_sees_the_redshift_pass(scene, helpers):
    scene.render.engine = "SYMRAY"
    settings = scene.symray
    settings.pass_error = settings.pass_steps = settings.pass_ending = False
    outputs = helpers.symray_outputs(scene)

    assert outputs() == set()
    settings.pass_redshift = True
    assert outputs() == {"SymRay Redshift"}


def test_disk_settings_are_checked(addon, scene, helpers):
    _disk_scene(scene, helpers)
    validation = addon.module("symray_addon.validation")
    settings = scene.symray
    assert validation.settings_problems(settings) == []
    isco = validation.inner_edge(settings)
    assert isco == pytest.approx(0.25 * 2.320883041761887, rel=1e-6)  # a/M = 0.9, M = 0.25
    settings.disk.use_isco = False
    settings.disk.inner_radius = 0.9 * isco
    assert any(p.startswith("Disk Inner Radius must be a finite number in [") for p in
               validation.settings_problems(settings))  # fmt: skip
    settings.disk.inner_radius = 1.0
    assert validation.settings_problems(settings) == []
    settings.disk.opacity = 0.5
    assert validation.settings_problems(settings) == []
    settings["disk"]["opacity"] = 0.0  # a .blend or script past the limits
    assert any(p.startswith("Disk Opacity must be a finite number in (0, 1]") for p in
               validation.settings_problems(settings))  # fmt: skip
    settings.disk.opacity = 1.0
    settings["disk"]["temperature"] = float("nan")  # a .blend or script past the limits
    assert any(p.startswith("Disk Temperature must be") for p in
               validation.settings_problems(settings))  # fmt: skip
    settings.disk.temperature = 5000.0
    settings.model = "MEDIUM"
    assert "Accretion Disk needs a Schwarzschild or Kerr model" in validation.settings_problems(
        settings
    )
    job = addon.module("symray_addon.render_job")
    with pytest.raises(ValueError, match="Accretion Disk needs"):
        job.prepare(scene, bpy.context.evaluated_depsgraph_get())


def test_f12_writes_the_redshift_pass(addon, scene, helpers, tmp_path):
    _disk_scene(scene, helpers)
    scene.render.engine = "SYMRAY"
    image = scene.render.image_settings
    if "media_type" in image.bl_rna.properties:
        image.media_type = "MULTI_LAYER_IMAGE"
    image.file_format = "OPEN_EXR_MULTILAYER"
    image.color_depth = "32"
    scene.render.filepath = str(tmp_path / "disk")
    scene.render.use_file_extension = True
    bpy.ops.render.render(write_still=True)
    with OpenEXR.File(str(tmp_path / "disk.exr"), separate_channels=True) as f:
        channels = {n: np.array(c.pixels) for part in f.parts for n, c in part.channels.items()}
    g = next(v for k, v in channels.items() if k.endswith("SymRay Redshift.X"))
    job = addon.module("symray_addon.render_job")
    reference = job.run(job.prepare(scene, bpy.context.evaluated_depsgraph_get()))
    on = np.isfinite(reference.passes["redshift"])
    assert on.sum() > 20
    np.testing.assert_array_equal(np.isfinite(g), on)
    # rtol: F12 reads the render depsgraph, the reference the viewport's (float32 camera
    # matrices that differ in the last bits; see test_render.py)
    np.testing.assert_allclose(g[on], reference.passes["redshift"][on], rtol=1e-4)
    assert g[on].min() < 0.9 and g[on].max() > 1.1  # the receding and approaching sides
    left = on & (np.arange(32) < 16)[None, :]
    assert np.median(g[left]) > np.median(g[on & ~left])  # approaching side: x < 0, left


@pytest.mark.parametrize("spin", [1.0, -1.0])
def test_an_extremal_spin_with_the_disk_is_a_named_problem(addon, scene, helpers, spin):
    """Spin a/M = ±1 with the disk: the panel's checks name it as it is typed, and a render
    refuses with the same message (never a bare ZeroDivisionError); without the disk, or
    just below ±1, nothing is wrong."""
    _disk_scene(scene, helpers)
    validation = addon.module("symray_addon.validation")
    settings = scene.symray
    settings.spin = spin
    message = (
        f"Spin must lie in (-1, 1) with an accretion disk, got {spin:g}: at ±1 the disk's "
        "innermost stable orbit meets the horizon"
    )
    assert [p for p in validation.settings_problems(settings) if p.startswith(message)]
    job = addon.module("symray_addon.render_job")
    with pytest.raises(ValueError, match=r"Spin must lie in \(-1, 1\) with an accretion"):
        job.prepare(scene, bpy.context.evaluated_depsgraph_get())
    settings.disk.enabled = False
    assert validation.settings_problems(settings) == []
    settings.disk.enabled = True
    settings.spin = 0.9999 * spin
    assert validation.settings_problems(settings) == []


@pytest.mark.parametrize("quality", ["RADIANS", "FINAL"])
def test_transparent_film_keeps_a_translucent_disk(addon, scene, helpers, quality):
    """Film › Transparent with a translucent disk (the preset's, opacity 0.5): a ray
    crossing the disk and escaping keeps the disk's light, premultiplied, with alpha
    1 - 0.5^k after k crossings (it was RGBA 0). The transparent render composited over
    the world colour is the opaque render, to float32, with one ray per pixel and with the
    preset's 16 samples (the same samples and filter weights: the anti-aliasing decisions
    agree here; a faint edge whose contrast is all in alpha would be anti-aliased in the
    transparent render only)."""
    _disk_scene(scene, helpers)
    world = np.array([0.2, 0.3, 0.4])
    helpers.set_world_color(scene, (*world, 1.0))
    settings = scene.symray
    settings.quality = quality
    settings.disk.opacity = 0.5
    settings.pass_ending = True
    job = addon.module("symray_addon.render_job")
    renders = {}
    for transparent in (False, True):
        scene.render.film_transparent = transparent
        renders[transparent] = job.run(job.prepare(scene, bpy.context.evaluated_depsgraph_get()))
    opaque, clear = renders[False].rgba, renders[True].rgba
    assert np.all(opaque[..., 3] == 1.0)
    composite = clear[..., :3] + (1.0 - clear[..., 3:]) * world
    np.testing.assert_allclose(composite, opaque[..., :3], rtol=1e-6, atol=1e-7)
    through = np.isfinite(renders[True].passes["redshift"])  # crossed the disk ...
    through &= renders[True].passes["ending"] == addon.core.ENDING["escaped"]  # ... and out
    assert through.sum() > 20
    assert np.all(clear[through][:, :3] > 0.0)
    if quality == "RADIANS":  # alpha of a pixel centre's ray after k crossings: 1 - 0.5^k
        crossings = np.log2(1.0 - clear[through][:, 3].astype(np.float64))
        np.testing.assert_allclose(crossings, np.round(crossings), atol=1e-6)
        assert np.all(crossings <= -1) and np.mean(crossings == -1) > 0.8
    else:
        assert np.all(clear[through][:, 3] > 0.0)
    sky = ~np.isfinite(renders[True].passes["redshift"])
    sky &= renders[True].passes["ending"] == addon.core.ENDING["escaped"]
    clear_sky = np.all(clear[sky] == 0.0, axis=1)
    # with samples, pixels beside an edge whose centre sees the sky are partly covered
    assert sky.sum() > 100 and (
        np.all(clear_sky) if quality == "RADIANS" else clear_sky.mean() > 0.8
    )


# --- looks and automatic exposure (issue 24) ----------------------------------------------

LUMA = np.array([0.2126, 0.7152, 0.0722])
"""Rec.709 luma weights: the brightness of display values."""


def _read_png(path) -> np.ndarray:
    """A PNG's display values (h, w, 4), row 0 at the top (read as Non-Color: a 16-bit
    PNG would otherwise be made scene-linear)."""
    img = bpy.data.images.load(str(path))
    img.colorspace_settings.name = "Non-Color"
    w, h = img.size
    flat = np.empty(w * h * 4, dtype=np.float32)
    img.pixels.foreach_get(flat)
    bpy.data.images.remove(img)
    return flat.reshape(h, w, 4)[::-1]


def test_the_look_settings_reach_the_core_disk(addon, scene, helpers):
    """Look, Beaming and Auto Exposure / Exposure become the core disk's look, beaming and
    exposure (None: automatic); the add-on's defaults: Physical, automatic."""
    _disk_scene(scene, helpers)
    models = addon.module("symray_addon.models")
    disk = scene.symray.disk
    rna = disk.bl_rna.properties
    assert (rna["look"].default, rna["auto_exposure"].default) == ("PHYSICAL", True)
    assert (disk.look, disk.auto_exposure) == ("PHYSICAL", True)
    core_disk = models.build_disk(scene.symray)
    assert (core_disk.look, core_disk.exposure) == ("physical", None)
    assert core_disk.beaming == pytest.approx(0.3)
    disk.look, disk.beaming, disk.auto_exposure, disk.exposure = "EHT", 0.0, False, 2.5
    core_disk = models.build_disk(scene.symray)
    assert (core_disk.look, core_disk.exposure, core_disk.beaming) == ("eht", 2.5, 0.0)
    disk.look = "CINEMATIC"
    assert models.build_disk(scene.symray).look == "cinematic"


@pytest.mark.parametrize("look", ["PHYSICAL", "CINEMATIC", "EHT"])
def test_each_look_shows_the_disk_near_middle_grey(addon, scene, helpers, tmp_path, look):
    """Acceptance (issue 24): the Kerr with Accretion Disk preset (its framing, at 160 x 90,
    Preview) in each look, with automatic exposure, rendered by F12 and written through
    Blender's colour management (AgX, the default view transform, and the same render
    saved through Standard): the median brightness (Rec.709 luma of the display values) of
    the pixels showing the disk (a finite SymRay Redshift) lies in [0.3, 0.7]."""
    assert bpy.ops.symray.apply_preset(preset="KERR_DISK") == {"FINISHED"}
    scene.render.resolution_x, scene.render.resolution_y = 160, 90
    settings = scene.symray
    settings.quality = "PREVIEW"
    settings.disk.look = look
    assert settings.disk.auto_exposure
    helpers.set_world_color(scene, (0.0, 0.0, 0.0, 1.0))
    assert scene.view_settings.view_transform == "AgX"
    scene.render.engine = "SYMRAY"
    image = scene.render.image_settings
    image.file_format, image.color_mode, image.color_depth = "PNG", "RGB", "16"
    scene.render.filepath = str(tmp_path / "look")
    scene.render.use_file_extension = True
    bpy.ops.render.render(write_still=True)
    scene.view_settings.view_transform = "Standard"
    bpy.data.images["Render Result"].save_render(str(tmp_path / "standard.png"), scene=scene)
    job = addon.module("symray_addon.render_job")
    reference = job.run(job.prepare(scene, bpy.context.evaluated_depsgraph_get()))
    on = np.isfinite(reference.passes["redshift"])
    assert on.sum() > 1000
    assert reference.summary["disk_exposure"] > 0
    medians = {}
    for name in ("look.png", "standard.png"):
        display = _read_png(tmp_path / name)
        assert display.shape[:2] == on.shape
        medians[name] = float(np.median(display[on, :3] @ LUMA))
        assert 0.3 <= medians[name] <= 0.7, (look, medians)
    exposure = reference.summary["disk_exposure"]
    print(f"{look}: AgX {medians['look.png']:.3f}, Standard {medians['standard.png']:.3f}, "
          f"exposure {exposure:.3g}")  # fmt: skip

"""The extension installs, enables, survives disable/enable, and registers the contract."""

from __future__ import annotations

from types import SimpleNamespace

import bpy
import pytest

MODELS = {"OBJECTS", "FLAT", "SCHWARZSCHILD", "KERR", "MEDIUM", "METRIC", "CUSTOM",
          "REISSNER_NORDSTROM", "KERR_NEWMAN"}  # fmt: skip
METHOD_ORDER = (
    # the numbers a .blend stores the Method enum by (once its items' positions): fixed
    ("symplectic_euler", "stormer_verlet", "implicit_midpoint", "gauss4", "yoshida4")
    + ("yoshida6", "yoshida8", "suzuki4", "suzuki6", "tao2", "tao4", "rk4", "dopri5")
    + ("leapfrog", "blanes_moan4", "blanes_moan6", "AUTO", "blanes_moan_s6", "blanes_moan_s10")
)


def _registered() -> bool:
    return (
        hasattr(bpy.types.Scene, "symray")
        and hasattr(bpy.types, "RENDER_PT_symray")
        and "SYMRAY" in _engines()
    )


def _engines() -> set[str]:
    """Render engines Blender accepts now (assigning an unknown one raises TypeError)."""
    render = bpy.context.scene.render
    previous = render.engine
    try:
        render.engine = "SYMRAY"
    except TypeError:
        return {previous}
    render.engine = previous
    return {previous, "SYMRAY"}


def test_installed_and_enabled(addon):
    import addon_utils

    assert addon_utils.check(addon.package) == (True, True)
    assert _registered()
    assert hasattr(bpy.ops.symray, "render")
    assert bpy.ops.symray.render.idname() == "SYMRAY_OT_render"


def test_disable_enable_survives(addon, scene):
    bpy.ops.preferences.addon_disable(module=addon.package)
    try:
        assert not hasattr(bpy.types.Scene, "symray")
        assert "SYMRAY" not in _engines()
        assert "SYMRAY" not in bpy.types.RENDER_PT_format.COMPAT_ENGINES
    finally:
        bpy.ops.preferences.addon_enable(module=addon.package)
    assert _registered()
    bpy.ops.preferences.addon_disable(module=addon.package)
    bpy.ops.preferences.addon_enable(module=addon.package)
    assert _registered()
    scene.render.engine = "SYMRAY"
    assert scene.symray.image_name == "SymRay Result"
    assert "SYMRAY" in bpy.types.RENDER_PT_format.COMPAT_ENGINES


def test_contract_properties(addon, scene):
    settings = scene.symray
    rna = settings.bl_rna.properties
    assert {item.identifier for item in rna["model"].enum_items} == MODELS
    # Blender stores an enum by its items' numbers: each method keeps the number it had
    # (old .blend files), and every method of the core is offered, with Automatic first
    items = rna["method"].enum_items
    assert {item.identifier: item.value for item in items} == {
        name: number for number, name in enumerate(METHOD_ORDER)
    }
    assert items[0].identifier == "AUTO" and [item.identifier for item in items[1:]] == list(
        addon.module("core.integrators").METHODS
    )
    settings["method"] = METHOD_ORDER.index("blanes_moan6")  # as a .blend stores it
    assert settings.method == "blanes_moan6"
    assert rna["center"].fixed_type.identifier == "Object"
    assert settings.center is None
    assert settings.image_name == "SymRay Result"
    assert settings.exr_path == ""
    assert settings.rg > 0 and rna["rg"].hard_min > 0
    assert rna["spin"].soft_min == -1.0 and rna["spin"].soft_max == 1.0
    for name in (
        "refractive_index",
        "metric",
        "hamiltonian",
        "tolerance",
        "quality",
        "tolerance_px",
        "samples",
        "max_steps",
        "pass_error",
        "pass_steps",
        "pass_ending",
    ):
        assert name in rna, name
    assert settings.tolerance > 0 and settings.max_steps > 0
    assert settings.passes() == ("steps",)  # the fixture switched the error pass off
    settings.pass_error = settings.pass_steps = settings.pass_ending = True
    assert settings.passes() == ("error_px", "steps", "ending")


def test_center_picker_offers_empties(scene, helpers):
    empty = helpers.add_empty(scene)
    helpers.add_cube(scene, "Cube")
    scene.symray.center = empty
    assert scene.symray.center == empty
    poll = type(scene.symray).bl_rna.properties["center"]
    assert poll.fixed_type.identifier == "Object"


def test_panels_and_compat_engines(addon, scene):
    """SymRay's panels only for the SYMRAY engine; the render button stays
    reachable for other engines; Film › Transparent and View Layer › Passes for SYMRAY."""
    context = SimpleNamespace(scene=scene)
    own = (
        "RENDER_PT_symray",
        "RENDER_PT_symray_integration",
        "RENDER_PT_symray_lighting",
        "RENDER_PT_symray_output",
        "RENDER_PT_symray_film",
    )
    for name in own:
        panel = getattr(bpy.types, name)
        assert panel.bl_context == "render"
        assert panel.COMPAT_ENGINES == {"SYMRAY"}
    passes = bpy.types.VIEWLAYER_PT_symray_passes
    assert passes.bl_parent_id == "VIEWLAYER_PT_layer_passes"
    launch = bpy.types.RENDER_PT_symray_launch
    for engine in ("CYCLES", "BLENDER_WORKBENCH", "SYMRAY"):
        scene.render.engine = engine
        shown = engine == "SYMRAY"
        for name in own:
            assert getattr(bpy.types, name).poll(context) is shown, (name, engine)
        assert passes.poll(context) is shown
        assert launch.poll(context) is not shown
    for name in (
        "RENDER_PT_format",
        "RENDER_PT_output",
        "DATA_PT_lens",
        "DATA_PT_context_mesh",
        "EEVEE_MATERIAL_PT_surface",
        "EEVEE_WORLD_PT_surface",
        "VIEWLAYER_PT_layer_passes",
    ):
        assert "SYMRAY" in getattr(bpy.types, name).COMPAT_ENGINES, name
    for name in ("RENDER_PT_eevee_film", "RENDER_PT_eevee_next_film", "RENDER_PT_opengl_film"):
        panel = getattr(bpy.types, name, None)  # Film is SymRay's own (no EEVEE overscan)
        assert panel is None or "SYMRAY" not in panel.COMPAT_ENGINES, name


def test_engine_passes_declared(scene):
    scene.render.engine = "SYMRAY"
    scene.symray.pass_error = scene.symray.pass_steps = True
    engine = next(
        c
        for c in bpy.types.RenderEngine.__subclasses__()
        if getattr(c, "bl_idname", "") == "SYMRAY"
    )
    assert engine.bl_use_postprocess is True
    assert engine.bl_label == "SymRay"


@pytest.mark.parametrize(
    "preset, model",
    [
        ("SCHWARZSCHILD_LENS", "SCHWARZSCHILD"),
        ("KERR", "KERR"),
        ("MIRAGE_EQ17", "MEDIUM"),
        ("MIRAGE_EQ18", "MEDIUM"),
    ],
)
def test_presets(addon, scene, preset, model):
    assert bpy.ops.symray.apply_preset(preset=preset) == {"FINISHED"}
    settings = scene.symray
    assert addon.module("symray_addon.objects").effective(settings).model == model
    if model != "MEDIUM":  # a black hole: the scene's hole object, framed by its camera
        assert settings.model == "OBJECTS" and scene.camera is not None
    else:
        assert settings.center is not None and settings.center.type == "EMPTY"
    if model == "MEDIUM":
        assert settings.index_form == "SEED"
        assert settings.refractive_index_error == ""


def test_compositor_sees_passes(scene, helpers):
    """Render Layers node outputs follow the pass toggles (update_render_passes)."""
    scene.render.engine = "SYMRAY"
    settings = scene.symray
    settings.pass_error, settings.pass_steps, settings.pass_ending = True, True, False
    outputs = helpers.symray_outputs(scene)

    assert outputs() == {"SymRay Error", "SymRay Steps"}
    settings.pass_ending = True
    assert outputs() == {"SymRay Error", "SymRay Steps", "SymRay Ending"}
    settings.pass_error = False
    assert outputs() == {"SymRay Steps", "SymRay Ending"}


def test_the_passes_follow_the_core_table(addon, scene):
    """The add-on's passes are the core table's labelled ones (core.passes.PASSES): each has
    its scene.symray toggle (named, default and description from the table), its render pass
    and its passes-EXR layer, in the table's order."""
    table = [p for p in addon.module("core.passes").PASSES if p.label]
    assert [p.name for p in table] == ["error_px", "steps", "ending", "redshift", "magnification"]
    rna = scene.symray.bl_rna.properties
    for kind in table:
        assert rna[kind.toggle].name == kind.label
        assert rna[kind.toggle].default == kind.shown
        assert kind.layer in rna[kind.toggle].description
    engine = addon.module("symray_addon.engine")
    assert engine.PASSES == tuple((p.name, p.layer, p.toggle) for p in table)
    layers = addon.module("symray_addon.output").PASS_LAYERS
    assert layers == {p.name: f"{p.layer}.X" for p in table}

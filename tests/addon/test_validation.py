"""Expressions are validated as they are typed; errors name the problem and its column."""

from __future__ import annotations

import bpy
import pytest


def test_index_error_appears_and_clears(scene):
    s = scene.symray
    s.refractive_index = "1 + 0.1*w"
    assert "unknown name 'w'" in s.refractive_index_error
    assert "column 9" in s.refractive_index_error
    s.refractive_index = "1 + 0.1*exp(-z)"
    assert s.refractive_index_error == ""


@pytest.mark.parametrize(
    "text, problem",
    [
        ("__import__('os').system('true')", "not allowed"),
        ("x.real", "attribute access"),
        ("1 +* 2", "syntax error"),
        ("open('f')", "unknown function"),
        ("", "empty"),
    ],
)
def test_index_refuses_unsafe_or_broken_text(scene, text, problem):
    scene.symray.refractive_index = text
    assert problem in scene.symray.refractive_index_error


def test_hamiltonian_names(scene):
    s = scene.symray
    s.hamiltonian = "0.5*(p_x**2 + p_y**2 + p_z**2) - 1/sqrt(x**2 + y**2 + z**2)"
    assert s.hamiltonian_error == ""
    s.hamiltonian = "0.5*px**2"
    assert "unknown name 'px'" in s.hamiltonian_error


def test_metric_valid_forms(scene):
    s = scene.symray
    assert s.metric_error == ""  # default: Minkowski
    s.metric = (
        "r = sqrt(x**2 + y**2 + z**2); f = 1 - 1/r; "
        "-1/f, 0, 0, 0; 0, f, 0, 0; 0, 0, 1, 0; 0, 0, 0, atan2(y, x)**0"
    )
    assert s.metric_error == ""


@pytest.mark.parametrize(
    "text, problem",
    [
        ("-1, 0, 0, 0; 0, 1, 0, 0; 0, 0, 1, 0", "has 3 rows, needs 4"),
        ("-1, 0, 0; 0, 1, 0, 0; 0, 0, 1, 0; 0, 0, 0, 1", "row 1 has 3 entries"),
        ("-1, x, 0, 0; 0, 1, 0, 0; 0, 0, 1, 0; 0, 0, 0, 1", "symmetric"),
        ("-1, 0, 0, 0; 0, 1, 0, 0; 0, 0, 1, 0; 0, 0, 0, q", "g^33: unknown name 'q'"),
    ],
)
def test_metric_errors(scene, text, problem):
    scene.symray.metric = text
    assert problem in scene.symray.metric_error


def test_metric_error_column_points_at_the_entry(addon):
    validation = addon.module("symray_addon.validation")
    text = "-1, 0, 0, 0; 0, 1, 0, 0; 0, 0, 1, 0; 0, 0, 0, 2*q"
    with pytest.raises(ValueError) as info:
        validation.parse_metric(text)
    assert info.value.column == text.index("q") + 1


def test_metric_text_block(scene, helpers):
    s = scene.symray
    text = bpy.data.texts.new("metric")
    text.write(
        "# Minkowski with a helper\nc = 1\n-c, 0, 0, 0\n0, 1, 0, 0\n0, 0, 1, 0\n0, 0, 0, oops\n"
    )
    s.metric_text = text
    assert "line 6" in s.metric_error and "oops" in s.metric_error
    props = addon_props()
    assert props.metric_source(s) == text.as_string()


def addon_props():
    import importlib

    return importlib.import_module("bl_ext.user_default.symray.symray_addon.properties")


def test_errors_refreshed_after_load(scene, tmp_path):
    scene.symray.refractive_index = "1 + y"
    path = str(tmp_path / "saved.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.open_mainfile(filepath=path)
    assert bpy.context.scene.symray.refractive_index_error == ""
    bpy.context.scene.symray.refractive_index = "1 + w"
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.open_mainfile(filepath=path)
    assert "unknown name 'w'" in bpy.context.scene.symray.refractive_index_error


def test_splitting_methods_need_a_model_with_a_split(scene, addon):
    """Automatic is the default; an explicit splitting on extremal Kerr or a user metric is
    named in the panel's problems before a render, and accepted for Schwarzschild, media
    and Kerr below extremal."""
    validation = addon.module("symray_addon.validation")
    s = scene.symray
    assert s.method == "AUTO"
    s.model, s.method, s.spin = "KERR", "blanes_moan_s10", 1.0
    assert any("explicit splitting" in p for p in validation.settings_problems(s))
    s.model = "METRIC"
    assert any("explicit splitting" in p for p in validation.settings_problems(s))
    s.spin = 0.9
    for model in ("SCHWARZSCHILD", "MEDIUM", "KERR"):
        s.model = model
        assert not any("explicit splitting" in p for p in validation.settings_problems(s))


@pytest.mark.parametrize(
    "model, observer, mass, time_scaled, split, disk",
    [("FLAT", False, False, False, False, False),
     ("SCHWARZSCHILD", True, True, True, True, True),
     ("KERR", True, True, True, True, True),
     ("MEDIUM", False, False, False, True, False),
     ("METRIC", True, False, False, False, False),
     ("CUSTOM", False, False, False, False, False)],
)  # fmt: skip
def test_the_panels_models_capabilities_come_from_the_core(
    addon, model, observer, mass, time_scaled, split, disk
):
    """What each panel model can do is asked of the core model it stands for (no list kept
    by hand): rays from an observer's frame (spacetimes), a mass, Poincaré time, an
    explicit split, disk orbits; Kerr at |a/M| = 1 has no split."""
    capabilities = addon.module("symray_addon.capabilities").capabilities
    traits = capabilities(model, 0.5)
    assert (traits.observer, traits.mass, traits.time_scaled, traits.split, traits.disk) == (
        observer,
        mass,
        time_scaled,
        split,
        disk,
    )
    if model == "KERR":
        assert not capabilities(model, 1.0).split and capabilities(model, -0.99).split

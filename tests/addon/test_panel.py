"""The panels draw every model's settings with existing properties and operators."""

from __future__ import annotations

from types import SimpleNamespace

import bpy
import pytest


class FakeLayout:
    """Records what a panel draws and checks that every property/operator exists."""

    def __init__(self, log: list):
        self.log = log
        self.use_property_split = self.use_property_decorate = False
        self.alert = self.active = False
        self.scale_y = 1.0

    def _child(self, *_args, **_kwargs) -> FakeLayout:
        return FakeLayout(self.log)

    row = column = split = box = _child

    def prop(self, data, name: str, **_kwargs) -> None:
        assert name in data.bl_rna.properties, name
        self.log.append(("prop", name))

    def operator(self, idname: str, **_kwargs):
        module, op = idname.split(".")
        assert hasattr(getattr(bpy.ops, module), op), idname
        self.log.append(("operator", idname))
        return SimpleNamespace()

    def menu(self, idname: str, **_kwargs) -> None:
        assert hasattr(bpy.types, idname), idname
        self.log.append(("menu", idname))

    def label(self, text: str = "", **_kwargs) -> None:
        self.log.append(("label", text))

    def separator(self, **_kwargs) -> None:
        pass


def _draw(panel_name: str, scene) -> list:
    panel = getattr(bpy.types, panel_name)
    if panel_name != "RENDER_PT_symray_launch":
        scene.render.engine = "SYMRAY"  # SymRay's panels show for its engine only
    log: list = []
    fake = SimpleNamespace(layout=FakeLayout(log))
    context = SimpleNamespace(scene=scene)
    assert panel.poll(context)
    panel.draw(fake, context)
    if hasattr(panel, "draw_header_preset"):
        panel.draw_header_preset(fake, context)
    return log


@pytest.mark.parametrize(
    "model",
    ["FLAT", "SCHWARZSCHILD", "KERR", "MEDIUM", "METRIC", "CUSTOM", "REISSNER_NORDSTROM",
     "KERR_NEWMAN"],
)  # fmt: skip
def test_main_panel_draws(scene, model):
    scene.symray.model = model
    log = _draw("RENDER_PT_symray", scene)
    assert ("prop", "model") in log and ("operator", "symray.render") in log
    expected = {
        "KERR": "spin",
        "MEDIUM": "refractive_index",
        "METRIC": "metric",
        "CUSTOM": "hamiltonian",
        "SCHWARZSCHILD": "rg",
        "REISSNER_NORDSTROM": "charge",  # rows made from the core's registry
        "KERR_NEWMAN": "charge",
    }.get(model)
    if expected:
        assert ("prop", expected) in log


def test_the_panel_says_how_to_add_a_black_hole(factory_scene):
    log = _draw("RENDER_PT_symray", factory_scene)  # the factory scene: no hole, flat space
    assert ("label", "Flat space: the scene has no black hole") in log
    assert ("operator", "symray.add_black_hole") in log
    bpy.ops.symray.add_black_hole(size=0.5)
    log = _draw("RENDER_PT_symray", factory_scene)
    assert ("operator", "symray.add_black_hole") not in log
    assert ("prop", "size") in log and ("prop", "spin") in log  # the hole's own settings
    hole = bpy.context.active_object
    log = _draw_object(hole, factory_scene)
    assert {("prop", "size"), ("prop", "spin"), ("prop", "outer_radius")} <= set(log)
    assert any(
        text.startswith("Innermost stable orbit: ") and text.endswith(" m")
        for kind, text in log
        if kind == "label"
    )


def test_a_holes_charge_is_drawn_and_checked_on_its_object(factory_scene):
    """The Black Hole object's panel has a Charge (from the registry's hole parameters);
    beyond spin² + charge² < 1 the row is marked and the core's message shown."""
    bpy.ops.symray.add_black_hole(size=0.5, spin=0.6, disk=False)
    hole = bpy.context.active_object
    hole.symray.charge = 0.5
    log = _draw_object(hole, factory_scene)
    assert ("prop", "charge") in log
    assert not any("Charge² < 1" in text for kind, text in log if kind == "label")
    hole.symray.charge = 0.9
    text = " ".join(text for kind, text in _draw_object(hole, factory_scene) if kind == "label")
    assert "Spin² + Charge² < 1" in text, text


def _draw_object(obj, scene) -> list:
    log: list = []
    fake = SimpleNamespace(layout=FakeLayout(log))
    context = SimpleNamespace(scene=scene, object=obj)
    assert bpy.types.OBJECT_PT_symray.poll(context)
    bpy.types.OBJECT_PT_symray.draw(fake, context)
    return log


def test_panel_shows_expression_errors(scene):
    scene.symray.model = "MEDIUM"
    scene.symray.refractive_index = "1 + w"
    labels = [text for kind, text in _draw("RENDER_PT_symray", scene) if kind == "label"]
    assert any("unknown name 'w'" in text for text in labels)
    scene.symray.model = "METRIC"
    text = bpy.data.texts.new("g")
    text.write("-1, 0, 0, 0\n0, 1, 0, 0\n0, 0, 1, 0\n0, 0, 0, zz\n")
    scene.symray.metric_text = text
    labels = [t for kind, t in _draw("RENDER_PT_symray", scene) if kind == "label"]
    assert any("zz" in t for t in labels)


@pytest.mark.parametrize(
    "panel",
    [
        "RENDER_PT_symray_integration",
        "RENDER_PT_symray_lighting",
        "RENDER_PT_symray_output",
        "VIEWLAYER_PT_symray_passes",
    ],
)
def test_sub_panels_draw(scene, panel):
    assert _draw(panel, scene)


def test_lighting_panel_states_the_limits(scene):
    """What baking cannot show is said in the panel, next to the bake button."""
    log = _draw("RENDER_PT_symray_lighting", scene)
    text = " ".join(t for kind, t in log if kind == "label")
    assert "no glossy" in text and "straight paths" in text
    assert ("operator", "symray.bake_lighting") in log
    assert ("prop", "lighting") in log and ("prop", "bake_texel_size") in log


def test_film_panel_shows_what_symray_honours(scene):
    log = _draw("RENDER_PT_symray_film", scene)
    assert ("prop", "filter_size") in log and ("prop", "film_transparent") in log


def test_passes_listed_under_view_layer(scene):
    log = _draw("VIEWLAYER_PT_symray_passes", scene)
    assert {("prop", f"pass_{name}") for name in ("error", "steps", "ending")} <= set(log)


def test_render_button_reachable_for_other_engines(scene):
    scene.render.engine = "CYCLES"
    assert ("operator", "symray.render") in _draw("RENDER_PT_symray_launch", scene)


def _labels(scene) -> list[str]:
    return [text for kind, text in _draw("RENDER_PT_symray", scene) if kind == "label"]


def _camera(scene, location):
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.location = location
    scene.collection.objects.link(cam)
    scene.camera = cam
    bpy.context.view_layer.update()


@pytest.mark.parametrize(
    "setup, words",
    [
        (dict(model="KERR", tolerance=float("nan")), "Tolerance must be a finite number"),
        (dict(model="KERR", method="tao4"), "method 'tao4' cannot render a black hole"),
        (dict(model="KERR", spin=float("nan")), "Spin a/M must be a finite number"),
        (
            dict(model="METRIC", metric="1, 0, 0, 0; 0, -1, 0, 0; 0, 0, -1, 0; 0, 0, 0, -1"),
            "signature (-, -, -, +)",
        ),
        (
            dict(model="METRIC", metric="0, 0, 0, 0; 0, 0, 0, 0; 0, 0, 0, 0; 0, 0, 0, 0"),
            "singular at the camera",
        ),
        (dict(model="SCHWARZSCHILD", rg=40.0), "inside the black hole's horizon"),
        (dict(model="KERR_NEWMAN", spin=0.9, charge=0.6), "Spin² + Charge² < 1"),
        (dict(model="REISSNER_NORDSTROM", rg=40.0), "inside the black hole's horizon"),
    ],
)
def test_panel_shows_render_problems_before_a_render(scene, setup, words):
    """What a render would refuse is shown in the panel before it starts."""
    _camera(scene, (0.0, -30.0, 0.0))
    assert not any(words in text for text in _labels(scene))  # the defaults are fine
    for name, value in setup.items():
        setattr(scene.symray, name, value)
    text = " ".join(_labels(scene))
    assert words in text, text


def test_panel_shows_nothing_for_a_good_setup(scene):
    _camera(scene, (0.0, -30.0, 0.0))
    for model in ("SCHWARZSCHILD", "KERR", "METRIC", "MEDIUM", "CUSTOM", "FLAT",
                  "REISSNER_NORDSTROM", "KERR_NEWMAN"):  # fmt: skip
        scene.symray.model = model
        assert _labels(scene) == [], model


def test_pass_toggles_reach_the_compositor(scene, helpers):
    """The View Layer › Passes toggles re-register the engine's passes: the Render Layers
    node of the compositor shows exactly the passes switched on."""
    scene.render.engine = "SYMRAY"
    scene.symray.pass_error, scene.symray.pass_steps = True, False
    shown = helpers.symray_outputs(scene)

    assert shown() == {"SymRay Error"}
    scene.symray.pass_ending = True
    assert shown() == {"SymRay Error", "SymRay Ending"}

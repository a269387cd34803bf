"""Panels and operators: visibility per engine, every drawn property exists, derived values copied."""

from __future__ import annotations

from pathlib import Path

import pytest
from addon_testing import run_bpy

from addon import mapping

pytestmark = [pytest.mark.blender, pytest.mark.timeout(300)]

UI_SCRIPT = """
import types
import bpy
from addon import engine, properties, render_ui, verify_operator

bpy.ops.wm.read_factory_settings(use_empty=True)
properties.register()
engine.register()
render_ui.register()
verify_operator.register()
scene = bpy.context.scene

class Layout:
    # Records what a panel draws and checks each property and operator against Blender's RNA.
    def __init__(self, log):
        self.log, self.use_property_split = log, False
    def prop(self, data, name, **_):
        assert name in data.bl_rna.properties, f"{type(data).__name__} has no property {name!r}"
        self.log.append(("prop", name))
    def label(self, text="", **_):
        self.log.append(("label", text))
    def operator(self, idname, **_):
        category, name = idname.split(".")
        assert hasattr(getattr(bpy.ops, category), name), idname
        self.log.append(("operator", idname))
    def column(self, **_):
        return self
    def template_ID(self, data, name, **_):
        assert name in data.bl_rna.properties, f"{type(data).__name__} has no property {name!r}"
        self.log.append(("template_ID", name))

def draw(panel, context):
    log = []
    panel.draw(types.SimpleNamespace(layout=Layout(log)), context)
    return log

mat = bpy.data.materials.new("M")
mat.use_nodes = True
bsdf = mat.node_tree.nodes["Principled BSDF"]
bsdf.inputs["Base Color"].default_value = (0.6, 0.3, 0.1, 1.0)
bsdf.inputs["Roughness"].default_value = 0.4
bsdf.inputs["Metallic"].default_value = 0.0
spot = bpy.data.lights.new("Spot", "SPOT")
spot.spot_size, spot.spot_blend, spot.shadow_soft_size = 1.2, 0.4, 0.3

panels = [getattr(render_ui, f"BLINN_PHONG_PT_{name}")
          for name in ("render", "render_effects", "render_last", "material", "light")]
polls = {}
for engine_id in ("BLENDER_WORKBENCH", engine.ENGINE_ID):
    scene.render.engine = engine_id
    ctx = types.SimpleNamespace(engine=scene.render.engine, scene=scene, material=mat, light=spot)
    polls[engine_id] = [p.poll(ctx) for p in panels]
shared = "BLINN_PHONG" in bpy.types.RENDER_PT_format.COMPAT_ENGINES

scene.blinn_phong.transparency = "DEPTH_PEELING"
scene.blinn_phong.shadows = "SOFT"
scene.blinn_phong.fog = "LINEAR"
ctx = types.SimpleNamespace(engine=engine.ENGINE_ID, scene=scene, material=mat, light=spot)
drawn = {p.__name__: draw(p, ctx) for p in panels}
mat.blinn_phong.source = "CUSTOM"
mat.blinn_phong.use_kay_greenberg = True
spot.blinn_phong.source = "CUSTOM"
drawn_custom = {p.__name__: draw(p, ctx) for p in panels[3:]}

mat.blinn_phong.source = "PRINCIPLED"
spot.blinn_phong.source = "BLENDER"
with bpy.context.temp_override(material=mat):
    bpy.ops.blinn_phong.copy_derived_material()
with bpy.context.temp_override(light=spot):
    bpy.ops.blinn_phong.copy_derived_light()
copied = {
    "material_source": mat.blinn_phong.source, "diffuse": list(mat.blinn_phong.diffuse),
    "shininess": mat.blinn_phong.shininess, "specular": list(mat.blinn_phong.specular),
    "light_source": spot.blinn_phong.source, "k": [spot.blinn_phong.constant, spot.blinn_phong.linear,
    spot.blinn_phong.quadratic], "exponent": spot.blinn_phong.spot_exponent,
}
def editor(tree_type):
    return types.SimpleNamespace(space_data=types.SimpleNamespace(tree_type=tree_type), scene=scene)
node_editor, shader_editor = editor("CompositorNodeTree"), editor("ShaderNodeTree")
verify_polls = [verify_operator.BLINN_PHONG_PT_verify.poll(c) for c in (node_editor, shader_editor)]
drawn_verify = draw(verify_operator.BLINN_PHONG_PT_verify, node_editor)
scene.render.engine = "BLENDER_WORKBENCH"
verify_operator.unregister()
render_ui.unregister()
engine.unregister()
properties.unregister()
shared_after = "BLINN_PHONG" in bpy.types.RENDER_PT_format.COMPAT_ENGINES
emit({"polls": polls, "shared": shared, "shared_after": shared_after, "drawn": drawn,
      "drawn_custom": drawn_custom, "copied": copied, "verify_polls": verify_polls,
      "drawn_verify": drawn_verify})
"""


@pytest.fixture(scope="module")
def ui(tmp_path_factory: pytest.TempPathFactory) -> dict:
    return run_bpy(UI_SCRIPT, tmp_path_factory.mktemp("ui"))


def test_panels_show_only_for_the_engine(ui: dict) -> None:
    assert ui["polls"]["BLENDER_WORKBENCH"] == [False] * 5
    assert ui["polls"]["BLINN_PHONG"] == [True] * 5
    assert ui["shared"] is True and ui["shared_after"] is False


def test_panels_draw_the_settings_that_matter(ui: dict) -> None:
    def props(log: list) -> set[str]:
        return {name for kind, name in log if kind == "prop"}

    drawn, custom = ui["drawn"], ui["drawn_custom"]
    assert {"shading", "samples_per_axis", "two_sided"} <= props(drawn["BLINN_PHONG_PT_render"])
    effects = props(drawn["BLINN_PHONG_PT_render_effects"])
    assert {
        "transparency",
        "peel_layers",
        "shadows",
        "shadow_samples",
        "shadow_bias",
        "fog",
        "fog_start",
    } <= effects
    assert ["label", "No render yet in this session"] in drawn["BLINN_PHONG_PT_render_last"]
    # Derived mode shows the derived values and the copy operator; custom mode the editable ones.
    assert ["operator", "blinn_phong.copy_derived_material"] in drawn["BLINN_PHONG_PT_material"]
    assert {
        "diffuse",
        "specular",
        "shininess",
        "opacity",
        "transparency_model",
        "kay_exponent",
        "specular_washout",
    } <= props(custom["BLINN_PHONG_PT_material"])
    assert {"constant", "linear", "quadratic", "spot_exponent"} <= props(custom["BLINN_PHONG_PT_light"])


def test_verify_panel_in_the_compositor_sidebar(ui: dict) -> None:
    assert ui["verify_polls"] == [True, False]
    assert ["template_ID", "verify_background"] in ui["drawn_verify"]
    assert ["prop", "verify_operator"] in ui["drawn_verify"]
    assert ["operator", "blinn_phong.verify_composite"] in ui["drawn_verify"]


def test_copy_derived_values_follow_the_principled_bsdf_and_the_light(ui: dict) -> None:
    copied = ui["copied"]
    assert copied["material_source"] == "CUSTOM" and copied["light_source"] == "CUSTOM"
    assert copied["diffuse"] == pytest.approx([0.6, 0.3, 0.1], abs=1e-6)
    # Walter et al.: s = 2/α² − 2 with α = roughness² = 0.16.
    assert copied["shininess"] == pytest.approx(2 / 0.16**2 - 2, rel=1e-5)
    # Specular: F0 = 0.04 (IOR 1.5, level 0.5) times the normalisation (s + 8)/8.
    s = 2 / 0.16**2 - 2
    assert copied["specular"] == pytest.approx([0.04 * (s + 8) / 8] * 3, rel=1e-5)
    assert copied["k"] == pytest.approx([0.09, 0.0, 1.0], rel=1e-6)
    assert copied["exponent"] == pytest.approx(mapping.spot_exponent(1.2, 0.4), rel=1e-6)


def test_module_registers_in_a_fresh_process(tmp_path: Path) -> None:
    # Registration order of the add-on modules: properties, engine, panels; reverse to unregister.
    got = run_bpy(
        """
        import bpy
        from addon import engine, properties, render_ui
        for _ in range(10):
            for module in (properties, engine, render_ui):
                module.register()
            for module in (render_ui, engine, properties):
                module.unregister()
        emit(hasattr(bpy.types, "BLINN_PHONG_PT_render"))
        """,
        tmp_path,
    )
    assert got is False

"""Blender settings the engine honours: Cast Shadow, Ray Visibility › Shadow, Film › Transparent,
Principled values outside the usual range, and a material that cannot be rendered.

The expected values are identities that hold whatever the light mapping: a sun lights an unoccluded
horizontal floor uniformly, so a floor pixel in the shadow region equals a floor pixel far away
exactly when no shadow is cast; the Fresnel reflectance at normal incidence is symmetric in the
relative index (F0(n) = F0(1/n)); Blender's Principled BSDF is defined on the sockets' declared
ranges (Roughness ≤ 1).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from addon_testing import run_bpy

pytestmark = [pytest.mark.blender, pytest.mark.timeout(300)]

# A floor (8×8 plane at z = 0), a cube above it at x = -1, a slanted sun that throws the cube's shadow
# toward +x, an orthographic camera looking straight down. Renders are read back from EXR files.
SCENE = """
import math, sys, json
import bpy
import numpy as np
from addon import engine, properties, render_ui

bpy.ops.wm.read_factory_settings(use_empty=True)
properties.register()
engine.register()
render_ui.register()
scene = bpy.context.scene
bpy.ops.mesh.primitive_plane_add(size=8.0, location=(0.0, 0.0, 0.0))
floor = bpy.context.active_object
floor.name = "Floor"
bpy.ops.mesh.primitive_cube_add(size=1.0, location=(-1.0, 0.0, 1.0))
cube = bpy.context.active_object
cube.name = "Cube"
def principled(name, **inputs):
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    node = mat.node_tree.nodes["Principled BSDF"]
    for key, value in inputs.items():
        node.inputs[key].default_value = value
    return mat
floor.data.materials.append(principled("FloorPaint", **{"Base Color": (0.8, 0.8, 0.8, 1.0)}))
cube.data.materials.append(principled("CubePaint", **{"Base Color": (0.2, 0.4, 0.8, 1.0)}))
cam = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
cam.data.type = "ORTHO"
cam.data.ortho_scale = 6.0
cam.location = (0.0, 0.0, 10.0)
scene.collection.objects.link(cam)
scene.camera = cam
sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
sun.data.energy = 3.0
sun.rotation_euler = (0.0, math.radians(-45.0), 0.0)  # travels toward +x and down
scene.collection.objects.link(sun)
scene.world = None
scene.render.engine = "BLINN_PHONG"
scene.render.film_transparent = True
scene.render.resolution_x = scene.render.resolution_y = 48
scene.render.resolution_percentage = 100
scene.blinn_phong.samples_per_axis = 1
scene.blinn_phong.shadows = "HARD"
scene.render.image_settings.file_format = "OPEN_EXR"
scene.render.image_settings.color_depth = "32"
scene.render.image_settings.color_mode = "RGBA"

def finish():
    # Switch the engine away and unregister everything: a RenderEngine or its panels left registered
    # at exit crash bpy 4.2.
    scene.render.engine = "CYCLES"
    render_ui.unregister()
    engine.unregister()
    properties.unregister()

def render(tag):
    scene.render.filepath = f"{sys.argv[1]}/{tag}.exr"
    bpy.ops.render.render(write_still=True)
    last = dict(engine.LAST_RENDER)
    return {"ok": last.get("ok"), "notes": last.get("notes", []), "error": last.get("error"),
            "shadows": last.get("choices", {}).get("shadows"), "status": last.get("status")}
"""


def _read(path: Path) -> np.ndarray:
    from compositing.io import read_image

    return read_image(path)


def _regions() -> tuple[np.ndarray, np.ndarray]:
    # 48 px over 6 units: pixel (row, col) centre -> x = -3 + (col + 0.5)/8, y = 3 - (row + 0.5)/8.
    # The cube (|x + 1| < 0.5, height 0.5..1.5) throws its shadow onto x in [-0.5, 1.5] under the
    # 45° sun; "shadow" keeps well inside it, "far" is floor no shadow can reach.
    rows, cols = np.indices((48, 48))
    x, y = -3 + (cols + 0.5) / 8, 3 - (rows + 0.5) / 8
    shadow = (x > -0.3) & (x < 0.3) & (np.abs(y) < 0.3)
    far = (x > 2.0) & (x < 2.8) & (np.abs(y) < 2.0)
    return shadow, far


def test_cast_shadow_and_ray_visibility_shadow(tmp_path: Path) -> None:
    got = run_bpy(
        SCENE
        + """
results = {"on": render("on")}
sun.data.use_shadow = False
results["light_off"] = render("light_off")
sun.data.use_shadow = True
cube.visible_shadow = False
results["cube_off"] = render("cube_off")
floor.visible_shadow = False
results["all_off"] = render("all_off")
finish()
emit(results)
""",
        tmp_path,
        args=(str(tmp_path),),
    )
    shadow, far = _regions()
    images = {tag: _read(tmp_path / f"{tag}.exr") for tag in ("on", "light_off", "cube_off", "all_off")}
    lit = images["on"][..., 0][far]
    assert lit.min() > 0.05 and np.ptp(lit) < 1e-6  # a sun lights the floor uniformly
    assert images["on"][..., 0][shadow].max() < 0.1 * lit.mean()  # the cube's shadow
    # The cube out of shadow casting (Ray Visibility > Shadow off on it alone), the light's
    # Cast Shadow off, or every object out: the floor where the shadow was is lit like open floor.
    for tag in ("light_off", "cube_off", "all_off"):
        assert got[tag]["ok"], got[tag]
        np.testing.assert_allclose(images[tag][..., 0][shadow], lit.mean(), rtol=1e-5)
    assert got["light_off"]["shadows"] == ["none"]
    assert "none" in got["light_off"]["status"]


def test_film_transparent_and_out_of_range_principled_values(tmp_path: Path) -> None:
    got = run_bpy(
        SCENE
        + """
node = cube.data.materials[0].node_tree.nodes["Principled BSDF"]
results = {}
node.inputs["IOR"].default_value = 0.75  # an air bubble in water
results["ior_075"] = render("ior_075")
node.inputs["IOR"].default_value = 1.0 / 0.75
results["ior_133"] = render("ior_133")
node.inputs["Roughness"].default_value = 1.2  # accepted from Python
results["rough_12"] = render("rough_12")
node.inputs["Roughness"].default_value = 1.0
results["rough_10"] = render("rough_10")
node.inputs["Emission Strength"].default_value = -1.0  # no defined Blinn-Phong meaning
results["bad"] = render("bad")
node.inputs["Emission Strength"].default_value = 0.0
scene.render.film_transparent = False
scene.world = bpy.data.worlds.new("W")
scene.world.color = (0.25, 0.5, 0.75)
if scene.world.node_tree is not None:
    scene.world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.25, 0.5, 0.75, 1.0)
    scene.world.use_nodes = True
cam.data.ortho_scale = 12.0  # the floor (8 units) no longer fills the frame's corners
results["opaque"] = render("opaque")
# The engine's Film sub-panel draws Film > Transparent; Exit on Error is not in the main panel.
import types
class Layout:
    def __init__(self): self.props, self.use_property_split = [], False
    def prop(self, data, name, **_): self.props.append(name)
def drawn(panel):
    layout = Layout()
    panel.draw(types.SimpleNamespace(layout=layout), bpy.context)
    return layout.props
results["panels"] = {name: drawn(getattr(render_ui, name)) for name in (
    "BLINN_PHONG_PT_render", "BLINN_PHONG_PT_render_film", "BLINN_PHONG_PT_render_pipeline")}
finish()
emit(results)
""",
        tmp_path,
        args=(str(tmp_path),),
    )
    for tag in ("ior_075", "ior_133", "rough_12", "rough_10", "bad", "opaque"):
        assert got[tag]["ok"], got[tag]
    images = {
        tag: _read(tmp_path / f"{tag}.exr") for tag in ("ior_075", "ior_133", "rough_12", "rough_10", "bad")
    }
    np.testing.assert_allclose(images["ior_075"], images["ior_133"], atol=1e-6)  # F0(n) = F0(1/n)
    np.testing.assert_allclose(images["rough_12"], images["rough_10"], atol=0)
    assert any("CubePaint" in n and "Roughness" in n and "1.2" in n for n in got["rough_12"]["notes"])
    # The failing material takes its object out of the frame and names both; the floor still renders.
    assert any("'Cube'" in n and "'CubePaint'" in n and "emission_strength" in n for n in got["bad"]["notes"])
    rows, cols = np.indices((48, 48))
    x, y = -3 + (cols + 0.5) / 8, 3 - (rows + 0.5) / 8
    on_cube = (np.abs(x + 1.0) < 0.4) & (np.abs(y) < 0.4)
    assert not np.allclose(images["bad"][on_cube], images["rough_10"][on_cube])
    # Film > Transparent off: alpha 1 everywhere, the world colour in the corners.
    opaque = _read(tmp_path / "opaque.exr")
    assert opaque.shape == (48, 48, 4)
    np.testing.assert_allclose(opaque[..., 3], 1.0, atol=0)
    np.testing.assert_allclose(opaque[0, 0], [0.25, 0.5, 0.75, 1.0], atol=1e-6)
    assert got["panels"]["BLINN_PHONG_PT_render_film"] == ["film_transparent"]
    assert "abort_on_error" not in got["panels"]["BLINN_PHONG_PT_render"]
    assert "abort_on_error" in got["panels"]["BLINN_PHONG_PT_render_pipeline"]


def test_a_broken_numba_falls_back_to_numpy_with_a_visible_warning(tmp_path: Path) -> None:
    # numba present but failing to import (a wheel for another numpy, a missing shared library):
    # the frame still renders, with the numpy kernels, and says so in the report and the status line.
    got = run_bpy(
        "import sys\nsys.modules['numba'] = None  # 'import numba' now raises ImportError\n"
        + SCENE
        + """
results = {"broken": render("broken")}
scene.blinn_phong.engine = "NUMPY"
results["numpy"] = render("numpy")
finish()
emit(results)
""",
        tmp_path,
        args=(str(tmp_path),),
    )
    broken = got["broken"]
    assert broken["ok"], broken
    assert any("compiled kernels unavailable" in note and "numpy" in note for note in broken["notes"])
    assert "| numpy, " in broken["status"] and "WARNING" in broken["status"]
    # Asking for numpy explicitly is not a fallback: no warning.
    assert not any("compiled kernels" in note for note in got["numpy"]["notes"])
    assert "WARNING" not in got["numpy"]["status"]
    np.testing.assert_allclose(_read(tmp_path / "broken.exr"), _read(tmp_path / "numpy.exr"), atol=0)

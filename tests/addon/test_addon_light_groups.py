"""Light groups in Blender: the engine registers ``Combined_<group>`` passes and fills them.

A cube on a floor lit by a sun (group "key"), a point light (group "fill") and the world
(``World.lightgroup = "key"``), rendered with the view layer's list ["key", "fill"] into a
multilayer EXR by Blender's writer: the Render Layers node shows both passes, they sum to
Combined (≤ 1e-6), and the "fill" pass equals a second render with the sun hidden and the world
black (the frame lit by the point light alone).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from addon_testing import exr_passes, run_bpy

pytestmark = [pytest.mark.blender, pytest.mark.timeout(300)]

SCRIPT = """
import math, sys
import bpy
from addon import compat, engine, properties, render_ui

out = sys.argv[1]
bpy.ops.wm.read_factory_settings(use_empty=True)
properties.register()
engine.register()
render_ui.register()
scene = bpy.context.scene
scene.render.engine = "BLINN_PHONG"
scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 40, 30, 100
scene.render.film_transparent = True
scene.blinn_phong.samples_per_axis = 2
layer = scene.view_layers[0]
for name in ("key", "fill"):
    layer.lightgroups.add(name=name)
bpy.ops.mesh.primitive_cube_add(size=1.5, location=(0, 0, 0.75))
bpy.ops.mesh.primitive_plane_add(size=8, location=(0, 0, 0))
cam = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
cam.location = (0.0, -7.0, 3.0)
cam.rotation_euler = (math.radians(70), 0.0, 0.0)
scene.collection.objects.link(cam)
scene.camera = cam
sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
sun.rotation_euler = (0.5, 0.3, 0.0)
sun.lightgroup = "key"
lamp = bpy.data.objects.new("Lamp", bpy.data.lights.new("Lamp", "POINT"))
lamp.location = (2.0, -2.0, 3.0)
lamp.data.energy = 500.0
lamp.lightgroup = "fill"
for obj in (sun, lamp):
    scene.collection.objects.link(obj)
scene.world = bpy.data.worlds.new("World")
scene.world.lightgroup = "key"
if compat.world_uses_nodes(scene.world):
    scene.world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.2, 0.2, 0.2, 1.0)
else:
    scene.world.color = (0.2, 0.2, 0.2)
compat.set_image_format(scene.render.image_settings, "OPEN_EXR_MULTILAYER", "32")
scene.render.filepath = out + "/groups.exr"
bpy.ops.render.render(write_still=True)
tree = compat.compositor_tree(scene)
outputs = [o.name for o in tree.nodes.new("CompositorNodeRLayers").outputs if o.enabled]
scene.render.use_compositing = False
sun.hide_render = True
if compat.world_uses_nodes(scene.world):
    scene.world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
else:
    scene.world.color = (0.0, 0.0, 0.0)
scene.render.filepath = out + "/fill_alone.exr"
bpy.ops.render.render(write_still=True)
render_ui.unregister()
engine.unregister()
properties.unregister()
emit({"outputs": outputs})
"""


def _parts(path: Path) -> dict[str, np.ndarray]:
    return exr_passes(path)[0]


def test_light_group_passes_are_registered_and_sum_to_combined(tmp_path: Path) -> None:
    got = run_bpy(SCRIPT, tmp_path, args=(str(tmp_path),))
    assert {"Combined_key", "Combined_fill"} <= set(got["outputs"])
    parts = _parts(tmp_path / "groups.exr")
    combined = parts["ViewLayer.Combined"]
    key, fill = parts["ViewLayer.Combined_key"], parts["ViewLayer.Combined_fill"]
    assert key.shape == fill.shape == (30, 40, 3)
    assert key.max() > 0.05 and fill.max() > 0.05
    np.testing.assert_allclose(key + fill, combined[..., :3], rtol=0, atol=1e-6)
    alone = _parts(tmp_path / "fill_alone.exr")["ViewLayer.Combined"]
    np.testing.assert_allclose(fill, alone[..., :3], rtol=0, atol=1e-6)

"""The add-on converts an Image Texture node feeding a Principled BSDF into a core Texture.

Blender (``bpy`` in a subprocess) builds a quad with two UV layers, an 8-bit sRGB image whose
pixels the test chooses (multiples of 1/255), and a material where that image, through a UV Map
node naming the second layer, feeds the Principled BSDF's Base Color and Alpha (Closest, Clip).
``addon.convert.scene_from_depsgraph`` must give a mesh whose ``uv`` are the chosen corner UVs of
that layer and whose texture holds the chosen pixels decoded by the IEC 61966-2-1 sRGB EOTF
(typed here from the standard), straight alpha premultiplied, row 0 at the top — the image's
top row is the last row of ``Image.pixels`` (Blender stores rows bottom-up).
"""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

pytestmark = [pytest.mark.blender, pytest.mark.timeout(300)]

SCRIPT = """
import bpy
import numpy as np
from addon import convert

args = json.loads(sys.argv[-1])
bpy.ops.wm.read_factory_settings(use_empty=True)
scene = bpy.context.scene
pixels = np.array(args["pixels"], np.float32)  # (H, W, 4), row 0 at the BOTTOM (Blender's order)
h, w = pixels.shape[:2]
image = bpy.data.images.new("tex", w, h, alpha=True)
image.colorspace_settings.name = "sRGB"
image.pixels.foreach_set(pixels.ravel())

mesh = bpy.data.meshes.new("quad")
mesh.from_pydata([(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)], [], [(0, 1, 2, 3)])
first = mesh.uv_layers.new(name="First")
second = mesh.uv_layers.new(name="Second")
for loop in mesh.loops:
    first.data[loop.index].uv = (0.0, 0.0)
    second.data[loop.index].uv = args["uv"][loop.vertex_index]
mesh.uv_layers.active = first

material = bpy.data.materials.new("textured")
material.use_nodes = True
nodes, links = material.node_tree.nodes, material.node_tree.links
principled = next(n for n in nodes if n.type == "BSDF_PRINCIPLED")
principled.inputs["Metallic"].default_value = 0.0
tex = nodes.new("ShaderNodeTexImage")
tex.image = image
tex.interpolation = "Closest"
tex.extension = "CLIP"
uvmap = nodes.new("ShaderNodeUVMap")
uvmap.uv_map = "Second"
links.new(uvmap.outputs["UV"], tex.inputs["Vector"])
links.new(tex.outputs["Color"], principled.inputs["Base Color"])
links.new(tex.outputs["Alpha"], principled.inputs["Alpha"])
mesh.materials.append(material)
obj = bpy.data.objects.new("quad", mesh)
scene.collection.objects.link(obj)
cam = bpy.data.objects.new("cam", bpy.data.cameras.new("cam"))
cam.location = (0, 0, 3)
scene.collection.objects.link(cam)
scene.camera = cam

converted = convert.scene_from_depsgraph(bpy.context.evaluated_depsgraph_get())
m = converted.scene.meshes[0]
t = m.material.base_color_texture
corner_vertex = [loop.vertex_index for loop in mesh.loops]
emit({
    "image": t.image.tolist(), "interpolation": t.interpolation, "extension": t.extension,
    "uv": m.uv.tolist(), "corner_vertex": corner_vertex, "diffuse": list(m.material.diffuse),
    "opacity": m.material.opacity, "notes": converted.notes,
})
"""


def srgb_eotf(c: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1:1999: c/12.92 up to 0.04045, else ((c + 0.055)/1.055)^2.4."""
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _run_bpy():
    path = Path(__file__).resolve().parents[1] / "addon" / "addon_testing.py"
    spec = importlib.util.spec_from_file_location("addon_testing", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.run_bpy


def test_image_texture_node_becomes_a_core_texture(tmp_path) -> None:
    pytest.importorskip("bpy")
    rng = np.random.default_rng(11)
    bottom_up = rng.integers(0, 256, (3, 4, 4)) / 255.0  # H = 3, W = 4, Blender's row order
    uv = [[-0.2, 0.1], [1.3, 0.0], [1.0, 1.1], [0.25, 0.9]]
    got = _run_bpy()(SCRIPT, tmp_path, args=(json.dumps({"pixels": bottom_up.tolist(), "uv": uv}),))

    top_down = bottom_up[::-1]
    alpha = top_down[..., 3:4]
    expected = np.concatenate([srgb_eotf(top_down[..., :3]) * alpha, alpha], axis=-1)
    np.testing.assert_allclose(np.array(got["image"]), expected, atol=1e-6)  # float32 storage
    assert (got["interpolation"], got["extension"]) == ("closest", "clip")
    # One UV row per face corner, the Second layer's value of that corner's vertex.
    np.testing.assert_allclose(got["uv"], np.array(uv)[got["corner_vertex"]], atol=1e-7)
    # Base Color textured: the Principled mapping with a white base (diffuse = 1 − metallic = 1);
    # Alpha textured: the socket's unlinked value no longer applies.
    np.testing.assert_allclose(got["diffuse"], [1.0, 1.0, 1.0])
    assert got["opacity"] == 1.0
    assert not any("is linked" in note for note in got["notes"]), got["notes"]


SHARED = """
import bpy
import numpy as np
from addon import convert

bpy.ops.wm.read_factory_settings(use_empty=True)
scene = bpy.context.scene
image = bpy.data.images.new("tex", 4, 4, alpha=True)
image.pixels.foreach_set(np.linspace(0.0, 1.0, 64, dtype=np.float32))
material = bpy.data.materials.new("textured")
material.use_nodes = True
nodes, links = material.node_tree.nodes, material.node_tree.links
principled = next(n for n in nodes if n.type == "BSDF_PRINCIPLED")
tex = nodes.new("ShaderNodeTexImage")
tex.image = image
links.new(tex.outputs["Color"], principled.inputs["Base Color"])
for k in range(3):
    mesh = bpy.data.meshes.new(f"quad{k}")
    mesh.from_pydata([(k, 0, 0), (k + 1, 0, 0), (k + 1, 1, 0), (k, 1, 0)], [], [(0, 1, 2, 3)])
    mesh.uv_layers.new(name="UVMap")
    mesh.materials.append(material)
    scene.collection.objects.link(bpy.data.objects.new(f"quad{k}", mesh))
cam = bpy.data.objects.new("cam", bpy.data.cameras.new("cam"))
cam.location = (1.5, 0.5, 4)
scene.collection.objects.link(cam)
scene.camera = cam
converted = convert.scene_from_depsgraph(bpy.context.evaluated_depsgraph_get())
textures = [m.material.base_color_texture for m in converted.scene.meshes]
emit({"meshes": len(textures), "distinct": len({id(t) for t in textures}), "none": textures.count(None)})
"""


def test_an_image_shared_by_objects_becomes_one_texture(tmp_path) -> None:
    """Three objects with one textured material: one Texture (16 bytes per texel), not three."""
    pytest.importorskip("bpy")
    got = _run_bpy()(SHARED, tmp_path)
    assert got == {"meshes": 3, "distinct": 1, "none": 0}

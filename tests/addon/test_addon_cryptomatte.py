"""Cryptomatte in Blender: the engine's passes against Cycles' and against Blender's Cryptomatte node.

One scene (a cube "Cubé" with material "Mat A", a sphere parented to it without a material, a
floor with material "Mat B"), rendered at 32×24 by Cycles (1 sample: enough for IDs) and by the
engine (2×2 samples), both saved as multilayer EXRs with Blender's own writer and read back with
OpenImageIO:

* the passes and channels are the ones Cycles writes (``ViewLayer.CryptoObject00.r`` …), the
  header's layer keys and names are Cycles', and every manifest entry of ours is bit-equal to
  Cycles' entry for that name;
* every ID float in our passes is one Cycles wrote too (bit for bit), and each object and
  material that covers pixels in both renders has the same ID in both;
* Blender's Cryptomatte node (source: our EXR as an image), asked for "Cubé" and then for
  "Mat B", extracts a matte equal to the coverage of our passes (:func:`compositing.cryptomatte.matte`)
  to 1e-6;
* the passes are registered (``update_render_passes``): the Render Layers node shows them.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import OpenImageIO as oiio  # noqa: N813
import pytest
from addon_testing import engine_scene, exr_passes, run_bpy

from compositing.cryptomatte import matte, name_hash, name_id

pytestmark = [pytest.mark.blender, pytest.mark.slow, pytest.mark.timeout(600)]

SCRIPT = (
    """
import math, sys
import bpy
from addon import compat, engine, properties, render_ui

out = sys.argv[1]
"""
    + engine_scene(32, 24)
    + """
scene.render.film_transparent = True
layer = scene.view_layers[0]
layer.use_pass_cryptomatte_object = True
layer.use_pass_cryptomatte_material = True
layer.use_pass_cryptomatte_asset = True
bpy.ops.mesh.primitive_cube_add(size=1.6, location=(-0.8, 0, 0.2))
cube = bpy.context.active_object
cube.name = "Cubé"
cube.data.materials.append(bpy.data.materials.new("Mat A"))
bpy.ops.mesh.primitive_uv_sphere_add(radius=0.8, location=(1.0, -0.3, 0.0))
sphere = bpy.context.active_object
sphere.name = "Sphere child"
sphere.parent = cube
bpy.ops.mesh.primitive_plane_add(size=8, location=(0, 0, -0.8))
floor = bpy.context.active_object
floor.name = "Floor"
floor.data.materials.append(bpy.data.materials.new("Mat B"))
cam = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
cam.location = (0.0, -7.0, 2.0)
cam.rotation_euler = (math.radians(76), 0.0, 0.0)
scene.collection.objects.link(cam)
scene.camera = cam
sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
scene.collection.objects.link(sun)
compat.set_image_format(scene.render.image_settings, "OPEN_EXR_MULTILAYER", "32")

scene.render.engine = "CYCLES"
scene.cycles.samples = 1
scene.cycles.device = "CPU"
scene.render.filepath = out + "/cycles.exr"
bpy.ops.render.render(write_still=True)

scene.render.engine = "BLINN_PHONG"
scene.blinn_phong.samples_per_axis = 2
scene.render.filepath = out + "/ours.exr"
bpy.ops.render.render(write_still=True)

# registered passes: the Render Layers node's outputs
tree = compat.compositor_tree(scene)
compat.set_full_precision(scene)
layers_node = tree.nodes.new("CompositorNodeRLayers")
outputs = [o.name for o in layers_node.outputs if o.enabled]

# Blender's Cryptomatte node on our EXR: one matte per name, through the final output
image = bpy.data.images.load(out + "/ours.exr")
len(image.pixels)  # loads the file: its layers and header
node = tree.nodes.new("CompositorNodeCryptomatteV2")
node.source = "IMAGE"
node.image = image
node.layer_name = "ViewLayer.CryptoObject"
final = compat.add_render_output(tree)
tree.links.new(node.outputs["Matte"], final)
compat.set_image_format(scene.render.image_settings, "OPEN_EXR", "32")
scene.render.image_settings.color_mode = "RGBA"
layer_names = [item for item in node.bl_rna.properties["layer_name"].enum_items.keys()]
for layer_name, name in (("ViewLayer.CryptoObject", "Cubé"), ("ViewLayer.CryptoMaterial", "Mat B")):
    node.layer_name = layer_name
    node.matte_id = name
    scene.render.filepath = out + f"/matte_{name}.exr"
    bpy.ops.render.render(write_still=True)
render_ui.unregister()
engine.unregister()
properties.unregister()
emit({"outputs": outputs, "layer_names": layer_names})
"""
)


def _layer(pixels: dict[str, np.ndarray], stem: str) -> list[np.ndarray]:
    return [pixels[f"ViewLayer.{stem}{i:02d}"] for i in range(3)]


def _ids(passes: list[np.ndarray]) -> set[int]:
    """The ID bits present with a non-zero coverage."""
    out: set[int] = set()
    for p in passes:
        for c in (0, 2):
            out |= set(p[..., c][p[..., c + 1] > 0].view(np.uint32).tolist())
    return out


def test_cryptomatte_matches_cycles_and_blenders_node(tmp_path: Path) -> None:
    got = run_bpy(SCRIPT, tmp_path, args=(str(tmp_path),), timeout=540)
    cycles, cycles_header, cycles_channels = exr_passes(tmp_path / "cycles.exr")
    ours, our_header, our_channels = exr_passes(tmp_path / "ours.exr")

    for stem in ("CryptoObject", "CryptoMaterial", "CryptoAsset"):
        assert f"{stem}00" in got["outputs"] and f"{stem}02" in got["outputs"]  # registered
        for i in range(3):
            part = f"ViewLayer.{stem}{i:02d}"
            assert our_channels[part] == cycles_channels[part]  # names and channel letters as Cycles'

    # header: the same layer keys and names; our manifest entries equal Cycles' for every name
    names = {k: v for k, v in cycles_header.items() if k.endswith("/name")}
    assert {k: v for k, v in our_header.items() if k.endswith("/name")} == names
    for key in names:
        prefix = key[: -len("name")]
        assert our_header[prefix + "hash"] == cycles_header[prefix + "hash"] == "MurmurHash3_32"
        assert our_header[prefix + "conversion"] == cycles_header[prefix + "conversion"]
        mine = json.loads(our_header[prefix + "manifest"])
        theirs = json.loads(cycles_header[prefix + "manifest"])
        assert mine and all(theirs[n] == h for n, h in mine.items()), (mine, theirs)
        assert all(int(h, 16) == name_hash(n) for n, h in mine.items())

    # IDs: bit-equal floats, every one of ours also in Cycles' render
    expected = {
        "CryptoObject": {"Cubé", "Sphere child", "Floor"},
        "CryptoMaterial": {"Mat A", "Mat B", "default_surface"},
        "CryptoAsset": {"Cubé", "Floor"},
    }
    for stem, wanted in expected.items():
        mine, theirs = _ids(_layer(ours, stem)), _ids(_layer(cycles, stem))
        bits = {int(np.float32(name_id(n)).view(np.uint32)) for n in wanted}
        assert mine == bits, stem
        assert mine <= theirs, stem

    # the coverages of a pixel sum to its alpha (every pixel here holds at most 3 IDs < 6 levels)
    alpha = ours["ViewLayer.Combined"][..., 3]
    for stem in expected:
        total = sum(p[..., 1] + p[..., 3] for p in _layer(ours, stem))
        np.testing.assert_allclose(total, alpha, rtol=0, atol=1e-6)

    # Blender's Cryptomatte node reads our EXR and extracts our coverage
    assert {"CryptoObject", "CryptoMaterial", "CryptoAsset"} <= set(got["layer_names"])
    for stem, name in (("CryptoObject", "Cubé"), ("CryptoMaterial", "Mat B")):
        coverage = matte(_layer(ours, stem), [name_id(name)])
        assert coverage.max() == 1.0 and 0 < coverage.mean() < 1
        node = oiio.ImageInput.open(str(tmp_path / f"matte_{name}.exr"))
        extracted = node.read_image(oiio.FLOAT)
        node.close()
        np.testing.assert_allclose(extracted[..., 0], coverage, rtol=0, atol=1e-6)

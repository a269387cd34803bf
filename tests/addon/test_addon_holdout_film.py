"""Holdouts with Film → Transparent off, and Holdout nodes in a Mix Shader: the engine against Cycles.

Both engines render one tiny scene (64×48, seen from above by an orthographic camera) with a world
colour and *Film → Transparent* off, saved by Blender as 32-bit RGBA EXRs and read with
OpenImageIO. Cycles renders one sample per pixel through a 0.01 px box filter (each pixel is its
centre's surface, as the engine's single sample), with no bounces; every surface is an emitter
(Principled BSDF with a black base colour, no specular, an emission colour), so both engines'
colour is the emission, or the world where nothing is hit.

The scene: an emitting floor smaller than the frame (the world shows around it), a cube whose
material is a Holdout node half over the floor and half over the world, a sphere with
``Object.is_holdout``, a cube whose material is *Mix Shader* (factor 1) of an emitter and a
Holdout, and a cube with the same mix at factor 0 (the emitter alone in Cycles). Cycles writes
alpha 0 and colour 0 wherever a holdout is seen, film transparent or not; the engine's Combined
must equal Cycles' RGBA on every pixel away from edges (3×3 neighbourhood uniform in both). A
second render with the mix at factor 0.5 (a partial holdout in Cycles: alpha and colour halved)
must warn with the material's name (ours renders the emitter alone there).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import OpenImageIO as oiio  # noqa: N813 (the library's documented alias)
import pytest
from addon_testing import engine_scene, run_bpy

pytestmark = [pytest.mark.blender, pytest.mark.slow, pytest.mark.timeout(600)]

SCRIPT = (
    """
import sys
import bpy
from addon import compat, engine, properties, render_ui

out = sys.argv[1]
"""
    + engine_scene(64, 48)
    + """
compat.set_image_format(scene.render.image_settings, "OPEN_EXR", "32")
scene.render.image_settings.color_mode = "RGBA"
scene.render.film_transparent = False
scene.cycles.samples = 1
scene.cycles.use_denoising = False
scene.cycles.use_adaptive_sampling = False
scene.cycles.pixel_filter_type = "BOX"
scene.cycles.filter_width = 0.01
scene.cycles.max_bounces = 0
scene.cycles.device = "CPU"
scene.blinn_phong.samples_per_axis = 1
world = bpy.data.worlds.new("Sky")
world.color = (0.05, 0.1, 0.2)
if world.node_tree is not None:  # Blender 5.0 gives a new world nodes (a grey Background)
    background = next(n for n in world.node_tree.nodes if n.type == "BACKGROUND")
    background.inputs["Color"].default_value = (0.05, 0.1, 0.2, 1.0)
    background.inputs["Strength"].default_value = 1.0
scene.world = world
cam = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
cam.data.type = "ORTHO"
cam.data.ortho_scale = 8.0
cam.location = (0.0, 0.0, 10.0)
scene.collection.objects.link(cam)
scene.camera = cam


def emitter(name, emission):
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    bsdf = next(n for n in mat.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    bsdf.inputs["Base Color"].default_value = (0, 0, 0, 1)
    bsdf.inputs["Specular IOR Level"].default_value = 0.0
    bsdf.inputs["Emission Color"].default_value = (*emission, 1)
    bsdf.inputs["Emission Strength"].default_value = 1.0
    return mat


def holdout(name):
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    output = next(n for n in nodes if n.type == "OUTPUT_MATERIAL")
    links.new(nodes.new("ShaderNodeHoldout").outputs[0], output.inputs["Surface"])
    return mat


def mixed(name, emission, fac):
    mat = emitter(name, emission)
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    output = next(n for n in nodes if n.type == "OUTPUT_MATERIAL")
    bsdf = next(n for n in nodes if n.type == "BSDF_PRINCIPLED")
    mix = nodes.new("ShaderNodeMixShader")
    mix.inputs[0].default_value = fac
    links.new(bsdf.outputs[0], mix.inputs[1])
    links.new(nodes.new("ShaderNodeHoldout").outputs[0], mix.inputs[2])
    links.new(mix.outputs[0], output.inputs["Surface"])
    return mat


def add(kind, location, mat, **size):
    getattr(bpy.ops.mesh, f"primitive_{kind}_add")(location=location, **size)
    obj = bpy.context.active_object
    obj.data.materials.append(mat)
    return obj


glow = emitter("Glow", (0.8, 0.5, 0.2))
add("plane", (0, 0, -1), glow, size=5.0)
add("cube", (-2.6, 0, 0), holdout("Hold"), size=1.6)
add("uv_sphere", (0, 0, 0), glow, radius=0.9).is_holdout = True
add("cube", (2.4, 0, 0), mixed("MixHold", (0.3, 0.9, 0.4), 1.0), size=1.6)
add("cube", (0, 2.2, 0), mixed("MixKeep", (0.3, 0.9, 0.4), 0.0), size=1.0)
for eng, tag in (("CYCLES", "cycles"), ("BLINN_PHONG", "ours")):
    scene.render.engine = eng
    scene.render.filepath = f"{out}/film_{tag}.exr"
    bpy.ops.render.render(write_still=True)
notes_full = list(engine.LAST_RENDER.get("notes", []))
bpy.data.materials["MixKeep"].node_tree.nodes["Mix Shader"].inputs[0].default_value = 0.5
scene.render.filepath = f"{out}/partial_ours.exr"
bpy.ops.render.render(write_still=True)
notes_partial = list(engine.LAST_RENDER.get("notes", []))
scene.render.engine = "CYCLES"
scene.render.filepath = f"{out}/partial_cycles.exr"
bpy.ops.render.render(write_still=True)
render_ui.unregister()
engine.unregister()
properties.unregister()
emit({"notes_full": notes_full, "notes_partial": notes_partial})
"""
)


def _read(path: Path) -> np.ndarray:
    image = oiio.ImageInput.open(str(path))
    assert image is not None, oiio.geterror()
    try:
        return np.asarray(image.read_image(oiio.FLOAT))
    finally:
        image.close()


def _uniform(values: np.ndarray) -> np.ndarray:
    """Pixels whose 3×3 neighbourhood (clipped at the border) all equal them (every channel)."""
    padded = np.pad(values, ((1, 1), (1, 1), (0, 0)), mode="edge")
    h, w = values.shape[:2]
    return np.all(
        [
            (padded[1 + dy : 1 + dy + h, 1 + dx : 1 + dx + w] == values).all(axis=-1)
            for dy in (-1, 0, 1)
            for dx in (-1, 0, 1)
        ],
        axis=0,
    )


@pytest.fixture(scope="module")
def renders(tmp_path_factory: pytest.TempPathFactory) -> tuple[dict[str, np.ndarray], dict[str, list[str]]]:
    out = tmp_path_factory.mktemp("holdout_film")
    notes = run_bpy(SCRIPT, out, args=(str(out),), timeout=540)
    return {p.stem: _read(p) for p in out.glob("*.exr")}, notes


def test_holdouts_stay_transparent_without_film_transparent(renders) -> None:
    images, _ = renders
    ours, cycles = images["film_ours"], images["film_cycles"]
    assert ours.shape == cycles.shape == (48, 64, 4)
    # Cycles: held-out pixels are (0, 0, 0, 0) with the film opaque; the world elsewhere
    assert (cycles[..., 3] == 0).sum() > 150
    assert np.allclose(cycles[0, 0], (0.05, 0.1, 0.2, 1.0), atol=1e-6)
    # compared away from edges: each pixel's 3×3 neighbourhood is one surface in both renders
    # (quantised to 1e-4 so that Cycles' float noise on one surface does not break uniformity)
    away = _uniform(np.round(ours, 4)) & _uniform(np.round(cycles, 4))
    assert away.mean() > 0.75
    np.testing.assert_allclose(ours[away], cycles[away], rtol=0, atol=1e-5)
    held = away & (cycles[..., 3] == 0)
    # each holdout (node on world and floor, is_holdout, Mix Shader at factor 1) is there
    for rows, columns in ((slice(18, 30), slice(3, 9)), (slice(18, 30), slice(9, 16)),
                          (slice(18, 30), slice(28, 36)), (slice(18, 30), slice(46, 54))):  # fmt: skip
        assert held[rows, columns].sum() > 10, (rows, columns)
        assert not ours[rows, columns][held[rows, columns]].any()
    # the Mix Shader at factor 0 is its emitter in both
    assert np.allclose(cycles[6, 32], (0.3, 0.9, 0.4, 1.0), atol=1e-5)


def test_partial_mix_holdout_is_reported(renders) -> None:
    _, notes = renders
    assert not any("without the holdout" in n for n in notes["notes_full"]), notes["notes_full"]
    partial = [n for n in notes["notes_partial"] if n.startswith("MixKeep:") and "holdout" in n]
    assert len(partial) == 1 and "0.5" in partial[0] and "holdout" in partial[0], notes["notes_partial"]
    # what is not rendered: Cycles' partial holdout, alpha and colour halved
    images, _ = renders
    np.testing.assert_allclose(images["partial_cycles"][6, 32], [0.15, 0.45, 0.2, 0.5], rtol=0, atol=1e-5)
    np.testing.assert_allclose(images["partial_ours"][6, 32], [0.3, 0.9, 0.4, 1.0], rtol=0, atol=1e-5)

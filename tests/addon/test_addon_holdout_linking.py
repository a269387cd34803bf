"""Holdouts and light/shadow linking in Blender: the engine against Cycles.

Both engines render the same tiny scenes (64×48, seen from above by an orthographic camera), saved
by Blender as 32-bit EXRs and read with OpenImageIO. Cycles renders one sample per pixel through a
0.01 px box filter (each pixel is its centre's surface, as the engine's single sample), with no
bounces (direct light only: light linking acts on a light's direct contribution).

* Holdouts: an emitting floor, a cube whose material is a Holdout node, a sphere with
  ``Object.is_holdout`` and a cube in a collection marked *Holdout* on the view layer, plus an
  emitting card over part of the first cube; film transparent. Alpha is equal (0 or 1) on every
  pixel away from edges (its 3×3 neighbourhood uniform in both renders), and each of the three
  holdouts makes transparent pixels in both.
* Light linking: a floor, a cube and a sphere lit by one point light whose receiver collection
  includes the cube alone; rendered with and without the light, in both engines: the pixels that
  change are the same away from edges (the cube's lit faces, never the floor or the sphere),
  and without the link the floor changes too (so the link is what the test sees). Likewise with
  a receiver collection that only excludes the floor (through a child collection set to Exclude):
  the cube and the sphere change, the floor does not.
* Shadow linking: the light's blocker collection includes the sphere alone; each engine renders it
  with the sphere's and then with the cube's shadow removed (Ray Visibility › Shadow off): the
  sphere's removal changes the same pixels in both (its shadow on the floor), the cube's changes
  none in either (it blocks nothing for this light).
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
import math, sys
import bpy
from addon import compat, engine, properties, render_ui

out = sys.argv[1]
"""
    + engine_scene(64, 48)
    + """
compat.set_image_format(scene.render.image_settings, "OPEN_EXR", "32")
scene.render.image_settings.color_mode = "RGBA"
scene.cycles.samples = 1
scene.cycles.use_denoising = False
scene.cycles.use_adaptive_sampling = False
scene.cycles.pixel_filter_type = "BOX"
scene.cycles.filter_width = 0.01
scene.cycles.max_bounces = 0
scene.cycles.device = "CPU"
scene.blinn_phong.samples_per_axis = 1
cam = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
cam.data.type = "ORTHO"
cam.data.ortho_scale = 8.0
cam.location = (0.0, 0.0, 10.0)
scene.collection.objects.link(cam)
scene.camera = cam


def material(name, emission=None, holdout=False):
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    output = next(n for n in nodes if n.type == "OUTPUT_MATERIAL")
    bsdf = next(n for n in nodes if n.type == "BSDF_PRINCIPLED")
    if holdout:
        links.new(nodes.new("ShaderNodeHoldout").outputs[0], output.inputs["Surface"])
    elif emission is not None:
        bsdf.inputs["Base Color"].default_value = (0, 0, 0, 1)
        bsdf.inputs["Specular IOR Level"].default_value = 0.0
        bsdf.inputs["Emission Color"].default_value = (*emission, 1)
        bsdf.inputs["Emission Strength"].default_value = 1.0
    return mat


def add(kind, location, mat, collection=None, **size):
    getattr(bpy.ops.mesh, f"primitive_{kind}_add")(location=location, **size)
    obj = bpy.context.active_object
    obj.data.materials.append(mat)
    if collection is not None:
        for c in obj.users_collection:
            c.objects.unlink(obj)
        collection.objects.link(obj)
    return obj


def shoot(name):
    for eng, tag in (("CYCLES", "cycles"), ("BLINN_PHONG", "ours")):
        scene.render.engine = eng
        scene.render.filepath = f"{out}/{name}_{tag}.exr"
        bpy.ops.render.render(write_still=True)


# ---- holdouts
scene.render.film_transparent = True
glow = material("Glow", emission=(0.8, 0.5, 0.2))
add("plane", (0, 0, -1), glow, size=20)
add("cube", (-2.4, 0, 0), material("Hold", holdout=True), size=1.6)
add("plane", (-2.4, 0.6, 1), material("Card", emission=(0.2, 0.6, 0.9)), size=0.8)
add("uv_sphere", (0, 0, 0), glow, radius=0.9).is_holdout = True
held = bpy.data.collections.new("Held")
scene.collection.children.link(held)
add("cube", (2.4, 0, 0), glow, collection=held, size=1.6)
bpy.context.view_layer.layer_collection.children["Held"].holdout = True
shoot("holdout")

# ---- light and shadow linking (a new scene)
for obj in list(bpy.data.objects):
    if obj is not cam:
        bpy.data.objects.remove(obj)
scene.render.film_transparent = False
white = material("White")
floor = add("plane", (0, 0, 0), white, size=20)
cube = add("cube", (-1.6, 0.4, 0.8), white, size=1.6)
sphere = add("uv_sphere", (1.6, -0.3, 1.0), white, radius=0.9)
lamp = bpy.data.objects.new("Lamp", bpy.data.lights.new("Lamp", "POINT"))
lamp.data.energy = 1500.0
lamp.data.shadow_soft_size = 0.0
lamp.location = (0.4, 1.2, 4.5)
scene.collection.objects.link(lamp)
shoot("light_unlinked")
receivers = bpy.data.collections.new("Receivers")
receivers.objects.link(cube)
lamp.light_linking.receiver_collection = receivers
shoot("light_linked")
excluded = bpy.data.collections.new("Excluded")
excluded.children.link(bpy.data.collections.new("Ground"))
excluded.children["Ground"].objects.link(floor)
excluded.collection_children[0].light_linking.link_state = "EXCLUDE"
lamp.light_linking.receiver_collection = excluded
shoot("light_excluded")
lamp.hide_render = True
shoot("dark")
lamp.hide_render = False
lamp.light_linking.receiver_collection = None
blockers = bpy.data.collections.new("Blockers")
blockers.objects.link(sphere)
lamp.light_linking.blocker_collection = blockers
shoot("shadow_linked")
sphere.visible_shadow = False
shoot("no_sphere_shadow")
sphere.visible_shadow = True
cube.visible_shadow = False
shoot("no_cube_shadow")
render_ui.unregister()
engine.unregister()
properties.unregister()
emit({"done": True})
"""
)


def _read(path: Path) -> np.ndarray:
    image = oiio.ImageInput.open(str(path))
    assert image is not None, oiio.geterror()
    try:
        return np.asarray(image.read_image(oiio.FLOAT))
    finally:
        image.close()


def _uniform(mask: np.ndarray) -> np.ndarray:
    """Pixels whose 3×3 neighbourhood (clipped at the border) all equal them."""
    padded = np.pad(mask, 1, mode="edge")
    h, w = mask.shape
    return np.all(
        [padded[1 + dy : 1 + dy + h, 1 + dx : 1 + dx + w] == mask for dy in (-1, 0, 1) for dx in (-1, 0, 1)],
        axis=0,
    )


def _changed(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Pixels whose colour differs by more than 1e-3 of the brighter image's largest value."""
    scale = max(float(a[..., :3].max()), float(b[..., :3].max()), 1e-6)
    return np.abs(a[..., :3] - b[..., :3]).max(axis=-1) > 1e-3 * scale


@pytest.fixture(scope="module")
def renders(tmp_path_factory: pytest.TempPathFactory) -> dict[str, np.ndarray]:
    out = tmp_path_factory.mktemp("holdout_linking")
    run_bpy(SCRIPT, out, args=(str(out),), timeout=540)
    return {p.stem: _read(p) for p in out.glob("*.exr")}


def test_holdout_alpha_matches_cycles(renders: dict[str, np.ndarray]) -> None:
    ours, cycles = renders["holdout_ours"][..., 3], renders["holdout_cycles"][..., 3]
    assert ours.shape == cycles.shape == (48, 64)
    away = _uniform(ours > 0.5) & _uniform(cycles > 0.5)
    assert away.mean() > 0.8
    np.testing.assert_allclose(ours[away], cycles[away], rtol=0, atol=1e-6)
    # each of the three kinds holds out pixels in both (left: Holdout node; middle: is_holdout;
    # right: the view layer's collection holdout); the card over the first cube stays opaque
    for columns in (slice(10, 20), slice(28, 36), slice(44, 54)):
        assert (ours[18:30, columns] == 0).sum() > 20
        assert (cycles[18:30, columns] == 0).sum() > 20
    assert (ours == 1).mean() > 0.5


def test_light_linking_lights_the_same_pixels_as_cycles(renders: dict[str, np.ndarray]) -> None:
    for engine in ("ours", "cycles"):
        linked = _changed(renders[f"light_linked_{engine}"], renders[f"dark_{engine}"])
        unlinked = _changed(renders[f"light_unlinked_{engine}"], renders[f"dark_{engine}"])
        assert 0.02 < linked.mean() < 0.3, engine  # the cube's lit faces only
        assert unlinked.mean() > linked.mean() + 0.3, engine  # the floor too, without the link
    for name in ("light_linked", "light_excluded"):
        ours = _changed(renders[f"{name}_ours"], renders["dark_ours"])
        cycles = _changed(renders[f"{name}_cycles"], renders["dark_cycles"])
        away = _uniform(ours) & _uniform(cycles)
        assert away.mean() > 0.8, name
        assert np.array_equal(ours[away], cycles[away]), name
    excluded = _changed(renders["light_excluded_ours"], renders["dark_ours"])
    linked = _changed(renders["light_linked_ours"], renders["dark_ours"])
    assert excluded.mean() > linked.mean() + 0.02 and excluded.mean() < 0.5  # cube and sphere, no floor


def test_shadow_linking_blocks_with_the_same_pixels_as_cycles(renders: dict[str, np.ndarray]) -> None:
    changed = {}
    for engine in ("ours", "cycles"):
        base = renders[f"shadow_linked_{engine}"]
        changed[engine] = _changed(base, renders[f"no_sphere_shadow_{engine}"])
        assert changed[engine].mean() > 0.02, engine  # the sphere's shadow on the floor
        assert not _changed(base, renders[f"no_cube_shadow_{engine}"]).any(), engine  # not a blocker
    away = _uniform(changed["ours"]) & _uniform(changed["cycles"])
    assert away.mean() > 0.8
    assert np.array_equal(changed["ours"][away], changed["cycles"][away])

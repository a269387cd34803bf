"""The textured sample scene (``blend_files/textures.blend``) rendered by the engine inside Blender.

Independent sources:

* the texture files are decoded by Pillow (not by Blender or the project) and the sRGB bytes
  turned into linear light with the IEC 61966-2-1 formula written out here;
* what each pixel sees is found by **Blender's own ray caster** (``Scene.ray_cast``) from the
  camera frame Blender reports (``Camera.view_frame``): the first surface hit, its texel (from the
  hit position on the plane, the planes' UVs spanning them 0…1), whether that texel of the fence is
  transparent in the PNG (then the ray goes on to what lies behind) and whether the sun is
  blocked (a shadow ray towards it);
* the lighting of a flat diffuse surface under a sun and a uniform world is the closed form
  ``k_a·W + k_d·(S/π)·max(0, n·l)`` (OpenGL 2.1 §2.14.1 with no specular; the sun's strength ``S``
  in W/m² → ``S/π`` as docs/addon.md states), times the texel colour for a textured surface
  (``GL_MODULATE``).

A pixel is compared only when its four corners, its centre and its 2×2 sample positions all see
the same surface, the same texel and an unblocked sun, so the engine's supersampling averages
equal values.
"""

from __future__ import annotations

import numpy as np
import pytest
from addon_testing import REPO, run_bpy

pytestmark = [pytest.mark.blender, pytest.mark.timeout(400)]

BLEND = REPO / "blend_files" / "textures.blend"
IMAGES = REPO / "blend_files" / "images"

SCRIPT = """
import sys
from pathlib import Path
import bpy
import numpy as np
from mathutils import Vector
from addon import compat, convert, engine, properties

out, blend = Path(sys.argv[1]), sys.argv[2]
properties.register()
engine.register()
try:
    bpy.ops.wm.open_mainfile(filepath=blend, load_ui=False)
    image_paths = {i.name: i.filepath for i in bpy.data.images}
    scene = bpy.context.scene
    scene.render.resolution_percentage = 50
    settings = scene.render.image_settings
    settings.file_format, settings.color_depth, settings.color_mode = "OPEN_EXR", "32", "RGBA"
    scene.render.filepath = str(out / "textures.exr")
    bpy.ops.render.render(write_still=True)
    last = dict(engine.LAST_RENDER)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    converted = convert.scene_from_depsgraph(depsgraph)
    textures = {}
    for name, mesh in zip(converted.mesh_names, converted.scene.meshes):
        texture = mesh.material.base_color_texture
        textures[name] = None if texture is None else {
            "alpha": np.asarray(texture.image)[..., 3].tolist(),
            "interpolation": texture.interpolation,
        }

    width = scene.render.resolution_x * scene.render.resolution_percentage // 100
    height = scene.render.resolution_y * scene.render.resolution_percentage // 100
    cam = scene.camera
    frame = [Vector(c) for c in cam.data.view_frame(scene=scene)]  # TR, BR, BL, TL (camera space)
    right, left = frame[0].x, frame[2].x
    top, bottom, depth = frame[0].y, frame[1].y, frame[0].z
    rotation = cam.matrix_world.to_3x3()
    origin = cam.matrix_world.translation.copy()
    sun = next(o for o in scene.objects if o.type == "LIGHT")
    to_sun = (sun.matrix_world.to_3x3() @ Vector((0, 0, 1))).normalized()
    objects = {o.name: o for o in scene.objects if o.type == "MESH"}
    fence = np.load(out / "fence_alpha.npy")  # the PNG's alpha (Pillow), row 0 at the top

    def plane_texel(obj, location, size):
        local = obj.matrix_world.inverted() @ location
        half = obj.data.vertices[0].co.length / np.sqrt(2.0)  # the plane's half edge (local)
        u, v = (local.x + half) / (2 * half), (local.y + half) / (2 * half)
        return int(np.floor(u * size)), int(np.floor(v * size))

    def trace(x, y):
        # What the camera sees through frame position (x, y) in pixels (row 0 at the top).
        point = Vector((left + (right - left) * x / width, top - (top - bottom) * y / height, depth))
        direction = (rotation @ point).normalized()
        start = origin.copy()
        for _ in range(4):
            hit, location, normal, _i, obj, _m = scene.ray_cast(depsgraph, start, direction)
            if not hit:
                return ("none",)
            name = obj.name
            if obj.data.materials[0].name == "Fence":
                i, j = plane_texel(obj, location, fence.shape[1])
                inside = 0 <= i < fence.shape[1] and 0 <= j < fence.shape[0]
                if inside and fence[fence.shape[0] - 1 - j, i] == 0:
                    start = location + direction * 1e-4  # a transparent texel: look behind it
                    continue
                return ("fence", i, j)
            blocked = scene.ray_cast(depsgraph, location + normal * 1e-4, to_sun)[0]
            texel = plane_texel(obj, location, 32) if "floor" in obj.data.materials[0].name else (0, 0)
            return (name, tuple(round(c, 6) for c in normal), texel, bool(blocked), start != origin)
        return ("deep",)

    # The pixel's corners, centre and the 2×2 sample positions (a shadow's corner may poke into
    # a pixel between its corners).
    PROBES = [(0.02, 0.02), (0.98, 0.02), (0.02, 0.98), (0.98, 0.98), (0.5, 0.5)]
    PROBES += [(x, y) for x in (0.25, 0.75) for y in (0.25, 0.75)]
    pixels = []
    for py in range(height):
        for px in range(width):
            seen = {trace(px + dx, py + dy) for dx, dy in PROBES}
            if len(seen) == 1:
                pixels.append([px, py, *[list(v) if isinstance(v, tuple) else v for v in next(iter(seen))]])
    materials = {}
    for name, obj in objects.items():
        bp = obj.data.materials[0].blinn_phong
        materials[name] = {
            "material": obj.data.materials[0].name, "source": bp.source,
            "ambient": list(bp.ambient), "diffuse": list(bp.diffuse), "specular": list(bp.specular),
        }
    background = scene.world.node_tree.nodes["Background"] if compat.world_uses_nodes(scene.world) else None
    world = list(background.inputs["Color"].default_value[:3]) if background else list(scene.world.color)
    strength = float(background.inputs["Strength"].default_value) if background else 1.0
finally:
    engine.unregister()
    properties.unregister()
emit({
    "ok": last["ok"], "error": last["error"], "choices": last["choices"], "textures": textures,
    "pixels": pixels, "materials": materials, "world": [c * strength for c in world],
    "sun": {"strength": float(sun.data.energy), "color": list(sun.data.color), "to_sun": list(to_sun)},
    "image_paths": image_paths,
})
"""


def srgb_to_linear(byte: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1:1999 §5.2: sRGB-encoded bytes → linear light."""
    c = np.asarray(byte, dtype=np.float64) / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _png(name: str) -> np.ndarray:
    image = pytest.importorskip("PIL.Image")
    with image.open(IMAGES / name) as handle:
        return np.asarray(handle.convert("RGBA"))


@pytest.fixture(scope="module")
def rendered(tmp_path_factory: pytest.TempPathFactory) -> tuple[np.ndarray, dict]:
    from compositing.io import read_image

    out = tmp_path_factory.mktemp("textures")
    np.save(out / "fence_alpha.npy", _png("fence.png")[..., 3])
    facts = run_bpy(SCRIPT, out, args=(str(out), str(BLEND)), timeout=360)
    return read_image(out / "textures.exr"), facts


def test_scene_renders_with_textures_found_and_shadows(rendered: tuple[np.ndarray, dict]) -> None:
    _, facts = rendered
    assert facts["ok"] is True, facts["error"]
    # Relative paths: the .blend opens from any checkout.
    assert facts["image_paths"] == {
        "fence": "//images/fence.png",
        "floor_checker": "//images/floor_checker.png",
    }
    by_material = {name.split("/", 1)[1]: tex for name, tex in facts["textures"].items()}
    assert by_material["Box"] is None
    assert by_material["Checker floor"] is not None and by_material["Fence"] is not None
    # The converter read the fence's alpha from the image: equal to the PNG's (decoded by Pillow).
    png_alpha = _png("fence.png")[..., 3] / 255.0
    np.testing.assert_array_equal(np.array(by_material["Fence"]["alpha"]), png_alpha)
    assert set(np.unique(png_alpha)) == {0.0, 1.0}  # alpha-clipped: every texel opaque or cut out
    assert by_material["Fence"]["interpolation"] == "closest"
    assert facts["choices"]["shadows"] and set(facts["choices"]["shadows"]) <= {"ray_traced", "shadow_map"}


def _lit(facts: dict, material: dict, normal: list[float]) -> np.ndarray:
    """Closed-form diffuse + ambient light on a flat surface (no specular), linear RGB."""
    assert material["specular"] == [0.0, 0.0, 0.0]
    sun = facts["sun"]
    n_dot_l = max(0.0, float(np.dot(normal, sun["to_sun"])))
    irradiance = np.array(sun["color"]) * sun["strength"] / np.pi * n_dot_l
    return (
        np.array(material["ambient"]) * np.array(facts["world"]) + np.array(material["diffuse"]) * irradiance
    )


def test_unshadowed_floor_and_box_equal_the_closed_form(rendered: tuple[np.ndarray, dict]) -> None:
    image, facts = rendered
    checker = srgb_to_linear(_png("floor_checker.png")[..., :3])
    floor_name = next(n for n, m in facts["materials"].items() if m["material"] == "Checker floor")
    box_name = next(n for n, m in facts["materials"].items() if m["material"] == "Box")
    counts = {"floor": 0, "through_fence": 0, "box": 0}
    bad = []
    for px, py, name, *rest in facts["pixels"]:
        if name not in (floor_name, box_name):
            continue
        normal, (i, j), blocked, behind_fence = rest
        if blocked:
            continue
        lit = _lit(facts, facts["materials"][name], normal)
        if name == floor_name:
            expected = lit * checker[checker.shape[0] - 1 - j, i]
            counts["through_fence" if behind_fence else "floor"] += 1
        else:
            expected = lit
            counts["box"] += 1
        # float32 image and shading: a few ulps of values below 1.
        if np.abs(image[py, px, :3] - expected).max() > 2e-5 or abs(image[py, px, 3] - 1.0) > 1e-6:
            bad.append((px, py, name, behind_fence, image[py, px].tolist(), expected.tolist()))
    assert not bad, f"{len(bad)} pixels differ from the closed form, e.g. {bad[:5]}"
    # Enough of each: open floor, floor seen through the fence's cut-out texels, the box's lit faces.
    assert counts["floor"] > 2000 and counts["box"] > 100 and counts["through_fence"] > 20, counts


def test_opaque_fence_texels_cover_the_floor(rendered: tuple[np.ndarray, dict]) -> None:
    image, facts = rendered
    fence = _png("fence.png")
    wood = srgb_to_linear(fence[..., :3])
    seen = [p for p in facts["pixels"] if p[2] == "fence"]
    assert len(seen) > 20  # pixels inside one texel (about 1.4 pixels wide at 50 %)
    for px, py, _, i, j in seen:
        assert fence[fence.shape[0] - 1 - j, i, 3] == 255
        assert image[py, px, 3] == pytest.approx(1.0, abs=1e-6)
        # The fence's colour is the texel's hue (red > green > blue for every wood texel), never
        # the magenta stored under the cut-out texels (red = blue, green = 0).
        r, g, b = image[py, px, :3]
        texel = wood[fence.shape[0] - 1 - j, i]
        assert r > g > b and texel[0] > texel[1] > texel[2], (px, py, image[py, px], texel)

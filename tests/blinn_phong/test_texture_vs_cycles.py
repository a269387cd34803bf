"""An emission-only textured plane: ours against Blender's Cycles, Closest interpolation.

Blender (through ``bpy`` in a subprocess, tests/addon/addon_testing.py) renders a plane tilted
50° under a perspective camera, its material an Image Texture node (Closest; Repeat, Extend or
Clip; a Non-Color float image, so no colour transform) feeding an Emission shader of strength
1, no lights, a black world (film transparent), Cycles with denoising off, a 0.01-pixel box
pixel filter and **one** sample per pixel, written to a 32-bit float EXR and read back through
``bpy`` (float, linear). One sample is exact here: a camera ray hitting an emitter returns its
emission, nothing else contributes. (Measured with Blender 5.0.1: with 4 or 16 samples pixels
close to a texel boundary blend neighbouring texels despite the 0.01-pixel filter — 315 of 2152
compared pixels at 4 samples — so the samples spread further than the filter width says; with
one sample every compared pixel is bitwise equal, and so are the pixels right at texel
boundaries.) Our render of the same plane, camera and texture
(``Material(emission=1, ambient=diffuse=0, base_color_texture=…)``) must give the texel
itself: texel-exact (|Δ| ≤ 1e-6, float32 storage) on pixels whose centre's texel coordinates
are ≥ 0.05 texel from a texel boundary and ≥ 1/16 pixel from the plane's edges.
"""

from __future__ import annotations

import importlib.util
import json
import math
from pathlib import Path

import numpy as np
import pytest

import blinn_phong as bp
from blinn_phong.model.texture import Texture
from tests.blinn_phong import renderer_scenes
from tests.pixels import interior_mask

pytestmark = [pytest.mark.blender, pytest.mark.slow]

SIZE = 64
FOV = 40.0
TILT = 50.0
EXTENSIONS = ("repeat", "extend", "clip")
UV_LOW, UV_HIGH = -0.25, 1.25

CYCLES = """
import math
import bpy
import numpy as np

args = json.loads(sys.argv[-1])
img = np.array(args["image"], np.float32)  # row 0 at the top
h, w = img.shape[:2]
out = {}
for ext in args["extensions"]:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = args.get("samples", 1)
    scene.cycles.use_denoising = False
    scene.cycles.use_adaptive_sampling = False
    scene.cycles.pixel_filter_type = "BOX"
    scene.render.filter_size = 0.01  # Film > Pixel Filter > Width (pixels)
    scene.render.film_transparent = True
    scene.render.resolution_x = scene.render.resolution_y = args["size"]
    scene.render.resolution_percentage = 100
    scene.view_settings.view_transform = "Standard"
    world = bpy.data.worlds.new("black")
    world.color = (0.0, 0.0, 0.0)
    if world.node_tree is not None:  # a node world: its Background shader, black
        for node in world.node_tree.nodes:
            if node.type == "BACKGROUND":
                node.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    scene.world = world

    image = bpy.data.images.new("tex", w, h, alpha=True, float_buffer=True)
    image.colorspace_settings.name = "Non-Color"
    image.pixels.foreach_set(np.ascontiguousarray(img[::-1]).ravel())  # Blender rows bottom-up

    material = bpy.data.materials.new("m")
    material.use_nodes = True
    nodes, links = material.node_tree.nodes, material.node_tree.links
    nodes.clear()
    tex = nodes.new("ShaderNodeTexImage")
    tex.image = image
    tex.interpolation = "Closest"
    tex.extension = ext.upper()
    emission = nodes.new("ShaderNodeEmission")
    emission.inputs["Strength"].default_value = 1.0
    output = nodes.new("ShaderNodeOutputMaterial")
    links.new(tex.outputs["Color"], emission.inputs["Color"])
    links.new(emission.outputs["Emission"], output.inputs["Surface"])

    lo, hi = args["uv"]
    mesh = bpy.data.meshes.new("plane")
    mesh.from_pydata([(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)], [], [(0, 1, 2, 3)])
    uv = mesh.uv_layers.new(name="UVMap")
    corner = {0: (lo, lo), 1: (hi, lo), 2: (hi, hi), 3: (lo, hi)}
    for loop in mesh.loops:
        uv.data[loop.index].uv = corner[loop.vertex_index]
    mesh.materials.append(material)
    plane = bpy.data.objects.new("plane", mesh)
    plane.rotation_euler = (math.radians(args["tilt"]), 0.0, 0.0)
    scene.collection.objects.link(plane)

    cam_data = bpy.data.cameras.new("cam")
    cam_data.sensor_fit = "AUTO"
    cam_data.angle = math.radians(args["fov"])
    cam_data.clip_start, cam_data.clip_end = 0.5, 10.0
    camera = bpy.data.objects.new("cam", cam_data)
    camera.location = (0.0, 0.0, 3.0)
    scene.collection.objects.link(camera)
    scene.camera = camera

    path = args["dir"] + f"/{ext}.exr"
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"
    scene.render.filepath = path
    bpy.ops.render.render(write_still=True)
    result = bpy.data.images.load(path)
    px = np.empty(args["size"] * args["size"] * 4, np.float32)
    result.pixels.foreach_get(px)
    out[ext] = px.reshape(args["size"], args["size"], 4)[::-1].tolist()  # row 0 at the top
emit(out)
"""


def _addon_testing():
    """tests/addon/addon_testing.py (the shared bpy-subprocess runner), loaded by path."""
    path = Path(__file__).resolve().parents[1] / "addon" / "addon_testing.py"
    spec = importlib.util.spec_from_file_location("addon_testing", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def texture_image() -> np.ndarray:
    rng = np.random.default_rng(7)
    img = rng.random((8, 8, 4)).astype(np.float32)
    img[..., 3] = 1.0
    return img


def our_scene(texture: Texture) -> bp.Scene:
    pos = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float)
    uv = np.array([[UV_LOW, UV_LOW], [UV_HIGH, UV_LOW], [UV_HIGH, UV_HIGH], [UV_LOW, UV_HIGH]])
    c, s = math.cos(math.radians(TILT)), math.sin(math.radians(TILT))
    tilt = np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])  # Blender's Rx
    material = bp.Material(
        ambient=(0, 0, 0), diffuse=(0, 0, 0), emission=(1, 1, 1), base_color_texture=texture
    )
    mesh = bp.Mesh(pos, np.array([[0, 1, 2], [0, 2, 3]]), transform=tilt, material=material, uv=uv)
    camera = bp.Camera(bp.look_at((0, 0, 3), (0, 0, 0)), bp.perspective_matrix(FOV, 1.0, 0.5, 10.0))
    return bp.Scene([mesh], [], camera, ambient=(0.0, 0.0, 0.0))


def texel_interior(scene: bp.Scene, texture: Texture, margin: float) -> np.ndarray:
    return renderer_scenes.texel_interior(scene, texture, SIZE, SIZE, margin)


def test_closest_texture_matches_cycles(tmp_path) -> None:
    pytest.importorskip("bpy")
    run_bpy = _addon_testing().run_bpy

    image = texture_image()
    args = {
        "image": image.tolist(),
        "extensions": list(EXTENSIONS),
        "size": SIZE,
        "fov": FOV,
        "tilt": TILT,
        "uv": [UV_LOW, UV_HIGH],
        "dir": str(tmp_path),
    }
    cycles = run_bpy(CYCLES, tmp_path, args=(json.dumps(args),), timeout=300)
    for ext in EXTENSIONS:
        texture = Texture(image, interpolation="closest", extension=ext)
        scene = our_scene(texture)
        ours = bp.render(scene, SIZE, SIZE, engine="numpy").rgba
        theirs = np.array(cycles[ext], np.float32)
        mask = interior_mask(scene, SIZE, SIZE) & texel_interior(scene, texture, 0.05)
        assert mask.sum() > 1000, ext
        err = np.abs(ours[..., :3] - theirs[..., :3]).max(axis=-1)[mask]
        assert err.max() <= 1e-6, (ext, float(err.max()), int((err > 1e-6).sum()))


# --- Image Texture → Principled BSDF: what the add-on converts against what Cycles renders -----

PRINCIPLED = """
import bpy
import numpy as np
from addon import convert

args = json.loads(sys.argv[-1])
out = {}
for case in args["cases"]:
    renders = {}
    for shader in ("principled", "emission"):
        bpy.ops.wm.read_factory_settings(use_empty=True)
        scene = bpy.context.scene
        scene.render.engine = "CYCLES"
        scene.cycles.device = "CPU"
        scene.cycles.samples = 1
        scene.cycles.use_denoising = False
        scene.cycles.use_adaptive_sampling = False
        scene.cycles.pixel_filter_type = "BOX"
        scene.render.filter_size = 0.01
        scene.render.film_transparent = True
        scene.render.resolution_x = scene.render.resolution_y = args["size"]
        scene.render.resolution_percentage = 100
        scene.view_settings.view_transform = "Standard"
        world = bpy.data.worlds.new("black")
        world.color = (0.0, 0.0, 0.0)
        if world.node_tree is not None:
            for node in world.node_tree.nodes:
                if node.type == "BACKGROUND":
                    node.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
        scene.world = world

        pixels = np.array(case["pixels"], np.float32)  # row 0 at the top
        h, w = pixels.shape[:2]
        image = bpy.data.images.new("tex", w, h, alpha=True, float_buffer=case["float"])
        image.colorspace_settings.name = case["colorspace"]
        image.pixels.foreach_set(np.ascontiguousarray(pixels[::-1]).ravel())

        material = bpy.data.materials.new("m")
        material.use_nodes = True
        nodes, links = material.node_tree.nodes, material.node_tree.links
        nodes.clear()
        tex = nodes.new("ShaderNodeTexImage")
        tex.image = image
        tex.interpolation = "Closest"
        tex.extension = "CLIP"
        output = nodes.new("ShaderNodeOutputMaterial")
        if shader == "principled":  # the film alpha is the surface's opacity
            bsdf = nodes.new("ShaderNodeBsdfPrincipled")
            links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
            if case["alpha_linked"]:
                links.new(tex.outputs["Alpha"], bsdf.inputs["Alpha"])
            links.new(bsdf.outputs["BSDF"], output.inputs["Surface"])
        else:  # the Color output itself, as the Principled BSDF receives it
            emission = nodes.new("ShaderNodeEmission")
            links.new(tex.outputs["Color"], emission.inputs["Color"])
            if case["alpha_linked"]:  # a linked Alpha output makes Color unassociated; strength 1
                strength = nodes.new("ShaderNodeMath")
                strength.operation = "MAXIMUM"
                strength.inputs[1].default_value = 1.0
                links.new(tex.outputs["Alpha"], strength.inputs[0])
                links.new(strength.outputs["Value"], emission.inputs["Strength"])
            links.new(emission.outputs["Emission"], output.inputs["Surface"])

        lo, hi = args["uv"]
        mesh = bpy.data.meshes.new("plane")
        mesh.from_pydata([(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)], [], [(0, 1, 2, 3)])
        uv = mesh.uv_layers.new(name="UVMap")
        corner = {0: (lo, lo), 1: (hi, lo), 2: (hi, hi), 3: (lo, hi)}
        for loop in mesh.loops:
            uv.data[loop.index].uv = corner[loop.vertex_index]
        mesh.materials.append(material)
        plane = bpy.data.objects.new("plane", mesh)
        scene.collection.objects.link(plane)
        cam_data = bpy.data.cameras.new("cam")
        cam_data.type = "ORTHO"
        cam_data.ortho_scale = 2.0
        cam_data.clip_start, cam_data.clip_end = 0.5, 10.0
        camera = bpy.data.objects.new("cam", cam_data)
        camera.location = (0.0, 0.0, 3.0)
        scene.collection.objects.link(camera)
        scene.camera = camera

        if shader == "principled":
            converted = convert.scene_from_depsgraph(bpy.context.evaluated_depsgraph_get())
            m = converted.scene.meshes[0]
            t = m.material.base_color_texture
            renders["converted"] = {
                "positions": m.positions.tolist(), "triangles": m.triangles.tolist(),
                "transform": m.transform.tolist(), "uv": m.uv.tolist(), "opacity": m.material.opacity,
                "image": t.image.tolist(), "interpolation": t.interpolation, "extension": t.extension,
                "use_alpha": t.use_alpha,
            }
        path = args["dir"] + f"/{case['name']}_{shader}.exr"
        scene.render.image_settings.file_format = "OPEN_EXR"
        scene.render.image_settings.color_depth = "32"
        scene.render.filepath = path
        bpy.ops.render.render(write_still=True)
        result = bpy.data.images.load(path)
        px = np.empty(args["size"] ** 2 * 4, np.float32)
        result.pixels.foreach_get(px)
        renders[shader] = px.reshape(args["size"], args["size"], 4)[::-1].tolist()
    out[case["name"]] = renders
emit(out)
"""

# A 2×2 image, row 0 at the top. Byte images: straight values whose products c·a are multiples
# of 1/255 (Cycles associates the stored bytes: no rounding there); one texel fully transparent.
BYTE_PIXELS = np.array(
    [[[255, 0, 255, 102], [51, 153, 204, 255]], [[255, 255, 0, 0], [0, 255, 255, 51]]], np.float64
) / 255.0
FLOAT_PIXELS = [[[0.4, 0.2, 0.1, 0.5], [0.3, 0.6, 0.9, 1.0]], [[0.0, 0.0, 0.0, 0.0], [0.05, 0.1, 0.2, 0.25]]]
PRINCIPLED_CASES = [
    {"name": "color_only_byte", "pixels": BYTE_PIXELS.tolist(), "float": False, "colorspace": "sRGB",
     "alpha_linked": False},
    {"name": "color_alpha_byte", "pixels": BYTE_PIXELS.tolist(), "float": False, "colorspace": "sRGB",
     "alpha_linked": True},
    {"name": "color_only_float", "pixels": FLOAT_PIXELS, "float": True, "colorspace": "Linear Rec.709",
     "alpha_linked": False},
]  # fmt: skip


def test_image_texture_into_principled_matches_cycles_opacity_and_colour(tmp_path) -> None:
    """Clip, Closest; Color → Base Color alone or with Alpha → Alpha (the reported case: alone).

    Cycles renders the plane twice per case, one sample, film transparent, black world: with the
    Principled BSDF (its film alpha is the surface's opacity) and with the node's Color output
    through an Emission shader (the colour the Base Color receives; its Alpha output linked in
    the same way, since that changes the Color output). The add-on converts the Principled
    scene; ours renders the converted plane, uv and texture with an emission-only material of
    the converted opacity. Ours must give Cycles' alpha (opaque outside the image when only
    Color is linked; with Alpha linked, where the texel alpha is 0 or 1 — Cycles samples a
    fractional one stochastically) and, where ours is not transparent, its straight colour must
    be Cycles' Color output (pixel centres lie ≥ 1/8 texel from texel boundaries).
    """
    pytest.importorskip("bpy")
    size = 8
    args = {"cases": PRINCIPLED_CASES, "size": size, "uv": [-0.5, 1.5], "dir": str(tmp_path)}
    cycles = _addon_testing().run_bpy(PRINCIPLED, tmp_path, args=(json.dumps(args),), timeout=600)
    camera = bp.Camera(bp.look_at((0, 0, 3), (0, 0, 0)), bp.orthographic_matrix(-1, 1, -1, 1, 0.5, 10.0))
    for case in PRINCIPLED_CASES:
        got = cycles[case["name"]]
        c = got["converted"]
        texture = Texture(
            np.array(c["image"], np.float32),
            interpolation=c["interpolation"],
            extension=c["extension"],
            use_alpha=c["use_alpha"],
        )
        material = bp.Material(
            ambient=(0, 0, 0), diffuse=(0, 0, 0), emission=(1, 1, 1), opacity=c["opacity"],
            base_color_texture=texture,
        )  # fmt: skip
        mesh = bp.Mesh(
            np.array(c["positions"]), np.array(c["triangles"]), transform=np.array(c["transform"]),
            material=material, uv=np.array(c["uv"]),
        )  # fmt: skip
        scene = bp.Scene([mesh], [], camera, ambient=(0.0, 0.0, 0.0))
        ours = bp.render(scene, size, size, engine="numpy").rgba
        principled = np.array(got["principled"])
        colour = np.array(got["emission"])[..., :3]
        name = case["name"]
        # A fractional Principled Alpha is sampled stochastically by Cycles (one sample gives a
        # film alpha of 1 or of a fraction of it): opacity is compared where it is 0 or 1.
        decided = (ours[..., 3] == 0.0) | (ours[..., 3] == 1.0)
        alpha_ours, alpha_cycles = ours[..., 3][decided], principled[..., 3][decided]
        np.testing.assert_allclose(alpha_ours, alpha_cycles, atol=1e-6, err_msg=name)
        assert (principled[..., 3][~decided] > 0.0).all(), name
        seen = ours[..., 3] > 0
        assert seen.sum() >= 12, name  # 3 or 4 of the 4 texels × 4 pixels
        straight = ours[..., :3][seen] / ours[..., 3:4][seen]
        np.testing.assert_allclose(straight, colour[seen], atol=2e-6, err_msg=name)
        if not case["alpha_linked"]:  # the reported case: opaque black outside the Clip image
            assert (principled[..., 3] == 1.0).all() and (ours[..., 3] == 1.0).all(), name

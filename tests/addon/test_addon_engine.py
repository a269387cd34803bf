"""The render engine inside Blender: registration, F12-style renders, passes, border, failures.

Pixels are compared with ``blinn_phong.frame.render`` on a scene built by hand here (not through the
converter), so a conversion mistake cannot hide behind the same mistake on both sides.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import OpenImageIO as oiio  # noqa: N813 (the library's documented alias)
import pytest
from addon_testing import run_bpy

pytestmark = [pytest.mark.blender, pytest.mark.timeout(300)]

# A rotated cube (Blender's primitive: corners at ±1) with custom Blinn-Phong coefficients, one sun,
# and a perspective camera on the -Y axis looking at the origin.
CUBE_SCENE = """
import math, sys
import bpy
from addon import compat, engine, properties

bpy.ops.wm.read_factory_settings(use_empty=True)
properties.register()
engine.register()
scene = bpy.context.scene
bpy.ops.mesh.primitive_cube_add(size=2.0, location=(0.2, 0.0, -0.1), rotation=(0.5, 0.3, 0.7))
cube = bpy.context.active_object
mat = bpy.data.materials.new("Paint")
mat.blinn_phong.source = "CUSTOM"
mat.blinn_phong.ambient = (0.2, 0.1, 0.05)
mat.blinn_phong.diffuse = (0.7, 0.35, 0.2)
mat.blinn_phong.specular = (0.5, 0.5, 0.5)
mat.blinn_phong.shininess = 24.0
cube.data.materials.append(mat)
cam = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
cam.location = (0.0, -6.0, 0.0)
cam.rotation_euler = (math.pi / 2, 0.0, 0.0)
cam.data.lens, cam.data.sensor_width, cam.data.sensor_fit = 50.0, 36.0, "HORIZONTAL"
cam.data.clip_start, cam.data.clip_end = 0.5, 30.0
scene.collection.objects.link(cam)
scene.camera = cam
sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
sun.data.energy = 2.0
sun.rotation_euler = (0.6, 0.0, 0.4)
scene.collection.objects.link(sun)
scene.world = bpy.data.worlds.new("World")
scene.world.color = (0.1, 0.1, 0.1)
if compat.world_uses_nodes(scene.world):
    scene.world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.1, 0.1, 0.1, 1.0)
scene.render.engine = "BLINN_PHONG"
scene.render.film_transparent = True
scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 96, 64, 100
scene.blinn_phong.samples_per_axis = 2
scene.blinn_phong.two_sided = False
scene.render.image_settings.file_format = "OPEN_EXR"
scene.render.image_settings.color_depth = "32"
scene.render.image_settings.color_mode = "RGBA"
scene.render.filepath = sys.argv[1]
"""

RENDER_F12 = (
    CUBE_SCENE
    + """
status = bpy.ops.render.render(write_still=True)
last = dict(engine.LAST_RENDER)
# Each extra pass through the compositor: Render Layers output -> final output, one render each.
tree = compat.compositor_tree(scene)
compat.set_full_precision(scene)
layers_node = tree.nodes.new("CompositorNodeRLayers")
outputs = [o.name for o in layers_node.outputs if o.enabled]
final = compat.add_render_output(tree)
for name in ("Depth", "Ambient", "Diffuse", "Specular"):
    for link in list(tree.links):
        tree.links.remove(link)
    tree.links.new(layers_node.outputs[name], final)
    scene.render.filepath = sys.argv[1].replace(".exr", f"_{name}.exr")
    bpy.ops.render.render(write_still=True)
engine.unregister()
properties.unregister()
emit({"status": sorted(status), "last": {k: last[k] for k in ("ok", "error", "size")}, "outputs": outputs})
"""
)


def _read_exr(path: Path) -> np.ndarray:
    """An EXR as (H, W, C) float32, row 0 at the top."""
    image = oiio.ImageInput.open(str(path))
    assert image is not None, oiio.geterror()
    try:
        return image.read_image(oiio.FLOAT)
    finally:
        image.close()


def _hand_scene():
    from blinn_phong.model.lights import DirectionalLight
    from blinn_phong.model.scene import Camera, LightModel, Material, Mesh, Scene
    from blinn_phong.model.transforms import look_at

    def euler(rx: float, ry: float, rz: float) -> np.ndarray:
        cx, sx, cy, sy, cz, sz = (
            math.cos(rx),
            math.sin(rx),
            math.cos(ry),
            math.sin(ry),
            math.cos(rz),
            math.sin(rz),
        )
        return (
            np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
            @ np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
            @ np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
        )

    positions, normals, triangles = [], [], []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            n = np.zeros(3)
            n[axis] = sign
            u, v = np.eye(3)[(axis + 1) % 3], np.eye(3)[(axis + 2) % 3]  # u × v = +axis
            if sign < 0:
                u, v = v, u
            corners = [n + a * u + b * v for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
            base = len(positions)
            positions += corners
            normals += [n] * 4
            triangles += [(base, base + 1, base + 2), (base, base + 2, base + 3)]
    transform = np.eye(4)
    transform[:3, :3] = euler(0.5, 0.3, 0.7)
    transform[:3, 3] = (0.2, 0.0, -0.1)
    material = Material(
        ambient=(0.2, 0.1, 0.05), diffuse=(0.7, 0.35, 0.2), specular=(0.5, 0.5, 0.5), shininess=24.0
    )
    mesh = Mesh(np.array(positions), np.array(triangles), np.array(normals), transform, material)
    sun_direction = euler(0.6, 0.0, 0.4) @ np.array([0.0, 0.0, -1.0])
    light = DirectionalLight(direction=sun_direction, intensity=2.0 / math.pi)
    fov_x = 2 * math.atan(18.0 / 50.0)
    fov_y = math.degrees(2 * math.atan(math.tan(fov_x / 2) * 64 / 96))
    camera = Camera.perspective(fov_y, 96 / 64, 0.5, 30.0, view=look_at((0, -6, 0), (0, 0, 0), (0, 0, 1)))
    scene = Scene(
        meshes=(mesh,),
        lights=(light,),
        camera=camera,
        ambient=(0.1, 0.1, 0.1),
        light_model=LightModel(local_viewer=True, two_sided=False),
    )
    return scene, camera.projection


def test_cube_faces_are_outward_and_counter_clockwise() -> None:
    # Sanity of the hand-built cube: every triangle's winding agrees with its face normal.
    scene, _ = _hand_scene()
    m = scene.meshes[0]
    p = m.positions[m.triangles]
    cross = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    assert (np.einsum("ij,ij->i", cross, m.normals[m.triangles[:, 0]]) > 0).all()


def test_register_unregister_many_times(tmp_path: Path) -> None:
    got = run_bpy(
        """
        import bpy
        from addon import engine, properties

        def engine_available():
            scene = bpy.context.scene
            try:
                scene.render.engine = engine.ENGINE_ID
            except TypeError:
                return False
            scene.render.engine = "BLENDER_WORKBENCH"
            return True

        seen = []
        for _ in range(40):
            properties.register()
            engine.register()
            seen.append(engine_available() and hasattr(bpy.types.Scene, "blinn_phong"))
            engine.unregister()
            properties.unregister()
        emit({"seen": seen, "after": engine_available() or hasattr(bpy.types.Scene, "blinn_phong")})
        """,
        tmp_path,
    )
    assert got["seen"] == [True] * 40
    assert got["after"] is False


def test_f12_render_matches_core_renderer(tmp_path: Path) -> None:
    from blinn_phong import render

    out = tmp_path / "cube.exr"
    got = run_bpy(RENDER_F12, tmp_path, args=(str(out),))
    assert got["status"] == ["FINISHED"]
    assert got["last"] == {"ok": True, "error": None, "size": [96, 64]}
    combined = _read_exr(out)
    scene, _ = _hand_scene()
    reference = render(scene, 96, 64, shading="phong", samples=4)
    assert combined.shape == (64, 96, 4)
    assert 0.15 < combined[..., 3].mean() < 0.9  # the cube is in view, not filling it
    np.testing.assert_allclose(combined, reference.rgba, atol=2e-5)

    # The passes appear on the Render Layers node and carry the lighting terms.
    assert {"Image", "Alpha", "Depth", "Ambient", "Diffuse", "Specular"} <= set(got["outputs"])
    light = {
        name: _read_exr(tmp_path / f"cube_{name}.exr")[..., :3] for name in ("Ambient", "Diffuse", "Specular")
    }
    np.testing.assert_allclose(sum(light.values()), combined[..., :3], atol=1e-5)
    for name in light:
        np.testing.assert_allclose(light[name], reference.passes[name.lower()], atol=2e-5)
    # Depth is the view-axis distance of the nearest surface, 1e10 where nothing was hit.
    depth = _read_exr(tmp_path / "cube_Depth.exr")[..., 0]
    assert (depth[combined[..., 3] == 0] == 1e10).all()
    near, far = 0.5, 30.0
    ndc = 2.0 * reference.depth.astype(np.float64) - 1.0
    distance = 2 * far * near / ((far + near) - ndc * (far - near))  # gluPerspective depth inverted
    full = combined[..., 3] == 1
    np.testing.assert_allclose(depth[full], distance[full], rtol=1e-4)
    assert 4.0 < depth[full].min() < depth[full].max() < 8.0


def test_film_not_transparent_shows_the_world_behind(tmp_path: Path) -> None:
    from blinn_phong import render

    out = tmp_path / "world.exr"
    script = (
        CUBE_SCENE
        + """
scene.render.film_transparent = False
bpy.ops.render.render(write_still=True)
engine.unregister()
properties.unregister()
emit(True)
"""
    )
    run_bpy(script, tmp_path, args=(str(out),))
    scene, _ = _hand_scene()
    reference = render(scene, 96, 64, shading="phong", samples=4).rgba
    # Porter-Duff src over an opaque world colour: C + (1 - α)·world, α = 1.
    expected = reference + (1.0 - reference[..., 3:4]) * np.array([0.1, 0.1, 0.1, 1.0], np.float32)
    np.testing.assert_allclose(_read_exr(out), expected, atol=2e-5)


@pytest.mark.parametrize("crop", [True, False])
def test_render_border_renders_only_the_border(tmp_path: Path, crop: bool) -> None:
    from blinn_phong import render

    out = tmp_path / "border.exr"
    got = run_bpy(
        CUBE_SCENE
        + f"""
scene.render.use_border = True
scene.render.use_crop_to_border = {crop}
scene.render.border_min_x, scene.render.border_max_x = 0.25, 0.75
scene.render.border_min_y, scene.render.border_max_y = 0.0, 0.5
status = bpy.ops.render.render(write_still=True)
engine.unregister()
properties.unregister()
emit(sorted(status))
""",
        tmp_path,
        args=(str(out),),
    )
    assert got == ["FINISHED"]
    image = _read_exr(out)
    # 96×64 frame, x 0.25–0.75 -> columns 24..72; y 0–0.5 from the bottom -> rows 32..64 from the top.
    full = render(_hand_scene()[0], 96, 64, shading="phong", samples=4).rgba
    assert full[32:64, 24:72, 3].max() == 1.0 and full[:32, 24:72, 3].max() == 1.0  # cube on both sides
    if crop:
        assert image.shape == (32, 48, 4)
        np.testing.assert_allclose(image, full[32:64, 24:72], atol=2e-5)
    else:  # the full frame, empty outside the border
        assert image.shape == (64, 96, 4)
        np.testing.assert_allclose(image[32:64, 24:72], full[32:64, 24:72], atol=2e-5)
        outside = np.ones((64, 96), bool)
        outside[32:64, 24:72] = False
        assert (image[outside] == 0).all()


def test_failure_exits_non_zero_in_background_and_is_never_black(tmp_path: Path) -> None:
    failing = (
        CUBE_SCENE
        + """
cam.data.type = "PANO"
scene.blinn_phong.abort_on_error = {abort}
try:
    bpy.ops.render.render(write_still=True)
    raised = None
except RuntimeError as error:
    raised = str(error)
last = dict(engine.LAST_RENDER)
engine.unregister()
properties.unregister()
emit({{"ok": last["ok"], "error": last["error"], "raised": raised}})
"""
    )
    out = tmp_path / "fail.exr"
    got = run_bpy(failing.format(abort="False"), tmp_path, args=(str(out),))
    assert got["ok"] is False and "panoramic" in got["error"]
    # The operator itself fails (Python callers get a RuntimeError) ...
    assert got["raised"] is not None and "Blinn-Phong render failed" in got["raised"]
    # ... and if Blender wrote a file at all, it holds the magenta/black error pattern, not a plausible frame.
    if out.exists():
        combined = _read_exr(out)
        assert (combined[..., 3] == 1).all()
        assert combined[..., 0].max() == 1.0 and (combined[..., 1] == 0).all()

    import subprocess
    import sys

    from addon_testing import REPO

    script = tmp_path / "abort.py"
    script.write_text(
        f"import json, sys\nsys.path.insert(0, {str(REPO)!r})\nemit = print\n" + failing.format(abort="True")
    )
    done = subprocess.run(
        [sys.executable, str(script), str(tmp_path / "abort.exr")],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    # Inside the bpy module (an embedding Python) abort_on_error does not end the process: the
    # script's own try/except sees the failure as RuntimeError (blender -b still exits with 1).
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    assert "Blinn-Phong render failed: ValueError" in done.stderr
    assert "'raised': \"Error: Blinn-Phong render failed: ValueError" in done.stdout


def test_cancel_stops_and_leaves_the_error_pattern(tmp_path: Path) -> None:
    # Blender's test_break() turns True when the user presses Esc; the engine stops, reports no error,
    # and (Blender crashes saving a still from an empty result) leaves the pattern, not a finished frame.
    out = tmp_path / "cancelled.exr"
    got = run_bpy(
        CUBE_SCENE
        + """
engine.user_cancelled = lambda render_engine: True  # as if Esc were pressed at the first check
try:
    bpy.ops.render.render(write_still=True)
    raised = None
except RuntimeError as error:
    raised = str(error)
last = dict(engine.LAST_RENDER)
engine.unregister()
properties.unregister()
emit({"ok": last["ok"], "error": last["error"], "raised": raised})
""",
        tmp_path,
        args=(str(out),),
    )
    assert got == {"ok": False, "error": "cancelled", "raised": None}
    combined = _read_exr(out)
    assert (combined[..., 3] == 1).all() and (combined[..., 1] == 0).all() and combined[..., 0].max() == 1.0


def test_each_view_layer_gets_its_own_render(tmp_path: Path) -> None:
    # A second view layer excludes the cube's collection: its Render Layers output must be empty.
    got = run_bpy(
        CUBE_SCENE
        + """
coll = bpy.data.collections.new("Things")
scene.collection.children.link(coll)
scene.collection.objects.unlink(cube)
coll.objects.link(cube)
second = scene.view_layers.new("Without Cube")
second.layer_collection.children["Things"].exclude = True
tree = compat.compositor_tree(scene)
compat.set_full_precision(scene)
layer_node = tree.nodes.new("CompositorNodeRLayers")
final = compat.add_render_output(tree)
tree.links.new(layer_node.outputs["Image"], final)
alphas = {}
for name in (scene.view_layers[0].name, "Without Cube"):
    layer_node.layer = name
    scene.render.filepath = sys.argv[1].replace(".exr", f"_{len(alphas)}.exr")
    bpy.ops.render.render(write_still=True)
    alphas[name] = scene.render.filepath
engine.unregister()
properties.unregister()
emit(alphas)
""",
        tmp_path,
        args=(str(tmp_path / "layers.exr"),),
    )
    with_cube, without_cube = (_read_exr(Path(p)) for p in got.values())
    assert 0.15 < with_cube[..., 3].mean() < 0.9
    assert (without_cube == 0).all()


def test_renders_with_only_what_blender_ships(tmp_path: Path) -> None:
    # Blender's Python has numpy and OpenImageIO but not embreex, numba or colour-science.
    from addon_testing import REPO

    got = run_bpy(
        """
        import sys
        for name in ("embreex", "numba", "colour"):
            sys.modules[name] = None  # any import of these now raises ImportError
        import bpy
        from addon import engine, properties
        properties.register()
        engine.register()
        try:
            bpy.ops.wm.open_mainfile(filepath=sys.argv[1], load_ui=False)
            bpy.context.scene.render.resolution_percentage = 25
            bpy.ops.render.render()
            last = dict(engine.LAST_RENDER)
        finally:
            engine.unregister()
            properties.unregister()
        emit({"ok": last["ok"], "error": last["error"], "shadows": last["choices"]["shadows"],
              "reasons": last["choices"]["reasons"]})
        """,
        tmp_path,
        args=(str(REPO / "blend_files" / "shadows.blend"),),
    )
    assert got["ok"] is True, got["error"]
    assert got["shadows"] == ["shadow_volume", "shadow_volume"]
    assert sum("Embree" in r for r in got["reasons"]) == 2

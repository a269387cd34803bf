"""addon.convert on real Blender scenes, against hand-computed matrices and Blender's own camera maths."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from addon_testing import run_bpy

# numpy 2 renamed trapz to trapezoid (numpy 1.26, for Blender 4.2–5.0, has only trapz).
_trapezoid = getattr(np, "trapezoid", None) or np.trapz

pytestmark = [pytest.mark.blender, pytest.mark.timeout(300)]

SCENE_SCRIPT = """
import math
from pathlib import Path
import bpy
import numpy as np
from addon import convert, properties

bpy.ops.wm.read_factory_settings(use_empty=True)
properties.register()
scene = bpy.context.scene

def new_mesh(name, verts, faces):
    me = bpy.data.meshes.new(name)
    me.from_pydata(verts, [], faces)
    me.update()
    return me

# A parented, scaled, rotated mesh with an Array modifier (object-space offset 0, 0, 2).
parent = bpy.data.objects.new("Parent", None)
parent.location = (1.0, -2.0, 0.5)
parent.rotation_euler = (0.3, -0.2, 0.9)
parent.scale = (2.0, 0.5, 1.5)
child = bpy.data.objects.new("Child", new_mesh("Tri", [(0, 0, 0), (1, 0, 0), (0, 1, 0)], [(0, 1, 2)]))
child.location = (0.5, 0.25, -1.0)
child.rotation_euler = (-0.4, 0.7, 0.1)
child.scale = (1.0, 3.0, 0.5)
child.parent = parent
mod = child.modifiers.new("Array", "ARRAY")
mod.count = 2
mod.use_relative_offset = False
mod.use_constant_offset = True
mod.constant_offset_displace = (0.0, 0.0, 2.0)
for ob in (parent, child):
    scene.collection.objects.link(ob)

# A quad with custom split normals.
quad = new_mesh("Quad", [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], [(0, 1, 2, 3)])
custom = [(0.0, 0.0, 1.0), (0.6, 0.0, 0.8), (0.0, 0.6, 0.8), (-0.6, 0.0, 0.8)]
quad.normals_split_custom_set(custom)
quad_obj = bpy.data.objects.new("Quad", quad)
quad_obj.location = (5.0, 0.0, 0.0)
scene.collection.objects.link(quad_obj)

# An object hidden from the camera (Visibility > Camera off) is not rendered.
hidden = bpy.data.objects.new("Hidden", new_mesh("HiddenTri", [(0, 0, 0), (1, 0, 0), (0, 1, 0)], [(0, 1, 2)]))
hidden.visible_camera = False
scene.collection.objects.link(hidden)

# A mirrored copy (negative scale) of the triangle.
mirror = bpy.data.objects.new("Mirror", new_mesh("MirrorTri", [(0, 0, 0), (1, 0, 0), (0, 1, 0)], [(0, 1, 2)]))
mirror.scale = (-1.0, 1.0, 1.0)
mirror.location = (-5.0, 0.0, 0.0)
scene.collection.objects.link(mirror)

# Two faces folded 90° along a sharp edge, shaded smooth: corners keep their own face's normal.
fold = new_mesh("Fold", [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (1, 0, -1), (0, 0, -1)],
                [(0, 1, 2, 3), (5, 4, 1, 0)])
fold.shade_smooth()
fold.edges[[set(e.vertices) for e in fold.edges].index({0, 1})].use_edge_sharp = True
fold_obj = bpy.data.objects.new("Fold", fold)
fold_obj.location = (0.0, 5.0, 0.0)
scene.collection.objects.link(fold_obj)
smooth = new_mesh("Smooth", [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (1, 0, -1), (0, 0, -1)],
                  [(0, 1, 2, 3), (5, 4, 1, 0)])
smooth.shade_smooth()
smooth_obj = bpy.data.objects.new("Smooth", smooth)
smooth_obj.location = (0.0, 8.0, 0.0)
scene.collection.objects.link(smooth_obj)

# A collection instance of a mesh whose collection has an instance offset.
coll = bpy.data.collections.new("Src")
src = bpy.data.objects.new("Src", new_mesh("SrcTri", [(0, 0, 0), (1, 0, 0), (0, 0, 1)], [(0, 1, 2)]))
src.location = (0.0, 1.0, 0.0)
coll.objects.link(src)
coll.instance_offset = (0.0, 0.5, 0.0)
inst = bpy.data.objects.new("Inst", None)
inst.instance_type = "COLLECTION"
inst.instance_collection = coll
inst.location = (-3.0, 0.0, 1.0)
inst.rotation_euler = (0.0, 0.0, math.pi / 2)
scene.collection.objects.link(inst)

# Orthographic camera with shift, non-square frame, 50 % resolution.
cam = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
cam.location = (0.0, -10.0, 3.0)
cam.rotation_euler = (1.2, 0.0, 0.1)
cam.data.type = "ORTHO"
cam.data.ortho_scale = 7.0
cam.data.shift_x = 0.1
cam.data.shift_y = -0.05
cam.data.clip_start = 0.5
cam.data.clip_end = 40.0
scene.collection.objects.link(cam)
scene.camera = cam
scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 320, 200, 50

# A spot light.
spot = bpy.data.objects.new("Spot", bpy.data.lights.new("Spot", "SPOT"))
spot.data.energy = 500.0
spot.data.spot_size = math.radians(60.0)
spot.data.spot_blend = 0.3
spot.data.shadow_soft_size = 0.2
spot.data.diffuse_factor = 0.5
spot.data.specular_factor = 2.0
exposure = 1.0 if hasattr(spot.data, "exposure") else 0.0  # Blender 5.0: power × 2^exposure
if exposure:
    spot.data.exposure = exposure
spot.location = (0.0, 0.0, 4.0)
scene.collection.objects.link(spot)

dg = bpy.context.evaluated_depsgraph_get()
c = convert.scene_from_depsgraph(dg)
blender_projection = np.array(cam.evaluated_get(dg).calc_matrix_camera(dg, x=160, y=100))
scene.render.use_border = True
scene.render.border_min_x, scene.render.border_max_x = 0.1, 0.55
scene.render.border_min_y, scene.render.border_max_y = 0.2, 0.9
dg = bpy.context.evaluated_depsgraph_get()
b = convert.scene_from_depsgraph(dg)
properties.unregister()

def mesh_info(m):
    used = np.unique(m.triangles)
    world = (np.c_[m.positions, np.ones(len(m.positions))] @ m.transform.T)[:, :3][m.triangles]
    winding = np.cross(world[:, 1] - world[:, 0], world[:, 2] - world[:, 0])
    normal_matrix = np.linalg.inv(m.transform[:3, :3]).T
    world_normals = m.normals[m.triangles[:, 0]] @ normal_matrix.T
    return {"transform": m.transform.tolist(), "positions": m.positions[used].tolist(),
            "normals": m.normals[used].tolist(), "n_triangles": len(m.triangles),
            "winding_agrees": bool((np.einsum("ij,ij->i", winding, world_normals) > 0).all())}

light = c.scene.lights[0]
emit({
    "names": c.mesh_names,
    "meshes": {n: mesh_info(m) for n, m in zip(c.mesh_names, c.scene.meshes)},
    "size": [c.width, c.height], "region": list(c.region),
    "view": c.scene.camera.view.tolist(), "projection": c.scene.camera.projection.tolist(),
    "blender_projection": blender_projection.tolist(), "kind": c.scene.camera.kind,
    "local_viewer": c.scene.light_model.local_viewer,
    "border_region": list(b.region), "border_projection": b.scene.camera.projection.tolist(),
    "light": {"type": type(light).__name__, "position": light.position, "direction": light.direction,
              "cutoff": light.cutoff, "exponent": light.exponent, "diffuse": light.diffuse,
              "specular": light.specular, "exposure": exposure,
              "k": [light.constant, light.linear, light.quadratic]},
})
"""


def _euler_xyz(rx: float, ry: float, rz: float) -> np.ndarray:
    """Blender's XYZ Euler: R = Rz · Ry · Rx."""
    cx, sx, cy, sy, cz, sz = (
        math.cos(rx),
        math.sin(rx),
        math.cos(ry),
        math.sin(ry),
        math.cos(rz),
        math.sin(rz),
    )
    r_x = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    r_y = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    r_z = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return r_z @ r_y @ r_x


def _trs(location: tuple, rotation: tuple, scale: tuple) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = _euler_xyz(*rotation) @ np.diag(scale)
    m[:3, 3] = location
    return m


@pytest.fixture(scope="module")
def converted(tmp_path_factory: pytest.TempPathFactory) -> dict:
    return run_bpy(SCENE_SCRIPT, tmp_path_factory.mktemp("convert"), timeout=180)


def test_parented_scaled_rotated_object_transform(converted: dict) -> None:
    parent = _trs((1.0, -2.0, 0.5), (0.3, -0.2, 0.9), (2.0, 0.5, 1.5))
    child = _trs((0.5, 0.25, -1.0), (-0.4, 0.7, 0.1), (1.0, 3.0, 0.5))
    mesh = converted["meshes"]["Child/(none)"]
    np.testing.assert_allclose(mesh["transform"], parent @ child, atol=1e-5)


def test_modifier_result_is_converted(converted: dict) -> None:
    mesh = converted["meshes"]["Child/(none)"]
    assert mesh["n_triangles"] == 2
    base = np.array([(0, 0, 0), (1, 0, 0), (0, 1, 0)], dtype=float)
    expected = np.concatenate([base, base + np.array([0.0, 0.0, 2.0])])
    got = np.array(mesh["positions"])
    assert sorted(map(tuple, got.round(6))) == sorted(map(tuple, expected.round(6)))


def test_custom_split_normals_reach_the_renderer(converted: dict) -> None:
    mesh = converted["meshes"]["Quad/(none)"]
    by_position = {tuple(np.round(p, 6)): n for p, n in zip(mesh["positions"], mesh["normals"], strict=True)}
    custom = {
        (0, 0, 0): (0.0, 0.0, 1.0),
        (1, 0, 0): (0.6, 0.0, 0.8),
        (1, 1, 0): (0.0, 0.6, 0.8),
        (0, 1, 0): (-0.6, 0.0, 0.8),
    }
    for position, normal in custom.items():
        np.testing.assert_allclose(by_position[tuple(float(v) for v in position)], normal, atol=2e-3)


def test_object_hidden_from_the_camera_is_not_converted(converted: dict) -> None:
    assert "Hidden/(none)" not in converted["names"]
    assert "Mirror/(none)" in converted["names"]


def test_mirrored_object_keeps_its_faces_front_facing(converted: dict) -> None:
    # Counter-clockwise winding in world space must agree with the (inverse-transpose) world normal.
    assert converted["meshes"]["Mirror/(none)"]["winding_agrees"] is True
    assert converted["meshes"]["Child/(none)"]["winding_agrees"] is True


def test_sharp_edge_splits_normals_and_smooth_edge_shares_them(converted: dict) -> None:
    def normals_at(name: str, position: tuple[float, float, float]) -> list[tuple[float, ...]]:
        mesh = converted["meshes"][f"{name}/(none)"]
        return sorted(
            {
                tuple(np.round(n, 4))
                for p, n in zip(mesh["positions"], mesh["normals"], strict=True)
                if np.allclose(p, position)
            }
        )

    # Faces: z = 0 (normal +z) and y = 0 (normal -y), meeting along the edge from (0,0,0) to (1,0,0).
    assert normals_at("Fold", (0.0, 0.0, 0.0)) == [(0.0, -1.0, 0.0), (0.0, 0.0, 1.0)]
    # Without the sharp mark both faces share the averaged normal (0, -1, 1)/√2 on the edge.
    r = round(1 / math.sqrt(2), 4)
    assert normals_at("Smooth", (0.0, 0.0, 0.0)) == [(0.0, -r, r)]


def test_collection_instance_transform(converted: dict) -> None:
    mesh = converted["meshes"]["Src/(none)"]
    instancer = _trs((-3.0, 0.0, 1.0), (0.0, 0.0, math.pi / 2), (1, 1, 1))
    offset = np.eye(4)
    offset[:3, 3] = (0.0, -0.5, 0.0)  # the collection's instance offset is subtracted
    src = _trs((0.0, 1.0, 0.0), (0, 0, 0), (1, 1, 1))
    np.testing.assert_allclose(mesh["transform"], instancer @ offset @ src, atol=1e-6)


def test_orthographic_camera_with_shift(converted: dict) -> None:
    assert converted["size"] == [160, 100]  # 320×200 at 50 %
    assert converted["kind"] == "orthographic" and converted["local_viewer"] is False
    view = np.linalg.inv(_trs((0.0, -10.0, 3.0), (1.2, 0.0, 0.1), (1, 1, 1)))
    np.testing.assert_allclose(converted["view"], view, atol=1e-6)
    # Hand: ortho_scale 7 spans the width (160 ≥ 100); half extents 3.5 × 2.1875; shift 0.1·7, -0.05·7.
    l, r = -3.5 + 0.7, 3.5 + 0.7
    b, t = -2.1875 - 0.35, 2.1875 - 0.35
    n, f = 0.5, 40.0
    expected = np.array(
        [
            [2 / (r - l), 0, 0, -(r + l) / (r - l)],
            [0, 2 / (t - b), 0, -(t + b) / (t - b)],
            [0, 0, -2 / (f - n), -(f + n) / (f - n)],
            [0, 0, 0, 1],
        ]
    )
    np.testing.assert_allclose(converted["projection"], expected, atol=1e-6)
    np.testing.assert_allclose(converted["projection"], converted["blender_projection"], atol=1e-5)


def test_render_border_region_and_cropped_camera(converted: dict) -> None:
    # Border x 0.1–0.55 of 160 px -> 16..88; y 0.2–0.9 of 100 px from the bottom -> rows 10..80 from the top.
    assert converted["border_region"] == [16, 10, 88, 80]
    full = np.array(converted["projection"])
    cropped = np.array(converted["border_projection"])
    eye_point = np.array([0.3, -0.4, -5.0, 1.0])
    ndc_full = (full @ eye_point)[:2]
    ndc_crop = (cropped @ eye_point)[:2]
    x_full = (ndc_full[0] + 1) * 160 / 2
    y_full_from_top = 100 - (ndc_full[1] + 1) * 100 / 2
    x_crop = (ndc_crop[0] + 1) * 72 / 2
    y_crop_from_top = 70 - (ndc_crop[1] + 1) * 70 / 2
    assert x_crop == pytest.approx(x_full - 16, abs=1e-9)
    assert y_crop_from_top == pytest.approx(y_full_from_top - 10, abs=1e-9)


def test_spot_light_conversion(converted: dict) -> None:
    light = converted["light"]
    assert light["type"] == "SpotLight"
    np.testing.assert_allclose(light["position"], (0, 0, 4), atol=1e-6)
    np.testing.assert_allclose(light["direction"], (0, 0, -1), atol=1e-6)
    assert light["cutoff"] == pytest.approx(30.0)
    intensity = 500.0 * 2 ** light["exposure"] / (4 * math.pi**2)
    np.testing.assert_allclose(light["diffuse"], [0.5 * intensity] * 3, rtol=1e-6)  # Diffuse factor 0.5
    np.testing.assert_allclose(light["specular"], [2.0 * intensity] * 3, rtol=1e-6)  # Specular factor 2
    np.testing.assert_allclose(light["k"], [0.2**2, 0.0, 1.0], rtol=1e-6)
    # Same light in the cone as Blender's smoothstep mask (mean over cos θ, by quadrature).
    c = math.cos(math.radians(30.0))
    t = np.linspace(c, 1.0, 200001)
    s = np.clip((t - c) / ((1 - c) * 0.3), 0, 1)
    blender_mean = _trapezoid(s * s * (3 - 2 * s), t) / (1 - c)
    gl_mean = _trapezoid(t ** light["exponent"], t) / (1 - c)
    assert gl_mean == pytest.approx(blender_mean, abs=1e-5)


CAMERA_SWEEP = """
import itertools
import bpy
import numpy as np
from addon import convert

bpy.ops.wm.read_factory_settings(use_empty=True)
scene = bpy.context.scene
cam = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
scene.collection.objects.link(cam)
scene.camera = cam
rows = []
for kind, fit, (rx, ry), (ax, ay), shift in itertools.product(
        ("PERSP", "ORTHO"), ("AUTO", "HORIZONTAL", "VERTICAL"), ((300, 200), (150, 400)),
        ((1.0, 1.0), (2.0, 1.0), (1.0, 1.5)), ((0.0, 0.0), (0.2, -0.1))):
    cam.data.type, cam.data.sensor_fit = kind, fit
    cam.data.lens, cam.data.sensor_width, cam.data.sensor_height = 42.0, 30.0, 20.0
    cam.data.ortho_scale, cam.data.clip_start, cam.data.clip_end = 5.0, 0.2, 60.0
    cam.data.shift_x, cam.data.shift_y = shift
    scene.render.resolution_x, scene.render.resolution_y = rx, ry
    scene.render.pixel_aspect_x, scene.render.pixel_aspect_y = ax, ay
    dg = bpy.context.evaluated_depsgraph_get()
    ours = convert.camera_from_object(cam.evaluated_get(dg), scene.render).projection
    theirs = np.array(cam.evaluated_get(dg).calc_matrix_camera(dg, x=rx, y=ry, scale_x=ax, scale_y=ay))
    rows.append([kind, fit, rx, ry, ax, ay, float(np.abs(ours - theirs).max())])
emit(rows)
"""


def test_camera_projection_matches_blender_calc_matrix_camera(tmp_path: Path) -> None:
    rows = run_bpy(CAMERA_SWEEP, tmp_path)
    assert len(rows) == 72
    worst = max(rows, key=lambda r: r[-1])
    assert worst[-1] < 1e-5, worst


MATERIALS = """
import bpy
from addon import convert, properties

bpy.ops.wm.read_factory_settings(use_empty=True)
properties.register()
principled = bpy.data.materials.new("Principled")
principled.use_nodes = True
# The default Principled BSDF (first in the tree) stays as a green decoy; a second one, linked to
# the Material Output's Surface, is the one to read.
tree = principled.node_tree
tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0.0, 1.0, 0.0, 1.0)
bsdf = tree.nodes.new("ShaderNodeBsdfPrincipled")
tree.links.new(bsdf.outputs["BSDF"], tree.nodes["Material Output"].inputs["Surface"])
bsdf.inputs["Base Color"].default_value = (0.5, 0.25, 0.125, 1.0)
bsdf.inputs["Metallic"].default_value = 0.5
bsdf.inputs["Roughness"].default_value = 0.6
bsdf.inputs["IOR"].default_value = 2.0
bsdf.inputs["Emission Color"].default_value = (1.0, 0.5, 0.0, 1.0)
bsdf.inputs["Emission Strength"].default_value = 3.0
bsdf.inputs["Alpha"].default_value = 0.75
glass = bpy.data.materials.new("Glass")
g = glass.blinn_phong
g.source = "CUSTOM"
g.diffuse, g.specular, g.shininess, g.opacity = (0.1, 0.2, 0.3), (0.4, 0.4, 0.4), 50.0, 0.3
g.transparency_model, g.use_kay_greenberg, g.specular_washout = "ABSORPTION", True, True
g.kay_min_transmission, g.kay_max_transmission, g.kay_exponent = 0.2, 0.7, 3.0
g.shading = "FLAT"
out = {}
for mat in (principled, glass, None):
    m, extras, notes = convert.material_from_blender(mat)
    out[mat.name if mat else "none"] = {
        "diffuse": m.diffuse, "ambient": m.ambient, "specular": m.specular, "emission": m.emission,
        "shininess": m.shininess, "opacity": m.opacity, "model": m.transparency_model,
        "kay": m.kay_greenberg, "washout": m.specular_washout, "shading": extras["shading"],
    }
properties.unregister()
emit(out)
"""


def test_materials_from_principled_and_custom_settings(tmp_path: Path) -> None:
    got = run_bpy(MATERIALS, tmp_path)
    p = got["Principled"]
    # Metallic 0.5: diffuse = base·(1 − m); F0 = mix(2·0.5·((2−1)/(2+1))², base, m); s = 2/α² − 2, α = 0.36.
    base = np.array([0.5, 0.25, 0.125])
    s = 2 / 0.36**2 - 2
    f0 = 0.5 * (1 / 9) + 0.5 * base
    np.testing.assert_allclose(p["diffuse"], base * 0.5, rtol=1e-6)
    np.testing.assert_allclose(p["ambient"], base * 0.5, rtol=1e-6)
    np.testing.assert_allclose(p["specular"], f0 * (s + 8) / 8, rtol=1e-5)
    assert p["shininess"] == pytest.approx(s, rel=1e-5)
    np.testing.assert_allclose(p["emission"], (3.0, 1.5, 0.0), rtol=1e-6)
    assert p["opacity"] == pytest.approx(0.75) and p["model"] == "partial_occlusion" and p["kay"] is None
    g = got["Glass"]
    np.testing.assert_allclose(g["diffuse"], (0.1, 0.2, 0.3), rtol=1e-6)
    assert g["shininess"] == 50.0 and g["opacity"] == pytest.approx(0.3)
    assert g["model"] == "absorption" and g["washout"] is True and g["shading"] == "flat"
    np.testing.assert_allclose(g["kay"], (0.2, 0.7, 3.0), rtol=1e-6)
    # No material: the default grey derived like a Principled BSDF of base colour 0.8.
    np.testing.assert_allclose(got["none"]["diffuse"], (0.8, 0.8, 0.8), rtol=1e-6)


INSTANCES_IN_RENDER = """
import sys
import bpy
import numpy as np
from addon import convert, engine, properties

properties.register()
engine.register()
bpy.ops.wm.read_factory_settings(use_empty=True)
scene = bpy.context.scene

def new_mesh(name, verts, faces):
    me = bpy.data.meshes.new(name)
    me.from_pydata(verts, [], faces)
    me.update()
    return me

# A small triangle "Dot" instanced at the vertices of "Dots" (moved by 7 in z).
dots = bpy.data.objects.new("Dots", new_mesh("DotsTri", [(0, 0, 0), (2, 0, 0), (0, 2, 0)], [(0, 1, 2)]))
dots.instance_type = "VERTS"
dots.location = (0.0, 0.0, 7.0)
dots.show_instancer_for_render = sys.argv[1] == "show"
dot = bpy.data.objects.new("Dot", new_mesh("DotTri", [(0, 0, 0), (0.1, 0, 0), (0, 0.1, 0)], [(0, 1, 2)]))
dot.parent = dots
cam = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
cam.location = (1.0, 1.0, 20.0)
for ob in (dots, dot, cam):
    scene.collection.objects.link(ob)
scene.camera = cam
scene.render.engine = "BLINN_PHONG"
scene.render.resolution_x, scene.render.resolution_y = 16, 16
seen = []
convert_scene = convert.scene_from_depsgraph
def recording(depsgraph):  # what the engine converts from the render depsgraph
    converted = convert_scene(depsgraph)
    seen.extend((n, np.round(m.transform[:3, 3], 6).tolist()) for n, m in zip(converted.mesh_names,
                                                                               converted.scene.meshes))
    return converted
convert.scene_from_depsgraph = recording
bpy.ops.render.render()
ok = engine.LAST_RENDER["ok"]
engine.unregister()
properties.unregister()
emit({"ok": ok, "seen": sorted(seen)})
"""


@pytest.mark.parametrize("instancer", ["show", "hide"])
def test_vertex_instances_in_the_render_depsgraph(tmp_path: Path, instancer: str) -> None:
    got = run_bpy(INSTANCES_IN_RENDER, tmp_path, args=(instancer,))
    assert got["ok"] is True
    dots = [position for name, position in got["seen"] if name == "Dot/(none)"]
    # One Dot per vertex of Dots, (0,0,0), (2,0,0), (0,2,0), moved with Dots to z = 7; no original.
    assert dots == [[0.0, 0.0, 7.0], [0.0, 2.0, 7.0], [2.0, 0.0, 7.0]]
    assert ("Dots/(none)" in [name for name, _ in got["seen"]]) is (instancer == "show")

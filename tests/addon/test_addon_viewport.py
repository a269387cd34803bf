"""The 3D viewport's camera and frame, inside bpy, up to the pixels handed to ``gpu``.

The bpy module has no window, so no ``RegionView3D`` exists and nothing can be drawn; the view is
described by stand-ins carrying the same attributes (``view_perspective``, ``view_matrix``,
``view_camera_zoom``, ...). Independent references: ``Object.calc_matrix_camera`` (Blender's own
``BKE_camera_params_from_object`` + ``compute_viewplane`` + ``compute_matrix``, the code path of
camera view at zoom factor 1 and no pan), and the engine's F12 render of the same camera.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from addon_testing import run_bpy

from compositing.io import read_image

pytestmark = [pytest.mark.blender, pytest.mark.timeout(300)]


def test_camera_view_matches_blender_and_the_viewport_frame_matches_the_render(tmp_path: Path) -> None:
    got = run_bpy(
        """
import math, sys, types
import bpy
import numpy as np
from addon import convert, engine, properties
properties.register()
engine.register()
try:
    scene = bpy.context.scene  # the start-up file: cube, light, camera
    scene.render.engine = engine.ENGINE_ID
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 96, 64, 100
    scene.render.film_transparent = True
    cam = scene.camera
    cam.data.shift_x = 0.1
    depsgraph = bpy.context.evaluated_depsgraph_get()
    blender = np.array(cam.evaluated_get(depsgraph).calc_matrix_camera(depsgraph, x=96, y=64))
    space = types.SimpleNamespace(camera=cam, lens=50.0, clip_start=0.01, clip_end=1000.0)
    region = types.SimpleNamespace(width=96, height=64)
    rv3d = types.SimpleNamespace(
        view_perspective="CAMERA", view_matrix=cam.matrix_world.inverted(), view_distance=10.0,
        view_camera_zoom=50.0 * (2.0 - math.sqrt(2.0)), view_camera_offset=(0.0, 0.0))
    camera = convert.viewport_camera(space, region, rv3d)
    full, w, h = engine.viewport_frame(depsgraph, camera, 96, 64, 1)
    reduced, rw, rh = engine.viewport_frame(depsgraph, camera, 96, 64, 4)
    np.save(sys.argv[1] + "/viewport.npy", full.reshape(h, w, 4))
    np.save(sys.argv[1] + "/reduced.npy", reduced.reshape(rh, rw, 4))
    scene.blinn_phong.samples_per_axis = 2
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"
    scene.render.filepath = sys.argv[1] + "/f12.exr"
    bpy.ops.render.render(write_still=True)
    emit({"blender": blender.tolist(), "ours": camera.projection.tolist(), "kind": camera.kind,
          "view": np.allclose(camera.view, np.linalg.inv(np.array(cam.matrix_world)), atol=1e-6),
          "sizes": [[w, h], [rw, rh]]})
finally:
    scene.render.engine = "CYCLES"
    engine.unregister()
    properties.unregister()
""",
        tmp_path,
        args=(str(tmp_path),),
    )
    # Blender computes in float32: agreement to float32 rounding of the matrix entries.
    np.testing.assert_allclose(got["ours"], got["blender"], rtol=1e-6, atol=1e-6)
    assert got["kind"] == "perspective" and got["view"]
    assert got["sizes"] == [[96, 64], [24, 16]]
    # The viewport frame (bottom row first, as textures are) equals the F12 render of that camera.
    viewport = np.load(tmp_path / "viewport.npy")[::-1]
    np.testing.assert_allclose(viewport, read_image(tmp_path / "f12.exr"), atol=1e-6)
    reduced = np.load(tmp_path / "reduced.npy")
    assert reduced.shape == (16, 24, 4) and 0.05 < reduced[..., 3].mean() < 0.95  # the cube, smaller


def test_viewport_reads_again_only_the_geometry_that_changed(tmp_path: Path) -> None:
    # depsgraph.updates (seen by a depsgraph_update_post handler, as view_update sees them): moving
    # the cube reads no geometry again, editing its mesh reads the cube only, never the plane; the
    # frame after the move equals a conversion from scratch.
    got = run_bpy(
        """
import math, sys, types
import bpy
import numpy as np
from addon import convert, engine, properties
properties.register()
engine.register()
try:
    scene = bpy.context.scene
    scene.render.engine = engine.ENGINE_ID
    scene.render.resolution_x, scene.render.resolution_y = 64, 48
    bpy.ops.mesh.primitive_plane_add(size=6.0, location=(0.0, 0.0, -1.0))
    cube, cam = bpy.data.objects["Cube"], scene.camera
    state = engine.ViewportState()
    dropped = []
    def handler(scene, depsgraph):
        dropped.append(state.apply_updates(depsgraph.updates))
    bpy.app.handlers.depsgraph_update_post.append(handler)
    reads = []
    original = convert.mesh_arrays
    def counting(mesh):
        reads.append(mesh.name)
        return original(mesh)
    convert.mesh_arrays = counting
    space = types.SimpleNamespace(camera=cam, lens=50.0, clip_start=0.01, clip_end=1000.0)
    region = types.SimpleNamespace(width=64, height=48)
    rv3d = types.SimpleNamespace(view_perspective="CAMERA", view_matrix=cam.matrix_world.inverted(),
        view_distance=10.0, view_camera_zoom=50.0 * (2.0 - math.sqrt(2.0)), view_camera_offset=(0.0, 0.0))
    def frame(use_state=True):
        depsgraph = bpy.context.evaluated_depsgraph_get()
        camera = convert.viewport_camera(space, region, rv3d)
        return engine.viewport_frame(depsgraph, camera, 64, 48, 1, state if use_state else None)[0]
    frame()
    steps = {"first": list(reads)}
    reads.clear(); dropped.clear()
    cube.location.x += 0.5
    bpy.context.view_layer.update()
    moved = frame()
    steps["move"] = (list(reads), [d for d in dropped if d])
    reads.clear(); dropped.clear()
    fresh = frame(use_state=False)
    reads.clear(); dropped.clear()
    cube.data.vertices[0].co.z += 0.5
    cube.data.update()
    bpy.context.view_layer.update()
    frame()
    steps["edit"] = (list(reads), [d for d in dropped if d])
    bpy.app.handlers.depsgraph_update_post.remove(handler)
    convert.mesh_arrays = original
    emit({"steps": steps, "same": bool(np.array_equal(moved, fresh))})
finally:
    scene.render.engine = "CYCLES"
    engine.unregister()
    properties.unregister()
""",
        tmp_path,
    )
    steps = got["steps"]
    assert sorted(steps["first"]) == ["Cube", "Plane"]
    assert steps["move"] == [[], []]
    assert steps["edit"][0] == ["Cube"] and ["Cube"] in steps["edit"][1]
    assert got["same"]  # the cached arrays are object space: a moved object is drawn where it is now

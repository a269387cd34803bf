"""Skipped shadow rays are the provably unoccluded ones: tracing only the rest changes no sample.

:mod:`blinn_phong.shadows.ray_culling` answers "lit" without Embree where a ray can reach the light by
two geometric facts (its own planar or convex mesh lies behind it; it misses every other caster's
bounding box). The reference is Embree tracing every ray: the visibilities must be equal sample for
sample (both are exact 0/1 answers for the same float32 rays), on scenes where each fact is used
and where it must not be (a torus shades itself, a mirrored sphere is not known convex, a point
light inside a sphere, scenes far from the origin where the offsets grow, float32 coordinates).
"""

import numpy as np
import pytest

from blinn_phong.frame.pipeline import _world_triangles, _world_vertices
from blinn_phong.frame.prepared import prepare_scene
from blinn_phong.geometry.raster_kernels import (
    nearest_winners_compiled,
    setup_triangles_compiled,
    winner_surfaces_compiled,
)
from blinn_phong.model.lights import PointLight
from blinn_phong.model.scene import Camera, Mesh, Scene
from blinn_phong.model.transforms import look_at
from blinn_phong.shadows.methods import light_visibility

from .volume_scenes import LIGHTS, casters, outside_camera, scene_with, sphere_mesh

pytest.importorskip("embreex")
pytest.importorskip("numba")


def _surfaces(scene: Scene, width: int = 160, height: int = 120):
    prepared = prepare_scene(scene)
    setup = setup_triangles_compiled(prepared.clip, prepared.triangles, width, height, 1, False)
    winner = nearest_winners_compiled(setup)
    verts = _world_vertices(scene)
    points, normals, _, mesh_of = winner_surfaces_compiled(
        setup, winner, prepared.triangles, np.concatenate(verts), prepared.triangle_mesh
    )
    return points, normals, mesh_of, _world_triangles(scene, verts)


def _check(scene: Scene, light) -> tuple[float, int]:
    """Assert culled == traced for ``light``; return the fraction of rays answered without Embree
    and the number answered "shadowed"."""
    from blinn_phong.shadows import raytrace
    from blinn_phong.shadows.method import ShadowFrame
    from blinn_phong.shadows.ray_culling import LIT, SHADOWED, TRACE, caster_tables
    from blinn_phong.shadows.ray_traced import _ray_answers, traced_hard

    points, normals, mesh_of, tris = _surfaces(scene)
    assert len(points) > 1000
    full = light_visibility("ray_traced", light, tris, points, normals, engine="numba")
    frame = ShadowFrame(scene, tris, points, normals, True, mesh_of)
    culled = traced_hard(frame, light, points, normals, mesh_of)
    np.testing.assert_array_equal(culled, full)
    centre = raytrace.cached_ray_scene(tris).centre
    answer = _ray_answers(light, points, normals, mesh_of, centre, caster_tables(scene, centre))
    np.testing.assert_array_equal(full[answer == LIT], 1.0)
    np.testing.assert_array_equal(full[answer == SHADOWED], 0.0)
    return float(np.mean(answer != TRACE)), int(np.sum(answer == SHADOWED))


@pytest.mark.parametrize("light_name", list(LIGHTS))
@pytest.mark.parametrize("name", ["sphere", "torus", "box", "pair"])
def test_culled_rays_equal_traced_rays(name, light_name):
    skipped, shadowed = _check(
        scene_with(casters(name), LIGHTS[light_name], outside_camera()), LIGHTS[light_name]
    )
    assert skipped > 0.3  # the ground away from the casters, the lit side of convex casters
    if name != "torus":  # convex casters: their dark side and the core of their shadow
        assert shadowed > 100


def _placed(mesh: Mesh, centre, mirror: bool = False) -> Mesh:
    transform = np.eye(4)
    transform[0, 0] = -1.0 if mirror else 1.0
    transform[:3, 3] = centre
    return Mesh(mesh.positions, mesh.triangles, mesh.normals, transform=transform, material=mesh.material)


@pytest.mark.parametrize("far", [0.0, 300.0, 3000.0])
def test_far_from_the_origin_and_mirrored(far):
    # Offsets grow with the distance from the BVH's centre; a mirror (det < 0) turns the second
    # sphere's winding inwards, so it is not known convex: its rays are all traced.
    shift = np.array([far, -far / 2, 0.0])
    ball, small = casters("pair")
    ground = scene_with([], LIGHTS["point"], outside_camera()).meshes[0]
    meshes = (
        _placed(ground, shift),
        _placed(ball, shift + np.array([0.0, 0.0, 1.2])),
        _placed(small, shift + np.array([0.55, 0.3, 1.55]), mirror=True),
    )
    view = look_at(shift + np.array([0.0, -6.0, 5.0]), shift + np.array([0.0, 0.0, 0.5]), (0, 0, 1))
    camera = Camera.perspective(40.0, 4 / 3, 0.5, 40.0, view=view)
    for light in (PointLight(tuple(shift + np.array([1.0, 0.5, 3.5]))), LIGHTS["directional"]):
        skipped, _ = _check(Scene(meshes, (light,), camera), light)
        assert skipped > 0.2


def test_point_light_inside_a_sphere_and_float32_coordinates():
    ball = sphere_mesh((0.0, 0.0, 1.2), 0.7)
    ball32 = Mesh(ball.positions.astype(np.float32).astype(np.float64), ball.triangles, ball.normals,
                  transform=ball.transform, material=ball.material)  # fmt: skip
    inside = PointLight((0.05, 0.0, 1.25))
    camera = Camera.perspective(
        50.0, 4 / 3, 0.3, 30.0, view=look_at((0.0, -4.0, 3.0), (0, 0, 0.8), (0, 0, 1))
    )
    for light in (inside, LIGHTS["spot"]):
        _check(scene_with([ball32], light, camera), light)


@pytest.mark.parametrize("light_name", list(LIGHTS))
def test_planar_shadows_by_culled_rays_equal_the_planar_method(light_name):
    # Planar shadows with every caster between the plane and the light cast the plane's shadow
    # rays against the frame's BVH; the frame answers most of them by culling. Same answers.
    from blinn_phong.shadows.method import ShadowFrame
    from blinn_phong.shadows.planar import planar_hard

    light = LIGHTS[light_name]
    scene = scene_with(casters("pair"), light, outside_camera())
    points, normals, mesh_of, tris = _surfaces(scene)
    plane = (0.0, 0.0, 1.0, 0.0)  # the ground quad of scene_with, z = 0
    got = planar_hard(ShadowFrame(scene, tris, points, normals, True, mesh_of), light, plane)
    assert got is not None
    want = light_visibility("planar", light, tris, points, normals, plane=plane)
    np.testing.assert_array_equal(got, want)
    assert 0.02 < np.mean(want == 0) < 0.5  # a real shadow on the ground
    # a caster below the plane is not between it and the light: the frame leaves it to the method
    sunk = scene_with([sphere_mesh((0.0, 0.0, -1.5), 0.7)], light, outside_camera())
    points, normals, mesh_of, tris = _surfaces(sunk)
    assert planar_hard(ShadowFrame(sunk, tris, points, normals, True, mesh_of), light, plane) is None

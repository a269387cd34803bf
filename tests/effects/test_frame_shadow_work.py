"""The frame's shadow work: fragment world points, and planar shadows answered by shadow rays.

* The world point of a fragment is its perspective-correct barycentric sum of the world-space
  corners; the reference is the other route, the interpolated eye-space point mapped back by the
  inverse view matrix (an affine map commutes with a sum whose weights add up to 1), so the two
  agree to rounding; the compiled pass equals the numpy one to rounding as well.
* ``light_visibility("planar")`` with every caster between the plane and the light casts shadow
  rays against the frame's BVH; the reference is Blinn's projection (``planar_shadow_mask``, the
  casters flattened onto the plane), which must give the same answer on the plane away from
  shadow edges.
"""

import numpy as np
import pytest

import blinn_phong as bp
from blinn_phong.frame.pipeline import _fragment_surface, _world_triangles, _world_vertices
from blinn_phong.frame.prepared import prepare_scene
from blinn_phong.frame.visibility import frame_fragments
from blinn_phong.geometry.raster import interpolate
from blinn_phong.model.lights import DirectionalLight, PointLight
from blinn_phong.model.primitives import grid_plane, uv_sphere
from blinn_phong.shadows.methods import light_visibility
from blinn_phong.shadows.planar import planar_shadow_mask

from .geometry import box_triangles, quad_triangles

pytest.importorskip("embreex")


def _scene() -> bp.Scene:
    pos, tris, normals = uv_sphere(24, 12, 0.8)
    transform = np.array([[1, 0, 0, 0.3], [0, 2, 0, 0.1], [0, 0, 1, 1.0], [0, 0, 0, 1]], float)  # scaled
    plane, ptris, pnormals = grid_plane(1, 1, (6.0, 6.0))
    view = bp.look_at((1, -5, 3), (0, 0, 0.5), (0, 0, 1))
    camera = bp.Camera.perspective(45.0, 4 / 3, 0.5, 30.0, view=view)
    return bp.Scene(
        [bp.Mesh(pos, tris, normals, transform=transform), bp.Mesh(plane, ptris, pnormals)],
        DirectionalLight((0.3, 0.2, -1.0)),
        camera,
    )


@pytest.mark.parametrize("compiled", [False, True])
def test_fragment_world_points_are_the_eye_points_mapped_back(compiled):
    if compiled:
        pytest.importorskip("numba")
    scene = _scene()
    prepared = prepare_scene(scene)
    f = frame_fragments(prepared.clip, prepared.triangles, 64, 48, engine="numpy").fragments
    assert len(f) > 500
    points, normals = _fragment_surface(prepared, f, _world_vertices(scene), compiled)
    eye = interpolate(f, prepared.triangles, prepared.eye_position)
    back = (np.c_[eye, np.ones(len(eye))] @ np.linalg.inv(scene.camera.view).T)[:, :3]
    # coordinates of size ~5; a few float64 roundings of the matrix products and sums
    np.testing.assert_allclose(points, back, rtol=0, atol=1e-12)
    # The face normal of the world corners is the model matrix's inverse transpose applied to the
    # object-space face normal, up to the determinant's sign ((Ma)×(Mb) = det M · M⁻ᵀ(a×b)): unit
    # vectors of equal direction, to a few roundings.
    expected = prepared.face_world_normal[f.triangle] * np.sign(np.linalg.det(scene.meshes[0].transform))
    np.testing.assert_allclose(normals, expected, rtol=0, atol=1e-14)
    assert points.flags.c_contiguous and normals.flags.c_contiguous
    assert _world_triangles(scene).shape == (len(prepared.triangles), 3, 3)


@pytest.mark.parametrize("cull", [False, True])
def test_winner_surfaces_are_the_fragment_surfaces(cull):
    # The opaque frame's shadow work starts from the z-buffer's winners, without fragment arrays:
    # the covered pixels in row-major order must be the compiled visibility stage's fragments (the
    # same winners, the same barycentrics: one shared helper), their world points and normals those
    # of the numpy reference (same sums in the same order; the normal's length by one einsum, so
    # a rounding or two: 1e-15 on unit vectors, 1e-14 on coordinates of size ~5).
    pytest.importorskip("numba")
    from blinn_phong.geometry.raster_kernels import (
        nearest_winners_compiled,
        setup_triangles_compiled,
        winner_surfaces_compiled,
    )

    scene = _scene()
    prepared = prepare_scene(scene)
    w, h = 64, 48
    setup = setup_triangles_compiled(prepared.clip, prepared.triangles, w, h, 1, cull)
    winner = nearest_winners_compiled(setup)
    verts = _world_vertices(scene)
    points, normals, rank, mesh = winner_surfaces_compiled(
        setup, winner, prepared.triangles, np.concatenate(verts), prepared.triangle_mesh
    )
    visible = frame_fragments(prepared.clip, prepared.triangles, w, h, cull_backfaces=cull, engine="numpy")
    f = visible.fragments
    assert len(f) > 500 and len(points) == len(f)
    np.testing.assert_array_equal(f.pixel, np.flatnonzero(rank >= 0))  # row-major, one per pixel
    np.testing.assert_array_equal(rank[f.pixel], np.arange(len(f)))
    np.testing.assert_array_equal(mesh, prepared.triangle_mesh[f.triangle])
    ref_points, ref_normals = _fragment_surface(prepared, f, verts, False)
    np.testing.assert_allclose(points, ref_points, rtol=0, atol=1e-14)
    np.testing.assert_allclose(normals, ref_normals, rtol=0, atol=1e-15)


@pytest.mark.parametrize("light", [DirectionalLight((0.4, -0.3, -1.0)), PointLight((0.5, 0.5, 4.0))])
def test_planar_by_shadow_rays_equals_the_projection(light):
    ground = quad_triangles(np.array([-4.0, -4.0, 0.0]), np.array([8.0, 0, 0]), np.array([0, 8.0, 0]))
    box = box_triangles((-0.5, -0.5, 0.5), (0.5, 0.5, 1.2))
    tris = np.concatenate([ground, box])
    rng = np.random.default_rng(2)
    p = np.column_stack([rng.uniform(-3.5, 3.5, 4000), rng.uniform(-3.5, 3.5, 4000), np.zeros(4000)])
    n = np.tile([0.0, 0.0, 1.0], (len(p), 1))
    plane = (0.0, 0.0, 1.0, 0.0)
    got = light_visibility("planar", light, tris, p, n, plane=plane)  # casters between: shadow rays
    if isinstance(light, DirectionalLight):
        homogeneous = np.r_[-np.asarray(light.direction), 0.0]
    else:
        homogeneous = np.r_[np.asarray(light.position), 1.0]
    reference = planar_shadow_mask(box, plane, homogeneous, p)  # Blinn's projection
    assert np.count_nonzero(reference == 0) > 50  # a real shadow on the sample
    # away from the shadow's edges the two classify every point alike; at most a few points whose
    # ray grazes a box edge (float32 Embree) may differ
    assert np.count_nonzero(got != reference) <= 4


def test_world_geometry_is_cached_per_scene_geometry_and_read_only():
    # A static scene rendered again reuses its world vertices and caster triangles (and so the
    # ray tracer's hash of them); another transform is another geometry.
    import dataclasses

    from blinn_phong.shadows.raytrace import world_triangles

    scene = _scene()
    tris = _world_triangles(scene)
    assert tris is _world_triangles(scene) and not tris.flags.writeable
    np.testing.assert_array_equal(tris, world_triangles(scene)[0])
    moved = dataclasses.replace(
        scene.meshes[0], transform=scene.meshes[0].transform @ np.diag([1, 1, 2.0, 1])
    )
    other = dataclasses.replace(scene, meshes=(moved, *scene.meshes[1:]))
    np.testing.assert_array_equal(_world_triangles(other), world_triangles(other)[0])
    assert not np.array_equal(_world_triangles(other), tris)
    with pytest.raises(ValueError):
        _world_vertices(scene)[0][0, 0] = 1.0

"""Ray-traced shadows (Embree) against analytic shadows of a box, a sphere and a straight edge."""

import numpy as np
import pytest

from blinn_phong.shadows.raytrace import (
    RayScene,
    area_light_visibility,
    directional_light_visibility,
    point_light_visibility,
)

from .geometry import (
    box_triangles,
    ground_points,
    quad_triangles,
    ray_box_distance,
    ray_sphere_distance,
    uv_sphere_triangles,
)

GROUND = quad_triangles(np.array([-10.0, -10.0, 0.0]), np.array([20.0, 0, 0]), np.array([0, 20.0, 0]))


def test_hard_shadow_of_a_box_matches_the_analytic_slab_test():
    lo, hi = (-0.5, -1.0, 0.5), (0.5, 1.0, 1.5)
    scene = RayScene(np.concatenate([GROUND, box_triangles(lo, hi)]))
    to_light = np.array([0.6, -0.3, 1.0])
    p, n = ground_points(20000)
    vis = directional_light_visibility(scene, p, n, to_light)
    margin = ray_box_distance(p, to_light / np.linalg.norm(to_light), lo, hi)
    clear = np.abs(margin) > 1e-4
    shadowed = margin > 0
    assert shadowed[clear].sum() > 1000 and (~shadowed[clear]).sum() > 1000
    np.testing.assert_array_equal(vis[clear], np.where(shadowed[clear], 0.0, 1.0))
    assert (~clear).sum() < 10


def test_hard_shadow_of_a_sphere_lies_between_its_inscribed_and_true_sphere():
    centre, radius = np.array([0.0, 0.0, 1.5]), 1.0
    tris = uv_sphere_triangles(tuple(centre), radius, 96, 48)
    # The tessellated sphere contains the sphere of radius = smallest face-plane distance.
    normals = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    r_in = np.min(np.einsum("ij,ij->i", normals, tris[:, 0] - centre))
    assert 0.99 * radius < r_in < radius
    scene = RayScene(np.concatenate([GROUND, tris]))
    to_light = np.array([-0.4, 0.2, 1.0])
    p, n = ground_points(20000)
    vis = directional_light_visibility(scene, p, n, to_light)
    dist = ray_sphere_distance(p, to_light, centre)
    assert np.all(vis[dist < r_in - 1e-4] == 0.0)
    assert np.all(vis[dist > radius + 1e-4] == 1.0)
    # The shadow of a sphere under a light at angle θ from the ground normal is an ellipse
    # of area π r² / cos θ.
    cos_theta = to_light[2] / np.linalg.norm(to_light)
    area = (1.0 - vis).mean() * 64.0
    assert area == pytest.approx(np.pi * radius**2 / cos_theta, rel=0.05)


def test_point_light_shadow_of_a_box_matches_the_slab_test_towards_the_light():
    lo, hi = (-0.5, -0.5, 1.0), (0.5, 0.5, 1.2)
    light = np.array([0.3, 0.2, 3.0])
    scene = RayScene(np.concatenate([GROUND, box_triangles(lo, hi)]))
    p, n = ground_points(10000, extent=3.0)
    vis = point_light_visibility(scene, p, n, light)
    d = light - p
    margin = ray_box_distance(p, d / np.linalg.norm(d, axis=1, keepdims=True), lo, hi)
    clear = np.abs(margin) > 1e-4
    np.testing.assert_array_equal(vis[clear], np.where(margin[clear] > 0, 0.0, 1.0))
    # the shadow of the 1 × 1 top face, projected from height 3 through height 1.2: scale 3/1.8
    assert (1.0 - vis).mean() * 36.0 == pytest.approx((3.0 / 1.8) ** 2, rel=0.05)


def test_point_light_between_surface_and_occluder_casts_no_shadow():
    scene = RayScene(np.concatenate([GROUND, box_triangles((-1, -1, 2.0), (1, 1, 2.5))]))
    p, n = ground_points(100, extent=0.5)
    assert np.all(point_light_visibility(scene, p, n, (0.0, 0.0, 1.0)) == 1.0)


@pytest.mark.parametrize("m", [4, 8])
def test_soft_shadow_of_a_straight_edge_is_the_linear_penumbra(m):
    # Square light of width W at height H, an occluding plate covering x < 0 at height h.
    # A ground point at x sees the light where the ray crosses height h at x ≥ 0, i.e. for
    # light x-coordinates lx ≥ x(1 − H/h): visible fraction clamp((W/2 − x(1 − H/h))/W, 0, 1).
    W, H, h = 2.0, 4.0, 2.0
    plate = quad_triangles(np.array([-50.0, -50.0, h]), np.array([50.0, 0, 0]), np.array([0, 100.0, 0]))
    scene = RayScene(np.concatenate([GROUND, plate]))
    x = np.linspace(-1.5, 1.5, 301)
    p = np.column_stack([x, np.zeros_like(x), np.zeros_like(x)])
    n = np.tile([0.0, 0.0, 1.0], (len(x), 1))
    vis = area_light_visibility(
        scene, p, n, (-W / 2, -W / 2, H), (W, 0, 0), (0, W, 0), samples_per_axis=m, seed=3
    )
    exact = np.clip((W / 2 - x * (1 - H / h)) / W, 0.0, 1.0)
    assert np.max(np.abs(vis - exact)) <= 1.0 / m + 1e-12
    # umbra and fully lit regions are exact
    np.testing.assert_array_equal(vis[exact == 0.0], 0.0)
    np.testing.assert_array_equal(vis[exact == 1.0], 1.0)
    penumbra = (exact > 0) & (exact < 1)
    assert np.all((vis[penumbra] > 0) | (exact[penumbra] < 1.0 / m))


def test_scene_rejects_bad_triangles():
    with pytest.raises(ValueError, match="triangles"):
        RayScene(np.zeros((4, 3)))
    with pytest.raises(ValueError, match="samples_per_axis"):
        area_light_visibility(
            RayScene(GROUND),
            np.zeros((1, 3)),
            np.array([[0, 0, 1.0]]),
            (0, 0, 1),
            (1, 0, 0),
            (0, 1, 0),
            samples_per_axis=0,
        )


def test_the_frame_hashes_its_casters_once_and_an_edited_array_gets_a_new_bvh(monkeypatch):
    import hashlib

    from blinn_phong.shadows import raytrace

    tris = np.concatenate([GROUND, box_triangles((-0.5, -0.5, 0.5), (0.5, 0.5, 1.5))])
    calls = []
    sha1 = hashlib.sha1
    monkeypatch.setattr(raytrace.hashlib, "sha1", lambda data: calls.append(1) or sha1(data))
    with raytrace.frame_triangles(tris):
        first = raytrace.cached_ray_scene(tris)
        assert raytrace.cached_ray_scene(tris) is first
    assert len(calls) == 1  # once for the block, not per light
    assert raytrace.cached_ray_scene(tris) is first  # outside: hashed again, same content
    tris[0, 0, 0] += 1.0
    assert raytrace.cached_ray_scene(tris) is not first  # outside a block, edits are seen
    assert len(calls) == 3

"""Shadow maps against the analytic shadow of a box; acne, peter-panning, PCF; planar fake shadows."""

import itertools

import numpy as np
import pytest

from blinn_phong.model.lights import DirectionalLight, PointLight, SpotLight
from blinn_phong.shadows.maps import PCF_KERNELS, light_shadow_maps, shadow_map_visibility
from blinn_phong.shadows.planar import planar_shadow_mask, planar_shadow_matrix
from blinn_phong.shadows.raytrace import RayScene, directional_light_visibility

from .geometry import box_triangles, ground_points, quad_triangles, ray_box_distance

GROUND = quad_triangles(np.array([-4.0, -4.0, 0.0]), np.array([8.0, 0, 0]), np.array([0, 8.0, 0]))
BOX_LO, BOX_HI = (-0.5, -0.5, 0.0), (0.5, 0.5, 1.0)
SCENE = np.concatenate([GROUND, box_triangles(BOX_LO, BOX_HI)])
LIGHTS = {
    "directional": DirectionalLight((-0.5, -0.3, -1.0)),
    "spot": SpotLight((1.0, 0.5, 3.0), (-0.3, -0.15, -1.0), 60.0),
    "point": PointLight((1.0, 0.5, 3.0)),
}


def receivers(n=20000):
    """Ground points outside the box's footprint (z = 0, normal +z)."""
    p, nrm = ground_points(n, extent=3.5, seed=7)
    keep = ~((np.abs(p[:, 0]) <= 0.5) & (np.abs(p[:, 1]) <= 0.5))
    return p[keep], nrm[keep]


def analytic_visibility(light, p):
    """1 where the segment/ray from p towards the light misses the box (slab test), else 0."""
    if isinstance(light, DirectionalLight):
        d = np.broadcast_to(-np.asarray(light.direction), p.shape)
        margin = ray_box_distance(p, d[0], BOX_LO, BOX_HI)
    else:
        d = np.asarray(light.position) - p
        d = d / np.linalg.norm(d, axis=1, keepdims=True)
        margin = np.array([ray_box_distance(p[i : i + 1], d[i], BOX_LO, BOX_HI)[0] for i in range(len(p))])
    return np.where(margin > 0, 0.0, 1.0)


@pytest.mark.parametrize("kind", list(LIGHTS))
def test_shadow_maps_converge_to_the_analytic_shadow(kind):
    light = LIGHTS[kind]
    p, n = receivers(6000)
    exact = analytic_visibility(light, p)
    assert 0.01 < 1 - exact.mean() < 0.2
    errors = []
    for res in (64, 128, 256, 512):
        maps = light_shadow_maps(light, SCENE, res, constant_bias=1e-4, slope_bias=2.0)
        errors.append(np.mean(shadow_map_visibility(light, maps, p, n) != exact))
    # edge error ≈ one texel footprint: halves (roughly) with each doubling of resolution
    assert errors[-1] < errors[0] / 4
    assert errors[-1] < 2e-3
    assert all(b <= a for a, b in itertools.pairwise(errors))


@pytest.mark.parametrize("kind", list(LIGHTS))
def test_acne_without_bias_and_its_cure(kind):
    light = LIGHTS[kind]
    p, n = receivers(6000)
    exact = analytic_visibility(light, p)
    lit = exact == 1
    maps = light_shadow_maps(light, SCENE, 256)
    acne = np.mean(shadow_map_visibility(light, maps, p, n)[lit] < 1)
    assert acne > 0.1  # the lit ground shadows itself in a large fraction of its points
    biased = light_shadow_maps(light, SCENE, 256, constant_bias=1e-4, slope_bias=2.0)
    assert np.mean(shadow_map_visibility(light, biased, p, n)[lit] < 1) < 2e-3


def test_normal_offset_also_removes_acne():
    light = LIGHTS["directional"]
    p, n = receivers(6000)
    lit = analytic_visibility(light, p) == 1
    maps = light_shadow_maps(light, SCENE, 256)
    texel = 2 * np.linalg.norm(np.array([4.0, 4.0, 1.0])) / 256  # ortho width / resolution
    vis = shadow_map_visibility(light, maps, p, n, normal_offset=2 * texel)
    assert np.mean(vis[lit] < 1) < 2e-3


def test_too_much_bias_detaches_the_shadow_from_its_caster():
    # A thin wall standing on the ground, 2 high, lit from +x: its shadow runs from the
    # wall's foot to x = −0.05 − 2·0.5 = −1.05 (light direction (−0.5, 0, −1)).
    wall = np.concatenate([GROUND, box_triangles((-0.05, -1.0, 0.0), (0.05, 1.0, 2.0))])
    light = DirectionalLight((-0.5, 0.0, -1.0))
    x = np.linspace(-1.5, -0.06, 400)
    p = np.column_stack([x, np.zeros_like(x), np.zeros_like(x)])
    n = np.tile([0.0, 0.0, 1.0], (len(x), 1))
    exact = np.where(x > -1.05, 0.0, 1.0)
    good = shadow_map_visibility(
        light, light_shadow_maps(light, wall, 512, constant_bias=1e-4, slope_bias=2.0), p, n
    )
    texel = 2 * np.linalg.norm([4.0, 4.0, 1.0]) / 512 * np.hypot(1, 0.5)  # along the ground
    clear = np.abs(x + 1.05) > 2 * texel
    np.testing.assert_array_equal(good[clear], exact[clear])
    # A bias of 0.05 window-depth units is 0.05·(depth range 3·radius) ≈ 0.86 world units along
    # the light ray, i.e. 0.86·sin(atan(0.5)) ≈ 0.385 along the ground: the shadow must start
    # that far from the wall's foot (peter-panning) and still end at x = −1.05.
    radius = np.linalg.norm([8.0, 8.0, 2.0]) / 2
    gap = 0.05 * 3 * radius * np.sin(np.arctan(0.5))
    too_much = shadow_map_visibility(
        light, light_shadow_maps(light, wall, 512, constant_bias=0.05, slope_bias=2.0), p, n
    )
    lit_by_gap = (x > -0.05 - gap + 0.1 + 2 * texel) & (x < -0.06)
    still_dark = (x < -0.05 - gap - 0.1 - 2 * texel) & (x > -1.05 + 2 * texel)
    assert lit_by_gap.sum() > 20 and still_dark.sum() > 100
    assert np.all(too_much[lit_by_gap] == 1)
    assert np.all(too_much[still_dark] == 0)


@pytest.mark.parametrize("kernel", PCF_KERNELS)
def test_pcf_kernels_soften_only_the_shadow_edge_and_converge(kernel):
    light = LIGHTS["directional"]
    p, n = receivers(8000)
    exact = analytic_visibility(light, p)
    errs = []
    # a tap h texels away in x and y meets the receiver's own depth up to 2·h·slope away:
    # wider kernels need a proportionally larger slope bias
    h = {"nearest": 0.5, "bilinear": 1.0}.get(kernel) or (int(kernel[3:]) - 1) / 2
    for res in (128, 512):
        maps = light_shadow_maps(light, SCENE, res, constant_bias=1e-4, slope_bias=1.0 + 2.0 * h)
        vis = shadow_map_visibility(light, maps, p, n, kernel=kernel)
        assert np.all((vis >= 0) & (vis <= 1))
        errs.append(np.mean(np.abs(vis - exact)))
        fractional = (vis > 0) & (vis < 1)
        if kernel == "nearest":
            assert not fractional.any()
        else:
            assert fractional.any()
        # far from the box (well outside any shadow) every kernel reports fully lit
        far = np.max(np.abs(p[:, :2]), axis=1) > 3.0
        far &= p[:, 0] > 0  # the shadow falls towards −x
        assert np.all(vis[far] == 1)
    assert errs[1] < errs[0] / 2


def test_shadow_maps_agree_with_embree_on_a_sphere():
    # A second, independent path: the ray-traced reference on a curved caster.
    from .geometry import uv_sphere_triangles

    tris = np.concatenate([GROUND, uv_sphere_triangles((0, 0, 1.2), 0.7, 48, 24)])
    light = DirectionalLight((0.4, -0.2, -1.0))
    p, n = ground_points(6000, extent=3.5, seed=11)
    ref = directional_light_visibility(RayScene(tris), p, n, -np.asarray(light.direction))
    vis = shadow_map_visibility(
        light, light_shadow_maps(light, tris, 512, constant_bias=1e-4, slope_bias=2.0), p, n
    )
    assert np.mean(vis != ref) < 3e-3


def test_planar_shadow_matrix_projects_along_the_light_onto_the_plane():
    plane = np.array([0.0, 0.0, 1.0, 0.0])
    rng = np.random.default_rng(5)
    pts = rng.uniform(-1, 1, (50, 3)) + np.array([0.0, 0.0, 2.0])
    for light in (np.array([0.5, 0.2, 5.0, 1.0]), np.array([0.3, -0.4, 1.0, 0.0])):
        m = planar_shadow_matrix(plane, light)
        h = np.c_[pts, np.ones(50)] @ m.T
        q = h[:, :3] / h[:, 3:]
        np.testing.assert_allclose(q[:, 2], 0.0, atol=1e-12)  # on the plane
        d = light[:3] - light[3] * pts  # direction from the point towards the light
        # q − p is parallel to the light direction: cross product zero
        np.testing.assert_allclose(np.cross(q - pts, d), 0.0, atol=1e-12)


def test_fake_shadows_match_ray_traced_shadows_on_their_plane_only():
    light_dir = np.array([0.5, 0.3, 1.0])  # towards the light
    p, _ = receivers(20000)
    box = box_triangles(BOX_LO, BOX_HI)
    fake = planar_shadow_mask(box, (0, 0, 1, 0), np.r_[light_dir, 0.0], p)
    exact = analytic_visibility(DirectionalLight(-light_dir), p)
    margin = ray_box_distance(p, light_dir / np.linalg.norm(light_dir), BOX_LO, BOX_HI)
    clear = np.abs(margin) > 1e-6
    np.testing.assert_array_equal(fake[clear], exact[clear])
    # the known failure: a caster below the plane still casts a fake shadow
    below = box_triangles((-0.5, -0.5, -2.0), (0.5, 0.5, -1.0))
    assert np.any(planar_shadow_mask(below, (0, 0, 1, 0), np.r_[light_dir, 0.0], p) == 0)

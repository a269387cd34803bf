"""The planner's rigorous bounds: the light factor ``att·spot`` over a mesh, and fog's factor range.

Each bound is checked against an independent evaluation: the lighting equation's own
``att·spot`` (:func:`blinn_phong.frame.lighting._light_direction`, OpenGL 2.1 §2.14.1) at points
sampled on every triangle, the fog formulas of OpenGL 2.1 §3.10 written out here, distances
from closed forms and dense sampling, and rendered images.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from blinn_phong.frame.lighting import _light_direction, lights_in_eye_space
from blinn_phong.frame.render import render
from blinn_phong.geometry.mesh_facts import _mesh_facts, nearest_triangle_distance, point_triangle_distances
from blinn_phong.model.lights import DirectionalLight, PointLight, SpotLight
from blinn_phong.model.primitives import uv_sphere
from blinn_phong.model.scene import Material, Mesh
from blinn_phong.planning.bounds import (
    _fog_range,
    _light_factor_bound,
    _light_factors,
    _shadow_weight,
)
from blinn_phong.planning.frame_plan import Fog
from blinn_phong.planning.planner import plan
from testbeds.planner_fuzz import random_scene
from tests.effects.scenes import flat_cube, horizontal_quad, ortho_camera, perspective_camera, quad, scene_of


def _on_triangles(tris: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """The corners of every triangle and ``n`` uniform random points on each, (T·(n + 3), 3)."""
    u, v = rng.random((2, len(tris), n))
    flip = u + v > 1
    u, v = np.where(flip, 1 - u, u), np.where(flip, 1 - v, v)
    a, b, c = tris[:, 0:1], tris[:, 1:2], tris[:, 2:3]
    inner = a + u[..., None] * (b - a) + v[..., None] * (c - a)
    return np.concatenate([tris.reshape(-1, 3), inner.reshape(-1, 3)])


def _att_spot(eye_lights, r: int, eye: np.ndarray) -> np.ndarray:
    """att·spot of eye-space light ``r`` at eye-space points (the lighting equation's own factors)."""
    return _light_direction(
        eye[:, 0],
        eye[:, 1],
        eye[:, 2],
        eye_lights.position[r],
        eye_lights.spot_direction[r],
        eye_lights.cos_cutoff[r],
        eye_lights.spot_exponent[r],
        eye_lights.attenuation[r],
    )[3]


def _old_bound(light, facts) -> float:
    """The former bound: attenuation at the distance to the nearest mesh's world bounding box, spot ≤ 1."""
    pos = np.asarray(light.position, float)
    d = min(
        float(np.linalg.norm(np.maximum(np.maximum(f.world.min(0) - pos, pos - f.world.max(0)), 0.0)))
        for f in facts
    )
    return 1.0 / (light.constant + light.linear * d + light.quadratic * d * d)


# --------------------------------------------------------------------------- distances


def test_triangle_distance_matches_closed_forms_and_dense_sampling():
    tri = np.array([[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]])
    assert point_triangle_distances(tri, np.array([0.2, 0.2, 3.0]))[0] == pytest.approx(3.0)  # above the face
    vertex = point_triangle_distances(tri, np.array([-1.0, -1.0, 0.0]))[0]
    assert vertex == pytest.approx(math.sqrt(2))
    assert point_triangle_distances(tri, np.array([0.5, -2.0, 1.0]))[0] == pytest.approx(math.sqrt(5))  # edge
    assert point_triangle_distances(tri, np.array([1.0, 1.0, 0.0]))[0] == pytest.approx(
        math.sqrt(0.5)
    )  # hypotenuse
    rng = np.random.default_rng(3)
    tris = rng.normal(size=(30, 3, 3))
    n = 80
    i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
    keep = i + j <= n
    u, v = i[keep] / n, j[keep] / n
    grid = tris[:, None, 0] + u[None, :, None] * (tris[:, None, 1] - tris[:, None, 0])
    grid = grid + v[None, :, None] * (tris[:, None, 2] - tris[:, None, 0])
    longest = np.max(np.linalg.norm(tris - np.roll(tris, 1, axis=1), axis=2), axis=1)
    for p in rng.normal(size=(8, 3)) * 2:
        exact = point_triangle_distances(tris, p)
        sampled = np.linalg.norm(grid - p, axis=2).min(axis=1)
        assert np.all(exact <= sampled + 1e-12)  # a distance to a point of the triangle
        assert np.all(sampled <= exact + longest / n)  # the nearest grid point is within one cell


def test_nearest_triangle_distance_is_the_smallest_exact_distance():
    # the bounding-ball pruning keeps the minimum to the bit: same triangles, same arithmetic
    rng = np.random.default_rng(11)
    positions, triangles, _ = uv_sphere(48, 24)
    sphere = positions[triangles]
    sizes = rng.uniform(0.01, 2.0, size=(500, 1, 1))
    soup = rng.normal(size=(500, 3, 3)) * sizes + rng.normal(size=(500, 1, 3)) * 4
    for tris in (sphere, soup, sphere[:1], np.concatenate([sphere, sphere + 3.0])):
        for p in [*rng.normal(size=(20, 3)) * 3, tris[0, 0], tris.mean(axis=(0, 1))]:
            assert nearest_triangle_distance(tris, p) == point_triangle_distances(tris, p).min()
    assert nearest_triangle_distance(np.zeros((0, 3, 3)), np.zeros(3)) == math.inf
    # a non-finite point: every triangle taken, as the full minimum gives it
    assert math.isnan(nearest_triangle_distance(sphere, np.array([np.nan, 0.0, 0.0])))


# --------------------------------------------------------------------------- att·spot


def _positional_scenes(count: int):
    found = []
    seed = 0
    while len(found) < count:
        scene = random_scene(seed)
        if any(isinstance(light, PointLight | SpotLight) for light in scene.lights):
            found.append(scene)
        seed += 1
    return found


@pytest.mark.parametrize("scene", _positional_scenes(8), ids=lambda s: f"{len(s.meshes)}meshes")
def test_the_light_factor_bounds_att_spot_at_every_point_of_each_mesh(scene):
    rng = np.random.default_rng(len(scene.meshes))
    facts = [_mesh_facts(m) for m in scene.meshes]
    factors = _light_factors(scene, facts)
    view = scene.camera.view
    eye_lights = lights_in_eye_space(scene.lights, view)
    for i, f in enumerate(facts):
        eye = _on_triangles(f.tris, 200, rng) @ view[:3, :3].T + view[:3, 3]
        for r, j in enumerate(eye_lights.source):
            att = _att_spot(eye_lights, r, eye)
            assert float(np.max(att)) <= factors[i, j] * (1 + 1e-9) + 1e-12, (i, j, scene.lights[j])


def test_the_bound_is_the_attenuation_at_the_nearest_point_and_tighter_than_the_bounding_box():
    # a long thin slab turned 45° about z: the light sits inside its bounding box but 0.6 from it
    slab = flat_cube((0.0, 0.0, 0.0), 1.0, transform=np.diag([2.0, 0.05, 0.05, 1.0]))
    turn = np.eye(4)
    c = s = math.sqrt(0.5)
    turn[:2, :2] = [[c, -s], [s, c]]
    slab = Mesh(slab.positions, slab.triangles, slab.normals, transform=turn @ slab.transform)
    light = PointLight((0.6 * c + 0.6, 0.6 * s - 0.6, 0.0), constant=0.01, quadratic=1.0)  # off the long side
    scene = scene_of([slab], [light])
    facts = [_mesh_facts(slab)]
    new = _light_factor_bound(light, facts, scene.camera.view)
    old = _old_bound(light, facts)
    assert old == pytest.approx(100.0)  # inside the bounding box: d = 0, att = 1/k_c
    # the nearest point is on the slab's side face 0.05 from its axis: d = |offset| − 0.05
    offset = np.array([0.6 * c + 0.6, 0.6 * s - 0.6]) @ np.array([-s, c])
    d = abs(offset) - 0.05
    assert new == pytest.approx(1.0 / (0.01 + d * d))
    assert new < old / 10


def test_a_spot_cone_that_misses_a_mesh_bounds_its_factor_by_zero_and_narrows_it_otherwise():
    floor = horizontal_quad(0.0, half=1.0)
    away = SpotLight((0.0, 0.0, 2.0), (0.0, 0.0, 1.0), 30.0, 2.0, constant=0.5)  # pointing up
    facts = [_mesh_facts(floor)]
    assert _light_factor_bound(away, facts) == 0.0
    assert _old_bound(away, facts) == pytest.approx(2.0)
    # aimed at a point 3 to the side: the cone's nearest angle to the quad is atan(2/2) − asin(ρ/D)
    aside = SpotLight((0.0, 0.0, 2.0), (3.0, 0.0, -2.0), 40.0, 4.0, constant=1.0)
    bound = _light_factor_bound(aside, facts)
    assert 0.0 < bound < 1.0
    eye = _on_triangles(facts[0].tris, 4000, np.random.default_rng(0))
    to = eye - np.asarray(aside.position)
    cos = (to @ np.asarray(aside.direction)) / np.linalg.norm(to, axis=1)
    att = 1.0 / (aside.constant + 0.0)
    exact = np.where(cos >= math.cos(math.radians(40.0)), np.maximum(cos, 0) ** 4.0, 0.0) * att
    assert exact.max() <= bound


# --------------------------------------------------------------------------- fog


def _gl_fog(c: float, mode: str, density: float = 1.0, start: float = 0.0, end: float = 1.0) -> float:
    """OpenGL 2.1 §3.10, clamped to [0, 1]."""
    if mode == "linear":
        f = (end - c) / (end - start)
    elif mode == "exp":
        f = math.exp(-density * c)
    else:
        f = math.exp(-((density * c) ** 2))
    return min(max(f, 0.0), 1.0)


@pytest.mark.parametrize(
    "fog",
    [
        Fog("exp", density=0.15),
        Fog("exp2", density=0.1),
        Fog("linear", start=5.0, end=12.0),
        Fog("linear", start=12.0, end=5.0),  # fog that thins with distance
        Fog("exp", density=0.15, distance="radial"),
    ],
    ids=lambda f: f"{f.mode}-{f.start}-{f.end}-{f.distance}",
)
def test_the_fog_range_of_a_mesh_is_the_closed_form_at_its_nearest_and_farthest_points(fog):
    # a quad tilted along x, z = 1.5 + 1.5·x over [−1, 1]², seen from (0, 0, 10) looking down
    tilted = quad([[-1, -1, 0.0], [1, -1, 3.0], [1, 1, 3.0], [-1, 1, 0.0]])
    scene = scene_of([tilted], [DirectionalLight((0, 0, -1))], ortho_camera())
    got = _fog_range(scene, [_mesh_facts(tilted)], fog)
    if fog.distance == "plane":
        near, far = 7.0, 10.0  # |z_eye| of the top and bottom edges
    else:
        near, far = math.sqrt(50.0), math.sqrt(102.0)  # nearest at (1, 0, 3), farthest at (−1, ±1, 0)
    ends = [_gl_fog(c, fog.mode, fog.density, fog.start, fog.end) for c in (near, far)]
    assert got.low[0] == pytest.approx(min(ends), rel=1e-12)
    assert got.high[0] == pytest.approx(max(ends), rel=1e-12)


def test_fog_scales_the_shadow_bound_and_the_rendered_shadow_stays_within_it():
    floor = horizontal_quad(0.0, half=3.0, colour=(0.9, 0.9, 0.9))
    cube = flat_cube((0.0, 0.0, 0.6), 0.4)
    sun = DirectionalLight((0.3, 0.2, -1.0))
    scene = scene_of([floor, cube], [sun], perspective_camera())
    fog = Fog("exp", (0.0, 0.0, 0.0), density=0.12)
    facts = [_mesh_facts(m) for m in scene.meshes]
    factors = _light_factors(scene, facts)
    plain = _shadow_weight(scene, sun, facts, factors, None, 0)
    fogged_range = _fog_range(scene, facts, fog)
    fogged = _shadow_weight(scene, sun, facts, factors, fogged_range, 0)
    # the largest fog factor is at the nearest eye depth of any mesh: exp(−density·|z|min)
    eye_z = [
        np.abs(f.world @ scene.camera.view[:3, :3].T + scene.camera.view[:3, 3])[:, 2].min() for f in facts
    ]
    peaks = [
        float(
            np.max(
                np.multiply(m.material.diffuse, sun.diffuse) + np.multiply(m.material.specular, sun.specular)
            )
        )
        for m in scene.meshes
    ]
    assert plain == pytest.approx(max(peaks))
    assert fogged == pytest.approx(max(math.exp(-0.12 * z) * w for z, w in zip(eye_z, peaks, strict=True)))
    lit = render(scene, 48, 48, shadows="none", fog=fog).rgba.astype(np.float64)
    shadowed = render(scene, 48, 48, shadows="ray_traced", fog=fog).rgba.astype(np.float64)
    change = 255 * np.abs(lit - shadowed).max()
    assert 0 < change <= 255 * fogged + 1e-3
    # and the plan states the fog, with the same range
    p = plan(scene, 8.0, width=48, height=48, fog=fog)
    assert p.fog is not None and p.fog.method == "exp"
    assert f"[{fogged_range.low.min():.3g}, {fogged_range.high.max():.3g}]" in p.fog.reason


def test_fog_bounds_the_colour_behind_peeled_layers_by_its_closed_form():
    from blinn_phong.planning.bounds import _fogged_radiance_bound, _max_radiance

    glow = Material(emission=(1.5, 1.5, 1.5), diffuse=(0.2, 0.2, 0.2), specular=(0, 0, 0), opacity=0.5)
    panes = [
        Mesh(m.positions, m.triangles, m.normals, material=glow)
        for m in (horizontal_quad(0.0, half=1.0), horizontal_quad(0.5, half=1.0))
    ]
    scene = scene_of(panes, [DirectionalLight((0, 0, -1))])  # seen from z = 10: eye distances 10 and 9.5
    facts = [_mesh_facts(m) for m in panes]
    factors = _light_factors(scene, facts)
    b = _max_radiance(scene, panes[0], list(factors[0]))
    assert b > 1.5
    for colour, expected in (
        ((1.0, 1.0, 1.0), max(0.5 * b + 0.5, 0.525 * b + 0.475)),  # f·c + (1 − f)·1, f = (20 − z)/20
        ((0.0, 0.0, 0.0), 0.525 * b),  # black fog only scales
    ):
        fog = Fog("linear", colour, start=0.0, end=20.0)
        bound = _fogged_radiance_bound(scene, facts, factors, _fog_range(scene, facts, fog))
        assert bound == pytest.approx(max(1.0, expected))
    assert _fogged_radiance_bound(scene, facts, factors, _fog_range(scene, facts, None)) == pytest.approx(b)


@pytest.mark.parametrize("scaled_view", [False, True])
def test_big_meshes_bound_att_spot_by_their_box_and_ball_under_any_view(scaled_view):
    """Above _EXACT_DISTANCE_TRIANGLES the bounds use a box and a ball around the mesh: the facts'
    world ones under a rigid view (rotation and translation keep distances and angles), the
    eye-space vertices' otherwise. Either way att·spot at every vertex and at random points of
    every triangle stays below the bound (the lighting equation's own factors)."""
    from blinn_phong.model.primitives import uv_sphere

    pos, tris, normals = uv_sphere(160, 80, 1.0)  # 25,280 triangles: the box-and-ball path
    transform = np.eye(4)
    transform[:3, 3] = (0.3, -0.2, 0.4)
    mesh = Mesh(pos, tris, normals, transform=transform)
    camera = perspective_camera()
    if scaled_view:  # a view with a non-uniform scale: distances change, the eye-space path is used
        view = np.diag([1.0, 2.0, 0.5, 1.0]) @ camera.view
        camera = type(camera)(view=view, projection=camera.projection)
    lights = [
        PointLight((1.2, 0.9, 1.8), constant=0.01, quadratic=1.0),
        SpotLight((0.2, 0.1, 2.5), (0.0, 0.0, -1.0), cutoff=25.0, exponent=8.0, constant=0.05, quadratic=1.0),
    ]
    scene = scene_of([mesh], lights, camera)
    facts = [_mesh_facts(m) for m in scene.meshes]
    assert facts[0].n_tris > 20_000
    factors = _light_factors(scene, facts)
    view = scene.camera.view
    eye_lights = lights_in_eye_space(scene.lights, view)
    eye = _on_triangles(facts[0].tris, 4, np.random.default_rng(5)) @ view[:3, :3].T + view[:3, 3]
    for r, j in enumerate(eye_lights.source):
        top = float(np.max(_att_spot(eye_lights, r, eye)))
        assert 0 < top <= factors[0, j] * (1 + 1e-9) + 1e-12, (j, top, factors[0, j])

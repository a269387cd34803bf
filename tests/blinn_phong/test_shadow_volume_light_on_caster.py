"""A point or spot light exactly on a caster's vertex, edge or face, with ``shadows="shadow_volume"``.

The volume extruded from the silhouette through such a light is degenerate: the renderer used to
light floor pixels straight through the caster and shadow pixels nothing blocks. The frame plan
now detects the light on the surface and casts exact rays instead, saying so. The reference is an
independent float64 segment test: a floor point is lit iff the segment from it to the light meets
no caster triangle (Möller–Trumbore, the light's own triangles excluded where it touches them).
"""

from __future__ import annotations

import numpy as np
import pytest

import blinn_phong as bp
from blinn_phong.model.primitives import box, grid_plane, uv_sphere
from blinn_phong.shadows.method import embree_available

FLOOR = np.array([[1, 0, 0, 0], [0, 0, 1, 0], [0, -1, 0, 0], [0, 0, 0, 1]], float)  # z = 0 → y = 0
W, H = 96, 72


def _scene(caster: bp.Mesh, light: object) -> bp.Scene:
    fp, ft, fn = grid_plane(8, 8, size=(12.0, 12.0))
    floor = bp.Mesh(fp, ft, fn, transform=FLOOR)
    camera = bp.Camera.perspective(50, W / H, 0.1, 50, view=bp.look_at((0.5, 6.0, 5.0), (0.0, 0.0, 0.0)))
    return bp.Scene([caster, floor], [light], camera)


def _box_caster() -> bp.Mesh:
    p, t, n = box((0.5, 0.5, 0.5))
    return bp.Mesh(
        p, t, n, transform=np.array([[1, 0, 0, 0], [0, 1, 0, 1.0], [0, 0, 1, 0], [0, 0, 0, 1]], float)
    )


def _sphere_caster() -> bp.Mesh:
    p, t, n = uv_sphere(16, 8, 0.6)
    return bp.Mesh(
        p, t, n, transform=np.array([[1, 0, 0, 0], [0, 1, 0, 1.2], [0, 0, 1, 0], [0, 0, 0, 1]], float)
    )


def _world(mesh: bp.Mesh) -> np.ndarray:
    return ((np.c_[mesh.positions, np.ones(len(mesh.positions))] @ mesh.transform.T)[:, :3])[mesh.triangles]


def _equator_vertex(mesh: bp.Mesh) -> tuple[float, float, float]:
    """A vertex on the sphere's equator (the floor below it is partly lit, partly shadowed)."""
    world = (np.c_[mesh.positions, np.ones(len(mesh.positions))] @ mesh.transform.T)[:, :3]
    on_equator = np.abs(mesh.positions[:, 1]) < 1e-12
    return tuple(float(v) for v in world[np.nonzero(on_equator)[0][1]])


def _blocked(points: np.ndarray, light: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """Float64 segment test: does the open segment point → light cross a triangle's interior?"""
    d = light - points  # (N, 3); t in (eps, 1 - eps) along it
    blocked = np.zeros(len(points), bool)
    for a, b, c in tris:
        e1, e2 = b - a, c - a
        pv = np.cross(d, e2)
        det = pv @ e1
        ok = np.abs(det) > 1e-12
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        s = points - a
        u = np.einsum("ij,ij->i", s, pv) * inv
        q = np.cross(s, e1)
        v = np.einsum("ij,ij->i", d, q) * inv
        t = (q @ e2) * inv
        eps = 1e-7
        hit = ok & (u > eps) & (v > eps) & (u + v < 1 - eps) & (t > 1e-6) & (t < 1 - 1e-6)
        blocked |= hit
    return blocked


CASES = {
    "point light on a sphere vertex": lambda: (_sphere_caster(), lambda m: bp.PointLight(_equator_vertex(m))),
    "point light on a box corner": lambda: (_box_caster(), lambda m: bp.PointLight((0.5, 1.5, 0.5))),
    "point light on a box edge's midpoint": lambda: (_box_caster(), lambda m: bp.PointLight((0.0, 1.5, 0.5))),
    "spot light on a box corner": lambda: (
        _box_caster(),
        lambda m: bp.SpotLight((0.5, 1.5, 0.5), (0.3, -1.0, 0.2), 70.0, 0.0),
    ),
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_light_on_caster_shadows_exactly(name: str) -> None:
    caster, make_light = CASES[name]()
    light = make_light(caster)
    scene = _scene(caster, light)
    result = bp.render(scene, W, H, shadows="shadow_volume", progress=False)
    choice = result.plan.shadows[0]
    assert "lies on a caster's surface" in choice.reason
    assert choice.method == ("ray_traced" if embree_available() else "shadow_map")
    # Floor pixels: lit (the diffuse pass) iff the segment to the light is unblocked.
    floor_only = bp.render(
        bp.Scene([scene.meshes[1]], [light], scene.camera), W, H, shadows="none", progress=False
    )
    depth = floor_only.depth
    on_floor = (depth < 1) & (np.abs(result.depth - depth) < 1e-7)  # the floor is the nearest surface
    ys, xs = np.nonzero(on_floor)
    ndc = np.stack(
        [(xs + 0.5) / W * 2 - 1, 1 - (ys + 0.5) / H * 2, depth[ys, xs] * 2 - 1, np.ones(len(xs))], 1
    )
    world = ndc @ np.linalg.inv(scene.camera.projection @ scene.camera.view).T
    world = world[:, :3] / world[:, 3:]
    blocked = _blocked(world, np.asarray(light.position, float), _world(caster))
    lit_free = floor_only.passes["diffuse"][ys, xs].max(axis=1) > 1e-4  # the light reaches it at all
    shadowed = result.passes["diffuse"][ys, xs].max(axis=1) < 1e-6
    check = lit_free & (np.abs(world[:, 1]) < 1e-3)
    assert check.sum() > 500
    assert blocked[check].any() and (~blocked[check]).any()
    # Pixels on the shadow's edge (a 4-neighbour with the other answer in the reference) may tip
    # either way: the pixel centre lies within float rounding of a silhouette ray.
    grid = np.full((H + 2, W + 2), -1, np.int8)
    grid[ys[check] + 1, xs[check] + 1] = blocked[check]
    centre = grid[1:-1, 1:-1]
    edge = np.zeros((H, W), bool)
    for dy, dx in ((0, 1), (2, 1), (1, 0), (1, 2)):
        other = grid[dy : dy + H, dx : dx + W]
        edge |= (other >= 0) & (centre >= 0) & (other != centre)
    inner = check & ~edge[ys, xs]
    assert inner.sum() > 0.9 * check.sum()
    np.testing.assert_array_equal(shadowed[inner], blocked[inner])


def test_light_just_off_the_surface_keeps_shadow_volumes() -> None:
    caster = _box_caster()
    scene = _scene(caster, bp.PointLight((0.5, 1.5 + 1e-3, 0.5)))
    result = bp.render(scene, W, H, shadows="shadow_volume", progress=False)
    assert result.plan.shadows[0].method == "shadow_volume"

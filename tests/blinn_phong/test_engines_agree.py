"""The compiled (numba) fast path agrees with the numpy reference.

The reference itself is checked against closed forms and Mesa elsewhere; here the
two engines must produce the same visible fragments (same triangle per sample,
barycentrics and depth equal up to summation order) and the same shading to float
rounding, on scenes that exercise near-plane clipping,
interpenetrating and coplanar surfaces (depth ties), supersampling, back faces,
all shading frequencies, every light type and both specular forms.
"""

from __future__ import annotations

import numpy as np
import pytest

import blinn_phong as bp
from blinn_phong.primitives import grid_plane, uv_sphere
from blinn_phong.visibility import visible_fragments

pytest.importorskip("numba")


def busy_scene(specular: str = "blinn", two_sided: bool = True) -> bp.Scene:
    meshes = []
    rng = np.random.default_rng(11)
    for i in range(5):
        pos, tris, normals = uv_sphere(20, 10)
        t = np.eye(4)
        t[:3, :3] = np.diag(rng.uniform(0.4, 1.2, 3))
        t[:3, 3] = rng.uniform(-1.5, 1.5, 3) + np.array([0, 0, 0.5 * i])  # some cross the near plane
        mat = bp.Material(
            diffuse=rng.uniform(0, 1, 3), specular=(0.8, 0.8, 0.8), shininess=float(rng.uniform(5, 90))
        )
        meshes.append(bp.Mesh(pos, tris, normals, transform=t, material=mat, back_material=bp.Material()))
    pos, tris, normals = grid_plane(6, 6, (8, 8))
    floor = np.array([[1, 0, 0, 0], [0, 0, 1, -1], [0, -1, 0, 0], [0, 0, 0, 1]], float)
    meshes.append(bp.Mesh(pos, tris, normals, transform=floor))
    meshes.append(bp.Mesh(pos, tris, normals, transform=floor))  # coplanar duplicate: exact depth ties
    lights = [
        bp.DirectionalLight((-1, -1, -1), ambient=(0.05, 0.05, 0.05)),
        bp.PointLight((2, 2, 2), linear=0.2, quadratic=0.05),
        bp.SpotLight((0, 4, 1), (0, -1, -0.2), 40, 8, quadratic=0.05),
        bp.AmbientLight((0.1, 0.1, 0.1)),
    ]
    cam = bp.Camera.perspective(60, 4 / 3, 0.5, 30, view=bp.look_at((0.3, 0.8, 3.0), (0, 0, 0)))
    return bp.Scene(meshes, lights, cam, light_model=bp.LightModel(specular=specular, two_sided=two_sided))


@pytest.mark.parametrize("samples", [1, 4])
def test_visible_fragments_are_identical(samples: int) -> None:
    prepared = bp.prepare_scene(busy_scene())
    ref = visible_fragments(prepared.clip, prepared.triangles, 96, 72, samples=samples, engine="numpy")
    fast = visible_fragments(prepared.clip, prepared.triangles, 96, 72, samples=samples, engine="numba")
    assert len(ref) > 0.5 * 96 * 72 * samples
    near_side = (prepared.clip[:, 2] + prepared.clip[:, 3] >= 0)[prepared.triangles].sum(axis=1)
    assert ((near_side == 1) | (near_side == 2)).any()  # near-plane clipping is exercised
    np.testing.assert_array_equal(fast.sample_key, ref.sample_key)
    np.testing.assert_array_equal(fast.triangle, ref.triangle)
    np.testing.assert_allclose(fast.depth, ref.depth, rtol=0, atol=1e-15)  # summation order only
    np.testing.assert_allclose(fast.bary, ref.bary, rtol=0, atol=1e-12)


@pytest.mark.parametrize("shading", ["flat", "gouraud", "phong"])
@pytest.mark.parametrize("specular", ["blinn", "phong"])
def test_renders_agree(shading: str, specular: str) -> None:
    scene = busy_scene(specular)
    ref = bp.render(scene, 80, 60, shading=shading, samples=4, engine="numpy")
    fast = bp.render(scene, 80, 60, shading=shading, samples=4, engine="numba")
    np.testing.assert_array_equal(fast.rgba[..., 3], ref.rgba[..., 3])
    np.testing.assert_allclose(fast.rgba, ref.rgba, rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(fast.depth, ref.depth, rtol=0, atol=1e-7)
    for name in ("ambient", "diffuse", "specular"):
        np.testing.assert_allclose(fast.passes[name], ref.passes[name], rtol=1e-6, atol=1e-7)


def test_shade_engines_agree_with_visibility() -> None:
    rng = np.random.default_rng(5)
    n = 5000
    points = rng.normal(size=(n, 3)) - [0, 0, 4]
    normals = rng.normal(size=(n, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    lights = bp.lights_in_eye_space([lt for lt in busy_scene().lights], np.eye(4))
    vis = rng.uniform(0, 1, (n, len(lights)))
    mat = bp.Material(emission=(0.1, 0, 0), specular=(1, 0.5, 0.2), shininess=33.0)
    for model in (bp.LightModel(), bp.LightModel(specular="phong", local_viewer=False)):
        a = bp.shade(points, normals, mat, lights, model=model, visibility=vis, engine="numpy")
        b = bp.shade(points, normals, mat, lights, model=model, visibility=vis, engine="numba")
        for name in ("ambient", "diffuse", "specular"):
            np.testing.assert_allclose(getattr(b, name), getattr(a, name), rtol=1e-12, atol=1e-14)

"""The compiled shadow kernels against the numpy reference, and ray-traced shadows far from the origin.

* Shadow maps: :mod:`blinn_phong.shadows.map_render_kernels` renders the maps and
  :mod:`blinn_phong.shadows.map_lookup_kernels` looks them up with the
  same formulas as the numpy reference in :mod:`blinn_phong.shadows.maps`. The only arithmetic
  that differs is the 4×4 transform (a BLAS product in the reference, a fixed summation
  order in the kernel), so map depths agree to 1e-12 (observed: ≤ 1e-13) and coverage is
  identical; look-ups agree to 1e-9 (bilinear weights: observed ≤ 2e-13) with the usual
  biases, where no receiver lies within rounding of a stored depth.
* Ray-traced shadows are translation and scale invariant (an identity of the geometry):
  the same scene moved 10⁴ units from the origin, or scaled up 10⁴ times, must classify
  its surface points as the scene at the origin does. Embree works in float32, whose
  spacing at 10⁴ is ~1e-3, so a fixed 1e-4 origin offset gives acne there; the renderer
  recentres the BVH and scales the offset with the float32 spacing of the point.
"""

import numpy as np
import pytest

from blinn_phong.model.lights import DirectionalLight, PointLight, SpotLight
from blinn_phong.shadows import raytrace
from blinn_phong.shadows.maps import PCF_KERNELS, light_shadow_maps, shadow_map_visibility
from blinn_phong.shadows.methods import light_visibility
from blinn_phong.shadows.raytrace import (
    RayScene,
    area_light_visibility,
    directional_light_visibility,
    point_light_visibility,
)

from .geometry import box_triangles, quad_triangles, uv_sphere_triangles

pytest.importorskip("numba")

GROUND = quad_triangles(np.array([-4.0, -4.0, 0.0]), np.array([8.0, 0, 0]), np.array([0, 8.0, 0]))
SCENE = np.concatenate(
    [
        GROUND,
        box_triangles((-1.5, -0.5, 0.0), (-0.5, 0.5, 1.0)),
        uv_sphere_triangles((1.0, 0.3, 0.8), 0.7, 24, 12),
    ]
)
LIGHTS = {
    "directional": DirectionalLight((-0.5, -0.3, -1.0)),
    "spot": SpotLight((1.0, 0.5, 3.0), (-0.3, -0.15, -1.0), 60.0),
    "point": PointLight((0.5, 1.5, 2.5)),
    # a point light 1e-3 above the ground: its cube faces clip ground triangles at the near plane
    "point_near_ground": PointLight((2.0, -2.0, 1e-3)),
}


def surface_samples(tris: np.ndarray, n: int, seed: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """``n`` random points on the triangles (uniform barycentrics per triangle) and their face normals."""
    rng = np.random.default_rng(seed)
    t = rng.integers(0, len(tris), n)
    u, v = rng.random(n), rng.random(n)
    flip = u + v > 1
    u, v = np.where(flip, 1 - u, u), np.where(flip, 1 - v, v)
    a, b, c = tris[t, 0], tris[t, 1], tris[t, 2]
    points = a + u[:, None] * (b - a) + v[:, None] * (c - a)
    normals = np.cross(b - a, c - a)
    return points, normals / np.linalg.norm(normals, axis=1, keepdims=True)


@pytest.mark.parametrize("kind", list(LIGHTS))
@pytest.mark.parametrize("bias", [(0.0, 0.0), (1e-4, 2.0)])
def test_compiled_shadow_maps_equal_the_reference(kind, bias):
    light = LIGHTS[kind]
    constant, slope = bias
    ours = light_shadow_maps(light, SCENE, 128, constant_bias=constant, slope_bias=slope, engine="numba")
    ref = light_shadow_maps(light, SCENE, 128, constant_bias=constant, slope_bias=slope, engine="numpy")
    assert len(ours) == len(ref)
    drawn = 0
    for a, b in zip(ours, ref, strict=True):
        np.testing.assert_array_equal(a.view, b.view)
        np.testing.assert_array_equal(a.depth < 1, b.depth < 1)  # identical coverage
        np.testing.assert_allclose(a.depth, b.depth, rtol=0, atol=1e-12)
        drawn += int((b.depth < 1).sum())
    assert drawn > 1000  # the maps do see the scene


@pytest.mark.parametrize("kind", list(LIGHTS))
@pytest.mark.parametrize("kernel", PCF_KERNELS)
@pytest.mark.parametrize("normal_offset", [0.0, 0.02])
def test_compiled_lookup_equals_the_reference(kind, kernel, normal_offset):
    light = LIGHTS[kind]
    points, normals = surface_samples(SCENE, 4000)
    maps = light_shadow_maps(light, SCENE, 128, constant_bias=1e-4, slope_bias=3.0, engine="numpy")
    ours = shadow_map_visibility(
        light, maps, points, normals, normal_offset=normal_offset, kernel=kernel, engine="numba"
    )
    ref = shadow_map_visibility(
        light, maps, points, normals, normal_offset=normal_offset, kernel=kernel, engine="numpy"
    )
    assert 0.02 < 1 - ref.mean() < 0.98  # shadowed and lit points both present
    np.testing.assert_allclose(ours, ref, rtol=0, atol=1e-9)


def test_light_visibility_engines_agree_and_bad_engine_is_named():
    points, normals = surface_samples(SCENE, 3000)
    for light in (LIGHTS["directional"], LIGHTS["point"]):
        a = light_visibility("shadow_map", light, SCENE, points, normals, resolution=256, engine="numba")
        b = light_visibility("shadow_map", light, SCENE, points, normals, resolution=256, engine="numpy")
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-9)
        a = light_visibility("ray_traced", light, SCENE, points, normals, engine="numba")
        b = light_visibility("ray_traced", light, SCENE, points, normals, engine="numpy")
        # same formulas in float64, rounded once to float32: identical rays up to a last bit
        assert np.mean(a != b) <= 1e-3
    with pytest.raises(ValueError, match="engine"):
        light_visibility("shadow_map", LIGHTS["point"], SCENE, points, normals, engine="cuda")
    bad = points.copy()
    bad[5, 1] = np.nan
    with pytest.raises(ValueError, match="finite"):
        light_visibility("ray_traced", LIGHTS["point"], SCENE, bad, normals, engine="numba")


def _classify(tris, points, normals, light, engine="auto"):
    scene = RayScene(tris)
    if isinstance(light, DirectionalLight):
        return directional_light_visibility(
            scene, points, normals, -np.asarray(light.direction), engine=engine
        )
    return point_light_visibility(scene, points, normals, light.position, engine=engine)


@pytest.mark.parametrize("engine", ["numpy", "numba"])
@pytest.mark.parametrize("kind", ["directional", "point"])
def test_ray_traced_shadows_are_translation_invariant_far_from_the_origin(kind, engine):
    """The scene moved by 10⁴ units (float32 spacing ~1e-3 there) classifies like the scene at the origin."""
    light = LIGHTS[kind]
    points, normals = surface_samples(SCENE, 20000)
    at_origin = _classify(SCENE, points, normals, light, engine)
    shift = np.array([1e4, -1e4, 1e4])
    moved_light = light if isinstance(light, DirectionalLight) else PointLight(tuple(light.position + shift))
    far = _classify(SCENE + shift, points + shift, normals, moved_light, engine)
    assert 0.05 < 1 - at_origin.mean() < 0.95
    assert np.mean(far != at_origin) <= 1e-3


def test_ray_offset_scales_with_the_float32_spacing_of_large_scenes(monkeypatch):
    """A scene 10⁴ times larger (kilometres instead of metres) classifies like the unit scene.

    Without the scaled offset (``OFFSET_ULPS = 0``: a fixed 1e-4 offset) the same check
    finds acne on a sizeable share of lit points, so the comparison can fail.
    """
    light = LIGHTS["directional"]
    points, normals = surface_samples(SCENE, 20000)
    unit = _classify(SCENE, points, normals, light)
    scale = 1e4
    large = _classify(SCENE * scale, points * scale, normals, light)
    lit = unit == 1
    assert np.mean(large[lit] == 0) <= 1e-3  # no acne
    assert np.mean(large != unit) <= 2e-3
    monkeypatch.setattr(raytrace, "OFFSET_ULPS", 0.0)
    fixed = _classify(SCENE * scale, points * scale, normals, light)
    assert np.mean(fixed[lit] == 0) > 0.01


def test_area_light_engines_agree():
    """Soft shadows: the compiled per-sample ray set-up and the numpy one, same seed, same rays."""
    points, normals = surface_samples(SCENE, 4000)
    scene = RayScene(SCENE)
    args = (scene, points, normals, (-0.5, -0.5, 4.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0))
    a = area_light_visibility(*args, samples_per_axis=3, seed=11, engine="numba")
    b = area_light_visibility(*args, samples_per_axis=3, seed=11, engine="numpy")
    assert 0.01 < np.mean((b > 0) & (b < 1))  # a penumbra is there
    # float64 set-up rounded once to float32: at most a stray ray differs (1/9 of a point)
    assert np.abs(a - b).max() <= 1 / 9 + 1e-12
    assert np.mean(a != b) <= 1e-3


@pytest.mark.parametrize("kind", ["directional", "point"])
def test_visibility_at_inside_another_compiled_kernel(kind):
    """A shading kernel can look shadows up per fragment: ``visibility_at`` with ``shadow_lookup``."""
    import numba

    from blinn_phong.shadows.map_lookup_kernels import visibility_at
    from blinn_phong.shadows.maps import shadow_lookup

    @numba.njit
    def shade(points, normals, depth, vp, view_z, face_mode, light_pos, normal_offset, kernel):
        out = np.empty(points.shape[0])
        for i in range(points.shape[0]):
            p, n = points[i], normals[i]
            out[i] = visibility_at(
                p[0],
                p[1],
                p[2],
                n[0],
                n[1],
                n[2],
                depth,
                vp,
                view_z,
                face_mode,
                light_pos,
                normal_offset,
                kernel,
            )
        return out

    light = LIGHTS[kind]
    points, normals = surface_samples(SCENE, 3000)
    maps = light_shadow_maps(light, SCENE, 128, constant_bias=1e-4, slope_bias=3.0)
    lookup = shadow_lookup(light, maps, normal_offset=0.02, kernel="bilinear")
    got = shade(points, normals, *lookup.arguments())
    ref = shadow_map_visibility(
        light, maps, points, normals, normal_offset=0.02, kernel="bilinear", engine="numpy"
    )
    assert 0.02 < 1 - ref.mean() < 0.98
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-9)

"""Where shadow maps fail: acne without bias, peter-panning with too much, light leaking with wide PCF.

The scene is planar, so the exact shadows are closed forms: a horizontal plate at height h
under a directional light along L = (0.5, 0, −1) shadows the ground (z = 0) over its own
rectangle shifted by 0.5·h in +x. The failing method's error (visibility × 255, i.e. 8-bit
steps of a white receiver under a unit light) must exceed a bound derived below; the
robust setting must stay under one; no output may hold NaN or Inf.
"""

from __future__ import annotations

import numpy as np
import pytest

import blinn_phong as bp
from blinn_phong.shadows.maps import light_shadow_maps, shadow_map_visibility
from testbeds.error_metrics import error_metrics, has_nonfinite

LIGHT = bp.DirectionalLight((0.5, 0.0, -1.0))
RES = 512
LOW_H, HIGH_H = 0.05, 1.0
LOW = (-2.0, -0.5, -0.75, 0.75)  # x0, x1, y0, y1 of the plate near the ground
HIGH = (0.5, 2.0, -0.75, 0.75)  # and of the plate one unit up


def _quad(x0: float, x1: float, y0: float, y1: float, z: float) -> np.ndarray:
    p = np.array([[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]], float)
    return p[np.array([[0, 1, 2], [0, 2, 3]])]


def _scene_triangles() -> np.ndarray:
    return np.concatenate([_quad(-3, 3, -3, 3, 0.0), _quad(*LOW, LOW_H), _quad(*HIGH, HIGH_H)])


def _exact_shadowed(points: np.ndarray) -> np.ndarray:
    """Closed form: a ground point is shadowed iff it lies in a plate's rectangle shifted by 0.5·h in x."""
    out = np.zeros(len(points), bool)
    for (x0, x1, y0, y1), h in ((LOW, LOW_H), (HIGH, HIGH_H)):
        x = points[:, 0] - 0.5 * h
        out |= (x > x0) & (x < x1) & (points[:, 1] > y0) & (points[:, 1] < y1)
    return out


def _ground_points(n: int = 20000, seed: int = 5) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    p = np.c_[rng.uniform(-2.5, 2.8, n), rng.uniform(-1.2, 1.2, n), np.zeros(n)]
    return p, np.tile([0.0, 0.0, 1.0], (n, 1))


def _visibility(constant: float, slope: float, kernel: str, points: np.ndarray, normals: np.ndarray):
    maps = light_shadow_maps(LIGHT, _scene_triangles(), RES, constant_bias=constant, slope_bias=slope)
    vis = shadow_map_visibility(LIGHT, maps, points, normals, kernel=kernel)
    assert not has_nonfinite(vis)
    return vis, maps[0]


def _texel_world(shadow_map) -> float:
    """World length of one texel along y (world y maps to the map's rows for a light in the xz-plane)."""
    vp = shadow_map.projection @ shadow_map.view
    a, b = np.array([0, -1.0, 0, 1]) @ vp.T, np.array([0, 1.0, 0, 1]) @ vp.T
    rows = ((a[1] / a[3] + 1) * 0.5 * RES, (b[1] / b[3] + 1) * 0.5 * RES)
    return 2.0 / abs(rows[1] - rows[0])


def _interior(points: np.ndarray, margin: float) -> np.ndarray:
    """Points at least ``margin`` away from every exact shadow boundary (both sides)."""
    far = np.ones(len(points), bool)
    for (x0, x1, y0, y1), h in ((LOW, LOW_H), (HIGH, HIGH_H)):
        x = points[:, 0] - 0.5 * h
        y = points[:, 1]
        near_x = (np.minimum(np.abs(x - x0), np.abs(x - x1)) < margin) & (y > y0 - margin) & (y < y1 + margin)
        near_y = (np.minimum(np.abs(y - y0), np.abs(y - y1)) < margin) & (x > x0 - margin) & (x < x1 + margin)
        far &= ~(near_x | near_y)
    return far


def test_shadow_acne_without_bias() -> None:
    points, normals = _ground_points()
    exact_vis = (~_exact_shadowed(points)).astype(float)
    unbiased, shadow_map = _visibility(0.0, 0.0, "nearest", points, normals)
    biased, _ = _visibility(1e-4, 2.0, "nearest", points, normals)
    tau = _texel_world(shadow_map)
    inside = _interior(points, 2 * tau)
    lit = inside & (exact_vis == 1)
    # Without bias the ground compares its own depth with the depth stored at the nearest texel
    # centre: the difference is the depth slope times an offset uniform in ±half a texel, so
    # about half the lit points fall behind their own surface (acne). Bound: more than 30 %.
    acne = np.mean(unbiased[lit] < 0.5)
    assert 0.3 < acne < 0.7
    assert error_metrics(unbiased[lit], exact_vis[lit])["mean_steps"] > 0.3 * 255
    # With a slope-scaled bias of 2 (more than the half-texel offset along the steepest axis,
    # which is at most 1·slope) every lit point away from the shadow edges is lit.
    assert error_metrics(biased[inside], exact_vis[inside])["max_steps"] < 1.0


def test_peter_panning_with_too_much_bias() -> None:
    points, normals = _ground_points()
    shadowed = _exact_shadowed(points)
    low_shadow = shadowed & (points[:, 0] < 0.3)  # the low plate's shadow: x in (-1.975, -0.475)
    high_shadow = shadowed & (points[:, 0] > 0.3)
    moderate, shadow_map = _visibility(1e-4, 2.0, "nearest", points, normals)
    tau = _texel_world(shadow_map)
    inside = _interior(points, 2 * tau)
    # A constant bias b (window depth) moves stored depths b·D world units away from the light,
    # D = far − near of the map's orthographic projection (3·r around the casters' bounding sphere).
    # Along the light ray the low plate is h·|L|/|L_z| = 0.05·√1.25 = 0.056 above the ground, the
    # high one 1.12: a bias with 0.056 < b·D < 1.12 lifts the low plate's shadow off entirely
    # (peter-panning: every point of it is lit, error 255 steps) and leaves the high plate's.
    heavy, heavy_map = _visibility(0.05, 0.0, "nearest", points, normals)
    depth_range = -2.0 / heavy_map.projection[2, 2]  # orthographic: P[2][2] = −2/(far − near)
    assert LOW_H * np.sqrt(1.25) < 0.05 * depth_range < HIGH_H * np.sqrt(1.25)
    exact_vis = (~shadowed).astype(float)
    failing = error_metrics(heavy[low_shadow & inside], exact_vis[low_shadow & inside])
    assert failing["mean_steps"] > 0.99 * 255
    assert np.mean(heavy[high_shadow & inside] > 0.5) < 0.01
    assert error_metrics(moderate[inside], exact_vis[inside])["max_steps"] < 1.0


@pytest.mark.parametrize("kernel", ["box5", "box7"])
def test_wide_pcf_kernels_leak_light_into_the_shadow(kernel: str) -> None:
    points, normals = _ground_points(40000)
    shadowed = _exact_shadowed(points)
    exact_vis = (~shadowed).astype(float)
    half = int(kernel[3:]) // 2  # taps reach this many texels on each side
    # A tap ``half`` texels away compares the receiver with its own surface ``half`` texels off:
    # the slope-scaled bias must cover that (half + 1 slopes), or the kernel itself causes acne.
    nearest, shadow_map = _visibility(1e-4, half + 1.0, "nearest", points, normals)
    wide, _ = _visibility(1e-4, half + 1.0, kernel, points, normals)
    tau = _texel_world(shadow_map)
    # Points inside the high plate's shadow at distance s from its edge y = 0.75 (texel rows are
    # world y), with (half − 1.5)·τ ≤ s ≤ (half − 1)·τ, away from the x edges: the row of taps
    # ``half`` texels towards the edge has its centres at least half a texel beyond the edge, so
    # it is lit: at least ``k`` of the ``k²`` taps see light, visibility ≥ 1/k, error ≥ 255/k steps.
    k = 2 * half + 1
    s = 0.75 - points[:, 1]
    band = (
        shadowed
        & (points[:, 0] > 1.0 + 4 * tau)
        & (points[:, 0] < 2.5 - 4 * tau)
        & (s >= (half - 1.5) * tau)
        & (s <= (half - 1.0) * tau)
    )
    assert band.sum() > 20
    leak = wide[band] - exact_vis[band]
    assert leak.min() >= 1.0 / k - 1e-12
    assert error_metrics(wide[band], exact_vis[band])["max_steps"] >= 255.0 / k
    # The nearest texel of such a point is inside the footprint (s ≥ 0.5·τ, and the bias is tiny
    # against the plate's 1.12 height above the ground): no leak at all.
    assert error_metrics(nearest[band], exact_vis[band])["max_steps"] < 1.0


@pytest.mark.parametrize("scale", [1.0, 1e4])
def test_ray_traced_shadows_at_large_scale_need_an_offset_in_float32_spacings(scale, monkeypatch):
    """Embree intersects in float32: a ground point of a scene 10⁴ units across sits ~1e-3 from
    the nearest float32 value, so a fixed 1e-4 origin offset lands on either side of its own
    surface (acne on a large share of lit points); an offset of 64 float32 spacings of the point
    (``raytrace.OFFSET_ULPS``) keeps every lit point lit. Exact answer: the closed form above,
    scaled; points within 1e-3·scale of a shadow edge are left out (float32 edge rounding).
    """
    from blinn_phong.shadows import raytrace

    points, normals = _ground_points()
    exact = _exact_shadowed(points)
    edge = np.zeros(len(points), bool)
    for (x0, x1, y0, y1), h in ((LOW, LOW_H), (HIGH, HIGH_H)):
        x = points[:, 0] - 0.5 * h
        edge |= (np.minimum(np.abs(x - x0), np.abs(x - x1)) < 1e-3) | (
            np.minimum(np.abs(points[:, 1] - y0), np.abs(points[:, 1] - y1)) < 1e-3
        )
    scene = raytrace.RayScene(_scene_triangles() * scale)
    to_light = -np.asarray(LIGHT.direction)
    lit = ~exact & ~edge

    def acne_share() -> float:
        vis = raytrace.directional_light_visibility(scene, points * scale, normals, to_light)
        assert not has_nonfinite(vis)
        assert np.all(vis[exact & ~edge] == 0)  # shadowed points stay shadowed
        return float(np.mean(vis[lit] == 0))

    assert acne_share() == 0.0
    monkeypatch.setattr(raytrace, "OFFSET_ULPS", 0.0)  # a fixed 1e-4 offset
    fixed = acne_share()
    if scale == 1.0:
        assert fixed == 0.0  # at unit scale 1e-4 is ~800 float32 spacings: enough
    else:
        assert fixed > 0.05  # at 10⁴ it is a tenth of one spacing: acne

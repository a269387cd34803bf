"""addon.mapping against closed forms, numerical quadrature and worked values (no bpy)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from addon import mapping
from blinn_phong.model.transforms import perspective_matrix

# numpy 2 renamed trapz to trapezoid (numpy 1.26, for Blender 4.2–5.0, has only trapz).
_trapezoid = getattr(np, "trapezoid", None) or np.trapz


def _smoothstep(x: np.ndarray) -> np.ndarray:
    t = np.clip(x, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _mean_over(t: np.ndarray, f: np.ndarray) -> float:
    """Mean of samples f(t) on a uniform grid t (trapezoid rule)."""
    return float(_trapezoid(f, t) / (t[-1] - t[0]))


# --------------------------------------------------------------------------- sizes and border


@pytest.mark.parametrize(
    ("res", "pct", "expected"),
    [
        ((1920, 1080), 100, (1920, 1080)),
        ((1920, 1080), 50, (960, 540)),
        ((101, 33), 50, (50, 16)),
        ((64, 48), 200, (128, 96)),
    ],
)
def test_render_size_is_integer_percentage(res: tuple[int, int], pct: int, expected: tuple[int, int]) -> None:
    assert mapping.render_size(res[0], res[1], pct) == expected


def test_border_matches_blender_observation_and_flips_y() -> None:
    # Blender: 100×50 frame, border x 0.2–0.6, y 0–0.5 (from the bottom) -> a 40×25 result.
    x0, y0, x1, y1 = mapping.border_rectangle(0.2, 0.6, 0.0, 0.5, 100, 50)
    assert (x1 - x0, y1 - y0) == (40, 25)
    assert (x0, x1) == (20, 60)
    assert (y0, y1) == (25, 50)  # the bottom half, counted from the top row


def test_border_rejects_inverted_range() -> None:
    with pytest.raises(ValueError, match="min <= max"):
        mapping.border_rectangle(0.6, 0.2, 0.0, 1.0, 10, 10)


# --------------------------------------------------------------------------- camera


def test_symmetric_frustum_equals_glu_perspective() -> None:
    near, far, fov_y, aspect = 0.5, 40.0, 50.0, 1.6
    top = near * math.tan(math.radians(fov_y) / 2)
    right = top * aspect
    got = mapping.frustum_matrix(-right, right, -top, top, near, far)
    np.testing.assert_allclose(got, perspective_matrix(fov_y, aspect, near, far), rtol=1e-12, atol=1e-12)


def test_frustum_maps_its_corners_to_the_ndc_cube() -> None:
    l, r, b, t, n, f = -0.3, 0.5, -0.2, 0.4, 0.25, 10.0
    m = mapping.frustum_matrix(l, r, b, t, n, f)
    for corner, ndc in (
        ((l, b, -n), (-1, -1, -1)),
        ((r, t, -n), (1, 1, -1)),
        ((r * f / n, b * f / n, -f), (1, -1, 1)),
    ):
        clip = m @ np.array([*corner, 1.0])
        np.testing.assert_allclose(clip[:3] / clip[3], ndc, atol=1e-12)


def test_perspective_horizontal_fit_focal_length() -> None:
    # Pinhole camera: horizontal half-angle atan((sensor/2)/lens), so P[0,0] = 2·lens/sensor.
    p = mapping.camera_projection(kind="PERSP", width=640, height=480, lens_mm=35.0, sensor_width_mm=36.0)
    assert p[0, 0] == pytest.approx(2 * 35.0 / 36.0, rel=1e-12)
    assert p[1, 1] == pytest.approx(2 * 35.0 / 36.0 * 640 / 480, rel=1e-12)  # square pixels


def test_auto_fit_uses_sensor_width_along_the_longer_side() -> None:
    # Portrait frame: AUTO fits the sensor width to the (longer) vertical side.
    p = mapping.camera_projection(
        kind="PERSP",
        width=300,
        height=600,
        lens_mm=50.0,
        sensor_width_mm=36.0,
        sensor_height_mm=24.0,
        sensor_fit="AUTO",
    )
    assert p[1, 1] == pytest.approx(2 * 50.0 / 36.0, rel=1e-12)
    v = mapping.camera_projection(
        kind="PERSP",
        width=300,
        height=600,
        lens_mm=50.0,
        sensor_width_mm=36.0,
        sensor_height_mm=24.0,
        sensor_fit="VERTICAL",
    )
    assert v[1, 1] == pytest.approx(2 * 50.0 / 24.0, rel=1e-12)


def test_shift_moves_the_view_plane_by_a_fraction_of_the_fitted_side() -> None:
    # Shift s (fraction of the fitted side) moves the window centre by 2·s in NDC along x for a
    # horizontal fit, and by 2·s·width/height along y.
    p = mapping.camera_projection(kind="PERSP", width=400, height=200, shift_x=0.1, shift_y=-0.05)
    assert p[0, 2] == pytest.approx(0.2, rel=1e-12)
    assert p[1, 2] == pytest.approx(-0.05 * 2 * 400 / 200, rel=1e-12)


def test_orthographic_scale_spans_the_fitted_side() -> None:
    o = mapping.camera_projection(
        kind="ORTHO", width=200, height=100, ortho_scale=8.0, shift_x=0.25, clip_start=0.5, clip_end=20.0
    )
    # x from -4 + 2 to 4 + 2 (shift 0.25 of the 8-unit width), y from -2 to 2.
    for eye, ndc_xy in (((-2.0, -2.0, -1.0), (-1, -1)), ((6.0, 2.0, -3.0), (1, 1))):
        clip = o @ np.array([*eye, 1.0])
        np.testing.assert_allclose(clip[:2] / clip[3], ndc_xy, atol=1e-12)
    assert (o @ np.array([0, 0, -0.5, 1]))[2] == pytest.approx(-1.0)
    assert (o @ np.array([0, 0, -20.0, 1]))[2] == pytest.approx(1.0)


def test_camera_rejects_panoramic_and_bad_clip() -> None:
    with pytest.raises(ValueError, match="kind"):
        mapping.camera_projection(kind="PANO", width=4, height=4)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="clip_end"):
        mapping.camera_projection(kind="PERSP", width=4, height=4, clip_start=1.0, clip_end=0.5)


# --------------------------------------------------------------------------- lights


def test_lambertian_emitter_intensity_integrates_to_its_power() -> None:
    # Radiant intensity I0·cos θ over the hemisphere must integrate to the power P.
    power = 75.0
    i0 = mapping.area_light_intensity(power) * math.pi  # radiant intensity along the normal (W/sr)
    theta = np.linspace(0.0, math.pi / 2, 20001)
    flux = _trapezoid(i0 * np.cos(theta) * np.sin(theta), theta) * 2 * math.pi
    assert flux == pytest.approx(power, rel=1e-6)


def test_point_light_irradiance_matches_isotropic_emitter() -> None:
    # Isotropic P watts: irradiance P/(4π d²); radiance from albedo ρ is ρ/π of that.
    power, d, albedo = 1000.0, 3.0, 0.8
    radiance_blender = albedo / math.pi * power / (4 * math.pi * d * d)
    kc, kl, kq = mapping.point_light_attenuation(0.0)
    radiance_bp = albedo * mapping.point_light_intensity(power) / (kc + kl * d + kq * d * d)
    assert radiance_bp == pytest.approx(radiance_blender, rel=1e-6)


def test_sun_on_white_lambertian_gives_strength_over_pi() -> None:
    assert mapping.sun_light_intensity(math.pi) == pytest.approx(1.0)


def test_disc_attenuation_equals_disc_form_factor_profile() -> None:
    # On-axis irradiance of a Lambertian disc (radius r, radiance L) at distance d: π L r²/(r² + d²).
    r = 0.5
    kc, kl, kq = mapping.point_light_attenuation(r)
    for d in (0.0, 0.3, 1.0, 4.0):
        exact = r * r / (r * r + d * d)
        assert r * r / (kc + kl * d + kq * d * d) == pytest.approx(exact, rel=1e-12)


@pytest.mark.parametrize("blend", [0.0, 0.15, 0.5, 1.0])
def test_blender_spot_mean_by_quadrature(blend: float) -> None:
    size = math.radians(70.0)
    c = math.cos(size / 2)
    t = np.linspace(c, 1.0, 200001)
    mask = np.ones_like(t) if blend == 0 else _smoothstep((t - c) / ((1 - c) * blend))
    assert mapping.spot_mean_blender(blend) == pytest.approx(_mean_over(t, mask), abs=1e-6)


@pytest.mark.parametrize(("size_deg", "blend"), [(30.0, 0.2), (75.0, 0.15), (120.0, 1.0), (179.0, 0.5)])
def test_spot_exponent_preserves_the_light_in_the_cone(size_deg: float, blend: float) -> None:
    size = math.radians(size_deg)
    c = math.cos(size / 2)
    e = mapping.spot_exponent(size, blend)
    t = np.linspace(c, 1.0, 400001)
    gl_mean = _mean_over(t, t**e)
    blender_mean = _mean_over(t, _smoothstep((t - c) / ((1 - c) * blend)))
    assert gl_mean == pytest.approx(blender_mean, abs=2e-5)
    assert mapping.spot_cutoff_degrees(size) == pytest.approx(size_deg / 2)


def test_hard_spot_edge_has_zero_exponent_and_more_blend_more_falloff() -> None:
    size = math.radians(60.0)
    assert mapping.spot_exponent(size, 0.0) == 0.0
    exps = [mapping.spot_exponent(size, b) for b in (0.1, 0.4, 0.8)]
    assert exps == sorted(exps) and exps[0] > 0


# --------------------------------------------------------------------------- materials


@pytest.mark.parametrize("roughness", [0.2, 0.35, 0.5, 0.8, 1.0])
def test_shininess_matches_beckmann_peak(roughness: float) -> None:
    # Walter et al. 2007: normalised Blinn-Phong D = (s+2)/(2π) cos^s θ has the Beckmann peak 1/(π α²).
    alpha = roughness**2
    s = mapping.roughness_to_shininess(roughness)
    assert (s + 2) / (2 * math.pi) == pytest.approx(1 / (math.pi * alpha**2), rel=1e-12)


def test_shininess_is_capped_for_mirrors() -> None:
    assert mapping.roughness_to_shininess(0.0) == mapping.MAX_SHININESS
    assert mapping.roughness_to_shininess(0.05) == mapping.MAX_SHININESS


def test_principled_dielectric_f0_is_four_percent_for_glass_ior() -> None:
    # Fresnel at normal incidence for n = 1.5: ((n-1)/(n+1))² = 0.04.
    m = mapping.blinn_phong_from_principled(base_color=(0.8, 0.2, 0.1), roughness=0.5, ior=1.5)
    s = mapping.roughness_to_shininess(0.5)
    np.testing.assert_allclose(m["specular"], [0.04 * (s + 8) / 8] * 3, rtol=1e-12)
    np.testing.assert_allclose(m["diffuse"], (0.8, 0.2, 0.1))
    assert m["opacity"] == 1.0


def test_principled_metal_has_no_diffuse_and_tinted_specular() -> None:
    m = mapping.blinn_phong_from_principled(
        base_color=(1.0, 0.5, 0.25),
        metallic=1.0,
        roughness=0.5,
        emission_color=(1.0, 1.0, 0.0),
        emission_strength=2.0,
        alpha=0.5,
    )
    s = mapping.roughness_to_shininess(0.5)
    np.testing.assert_allclose(m["diffuse"], (0.0, 0.0, 0.0))
    np.testing.assert_allclose(m["specular"], np.array([1.0, 0.5, 0.25]) * (s + 8) / 8)
    np.testing.assert_allclose(m["emission"], (2.0, 2.0, 0.0))
    assert m["opacity"] == 0.5


def test_principled_rejects_negative_colour() -> None:
    with pytest.raises(ValueError, match="base_color"):
        mapping.blinn_phong_from_principled(base_color=(-0.1, 0.0, 0.0))


def test_rendering_a_crop_equals_cropping_the_render() -> None:
    # Rasterize the same triangles into the full frame and into a cropped frame: identical
    # coverage and depth in the overlap (the OpenGL viewport transform is an exact pixel shift).
    from blinn_phong.geometry.raster import rasterize, resolve_nearest

    rng = np.random.default_rng(7)
    width, height, region = 48, 32, (9, 5, 37, 26)
    projection = mapping.camera_projection(kind="PERSP", width=width, height=height, shift_x=0.05)
    eye = np.column_stack([rng.uniform(-1.5, 1.5, (30, 2)), rng.uniform(-6.0, -3.0, 30), np.ones(30)])
    triangles = rng.integers(0, 30, (20, 3))

    def render(proj: np.ndarray, w: int, h: int) -> tuple[np.ndarray, np.ndarray]:
        frags = rasterize((proj @ eye.T).T, triangles, w, h, samples=4)
        nearest = resolve_nearest(frags)
        depth = np.full(w * h * 4, np.inf)
        hit = nearest >= 0
        depth[hit] = frags.depth[nearest[hit]]
        return hit.reshape(h, w, 4), depth.reshape(h, w, 4)

    full_hit, full_depth = render(projection, width, height)
    crop = mapping.crop_projection(projection, width, height, region)
    x0, y0, x1, y1 = region
    crop_hit, crop_depth = render(crop, x1 - x0, y1 - y0)
    assert full_hit[y0:y1, x0:x1].any()
    np.testing.assert_array_equal(crop_hit, full_hit[y0:y1, x0:x1])
    np.testing.assert_allclose(crop_depth, full_depth[y0:y1, x0:x1], atol=1e-6)


@pytest.mark.parametrize("kind", ["PERSP", "ORTHO"])
def test_window_depth_round_trips_to_eye_distance(kind: str) -> None:
    # Project eye-space points with the matrix, apply the OpenGL depth-range map, invert.
    p = mapping.camera_projection(kind=kind, width=64, height=48, clip_start=0.3, clip_end=50.0, shift_y=0.1)
    distances = np.array([0.3, 0.5, 2.0, 17.0, 49.0])
    clip = p @ np.c_[np.zeros((5, 2)), -distances, np.ones(5)].T
    window = (clip[2] / clip[3] + 1.0) / 2.0
    got = mapping.window_depth_to_distance(np.r_[window, 1.0], p)
    np.testing.assert_allclose(got[:5], distances, rtol=1e-5)
    assert got[5] == mapping.BLENDER_EMPTY_DEPTH


# --------------------------------------------------------------------------- 3D viewport camera
# Hand computation (BKE_camera_params_from_view3d + BKE_camera_params_compute_viewplane): the free
# perspective view of a 200×100 region, lens 50, clip 0.1–100 sees the 36 mm sensor at zoom 2, so the
# view plane at the near plane spans x ∈ ±0.5·36·0.1/50·2 = ±0.072 and y ∈ ±0.036 (square pixels).


def test_viewport_perspective_projection_by_hand() -> None:
    got, kind = mapping.viewport_projection(
        view_perspective="PERSP",
        region_width=200,
        region_height=100,
        lens_mm=50.0,
        clip_start=0.1,
        clip_end=100.0,
    )
    n, f = 0.1, 100.0
    expected = np.array(
        [
            [n / 0.072, 0, 0, 0],
            [0, n / 0.036, 0, 0],
            [0, 0, -(f + n) / (f - n), -2 * f * n / (f - n)],
            [0, 0, -1, 0],
        ]
    )
    assert kind == "perspective"
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(got[0, 0], 50.0 / 36.0, rtol=1e-12)  # = lens / (sensor · zoom / 2)


def test_viewport_orthographic_projection_by_hand() -> None:
    # Portrait region 100×200: the sensor (ortho_scale = 10·36/50 = 7.2) spans the height (AUTO fit),
    # zoom 2 gives a 14.4 × 7.2 view; clip range ±clip_end/2.
    got, kind = mapping.viewport_projection(
        view_perspective="ORTHO",
        region_width=100,
        region_height=200,
        lens_mm=50.0,
        clip_end=1000.0,
        view_distance=10.0,
    )
    expected = np.array([[2 / 7.2, 0, 0, 0], [0, 2 / 14.4, 0, 0], [0, 0, -2 / 1000.0, 0], [0, 0, 0, 1]])
    assert kind == "orthographic"
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-15)


def test_viewport_camera_view_with_zoom_offset_and_shift_by_hand() -> None:
    # camzoom 0: factor (√2)²/4 = 1/2, zoom 2; view_camera_offset (0.1, 0): offset 2·0.1·½ = 0.1;
    # shift 0.2·½ = 0.1. Region 200×100 (horizontal fit, viewfac 200), lens 50, sensor 36, near 0.1:
    # pixel 36·0.1/50/200·2 = 0.00072; dx = 0.1·200 + 200·0.1 = 40 px → x ∈ [−60, 140]·0.00072.
    camera = {
        "kind": "PERSP",
        "lens_mm": 50.0,
        "sensor_width_mm": 36.0,
        "shift_x": 0.2,
        "clip_start": 0.1,
        "clip_end": 100.0,
    }
    got, kind = mapping.viewport_projection(
        view_perspective="CAMERA",
        region_width=200,
        region_height=100,
        camera=camera,
        camera_zoom=0.0,
        camera_offset=(0.1, 0.0),
    )
    left, right, half_y = -60 * 0.00072, 140 * 0.00072, 50 * 0.00072
    assert kind == "perspective"
    np.testing.assert_allclose(got[0, 0], 2 * 0.1 / (right - left), rtol=1e-12)
    np.testing.assert_allclose(got[0, 2], (right + left) / (right - left), rtol=1e-12)  # 0.4
    np.testing.assert_allclose(got[0, 2], 0.4, rtol=1e-12)
    np.testing.assert_allclose(got[1, 1], 0.1 / half_y, rtol=1e-12)


def test_view3d_zoom_factor_is_one_where_the_frame_fills_the_region() -> None:
    assert mapping.view3d_zoom_factor(0.0) == pytest.approx(0.5, rel=1e-15)
    assert mapping.view3d_zoom_factor(50.0 * (2.0 - math.sqrt(2.0))) == pytest.approx(1.0, rel=1e-12)


def test_viewport_bad_inputs_are_named() -> None:
    with pytest.raises(ValueError, match="view_perspective"):
        mapping.viewport_projection(view_perspective="PANO", region_width=10, region_height=10)
    with pytest.raises(ValueError, match="camera"):
        mapping.viewport_projection(view_perspective="CAMERA", region_width=10, region_height=10)
    with pytest.raises(ValueError, match="width"):
        mapping.viewport_projection(view_perspective="PERSP", region_width=0, region_height=10)
    with pytest.raises(ValueError, match="reduction"):
        mapping.viewport_size(100, 50, 0)
    assert mapping.viewport_size(101, 50, 4) == (25, 12)

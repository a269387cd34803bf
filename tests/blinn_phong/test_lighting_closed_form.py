"""The lighting equation and renders against closed forms (OpenGL 2.1 §2.14.1; Phong 1975; Blinn 1977)."""

from __future__ import annotations

import numpy as np
import pytest

import blinn_phong as bp
from blinn_phong.model.primitives import grid_plane, uv_sphere

RNG = np.random.default_rng(7)


def unit(v) -> np.ndarray:
    v = np.asarray(v, float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def ortho_topdown(size: float = 2.0) -> bp.Camera:
    """Looking down -Z at the z = 0 plane; x right, y up; pixels map to [-size/2, size/2]²."""
    h = size / 2
    return bp.Camera.orthographic(-h, h, -h, h, 0.1, 10.0, view=bp.look_at((0, 0, 5), (0, 0, 0)))


def pixel_centres(width: int, height: int, size: float = 2.0) -> tuple[np.ndarray, np.ndarray]:
    """World x, y of every pixel centre for :func:`ortho_topdown` (row 0 at the top)."""
    col = (np.arange(width) + 0.5) / width
    row = (np.arange(height) + 0.5) / height
    x, y = np.meshgrid((col - 0.5) * size, (0.5 - row) * size)
    return x, y


def plane(material: bp.Material, n: int = 1) -> bp.Mesh:
    pos, tris, normals = grid_plane(n, n, (2.4, 2.4))
    return bp.Mesh(pos, tris, normals, material=material)


@pytest.mark.parametrize("shading", ["flat", "gouraud", "phong"])
def test_flat_quad_under_directional_light_is_ka_ia_plus_kd_i_cos(shading: str) -> None:
    ka, kd = np.array([0.2, 0.3, 0.1]), np.array([0.5, 0.25, 0.8])
    ia, i_light = np.array([0.3, 0.3, 0.4]), np.array([0.9, 0.7, 1.1])
    direction = unit([0.3, -0.5, -1.0])
    mat = bp.Material(ambient=ka, diffuse=kd, specular=(0, 0, 0), shininess=10.0)
    scene = bp.Scene([plane(mat, 3)], [bp.DirectionalLight(direction, i_light)], ortho_topdown(), ambient=ia)
    img = bp.render(scene, 32, 32, shading=shading).rgba
    expected = ka * ia + kd * i_light * max(0.0, float(np.dot([0, 0, 1], -direction)))
    np.testing.assert_allclose(img[..., :3], np.broadcast_to(expected, (32, 32, 3)), rtol=1e-6)
    np.testing.assert_array_equal(img[..., 3], 1.0)


def test_light_behind_the_surface_gives_only_ambient() -> None:
    mat = bp.Material(ambient=(0.5, 0.5, 0.5), diffuse=(1, 1, 1), specular=(1, 1, 1), shininess=5.0)
    lights = [bp.DirectionalLight((0.2, 0.1, 1.0)), bp.PointLight((0.0, 0.0, -0.5))]  # both below z = 0
    scene = bp.Scene([plane(mat, 2)], lights, ortho_topdown(), ambient=(0.4, 0.4, 0.4))
    img = bp.render(scene, 16, 16).rgba
    np.testing.assert_allclose(img[..., :3], 0.5 * 0.4, rtol=1e-6)


def test_point_light_attenuation_at_measured_distances() -> None:
    # Plane z = 0 under a point light at height hgt: at a pixel at horizontal offset r, d = sqrt(r² + hgt²),
    # n·l = hgt / d, so diffuse = kd·I·(hgt/d) / (kc + kl·d + kq·d²).
    kc, kl, kq, hgt = 0.5, 0.7, 1.3, 0.8
    light_xy = np.array([0.25, -0.1])
    mat = bp.Material(ambient=(0, 0, 0), diffuse=(1, 1, 1))
    light = bp.PointLight((*light_xy, hgt), (1, 1, 1), 2.0, constant=kc, linear=kl, quadratic=kq)
    scene = bp.Scene([plane(mat, 4)], [light], ortho_topdown(), ambient=(0, 0, 0))
    img = bp.render(scene, 40, 40).rgba
    x, y = pixel_centres(40, 40)
    d = np.sqrt((x - light_xy[0]) ** 2 + (y - light_xy[1]) ** 2 + hgt**2)
    expected = 2.0 * (hgt / d) / (kc + kl * d + kq * d * d)
    np.testing.assert_allclose(img[..., 0], expected, rtol=3e-7)


def test_spot_light_falloff_and_cutoff_at_measured_angles() -> None:
    # Spot straight down from height hgt: the angle at a pixel is atan(r / hgt); inside the cone
    # the factor is cos(angle)^exponent, outside 0; diffuse also carries n·l = cos(angle).
    hgt, cutoff, exponent = 1.0, 30.0, 5.0
    mat = bp.Material(ambient=(0, 0, 0), diffuse=(1, 1, 1))
    light = bp.SpotLight((0.0, 0.0, hgt), (0.0, 0.0, -1.0), cutoff=cutoff, exponent=exponent)
    scene = bp.Scene([plane(mat, 4)], [light], ortho_topdown(), ambient=(0, 0, 0))
    img = bp.render(scene, 64, 64).rgba[..., 0]
    x, y = pixel_centres(64, 64)
    cos_a = hgt / np.sqrt(x**2 + y**2 + hgt**2)
    expected = np.where(cos_a >= np.cos(np.radians(cutoff)), cos_a**exponent * cos_a, 0.0)
    away_from_rim = np.abs(np.degrees(np.arccos(cos_a)) - cutoff) > 0.05
    np.testing.assert_allclose(img[away_from_rim], expected[away_from_rim], rtol=3e-7, atol=1e-9)
    assert (img > 0).sum() > 100 and (img == 0).sum() > 100  # both inside and outside were sampled


def test_sphere_highlight_sits_where_normal_equals_half_vector() -> None:
    # Orthographic view along -Z (viewer at infinity): the highlight peak is where n = h =
    # normalize(l + v); on a unit sphere that point is h itself, seen at pixel (h_x, h_y).
    size, res = 2.4, 241
    pos, tris, normals = uv_sphere(256, 128)
    mat = bp.Material(ambient=(0, 0, 0), diffuse=(0, 0, 0), specular=(1, 1, 1), shininess=200.0)
    to_light = unit([0.5, 0.35, 1.0])
    scene = bp.Scene(
        [bp.Mesh(pos, tris, normals, material=mat)],
        [bp.DirectionalLight(-to_light)],
        ortho_topdown(size),
        ambient=(0, 0, 0),
        light_model=bp.LightModel(local_viewer=False),
    )
    img = bp.render(scene, res, res).rgba[..., 0]
    h = unit(to_light + np.array([0, 0, 1.0]))
    row, col = np.unravel_index(np.argmax(img), img.shape)
    x, y = pixel_centres(res, res, size)
    pixel = size / res
    assert abs(x[row, col] - h[0]) <= pixel and abs(y[row, col] - h[1]) <= pixel
    assert img.max() > 0.99


def _shade_one(normal, to_light, to_eye, shininess: float, specular: str) -> float:
    """Specular term of one directional light at a point seen along ``to_eye`` (viewer at infinity)."""
    mat = bp.Material(ambient=(0, 0, 0), diffuse=(0, 0, 0), specular=(1, 1, 1), shininess=shininess)
    # Rotate so the eye direction is +Z (the infinite viewer's v = (0, 0, 1)).
    z = unit(to_eye)
    x = unit(np.cross([0.31, 0.95, 0.02], z))
    rot = np.stack([x, np.cross(z, x), z])
    lights = bp.lights_in_eye_space([bp.DirectionalLight(-(rot @ unit(to_light)))], np.eye(4))
    terms = bp.shade(
        np.zeros((1, 3)),
        (rot @ unit(normal))[None],
        mat,
        lights,
        global_ambient=(0, 0, 0),
        model=bp.LightModel(specular=specular, local_viewer=False),
    )
    return float(terms.specular[0, 0])


def test_phong_and_blinn_specular_obey_the_half_angle_relation() -> None:
    # With n, l, v coplanar the angle between r and v is twice the angle between n and h:
    # r·v = cos 2θ = 2(n·h)² - 1, so phong(s) = (2 (n·h)² - 1)^s exactly.
    for _ in range(50):
        n = unit(RNG.normal(size=3))
        tangent = unit(np.cross(n, RNG.normal(size=3)))
        a, b = RNG.uniform(0.05, 1.4, 2)
        to_light = np.cos(a) * n + np.sin(a) * tangent
        to_eye = np.cos(b) * n - np.sin(b) * tangent
        s = float(RNG.uniform(1, 60))
        n_dot_h = np.dot(n, unit(to_light + to_eye))
        r_dot_v = 2 * n_dot_h**2 - 1
        assert _shade_one(n, to_light, to_eye, s, "blinn") == pytest.approx(n_dot_h**s, rel=1e-9, abs=1e-300)
        assert _shade_one(n, to_light, to_eye, s, "phong") == pytest.approx(
            max(r_dot_v, 0) ** s, rel=1e-9, abs=1e-12
        )


def _half_max_angle(specular: str, exponent: float) -> float:
    """Angle θ between n and h (radians) at which the specular term first drops below 1/2."""
    n = np.array([0, 0, 1.0])
    to_light = np.array([np.sin(0.3), 0, np.cos(0.3)])
    for t in np.radians(np.linspace(0, 30, 3001)):
        # Move the eye away from the mirror direction by 2t: the angle between n and h is t.
        eye_angle = -0.3 + 2 * t
        to_eye = np.array([np.sin(eye_angle), 0, np.cos(eye_angle)])
        if _shade_one(n, to_light, to_eye, exponent, specular) < 0.5:
            return float(t)
    raise AssertionError("no half-maximum within 30 degrees")


@pytest.mark.parametrize("s", [20.0, 80.0])
def test_blinn_with_four_times_the_exponent_matches_phong_highlight_width(s: float) -> None:
    # Near the peak cos(2θ)^s ≈ exp(-2sθ²) and cos(θ)^(4s) ≈ exp(-2sθ²): the half-maximum angles
    # of Phong(s) and Blinn(4s) agree to second order (exact as s → ∞), while Blinn(s) is twice as wide.
    phong = _half_max_angle("phong", s)
    assert phong == pytest.approx(_half_max_angle("blinn", 4 * s), rel=0.02)
    assert _half_max_angle("blinn", s) == pytest.approx(2 * phong, rel=0.02)


def test_visibility_scales_only_diffuse_and_specular_per_light() -> None:
    pts = RNG.normal(size=(20, 3)) - [0, 0, 5]
    nrm = unit(RNG.normal(size=(20, 3)) + np.array([0, 0, 2.0]))
    mat = bp.Material(
        ambient=(0.3, 0.2, 0.1), diffuse=(0.6, 0.6, 0.6), specular=(0.5, 0.5, 0.5), shininess=12.0
    )
    lights = bp.lights_in_eye_space(
        [bp.DirectionalLight((0, -1, -1), ambient=(0.1, 0.1, 0.1)), bp.PointLight((1, 2, 0), quadratic=0.1)],
        np.eye(4),
    )
    vis = RNG.uniform(0, 1, (20, 2))
    full = bp.shade(pts, nrm, mat, lights, per_light=True)
    shadowed = bp.shade(pts, nrm, mat, lights, visibility=vis)
    np.testing.assert_allclose(shadowed.ambient, full.ambient)
    np.testing.assert_allclose(shadowed.diffuse, np.einsum("nlc,nl->nc", full.diffuse_per_light, vis))
    np.testing.assert_allclose(shadowed.specular, np.einsum("nlc,nl->nc", full.specular_per_light, vis))
    np.testing.assert_allclose(full.diffuse, full.diffuse_per_light.sum(axis=1))


def test_local_viewer_uses_the_true_view_vector() -> None:
    # A point off-axis: the local viewer's v = -p/|p|; the highlight value must equal (n·h)^s with that v.
    p = np.array([[1.0, 0.5, -3.0]])
    n = unit([[0.1, 0.2, 1.0]])
    to_light = unit([0.3, 0.6, 1.0])
    mat = bp.Material(ambient=(0, 0, 0), diffuse=(0, 0, 0), specular=(1, 1, 1), shininess=30.0)
    lights = bp.lights_in_eye_space([bp.DirectionalLight(-to_light)], np.eye(4))
    for local, v in ((True, unit(-p[0])), (False, np.array([0, 0, 1.0]))):
        terms = bp.shade(p, n, mat, lights, model=bp.LightModel(local_viewer=local))
        assert terms.specular[0, 0] == pytest.approx(np.dot(n[0], unit(to_light + v)) ** 30.0, rel=1e-12)


def test_two_sided_lighting_uses_flipped_normal_and_back_material() -> None:
    # Looking at the back of a plane: one-sided lighting uses the front normal (facing away,
    # light in front of it lights nothing but ambient); two-sided flips the normal and uses the
    # back material, giving ka_b·Ia + kd_b·I·(n_back·l).
    front = bp.Material(ambient=(0.1, 0.1, 0.1), diffuse=(1, 0, 0))
    back = bp.Material(ambient=(0.2, 0.2, 0.2), diffuse=(0, 0.5, 1))
    pos, tris, normals = grid_plane(2, 2, (2.4, 2.4))
    mesh = bp.Mesh(pos, tris, normals, material=front, back_material=back)
    cam = bp.Camera.orthographic(-1, 1, -1, 1, 0.1, 10, view=bp.look_at((0, 0, -5), (0, 0, 0)))
    light = bp.DirectionalLight(unit([0.2, 0.1, 1.0]))  # shines towards +z, i.e. onto the back side
    n_back_dot_l = float(np.dot([0, 0, -1], -unit([0.2, 0.1, 1.0])))
    one = bp.render(bp.Scene([mesh], [light], cam, ambient=(0.5, 0.5, 0.5)), 8, 8).rgba
    two = bp.render(
        bp.Scene([mesh], [light], cam, ambient=(0.5, 0.5, 0.5), light_model=bp.LightModel(two_sided=True)),
        8,
        8,
    ).rgba
    np.testing.assert_allclose(one[..., :3], 0.1 * 0.5, rtol=1e-6)
    expected = 0.2 * 0.5 + np.array([0, 0.5, 1]) * n_back_dot_l
    np.testing.assert_allclose(two[..., :3], np.broadcast_to(expected, (8, 8, 3)), rtol=1e-6)


def test_emission_ambient_lights_and_gl_clamp() -> None:
    mat = bp.Material(ambient=(0.5, 0.25, 1.0), diffuse=(0, 0, 0), emission=(0.1, 0.2, 0.3))
    lights = bp.lights_in_eye_space([bp.AmbientLight((1.0, 2.0, 0.5), 0.5)], np.eye(4))
    terms = bp.shade(
        np.zeros((1, 3)) - [0, 0, 1], unit([[0, 0, 1.0]]), mat, lights, global_ambient=(0.2, 0.2, 0.2)
    )
    expected = np.array([0.1, 0.2, 0.3]) + np.array([0.5, 0.25, 1.0]) * (0.2 + np.array([0.5, 1.0, 0.25]))
    np.testing.assert_allclose(terms.color[0], expected)
    hot = bp.ShadingTerms(
        np.array([[0.5, 0.2, 0.1]]), np.array([[0.7, 0.1, 0.0]]), np.array([[0.4, 1.5, 0.2]]), np.ones(1)
    )
    pri, sec = bp.gl_clamp(hot, separate_specular=True)
    np.testing.assert_allclose(pri, [[1.0, 0.3, 0.1]])
    np.testing.assert_allclose(sec, [[0.4, 1.0, 0.2]])
    pri, sec = bp.gl_clamp(hot, separate_specular=False)
    np.testing.assert_allclose(pri, [[1.0, 1.0, 0.3]])
    np.testing.assert_array_equal(sec, 0.0)

"""Snell's law, total internal reflection, a slab and a prism traced with Embree, Hall's highlight."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from blinn_phong.effects.refraction import reflect, refract, trace_refraction, transmitted_highlight
from blinn_phong.shadows.raytrace import RayScene

from .geometry import box_triangles


def direction_at(theta):
    """Unit direction travelling down (−z) at angle θ from the −z axis, tilted towards +x."""
    return np.array([math.sin(theta), 0.0, -math.cos(theta)])


@pytest.mark.parametrize("n1, n2", [(1.0, 1.5), (1.5, 1.0), (1.0, 1.333), (1.333, 2.4)])
@pytest.mark.parametrize("deg", [0.0, 10.0, 30.0, 40.0])
def test_snell_angles(n1, n2, deg):
    theta1 = math.radians(deg)
    s2 = n1 / n2 * math.sin(theta1)
    if s2 > 1:
        pytest.skip("beyond the critical angle")
    t, tir = refract(direction_at(theta1), np.array([0.0, 0.0, 1.0]), n1 / n2)
    assert not tir
    np.testing.assert_allclose(t, direction_at(math.asin(s2)), atol=1e-12)


def test_normal_orientation_does_not_matter():
    i = direction_at(0.5)
    a, _ = refract(i, np.array([0.0, 0.0, 1.0]), 1 / 1.5)
    b, _ = refract(i, np.array([0.0, 0.0, -1.0]), 1 / 1.5)
    np.testing.assert_allclose(a, b, atol=1e-15)


def test_total_internal_reflection_starts_at_the_critical_angle():
    n1, n2 = 1.5, 1.0
    critical = math.asin(n2 / n1)
    angles = np.array([critical - 1e-6, critical + 1e-6, math.radians(60), math.radians(30)])
    dirs = np.stack([direction_at(a) for a in angles])
    t, tir = refract(dirs, np.tile([0.0, 0.0, 1.0], (4, 1)), n1 / n2)
    np.testing.assert_array_equal(tir, [False, True, True, False])
    # just below the critical angle the transmitted ray grazes the surface (θ₂ → 90°)
    assert abs(t[0, 2]) < 2e-3
    # with TIR the ray is mirrored: same tangential part, z flipped
    np.testing.assert_allclose(t[2], dirs[2] * [1, 1, -1], atol=1e-12)
    np.testing.assert_allclose(reflect(dirs[2], np.array([0.0, 0, 1])), dirs[2] * [1, 1, -1], atol=1e-12)


@pytest.mark.parametrize("deg", [15.0, 35.0, 60.0])
def test_flat_slab_shifts_a_ray_parallel_to_itself(deg):
    thickness, n_glass = 0.8, 1.5
    scene = RayScene(box_triangles((-50, -50, -thickness), (50, 50, 0.0)))
    theta1 = math.radians(deg)
    d = direction_at(theta1)
    origin = np.array([0.0, 0.0, 2.0])
    out = trace_refraction(scene, origin[None], d[None], n_glass, max_bounces=4)
    assert out.bounces[0] == 2 and out.escaped[0] and out.tir_count[0] == 0
    np.testing.assert_allclose(out.directions[0], d, atol=1e-6)
    # perpendicular distance between the incoming line and the outgoing line
    w = out.origins[0] - origin
    shift = np.linalg.norm(w - (w @ d) * d)
    theta2 = math.asin(math.sin(theta1) / n_glass)
    expected = thickness * math.sin(theta1 - theta2) / math.cos(theta2)
    assert shift == pytest.approx(expected, rel=1e-4)


def test_prism_deviation_matches_the_closed_form():
    # Right prism with apex angle A = 60° (equilateral cross-section in x-z, extruded in y).
    # Minimum deviation: n = sin((A + δ)/2)/sin(A/2) → δ = 2·asin(n·sin(A/2)) − A, reached
    # by the ray that crosses the prism parallel to its base.
    n_glass, A = 1.5, math.radians(60.0)
    s = 1.0
    p0, p1, p2 = np.array([-s, 0.0]), np.array([s, 0.0]), np.array([0.0, s * math.sqrt(3)])
    ys = (-20.0, 20.0)

    def v(p, y):
        return np.array([p[0], y, p[1]])

    tris = []
    for a, b in ((p0, p1), (p1, p2), (p2, p0)):
        tris.append([v(a, ys[0]), v(b, ys[0]), v(b, ys[1])])
        tris.append([v(a, ys[0]), v(b, ys[1]), v(a, ys[1])])
    tris.append([v(p0, ys[0]), v(p2, ys[0]), v(p1, ys[0])])
    tris.append([v(p0, ys[1]), v(p1, ys[1]), v(p2, ys[1])])
    scene = RayScene(np.array(tris)[:, ::-1])  # reversed corners: outward winding
    assert np.all(np.einsum("ij,ij->i", scene.normals, scene.triangles.mean(axis=1) - [0, 0, 0.5]) > 0)
    delta = 2 * math.asin(n_glass * math.sin(A / 2)) - A
    theta_in = (A + delta) / 2  # incidence angle on the left face at minimum deviation
    left_normal = np.array([-math.cos(math.pi / 6), 0.0, 0.5])  # outward normal of the face p2–p0
    # incoming direction: rotate −left_normal by θ_in towards the base (downwards)
    inward = -left_normal
    down = np.array([0.0, 0.0, -1.0])
    tangent = down - (down @ inward) * inward
    tangent /= np.linalg.norm(tangent)
    d = math.cos(theta_in) * inward + math.sin(theta_in) * tangent
    hit_point = (p0 + p2) / 2
    origin = np.array([hit_point[0], 0.0, hit_point[1]]) - 3.0 * d
    out = trace_refraction(scene, origin[None], d[None], n_glass, max_bounces=3)
    assert out.bounces[0] == 2 and out.escaped[0]
    angle = math.acos(np.clip(out.directions[0] @ d, -1, 1))
    assert angle == pytest.approx(delta, rel=1e-5)


def test_hall_transmitted_highlight_peaks_on_the_snell_direction():
    n_air, n_glass = 1.0, 1.5
    normal = np.array([0.0, 0.0, 1.0])  # viewer above in air, light below in glass
    theta_light = math.radians(25.0)
    to_light = -direction_at(theta_light) * [-1, 1, 1]  # below the surface, tilted to −x
    # the light's ray travels along −to_light; refracted into the air it goes along Snell's direction
    t, tir = refract(-to_light, normal, n_glass / n_air)
    assert not tir
    peak = transmitted_highlight(
        normal, to_light, t, eta_light_side=n_glass, eta_viewer_side=n_air, shininess=50.0
    )
    assert peak == pytest.approx(1.0, abs=1e-12)
    # moving the viewer off the refracted direction lowers the highlight monotonically
    offs = []
    for k in (0.05, 0.1, 0.2):
        v = t + np.array([k, 0.0, 0.0])
        offs.append(
            transmitted_highlight(
                normal, to_light, v, eta_light_side=n_glass, eta_viewer_side=n_air, shininess=50.0
            )
        )
    assert 1.0 > offs[0] > offs[1] > offs[2] > 0.0
    # viewer on the light's side: no transmitted highlight
    same_side = transmitted_highlight(
        normal, to_light, -t, eta_light_side=n_glass, eta_viewer_side=n_air, shininess=50.0
    )
    assert same_side == 0.0


def test_refract_rejects_bad_eta_and_zero_vectors():
    with pytest.raises(ValueError, match="eta"):
        refract(np.array([0, 0, -1.0]), np.array([0, 0, 1.0]), -1.0)
    with pytest.raises(ValueError, match="incident"):
        refract(np.zeros(3), np.array([0, 0, 1.0]), 1.0)


@settings(max_examples=200, deadline=None)
@given(
    theta=st.floats(0.0, 1.55),
    phi=st.floats(0.0, 6.28),
    eta=st.floats(0.3, 3.0),
)
def test_refraction_obeys_snell_in_the_plane_of_incidence(theta, phi, eta):
    n = np.array([0.0, 0.0, 1.0])
    i = np.array([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), -np.cos(theta)])
    t, tir = refract(i, n, eta)
    assert abs(np.linalg.norm(t) - 1) < 1e-12
    s1 = np.sin(theta)
    if eta * s1 > 1 + 1e-12:
        assert tir
        np.testing.assert_allclose(t, i * [1, 1, -1], atol=1e-12)  # mirrored
    elif eta * s1 < 1 - 1e-12:
        assert not tir
        # η sin θ₁ = sin θ₂, same side of the tangent plane as the incident ray continues
        assert np.hypot(t[0], t[1]) == pytest.approx(eta * s1, abs=1e-9)
        assert t[2] <= 0
        # coplanar with the incident ray and the normal
        assert abs(np.dot(np.cross(i, n), t)) < 1e-9

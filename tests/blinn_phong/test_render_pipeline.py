"""The render pipeline: buffers, supersampled coverage, passes, errors, normals and cameras."""

from __future__ import annotations

import numpy as np
import pytest

import blinn_phong as bp
from blinn_phong.geometry.normals import face_normals, transform_normals, vertex_normals
from blinn_phong.model.primitives import grid_plane, uv_sphere


def pixel_camera(width: int, height: int, near: float = 1.0, far: float = 5.0) -> bp.Camera:
    """Orthographic camera with one world unit per pixel, x right, y up, looking down -Z from z = 0."""
    return bp.Camera.orthographic(0, width, 0, height, near, far)


def rectangle(x0: float, x1: float, y0: float, y1: float, z: float, material: bp.Material) -> bp.Mesh:
    pos = np.array([[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]], float)
    return bp.Mesh(pos, np.array([[0, 1, 2], [0, 2, 3]]), np.tile([0, 0, 1.0], (4, 1)), material=material)


EMISSIVE = bp.Material(ambient=(0, 0, 0), diffuse=(0, 0, 0), emission=(0.8, 0.4, 0.2))


@pytest.mark.parametrize("k", [1, 2, 4])
def test_supersampled_coverage_alpha_counts_samples_left_of_an_edge(k: int) -> None:
    # Right edge at x = 5.3 px: in column 5 the k sample columns sit at 5 + (i + 0.5)/k, and
    # those left of 5.3 are covered, so alpha = #{i : (i + 0.5)/k < 0.3} / k; the rgb stays
    # premultiplied: rgb = alpha · emission.
    w, h = 10, 6
    scene = bp.Scene([rectangle(-1, 5.3, -1, h + 1, -2, EMISSIVE)], [], pixel_camera(w, h), ambient=(0, 0, 0))
    img = bp.render(scene, w, h, samples=k * k).rgba
    expected_col5 = np.count_nonzero((np.arange(k) + 0.5) / k < 0.3) / k
    expected = np.array([1, 1, 1, 1, 1, expected_col5, 0, 0, 0, 0], float)
    np.testing.assert_allclose(img[..., 3], np.broadcast_to(expected, (h, w)))
    np.testing.assert_allclose(img[..., :3], img[..., 3:] * np.array([0.8, 0.4, 0.2]), rtol=1e-6)


def test_opacity_is_premultiplied_and_depth_normal_buffers_are_closed_form() -> None:
    w, h = 8, 8
    mat = bp.Material(ambient=(0, 0, 0), diffuse=(0, 0, 0), emission=(0.5, 1.0, 0.25), opacity=0.4)
    # A rectangle at eye depth 2 (z = -2) in a glOrtho(near 1, far 5) camera: window depth (2 - 1)/(5 - 1).
    scene = bp.Scene([rectangle(2, 6, 2, 6, -2, mat)], [], pixel_camera(w, h), ambient=(0, 0, 0))
    res = bp.render(scene, w, h)
    inside = np.zeros((h, w), bool)
    inside[2:6, 2:6] = True
    np.testing.assert_allclose(res.rgba[inside], np.array([0.2, 0.4, 0.1, 0.4]) * np.ones((16, 4)), rtol=1e-6)
    np.testing.assert_array_equal(res.rgba[~inside], 0.0)
    np.testing.assert_allclose(res.depth[inside], 0.25, rtol=1e-6)
    np.testing.assert_array_equal(res.depth[~inside], 1.0)
    np.testing.assert_allclose(res.normal[inside], np.tile([0, 0, 1.0], (16, 1)), atol=1e-7)
    np.testing.assert_array_equal(res.normal[~inside], 0.0)
    assert res.rgba.dtype == np.float32 and res.depth.dtype == np.float32


def test_normal_buffer_is_world_space_and_passes_sum_to_colour() -> None:
    pos, tris, normals = uv_sphere(24, 12)
    rot = np.array([[0, -1, 0, 0], [1, 0, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], float)  # 90° about Z
    mat = bp.Material(emission=(0.05, 0.0, 0.0), specular=(0.5, 0.5, 0.5), shininess=20.0)
    mesh = bp.Mesh(pos, tris, normals, transform=rot, material=mat)
    cam = bp.Camera.perspective(40, 1, 1, 10, view=bp.look_at((0, 0, 4), (0, 0, 0)))
    scene = bp.Scene([mesh], [bp.DirectionalLight((-1, -1, -1)), bp.PointLight((2, 1, 2))], cam)
    res = bp.render(scene, 48, 48, samples=4)
    total = res.passes["ambient"] + res.passes["diffuse"] + res.passes["specular"]
    np.testing.assert_allclose(total, res.rgba[..., :3], rtol=1e-5, atol=1e-7)
    # The sphere's world normal at a pixel is its world position's direction: check the centre pixel.
    centre = res.normal[24, 24]
    np.testing.assert_allclose(centre, [0.0, 0.0, 1.0], atol=0.05)
    covered = res.rgba[..., 3] > 0
    np.testing.assert_allclose(np.linalg.norm(res.normal[covered], axis=-1), 1.0, atol=1e-5)


@pytest.mark.parametrize("engine", ["numpy", "numba"])
def test_progress_is_reported_in_order_and_stats_are_filled(engine: str) -> None:
    calls: list[tuple[str, float]] = []
    scene = bp.Scene([rectangle(1, 7, 1, 7, -2, EMISSIVE)], [], pixel_camera(8, 8))
    res = bp.render(scene, 8, 8, engine=engine, progress=lambda stage, f: calls.append((stage, f)))
    fractions = [f for _, f in calls]
    assert fractions == sorted(fractions) and fractions[-1] == 1.0
    assert {"prepare", "visibility", "shade"} <= {stage for stage, _ in calls}
    assert res.stats.triangles == 2 and res.stats.shaded == 36
    assert set(res.stats.seconds) >= {"visibility", "shade", "resolve_samples"}


def test_per_mesh_shading_overrides_the_render_setting() -> None:
    pos, tris, normals = uv_sphere(12, 6)
    mat = bp.Material(specular=(1, 1, 1), shininess=30.0)
    cam = bp.Camera.perspective(40, 1, 1, 10, view=bp.look_at((0, 0, 4), (0, 0, 0)))
    lights = [bp.DirectionalLight((-1, -1, -1))]
    flat_mesh = bp.Mesh(pos, tris, normals, material=mat, shading="flat")
    a = bp.render(bp.Scene([flat_mesh], lights, cam), 32, 32, shading="phong").rgba
    b = bp.render(
        bp.Scene([bp.Mesh(pos, tris, normals, material=mat)], lights, cam), 32, 32, shading="flat"
    ).rgba
    # bitwise: the same flat shading arithmetic on the same inputs, deterministic by construction
    np.testing.assert_array_equal(a, b)


def test_degenerate_triangles_and_zero_normals_give_finite_pixels() -> None:
    pos = np.array([[0, 0, -2], [4, 0, -2], [0, 4, -2], [2, 2, -2], [2, 2, -2], [6, 6, -2]], float)
    tris = np.array([[0, 1, 2], [3, 4, 5], [0, 0, 1]])  # a real one, a collinear one, a repeated-index one
    normals = np.zeros((6, 3))  # zero-length normals everywhere
    mesh = bp.Mesh(pos, tris, normals, material=bp.Material(specular=(1, 1, 1), shininess=10.0))
    scene = bp.Scene([mesh], [bp.PointLight((2, 2, 0)), bp.DirectionalLight((0, 0, -1))], pixel_camera(8, 8))
    for shading in ("flat", "gouraud", "phong"):
        res = bp.render(scene, 8, 8, shading=shading, samples=4)
        assert np.isfinite(res.rgba).all() and np.isfinite(res.normal).all() and np.isfinite(res.depth).all()
        covered = res.rgba[..., 3] == 1
        assert covered.sum() == 6  # pixels whose 4 samples (offsets 0.25, 0.75) all satisfy x + y < 4
        if shading != "flat":  # flat uses the (valid) face normal instead of the vertex normals
            # Zero normals: ambient only, a_cm · a_cs = 0.2 · 0.2, where covered.
            np.testing.assert_allclose(res.rgba[covered][:, :3], 0.04, rtol=1e-6)


def test_bad_scenes_are_rejected_with_clear_messages() -> None:
    pos, tris, _ = grid_plane(1, 1)
    cam = pixel_camera(4, 4)
    with pytest.raises(ValueError, match="camera"):
        bp.Scene([bp.Mesh(pos, tris)], [], None)
    with pytest.raises(ValueError, match=r"Mesh.positions.*NaN"):
        bp.Mesh(np.where(np.arange(12).reshape(4, 3) == 5, np.nan, pos), tris)
    with pytest.raises(ValueError, match=r"Mesh.triangles.*\[0, 3\]"):
        bp.Mesh(pos, tris + 1)
    with pytest.raises(ValueError, match=r"PointLight\.linear"):
        bp.PointLight((0, 0, 1), linear=-0.1)
    with pytest.raises(ValueError, match=r"SpotLight\.quadratic"):
        bp.SpotLight(quadratic=-1.0)
    with pytest.raises(ValueError, match="all be 0"):
        bp.PointLight(constant=0.0)
    with pytest.raises(ValueError, match="near"):
        bp.Camera.perspective(45, 1, 0.0, 10)
    with pytest.raises(ValueError, match="near"):
        bp.Camera.perspective(45, 1, -1.0, 10)
    with pytest.raises(ValueError, match="cutoff"):
        bp.SpotLight(cutoff=120.0)
    with pytest.raises(ValueError, match="shading"):
        bp.render(bp.Scene([bp.Mesh(pos, tris)], [], cam), 4, 4, shading="toon")
    glossy = bp.Mesh(pos, tris, material=bp.Material(shininess=200.0))
    with pytest.raises(ValueError, match=r"shininess: OpenGL accepts \[0, 128\]"):
        bp.render(bp.Scene([glossy], [], cam), 4, 4, gl_compat=True)
    with pytest.raises(ValueError, match="engine"):
        bp.render(bp.Scene([bp.Mesh(pos, tris)], [], cam), 4, 4, engine="cuda")
    with pytest.raises(TypeError, match=r"Scene\.lights"):
        bp.Scene([bp.Mesh(pos, tris)], ["sun"], cam)


def test_vertex_normal_weighting_area_versus_angle() -> None:
    # A vertex shared by a large triangle in the z = 0 plane (normal +Z, angle 90°) and a small
    # triangle in the x = 0 plane (normal +X, angle 90°): angle weighting gives equal weights,
    # area weighting favours the large face by the area ratio (here 16 : 1).
    pos = np.array([[0, 0, 0], [4, 0, 0], [0, 4, 0], [0, 1, 0], [0, 0, 1]], float)
    tris = np.array([[0, 1, 2], [0, 3, 4]])
    by_angle = vertex_normals(pos, tris, "angle")[0]
    by_area = vertex_normals(pos, tris, "area")[0]
    np.testing.assert_allclose(by_angle, np.array([1, 0, 1]) / np.sqrt(2), atol=1e-12)
    np.testing.assert_allclose(by_area, np.array([1, 0, 16]) / np.sqrt(257), atol=1e-12)
    np.testing.assert_array_equal(face_normals(np.zeros((3, 3)), np.array([[0, 1, 2]])), 0.0)


def test_inverse_transpose_keeps_normals_perpendicular_under_non_uniform_scale() -> None:
    rng = np.random.default_rng(3)
    m = np.eye(4)
    m[:3, :3] = np.diag([3.0, 0.5, 1.7]) @ np.linalg.qr(rng.normal(size=(3, 3)))[0]
    for _ in range(20):
        n = rng.normal(size=3)
        t = np.cross(n, rng.normal(size=3))  # a tangent: n · t = 0
        n_world = transform_normals(n[None], m)[0]
        assert abs(np.dot(n_world, m[:3, :3] @ t)) < 1e-12 * np.linalg.norm(t) * 10
        assert np.linalg.norm(n_world) == pytest.approx(1.0)


def test_cameras_follow_the_glu_and_gl_formulas() -> None:
    view = bp.look_at((1, 2, 3), (4, 0, -1), (0, 1, 0))
    np.testing.assert_allclose(view @ [1, 2, 3, 1], [0, 0, 0, 1], atol=1e-12)
    target_eye = view @ [4, 0, -1, 1]
    np.testing.assert_allclose(target_eye[:2], 0, atol=1e-12)
    assert target_eye[2] == pytest.approx(-np.sqrt(9 + 4 + 16))
    # gluPerspective: a point on the near plane at the top of the field of view maps to ndc (0, 1, -1).
    near, far, fov = 0.5, 10.0, 50.0
    proj = bp.perspective_matrix(fov, 2.0, near, far)
    p = proj @ [0, near * np.tan(np.radians(fov / 2)), -near, 1]
    np.testing.assert_allclose(p[:3] / p[3], [0, 1, -1], atol=1e-12)
    p = proj @ [2 * far * np.tan(np.radians(fov / 2)), 0, -far, 1]
    np.testing.assert_allclose(p[:3] / p[3], [1, 0, 1], atol=1e-12)
    ortho = bp.orthographic_matrix(-2, 6, -1, 3, 1, 9)
    np.testing.assert_allclose(ortho @ [6, -1, -9, 1], [1, -1, 1, 1], atol=1e-12)
    np.testing.assert_allclose(ortho @ [-2, 3, -1, 1], [-1, 1, -1, 1], atol=1e-12)

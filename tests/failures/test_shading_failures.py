"""Where shading fails: Gouraud inside large triangles, Mach bands, huge shininess, grazing light, spot cones.

References are closed forms: the lighting equation (OpenGL 2.1 §2.14.1, Blinn's half vector)
evaluated with the exact normal at each pixel centre, written out here in numpy. The failing
method's error must exceed a bound derived in the comments, the robust method's must stay
under one, and no image may hold NaN or Inf. Errors are in 8-bit steps.
"""

from __future__ import annotations

import numpy as np

import blinn_phong as bp
from blinn_phong.model.primitives import grid_plane, uv_sphere
from testbeds.error_metrics import error_metrics, has_nonfinite

TOP = bp.look_at((0.0, 0.0, 5.0), (0.0, 0.0, 0.0))
DISTANT_VIEWER = bp.LightModel(local_viewer=False)


def _centres(size: int, half: float) -> tuple[np.ndarray, np.ndarray]:
    """World x, y of pixel centres for an orthographic camera spanning [−half, half]², row 0 at the top."""
    c = (np.arange(size) + 0.5) / size * 2 * half - half
    x, y = np.meshgrid(c, -c)
    return x, y


def _render(scene: bp.Scene, size: int, shading: str) -> bp.RenderResult:
    result = bp.render(scene, size, size, shading=shading)
    assert not has_nonfinite(result.rgba, *result.passes.values())
    return result


def _plane_scene(material: bp.Material, light: object) -> bp.Scene:
    pos, tris, normals = grid_plane(1, 1, (2.4, 2.4))  # two triangles, corners at ±1.2
    camera = bp.Camera.orthographic(-1, 1, -1, 1, 0.1, 10, view=TOP)
    return bp.Scene(
        [bp.Mesh(pos, tris, normals, material=material)],
        [light],
        camera,
        ambient=(0, 0, 0),
        light_model=DISTANT_VIEWER,
    )


def test_gouraud_misses_a_highlight_inside_a_large_triangle() -> None:
    size, s = 65, 60.0
    material = bp.Material(ambient=(0, 0, 0), diffuse=(0, 0, 0), specular=(1, 1, 1), shininess=s)
    scene = _plane_scene(material, bp.PointLight((0.0, 0.0, 0.3)))
    x, y = _centres(size, 1.0)
    to_light = np.stack([-x, -y, np.full_like(x, 0.3)], -1)
    to_light /= np.linalg.norm(to_light, axis=-1, keepdims=True)
    h = to_light + np.array([0.0, 0.0, 1.0])  # distant viewer: v = +z
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    exact = h[..., 2] ** s  # n = +z, n·l > 0 everywhere
    phong = _render(scene, size, "phong").passes["specular"][..., 0]
    gouraud = _render(scene, size, "gouraud").passes["specular"][..., 0]
    assert error_metrics(phong, exact)["max_steps"] < 1.0
    # Closed form: at the corners (±1.2, ±1.2) n·h = cos(½·atan(1.2·√2/0.3)) ≈ 0.59, and 0.59⁶⁰ < 1e-13;
    # Gouraud interpolates those vertex values, so it shows nothing where the exact peak is 1
    # (the centre pixel lies under the light): error ≥ 255·(1 − 1e-13) steps.
    assert error_metrics(gouraud, exact)["max_steps"] > 254.0


def test_spot_cone_inside_a_large_triangle_vanishes_with_gouraud() -> None:
    size, cutoff = 65, 20.0
    material = bp.Material(ambient=(0, 0, 0), diffuse=(1, 1, 1), specular=(0, 0, 0))
    spot = bp.SpotLight((0.0, 0.0, 1.0), (0.0, 0.0, -1.0), cutoff=cutoff, exponent=0.0)
    scene = _plane_scene(material, spot)
    x, y = _centres(size, 1.0)
    to_light = np.stack([-x, -y, np.ones_like(x)], -1)
    to_light /= np.linalg.norm(to_light, axis=-1, keepdims=True)
    inside = to_light[..., 2] >= np.cos(np.radians(cutoff))  # angle to the spot axis ≤ cut-off
    exact = np.where(inside, to_light[..., 2], 0.0)  # n·l, spot factor cos⁰ = 1 inside, 0 outside
    phong = _render(scene, size, "phong").passes["diffuse"][..., 0]
    gouraud = _render(scene, size, "gouraud").passes["diffuse"][..., 0]
    assert error_metrics(phong, exact)["max_steps"] < 1.0
    # Every vertex is atan(1.2·√2) = 59° off the axis, outside the 20° cone: each vertex gets 0
    # and so does every Gouraud pixel, where the exact centre pixel gets n·l ≈ 1: > 250 steps.
    assert error_metrics(gouraud, exact)["max_steps"] > 250.0
    # The cone's edge is a step of the spot factor: across it neighbouring exact pixels jump by
    # n·l ≈ cos 20° = 0.94, which per-pixel shading reproduces (an edge no shading frequency can smooth).
    jump = np.abs(np.diff(phong, axis=1)).max()
    assert jump > 0.9 * np.cos(np.radians(cutoff))


def _sphere_scene(segments: int, material: bp.Material, light: object) -> bp.Scene:
    pos, tris, normals = uv_sphere(segments, segments // 2)
    camera = bp.Camera.orthographic(-1.2, 1.2, -1.2, 1.2, 0.1, 10, view=TOP)
    return bp.Scene(
        [bp.Mesh(pos, tris, normals, material=material)],
        [light],
        camera,
        ambient=(0, 0, 0),
        light_model=DISTANT_VIEWER,
    )


def test_flat_shading_shows_mach_bands_where_phong_is_smooth() -> None:
    size = 160
    material = bp.Material(ambient=(0, 0, 0), diffuse=(1, 1, 1), specular=(0, 0, 0))
    scene = _sphere_scene(16, material, bp.DirectionalLight((-1.0, 0.0, -1.0)))  # l = (1, 0, 1)/√2
    x, y = _centres(size, 1.2)
    window = (np.abs(x) < 0.5) & (np.abs(y) < 0.3)
    window = window[:, 1:] & window[:, :-1]
    steps = {}
    for shading in ("flat", "phong"):
        img = _render(scene, size, shading).rgba[..., 0]
        steps[shading] = 255 * np.abs(np.diff(img, axis=1))[window].max()
    # Flat: across an edge between faces at azimuths φ ± 11.25° (16 segments) n·l = cos β·cos(φ − 45°)
    # jumps by cos β·2·sin(|45° − φ|)·sin(11.25°). Within |x| < 0.5 some edge has |φ| ≤ 11.25°, and
    # faces touching the equator have cos β ≥ cos 22.5°: a jump ≥ 0.924·2·sin(33.75°)·sin(11.25°)
    # = 0.200, i.e. > 50 steps between two neighbouring pixels — a visible band.
    assert steps["flat"] > 50.0
    # Exact: ∂(n·l)/∂x = (1 − x/z)/√2 ≤ (1 + 0.5/0.81)/√2 = 1.14 in this window, times the pixel
    # size 0.015: 4.4 steps; Phong's interpolated normal is continuous and deviates from the
    # exact one by at most Δφ²/8 = 0.019 rad on either side: ≤ 4.4 + 2·0.019·255 ≈ 14 steps.
    assert steps["phong"] < 14.0


def test_huge_shininess_highlight_is_lost_between_vertices() -> None:
    size, s, segments = 256, 5000.0, 64
    material = bp.Material(ambient=(0, 0, 0), diffuse=(0, 0, 0), specular=(1, 1, 1), shininess=s)
    light = bp.DirectionalLight((-0.21, -0.13, -1.0))
    scene = _sphere_scene(segments, material, light)
    to_light = -np.asarray(light.direction) / np.linalg.norm(light.direction)
    h = to_light + np.array([0.0, 0.0, 1.0])
    h /= np.linalg.norm(h)
    _, _, normals = uv_sphere(segments, segments // 2)
    vertex_peak = float(np.max(np.clip(normals @ h, 0, None) ** s))
    phong = _render(scene, size, "phong").passes["specular"][..., 0]
    gouraud = _render(scene, size, "gouraud").passes["specular"][..., 0]
    # Gouraud interpolates vertex colours with convex weights: it can never exceed the largest
    # vertex value (n_v·h)^s, which is tiny when h falls between vertices.
    assert float(gouraud.max()) <= vertex_peak + 1e-9
    # The exact peak (n = h) lies within half a pixel diagonal (0.0066) of a pixel centre: an angle
    # ≤ 0.0066/h_z, plus Phong's normal interpolation error ≤ Δφ²/8 = 0.0012 rad: ≤ 0.0081 rad, and
    # cos(0.0081)^5000 ≥ exp(−5000·0.0081²/2) = 0.85.
    assert float(phong.max()) > 0.85
    # So Gouraud is off by at least 255·(0.85 − vertex_peak) at the highlight.
    assert vertex_peak < 0.1
    assert 255 * (float(phong.max()) - float(gouraud.max())) > 255 * (0.85 - 0.1)


def test_grazing_light_gives_blinn_phong_a_hard_terminator() -> None:
    size = 160
    jumps = {}
    for s in (4.0, 64.0):
        material = bp.Material(ambient=(0, 0, 0), diffuse=(0, 0, 0), specular=(1, 1, 1), shininess=s)
        scene = _sphere_scene(128, material, bp.DirectionalLight((-1.0, 0.0, 0.0)))  # l = +x, v = +z
        spec = _render(scene, size, "phong").passes["specular"][..., 0]
        rows = slice(size // 2 - 8, size // 2 + 8)  # |y| < 0.12
        # the two columns on either side of the terminator x = 0 (centres at x = ∓0.0075)
        jumps[s] = 255 * np.abs(spec[rows, size // 2] - spec[rows, size // 2 - 1]).max()
    # On the terminator n·l → 0⁺ while n·h = (n_x + n_z)/√2 → n_z/√2: the specular term drops from
    # (n_z/√2)^s to 0 (OpenGL gates it on n·l > 0) between the two pixels astride x = 0. With
    # |y| < 0.12, n_z > 0.99: for s = 4 a jump ≥ 0.99⁴/4 = 0.24 = 61 steps; for s = 64 it is
    # ≤ 2^-32: far below a step.
    assert jumps[4.0] > 60.0
    assert jumps[64.0] < 1.0

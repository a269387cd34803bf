"""Flat, Gouraud and Phong shading differ where the theory says (Gouraud 1971; Phong 1975).

References are closed forms: the lighting equation evaluated with the exact
surface normal at each pixel (an analytic plane, an analytic ray-cast sphere).
"""

from __future__ import annotations

import numpy as np
import pytest

import blinn_phong as bp
from blinn_phong.model.primitives import grid_plane, uv_sphere

SHINY = bp.Material(ambient=(0, 0, 0), diffuse=(0.3, 0.3, 0.3), specular=(1, 1, 1), shininess=60.0)


def test_highlight_inside_a_large_triangle_is_missed_by_gouraud_and_caught_by_phong() -> None:
    # Two triangles span [-1.2, 1.2]²; a point light 0.3 above the centre puts the highlight
    # (n = h, here the point under the light for an overhead viewer) far from every vertex.
    pos, tris, normals = grid_plane(1, 1, (2.4, 2.4))
    light = bp.PointLight((0.0, 0.0, 0.3))
    cam = bp.Camera.orthographic(-1, 1, -1, 1, 0.1, 10, view=bp.look_at((0, 0, 5), (0, 0, 0)))
    scene = bp.Scene(
        [bp.Mesh(pos, tris, normals, material=SHINY)],
        [light],
        cam,
        ambient=(0, 0, 0),
        light_model=bp.LightModel(local_viewer=False),
    )
    peaks = {}
    for shading in ("flat", "gouraud", "phong"):
        spec = bp.render(scene, 65, 65, shading=shading).passes["specular"][..., 0]
        peaks[shading] = float(spec.max())
    # Closed form at the pixel under the light (pixel 32's centre is exactly x = y = 0): l = v = n, spec = 1.
    assert peaks["phong"] == pytest.approx(1.0, abs=1e-6)
    # At the corners l·n = 0.3/sqrt(0.3² + 2·1.2²) ≈ 0.17; (n·h)^60 there is ~1e-12: Gouraud sees nothing.
    assert peaks["gouraud"] < 1e-6
    # Flat: one evaluation at each triangle's centroid (offset 0.4·√2 from the light): also far below.
    assert peaks["flat"] < 1e-3


def _exact_sphere_reference(width: int, light_dir: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Ray-cast unit sphere, orthographic along -Z, lit per pixel with the exact normal (closed form)."""
    c = (np.arange(width) + 0.5) / width * 2.4 - 1.2
    x, y = np.meshgrid(c, -c)
    inside = x**2 + y**2 < 1.0
    z = np.sqrt(np.maximum(1 - x**2 - y**2, 0))
    n = np.stack([x, y, z], -1)[inside]
    lights = bp.lights_in_eye_space([bp.DirectionalLight(light_dir)], bp.look_at((0, 0, 5), (0, 0, 0)))
    pts = n - np.array([0, 0, 5.0])
    terms = bp.shade(pts, n, SHINY, lights, global_ambient=(0, 0, 0), model=bp.LightModel(local_viewer=False))
    ref = np.zeros((width, width))
    ref[inside] = terms.color[:, 0]
    return ref, inside


def test_error_against_exact_sphere_orders_flat_gouraud_phong_and_falls_with_tessellation() -> None:
    width = 160
    light_dir = np.array([-0.5, -0.6, -1.0])
    ref, inside = _exact_sphere_reference(width, light_dir)
    # Compare where the tessellated and the exact sphere both cover (interior of the disc).
    radius_px = ((np.indices(ref.shape) + 0.5 - width / 2) ** 2).sum(0) ** 0.5
    core = inside & (radius_px < 0.9 * width / 2.4)
    cam = bp.Camera.orthographic(-1.2, 1.2, -1.2, 1.2, 0.1, 10, view=bp.look_at((0, 0, 5), (0, 0, 0)))
    errors: dict[tuple[str, int], float] = {}
    for segments in (16, 64):
        pos, tris, normals = uv_sphere(segments, segments // 2)
        scene = bp.Scene(
            [bp.Mesh(pos, tris, normals, material=SHINY)],
            [bp.DirectionalLight(light_dir)],
            cam,
            ambient=(0, 0, 0),
            light_model=bp.LightModel(local_viewer=False),
        )
        for shading in ("flat", "gouraud", "phong"):
            img = bp.render(scene, width, width, shading=shading).rgba[..., 0]
            errors[shading, segments] = float(np.abs(img - ref)[core].mean())
    for segments in (16, 64):
        assert errors["phong", segments] < errors["gouraud", segments] < errors["flat", segments]
    for shading in ("flat", "gouraud", "phong"):
        assert errors[shading, 64] < errors[shading, 16] / 2
    # Phong's error at 64 segments is dominated by the polygonal silhouette/normal interpolation: small.
    assert errors["phong", 64] < 1e-3

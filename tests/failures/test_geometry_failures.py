"""Where geometry breaks formulas: degenerate triangles and total internal reflection.

Degenerate (zero-area) triangles have no normal: the textbook ``n/|n|`` divides by zero. Past
the critical angle Snell's law has no real solution: the textbook ``sqrt(1 − η²(1 − cos²θ))``
takes the root of a negative number, and a renderer that treats the surface as alpha
transparency keeps showing what lies behind it. The robust methods must give the closed-form
answers; no output may hold NaN or Inf.
"""

from __future__ import annotations

import numpy as np

import blinn_phong as bp
from blinn_phong.effects.refraction import refract
from blinn_phong.geometry.normals import face_normals, vertex_normals
from blinn_phong.model.primitives import grid_plane
from testbeds.error_metrics import error_metrics, has_nonfinite


def _scene(mesh: bp.Mesh) -> bp.Scene:
    camera = bp.Camera.perspective(40.0, 1.0, 0.5, 20.0, view=bp.look_at((0.5, -2.0, 3.0), (0, 0, 0)))
    return bp.Scene([mesh], [bp.PointLight((1.0, 1.0, 2.0))], camera, ambient=(0.1, 0.1, 0.1))


def test_degenerate_triangles_have_zero_normals_and_draw_nothing() -> None:
    pos, tris, _ = grid_plane(4, 4, (2.0, 2.0))
    material = bp.Material(diffuse=(0.7, 0.6, 0.5), specular=(0.5, 0.5, 0.5), shininess=20.0)
    # Extra vertices: three on one line, and one repeated position.
    extra = np.array([[0.0, 0.0, 0.2], [0.5, 0.5, 0.2], [1.0, 1.0, 0.2], [0.3, -0.2, 0.1]])
    v = len(pos)
    degenerate = np.array([[v, v + 1, v + 2], [v + 3, v + 3, v + 3], [0, 0, 1], [v + 3, v + 3, 5]])
    clean = bp.Mesh(np.r_[pos, extra], tris, material=material)
    dirty = bp.Mesh(np.r_[pos, extra], np.r_[tris, degenerate], material=material)
    # Failing: the textbook normalisation of the cross product gives NaN for every degenerate face.
    p = np.r_[pos, extra][degenerate]
    cross = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    with np.errstate(invalid="ignore", divide="ignore"):
        textbook = cross / np.linalg.norm(cross, axis=1, keepdims=True)
    assert np.isnan(textbook).all()
    # Robust: zero normals, zero vertex normals for vertices used by degenerate faces only.
    assert np.array_equal(face_normals(np.r_[pos, extra], degenerate), np.zeros((4, 3)))
    vn = vertex_normals(np.r_[pos, extra], np.r_[tris, degenerate])
    assert not has_nonfinite(vn)
    assert np.array_equal(vn[v:], np.zeros((4, 3)))
    # A zero-area triangle covers no sample (its edge functions vanish): the image is the one
    # without them, exactly, in every shading frequency.
    for shading in ("flat", "gouraud", "phong"):
        a = bp.render(_scene(clean), 64, 64, shading=shading).rgba
        b = bp.render(_scene(dirty), 64, 64, shading=shading).rgba
        assert not has_nonfinite(a, b)
        assert error_metrics(b, a)["max_steps"] == 0.0


def test_total_internal_reflection_past_the_critical_angle() -> None:
    eta = 1.5  # from glass (n = 1.5) into air (n = 1)
    theta = np.radians(np.linspace(0.0, 89.0, 891))
    normal = np.tile([0.0, 0.0, 1.0], (len(theta), 1))
    incident = np.stack([np.sin(theta), np.zeros_like(theta), -np.cos(theta)], axis=1)  # hits from above
    critical = np.arcsin(1.0 / eta)  # 41.81°
    # Failing 1: the textbook Snell root is NaN past the critical angle.
    cos_i = np.cos(theta)
    with np.errstate(invalid="ignore"):
        textbook = np.sqrt(1.0 - eta**2 * (1.0 - cos_i**2))
    assert np.isnan(textbook[theta > critical + 1e-9]).all()
    # Robust: refract() flags TIR exactly past the critical angle and returns the mirror direction.
    direction, tir = refract(incident, normal, eta)
    assert not has_nonfinite(direction)
    assert np.array_equal(tir, eta * np.sin(theta) > 1.0)
    mirror = incident * np.array([1.0, 1.0, -1.0])
    assert np.allclose(direction[tir], mirror[tir], atol=1e-12)
    ok = ~tir
    assert np.allclose(np.hypot(direction[ok, 0], direction[ok, 1]), eta * np.sin(theta[ok]), atol=1e-12)
    # Failing 2: alpha transparency (opacity a) transmits (1 − a) of a white background at every
    # angle; past the critical angle nothing is transmitted (the closed form above): error
    # (1 − a)·255 steps = 204 steps for a = 0.2, on every angle refract() flags.
    a = 0.2
    exact_transmitted = np.where(tir, 0.0, 1.0 - a)
    alpha_blended = np.full_like(theta, 1.0 - a)
    assert error_metrics(alpha_blended[tir], exact_transmitted[tir])["max_steps"] > 200.0
    assert tir.sum() == np.count_nonzero(theta > critical)

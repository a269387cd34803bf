"""The camera's matrices, as OpenGL's GLU and ``glOrtho`` build them: :func:`look_at` (world → eye),
:func:`perspective_matrix` and :func:`orthographic_matrix` (eye → clip). 4×4 float64 arrays acting
on column vectors; angles in degrees."""

from __future__ import annotations

import math

import numpy as np

from blinn_phong._checks import number, vector3

__all__ = ["look_at", "orthographic_matrix", "perspective_matrix"]


def look_at(eye: object, target: object, up: object = (0.0, 1.0, 0.0)) -> np.ndarray:
    """The 4×4 view matrix of ``gluLookAt(eye, target, up)`` (world → eye space).

    The eye goes to the origin, ``target - eye`` to -Z and ``up`` (projected) to +Y.
    Source: the ``gluLookAt`` reference page (OpenGL 2.1 GLU), matrix ``M · T(-eye)``
    with rows s, u, -f.

    Raises:
        ValueError: eye == target, or ``up`` parallel to the viewing direction.
    """
    e = np.asarray(vector3(eye, "look_at eye"))
    t = np.asarray(vector3(target, "look_at target"))
    u = np.asarray(vector3(up, "look_at up", unit=True))
    f = t - e
    if np.linalg.norm(f) == 0.0:
        raise ValueError(f"look_at: eye and target must differ, both are {tuple(e.tolist())}")
    f = f / np.linalg.norm(f)
    s = np.cross(f, u)
    if np.linalg.norm(s) < 1e-12:
        raise ValueError(
            f"look_at: up {tuple(u.tolist())} is parallel to the viewing direction {tuple(f.tolist())}"
        )
    s = s / np.linalg.norm(s)
    uu = np.cross(s, f)
    m = np.eye(4)
    m[0, :3], m[1, :3], m[2, :3] = s, uu, -f
    m[:3, 3] = -m[:3, :3] @ e
    return m


def perspective_matrix(fov_y: float, aspect: float, near: float, far: float) -> np.ndarray:
    """``gluPerspective(fov_y, aspect, near, far)`` (eye → clip), ``fov_y`` in degrees.

    ``f = cot(fov_y/2)``; rows ``(f/aspect,0,0,0), (0,f,0,0), (0,0,(far+near)/(near-far),
    2·far·near/(near-far)), (0,0,-1,0)`` (GLU reference page).

    Raises:
        ValueError: near <= 0, far <= near, fov_y outside (0, 180), aspect <= 0.
    """
    fov_y = number(fov_y, "Camera fov_y (degrees)", low=0.0, high=180.0, low_open=True)
    if fov_y == 180.0:
        raise ValueError("Camera fov_y (degrees): expected a value in (0, 180), got 180.0")
    aspect = number(aspect, "Camera aspect", low=0.0, low_open=True)
    near = number(near, "Camera near", low=0.0, low_open=True)
    far = number(far, "Camera far", low=0.0, low_open=True)
    if far <= near:
        raise ValueError(f"Camera far: expected far > near = {near}, got {far}")
    f = 1.0 / math.tan(math.radians(fov_y) / 2.0)
    m = np.zeros((4, 4))
    m[0, 0] = f / aspect
    m[1, 1] = f
    m[2, 2] = (far + near) / (near - far)
    m[2, 3] = 2.0 * far * near / (near - far)
    m[3, 2] = -1.0
    return m


def orthographic_matrix(
    left: float, right: float, bottom: float, top: float, near: float, far: float
) -> np.ndarray:
    """``glOrtho(left, right, bottom, top, near, far)`` (eye → clip), OpenGL 2.1 §2.11.1 eq. for Ortho.

    Raises:
        ValueError: left == right, bottom == top or near == far.
    """
    vals = [
        number(v, f"Camera {n}")
        for v, n in zip(
            (left, right, bottom, top, near, far),
            ("left", "right", "bottom", "top", "near", "far"),
            strict=True,
        )
    ]
    l, r, b, t, n, f = vals
    if l == r or b == t or n == f:
        raise ValueError(f"orthographic: need left != right, bottom != top, near != far; got {tuple(vals)}")
    m = np.eye(4)
    m[0, 0], m[1, 1], m[2, 2] = 2 / (r - l), 2 / (t - b), -2 / (f - n)
    m[0, 3], m[1, 3], m[2, 3] = -(r + l) / (r - l), -(t + b) / (t - b), -(f + n) / (f - n)
    return m

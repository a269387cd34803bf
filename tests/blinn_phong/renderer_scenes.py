"""Scenes shared by the renderer tests (float32-representable geometry, as OpenGL stores it)."""

from __future__ import annotations

import numpy as np

import blinn_phong as bp
from blinn_phong.model.primitives import grid_plane, uv_sphere


def f32(x: np.ndarray) -> np.ndarray:
    """Round to the nearest float32 (what OpenGL keeps) and back to float64."""
    return np.asarray(x, np.float32).astype(np.float64)


def sphere_mesh(
    material: bp.Material, transform: np.ndarray | None = None, *, segments: int = 48, rings: int = 24
) -> bp.Mesh:
    pos, tris, normals = uv_sphere(segments, rings)
    return bp.Mesh(
        f32(pos),
        tris,
        f32(normals),
        transform=np.eye(4) if transform is None else transform,
        material=material,
    )


def floor_mesh(material: bp.Material, n: int = 12, y: float = -1.0, size: float = 6.0) -> bp.Mesh:
    pos, tris, normals = grid_plane(n, n, (size, size))
    rot = np.array(
        [[1, 0, 0, 0], [0, 0, 1, y], [0, -1, 0, 0], [0, 0, 0, 1]], float
    )  # z-up plane -> y-up floor
    return bp.Mesh(f32(pos), tris, normals, transform=rot, material=material)


SHINY = bp.Material(
    ambient=(0.25, 0.2, 0.2), diffuse=(0.7, 0.45, 0.3), specular=(0.9, 0.9, 0.8), shininess=40.0
)
MATTE = bp.Material(
    ambient=(0.3, 0.3, 0.35), diffuse=(0.35, 0.55, 0.6), specular=(0.2, 0.2, 0.2), shininess=8.0
)

DIRECTIONAL = bp.DirectionalLight(
    (-0.6, -0.5, -1.0), diffuse=(0.8, 0.8, 0.75), specular=(1.0, 1.0, 1.0), ambient=(0.05, 0.05, 0.05)
)
POINT = bp.PointLight(
    (2.0, 1.5, 2.5),
    diffuse=(0.9, 0.6, 0.4),
    specular=(0.8, 0.7, 0.6),
    ambient=(0.02, 0.0, 0.0),
    constant=1.0,
    linear=0.2,
    quadratic=0.05,
)
SPOT = bp.SpotLight(
    (0.5, 3.5, 1.0),
    (-0.1, -1.0, -0.25),
    cutoff=35.0,
    exponent=6.0,
    diffuse=(0.5, 0.7, 1.0),
    specular=(0.6, 0.8, 1.0),
    constant=1.0,
    quadratic=0.1,
)


def perspective_camera(aspect: float = 1.0) -> bp.Camera:
    return bp.Camera.perspective(38.0, aspect, 1.0, 20.0, view=bp.look_at((0.4, 1.2, 5.0), (0.0, -0.2, 0.0)))


def ortho_camera() -> bp.Camera:
    return bp.Camera.orthographic(
        -1.6, 1.6, -1.6, 1.6, 0.5, 20.0, view=bp.look_at((0.4, 1.2, 5.0), (0.0, -0.2, 0.0))
    )


def texel_interior(scene: bp.Scene, texture, width: int, height: int, margin: float) -> np.ndarray:
    """(H, W) bool: pixels whose centre's texel coordinates ``(u·W_tex, v·H_tex)`` on the first
    mesh lie ≥ ``margin`` texel from a texel boundary (uncovered pixels are False)."""
    prepared = bp.prepare_scene(scene)
    frags = bp.rasterize(prepared.clip, prepared.triangles, width, height)
    winner = bp.resolve_nearest(frags)
    hit = np.flatnonzero(winner >= 0)
    uv = bp.interpolate(frags.subset(winner[hit]), prepared.triangles, scene.meshes[0].uv)
    t = uv * [texture.width, texture.height]
    frac = t - np.floor(t)
    ok = np.zeros(width * height, bool)
    ok[hit] = ((frac > margin) & (frac < 1.0 - margin)).all(axis=1)
    return ok.reshape(height, width)

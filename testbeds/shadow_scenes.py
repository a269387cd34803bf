"""The shadow-mapping scene measured against Mesa, and the masks its comparisons use.

Shared by ``benchmarks/bench_shadows_mesa.py`` and ``tests/mesa/test_shadows_vs_mesa.py``.
"""

from __future__ import annotations

import numpy as np

__all__ = ["away_from_shadow_edges", "two_spheres_over_ground"]


def two_spheres_over_ground(
    segments: int = 256, aspect: float = 16 / 9, lights: list | None = None, rings: int | None = None
) -> object:  # a blinn_phong.Scene
    """Two spheres of ``2·segments·(rings−1)`` triangles over a ground plane, lit by ``lights``.

    ``rings`` defaults to ``segments // 2 + 1``; ``lights`` to a sun and a point light.
    The scene of ``benchmarks/bench_shadows_mesa.py`` and, with small spheres, of
    tests/mesa/test_shadows_vs_mesa.py.
    """
    import blinn_phong as bp
    from blinn_phong.model.primitives import grid_plane, uv_sphere

    meshes = []
    for x, colour in ((-1.2, (0.8, 0.3, 0.2)), (1.2, (0.2, 0.5, 0.8))):
        p, t, n = uv_sphere(segments, segments // 2 + 1 if rings is None else rings)
        transform = np.eye(4)
        transform[:3, 3] = (x, 1.0, 0.0)
        material = bp.Material(ambient=colour, diffuse=colour, specular=(0.5, 0.5, 0.5), shininess=32.0)
        meshes.append(bp.Mesh(p, t, n, transform=transform, material=material))
    p, t, n = grid_plane(8, 8, (12.0, 12.0))
    floor = np.array([[1, 0, 0, 0], [0, 0, 1, 0], [0, -1, 0, 0], [0, 0, 0, 1]], float)
    meshes.append(bp.Mesh(p, t, n, transform=floor, material=bp.Material(diffuse=(0.6, 0.6, 0.6))))
    if lights is None:
        lights = [
            bp.DirectionalLight((-0.5, -1.0, -0.4), (0.8, 0.8, 0.8)),
            bp.PointLight((2.0, 4.0, 2.0), (0.6, 0.6, 0.6)),
        ]
    camera = bp.Camera.perspective(45.0, aspect, 0.5, 50.0, view=bp.look_at((0, 3, 8), (0, 0.5, 0)))
    return bp.Scene(meshes, lights, camera, ambient=(0.1, 0.1, 0.1))


def away_from_shadow_edges(shadow: np.ndarray) -> np.ndarray:
    """True where the visibility pass is the same over the pixel's 3×3 neighbourhood."""
    v = np.pad(shadow, 1, mode="edge")
    h, w = shadow.shape
    same = np.ones((h, w), bool)
    for dy in range(3):
        for dx in range(3):
            same &= v[dy : dy + h, dx : dx + w] == shadow
    return same

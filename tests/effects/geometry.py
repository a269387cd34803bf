"""Small closed meshes for the effects tests: boxes, UV spheres, quads, prisms."""

from __future__ import annotations

import numpy as np


def box_triangles(lo: tuple[float, float, float], hi: tuple[float, float, float]) -> np.ndarray:
    """(12, 3, 3) triangles of an axis-aligned box, wound so the normals point outwards."""
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    c = np.array(
        [
            [x0, y0, z0],
            [x1, y0, z0],
            [x1, y1, z0],
            [x0, y1, z0],
            [x0, y0, z1],
            [x1, y0, z1],
            [x1, y1, z1],
            [x0, y1, z1],
        ],
        dtype=np.float64,
    )
    quads = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (2, 3, 7, 6), (1, 2, 6, 5), (0, 4, 7, 3)]
    tris = []
    for a, b, cc, d in quads:
        tris.append([c[a], c[b], c[cc]])
        tris.append([c[a], c[cc], c[d]])
    return np.array(tris)


def uv_sphere_triangles(
    centre: tuple[float, float, float], radius: float, n_lon: int, n_lat: int
) -> np.ndarray:
    """Triangles of a UV sphere with vertices on the sphere, wound outwards."""
    c = np.asarray(centre, dtype=np.float64)
    th = np.linspace(0, np.pi, n_lat + 1)
    ph = np.linspace(0, 2 * np.pi, n_lon + 1)
    p = np.stack(
        [
            np.sin(th)[:, None] * np.cos(ph)[None, :],
            np.sin(th)[:, None] * np.sin(ph)[None, :],
            np.cos(th)[:, None] * np.ones_like(ph)[None, :],
        ],
        axis=-1,
    )
    p = c + radius * p
    tris = []
    for i in range(n_lat):
        for j in range(n_lon):
            a, b, cc, d = p[i, j], p[i + 1, j], p[i + 1, j + 1], p[i, j + 1]
            if i != 0:
                tris.append([a, b, d])
            if i != n_lat - 1:
                tris.append([b, cc, d])
    return np.array(tris)


def quad_triangles(corner: np.ndarray, edge_u: np.ndarray, edge_v: np.ndarray) -> np.ndarray:
    """(2, 3, 3) triangles of the parallelogram ``corner + s·edge_u + t·edge_v``."""
    a = np.asarray(corner, dtype=np.float64)
    u = np.asarray(edge_u, dtype=np.float64)
    v = np.asarray(edge_v, dtype=np.float64)
    return np.array([[a, a + u, a + u + v], [a, a + u + v, a + v]])

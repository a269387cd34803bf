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


def ray_box_distance(points, direction, lo, hi):
    """Signed slab-test margin: > 0 where the ray p + t·dir (t > 0) passes through the box
    interior by at least that much in every slab, < 0 where it misses (Kay & Kajiya 1986)."""
    d = np.where(direction == 0, 1e-300, direction)
    t0 = (np.asarray(lo) - points) / d
    t1 = (np.asarray(hi) - points) / d
    tmin = np.max(np.minimum(t0, t1), axis=1)
    tmax = np.min(np.maximum(t0, t1), axis=1)
    return np.minimum(tmax - np.maximum(tmin, 0.0), tmax)


def ray_sphere_distance(points, direction, centre):
    """Distance from the sphere centre to the ray p + t·dir, t ≥ 0 (closed form)."""
    d = direction / np.linalg.norm(direction)
    w = np.asarray(centre) - points
    t = np.maximum(w @ d, 0.0)
    return np.linalg.norm(w - t[:, None] * d, axis=1)


def ground_points(n: int, extent: float = 4.0, seed: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """``n`` random points on the plane z = 0 in [−extent, extent]² and their normals (0, 0, 1)."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform(-extent, extent, size=(n, 2))
    return np.column_stack([xy, np.zeros(n)]), np.tile([0.0, 0.0, 1.0], (n, 1))

"""Procedural meshes for tests, benchmarks and demos (counter-clockwise = outward/front).

Each function returns ``(positions (V, 3) float64, triangles (T, 3) int64, normals (V, 3))``
with exact analytic normals, ready for :class:`blinn_phong.model.scene.Mesh`.
"""

from __future__ import annotations

import numpy as np

__all__ = ["box", "grid_plane", "uv_sphere"]


def uv_sphere(
    segments: int = 32, rings: int = 16, radius: float = 1.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A latitude/longitude sphere centred at the origin, poles on ±Y.

    Args:
        segments: divisions around Y (>= 3).
        rings: divisions from pole to pole (>= 2).
        radius: sphere radius (> 0).

    Returns:
        ``(positions, triangles, normals)`` with ``2·segments·(rings - 1)`` triangles
        (one per segment at each pole cap) and outward unit normals ``p / radius``.
    """
    if segments < 3 or rings < 2 or not radius > 0:
        raise ValueError(
            f"uv_sphere: need segments >= 3, rings >= 2, radius > 0; got {segments}, {rings}, {radius}"
        )
    theta = np.linspace(0.0, np.pi, rings + 1)[1:-1]  # interior latitudes
    phi = np.linspace(0.0, 2.0 * np.pi, segments + 1)[:-1]
    t, p = np.meshgrid(theta, phi, indexing="ij")
    ring_pts = np.stack([np.sin(t) * np.cos(p), np.cos(t), -np.sin(t) * np.sin(p)], axis=-1).reshape(-1, 3)
    unit = np.concatenate([[[0.0, 1.0, 0.0]], ring_pts, [[0.0, -1.0, 0.0]]])
    top, bottom = 0, len(unit) - 1

    def ring_index(r: np.ndarray, s: np.ndarray) -> np.ndarray:
        return 1 + r * segments + (s % segments)

    s = np.arange(segments)
    tris = [np.stack([np.full(segments, top), ring_index(0, s), ring_index(0, s + 1)], axis=1)]
    for r in range(rings - 2):
        a, b = ring_index(r, s), ring_index(r, s + 1)
        c, d = ring_index(r + 1, s), ring_index(r + 1, s + 1)
        tris += [np.stack([a, c, d], axis=1), np.stack([a, d, b], axis=1)]
    last = rings - 2
    tris.append(np.stack([ring_index(last, s), np.full(segments, bottom), ring_index(last, s + 1)], axis=1))
    return unit * radius, np.concatenate(tris).astype(np.int64), unit.copy()


def grid_plane(
    nx: int = 1, ny: int = 1, size: tuple[float, float] = (2.0, 2.0)
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A flat grid in the z = 0 plane centred at the origin, facing +Z.

    Args:
        nx: cells along X (>= 1).
        ny: cells along Y (>= 1).
        size: (width, height) extent.

    Returns:
        ``(positions, triangles, normals)``: ``(nx+1)(ny+1)`` vertices, ``2·nx·ny`` triangles,
        normals (0, 0, 1).
    """
    if nx < 1 or ny < 1:
        raise ValueError(f"grid_plane: need nx, ny >= 1, got {nx}, {ny}")
    x = np.linspace(-size[0] / 2, size[0] / 2, nx + 1)
    y = np.linspace(-size[1] / 2, size[1] / 2, ny + 1)
    gx, gy = np.meshgrid(x, y)
    pos = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], axis=1)
    i, j = np.meshgrid(np.arange(nx), np.arange(ny))
    v = (j * (nx + 1) + i).ravel()
    tris = np.concatenate([np.stack([v, v + 1, v + nx + 2], 1), np.stack([v, v + nx + 2, v + nx + 1], 1)])
    normals = np.tile([0.0, 0.0, 1.0], (len(pos), 1))
    return pos, tris.astype(np.int64), normals


def box(
    half_extents: tuple[float, float, float] = (1.0, 1.0, 1.0),
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """An axis-aligned box centred at the origin, four vertices and one normal per face.

    Args:
        half_extents: half the box's size along X, Y and Z (each > 0).

    Returns:
        ``(positions, triangles, normals)``: 24 vertices (faces do not share vertices, so each
        face keeps its own outward normal and the box shades flat), 12 counter-clockwise
        (outward) triangles, unit face normals.
    """
    half = np.asarray(half_extents, dtype=np.float64)
    if half.shape != (3,) or not np.isfinite(half).all() or not (half > 0).all():
        raise ValueError(f"box: half_extents must be three finite numbers > 0, got {half_extents!r}")
    positions, triangles, normals = [], [], []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            n = np.zeros(3)
            n[axis] = sign
            u = np.zeros(3)
            u[(axis + 1) % 3] = 1.0
            v = np.cross(n, u)  # (u, v, n) right-handed: corners below run counter-clockwise about n
            base = len(positions)
            for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                positions.append((n + a * u + b * v) * half)
                normals.append(n)
            triangles += [[base, base + 1, base + 2], [base, base + 2, base + 3]]
    return np.array(positions), np.array(triangles, dtype=np.int64), np.array(normals)

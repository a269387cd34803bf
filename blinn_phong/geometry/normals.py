"""Surface normals: face normals, averaged vertex normals, and their transformation.

* Face normal: ``(p1 - p0) × (p2 - p0)`` normalised; counter-clockwise triangles face
  the viewer (right-hand rule, OpenGL ``GL_CCW``).
* Vertex normals: the normalised sum of adjacent face normals weighted by face area
  (the un-normalised cross product, Gouraud 1971) or by the triangle's interior angle
  at the vertex (Thürmer & Wüthrich, "Computing vertex normals from polygonal
  facets", JGT 3(1), 1998).
* Transformation: normals are covectors and transform with the inverse-transpose of
  the upper 3×3 of the model(-view) matrix (OpenGL 2.1 §2.11.3), so non-uniform
  scale keeps them perpendicular to the surface.

Degenerate triangles and zero-length normals give zero vectors, never NaN.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from blinn_phong._vectors import normalize

__all__ = [
    "face_normals",
    "max_normal_angle",
    "normal_matrix",
    "normalize",
    "transform_normals",
    "vertex_normals",
]


def face_normals(positions: np.ndarray, triangles: np.ndarray, *, unit: bool = True) -> np.ndarray:
    """(T, 3) normals ``(p1 - p0) × (p2 - p0)`` of each triangle (unit length unless ``unit=False``).

    Args:
        positions: (V, 3) vertex positions (any length unit).
        triangles: (T, 3) vertex indices, counter-clockwise = front.
        unit: normalise (zero-area triangles give (0, 0, 0)); if False the length is twice the area.
    """
    p = np.asarray(positions, dtype=np.float64)[np.asarray(triangles)]
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    return normalize(n) if unit else n


def vertex_normals(
    positions: np.ndarray, triangles: np.ndarray, weighting: Literal["area", "angle"] = "area"
) -> np.ndarray:
    """(V, 3) unit vertex normals averaged from the adjacent faces.

    Args:
        positions: (V, 3) vertex positions.
        triangles: (T, 3) vertex indices, counter-clockwise = front.
        weighting: ``"area"`` (each face weighted by its area) or ``"angle"`` (by the
            interior angle at the vertex, in radians).

    Returns:
        Unit normals; a vertex with no (non-degenerate) face gets (0, 0, 0).
    """
    if weighting not in ("area", "angle"):
        raise ValueError(f"weighting: expected 'area' or 'angle', got {weighting!r}")
    pos = np.asarray(positions, dtype=np.float64)
    tri = np.asarray(triangles, dtype=np.int64)
    acc = np.zeros_like(pos)
    if weighting == "area":
        n = face_normals(pos, tri, unit=False)
        for i in range(3):
            np.add.at(acc, tri[:, i], n)
    else:
        n = face_normals(pos, tri)
        p = pos[tri]
        for i in range(3):
            e1 = normalize(p[:, (i + 1) % 3] - p[:, i])
            e2 = normalize(p[:, (i + 2) % 3] - p[:, i])
            angle = np.arccos(np.clip(np.einsum("ij,ij->i", e1, e2), -1.0, 1.0))
            np.add.at(acc, tri[:, i], n * angle[:, None])
    return normalize(acc)


def normal_matrix(matrix: np.ndarray) -> np.ndarray:
    """The 3×3 inverse-transpose of the upper-left 3×3 of a 4×4 model(-view) matrix (OpenGL 2.1 §2.11.3)."""
    m = np.asarray(matrix, dtype=np.float64)
    if m.shape != (4, 4):
        raise ValueError(f"matrix: expected a 4×4 matrix, got shape {m.shape}")
    r0, r1, r2 = m[0, :3], m[1, :3], m[2, :3]
    cofactor = np.stack([np.cross(r1, r2), np.cross(r2, r0), np.cross(r0, r1)])  # (M⁻¹)ᵀ · det M
    det = float(np.dot(r0, cofactor[0]))
    if det == 0.0:
        raise ValueError("matrix: the upper 3×3 is singular; normals cannot be transformed")
    return cofactor / det


def transform_normals(normals: np.ndarray, matrix: np.ndarray) -> np.ndarray:
    """Unit normals after the model(-view) ``matrix`` (4×4): ``normalize(N⁻ᵀ n)``; zero stays zero."""
    return normalize(np.asarray(normals, dtype=np.float64) @ normal_matrix(matrix).T)


def max_normal_angle(normals: np.ndarray, triangles: np.ndarray) -> float:
    """Largest angle (radians) between the vertex normals at the two ends of any triangle edge.

    Args:
        normals: (V, 3) vertex normals (any length > 0; zero vectors count as angle 0).
        triangles: (T, 3) vertex indices.
    """
    n = np.asarray(normals, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64)
    if n.ndim != 2 or n.shape[1] != 3 or t.ndim != 2 or t.shape[1] != 3:
        raise ValueError(
            f"normals, triangles: expected shapes (V, 3) and (T, 3), got {n.shape} and {t.shape}"
        )
    unit = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    worst = 0.0
    for a, b in ((0, 1), (1, 2), (2, 0)):
        cos = np.einsum("ij,ij->i", unit[t[:, a]], unit[t[:, b]])
        worst = max(worst, float(np.arccos(np.clip(cos, -1.0, 1.0)).max(initial=0.0)))
    return worst

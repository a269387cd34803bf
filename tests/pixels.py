"""Pixel masks the image comparisons share (Mesa, Cycles): where a comparison may not depend on
coverage rules or edge rounding."""

from __future__ import annotations

import numpy as np

import blinn_phong as bp


def interior_mask(scene: bp.Scene, width: int, height: int, margin: float = 1.0 / 16.0) -> np.ndarray:
    """Pixels whose centre lies inside its visible triangle, at least ``margin`` pixels from every edge.

    Away from edges, coverage cannot depend on the fill rule or on float32 vs float64
    vertex transformation, and all three vertices' colours contribute. Edges are the
    projected lines through the vertices' homogeneous window positions (valid for
    triangles crossing the near plane too); fragments within 1e-3 of the near plane in
    window depth (the clipping edge) are excluded as well.
    """
    prepared = bp.prepare_scene(scene)
    frags = bp.rasterize(prepared.clip, prepared.triangles, width, height)
    winner = bp.resolve_nearest(frags)
    mask = np.zeros(width * height, bool)
    hit = np.flatnonzero(winner >= 0)
    clip = prepared.clip[prepared.triangles[frags.triangle[winner[hit]]]]  # (n, 3, 4)
    # Homogeneous window coordinates: x = (x_c + w)·W/2, row = (w - y_c)·H/2, weight w.
    hom = np.stack(
        [(clip[..., 0] + clip[..., 3]) * width / 2, (clip[..., 3] - clip[..., 1]) * height / 2, clip[..., 3]],
        -1,
    )
    centre = np.stack([hit % width + 0.5, hit // width + 0.5, np.ones(len(hit))], -1)
    nearest_edge = np.full(len(hit), np.inf)
    for i, j in ((0, 1), (1, 2), (2, 0)):
        line = np.cross(hom[:, i], hom[:, j])
        distance = np.abs(np.einsum("nk,nk->n", line, centre)) / np.hypot(line[:, 0], line[:, 1])
        nearest_edge = np.minimum(nearest_edge, distance)
    mask[hit] = (nearest_edge >= margin) & (frags.depth[winner[hit]] > 1e-3)
    return mask.reshape(height, width)

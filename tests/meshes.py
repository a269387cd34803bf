"""Flat quads the renderer, effects and add-on tests build their scenes from.

Import as ``from tests.meshes import ...`` (the repository root is on ``sys.path`` when the
tests run as ``python -m pytest`` from it).
"""

from __future__ import annotations

import numpy as np

from blinn_phong.model.scene import Material, Mesh


def square(
    z: float,
    half: float,
    material: Material,
    centre: tuple[float, float] = (0.0, 0.0),
    **mesh_options: object,
) -> Mesh:
    """A square of half-width ``half`` facing +Z at height ``z``, counter-clockwise seen from
    above, with explicit +Z vertex normals; ``mesh_options`` go to :class:`Mesh` (e.g.
    ``casts_shadows``)."""
    cx, cy = centre
    positions = np.array(
        [
            (cx - half, cy - half, z),
            (cx + half, cy - half, z),
            (cx + half, cy + half, z),
            (cx - half, cy + half, z),
        ],
        dtype=float,
    )
    return Mesh(
        positions,
        np.array([(0, 1, 2), (0, 2, 3)]),
        np.tile([0.0, 0.0, 1.0], (4, 1)),
        material=material,
        **mesh_options,
    )


def rectangle(
    x0: float, x1: float, y0: float, y1: float, z: float, material: Material, **mesh_options: object
) -> Mesh:
    """The rectangle ``[x0, x1] × [y0, y1]`` at height ``z``, two triangles, normals left to
    :class:`Mesh` (computed from the winding); the corners keep the type they are given.
    ``mesh_options`` go to :class:`Mesh` (e.g. ``holdout``)."""
    return Mesh(
        np.array([(x0, y0, z), (x1, y0, z), (x1, y1, z), (x0, y1, z)]),
        np.array([[0, 1, 2], [0, 2, 3]]),
        material=material,
        **mesh_options,
    )

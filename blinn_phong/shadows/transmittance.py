"""How much light a shadow caster lets through: per-material and per-triangle RGB transmittance
for the coloured shadows of transparent casters (ray traced, :mod:`blinn_phong.shadows.raytrace`).
"""

from __future__ import annotations

import numpy as np


def shadow_transmittance(material: object) -> np.ndarray:
    """(3,) RGB fraction of light a surface of ``material`` lets through, for shadow rays.

    By the material's transparency model (docs/transparency_models.md): an opaque material
    (``not material.transparent``) 0; ``partial_occlusion`` — the surface covers the fraction α,
    so ``1 − α`` of the light passes (Porter & Duff's ``over`` for the light); ``absorption`` —
    the grey filter ``T = 1 − α`` the renderer gives it; ``emission`` — it only adds light and
    hides nothing: 1. A material whose opacity varies over the surface (a base-colour texture, an
    alpha clip, Kay–Greenberg) has no single transmittance: 0, a full shadow, as before coloured
    shadows existed. Specular wash-out depends on the viewer, not the light: the base opacity counts.

    Args:
        material: a :class:`blinn_phong.model.scene.Material`.

    Returns:
        (3,) float64 in [0, 1].
    """
    if not material.transparent or material.textured or material.kay_greenberg is not None:  # type: ignore[attr-defined]
        return np.zeros(3)
    if material.transparency_model == "emission":  # type: ignore[attr-defined]
        return np.ones(3)
    return np.full(3, 1.0 - float(material.opacity))  # type: ignore[attr-defined]


def mesh_shadow_transmittance(mesh: object, two_sided: bool) -> np.ndarray:
    """(3,) RGB transmittance of a mesh as a shadow caster: :func:`shadow_transmittance` of its material.

    Under two-sided lighting (``two_sided``) a mesh whose back material lets through other light
    than its front one casts a full shadow (0): a shadow ray may cross either side.
    """
    t = shadow_transmittance(mesh.material)  # type: ignore[attr-defined]
    back = mesh.back_material  # type: ignore[attr-defined]
    if two_sided and back is not None and not np.array_equal(t, shadow_transmittance(back)):
        return np.zeros(3)
    return t


def caster_transmittance(scene: object) -> np.ndarray | None:
    """(T, 3) per-triangle RGB transmittance of a scene's shadow casters, or None when every caster is opaque.

    Triangles of the meshes with ``casts_shadows``, in scene order (the order of the frame's
    caster triangles), each with :func:`mesh_shadow_transmittance` of its mesh.

    Args:
        scene: a :class:`blinn_phong.model.scene.Scene`.

    Returns:
        (T, 3) float64 in [0, 1], or None.
    """
    two_sided = scene.light_model.two_sided  # type: ignore[attr-defined]
    parts, any_light = [], False
    for mesh in scene.meshes:  # type: ignore[attr-defined]
        if not mesh.casts_shadows:
            continue
        t = mesh_shadow_transmittance(mesh, two_sided)
        any_light = any_light or bool(np.any(t > 0))
        parts.append(np.broadcast_to(t, (len(mesh.triangles), 3)))
    if not any_light:
        return None
    return np.ascontiguousarray(np.concatenate(parts))

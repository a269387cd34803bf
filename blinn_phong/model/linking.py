"""Holdouts and light/shadow linking: what the frame's stages read of ``Mesh.holdout`` and
``Scene.light_links``.

**Holdouts** (Blender's Holdout shader, ``Object.is_holdout``, a collection's *Holdout* on the view
layer). A holdout mesh is an opaque surface whose fragment is transparent black: its premultiplied
colour is ``(0, 0, 0, 0)``. Every transparency method composites a sample's transparent fragments
over its nearest opaque fragment and keeps nothing behind that one (the visibility stage drops
what lies behind it), so one rule serves all of them — z-buffer, A-buffer, depth peeling, the
sorted-drawing methods and weighted blended OIT: where a holdout is the nearest opaque surface,
the sample is what lies in front of it composited over ``(0, 0, 0, 0)``, i.e. Porter & Duff's
``(front) over ((behind) out (holdout))``. The box filter then gives a pixel the alpha of its
samples not held out, so a holdout covering 4 of 16 samples of an opaque surface leaves alpha
12/16. The light passes of a held-out sample are 0 (they are weighted by the fragment's alpha).

**Light linking** (Blender 4.0+ ``Object.light_linking``). Per light, a receiver mask and a blocker
mask over the scene's meshes (:class:`blinn_phong.model.scene.LightLink`; None: everyone, and then no
work at all):

* receivers: the light's visibility at a fragment of a mesh outside the mask is 0 (its diffuse
  and specular terms vanish there), applied after the shadow method to the (N, L) visibility
  every stage already takes;
* blockers: the light's shadows are computed against the casters in the mask only, by the same
  shadow method (shadow map, ray tracing, soft, shadow volume, planar) — the scene the method
  sees has ``casts_shadows`` off on the other meshes (:func:`blocker_scene`), which every method
  honours.

The planner counts only linked pairs (a blocker of the light shadowing one of its receivers), so
a light none of whose blockers can shadow any of its receivers is planned without shadows.
"""

from __future__ import annotations

import copy
from collections.abc import Callable

import numpy as np

from blinn_phong.model.lights import AmbientLight
from blinn_phong.model.scene import LightLink, Scene

__all__ = ["blocker_scene", "holdout_meshes", "linked_visibility", "links_of_lights", "lit_links"]


def holdout_meshes(scene: Scene) -> np.ndarray | None:
    """(M,) bool: which of ``scene.meshes`` are holdouts; None when none is (no work)."""
    flags = [bool(m.holdout) for m in scene.meshes]
    return np.array(flags, dtype=bool) if any(flags) else None


def lit_links(scene: Scene) -> list[LightLink | None] | None:
    """The :class:`LightLink` of each non-ambient light of ``scene`` in scene order (the columns of
    the frame's visibility); None when no light is linked."""
    if scene.light_links is None:
        return None
    return [
        link
        for light, link in zip(scene.lights, scene.light_links, strict=True)
        if not isinstance(light, AmbientLight)
    ]


def links_of_lights(scene: Scene, kept: list[int]) -> tuple[LightLink | None, ...] | None:
    """``scene.light_links`` of the lights ``kept`` (indices into ``scene.lights``), or None."""
    if scene.light_links is None:
        return None
    return tuple(scene.light_links[i] for i in kept)


def blocker_scene(scene: Scene, blockers: np.ndarray) -> Scene:
    """``scene`` in which only the meshes of ``blockers`` (and ``casts_shadows``) cast shadows,
    without light links.

    The meshes are shallow copies sharing the original arrays (the frame's world-geometry cache
    and the shadow kernels see the same vertices), with ``casts_shadows`` cleared outside the mask.
    """
    meshes = []
    for mesh, blocks in zip(scene.meshes, blockers, strict=True):
        if mesh.casts_shadows and not blocks:
            mesh = copy.copy(mesh)
            object.__setattr__(mesh, "casts_shadows", False)
        meshes.append(mesh)
    out = copy.copy(scene)
    object.__setattr__(out, "meshes", tuple(meshes))
    object.__setattr__(out, "light_links", None)
    return out


def linked_visibility(
    scene: Scene,
    lit: list[tuple[object, object]],
    mesh_of: np.ndarray,
    visibility_of: Callable[[Scene, list[tuple[object, object]]], np.ndarray],
) -> np.ndarray:
    """The frame's per-light visibility with ``scene.light_links`` applied.

    Args:
        scene: the frame's scene (``light_links`` set).
        lit: its non-ambient lights with their shadow choices, in scene order.
        mesh_of: (N,) the scene mesh of each point.
        visibility_of: ``visibility_of(scene, lights)``: the (N, l) or (N, l, 3) visibility of the
            points for ``lights`` (a sub-list of ``lit``) by their shadow methods against the
            casters of ``scene`` (the frame's shadow stage).

    Returns:
        (N, L) or (N, L, 3) float64: the unlinked lights' columns from one call, each light with
        blockers from its own call on :func:`blocker_scene`, then 0 where a light's receiver mask
        excludes the point's mesh.
    """
    links = lit_links(scene)
    assert links is not None
    plain = [i for i, link in enumerate(links) if link is None or link.blockers is None]
    columns: dict[int, np.ndarray] = {}
    if plain:
        shared = visibility_of(scene, [lit[i] for i in plain])
        columns.update((i, shared[:, j]) for j, i in enumerate(plain))
    for i, link in enumerate(links):
        if link is not None and link.blockers is not None:
            columns[i] = visibility_of(blocker_scene(scene, link.blockers), [lit[i]])[:, 0]
    coloured = any(c.ndim == 2 for c in columns.values())
    out = np.empty((len(mesh_of), len(lit), 3) if coloured else (len(mesh_of), len(lit)))
    for i, column in columns.items():
        out[:, i] = column[:, None] if coloured and column.ndim == 1 else column
        link = links[i]
        if link is not None and link.receivers is not None:
            out[~link.receivers[mesh_of], i] = 0.0
    return out

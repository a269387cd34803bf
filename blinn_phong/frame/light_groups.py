"""Light groups: one pass per group holding the light that group's emitters put into the frame.

Blender's light groups (``Object.lightgroup`` on lights and emissive objects, ``World.lightgroup``,
the view layer's ``lightgroups`` list) give Cycles one pass per group, ``Combined_<group>``.
Here the lighting equation is a sum of terms, each from one emitter:

* each light's ambient, diffuse and specular terms (with its shadowing) — the light's group;
* the global ambient ``Scene.ambient · a_cm`` (the world's light) — the world's group;
* each mesh's emission ``e_cm`` — the mesh's (its object's) group.

A group's pass is the frame's colour from only its own emitters (the other lights left out, the
world's ambient and the other meshes' emission set to 0), following the frame's own plan (the
same transparency method, shading frequencies and shadow methods), so it is exactly the part of
Combined those emitters make: the frame's colour is linear in them, fragment by fragment and
through every transparency resolve (alphas do not depend on light).

How it is made: when the frame takes the compiled engine's fused pass (one sample per pixel, the
z-buffer, the A-buffer or depth peeling, no Gouraud-shaded mesh, a frame small enough for one
strip), that pass makes the group passes as it shades: the lighting equation adds each light's
terms into its group too (:func:`blinn_phong.frame.lighting.point_terms` with
:meth:`LightGroups.kernel_tables`),
and each group's fragment colour is composited with the frame's own alphas. Every other frame
(the numpy engine, several samples, weighted blended OIT and the sorted draw orders, Gouraud
meshes, holdouts with transparency, deep output, strips) renders each group's frame apart with
the scene of :meth:`LightGroups.group_scene` (visibility, shadows and shading again per group).

Hence, when every emitter belongs to some group, the group passes sum to Combined's RGB up to
float rounding. Emitters in
no group appear in no pass (as in Cycles). Fog's own colour is in no group: each group's pass is
fogged towards black (the fog factor applied to the group's light), so with fog the passes sum to
Combined minus the fog's colour contribution. The GL preset clamps colours, which is not linear:
light groups are refused with ``gl_compat``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from blinn_phong.model.lights import AmbientLight
from blinn_phong.model.linking import links_of_lights
from blinn_phong.model.scene import Material, Scene

__all__ = ["LightGroups"]

_BLACK = (0.0, 0.0, 0.0)


def _check_members(values: Sequence[str | None], what: str, groups: tuple[str, ...]) -> tuple:
    if isinstance(values, str) or not isinstance(values, Sequence):
        raise TypeError(f"LightGroups.{what}: expected a sequence of group names or None, got {values!r}")
    for i, v in enumerate(values):
        if v is not None and v not in groups:
            raise ValueError(f"LightGroups.{what}[{i}]: group {v!r} is not in groups {list(groups)}")
    return tuple(values)


@dataclass(frozen=True)
class LightGroups:
    """Which group each emitter of a scene belongs to.

    Attributes:
        groups: the group names, in pass order (the view layer's list); each gives a pass
            ``Combined_<name>``, (H, W, 3) float32 premultiplied linear RGB.
        lights: one group name (or None: no group) per entry of ``Scene.lights``.
        meshes: one group name (or None) per entry of ``Scene.meshes``: the group of its emission.
        world: the group of the global ambient ``Scene.ambient`` (the world), or None.
    """

    groups: tuple[str, ...]
    lights: tuple[str | None, ...]
    meshes: tuple[str | None, ...]
    world: str | None = None

    def __post_init__(self) -> None:
        groups = tuple(self.groups)
        if not groups or not all(isinstance(g, str) and g for g in groups) or len(set(groups)) != len(groups):
            raise ValueError(f"LightGroups.groups: expected distinct non-empty names, got {self.groups!r}")
        if self.world is not None and self.world not in groups:
            raise ValueError(f"LightGroups.world: group {self.world!r} is not in groups {list(groups)}")
        object.__setattr__(self, "groups", groups)
        object.__setattr__(self, "lights", _check_members(self.lights, "lights", groups))
        object.__setattr__(self, "meshes", _check_members(self.meshes, "meshes", groups))

    def check(self, scene: Scene) -> None:
        """Raise ValueError unless there is one entry per light and per mesh of ``scene``."""
        if len(self.lights) != len(scene.lights) or len(self.meshes) != len(scene.meshes):
            raise ValueError(
                f"light_groups: expected one entry per light ({len(scene.lights)}) and per mesh "
                f"({len(scene.meshes)}), got {len(self.lights)} and {len(self.meshes)}"
            )

    def subset_meshes(self, keep: Sequence[bool]) -> LightGroups:
        """The groups for the meshes where ``keep`` is True (the render drops empty meshes)."""
        kept = tuple(g for g, k in zip(self.meshes, keep, strict=True) if k)
        return replace(self, meshes=kept)

    @staticmethod
    def pass_name(group: str) -> str:
        """``Combined_<group>``, Cycles' name of a group's pass."""
        return f"Combined_{group}"

    def kernel_tables(self, scene: Scene, source: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """What the shading kernels need to split each fragment's colour by group in the frame's
        own pass: ``(group_of, base)``.

        ``group_of`` (L,) int64: the group index (in ``groups``) of each light of the kernel's light
        tables, ``source`` (L,) being their indices in ``scene.lights``
        (:attr:`blinn_phong.frame.lighting.EyeLights.source`); −1 for a light in no group. ``base``
        (2·M, G, 3) float64, per material side (``2·mesh + back``, as the kernels' material
        tables) and group: the terms of :func:`blinn_phong.frame.lighting.material_tables`'s ``base``
        that belong to the group, ``e_cm`` if the mesh is in it, plus ``a_cm`` times the world's
        ambient if the world is in it and the radiances of its AmbientLights.
        """
        self.check(scene)
        index = {g: k for k, g in enumerate(self.groups)}
        group_of = np.array(
            [-1 if self.lights[i] is None else index[self.lights[i]] for i in np.asarray(source, np.int64)],
            dtype=np.int64,
        )
        ambient = np.zeros((len(self.groups), 3))  # the world's and the AmbientLights' radiance, per group
        if self.world is not None:
            ambient[index[self.world]] += np.asarray(scene.ambient, dtype=np.float64)
        for light, g in zip(scene.lights, self.lights, strict=True):
            if g is not None and isinstance(light, AmbientLight):
                ambient[index[g]] += np.asarray(light.radiance, dtype=np.float64)
        base = np.zeros((2 * len(scene.meshes), len(self.groups), 3))
        for m, (mesh, g) in enumerate(zip(scene.meshes, self.meshes, strict=True)):
            for side, material in enumerate((mesh.material, mesh.back_material or mesh.material)):
                base[2 * m + side] = np.asarray(material.ambient, dtype=np.float64) * ambient
                if g is not None:
                    base[2 * m + side, index[g]] += np.asarray(material.emission, dtype=np.float64)
        return group_of, base

    def group_scene(self, scene: Scene, group: str) -> tuple[Scene, list[int]] | None:
        """``scene`` with only ``group``'s emitters, and the indices of the lights it keeps;
        None when the group has no emitter (its pass is 0)."""
        self.check(scene)
        lights = [i for i, g in enumerate(self.lights) if g == group]
        world = self.world == group and any(scene.ambient)
        meshes = []
        emits = False
        for mesh, g in zip(scene.meshes, self.meshes, strict=True):
            if g == group:
                emits = emits or any(
                    m is not None and any(m.emission) for m in (mesh.material, mesh.back_material)
                )
                meshes.append(mesh)
                continue
            meshes.append(
                replace(
                    mesh,
                    material=_dark(mesh.material),
                    back_material=None if mesh.back_material is None else _dark(mesh.back_material),
                )
            )
        if not (lights or world or emits):
            return None
        return (
            replace(
                scene,
                meshes=tuple(meshes),
                lights=tuple(scene.lights[i] for i in lights),
                light_links=links_of_lights(scene, lights),
                ambient=scene.ambient if self.world == group else _BLACK,
            ),
            lights,
        )


def _dark(material: Material) -> Material:
    return material if not any(material.emission) else replace(material, emission=_BLACK)

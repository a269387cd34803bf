"""Stage 1 of the frame: a scene flattened into eye- and clip-space arrays (``scene -> prepared``).

:func:`prepare_scene` transforms every mesh to eye and clip space (normals with the
inverse-transpose of the model(-view) matrix, OpenGL 2.1 §2.11.3) and the lights to eye
space. Every later stage (:mod:`blinn_phong.frame.visibility`, :mod:`blinn_phong.frame.shading`,
:mod:`blinn_phong.frame.resolve`) reads the :class:`PreparedScene`.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from blinn_phong.frame.lighting import EyeLights, lights_in_eye_space
from blinn_phong.geometry.normals import face_normals, transform_normals, vertex_normals
from blinn_phong.model.scene import Scene

__all__ = ["PreparedScene", "prepare_scene"]


@dataclass(frozen=True, eq=False)
class PreparedScene:
    """A scene flattened into concatenated arrays in eye and clip space.

    Attributes:
        scene: the source scene.
        clip: (V, 4) clip-space positions of all meshes' vertices.
        eye_position: (V, 3) eye-space positions.
        eye_normal: (V, 3) eye-space unit vertex normals (given, or averaged from faces).
        world_normal: (V, 3) world-space unit vertex normals.
        triangles: (T, 3) vertex indices into the concatenated arrays, meshes in scene order.
        triangle_mesh: (T,) index of each triangle's mesh.
        vertex_offset: (M + 1,) first vertex of each mesh (and the total).
        lights: lights in eye space.
        face_eye_normal, face_world_normal: (T, 3) unit face normals (inverse-transpose
            transformed), computed on first use (flat shading, shadows, sorting).
        face_eye_centroid: (T, 3) eye-space centroids, computed on first use.
    """

    scene: Scene
    clip: np.ndarray
    eye_position: np.ndarray
    eye_normal: np.ndarray
    world_normal: np.ndarray
    triangles: np.ndarray
    triangle_mesh: np.ndarray
    vertex_offset: np.ndarray
    lights: EyeLights

    @cached_property
    def _face_normals(self) -> tuple[np.ndarray, np.ndarray]:
        """(eye, world) unit face normals of all meshes, in scene order."""
        view = self.scene.camera.view
        eye, world = [], []
        for mesh in self.scene.meshes:
            face_obj = face_normals(mesh.positions, mesh.triangles)
            eye.append(transform_normals(face_obj, view @ mesh.transform))
            world.append(transform_normals(face_obj, mesh.transform))
        if not eye:
            return np.zeros((0, 3)), np.zeros((0, 3))
        return np.concatenate(eye), np.concatenate(world)

    @property
    def face_eye_normal(self) -> np.ndarray:
        """(T, 3) unit eye-space face normals (inverse-transpose of the model-view matrix)."""
        return self._face_normals[0]

    @property
    def face_world_normal(self) -> np.ndarray:
        """(T, 3) unit world-space face normals (inverse-transpose of the model matrix)."""
        return self._face_normals[1]

    @cached_property
    def face_eye_centroid(self) -> np.ndarray:
        """(T, 3) eye-space centroids of the triangles."""
        return self.eye_position[self.triangles].mean(axis=1)


def prepare_scene(scene: Scene) -> PreparedScene:
    """Transform every mesh of ``scene`` to eye and clip space and move the lights to eye space.

    Normals use the inverse-transpose of the model(-view) matrix (OpenGL 2.1 §2.11.3);
    meshes without normals get :func:`~blinn_phong.geometry.normals.vertex_normals` with the
    mesh's ``normal_weighting``.
    """
    if not isinstance(scene, Scene):
        raise TypeError(f"scene: expected a blinn_phong.Scene, got {type(scene).__name__}")
    view, proj = scene.camera.view, scene.camera.projection
    clips, eyes, eye_ns, world_ns, tris, owner = [], [], [], [], [], []
    offsets = [0]
    for m, mesh in enumerate(scene.meshes):
        model_view = view @ mesh.transform
        hom = np.c_[mesh.positions, np.ones(len(mesh.positions))]
        eye = hom @ model_view.T
        clips.append(eye @ proj.T)
        eyes.append(eye[:, :3])
        obj_n = mesh.normals
        if obj_n is None:
            obj_n = vertex_normals(mesh.positions, mesh.triangles, mesh.normal_weighting)
        eye_ns.append(transform_normals(obj_n, model_view))
        world_ns.append(transform_normals(obj_n, mesh.transform))
        tris.append(mesh.triangles + offsets[-1])
        owner.append(np.full(len(mesh.triangles), m, np.int64))
        offsets.append(offsets[-1] + len(mesh.positions))

    def cat(parts: list[np.ndarray], shape: tuple[int, ...], dtype: type = np.float64) -> np.ndarray:
        return np.concatenate(parts) if parts else np.zeros((0, *shape), dtype)

    return PreparedScene(
        scene=scene,
        clip=cat(clips, (4,)),
        eye_position=cat(eyes, (3,)),
        eye_normal=cat(eye_ns, (3,)),
        world_normal=cat(world_ns, (3,)),
        triangles=cat(tris, (3,), np.int64),
        triangle_mesh=cat(owner, (), np.int64),
        vertex_offset=np.asarray(offsets, np.int64),
        lights=lights_in_eye_space(scene.lights, view),
    )

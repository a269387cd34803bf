"""Small scenes for the planner tests and a transparency pass built from the renderer's stages."""

from __future__ import annotations

import numpy as np

from blinn_phong.effects.oit import transparency_pass
from blinn_phong.frame.render import prepare_scene, shade_fragments
from blinn_phong.geometry.raster import interpolate, rasterize, resolve_nearest
from blinn_phong.model.primitives import box, uv_sphere
from blinn_phong.model.scene import Camera, LightModel, Material, Mesh, Scene
from blinn_phong.model.transforms import look_at

TOP_VIEW = look_at((0.0, 0.0, 10.0), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0))


def ortho_camera(extent: float = 2.0) -> Camera:
    return Camera.orthographic(-extent, extent, -extent, extent, 0.1, 30.0, view=TOP_VIEW)


def perspective_camera(eye=(0.0, -6.0, 5.0)) -> Camera:
    return Camera.perspective(40.0, 1.0, 0.5, 40.0, view=look_at(eye, (0.0, 0.0, 0.5), (0, 0, 1)))


def quad(corners, colour=(1.0, 1.0, 1.0), opacity=1.0) -> Mesh:
    """A quad from 4 corners (counter-clockwise seen from its front), flat normals."""
    c = np.asarray(corners, dtype=np.float64)
    n = np.cross(c[1] - c[0], c[2] - c[0])
    n = n / np.linalg.norm(n)
    mat = Material(ambient=colour, diffuse=colour, specular=(0, 0, 0), opacity=opacity)
    return Mesh(c, np.array([[0, 1, 2], [0, 2, 3]]), normals=np.tile(n, (4, 1)), material=mat)


def horizontal_quad(z, half=1.5, colour=(1.0, 1.0, 1.0), opacity=1.0, centre=(0.0, 0.0)) -> Mesh:
    x, y = centre
    return quad(
        [[x - half, y - half, z], [x + half, y - half, z], [x + half, y + half, z], [x - half, y + half, z]],
        colour,
        opacity,
    )


def sphere(centre, radius, colour=(1.0, 1.0, 1.0), opacity=1.0, segments=24, rings=12) -> Mesh:
    p, t, n = uv_sphere(segments, rings, radius)
    transform = np.eye(4)
    transform[:3, 3] = centre
    mat = Material(ambient=colour, diffuse=colour, specular=(0.3, 0.3, 0.3), shininess=20.0, opacity=opacity)
    return Mesh(p, t, normals=n, transform=transform, material=mat)


def flat_cube(centre, half, colour=(0.8, 0.6, 0.4), transform=None) -> Mesh:
    """A cube with 4 vertices per face and per-face normals (planar faces): ``primitives.box``."""
    pos, tris, nrm = box((half, half, half))
    mat = Material(ambient=colour, diffuse=colour, specular=(0.5, 0.5, 0.5), shininess=30.0)
    return Mesh(
        np.asarray(centre, dtype=np.float64) + pos,
        tris,
        normals=nrm,
        material=mat,
        transform=np.eye(4) if transform is None else transform,
    )


def scene_of(meshes, lights=(), camera=None, light_model=None) -> Scene:
    return Scene(
        tuple(meshes), tuple(lights), camera or ortho_camera(), light_model=light_model or LightModel()
    )


def render_transparency(scene: Scene, method: str, size: int = 48, layers: int | None = None) -> np.ndarray:
    """Opaque pass with a z-buffer, then transparent fragments resolved by ``method``: (size², 4)."""
    prepared = prepare_scene(scene)
    frags = rasterize(prepared.clip, prepared.triangles, size, size)
    opacity = np.array([m.material.opacity for m in scene.meshes])[prepared.triangle_mesh]

    def shade(index):
        shaded = shade_fragments(prepared, frags.subset(index), shading="flat")
        return np.c_[shaded.rgb * shaded.alpha[:, None], shaded.alpha]

    rgba, _ = transparency_pass(
        frags,
        opacity[frags.triangle] >= 1.0,
        shade,
        method,
        triangle_mesh=prepared.triangle_mesh,
        triangle_eye_distance=-prepared.face_eye_centroid[:, 2],
        layers=layers,
    )
    return rgba


def visible_surface_points(scene: Scene, size: int = 96) -> tuple[np.ndarray, np.ndarray]:
    """World positions and face normals of the nearest fragment of every covered pixel."""
    prepared = prepare_scene(scene)
    frags = rasterize(prepared.clip, prepared.triangles, size, size)
    win = resolve_nearest(frags)
    vis = frags.subset(win[win >= 0])
    inv_view = np.linalg.inv(scene.camera.view)
    eye = interpolate(vis, prepared.triangles, prepared.eye_position)
    world = (np.c_[eye, np.ones(len(eye))] @ inv_view.T)[:, :3]
    return world, prepared.face_world_normal[vis.triangle]


def world_triangles(scene: Scene) -> np.ndarray:
    parts = []
    for m in scene.meshes:
        w = (np.c_[m.positions, np.ones(len(m.positions))] @ m.transform.T)[:, :3]
        parts.append(w[m.triangles])
    return np.concatenate(parts)
